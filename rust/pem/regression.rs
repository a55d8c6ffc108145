//! Regressions on lagged columns of filtered signals, for the starts, the initial states and the
//! Gauss–Newton steps: the R of `[columns | target]` by TSQR, least squares, instrumental variables.

use faer::Mat;
use rayon::prelude::*;

use crate::arx::fit::solve_subset;
use crate::error::Result;
use crate::linalg::qr::{
    back_substitute, check_rank, qr_r_in_place, rank_tolerance, small_qr, stack_and_reduce, take_r, to_col_major,
    BLOCK_ROWS,
};

/// One column of a Jacobian or regressor: `sign · signal[t − lag]`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Column {
    pub(super) signal: usize,
    pub(super) lag: usize,
    pub(super) sign: f64,
}

/// R factor ((p+1) × (p+1), column-major) of `[columns | target]` over `rows`, by TSQR. Lagged
/// values from before sample `floor` read as zero (the filters' rest before a segment).
pub(super) fn reduce_columns(
    signals: &[Vec<f64>],
    cols: &[Column],
    target: &[f64],
    rows: &[usize],
    floor: usize,
    parallel: bool,
) -> Vec<f64> {
    let q = cols.len() + 1;
    let block_r = |block: &[usize]| -> Mat<f64> {
        let mut a = Mat::<f64>::zeros(block.len(), q);
        for (c, col) in cols.iter().enumerate() {
            let s = &signals[col.signal];
            for (dst, &t) in a.col_as_slice_mut(c).iter_mut().zip(block) {
                *dst = if t >= floor + col.lag { col.sign * s[t - col.lag] } else { 0.0 };
            }
        }
        for (dst, &t) in a.col_as_slice_mut(q - 1).iter_mut().zip(block) {
            *dst = target[t];
        }
        qr_r_in_place(a.as_mut());
        take_r(&a, q)
    };
    let blocks: Vec<Mat<f64>> = if parallel {
        rows.par_chunks(BLOCK_ROWS).map(block_r).collect()
    } else {
        rows.chunks(BLOCK_ROWS).map(block_r).collect()
    };
    to_col_major(&stack_and_reduce(&blocks, q))
}

/// Least squares of `target` on `cols` over `rows` by QR: θ and the residual sum of squares.
pub(super) fn least_squares(
    signals: &[Vec<f64>],
    cols: &[Column],
    target: &[f64],
    rows: &[usize],
    parallel: bool,
) -> Result<(Vec<f64>, f64)> {
    let q = cols.len() + 1;
    let r = reduce_columns(signals, cols, target, rows, 0, parallel);
    let idx: Vec<usize> = (0..cols.len()).collect();
    let (theta, rss, _) = solve_subset(&r, q, &idx, rows.len())?;
    Ok((theta, rss))
}

/// Instrumental-variable estimate: solves $\sum \zeta \varphi^T \theta = \sum \zeta\, \mathrm{target}$
/// (square, solved by QR).
pub(super) fn iv_solve(
    signals: &[Vec<f64>],
    phi: &[Column],
    zeta: &[Column],
    target: &[f64],
    rows: &[usize],
) -> Result<Vec<f64>> {
    let p = phi.len();
    let at = |c: &Column, t: usize| c.sign * signals[c.signal][t - c.lag];
    // [Σ ζ φᵀ | Σ ζ target], column-major p × (p + 1).
    let mut a = vec![0.0; p * (p + 1)];
    for &t in rows {
        for (i, z) in zeta.iter().enumerate() {
            let zi = at(z, t);
            for (j, f) in phi.iter().enumerate() {
                a[i + j * p] += zi * at(f, t);
            }
            a[i + p * p] += zi * target[t];
        }
    }
    small_qr(&mut a, p, p + 1);
    check_rank(&a, p, p, rank_tolerance(rows.len(), p))?;
    let rhs: Vec<f64> = (0..p).map(|i| a[i + p * p]).collect();
    let mut theta = vec![0.0; p];
    back_substitute(&a, p, &rhs, &mut theta);
    Ok(theta)
}

/// Columns `sign · signal[t − k]` for k in `lags`.
pub(super) fn lagged(signal: usize, lags: std::ops::Range<usize>, sign: f64) -> Vec<Column> {
    lags.map(|lag| Column { signal, lag, sign }).collect()
}

/// `target − Σ θ_j col_j` on `rows`, zero elsewhere.
pub(super) fn residual_of(
    signals: &[Vec<f64>],
    cols: &[Column],
    theta: &[f64],
    target: &[f64],
    rows: &[usize],
) -> Vec<f64> {
    let mut e = vec![0.0; target.len()];
    for &t in rows {
        e[t] =
            target[t] - cols.iter().zip(theta).map(|(c, th)| th * c.sign * signals[c.signal][t - c.lag]).sum::<f64>();
    }
    e
}
