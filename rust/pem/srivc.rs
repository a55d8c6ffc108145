//! State-variable filtering for continuous-time identification (SRIVC): a sampled signal passed
//! through the exact discretisation of `1 / A(s)` in controllable canonical form, whose states are
//! the filtered signal and its first `n − 1` derivatives.
//!
//! The discretisation itself (the matrices below) is computed by the caller for the signal's
//! inter-sample behaviour: for a zero-order hold with an input delay `ℓ·ts + δ`,
//! $x_{k+1} = \Phi x_k + \Gamma_0 v_k + \Gamma_1 v_{k-1}$ with $v_k = s_{k-\ell}$; for a first-order
//! hold (linear interpolation), $x_{k+1} = \Phi x_k + (\Gamma - \Lambda) v_k + \Lambda v_{k+1}$. The
//! kernel takes the three taps `prev`, `cur`, `next` and runs the recursion in each segment from
//! rest.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{ArxError, Result};

/// Samples between two looks at the cancel flag.
const POLL: usize = 1 << 16;

/// The discretised filter: `phi` is `n × n` row-major, `prev`, `cur`, `next` the input vectors of
/// `v(k−1)`, `v(k)` and `v(k+1)`.
#[derive(Debug, Clone)]
pub struct StateFilter {
    pub n: usize,
    pub phi: Vec<f64>,
    pub prev: Vec<f64>,
    pub cur: Vec<f64>,
    pub next: Vec<f64>,
}

impl StateFilter {
    /// Checks the shapes.
    ///
    /// # Errors
    /// `ShapeMismatch` when `phi` is not `n × n` or a tap does not have `n` entries.
    pub fn new(n: usize, phi: Vec<f64>, prev: Vec<f64>, cur: Vec<f64>, next: Vec<f64>) -> Result<Self> {
        if phi.len() != n * n {
            return Err(ArxError::ShapeMismatch { what: "phi".into(), expected: n * n, got: phi.len() });
        }
        for (what, v) in [("prev", &prev), ("cur", &cur), ("next", &next)] {
            if v.len() != n {
                return Err(ArxError::ShapeMismatch { what: what.into(), expected: n, got: v.len() });
            }
        }
        Ok(Self { n, phi, prev, cur, next })
    }
}

/// States of the filter (`n` per sample, row-major `len × n`) driven by `v(k) = signal(k − shift)`
/// in each half-open segment; the filter starts at rest in each segment and `v` is zero before its
/// start (the signal held at rest), held at its last value past its end. Samples outside every
/// segment are NaN.
///
/// # Errors
/// `ShapeMismatch` for a segment beyond the signal; `Interrupted` once `cancel` is set.
pub fn state_filter(
    signal: &[f64],
    segments: &[(usize, usize)],
    f: &StateFilter,
    shift: usize,
    cancel: &AtomicBool,
) -> Result<Vec<f64>> {
    let n = f.n;
    let len = signal.len();
    let mut out = vec![f64::NAN; len * n];
    let mut x = vec![0.0; n];
    let mut nx = vec![0.0; n];
    let mut done = 0usize;
    for &(a, b) in segments {
        if a > b || b > len {
            return Err(ArxError::ShapeMismatch { what: "segment end".into(), expected: len, got: b });
        }
        x.iter_mut().for_each(|v| *v = 0.0);
        // v(k) = signal(k − shift) inside the segment's shifted range, 0 before it (at rest).
        let v = |k: usize| if k >= a + shift { signal[k - shift] } else { 0.0 };
        let (mut vp, mut vc) = (0.0, if a < b { v(a) } else { 0.0 });
        for (k, row_out) in out[a * n..b * n].chunks_exact_mut(n).enumerate() {
            let k = a + k;
            row_out.copy_from_slice(&x);
            let vn = if k + 1 < b { v(k + 1) } else { vc };
            for (i, (nxi, row)) in nx.iter_mut().zip(f.phi.chunks_exact(n)).enumerate() {
                let s: f64 = row.iter().zip(x.iter()).map(|(p, xj)| p * xj).sum();
                *nxi = s + f.prev[i] * vp + f.cur[i] * vc + f.next[i] * vn;
            }
            std::mem::swap(&mut x, &mut nx);
            (vp, vc) = (vc, vn);
            done += 1;
            if done.is_multiple_of(POLL) && cancel.load(Ordering::Relaxed) {
                return Err(ArxError::Interrupted);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn first_order(a: f64, ts: f64) -> StateFilter {
        // 1/(s + a), ZOH: phi = e^{-a ts}, gamma = (1 - phi)/a.
        let phi = (-a * ts).exp();
        StateFilter::new(1, vec![phi], vec![0.0], vec![(1.0 - phi) / a], vec![0.0]).unwrap()
    }

    #[test]
    fn step_response_of_a_first_order_filter_is_exact() {
        let (a, ts) = (2.0, 0.1);
        let u = vec![1.0; 50];
        let out = state_filter(&u, &[(0, 50)], &first_order(a, ts), 0, &AtomicBool::new(false)).unwrap();
        for (k, v) in out.iter().enumerate() {
            let exact = (1.0 - (-a * ts * k as f64).exp()) / a;
            assert!((v - exact).abs() < 1e-14, "{k}: {v} vs {exact}");
        }
    }

    #[test]
    fn first_order_hold_taps_filter_a_ramp_exactly() {
        // 1/(s + a) driven by v(t) = t, linear between samples: x(t) = t/a − (1 − e^{−at})/a².
        let (a, ts): (f64, f64) = (1.5, 0.2);
        let phi = (-a * ts).exp();
        let gamma = (1.0 - phi) / a;
        let lam = (ts / a - (1.0 - phi) / (a * a)) / ts;
        let f = StateFilter::new(1, vec![phi], vec![0.0], vec![gamma - lam], vec![lam]).unwrap();
        let ramp: Vec<f64> = (0..40).map(|k| k as f64 * ts).collect();
        let out = state_filter(&ramp, &[(0, 40)], &f, 0, &AtomicBool::new(false)).unwrap();
        for (k, v) in out.iter().enumerate() {
            let t = k as f64 * ts;
            let exact = t / a - (1.0 - (-a * t).exp()) / (a * a);
            assert!((v - exact).abs() < 1e-13, "{k}: {v} vs {exact}");
        }
    }

    #[test]
    fn segments_restart_from_rest_and_shift_stays_inside() {
        let u = vec![1.0; 20];
        let f = first_order(1.0, 0.5);
        let out = state_filter(&u, &[(0, 8), (10, 20)], &f, 2, &AtomicBool::new(false)).unwrap();
        assert!(out[8].is_nan() && out[9].is_nan());
        // Two samples of shift: zero input for the first two steps of each segment.
        assert_eq!(&out[0..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&out[10..13], &[0.0, 0.0, 0.0]);
        assert!(out[3] > 0.0 && (out[3] - out[13]).abs() < 1e-15);
    }

    #[test]
    fn shapes_and_cancel_are_checked() {
        assert!(StateFilter::new(2, vec![0.0; 3], vec![0.0; 2], vec![0.0; 2], vec![0.0; 2]).is_err());
        let f = first_order(1.0, 0.1);
        assert!(state_filter(&[1.0; 3], &[(0, 4)], &f, 0, &AtomicBool::new(false)).is_err());
        let big = vec![1.0; POLL + 1];
        let err = state_filter(&big, &[(0, big.len())], &f, 0, &AtomicBool::new(true)).unwrap_err();
        assert_eq!(err, ArxError::Interrupted);
    }
}
