//! The procedural scenes' RGB / normal-map pairs as a [`PairSource`] (`--synthetic`).
//!
//! Two sources, one type:
//!
//! - **a folder** written by `gb_nerf::scene::procedural::write_pairs`
//!   (or `write_scene_pairs`): `NAME_rgb.png`, `NAME_normal.png` and `captions.jsonl`
//!   with one line `{"name", "rgb", "normal", "caption"}` per pair (file names relative to
//!   the folder) — [`SyntheticPairs::open`];
//! - **in memory**, rendered by `gb_nerf::scene::procedural::rgb_normal_pairs` for several
//!   scenes and seeds — [`SyntheticPairs::generate`] / [`SyntheticPairs::generate_with`].
//!
//! The procedural normal maps already use this crate's convention (`(n + 1) / 2` of the unit
//! camera-space normal, OpenGL axes; see [`crate::normal_map`]). Background pixels with no
//! hit are `(0.5, 0.5, 0.5)`, the zero vector, so they are INVALID (`normal_valid` 0), the
//! same rule as for DIODE's sky. Every normal map is canonicalised on load
//! ([`crate::normal_map::canonicalize_map`]): 8-bit PNG values are renormalised to unit
//! vectors and invalid pixels set to exactly the neutral value.

use crate::normal_map::canonicalize_map;
use crate::sample::{PairSample, PairSource};
use crate::FinetuneError;
use gb_nerf::scene::procedural::{rgb_normal_pairs, ProceduralOptions, RgbNormalPair, SceneName};
use std::path::{Path, PathBuf};

/// Views rendered per scene and seed by [`SyntheticPairs::generate`].
pub const DEFAULT_VIEWS: usize = 8;
/// Of which test views (rendered without the object) — they give pairs of the empty scene.
pub const DEFAULT_TEST_VIEWS: usize = 2;

/// The caption file of a pairs folder.
pub const CAPTIONS_FILE: &str = "captions.jsonl";

#[derive(Debug, Clone)]
enum Item {
    File {
        name: String,
        rgb: PathBuf,
        normal: PathBuf,
        caption: String,
    },
    Memory(PairSample),
}

/// Procedural RGB / normal pairs (see the module docs).
#[derive(Debug, Clone)]
pub struct SyntheticPairs {
    items: Vec<Item>,
}

/// A rendered pair as a sample (normal map canonicalised).
pub fn sample_of_pair(pair: &RgbNormalPair) -> PairSample {
    let (normal, normal_valid) = canonicalize_map(&pair.normal.data);
    PairSample {
        name: pair.name.clone(),
        width: pair.rgb.width,
        height: pair.rgb.height,
        rgb: pair.rgb.data.clone(),
        normal: Some(normal),
        normal_valid,
        caption: pair.caption.clone(),
    }
}

fn read_image(path: &Path) -> Result<gb_core::RgbImage, FinetuneError> {
    gb_core::read_rgb(path, None).map_err(|err| FinetuneError::Invalid {
        path: path.to_path_buf(),
        message: match err {
            gb_core::ImageIoError::Read { error, .. } => format!("cannot read image: {error}"),
            other => other.to_string(),
        },
    })
}

impl SyntheticPairs {
    /// Pairs already in memory.
    pub fn from_pairs(pairs: &[RgbNormalPair]) -> Self {
        Self {
            items: pairs
                .iter()
                .map(|p| Item::Memory(sample_of_pair(p)))
                .collect(),
        }
    }

    /// Renders every scene (`stairs`, `fence`) for every seed at `width x height`, with
    /// [`DEFAULT_VIEWS`] views each ([`DEFAULT_TEST_VIEWS`] of them without the object), in
    /// the order scene-major, seed, view.
    pub fn generate(
        scenes: &[&str],
        seeds: &[u64],
        width: usize,
        height: usize,
    ) -> Result<Self, FinetuneError> {
        let mut opts = Vec::new();
        for s in scenes {
            let name: SceneName = s.parse().map_err(|message| FinetuneError::Config {
                field: "synthetic.scenes".into(),
                message,
            })?;
            for &seed in seeds {
                opts.push(ProceduralOptions {
                    name,
                    seed,
                    width,
                    height,
                    views: DEFAULT_VIEWS,
                    test_views: DEFAULT_TEST_VIEWS,
                    dilate: 0,
                });
            }
        }
        if opts.is_empty() {
            return Err(FinetuneError::Config {
                field: "synthetic".into(),
                message: "no scene or no seed given".into(),
            });
        }
        Self::generate_with(&opts)
    }

