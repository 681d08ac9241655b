//! `[reference]` of a method: reference views and how they are carried
//! ([`crate::reference`] applies it), with the record of `--reference auto`
//! ([`crate::fill::auto_reference`]).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// The `[reference]` table of a method (module docs). Left out of a written config while it
/// is the default, so configs and checkpoints of runs without a reference read as before.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceConfig {
    /// `VIEW=IMAGE` pairs (`--reference` adds to them); empty: no reference.
    #[serde(default)]
    pub images: Vec<String>,
    /// Weight of the reference colour MSE (the reconstruction's colour MSE has weight 1).
    #[serde(default = "default_weight")]
    pub weight: f64,
    /// Rays per step through reference and carried pixels.
    #[serde(default = "default_rays")]
    pub rays: usize,
    /// Carry the reference to the other training views through the rendered depth.
    #[serde(default = "default_true")]
    pub carry: bool,
    /// Share of the rays drawn from the carried pixels (once there are any).
    #[serde(default = "default_share")]
    pub carry_share: f32,
    /// First step of the reference term, counted out of the method's `reference_steps`: the
    /// field needs a geometry first, which the term's depth anchors then hold. Half the run,
    /// chosen on tuning seed 100 of `stairs` and `alcove` against a fifth
    /// (`bench/results/reference-tuning-seed-100.json`).
    #[serde(default = "default_start")]
    pub start_step: usize,
    /// Weight of the depth anchor of the reference rays: the disparity loss of the
    /// reconstruction (`gb_nerf::train::losses::disparity_loss`) toward the depth the field
    /// rendered through each ray when the term started (a carried pixel: when it was
    /// carried). 0: no anchor.
    #[serde(default = "default_anchor")]
    pub anchor_weight: f64,
    /// Steps between recomputations of the carried pixels from the current field.
    #[serde(default = "default_refresh")]
    pub refresh_every: usize,
    /// Relative depth agreement of the depth test.
    #[serde(default = "default_tolerance")]
    pub depth_tolerance: f32,
    /// At most this many masked pixels of each other view are tested (a stride grid).
    #[serde(default = "default_max_pixels")]
    pub max_pixels_per_view: usize,
    /// Let the reference's colour loss move the density too (the default). Off, only the
    /// colour is in the graph (`gb_nerf::render::render_samples_fixed_geometry`); that was
    /// worse on `stairs` tuning seed 100 (mask-box D-PSNR 20.4 against 23.6 dB without an
    /// anchor), since colour and density share the hash grid's features.
    #[serde(default = "default_true")]
    pub shapes_geometry: bool,
    /// Supervise and carry only the reference pixels that no other training view observes
    /// ([`carry::observed_reference_pixels`]: the visibility test of [`crate::visibility`],
    /// recomputed at every refresh). For a reference that is worse than what the other views
    /// show of the same surface (a 2D fill, not a clean plate). Off by default; left out of a
    /// written config while off.
    #[serde(default, skip_serializing_if = "is_false")]
    pub skip_observed: bool,
    /// How `--reference auto` made its reference (`crate::fill::auto_reference`); a record,
    /// left out when there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub auto: Option<AutoReference>,
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn default_weight() -> f64 {
    1.0
}
fn default_rays() -> usize {
    256
}
fn default_true() -> bool {
    true
}
fn default_share() -> f32 {
    0.5
}
fn default_start() -> usize {
    5000
}
fn default_refresh() -> usize {
    100
}
fn default_anchor() -> f64 {
    1.0
}
fn default_tolerance() -> f32 {
    0.05
}
fn default_max_pixels() -> usize {
    4096
}

impl Default for ReferenceConfig {
    fn default() -> Self {
        Self {
            images: Vec::new(),
            weight: default_weight(),
            rays: default_rays(),
            carry: default_true(),
            carry_share: default_share(),
            start_step: default_start(),
            anchor_weight: default_anchor(),
            refresh_every: default_refresh(),
            depth_tolerance: default_tolerance(),
            max_pixels_per_view: default_max_pixels(),
            shapes_geometry: true,
            skip_observed: false,
            auto: None,
        }
    }
}

impl ReferenceConfig {
    /// True for the default table (no reference, default settings).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// True when the run has a reference.
    pub fn enabled(&self) -> bool {
        !self.images.is_empty()
    }

    /// A message naming the first invalid field, if any.
    pub fn check(&self) -> Option<String> {
        let weights = [
            ("weight", self.weight),
            ("anchor_weight", self.anchor_weight),
        ];
        if let Some(msg) = super::first_negative_weight("reference", &weights) {
            return Some(msg);
        }
        if self.rays == 0 {
            return Some("reference.rays must be >= 1".into());
        }
        if !(self.carry_share.is_finite() && (0.0..=1.0).contains(&self.carry_share)) {
            return Some("reference.carry_share must be in [0, 1]".into());
        }
        if self.refresh_every == 0 {
            return Some("reference.refresh_every must be >= 1".into());
        }
        if !(self.depth_tolerance.is_finite() && self.depth_tolerance > 0.0) {
            return Some("reference.depth_tolerance must be a positive number".into());
        }
        if self.max_pixels_per_view == 0 {
            return Some("reference.max_pixels_per_view must be >= 1".into());
        }
        self.images
            .iter()
            .find_map(|s| ReferencePair::parse(s).err())
    }
}

/// One `VIEW=IMAGE` pair.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReferencePair {
    /// A training view's file name or stem.
    pub view: String,
    /// The view without the object.
    pub image: PathBuf,
}

impl ReferencePair {
    /// Parses `VIEW=IMAGE` (split at the first `=`); the error names the flag.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.split_once('=') {
            Some((v, i)) if !v.trim().is_empty() && !i.trim().is_empty() => Ok(Self {
                view: v.trim().to_string(),
                image: PathBuf::from(i.trim()),
            }),
            _ => Err(format!(
                "--reference {s}: expected VIEW=IMAGE (a training view's file name, then the \
                 image of that view without the object)"
            )),
        }
    }

    /// `VIEW=IMAGE` with the image's path made absolute (a run's config reproduces it from
    /// any folder).
    pub fn to_absolute_string(&self) -> String {
        let image = std::path::absolute(&self.image).unwrap_or_else(|_| self.image.clone());
        format!("{}={}", self.view, image.display())
    }
}

/// Which 2D fill [`fill_view`] runs (module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FillWith {
    /// Frequency-selective reconstruction ([`gb_fill::fsr`]), the default: it beats the
    /// tiny prior's fill by 5-9 dB of masked PSNR on every procedural scene
    /// (`bench/results/fill-2026-12-05.json`) and needs no weights.
    #[default]
    Fsr,
    /// The membrane fill ([`gb_fill::smooth`]).
    Smooth,
    /// The diffusion prior (DDIM sampling).
    Prior,
}

impl FillWith {
    /// The name `--with` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Fsr => "fsr",
            Self::Smooth => "smooth",
            Self::Prior => "prior",
        }
    }
}

/// The record of `--reference auto` in the run's method (`[reference.auto]`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AutoReference {
    /// The filled training view.
    pub view: String,
    /// The fill.
    pub with: FillWith,
    /// Its settings.
    pub fsr: gb_fill::FsrSettings,
}
