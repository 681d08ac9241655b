//! The extra rows of `bench quality` beside the method grid: the oracles, and the reference
//! rows (`reference-fill`, `reference-auto`, `reference-auto-unseen`), each written as a
//! method file the grid runs (module docs of [`super`]).

use std::path::{Path, PathBuf};

use anyhow::Context;
use gb_nerf::scene::procedural;

/// An oracle row of `bench quality --oracle` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OracleRow {
    /// `reference-oracle`: one exact reference view.
    Reference,
    /// `prior-oracle`: the prior personalised on every exact object-free view.
    Prior,
    /// `score-oracle`: the exact RGB score of the object-free views.
    Score,
}

/// The extra rows of `bench quality` beside the method grid.
#[derive(Debug, Clone, Default)]
pub struct ExtraRows {
    /// The oracle rows (`--oracle`).
    pub oracle: Vec<OracleRow>,
    /// `reference-fill` (`--fill-reference`).
    pub fill: bool,
    /// `reference-auto` (`--auto-reference`).
    pub auto: bool,
    /// `reference-auto-unseen` (`--auto-reference-unseen`).
    pub auto_unseen: bool,
}

/// The name of the oracle row of `--oracle`.
pub const REFERENCE_ORACLE: &str = "reference-oracle";

/// The name of the second oracle row of `--oracle`.
pub const PRIOR_ORACLE: &str = "prior-oracle";

/// The name of the third oracle row of `--oracle`.
pub const SCORE_ORACLE: &str = "score-oracle";

/// What `score-oracle` is, in the JSON.
pub const SCORE_ORACLE_NOTE: &str = "ORACLE, not a method: gb-nerf-unseen whose RGB score is \
    the exact one of each guided view's object-free image (the scene's clean/; SDS with \
    guidance scale 1, lambda_rgb 1e-4), the normal term unchanged; no direct supervision";

/// AdamW steps of the `prior-oracle` personalisation.
pub const PRIOR_ORACLE_STEPS: usize = 300;

/// The name of the row of `--fill-reference`.
pub const REFERENCE_FILL: &str = "reference-fill";

/// The name of the row of `--auto-reference`.
pub const REFERENCE_AUTO: &str = "reference-auto";

/// The name of the second row of `--auto-reference`: `reference-auto` with `[reference]
/// skip_observed`.
pub const REFERENCE_AUTO_UNSEEN: &str = "reference-auto-unseen";

/// The middle masked training view of a generated scene: the reference view of the
/// `reference-*` rows.
pub fn reference_view(scene: &procedural::GeneratedScene) -> Option<&procedural::GeneratedView> {
    let train: Vec<&procedural::GeneratedView> = scene
        .views
        .iter()
        .filter(|v| v.split == gb_nerf::scene::Split::Train && v.mask.data.iter().any(|b| *b))
        .collect();
    train.get(train.len() / 2).copied()
}

/// Writes `dir/NAME.toml`: the `none` method with the reference `VIEW.png=IMAGE`, described
/// by `comment`. Returns its path.
fn write_reference_method(
    dir: &Path,
    name: &str,
    comment: &str,
    view: &str,
    image: &Path,
) -> anyhow::Result<PathBuf> {
    let mut method = gb_inpaint::MethodConfig::load("none")?;
    method.name = name.into();
    method.description = comment.into();
    let image = std::path::absolute(image)?;
    method.reference.images = vec![format!("{view}.png={}", image.display())];
    write_method(dir, &method)
}

/// Writes `dir/reference-oracle.toml` (module docs): the `none` method with the middle
/// masked training view of `scene` as its reference, from the scene's `clean/`.
pub fn write_reference_oracle(
    scene: &procedural::GeneratedScene,
    scene_dir: &Path,
    dir: &Path,
) -> anyhow::Result<PathBuf> {
    let view = reference_view(scene)
        .ok_or_else(|| anyhow::anyhow!("{}: no masked training view", scene_dir.display()))?;
    write_reference_method(
        dir,
        REFERENCE_ORACLE,
        "ORACLE, not a method: no prior; one training view without the object (exact ground \
         truth from the scene's clean/) is the reference",
        &view.name,
        &scene_dir.join("clean").join(format!("{}.png", view.name)),
    )
}

