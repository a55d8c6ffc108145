//! The triangular factor of a few columns projected off an orthonormal basis, beside a residual:
//! R of [Z − Q(QᵀZ) | y], with Q (n × p, orthonormal columns) fixed and Z (n × k) new at each call.
//!
//! A shape scan of the diagnosis asks for it once per value tried (the shaped input's lags Z, the
//! model's other columns Q, the output's residual y on them): the last diagonal entry of R is the
//! residual's norm of the refit with Z. Two passes over the rows, in fixed blocks (the result does
//! not depend on the thread count): QᵀZ summed block by block in order, then each block's
//! projected rows written and factored by Householder QR, the blocks' R's stacked and reduced (as
//! [`crate::linalg::lagged_qr`]). No tall temporary: one block per thread.

use std::sync::atomic::{AtomicBool, Ordering};

use std::ops::Range;

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

use crate::error::{ArxError, Result};
use crate::linalg::lagged_qr::Source;
use crate::linalg::qr::{stack_and_reduce, BLOCK_ROWS};

/// R of the projected columns beside the residual, and each column's sum of squares before the
/// projection (the scale of the rank rule).
#[derive(Debug)]
pub struct ProjectedFactor {
    /// (k + 1) × (k + 1) upper triangular, column-major.
    pub r: Vec<f64>,
    /// Σ_t z(t, c)² per column c.
    pub squares: Vec<f64>,
}

/// R of [Z − Q(QᵀZ) | y] and the columns' sums of squares (see the module's note).
///
/// # Errors
/// `ShapeMismatch` when Q, Z and y have different numbers of rows; `Interrupted` when `cancel` is
/// set.
pub fn projected_r(
    q: &Source<'_>,
    y: &[f64],
    z: &Source<'_>,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<ProjectedFactor> {
    let n = y.len();
    for (what, rows) in [("the basis's rows", q.rows), ("the projected columns' rows", z.rows)] {
        if rows != n {
            return Err(ArxError::ShapeMismatch { what: what.into(), expected: n, got: rows });
        }
    }
    let (p, k) = (q.columns, z.columns);
    let starts: Vec<usize> = (0..n).step_by(BLOCK_ROWS).collect();
    let block = |start: usize| start..(start + BLOCK_ROWS).min(n);
    let products = |&start: &usize| -> Option<(Mat<f64>, Vec<f64>)> {
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let (qb, zb) = (view(q, block(start)), view(z, block(start)));
        let mut qtz = Mat::<f64>::zeros(p, k);
        matmul(qtz.as_mut(), Accum::Replace, qb.transpose(), zb, 1.0, Par::Seq);
        Some((qtz, (0..k).map(|c| column_squares(zb, c)).collect()))
    };
    let partial: Option<Vec<_>> =
        if parallel { starts.par_iter().map(products).collect() } else { starts.iter().map(products).collect() };
    // Summed in block order: the same bits for any number of threads.
    let (mut qtz, mut squares) = (Mat::<f64>::zeros(p, k), vec![0.0; k]);
    for (a, s) in partial.ok_or(ArxError::Interrupted)? {
        qtz += a;
        squares.iter_mut().zip(&s).for_each(|(t, v)| *t += v);
    }
    let m = k + 1;
    let factor = |a: &mut Mat<f64>, start: &usize| -> Option<Mat<f64>> {
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let rows = block(*start);
        a.resize_with(rows.len(), m, |_, _| 0.0);
        let (qb, zb) = (view(q, rows.clone()), view(z, rows.clone()));
        a.as_mut().subcols_mut(0, k).copy_from(zb);
        matmul(a.as_mut().subcols_mut(0, k), Accum::Add, qb, qtz.as_ref(), -1.0, Par::Seq);
        a.col_as_slice_mut(k).copy_from_slice(&y[rows]);
        Some(householder_r(a))
    };
    let blocks: Option<Vec<Mat<f64>>> = if parallel {
        starts.par_iter().map_init(|| Mat::<f64>::zeros(0, m), factor).collect()
    } else {
        let mut a = Mat::<f64>::zeros(0, m);
        starts.iter().map(|s| factor(&mut a, s)).collect()
    };
    let r = stack_and_reduce(&blocks.ok_or(ArxError::Interrupted)?, m);
    Ok(ProjectedFactor {
        r: (0..m).flat_map(|j| (0..m).map(move |i| (i, j))).map(|(i, j)| r[(i, j)]).collect(),
        squares,
    })
}

