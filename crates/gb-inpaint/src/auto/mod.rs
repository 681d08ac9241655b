//! Guidance weights each scene picks for itself: `lambda_rgb = "auto"`,
//! `lambda_normal = "auto"`.
//!
//! A user of the paper's code tunes the guidance scale per scene by eye. Here the scene's own
//! data decides, before the guided run:
//!
//! 1. **pseudo-holes** are placed on observed background away from the object
//!    ([`pseudo_hole`]): cubes whose images are withheld from the colour, depth and
//!    sparse-point losses of every training view, so no view sees them, like the real hole;
//!    the first where the ring around its image looks most like the ring around the object's
//!    mask ([`resemblance`]), up to `[auto] holes` of them on different surfaces;
//!    the surfaces are the scene's COLMAP points or depth maps outside the masks, else (a
//!    capture with neither) a short unguided [`scout`] field's depth;
//! 2. one short **trial** per candidate (the product of `[auto] rgb` and `[auto] normal` over
//!    the weights that are `"auto"`; the others keep their value) trains the method on the
//!    scene with the object's masks withheld too and the pseudo-holes as the guided hole. The
//!    first `[auto] prefix` of a trial's steps are trained once, without guidance, and every
//!    trial continues from them (the same field, optimiser and random stream), so only the
//!    guided rest is paid per trial. A trial is thus guided over its last quarter (default),
//!    where the run guides from a twentieth (normal) or a fifth (RGB) of its steps on: the
//!    trials compare the guidance on a nearly trained field, for a quarter of the cost;
//! 3. each trial is **scored** on the withheld pixels of the training views, whose truth the
//!    training images hold: mask-box SSIM, ST-LPIPS and D-PSNR (D-PSNR only where the scene
//!    has depth maps) over the boxes of every pseudo-hole together (each hole's own are
//!    recorded too), each candidate ranked per metric, the lowest rank sum winning
//!    (`tools/diag/rank_methods.py`'s rule); a tie goes to the smaller total weight, so that
//!    a scene gets guidance only on evidence ("model only what a scene requires").
//!
//! The pseudo-holes, every trial's scores and the choice go into `metrics.json`'s `auto`, and
//! are cached in `OUT/auto/choice.json`, keyed by the contents of the scene's training views,
//! the method, the preset, the prior (and LoRAs) and the oracle: a resumed or repeated run
//! reuses the choice. With an `[oracle]`, the trials' guidance is the oracle's too (its
//! object-free images are the truth of the pseudo-hole as well).
//!
//! ```toml
//! lambda_rgb = "auto"
//! lambda_normal = "auto"
//! [auto]
//! rgb = [0.0, 1e-5]      # candidates (default)
//! normal = [0.0, 1e-5]
//! trial_steps = 0.5      # a trial's steps, as a fraction of the run's
//! hole_scale = 1.0       # the pseudo-hole's side, as a multiple of the mask's
//! holes = 2              # pseudo-holes, on different surfaces (fewer where they do not fit)
//! prefix = 0.75          # the share of a trial's steps trained once, unguided, for all
//! ```

pub mod pseudo_hole;
pub mod resemblance;
mod score;
pub mod scout;

use std::path::{Path, PathBuf};
use std::time::Instant;

use gb_core::{Devices, RgbImage};
use gb_nerf::scene::{Mask, Scene, Split};
use gb_nerf::train::data::downscale_mask;
use gb_nerf::train::NerfConfig;
use serde::{Deserialize, Serialize};

pub use crate::method::{AutoSettings, Weight};
pub use pseudo_hole::{PlacedHole, PseudoHole};
pub use scout::SurfaceSource;

use crate::error::InpaintError;
use crate::geometry::HiddenDepth;
use crate::method::{MethodConfig, Prompts};
use crate::prior::SdPrior;
use crate::trainer::{FitOptions, GuidedTrainer};
pub use score::MIN_SCORE_SIDE;
use score::{best_trial, rank, score, score_targets, ScoreTarget, TrialScores, METRICS};

