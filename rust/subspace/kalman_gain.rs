//! The Kalman gain K of the innovation form, by two linear regressions on the output error
//! `v = y − ŷ_sim` of the model (A, B, C, D) from its initial states (Hannan–Rissanen).
//!
//! First the innovations e are estimated by a long vector autoregression of v (`lags` samples);
//! then `v − e = C (zI − A)⁻¹ K e` (plus the initial state's response) is linear in K: the same
//! least squares as B ([`input_matrices`]) with e as the input. The autoregression's normal
//! equations come from the lagged Gram of v ([`lagged_gram`]), so neither its regressors nor any
//! other N-sized matrix is formed: one simulation and one regression pass over the data.

use std::sync::atomic::AtomicBool;

use faer::Mat;

use super::hankel::Signals;
use super::input_matrices::{input_matrices, Unknowns};
use super::pseudo_inverse;
use super::response::{respond, StateSpaceRef};
use crate::error::{ArxError, Result};
use crate::linalg::lagged_gram::lagged_gram;
use crate::linalg::lagged_products::dot_product;
use crate::linalg::lagged_qr::{LaggedColumn, Source};

/// K (n × ny) of the model `m`, started from `x0[i]` on segment i of `s`, with an autoregression
/// of `lags` samples for the innovations.
///
/// # Errors
/// `InvalidStructure` when a segment is not longer than `lags` or the initial states do not match
/// the segments, the errors of [`respond`] and of [`input_matrices`].
pub fn kalman_gain(
    m: StateSpaceRef<'_>,
    x0: &[Vec<f64>],
    s: &Signals<'_>,
    lags: usize,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    m.check()?;
    if x0.len() != s.segments.len() || s.segments.iter().any(|&(lo, hi)| hi < lo + lags + 1) {
        return Err(ArxError::InvalidStructure(format!(
            "the Kalman gain needs one initial state per segment and segments longer than {lags} samples"
        )));
    }
    let v = output_error(m, x0, s, cancel)?;
    let e = innovations(&v, s, lags, parallel, cancel)?;
    let explained: Vec<f64> = v.iter().zip(&e).map(|(v, e)| v - e).collect();
    let ny = s.n_outputs;
    let regression = Signals { u: &e, y: &explained, n_inputs: ny, n_outputs: ny, segments: s.segments };
    let unknowns = Unknowns { feedthrough: false, initial_state: true };
    Ok(input_matrices(m.a, m.c, &regression, unknowns, cancel)?.b)
}

/// `v = y − ŷ_sim` on the segments (row-major N × ny, zero outside them).
fn output_error(m: StateSpaceRef<'_>, x0: &[Vec<f64>], s: &Signals<'_>, cancel: &AtomicBool) -> Result<Vec<f64>> {
    let (nu, ny) = (s.n_inputs, s.n_outputs);
    // Without inputs, one zero input: the response counts its samples by the inputs.
    let (b0, d0) = (Mat::<f64>::zeros(m.a.nrows(), 1), Mat::<f64>::zeros(ny, 1));
    let m = if nu == 0 { StateSpaceRef { b: b0.as_ref(), d: d0.as_ref(), ..m } } else { m };
    let zeros = vec![0.0; if nu == 0 { s.n_samples() } else { 0 }];
    let (u, width) = if nu == 0 { (&zeros[..], 1) } else { (s.u, nu) };
    let mut v = vec![0.0; s.y.len()];
    for (&(lo, hi), x) in s.segments.iter().zip(x0) {
        let (simulated, _) = respond(m, x, &u[lo * width..hi * width], cancel)?;
        let rows = lo * ny..hi * ny;
        v[rows.clone()].iter_mut().zip(&s.y[rows]).zip(&simulated).for_each(|((v, y), p)| *v = y - p);
    }
    Ok(v)
}

