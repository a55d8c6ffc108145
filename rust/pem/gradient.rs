//! Prediction errors of a polynomial model and their Jacobian ∂ε/∂θ by filtering; with estimated
//! initial states, the Jacobian projected on the complement of each segment's free responses.

use faer::Mat;

use crate::linalg::qr::{back_substitute, stack_and_reduce, to_col_major};
use crate::pem::polynomial::{conv, filter, Initial, PolyStructure, Polys, Segments};
use crate::pem::regression::{lagged, reduce_columns, Column};

/// The part of a signal an unknown initial state explains, per segment.
pub(super) struct InitialFit {
    /// Segments it was fitted on (those longer than `n`).
    pub(super) segments: Vec<(usize, usize)>,
    /// Parameters per segment.
    pub(super) n: usize,
    /// $g$: in each segment, the impulse response of $1/\mathrm{den}$ from its first sample.
    pub(super) basis: Vec<f64>,
    /// $\eta$ per segment: the fitted part is $\sum_{k<n} \eta_k\, g(t - k)$.
    pub(super) states: Vec<Vec<f64>>,
    /// The fitted part, full length (zero outside the segments).
    pub(super) response: Vec<f64>,
}

/// Least-squares fit of `target` by the free responses $q^{-k}/\mathrm{den}\;\delta(t - t_0)$,
/// $k < n$, within each segment longer than `n` ($t_0$ its first sample).
pub(super) fn fit_initial(data: &Segments<'_>, den: &[f64], n: usize, target: &[f64], parallel: bool) -> InitialFit {
    let segments = data.longer_than(n);
    let (mut basis, mut response) = (vec![0.0; target.len()], vec![0.0; target.len()]);
    let cols = lagged(0, 0..n, 1.0);
    let mut states = Vec::with_capacity(segments.len());
    for &(a, b) in &segments {
        let mut impulse = vec![0.0; b - a];
        impulse[0] = 1.0;
        filter(&[1.0], den, &impulse, &mut basis[a..b]);
        let rows: Vec<usize> = (a..b).collect();
        let r = reduce_columns(std::slice::from_ref(&basis), &cols, target, &rows, a, parallel);
        let rhs: Vec<f64> = (0..n).map(|i| r[i + n * (n + 1)]).collect();
        let mut eta = vec![0.0; n];
        back_substitute(&r, n + 1, &rhs, &mut eta);
        for t in a..b {
            response[t] = (0..n.min(t - a + 1)).map(|k| eta[k] * basis[t - k]).sum();
        }
        states.push(eta);
    }
    InitialFit { segments, n, basis, states, response }
}

/// Prediction errors of θ and, with `gradient`, the filtered signals and columns of ∂ε/∂θ.
pub(super) struct Evaluation {
    pub(super) eps: Vec<f64>,
    pub(super) signals: Vec<Vec<f64>>,
    pub(super) columns: Vec<Column>,
    /// With [`Initial::Estimate`]: the initial states, already taken out of `eps`.
    pub(super) initial: Option<InitialFit>,
}

pub(super) fn evaluate(
    data: &Segments<'_>,
    s: &PolyStructure,
    xs: &[Vec<f64>],
    p: &Polys,
    gradient: bool,
    initial: Initial,
) -> Evaluation {
    let one = [1.0];
    let ws: Vec<Vec<f64>> = (0..s.m()).map(|i| data.filter(&p.b[i], &p.f[i], &xs[i])).collect();
    let mut v = data.filter(&p.a, &one, data.y);
    for w in &ws {
        v.iter_mut().zip(w).for_each(|(a, b)| *a -= b);
    }
    let mut eps = data.filter(&p.d, &p.c, &v);
    let initial = (initial == Initial::Estimate).then(|| {
        let den = p.f.iter().fold(p.c.clone(), |acc, f| conv(&acc, f));
        let fit = fit_initial(data, &den, s.n_initial(), &eps, false);
        eps.iter_mut().zip(&fit.response).for_each(|(e, r)| *e -= r);
        fit
    });
    let mut ev = Evaluation { eps, signals: vec![], columns: vec![], initial };
    if gradient {
        add_gradient(data, s, xs, p, &ws, &v, &mut ev);
        // The initial-state basis goes last, for the projection in `jacobian_r`.
        if let Some(init) = &ev.initial {
            ev.signals.push(init.basis.clone());
        }
    }
    ev
}

