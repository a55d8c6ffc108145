//! Prediction of a fitted polynomial model: k steps ahead from the prediction errors, or the free
//! run, with each segment's initial state at rest or fitted to the data.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{ArxError, Result};
use crate::pem::gradient::{evaluate, fit_initial};
use crate::pem::polynomial::{conv, filter, Initial, PolyStructure, Polys, Segments};

/// Predicted output: `horizon = Some(k)` the k-step-ahead predictor
/// $\hat y(t|t-k) = y(t) - \sum_{j<k} h_j\, \varepsilon(t-j)$ ($h$ the impulse response of
/// $C/(A D)$), `None` the free run $\sum_i B_i/(A F_i)\, u_i$. NaN outside the scored samples.
/// With [`Initial::Estimate`] the initial state of each segment is fitted to the data first: to
/// the prediction errors for a horizon, to the output for the free run (as MATLAB's `compare`).
pub fn predict(
    data: &Segments<'_>,
    s: &PolyStructure,
    theta: &[f64],
    horizon: Option<usize>,
    initial: Initial,
) -> Vec<f64> {
    let never = AtomicBool::new(false);
    predict_cancellable(data, s, theta, horizon, initial, &never).unwrap_or_else(|_| vec![f64::NAN; data.y.len()])
}

/// As [`predict`], checking `cancel` between the filters of the free run and, in a k-step
/// prediction (O(N k)), every few thousand multiply-adds.
///
/// # Errors
/// `Interrupted` once `cancel` is set.
pub fn predict_cancellable(
    data: &Segments<'_>,
    s: &PolyStructure,
    theta: &[f64],
    horizon: Option<usize>,
    initial: Initial,
    cancel: &AtomicBool,
) -> Result<Vec<f64>> {
    let stopped = || cancel.load(Ordering::Relaxed);
    let p = Polys::of(s, theta);
    let xs: Vec<Vec<f64>> = (0..s.m()).map(|i| data.delayed(i, s.nk[i])).collect();
    let mut out = vec![f64::NAN; data.y.len()];
    match horizon {
        None => {
            let mut sim = vec![0.0; data.y.len()];
            for ((b, f), x) in p.b.iter().zip(&p.f).zip(&xs) {
                if stopped() {
                    return Err(ArxError::Interrupted);
                }
                let w = data.filter(b, &conv(&p.a, f), x);
                sim.iter_mut().zip(&w).for_each(|(a, b)| *a += b);
            }
            if stopped() {
                return Err(ArxError::Interrupted);
            }
            let rows = match initial {
                Initial::Zero => data.rows(s.max_lag()),
                Initial::Estimate => free_run_initial(data, s, &p, &mut sim),
            };
            rows.iter().for_each(|&t| out[t] = sim[t]);
        }
        Some(k) => {
            let ev = evaluate(data, s, &xs, &p, false, initial);
            let every = (4096 / k.max(1)).max(1);
            let (lag, segments) = match &ev.initial {
                None => (s.max_lag(), data.segments.to_vec()),
                Some(init) => (0, init.segments.clone()),
            };
            let mut impulse = vec![0.0; k];
            impulse[0] = 1.0;
            let mut h = vec![0.0; k];
            filter(&p.c, &conv(&p.a, &p.d), &impulse, &mut h);
            for (a, b) in segments {
                for (t, o) in out.iter_mut().enumerate().take(b).skip((a + lag).min(b)) {
                    if t % every == 0 && stopped() {
                        return Err(ArxError::Interrupted);
                    }
                    let e: f64 = (0..k.min(t - a + 1)).map(|j| h[j] * ev.eps[t - j]).sum();
                    *o = data.y[t] - e;
                }
            }
        }
    }
    Ok(out)
}

/// Adds to the free run `sim` the free response of each segment's initial state fitted to the
/// output (numerator over $A \prod_i F_i$); returns the samples it predicts.
fn free_run_initial(data: &Segments<'_>, s: &PolyStructure, p: &Polys, sim: &mut [f64]) -> Vec<usize> {
    let den = p.f.iter().fold(p.a.clone(), |acc, f| conv(&acc, f));
    let gap: Vec<f64> = data.y.iter().zip(sim.iter()).map(|(y, m)| y - m).collect();
    let fit = fit_initial(data, &den, s.n_initial_free_run(), &gap, false);
    sim.iter_mut().zip(&fit.response).for_each(|(m, r)| *m += r);
    fit.segments.into_iter().flat_map(|(a, b)| a..b).collect()
}
