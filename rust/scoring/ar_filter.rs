//! The Cochrane–Orcutt filter `v(t) − Σ_j a_j v(t − 1 − j)` of the rows of a matrix, in place: the
//! dependence test prewhitens its regressors, output and tested functions with it (numpy needs a
//! temporary per coefficient and a pass over the rows for each).

use crate::error::{ArxError, Result};

/// Filters the rows of `v` (row-major, `width` columns) in place. Each run `(at, first, end)` asks
/// for rows `first..end` filtered, written to rows `at..at + end − first`; a run reads the
/// `a.len()` rows before each of its rows, which must not have been overwritten (`at + a.len() <=
/// first`, and runs in increasing order, as the positions with their previous samples give them).
///
/// Each product and each sum is rounded as numpy rounds `acc = a[0] * v; acc += a[j] * v`, so the
/// numbers are numpy's to the last bit.
///
/// # Errors
/// `InvalidStructure` when a run reads before the first row, writes over rows a later row reads, or
/// passes the end of `v`.
pub fn filter_rows_in_place(v: &mut [f64], width: usize, a: &[f64], runs: &[(usize, usize, usize)]) -> Result<()> {
    let order = a.len();
    if order == 0 {
        return Ok(());
    }
    let rows = v.len().checked_div(width).unwrap_or(0);
    let mut written = 0;
    for &(at, first, end) in runs {
        if first < order || at + order > first || end > rows || at < written || end < first {
            return Err(ArxError::InvalidStructure(format!(
                "the filter's run ({at}, {first}, {end}) does not fit {rows} rows read {order} back"
            )));
        }
        written = at + (end - first);
    }
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if crate::linalg::simd::avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        unsafe { filter_avx2(v, width, a, runs) };
        return Ok(());
    }
    filter(v, width, a, runs);
    Ok(())
}

/// [`filter`] compiled for AVX2: four products at once. No FMA is enabled (nor written), so each
/// product is rounded before its sum, as in numpy.
#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2")]
unsafe fn filter_avx2(v: &mut [f64], width: usize, a: &[f64], runs: &[(usize, usize, usize)]) {
    filter(v, width, a, runs);
}

/// The filter of checked runs (see [`filter_rows_in_place`]). A block of rows at a time: each
/// coefficient's term is then one long contiguous multiply-add over the block (vectorised), not one
/// short loop per row.
#[inline(always)]
fn filter(v: &mut [f64], width: usize, a: &[f64], runs: &[(usize, usize, usize)]) {
    let mut acc = vec![0.0; BLOCK_ROWS * width];
    for &(at, first, end) in runs {
        let mut t0 = first;
        while t0 < end {
            let t1 = (t0 + BLOCK_ROWS).min(end);
            let len = (t1 - t0) * width;
            let acc = &mut acc[..len];
            let lagged = |j: usize| (t0 - 1 - j) * width..(t1 - 1 - j) * width;
            for (s, &x) in acc.iter_mut().zip(&v[lagged(0)]) {
                *s = a[0] * x;
            }
            for (j, &c) in a.iter().enumerate().skip(1) {
                for (s, &x) in acc.iter_mut().zip(&v[lagged(j)]) {
                    *s += c * x;
                }
            }
            // Rows at.. lie below every row this block and the later ones still read.
            let to = (at + t0 - first) * width;
            for (k, &s) in acc.iter().enumerate() {
                v[to + k] = v[t0 * width + k] - s;
            }
            t0 = t1;
        }
    }
}

/// Rows filtered at a time: a block's rows and its running sums stay in the processor's cache.
const BLOCK_ROWS: usize = 512;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filtered_rows_overwrite_the_first_ones() {
        let width = 2;
        let v0: Vec<f64> = (0..20).map(|i| (i as f64 * 0.7).sin()).collect();
        let a = [0.5, -0.25];
        let mut v = v0.clone();
        filter_rows_in_place(&mut v, width, &a, &[(0, 2, 10)]).unwrap();
        for i in 0..8 {
            let t = i + 2;
            for c in 0..width {
                let want = v0[t * width + c] - (0.5 * v0[(t - 1) * width + c] + -0.25 * v0[(t - 2) * width + c]);
                assert_eq!(v[i * width + c], want);
            }
        }
        assert!(filter_rows_in_place(&mut v, width, &a, &[(1, 2, 10)]).is_err());
        assert!(filter_rows_in_place(&mut v, width, &a, &[(0, 2, 11)]).is_err());
    }
}
