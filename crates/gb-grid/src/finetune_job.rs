//! Job files of a data-parallel fine-tuning run (`gb-nerf finetune ... --emit
//! slurm,kubernetes --ranks N`), for the MPI launchers clusters already run:
//!
//! - `OUT/finetune-slurm.sh`: one Slurm job of N tasks, one MPI rank each. Inside the
//!   allocation `mpirun -n $SLURM_NTASKS` starts the ranks (Open MPI reads the allocation);
//!   `GB_LAUNCH=srun` uses `srun --mpi=pmix` instead. Submit it with `sbatch`.
//! - `OUT/finetune-mpijob.yaml`: a Kubeflow MPI Operator `MPIJob` (`kubeflow.org/v2beta1`,
//!   Open MPI): a launcher pod running `mpirun -n N gb-nerf finetune ...` and N worker pods.
//!   The image must hold `gb-nerf` built with the `mpi` feature, and the launcher reaches the
//!   workers as the operator arranges (its SSH keys). The command runs in the folder it was
//!   emitted from, which a PersistentVolumeClaim `gb-nerf-finetune` is mounted at: the data,
//!   prior and output paths of the command line must lie under it (or be mounted likewise).
//!   Written as JSON, which YAML reads; apply it with `kubectl apply -f`.
//!
//! Both run the command line that emitted them, without `--emit` and `--ranks`, with
//! `--data-parallel mpi`, from the same working folder.

use std::path::PathBuf;

use gb_inpaint::run::shell_quote;
use gb_inpaint::InpaintError;

use crate::emit::{k8s_name, write_job_file, EmitOptions, Engine};

/// The Slurm script's name in the output folder.
pub const SLURM_FILE: &str = "finetune-slurm.sh";
/// The MPIJob manifest's name in the output folder.
pub const MPIJOB_FILE: &str = "finetune-mpijob.yaml";

/// What the jobs of one fine-tuning run share.
#[derive(Debug, Clone)]
pub struct FinetuneJob {
    /// The `finetune` arguments each rank runs (after the command's name and `finetune`),
    /// [`job_args`].
    pub args: Vec<String>,
    /// Ranks (MPI processes).
    pub ranks: usize,
    /// The folder the command runs in (absolute).
    pub workdir: PathBuf,
    /// The run's output folder (absolute): the Slurm log lands there.
    pub out: PathBuf,
}

/// The `finetune` arguments of a command line `argv` (its arguments after `finetune`),
/// without the emission's own flags (`--emit`, `--ranks`, `--image`, `--cpus`, `--gpus`) and
/// any `--data-parallel`, which the job sets to `mpi`.
pub fn job_args(argv: &[String]) -> Vec<String> {
    let dropped = [
        "--emit",
        "--ranks",
        "--image",
        "--cpus",
        "--gpus",
        "--data-parallel",
    ];
    let mut out = Vec::new();
    let mut skip_value = false;
    for a in argv {
        if std::mem::take(&mut skip_value) {
            continue;
        }
        if dropped.contains(&a.as_str()) {
            skip_value = true;
            continue;
        }
        if dropped.iter().any(|d| a.starts_with(&format!("{d}="))) {
            continue;
        }
        out.push(a.clone());
    }
    out.extend(["--data-parallel".to_string(), "mpi".to_string()]);
    out
}

