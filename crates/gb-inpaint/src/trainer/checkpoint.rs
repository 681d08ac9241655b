//! The guided trainer's checkpoints: its own state in gb-nerf's container, and the loose and
//! strict resumes from it ([`crate::resume`] holds the saved types and the checks).

use super::*;

impl GuidedTrainer {
    /// Restores a trainer from a checkpoint of the same scene (parameters, Adam state,
    /// occupancy grid, step, random stream, counters, visibility maps); the preset stored in
    /// the checkpoint is used, with `steps` overriding its step count when given. Refuses a
    /// checkpoint of another method (by name); [`Self::resume_matching`] checks everything.
    pub fn resume(
        scene: &Scene,
        path: &Path,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
        devices: impl Into<Devices>,
        steps: Option<usize>,
    ) -> Result<Self, InpaintError> {
        let parts = nerf_checkpoint::load(path)?;
        let mut config = parts.meta.config(path)?;
        if let Some(s) = steps {
            config.train.steps = s;
        }
        Self::resume_parts(scene, path, parts, config, method, guidance, devices, false)
    }

    /// A trainer that only renders: the field, occupancy grid and preset of the checkpoint
    /// at `path`, written by a run of any method, under the `none` method (no prior, no
    /// guidance state), for the export of a finished run ([`crate::run::export_run`]).
    /// Rendering reads nothing else.
    pub fn for_rendering(
        scene: &Scene,
        path: &Path,
        devices: impl Into<Devices>,
    ) -> Result<Self, InpaintError> {
        let nerf = gb_nerf::train::Trainer::resume(scene, path, devices)?;
        Self::from_base(nerf, scene, MethodConfig::builtin("none")?, None)
    }

    /// The strict resume of `cargo xtask inpaint --resume` from `parts`, the checkpoint read
    /// from `path` ([`nerf_checkpoint::load`]): like [`Self::resume`], training with `config`, but
    /// a checkpoint written with another preset (any field but `train.steps` and
    /// `train.checkpoint_every`), method, prompts or prior is refused with one line naming
    /// the file and the first field that differs.
    #[allow(clippy::too_many_arguments)]
    pub fn resume_matching(
        scene: &Scene,
        path: &Path,
        parts: CheckpointParts,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
        devices: impl Into<Devices>,
        config: NerfConfig,
    ) -> Result<Self, InpaintError> {
        resume::check_preset(path, &parts.meta.config(path)?, &config)?;
        Self::resume_parts(scene, path, parts, config, method, guidance, devices, true)
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn resume_parts(
        scene: &Scene,
        path: &Path,
        mut parts: CheckpointParts,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(SdPrior, Prompts)>,
        devices: impl Into<Devices>,
        strict: bool,
    ) -> Result<Self, InpaintError> {
        let bad = |reason: String| gb_nerf::train::NerfError::Checkpoint {
            path: path.to_path_buf(),
            reason,
        };
        let extra = std::mem::take(&mut parts.meta.extra);
        let state: Option<GuidedState> = if extra.is_null() {
            None
        } else {
            Some(serde_json::from_value(extra).map_err(|e| bad(format!("guided state: {e}")))?)
        };
        let identity = resume::identity(
            &method,
            guidance.as_ref().map(|(p, prompts)| (&p.info, prompts)),
        )
        .map_err(|e| bad(format!("run identity: {e}")))?;
        match &state {
            Some(st) => resume::check_identity(path, &st.identity_toml, &identity, strict)?,
            None if strict => {
                return Err(bad(
                    "written by the plain reconstruction trainer: it has no guided-run state \
                     (method, counters)"
                        .into(),
                )
                .into())
            }
            None => {}
        }
        let nerf = Trainer::resume_from(scene, path, parts, config, devices)?;
        let mut t = Self::from_base(nerf, scene, method, guidance)?;
        if let Some(st) = state {
            t.totals = st.totals;
            t.restored_carry = st.reference_carry;
            if let Some(g) = t.guidance.as_mut() {
                g.visibility = st.visibility.iter().map(SavedMap::to_map).collect();
            }
        }
        t.last_good_checkpoint = Some((path.to_path_buf(), t.nerf.step));
        Ok(t)
    }

    /// Writes this trainer's checkpoint to `path` now (atomically), as [`Self::fit`] does at
    /// its checkpoint steps: for a run whose field was read, not trained.
    pub(crate) fn save_checkpoint(&mut self, path: &Path) -> Result<(), InpaintError> {
        let state = self.checkpoint_state()?;
        self.nerf.save_checkpoint_with(path, state)?;
        self.last_good_checkpoint = Some((path.to_path_buf(), self.nerf.step));
        Ok(())
    }

    /// The guided trainer's state for a checkpoint ([`crate::resume`]).
    pub(super) fn checkpoint_state(&self) -> Result<serde_json::Value, InpaintError> {
        let mut visibility: Vec<SavedMap> = self
            .guidance
            .as_ref()
            .map(|g| {
                g.visibility
                    .iter()
                    .map(|(v, m)| SavedMap::new(*v, m))
                    .collect()
            })
            .unwrap_or_default();
        visibility.sort_by_key(|m| m.view);
        let state_error = |reason: String| {
            InpaintError::Nerf(gb_nerf::train::NerfError::Checkpoint {
                path: PathBuf::from("(guided state)"),
                reason,
            })
        };
        // An empty identity would let any run resume this checkpoint: a failure is an error.
        let identity_toml = toml::to_string(&self.identity)
            .map_err(|e| state_error(format!("run identity: {e}")))?;
        let state = GuidedState {
            identity_toml,
            totals: self.totals.clone(),
            visibility,
            reference_carry: self.reference.as_ref().and_then(|r| r.carried.clone()),
        };
        serde_json::to_value(&state).map_err(|e| state_error(e.to_string()))
    }
}
