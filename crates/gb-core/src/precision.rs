//! The float precision the frozen diffusion prior (CLIP, U-Net, VAE) computes in:
//! `--precision f32|f16`.
//!
//! The default follows the hardware: f16 on a GPU card (where wgpu's tensor-core and
//! half-rate paths apply), f32 on the CPU backends and on a wgpu device without a physical
//! GPU (Mesa's lavapipe), where half precision saves nothing. f16 needs a backend with f16
//! tensors: flex and wgpu have them, ndarray has not.

use std::fmt;
use std::str::FromStr;

use burn::tensor::{DType, Device, FloatDType};
use serde::{Deserialize, Serialize};

use crate::backend::is_gpu_card;

/// Precision of the frozen prior's weights and activations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Single precision throughout.
    F32,
    /// Half-precision weights and activations; norms, softmax and what leaves the networks
    /// stay in f32.
    F16,
}

impl Precision {
    /// Both, in the order `--help` lists them.
    pub const ALL: [Precision; 2] = [Precision::F32, Precision::F16];

    /// The lowercase name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
        }
    }

    /// The Burn float dtype of the weights.
    pub fn float_dtype(self) -> FloatDType {
        match self {
            Precision::F32 => FloatDType::F32,
            Precision::F16 => FloatDType::F16,
        }
    }

    /// The default on `device`: f16 on a GPU card, f32 elsewhere (module docs).
    pub fn default_for(device: &Device) -> Precision {
        if is_gpu_card(device) && device.supports_dtype(DType::F16) {
            Precision::F16
        } else {
            Precision::F32
        }
    }

    /// `requested`, or the device's default when `None`; an error when f16 is asked of a
    /// backend without f16 tensors.
    pub fn resolve(
        requested: Option<Precision>,
        device: &Device,
    ) -> Result<Precision, PrecisionError> {
        match requested {
            None => Ok(Precision::default_for(device)),
            Some(Precision::F16) if !device.supports_dtype(DType::F16) => {
                Err(PrecisionError::Unsupported {
                    precision: Precision::F16,
                    device: format!("{device:?}"),
                })
            }
            Some(p) => Ok(p),
        }
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Precision {
    type Err = PrecisionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim().to_ascii_lowercase();
        Precision::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or(PrecisionError::Unknown(s))
    }
}

/// `--precision` on a command line.
#[cfg(feature = "clap")]
impl clap::ValueEnum for Precision {
    fn value_variants<'a>() -> &'a [Self] {
        &Precision::ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// A precision that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PrecisionError {
    /// Not a precision name.
    #[error("unknown precision '{0}': expected f32 or f16")]
    Unknown(String),
    /// The backend has no tensors of that precision.
    #[error("{precision} needs a device with {precision} tensors, and {device} has none (ndarray computes in f32 only; use --device flex or wgpu)")]
    Unsupported {
        /// The precision asked for.
        precision: Precision,
        /// The device, as Burn names it.
        device: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BackendKind;

    #[test]
    fn names_parse_and_print() {
        for p in Precision::ALL {
            assert_eq!(p.name().parse::<Precision>().unwrap(), p);
            assert_eq!(p.to_string(), p.name());
        }
        assert_eq!(" F16 ".parse::<Precision>().unwrap(), Precision::F16);
        let err = "bf16".parse::<Precision>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown precision 'bf16': expected f32 or f16"
        );
    }

    #[test]
    fn cpu_backends_default_to_f32_and_ndarray_refuses_f16() {
        let flex = BackendKind::Flex.device();
        assert_eq!(Precision::default_for(&flex), Precision::F32);
        assert_eq!(
            Precision::resolve(Some(Precision::F16), &flex),
            Ok(Precision::F16)
        );
        let ndarray = BackendKind::Ndarray.device();
        assert_eq!(Precision::resolve(None, &ndarray), Ok(Precision::F32));
        let err = Precision::resolve(Some(Precision::F16), &ndarray).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("f16 needs a device with f16 tensors, and "),
            "{err}"
        );
    }
}
