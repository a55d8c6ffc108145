//! Least-squares fit of one structure by Householder QR, with rank check and covariance.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::arx::reduce::reduce_checked;
use crate::arx::structure::{fill_row, usable_rows, Data, Structure};
use crate::error::{ensure_memory, ArxError, Result};
use crate::linalg::qr::{
    back_substitute, check_rank, column_scale, rank_tolerance, reduce_memory, small_qr, to_col_major,
};

/// A fitted parameter vector with what the Python layer needs for statistics.
#[derive(Debug, Clone)]
pub struct Fit {
    /// Parameters in the order a's, each input's b's, output terms.
    pub theta: Vec<f64>,
    /// Residual sum of squares on the regression rows.
    pub rss: f64,
    /// Number of regression rows used.
    pub n_rows: usize,
    /// Rows left out because a regressor or the output touched a NaN or inf.
    pub n_skipped: usize,
    /// $(R^T R)^{-1} = (\Phi^T \Phi)^{-1}$, row-major p × p; times the noise variance it is the
    /// parameter covariance.
    pub inv_gram: Vec<f64>,
}

/// Solves the least-squares problem whose `[Φ | y]` has the column-major (q × q) triangular factor
/// `r`, restricted to the regressor columns `cols` (the output is the last column of `r`).
/// Returns θ, the residual sum of squares, and the small re-triangularised factor (column-major,
/// (k+1) × (k+1) with leading dimension q).
///
/// Each column is scaled by a power of two ([`column_scale`]) before the re-triangularisation and
/// the solution scaled back, so outputs or inputs near 1e154 or 1e-200 do not overflow or underflow
/// the column norms (a false rank deficiency); for other data the result is unchanged to the bit.
pub fn solve_subset(r: &[f64], q: usize, cols: &[usize], n_rows: usize) -> Result<(Vec<f64>, f64, Vec<f64>)> {
    let k = cols.len();
    let mut a = vec![0.0; q * (k + 1)];
    let mut scale = vec![1.0; k + 1];
    for (c, &j) in cols.iter().chain(std::iter::once(&(q - 1))).enumerate() {
        let col = &r[j * q..j * q + q];
        scale[c] = column_scale(col);
        for (dst, v) in a[c * q..c * q + q].iter_mut().zip(col) {
            *dst = v * scale[c];
        }
    }
    small_qr(&mut a, q, k + 1);
    check_rank(&a, q, k, rank_tolerance(n_rows, k)).map_err(|e| match e {
        ArxError::RankDeficient { column, ratio } => ArxError::RankDeficient { column: cols[column], ratio },
        other => other,
    })?;
    let mut theta = vec![0.0; k];
    let rhs: Vec<f64> = (0..k).map(|i| a[i + k * q]).collect();
    back_substitute(&a, q, &rhs, &mut theta);
    let sy = scale[k];
    for (t, sc) in theta.iter_mut().zip(&scale) {
        *t *= sc / sy;
    }
    let rss = if k < q { (a[k + k * q] / sy) * (a[k + k * q] / sy) } else { 0.0 };
    // The factor of the unscaled columns (exact: the scales are powers of two).
    for (c, sc) in scale.iter().enumerate() {
        for v in &mut a[c * q..c * q + q] {
            *v /= sc;
        }
    }
    Ok((theta, rss, a))
}

/// $(R^T R)^{-1}$ for the leading k × k block of a column-major upper-triangular `r` (leading dim `ld`).
pub fn inverse_gram(r: &[f64], ld: usize, k: usize) -> Vec<f64> {
    // Rinv upper triangular, column-major k × k.
    let mut rinv = vec![0.0; k * k];
    for j in 0..k {
        rinv[j + j * k] = 1.0 / r[j + j * ld];
        for i in (0..j).rev() {
            let mut acc = 0.0;
            for l in (i + 1)..=j {
                acc += r[i + l * ld] * rinv[l + j * k];
            }
            rinv[i + j * k] = -acc / r[i + i * ld];
        }
    }
    // (RᵀR)⁻¹ = Rinv Rinvᵀ.
    let mut out = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..k {
            let mut acc = 0.0;
            for l in i.max(j)..k {
                acc += rinv[i + l * k] * rinv[j + l * k];
            }
            out[i * k + j] = acc;
        }
    }
    out
}

