//! Caption files and the prompts of the paper's three ablation modes.
//!
//! **Caption file**: JSON Lines, one object per image, e.g.
//!
//! ```text
//! {"image": "val/indoors/scene_00019/scan_00183/00019_00183_indoors_000_010.png", "caption": "a kitchen with a table"}
//! {"name": "stairs_s0_view_003", "rgb": "stairs_s0_view_003_rgb.png", "text": "stone stairs"}
//! ```
//!
//! - the image is named by any of the keys `image`, `rgb`, `file`, `name` (every one present
//!   is indexed): a path relative to the dataset root (or any suffix of it), a file name, or a
//!   file stem;
//! - the caption is `caption` or `text` (a string; it may be empty);
//! - blank lines are skipped; any other line that is not such an object is an error naming
//!   the file and the 1-based line number.
//!
//! The paper uses BLIP captions; the user brings them. One caption is shared by an RGB image
//! and its normal map: the prompt only differs in the modality prefix ([`prompts_for`]).

use crate::FinetuneError;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Keys naming the image in a caption line, in the order they are tried for the entry's
/// display name.
pub const IMAGE_KEYS: [&str; 4] = ["image", "rgb", "file", "name"];
/// Keys holding the caption, in order of preference.
pub const CAPTION_KEYS: [&str; 2] = ["caption", "text"];

/// Which prompts the fine-tuning uses (the paper's normal-map ablation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CaptionMode {
    /// Both modalities, identifier plus caption: `RGB image, {caption}` and
    /// `normal map, {caption}` (the paper's choice and the default).
    #[default]
    Captions,
    /// Both modalities with the bare identifiers `RGB image` and `normal map`.
    Identifiers,
    /// Normal maps only, with the prompt `normal map`.
    NormalOnly,
}

impl CaptionMode {
    /// Every mode.
    pub const ALL: [CaptionMode; 3] = [
        CaptionMode::Captions,
        CaptionMode::Identifiers,
        CaptionMode::NormalOnly,
    ];

    /// Its command-line name: `captions`, `identifiers` or `normal-only`.
    pub fn as_str(&self) -> &'static str {
        match self {
            CaptionMode::Captions => "captions",
            CaptionMode::Identifiers => "identifiers",
            CaptionMode::NormalOnly => "normal-only",
        }
    }
}

impl std::fmt::Display for CaptionMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for CaptionMode {
    type Err = FinetuneError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().replace('_', "-").as_str() {
            "captions" => Ok(CaptionMode::Captions),
            "identifiers" => Ok(CaptionMode::Identifiers),
            "normal-only" => Ok(CaptionMode::NormalOnly),
            other => Err(FinetuneError::Config {
                field: "mode".into(),
                message: format!(
                    "unknown caption mode '{other}' (expected captions, identifiers or normal-only)"
                ),
            }),
        }
    }
}

/// Which image a prompt is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Modality {
    /// The RGB image.
    Rgb,
    /// The normal-map image.
    Normal,
}

impl Modality {
    /// The modality identifier that prefixes prompts: `RGB image` or `normal map`.
    pub fn identifier(&self) -> &'static str {
        match self {
            Modality::Rgb => "RGB image",
            Modality::Normal => "normal map",
        }
    }

    /// The prompt `"{identifier}, {caption}"`, or the bare identifier when the caption is
    /// empty (or only white space), so a missing caption never leaves a dangling comma.
    pub fn prompt(&self, caption: &str) -> String {
        let c = caption.trim();
        if c.is_empty() {
            self.identifier().to_string()
        } else {
            format!("{}, {c}", self.identifier())
        }
    }
}

/// The prompts one training pair contributes in `mode`, in a fixed order (RGB first):
///
/// - [`CaptionMode::Captions`]: `[(Rgb, "RGB image, {caption}"), (Normal, "normal map, {caption}")]`
///   — with an empty caption, the bare identifiers (see [`Modality::prompt`]);
/// - [`CaptionMode::Identifiers`]: `[(Rgb, "RGB image"), (Normal, "normal map")]`;
/// - [`CaptionMode::NormalOnly`]: `[(Normal, "normal map")]`.
pub fn prompts_for(mode: CaptionMode, caption: &str) -> Vec<(Modality, String)> {
    match mode {
        CaptionMode::Captions => vec![
            (Modality::Rgb, Modality::Rgb.prompt(caption)),
            (Modality::Normal, Modality::Normal.prompt(caption)),
        ],
        CaptionMode::Identifiers => vec![
            (Modality::Rgb, Modality::Rgb.identifier().to_string()),
            (Modality::Normal, Modality::Normal.identifier().to_string()),
        ],
        CaptionMode::NormalOnly => {
            vec![(Modality::Normal, Modality::Normal.identifier().to_string())]
        }
    }
}

/// A loaded caption file (see the module docs for the format).
#[derive(Debug, Clone, Default)]
pub struct CaptionFile {
    /// The file it was read from (for messages).
    pub path: PathBuf,
    /// `(image name as written, caption)` in file order.
    pub entries: Vec<(String, String)>,
    /// Normalised full key -> entry index.
    by_path: HashMap<String, usize>,
    /// File stem -> entry index (first one wins).
    by_stem: HashMap<String, usize>,
}

