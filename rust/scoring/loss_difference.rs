//! The sums of a Diebold–Mariano test of one model's errors against another's, in one call: the
//! squared-error differences `d(t) = base(t) − (y(t) − pred(t))²` on the samples where both errors
//! exist, their mean, and the lagged products of the centred differences up to the Bartlett
//! bandwidth ⌊n^(1/3)⌋ ([`crate::linalg::lagged_products`]).
//!
//! A diagnosis tests each shape model's validation errors against the model's (kept squared): in
//! numpy that was eight passes over a record's temporaries per shape (the error, where it is
//! finite, its square, the difference, the gather, the mean, the centring) before the lagged sums.
//! Here the differences are written over the prediction itself, and only the lagged sums read them
//! again.

use std::sync::atomic::AtomicBool;

use crate::error::{ArxError, Result};
use crate::linalg::lagged_products::lagged_products;

/// The differences' count, mean and the lagged products of the centred ones.
#[derive(Clone, Debug, PartialEq)]
pub struct LossDifference {
    /// Samples where both errors exist.
    pub n: usize,
    /// Mean of the differences (NaN without samples).
    pub mean: f64,
    /// `Σ_t dc(t) dc(t − k)` for k = 0..=⌊n^(1/3)⌋, dc the centred differences (empty below 2 samples).
    pub sums: Vec<f64>,
}

/// [`LossDifference`] of `base` (the first model's squared errors, NaN where its error is not
/// finite) against the errors `y − pred` of the second; `pred` is overwritten (its first `n`
/// entries hold the centred differences, in sample order).
///
/// # Errors
/// `ShapeMismatch` when the three series differ in length; `Interrupted` once `cancel` is set.
pub fn loss_difference(y: &[f64], base: &[f64], pred: &mut [f64], cancel: &AtomicBool) -> Result<LossDifference> {
    for (what, len) in [("first model's squared errors", base.len()), ("predictions", pred.len())] {
        if len != y.len() {
            return Err(ArxError::ShapeMismatch { what: what.into(), expected: y.len(), got: len });
        }
    }
    let mut n = 0;
    for t in 0..y.len() {
        let e = y[t] - pred[t];
        if e.is_finite() && !base[t].is_nan() {
            pred[n] = base[t] - e * e;
            n += 1;
        }
    }
    let d = &mut pred[..n];
    let mean = pairwise_sum(d) / n as f64;
    if n < 2 {
        return Ok(LossDifference { n, mean, sums: Vec::new() });
    }
    d.iter_mut().for_each(|v| *v -= mean);
    let lag = (n as f64).powf(1.0 / 3.0) as isize; // Python's int(n ** (1 / 3))
    let sums = lagged_products(d, d, 0, lag, cancel)?;
    Ok(LossDifference { n, mean, sums })
}

/// Σ x by halves down to blocks of [`PAIRWISE_BLOCK`], each summed in eight lanes (numpy's
/// pairwise summation: an error that grows with log n, not n).
fn pairwise_sum(x: &[f64]) -> f64 {
    if x.len() > PAIRWISE_BLOCK {
        let half = x.len() / 2;
        return pairwise_sum(&x[..half]) + pairwise_sum(&x[half..]);
    }
    let mut lanes = [0.0f64; 8];
    let chunks = x.chunks_exact(8);
    let tail: f64 = chunks.remainder().iter().sum();
    for c in chunks {
        for l in 0..8 {
            lanes[l] += c[l];
        }
    }
    ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) + ((lanes[4] + lanes[5]) + (lanes[6] + lanes[7])) + tail
}

/// Samples per block of [`pairwise_sum`].
const PAIRWISE_BLOCK: usize = 128;

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    /// The differences, their mean and the centred lagged sums are the direct formulas' (to 1e-12),
    /// with samples left out where either error is missing.
    #[test]
    fn equals_the_direct_formulas() {
        let mut seed = 3;
        let n = 5000;
        let y: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let mut pred: Vec<f64> = y.iter().map(|v| v + 0.3 * lcg(&mut seed) + 0.01).collect();
        let mut base: Vec<f64> = (0..n).map(|_| (0.3 * lcg(&mut seed)).powi(2)).collect();
        base[10] = f64::NAN;
        pred[20] = f64::NAN;
        pred[30] = f64::INFINITY;
        let d: Vec<f64> = (0..n)
            .filter(|&t| (y[t] - pred[t]).is_finite() && !base[t].is_nan())
            .map(|t| base[t] - (y[t] - pred[t]).powi(2))
            .collect();
        let got = loss_difference(&y, &base, &mut pred, &AtomicBool::new(false)).unwrap();
        assert_eq!(got.n, n - 3);
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        assert!((got.mean - mean).abs() <= 1e-13 * mean.abs());
        let lag = (d.len() as f64).powf(1.0 / 3.0) as usize;
        assert_eq!(got.sums.len(), lag + 1);
        for k in 0..=lag {
            let want: f64 = (k..d.len()).map(|t| (d[t] - mean) * (d[t - k] - mean)).sum();
            assert!((got.sums[k] - want).abs() <= 1e-12 * got.sums[0], "lag {k}: {} vs {want}", got.sums[k]);
        }
    }

    #[test]
    fn refuses_unequal_lengths_and_answers_on_too_few_samples() {
        let never = AtomicBool::new(false);
        let got = loss_difference(&[1.0, 2.0], &[1.0], &mut [0.0, 0.0], &never);
        assert!(matches!(got, Err(ArxError::ShapeMismatch { .. })));
        let one = loss_difference(&[1.0, 2.0], &[1.0, f64::NAN], &mut [0.0, 0.0], &never).unwrap();
        assert_eq!((one.n, one.mean, one.sums.len()), (1, 0.0, 0));
    }
}