/// The cache's folder in the run folder.
pub const FOLDER: &str = "auto";
/// The shared unguided prefix's checkpoint, in [`FOLDER`].
const PREFIX_FILE: &str = "prefix.bin";

/// Whether `method` has a weight to choose.
pub fn has_auto(method: &MethodConfig) -> bool {
    method.lambda_rgb.is_auto() || method.lambda_normal.is_auto()
}

/// One trial's weights and scores.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trial {
    /// Its `lambda_rgb`.
    pub lambda_rgb: f64,
    /// Its `lambda_normal`.
    pub lambda_normal: f64,
    /// Mask-box SSIM over the withheld pixels' boxes (mean over views).
    pub ssim_bbox: Option<f64>,
    /// Mask-box ST-LPIPS.
    pub lpips_bbox: Option<f64>,
    /// Mask-box D-PSNR (scenes with depth maps).
    pub d_psnr_bbox: Option<f64>,
    /// The same scores on each pseudo-hole alone, in the order of [`AutoReport::holes`].
    #[serde(default)]
    pub per_hole: Vec<HoleScores>,
    /// Its rank sum over the ranked metrics (lower is better).
    pub rank_sum: f64,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// A trial's scores on one pseudo-hole.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HoleScores {
    /// Mask-box SSIM.
    pub ssim_bbox: Option<f64>,
    /// Mask-box ST-LPIPS.
    pub lpips_bbox: Option<f64>,
    /// Mask-box D-PSNR.
    pub d_psnr_bbox: Option<f64>,
}

/// What the choice did (`metrics.json`'s `auto`, and the cache file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoReport {
    /// The pseudo-holes, the one most like the hole first, each with its resemblance.
    pub holes: Vec<PlacedHole>,
    /// Training views that a pseudo-hole shows in (all withheld there).
    pub withheld_views: usize,
    /// Withheld pixels over those views, at the training resolution, summed over the holes.
    pub withheld_pixels: usize,
    /// Steps of each trial (the shared prefix's included).
    pub trial_steps: usize,
    /// Steps of the shared unguided prefix (0: none).
    #[serde(default)]
    pub prefix_steps: usize,
    /// Wall time of the shared prefix, seconds.
    #[serde(default)]
    pub prefix_seconds: f64,
    /// Where the pseudo-holes' surface points came from: the scene, or a scout field when
    /// it has neither COLMAP points nor depth maps outside the masks ([`scout`]).
    #[serde(default)]
    pub surface: SurfaceSource,
    /// The metrics that ranked the trials.
    pub ranked_by: Vec<String>,
    /// Every trial, in grid order.
    pub trials: Vec<Trial>,
    /// The chosen `lambda_rgb`.
    pub lambda_rgb: f64,
    /// The chosen `lambda_normal`.
    pub lambda_normal: f64,
    /// Wall time of the trials, seconds (of the run that ran them).
    pub seconds: f64,
    /// Whether this run reused the cache.
    pub cached: bool,
}

impl AutoReport {
    /// `method` with the chosen weights in place of `"auto"`.
    pub fn apply(&self, method: &mut MethodConfig) {
        if method.lambda_rgb.is_auto() {
            method.lambda_rgb = Weight::Fixed(self.lambda_rgb);
        }
        if method.lambda_normal.is_auto() {
            method.lambda_normal = Weight::Fixed(self.lambda_normal);
        }
    }
}

