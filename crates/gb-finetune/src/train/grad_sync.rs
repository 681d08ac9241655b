//! The gradient exchange of data-parallel fine-tuning (issue 35). Every rank trains the same
//! LoRA from the same seed on its shard of each global batch; before the clip and the
//! optimiser step, the ranks replace their gradients by the mean over all ranks, so that
//! every rank takes the same step. [`GradSync`] is that exchange. [`SingleProcess`] has
//! nothing to exchange, so a one-process run goes through the same call; a transport over
//! MPI implements the trait behind the `mpi` feature.
//!
//! The gradients travel as one flat `f32` buffer: every float parameter of the module that
//! has a gradient, in the module's visiting order (the same on every rank, since every rank
//! builds the same module), each flattened row-major.

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};

use crate::FinetuneError;

/// How the ranks of a run agree on one gradient.
pub trait GradSync {
    /// This process's rank, from 0.
    fn rank(&self) -> usize;
    /// How many ranks train together.
    fn ranks(&self) -> usize;
    /// Replaces every value of `buffer` by its mean over the ranks. Every rank passes a
    /// buffer of the same length, laid out the same way.
    fn mean(&self, buffer: &mut [f32]) -> Result<(), FinetuneError>;
    /// Waits until every rank has reached this call (after rank 0 alone writes a file that
    /// the others may read next).
    fn barrier(&self) -> Result<(), FinetuneError>;
}

/// One process: the mean of one rank is its own gradient.
#[derive(Debug, Clone, Copy, Default)]
pub struct SingleProcess;

impl GradSync for SingleProcess {
    fn rank(&self) -> usize {
        0
    }

    fn ranks(&self) -> usize {
        1
    }

    fn mean(&self, _buffer: &mut [f32]) -> Result<(), FinetuneError> {
        Ok(())
    }

    fn barrier(&self) -> Result<(), FinetuneError> {
        Ok(())
    }
}

/// The variables that MPI launchers set to the number of ranks: Open MPI's `mpirun`, and the
/// PMI of MPICH's `mpiexec` and of Slurm's `srun --mpi=pmi2`.
pub const MPI_SIZE_VARIABLES: [&str; 2] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"];

/// How many ranks an MPI launcher started this process among, read from its environment
/// ([`MPI_SIZE_VARIABLES`]); `None` outside such a launch. The command line uses it to train
/// data-parallel when launched by `mpirun -n N` (N > 1), and to refuse a build without the
/// `mpi` feature in that case rather than train N identical copies.
pub fn launched_ranks(var: impl Fn(&str) -> Option<String>) -> Option<usize> {
    MPI_SIZE_VARIABLES
        .iter()
        .find_map(|name| var(name).and_then(|v| v.trim().parse::<usize>().ok()))
}

/// Counts the values of the parameters that train (require a gradient).
struct CountTrainable(usize);

impl ModuleVisitor for CountTrainable {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let value = param.val();
        if value.is_require_grad() {
            self.0 += value.shape().num_elements();
        }
    }
}

/// How many values of `module` train: what a full exchange moves per rank and step.
pub fn trainable_values<M: Module>(module: &M) -> usize {
    let mut count = CountTrainable(0);
    module.visit(&mut count);
    count.0
}

/// Where one parameter's gradient lies in the flat buffer.
#[derive(Debug, Clone)]
struct Slot {
    id: ParamId,
    shape: Vec<usize>,
    start: usize,
    len: usize,
}

/// Collects the gradients of a module's parameters into the flat buffer.
struct Gather<'a> {
    grads: &'a GradientsParams,
    buffer: Vec<f32>,
    slots: Vec<Slot>,
    device: Option<Device>,
    error: Option<String>,
}

impl ModuleVisitor for Gather<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let Some(g) = self.grads.get::<D>(param.id) else {
            return;
        };
        self.device.get_or_insert_with(|| g.device());
        let shape = g.dims().to_vec();
        match g.into_data().try_into_vec_as::<f32>() {
            Ok(values) => {
                self.slots.push(Slot {
                    id: param.id,
                    shape,
                    start: self.buffer.len(),
                    len: values.len(),
                });
                self.buffer.extend(values);
            }
            Err(e) => {
                self.error
                    .get_or_insert(format!("reading the gradient of {}: {e:?}", param.id));
            }
        }
    }
}

/// Writes one slot of the buffer back as the gradient of its parameter.
fn write_back<const D: usize>(
    grads: &mut GradientsParams,
    slot: &Slot,
    buffer: &[f32],
    device: &Device,
) {
    let values = buffer[slot.start..slot.start + slot.len].to_vec();
    let tensor = Tensor::<D>::from_data(TensorData::new(values, slot.shape.clone()), device);
    grads.register(slot.id, tensor);
}