/// Writes `dir/prior-oracle.toml` (module docs): the guided method at fixed weights
/// ([`gb_inpaint::run::DEFAULT_METHOD`]) with its prior personalised
/// ([`gb_inpaint::personalize`], [`PRIOR_ORACLE_STEPS`] steps) on the scene's `clean/`, every
/// training view without the object: the prior then knows what the hole holds, and only the
/// distillation carries it into the NeRF (no reference, no direct supervision).
pub fn write_prior_oracle(scene_dir: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    let mut method = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD)?;
    method.name = PRIOR_ORACLE.into();
    method.description = format!(
        "ORACLE, not a method: {} with its prior personalised on every training view without \
         the object (exact ground truth from the scene's clean/)",
        gb_inpaint::run::DEFAULT_METHOD
    );
    method.personalize.steps = PRIOR_ORACLE_STEPS;
    method.personalize.object_free = Some(std::path::absolute(scene_dir.join("clean"))?);
    write_method(dir, &method)
}

/// Writes `dir/score-oracle.toml` (module docs, [`SCORE_ORACLE_NOTE`]): the guided method
/// with its RGB score replaced by the exact score of the object-free images
/// ([`gb_inpaint::oracle`]): SDS at guidance scale 1, so that the direction is exactly the
/// pull of the crop's latents to the truth's, at `lambda_rgb = 1e-4` (ten times the
/// gb-nerf-unseen's: the exact direction has no noise in it and is smaller than BSD's; the one
/// weight tried, on tuning seed 100).
pub fn write_score_oracle(scene_dir: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    use gb_diffusion::distill::{Branch, GuidanceMethod};
    let mut method = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD)?;
    method.name = SCORE_ORACLE.into();
    method.description = SCORE_ORACLE_NOTE.into();
    method.lambda_rgb = 1e-4.into();
    let rgb = method
        .rgb
        .as_mut()
        .ok_or_else(|| anyhow::anyhow!("the guided method has no RGB guidance"))?;
    rgb.guidance = GuidanceMethod::Sds {
        guidance_scale: 1.0,
    };
    method.oracle = gb_inpaint::oracle::OracleSettings {
        clean: Some(std::path::absolute(scene_dir.join("clean"))?),
        branches: vec![Branch::Text, Branch::Unconditional],
    };
    write_method(dir, &method)
}

