//! Prediction and free-run simulation of a fitted structure.
//!
//! Horizon 1 is the one-step predictor (measured past outputs), horizon k runs the model k steps
//! from measured outputs up to t−k, and free run (no horizon) feeds back only simulated outputs.
//! Output-derived effect terms are evaluated on the same outputs the AR part uses, so in free run
//! `y^3` reads the simulated output, never the measured one.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::arx::structure::{Data, Structure};
use crate::error::{ArxError, Result};

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

/// Whether every input sample the structure reads at time `t` is finite.
fn inputs_finite(d: &Data, s: &Structure, t: usize) -> bool {
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            if !d.u_at(t - k - j, i).is_finite() {
                return false;
            }
        }
    }
    s.output_terms.iter().all(|term| term.multiplier.is_none_or(|m| d.u_at(t - 1, m).is_finite()))
}

/// Predicted output for every sample (NaN for the first `max(first_lag, lag)` samples of each
/// experiment, which only serve as initial conditions).
///
/// `horizon = None` is free-run simulation; `Some(k)` the k-step-ahead prediction. Samples whose
/// inputs are missing (NaN) predict NaN, and the simulation restarts from measured outputs after them.
pub fn predict(d: &Data, s: &Structure, theta: &[f64], horizon: Option<usize>, first_lag: usize) -> Vec<f64> {
    let never = AtomicBool::new(false);
    predict_cancellable(d, s, theta, horizon, first_lag, &never).unwrap_or_else(|_| vec![f64::NAN; d.len()])
}

/// Whether experiment `[a, b)` has finite inputs and finite initial outputs `[a, start)`: then the
/// free run never restarts from measurements and is a plain recursion.
pub(crate) fn complete(d: &Data, a: usize, start: usize, b: usize) -> bool {
    d.y[a..start].iter().all(|v| v.is_finite()) && d.u[a * d.m..b * d.m].iter().all(|v| v.is_finite())
}

/// Samples (or k-step windows) between two looks at the cancel flag of [`predict_cancellable`].
const CANCEL_EVERY: usize = 4096;

/// As [`predict`], checking `cancel` every [`CANCEL_EVERY`] samples (a k-step prediction with a
/// long horizon costs O(N k p) and may run for minutes).
///
/// # Errors
/// `Interrupted` once `cancel` is set.
pub fn predict_cancellable(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
) -> Result<Vec<f64>> {
    // Zero pages from the system, not a NaN pass: every sample is written.
    let mut out = vec![0.0; d.len()];
    predict_paths(d, s, theta, horizon, first_lag, cancel, true, &mut out)?;
    Ok(out)
}

/// As [`predict_cancellable`], into `out` (`d.len()` long; every sample is written), so that the
/// caller chooses the allocation (Python's numpy array).
///
/// # Errors
/// `Interrupted` once `cancel` is set.
///
/// # Panics
/// When `out.len() != d.len()`.
pub fn predict_into(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
    out: &mut [f64],
) -> Result<()> {
    predict_paths(d, s, theta, horizon, first_lag, cancel, true, out)
}

