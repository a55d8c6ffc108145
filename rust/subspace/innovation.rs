//! The one-step predictor of the innovation form, its prediction errors, and their Jacobian by
//! forward sensitivities.
//!
//! The model `x(t+1) = A x + B u + K e`, `y = C x + D u + e` predicts with
//! $\hat x(t+1) = \bar A \hat x(t) + \bar B u(t) + K y(t)$, $\bar A = A - KC$, $\bar B = B - KD$,
//! and its prediction error is $\varepsilon(t) = y(t) - C \hat x(t) - D u(t)$, the predictor
//! starting at each segment's initial state. The derivative of ε along a parameter θ_k follows
//! from the sensitivity $s_k = \partial \hat x / \partial \theta_k$:
//! $s_k(t+1) = \bar A s_k(t) + f_k(t)$, $\partial\varepsilon/\partial\theta_k = -C s_k - g_k(t)$,
//! where the forcing of `A[i,j]` is $e_i \hat x_j$, of `B[i,j]` $e_i u_j$, of `C[i,j]`
//! $-K_{:,i} \hat x_j$ (and $g = e_i \hat x_j$), of `D[i,j]` $-K_{:,i} u_j$ (and $g = e_i u_j$),
//! of `K[i,j]` $e_i \varepsilon_j$; an initial state's sensitivity starts at $e_i$.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::Mat;
use rayon::prelude::*;

use super::hankel::Signals;
use super::response::StateSpaceRef;
use crate::error::{ArxError, Result};
use crate::linalg::dense::rows_product;
use crate::linalg::qr::{reduce_appended, stack_and_reduce, BLOCK_ROWS};

/// A state-space model in innovation form with one initial state per segment of its data.
#[derive(Clone, Debug)]
pub struct Innovation {
    pub a: Mat<f64>,
    pub b: Mat<f64>,
    pub c: Mat<f64>,
    pub d: Mat<f64>,
    pub k: Mat<f64>,
    pub x0: Vec<Vec<f64>>,
}

/// Where each matrix sits in the parameter vector θ: A, B, C, D, K row by row, then the initial
/// states (when estimated), segment after segment.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    pub n: usize,
    pub nu: usize,
    pub ny: usize,
    /// Initial states in θ (0 when they are held).
    pub n_initial: usize,
}

impl Layout {
    pub fn b(&self) -> usize {
        self.n * self.n
    }
    pub fn c(&self) -> usize {
        self.b() + self.n * self.nu
    }
    pub fn d(&self) -> usize {
        self.c() + self.ny * self.n
    }
    pub fn k(&self) -> usize {
        self.d() + self.ny * self.nu
    }
    pub fn x0(&self) -> usize {
        self.k() + self.n * self.ny
    }
    pub fn n_params(&self) -> usize {
        self.x0() + self.n * self.n_initial
    }
}

impl Innovation {
    /// The layout of θ for this model, with or without its initial states.
    pub fn layout(&self, estimate_initial: bool) -> Layout {
        let n_initial = if estimate_initial { self.x0.len() } else { 0 };
        Layout { n: self.a.nrows(), nu: self.b.ncols(), ny: self.c.nrows(), n_initial }
    }

    /// Checks that the matrices agree and that there is one initial state per segment.
    ///
    /// # Errors
    /// `ShapeMismatch` naming what does not fit.
    pub fn check(&self, segments: usize) -> Result<()> {
        StateSpaceRef { a: self.a.as_ref(), b: self.b.as_ref(), c: self.c.as_ref(), d: self.d.as_ref() }.check()?;
        let (n, ny) = (self.a.nrows(), self.c.nrows());
        let shapes = [
            ("K's rows", self.k.nrows(), n),
            ("K's columns", self.k.ncols(), ny),
            ("the initial states (one per stretch of data)", self.x0.len(), segments),
        ];
        if let Some((what, got, expected)) = shapes.into_iter().find(|&(_, got, expected)| got != expected) {
            return Err(ArxError::ShapeMismatch { what: what.into(), expected, got });
        }
        if let Some(x) = self.x0.iter().find(|x| x.len() != n) {
            return Err(ArxError::ShapeMismatch { what: "an initial state".into(), expected: n, got: x.len() });
        }
        Ok(())
    }

