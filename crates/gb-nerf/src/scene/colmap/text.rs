//! COLMAP's text model: `cameras.txt`, `images.txt` (two lines per image), `points3D.txt`.

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use super::{bad, model_id, Camera, Image, Model, Point3d};
use crate::scene::SceneError;

/// The non-comment lines of `path` with their 1-based numbers (blank lines kept: an image's
/// second line may be empty).
fn lines(path: &Path) -> Result<Vec<(usize, String)>, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, e.to_string()))?;
    Ok(text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .map(|(i, l)| (i + 1, l.trim().to_string()))
        .collect())
}

/// The fields of one line, parsed on demand with errors naming the file and line.
struct Fields<'a> {
    path: &'a Path,
    line: usize,
    items: std::str::SplitWhitespace<'a>,
}

impl<'a> Fields<'a> {
    fn new(path: &'a Path, line: usize, text: &'a str) -> Self {
        Self {
            path,
            line,
            items: text.split_whitespace(),
        }
    }

    fn next<T: FromStr>(&mut self, what: &str) -> Result<T, SceneError> {
        let raw = self
            .items
            .next()
            .ok_or_else(|| bad(self.path, format!("line {}: missing {what}", self.line)))?;
        raw.parse().map_err(|_| {
            bad(
                self.path,
                format!("line {}: {what} '{raw}' is not a number", self.line),
            )
        })
    }

    fn rest<T: FromStr>(&mut self, what: &str) -> Result<Vec<T>, SceneError> {
        let mut out = Vec::new();
        for raw in self.items.by_ref() {
            out.push(raw.parse().map_err(|_| {
                bad(
                    self.path,
                    format!("line {}: {what} '{raw}' is not a number", self.line),
                )
            })?);
        }
        Ok(out)
    }
}

/// Reads the three text files of `dir`.
pub(super) fn read(dir: &Path) -> Result<Model, SceneError> {
    let mut model = Model::default();
    let path = dir.join("cameras.txt");
    for (n, l) in lines(&path)?.iter().filter(|(_, l)| !l.is_empty()) {
        let mut f = Fields::new(&path, *n, l);
        let id: i32 = f.next("camera id")?;
        let name: String = f.next("camera model")?;
        let (_, count) = model_id(&name)
            .ok_or_else(|| bad(&path, format!("line {n}: unknown camera model '{name}'")))?;
        let (width, height) = (f.next("width")?, f.next("height")?);
        let params: Vec<f64> = f.rest("parameter")?;
        if params.len() != count {
            return Err(bad(
                &path,
                format!(
                    "line {n}: {name} takes {count} parameters, got {}",
                    params.len()
                ),
            ));
        }
        model.cameras.insert(
            id,
            Camera {
                model: name,
                width,
                height,
                params,
            },
        );
    }
    let path = dir.join("images.txt");
    let all = lines(&path)?;
    let mut rows = all.iter();
    while let Some((n, l)) = rows.next() {
        if l.is_empty() {
            continue;
        }
        let mut f = Fields::new(&path, *n, l);
        let id: i32 = f.next("image id")?;
        let qvec = [f.next("qw")?, f.next("qx")?, f.next("qy")?, f.next("qz")?];
        let tvec = [f.next("tx")?, f.next("ty")?, f.next("tz")?];
        let camera_id = f.next("camera id")?;
        let name: String = f.next("name")?;
        let (m, points) = rows
            .next()
            .ok_or_else(|| bad(&path, format!("line {n}: image {id} has no keypoint line")))?;
        let values: Vec<f64> = Fields::new(&path, *m, points).rest("keypoint value")?;
        if !values.len().is_multiple_of(3) {
            return Err(bad(
                &path,
                format!("line {m}: keypoints come as X Y POINT3D_ID triples"),
            ));
        }
        let points2d = values
            .chunks(3)
            .map(|c| ([c[0], c[1]], c[2] as i64))
            .collect();
        model.images.insert(
            id,
            Image {
                qvec,
                tvec,
                camera_id,
                name,
                points2d,
            },
        );
    }
    let path = dir.join("points3D.txt");
    for (n, l) in lines(&path)?.iter().filter(|(_, l)| !l.is_empty()) {
        let mut f = Fields::new(&path, *n, l);
        let id: u64 = f.next("point id")?;
        let xyz = [f.next("x")?, f.next("y")?, f.next("z")?];
        let rgb = [f.next("r")?, f.next("g")?, f.next("b")?];
        let error = f.next("error")?;
        let track: Vec<i64> = f.rest("track value")?;
        if !track.len().is_multiple_of(2) {
            return Err(bad(
                &path,
                format!("line {n}: the track comes as IMAGE_ID POINT2D_IDX pairs"),
            ));
        }
        let track = track
            .chunks(2)
            .map(|c| (c[0] as i32, c[1] as u32))
            .collect();
        model.points.insert(
            id,
            Point3d {
                xyz,
                rgb,
                error,
                track,
            },
        );
    }
    Ok(model)
}

/// Writes `model` as the three text files in `dir` (created), with full `f64` precision.
pub fn write_text(model: &Model, dir: &Path) -> Result<(), SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| bad(dir, e.to_string()))?;
    let mut cams = String::from("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    for (id, c) in &model.cameras {
        let _ = write!(cams, "{id} {} {} {}", c.model, c.width, c.height);
        c.params.iter().for_each(|p| {
            let _ = write!(cams, " {p:?}");
        });
        cams.push('\n');
    }
    let mut ims = String::from(
        "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n# POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    for (id, im) in &model.images {
        let [qw, qx, qy, qz] = im.qvec;
        let [tx, ty, tz] = im.tvec;
        let _ = writeln!(
            ims,
            "{id} {qw:?} {qx:?} {qy:?} {qz:?} {tx:?} {ty:?} {tz:?} {} {}",
            im.camera_id, im.name
        );
        let kp: Vec<String> = im
            .points2d
            .iter()
            .map(|([x, y], p)| format!("{x:?} {y:?} {p}"))
            .collect();
        ims.push_str(&kp.join(" "));
        ims.push('\n');
    }
    let mut pts =
        String::from("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    for (id, p) in &model.points {
        let [x, y, z] = p.xyz;
        let [r, g, b] = p.rgb;
        let _ = write!(pts, "{id} {x:?} {y:?} {z:?} {r} {g} {b} {:?}", p.error);
        p.track.iter().for_each(|(i, k)| {
            let _ = write!(pts, " {i} {k}");
        });
        pts.push('\n');
    }
    for (name, text) in [
        ("cameras.txt", cams),
        ("images.txt", ims),
        ("points3D.txt", pts),
    ] {
        let path = dir.join(name);
        gb_core::write_atomic(&path, text.as_bytes()).map_err(|e| bad(&path, e.to_string()))?;
    }
    Ok(())
}
