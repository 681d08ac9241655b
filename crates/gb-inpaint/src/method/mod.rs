//! Method configurations (`configs/methods/*.toml`, embedded at build time): which guidance
//! runs on RGB renders and on normal maps, with which weights, prompts and schedule.
//!
//! ```toml
//! name = "gb-nerf"
//! use_lora = true                  # attach the prior's RGB/normal LoRA
//! lambda_rgb = 1e-4                # paper: lambda2
//! lambda_normal = 1e-4             # paper: lambda3
//! normal_start_step = 500          # the reference's start of the normal guidance ...
//! reference_steps = 10000          # ... out of its 10k steps; scaled to the run's steps
//! guide_every = 1                  # guidance every k steps
//! prior_input = "paste_on_ground_truth"   # or "render_only"
//!
//! [prompts]                        # {caption} / {object_caption}: from the scene
//! appearance = "RGB image, {caption}"
//! negative = "RGB image, {object_caption}"
//! geometry = "normal map, {caption}"
//! geometry_negative = "normal map, {object_caption}"
//!
//! [rgb]                            # method = none | sds | csd | bsd
//! method = "bsd"
//! w1 = 7.5
//! w2 = 6.5
//!
//! [normal]
//! method = "bsd"
//! w1 = 1.5
//! w2 = 0.5
//! ```
//!
//! Each guidance table is gb-diffusion's `DistillSettings` in its flat form
//! (`gb_diffusion::distill::settings_table`): SDS takes `guidance_scale` (diffusers'
//! convention), CSD `w1`, `w2` and optionally `w3` (default `w2 - w1`, the original CSD),
//! BSD `w1` and `w2`; each also takes `timesteps` (`t_min`, `t_max`, `schedule`),
//! `weighting` (`one_minus_alpha_bar` | `constant`) and `grad_clamp`.
//!
//! # The scale of lambda (how our gradient maps to the paper's 1e-4)
//!
//! The guided loss of one modality is `lambda * s(t) * (z * g.detach()).sum()`, where `z` is
//! the VAE encoding of the prior input (the crop, in `[-1, 1]`, times the VAE scaling factor)
//! and `g = w(t) * mask_latent * direction` with `w(t) = 1 - alpha_bar(t)` and the method's
//! eps combination as `direction` (gb-diffusion's `ScoreDistiller`, with its NaN zeroing).
//! Its gradient reaches the rendered pixels through the encoder only; the U-Net runs
//! without a graph. This is the reference code's injection (Arcxml/GB-NeRF,
//! `DS_NeRF/guidance/sd_utils.py`, `train_step_sd` / `train_step_sd_normal`:
//! `SpecifyGradient.apply(latents, grad, mask)` with `grad = w * noise_pred`,
//! `w = 1 - alphas_cumprod[t]`, and in `run.py` `loss += sds_loss_weight * loss_sds` with
//! `sds_loss_weight = 1e-4` for the sum of the RGB and normal terms), with two checked
//! details:
//!
//! - the reference applies `grad` to the *noisy* latents `x_t = sqrt(ab) z + sqrt(1-ab) eps`
//!   that diffusers' `prepare_latents` builds from the encoded image with autodiff on, so
//!   the encoded latents receive `sqrt(alpha_bar(t)) * grad`. With
//!   `reference_chain_rule = true` (the default) we multiply by the same
//!   `s(t) = sqrt(alpha_bar(t))`; with `false`, `s = 1` (threestudio's convention);
//! - the reference feeds the whole image resized to 512 x 512, we feed the mask's bounding
//!   box (plus `crop_margin`) rendered directly at the prior's resolution. A rendered pixel
//!   therefore receives the gradient of exactly one prior pixel here, and of
//!   `512^2 / (H W)` prior pixels (through the bilinear resize) in the reference: about 0.46
//!   for SPIn-NeRF's 1008 x 567 images. The same lambda thus means the same per-pixel
//!   gradient up to that resampling factor, which we do not compensate (Adam's per-parameter
//!   normalisation makes the step size insensitive to such a constant where only the
//!   guidance reaches a parameter).
//!
//! So `lambda_rgb = lambda_normal = 1e-4` is the paper's setting.

use std::path::Path;