    /// θ in the order of [`Layout`].
    pub fn theta(&self, layout: Layout) -> Vec<f64> {
        fn rows(m: &Mat<f64>) -> impl Iterator<Item = f64> + '_ {
            (0..m.nrows()).flat_map(move |i| (0..m.ncols()).map(move |j| m[(i, j)]))
        }
        let mut theta: Vec<f64> =
            rows(&self.a).chain(rows(&self.b)).chain(rows(&self.c)).chain(rows(&self.d)).chain(rows(&self.k)).collect();
        if layout.n_initial > 0 {
            theta.extend(self.x0.iter().flatten());
        }
        theta
    }

    /// The model of θ (initial states from `self` when θ does not hold them).
    pub fn with_theta(&self, layout: Layout, theta: &[f64]) -> Self {
        let Layout { n, nu, ny, .. } = layout;
        let at = |start: usize, cols: usize| move |i: usize, j: usize| theta[start + i * cols + j];
        let x0 = if layout.n_initial > 0 {
            theta[layout.x0()..].chunks_exact(n).map(<[f64]>::to_vec).collect()
        } else {
            self.x0.clone()
        };
        Self {
            a: Mat::from_fn(n, n, at(0, n)),
            b: Mat::from_fn(n, nu, at(layout.b(), nu)),
            c: Mat::from_fn(ny, n, at(layout.c(), n)),
            d: Mat::from_fn(ny, nu, at(layout.d(), nu)),
            k: Mat::from_fn(n, ny, at(layout.k(), ny)),
            x0,
        }
    }

    /// The predictor's state matrix A − KC.
    pub fn predictor_a(&self) -> Mat<f64> {
        &self.a - &self.k * &self.c
    }

    /// The tangent of the similarity class at θ: column `i·n + j` is the change of θ under
    /// `T = I + ε E_ij` (`A → TAT⁻¹`, `B → TB`, `C → CT⁻¹`, `K → TK`, `x0 → T x0`), to first order.
    pub fn similarity_tangent(&self, layout: Layout) -> Mat<f64> {
        let n = layout.n;
        let mut t = Mat::zeros(layout.n_params(), n * n);
        for i in 0..n {
            for j in 0..n {
                let col = i * n + j;
                // d(A) = E_ij A − A E_ij
                for c in 0..n {
                    t[(i * n + c, col)] += self.a[(j, c)];
                }
                for r in 0..n {
                    t[(r * n + j, col)] -= self.a[(r, i)];
                }
                for c in 0..layout.nu {
                    t[(layout.b() + i * layout.nu + c, col)] = self.b[(j, c)];
                }
                for r in 0..layout.ny {
                    t[(layout.c() + r * n + j, col)] = -self.c[(r, i)];
                }
                for c in 0..layout.ny {
                    t[(layout.k() + i * layout.ny + c, col)] = self.k[(j, c)];
                }
                for s in 0..layout.n_initial {
                    t[(layout.x0() + s * n + i, col)] = self.x0[s][j];
                }
            }
        }
        t
    }
}

/// The predictor state and its sensitivities at one sample.
#[derive(Clone)]
struct Predictor {
    x: Vec<f64>,
    /// ∂x̂/∂θ, row-major n × p (empty when only the errors are wanted): each update is n²
    /// contiguous axpys of length p.
    sens: Vec<f64>,
}

/// A matrix as row-major values, for the sample loops.
fn row_major(m: &Mat<f64>) -> Vec<f64> {
    (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)])).collect()
}

/// The model's matrices as the predictor loop reads them (row-major; A − KC and B − KD formed once).
struct Step {
    layout: Layout,
    abar: Vec<f64>,
    bbar: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
    k: Vec<f64>,
    x0: Vec<Vec<f64>>,
}

impl Step {
    fn new(m: &Innovation, layout: Layout) -> Self {
        Self {
            layout,
            abar: row_major(&m.predictor_a()),
            bbar: row_major(&(&m.b - &m.k * &m.d)),
            c: row_major(&m.c),
            d: row_major(&m.d),
            k: row_major(&m.k),
            x0: m.x0.clone(),
        }
    }