fn quoted(args: &[String]) -> String {
    args.iter()
        .map(|a| shell_quote(a))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The Slurm script of `job`.
pub fn slurm_script(job: &FinetuneJob, opts: &EmitOptions) -> String {
    let gpus = if opts.gpus > 0 {
        format!("#SBATCH --gpus-per-task={}\n", opts.gpus)
    } else {
        String::new()
    };
    let out = job.out.display().to_string();
    let args = quoted(&job.args);
    format!(
        "#!/bin/bash\n\
         # gb-nerf data-parallel LoRA fine-tuning: {ranks} MPI ranks, one Slurm task each.\n\
         # Submit: sbatch {script}\n\
         #SBATCH --job-name=gb-nerf-finetune\n\
         #SBATCH --ntasks={ranks}\n\
         #SBATCH --cpus-per-task={cpus}\n\
         {gpus}\
         #SBATCH --output={out}/slurm-%j.out\n\
         #SBATCH --chdir={workdir}\n\
         set -euo pipefail\n\
         # each rank's thread pool on its own cores\n\
         export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n\
         cmd=\"${{GB_NERF:-{command}}}\"\n\
         if [ \"${{GB_LAUNCH:-mpirun}}\" = srun ]; then\n\
         \x20   exec srun --mpi=pmix \"$cmd\" finetune {args}\n\
         fi\n\
         exec mpirun -n \"$SLURM_NTASKS\" -x RAYON_NUM_THREADS \"$cmd\" finetune {args}\n",
        ranks = job.ranks,
        script = shell_quote(&job.out.join(SLURM_FILE).display().to_string()),
        cpus = opts.cpus,
        workdir = job.workdir.display(),
        command = opts.command,
    )
}

/// The MPIJob manifest of `job`.
pub fn mpijob_manifest(job: &FinetuneJob, opts: &EmitOptions) -> String {
    let workdir = job.workdir.display().to_string();
    let mut command: Vec<String> = ["mpirun", "-n"].iter().map(|s| s.to_string()).collect();
    command.push(job.ranks.to_string());
    command.extend(["-x", "RAYON_NUM_THREADS", "gb-nerf", "finetune"].map(String::from));
    command.extend(job.args.iter().cloned());
    let cpu = opts.cpus.to_string();
    let mut limits = serde_json::json!({ "cpu": cpu });
    if opts.gpus > 0 {
        limits["nvidia.com/gpu"] = serde_json::json!(opts.gpus.to_string());
    }
    let mount = serde_json::json!([{ "name": "work", "mountPath": workdir }]);
    let volumes = serde_json::json!([{
        "name": "work",
        "persistentVolumeClaim": { "claimName": "gb-nerf-finetune" }
    }]);
    let manifest = serde_json::json!({
        "apiVersion": "kubeflow.org/v2beta1",
        "kind": "MPIJob",
        "metadata": { "name": k8s_name("gb-nerf-finetune", &job.out) },
        "spec": {
            "slotsPerWorker": 1,
            "runPolicy": { "cleanPodPolicy": "Running" },
            "mpiImplementation": "OpenMPI",
            "mpiReplicaSpecs": {
                "Launcher": {
                    "replicas": 1,
                    "template": { "spec": {
                        "containers": [{
                            "name": "launcher",
                            "image": opts.image,
                            "command": command,
                            "workingDir": workdir,
                            "env": [{ "name": "RAYON_NUM_THREADS", "value": cpu }],
                            "volumeMounts": mount,
                        }],
                        "volumes": volumes,
                    }},
                },
                "Worker": {
                    "replicas": job.ranks,
                    "template": { "spec": {
                        "containers": [{
                            "name": "worker",
                            "image": opts.image,
                            "resources": { "requests": { "cpu": cpu }, "limits": limits },
                            "volumeMounts": mount,
                        }],
                        "volumes": volumes,
                    }},
                },
            },
        },
    });
    // `{:#}`: serde_json's pretty form, which cannot fail for a `Value`
    format!(
        "# gb-nerf data-parallel LoRA fine-tuning: {} MPI ranks (Kubeflow MPI Operator).\n\
         # Apply: kubectl apply -f {MPIJOB_FILE}\n{manifest:#}\n",
        job.ranks
    )
}

/// Writes the job files of `engines` into `job.out`; returns their paths.
pub fn write_finetune_jobs(
    job: &FinetuneJob,
    engines: &[Engine],
    opts: &EmitOptions,
) -> Result<Vec<PathBuf>, InpaintError> {
    std::fs::create_dir_all(&job.out).map_err(|e| InpaintError::io(&job.out, e))?;
    let mut written = Vec::new();
    for engine in engines {
        let (file, text) = match engine {
            Engine::Slurm => (SLURM_FILE, slurm_script(job, opts)),
            Engine::Kubernetes => (MPIJOB_FILE, mpijob_manifest(job, opts)),
        };
        written.push(write_job_file(&job.out.join(file), &text, *engine)?);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn the_job_runs_the_command_line_without_the_emission_s_flags() {
        let argv = strings(&[
            "--diode",
            "data/diode",
            "--emit",
            "slurm,kubernetes",
            "--ranks=4",
            "--base",
            "my prior",
            "--data-parallel",
            "none",
        ]);
        assert_eq!(
            job_args(&argv),
            strings(&[
                "--diode",
                "data/diode",
                "--base",
                "my prior",
                "--data-parallel",
                "mpi"
            ])
        );
    }

    #[test]
    fn the_slurm_script_starts_one_rank_per_task() {
        let job = FinetuneJob {
            args: job_args(&strings(&["--synthetic", "--out", "runs/lora 1"])),
            ranks: 3,
            workdir: "/cluster/home/me".into(),
            out: "/cluster/home/me/runs/lora 1".into(),
        };
        let opts = EmitOptions {
            command: "/opt/gb-nerf".into(),
            cpus: 2,
            ..EmitOptions::default()
        };
        let s = slurm_script(&job, &opts);
        assert!(s.starts_with("#!/bin/bash\n"), "{s}");
        for line in [
            "#SBATCH --ntasks=3\n",
            "#SBATCH --cpus-per-task=2\n",
            "#SBATCH --chdir=/cluster/home/me\n",
            "cmd=\"${GB_NERF:-/opt/gb-nerf}\"\n",
            "exec mpirun -n \"$SLURM_NTASKS\" -x RAYON_NUM_THREADS \"$cmd\" finetune \
             --synthetic --out 'runs/lora 1' --data-parallel mpi\n",
        ] {
            assert!(s.contains(line), "no {line:?} in\n{s}");
        }
        assert_eq!(
            k8s_name("gb-nerf-finetune", &job.out),
            "gb-nerf-finetune-lora-1"
        );
    }
}
