//! The prediction-error search: Gauss–Newton steps with Levenberg–Marquardt damping, solved by QR
//! of the Jacobian, from the start until the loss stops falling.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::arx::fit::inverse_gram;
use crate::error::{ArxError, Result};
use crate::linalg::levenberg::damped_step;
pub use crate::linalg::levenberg::Termination;
use crate::linalg::qr::{check_rank, rank_tolerance};
use crate::pem::gradient::{evaluate, jacobian_r, sum_squares, Evaluation};
use crate::pem::polynomial::{Initial, PolyStructure, Polys, Segments};
use crate::pem::start::start;

/// Settings of [`pem`].
#[derive(Debug, Clone)]
pub struct PemOptions {
    pub max_iterations: usize,
    /// Relative loss improvement below which the iterations stop.
    pub tolerance: f64,
    pub sriv_iterations: usize,
    pub parallel: bool,
    pub initial: Initial,
}

impl Default for PemOptions {
    fn default() -> Self {
        PemOptions { max_iterations: 100, tolerance: 1e-6, sriv_iterations: 30, parallel: true, initial: Initial::Zero }
    }
}

/// A prediction-error fit.
#[derive(Debug, Clone)]
pub struct PemFit {
    /// Parameters in `getpvec` order (A, B, C, D, F).
    pub theta: Vec<f64>,
    /// The start the iterations began from (after stabilisation).
    pub start: Vec<f64>,
    /// Sum of squared prediction errors on the scored samples.
    pub rss: f64,
    /// Same at the start.
    pub start_rss: f64,
    /// Number of scored samples.
    pub n_rows: usize,
    /// $(J^T J)^{-1}$ at the estimate, row-major p × p (times the noise variance: covariance).
    pub inv_gram: Vec<f64>,
    /// Accepted Gauss–Newton steps.
    pub iterations: usize,
    /// Loss (rss / n_rows) after each accepted step, the start first.
    pub losses: Vec<f64>,
    pub termination: Termination,
    /// With [`Initial::Estimate`]: each scored segment and its initial state η (the prediction error
    /// is $\varepsilon_0(t) - \sum_k \eta_k g(t-k)$, $g$ the impulse response of $1/(C \prod_i F_i)$
    /// from the segment's first sample, $\varepsilon_0$ the error from rest). Empty with `Zero`.
    pub initial_states: Vec<((usize, usize), Vec<f64>)>,
}

/// The loop state of [`pem`]: current polynomials, their evaluation and the Gauss–Newton R.
struct Iterate {
    polys: Polys,
    ev: Evaluation,
    rss: f64,
    r: Vec<f64>,
}

/// What the iterations need besides the parameters: data, delayed inputs, scored rows, settings.
struct Problem<'a, 'b> {
    data: &'a Segments<'b>,
    s: &'a PolyStructure,
    xs: Vec<Vec<f64>>,
    rows: Vec<usize>,
    opts: &'a PemOptions,
    cancel: &'a AtomicBool,
}

impl Problem<'_, '_> {
    fn rss(&self, polys: &Polys) -> f64 {
        sum_squares(&evaluate(self.data, self.s, &self.xs, polys, false, self.opts.initial).eps, &self.rows)
    }

    fn stop(&self) -> Result<()> {
        if self.cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(())
    }

    fn iterate(&self, polys: Polys) -> Result<Iterate> {
        self.stop()?;
        let ev = evaluate(self.data, self.s, &self.xs, &polys, true, self.opts.initial);
        let rss = sum_squares(&ev.eps, &self.rows);
        self.stop()?;
        let r = jacobian_r(&ev, &self.rows, self.opts.parallel);
        Ok(Iterate { polys, ev, rss, r })
    }

    /// The first damped step that lowers the loss (λ raised tenfold until one does), with the λ
    /// it used; None when λ reaches 1e12 first.
    fn damped(&self, it: &Iterate, lambda: &mut f64) -> Result<Option<(Polys, f64, f64)>> {
        let p = self.s.n_params();
        let scale: Vec<f64> = (0..p)
            .map(|j| (0..=j).map(|i| it.r[i + j * (p + 1)].powi(2)).sum::<f64>().sqrt().max(f64::MIN_POSITIVE))
            .collect();
        while *lambda < 1e12 {
            self.stop()?;
            let delta = damped_step(&it.r, p, *lambda, &scale);
            let theta: Vec<f64> = it.polys.theta().iter().zip(&delta).map(|(a, b)| a + b).collect();
            let mut cand = Polys::of(self.s, &theta);
            cand.stabilise();
            let cand_rss = self.rss(&cand);
            if cand_rss.is_finite() && cand_rss < it.rss {
                let used = *lambda;
                *lambda = (*lambda * 0.1).max(1e-12);
                return Ok(Some((cand, cand_rss, used)));
            }
            *lambda *= 10.0;
        }
        Ok(None)
    }
}