/// Everything the choice needs.
pub struct AutoInputs<'a> {
    /// The scene (with its real masks).
    pub scene: &'a Scene,
    /// The method, with its `"auto"` weights.
    pub method: &'a MethodConfig,
    /// The run's preset.
    pub config: &'a NerfConfig,
    /// The run's prompts.
    pub prompts: &'a Prompts,
    /// The oracle's object-free images per training view (training resolution), if the
    /// method has an `[oracle]`.
    pub oracle: Option<&'a [Option<RgbImage>]>,
    /// The run's devices.
    pub devices: Devices,
    /// The metric weights folder (ST-LPIPS).
    pub weights: Option<PathBuf>,
    /// The run folder (the cache lives in `OUT/auto/`).
    pub out: &'a Path,
    /// Show progress bars.
    pub progress: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CacheKey {
    scene: String,
    method: String,
    preset: String,
    prior: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct CacheFile {
    key: CacheKey,
    report: AutoReport,
}

fn auto_err(reason: String) -> InpaintError {
    InpaintError::Spec {
        field: "lambda_rgb / lambda_normal = \"auto\"".into(),
        reason,
    }
}

/// The cache key of a choice (module docs).
fn cache_key(i: &AutoInputs, prior: Option<&SdPrior>) -> Result<CacheKey, InpaintError> {
    let mut h = gb_core::fingerprint::Fnv64::default();
    for v in i.scene.split(Split::Train) {
        h.bytes(v.name.as_bytes());
        v.image.data.iter().for_each(|f| h.word(f.to_bits() as u64));
        if let Some(m) = &v.mask {
            m.data.iter().for_each(|b| h.word(*b as u64 + 2));
        }
        v.camera
            .c2w
            .iter()
            .flatten()
            .for_each(|f| h.word(f.to_bits() as u64));
    }
    let prior = match prior {
        None => None,
        Some(p) => {
            let mut ph = gb_core::fingerprint::Fnv64::default();
            let mut files = vec![p.info.folder.clone()];
            files.extend(p.info.lora.clone());
            files.extend(p.info.personal_lora.clone());
            for f in files {
                let c = gb_core::fingerprint::contents(&f).map_err(|e| InpaintError::io(&f, e))?;
                ph.word(c);
            }
            Some(format!("{:016x}", ph.finish()))
        }
    };
    Ok(CacheKey {
        scene: format!("{:016x}", h.finish()),
        method: toml_text(i.method),
        preset: toml_text(i.config),
        prior,
    })
}

/// A config as TOML text (for cache keys).
fn toml_text<T: Serialize>(v: &T) -> String {
    toml::to_string(v).unwrap_or_else(|e| format!("unserialisable: {e}"))
}

/// The grid: every `"auto"` weight over its candidates, the others fixed.
fn grid(method: &MethodConfig) -> Vec<(f64, f64)> {
    let s = &method.auto;
    let options = |w: Weight, list: &[f64]| match w {
        Weight::Auto => list.to_vec(),
        Weight::Fixed(v) => vec![v],
    };
    let rgb = options(method.lambda_rgb, &s.rgb);
    let normal = options(method.lambda_normal, &s.normal);
    rgb.iter()
        .flat_map(|r| normal.iter().map(move |n| (*r, *n)))
        .collect()
}

/// Chooses the `"auto"` weights of `i.method` (module docs), or reads the choice from the
/// cache. `prior` is lent to the trials and handed back.
pub fn choose_weights(
    i: &AutoInputs,
    prior: &mut Option<SdPrior>,
) -> Result<AutoReport, InpaintError> {
    let key = cache_key(i, prior.as_ref())?;
    let dir = i.out.join(FOLDER);
    let path = dir.join("choice.json");
    if let Some(cached) = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str::<CacheFile>(&t).ok())
        .filter(|c| c.key == key)
    {
        tracing::info!(
            lambda_rgb = cached.report.lambda_rgb,
            lambda_normal = cached.report.lambda_normal,
            "auto weights: reusing the cached choice"
        );
        return Ok(AutoReport {
            cached: true,
            ..cached.report
        });
    }
    let started = Instant::now();
    let auto = &i.method.auto;
    let steps = ((i.config.train.steps as f64 * auto.trial_steps).round() as usize).max(1);
    let prefix_steps = ((steps as f64 * auto.prefix).round() as usize).min(steps - 1);
    let (scouted, surface) = if scout::has_surface(i.scene) {
        (None, SurfaceSource::Scene)
    } else {
        // as long as the trials' shared prefix, which is trained as this scout is, and at
        // least half a trial
        let scout_steps = prefix_steps.max(steps / 2).max(1);
        let (s, source) = scout::scouted(i.scene, i.config, &i.devices, scout_steps, i.progress)?;
        (Some(s), source)
    };
    let placed = pseudo_hole::place_holes(
        scouted.as_ref().unwrap_or(i.scene),
        auto.hole_scale,
        auto.holes,
    )
    .map_err(auto_err)?;
    let f = i.config.train.image_downscale.max(1);
    let each: Vec<Vec<Option<Mask>>> = placed
        .iter()
        .map(|p| pseudo_hole::withheld(i.scene, &p.hole))
        .collect();
    let holes = pseudo_hole::union_per_view(&each);
    // the trial scene: the pseudo-hole is the guided hole, the object's masks are withheld
    let mut trial_scene = i.scene.clone();
    let mut objects = Vec::new();
    let train_views = trial_scene
        .views
        .iter_mut()
        .filter(|v| v.split == Split::Train);
    for (v, m) in train_views.zip(&holes) {
        objects.push(v.mask.as_ref().map(|m| downscale_mask(m, f)));
        v.mask = m.clone();
    }
    let scored: Vec<Vec<ScoreTarget>> = each.iter().map(|h| score_targets(i.scene, h, f)).collect();
    let withheld_pixels = scored
        .iter()
        .flatten()
        .map(|t| t.mask.iter().filter(|b| **b).count())
        .sum();
    let withheld_views = holes.iter().filter(|h| h.is_some()).count();
    for p in &placed {
        tracing::info!(
            hole = ?p.hole,
            resemblance = p.resemblance,
            whole_views = p.whole_views,
            "auto weights: pseudo-hole placed"
        );
    }
    tracing::info!(
        holes = placed.len(),
        views = withheld_views,
        pixels = withheld_pixels,
        trial_steps = steps,
        "auto weights: pseudo-holes withheld"
    );
    let prefix_start = Instant::now();
    let (prefix, hold) = if prefix_steps > 0 {
        let path = dir.join(PREFIX_FILE);
        std::fs::create_dir_all(&dir).map_err(|e| InpaintError::io(&dir, e))?;
        let hold = shared_prefix(i, &trial_scene, &objects, prefix_steps, &path)?;
        (Some(path), hold)
    } else {
        (None, None)
    };
    let prefix_seconds = prefix_start.elapsed().as_secs_f64();
    let setup = TrialSetup {
        scene: &trial_scene,
        objects: &objects,
        scored: &scored,
        steps,
        prefix: prefix.as_deref(),
        hold: hold.as_ref(),
    };
    let trials = run_trials(i, &setup, prior);
    if let Some(path) = &prefix {
        // the field and optimiser of the prefix: no use once the trials are done
        if let Err(e) = std::fs::remove_file(path) {
            tracing::warn!(path = %path.display(), error = %e, "auto weights: prefix left");
        }
    }
    let mut trials = trials?;
    let ranked_by = rank(&mut trials);
    let has_depth_maps = i.scene.split(Split::Train).any(|v| v.depth.is_some());
    let left_out: Vec<&str> = METRICS
        .iter()
        .map(|(k, _)| *k)
        .filter(|k| !ranked_by.iter().any(|r| r == k))
        // D-PSNR needs the scene's depth maps (module docs): its absence is expected there
        .filter(|k| has_depth_maps || *k != "d_psnr_bbox")
        .collect();
    if !has_depth_maps {
        tracing::info!("auto weights: ranked without D-PSNR (the scene has no depth maps)");
    }
    if !left_out.is_empty() {
        tracing::warn!(
            ?left_out,
            "auto weights: ranked without these metrics (unavailable on the pseudo-holes' \
             boxes: their weights are missing, pass --weights DIR or set GB_TEST_DATA to the \
             folder holding weights/, or see the warnings above)"
        );
    }
    let best = best_trial(&trials);
    let report = AutoReport {
        holes: placed,
        withheld_views,
        withheld_pixels,
        trial_steps: steps,
        prefix_steps,
        prefix_seconds,
        surface,
        ranked_by,
        lambda_rgb: trials[best].lambda_rgb,
        lambda_normal: trials[best].lambda_normal,
        trials,
        seconds: started.elapsed().as_secs_f64(),
        cached: false,
    };
    tracing::info!(
        lambda_rgb = report.lambda_rgb,
        lambda_normal = report.lambda_normal,
        "auto weights: chosen"
    );
    std::fs::create_dir_all(&dir).map_err(|e| InpaintError::io(&dir, e))?;
    let text = serde_json::to_vec_pretty(&CacheFile {
        key,
        report: report.clone(),
    })
    .map_err(|e| InpaintError::io(&path, std::io::Error::other(e)))?;
    gb_core::atomic::write_atomic(&path, &text).map_err(|e| InpaintError::io(&path, e))?;
    Ok(report)
}