use gb_diffusion::distill::{DistillSettings, PriorInputMode};
use serde::{Deserialize, Serialize};

mod auto_table;
mod geometry_table;
mod personalize_table;
mod prompts;
mod reference_table;
mod weight;

use crate::error::InpaintError;
use crate::visibility::VisibilityConfig;
pub use auto_table::AutoSettings;
pub use geometry_table::{GeometryConfig, GeometryRegion};
pub use personalize_table::PersonalizeSettings;
pub use prompts::{PromptOverrides, PromptTemplates, Prompts, SceneCaptions};
pub use reference_table::{AutoReference, FillWith, ReferenceConfig, ReferencePair};
pub use weight::Weight;

/// The method a run uses when none is given: the one the README recommends,
/// `gb-nerf-unseen` (the paper's guidance, confined to the pixels no other training view
/// sees), which beats the paper's `gb-nerf` on every mask-box metric measured with the
/// built-in prior (README, "Which method").
pub const DEFAULT_METHOD: &str = "gb-nerf-unseen";

/// The built-in methods: name and TOML text (`configs/methods/NAME.toml`).
pub const BUILTIN_METHODS: &[(&str, &str)] = &[
    (
        "gb-nerf",
        include_str!("../../../../configs/methods/gb-nerf.toml"),
    ),
    (
        "gb-nerf-unseen",
        include_str!("../../../../configs/methods/gb-nerf-unseen.toml"),
    ),
    (
        "gb-nerf-auto",
        include_str!("../../../../configs/methods/gb-nerf-auto.toml"),
    ),
    ("bsd", include_str!("../../../../configs/methods/bsd.toml")),
    (
        "mvip-nerf",
        include_str!("../../../../configs/methods/mvip-nerf.toml"),
    ),
    (
        "sds-lora",
        include_str!("../../../../configs/methods/sds-lora.toml"),
    ),
    (
        "spin-nerf-sds",
        include_str!("../../../../configs/methods/spin-nerf-sds.toml"),
    ),
    ("csd", include_str!("../../../../configs/methods/csd.toml")),
    (
        "none",
        include_str!("../../../../configs/methods/none.toml"),
    ),
    (
        "pre-inpainted",
        include_str!("../../../../configs/methods/pre-inpainted.toml"),
    ),
];

