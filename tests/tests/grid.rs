//! The method grid as independent cells (`gb_grid`): a 2-cell grid is planned and
//! its Slurm and Kubernetes job files emitted, each cell is run by its index (one through
//! the CLI, one through the library), and the merged tables equal the single-process
//! `cargo xtask ablate` of the same grid, timings aside. The Kubernetes manifest parses
//! into the Kubernetes API types. The jobs of a data-parallel fine-tuning run
//! (`finetune --emit slurm,kubernetes --ranks N`): the MPIJob parses into typed structs of
//! the MPI Operator's `kubeflow.org/v2beta1` schema.

use std::path::Path;

use gb_grid::emit::{kubernetes_job, EmitOptions};
use gb_tests::{
    assert_success, path_str as s, small_grid_flags, small_preset, small_stairs, xtask,
};
use serde_json::Value;

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A table without its wall times (`seconds`, `train_seconds`), which differ between runs.
fn without_times(mut v: Value) -> Value {
    fn strip(v: &mut Value) {
        match v {
            Value::Object(m) => {
                m.remove("seconds");
                m.remove("train_seconds");
                m.values_mut().for_each(strip);
            }
            Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut v);
    v
}

#[test]
fn a_two_cell_grid_runs_by_index_and_merges_like_the_single_process_ablate() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_stairs(dir.path(), 128, 96, 0);
    let preset = small_preset(dir.path(), None);
    let (grid, single) = (dir.path().join("grid"), dir.path().join("single"));
    let common = small_grid_flags(s(&scene), s(&preset));
    let mut emit = vec!["ablate"];
    emit.extend(&common);
    emit.extend(["--emit", "slurm,kubernetes", "--out", s(&grid)]);
    assert_success(&xtask(&emit), "ablate --emit");
    let planned = gb_grid::Grid::read(&grid).unwrap();
    let dirs: Vec<&str> = planned.cells.iter().map(|c| c.dir.as_str()).collect();
    assert_eq!(dirs, ["none", "mvip-nerf"]);
    assert!(planned.sweep.is_empty(), "no csd, no --w3: no sweep");
    let slurm = std::fs::read_to_string(grid.join("slurm.sh")).unwrap();
    assert!(slurm.contains("#SBATCH --array=0-1\n"), "{slurm}");
    let job = std::fs::read_to_string(grid.join("job.yaml")).unwrap();
    assert!(job.contains("completions: 2\n"), "{job}");
    assert!(!grid.join("none").exists(), "--emit runs nothing");

    // cell 0 by the CLI; the merge then names the missing cell 1 and fails
    let g = s(&grid);
    assert_success(&xtask(&["ablate", "--grid", g, "--cell", "0"]), "--cell 0");
    assert_eq!(json(&grid.join("none/metrics.json"))["steps"], 2);
    let partial = xtask(&["ablate", "--grid", g, "--merge"]);
    let err = String::from_utf8_lossy(&partial.stderr);
    assert_eq!(partial.status.code(), Some(2), "{err}");
    assert!(err.contains("1 cell(s) have not finished: [1]"), "{err}");
    let report = gb_grid::merge(&grid).unwrap();
    assert_eq!(report.missing, [1]);

    // cell 1 by the library; a bad index is an error naming it
    let outcome = {
        // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
        let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
        gb_grid::run_cell(&grid, 1).unwrap()
    };
    assert_eq!(outcome.result.as_ref().map(|r| r.steps), Ok(2));
    let bad = gb_grid::run_cell(&grid, 2).unwrap_err().to_string();
    assert!(
        bad.starts_with("--cell 2: ") && bad.contains("2 cell(s)"),
        "{bad}"
    );
    assert_success(&xtask(&["ablate", "--grid", g, "--merge"]), "--merge");

    let mut one = vec!["ablate"];
    one.extend(&common);
    one.extend(["--out", s(&single)]);
    assert_success(&xtask(&one), "ablate");
    for table in ["baselines.json", "ablation.json", "w3_sweep.json"] {
        let (a, b) = (json(&grid.join(table)), json(&single.join(table)));
        assert_eq!(without_times(a.clone()), without_times(b), "{table}");
        if table == "baselines.json" {
            let rows = a["rows"].as_array().unwrap();
            assert_eq!(rows.len(), 2, "{a:#}");
            assert!(
                rows.iter().all(|r| r["ssim_bbox"].as_f64().is_some()),
                "{a:#}"
            );
        }
    }
}

#[test]
fn the_kubernetes_job_parses_into_the_api_types() {
    use k8s_openapi::api::batch::v1::Job;
    let opts = EmitOptions {
        image: "registry.example/gb-nerf:0.1".into(),
        cpus: 8,
        gpus: 1,
        ..EmitOptions::default()
    };
    let text = kubernetes_job(Path::new("/data/grids/stairs w3"), 7, &opts);
    let job: Job = serde_norway::from_str(&text).unwrap();
    assert_eq!(job.metadata.name.as_deref(), Some("gb-nerf-grid-stairs-w3"));
    let spec = job.spec.unwrap();
    assert_eq!(spec.completion_mode.as_deref(), Some("Indexed"));
    assert_eq!((spec.completions, spec.parallelism), (Some(7), Some(7)));
    let pod = spec.template.spec.unwrap();
    assert_eq!(pod.restart_policy.as_deref(), Some("Never"));
    let c = &pod.containers[0];
    assert_eq!(c.image.as_deref(), Some("registry.example/gb-nerf:0.1"));
    let cmd = c.command.as_ref().unwrap();
    assert_eq!(cmd[..2], ["/bin/sh".to_string(), "-c".to_string()]);
    assert_eq!(
        cmd[2],
        "exec gb-nerf ablate --grid '/data/grids/stairs w3' --cell \"$JOB_COMPLETION_INDEX\""
    );
    let limits = c.resources.as_ref().unwrap().limits.as_ref().unwrap();
    assert_eq!(limits["cpu"].0, "8");
    assert_eq!(limits["nvidia.com/gpu"].0, "1");
    let mount = &c.volume_mounts.as_ref().unwrap()[0];
    assert_eq!(mount.mount_path, "/data/grids/stairs w3");
    let volume = &pod.volumes.as_ref().unwrap()[0];
    assert_eq!(volume.name, mount.name);
    assert!(volume.persistent_volume_claim.is_some());
}

