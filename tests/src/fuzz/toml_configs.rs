//! TOML configurations: the reconstruction presets (`NerfConfig::from_toml`) and the methods
//! (`MethodConfig::from_toml`). Valid configurations with random values round-trip through
//! `toml::to_string`; mutated preset / method texts give `Ok` or `Err`.

use std::path::Path;

use gb_diffusion::distill::GuidanceMethod;
use gb_inpaint::method::BUILTIN_METHODS;
use gb_inpaint::MethodConfig;
use gb_nerf::train::NerfConfig;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::mutate::{any_bytes, mutated, mutations, Mutation};
use super::{ensure, Harness};

const PRESETS: &[&str] = &[
    include_str!("../../../configs/presets/fast.toml"),
    include_str!("../../../configs/presets/balanced.toml"),
    include_str!("../../../configs/presets/paper.toml"),
];

/// Tokens for mutating a TOML file: keys, enum names, tables, arrays, inline tables.
const TOML_TOKENS: &[&str] = &[
    "kind",
    "hash",
    "mlp",
    "method",
    "bsd",
    "csd",
    "sds",
    "none",
    "schedule",
    "annealed",
    "uniform",
    "plane_fit",
    "[train]",
    "[field.grid]",
    "[[x]]",
    "a.b.c = 1",
    "x = { y = [1, 2] }",
    "= =",
    "\"\"\"",
    "'''",
    "1979-05-27T07:32:00Z",
];

#[derive(Debug, Clone)]
enum Case {
    /// Built-in text `index` (modulo the count), then `mutations` (none: must parse).
    Text(usize, Vec<Mutation>),
    /// Arbitrary bytes (lossily as UTF-8).
    Raw(Vec<u8>),
    /// A valid configuration with random values, serialised: must parse back equal.
    Values(usize, [u64; 6], [f64; 4]),
}

fn case() -> impl Strategy<Value = Case> {
    prop_oneof![
        1 => any::<usize>().prop_map(|i| Case::Text(i, Vec::new())),
        6 => (any::<usize>(), mutations(TOML_TOKENS)).prop_map(|(i, m)| Case::Text(i, m)),
        1 => any_bytes(256).prop_map(Case::Raw),
        2 => (
            any::<usize>(),
            proptest::array::uniform6(0u64..1 << 40),
            proptest::array::uniform4(1e-6f64..1.0)
        )
            .prop_map(|(i, n, x)| Case::Values(i, n, x)),
    ]
}

impl Case {
    /// The text to parse (`None` for [`Case::Values`], which the property serialises).
    fn text(&self, texts: &[&str]) -> Option<String> {
        match self {
            Case::Text(i, m) => {
                Some(String::from_utf8_lossy(&mutated(texts[i % texts.len()].as_bytes(), m)).into())
            }
            Case::Raw(b) => Some(String::from_utf8_lossy(b).into()),
            Case::Values(..) => None,
        }
    }
}

/// `NerfConfig::from_toml`: never panics; the presets parse; random valid values round-trip.
pub fn nerf(h: &mut Harness) -> Result<(), String> {
    let origin = Path::new("fuzz.toml");
    h.check(case(), |case, _| {
        if let Case::Values(i, n, x) = case {
            let mut cfg = NerfConfig::from_toml(PRESETS[i % PRESETS.len()], origin)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            let t = &mut cfg.train;
            t.steps = n[0] as usize;
            t.rays_per_batch = 1 + n[1] as usize;
            t.lr_decay_steps = 1 + n[2] as usize;
            t.checkpoint_every = n[3] as usize;
            t.image_downscale = 1 + (n[4] % 16) as usize;
            t.seed = n[5];
            t.lr = x[0];
            t.lr_decay = x[1];
            t.depth_weight = x[2] as f32;
            t.distortion_weight = x[3] as f32;
            cfg.sampler.samples_per_ray = 1 + (n[0] % 512) as usize;
            let text = toml::to_string(&cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let back = NerfConfig::from_toml(&text, origin)
                .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
            return ensure(back == cfg, || format!("round trip changed:\n{text}"));
        }
        let text = case.text(PRESETS).unwrap_or_default();
        let got = NerfConfig::from_toml(&text, origin);
        if matches!(&case, Case::Text(_, m) if m.is_empty()) {
            got.map_err(|e| TestCaseError::fail(format!("preset rejected: {e}")))?;
        }
        Ok(())
    })
}

/// `MethodConfig::from_toml`: never panics; the built-in methods parse; random valid
/// weights round-trip.
pub fn method(h: &mut Harness) -> Result<(), String> {
    let texts: Vec<&str> = BUILTIN_METHODS.iter().map(|(_, t)| *t).collect();
    let origin = Path::new("method.toml");
    h.check(case(), |case, _| {
        if let Case::Values(i, n, x) = case {
            let mut cfg = MethodConfig::from_toml(texts[i % texts.len()], origin)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            cfg.lambda_rgb = x[0].into();
            cfg.lambda_normal = x[1].into();
            cfg.crop_margin = (x[2] * 4.0) as f32;
            cfg.guide_every = 1 + n[0] as usize;
            cfg.reference_steps = 1 + n[1] as usize;
            cfg.normal_start_step = n[2] as usize;
            cfg.max_consecutive_nan = 1 + n[3] as usize;
            cfg.normal_render_divisor = 1 + (n[4] % 8) as usize;
            if let Some(settings) = &mut cfg.rgb {
                if let GuidanceMethod::Csd { w1, .. } | GuidanceMethod::Bsd { w1, .. } =
                    &mut settings.guidance
                {
                    *w1 = (x[3] * 10.0) as f32;
                }
            }
            let text = toml::to_string(&cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let back = MethodConfig::from_toml(&text, origin)
                .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
            return ensure(back == cfg, || format!("round trip changed:\n{text}"));
        }
        let text = case.text(&texts).unwrap_or_default();
        let got = MethodConfig::from_toml(&text, origin);
        if matches!(&case, Case::Text(_, m) if m.is_empty()) {
            got.map_err(|e| TestCaseError::fail(format!("built-in method rejected: {e}")))?;
        }
        Ok(())
    })
}