/// The innovations of `v`: its residuals from a vector autoregression of `lags` samples fitted on
/// every segment (v itself over each segment's first `lags` samples).
fn innovations(v: &[f64], s: &Signals<'_>, lags: usize, parallel: bool, cancel: &AtomicBool) -> Result<Vec<f64>> {
    let ny = s.n_outputs;
    let n = v.len() / ny.max(1);
    let source = [Source { values: v, rows: n, columns: ny, row_stride: ny, col_stride: 1 }];
    // The targets v(t), then the regressors v(t−1) … v(t−lags), as the rows of the regression.
    let columns: Vec<LaggedColumn> = (0..=lags)
        .flat_map(|lag| (0..ny).map(move |column| LaggedColumn { source: 0, column, lag: lag as isize }))
        .collect();
    let ranges: Vec<(usize, usize)> = s.segments.iter().map(|&(lo, hi)| (lo + lags, hi)).collect();
    let gram = lagged_gram(&source, &columns, &ranges, parallel, cancel)?;
    let p = lags * ny;
    let theta = pseudo_inverse(gram.as_ref().submatrix(ny, ny, p, p)) * gram.as_ref().submatrix(ny, 0, p, ny);
    // Row o of the predictor, over v(t−lags) … v(t−1) oldest first (the regressors run newest first).
    let weights: Vec<f64> = (0..ny)
        .flat_map(|o| (0..p).map(move |i| (o, lags - 1 - i / ny, i % ny)))
        .map(|(o, j, k)| theta[(j * ny + k, o)])
        .collect();
    let mut e = v.to_vec();
    for &(lo, hi) in &ranges {
        for t in lo..hi {
            let past = &v[(t - lags) * ny..t * ny];
            for (o, row) in weights.chunks_exact(p).enumerate() {
                e[t * ny + o] -= dot_product(row, past);
            }
        }
    }
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On white innovations through a known innovation-form model (no input), the gain comes back
    /// close to the true K.
    #[test]
    fn the_gain_of_a_simulated_innovation_model_is_recovered() {
        let (a, c, k) = (
            faer::mat![[0.8, 0.3], [-0.2, 0.5]],
            faer::mat![[1.0, 0.0], [0.4, 1.0]],
            faer::mat![[0.5, 0.1], [0.0, 0.3]],
        );
        let n = 40_000;
        let mut seed = 12345u64;
        let mut noise = || {
            // Sum of uniforms: near-Gaussian, deterministic.
            (0..12)
                .map(|_| {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    (seed >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        let (mut x, mut y) = ([0.0; 2], Vec::with_capacity(2 * n));
        for _ in 0..n {
            let e = [noise(), noise()];
            let out = [c[(0, 0)] * x[0] + c[(0, 1)] * x[1] + e[0], c[(1, 0)] * x[0] + c[(1, 1)] * x[1] + e[1]];
            y.extend(out);
            x = [
                a[(0, 0)] * x[0] + a[(0, 1)] * x[1] + k[(0, 0)] * e[0] + k[(0, 1)] * e[1],
                a[(1, 0)] * x[0] + a[(1, 1)] * x[1] + k[(1, 0)] * e[0] + k[(1, 1)] * e[1],
            ];
        }
        let u = vec![0.0; n];
        let segments = [(0, n / 2), (n / 2, n)];
        let s = Signals { u: &u, y: &y, n_inputs: 1, n_outputs: 2, segments: &segments };
        let (b, d) = (Mat::<f64>::zeros(2, 1), Mat::<f64>::zeros(2, 1));
        let m = StateSpaceRef { a: a.as_ref(), b: b.as_ref(), c: c.as_ref(), d: d.as_ref() };
        let never = AtomicBool::new(false);
        let gain = kalman_gain(m, &[vec![0.0; 2], vec![0.0; 2]], &s, 10, true, &never).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!((gain[(i, j)] - k[(i, j)]).abs() < 0.05, "{i} {j}: {:?}", gain);
            }
        }
        assert!(kalman_gain(m, &[vec![0.0; 2]], &s, 10, true, &never).is_err());
    }
}
