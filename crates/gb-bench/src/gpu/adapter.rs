//! The adapter a backend opens: its name, kernel target, and whether it is a GPU card.

use gb_core::BackendKind;
use serde_json::{json, Value};

use super::WGPU_COMPILER;

/// The adapter that a backend opens (module docs).
#[derive(Debug, Clone)]
pub struct Adapter {
    /// The backend.
    pub backend: BackendKind,
    /// The name the device gives itself (`NVIDIA H100 80GB HBM3`, `llvmpipe (LLVM 15.0.6,
    /// 256 bits)`), or the backend's for a CPU backend.
    pub name: String,
    /// What its kernels are compiled for (CubeCL's fingerprint), when it reports one.
    pub target: Option<String>,
    /// Whether it is a GPU card ([`gb_core::backend::is_gpu_card`]).
    pub is_card: bool,
    /// Why it could not be opened, when it could not.
    pub error: Option<String>,
}

impl Adapter {
    /// Opens `backend`'s device and reads who it is; a device that fails to open (no Vulkan
    /// loader) is an adapter that is no card, with the failure.
    pub fn open(backend: BackendKind) -> Self {
        let opened = std::panic::catch_unwind(|| backend.device().identity());
        let (identity, error) = match opened {
            Ok(id) => (id, None),
            Err(e) => (
                None,
                Some(
                    e.downcast_ref::<String>()
                        .cloned()
                        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_else(|| "the device failed to open".into()),
                ),
            ),
        };
        Self {
            backend,
            name: match (&identity, &error) {
                (Some(id), _) => id.name.clone(),
                (None, Some(_)) => format!("{} (did not open)", backend.name()),
                (None, None) => format!("{} (CPU backend)", backend.name()),
            },
            target: identity.as_ref().map(|id| id.fingerprint.clone()),
            is_card: identity.is_some_and(|id| id.physical.is_some()),
            error,
        }
    }

    /// Its type in words.
    pub fn kind(&self) -> &'static str {
        match (self.is_card, self.backend) {
            (true, _) => "gpu card",
            (false, BackendKind::Wgpu) => {
                "no card: a CPU or a software rasterizer such as lavapipe"
            }
            (false, _) => "cpu",
        }
    }

    /// The report's `adapter` section: name, type, kernel target, backend, shader compiler,
    /// and the driver (`nvidia-smi`'s, on a card that has it).
    pub fn to_json(&self) -> Value {
        let driver = if self.is_card {
            crate::pipeline::gpu_name()
                .and_then(|g| g.split(',').nth(1).map(|d| d.trim().to_string()))
        } else {
            None
        };
        json!({
            "name": self.name,
            "type": self.kind(),
            "is_gpu_card": self.is_card,
            "target": self.target,
            "backend": self.backend.name(),
            "shader_compiler": (self.backend == BackendKind::Wgpu).then_some(WGPU_COMPILER),
            "driver": driver,
            "error": self.error,
        })
    }
}