/// A method: the guidance of each modality and everything around it (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodConfig {
    /// Method name.
    pub name: String,
    /// One line for reports.
    #[serde(default)]
    pub description: String,
    /// Attach the prior's LoRA (`PRIOR/pytorch_lora_weights.safetensors`, or `--lora`).
    #[serde(default)]
    pub use_lora: bool,
    /// Train on a SPIn-NeRF scene's `RGB_inpainted/` (+ `Depth_inpainted/`) images instead
    /// of masking (the SPIn-NeRF + LaMa baseline); see [`crate::pre_inpainted`].
    #[serde(default)]
    pub pre_inpainted: bool,
    /// Weight of the RGB guidance (paper's lambda2 = 1e-4), or `"auto"`: chosen per scene
    /// from `[auto] rgb` ([`crate::auto`]).
    #[serde(default = "default_lambda")]
    pub lambda_rgb: Weight,
    /// Weight of the normal-map guidance (paper's lambda3 = 1e-4), or `"auto"` (`[auto]
    /// normal`).
    #[serde(default = "default_lambda")]
    pub lambda_normal: Weight,
    /// First step of the normal guidance, counted out of `reference_steps` (reference: 500
    /// of 10000); a run of `N` steps starts it at `normal_start_step * N / reference_steps`.
    #[serde(default = "default_normal_start")]
    pub normal_start_step: usize,
    /// The step count `normal_start_step` refers to (set it to the run's steps for an
    /// absolute start).
    #[serde(default = "default_reference_steps")]
    pub reference_steps: usize,
    /// Guidance on every k-th step (1: every step).
    #[serde(default = "default_one")]
    pub guide_every: usize,
    /// The RGB prior input: the render alone, or pasted inside the mask onto the ground
    /// truth (the reference). Normal maps are always the render alone (no ground truth).
    #[serde(default)]
    pub prior_input: PriorInputMode,
    /// The crop is the mask's bounding box grown by this fraction of its size on each side
    /// (clamped to the image), so that the prior sees context around the hole.
    #[serde(default = "default_margin")]
    pub crop_margin: f32,
    /// The normal map's depth is rendered at `resolution / normal_render_divisor` and the
    /// normal map upsampled (bilinear) to the prior's resolution (the reference renders
    /// normals at 1/7 of the image resolution).
    #[serde(default = "default_normal_divisor")]
    pub normal_render_divisor: usize,
    /// Multiply the injected gradient by `sqrt(alpha_bar(t))` as the reference's chain rule
    /// through the noisy latents does (see the module docs).
    #[serde(default = "default_true")]
    pub reference_chain_rule: bool,
    /// Whether the RGB guidance's gradient reaches the geometry (the density and the
    /// encoding the colour head shares with it). `false`: only the colour head learns from
    /// it (`gb_nerf::render::render_samples_appearance_only`); the normal term still shapes
    /// the geometry. Left out of the written config while true (the paper).
    #[serde(default = "default_true", skip_serializing_if = "is_true")]
    pub rgb_moves_geometry: bool,
    /// Stop after this many consecutive non-finite losses.
    #[serde(default = "default_max_nan")]
    pub max_consecutive_nan: usize,
    /// Prompt templates.
    #[serde(default)]
    pub prompts: PromptTemplates,
    /// RGB guidance (`None`: `method = "none"`, or no `[rgb]` table).
    #[serde(default, with = "gb_diffusion::distill::settings_table::optional")]
    pub rgb: Option<DistillSettings>,
    /// Normal-map guidance.
    #[serde(default, with = "gb_diffusion::distill::settings_table::optional")]
    pub normal: Option<DistillSettings>,
    /// Visibility-aware guidance: how much the guidance acts on pixels that other training
    /// views observe (off by default; see [`crate::visibility`]).
    #[serde(default)]
    pub visibility: VisibilityConfig,
    /// Per-scene personalisation of the prior before guidance (off by default; see
    /// [`crate::personalize`]). Left out of the written config while it is the default, so
    /// that configs and checkpoints of methods without it read as before.
    #[serde(default, skip_serializing_if = "PersonalizeSettings::is_default")]
    pub personalize: PersonalizeSettings,
    /// Reference views: images of training views without the object that supervise the
    /// field and are carried to the other views (off by default; see [`crate::reference`]).
    /// Left out of the written config while it is the default.
    #[serde(default, skip_serializing_if = "ReferenceConfig::is_default")]
    pub reference: ReferenceConfig,
    /// The hidden region's geometry held to the unguided field's ([`crate::geometry`]; off
    /// when left out, on in the built-in `none` and `gb-nerf-unseen`). Left out of the written
    /// config while it is off.
    #[serde(default, skip_serializing_if = "GeometryConfig::is_default")]
    pub geometry: GeometryConfig,
    /// Oracle guidance for experiments: the RGB term's prompt branch answered by the exact
    /// score of the object-free image (off by default; see [`crate::oracle`]). Left out of
    /// the written config while it is the default.
    #[serde(
        default,
        skip_serializing_if = "crate::oracle::OracleSettings::is_default"
    )]
    pub oracle: crate::oracle::OracleSettings,
    /// The candidates and trials of the `"auto"` weights ([`crate::auto`]). Left out of the
    /// written config while it is the default.
    #[serde(default, skip_serializing_if = "AutoSettings::is_default")]
    pub auto: AutoSettings,
}

fn default_lambda() -> Weight {
    Weight::Fixed(1e-4)
}
fn default_normal_start() -> usize {
    500
}
fn default_reference_steps() -> usize {
    10_000
}
fn default_one() -> usize {
    1
}
fn default_margin() -> f32 {
    0.25
}
fn default_normal_divisor() -> usize {
    2
}
fn is_true(v: &bool) -> bool {
    *v
}

fn default_true() -> bool {
    true
}
fn default_max_nan() -> usize {
    10
}

