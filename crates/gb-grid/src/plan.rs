//! [`Grid::plan`]: the cells of a method grid, checked before anything trains.

use std::path::{Path, PathBuf};

use gb_diffusion::checkpoint::PriorSpec;
use gb_diffusion::distill::{DistillSettings, GuidanceMethod};

use super::{Grid, GridCell, GridSettings, SweepPoint};
use crate::ablate::{ABLATION_ROWS, BASELINE_ROWS, DEFAULT_W3};
use gb_inpaint::prior::lora_for;
use gb_inpaint::InpaintError;
use gb_inpaint::MethodConfig;

/// The grid's methods in run order (none first: it is every report's baseline): the
/// tables' methods, restricted to `selected` when given, then any other selected method.
pub fn grid_methods(selected: Option<&[String]>) -> Vec<String> {
    let mut all: Vec<String> = Vec::new();
    for (_, m) in BASELINE_ROWS.iter().chain(ABLATION_ROWS) {
        if !all.iter().any(|x| x == m) {
            all.push(m.to_string());
        }
    }
    let Some(list) = selected else {
        return all;
    };
    let mut out: Vec<String> = all
        .into_iter()
        .filter(|m| list.iter().any(|s| s.trim() == m.as_str()))
        .collect();
    for s in list.iter().map(|s| s.trim()) {
        if !s.is_empty() && !out.iter().any(|m| m == s) {
            out.push(s.to_string());
        }
    }
    out
}

/// `p` made absolute against the current folder (cells run from anywhere).
fn absolute(p: &Path) -> Result<PathBuf, InpaintError> {
    std::path::absolute(p).map_err(|e| InpaintError::io(p, e))
}

/// A method or preset spec with its `.toml` file made absolute (the rule of
/// `MethodConfig::load` and `NerfConfig::preset`: only a `.toml` spec is a file); a
/// built-in name as given.
fn absolute_toml(spec: &str) -> Result<String, InpaintError> {
    if spec.ends_with(".toml") {
        Ok(absolute(Path::new(spec))?.display().to_string())
    } else {
        Ok(spec.to_string())
    }
}

/// A prior spec with its folder made absolute (`PriorSpec::parse` decides what is a
/// folder); `tiny` and hub ids as given. A spec that names nothing is left for the check.
fn absolute_prior(spec: &str) -> Result<String, InpaintError> {
    match PriorSpec::parse(spec) {
        Ok(PriorSpec::Folder(dir)) => Ok(absolute(&dir)?.display().to_string()),
        _ => Ok(spec.to_string()),
    }
}

