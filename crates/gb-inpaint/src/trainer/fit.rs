//! One training step (the reconstruction loss plus every guidance term, one backward pass)
//! and the loop of a whole run with its checkpoints and non-finite-loss policy.

use super::*;
use gb_diffusion::distill::LatentEncoder;

impl GuidedTrainer {
    /// One guidance term of `modality` on a prior input `image` of training view `view`, at
    /// step `step` (its seed and schedule position); `at` fixes the timestep and noise.
    pub fn term(
        &mut self,
        modality: Modality,
        view: usize,
        image: Tensor<4>,
        step: usize,
        at: Option<(usize, Tensor<4>)>,
    ) -> Result<TermOutput, InpaintError> {
        self.view_guidance(view)?;
        let seed = derive_seed(self.nerf.config.train.seed, step, modality.salt());
        let k = self.method.guide_every;
        let normal_start = self.normal_start();
        let unobserved_mask = self.conditioning_mask(view)?;
        let (lambda, chain) = match modality {
            Modality::Rgb => (
                self.method.lambda_rgb.value(),
                self.method.reference_chain_rule,
            ),
            Modality::Normal => (
                self.method.lambda_normal.value(),
                self.method.reference_chain_rule,
            ),
        };
        let g = self
            .guidance
            .as_ref()
            .ok_or_else(|| InpaintError::PriorRequired {
                method: self.method.name.clone(),
            })?;
        let vg = g.cache.get(&view).ok_or(InpaintError::Distill(
            gb_diffusion::distill::DistillError::UnknownView(view),
        ))?;
        let (settings, prompts, iteration) = match modality {
            Modality::Rgb => {
                let (s, p) = g.rgb.as_ref().ok_or_else(|| no_guidance("rgb"))?;
                (s, p, multiples_in(0, step, k))
            }
            Modality::Normal => {
                let (s, p) = g.normal.as_ref().ok_or_else(|| no_guidance("normal"))?;
                (s, p, multiples_in(normal_start, step, k))
            }
        };
        let mut distiller = distiller_for(settings, &g.prior, seed, iteration)?;
        let encoder = &g.prior.encoder;
        let (mask_latent, masked_latents) = match (unobserved_mask, modality) {
            // visibility-aware conditioning: the prior is told that only the unobserved
            // pixels are unknown, and sees the current render (detached) on the others
            (Some(mask), _) => {
                let current = image.clone().detach().inner();
                let known = match modality {
                    Modality::Rgb => compose(
                        current,
                        Some(&vg.ground_truth),
                        &vg.mask,
                        PriorInputMode::PasteOnGroundTruth,
                        view,
                    )?,
                    Modality::Normal => current,
                };
                let latent = latent_mask(mask.clone(), encoder.downsample_factor());
                (latent, masked_image_latents(encoder, known, &mask)?)
            }
            (None, Modality::Rgb) => (vg.mask_latent.clone(), vg.masked_image_latents.clone()),
            // no ground-truth normal map: the conditioning is the current normal map
            // itself (detached), masked, as in the reference
            (None, Modality::Normal) => {
                let current = image.clone().detach().inner();
                let latents = masked_image_latents(encoder, current, &vg.mask)?;
                (vg.mask_latent.clone(), latents)
            }
        };
        let oracle = match (modality, self.oracle.as_mut()) {
            (Modality::Rgb, Some(o)) => o
                .latents(view, &vg.geometry, g.prior.resolution, encoder, &g.device)?
                .map(|z| (z, o.branches.as_slice())),
            _ => None,
        };
        let cond = TermConditioning {
            mask_latent: &mask_latent,
            masked_image_latents: &masked_latents,
            prompts,
            oracle,
        };
        guidance_term(&mut distiller, &g.prior, image, &cond, lambda, chain, at)
    }