/// Forward slashes, no leading `./`, no trailing or doubled separators.
fn normalize_key(s: &str) -> String {
    let s = s.trim().replace('\\', "/");
    s.split('/')
        .filter(|c| !c.is_empty() && *c != ".")
        .collect::<Vec<_>>()
        .join("/")
}

fn stem_of(key: &str) -> String {
    let name = key.rsplit('/').next().unwrap_or(key);
    match name.rfind('.') {
        Some(i) if i > 0 => name[..i].to_string(),
        _ => name.to_string(),
    }
}

impl CaptionFile {
    /// Reads and parses a caption file.
    pub fn load(path: &Path) -> Result<Self, FinetuneError> {
        let bytes = std::fs::read(path).map_err(|e| FinetuneError::io(path, e))?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let at = e.utf8_error().valid_up_to();
            let line = e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count() + 1;
            FinetuneError::Invalid {
                path: path.to_path_buf(),
                message: format!(
                    "line {line}: not UTF-8 text (invalid byte at offset {at}); a caption file \
                     is UTF-8 JSON Lines"
                ),
            }
        })?;
        Self::parse(&text, path)
    }

    /// Parses caption-file text; `path` is only used in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, FinetuneError> {
        let mut out = CaptionFile {
            path: path.to_path_buf(),
            ..Default::default()
        };
        for (ln, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let bad = |message: String| FinetuneError::Invalid {
                path: path.to_path_buf(),
                message: format!("line {}: {message}", ln + 1),
            };
            let value: serde_json::Value =
                serde_json::from_str(line).map_err(|e| bad(format!("not valid JSON: {e}")))?;
            let obj = value
                .as_object()
                .ok_or_else(|| bad("expected a JSON object".into()))?;
            let mut names = Vec::new();
            for key in IMAGE_KEYS {
                if let Some(v) = obj.get(key) {
                    let s = v
                        .as_str()
                        .ok_or_else(|| bad(format!("key \"{key}\" must be a string")))?;
                    if !s.trim().is_empty() {
                        names.push(s.to_string());
                    }
                }
            }
            if names.is_empty() {
                return Err(bad(format!(
                    "no image key (one of {})",
                    IMAGE_KEYS.join(", ")
                )));
            }
            let caption = CAPTION_KEYS
                .iter()
                .find_map(|k| obj.get(*k).map(|v| (*k, v)))
                .ok_or_else(|| bad(format!("no caption key ({})", CAPTION_KEYS.join(" or "))))
                .and_then(|(k, v)| {
                    v.as_str()
                        .map(str::to_string)
                        .ok_or_else(|| bad(format!("key \"{k}\" must be a string")))
                })?;
            let idx = out.entries.len();
            for n in &names {
                let key = normalize_key(n);
                out.by_path.entry(key.clone()).or_insert(idx);
                out.by_stem.entry(stem_of(&key)).or_insert(idx);
            }
            out.entries.push((names[0].clone(), caption));
        }
        Ok(out)
    }

    /// Number of captions.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the file holds no caption.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The caption of an image given by its path relative to the dataset root (or a file
    /// name or stem). Tried in order: the whole path, every shorter suffix of it (so a file
    /// keyed `scene_1/scan_2/x.png` matches `val/indoors/scene_1/scan_2/x.png`), then the
    /// file stem.
    pub fn get(&self, image: &str) -> Option<&str> {
        let key = normalize_key(image);
        let parts: Vec<&str> = key.split('/').collect();
        for start in 0..parts.len() {
            if let Some(&i) = self.by_path.get(&parts[start..].join("/")) {
                return Some(&self.entries[i].1);
            }
        }
        self.by_stem
            .get(&stem_of(&key))
            .map(|&i| self.entries[i].1.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_by_suffix_and_stem() {
        let text = "{\"image\": \"scene_1/scan_2/a.png\", \"caption\": \"A\"}\n\n\
                    {\"name\": \"b\", \"rgb\": \"b_rgb.png\", \"text\": \"B\"}\n";
        let f = CaptionFile::parse(text, Path::new("c.jsonl")).unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f.get("val/indoors/scene_1/scan_2/a.png"), Some("A"));
        assert_eq!(f.get("a"), Some("A"));
        assert_eq!(f.get("b_rgb.png"), Some("B"));
        assert_eq!(f.get("b"), Some("B"));
        assert_eq!(f.get("c.png"), None);
    }

    #[test]
    fn a_file_that_is_not_utf8_names_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("latin1.jsonl");
        std::fs::write(&p, b"{\"image\": \"a\", \"caption\": \"ok\"}\n{\"image\": \"b\", \"caption\": \"caf\xe9\"}\n").unwrap();
        let err = CaptionFile::load(&p).unwrap_err().to_string();
        assert!(
            err.contains("latin1.jsonl") && err.contains("line 2") && err.contains("UTF-8"),
            "{err}"
        );
    }
}
