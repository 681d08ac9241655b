//! Row lookups with a fast backward pass on every backend.
//!
//! `Tensor::select(0, rows)` is the obvious row lookup, but under autodiff its backward is
//! `select_assign`, which the cubecl backends (wgpu) run with one thread per *column*, each
//! looping over every index: for a hash table of 2 features that is 2 threads for millions
//! of rows. A `gather` along dim 0 with the indices expanded over the columns computes the
//! same values, and its backward is a scatter-add with one thread per element.
//!
//! flex keeps `select`: there the gather needs its indices expanded over the columns and
//! copied (`rows * columns` integers, about 160 MB for a `fast` batch of the hash grid), while
//! `select`'s backward adds whole rows: the same values and gradients, in less time. ndarray
//! keeps the gather: its `select` backward walks a dynamic-rank view per index.

use burn::tensor::{DType, Device, Int, Tensor, TensorData};

/// Rows `rows` of `values` (`[N, C...]`), as `[rows.len(), C...]`: the values of
/// `values.select(0, rows)`, through a `gather` whose backward is parallel, or on flex
/// `select` itself (module docs). Repeated rows are allowed; their gradients add up.
pub fn gather_rows<const D: usize>(values: Tensor<D>, rows: Tensor<1, Int>) -> Tensor<D> {
    if is_flex(&values.device()) {
        return values.select(0, rows);
    }
    let k = rows.dims()[0];
    let mut index_shape = [1usize; D];
    index_shape[0] = k;
    let mut out_shape = values.dims();
    out_shape[0] = k;
    let index = rows.reshape(index_shape).expand(out_shape);
    values.gather(0, index)
}

/// The row indices `rows` as a tensor on `device`, for [`gather_rows`]: `i64` on flex, which
/// reads such indices in place (its default integer type would cost a converted copy of every
/// index), the device's default integer type elsewhere.
pub fn row_indices(rows: Vec<i64>, device: &Device) -> Tensor<1, Int> {
    let n = rows.len();
    let data = TensorData::new(rows, [n]);
    if is_flex(device) {
        Tensor::from_data(data, (device, DType::I64))
    } else {
        Tensor::from_data(data, device)
    }
}

/// Whether `device` is flex, plain or autodiff (device equality ignores autodiff).
fn is_flex(device: &Device) -> bool {
    *device == Device::flex()
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Distribution, TensorData};

    use super::*;
    use crate::backend::test_backends;

    /// Values and gradients of `gather_rows` against `select`, with repeated rows (on flex
    /// `gather_rows` is `select` itself: the comparison bites on ndarray and wgpu).
    #[test]
    fn gather_rows_matches_select_in_values_and_gradients() {
        let rows: Vec<i64> = vec![3, 0, 3, 7, 1, 1, 1, 6, 2, 3, 0];
        for kind in test_backends() {
            let device = kind.autodiff_device();
            let table = Tensor::<2>::random([8, 5], Distribution::Normal(0.0, 1.0), &device);
            let weights =
                Tensor::<2>::random([rows.len(), 5], Distribution::Normal(0.0, 1.0), &device);
            let index = || {
                Tensor::<1, Int>::from_data(TensorData::new(rows.clone(), [rows.len()]), &device)
            };
            let run = |gathered: bool| {
                let t = table.clone().detach().require_grad();
                let out = if gathered {
                    gather_rows(t.clone(), index())
                } else {
                    t.clone().select(0, index())
                };
                let grads = (out.clone() * weights.clone()).sum().backward();
                let grad = t.grad(&grads).expect("table gradient");
                (
                    out.into_data().try_to_vec::<f32>().unwrap(),
                    grad.into_data().try_to_vec::<f32>().unwrap(),
                )
            };
            let (v_gather, g_gather) = run(true);
            let (v_select, g_select) = run(false);
            assert_eq!(v_gather.len(), rows.len() * 5, "{kind}");
            for (a, b) in v_gather.iter().zip(&v_select) {
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1.0),
                    "{kind}: {a} vs {b}"
                );
            }
            assert_eq!(g_gather.len(), 40, "{kind}");
            for (a, b) in g_gather.iter().zip(&g_select) {
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1.0),
                    "{kind}: {a} vs {b}"
                );
            }
            // row 4 and 5 are never looked up: zero gradient; row 1 three times
            assert!(g_gather[4 * 5..6 * 5].iter().all(|&g| g == 0.0), "{kind}");
            assert!(g_gather[5..10].iter().any(|&g| g != 0.0), "{kind}");
        }
    }

    /// `row_indices` gives flex `i64` indices (read in place) and every backend the same rows.
    #[test]
    fn row_indices_are_i64_on_flex_and_look_up_the_same_rows() {
        let rows: Vec<i64> = vec![2, 0, 2, 3];
        for kind in test_backends() {
            let device = kind.device();
            let index = row_indices(rows.clone(), &device);
            if kind == crate::BackendKind::Flex {
                assert_eq!(index.dtype(), DType::I64, "{kind}");
            }
            let values = Tensor::<2>::from_data(
                TensorData::new((0..8).map(|v| v as f32).collect::<Vec<_>>(), [4, 2]),
                &device,
            );
            let out = gather_rows(values, index)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            assert_eq!(out, [4.0, 5.0, 0.0, 1.0, 4.0, 5.0, 6.0, 7.0], "{kind}");
        }
    }

    #[test]
    fn gather_rows_keeps_trailing_dimensions() {
        let device = crate::BackendKind::Flex.device();
        let values = Tensor::<3>::from_data(
            TensorData::new((0..24).map(|v| v as f32).collect::<Vec<_>>(), [4, 3, 2]),
            &device,
        );
        let rows = Tensor::<1, Int>::from_data(TensorData::new(vec![2i64, 2, 0], [3]), &device);
        let out = gather_rows(values, rows);
        assert_eq!(out.dims(), [3, 3, 2]);
        let v = out.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(&v[..6], &[12.0, 13.0, 14.0, 15.0, 16.0, 17.0]);
        assert_eq!(&v[6..12], &v[..6]);
        assert_eq!(&v[12..], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    }
}
