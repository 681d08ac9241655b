//! Unit normal vectors <-> normal-map images, the DIODE axis conversion, and the masked
//! angular error used as the validation metric.
//!
//! **Convention** (one for the whole project, identical to the NeRF renderer's
//! `gb_nerf::render::normals` and to the procedural scenes'
//! `gb_nerf::scene::procedural::normal_map_image`): normals are unit vectors in CAMERA space
//! with OpenGL axes — x right, y up, z towards the camera (the camera looks along -z). A
//! surface that faces the camera has `n ~ (0, 0, 1)`. The image stores `(n + 1) / 2` per
//! channel (R = x, G = y, B = z), so a fronto-parallel surface is `(0.5, 0.5, 1.0)`.
//!
//! **Invalid pixels** (no depth, sky, a zero-length normal) are the neutral colour
//! [`INVALID_PIXEL`] `(0.5, 0.5, 0.5)`, the encoding of the zero vector, and 0 in the
//! validity mask. When a normal-map image is decoded, a pixel whose decoded vector is shorter
//! than [`MIN_VALID_LENGTH`] is invalid; this tolerates 8-bit quantisation (a quantised unit
//! vector has length `1 +- 0.01`, the quantised neutral colour `128/255` about `0.007`).
//!
//! **DIODE** (`*_normal.npy` of the DIODE normals release): the dataset's devkit
//! (github.com/diode-dataset/diode-devkit, README "File Naming Conventions and Formats")
//! documents only that the array is `(H, W, 3)` and that invalid normals are `(0, 0, 0)`; it
//! does not state the axes. We take them from Metric3D's DIODE loader
//! (github.com/YvanYin/Metric3D, `training/mono/datasets/diode_dataset.py`,
//! `load_norm_label`), which converts DIODE normals into its OpenCV camera frame (x right,
//! y down, z forward, normals facing the camera) with `normal[:, :, 1:] *= -1` — the same
//! conversion it applies to Hypersim's OpenGL camera-space normals — and then flips the
//! normals that face away from the camera. So DIODE's stored axes are OpenGL camera axes
//! (x right, y up, z towards the camera): [`DIODE_AXIS_SIGNS`] is `(+1, +1, +1)` and
//! [`diode_to_camera_gl`] only re-orients normals towards the camera. Should this turn out
//! wrong, [`DIODE_AXIS_SIGNS`] is the one place to change.

/// The image value of an invalid pixel: the encoding of the zero vector.
pub const INVALID_PIXEL: [f32; 3] = [0.5, 0.5, 0.5];

/// A decoded normal-map pixel shorter than this is invalid (see the module docs).
pub const MIN_VALID_LENGTH: f32 = 0.5;

/// Per-axis signs taking a DIODE `*_normal.npy` vector to our OpenGL camera axes (see the
/// module docs for the source): DIODE's axes already are x right, y up, z towards the camera.
pub const DIODE_AXIS_SIGNS: [f32; 3] = [1.0, 1.0, 1.0];

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `n / |n|`, or `None` when `n` is not finite or shorter than `min_len`.
fn normalized(n: [f32; 3], min_len: f32) -> Option<[f32; 3]> {
    let len = dot(n, n).sqrt();
    if !len.is_finite() || len < min_len || len <= 0.0 {
        return None;
    }
    Some(n.map(|v| v / len))
}

/// The image value `(n + 1) / 2` of a normal, normalised first; [`INVALID_PIXEL`] and
/// `false` for a zero-length or non-finite vector.
pub fn encode_normal(n: [f32; 3]) -> ([f32; 3], bool) {
    match normalized(n, 1e-6) {
        Some(u) => (u.map(|v| ((v + 1.0) * 0.5).clamp(0.0, 1.0)), true),
        None => (INVALID_PIXEL, false),
    }
}