/// The rows `rows` of a source as a matrix view, read where they lie.
fn view<'a>(s: &Source<'a>, rows: Range<usize>) -> MatRef<'a, f64> {
    assert!(rows.end <= s.rows, "a block beyond the source's rows");
    if rows.is_empty() || s.columns == 0 {
        return MatRef::from_row_major_slice(&[], rows.len(), s.columns);
    }
    let last = (rows.end - 1) * s.row_stride + (s.columns - 1) * s.col_stride;
    assert!(last < s.values.len(), "a source shorter than its strides say");
    // SAFETY: every entry (t, c) of the view, t in rows and c < columns, is at
    // values[t·row_stride + c·col_stride] <= values[last], inside the slice (checked above).
    unsafe {
        MatRef::from_raw_parts(
            s.values.as_ptr().add(rows.start * s.row_stride),
            rows.len(),
            s.columns,
            s.row_stride as isize,
            s.col_stride as isize,
        )
    }
}

/// Σ a_i b_i in four running sums (a dependency chain of a quarter of the length).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0; 4];
    let (a4, b4) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = a4.remainder().iter().zip(b4.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in a4.zip(b4) {
        for l in 0..4 {
            s[l] += x[l] * y[l];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// Σ z(i, c)² of a column of a strided view.
fn column_squares(z: MatRef<'_, f64>, c: usize) -> f64 {
    let col = z.col(c);
    let mut s = [0.0; 4];
    let n = z.nrows();
    for i in (0..n - n % 4).step_by(4) {
        for l in 0..4 {
            s[l] += col[i + l] * col[i + l];
        }
    }
    let tail: f64 = (n - n % 4..n).map(|i| col[i] * col[i]).sum();
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// R (m × m, upper triangular) of `a` (len × m) by Householder reflections, `a` overwritten: at a
/// few columns a plain sweep beats a blocked QR's set-up.
fn householder_r(a: &mut Mat<f64>) -> Mat<f64> {
    let (len, m) = (a.nrows(), a.ncols());
    let mut r = Mat::<f64>::zeros(m, m);
    let mut v = vec![0.0; len];
    for j in 0..m.min(len) {
        let x = &a.col_as_slice(j)[j..];
        let norm2 = dot(x, x);
        if norm2 == 0.0 {
            for c in j..m {
                r[(j, c)] = a[(j, c)];
            }
            continue;
        }
        let alpha = x[0];
        let beta = if alpha >= 0.0 { -norm2.sqrt() } else { norm2.sqrt() };
        let v = &mut v[..len - j];
        v.copy_from_slice(x);
        v[0] = alpha - beta;
        let vnorm2 = norm2 - alpha * alpha + v[0] * v[0];
        r[(j, j)] = beta;
        for c in (j + 1)..m {
            let w = &mut a.col_as_slice_mut(c)[j..];
            let f = 2.0 * dot(v, w) / vnorm2;
            w.iter_mut().zip(v.iter()).for_each(|(w, v)| *w -= f * v);
            r[(j, c)] = w[0];
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn source(values: &[f64], rows: usize, columns: usize) -> Source<'_> {
        Source { values, rows, columns, row_stride: columns, col_stride: 1 }
    }

    #[test]
    fn the_factor_gives_the_residual_of_the_projected_fit_for_any_thread_count() {
        // Q: the normalised constant; Z: two columns; y: orthogonal to the constant.
        let n = 3 * BLOCK_ROWS + 17;
        let q: Vec<f64> = vec![1.0 / (n as f64).sqrt(); n];
        let z: Vec<f64> = (0..n).flat_map(|t| [(t as f64 * 0.37).sin() + 2.0, ((t * t) % 7) as f64]).collect();
        let y0: Vec<f64> = (0..n).map(|t| (t as f64 * 0.11).cos() + 0.5 * z[2 * t]).collect();
        let mean = y0.iter().sum::<f64>() / n as f64;
        let y: Vec<f64> = y0.iter().map(|v| v - mean).collect();
        let never = AtomicBool::new(false);
        let (qs, zs) = (source(&q, n, 1), source(&z, n, 2));
        let seq = projected_r(&qs, &y, &zs, false, &never).unwrap();
        let par = projected_r(&qs, &y, &zs, true, &never).unwrap();
        assert_eq!(seq.r, par.r);
        assert_eq!(seq.squares, par.squares);
        let want: f64 = (0..n).map(|t| z[2 * t] * z[2 * t]).sum();
        assert!((seq.squares[0] - want).abs() <= 1e-12 * want);
        // R'R = M'M for M = [Z − mean(Z) | y]: the (0, 2) entry is Σ (z0 − mean z0) y.
        let m0 = (0..n).map(|t| z[2 * t]).sum::<f64>() / n as f64;
        let cross: f64 = (0..n).map(|t| (z[2 * t] - m0) * y[t]).sum();
        let r = &seq.r;
        assert!((r[0] * r[6] - cross).abs() <= 1e-9 * cross.abs());
    }

    #[test]
    fn rows_that_disagree_are_refused() {
        let never = AtomicBool::new(false);
        let (q, z) = (vec![1.0; 4], vec![1.0; 6]);
        let err = projected_r(&source(&q, 4, 1), &[0.0; 4], &source(&z, 3, 2), false, &never).unwrap_err();
        assert!(matches!(err, ArxError::ShapeMismatch { .. }));
    }
}