    /// The guidance terms of step `step` (empty when none is due).
    pub(super) fn guidance_terms(
        &mut self,
        step: usize,
    ) -> Result<(Vec<TermOutput>, Vec<TermRecord>), InpaintError> {
        let mut outs = Vec::new();
        let mut records = Vec::new();
        let Some(g) = self.guidance.as_ref() else {
            return Ok((outs, records));
        };
        if !step.is_multiple_of(self.method.guide_every) {
            return Ok((outs, records));
        }
        // with visibility-aware guidance at weight 0, a term before the maps start would
        // carry no gradient: skip its U-Net calls
        let vis = &self.method.visibility;
        if vis.enabled() && vis.observed_weight == 0.0 && step < self.visibility_start() {
            return Ok((outs, records));
        }
        let do_rgb = g.rgb.is_some() && self.method.lambda_rgb.value() > 0.0;
        let do_normal = g.normal.is_some()
            && self.method.lambda_normal.value() > 0.0
            && step >= self.normal_start();
        if !(do_rgb || do_normal) || g.views.is_empty() {
            return Ok((outs, records));
        }
        let mut pick = ChaCha8Rng::seed_from_u64(derive_seed(self.nerf.config.train.seed, step, 0));
        let view = g.views[pick.random_range(0..g.views.len())];
        if do_rgb {
            let t0 = Instant::now();
            let (image, rays) = self.rgb_prior_input(view)?;
            let out = self.term(Modality::Rgb, view, image, step, None)?;
            records.push(TermRecord::new(
                Modality::Rgb,
                view,
                &out,
                rays,
                t0.elapsed().as_secs_f64(),
            ));
            outs.push(out);
        }
        if do_normal {
            let t0 = Instant::now();
            let (image, rays) = self.normal_prior_input(view)?;
            let out = self.term(Modality::Normal, view, image, step, None)?;
            records.push(TermRecord::new(
                Modality::Normal,
                view,
                &out,
                rays,
                t0.elapsed().as_secs_f64(),
            ));
            outs.push(out);
        }
        Ok((outs, records))
    }

    /// One optimisation step (module docs); a non-finite loss skips the update.
    pub fn train_step(&mut self) -> Result<StepRecord, InpaintError> {
        let start = Instant::now();
        let step = self.nerf.step;
        let recon = self.nerf.reconstruction_loss()?;
        let (terms, records) = self.guidance_terms(step)?;
        let reference = self.reference_term(step)?;
        // the geometry term's loss and its rays
        let geometry = match self.hidden_depth.as_ref() {
            Some(h) => {
                let seed = derive_seed(self.nerf.config.train.seed, step, GEOMETRY_SALT);
                h.loss(&self.render_context(), &self.nerf.data.views, seed)
                    .map_err(gb_nerf::train::NerfError::from)?
                    .map(|g| (g, h.config.rays))
            }
            None => None,
        };
        let mut loss = recon.loss.clone();
        if let Some((g, _)) = &geometry {
            loss = loss + g.clone();
        }
        for t in terms {
            loss = loss + t.loss;
        }
        if let Some((t, _)) = &reference {
            loss = loss + t.loss.clone();
        }
        if self.inject_nan_from_step.is_some_and(|s| step >= s) {
            loss = loss.add_scalar(f32::NAN);
        }
        let mut read = vec![recon.loss.detach(), loss.clone().detach(), recon.rgb_mse];
        // where the reference's and the geometry term's values are in the read
        let reference_at = reference.as_ref().map(|(t, _)| {
            read.push(t.loss.clone().detach());
            read.len() - 1
        });
        let geometry_at = geometry.as_ref().map(|(g, _)| {
            read.push(g.clone().detach());
            read.len() - 1
        });
        // one read for the step's own values (the guidance terms read their diagnostics)
        let values = gb_core::read_f32(Tensor::cat(read, 0), "step losses")
            .map_err(gb_nerf::train::NerfError::from)?;
        let (recon_value, loss_value, rgb_mse) = (values[0], values[1], values[2]);
        let finite = |v: f32| v.is_finite().then_some(v as f64);
        let value_at = |at: Option<usize>| at.and_then(|i| values.get(i).copied()).and_then(finite);
        let geometry_record = geometry.map(|(_, rays)| GeometryRecord {
            loss: value_at(geometry_at),
            rays,
        });
        let mut record = StepRecord {
            step,
            loss: finite(loss_value),
            recon_loss: finite(recon_value),
            psnr: psnr_from_mse((rgb_mse as f64).max(LOG_MIN_MSE)),
            lr: self.nerf.config.lr_at(step),
            skipped: false,
            evaluations_per_ray: recon.evaluations_per_ray,
            seconds: 0.0,
            guidance: records,
            reference: reference.map(|(t, carried)| ReferenceRecord {
                loss: value_at(reference_at),
                direct_rays: t.direct_rays,
                carried_rays: t.carried_rays,
                carried_pixels: carried,
            }),
            geometry: geometry_record,
        };
        if self.nerf.apply_loss_valued(loss, loss_value)? {
            self.nan_streak = 0;
        } else {
            self.nan_streak += 1;
            record.skipped = true;
            tracing::warn!(
                step,
                loss = loss_value,
                streak = self.nan_streak,
                "non-finite loss: step skipped"
            );
        }
        record.seconds = start.elapsed().as_secs_f64();
        Ok(record)
    }

