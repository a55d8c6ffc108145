//! Prediction and free-run simulation of a fitted structure.
//!
//! Horizon 1 is the one-step predictor (measured past outputs), horizon k runs the model k steps
//! from measured outputs up to t−k, and free run (no horizon) feeds back only simulated outputs.
//! Output-derived effect terms are evaluated on the same outputs the AR part uses, so in free run
//! `y^3` reads the simulated output, never the measured one.

use crate::structure::{Data, Structure};

/// Sum of the input (FIR) part and effect inputs at time `t` plus the AR and output-term parts
/// evaluated on `hist(i)` = the output i steps back.
#[inline]
fn step(d: &Data, s: &Structure, theta: &[f64], t: usize, hist: &dyn Fn(usize) -> f64) -> f64 {
    let mut acc = 0.0;
    let mut c = 0;
    for i in 1..=s.na {
        acc -= theta[c] * hist(i);
        c += 1;
    }
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            acc += theta[c] * d.u_at(t - k - j, i);
            c += 1;
        }
    }
    for term in &s.output_terms {
        let y2 = if term.lag() >= 2 { hist(2) } else { 0.0 };
        let s1 = term.multiplier.map_or(1.0, |m| d.u_at(t - 1, m));
        acc += theta[c] * term.eval(hist(1), y2, s1);
        c += 1;
    }
    acc
}

/// Predicted output for every sample (NaN for the first `max(first_lag, lag)` samples of each
/// experiment, which only serve as initial conditions).
///
/// `horizon = None` is free-run simulation; `Some(k)` the k-step-ahead prediction. Samples whose
/// inputs are missing (NaN) predict NaN, and the simulation restarts from measured outputs after them.
pub fn predict(d: &Data, s: &Structure, theta: &[f64], horizon: Option<usize>, first_lag: usize) -> Vec<f64> {
    let n = d.len();
    let lag = first_lag.max(s.max_lag());
    let mut out = vec![f64::NAN; n];
    for (a, b) in d.segments() {
        let start = a + lag;
        if start >= b {
            continue;
        }
        match horizon {
            Some(k) if k <= 1 => {
                for t in start..b {
                    out[t] = step(d, s, theta, t, &|i| d.y[t - i]);
                }
            }
            None => {
                // `sim[t]` NaN marks a sample to take from the measurement (initial or after a gap).
                let mut sim = vec![f64::NAN; b - a];
                for t in start..b {
                    let v = {
                        let sim_ref = &sim;
                        step(d, s, theta, t, &|i| {
                            let v = sim_ref[t - i - a];
                            if v.is_nan() {
                                d.y[t - i]
                            } else {
                                v
                            }
                        })
                    };
                    sim[t - a] = v;
                    out[t] = v;
                }
            }
            Some(k) => {
                let mut local = vec![0.0f64; k];
                for t in start..b {
                    let t0 = (t + 1).saturating_sub(k).max(start);
                    for tau in t0..=t {
                        let v = {
                            let loc = &local;
                            step(d, s, theta, tau, &|i| {
                                if tau >= t0 + i {
                                    let v = loc[tau - i - t0];
                                    if v.is_nan() {
                                        d.y[tau - i]
                                    } else {
                                        v
                                    }
                                } else {
                                    d.y[tau - i]
                                }
                            })
                        };
                        local[tau - t0] = v;
                    }
                    out[t] = local[t - t0];
                }
            }
        }
    }
    out
}

/// Outcome of a free-run (or k-step) check of one structure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimScore {
    /// Root mean square of measured − simulated output over the scored samples (NaN if diverged).
    pub rms: f64,
    /// Number of samples scored.
    pub n: usize,
    /// The simulation left any plausible range and was stopped.
    pub diverged: bool,
}

