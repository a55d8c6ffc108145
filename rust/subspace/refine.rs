//! The prediction-error refinement of a state-space model in innovation form: Levenberg–Marquardt
//! on the sum of squared one-step prediction errors over (A, B, C, D, K, x0), from the subspace
//! estimate.
//!
//! The parameterisation is the full one (every entry of every matrix) searched in data-driven local
//! coordinates (McKelvey, Helmersson & Ribarits, Automatica 40, 2004): a similarity transform
//! `T` changes every matrix but not the predictions, so the n² directions of the similarity class
//! at the current model are removed and each step moves orthogonally to them. The search
//! directions are an orthonormal basis Q of the complement of that tangent (from its SVD),
//! renewed at every iteration, and the Jacobian in them is `J Q`. Unlike a canonical form, these
//! coordinates are well conditioned wherever the model is minimal, for any order and number of
//! outputs. The Jacobian `J = ∂ε/∂θ` comes from forward sensitivities ([`super::innovation`]) and
//! is reduced by streamed QR, never held.
//!
//! A step is accepted only when it lowers the loss and keeps the predictor stable (the
//! eigenvalues of A − KC inside the unit circle), and A stable too when asked.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::Mat;

use super::hankel::Signals;
use super::innovation::{jacobian_factor, loss, Innovation, Layout};
use crate::error::{ArxError, Result};
use crate::linalg::levenberg::{damped_step, Termination};
use crate::linalg::qr::small_qr;

/// Settings of [`refine`].
#[derive(Clone, Copy, Debug)]
pub struct RefineOptions {
    pub max_iterations: usize,
    /// Relative loss improvement below which the iterations stop.
    pub tolerance: f64,
    /// Estimate each segment's initial state (otherwise the start's are kept).
    pub estimate_initial: bool,
    /// Keep A's eigenvalues inside the unit circle as well as A − KC's.
    pub stable: bool,
    pub parallel: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self { max_iterations: 50, tolerance: 1e-7, estimate_initial: true, stable: false, parallel: true }
    }
}

/// The refined model and how the search went.
#[derive(Debug)]
pub struct Refinement {
    pub model: Innovation,
    /// Mean squared prediction error (over samples and outputs) at the start and at the end.
    pub start_loss: f64,
    pub loss: f64,
    /// Loss after each accepted step, the start first.
    pub losses: Vec<f64>,
    pub iterations: usize,
    pub termination: Termination,
    /// Free parameters searched (the full parameterisation less the similarity directions).
    pub n_free: usize,
}

/// The largest eigenvalue magnitude of `m` (infinite when the eigenvalues cannot be computed).
pub fn spectral_radius(m: &Mat<f64>) -> f64 {
    match m.eigenvalues() {
        Ok(values) => values.iter().map(|v| v.re.hypot(v.im)).fold(0.0, f64::max),
        Err(_) => f64::INFINITY,
    }
}

/// Orthonormal basis (p × m) of the complement of the similarity tangent at `m`.
fn local_coordinates(m: &Innovation, layout: Layout) -> Result<Mat<f64>> {
    let tangent = m.similarity_tangent(layout);
    let svd = tangent
        .svd()
        .map_err(|_| ArxError::NotConverged("the SVD of the similarity directions did not converge".into()))?;
    let s = svd.S().column_vector();
    let largest = (0..s.nrows()).map(|i| s[i]).fold(0.0, f64::max);
    let rank = (0..s.nrows()).filter(|&i| s[i] > 1e-10 * largest).count();
    Ok(svd.U().subcols(rank, layout.n_params() - rank).to_owned())
}

/// The iterate: model, θ, loss, and the Gauss–Newton factor in local coordinates.
struct Iterate {
    model: Innovation,
    theta: Vec<f64>,
    rss: f64,
    basis: Mat<f64>,
    /// (m+1) × (m+1) column-major R of `[J Q | ε]`.
    r: Vec<f64>,
}

struct Problem<'a, 'b> {
    signals: &'a Signals<'b>,
    layout: Layout,
    options: RefineOptions,
    cancel: &'a AtomicBool,
}

impl Problem<'_, '_> {
    fn stop(&self) -> Result<()> {
        if self.cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(())
    }

