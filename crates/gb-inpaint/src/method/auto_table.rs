//! `[auto]` of a method: the candidates and trials of the `"auto"` weights
//! ([`crate::auto`] runs them).

use serde::{Deserialize, Serialize};

use super::MethodConfig;

/// `[auto]` of a method (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoSettings {
    /// Candidates of `lambda_rgb` when it is `"auto"`.
    pub rgb: Vec<f64>,
    /// Candidates of `lambda_normal` when it is `"auto"`.
    pub normal: Vec<f64>,
    /// A trial's steps, as a fraction of the run's (at least one step).
    pub trial_steps: f64,
    /// The pseudo-hole's side, as a multiple of the object mask's.
    pub hole_scale: f32,
    /// The most pseudo-holes, each on another surface ([`pseudo_hole::place_holes`]).
    pub holes: usize,
    /// The share of a trial's steps trained once, without guidance, and shared by every
    /// trial (0: each trial trains from scratch).
    pub prefix: f64,
}

impl Default for AutoSettings {
    fn default() -> Self {
        Self {
            rgb: vec![0.0, 1e-5],
            normal: vec![0.0, 1e-5],
            trial_steps: 0.5,
            hole_scale: 1.0,
            holes: 2,
            prefix: 0.75,
        }
    }
}

impl AutoSettings {
    /// Whether these are the default settings.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Checks the settings against `method`'s weights.
    pub fn check(&self, method: &MethodConfig) -> Result<(), String> {
        for (name, list, weight, guided) in [
            ("rgb", &self.rgb, method.lambda_rgb, method.rgb.is_some()),
            (
                "normal",
                &self.normal,
                method.lambda_normal,
                method.normal.is_some(),
            ),
        ] {
            if list.is_empty() {
                return Err(format!("[auto] {name} must list at least one weight"));
            }
            if let Some(v) = list.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(format!("[auto] {name}: {v} is not a finite number >= 0"));
            }
            if weight.is_auto() && !guided {
                return Err(format!(
                    "lambda_{name} = \"auto\" but the method has no [{name}] guidance"
                ));
            }
        }
        if !(self.trial_steps.is_finite() && self.trial_steps > 0.0 && self.trial_steps <= 1.0) {
            return Err(format!(
                "[auto] trial_steps = {} must be in (0, 1]",
                self.trial_steps
            ));
        }
        if !(self.hole_scale.is_finite() && self.hole_scale > 0.0 && self.hole_scale <= 4.0) {
            return Err(format!(
                "[auto] hole_scale = {} must be in (0, 4]",
                self.hole_scale
            ));
        }
        if !(self.prefix.is_finite() && (0.0..1.0).contains(&self.prefix)) {
            return Err(format!("[auto] prefix = {} must be in [0, 1)", self.prefix));
        }
        if !(1..=4).contains(&self.holes) {
            return Err(format!("[auto] holes = {} must be 1 to 4", self.holes));
        }
        Ok(())
    }
}
