//! The triangular factor of a shaped input's lags projected off a model's other columns, beside the
//! output's residual, for each value of a shape scan: R of [Z − Q(QᵀZ) | y] by
//! [`crate::linalg::projected_qr::projected_r`], with Z gathered here from the shaped series through
//! fixed sample indices (column c of row t is `series[index[t, c]]`), not in Python.
//!
//! A scan (a dead zone's width, a saturation's levels, an exponent) asks for it at every value it
//! tries, Q (the model's other columns, orthonormal) and y fixed and only the shaped series new: a
//! scan's grid of values is one call. Each value's R is the one `projected_r` gives for its Z, to
//! the bit. A value whose gathered lags are not all finite is flagged and left unfactored (the
//! caller refits it on the rows without them).

use std::sync::atomic::AtomicBool;

use crate::error::{ArxError, Result};
use crate::linalg::lagged_qr::Source;
use crate::linalg::projected_qr::{projected_r, ProjectedFactor};

/// R of [Z − Q(QᵀZ) | y] and the lags' sums of squares for each shaped series (row v of `series`,
/// `len` samples each, `index` rows × k row-major); None for a value whose lags are not all finite.
///
/// # Errors
/// `ShapeMismatch` when Q, y and the index have different numbers of rows, the series' length is
/// not a multiple of `len`, or an index reaches beyond a series; `Interrupted` when `cancel` is set.
#[allow(clippy::too_many_arguments)]
pub fn shaped_projected_r(
    q: &Source<'_>,
    y: &[f64],
    series: &[f64],
    len: usize,
    index: &[i64],
    k: usize,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Vec<Option<ProjectedFactor>>> {
    let n = y.len();
    let mismatch =
        |what: &str, expected: usize, got: usize| ArxError::ShapeMismatch { what: what.into(), expected, got };
    if index.len() != n * k {
        return Err(mismatch("the lag indices", n * k, index.len()));
    }
    if len == 0 || !series.len().is_multiple_of(len) {
        return Err(mismatch("the shaped series' samples", len, series.len()));
    }
    if let Some(&far) = index.iter().find(|&&i| !(0..len as i64).contains(&i)) {
        return Err(mismatch("a lag index within the series", len, far.unsigned_abs() as usize));
    }
    let mut z = vec![0.0; n * k];
    series
        .chunks_exact(len)
        .map(|s| {
            z.iter_mut().zip(index).for_each(|(v, &i)| *v = s[i as usize]);
            if !z.iter().all(|v| v.is_finite()) {
                return Ok(None);
            }
            let lags = Source { values: &z, rows: n, columns: k, row_stride: k, col_stride: 1 };
            projected_r(q, y, &lags, parallel, cancel).map(Some)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::qr::BLOCK_ROWS;

    fn source(values: &[f64], rows: usize, columns: usize) -> Source<'_> {
        Source { values, rows, columns, row_stride: columns, col_stride: 1 }
    }

    #[test]
    fn each_value_is_the_projected_factor_of_its_gathered_lags() {
        let n = 2 * BLOCK_ROWS + 31;
        let len = n + 2;
        let q: Vec<f64> = vec![1.0 / (n as f64).sqrt(); n];
        let y: Vec<f64> = (0..n).map(|t| (t as f64 * 0.11).cos()).collect();
        let mean = y.iter().sum::<f64>() / n as f64;
        let y: Vec<f64> = y.iter().map(|v| v - mean).collect();
        let series: Vec<f64> = (0..2 * len).map(|t| ((t % len) as f64 * 0.37).sin() * (1 + t / len) as f64).collect();
        let index: Vec<i64> = (0..n as i64).flat_map(|t| [t + 1, t]).collect();
        let never = AtomicBool::new(false);
        let out = shaped_projected_r(&source(&q, n, 1), &y, &series, len, &index, 2, false, &never).unwrap();
        assert_eq!(out.len(), 2);
        for (v, got) in out.iter().enumerate() {
            let z: Vec<f64> = index.iter().map(|&i| series[v * len + i as usize]).collect();
            let want = projected_r(&source(&q, n, 1), &y, &source(&z, n, 2), false, &never).unwrap();
            let got = got.as_ref().unwrap();
            assert_eq!((&got.r, &got.squares), (&want.r, &want.squares));
        }
    }

    #[test]
    fn a_value_with_a_missing_lag_is_flagged_and_an_index_beyond_the_series_refused() {
        let never = AtomicBool::new(false);
        let (q, y) = (vec![0.5; 4], vec![1.0, -1.0, 1.0, -1.0]);
        let series = [1.0, f64::NAN, 2.0, 3.0, 4.0];
        let out = shaped_projected_r(&source(&q, 4, 1), &y, &series, 5, &[0, 1, 2, 3], 1, false, &never).unwrap();
        assert!(out[0].is_none());
        let err = shaped_projected_r(&source(&q, 4, 1), &y, &series, 5, &[0, 1, 2, 5], 1, false, &never).unwrap_err();
        assert!(matches!(err, ArxError::ShapeMismatch { .. }));
    }
}
