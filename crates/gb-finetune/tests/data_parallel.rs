//! Data-parallel fine-tuning (issue 35) with two ranks as two threads of this process,
//! exchanging through memory what an MPI run exchanges over the network: the ranks end with
//! bit-identical LoRA weights, and they train what one process trains at the same global
//! batch (`grad_accum` times the ranks).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Barrier, Mutex};

use gb_core::BackendKind;
use gb_finetune::captions::CaptionMode;
use gb_finetune::synthetic::SyntheticPairs;
use gb_finetune::train::grad_sync::{trainable_values, GradSync};
use gb_finetune::train::models::parameter_values;
use gb_finetune::train::{FinetuneConfig, FinetuneTrainer, PriorModels, TrainTarget};
use gb_finetune::FinetuneError;

use crate::DEVICE_RNG as LOCK;

fn prior_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../gb-diffusion/tests/fixtures/sd_image/pipeline")
}

fn config(grad_accum: usize) -> FinetuneConfig {
    FinetuneConfig {
        target: TrainTarget::Lora,
        steps: 3,
        batch: 1,
        grad_accum,
        lr: 1e-2,
        rank: 4,
        alpha: 4.0,
        resolution: 32,
        mode: CaptionMode::Identifiers,
        seed: 11,
        checkpoint_every: 0,
        validate_every: 0,
        validation_samples: 0,
        ..FinetuneConfig::default()
    }
}

/// The memory both threads exchange through: one slot per rank, and a barrier.
struct Exchange {
    slots: Mutex<Vec<Vec<f32>>>,
    barrier: Barrier,
}

/// One rank of a run whose ranks are the threads sharing `exchange`. Every rank sums the
/// slots in rank order, so every rank gets the same floats (as `MpiSync`'s reduce and
/// broadcast give).
struct ThreadRank {
    rank: usize,
    ranks: usize,
    exchange: Arc<Exchange>,
}

impl GradSync for ThreadRank {
    fn rank(&self) -> usize {
        self.rank
    }
    fn ranks(&self) -> usize {
        self.ranks
    }
    fn mean(&self, buffer: &mut [f32]) -> Result<(), FinetuneError> {
        self.exchange.slots.lock().unwrap()[self.rank] = buffer.to_vec();
        self.exchange.barrier.wait();
        {
            let slots = self.exchange.slots.lock().unwrap();
            for (i, v) in buffer.iter_mut().enumerate() {
                let sum: f32 = slots.iter().map(|s| s[i]).sum();
                *v = sum / self.ranks as f32;
            }
        }
        // nobody writes the next exchange before every rank has read this one
        self.exchange.barrier.wait();
        Ok(())
    }
    fn barrier(&self) -> Result<(), FinetuneError> {
        self.exchange.barrier.wait();
        Ok(())
    }
}

/// The LoRA factors of a trainer, by path.
fn lora(t: &FinetuneTrainer) -> BTreeMap<String, Vec<f32>> {
    parameter_values(&t.models.trainable)
        .unwrap()
        .into_iter()
        .filter(|(k, _)| k.contains(".lora.") || k.contains(".conv_lora."))
        .collect()
}

fn relative_gap(a: &[f32], b: &[f32]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    let norm: f64 = a.iter().map(|x| f64::from(*x).powi(2)).sum();
    (diff / norm.max(1e-30)).sqrt()
}