/// Bytes [`fit_rows_like`] allocates for `n_rows` regression rows and `n_params` parameters on
/// `threads` threads: the row list, the QR reduction ([`reduce_memory`]) and the small factors.
pub fn fit_memory(n_rows: usize, n_params: usize, threads: usize) -> usize {
    let q = n_params.saturating_add(1);
    let small = q.saturating_mul(q).saturating_mul(std::mem::size_of::<f64>()).saturating_mul(4);
    n_rows
        .saturating_mul(std::mem::size_of::<usize>())
        .saturating_add(reduce_memory(n_rows, q, threads))
        .saturating_add(small)
}

/// [`inverse_gram`] computed on power-of-two scaled columns and scaled back, so that factors with
/// entries near 1e154 or 1e-200 do not overflow or underflow on the way.
fn scaled_inverse_gram(mut r: Vec<f64>, ld: usize, k: usize) -> Vec<f64> {
    let scale: Vec<f64> = (0..k).map(|j| column_scale(&r[j * ld..j * ld + ld])).collect();
    for (j, sc) in scale.iter().enumerate() {
        for v in &mut r[j * ld..j * ld + ld] {
            *v *= sc;
        }
    }
    let mut g = inverse_gram(&r, ld, k);
    for i in 0..k {
        for j in 0..k {
            g[i * k + j] *= scale[i] * scale[j];
        }
    }
    g
}

/// Fits structure `s` to `d` by least squares on rows that start `first_lag` into each experiment.
///
/// # Errors
/// `TooFewSamples` when there are fewer usable rows than parameters; `RankDeficient` naming the first
/// regressor column that depends on the ones before it.
pub fn fit(d: &Data, s: &Structure, first_lag: usize, parallel: bool) -> Result<Fit> {
    fit_rows_like(d, s, first_lag, parallel, None, &AtomicBool::new(false))
}

/// [`fit`] on the rows where the regressors of `rows_like` (normally a sweep's grid envelope,
/// which reads every lag `s` reads) are finite too, so that a structure refitted after a sweep on
/// data with NaN uses exactly the sweep's rows. `n_skipped` then counts the rows either left out.
///
/// # Errors
/// As [`fit`]; `ShapeMismatch` or `InvalidStructure` when `rows_like` does not fit the data;
/// `OutOfMemory` when the buffers cannot be allocated; `Interrupted` once `cancel` is set.
pub fn fit_rows_like(
    d: &Data,
    s: &Structure,
    first_lag: usize,
    parallel: bool,
    rows_like: Option<&Structure>,
    cancel: &AtomicBool,
) -> Result<Fit> {
    s.check(d.m)?;
    let p = s.n_params();
    let lag = first_lag.max(s.max_lag()).max(rows_like.map_or(0, |r| r.max_lag()));
    let bound = d.max_rows(lag);
    if bound < p + 1 {
        return Err(ArxError::TooFewSamples { needed: p + 1, got: bound });
    }
    ensure_memory(bound.saturating_mul(std::mem::size_of::<usize>()), "the list of regression rows")?;
    let (rows, n_skipped) = match rows_like {
        None => usable_rows(d, s, first_lag),
        Some(env) => {
            if env.nb.len() != d.m {
                return Err(ArxError::ShapeMismatch {
                    what: "row structure nb (one order per input)".into(),
                    expected: d.m,
                    got: env.nb.len(),
                });
            }
            let mut row = vec![0.0; p];
            let rows: Vec<usize> =
                usable_rows(d, env, lag).0.into_iter().filter(|&t| fill_row(d, s, t, &mut row)).collect();
            let skipped = bound - rows.len();
            (rows, skipped)
        }
    };
    if rows.len() < p + 1 {
        return Err(ArxError::TooFewSamples { needed: p + 1, got: rows.len() });
    }
    let r = to_col_major(&reduce_checked(d, s, &rows, parallel, &|| !cancel.load(Ordering::Relaxed))?);
    let cols: Vec<usize> = (0..p).collect();
    Ok(Fit { n_skipped, ..fit_from_factor(&r, p + 1, &cols, rows.len())? })
}