impl MethodConfig {
    /// The names of the built-in methods.
    pub fn builtin_names() -> Vec<&'static str> {
        BUILTIN_METHODS.iter().map(|(n, _)| *n).collect()
    }

    /// A built-in method by name.
    pub fn builtin(name: &str) -> Result<Self, InpaintError> {
        let (_, text) = BUILTIN_METHODS
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| InpaintError::UnknownMethod {
                name: name.to_string(),
                known: Self::builtin_names().join(", "),
            })?;
        Self::from_toml(text, Path::new(&format!("configs/methods/{name}.toml")))
    }

    /// A built-in method name, or a path to a `.toml` file.
    pub fn load(name_or_path: &str) -> Result<Self, InpaintError> {
        if name_or_path.ends_with(".toml") {
            let path = Path::new(name_or_path);
            let text = std::fs::read_to_string(path).map_err(|e| InpaintError::MethodConfig {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })?;
            return Self::from_toml(&text, path);
        }
        Self::builtin(name_or_path)
    }

    /// Parses and validates a method; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, InpaintError> {
        let cfg: MethodConfig = toml::from_str(text).map_err(|e| InpaintError::MethodConfig {
            path: origin.to_path_buf(),
            reason: gb_core::messages::at_line(text, e.span(), e.message()),
        })?;
        cfg.validate()
            .map_err(|reason| InpaintError::MethodConfig {
                path: origin.to_path_buf(),
                reason,
            })?;
        Ok(cfg)
    }

    /// Checks every field that can be checked without a prior or a scene.
    pub fn validate(&self) -> Result<(), String> {
        for (name, w) in [
            ("lambda_rgb", self.lambda_rgb),
            ("lambda_normal", self.lambda_normal),
        ] {
            if let Weight::Fixed(v) = w {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!(
                        "{name} = {v} must be a finite number >= 0 or \"auto\""
                    ));
                }
            }
        }
        self.auto.check(self)?;
        if self.guide_every == 0 {
            return Err("guide_every must be >= 1".into());
        }
        if self.reference_steps == 0 {
            return Err("reference_steps must be >= 1".into());
        }
        if !(self.crop_margin.is_finite() && (0.0..=4.0).contains(&self.crop_margin)) {
            return Err(format!(
                "crop_margin = {} must be in [0, 4]",
                self.crop_margin
            ));
        }
        if self.normal_render_divisor == 0 {
            return Err("normal_render_divisor must be >= 1".into());
        }
        if self.max_consecutive_nan == 0 {
            return Err("max_consecutive_nan must be >= 1".into());
        }
        if let Some(msg) = self.visibility.check() {
            return Err(msg.into());
        }
        if self.oracle.clean.is_some() {
            let branches = match &self.rgb {
                Some(r) => r
                    .guidance
                    .build()
                    .map_err(|e| e.to_string())?
                    .branches()
                    .to_vec(),
                None => Vec::new(),
            };
            if !self.oracle.branches.iter().any(|b| branches.contains(b)) {
                return Err(format!(
                    "[oracle] answers {:?}, but the RGB guidance evaluates {:?}: the oracle \
                     would change nothing",
                    self.oracle.branches, branches
                ));
            }
        }
        if let Some(msg) = self.reference.check() {
            return Err(msg);
        }
        if let Some(msg) = self.geometry.check() {
            return Err(msg);
        }
        for (table, settings) in [("rgb", &self.rgb), ("normal", &self.normal)] {
            if let Some(s) = settings {
                s.validate().map_err(|e| format!("[{table}] {e}"))?;
            }
        }
        if self.pre_inpainted && self.needs_prior() {
            return Err(
                "pre_inpainted trains on every pixel of the 2D-inpainted images; it cannot be \
                 combined with rgb or normal guidance"
                    .into(),
            );
        }
        if self.use_lora && !self.needs_prior() {
            return Err("use_lora = true but neither rgb nor normal guidance is active".into());
        }
        if self.prompts.appearance.trim().is_empty() && self.rgb.is_some() {
            return Err("prompts.appearance must not be empty".into());
        }
        if self.prompts.geometry.trim().is_empty() && self.normal.is_some() {
            return Err("prompts.geometry must not be empty".into());
        }
        Ok(())
    }

    /// True when a modality has guidance (the run needs a diffusion prior).
    pub fn needs_prior(&self) -> bool {
        self.rgb.is_some() || self.normal.is_some()
    }

    /// True when some modality is guided with a weight other than zero (`"auto"` counts: it
    /// may choose one). A method whose weights are all zero (an auto choice of no guidance)
    /// trains exactly as `none`.
    pub fn guides(&self) -> bool {
        let on = |table: bool, w: Weight| table && w != Weight::Fixed(0.0);
        on(self.rgb.is_some(), self.lambda_rgb) || on(self.normal.is_some(), self.lambda_normal)
    }

    /// True when `[geometry]` has a weight and the run has a term inside the mask for it to
    /// hold against: guidance with a weight ([`Self::guides`]), or `has_references`
    /// (reference views). The built-in `none` carries the table so that a reference added to
    /// it is held, while a plain `none` run, or a guided method whose weights are zero, pays
    /// nothing.
    pub fn holds_geometry(&self, has_references: bool) -> bool {
        self.geometry.enabled() && (self.guides() || has_references)
    }

    /// `step` (counted out of `reference_steps`) in a run of `total_steps` steps:
    /// `step * total_steps / reference_steps` (rounded down).
    fn scaled_to_run(&self, step: usize, total_steps: usize) -> usize {
        ((step as u128 * total_steps as u128) / self.reference_steps.max(1) as u128) as usize
    }

    /// The first step of the reference's carrying in a run of `total_steps` steps
    /// (`reference.start_step`, scaled like [`Self::normal_start_for`]).
    pub fn reference_start_for(&self, total_steps: usize) -> usize {
        self.scaled_to_run(self.reference.start_step, total_steps)
    }

    /// The first step of the normal guidance in a run of `total_steps` steps:
    /// `normal_start_step * total_steps / reference_steps` (rounded down).
    pub fn normal_start_for(&self, total_steps: usize) -> usize {
        self.scaled_to_run(self.normal_start_step, total_steps)
    }

    /// The first step of the visibility maps in a run of `total_steps` steps
    /// (`visibility.start_step`, scaled like [`Self::normal_start_for`]).
    pub fn visibility_start_for(&self, total_steps: usize) -> usize {
        self.scaled_to_run(self.visibility.start_step, total_steps)
    }

    /// The prompts of a run: the templates with the scene's captions filled in, then the
    /// command-line overrides ([`PromptTemplates::resolve`]).
    pub fn resolve_prompts(&self, scene: &SceneCaptions, overrides: &PromptOverrides) -> Prompts {
        self.prompts.resolve(scene, overrides)
    }
}

