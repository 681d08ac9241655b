//! Resampling weights shared by the NeRF crop renderer and the distillation crop.

/// Row weights of a 1-D bilinear resampling from `src` to `dst` samples with half-pixel
/// centres (PyTorch's `align_corners=False`, no antialiasing): `[dst, src]`, row-major.
pub fn bilinear_matrix(src: usize, dst: usize) -> Vec<f32> {
    let mut m = vec![0.0f32; dst * src];
    let scale = src as f32 / dst as f32;
    for o in 0..dst {
        let x = ((o as f32 + 0.5) * scale - 0.5).max(0.0);
        let i0 = (x.floor() as usize).min(src - 1);
        let i1 = (i0 + 1).min(src - 1);
        let l = x - i0 as f32;
        m[o * src + i0] += 1.0 - l;
        m[o * src + i1] += l;
    }
    m
}
