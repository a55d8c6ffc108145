//! The triangular factor R (R'R = M'M) of a tall matrix M whose columns are signals read at lags,
//! by Householder TSQR in fixed blocks of rows: M is never held, only one block per thread.
//!
//! The Python layer's least squares, residual prewhitening, feedback test and nonlinear-dependence
//! test all factor such matrices (the regressors as they are, or lags of a residual). A block is
//! written column by column from the signals, factored by faer's Householder QR and its R kept; the
//! R's are stacked and factored again in block order, so the result does not depend on the number
//! of threads.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::Mat;
use rayon::prelude::*;

use crate::error::{ensure_memory, ArxError, Result};
use crate::linalg::qr::{fill_from_samples, qr_r_in_place, reduce_memory, stack_and_reduce, take_r, BLOCK_ROWS};
use crate::linalg::simd::all_finite;

/// A two-dimensional array read through its strides (in elements): entry (t, c) is
/// `values[t * row_stride + c * col_stride]`. A one-dimensional signal is one column.
#[derive(Clone, Copy, Debug)]
pub struct Source<'a> {
    pub values: &'a [f64],
    pub rows: usize,
    pub columns: usize,
    pub row_stride: usize,
    pub col_stride: usize,
}

/// Column `column` of source `source` read `lag` samples back (a negative lag reads ahead).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaggedColumn {
    pub source: usize,
    pub column: usize,
    pub lag: isize,
}

/// The factor and the number of rows it holds.
#[derive(Debug)]
pub struct LaggedFactor {
    /// q × q upper triangular, column-major (q = number of columns; zero rows below the last row
    /// when M has fewer rows than columns).
    pub r: Vec<f64>,
    /// Rows of M: the rows asked for, less those with a missing value when they are skipped.
    pub n_rows: usize,
}