    fn admissible(&self, m: &Innovation) -> bool {
        spectral_radius(&m.predictor_a()) < 1.0 && (!self.options.stable || spectral_radius(&m.a) < 1.0)
    }

    fn iterate(&self, model: Innovation, rss: f64) -> Result<Iterate> {
        self.stop()?;
        let basis = local_coordinates(&model, self.layout)?;
        let full = jacobian_factor(&model, self.layout, self.signals, self.options.parallel, self.cancel)?;
        let r = project(&full, &basis);
        Ok(Iterate { theta: model.theta(self.layout), model, rss, basis, r })
    }

    /// The first damped step that lowers the loss and keeps the model admissible (λ raised
    /// tenfold until one does); None when λ passes 1e12 first.
    fn damped(&self, it: &Iterate, lambda: &mut f64) -> Result<Option<(Innovation, f64, f64)>> {
        let m = it.basis.ncols();
        let norms: Vec<f64> =
            (0..m).map(|j| (0..=j).map(|i| it.r[i + j * (m + 1)].powi(2)).sum::<f64>().sqrt()).collect();
        // A column the data do not see (K on noise-free data) is damped against the others' size.
        let floor = 1e-8 * norms.iter().copied().fold(0.0, f64::max);
        let scale: Vec<f64> = norms.iter().map(|v| v.max(floor).max(f64::MIN_POSITIVE)).collect();
        while *lambda < 1e12 {
            self.stop()?;
            let delta = damped_step(&it.r, m, *lambda, &scale);
            let theta: Vec<f64> = (0..it.theta.len())
                .map(|i| it.theta[i] + (0..m).map(|j| it.basis[(i, j)] * delta[j]).sum::<f64>())
                .collect();
            let candidate = it.model.with_theta(self.layout, &theta);
            if self.admissible(&candidate) {
                let rss = loss(&candidate, self.layout, self.signals);
                if rss.is_finite() && rss < it.rss {
                    let used = *lambda;
                    *lambda = (*lambda * 0.1).max(1e-12);
                    return Ok(Some((candidate, rss, used)));
                }
            }
            *lambda *= 10.0;
        }
        Ok(None)
    }
}

/// `[R11 Q | r]` re-triangularised: the (m+1) × (m+1) R of `[J Q | ε]` from the R of `[J | ε]`.
fn project(full: &Mat<f64>, basis: &Mat<f64>) -> Vec<f64> {
    let (p, m) = (basis.nrows(), basis.ncols());
    let rows = p + 1;
    let mut a = vec![0.0; rows * (m + 1)];
    for j in 0..m {
        for i in 0..p {
            a[i + j * rows] = (i..p).map(|k| full[(i, k)] * basis[(k, j)]).sum();
        }
    }
    for i in 0..=p {
        a[i + m * rows] = full[(i, p)];
    }
    small_qr(&mut a, rows, m + 1);
    let mut r = vec![0.0; (m + 1) * (m + 1)];
    for j in 0..=m {
        for i in 0..=j.min(rows - 1) {
            r[i + j * (m + 1)] = a[i + j * rows];
        }
    }
    r
}

