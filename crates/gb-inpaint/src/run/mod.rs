//! One object-removal run, the project's main operation, as a library call:
//! [`run`]`(&`[`RunSpec`]`) -> `[`RunSummary`]. `cargo xtask inpaint` parses its flags into a
//! [`RunSpec`]; the method grid (the gb-grid crate), the benchmarks and the end-to-end tests
//! call [`run`] directly.
//!
//! A run resolves and checks everything a user can get wrong before it trains (method and
//! preset, prior and LoRA, scene and masks, output and baseline folders), trains with an
//! atomic checkpoint (resumable exactly), then writes into `spec.out`:
//! `config.toml` (the reproducing command and the resolved configuration),
//! `train_log.jsonl`, `renders/`, `metrics.json` (the [`RunSummary`]), `orbit.gif`,
//! `report.html` and, with `--export full`, `export/` (nerfstudio; [`export_run`] writes it
//! later from the checkpoint).

mod config_file;
mod export_run;
pub mod probe;
mod setup;
pub mod summary;
mod test_views;
mod unguided;

use std::path::PathBuf;
use std::time::Instant;

use burn::tensor::Device;
use gb_core::{BackendKind, Devices, Precision};
use gb_eval::suite::{evaluate, PairSet, SuiteOptions};
use gb_nerf::train::DepthSupervision;

pub use crate::method::DEFAULT_METHOD;
pub use config_file::shell_quote;
pub use export_run::export_run;
pub use setup::{load_method, load_preset, method_and_prior};
pub use summary::{GuidanceSummary, MeanMetrics, OrbitSummary, RunSummary, ViewMetrics, NOTES};
pub use test_views::{disparity_map, render_test_views, TestViews};

use crate::error::InpaintError;
use crate::method::{PromptOverrides, SceneCaptions};
use crate::personalize::{PersonalizeInputs, PersonalizeReport};
use crate::prior::{lora_for, SdPrior};
use crate::report::RunPage;
use crate::trainer::{FitOptions, GuidedTrainer};

