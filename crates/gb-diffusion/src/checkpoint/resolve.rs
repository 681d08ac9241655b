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

    /// The local folder, downloading a hub id into the hub cache when allowed.
    fn locate(&self, spec: &str) -> Result<PathBuf, CheckpointError> {
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
            Self::Hub(id) => hub::resolve(id, &HubSettings::from_env()),
        }
    }
}

/// The diffusers folder of `spec` (see the module docs), checked to be a pipeline folder
/// whose weight-holding components have `.safetensors` weights. Errors name `spec`.
pub fn resolve_prior(spec: &str) -> Result<PathBuf, CheckpointError> {
    let wrap = |e: CheckpointError| match e {
        e @ (CheckpointError::PriorSpec { .. } | CheckpointError::Prior { .. }) => e,
        e => CheckpointError::Prior {
            spec: spec.to_string(),
            source: Box::new(e),
        },
    };
    let dir = PriorSpec::parse(spec)?.locate(spec).map_err(wrap)?;
    DiffusersFolder::open(&dir)
        .and_then(|folder| folder.check_weight_formats())
        .map_err(wrap)?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

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
