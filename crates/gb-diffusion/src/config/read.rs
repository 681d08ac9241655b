//! Reading a JSON config file into one of the config structs.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// Error reading or parsing a `config.json` / `model_index.json`.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// The file is not valid JSON for the expected struct.
    #[error("invalid config {path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The serde error, which names the field.
        source: serde_json::Error,
    },
    /// A field has a value this implementation does not support.
    #[error("unsupported value in {path}: field `{field}` = {value}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The field name.
        field: String,
        /// The offending value.
        value: String,
    },
}

/// Reads and parses a JSON config file.
pub fn read_json_config<T: DeserializeOwned>(path: &Path) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|source| ConfigError::Parse {
        path: path.to_path_buf(),
        source,
    })
}