#[test]
fn two_ranks_train_what_one_process_trains_at_the_same_global_batch() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = BackendKind::Flex.autodiff_device();
    let src = SyntheticPairs::generate(&["stairs"], &[3], 48, 36).unwrap();
    let cfg = config(1);
    let steps = cfg.steps;

    // one process, two micro-batches per step
    let mut single = FinetuneTrainer::new(
        PriorModels::load(&prior_dir(), &device).unwrap(),
        config(2),
        &device,
    )
    .unwrap();
    for _ in 0..steps {
        let stats = single.train_step(&src).unwrap();
        assert_eq!((stats.exchanged_values, stats.exchange_seconds), (0, 0.0));
    }

    // two ranks of one micro-batch each; built here, one after the other, since the LoRA's
    // initialisation draws from the process-wide device RNG
    let exchange = Arc::new(Exchange {
        slots: Mutex::new(vec![Vec::new(); 2]),
        barrier: Barrier::new(2),
    });
    let ranks: Vec<FinetuneTrainer> = (0..2)
        .map(|rank| {
            FinetuneTrainer::new(
                PriorModels::load(&prior_dir(), &device).unwrap(),
                cfg.clone(),
                &device,
            )
            .unwrap()
            .with_sync(Box::new(ThreadRank {
                rank,
                ranks: 2,
                exchange: exchange.clone(),
            }))
        })
        .collect();
    let trained: Vec<FinetuneTrainer> = std::thread::scope(|s| {
        let handles: Vec<_> = ranks
            .into_iter()
            .map(|mut t| {
                let src = &src;
                s.spawn(move || {
                    for _ in 0..steps {
                        let stats = t.train_step(src).unwrap();
                        // every adapter value travels, once per step
                        let adapters = trainable_values(&t.models.trainable);
                        assert!(adapters > 0);
                        assert_eq!(stats.exchanged_values, adapters);
                    }
                    t
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });

    let (zero, one) = (lora(&trained[0]), lora(&trained[1]));
    assert!(!zero.is_empty());
    assert_eq!(zero, one, "the two ranks' LoRA weights differ");
    assert_eq!(trained[0].losses, trained[1].losses);

    let reference = lora(&single);
    let base = lora(
        &FinetuneTrainer::new(
            PriorModels::load(&prior_dir(), &device).unwrap(),
            config(2),
            &device,
        )
        .unwrap(),
    );
    let (mut moved, mut gap) = (0.0f64, 0.0f64);
    for (k, v) in &reference {
        gap = gap.max(relative_gap(v, &zero[k]));
        moved = moved.max(relative_gap(v, &base[k]));
    }
    assert!(
        gap < 1e-5,
        "LoRA weights {gap:e} (relative) from one process's"
    );
    // and the steps moved the factors far more than that
    assert!(moved > 1e-3, "the LoRA hardly moved ({moved:e})");
    for (a, b) in single.losses.iter().zip(&trained[0].losses) {
        assert!((a - b).abs() <= 1e-5 * a.abs(), "loss {a} against {b}");
    }
    // one micro-batch of one rank is not the global batch: a different loss
    let mut alone = FinetuneTrainer::new(
        PriorModels::load(&prior_dir(), &device).unwrap(),
        cfg,
        &device,
    )
    .unwrap();
    let l = alone.train_step(&src).unwrap().loss;
    assert!(
        (l - single.losses[0]).abs() > 1e-4 * l.abs(),
        "one rank's batch has the global batch's loss {l}"
    );
}

/// The same over MPI (the `mpi` feature): the test starts `mpirun -n 2` on this test binary,
/// filtered to itself; in each rank (`GB_MPI_ROLE` set) it trains with `MpiSync` and writes
/// its losses and LoRA factors to `GB_MPI_OUT/rank-R.json`.
#[cfg(feature = "mpi")]
mod over_mpi {
    use super::*;
    use gb_finetune::train::mpi_sync::MpiSync;
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    /// `mpirun -n 2` on this test binary, running only `test` in each rank with `role`; its
    /// exit status and how long it took. Killed after `limit`.
    fn mpirun(test: &str, role: &str, out: &std::path::Path, limit: Duration) -> (bool, Duration) {
        let exe = std::env::current_exe().unwrap();
        let start = Instant::now();
        let mut child = Command::new("mpirun")
            .args(["-n", "2", "--oversubscribe", "--allow-run-as-root"])
            .args([
                "-x",
                "GB_MPI_ROLE",
                "-x",
                "GB_MPI_OUT",
                "-x",
                "RAYON_NUM_THREADS",
                "-x",
                "GB_MPI_FIRST_TIMEOUT",
            ])
            // a short deadline for the rank that never arrives, the default's for the rest
            .env(
                "GB_MPI_FIRST_TIMEOUT",
                if role == "stall" { "4" } else { "600" },
            )
            .arg(exe)
            .args([test, "--exact", "--test-threads", "1", "--nocapture"])
            .env("GB_MPI_ROLE", role)
            .env("GB_MPI_OUT", out)
            .env("RAYON_NUM_THREADS", "1")
            .stdin(Stdio::null())
            .spawn()
            .expect("mpirun (Debian's openmpi-bin) is needed by the `mpi` feature's tests");
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                return (status.success(), start.elapsed());
            }
            if start.elapsed() > limit {
                child.kill().ok();
                child.wait().ok();
                return (false, start.elapsed());
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// One rank's part: train `steps` steps (with `die`, rank 1 aborts after the first).
    fn rank_main(role: &str) {
        let device = BackendKind::Flex.autodiff_device();
        let src = SyntheticPairs::generate(&["stairs"], &[3], 48, 36).unwrap();
        let sync = MpiSync::init().unwrap();
        let rank = sync.rank();
        let mut t = FinetuneTrainer::new(
            PriorModels::load(&prior_dir(), &device).unwrap(),
            config(1),
            &device,
        )
        .unwrap()
        .with_sync(Box::new(sync));
        if role == "stall" && rank == 1 {
            // a rank that never reaches its first exchange
            std::thread::sleep(Duration::from_secs(120));
        }
        for step in 0..t.config.steps {
            if role == "die" && rank == 1 && step == 1 {
                std::process::abort();
            }
            t.train_step(&src).unwrap();
        }
        let out = std::path::PathBuf::from(std::env::var("GB_MPI_OUT").unwrap());
        let json = serde_json::json!({"losses": t.losses, "lora": lora(&t)});
        std::fs::write(out.join(format!("rank-{rank}.json")), json.to_string()).unwrap();
    }

    #[test]
    fn two_mpi_ranks_train_what_one_process_trains() {
        if let Ok(role) = std::env::var("GB_MPI_ROLE") {
            return rank_main(&role);
        }
        let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let dir = tempfile::tempdir().unwrap();
        let (ok, _) = mpirun(
            "data_parallel::over_mpi::two_mpi_ranks_train_what_one_process_trains",
            "train",
            dir.path(),
            Duration::from_secs(600),
        );
        assert!(ok, "mpirun -n 2 failed");
        let read = |r: usize| -> serde_json::Value {
            serde_json::from_str(
                &std::fs::read_to_string(dir.path().join(format!("rank-{r}.json"))).unwrap(),
            )
            .unwrap()
        };
        let (zero, one) = (read(0), read(1));
        assert_eq!(zero, one, "the two ranks' losses or LoRA weights differ");
        let device = BackendKind::Flex.autodiff_device();
        let src = SyntheticPairs::generate(&["stairs"], &[3], 48, 36).unwrap();
        let mut single = FinetuneTrainer::new(
            PriorModels::load(&prior_dir(), &device).unwrap(),
            config(2),
            &device,
        )
        .unwrap();
        for _ in 0..single.config.steps {
            single.train_step(&src).unwrap();
        }
        let mpi_lora: BTreeMap<String, Vec<f32>> =
            serde_json::from_value(zero["lora"].clone()).unwrap();
        let mpi_losses: Vec<f64> = serde_json::from_value(zero["losses"].clone()).unwrap();
        let reference = lora(&single);
        assert_eq!(mpi_lora.len(), reference.len());
        for (k, v) in &reference {
            let gap = relative_gap(v, &mpi_lora[k]);
            assert!(gap < 1e-5, "{k}: {gap:e} (relative) from one process's");
        }
        for (a, b) in single.losses.iter().zip(&mpi_losses) {
            assert!((a - b).abs() <= 1e-5 * a.abs(), "loss {a} against {b}");
        }
    }

    /// Runs `test` as a two-rank job whose rank 1 fails as `role` says, and checks that the
    /// job fails within 60 s without rank 0 finishing alone.
    fn assert_the_job_ends(test: &str, role: &str) {
        let dir = tempfile::tempdir().unwrap();
        let (ok, took) = mpirun(test, role, dir.path(), Duration::from_secs(120));
        assert!(!ok, "mpirun succeeded although rank 1 failed ({role})");
        assert!(
            took < Duration::from_secs(60),
            "the job took {took:?} to end"
        );
        let finished = dir.path().join("rank-0.json").exists();
        assert!(!finished, "rank 0 finished alone");
    }

    #[test]
    fn a_rank_that_dies_ends_the_other() {
        if let Ok(role) = std::env::var("GB_MPI_ROLE") {
            return rank_main(&role);
        }
        // rank 1 aborts after its first step
        assert_the_job_ends(
            "data_parallel::over_mpi::a_rank_that_dies_ends_the_other",
            "die",
        );
    }

    #[test]
    fn a_rank_that_never_arrives_ends_the_job_at_the_first_exchange_s_deadline() {
        if let Ok(role) = std::env::var("GB_MPI_ROLE") {
            return rank_main(&role);
        }
        // rank 1 sleeps 120 s before its first exchange; rank 0 gives up after 4 s
        assert_the_job_ends(
            "data_parallel::over_mpi::\
             a_rank_that_never_arrives_ends_the_job_at_the_first_exchange_s_deadline",
            "stall",
        );
    }
}