/// Free-run RMS of a linear structure (no output terms), the hot loop of a sweep.
///
/// The input part is accumulated first in a vectorisable pass; only the AR recursion is sequential.
/// A simulation whose output exceeds `limit` in magnitude is stopped and reported as diverged.
pub fn free_run_rms_linear(d: &Data, s: &Structure, theta: &[f64], first_lag: usize, limit: f64, fir: &mut Vec<f64>) -> SimScore {
    debug_assert!(s.output_terms.is_empty());
    let lag = first_lag.max(s.max_lag());
    let na = s.na;
    let a = &theta[..na];
    let mut sse = 0.0;
    let mut count = 0usize;
    for (sa, sb) in d.segments() {
        let start = sa + lag;
        if start >= sb {
            continue;
        }
        let len = sb - start;
        fir.clear();
        fir.resize(len, 0.0);
        let mut c = na;
        for (i, (&nb, &nk)) in s.nb.iter().zip(&s.nk).enumerate() {
            for j in 0..nb {
                let bj = theta[c];
                c += 1;
                let off = start - nk - j;
                let m = d.m;
                for (idx, f) in fir.iter_mut().enumerate() {
                    *f += bj * d.u[(off + idx) * m + i];
                }
            }
        }
        // AR recursion with a small history buffer of simulated outputs (initial: measured).
        let mut hist = [0.0f64; 64];
        let big = na > 64;
        let mut hist_vec = if big { vec![0.0; na] } else { Vec::new() };
        let h: &mut [f64] = if big { &mut hist_vec } else { &mut hist[..na] };
        for (i, hv) in h.iter_mut().enumerate() {
            *hv = d.y[start - 1 - i];
        }
        for (idx, &f) in fir.iter().enumerate() {
            let mut v = f;
            for i in 0..na {
                v -= a[i] * h[i];
            }
            if !(v.abs() <= limit) {
                if v.is_nan() && d.y[start + idx].is_nan() {
                    // A missing sample, not a divergence: handled by the generic path.
                }
                return SimScore { rms: f64::NAN, n: count, diverged: true };
            }
            if na > 0 {
                h.copy_within(0..na - 1, 1);
                h[0] = v;
            }
            let e = d.y[start + idx] - v;
            if e.is_finite() {
                sse += e * e;
                count += 1;
            }
        }
    }
    SimScore { rms: if count > 0 { (sse / count as f64).sqrt() } else { f64::NAN }, n: count, diverged: false }
}

/// RMS of measured − predicted over the samples where both are finite; diverged when a prediction
/// exceeds `limit` or is infinite.
pub fn score(d: &Data, pred: &[f64], limit: f64) -> SimScore {
    let mut sse = 0.0;
    let mut n = 0;
    for (yt, pt) in d.y.iter().zip(pred) {
        if pt.is_infinite() || pt.abs() > limit {
            return SimScore { rms: f64::NAN, n, diverged: true };
        }
        let e = yt - pt;
        if e.is_finite() {
            sse += e * e;
            n += 1;
        }
    }
    SimScore { rms: if n > 0 { (sse / n as f64).sqrt() } else { f64::NAN }, n, diverged: false }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_run_reproduces_noise_free_system_and_fast_path_agrees() {
        let n = 500;
        let u: Vec<f64> = (0..n).map(|t| ((t * 7919) % 13) as f64 - 6.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.3 * u[t - 2] + 0.1 * u[t - 3];
        }
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![2], vec![]).unwrap();
        let theta = [-1.2, 0.5, 0.3, 0.1];
        let sim = predict(&d, &s, &theta, None, 0);
        for t in 3..n {
            assert!((sim[t] - y[t]).abs() < 1e-9);
        }
        let k5 = predict(&d, &s, &theta, Some(5), 0);
        assert!((k5[100] - y[100]).abs() < 1e-9);
        let mut fir = Vec::new();
        let sc = free_run_rms_linear(&d, &s, &theta, 0, 1e6, &mut fir);
        assert!(sc.rms < 1e-9 && !sc.diverged);
        let bad = [-2.5, 0.5, 0.3, 0.1];
        assert!(free_run_rms_linear(&d, &s, &bad, 0, 1e6, &mut fir).diverged);
    }
}