    fn start(&self, segment: usize, sensitivities: bool) -> Predictor {
        let (n, p) = (self.layout.n, self.layout.n_params());
        let mut sens = if sensitivities { vec![0.0; n * p] } else { Vec::new() };
        if sensitivities && self.layout.n_initial > 0 {
            for i in 0..n {
                sens[i * p + self.layout.x0() + segment * n + i] = 1.0;
            }
        }
        Predictor { x: self.x0[segment].clone(), sens }
    }

    /// ε(t) into `eps` (length ny).
    fn error(&self, x: &[f64], u: &[f64], y: &[f64], eps: &mut [f64]) {
        let (n, nu) = (self.layout.n, self.layout.nu);
        for (o, e) in eps.iter_mut().enumerate() {
            let cx: f64 = self.c[o * n..(o + 1) * n].iter().zip(x).map(|(a, b)| a * b).sum();
            let du: f64 = self.d[o * nu..(o + 1) * nu].iter().zip(u).map(|(a, b)| a * b).sum();
            *e = y[o] - cx - du;
        }
    }

    /// One sample on: x̂ (and the sensitivities, when held) advanced with `eps` = ε(t).
    fn advance(&self, p: &mut Predictor, u: &[f64], y: &[f64], eps: &[f64], scratch: &mut Vec<f64>) {
        let Layout { n, nu, ny, .. } = self.layout;
        if !p.sens.is_empty() {
            scratch.resize(p.sens.len(), 0.0);
            rows_product(&self.abar, &p.sens, n, 0, scratch);
            self.add_forcing(scratch, &p.x, u, eps);
            std::mem::swap(&mut p.sens, scratch);
        }
        let dot = |row: &[f64], v: &[f64]| row.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
        let mut next = [0.0; 64];
        let next = if n <= 64 { &mut next[..n] } else { &mut vec![0.0; n][..] };
        for (i, v) in next.iter_mut().enumerate() {
            *v = dot(&self.abar[i * n..(i + 1) * n], &p.x)
                + dot(&self.bbar[i * nu..(i + 1) * nu], u)
                + dot(&self.k[i * ny..(i + 1) * ny], y);
        }
        p.x.copy_from_slice(next);
    }

    /// Adds the forcing f_k(t) of every parameter to the propagated sensitivities `s` (row-major).
    fn add_forcing(&self, s: &mut [f64], x: &[f64], u: &[f64], eps: &[f64]) {
        let l = self.layout;
        let (n, nu, ny, p) = (l.n, l.nu, l.ny, l.n_params());
        for (i, row) in s.chunks_exact_mut(p).enumerate() {
            row[i * n..(i + 1) * n].iter_mut().zip(x).for_each(|(v, xj)| *v += xj);
            row[l.b() + i * nu..l.b() + (i + 1) * nu].iter_mut().zip(u).for_each(|(v, uj)| *v += uj);
            row[l.k() + i * ny..l.k() + (i + 1) * ny].iter_mut().zip(eps).for_each(|(v, ej)| *v += ej);
            for o in 0..ny {
                let gain = self.k[i * ny + o];
                row[l.c() + o * n..l.c() + (o + 1) * n].iter_mut().zip(x).for_each(|(v, xj)| *v -= gain * xj);
                row[l.d() + o * nu..l.d() + (o + 1) * nu].iter_mut().zip(u).for_each(|(v, uj)| *v -= gain * uj);
            }
        }
    }

    /// The Jacobian row of output `o` (∂ε_o/∂θ) into `row` (length p).
    fn jacobian_row(&self, row: &mut [f64], p: &Predictor, u: &[f64], o: usize) {
        let l = self.layout;
        let n = l.n;
        rows_product(&self.c[o * n..(o + 1) * n], &p.sens, n, 0, row);
        row.iter_mut().for_each(|v| *v = -*v);
        row[l.c() + o * n..l.c() + (o + 1) * n].iter_mut().zip(&p.x).for_each(|(v, xj)| *v -= xj);
        row[l.d() + o * l.nu..l.d() + (o + 1) * l.nu].iter_mut().zip(u).for_each(|(v, uj)| *v -= uj);
    }
}

/// Samples per chunk of a segment in [`jacobian_factor`]: chunks are reduced in parallel from the
/// predictor at their first sample, their R's stacked in order (the result does not depend on
/// the number of threads).
const CHUNK_SAMPLES: usize = 4096;

