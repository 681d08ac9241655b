//! `OUT/config.toml`: the command that reproduces a run, then its resolved prior, prompts,
//! preset and method. `--preset` and `--method` of that command point at the file itself.

use std::path::Path;

use gb_diffusion::checkpoint::PriorSpec;

use super::RunSpec;
use crate::error::InpaintError;
use crate::method::{MethodConfig, Prompts};
use crate::pre_inpainted::PreInpaintedReport;
use crate::prior::PriorInfo;
use crate::trainer::GuidedTrainer;

/// `s` quoted for a POSIX shell when it needs quoting.
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=+,".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// What the config file records besides the spec.
pub struct ResolvedRun<'a> {
    /// The scene folder (given or generated).
    pub scene_dir: &'a Path,
    /// The trainer (its preset, backend and steps).
    pub trainer: &'a GuidedTrainer,
    /// The method.
    pub method: &'a MethodConfig,
    /// The prompts, templates filled.
    pub prompts: &'a Prompts,
    /// The prior as given (`tiny`, a folder, a hub id), if any.
    pub prior_spec: Option<&'a str>,
    /// The loaded prior.
    pub prior: Option<&'a PriorInfo>,
    /// The pre-inpainted inputs, for that baseline.
    pub pre: Option<&'a PreInpaintedReport>,
    /// Whether this process resumed from a checkpoint.
    pub resumed: bool,
}

fn toml_err(path: &Path, e: impl std::error::Error + Send + Sync + 'static) -> InpaintError {
    InpaintError::io(path, std::io::Error::other(e))
}

/// The `--prior` of the reproducing command: the spec as given for the built-in prior and
/// hub ids (they do not depend on where the clone or cache lies), the folder otherwise.
fn prior_arg(spec: Option<&str>, prior: &PriorInfo) -> String {
    match spec.map(|s| (s, PriorSpec::parse(s))) {
        Some((s, Ok(PriorSpec::Tiny | PriorSpec::Hub(_)))) => s.to_string(),
        _ => prior.folder.display().to_string(),
    }
}

/// Writes `OUT/config.toml` atomically.
pub fn write_config(spec: &RunSpec, r: &ResolvedRun) -> Result<(), InpaintError> {
    let path = spec.out.join("config.toml");
    let cfg = path.display().to_string();
    let mut cmd = vec![
        format!("{} inpaint", spec.program),
        format!(
            "--scene {}",
            shell_quote(&r.scene_dir.display().to_string())
        ),
        format!("--preset {}", shell_quote(&cfg)),
        format!("--method {}", shell_quote(&cfg)),
        format!("--device {}", spec.device.name()),
        format!("--out {}", shell_quote(&spec.out.display().to_string())),
    ];
    match r.prior {
        Some(p) => {
            cmd.push(format!(
                "--prior {}",
                shell_quote(&prior_arg(r.prior_spec, p))
            ));
            if let Some(l) = &p.lora {
                cmd.push(format!("--lora {}", shell_quote(&l.display().to_string())));
            }
            cmd.push(format!("--precision {}", p.precision));
        }
        None => cmd.push("--prior none".into()),
    }
    for (flag, v) in [
        ("--prompt", &spec.prompts.appearance),
        ("--negative-prompt", &spec.prompts.negative),
        ("--normal-prompt", &spec.prompts.geometry),
    ] {
        if let Some(v) = v {
            cmd.push(format!("{flag} {}", shell_quote(v)));
        }
    }
    let trainer = r.trainer;
    let mut run = toml::Table::new();
    run.insert("reproduce".into(), cmd.join(" ").into());
    // absolute, so that `export --run` finds it from any folder
    let scene = std::path::absolute(r.scene_dir).unwrap_or_else(|_| r.scene_dir.to_path_buf());
    run.insert("scene".into(), scene.display().to_string().into());
    run.insert("method".into(), r.method.name.clone().into());
    run.insert("preset".into(), trainer.config.name.clone().into());
    run.insert("device".into(), spec.device.name().into());
    run.insert("steps".into(), (trainer.config.train.steps as i64).into());
    run.insert(
        "normal_start".into(),
        (trainer.normal_start() as i64).into(),
    );
    run.insert(
        "resumed_from_step".into(),
        (if r.resumed { trainer.step as i64 } else { 0 }).into(),
    );
    let mut sections: Vec<(&str, toml::Value)> = vec![("run", run.into())];
    let mut prior_t = toml::Table::new();
    prior_t.insert("spec".into(), r.prior_spec.unwrap_or("none").into());
    if let Some(p) = r.prior {
        let v = toml::Value::try_from(p).map_err(|e| toml_err(&path, e))?;
        if let Some(t) = v.as_table() {
            prior_t.extend(t.clone());
        }
    }
    sections.push(("prior", prior_t.into()));
    let value = |v: Result<toml::Value, toml::ser::Error>| v.map_err(|e| toml_err(&path, e));
    sections.push(("prompts", value(toml::Value::try_from(r.prompts))?));
    if let Some(pre) = r.pre {
        sections.push(("pre_inpainted", value(toml::Value::try_from(pre))?));
    }
    sections.push(("preset", value(toml::Value::try_from(&trainer.config))?));
    sections.push(("method", value(toml::Value::try_from(r.method))?));
    let mut body = String::new();
    for (name, v) in sections {
        let mut one = toml::Table::new();
        one.insert(name.into(), v);
        body.push_str(&toml::to_string(&one).map_err(|e| toml_err(&path, e))?);
        body.push('\n');
    }
    let text = format!(
        "# The resolved configuration of this run ({} inpaint). Reproduce it with\n#   {}\n{}",
        spec.program,
        cmd.join(" "),
        body
    );
    gb_core::write_atomic(&path, text.as_bytes()).map_err(|e| InpaintError::io(&path, e))
}
