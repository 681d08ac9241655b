//! The frozen networks in the run's [`Precision`]: [`cast_frozen`] casts a loaded CLIP,
//! U-Net or VAE, and the networks' own `forward`s keep the rest consistent.
//!
//! In f16 the weights and the activations between layers are half precision. What overflows
//! or loses most in half precision stays in f32:
//! - group and layer norms keep f32 weights and compute their statistics in f32
//!   ([`group_norm_f32`], [`layer_norm_f32`]): the variance of activations near 1e4 is 1e8,
//!   past f16's 65504;
//! - attention's softmax runs in f32 (`models::attention`, `clip::attention`);
//! - every network takes and returns f32 tensors, so the score combination and the gradient
//!   handed back to the NeRF are f32.

use burn::module::{Module, ModuleMapper, Param};
use burn::nn::{GroupNorm, LayerNorm};
use burn::tensor::{DType, FloatDType, Tensor};
pub use gb_core::Precision;

/// `module` with its float weights in `precision`, norms excepted (module docs). Casting to
/// f32 restores f32 weights exactly from f32 (and widens f16 weights losslessly).
pub fn cast_frozen<M: Module>(module: M, precision: Precision) -> M {
    let mut mapper = CastWeights {
        dtype: precision.float_dtype(),
        containers: Vec::new(),
    };
    module.map(&mut mapper)
}

/// Casts every float parameter outside a norm.
struct CastWeights {
    dtype: FloatDType,
    /// The container type of each module entered, innermost last.
    containers: Vec<String>,
}

impl ModuleMapper for CastWeights {
    fn enter_module(&mut self, _name: &str, container_type: &str) {
        self.containers.push(container_type.to_owned());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.containers.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let in_norm = matches!(
            self.containers.last().map(String::as_str),
            Some("Struct:GroupNorm" | "Struct:LayerNorm")
        );
        if in_norm {
            param
        } else {
            let dtype = self.dtype;
            param.map(|t| t.cast(dtype))
        }
    }
}

/// The dtype a network computes in: that of one of its weights.
pub fn compute_dtype<const D: usize>(weight: &Param<Tensor<D>>) -> DType {
    weight.val().dtype()
}

/// `x` in `dtype` (a no-op when it already is).
pub fn to_dtype<const D: usize>(x: Tensor<D>, dtype: DType) -> Tensor<D> {
    x.cast(FloatDType::from(dtype))
}

/// A group norm computed in f32, returned in `x`'s dtype.
pub fn group_norm_f32<const D: usize>(norm: &GroupNorm, x: Tensor<D>) -> Tensor<D> {
    let dtype = x.dtype();
    to_dtype(norm.forward(x.cast(FloatDType::F32)), dtype)
}

/// A layer norm computed in f32, returned in `x`'s dtype.
pub fn layer_norm_f32<const D: usize>(norm: &LayerNorm, x: Tensor<D>) -> Tensor<D> {
    let dtype = x.dtype();
    to_dtype(norm.forward(x.cast(FloatDType::F32)), dtype)
}
