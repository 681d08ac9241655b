//! Run-time backend selection: every model runs on ndarray, flex or wgpu, chosen by
//! `--device` on the command line.

use std::fmt;
use std::str::FromStr;

use burn::tensor::{Device, DeviceKind};
use serde::{Deserialize, Serialize};

/// A compute backend that gb-nerf-rs can run on, chosen at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// Burn's deprecated NdArray CPU backend (slow; kept as a reference).
    Ndarray,
    /// Burn's pure-Rust Flex CPU backend (the fast CPU default).
    #[default]
    Flex,
    /// wgpu: Vulkan/Metal/DX12 GPUs, or Mesa's lavapipe on a CPU-only machine.
    Wgpu,
}

impl BackendKind {
    /// Every backend, in the order the tests visit them.
    pub const ALL: [BackendKind; 3] = [BackendKind::Ndarray, BackendKind::Flex, BackendKind::Wgpu];

    /// The plain (non-autodiff) Burn device for this backend.
    #[allow(deprecated)]
    pub fn device(self) -> Device {
        match self {
            BackendKind::Ndarray => Device::ndarray(),
            BackendKind::Flex => Device::flex(),
            BackendKind::Wgpu => Device::wgpu(DeviceKind::DefaultDevice),
        }
    }

    /// The same device with autodiff enabled, for training.
    pub fn autodiff_device(self) -> Device {
        self.device().autodiff()
    }

    /// The lowercase name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Ndarray => "ndarray",
            BackendKind::Flex => "flex",
            BackendKind::Wgpu => "wgpu",
        }
    }

    /// Other names accepted for this backend on the command line.
    pub fn aliases(self) -> &'static [&'static str] {
        match self {
            BackendKind::Ndarray => &[],
            BackendKind::Flex => &["cpu"],
            BackendKind::Wgpu => &["gpu", "vulkan"],
        }
    }
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// `--device` on a command line: the backends by name, their aliases accepted, all listed
/// by `--help`.
#[cfg(feature = "clap")]
impl clap::ValueEnum for BackendKind {
    fn value_variants<'a>() -> &'a [Self] {
        &BackendKind::ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()).aliases(self.aliases().iter().copied()))
    }
}

/// Error for an unknown backend name.
#[derive(Debug, thiserror::Error)]
#[error("unknown device '{0}': expected one of ndarray, flex, wgpu")]
pub struct UnknownBackend(pub String);

impl FromStr for BackendKind {
    type Err = UnknownBackend;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim().to_ascii_lowercase();
        BackendKind::ALL
            .into_iter()
            .find(|k| k.name() == s || k.aliases().contains(&s.as_str()))
            .ok_or(UnknownBackend(s))
    }
}

/// The devices of one run, built once from its `--device` choice and handed down: the plain
/// device (the prior, rendering, the metrics) and the same device with autodiff (training).
#[derive(Debug, Clone)]
pub struct Devices {
    /// The choice they were built from, as logs and configs name it.
    pub kind: BackendKind,
    /// The plain device.
    pub plain: Device,
    /// The autodiff device, for training.
    pub train: Device,
}

impl Devices {
    /// Builds both devices of `kind`.
    pub fn new(kind: BackendKind) -> Self {
        let plain = kind.device();
        Self {
            kind,
            train: plain.clone().autodiff(),
            plain,
        }
    }

    /// The backend's lowercase name ([`BackendKind::name`]).
    pub fn name(&self) -> &'static str {
        self.kind.name()
    }
}

impl From<BackendKind> for Devices {
    fn from(kind: BackendKind) -> Self {
        Self::new(kind)
    }
}

impl From<&Devices> for Devices {
    fn from(devices: &Devices) -> Self {
        devices.clone()
    }
}

impl fmt::Display for Devices {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Whether `device` computes on a GPU card: false for the CPU backends (flex, ndarray) and for
/// a wgpu device on a software rasterizer such as Mesa's lavapipe, which reports no physical
/// device. Opens the device.
pub fn is_gpu_card(device: &Device) -> bool {
    device.identity().is_some_and(|id| id.physical.is_some())
}

/// The backends a multi-backend test should visit.
///
/// All three by default; CI installs Mesa's lavapipe so wgpu really runs. A developer
/// without a Vulkan driver may restrict the list with `GB_TEST_BACKENDS=ndarray,flex`.
pub fn test_backends() -> Vec<BackendKind> {
    match std::env::var("GB_TEST_BACKENDS") {
        Ok(list) if !list.trim().is_empty() => list
            .split(',')
            .map(|s| {
                s.parse()
                    .unwrap_or_else(|e| panic!("GB_TEST_BACKENDS: {e}"))
            })
            .collect(),
        _ => BackendKind::ALL.to_vec(),
    }
}

/// The backends a test of a whole network (U-Net, pipeline, NeRF training) should visit:
/// ndarray and flex, plus wgpu when `GB_TEST_HEAVY_WGPU=1`.
///
/// On a CPU-only machine wgpu runs on Mesa's lavapipe, which JIT-compiles every distinct
/// kernel; a full network then takes minutes per test. CI therefore checks wgpu on the
/// operator-level tests (which use [`test_backends`]) and leaves the whole-network wgpu runs
/// to machines with a GPU (`GB_TEST_HEAVY_WGPU=1`). `GB_TEST_BACKENDS` still restricts both.
pub fn heavy_test_backends() -> Vec<BackendKind> {
    let heavy_wgpu = std::env::var("GB_TEST_HEAVY_WGPU").is_ok_and(|v| v == "1");
    test_backends()
        .into_iter()
        .filter(|k| heavy_wgpu || *k != BackendKind::Wgpu)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_s_devices_are_one_backend_plain_and_with_autodiff() {
        let d = Devices::from(BackendKind::Ndarray);
        assert_eq!(d.kind, BackendKind::Ndarray);
        assert_eq!(d.plain, BackendKind::Ndarray.device());
        assert!(!d.plain.is_autodiff());
        assert!(d.train.is_autodiff());
        assert_eq!(d.train.clone().inner(), d.plain);
        assert_eq!(d.to_string(), "ndarray");
        assert_eq!(Devices::from(&d).train, d.train);
    }

    #[test]
    fn parses_names_and_rejects_unknown() {
        assert_eq!(
            "ndarray".parse::<BackendKind>().unwrap(),
            BackendKind::Ndarray
        );
        assert_eq!("FLEX".parse::<BackendKind>().unwrap(), BackendKind::Flex);
        assert_eq!("wgpu".parse::<BackendKind>().unwrap(), BackendKind::Wgpu);
        assert_eq!(" cpu".parse::<BackendKind>().unwrap(), BackendKind::Flex);
        assert_eq!("Vulkan".parse::<BackendKind>().unwrap(), BackendKind::Wgpu);
        let err = "cuda".parse::<BackendKind>().unwrap_err();
        assert!(err.to_string().contains("cuda"));
    }

    #[test]
    fn every_backend_adds_numbers() {
        for kind in test_backends() {
            let device = kind.device();
            let t = burn::tensor::Tensor::<1>::from_floats([1.0, 2.0, 3.5], &device);
            let s: f32 = t.sum().into_scalar::<f32>();
            assert_eq!(s, 6.5, "backend {kind}");
        }
    }
}