/// [`predict_into`]; `fast = false` sends every structure through the general step (the
/// reference the tests hold the fast paths of [`crate::simulate::linear_predict`] to).
#[allow(clippy::too_many_arguments)]
fn predict_paths(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
    fast: bool,
    out: &mut [f64],
) -> Result<()> {
    assert_eq!(out.len(), d.len(), "one prediction per sample");
    let stop = |t: usize, work: usize| {
        t.is_multiple_of((CANCEL_EVERY / work.clamp(1, CANCEL_EVERY)).max(1)) && cancel.load(Ordering::Relaxed)
    };
    let lag = first_lag.max(s.max_lag());
    // Every path below writes each sample it predicts; the samples before each experiment's first
    // prediction are set to NaN here.
    for (a, b) in d.segments() {
        let start = a + lag;
        out[a..start.min(b)].fill(f64::NAN);
        if start >= b {
            continue;
        }
        let linear = fast && s.output_terms.is_empty();
        match horizon {
            // Without output terms: vectorised passes (and a one-multiply-add chain in free run).
            Some(k) if k <= 1 && linear => {
                crate::simulate::linear_predict::one_step(d, s, theta, (start, b), out, cancel)?
            }
            // A free run that stays finite read no missing sample; otherwise the data are scanned,
            // and a missing sample calls for the general step (which restarts after it).
            None if linear
                && (crate::simulate::linear_predict::free_run(d, s, theta, (start, b), out, cancel)?
                    || complete(d, a, start, b)) => {}
            // With output terms, complete data never restart the simulation: a plain recursion.
            None if fast
                && complete(d, a, start, b)
                && crate::simulate::term_free_run::free_run(d, s, theta, (start, b), out, cancel)? => {}
            Some(k) if k <= 1 => {
                for (t, o) in out.iter_mut().enumerate().take(b).skip(start) {
                    if stop(t, 1) {
                        return Err(ArxError::Interrupted);
                    }
                    *o = step(d, s, theta, t, &|i| d.y[t - i]);
                }
            }
            None => restarting_free_run(d, s, theta, (a, start, b), out, cancel, fast && s.output_terms.is_empty())?,
            Some(k) => {
                // Beyond the segment every prediction starts from the measured initial outputs, so a
                // longer horizon changes nothing (and must not size the buffer).
                let k = k.min(b - start);
                let mut local = vec![0.0f64; k];
                for t in start..b {
                    if stop(t, k) {
                        return Err(ArxError::Interrupted);
                    }
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
    Ok(())
}

/// The free run of experiment `[a, b)` from `start` when a sample is missing: sample by sample,
/// y(t) taken from the data where `from_measurement[t]` (initial conditions, and samples whose
/// inputs or measured initial outputs are missing, after which the simulation restarts from the
/// measurements). A simulation that overflows is not restarted: its NaN/inf propagate so the
/// divergence stays visible.
///
/// With `linear` (no output terms), every stretch that starts from measured outputs only and reads
/// no missing input runs as the fast recursion ([`crate::simulate::linear_predict::free_run`]),
/// which the general step would repeat sample by sample (to rounding): after a gap, the run
/// restarts that way, and only the samples around the gap take the general step.
fn restarting_free_run(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    (a, start, b): (usize, usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
    linear: bool,
) -> Result<()> {
    // The simulated outputs are `out` itself: a sample is read back only once written (the
    // samples before `start` are always taken from the data).
    let mut from_measurement = vec![true; b - a];
    let reach = s.max_lag().max(1);
    let mut general_until = start; // a stretch whose fast run overflowed takes the general step
    let mut t = start;
    while t < b {
        if linear && t >= general_until && measured_history(d, s.na, t, &from_measurement[..t - a]) {
            let end = finite_inputs_end(d, s, t, b);
            if end > t {
                if crate::simulate::linear_predict::free_run(d, s, theta, (t, end), out, cancel)? {
                    from_measurement[t - a..end - a].fill(false);
                    t = end;
                    continue;
                }
                general_until = end;
            }
        }
        if t.is_multiple_of(CANCEL_EVERY) && cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let v = {
            let (sim, meas) = (&*out, &from_measurement);
            step(d, s, theta, t, &|i| if meas[t - i - a] { d.y[t - i] } else { sim[t - i] })
        };
        let missing_history = (1..=reach.min(t - a)).any(|i| from_measurement[t - i - a] && d.y[t - i].is_nan());
        from_measurement[t - a] = v.is_nan() && (missing_history || !inputs_finite(d, s, t));
        out[t] = v;
        t += 1;
    }
    Ok(())
}

/// Whether the `na` outputs before `t` are all taken from the data and finite (`from_measurement`
/// up to sample `t`, from the experiment's first): a free run from `t` then starts as from the
/// experiment's own initial conditions.
fn measured_history(d: &Data, na: usize, t: usize, from_measurement: &[bool]) -> bool {
    let n = from_measurement.len();
    (1..=na).all(|i| from_measurement[n - i] && d.y[t - i].is_finite())
}

/// The first sample from `t` on (`b` at most) at which the structure reads a missing input.
fn finite_inputs_end(d: &Data, s: &Structure, t: usize, b: usize) -> usize {
    let mut end = b;
    for (i, (&nb, &nk)) in s.nb.iter().zip(&s.nk).enumerate() {
        if nb == 0 {
            continue;
        }
        // Sample p of input i is read from p + nk to p + nk + nb − 1: the first missing one from
        // the oldest read at t ends the stretch at p + nk (at t itself when t reads it).
        let mut p = t - nk - (nb - 1);
        while p + nk < end && d.u_at(p, i).is_finite() {
            p += 1;
        }
        end = end.min((p + nk).max(t));
    }
    end
}

/// [`predict`] through the general step only, whatever the structure: the reference for the fast
/// linear paths.
#[cfg(test)]
pub(crate) fn step_reference(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
) -> Vec<f64> {
    let mut out = vec![0.0; d.len()];
    predict_paths(d, s, theta, horizon, first_lag, &AtomicBool::new(false), false, &mut out).unwrap();
    out
}

/// k-step-ahead prediction of a linear structure (no output terms) on complete data: the same
/// numbers as [`predict`] with `Some(k)` (up to rounding) at a cost of O(N (na + nb)) for any k,
/// computed as a filter by [`crate::simulate::kstep::predict_k`].
///
/// # Panics
/// When `s` has output terms or `k == 0`.
pub fn predict_k_linear(d: &Data, s: &Structure, theta: &[f64], k: usize, first_lag: usize) -> Vec<f64> {
    crate::simulate::kstep::predict_k(d, s, theta, k, first_lag)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::kstep::predict_k;
    use crate::simulate::score::free_run_rms_linear;

    /// The linear paths of [`crate::simulate::linear_predict`] give the general step's numbers to rounding
    /// (they sum in another order), and the same bits on every run; the same data with one NaN
    /// input in a later experiment (a restart) still takes the general step there.
    #[test]
    fn linear_paths_match_the_general_step() {
        let n = 400;
        let mut u: Vec<f64> = (0..2 * n).map(|t| (((t * 7919) % 17) as f64 - 8.0) * 0.37).collect();
        let y: Vec<f64> = (0..n).map(|t| ((t * 104_729) % 23) as f64 * 0.11 - 1.2).collect();
        u[2 * 350] = f64::NAN; // experiment 2 has a gap: the general path
        let starts = [0, 200];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let s = Structure::new(3, vec![2, 3], vec![1, 0], vec![]).unwrap();
        let theta = [-0.9, 0.3, -0.05, 0.5, 0.25, 0.1, -0.2, 0.07];
        let never = AtomicBool::new(false);
        for horizon in [None, Some(1)] {
            let fast = predict(&d, &s, &theta, horizon, 4);
            let mut general = vec![f64::NAN; n];
            for t in 4..200 {
                let past = |i: usize| if horizon.is_some() || t - i < 4 { y[t - i] } else { general[t - i] };
                general[t] = step(&d, &s, &theta, t, &past);
            }
            assert!((4..200).all(|t| (fast[t] - general[t]).abs() <= 1e-13 * general[t].abs().max(1.0)), "{horizon:?}");
            assert!((0..4).all(|t| fast[t].is_nan()));
            let again = predict_cancellable(&d, &s, &theta, horizon, 4, &never).unwrap();
            assert!(fast.iter().zip(&again).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

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

    #[test]
    fn k_step_filter_equals_step_by_step_prediction() {
        let n = 700;
        let u: Vec<f64> = (0..2 * n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.9 * y[t - 1] - 0.905 * y[t - 2]
                + 0.3 * u[2 * (t - 2)]
                + 0.1 * u[2 * (t - 3) + 1]
                + 0.01 * ((t * 31 % 7) as f64 - 3.0);
        }
        let starts = [0, 300];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let s = Structure::new(3, vec![2, 1], vec![1, 3], vec![]).unwrap();
        let theta = [-1.8, 0.85, -0.03, 0.3, 0.05, 0.1];
        for k in [1, 2, 5, 17] {
            let slow = predict(&d, &s, &theta, Some(k), 9);
            let fast = predict_k_linear(&d, &s, &theta, k, 9);
            for (t, (a, b)) in slow.iter().zip(&fast).enumerate() {
                assert_eq!(a.is_nan(), b.is_nan(), "t={t} k={k}");
                if a.is_finite() {
                    assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "t={t} k={k}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn filter_equals_step_by_step_prediction_for_any_horizon() {
        let n = 900;
        let u: Vec<f64> = (0..n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.6 * y[t - 1] - 0.8 * y[t - 2] + 0.3 * u[t - 2] + 0.02 * ((t * 31 % 7) as f64 - 3.0);
        }
        let starts = [0, 400];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![2], vec![]).unwrap();
        let theta = [-1.55, 0.78, 0.29, 0.01];
        for k in [1, 2, 3, 7, 64, 399, 500, 10_000] {
            let slow = predict(&d, &s, &theta, Some(k), 4);
            let fast = predict_k(&d, &s, &theta, k, 4);
            for (t, (a, b)) in slow.iter().zip(&fast).enumerate() {
                assert_eq!(a.is_nan(), b.is_nan(), "t={t} k={k}");
                if a.is_finite() {
                    assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "t={t} k={k}: {a} vs {b}");
                }
            }
        }
    }
}