/// The least-squares fit of the columns `cols` of a factor `r` (column-major q × q, output last) of
/// a regressor with `n_rows` rows: parameters, loss and $(\Phi^T\Phi)^{-1}$. On a sweep's envelope
/// factor this is the fit of a structure on the sweep's rows without going back to the data.
///
/// # Errors
/// `RankDeficient` naming the first column that depends on the ones before it.
pub fn fit_from_factor(r: &[f64], q: usize, cols: &[usize], n_rows: usize) -> Result<Fit> {
    let (theta, rss, small) = solve_subset(r, q, cols, n_rows)?;
    let inv_gram = scaled_inverse_gram(small, q, cols.len());
    Ok(Fit { theta, rss, n_rows, n_skipped: 0, inv_gram })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::structure::Structure;
    use crate::linalg::qr::stack_and_reduce;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    #[test]
    fn recovers_noise_free_arx_exactly() {
        // y(t) - 1.5 y(t-1) + 0.7 y(t-2) = 0.5 u(t-3) + 0.25 u(t-4)
        let n = 3000;
        let mut seed = 7;
        let u: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let mut y = vec![0.0; n];
        for t in 4..n {
            y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3] + 0.25 * u[t - 4];
        }
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![3], vec![]).unwrap();
        let f = fit(&d, &s, 0, true).unwrap();
        let truth = [-1.5, 0.7, 0.5, 0.25];
        for (a, b) in f.theta.iter().zip(truth) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        assert!(f.rss < 1e-20);
    }

    #[test]
    fn constant_duplicate_input_is_rank_deficient() {
        let n = 200;
        let mut seed = 3;
        let y: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let u = vec![1.0; n];
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(1, vec![2], vec![1], vec![]).unwrap();
        assert!(matches!(fit(&d, &s, 0, false), Err(ArxError::RankDeficient { column: 2, .. })));
    }

    #[test]
    fn orders_beyond_any_data_are_refused_before_allocating() {
        assert!(matches!(Structure::new(usize::MAX, vec![2], vec![1], vec![]), Err(ArxError::InvalidStructure(_))));
        assert!(matches!(Structure::new(1, vec![2], vec![usize::MAX - 1], vec![]), Err(ArxError::InvalidStructure(_))));
        let y = vec![0.5; 50];
        let starts = [0];
        let d = Data::new(&y, &y, 1, &starts).unwrap();
        let s = Structure::new(1 << 39, vec![1], vec![0], vec![]).unwrap();
        assert!(matches!(fit(&d, &s, 0, false), Err(ArxError::TooFewSamples { got: 0, .. })));
    }

    #[test]
    fn fit_from_two_stacked_factors_equals_the_fit_of_both_experiments() {
        let n = 600;
        let mut seed = 11;
        let u: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let y: Vec<f64> = (0..n).map(|t| if t > 0 { 0.3 * u[t - 1] + lcg(&mut seed) } else { 0.0 }).collect();
        let s = Structure::new(1, vec![2], vec![1], vec![]).unwrap();
        let starts = [0, 250];
        let whole = fit(&Data::new(&y, &u, 1, &starts).unwrap(), &s, 0, false).unwrap();
        let (p, q) = (s.n_params(), s.n_params() + 1);
        let blocks: Vec<_> = [(0, 250), (250, n)]
            .iter()
            .map(|&(a, b)| {
                let d = Data::new(&y[a..b], &u[a..b], 1, &[0]).unwrap();
                let (rows, _) = usable_rows(&d, &s, 0);
                reduce_checked(&d, &s, &rows, false, &|| true).unwrap()
            })
            .collect();
        let r = to_col_major(&stack_and_reduce(&blocks, q));
        let cols: Vec<usize> = (0..p).collect();
        let f = fit_from_factor(&r, q, &cols, whole.n_rows).unwrap();
        for (a, b) in f.theta.iter().zip(&whole.theta) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        assert!((f.rss - whole.rss).abs() < 1e-10 * whole.rss);
        assert_eq!(f.inv_gram.len(), p * p);
    }

    #[test]
    fn too_few_samples() {
        let y = vec![1.0, 2.0, 3.0];
        let u = vec![1.0, 0.0, 1.0];
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![1], vec![1], vec![]).unwrap();
        assert!(matches!(fit(&d, &s, 0, false), Err(ArxError::TooFewSamples { .. })));
    }
}
