//! k-step-ahead prediction of a linear ARX structure as a filter: O(N (na + nb)) for any horizon k.
//!
//! By linearity, the prediction from measured outputs up to `c = t − k` equals any free run `s` of
//! the model plus the response of its AR part to the difference between measured and simulated
//! outputs at `c, c − 1, …, c − na + 1`:
//! $\hat y(t \mid c) = s(t) + \sum_{i<n_a} g_{k,i} \, (y(c-i) - s(c-i))$,
//! where $g_{k,i}$ is what the homogeneous recursion $A(q) y = 0$ makes of a unit initial output
//! at lag i after k steps. The free run is restarted from measured outputs every k samples (each
//! run covers 2k − 1 samples), so neither its drift nor an unstable model's growth accumulates
//! over the record: the work is about 2 N (na + nb) plus N na, whatever k is.

use crate::arx::structure::{Data, Structure};

/// $g_{k,i}$ for i < na: $y(c + k) = \sum_i g_{k,i} \, y(c - i)$ under $A(q) y = 0$.
///
/// With h the impulse response of 1/A (h(0) = 1, h(n < 0) = 0),
/// $g_{k,i} = -\sum_{j=i+1}^{n_a} a_j \, h(k + i - j)$; h is needed up to k − 1 (O(k na) work).
pub fn homogeneous_gains(a: &[f64], k: usize) -> Vec<f64> {
    let na = a.len();
    let mut h = vec![0.0; k.max(1)];
    h[0] = 1.0;
    for n in 1..k {
        let mut v = 0.0;
        for (j, aj) in a.iter().enumerate().take(n.min(na)) {
            v -= aj * h[n - j - 1];
        }
        h[n] = v;
    }
    (0..na)
        .map(|i| {
            let mut g = 0.0;
            for j in (i + 1)..=na {
                // h(k + i − j); k + i − j ≤ k − 1 since j ≥ i + 1, and < 0 contributes nothing.
                if let Some(idx) = (k + i).checked_sub(j) {
                    g -= a[j - 1] * h[idx];
                }
            }
            g
        })
        .collect()
}

/// One step of the linear recursion at time `t`, outputs read from `hist(i)` = the output i back.
#[inline]
fn step(d: &Data, s: &Structure, theta: &[f64], t: usize, hist: impl Fn(usize) -> f64) -> f64 {
    let mut acc = 0.0;
    for i in 1..=s.na {
        acc -= theta[i - 1] * hist(i);
    }
    let mut c = s.na;
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            acc += theta[c] * d.u_at(t - k - j, i);
            c += 1;
        }
    }
    acc
}

/// [`predict_k`] when the filter applies, a structure without output terms on data without a
/// missing sample (the k-step predictor of a linear structure is a filter: O(N (na + nb)) for any
/// k); None otherwise, for the general step to predict.
pub fn predict_k_by_filter(d: &Data, s: &Structure, theta: &[f64], k: usize, first_lag: usize) -> Option<Vec<f64>> {
    // Scanned only for a k-step prediction (a pass over all the data).
    let complete = s.output_terms.is_empty() && d.y.iter().chain(d.u).all(|v| v.is_finite());
    complete.then(|| predict_k(d, s, theta, k, first_lag))
}

/// k-step-ahead prediction (k ≥ 1) of a linear structure (no output terms) on finite data; NaN
/// for the first `max(first_lag, lag)` samples of each experiment. Predictions within k − 1 samples
/// of an experiment's first predicted sample start from the measured outputs before it (shorter
/// horizons), as the step-by-step prediction does.
///
/// # Panics
/// When `s` has output terms, `k == 0` or `theta` does not match `s`.
pub fn predict_k(d: &Data, s: &Structure, theta: &[f64], k: usize, first_lag: usize) -> Vec<f64> {
    assert!(s.output_terms.is_empty() && k >= 1 && theta.len() == s.n_params());
    let lag = first_lag.max(s.max_lag());
    let mut out = vec![f64::NAN; d.len()];
    for (a, b) in d.segments() {
        let start = a + lag;
        if start >= b {
            continue;
        }
        // Beyond the experiment every prediction starts from the outputs before `start`.
        let k = k.min(b - start);
        let gains = homogeneous_gains(&theta[..s.na], k);
        predict_segment(d, s, theta, k, &gains, (a, start, b), &mut out);
    }
    out
}

/// [`predict_k`] on one experiment `[a, b)` whose predictions start at `start`.
fn predict_segment(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    k: usize,
    gains: &[f64],
    (a, start, b): (usize, usize, usize),
    out: &mut [f64],
) {
    let na = s.na;
    // `sim[τ − base]` for τ in [base, run_start + 2k − 1): measured before the run, simulated from it.
    let mut sim = vec![0.0; 2 * k + na];
    let mut run_start = start;
    // Run r predicts [run_start + k − 1, run_start + 2k − 1); run 0 also [start, start + k − 1).
    let mut first_out = start;
    while first_out < b {
        let base = run_start.saturating_sub(na).max(a);
        let end = (run_start + 2 * k - 1).min(b);
        sim[..run_start - base].copy_from_slice(&d.y[base..run_start]);
        for tau in run_start..end {
            let v = step(d, s, theta, tau, |i| if tau - i >= base { sim[tau - i - base] } else { d.y[tau - i] });
            sim[tau - base] = v;
        }
        for t in first_out..end {
            let mut v = sim[t - base];
            // Measured outputs up to c = t − k; before the run they equal the simulation's.
            if let Some(c) = t.checked_sub(k).filter(|&c| c >= run_start) {
                for (i, g) in gains.iter().enumerate() {
                    let tau = c - i;
                    if tau >= run_start {
                        v += g * (d.y[tau] - sim[tau - base]);
                    }
                }
            }
            out[t] = v;
        }
        first_out = end;
        run_start += k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homogeneous_gains_follow_the_recursion() {
        let a = [-1.5, 0.7, 0.1];
        for k in 1..12 {
            let g = homogeneous_gains(&a, k);
            for i in 0..3 {
                // Unit initial output at lag i, run k steps.
                let mut hist = vec![0.0; 3 + k];
                hist[2 - i] = 1.0;
                for n in 3..3 + k {
                    hist[n] = -(a[0] * hist[n - 1] + a[1] * hist[n - 2] + a[2] * hist[n - 3]);
                }
                assert!((hist[2 + k] - g[i]).abs() < 1e-12, "k={k} i={i}: {} vs {}", hist[2 + k], g[i]);
            }
        }
    }

    #[test]
    fn an_fir_structure_ignores_the_horizon() {
        let u: Vec<f64> = (0..50).map(|t| (t % 5) as f64).collect();
        let y = vec![1.0; 50];
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(0, vec![2], vec![1], vec![]).unwrap();
        let one = predict_k(&d, &s, &[0.5, 0.25], 1, 0);
        let many = predict_k(&d, &s, &[0.5, 0.25], 9, 0);
        assert_eq!(
            one.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            many.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}