/// Refines `start` on `signals` by minimising the sum of squared one-step prediction errors.
///
/// # Errors
/// `ShapeMismatch` when the matrices or initial states do not fit the data; `TooFewSamples` when
/// the prediction errors do not outnumber the free parameters; `NotConverged` when the start's
/// predictor is unstable (A − KC, or A when `stable`) or its loss is not finite, or an SVD fails;
/// `Interrupted` on Ctrl-C. A search that stops without converging is not an error: its
/// [`Termination`] says so.
pub fn refine(
    start: &Innovation,
    signals: &Signals<'_>,
    options: RefineOptions,
    cancel: &AtomicBool,
) -> Result<Refinement> {
    signals.check()?;
    start.check(signals.segments.len())?;
    if start.b.ncols() != signals.n_inputs || start.c.nrows() != signals.n_outputs {
        return Err(ArxError::ShapeMismatch {
            what: "the model's inputs and outputs against the data's".into(),
            expected: signals.n_inputs + signals.n_outputs,
            got: start.b.ncols() + start.c.nrows(),
        });
    }
    let layout = start.layout(options.estimate_initial);
    let n = layout.n;
    let n_free = layout.n_params() - n * n;
    let n_errors: usize = signals.segments.iter().map(|&(a, b)| (b - a) * layout.ny).sum();
    if n_errors <= n_free {
        return Err(ArxError::TooFewSamples { needed: n_free + 1, got: n_errors });
    }
    let problem = Problem { signals, layout, options, cancel };
    for (what, matrix) in [("A − KC", start.predictor_a()), ("A", start.a.clone())] {
        let radius = spectral_radius(&matrix);
        if (what == "A − KC" || options.stable) && radius >= 1.0 {
            return Err(ArxError::NotConverged(format!(
                "the start's {what} has a pole of magnitude {radius:.4}, so its one-step predictor (or the model, \
                 with stable=True) is unstable and cannot be refined; identify with stable=True or a lower order"
            )));
        }
    }
    let start_rss = loss(start, layout, signals);
    if !start_rss.is_finite() {
        return Err(ArxError::NotConverged("the start's prediction errors are not finite".into()));
    }
    let mut it = problem.iterate(start.clone(), start_rss)?;
    let count = n_errors as f64;
    let mut losses = vec![start_rss / count];
    let mut termination = Termination::MaxIterations;
    // A loss at round-off level (noise-free data fitted exactly) is a minimum whatever the gain.
    let exact = 1e-24 * signals.y.iter().map(|v| v * v).sum::<f64>();
    let mut lambda = 1e-4;
    while losses.len() <= options.max_iterations {
        let m = it.basis.ncols();
        let gain: f64 = (0..m).map(|i| it.r[i + m * (m + 1)].powi(2)).sum();
        if gain <= options.tolerance * it.rss || it.rss <= exact {
            termination = Termination::Converged;
            break;
        }
        let Some((candidate, rss, used)) = problem.damped(&it, &mut lambda)? else {
            termination = Termination::Stalled;
            break;
        };
        let improvement = (it.rss - rss) / it.rss;
        it = problem.iterate(candidate, rss)?;
        losses.push(rss / count);
        // A small gain from a strongly damped step is no sign of a minimum: keep going then.
        if improvement < options.tolerance && used <= 1e-2 {
            termination = Termination::SmallImprovement;
            break;
        }
    }
    Ok(Refinement {
        start_loss: start_rss / count,
        loss: it.rss / count,
        iterations: losses.len() - 1,
        losses,
        termination,
        n_free: it.basis.ncols(),
        model: it.model,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    fn truth() -> Innovation {
        Innovation {
            a: faer::mat![[0.8, 0.3], [-0.3, 0.8]],
            b: faer::mat![[1.0, 0.0], [0.5, -1.0]],
            c: faer::mat![[1.0, 0.0], [0.5, 1.0]],
            d: faer::mat![[0.0, 0.2], [0.0, 0.0]],
            k: faer::mat![[0.5, 0.1], [-0.2, 0.4]],
            x0: vec![vec![2.0, -1.0]],
        }
    }

    /// (u, y) of `m` driven by random binary inputs and innovations of standard deviation `sigma`.
    fn simulate(m: &Innovation, n: usize, sigma: f64) -> (Vec<f64>, Vec<f64>) {
        let mut seed = 3;
        let (nu, ny, nx) = (m.b.ncols(), m.c.nrows(), m.a.nrows());
        let u: Vec<f64> = (0..n * nu).map(|_| if noise(&mut seed) > 0.0 { 1.0 } else { -1.0 }).collect();
        let mut y = vec![0.0; n * ny];
        let mut x = m.x0[0].clone();
        for t in 0..n {
            let e: Vec<f64> = (0..ny).map(|_| sigma * noise(&mut seed) * 12f64.sqrt()).collect();
            let ut = &u[t * nu..(t + 1) * nu];
            for o in 0..ny {
                y[t * ny + o] = (0..nx).map(|i| m.c[(o, i)] * x[i]).sum::<f64>()
                    + (0..nu).map(|j| m.d[(o, j)] * ut[j]).sum::<f64>()
                    + e[o];
            }
            x = (0..nx)
                .map(|i| {
                    (0..nx).map(|k| m.a[(i, k)] * x[k]).sum::<f64>()
                        + (0..nu).map(|j| m.b[(i, j)] * ut[j]).sum::<f64>()
                        + (0..ny).map(|j| m.k[(i, j)] * e[j]).sum::<f64>()
                })
                .collect();
        }
        (u, y)
    }

    fn perturbed(m: &Innovation, size: f64) -> Innovation {
        let layout = m.layout(true);
        let mut seed = 17;
        let theta: Vec<f64> = m.theta(layout).iter().map(|v| v + size * noise(&mut seed)).collect();
        m.with_theta(layout, &theta)
    }

    fn markov(m: &Innovation, k: usize) -> Mat<f64> {
        let mut p = m.b.clone();
        for _ in 0..k {
            p = &m.a * &p;
        }
        &m.c * p
    }

    #[test]
    fn noise_free_data_bring_a_perturbed_model_back_to_the_exact_one() {
        let t = truth();
        let (u, y) = simulate(&t, 400, 0.0);
        let segments = [(0, 400)];
        let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
        let start = Innovation { k: Mat::zeros(2, 2), ..perturbed(&t, 1e-3) };
        let fit = refine(&start, &s, RefineOptions::default(), &AtomicBool::new(false)).unwrap();
        assert!(fit.loss < 1e-20, "{:?}", fit.losses);
        assert_eq!(fit.n_free, 2 * 2 + 2 * 2 + 2 * 2 + 2 * 2 + 2);
        for k in 0..6 {
            let (a, b) = (markov(&fit.model, k), markov(&t, k));
            assert!((&a - &b).norm_max() < 1e-8, "Markov parameter {k}");
        }
        assert!((&fit.model.d - &t.d).norm_max() < 1e-8);
    }

    #[test]
    fn coloured_noise_is_fitted_down_to_the_true_predictor() {
        let t = truth();
        let (u, y) = simulate(&t, 3000, 0.3);
        let segments = [(0, 1000), (1000, 3000)];
        let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
        let mut start = Innovation { k: Mat::zeros(2, 2), ..perturbed(&t, 0.05) };
        start.x0 = vec![vec![0.0; 2]; 2];
        let fit = refine(&start, &s, RefineOptions::default(), &AtomicBool::new(false)).unwrap();
        let mut true_model = t.clone();
        true_model.x0 = vec![t.x0[0].clone(), vec![0.0; 2]];
        let true_loss = loss(&true_model, true_model.layout(false), &s) / 6000.0;
        assert!(fit.termination.converged(), "{}", fit.termination);
        // The minimum lies below the true system's loss (it is fitted to these errors), not far.
        assert!(fit.loss <= true_loss && fit.loss > 0.97 * true_loss, "{} {}", fit.loss, true_loss);
        assert!(fit.start_loss > 1.2 * fit.loss);
        assert!((&fit.model.k * &fit.model.c - &t.k * &t.c).norm_max() < 0.1);
        assert!(spectral_radius(&fit.model.predictor_a()) < 1.0);
    }

    #[test]
    fn an_unstable_predictor_or_short_data_are_refused() {
        let t = truth();
        let (u, y) = simulate(&t, 400, 0.1);
        let segments = [(0, 400)];
        let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
        let never = AtomicBool::new(false);
        let unstable = Innovation { k: faer::mat![[-2.0, 0.0], [0.0, 0.0]], ..t.clone() };
        assert!(matches!(refine(&unstable, &s, RefineOptions::default(), &never), Err(ArxError::NotConverged(_))));
        let short = [(0, 5)];
        let s = Signals { segments: &short, ..s };
        assert!(matches!(refine(&t, &s, RefineOptions::default(), &never), Err(ArxError::TooFewSamples { .. })));
        let two = [(0, 5), (5, 9)];
        let s = Signals { segments: &two, ..s };
        assert!(matches!(refine(&t, &s, RefineOptions::default(), &never), Err(ArxError::ShapeMismatch { .. })));
        assert_eq!(
            refine(&t, &Signals { segments: &segments, ..s }, RefineOptions::default(), &AtomicBool::new(true))
                .unwrap_err(),
            ArxError::Interrupted
        );
    }
}