    /// Renders the pairs of each option set, in order.
    pub fn generate_with(options: &[ProceduralOptions]) -> Result<Self, FinetuneError> {
        let mut items = Vec::new();
        for o in options {
            let pairs = rgb_normal_pairs(o).map_err(|e| FinetuneError::Config {
                field: "synthetic".into(),
                message: format!("scene {} seed {}: {e}", o.name, o.seed),
            })?;
            items.extend(pairs.iter().map(|p| Item::Memory(sample_of_pair(p))));
        }
        Ok(Self { items })
    }

    /// Opens a folder written by `write_pairs`: reads `captions.jsonl` (keys `rgb`, `normal`,
    /// `caption`, optional `name`) and checks that every listed image exists. Images load
    /// lazily.
    pub fn open(dir: &Path) -> Result<Self, FinetuneError> {
        if !dir.is_dir() {
            return Err(FinetuneError::Missing {
                what: "folder of procedural RGB/normal pairs (written by `write_pairs`)".into(),
                path: dir.to_path_buf(),
            });
        }
        let cap = dir.join(CAPTIONS_FILE);
        if !cap.is_file() {
            return Err(FinetuneError::Missing {
                what: format!(
                    "pairs caption file `{CAPTIONS_FILE}` (one line {{\"name\", \"rgb\", \"normal\", \"caption\"}} per pair)"
                ),
                path: cap,
            });
        }
        let text = std::fs::read_to_string(&cap).map_err(|e| FinetuneError::io(&cap, e))?;
        let mut items = Vec::new();
        for (ln, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let bad = |message: String| FinetuneError::Invalid {
                path: cap.clone(),
                message: format!("line {}: {message}", ln + 1),
            };
            let v: serde_json::Value =
                serde_json::from_str(line).map_err(|e| bad(format!("not valid JSON: {e}")))?;
            let get = |key: &str| -> Result<Option<String>, FinetuneError> {
                match v.get(key) {
                    None => Ok(None),
                    Some(x) => x
                        .as_str()
                        .map(|s| Some(s.to_string()))
                        .ok_or_else(|| bad(format!("key \"{key}\" must be a string"))),
                }
            };
            let rgb = get("rgb")?.ok_or_else(|| bad("no \"rgb\" key".into()))?;
            let normal = get("normal")?.ok_or_else(|| bad("no \"normal\" key".into()))?;
            let caption = match get("caption")? {
                Some(c) => c,
                None => get("text")?.unwrap_or_default(),
            };
            let name = match get("name")? {
                Some(n) => n,
                None => Path::new(&rgb)
                    .file_stem()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_default(),
            };
            let (rgb, normal) = (dir.join(rgb), dir.join(normal));
            for (p, what) in [(&rgb, "RGB image"), (&normal, "normal-map image")] {
                if !p.is_file() {
                    return Err(FinetuneError::Missing {
                        what: format!("{what} listed on line {} of {}", ln + 1, cap.display()),
                        path: p.clone(),
                    });
                }
            }
            items.push(Item::File {
                name,
                rgb,
                normal,
                caption,
            });
        }
        if items.is_empty() {
            return Err(FinetuneError::Invalid {
                path: cap,
                message: "lists no pair".into(),
            });
        }
        Ok(Self { items })
    }

    /// Appends the pairs of another source (e.g. several folders or renders).
    pub fn extend(&mut self, other: SyntheticPairs) {
        self.items.extend(other.items);
    }
}

impl PairSource for SyntheticPairs {
    fn len(&self) -> usize {
        self.items.len()
    }

    fn load(&self, index: usize) -> Result<PairSample, FinetuneError> {
        let item = self.items.get(index).ok_or_else(|| FinetuneError::Config {
            field: "index".into(),
            message: format!(
                "sample {index} out of range: {} synthetic pairs",
                self.items.len()
            ),
        })?;
        match item {
            Item::Memory(s) => Ok(s.clone()),
            Item::File {
                name,
                rgb,
                normal,
                caption,
            } => {
                let img = read_image(rgb)?;
                let nimg = read_image(normal)?;
                if (nimg.width, nimg.height) != (img.width, img.height) {
                    return Err(FinetuneError::Invalid {
                        path: normal.clone(),
                        message: format!(
                            "normal map is {}x{}, its RGB image {} is {}x{}",
                            nimg.width,
                            nimg.height,
                            rgb.display(),
                            img.width,
                            img.height
                        ),
                    });
                }
                let (normal, normal_valid) = canonicalize_map(&nimg.data);
                Ok(PairSample {
                    name: name.clone(),
                    width: img.width,
                    height: img.height,
                    rgb: img.data,
                    normal: Some(normal),
                    normal_valid,
                    caption: caption.clone(),
                })
            }
        }
    }
}