/// The columns of ∂ε/∂θ. With an initial-state part $s = -\sum_k \eta_k g(t-k)$ in ε (η held
/// fixed, $g$ = 1/(C ΠF) δ): $\partial s/\partial c_k = -s(t-k)/C$, so the C columns filter the full
/// ε, and $\partial s/\partial f_{ik} = -s(t-k)/F_i$ is added to the F columns.
fn add_gradient(
    data: &Segments<'_>,
    s: &PolyStructure,
    xs: &[Vec<f64>],
    p: &Polys,
    ws: &[Vec<f64>],
    v: &[f64],
    ev: &mut Evaluation,
) {
    let one = [1.0];
    let add = |sig: Vec<f64>, lags: std::ops::Range<usize>, sign: f64, ev: &mut Evaluation| {
        if !lags.is_empty() {
            ev.signals.push(sig);
            ev.columns.extend(lagged(ev.signals.len() - 1, lags, sign));
        }
    };
    // ∂ε/∂a_k = (D/C) y(t−k)
    let ya = if s.na > 0 { data.filter(&p.d, &p.c, data.y) } else { vec![] };
    add(ya, 1..s.na + 1, 1.0, ev);
    // ∂ε/∂b_ij = −(D/(C F_i)) x_i(t−j)
    let cf: Vec<Vec<f64>> = p.f.iter().map(|f| conv(&p.c, f)).collect();
    for i in 0..s.m() {
        let g = if s.nb[i] > 0 { data.filter(&p.d, &cf[i], &xs[i]) } else { vec![] };
        add(g, 0..s.nb[i], -1.0, ev);
    }
    // ∂ε/∂c_k = −(1/C) ε(t−k);  ∂ε/∂d_k = (1/C) v(t−k)
    let ec = if s.nc > 0 { data.filter(&one, &p.c, &ev.eps) } else { vec![] };
    add(ec, 1..s.nc + 1, -1.0, ev);
    let vc = if s.nd > 0 { data.filter(&one, &p.c, v) } else { vec![] };
    add(vc, 1..s.nd + 1, 1.0, ev);
    // ∂ε/∂f_ij = (D/(C F_i)) w_i(t−j) (+ (1/F_i) of the initial-state part)
    for i in 0..s.m() {
        let mut h = if s.nf[i] > 0 { data.filter(&p.d, &cf[i], &ws[i]) } else { vec![] };
        if let (Some(init), false) = (&ev.initial, h.is_empty()) {
            let extra = data.filter(&one, &p.f[i], &init.response);
            h.iter_mut().zip(&extra).for_each(|(a, b)| *a += b);
        }
        add(h, 1..s.nf[i] + 1, 1.0, ev);
    }
}

/// R factor ((p+1) × (p+1), column-major) of the Gauss–Newton problem `[∂ε/∂θ | ε]` on `rows`; with
/// estimated initial states, of its projection on the complement of each segment's free responses
/// (the trailing block of the QR of `[G | ∂ε/∂θ | ε]` per segment).
pub(super) fn jacobian_r(ev: &Evaluation, rows: &[usize], parallel: bool) -> Vec<f64> {
    let Some(init) = &ev.initial else {
        return reduce_columns(&ev.signals, &ev.columns, &ev.eps, rows, 0, parallel);
    };
    let (n, p) = (init.n, ev.columns.len());
    let basis = ev.signals.len() - 1;
    let cols: Vec<Column> = lagged(basis, 0..n, 1.0).into_iter().chain(ev.columns.iter().copied()).collect();
    let q = n + p + 1;
    let blocks: Vec<Mat<f64>> = init
        .segments
        .iter()
        .map(|&(a, b)| {
            let seg_rows: Vec<usize> = (a..b).collect();
            let r = reduce_columns(&ev.signals, &cols, &ev.eps, &seg_rows, a, parallel);
            Mat::from_fn(p + 1, p + 1, |i, j| if i <= j { r[(n + i) + (n + j) * q] } else { 0.0 })
        })
        .collect();
    to_col_major(&stack_and_reduce(&blocks, p + 1))
}