/// What every trial shares.
struct TrialSetup<'a> {
    /// The trial scene: the pseudo-holes as its masks.
    scene: &'a Scene,
    /// The object's masks per training view, withheld.
    objects: &'a [Option<Mask>],
    /// Each pseudo-hole's score targets.
    scored: &'a [Vec<ScoreTarget>],
    /// Steps of a trial, the prefix's included.
    steps: usize,
    /// The shared unguided prefix's checkpoint, if any.
    prefix: Option<&'a Path>,
    /// The geometry term's targets from the prefix's field, when the method has the term.
    hold: Option<&'a HiddenDepth>,
}

/// Every trial of the grid, in grid order.
fn run_trials(
    i: &AutoInputs,
    setup: &TrialSetup,
    prior: &mut Option<SdPrior>,
) -> Result<Vec<Trial>, InpaintError> {
    let mut trials = Vec::new();
    for (lambda_rgb, lambda_normal) in grid(i.method) {
        let t0 = Instant::now();
        let scores = trial(i, setup, (lambda_rgb, lambda_normal), prior)?;
        let seconds = t0.elapsed().as_secs_f64();
        tracing::info!(
            lambda_rgb,
            lambda_normal,
            ?scores,
            seconds,
            "auto weights: trial"
        );
        trials.push(Trial {
            lambda_rgb,
            lambda_normal,
            ssim_bbox: scores.0[0],
            lpips_bbox: scores.0[1],
            d_psnr_bbox: scores.0[2],
            per_hole: scores.1,
            rank_sum: 0.0,
            seconds,
        });
    }
    Ok(trials)
}