    pub(super) fn stop_message(&self) -> String {
        match &self.last_good_checkpoint {
            Some((p, s)) => format!(
                "the last good checkpoint is {} (step {s}); continue from it with --resume, \
                 e.g. with a lower lambda or learning rate",
                p.display()
            ),
            None => "no checkpoint was written before the failure".into(),
        }
    }

    /// Trains until `config.train.steps` (module docs), writing the log, checkpoints and a
    /// progress bar as `opts` says.
    pub fn fit(&mut self, opts: &FitOptions) -> Result<FitSummary, InpaintError> {
        let total = self.nerf.config.train.steps;
        let start = Instant::now();
        let first = self.nerf.step;
        let bar =
            gb_core::progress::training_bar(total as u64, self.nerf.step as u64, opts.progress);
        let mut log = match &opts.log {
            Some(path) => {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))?;
                }
                if opts.append_log {
                    resume::truncate_log(path, self.nerf.step)
                        .map_err(|e| InpaintError::io(path, e))?;
                }
                let file = std::fs::OpenOptions::new()
                    .create(true)
                    .write(true)
                    .append(opts.append_log)
                    .truncate(!opts.append_log)
                    .open(path)
                    .map_err(|e| InpaintError::io(path, e))?;
                Some((path.clone(), std::io::LineWriter::new(file)))
            }
            None => None,
        };
        while self.nerf.step < total {
            let rec = self.train_step()?;
            let totals = &mut self.totals;
            totals.evaluations_per_ray_sum += rec.evaluations_per_ray as f64;
            if rec.skipped {
                totals.skipped_steps += 1;
            }
            if rec.guidance.is_empty() {
                totals.unguided_steps += 1;
                totals.unguided_seconds += rec.seconds;
            } else {
                totals.guided_steps += 1;
                totals.guided_seconds += rec.seconds;
                totals.unet_calls += rec.guidance.iter().map(|g| g.unet_calls).sum::<usize>();
            }
            if let Some((path, w)) = log.as_mut() {
                let line = serde_json::to_string(&rec).unwrap_or_default();
                writeln!(w, "{line}").map_err(|e| InpaintError::io(path.as_path(), e))?;
            }
            let done = (self.nerf.step - first) as f64;
            let guide = rec
                .guidance
                .iter()
                .map(|g| format!(" {:?} t={:.2} |g|={:.2e}", g.modality, g.t, g.grad_norm))
                .collect::<String>();
            bar.set_position(self.nerf.step as u64);
            bar.set_message(format!(
                "loss {} psnr {:.2} dB {:.2} it/s{guide}",
                rec.loss
                    .map_or_else(|| "NaN (skipped)".to_string(), |l| format!("{l:.5}")),
                rec.psnr,
                done / start.elapsed().as_secs_f64().max(1e-9),
            ));
            if self.nan_streak >= self.method.max_consecutive_nan {
                bar.abandon();
                return Err(InpaintError::NonFiniteLoss {
                    step: rec.step,
                    count: self.nan_streak,
                    checkpoint: self.stop_message(),
                });
            }
            let every = self.nerf.config.train.checkpoint_every;
            if let Some(path) = &opts.checkpoint {
                let due =
                    (every > 0 && self.nerf.step.is_multiple_of(every)) || self.nerf.step == total;
                if due && self.nan_streak == 0 {
                    let state = self.checkpoint_state()?;
                    self.nerf.save_checkpoint_with(path, state)?;
                    self.last_good_checkpoint = Some((path.clone(), self.nerf.step));
                }
            }
        }
        bar.finish();
        let t = &self.totals;
        let counted = t.guided_steps + t.unguided_steps;
        let summary = FitSummary {
            steps_run: self.nerf.step - first,
            seconds: start.elapsed().as_secs_f64(),
            skipped_steps: t.skipped_steps,
            guided_steps: t.guided_steps,
            guided_seconds: t.guided_seconds,
            unguided_steps: t.unguided_steps,
            unguided_seconds: t.unguided_seconds,
            unet_calls: t.unet_calls,
            mean_evaluations_per_ray: if counted > 0 {
                (t.evaluations_per_ray_sum / counted as f64) as f32
            } else {
                0.0
            },
        };
        tracing::info!(
            steps_run = summary.steps_run,
            guided = summary.guided_steps,
            skipped = summary.skipped_steps,
            seconds = summary.seconds,
            "training finished"
        );
        Ok(summary)
    }
}

fn no_guidance(table: &str) -> InpaintError {
    InpaintError::MethodConfig {
        path: PathBuf::from(format!("[{table}]")),
        reason: "this modality has method = \"none\"".into(),
    }
}
