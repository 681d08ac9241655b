//! COLMAP sparse models (`gb_nerf::scene::colmap::Model::read`), binary and text: a valid
//! model written by our writers must read back equal; a model with one of its three files
//! mutated, or replaced by arbitrary bytes, gives `Ok` or `Err`, never a panic.

use std::collections::BTreeMap;
use std::path::Path;

use gb_nerf::scene::colmap::{write_binary, write_text, Camera, Image, Model, Point3d};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::mutate::{any_bytes, mutated, mutations, Mutation};
use super::{ensure, Harness};

/// Tokens for mutating the text files.
const TEXT_TOKENS: &[&str] = &[
    "PINHOLE",
    "SIMPLE_RADIAL",
    "OPENCV",
    "UNKNOWN_MODEL",
    "-1",
    "nan",
    "inf",
    "1e308",
    "18446744073709551615",
    "#",
    "\n",
    " ",
];

/// A small valid model: one camera, up to three images with keypoints, up to four points.
fn valid() -> impl Strategy<Value = Model> {
    let camera = (
        1u64..4000,
        1u64..4000,
        proptest::collection::vec(-1e4f64..1e4, 4),
    )
        .prop_map(|(width, height, params)| Camera {
            model: "PINHOLE".into(),
            width,
            height,
            params,
        });
    let keypoint = (-1e4f64..1e4, -1e4f64..1e4, -1i64..4).prop_map(|(x, y, id)| ([x, y], id));
    let image = (
        proptest::array::uniform4(-1.0f64..1.0),
        proptest::array::uniform3(-100.0f64..100.0),
        "[a-z]{1,8}\\.(png|jpg)",
        proptest::collection::vec(keypoint, 0..5),
    )
        .prop_map(|(qvec, tvec, name, points2d)| Image {
            qvec,
            tvec,
            camera_id: 1,
            name,
            points2d,
        });
    let point = (
        proptest::array::uniform3(-100.0f64..100.0),
        proptest::array::uniform3(any::<u8>()),
        0.0f64..10.0,
        proptest::collection::vec((1i32..4, 0u32..5), 0..4),
    )
        .prop_map(|(xyz, rgb, error, track)| Point3d {
            xyz,
            rgb,
            error,
            track,
        });
    (
        camera,
        proptest::collection::vec(image, 1..4),
        proptest::collection::vec(point, 0..5),
    )
        .prop_map(|(camera, images, points)| Model {
            cameras: BTreeMap::from([(1, camera)]),
            images: images
                .into_iter()
                .enumerate()
                .map(|(i, im)| (i as i32 + 1, im))
                .collect(),
            points: points
                .into_iter()
                .enumerate()
                .map(|(i, p)| (i as u64, p))
                .collect(),
        })
}

#[derive(Debug, Clone)]
enum Case {
    /// A valid model with mutations of its file `file` (0: cameras, 1: images, 2: points).
    Valid(Model, usize, Vec<Mutation>),
    /// A valid model with file `file` replaced by arbitrary bytes.
    Raw(Model, usize, Vec<u8>),
}

fn case() -> impl Strategy<Value = Case> {
    prop_oneof![
        2 => valid().prop_map(|m| Case::Valid(m, 0, Vec::new())),
        5 => (valid(), 0usize..3, mutations(TEXT_TOKENS)).prop_map(|(m, f, x)| Case::Valid(m, f, x)),
        1 => (valid(), 0usize..3, any_bytes(256)).prop_map(|(m, f, b)| Case::Raw(m, f, b)),
    ]
}

/// Writes the case's model into `dir` in one form, corrupts one file, reads it back.
fn check(case: Case, dir: &Path, binary: bool) -> Result<(), TestCaseError> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).expect("scratch model folder");
    }
    let (model, file) = match &case {
        Case::Valid(m, f, _) | Case::Raw(m, f, _) => (m, *f),
    };
    if binary {
        write_binary(model, dir).expect("write_binary");
    } else {
        write_text(model, dir).expect("write_text");
    }
    let ext = if binary { "bin" } else { "txt" };
    let path = dir.join(format!("{}.{ext}", ["cameras", "images", "points3D"][file]));
    match &case {
        Case::Valid(_, _, m) if m.is_empty() => {}
        Case::Valid(_, _, m) => {
            let bytes = std::fs::read(&path).expect("scratch model file");
            std::fs::write(&path, mutated(&bytes, m)).expect("scratch model file");
        }
        Case::Raw(_, _, b) => std::fs::write(&path, b).expect("scratch model file"),
    }
    let got = Model::read(dir);
    if let Case::Valid(m, _, x) = &case {
        if x.is_empty() {
            let back =
                got.map_err(|e| TestCaseError::fail(format!("valid model rejected: {e}")))?;
            ensure(back == *m, || format!("read back {back:?}, wrote {m:?}"))?;
        }
    }
    Ok(())
}

/// The binary model never panics; a valid one reads back equal.
pub fn binary(h: &mut Harness) -> Result<(), String> {
    h.check(case(), |case, scratch| {
        check(case, &scratch.join("colmap-bin"), true)
    })
}

/// The text model never panics; a valid one reads back equal.
pub fn text(h: &mut Harness) -> Result<(), String> {
    h.check(case(), |case, scratch| {
        check(case, &scratch.join("colmap-txt"), false)
    })
}