/// The MPI Operator's `MPIJob` (kubeflow.org/v2beta1), the fields the emitted manifest
/// uses; an unknown field is an error, so a misspelt one fails.
mod mpijob {
    use k8s_openapi::api::core::v1::PodTemplateSpec;
    use k8s_openapi::apimachinery::pkg::apis::meta::v1::ObjectMeta;
    use serde::Deserialize;

    #[derive(Deserialize)]
    #[serde(rename_all = "camelCase", deny_unknown_fields)]
    pub struct MpiJob {
        pub api_version: String,
        pub kind: String,
        pub metadata: ObjectMeta,
        pub spec: MpiJobSpec,
    }

    #[derive(Deserialize)]
    #[serde(rename_all = "camelCase", deny_unknown_fields)]
    pub struct MpiJobSpec {
        pub slots_per_worker: i32,
        pub run_policy: RunPolicy,
        pub mpi_implementation: String,
        pub mpi_replica_specs: ReplicaSpecs,
    }

    #[derive(Deserialize)]
    #[serde(rename_all = "camelCase", deny_unknown_fields)]
    pub struct RunPolicy {
        pub clean_pod_policy: String,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct ReplicaSpecs {
        #[serde(rename = "Launcher")]
        pub launcher: ReplicaSpec,
        #[serde(rename = "Worker")]
        pub worker: ReplicaSpec,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct ReplicaSpec {
        pub replicas: i32,
        pub template: PodTemplateSpec,
    }
}

#[test]
fn the_finetune_jobs_run_the_command_line_over_mpi() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("lora run");
    let args = [
        "finetune",
        "--synthetic",
        "--base",
        "tiny",
        "--steps",
        "3",
        "--out",
        s(&out),
        "--emit",
        "slurm,kubernetes",
        "--ranks",
        "2",
        "--image",
        "registry.example/gb-nerf:mpi",
        "--cpus",
        "3",
    ];
    let o = xtask(&args);
    assert_success(&o, "finetune --emit");
    // nothing trained
    assert!(!out.join("config.toml").exists());
    let text = std::fs::read_to_string(out.join("finetune-mpijob.yaml")).unwrap();
    let job: mpijob::MpiJob = serde_norway::from_str(&text).unwrap();
    assert_eq!(
        (job.api_version.as_str(), job.kind.as_str()),
        ("kubeflow.org/v2beta1", "MPIJob")
    );
    assert_eq!(
        job.metadata.name.as_deref(),
        Some("gb-nerf-finetune-lora-run")
    );
    let spec = job.spec;
    assert_eq!(spec.mpi_implementation, "OpenMPI");
    assert_eq!(
        (
            spec.slots_per_worker,
            spec.run_policy.clean_pod_policy.as_str()
        ),
        (1, "Running")
    );
    let specs = spec.mpi_replica_specs;
    assert_eq!((specs.launcher.replicas, specs.worker.replicas), (1, 2));
    let launcher = &specs.launcher.template.spec.unwrap().containers[0];
    assert_eq!(
        launcher.image.as_deref(),
        Some("registry.example/gb-nerf:mpi")
    );
    let command = launcher.command.clone().unwrap();
    // the command line before --emit, run by mpirun over the ranks
    let expected: Vec<String> = ["mpirun", "-n", "2", "-x", "RAYON_NUM_THREADS", "gb-nerf"]
        .iter()
        .chain(&args[..8])
        .chain(&["--data-parallel", "mpi"])
        .map(|a| a.to_string())
        .collect();
    assert_eq!(&args[7], &s(&out));
    assert_eq!(command, expected);
    let worker = specs.worker.template.spec.unwrap();
    let limits = worker.containers[0]
        .resources
        .clone()
        .unwrap()
        .limits
        .unwrap();
    assert_eq!(limits["cpu"].0, "3");
    assert_eq!(
        worker.volumes.unwrap()[0]
            .persistent_volume_claim
            .as_ref()
            .unwrap()
            .claim_name,
        "gb-nerf-finetune"
    );
    let script = std::fs::read_to_string(out.join("finetune-slurm.sh")).unwrap();
    assert!(script.contains("#SBATCH --ntasks=2\n"), "{script}");
    assert!(script.contains("#SBATCH --cpus-per-task=3\n"), "{script}");
    assert!(
        script.contains("finetune --synthetic --base tiny --steps 3 --out "),
        "{script}"
    );
    assert!(
        script.trim_end().ends_with("run' --data-parallel mpi"),
        "{script}"
    );
    // one clear line for a job of one rank
    let o = xtask(&[
        "finetune",
        "--synthetic",
        "--base",
        "tiny",
        "--out",
        s(&out),
        "--emit",
        "slurm",
        "--ranks",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--ranks 1: a data-parallel job needs at least 2 ranks"),
        "{err}"
    );
}