/// Everything one run needs. Field names follow `cargo xtask inpaint`'s flags, and errors
/// name a field by its flag. With the `clap` feature it is those flags: the command line
/// flattens it (`#[command(flatten)]`), so each flag's help is the field's doc below.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct RunSpec {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout). Default: generate the procedural
    /// `stairs` scene into OUT/scene.
    #[cfg_attr(feature = "clap", arg(long))]
    pub scene: Option<PathBuf>,
    /// Method: gb-nerf-unseen (default, the recommended one), gb-nerf (the paper), bsd,
    /// mvip-nerf, spin-nerf-sds, csd, none, pre-inpainted, or a .toml file (a method, or a
    /// run's config.toml). Default: none when --prior is none.
    #[cfg_attr(feature = "clap", arg(long))]
    pub method: Option<String>,
    /// Preset name (fast, balanced, paper) or a path to a TOML config.
    #[cfg_attr(feature = "clap", arg(long, default_value = "fast"))]
    pub preset: String,
    /// The diffusion prior: tiny (default), a diffusers folder, a hub id, or none.
    #[cfg_attr(feature = "clap", arg(long))]
    pub prior: Option<String>,
    /// A LoRA file (.safetensors) to attach to the prior's U-Net and text encoder (default:
    /// the prior's own, for methods with `use_lora`).
    #[cfg_attr(feature = "clap", arg(long))]
    pub lora: Option<PathBuf>,
    /// Prompts replacing the method's templates.
    #[cfg_attr(feature = "clap", command(flatten))]
    pub prompts: PromptOverrides,
    /// Output folder.
    #[cfg_attr(feature = "clap", arg(long, default_value = "out/inpaint"))]
    pub out: PathBuf,
    /// Compute backend: ndarray, flex or wgpu.
    #[cfg_attr(
        feature = "clap",
        arg(long, value_enum, default_value_t = BackendKind::default())
    )]
    pub device: BackendKind,
    /// The prior's precision: f16 (half-precision weights and activations; norms, softmax
    /// and the gradient to the NeRF in f32) or f32. Default: f16 on a GPU card, f32 on the
    /// CPU backends and on lavapipe. ndarray has f32 only.
    #[cfg_attr(feature = "clap", arg(long, value_enum))]
    pub precision: Option<Precision>,
    /// Continue from OUT/checkpoint.bin when it exists.
    #[cfg_attr(feature = "clap", arg(long))]
    pub resume: bool,
    /// Override the preset's number of training steps (at least 1).
    #[cfg_attr(feature = "clap", arg(long, value_parser = gb_core::cli::at_least_one))]
    pub steps: Option<usize>,
    /// Override the preset's training seed (`[train] seed`: ray batches, the guidance's
    /// timesteps and noise); `bench quality --seeds` repeats a grid over seeds with it.
    #[cfg_attr(feature = "clap", arg(long))]
    pub seed: Option<u64>,
    /// Depth supervision: sparse (COLMAP's points in `sparse/0`, the preset default), dense
    /// (per-pixel depth maps, an oracle real captures lack) or none.
    #[cfg_attr(feature = "clap", arg(long))]
    pub depth: Option<DepthSupervision>,
    /// Personalise the prior to the scene first: fine-tune a per-scene LoRA for this many
    /// steps on the training views' unmasked patches (cached in OUT/personalize/; 0: off;
    /// default: the method's `[personalize] steps`).
    #[cfg_attr(feature = "clap", arg(long, value_name = "STEPS"))]
    pub personalize: Option<usize>,
    /// A reference view, repeatable: VIEW (a training view's file name) with the object
    /// removed, as IMAGE (a clean plate or any 2D fill, at the scene's image size). It
    /// supervises the colour inside VIEW's mask and is carried to the other views through
    /// the rendered depth; the guidance acts only where no reference reaches. `auto`: the
    /// middle masked training view filled by `fill --with fsr`, written into OUT.
    #[cfg_attr(
        feature = "clap",
        arg(long = "reference", value_name = "VIEW=IMAGE|auto")
    )]
    pub references: Vec<String>,
    /// The nerfstudio export of the inpainted scene, `OUT/export/`: full (every training view
    /// rendered, with depth and cameras) or none, the default (on a real capture it takes
    /// about as long as the training on a CPU; `cargo xtask export --run OUT` writes it later
    /// from the checkpoint).
    #[cfg_attr(
        feature = "clap",
        arg(long, default_value = "none", value_name = "full|none")
    )]
    pub export: crate::export::ExportMode,
    /// Another run's output folder (or its `renders/`): its test-view renders are the
    /// baseline column of `report.html` (default: the masked input, said so on the page).
    /// A finished `--method none` run of the same preset, seed, scene and device is also the
    /// geometry term's unguided field, read from its checkpoint instead of trained again, and
    /// the whole field of an `auto` run whose choice is no guidance.
    #[cfg_attr(feature = "clap", arg(long))]
    pub baseline: Option<PathBuf>,
    /// Folder of metric weights (ST-LPIPS, FID, BRISQUE, NIMA; default
    /// `$GB_TEST_DATA/weights` when it exists). Metrics without weights are reported
    /// unavailable, with the reason.
    #[cfg_attr(feature = "clap", arg(long))]
    pub weights: Option<PathBuf>,
    /// Frames of the orbit animation `orbit.gif` (0: none).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 24))]
    pub orbit_frames: usize,
    /// Also write `OUT/probe/`: per test view, the hidden region's depth error against the
    /// truth, its normals and the weights along a few hidden rays (a diagnosis of the
    /// filled geometry; needs a scene with true depth).
    #[cfg_attr(feature = "clap", arg(long))]
    pub probe: bool,
    /// Show progress bars (on from the command line).
    #[cfg_attr(feature = "clap", arg(skip = true))]
    pub progress: bool,
    /// The command that runs `inpaint`, for `config.toml`'s reproducing line: `cargo xtask`
    /// in a clone, `gb-nerf` (the default) for the installed command. The command line sets
    /// it after parsing.
    #[cfg_attr(feature = "clap", arg(skip = String::from("gb-nerf")))]
    pub program: String,
}

impl Default for RunSpec {
    fn default() -> Self {
        Self {
            scene: None,
            method: None,
            preset: "fast".into(),
            prior: None,
            lora: None,
            prompts: PromptOverrides::default(),
            device: BackendKind::default(),
            precision: None,
            seed: None,
            steps: None,
            depth: None,
            personalize: None,
            references: Vec::new(),
            out: PathBuf::from("out/inpaint"),
            resume: false,
            baseline: None,
            weights: None,
            orbit_frames: 24,
            export: crate::export::ExportMode::None,
            probe: false,
            progress: false,
            program: "gb-nerf".into(),
        }
    }
}

