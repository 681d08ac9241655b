//! The one place a prior specification becomes a diffusers folder: `tiny` (the built-in
//! prior, `gb_core::tiny_prior_dir`), an existing folder, or a Hugging Face hub id
//! (`owner/name[@revision]`, through [`super::hub`], offline first).

use std::path::{Path, PathBuf};

use super::hub::{self, HubSettings};
use super::{CheckpointError, DiffusersFolder};

/// The name of the built-in prior.
pub const TINY: &str = "tiny";

/// Where a prior specification points, before anything is read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PriorSpec {
    /// The built-in tiny prior.
    Tiny,
    /// A local diffusers folder.
    Folder(PathBuf),
    /// A hub id (`owner/name[@revision]`).
    Hub(String),
}

impl PriorSpec {
    /// Classifies `spec`: `tiny`, an existing path, or a hub id; anything else is an error
    /// naming it.
    pub fn parse(spec: &str) -> Result<Self, CheckpointError> {
        if spec == TINY {
            return Ok(Self::Tiny);
        }
        let path = Path::new(spec);
        if path.exists() {
            return Ok(Self::Folder(path.to_path_buf()));
        }
        if hub::is_hub_id(spec) {
            return Ok(Self::Hub(spec.to_string()));
        }
        Err(CheckpointError::PriorSpec {
            spec: spec.to_string(),
            message: "no such folder, and not a hub id (owner/name)".into(),
        })
    }

    /// The local folder, downloading a hub id into the hub cache when `hub` allows.
    fn locate(&self, spec: &str, hub: &HubSettings) -> Result<PathBuf, CheckpointError> {
        match self {
            Self::Tiny => {
                let dir = gb_core::tiny_prior_dir();
                if !dir.join("model_index.json").is_file() {
                    return Err(CheckpointError::PriorSpec {
                        spec: spec.to_string(),
                        message: format!(
                            "the built-in prior is missing at {} (reproduce it with `cargo \
                             xtask finetune --synthetic --from-scratch --out out/tiny` and copy \
                             out/tiny/prior there)",
                            dir.display()
                        ),
                    });
                }
                Ok(dir)
            }
            Self::Folder(dir) => Ok(dir.clone()),
            Self::Hub(id) => hub::resolve(id, hub),
        }
    }
}

/// The diffusers folder of `spec` (see the module docs), checked to be a pipeline folder
/// whose weight-holding components have `.safetensors` weights, with the hub settings of the
/// environment ([`HubSettings::from_env`]). Errors name `spec`.
pub fn resolve_prior(spec: &str) -> Result<PathBuf, CheckpointError> {
    resolve_prior_with(spec, &HubSettings::from_env())
}

/// [`resolve_prior`] with the hub settings `hub` (an endpoint of the caller's, say).
pub fn resolve_prior_with(spec: &str, hub: &HubSettings) -> Result<PathBuf, CheckpointError> {
    let dir = locate_model(spec, hub)?;
    DiffusersFolder::open(&dir)
        .and_then(|folder| folder.check_weight_formats())
        .map_err(|e| wrap_for(spec, e))?;
    Ok(dir)
}

/// The local folder that `spec` names, with nothing in it checked: what [`resolve_prior`]
/// then checks as a whole pipeline, and what a reader of single components (`parity
/// --model`) opens itself. Errors name `spec`.
pub fn locate_model(spec: &str, hub: &HubSettings) -> Result<PathBuf, CheckpointError> {
    PriorSpec::parse(spec)?
        .locate(spec, hub)
        .map_err(|e| wrap_for(spec, e))
}

/// `e` with `spec` named, unless it names it already.
fn wrap_for(spec: &str, e: CheckpointError) -> CheckpointError {
    match e {
        e @ (CheckpointError::PriorSpec { .. } | CheckpointError::Prior { .. }) => e,
        e => CheckpointError::Prior {
            spec: spec.to_string(),
            source: Box::new(e),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_is_located_as_it_is_and_resolved_only_with_safetensors_weights() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().display().to_string();
        // pickle weights only: a folder all the same, but no pipeline this crate can load
        std::fs::create_dir(dir.path().join("unet")).unwrap();
        std::fs::write(
            dir.path().join("unet/diffusion_pytorch_model.bin"),
            b"pickle",
        )
        .unwrap();
        let hub = HubSettings::from_env();
        assert_eq!(locate_model(&d, &hub).unwrap(), dir.path());
        let err = resolve_prior_with(&d, &hub).unwrap_err();
        assert!(matches!(err, CheckpointError::Prior { .. }), "{err:?}");
        assert!(
            err.to_string().starts_with(&format!("prior `{d}`: ")),
            "{err}"
        );
        let err = locate_model("no/such/thing/here", &hub).unwrap_err();
        assert!(matches!(err, CheckpointError::PriorSpec { .. }), "{err:?}");
    }

    #[test]
    fn specs_are_classified_and_bad_ones_named() {
        assert_eq!(PriorSpec::parse("tiny").unwrap(), PriorSpec::Tiny);
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().display().to_string();
        assert_eq!(
            PriorSpec::parse(&d).unwrap(),
            PriorSpec::Folder(dir.path().to_path_buf())
        );
        assert_eq!(
            PriorSpec::parse("owner/model@v1").unwrap(),
            PriorSpec::Hub("owner/model@v1".into())
        );
        let e = PriorSpec::parse("/no/such/prior/here")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("prior `/no/such/prior/here`") && e.contains("not a hub id"),
            "{e}"
        );
        // an existing single-file checkpoint: the folder's refusal, under the spec
        let file = dir.path().join("model.ckpt");
        std::fs::write(&file, b"not a pipeline").unwrap();
        let f = file.display().to_string();
        let e = resolve_prior(&f).unwrap_err().to_string();
        assert!(e.starts_with(&format!("prior `{f}`: ")), "{e}");
        assert!(e.contains("model.ckpt") && e.len() > f.len() + 12, "{e}");
    }

    #[test]
    fn the_built_in_prior_resolves() {
        let dir = resolve_prior(TINY).unwrap();
        assert!(dir.join("unet").is_dir(), "{}", dir.display());
    }
}