pub(super) fn sum_squares(e: &[f64], rows: &[usize]) -> f64 {
    rows.iter().map(|&t| e[t] * e[t]).sum()
}

/// Prediction errors ε of θ (NaN outside the scored samples) and the Jacobian ∂ε/∂θ, row-major
/// `len(y) × p` in `getpvec` order (NaN rows outside the scored samples): the gradient ψ = −∂ε/∂θ
/// of the prediction-error method, for score tests of terms the model lacks.
pub fn gradient(data: &Segments<'_>, s: &PolyStructure, theta: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let p = Polys::of(s, theta);
    let xs: Vec<Vec<f64>> = (0..s.m()).map(|i| data.delayed(i, s.nk[i])).collect();
    let ev = evaluate(data, s, &xs, &p, true, Initial::Zero);
    let (n, q) = (data.y.len(), ev.columns.len());
    let mut eps = vec![f64::NAN; n];
    let mut jac = vec![f64::NAN; n * q];
    for t in data.rows(s.max_lag()) {
        eps[t] = ev.eps[t];
        for (j, c) in ev.columns.iter().enumerate() {
            jac[t * q + j] = c.sign * ev.signals[c.signal][t - c.lag];
        }
    }
    (eps, jac)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pem::lcg;

    #[test]
    fn gradient_matches_finite_differences() {
        let mut seed = 7u64;
        let n = 400;
        let u: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let y: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let segs = [(0usize, n)];
        let d = Segments::new(&y, &u, 1, &segs).unwrap();
        let s = PolyStructure::new(0, vec![2], 1, 1, vec![1], vec![1]).unwrap();
        let theta = [0.5, 0.2, 0.3, -0.4, -0.6];
        let (eps, jac) = gradient(&d, &s, &theta);
        let q = theta.len();
        let rows = d.rows(s.max_lag());
        for j in 0..q {
            let mut th = theta;
            th[j] += 1e-6;
            let (e2, _) = gradient(&d, &s, &th);
            for &t in &rows {
                let fd = (e2[t] - eps[t]) / 1e-6;
                assert!((fd - jac[t * q + j]).abs() < 1e-4, "column {j} row {t}: {fd} vs {}", jac[t * q + j]);
            }
        }
        assert!(eps[..s.max_lag()].iter().all(|e| e.is_nan()));
    }

    /// With estimated initial states the loss is $\min_\eta \|\varepsilon\|^2$; its gradient
    /// $2 R_{11}^T r$ from the projected R must match finite differences (Kaufman's Jacobian gives the
    /// exact gradient of the projected loss) for every polynomial of a Box–Jenkins model.
    #[test]
    fn projected_gradient_matches_finite_differences() {
        let mut seed = 3u64;
        let n = 300;
        let u: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let y: Vec<f64> = (0..n).map(|_| lcg(&mut seed)).collect();
        let segs = [(0usize, 120), (120, n)];
        let d = Segments::new(&y, &u, 1, &segs).unwrap();
        let s = PolyStructure::new(0, vec![2], 1, 2, vec![2], vec![2]).unwrap();
        let theta = [0.5, 0.2, 0.3, -0.4, 0.1, -0.6, 0.2];
        let xs = vec![d.delayed(0, 2)];
        let rows = d.scored(&s, Initial::Estimate);
        assert_eq!(rows.len(), n);
        let loss = |th: &[f64]| {
            let ev = evaluate(&d, &s, &xs, &Polys::of(&s, th), false, Initial::Estimate);
            sum_squares(&ev.eps, &rows)
        };
        let ev = evaluate(&d, &s, &xs, &Polys::of(&s, &theta), true, Initial::Estimate);
        assert_eq!(ev.initial.as_ref().unwrap().states.len(), 2);
        let p = theta.len();
        let r = jacobian_r(&ev, &rows, false);
        for j in 0..p {
            let grad: f64 = 2.0 * (0..=j).map(|i| r[i + j * (p + 1)] * r[i + p * (p + 1)]).sum::<f64>();
            let (mut up, mut down) = (theta, theta);
            up[j] += 1e-6;
            down[j] -= 1e-6;
            let fd = (loss(&up) - loss(&down)) / 2e-6;
            assert!((fd - grad).abs() < 1e-5 * (1.0 + fd.abs()), "parameter {j}: {fd} vs {grad}");
        }
    }
}