/// Trains the trial scene without guidance (the `none` method) for `steps` and writes the
/// checkpoint `path` that every trial continues from. Returns the method's geometry targets
/// from this unguided field (the pseudo-holes' depth), when it has the term: what each guided
/// trial holds, as the run holds the real hole to its unguided pass.
fn shared_prefix(
    i: &AutoInputs,
    scene: &Scene,
    objects: &[Option<Mask>],
    steps: usize,
    path: &Path,
) -> Result<Option<HiddenDepth>, InpaintError> {
    let mut config = i.config.clone();
    config.train.steps = steps;
    let none = MethodConfig::builtin("none")?;
    let mut t = GuidedTrainer::new_withholding(scene, config, none, None, &i.devices, objects)?;
    t.fit(&FitOptions {
        checkpoint: None,
        log: None,
        append_log: false,
        progress: i.progress,
    })?;
    t.nerf.save_checkpoint(path)?;
    tracing::info!(steps, "auto weights: the trials' shared unguided prefix");
    let geometry = &i.method.geometry;
    geometry
        .enabled()
        .then(|| HiddenDepth::from_field(&t.nerf, geometry.clone(), i.method.crop_margin))
        .transpose()
}

/// One trial: trains and scores `weights` on the trial scene (from the shared prefix, when
/// there is one); the prior is lent and handed back. Returns the [`METRICS`] means (`None`
/// where unavailable), pooled and per hole.
fn trial(
    i: &AutoInputs,
    setup: &TrialSetup,
    weights: (f64, f64),
    prior: &mut Option<SdPrior>,
) -> Result<TrialScores, InpaintError> {
    let mut method = i.method.clone();
    method.lambda_rgb = Weight::Fixed(weights.0);
    method.lambda_normal = Weight::Fixed(weights.1);
    method.personalize = Default::default();
    method.reference = Default::default();
    let mut config = i.config.clone();
    config.train.steps = setup.steps;
    // the field first, so that a failure here leaves the prior with the caller
    let nerf = GuidedTrainer::withholding_base(
        setup.scene,
        config,
        &i.devices,
        setup.objects,
        setup.prefix,
    )?;
    // the run's geometry term, held to the shared unguided prefix (the trials' unguided field)
    let hold = setup.hold.filter(|_| method.holds_geometry(false)).cloned();
    let guidance = if method.needs_prior() {
        let p = prior.take().ok_or_else(|| InpaintError::PriorRequired {
            method: method.name.clone(),
        })?;
        Some((p, i.prompts.clone()))
    } else {
        None
    };
    let mut t = GuidedTrainer::from_base(nerf, setup.scene, method, guidance)?;
    if let Some(hold) = hold {
        t.set_hidden_depth(hold);
    }
    if let (Some(images), Some(_)) = (i.oracle, i.method.oracle.clean.as_ref()) {
        t.set_oracle(crate::oracle::OracleTargets::new(
            images.to_vec(),
            i.method.oracle.branches.clone(),
        ));
    }
    let fitted = t.fit(&FitOptions {
        checkpoint: None,
        log: None,
        append_log: false,
        progress: i.progress,
    });
    let scores = fitted.and_then(|_| score(i, &t, setup.scored));
    *prior = t.into_prior().or(prior.take());
    scores
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_auto_method_is_the_default_s_but_for_its_weights() {
        let unseen = MethodConfig::builtin("gb-nerf-unseen").unwrap();
        let mut auto = MethodConfig::builtin("gb-nerf-auto").unwrap();
        assert!(auto.lambda_rgb.is_auto() && auto.lambda_normal.is_auto());
        // its geometry term too: a guided choice is held like the default
        assert!(auto.geometry.enabled());
        auto.name = unseen.name.clone();
        auto.description = unseen.description.clone();
        auto.lambda_rgb = unseen.lambda_rgb;
        auto.lambda_normal = unseen.lambda_normal;
        auto.auto = unseen.auto.clone();
        assert_eq!(auto, unseen);
    }

    #[test]
    fn the_grid_spans_the_auto_weights_only() {
        let mut m = MethodConfig::builtin("gb-nerf-unseen").unwrap();
        m.lambda_rgb = Weight::Auto;
        assert_eq!(grid(&m), vec![(0.0, 1e-5), (1e-5, 1e-5)]);
        m.lambda_normal = Weight::Auto;
        m.auto.normal = vec![0.0, 3e-5];
        assert_eq!(grid(&m).len(), 4);
        assert_eq!(grid(&m)[3], (1e-5, 3e-5));
        m.auto.trial_steps = 0.0;
        assert!(m.validate().unwrap_err().contains("trial_steps"));
        m.auto.trial_steps = 0.5;
        m.auto.prefix = 1.0;
        assert!(m.validate().unwrap_err().contains("[auto] prefix = 1"));
        m.auto.prefix = 0.0;
        m.auto.holes = 0;
        assert!(m.validate().unwrap_err().contains("[auto] holes = 0"));
        let mut none = MethodConfig::builtin("bsd").unwrap();
        none.normal = None;
        none.lambda_normal = Weight::Auto;
        assert!(none
            .validate()
            .unwrap_err()
            .contains("no [normal] guidance"));
    }
}
