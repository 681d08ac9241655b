//! Building a guided trainer (fresh, withholding pseudo-holes, around a restored base),
//! attaching its references, oracle and geometry term, and what it reports between steps.

use super::*;

impl GuidedTrainer {
    /// A fresh trainer. `guidance` must be given exactly when the method needs a prior.
    pub fn new(
        scene: &Scene,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
        devices: impl Into<Devices>,
    ) -> Result<Self, InpaintError> {
        Self::from_base(
            Trainer::new(scene, config, devices)?,
            scene,
            method,
            guidance,
        )
    }

    /// [`Self::new`], with the pixels under `withheld` (one mask per training view, at the
    /// training resolution) kept from every loss (gb-nerf's `Trainer::withhold`): the
    /// pseudo-holes of [`crate::auto`].
    pub fn new_withholding(
        scene: &Scene,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
        devices: impl Into<Devices>,
        withheld: &[Option<gb_nerf::scene::Mask>],
    ) -> Result<Self, InpaintError> {
        let nerf = Self::withholding_base(scene, config, devices, withheld, None)?;
        Self::from_base(nerf, scene, method, guidance)
    }

    /// The reconstruction trainer of `scene` with the pixels `withheld` from every loss,
    /// restored from the checkpoint at `prefix` when given: one written by a trainer of the
    /// same scene, preset and withheld pixels (the auto-weight trials' shared unguided
    /// prefix, [`crate::auto`]), whose field, optimiser, occupancy grid, step and random
    /// stream it continues; `config`'s step count is where it stops.
    pub(crate) fn withholding_base(
        scene: &Scene,
        config: NerfConfig,
        devices: impl Into<Devices>,
        withheld: &[Option<gb_nerf::scene::Mask>],
        prefix: Option<&Path>,
    ) -> Result<Trainer, InpaintError> {
        let mut nerf = Trainer::new(scene, config, devices)?;
        nerf.withhold(withheld)?;
        Ok(match prefix {
            Some(path) => Trainer::restore(nerf, path, nerf_checkpoint::load(path)?)?,
            None => nerf,
        })
    }

    /// The prior, handed back when the trainer is done with it.
    pub fn into_prior(self) -> Option<SdPrior> {
        self.guidance.map(|g| g.prior)
    }

    /// The guided trainer around the reconstruction trainer `nerf` (fresh or restored).
    pub(crate) fn from_base(
        nerf: Trainer,
        scene: &Scene,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
    ) -> Result<Self, InpaintError> {
        if method.lambda_rgb.is_auto() || method.lambda_normal.is_auto() {
            return Err(InpaintError::MethodConfig {
                path: PathBuf::from(&method.name),
                reason: "a weight is still \"auto\": choose it first (gb_inpaint::auto)".into(),
            });
        }
        let identity = resume::identity(
            &method,
            guidance.as_ref().map(|(p, prompts)| (&p.info, prompts)),
        )
        .map_err(|e| InpaintError::MethodConfig {
            path: PathBuf::from(&method.name),
            reason: e,
        })?;
        let guidance = match (method.needs_prior(), guidance) {
            (true, Some((prior, prompts))) => Some(GuidanceState::new(
                &method,
                prior,
                prompts,
                &nerf.data,
                &scene.name,
                nerf.devices.plain.clone(),
            )?),
            (true, None) => {
                return Err(InpaintError::PriorRequired {
                    method: method.name.clone(),
                })
            }
            (false, _) => None,
        };
        Ok(Self {
            nerf,
            method,
            guidance,
            reference: None,
            restored_carry: None,
            oracle: None,
            hidden_depth: None,
            totals: RunTotals::default(),
            identity,
            nan_streak: 0,
            last_good_checkpoint: None,
            inject_nan_from_step: std::env::var(INJECT_NAN_ENV)
                .ok()
                .and_then(|v| v.parse().ok()),
        })
    }

    /// Attaches the geometry term ([`crate::geometry`]): from now on every step holds the
    /// hidden pixels' depth to `targets`.
    pub fn set_hidden_depth(&mut self, targets: crate::geometry::HiddenDepth) {
        self.hidden_depth = Some(targets);
    }

    /// Attaches oracle guidance ([`crate::oracle`]): the RGB term's chosen branches are
    /// answered by the exact score of each guided view's object-free image.
    pub fn set_oracle(&mut self, targets: crate::oracle::OracleTargets) {
        self.oracle = Some(targets);
    }

    /// Attaches the run's reference views ([`crate::reference`], settings from the method's
    /// `[reference]` table); an empty list removes them. A resumed trainer gets back the
    /// carried pixels of its checkpoint. The guidance no longer draws the reference views
    /// (the reference fills their masks) unless every guided view has a reference.
    pub fn set_references(&mut self, views: Vec<ReferenceView>) {
        if views.is_empty() {
            self.reference = None;
            return;
        }
        let indices: Vec<usize> = views.iter().map(|r| r.view).collect();
        if let Some(g) = self.guidance.as_mut() {
            let rest: Vec<usize> = g
                .views
                .iter()
                .copied()
                .filter(|v| !indices.contains(v))
                .collect();
            if !rest.is_empty() {
                g.views = rest;
            }
        }
        self.reference = Some(ReferenceState {
            config: self.method.reference.clone(),
            views,
            carried: self.restored_carry.take(),
            carry_start: self
                .method
                .reference_start_for(self.nerf.config.train.steps),
        });
    }

    /// The reference term of `step` (refreshing the carried pixels when due), or `None`.
    pub(super) fn reference_term(
        &mut self,
        step: usize,
    ) -> Result<Option<(crate::reference::ReferenceTerm, usize)>, InpaintError> {
        let Some(mut state) = self.reference.take() else {
            return Ok(None);
        };
        let seed = derive_seed(self.nerf.config.train.seed, step, REFERENCE_SALT);
        let ctx = self.render_context();
        let result = state
            .refresh(&ctx, &self.nerf.data.views, step)
            .and_then(|_| {
                state
                    .loss(&ctx, &self.nerf.data.views, seed)
                    .map_err(|e| InpaintError::from(gb_nerf::train::NerfError::from(e)))
            });
        let carried = state.carried.as_ref().map_or(0, |c| c.pixels.len());
        self.reference = Some(state);
        Ok(result?.map(|t| (t, carried)))
    }

    /// The first step of the normal guidance in this run.
    pub fn normal_start(&self) -> usize {
        self.method.normal_start_for(self.nerf.config.train.steps)
    }

    /// Consecutive non-finite losses so far.
    pub fn nan_streak(&self) -> usize {
        self.nan_streak
    }

    /// The last checkpoint written after a finite step (or resumed from), with its step.
    pub fn last_good_checkpoint(&self) -> Option<&(PathBuf, usize)> {
        self.last_good_checkpoint.as_ref()
    }

    pub(super) fn render_context(&self) -> RenderContext<'_> {
        RenderContext {
            field: &self.nerf.field,
            settings: self.nerf.image_settings(),
            rgb_appearance_only: !self.method.rgb_moves_geometry,
        }
    }
}