/// The prior and LoRA of `method`, resolved and loaded; `None` for a method without
/// guidance (a LoRA given to one is an error).
fn method_prior(
    spec: &RunSpec,
    method: &crate::MethodConfig,
    prior_spec: Option<&str>,
    device: &Device,
) -> Result<Option<SdPrior>, InpaintError> {
    if !method.needs_prior() {
        if let Some(p) = spec.prior.as_deref().filter(|p| *p != "none") {
            tracing::info!(prior = p, method = %method.name, "method has no guidance: prior not used");
        }
        if let Some(l) = &spec.lora {
            return Err(InpaintError::Spec {
                field: format!("--lora {}", l.display()),
                reason: format!(
                    "method '{}' has no guidance, so there is no prior to attach it to",
                    method.name
                ),
            });
        }
        return Ok(None);
    }
    let prior_spec = prior_spec.ok_or_else(|| InpaintError::PriorRequired {
        method: method.name.clone(),
    })?;
    let dir = gb_diffusion::checkpoint::resolve_prior(prior_spec)?;
    let lora = lora_for(method, &dir, spec.lora.as_deref())?;
    tracing::info!(prior = %dir.display(), lora = ?lora, "loading the prior");
    let precision = prior_precision(spec, device)?;
    tracing::info!(%precision, "prior precision");
    let opts = crate::prior::PriorOptions {
        lora,
        personal: None,
        precision: Some(precision),
    };
    Ok(Some(crate::prior::load_prior(&dir, &opts, device)?))
}

/// The precision of the run's prior: `--precision` when the device has it, else the device's
/// default; f16 on a backend without f16 tensors is an error naming the flag.
fn prior_precision(spec: &RunSpec, device: &Device) -> Result<Precision, InpaintError> {
    Precision::resolve(spec.precision, device).map_err(|e| InpaintError::Spec {
        field: "--precision".into(),
        reason: e.to_string(),
    })
}

/// Personalises `prior` to the scene when the method asks for it ([`crate::personalize`]):
/// trains or reuses `OUT/personalize/lora.safetensors`, then reloads the prior with it
/// merged. A method without a prior ignores the setting, with a note in the log.
#[allow(clippy::too_many_arguments)]
fn personalize_prior(
    spec: &RunSpec,
    method: &crate::MethodConfig,
    scene: &gb_nerf::scene::Scene,
    config: &gb_nerf::train::NerfConfig,
    prompts: &crate::Prompts,
    references: &[crate::reference::ReferenceView],
    devices: &Devices,
    prior: &mut Option<SdPrior>,
) -> Result<Option<PersonalizeReport>, InpaintError> {
    if !method.personalize.enabled() {
        return Ok(None);
    }
    let Some(p) = prior.as_ref() else {
        tracing::info!(method = %method.name, "method has no prior: personalisation not used");
        return Ok(None);
    };
    let info = p.info.clone();
    let report = crate::personalize::personalize(&PersonalizeInputs {
        scene,
        downscale: config.train.image_downscale,
        crop_margin: method.crop_margin,
        prior: &info.folder,
        lora: info.lora.as_deref(),
        resolution: info.resolution,
        prompt: &prompts.appearance,
        settings: &method.personalize,
        references,
        devices: devices.clone(),
        out: &spec.out,
    })?;
    let opts = crate::prior::PriorOptions {
        lora: info.lora.clone(),
        personal: Some(spec.out.join(&report.lora)),
        precision: Some(info.precision),
    };
    *prior = Some(crate::prior::load_prior(
        &info.folder,
        &opts,
        &devices.plain,
    )?);
    Ok(Some(report))
}