/// The message of the first of `fields` (of the table `section`) that is not a finite
/// number >= 0, if any: the check every weight of a method's tables shares.
pub(crate) fn first_negative_weight(section: &str, fields: &[(&str, f64)]) -> Option<String> {
    fields
        .iter()
        .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
        .map(|(name, v)| format!("{section}.{name} = {v} must be a finite number >= 0"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gb_diffusion::distill::GuidanceMethod;

    #[test]
    fn the_default_method_and_a_reference_on_none_hold_the_crop_geometry() {
        use super::GeometryRegion;
        let none = MethodConfig::builtin("none").unwrap();
        assert_eq!(none.geometry.depth_weight, 1.0);
        assert_eq!(none.geometry.region, GeometryRegion::Crop);
        // a plain `none` run has nothing inside the mask to hold against: no unguided pass
        assert!(!none.holds_geometry(false));
        assert!(none.holds_geometry(true));
        let default = MethodConfig::builtin(DEFAULT_METHOD).unwrap();
        assert!(default.holds_geometry(false));
        assert_eq!(default.geometry, none.geometry);
        // a weight of zero guides nothing, so there is nothing to hold
        let mut zero = default.clone();
        zero.lambda_rgb = Weight::Fixed(0.0);
        assert!(zero.holds_geometry(false));
        zero.lambda_normal = Weight::Fixed(0.0);
        assert!(!zero.guides() && !zero.holds_geometry(false));
        assert!(zero.holds_geometry(true));
        // the paper's method stays as published
        assert!(!MethodConfig::builtin("gb-nerf")
            .unwrap()
            .holds_geometry(true));
    }

    #[test]
    fn every_builtin_parses_and_matches_its_name() {
        for (name, _) in BUILTIN_METHODS {
            let m = MethodConfig::builtin(name).unwrap();
            assert_eq!(m.name, *name);
        }
        let gb = MethodConfig::builtin("gb-nerf").unwrap();
        assert!(gb.use_lora && gb.needs_prior());
        assert_eq!(
            gb.rgb.as_ref().unwrap().guidance,
            GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 }
        );
        assert_eq!(
            gb.normal.as_ref().unwrap().guidance,
            GuidanceMethod::Bsd { w1: 1.5, w2: 0.5 }
        );
        assert_eq!(
            (gb.lambda_rgb, gb.lambda_normal),
            (Weight::Fixed(1e-4), Weight::Fixed(1e-4))
        );
        assert_eq!(gb.normal_start_for(10_000), 500);
        assert_eq!(gb.normal_start_for(400), 20);
        assert_eq!(gb.normal_start_for(3), 0);
        let bsd = MethodConfig::builtin("bsd").unwrap();
        assert!(!bsd.use_lora);
        assert_eq!(bsd.rgb, gb.rgb);
        let spin = MethodConfig::builtin("spin-nerf-sds").unwrap();
        assert!(spin.rgb.is_some() && spin.normal.is_none());
        let csd = MethodConfig::builtin("csd").unwrap();
        assert!(matches!(
            csd.rgb.as_ref().unwrap().guidance,
            GuidanceMethod::Csd { w3: Some(_), .. }
        ));
        assert!(!MethodConfig::builtin("none").unwrap().needs_prior());
        assert!(
            MethodConfig::builtin("pre-inpainted")
                .unwrap()
                .pre_inpainted
        );
    }

    #[test]
    fn bad_methods_are_named_errors() {
        let err = MethodConfig::builtin("nope").unwrap_err().to_string();
        assert!(err.contains("nope") && err.contains("gb-nerf"), "{err}");
        let bad = "name = \"x\"\n[rgb]\nmethod = \"bsd\"\nw1 = 1.0\n";
        let err = MethodConfig::from_toml(bad, Path::new("m.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m.toml:") && err.contains("w2"), "{err}");
        let typo = "name = \"x\"\nlamda_rgb = 1.0\n";
        let err = MethodConfig::from_toml(typo, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("lamda_rgb"), "{err}");
        let nan = "name = \"x\"\nlambda_rgb = nan\n";
        assert!(MethodConfig::from_toml(nan, Path::new("n.toml")).is_err());
    }

    #[test]
    fn an_oracle_must_answer_a_branch_the_rgb_guidance_evaluates() {
        let mut m = MethodConfig::builtin("gb-nerf-unseen").unwrap();
        m.oracle.clean = Some("clean".into());
        let text = toml::to_string(&m).unwrap();
        assert!(text.contains("[oracle]"), "{text}");
        let back = MethodConfig::from_toml(&text, Path::new("o.toml")).unwrap();
        assert_eq!(
            back.oracle.branches,
            vec![gb_diffusion::distill::Branch::Text]
        );
        // BSD evaluates the prompt and the negative, never the unconditional branch
        m.oracle.branches = vec![gb_diffusion::distill::Branch::Unconditional];
        let text = toml::to_string(&m).unwrap();
        let err = MethodConfig::from_toml(&text, Path::new("o.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("[oracle]") && err.contains("o.toml"), "{err}");
    }

    #[test]
    fn method_round_trips_through_toml() {
        for (name, _) in BUILTIN_METHODS {
            let m = MethodConfig::builtin(name).unwrap();
            let text = toml::to_string(&m).unwrap();
            let back = MethodConfig::from_toml(&text, Path::new("rt.toml")).unwrap();
            assert_eq!(back, m, "{text}");
            // without personalisation the written method is what it was before the setting
            // existed, so older configs and checkpoints still match
            assert!(!text.contains("personalize"), "{text}");
            assert!(!text.contains("oracle"), "{text}");
        }
        let mut m = MethodConfig::builtin("gb-nerf-unseen").unwrap();
        m.personalize.steps = 50;
        let text = toml::to_string(&m).unwrap();
        assert!(
            text.contains("[personalize]") && text.contains("steps = 50"),
            "{text}"
        );
        let back = MethodConfig::from_toml(&text, Path::new("rt.toml")).unwrap();
        assert_eq!(back, m);
        let typo = text.replace("steps = 50", "stpes = 50");
        let e = MethodConfig::from_toml(&typo, Path::new("rt.toml")).unwrap_err();
        assert!(e.to_string().contains("stpes"), "{e}");
    }
}