/// Sum of squared prediction errors of `m` on the segments of `s` (infinite when the predictor's
/// state blows up).
pub fn loss(m: &Innovation, layout: Layout, s: &Signals<'_>) -> f64 {
    let step = Step::new(m, layout);
    let (nu, ny) = (s.n_inputs, s.n_outputs);
    let mut eps = vec![0.0; ny];
    let mut scratch = Vec::new();
    let mut total = 0.0;
    for (index, &(a, b)) in s.segments.iter().enumerate() {
        let mut p = step.start(index, false);
        for t in a..b {
            let (u, y) = (&s.u[t * nu..(t + 1) * nu], &s.y[t * ny..(t + 1) * ny]);
            step.error(&p.x, u, y, &mut eps);
            total += eps.iter().map(|e| e * e).sum::<f64>();
            step.advance(&mut p, u, y, &eps, &mut scratch);
        }
        if !total.is_finite() {
            return f64::INFINITY;
        }
    }
    total
}

/// The R factor ((p+1) × (p+1)) of `[∂ε/∂θ | ε]` over every sample of every segment.
///
/// # Errors
/// `Interrupted` on Ctrl-C.
pub fn jacobian_factor(
    m: &Innovation,
    layout: Layout,
    s: &Signals<'_>,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let step = Step::new(m, layout);
    let (nu, ny) = (s.n_inputs, s.n_outputs);
    let mut chunks = Vec::new();
    let mut eps = vec![0.0; ny];
    let mut scratch = Vec::new();
    for (index, &(a, b)) in s.segments.iter().enumerate() {
        let mut p = step.start(index, true);
        for t0 in (a..b).step_by(CHUNK_SAMPLES) {
            let t1 = (t0 + CHUNK_SAMPLES).min(b);
            chunks.push(((t0, t1), p.clone()));
            for t in t0..t1 {
                let (u, y) = (&s.u[t * nu..(t + 1) * nu], &s.y[t * ny..(t + 1) * ny]);
                step.error(&p.x, u, y, &mut eps);
                step.advance(&mut p, u, y, &eps, &mut scratch);
            }
        }
    }
    let chunk = |((t0, t1), p): ((usize, usize), Predictor)| chunk_factor(&step, s, (t0, t1), p, cancel);
    let factors = if parallel {
        chunks.into_par_iter().map(chunk).collect::<Result<Vec<_>>>()?
    } else {
        chunks.into_iter().map(chunk).collect::<Result<Vec<_>>>()?
    };
    Ok(stack_and_reduce(&factors, layout.n_params() + 1))
}