/// R of M, row i of M being every column read at sample `rows[i]`.
///
/// With `skip_missing`, a row holding a non-finite value is left out (as a regression leaves out
/// rows that touch a missing sample); without it, such a row goes into R (NaN spreads, as in a
/// QR of M itself).
///
/// # Errors
/// `InvalidStructure` when a column names a source or column that does not exist, or reads a
/// sample outside its source; `OutOfMemory` when the block buffers cannot be allocated;
/// `Interrupted` when `cancel` is set.
pub fn lagged_r(
    sources: &[Source<'_>],
    columns: &[LaggedColumn],
    rows: &[usize],
    skip_missing: bool,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<LaggedFactor> {
    check_reads(sources, columns, rows)?;
    let q = columns.len();
    let threads = if parallel { rayon::current_num_threads() } else { 1 };
    ensure_memory(reduce_memory(rows.len(), q, threads), "the QR reduction of a lagged matrix")?;
    let block_r = |a: &mut Mat<f64>, block: &[usize]| -> Option<(Mat<f64>, usize)> {
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        a.resize_with(block.len(), q, |_, _| 0.0);
        for (j, c) in columns.iter().enumerate() {
            let s = &sources[c.source];
            let at = |t: usize| (t as isize - c.lag) as usize * s.row_stride + c.column * s.col_stride;
            fill_from_samples(a.col_as_slice_mut(j), s.values, block, s.row_stride, at);
        }
        let kept = if skip_missing { keep_finite_rows(a) } else { block.len() };
        a.resize_with(kept, q, |_, _| 0.0);
        qr_r_in_place(a.as_mut());
        Some((take_r(a, q), kept))
    };
    let blocks: Option<Vec<(Mat<f64>, usize)>> = if parallel {
        rows.par_chunks(BLOCK_ROWS).map_init(|| Mat::<f64>::zeros(0, q), block_r).collect()
    } else {
        let mut a = Mat::<f64>::zeros(0, q);
        rows.chunks(BLOCK_ROWS).map(|block| block_r(&mut a, block)).collect()
    };
    let blocks = blocks.ok_or(ArxError::Interrupted)?;
    let n_rows = blocks.iter().map(|(_, n)| n).sum();
    let factors: Vec<Mat<f64>> = blocks.into_iter().filter(|(_, n)| *n > 0).map(|(r, _)| r).collect();
    let r = stack_and_reduce(&factors, q);
    Ok(LaggedFactor { r: (0..q).flat_map(|j| (0..q).map(move |i| (i, j))).map(|(i, j)| r[(i, j)]).collect(), n_rows })
}

/// Moves the rows of `a` whose entries are all finite to its top, in order; returns how many.
fn keep_finite_rows(a: &mut Mat<f64>) -> usize {
    let (m, q) = (a.nrows(), a.ncols());
    if (0..q).all(|j| all_finite(a.col_as_slice(j))) {
        return m; // the usual block: no row to move
    }
    // Column by column (contiguous), not row by row across the columns.
    let mut finite = vec![true; m];
    for j in 0..q {
        for (f, v) in finite.iter_mut().zip(a.col_as_slice(j)) {
            *f &= v.is_finite();
        }
    }
    let kept = finite.iter().filter(|&&f| f).count();
    if kept < m {
        for j in 0..q {
            let col = a.col_as_slice_mut(j);
            let mut w = 0;
            for i in 0..m {
                if finite[i] {
                    col[w] = col[i];
                    w += 1;
                }
            }
        }
    }
    kept
}

/// Every read `t − lag` of every row lies inside its source, and every source and column exists.
pub(crate) fn check_reads(sources: &[Source<'_>], columns: &[LaggedColumn], rows: &[usize]) -> Result<()> {
    let (Some(&lo), Some(&hi)) = (rows.iter().min(), rows.iter().max()) else {
        return Ok(());
    };
    for c in columns {
        let s = sources.get(c.source).ok_or_else(|| {
            ArxError::InvalidStructure(format!("a lagged column reads source {}, which is not given", c.source))
        })?;
        if c.column >= s.columns {
            return Err(ArxError::InvalidStructure(format!("source {} has no column {}", c.source, c.column)));
        }
        let (first, last) = (lo as isize - c.lag, hi as isize - c.lag);
        if first < 0 || last >= s.rows as isize {
            return Err(ArxError::InvalidStructure(format!(
                "lag {} of source {} reads samples {first}..={last}, outside its {} samples",
                c.lag, c.source, s.rows
            )));
        }
        let end = last as usize * s.row_stride + c.column * s.col_stride;
        if end >= s.values.len() {
            return Err(ArxError::ShapeMismatch {
                what: "a source's values".into(),
                expected: end + 1,
                got: s.values.len(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gram_of_r(r: &[f64], q: usize) -> Vec<f64> {
        let mut g = vec![0.0; q * q];
        for i in 0..q {
            for j in 0..q {
                g[i * q + j] = (0..q).map(|k| r[k + i * q] * r[k + j * q]).sum();
            }
        }
        g
    }

    #[test]
    fn factor_of_lags_matches_the_cross_products_for_any_thread_count() {
        let n = 10_000;
        let x: Vec<f64> = (0..n).map(|t| ((t * 7919) % 1013) as f64 / 1013.0 - 0.5 + (t as f64 * 0.01).sin()).collect();
        let src = [Source { values: &x, rows: n, columns: 1, row_stride: 1, col_stride: 1 }];
        let cols: Vec<LaggedColumn> = (0..4).map(|lag| LaggedColumn { source: 0, column: 0, lag }).collect();
        let rows: Vec<usize> = (3..n).collect();
        let never = AtomicBool::new(false);
        let seq = lagged_r(&src, &cols, &rows, true, false, &never).unwrap();
        let par = lagged_r(&src, &cols, &rows, true, true, &never).unwrap();
        assert_eq!(seq.r, par.r);
        assert_eq!(seq.n_rows, n - 3);
        let g = gram_of_r(&seq.r, 4);
        for i in 0..4 {
            for j in 0..4 {
                let direct: f64 = rows.iter().map(|&t| x[t - i] * x[t - j]).sum();
                assert!((g[i * 4 + j] - direct).abs() <= 1e-10 * direct.abs().max(1.0));
            }
        }
    }

    #[test]
    fn rows_with_a_missing_value_are_left_out_and_bad_reads_refused() {
        let mut x: Vec<f64> = (0..100).map(|t| (t as f64).cos()).collect();
        x[50] = f64::NAN;
        let src = [Source { values: &x, rows: 100, columns: 1, row_stride: 1, col_stride: 1 }];
        let cols = [LaggedColumn { source: 0, column: 0, lag: 1 }, LaggedColumn { source: 0, column: 0, lag: 0 }];
        let rows: Vec<usize> = (1..100).collect();
        let never = AtomicBool::new(false);
        assert_eq!(lagged_r(&src, &cols, &rows, true, false, &never).unwrap().n_rows, 97);
        assert!(lagged_r(&src, &cols, &rows, false, false, &never).unwrap().r.iter().any(|v| v.is_nan()));
        let early: Vec<usize> = (0..100).collect();
        assert!(matches!(lagged_r(&src, &cols, &early, true, false, &never), Err(ArxError::InvalidStructure(_))));
        let stop = AtomicBool::new(true);
        assert!(matches!(lagged_r(&src, &cols, &rows, true, false, &stop), Err(ArxError::Interrupted)));
    }
}
