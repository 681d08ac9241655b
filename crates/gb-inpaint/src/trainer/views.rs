//! Per-view guidance inputs: the cached crop constants, the prior's RGB and normal inputs,
//! the visibility maps and the gate that keeps the guidance off observed pixels.

use super::*;

impl GuidedTrainer {
    /// The cached crop constants of training view `view` (computed on first use).
    pub fn view_guidance(&mut self, view: usize) -> Result<&ViewGuidance, InpaintError> {
        let margin = self.method.crop_margin;
        let g = self
            .guidance
            .as_mut()
            .ok_or_else(|| InpaintError::PriorRequired {
                method: self.method.name.clone(),
            })?;
        if !g.cache.contains_key(&view) {
            let v = ViewGuidance::new(
                view,
                &self.nerf.data.views[view],
                margin,
                g.prior.resolution,
                &g.prior.encoder,
                &g.device,
            )?;
            g.cache.insert(view, v);
        }
        g.cache.get(&view).ok_or(InpaintError::Distill(
            gb_diffusion::distill::DistillError::UnknownView(view),
        ))
    }

    /// The RGB prior input of training view `view` with its graph to the field, and the
    /// number of rays rendered.
    /// With visibility-aware guidance on, the gradient reaching observed pixels is scaled
    /// by the method's `visibility.observed_weight` ([`crate::visibility`]).
    pub fn rgb_prior_input(&mut self, view: usize) -> Result<(Tensor<4>, usize), InpaintError> {
        self.view_guidance(view)?;
        let mode = self.method.prior_input;
        let vg = self.cached(view)?;
        let (image, rays) = render_rgb_input(&self.render_context(), vg, mode)
            .map_err(gb_nerf::train::NerfError::from)?;
        Ok((self.gate_observed(view, image)?, rays))
    }

    /// The normal-map prior input of training view `view` with its graph to the field, and
    /// the number of rays rendered, gated like [`Self::rgb_prior_input`] (on the normal
    /// image: gating the depth under the plane fit instead measured worse on `fence`, D-PSNR
    /// 18.9 against 22.1 dB).
    pub fn normal_prior_input(&mut self, view: usize) -> Result<(Tensor<4>, usize), InpaintError> {
        self.view_guidance(view)?;
        let divisor = self.method.normal_render_divisor;
        let vg = self.cached(view)?;
        let (image, rays) = render_normal_input(&self.render_context(), vg, divisor)
            .map_err(gb_nerf::train::NerfError::from)?;
        Ok((self.gate_observed(view, image)?, rays))
    }

    /// The observed map of `view`, recomputed from the current field when it is missing or
    /// `visibility.refresh_every` steps old; `None` when visibility-aware guidance is off.
    /// Errors when the rendered depth cannot be read back.
    pub fn observed_map(&mut self, view: usize) -> Result<Option<&ObservedMap>, InpaintError> {
        let cfg = self.method.visibility.clone();
        if !cfg.enabled() || self.guidance.is_none() {
            return Ok(None);
        }
        let step = self.nerf.step;
        let stale = self.guidance.as_ref().is_some_and(|g| {
            g.visibility
                .get(&view)
                .is_none_or(|m| step >= m.step + cfg.refresh_every)
        });
        if stale {
            let margin = self.method.crop_margin;
            let references = self
                .reference
                .as_ref()
                .map(ReferenceState::view_indices)
                .unwrap_or_default();
            let computed = ObservedMap::compute(
                &self.render_context(),
                &self.nerf.data.views,
                view,
                margin,
                &cfg,
                step,
                &references,
            )
            .map_err(NerfError::from)?;
            let Some(map) = computed else {
                return Ok(None);
            };
            tracing::debug!(
                view,
                step,
                observed = map.observed_share(),
                "visibility map recomputed"
            );
            if let Some(g) = self.guidance.as_mut() {
                g.visibility.insert(view, map);
            }
        }
        Ok(self.guidance.as_ref().and_then(|g| g.visibility.get(&view)))
    }

    /// The first step of the visibility maps (`visibility.start_step` scaled to the run).
    pub fn visibility_start(&self) -> usize {
        self.method
            .visibility_start_for(self.nerf.config.train.steps)
    }

    /// The per-pixel gradient weights `[1, 1, r, r]` of `view`'s prior input (`None` when
    /// visibility-aware guidance is off): `observed_weight` everywhere before
    /// [`Self::visibility_start`], then from the view's observed map.
    pub(super) fn observed_weights(
        &mut self,
        view: usize,
        r: usize,
    ) -> Result<Option<Tensor<4>>, InpaintError> {
        let weight = self.method.visibility.observed_weight;
        if !self.method.visibility.enabled() {
            return Ok(None);
        }
        let device = self.nerf.field.device();
        if self.nerf.step < self.visibility_start() {
            return Ok(Some(Tensor::<4>::full(
                [1, 1, r, r],
                weight as f32,
                &device,
            )));
        }
        Ok(self
            .observed_map(view)?
            .map(|map| map.weights(r, weight, &device)))
    }

    /// The prior's inpainting mask `[1, 1, R, R]` of `view` under visibility-aware
    /// conditioning (`visibility.condition_on_observed`): the crop's mask less the pixels
    /// that other training views observe. `None` when that conditioning is off or before
    /// the maps start (the crop's own mask applies).
    pub(super) fn conditioning_mask(
        &mut self,
        view: usize,
    ) -> Result<Option<Tensor<4>>, InpaintError> {
        let vis = &self.method.visibility;
        if !(vis.enabled() && vis.condition_on_observed) || self.nerf.step < self.visibility_start()
        {
            return Ok(None);
        }
        let Ok(cached) = self.cached(view) else {
            return Ok(None);
        };
        let mask = cached.mask.clone();
        let r = mask.dims()[2];
        let device = mask.device();
        Ok(self
            .observed_map(view)?
            .map(|map| map.weights(r, 0.0, &device))
            .map(|unobserved| mask * unobserved))
    }

    /// `image` with the gradient on observed pixels scaled (identity when off).
    pub(super) fn gate_observed(
        &mut self,
        view: usize,
        image: Tensor<4>,
    ) -> Result<Tensor<4>, InpaintError> {
        let r = image.dims()[2];
        Ok(match self.observed_weights(view, r)? {
            Some(w) => gate_gradient(image, w),
            None => image,
        })
    }

    pub(super) fn cached(&self, view: usize) -> Result<&ViewGuidance, InpaintError> {
        self.guidance
            .as_ref()
            .and_then(|g| g.cache.get(&view))
            .ok_or(InpaintError::Distill(
                gb_diffusion::distill::DistillError::UnknownView(view),
            ))
    }
}