/// The unit normal of an image value `p` (`2 p - 1`, normalised), or `None` for an invalid
/// pixel (decoded length below [`MIN_VALID_LENGTH`], or not finite).
pub fn decode_pixel(p: [f32; 3]) -> Option<[f32; 3]> {
    normalized(p.map(|v| 2.0 * v - 1.0), MIN_VALID_LENGTH)
}

/// Encodes camera-space normals `[h * w]` as a normal-map image `[h, w, 3]` and its validity
/// `[h * w]`. A pixel is valid when its normal is non-zero and finite and, if `valid` is
/// given, `valid[i] > 0.5` (e.g. a depth mask); invalid pixels get [`INVALID_PIXEL`].
pub fn normals_to_map(normals: &[[f32; 3]], valid: Option<&[f32]>) -> (Vec<f32>, Vec<f32>) {
    let mut image = Vec::with_capacity(normals.len() * 3);
    let mut validity = Vec::with_capacity(normals.len());
    for (i, n) in normals.iter().enumerate() {
        let masked_out = valid.is_some_and(|m| m.get(i).copied().unwrap_or(0.0) <= 0.5);
        let (px, ok) = if masked_out {
            (INVALID_PIXEL, false)
        } else {
            encode_normal(*n)
        };
        image.extend_from_slice(&px);
        validity.push(if ok { 1.0 } else { 0.0 });
    }
    (image, validity)
}

/// Decodes a normal-map image `[h, w, 3]` to unit normals `[h * w]`; invalid pixels (see
/// [`decode_pixel`]) become the zero vector.
pub fn map_to_normals(image: &[f32]) -> Vec<[f32; 3]> {
    image
        .chunks_exact(3)
        .map(|p| decode_pixel([p[0], p[1], p[2]]).unwrap_or([0.0; 3]))
        .collect()
}

/// Re-encodes a normal-map image (e.g. an 8-bit PNG): valid pixels are renormalised to unit
/// vectors, invalid ones become exactly [`INVALID_PIXEL`]. Returns the image and its
/// validity `[h * w]`.
pub fn canonicalize_map(image: &[f32]) -> (Vec<f32>, Vec<f32>) {
    normals_to_map(&map_to_normals(image), None)
}

/// The direction of the ray through the centre of pixel `(u, v)` in OpenGL camera axes, for
/// a pinhole camera `(fx, fy, cx, cy)` (not normalised; its z is -1).
pub fn pixel_ray_gl(u: usize, v: usize, fx: f32, fy: f32, cx: f32, cy: f32) -> [f32; 3] {
    [
        (u as f32 + 0.5 - cx) / fx,
        -(v as f32 + 0.5 - cy) / fy,
        -1.0,
    ]
}

/// Flips `n` when it faces away from the camera along `ray` (`n . ray > 0`).
pub fn orient_towards_camera(n: [f32; 3], ray: [f32; 3]) -> [f32; 3] {
    if dot(n, ray) > 0.0 {
        n.map(|v| -v)
    } else {
        n
    }
}

/// A DIODE `*_normal.npy` vector seen along `ray` (see [`pixel_ray_gl`]) in our OpenGL camera
/// axes: [`DIODE_AXIS_SIGNS`] applied, then oriented towards the camera (as Metric3D's
/// loader does). The zero vector stays zero.
pub fn diode_to_camera_gl(n: [f32; 3], ray: [f32; 3]) -> [f32; 3] {
    let m = [
        n[0] * DIODE_AXIS_SIGNS[0],
        n[1] * DIODE_AXIS_SIGNS[1],
        n[2] * DIODE_AXIS_SIGNS[2],
    ];
    orient_towards_camera(m, ray)
}