/// Runs one object removal (see the module docs) and returns what it measured, also
/// written as `OUT/metrics.json`.
pub fn run(spec: &RunSpec) -> Result<RunSummary, InpaintError> {
    // the one place `--device` becomes devices: everything below is handed these
    let devices = Devices::new(spec.device);
    setup::check_paths(spec)?;
    let (method_name, prior_spec) = method_and_prior(spec);
    let mut method = load_method(&method_name)?;
    if let Some(steps) = spec.personalize {
        method.personalize.steps = steps;
    }
    let auto_reference = spec.references.iter().any(|r| r == "auto");
    for raw in spec.references.iter().filter(|r| *r != "auto") {
        let pair =
            crate::reference::ReferencePair::parse(raw).map_err(|reason| InpaintError::Spec {
                field: "--reference".into(),
                reason,
            })?;
        method.reference.images.push(pair.to_absolute_string());
    }
    let mut config = load_preset(&spec.preset)?;
    if let Some(steps) = spec.steps {
        config.train.steps = steps;
    }
    if let Some(seed) = spec.seed {
        config.train.seed = seed;
    }
    if let Some(depth) = spec.depth {
        config.train.depth = depth;
    }
    let mut prior = method_prior(spec, &method, prior_spec.as_deref(), &devices.plain)?;

    let (scene_dir, mut scene) = setup::load_or_generate(spec)?;
    setup::require_masks(&scene)?;
    if auto_reference {
        let (pair, record) = crate::fill::auto_reference(&scene, &scene_dir, &spec.out)?;
        method.reference.images.push(pair);
        method.reference.auto = Some(record);
    }
    let references = crate::reference::load_references(
        &scene,
        &method.reference.images,
        config.train.image_downscale,
    )?;
    let pre = if method.pre_inpainted {
        let report = crate::pre_inpainted::apply(&mut scene, &scene_dir)?;
        // SPIn-NeRF supervises with its inpainted depth maps, densely (unless `--depth` says)
        if report.depths > 0
            && spec.depth.is_none()
            && config.train.depth != DepthSupervision::Dense
        {
            tracing::info!(
                depths = report.depths,
                "pre-inpainted: the inpainted depth maps supervise densely (depth = \"dense\")"
            );
            config.train.depth = DepthSupervision::Dense;
        }
        Some(report)
    } else {
        None
    };
    let prompts = method.resolve_prompts(&SceneCaptions::read(&scene_dir), &spec.prompts);

    let out = &spec.out;
    std::fs::create_dir_all(out).map_err(|e| InpaintError::Spec {
        field: format!("--out {}", out.display()),
        reason: format!("cannot create the output folder: {e}"),
    })?;
    let personalized = personalize_prior(
        spec,
        &method,
        &scene,
        &config,
        &prompts,
        &references,
        &devices,
        &mut prior,
    )?;
    let oracle_images = method
        .oracle
        .clean
        .as_deref()
        .map(|dir| {
            crate::oracle::load_object_free(
                &scene,
                dir,
                config.train.image_downscale,
                "[oracle] clean",
            )
        })
        .transpose()?;
    let auto = if crate::auto::has_auto(&method) {
        let report = crate::auto::choose_weights(
            &crate::auto::AutoInputs {
                scene: &scene,
                method: &method,
                config: &config,
                prompts: &prompts,
                oracle: oracle_images.as_deref(),
                devices: devices.clone(),
                weights: spec.weights.clone(),
                out,
                progress: spec.progress,
            },
            &mut prior,
        )?;
        report.apply(&mut method);
        Some(report)
    } else {
        None
    };
    let prior_info = prior.as_ref().map(|p| p.info.clone());
    let ckpt = out.join("checkpoint.bin");
    // read once: its step decides the unguided pass, its state the trainer
    let resumed = if spec.resume && ckpt.is_file() {
        let parts = gb_nerf::train::checkpoint::load(&ckpt)?;
        // another preset is refused before any training (the unguided pass below)
        crate::resume::check_preset(&ckpt, &parts.meta.config(&ckpt)?, &config)?;
        Some(parts)
    } else {
        None
    };
    let resuming = resumed.is_some();
    if spec.resume && !resuming {
        tracing::warn!(
            "--resume: no checkpoint at {}, so the run starts afresh",
            ckpt.display()
        );
    }
    let holds_geometry = method.holds_geometry(!references.is_empty());
    if method.geometry.enabled() && !holds_geometry {
        tracing::info!("geometry: no term inside the mask to hold against, so no unguided pass");
    }
    // a finished checkpoint trains no more: its targets would go unused
    let finished = resumed
        .as_ref()
        .is_some_and(|parts| parts.meta.step >= config.train.steps);
    if holds_geometry && finished {
        tracing::info!("geometry: the checkpoint is finished, so no unguided pass");
    }
    let unguided = if holds_geometry && !finished {
        Some(unguided::unguided_depth(
            &scene,
            &config,
            &method,
            &devices,
            spec.baseline.as_deref(),
            spec.progress,
        )?)
    } else {
        None
    };
    let unguided_seconds = unguided.as_ref().map(|u| u.seconds);
    let unguided_from = unguided.as_ref().and_then(|u| u.from.clone());
    let hidden_depth = unguided.map(|u| u.targets);
    // an `auto` choice of zero weights trains exactly as `none` (without a reference or an
    // oracle): a matching `--baseline` none run is this run's field already
    let adopted = match spec.baseline.as_deref() {
        Some(dir)
            if auto.is_some()
                && !method.guides()
                && references.is_empty()
                && oracle_images.is_none()
                && pre.is_none()
                && !resuming =>
        {
            match unguided::baseline_field(dir, &scene, &config, &devices) {
                Ok(found) => Some(found),
                Err(reason) => {
                    tracing::info!(
                        "auto: --baseline {} is not this run's field ({reason}), so it is trained",
                        dir.display()
                    );
                    None
                }
            }
        }
        _ => None,
    };
    let field_from = adopted.as_ref().map(|(_, _, path)| path.clone());
    let guidance = prior.map(|p| (p, prompts.clone()));
    let mut trainer = match (resumed, adopted) {
        (None, Some((nerf, totals, path))) => {
            tracing::info!(
                path = %path.display(),
                "auto: the choice trains exactly as none, so the --baseline run's field is this \
                 run's"
            );
            let mut t = GuidedTrainer::from_base(nerf, &scene, method.clone(), guidance)?;
            t.totals = totals;
            t
        }
        (Some(parts), _) => {
            tracing::info!(path = %ckpt.display(), "resuming");
            GuidedTrainer::resume_matching(
                &scene,
                &ckpt,
                parts,
                method.clone(),
                guidance,
                &devices,
                config,
            )?
        }
        (None, None) => GuidedTrainer::new(&scene, config, method.clone(), guidance, &devices)?,
    };
    if !references.is_empty() {
        tracing::info!(
            views = ?references.iter().map(|r| r.name.as_str()).collect::<Vec<_>>(),
            pixels = references.iter().map(|r| r.pixels.len()).sum::<usize>(),
            carry_start = method.reference_start_for(trainer.config.train.steps),
            "reference views"
        );
    }
    trainer.set_references(references);
    if let Some(h) = hidden_depth {
        trainer.set_hidden_depth(h);
    }
    if let Some(images) = oracle_images {
        tracing::warn!(
            views = images.iter().flatten().count(),
            branches = ?method.oracle.branches,
            "ORACLE guidance: the RGB term's score is the exact one of the object-free images"
        );
        trainer.set_oracle(crate::oracle::OracleTargets::new(
            images,
            method.oracle.branches.clone(),
        ));
    }
    config_file::write_config(
        spec,
        &config_file::ResolvedRun {
            scene_dir: &scene_dir,
            trainer: &trainer,
            method: &method,
            prompts: &prompts,
            prior_spec: prior_spec.as_deref(),
            prior: prior_info.as_ref(),
            pre: pre.as_ref(),
            resumed: resuming,
        },
    )?;
    tracing::info!(
        scene = %scene.name, preset = %trainer.config.name, method = %method.name,
        device = %devices, train_views = trainer.data.views.len(),
        pixels = trainer.data.pixels.len(), steps = trainer.config.train.steps,
        guided_views = trainer.guidance.as_ref().map_or(0, |g| g.views.len()),
        normal_start = trainer.normal_start(),
        "training"
    );
    let fit = trainer.fit(&FitOptions {
        checkpoint: Some(ckpt.clone()),
        log: Some(out.join("train_log.jsonl")),
        append_log: resuming,
        progress: spec.progress,
    })?;
    if let Some(from) = &field_from {
        // the field's steps are the baseline's: its log, and a checkpoint of this run
        let theirs = from.with_file_name("train_log.jsonl");
        let ours = out.join("train_log.jsonl");
        std::fs::copy(&theirs, &ours).map_err(|e| InpaintError::io(&theirs, e))?;
        trainer.save_checkpoint(&ckpt)?;
    }

    let render_start = Instant::now();
    let tested = test_views::render_test_views(&out.join("renders"), &scene, &trainer)?;
    // a scene without test views: its masked training views, scored without a reference
    let train_views = if tested.pairs.is_empty() {
        crate::report::render_masked_train_views(out, &scene, &trainer)?
    } else {
        Vec::new()
    };
    if spec.probe {
        let report = probe::write_probe(&out.join("probe"), &scene, &trainer, &tested.renders)?;
        for v in &report.views {
            tracing::info!(
                view = %v.view,
                hidden_mean_signed = v.hidden.mean_signed,
                in_front = v.hidden_weights.in_front,
                at_surface = v.hidden_weights.at_surface,
                "probe"
            );
        }
    }
    let render_seconds = render_start.elapsed().as_secs_f64();
    let eval_start = Instant::now();
    let renders: Vec<_> = train_views.iter().map(|t| t.render.clone()).collect();
    let scored = PairSet {
        noun: "test view",
        no_reference: "the scene has no test view with ground truth",
        no_depth: "the scene has no ground-truth depth",
        ..PairSet::new(if tested.pairs.is_empty() {
            &renders
        } else {
            &tested.pairs
        })
    };
    let eval = evaluate(&scored, &SuiteOptions::new(spec.weights.clone(), &devices))?;
    let views = tested.metrics(&eval);
    let eval_seconds = eval_start.elapsed().as_secs_f64();
    let orbit = crate::gif::write_orbit(out, &scene, &trainer, spec.orbit_frames)?;
    let export = if spec.export.enabled() {
        let mut export =
            crate::export::write_export(&out.join("export"), &scene, &trainer, spec.orbit_frames)?;
        // relative to the run folder, like `report`: metrics.json does not depend on where it
        // lies
        export.folder = PathBuf::from("export");
        Some(export)
    } else {
        None
    };
    let per_step = |secs: f64, n: usize| (n > 0).then(|| secs / n as f64);
    let summary = RunSummary {
        method: method.name.clone(),
        prior: prior_info
            .as_ref()
            .map_or_else(|| "none".into(), |p| p.folder.display().to_string()),
        lora: prior_info.as_ref().and_then(|p| p.lora.clone()),
        scene: scene.name.clone(),
        preset: trainer.config.name.clone(),
        device: devices.name().to_string(),
        steps: trainer.step,
        train_seconds_this_run: fit.seconds,
        unguided_seconds,
        unguided_from,
        field_from,
        render_seconds,
        eval_seconds,
        export,
        orbit: orbit.map(|o| OrbitSummary {
            file: "orbit.gif".into(),
            frames: o.frames,
            width: o.width,
            height: o.height,
            seconds: o.seconds,
        }),
        personalize: personalized,
        auto,
        samples_per_ray: trainer.config.sampler.samples_per_ray,
        mean_train_evaluations_per_ray: fit.mean_evaluations_per_ray,
        guidance: GuidanceSummary {
            guided_steps: fit.guided_steps,
            unguided_steps: fit.unguided_steps,
            skipped_steps: fit.skipped_steps,
            seconds_per_guided_step: per_step(fit.guided_seconds, fit.guided_steps),
            seconds_per_unguided_step: per_step(fit.unguided_seconds, fit.unguided_steps),
            unet_calls: fit.unet_calls,
            normal_start: trainer.normal_start(),
            resolution: prior_info.as_ref().map(|p| p.resolution),
        },
        test_views: views.len(),
        mean: MeanMetrics::of(&views),
        views,
        eval: eval.to_json(),
        report: "report.html".into(),
        notes: NOTES.into(),
    };
    summary.write(&out.join("metrics.json"))?;
    let metrics_json = serde_json::to_value(&summary)
        .map_err(|e| InpaintError::io(out.join("metrics.json"), std::io::Error::other(e)))?;
    crate::report::write_run_report(&RunPage {
        out,
        scene: &scene,
        trainer: &trainer,
        pairs: &tested.pairs,
        train_views: &train_views,
        eval: &eval,
        metrics: &metrics_json,
        baseline: spec.baseline.as_deref(),
        orbit: summary.orbit.is_some(),
    })?;
    Ok(summary)
}