/// R of the Jacobian rows of samples `t0..t1`, from predictor `p` at `t0`.
fn chunk_factor(
    step: &Step,
    s: &Signals<'_>,
    (t0, t1): (usize, usize),
    mut p: Predictor,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let (nu, ny) = (s.n_inputs, s.n_outputs);
    let q = step.layout.n_params() + 1;
    let mut work = Mat::<f64>::zeros(q + BLOCK_ROWS, q);
    let (mut filled, mut eps, mut scratch, mut row) = (0, vec![0.0; ny], Vec::new(), vec![0.0; q - 1]);
    for t in t0..t1 {
        if filled + ny > BLOCK_ROWS {
            if cancel.load(Ordering::Relaxed) {
                return Err(ArxError::Interrupted);
            }
            reduce_appended(&mut work, filled);
            filled = 0;
        }
        let (u, y) = (&s.u[t * nu..(t + 1) * nu], &s.y[t * ny..(t + 1) * ny]);
        step.error(&p.x, u, y, &mut eps);
        for (o, &e) in eps.iter().enumerate() {
            step.jacobian_row(&mut row, &p, u, o);
            for (k, &v) in row.iter().enumerate() {
                work[(q + filled, k)] = v;
            }
            work[(q + filled, q - 1)] = e;
            filled += 1;
        }
        step.advance(&mut p, u, y, &eps, &mut scratch);
    }
    reduce_appended(&mut work, filled);
    Ok(work.as_ref().subrows(0, q).to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Innovation {
        Innovation {
            a: faer::mat![[0.7, 0.2], [-0.3, 0.6]],
            b: faer::mat![[1.0], [0.5]],
            c: faer::mat![[1.0, 0.3], [0.0, 1.0]],
            d: faer::mat![[0.2], [0.0]],
            k: faer::mat![[0.3, 0.1], [0.0, 0.2]],
            x0: vec![vec![0.5, -1.0], vec![0.2, 0.1]],
        }
    }

    fn errors(m: &Innovation, layout: Layout, s: &Signals<'_>) -> Vec<f64> {
        let step = Step::new(m, layout);
        let (nu, ny) = (s.n_inputs, s.n_outputs);
        let (mut out, mut eps, mut scratch) = (Vec::new(), vec![0.0; ny], Vec::new());
        for (index, &(a, b)) in s.segments.iter().enumerate() {
            let mut p = step.start(index, false);
            for t in a..b {
                let (u, y) = (&s.u[t * nu..(t + 1) * nu], &s.y[t * ny..(t + 1) * ny]);
                step.error(&p.x, u, y, &mut eps);
                out.extend_from_slice(&eps);
                step.advance(&mut p, u, y, &eps, &mut scratch);
            }
        }
        out
    }

    #[test]
    fn the_factor_matches_the_finite_difference_jacobian() {
        let m = model();
        let u: Vec<f64> = (0..60).map(|t| ((t * 7) % 5) as f64 - 2.0).collect();
        let y: Vec<f64> = (0..120).map(|i| ((i * 13) % 9) as f64 * 0.3 - 1.0).collect();
        let segments = [(0, 25), (30, 60)];
        let s = Signals { u: &u, y: &y, n_inputs: 1, n_outputs: 2, segments: &segments };
        let layout = m.layout(true);
        let p = layout.n_params();
        let theta = m.theta(layout);
        assert_eq!(p, theta.len());
        let eps = errors(&m, layout, &s);
        let h = 1e-6;
        let jac: Vec<Vec<f64>> = (0..p)
            .map(|k| {
                let (mut up, mut down) = (theta.clone(), theta.clone());
                up[k] += h;
                down[k] -= h;
                let (e1, e0) =
                    (errors(&m.with_theta(layout, &up), layout, &s), errors(&m.with_theta(layout, &down), layout, &s));
                e1.iter().zip(&e0).map(|(a, b)| (a - b) / (2.0 * h)).collect()
            })
            .collect();
        let r = jacobian_factor(&m, layout, &s, true, &AtomicBool::new(false)).unwrap();
        let column = |k: usize| if k < p { &jac[k] } else { &eps };
        for i in 0..=p {
            for j in 0..=p {
                let direct: f64 = column(i).iter().zip(column(j)).map(|(a, b)| a * b).sum();
                let from_r: f64 = (0..=p).map(|k| r[(k, i)] * r[(k, j)]).sum();
                assert!((direct - from_r).abs() < 1e-6 * direct.abs().max(1.0), "{i} {j}: {direct} {from_r}");
            }
        }
        let total: f64 = eps.iter().map(|e| e * e).sum();
        assert!((loss(&m, layout, &s) - total).abs() < 1e-12 * total);
    }

    #[test]
    fn a_similarity_transform_moves_theta_along_the_tangent() {
        let m = model();
        let layout = m.layout(true);
        let tangent = m.similarity_tangent(layout);
        let (i, j, e) = (1, 0, 1e-7);
        // T = I + e E_ij, T⁻¹ = I − e E_ij to first order.
        let mut t = Mat::<f64>::identity(2, 2);
        t[(i, j)] += e;
        let mut ti = Mat::<f64>::identity(2, 2);
        ti[(i, j)] -= e;
        let moved = Innovation {
            a: &t * &m.a * &ti,
            b: &t * &m.b,
            c: &m.c * &ti,
            d: m.d.clone(),
            k: &t * &m.k,
            x0: m.x0.iter().map(|x| (0..2).map(|r| x[r] + if r == i { e * x[j] } else { 0.0 }).collect()).collect(),
        };
        let (before, after) = (m.theta(layout), moved.theta(layout));
        for (k, (a, b)) in before.iter().zip(&after).enumerate() {
            assert!(((b - a) / e - tangent[(k, i * 2 + j)]).abs() < 1e-6, "{k}");
        }
    }
}