/// The angle in degrees between two unit (or at least non-zero) vectors, in f64.
pub fn angle_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
    let a = a.map(f64::from);
    let b = b.map(f64::from);
    let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let la = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let lb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    if la <= 0.0 || lb <= 0.0 {
        return 90.0;
    }
    (d / (la * lb)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The weighted mean angular error in degrees between two normal-map images `[h, w, 3]`
/// (values in `[0, 1]`, this module's encoding), over the pixels with `weight[i] > 0`
/// (`weight` is `[h * w]`, e.g. hole mask x target validity; it may be soft).
///
/// Pixels whose TARGET is invalid ([`decode_pixel`] gives `None`) are skipped. A PREDICTED
/// pixel that decodes to no direction (e.g. the neutral grey) counts as 90 degrees, the
/// expected error of a random direction. Returns `None` when no pixel has weight (or the
/// buffer sizes do not match `w * h`), so an empty mask is never reported as 0 degrees.
pub fn masked_angular_error_deg(
    pred: &[f32],
    target: &[f32],
    weight: &[f32],
    w: usize,
    h: usize,
) -> Option<f64> {
    let n = w * h;
    if pred.len() != n * 3 || target.len() != n * 3 || weight.len() != n {
        return None;
    }
    let (mut sum, mut wsum) = (0.0f64, 0.0f64);
    for i in 0..n {
        let wi = weight[i];
        if !(wi > 0.0 && wi.is_finite()) {
            continue;
        }
        let Some(t) = decode_pixel([target[3 * i], target[3 * i + 1], target[3 * i + 2]]) else {
            continue;
        };
        let err = match decode_pixel([pred[3 * i], pred[3 * i + 1], pred[3 * i + 2]]) {
            Some(p) => angle_deg(p, t),
            None => 90.0,
        };
        sum += f64::from(wi) * err;
        wsum += f64::from(wi);
    }
    (wsum > 0.0).then(|| sum / wsum)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_neutral_value() {
        let n = [0.3f32, -0.4, 0.866];
        let (px, ok) = encode_normal(n);
        assert!(ok);
        let back = decode_pixel(px).unwrap();
        assert!(angle_deg(back, n) < 1e-3);
        assert_eq!(encode_normal([0.0; 3]), (INVALID_PIXEL, false));
        assert_eq!(decode_pixel(INVALID_PIXEL), None);
        // the 8-bit neutral grey is invalid too
        assert_eq!(decode_pixel([128.0 / 255.0; 3]), None);
        // facing the camera
        assert_eq!(encode_normal([0.0, 0.0, 1.0]).0, [0.5, 0.5, 1.0]);
    }

    #[test]
    fn masked_error_weights_and_skips() {
        let up = encode_normal([0.0, 1.0, 0.0]).0;
        let front = encode_normal([0.0, 0.0, 1.0]).0;
        let pred: Vec<f32> = [front, front, up].concat();
        let target: Vec<f32> = [front, up, INVALID_PIXEL].concat();
        // pixel 0: 0 deg, pixel 1: 90 deg, pixel 2: target invalid -> skipped
        let e = masked_angular_error_deg(&pred, &target, &[1.0, 1.0, 1.0], 3, 1).unwrap();
        assert!((e - 45.0).abs() < 1e-4, "{e}");
        let e = masked_angular_error_deg(&pred, &target, &[1.0, 0.0, 1.0], 3, 1).unwrap();
        assert!(e.abs() < 1e-4, "{e}");
        assert_eq!(
            masked_angular_error_deg(&pred, &target, &[0.0; 3], 3, 1),
            None
        );
        assert_eq!(
            masked_angular_error_deg(&pred, &target, &[1.0; 2], 3, 1),
            None
        );
    }

    #[test]
    fn diode_normals_are_oriented_towards_the_camera() {
        let ray = pixel_ray_gl(10, 10, 50.0, 50.0, 10.5, 10.5); // (0, 0, -1)
        assert_eq!(diode_to_camera_gl([0.0, 0.0, -1.0], ray), [0.0, 0.0, 1.0]);
        assert_eq!(diode_to_camera_gl([0.0, 0.6, 0.8], ray), [0.0, 0.6, 0.8]);
    }
}