impl Grid {
    /// Plans the grid in `grid_dir`: the methods of `methods` (default: the whole grid, see
    /// `grid_methods`) and the CSD w3 sweep over `w3` (default [`DEFAULT_W3`] when `csd` is
    /// in the grid, none otherwise; an empty list: no sweep). Every method file and, for the
    /// guided methods, the prior and LoRA are checked first; the sweep's method files
    /// (`csd-w3=X.toml`) are written into `grid_dir`.
    pub fn plan(
        mut settings: GridSettings,
        methods: Option<&[String]>,
        w3: Option<&[f64]>,
        grid_dir: &Path,
    ) -> Result<Self, InpaintError> {
        if !settings.scene.is_dir() {
            return Err(InpaintError::Spec {
                field: format!("--scene {}", settings.scene.display()),
                reason: "not a folder".into(),
            });
        }
        settings.scene = absolute(&settings.scene)?;
        settings.preset = absolute_toml(&settings.preset)?;
        settings.prior = absolute_prior(&settings.prior)?;
        settings.lora = settings.lora.as_deref().map(absolute).transpose()?;
        // the weights are resolved once, here: every cell scores with the same metrics,
        // whatever folder or machine it runs on
        settings.weights = settings
            .weights
            .or_else(gb_eval::default_weights_dir)
            .as_deref()
            .map(absolute)
            .transpose()?;
        let names = grid_methods(methods);
        if names.is_empty() {
            return Err(InpaintError::Spec {
                field: "--methods".into(),
                reason: "empty list".into(),
            });
        }
        let mut configs = Vec::new();
        for name in &names {
            let spec = absolute_toml(name)?;
            let m = MethodConfig::load(&spec).map_err(|e| InpaintError::Spec {
                field: format!("--methods: {name}"),
                reason: e.to_string(),
            })?;
            configs.push((spec, m));
        }
        let csd = MethodConfig::load("csd")?;
        let w3: Vec<f64> = match w3 {
            Some(list) => list.to_vec(),
            None if names.iter().any(|m| m == "csd") => DEFAULT_W3.to_vec(),
            None => Vec::new(),
        };
        let mut to_check: Vec<&MethodConfig> = configs.iter().map(|(_, m)| m).collect();
        if !w3.is_empty() {
            to_check.push(&csd);
        }
        check_priors(&settings, &to_check)?;

        let mut cells: Vec<GridCell> = configs
            .iter()
            .map(|(spec, m)| GridCell {
                method: spec.clone(),
                dir: m.name.clone(),
                use_lora: m.use_lora,
            })
            .collect();
        let csd_w3 = (csd_w3_of(&csd.rgb), csd_w3_of(&csd.normal));
        let mut sweep = Vec::new();
        for w in w3 {
            let reuse = cells.iter().any(|c| c.method == "csd")
                && csd_w3 == (Some(w as f32), Some(w as f32));
            if reuse {
                sweep.push(SweepPoint {
                    w3: w,
                    dir: "csd".into(),
                });
                continue;
            }
            let name = format!("csd-w3={w}");
            let mut m = csd.clone();
            m.name = name.clone();
            m.description = format!("CSD with w3 = {w} on RGB and normal maps (w3 sweep)");
            for settings in [&mut m.rgb, &mut m.normal] {
                if let Some(DistillSettings {
                    guidance: GuidanceMethod::Csd { w3, .. },
                    ..
                }) = settings
                {
                    *w3 = Some(w as f32);
                }
            }
            let file = format!("{name}.toml");
            let path = grid_dir.join(&file);
            std::fs::create_dir_all(grid_dir).map_err(|e| InpaintError::io(grid_dir, e))?;
            let text = toml::to_string(&m)
                .map_err(|e| InpaintError::io(&path, std::io::Error::other(e)))?;
            gb_core::write_atomic(&path, text.as_bytes())
                .map_err(|e| InpaintError::io(&path, e))?;
            cells.push(GridCell {
                method: file,
                dir: name.clone(),
                use_lora: true,
            });
            sweep.push(SweepPoint { w3: w, dir: name });
        }
        Ok(Self {
            settings,
            cells,
            sweep,
        })
    }
}

/// Resolves the prior once and checks the LoRA of every guided method.
fn check_priors(settings: &GridSettings, methods: &[&MethodConfig]) -> Result<(), InpaintError> {
    let mut prior_dir: Option<PathBuf> = None;
    for m in methods.iter().filter(|m| m.needs_prior()) {
        if prior_dir.is_none() {
            prior_dir = Some(
                gb_diffusion::checkpoint::resolve_prior(&settings.prior).map_err(|e| {
                    InpaintError::Spec {
                        field: format!("method {} needs a prior", m.name),
                        reason: e.to_string(),
                    }
                })?,
            );
        }
        if let Some(dir) = &prior_dir {
            let explicit = settings.lora.as_deref().filter(|_| m.use_lora);
            lora_for(m, dir, explicit)?;
        }
    }
    Ok(())
}

/// The `w3` of a CSD guidance (`None` for another method, or CSD's default `w2 - w1`).
fn csd_w3_of(settings: &Option<DistillSettings>) -> Option<f32> {
    match settings.as_ref()?.guidance {
        GuidanceMethod::Csd { w3, .. } => w3,
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_toml_specs_and_prior_folders_become_absolute_paths() {
        assert_eq!(absolute_toml("fast").unwrap(), "fast");
        let file = absolute_toml("my-method.toml").unwrap();
        assert!(
            Path::new(&file).is_absolute() && file.ends_with("my-method.toml"),
            "{file}"
        );
        assert_eq!(absolute_prior("tiny").unwrap(), "tiny");
        assert_eq!(absolute_prior("owner/model").unwrap(), "owner/model");
        let dir = tempfile::tempdir().unwrap();
        let prior = absolute_prior(&dir.path().display().to_string()).unwrap();
        assert_eq!(Path::new(&prior), dir.path());
    }

    #[test]
    fn methods_keep_the_table_order_with_none_first() {
        let all = grid_methods(None);
        assert_eq!(all[0], "none");
        assert_eq!(all.len(), 8, "{all:?}");
        let sel: Vec<String> = ["gb-nerf", "x.toml", "none"].map(String::from).to_vec();
        assert_eq!(grid_methods(Some(&sel)), ["none", "gb-nerf", "x.toml"]);
    }
}
