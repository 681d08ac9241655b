//! Square crops: sizes, exact constant normal fields, validity erosion.

use gb_finetune::crop::{center_square_resize, crop_and_resize, random_square_crop};
use gb_finetune::normal_map::{decode_pixel, encode_normal, INVALID_PIXEL};
use gb_finetune::sample::PairSample;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn sample(w: usize, h: usize, n: [f32; 3]) -> PairSample {
    let px = encode_normal(n).0;
    PairSample {
        name: "s".into(),
        width: w,
        height: h,
        rgb: (0..w * h)
            .flat_map(|i| [(i % w) as f32 / w as f32, (i / w) as f32 / h as f32, 0.5])
            .collect(),
        normal: Some(px.repeat(w * h)),
        normal_valid: vec![1.0; w * h],
        caption: "c".into(),
    }
}

#[test]
fn constant_normals_survive_crop_and_resize() {
    let n = {
        let v = [0.3f32, -0.5, 0.8];
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / l)
    };
    let s = sample(37, 23, n);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    for size in [8usize, 16, 64] {
        for _ in 0..5 {
            let c = random_square_crop(&s, size, &mut rng);
            assert_eq!((c.width, c.height), (size, size));
            assert_eq!(c.rgb.len(), size * size * 3);
            assert_eq!(c.normal_valid, vec![1.0; size * size]);
            assert_eq!(c.caption, "c");
            let nm = c.normal.unwrap();
            assert_eq!(nm.len(), size * size * 3);
            for px in nm.chunks(3) {
                let d = decode_pixel([px[0], px[1], px[2]]).unwrap();
                for k in 0..3 {
                    assert!((d[k] - n[k]).abs() < 1e-6, "{d:?} vs {n:?}");
                }
            }
        }
        let c = center_square_resize(&s, size);
        assert_eq!((c.width, c.height), (size, size));
        assert_eq!(c, center_square_resize(&s, size), "deterministic");
    }
}

#[test]
fn crops_stay_inside_and_resample_vectors() {
    let s = sample(40, 30, [0.0, 0.0, 1.0]);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..50 {
        let c = random_square_crop(&s, 12, &mut rng);
        // RGB x coordinate ramp stays inside [0, 1) and the crop spans >= 60% of the short side
        let xs: Vec<f32> = c.rgb.chunks(3).map(|p| p[0]).collect();
        let span = xs.iter().cloned().fold(f32::MIN, f32::max)
            - xs.iter().cloned().fold(f32::MAX, f32::min);
        assert!(span >= 0.6 * 30.0 / 40.0 - 2.0 / 40.0, "{span}");
        assert!(span <= 30.0 / 40.0, "{span}");
    }
    // identity crop: same pixels back
    let c = crop_and_resize(&s, 5, 0, 30, 30);
    for y in 0..30 {
        for x in 0..30 {
            let a = &c.rgb[(y * 30 + x) * 3..][..3];
            let b = &s.rgb[(y * 40 + x + 5) * 3..][..3];
            assert_eq!(a, b);
        }
    }
    // a 90-degree edge of normals: the resampled vectors are unit length and in between
    let (w, h) = (8, 8);
    let left = encode_normal([1.0, 0.0, 0.0]).0;
    let right = encode_normal([0.0, 0.0, 1.0]).0;
    let mut e = sample(w, h, [0.0, 0.0, 1.0]);
    e.normal = Some(
        (0..w * h)
            .flat_map(|i| if i % w < 4 { left } else { right })
            .collect(),
    );
    let c = crop_and_resize(&e, 0, 0, 8, 5);
    for px in c.normal.unwrap().chunks(3) {
        let v = [2.0 * px[0] - 1.0, 2.0 * px[1] - 1.0, 2.0 * px[2] - 1.0];
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-5, "{v:?}");
    }
}

#[test]
fn invalid_pixels_only_shrink_validity() {
    let (w, h) = (20, 20);
    let mut s = sample(w, h, [0.0, 0.6, 0.8]);
    // invalid block in the middle
    for y in 8..12 {
        for x in 8..12 {
            s.normal_valid[y * w + x] = 0.0;
            s.normal.as_mut().unwrap()[(y * w + x) * 3..][..3].copy_from_slice(&INVALID_PIXEL);
        }
    }
    let c = crop_and_resize(&s, 0, 0, 20, 10);
    let nm = c.normal.as_ref().unwrap();
    let invalid = c.normal_valid.iter().filter(|&&v| v == 0.0).count();
    // the 4x4 block at half resolution touches at least 2x2 output pixels, never the corners
    assert!(invalid >= 4, "{invalid}");
    assert_eq!(c.normal_valid[0], 1.0);
    for (i, &v) in c.normal_valid.iter().enumerate() {
        let px = &nm[i * 3..][..3];
        if v == 0.0 {
            assert_eq!(px, &INVALID_PIXEL);
        } else {
            let d = decode_pixel([px[0], px[1], px[2]]).unwrap();
            assert!(
                (d[1] - 0.6).abs() < 1e-5 && (d[2] - 0.8).abs() < 1e-5,
                "{d:?}"
            );
        }
    }
    // no normal map: validity is still cropped
    s.normal = None;
    let c = random_square_crop(&s, 7, &mut ChaCha8Rng::seed_from_u64(0));
    assert!(c.normal.is_none());
    assert_eq!(c.normal_valid.len(), 49);
}