/// Writes `dir/NAME.toml` for `method`, headed by its description. Returns its path.
fn write_method(dir: &Path, method: &gb_inpaint::MethodConfig) -> anyhow::Result<PathBuf> {
    let text = format!("# {}\n{}", method.description, toml::to_string(method)?);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{}.toml", method.name));
    gb_core::write_atomic(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// Writes `dir/reference-fill.toml` (module docs): the `none` method with the middle masked
/// training view of `scene` filled by `prior` (`gb_inpaint::fill`, its default settings) as
/// its reference, the fill saved beside it.
pub fn write_reference_fill(
    scene: &procedural::GeneratedScene,
    scene_dir: &Path,
    dir: &Path,
    prior: &str,
    device: gb_core::BackendKind,
) -> anyhow::Result<PathBuf> {
    let view = reference_view(scene)
        .ok_or_else(|| anyhow::anyhow!("{}: no masked training view", scene_dir.display()))?;
    let png = dir.join(format!("{REFERENCE_FILL}-{}.png", view.name));
    if !png.is_file() {
        let opts = gb_inpaint::fill::FillOptions {
            with: gb_inpaint::fill::FillWith::Prior,
            prior: prior.to_string(),
            device,
            ..Default::default()
        };
        let filled = gb_inpaint::fill::fill(scene_dir, &view.name, &opts)?;
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        gb_core::write_rgb_png(&png, &filled.image)
            .with_context(|| format!("writing {}", png.display()))?;
    }
    write_reference_method(
        dir,
        REFERENCE_FILL,
        &format!(
            "no prior in the NeRF; one training view filled in 2D by the prior '{prior}' \
             (cargo xtask fill) is the reference"
        ),
        &view.name,
        &png,
    )
}

/// Writes `dir/reference-auto.toml` and `dir/reference-auto-unseen.toml` (module docs): the
/// `none` method with the reference that `inpaint --reference auto` makes
/// ([`gb_inpaint::fill::auto_reference`]: the middle masked training view filled by
/// frequency-selective reconstruction), the fill saved beside it; the second supervises and
/// carries only the reference pixels that no other view observes (`[reference]
/// skip_observed`).
pub fn write_reference_auto(scene_dir: &Path, dir: &Path) -> anyhow::Result<[PathBuf; 2]> {
    let (_, scene) = gb_nerf::scene::load(scene_dir, &gb_nerf::scene::LoadOptions::default())?;
    let (_, auto) = gb_inpaint::fill::auto_reference(&scene, scene_dir, dir)?;
    let png = dir.join(format!("reference-auto-{}.png", auto.view));
    let all = write_reference_method(
        dir,
        REFERENCE_AUTO,
        "no prior in the NeRF; one training view filled in 2D by frequency-selective \
         reconstruction (inpaint --reference auto, no weights) is the reference",
        &auto.view,
        &png,
    )?;
    let mut method = gb_inpaint::MethodConfig::load(all.to_str().context("a non-UTF-8 path")?)?;
    method.name = REFERENCE_AUTO_UNSEEN.into();
    method.description = format!(
        "{}, on the pixels no other training view observes",
        method.description
    );
    method.reference.skip_observed = true;
    Ok([all, write_method(dir, &method)?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use gb_nerf::scene::procedural::ProceduralOptions;

    #[test]
    fn the_oracle_rows_are_the_default_method_with_the_scenes_clean_views() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        let prior = gb_inpaint::MethodConfig::load(
            write_prior_oracle(&scene, dir.path())
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        assert_eq!(prior.name, PRIOR_ORACLE);
        assert_eq!(prior.personalize.steps, PRIOR_ORACLE_STEPS);
        assert!(prior
            .personalize
            .object_free
            .unwrap()
            .ends_with("scene/clean"));
        assert!(prior.oracle.clean.is_none());
        let score = gb_inpaint::MethodConfig::load(
            write_score_oracle(&scene, dir.path())
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        let default = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD).unwrap();
        assert_eq!(score.name, SCORE_ORACLE);
        assert!(score.oracle.clean.unwrap().ends_with("scene/clean"));
        assert_eq!(score.lambda_rgb.value(), 1e-4);
        assert_eq!(
            (score.lambda_normal, &score.normal, &score.visibility),
            (default.lambda_normal, &default.normal, &default.visibility)
        );
        assert_eq!(score.rgb.unwrap().guidance.name(), "sds");
        let reference = gb_inpaint::MethodConfig::load(
            write_reference_method(dir.path(), "r", "a note", "view_003", &scene.join("x.png"))
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        assert_eq!(
            (reference.name.as_str(), reference.rgb.is_none()),
            ("r", true)
        );
        assert_eq!(reference.reference.images.len(), 1);
        assert!(reference.reference.images[0].starts_with("view_003.png="));
        assert!(reference.reference.images[0].ends_with("scene/x.png"));
    }

    /// `reference-auto` is `none` with the fsr fill of the view that the reference oracle
    /// uses: the fill is written, it matches the view outside the mask and is closer to the
    /// clean view than the object inside it.
    #[test]
    fn the_auto_reference_row_fills_the_oracle_s_view_by_fsr() {
        let dir = tempfile::tempdir().unwrap();
        let scene_dir = dir.path().join("scene");
        let opts = ProceduralOptions {
            width: 64,
            height: 48,
            views: 8,
            test_views: 2,
            ..Default::default()
        };
        let generated = procedural::write(&opts, &scene_dir).unwrap();
        let view = reference_view(&generated).unwrap();
        let [path, unseen] = write_reference_auto(&scene_dir, &dir.path().join("runs")).unwrap();
        let method = gb_inpaint::MethodConfig::load(path.to_str().unwrap()).unwrap();
        let unseen = gb_inpaint::MethodConfig::load(unseen.to_str().unwrap()).unwrap();
        assert_eq!(unseen.name, REFERENCE_AUTO_UNSEEN);
        assert!(unseen.reference.skip_observed && !method.reference.skip_observed);
        assert_eq!(unseen.reference.images, method.reference.images);
        assert_eq!(
            (method.name.as_str(), method.rgb.is_none()),
            (REFERENCE_AUTO, true)
        );
        assert_eq!(method.reference.images.len(), 1);
        let (name, png) = method.reference.images[0].split_once('=').unwrap();
        assert_eq!(name, format!("{}.png", view.name));
        let filled = gb_core::read_rgb(std::path::Path::new(png), None).unwrap();
        let clean = gb_core::read_rgb(
            &scene_dir.join("clean").join(format!("{}.png", view.name)),
            None,
        )
        .unwrap();
        let object = gb_core::read_rgb(
            &scene_dir
                .join("images_1")
                .join(format!("{}.png", view.name)),
            None,
        )
        .unwrap();
        let (mut err_fill, mut err_object) = (0.0f64, 0.0f64);
        for (i, &m) in view.mask.data.iter().enumerate() {
            for c in 0..3 {
                let k = 3 * i + c;
                if m {
                    err_fill += (filled.data[k] - clean.data[k]).powi(2) as f64;
                    err_object += (object.data[k] - clean.data[k]).powi(2) as f64;
                } else {
                    assert_eq!(filled.data[k], object.data[k], "pixel {i} outside the mask");
                }
            }
        }
        assert!(err_fill < 0.5 * err_object, "{err_fill} vs {err_object}");
    }
}