/// Minimises the sum of squared prediction errors of `s` on `data` from `start` (or the SRIV /
/// Hannan–Rissanen start when None). With [`Initial::Estimate`] each segment's initial state is
/// estimated as well (projected out of every step, so the covariance of θ accounts for it).
///
/// # Errors
/// `TooFewSamples` when the scored samples do not outnumber the parameters; `RankDeficient` when the
/// gradient's columns are dependent at the start (orders not identifiable on these data);
/// `NotConverged` when the loss is not finite at the start or every step makes it so; `Interrupted`
/// once `cancel` is set (checked between steps and in the start's refinement rounds).
pub fn pem(
    data: &Segments<'_>,
    s: &PolyStructure,
    opts: &PemOptions,
    start_theta: Option<&[f64]>,
    cancel: &AtomicBool,
) -> Result<PemFit> {
    if s.m() != data.m {
        return Err(ArxError::ShapeMismatch { what: "nb (one order per input)".into(), expected: data.m, got: s.m() });
    }
    let p = s.n_params();
    let rows = data.scored(s, opts.initial);
    let nuisance =
        if opts.initial == Initial::Estimate { s.n_initial() * data.longer_than(s.n_initial()).len() } else { 0 };
    if rows.len() < p + nuisance + 1 {
        return Err(ArxError::TooFewSamples { needed: p + nuisance + 1, got: rows.len() });
    }
    let theta0 = match start_theta {
        Some(t) if t.len() == p => t.to_vec(),
        Some(t) => return Err(ArxError::ShapeMismatch { what: "start parameters".into(), expected: p, got: t.len() }),
        None => start(data, s, opts.sriv_iterations, opts.parallel, cancel)?,
    };
    let mut polys = Polys::of(s, &theta0);
    polys.stabilise();
    let xs: Vec<Vec<f64>> = (0..s.m()).map(|i| data.delayed(i, s.nk[i])).collect();
    let problem = Problem { data, s, xs, rows, opts, cancel };
    let mut it = problem.iterate(polys)?;
    if !it.rss.is_finite() {
        return Err(ArxError::NotConverged(
            "the prediction errors of the start are not finite (check the data for huge values)".into(),
        ));
    }
    check_rank(&it.r, p + 1, p, rank_tolerance(problem.rows.len(), p))?;
    let n = problem.rows.len() as f64;
    let mut fit = PemFit {
        theta: it.polys.theta(),
        start: it.polys.theta(),
        rss: it.rss,
        start_rss: it.rss,
        n_rows: problem.rows.len(),
        inv_gram: vec![],
        iterations: 0,
        losses: vec![it.rss / n],
        termination: Termination::MaxIterations,
        initial_states: vec![],
    };
    // A loss at round-off level (noise-free data fitted exactly) is a minimum whatever the gain.
    let exact = 1e-24 * sum_squares(data.y, &problem.rows);
    let mut lambda = 1e-4;
    while fit.iterations < opts.max_iterations {
        let gain: f64 = (0..p).map(|i| it.r[i + p * (p + 1)].powi(2)).sum();
        if gain <= opts.tolerance * it.rss || it.rss <= exact {
            fit.termination = Termination::Converged;
            break;
        }
        let Some((cand, cand_rss, used)) = problem.damped(&it, &mut lambda)? else {
            fit.termination = Termination::Stalled;
            break;
        };
        let improvement = (it.rss - cand_rss) / it.rss;
        it = problem.iterate(cand)?;
        fit.iterations += 1;
        fit.losses.push(it.rss / n);
        // A small gain from a strongly damped step is no sign of a minimum: keep going then.
        if improvement < opts.tolerance && used <= 1e-2 {
            fit.termination = Termination::SmallImprovement;
            break;
        }
    }
    fit.theta = it.polys.theta();
    fit.rss = it.rss;
    fit.inv_gram = inverse_gram(&it.r, p + 1, p);
    if let Some(init) = it.ev.initial {
        fit.initial_states = init.segments.into_iter().zip(init.states).collect();
    }
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pem::lcg;

    #[test]
    fn cancelled_fit_stops_with_interrupted() {
        let mut seed = 5u64;
        let u: Vec<f64> = (0..500).map(|_| lcg(&mut seed)).collect();
        let y: Vec<f64> = (0..500).map(|_| lcg(&mut seed)).collect();
        let segs = [(0usize, 500)];
        let d = Segments::new(&y, &u, 1, &segs).unwrap();
        let s = PolyStructure::new(0, vec![2], 0, 0, vec![2], vec![1]).unwrap();
        let err = pem(&d, &s, &PemOptions::default(), None, &AtomicBool::new(true)).unwrap_err();
        assert_eq!(err, ArxError::Interrupted);
    }

    #[test]
    fn output_error_recovers_the_plant_under_white_output_noise() {
        let n = 4000;
        let mut seed = 11;
        let u: Vec<f64> = (0..n).map(|_| if lcg(&mut seed) > 0.0 { 1.0 } else { -1.0 }).collect();
        let mut x = vec![0.0; n];
        for t in 4..n {
            x[t] = 1.5 * x[t - 1] - 0.7 * x[t - 2] + 0.5 * u[t - 3] + 0.3 * u[t - 4];
        }
        let y: Vec<f64> = x.iter().map(|v| v + 0.3 * lcg(&mut seed)).collect();
        let segs = [(0, n)];
        let d = Segments::new(&y, &u, 1, &segs).unwrap();
        let s = PolyStructure::new(0, vec![2], 0, 0, vec![2], vec![3]).unwrap();
        let f = pem(&d, &s, &PemOptions::default(), None, &AtomicBool::new(false)).unwrap();
        let truth = [0.5, 0.3, -1.5, 0.7];
        for (a, b) in f.theta.iter().zip(truth) {
            assert!((a - b).abs() < 0.03, "{:?}", f.theta);
        }
        assert!(f.termination.converged());
    }
}
