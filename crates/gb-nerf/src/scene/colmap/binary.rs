//! COLMAP's binary model: `cameras.bin`, `images.bin`, `points3D.bin` (little endian, as
//! COLMAP's `read_write_model.py` reads them).

use std::path::Path;

use super::{bad, model_id, model_params, Camera, Image, Model, Point3d};
use crate::scene::SceneError;

/// A little-endian reader over one file's bytes; errors name the file and the offset.
struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], SceneError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(bad(
                self.path,
                format!("truncated at byte {} reading {what}", self.at),
            ));
        };
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    /// The next `N` bytes as an array.
    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], SceneError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    fn u64(&mut self, what: &str) -> Result<u64, SceneError> {
        self.array(what).map(u64::from_le_bytes)
    }

    fn i64(&mut self, what: &str) -> Result<i64, SceneError> {
        self.array(what).map(i64::from_le_bytes)
    }

    fn i32(&mut self, what: &str) -> Result<i32, SceneError> {
        self.array(what).map(i32::from_le_bytes)
    }

    fn f64(&mut self, what: &str) -> Result<f64, SceneError> {
        self.array(what).map(f64::from_le_bytes)
    }

    fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N], SceneError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    /// A count that must fit in what is left of the file at `min_size` bytes per item.
    fn count(&mut self, what: &str, min_size: usize) -> Result<usize, SceneError> {
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.saturating_mul(min_size as u64) > left {
            return Err(bad(
                self.path,
                format!(
                    "{what} = {n} at byte {} does not fit in the file",
                    self.at - 8
                ),
            ));
        }
        Ok(n as usize)
    }

    fn name(&mut self) -> Result<String, SceneError> {
        let rest = &self.bytes[self.at..];
        let len = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            bad(
                self.path,
                format!("unterminated image name at byte {}", self.at),
            )
        })?;
        let name = String::from_utf8_lossy(&rest[..len]).into_owned();
        self.at += len + 1;
        Ok(name)
    }
}

fn file(dir: &Path, name: &str) -> Result<(std::path::PathBuf, Vec<u8>), SceneError> {
    let path = dir.join(name);
    let bytes = std::fs::read(&path).map_err(|e| bad(&path, e.to_string()))?;
    Ok((path, bytes))
}

/// Reads the three binary files of `dir`.
pub(super) fn read(dir: &Path) -> Result<Model, SceneError> {
    let mut model = Model::default();
    let (path, bytes) = file(dir, "cameras.bin")?;
    let mut r = Reader {
        path: &path,
        bytes: &bytes,
        at: 0,
    };
    for _ in 0..r.count("number of cameras", 24)? {
        let id = r.i32("camera id")?;
        let model_id = r.i32("camera model")?;
        let (name, n) = model_params(model_id).ok_or_else(|| {
            bad(
                &path,
                format!("camera {id}: unknown camera model id {model_id}"),
            )
        })?;
        let (width, height) = (r.u64("width")?, r.u64("height")?);
        let params = (0..n)
            .map(|_| r.f64("parameter"))
            .collect::<Result<_, _>>()?;
        let camera = Camera {
            model: name.to_string(),
            width,
            height,
            params,
        };
        model.cameras.insert(id, camera);
    }
    let (path, bytes) = file(dir, "images.bin")?;
    let mut r = Reader {
        path: &path,
        bytes: &bytes,
        at: 0,
    };
    for _ in 0..r.count("number of images", 69)? {
        let id = r.i32("image id")?;
        let qvec = r.f64s::<4>("qvec")?;
        let tvec = r.f64s::<3>("tvec")?;
        let camera_id = r.i32("camera id")?;
        let name = r.name()?;
        let n = r.count("number of keypoints", 24)?;
        let mut points2d = Vec::with_capacity(n);
        for _ in 0..n {
            let xy = r.f64s::<2>("keypoint")?;
            points2d.push((xy, r.i64("keypoint's point id")?));
        }
        let image = Image {
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        };
        model.images.insert(id, image);
    }
    let (path, bytes) = file(dir, "points3D.bin")?;
    let mut r = Reader {
        path: &path,
        bytes: &bytes,
        at: 0,
    };
    for _ in 0..r.count("number of points", 43)? {
        let id = r.u64("point id")?;
        let xyz = r.f64s::<3>("xyz")?;
        let rgb = r.array::<3>("rgb")?;
        let error = r.f64("error")?;
        let n = r.count("track length", 8)?;
        let mut track = Vec::with_capacity(n);
        for _ in 0..n {
            let image = r.i32("track image id")?;
            track.push((image, r.i32("track keypoint index")? as u32));
        }
        let point = Point3d {
            xyz,
            rgb,
            error,
            track,
        };
        model.points.insert(id, point);
    }
    Ok(model)
}

/// Writes `model` as the three binary files in `dir` (created); an unknown camera model name
/// is an error.
pub fn write_binary(model: &Model, dir: &Path) -> Result<(), SceneError> {
    std::fs::create_dir_all(dir).map_err(|e| bad(dir, e.to_string()))?;
    let mut cams = (model.cameras.len() as u64).to_le_bytes().to_vec();
    for (id, c) in &model.cameras {
        let (model_id, n) = model_id(&c.model).ok_or_else(|| {
            bad(
                &dir.join("cameras.bin"),
                format!("unknown camera model {}", c.model),
            )
        })?;
        if n != c.params.len() {
            return Err(bad(
                &dir.join("cameras.bin"),
                format!(
                    "camera {id}: {} takes {n} parameters, got {}",
                    c.model,
                    c.params.len()
                ),
            ));
        }
        cams.extend(id.to_le_bytes());
        cams.extend(model_id.to_le_bytes());
        cams.extend(c.width.to_le_bytes());
        cams.extend(c.height.to_le_bytes());
        c.params.iter().for_each(|p| cams.extend(p.to_le_bytes()));
    }
    let mut ims = (model.images.len() as u64).to_le_bytes().to_vec();
    for (id, im) in &model.images {
        ims.extend(id.to_le_bytes());
        im.qvec
            .iter()
            .chain(&im.tvec)
            .for_each(|v| ims.extend(v.to_le_bytes()));
        ims.extend(im.camera_id.to_le_bytes());
        ims.extend(im.name.as_bytes());
        ims.push(0);
        ims.extend((im.points2d.len() as u64).to_le_bytes());
        for ([x, y], p) in &im.points2d {
            ims.extend(x.to_le_bytes());
            ims.extend(y.to_le_bytes());
            ims.extend(p.to_le_bytes());
        }
    }
    let mut pts = (model.points.len() as u64).to_le_bytes().to_vec();
    for (id, p) in &model.points {
        pts.extend(id.to_le_bytes());
        p.xyz.iter().for_each(|v| pts.extend(v.to_le_bytes()));
        pts.extend(p.rgb);
        pts.extend(p.error.to_le_bytes());
        pts.extend((p.track.len() as u64).to_le_bytes());
        for (i, k) in &p.track {
            pts.extend(i.to_le_bytes());
            pts.extend((*k as i32).to_le_bytes());
        }
    }
    for (name, bytes) in [
        ("cameras.bin", cams),
        ("images.bin", ims),
        ("points3D.bin", pts),
    ] {
        let path = dir.join(name);
        gb_core::write_atomic(&path, &bytes).map_err(|e| bad(&path, e.to_string()))?;
    }
    Ok(())
}