/// Replaces `grads` (of `module`'s parameters) by their mean over the ranks of `sync`, and
/// returns how many values each rank exchanged. With one rank there is nothing to exchange
/// (0) and the gradients stay as they are, untouched.
pub fn mean_gradients<M: Module>(
    module: &M,
    grads: &mut GradientsParams,
    sync: &dyn GradSync,
) -> Result<usize, FinetuneError> {
    if sync.ranks() <= 1 {
        return Ok(0);
    }
    let mut gather = Gather {
        grads,
        buffer: Vec::new(),
        slots: Vec::new(),
        device: None,
        error: None,
    };
    module.visit(&mut gather);
    let Gather {
        mut buffer,
        slots,
        device,
        error,
        ..
    } = gather;
    if let Some(e) = error {
        return Err(FinetuneError::diffusion("data-parallel gradients", e));
    }
    let Some(device) = device else {
        // no parameter has a gradient: every rank agrees on nothing to exchange
        return Ok(0);
    };
    sync.mean(&mut buffer)?;
    for slot in &slots {
        match slot.shape.len() {
            1 => write_back::<1>(grads, slot, &buffer, &device),
            2 => write_back::<2>(grads, slot, &buffer, &device),
            3 => write_back::<3>(grads, slot, &buffer, &device),
            4 => write_back::<4>(grads, slot, &buffer, &device),
            rank => {
                return Err(FinetuneError::diffusion(
                    "data-parallel gradients",
                    format!("a parameter of rank {rank} (1 to 4 are exchanged)"),
                ))
            }
        }
    }
    Ok(buffer.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::{Linear, LinearConfig};
    use std::cell::RefCell;

    /// Two ranks in one process: the other rank's buffer is given, and the mean is taken
    /// with it (what an all-reduce of the two would return).
    struct TwoRanks {
        other: RefCell<Vec<f32>>,
    }

    impl GradSync for TwoRanks {
        fn rank(&self) -> usize {
            0
        }
        fn ranks(&self) -> usize {
            2
        }
        fn mean(&self, buffer: &mut [f32]) -> Result<(), FinetuneError> {
            let other = self.other.borrow();
            if other.len() != buffer.len() {
                return Err(FinetuneError::diffusion(
                    "test",
                    format!("{} values against {}", buffer.len(), other.len()),
                ));
            }
            for (v, o) in buffer.iter_mut().zip(other.iter()) {
                *v = (*v + o) / 2.0;
            }
            Ok(())
        }
        fn barrier(&self) -> Result<(), FinetuneError> {
            Ok(())
        }
    }

    fn input(seed: u64, device: &Device) -> Tensor<2> {
        let values: Vec<f32> = (0..12)
            .map(|i| (((i as u64 + 1) * (seed * 7 + 3)) % 11) as f32 / 11.0 - 0.4)
            .collect();
        Tensor::from_data(TensorData::new(values, [3, 4]), device)
    }

    /// The gradients of the loss `sum(layer(x)^2)` on the shard `x`.
    fn grads_of(layer: &Linear, x: Tensor<2>) -> GradientsParams {
        let loss = layer.forward(x).powi_scalar(2).sum();
        GradientsParams::from_grads(loss.backward(), layer)
    }

    fn values(grads: &GradientsParams, layer: &Linear) -> Vec<f32> {
        let mut g = Gather {
            grads,
            buffer: Vec::new(),
            slots: Vec::new(),
            device: None,
            error: None,
        };
        layer.visit(&mut g);
        g.buffer
    }

    #[test]
    fn two_ranks_end_with_the_gradient_of_the_mean_loss() {
        let device = gb_core::BackendKind::Flex.autodiff_device();
        device.seed(5);
        let layer: Linear = LinearConfig::new(4, 2).init(&device);
        let (a, b) = (input(1, &device), input(2, &device));
        let mut mine = grads_of(&layer, a.clone());
        let other = values(&grads_of(&layer, b.clone()), &layer);
        assert_eq!(other.len(), 4 * 2 + 2, "weight and bias");
        let sync = TwoRanks {
            other: RefCell::new(other),
        };
        assert_eq!(mean_gradients(&layer, &mut mine, &sync).unwrap(), 10);
        assert_eq!(trainable_values(&layer), 10);
        // the mean of the two shards' gradients is the gradient of the mean of their losses
        let loss = (layer.forward(a).powi_scalar(2).sum() + layer.forward(b).powi_scalar(2).sum())
            .div_scalar(2.0);
        let expected = values(
            &GradientsParams::from_grads(loss.backward(), &layer),
            &layer,
        );
        let got = values(&mine, &layer);
        assert_eq!(got.len(), expected.len());
        for (g, e) in got.iter().zip(&expected) {
            assert!((g - e).abs() < 1e-5, "{got:?} against {expected:?}");
        }
        // a rank whose buffer is laid out otherwise is an error, not a silent mix
        let short = TwoRanks {
            other: RefCell::new(vec![0.0; 3]),
        };
        assert!(mean_gradients(&layer, &mut mine, &short).is_err());
    }

    #[test]
    fn an_mpi_launch_is_read_from_its_environment() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(
            launched_ranks(env(&[("OMPI_COMM_WORLD_SIZE", "4")])),
            Some(4)
        );
        assert_eq!(launched_ranks(env(&[("PMI_SIZE", " 2\n")])), Some(2));
        assert_eq!(launched_ranks(env(&[("SLURM_NTASKS", "2")])), None);
        assert_eq!(launched_ranks(env(&[("PMI_SIZE", "two")])), None);
    }

    #[test]
    fn one_process_leaves_the_gradients_as_they_are() {
        let device = gb_core::BackendKind::Flex.autodiff_device();
        device.seed(6);
        let layer: Linear = LinearConfig::new(4, 2).init(&device);
        let mut grads = grads_of(&layer, input(3, &device));
        let before = values(&grads, &layer);
        assert_eq!(
            mean_gradients(&layer, &mut grads, &SingleProcess).unwrap(),
            0
        );
        assert_eq!(values(&grads, &layer), before);
        assert_eq!((SingleProcess.rank(), SingleProcess.ranks()), (0, 1));
    }
}
