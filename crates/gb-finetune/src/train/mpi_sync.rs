//! [`MpiSync`]: the gradient exchange of [`super::grad_sync`] over MPI (the `mpi` feature,
//! off by default; it needs Debian's `libopenmpi-dev openmpi-bin libclang-dev`).
//!
//! The mean is a reduction to rank 0 followed by a broadcast from it, not an `MPI_Allreduce`:
//! MPI does not promise that every rank of an all-reduce gets the same floats, and the ranks
//! must take bit-identical steps, or their LoRA weights drift apart.
//!
//! A rank that dies ends the others: MPI's default error handler on the world communicator
//! aborts the job, and `mpirun` and `srun` end the remaining ranks when one exits early. A
//! rank that never arrives (it hangs before its first exchange) would leave the others
//! waiting forever: the first collective of each rank has a deadline
//! ([`FIRST_EXCHANGE_TIMEOUT_VAR`], default [`FIRST_EXCHANGE_TIMEOUT`]), after which the rank
//! exits with one line naming itself, and the launcher ends the rest.

use std::cell::Cell;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

use mpi::collective::SystemOperation;
use mpi::environment::Universe;
use mpi::traits::{Communicator, CommunicatorCollectives, Root};
use mpi::Threading;

use super::grad_sync::GradSync;
use crate::FinetuneError;

/// How long a rank's first collective waits for the others by default (loading a full-size
/// prior on a slow file system takes minutes).
pub const FIRST_EXCHANGE_TIMEOUT: Duration = Duration::from_secs(600);
/// The variable that sets that deadline, in seconds.
pub const FIRST_EXCHANGE_TIMEOUT_VAR: &str = "GB_MPI_FIRST_TIMEOUT";

/// One rank of a data-parallel run launched by `mpirun`, `srun` or an MPI operator.
pub struct MpiSync {
    universe: Universe,
    rank: usize,
    ranks: usize,
    /// The deadline of the first collective, until it has run.
    first: Cell<Option<Duration>>,
}

// SAFETY: MPI is initialised with `Threading::Serialized`, under which any thread may call
// MPI as long as no two do at once. `MpiSync` is not `Sync`, and each of its calls takes
// `&self` on the one thread that holds it, so moving it to another thread keeps the calls
// serialised.
unsafe impl Send for MpiSync {}

impl MpiSync {
    /// Initialises MPI for this process (once per process; dropping the `MpiSync` finalises
    /// it). An error when MPI was already initialised, or cannot give serialised threading.
    pub fn init() -> Result<Self, FinetuneError> {
        let bad = |message: String| FinetuneError::Config {
            field: "--data-parallel".into(),
            message,
        };
        let (universe, threading) = mpi::initialize_with_threading(Threading::Serialized)
            .ok_or_else(|| bad("MPI was already initialised in this process".into()))?;
        if threading < Threading::Serialized {
            return Err(bad(format!(
                "the MPI library offers threading level {threading:?}; serialised is needed"
            )));
        }
        let first = match std::env::var(FIRST_EXCHANGE_TIMEOUT_VAR) {
            Ok(v) => Duration::from_secs_f64(
                v.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|s| s.is_finite() && *s > 0.0)
                    .ok_or_else(|| FinetuneError::Config {
                        field: FIRST_EXCHANGE_TIMEOUT_VAR.into(),
                        message: format!("'{v}' is not a positive number of seconds"),
                    })?,
            ),
            Err(_) => FIRST_EXCHANGE_TIMEOUT,
        };
        let world = universe.world();
        let (rank, ranks) = (world.rank() as usize, world.size() as usize);
        Ok(Self {
            universe,
            rank,
            ranks,
            first: Cell::new(Some(first)),
        })
    }

    /// Runs a collective; the first one under its deadline (module docs): a watchdog thread,
    /// which calls no MPI, ends the process if the collective has not returned by then.
    fn collective<T>(&self, run: impl FnOnce() -> T) -> T {
        let Some(limit) = self.first.take() else {
            return run();
        };
        let (done, wait) = mpsc::channel::<()>();
        let (rank, ranks) = (self.rank, self.ranks);
        std::thread::spawn(move || {
            if let Err(RecvTimeoutError::Timeout) = wait.recv_timeout(limit) {
                eprintln!(
                    "error: rank {rank} of {ranks}: the first exchange waited {:.0} s for the \
                     other ranks; one of them did not start or hangs before it \
                     ({FIRST_EXCHANGE_TIMEOUT_VAR} sets the limit)",
                    limit.as_secs_f64()
                );
                std::process::exit(1);
            }
        });
        let out = run();
        done.send(()).ok();
        out
    }
}

impl GradSync for MpiSync {
    fn rank(&self) -> usize {
        self.rank
    }

    fn ranks(&self) -> usize {
        self.ranks
    }

    fn mean(&self, buffer: &mut [f32]) -> Result<(), FinetuneError> {
        if self.ranks <= 1 {
            return Ok(());
        }
        let world = self.universe.world();
        let root = world.process_at_rank(0);
        self.collective(|| {
            if self.rank == 0 {
                let mine = buffer.to_vec();
                root.reduce_into_root(&mine[..], buffer, SystemOperation::sum());
                let n = self.ranks as f32;
                for v in buffer.iter_mut() {
                    *v /= n;
                }
            } else {
                root.reduce_into(&buffer[..], SystemOperation::sum());
            }
            root.broadcast_into(buffer);
        });
        Ok(())
    }

    fn barrier(&self) -> Result<(), FinetuneError> {
        self.collective(|| self.universe.world().barrier());
        Ok(())
    }
}
