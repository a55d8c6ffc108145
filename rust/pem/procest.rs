//! Process models (MATLAB's `idproc`: gain, time constants, underdamped pair, zero, integrator,
//! dead time) refined by a bounded prediction-error search of the output error.
//!
//! Each residual evaluation samples every input's process model exactly with a zero-order hold,
//! its dead time split into whole samples `ℓ` and a fraction `δ` (`τ = ℓ·ts + δ`, `0 <= δ < ts`),
//! as `arxid.models.continuous.zoh_matrices` does in Python: in controllable canonical form
//! `x(k+1) = Φ x(k) + Γ0 v(k) + Γ1 v(k−1)`, `v(k) = u(k − ℓ)`, with `Φ = e^{A ts}`,
//! `Γ0 = ∫_0^{ts−δ} e^{As} ds B` and `Γ1 = e^{A(ts−δ)} ∫_0^δ e^{As} ds B` (the modified
//! z-transform). The exponentials and integrals come from one block exponential
//! `exp([[A, B], [0, 0]] t)` (Van Loan), by Padé-13 scaling and squaring (Higham 2005). The model
//! is simulated from rest in each run of finite samples (experiments, NaN gaps) and the residual
//! is `y − Σ_i G_i u_i` on those runs.
//!
//! The search is a **projected Levenberg–Marquardt** method with an active set: the parameters
//! sit in a box (time constants and `Tw` above `1e-6·ts`, `Zeta` above `1e-6`, `Td` in
//! `[0, max_delay]`, narrowed further by the caller); a parameter on a bound whose gradient points
//! out of the box is held for the step, the others take the damped Gauss–Newton step
//! `(JᵀJ + λ D) δ = −Jᵀ r` (`D` Moré's scaling, the largest diagonal of `JᵀJ` seen), and the trial
//! point is projected onto the box; a trial that lowers the cost is accepted and `λ` shrinks,
//! otherwise `λ` grows. The Jacobian is by forward finite differences (backward at an upper
//! bound), one single-input simulation per column.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{ArxError, Result};
use crate::linalg::dense::{expm, matmul, solve};

/// One input's process model structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Process {
    /// 1, 2 or 3 poles (besides the integrator).
    pub n_poles: usize,
    pub zero: bool,
    pub underdamped: bool,
    pub integrator: bool,
    pub delay: bool,
}

/// What a parameter is (its bounds and finite-difference step follow from it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Gain,
    TimeConstant,
    Zeta,
    Zero,
    DeadTime,
}

impl Process {
    /// Checks the structure.
    ///
    /// # Errors
    /// `InvalidStructure` for a pole count outside 1..=3 or an underdamped pair with one pole.
    pub fn new(n_poles: usize, zero: bool, underdamped: bool, integrator: bool, delay: bool) -> Result<Self> {
        if !(1..=3).contains(&n_poles) {
            return Err(ArxError::InvalidStructure(format!("a process model has 1, 2 or 3 poles, got {n_poles}")));
        }
        if underdamped && n_poles < 2 {
            return Err(ArxError::InvalidStructure("an underdamped pair (U) needs two poles at least".into()));
        }
        Ok(Self { n_poles, zero, underdamped, integrator, delay })
    }

    /// Parameter kinds in the order K, (Tw, Zeta, [Tp3] | Tp1..Tpn), [Tz], [Td].
    pub fn kinds(&self) -> Vec<Kind> {
        let mut k = vec![Kind::Gain];
        if self.underdamped {
            k.push(Kind::TimeConstant);
            k.push(Kind::Zeta);
            if self.n_poles == 3 {
                k.push(Kind::TimeConstant);
            }
        } else {
            k.extend(std::iter::repeat_n(Kind::TimeConstant, self.n_poles));
        }
        if self.zero {
            k.push(Kind::Zero);
        }
        if self.delay {
            k.push(Kind::DeadTime);
        }
        k
    }

    pub fn n_params(&self) -> usize {
        self.kinds().len()
    }

    /// Numerator and denominator (descending powers of s, denominator monic) and dead time of the
    /// parameters `p` (in the order of [`Process::kinds`]).
    pub fn transfer(&self, p: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
        let mut at = 1;
        let mut den = vec![1.0];
        if self.underdamped {
            let (tw, zeta) = (p[1], p[2]);
            den = vec![tw * tw, 2.0 * zeta * tw, 1.0];
            at = 3;
            if self.n_poles == 3 {
                den = polymul(&den, &[p[3], 1.0]);
                at = 4;
            }
        } else {
            for t in &p[1..=self.n_poles] {
                den = polymul(&den, &[*t, 1.0]);
            }
            at += self.n_poles;
        }
        let mut num = vec![p[0]];
        if self.zero {
            num = vec![p[0] * p[at], p[0]];
            at += 1;
        }
        if self.integrator {
            den.push(0.0);
        }
        let tau = if self.delay { p[at] } else { 0.0 };
        let lead = den[0];
        (num.iter().map(|v| v / lead).collect(), den.iter().map(|v| v / lead).collect(), tau)
    }
}

fn polymul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

// ------------------------------------------------------------------ exact ZOH sampling
/// One input's exact ZOH sample: `x(k+1) = Φ x + Γ0 v(k) + Γ1 v(k−1)`, `y = c·x`,
/// `v(k) = u(k − whole)`.
#[derive(Debug, Clone)]
pub struct Sampled {
    pub n: usize,
    pub phi: Vec<f64>,
    pub g0: Vec<f64>,
    pub g1: Vec<f64>,
    pub c: Vec<f64>,
    pub whole: usize,
}

/// Whole samples and fraction (seconds) of a dead time, as `arxid.models.continuous.split_delay`.
pub fn split_delay(tau: f64, ts: f64) -> (usize, f64) {
    let whole = (tau / ts + 1e-9).floor().max(0.0);
    let fraction = (tau - whole * ts).max(0.0);
    (whole as usize, if fraction < 1e-9 * ts { 0.0 } else { fraction })
}

/// `(e^{A t}, ∫_0^t e^{As} ds B)` from the block exponential of `[[A, B], [0, 0]] t`.
fn propagate(ac: &[f64], bc: &[f64], n: usize, t: f64) -> Option<(Vec<f64>, Vec<f64>)> {
    let m = n + 1;
    let mut big = vec![0.0; m * m];
    for i in 0..n {
        for j in 0..n {
            big[i * m + j] = ac[i * n + j] * t;
        }
        big[i * m + n] = bc[i] * t;
    }
    let e = expm(&big, m)?;
    let phi = (0..n).flat_map(|i| e[i * m..i * m + n].to_vec()).collect();
    let gam = (0..n).map(|i| e[i * m + n]).collect();
    Some((phi, gam))
}

/// The exact ZOH sample of `num(s) / den(s) · e^{-s τ}` (descending powers, `den` monic, strictly
/// proper) with sampling time `ts`; None when the model's exponential is not finite.
pub fn sample(num: &[f64], den: &[f64], tau: f64, ts: f64) -> Option<Sampled> {
    let n = den.len() - 1;
    let mut ac = vec![0.0; n * n];
    for i in 0..n - 1 {
        ac[i * n + i + 1] = 1.0;
    }
    for j in 0..n {
        ac[(n - 1) * n + j] = -den[n - j];
    }
    let mut bc = vec![0.0; n];
    bc[n - 1] = 1.0;
    let mut c = vec![0.0; n];
    for (j, v) in num.iter().rev().enumerate() {
        c[j] = *v;
    }
    let (whole, fraction) = split_delay(tau, ts);
    let (e_rest, m_rest) = propagate(&ac, &bc, n, ts - fraction)?;
    let (phi, g1) = if fraction > 0.0 {
        let (e_delta, m_delta) = propagate(&ac, &bc, n, fraction)?;
        let phi = matmul(&e_rest, &e_delta, n);
        let g1 = (0..n).map(|i| (0..n).map(|j| e_rest[i * n + j] * m_delta[j]).sum()).collect();
        (phi, g1)
    } else {
        (e_rest.clone(), vec![0.0; n])
    };
    let ok = phi.iter().chain(&m_rest).chain(&g1).all(|v: &f64| v.is_finite());
    ok.then_some(Sampled { n, phi, g0: m_rest, g1, c, whole })
}

/// Adds input `i`'s simulated output (from rest in each segment) to `out`, which holds the
/// segments' samples one after the other; `u` is row-major `len × m`.
fn simulate_into(s: &Sampled, u: &[f64], m: usize, i: usize, segments: &[(usize, usize)], out: &mut [f64]) {
    let n = s.n;
    let mut x = vec![0.0; n];
    let mut nx = vec![0.0; n];
    let mut row = 0;
    for &(a, b) in segments {
        x.iter_mut().for_each(|v| *v = 0.0);
        let mut vp = 0.0;
        for k in a..b {
            out[row] += s.c.iter().zip(&x).map(|(c, x)| c * x).sum::<f64>();
            row += 1;
            let vc = if k >= a + s.whole { u[(k - s.whole) * m + i] } else { 0.0 };
            for (r, nxr) in nx.iter_mut().enumerate() {
                let dot: f64 = s.phi[r * n..(r + 1) * n].iter().zip(&x).map(|(p, x)| p * x).sum();
                *nxr = dot + s.g0[r] * vc + s.g1[r] * vp;
            }
            std::mem::swap(&mut x, &mut nx);
            vp = vc;
        }
    }
}

/// The problem: data, segments and one process structure per input.
pub struct Problem<'a> {
    pub y: &'a [f64],
    /// Row-major `len × m`.
    pub u: &'a [f64],
    pub m: usize,
    pub ts: f64,
    pub segments: &'a [(usize, usize)],
    pub processes: &'a [Process],
}

impl Problem<'_> {
    /// Checks shapes and segments.
    ///
    /// # Errors
    /// `ShapeMismatch` for inconsistent lengths or a segment beyond the data; `InvalidStructure`
    /// for a non-positive sampling time or a structure count other than the input count.
    pub fn check(&self) -> Result<()> {
        let len = self.y.len();
        if self.u.len() != len * self.m {
            return Err(ArxError::ShapeMismatch { what: "u".into(), expected: len * self.m, got: self.u.len() });
        }
        if self.processes.len() != self.m {
            return Err(ArxError::InvalidStructure(format!(
                "{} process structures for {} inputs; give one per input",
                self.processes.len(),
                self.m
            )));
        }
        if !(self.ts > 0.0 && self.ts.is_finite()) {
            return Err(ArxError::InvalidStructure(format!("the sampling time must be > 0, got {}", self.ts)));
        }
        for &(a, b) in self.segments {
            if a > b || b > len {
                return Err(ArxError::ShapeMismatch { what: "segment end".into(), expected: len, got: b });
            }
        }
        Ok(())
    }

    pub fn n_params(&self) -> usize {
        self.processes.iter().map(Process::n_params).sum()
    }

    fn n_rows(&self) -> usize {
        self.segments.iter().map(|(a, b)| b - a).sum()
    }

    /// Offset of each input's parameters in the parameter vector.
    fn offsets(&self) -> Vec<usize> {
        let mut at = 0;
        self.processes
            .iter()
            .map(|p| {
                let o = at;
                at += p.n_params();
                o
            })
            .collect()
    }

    /// Input `i`'s simulated output on the segments' rows (None when its sample is not finite).
    fn part(&self, i: usize, p: &[f64]) -> Option<Vec<f64>> {
        let (num, den, tau) = self.processes[i].transfer(p);
        if !den.iter().chain(&num).all(|v| v.is_finite()) || !tau.is_finite() || tau < 0.0 {
            return None;
        }
        let s = sample(&num, &den, tau, self.ts)?;
        let mut out = vec![0.0; self.n_rows()];
        simulate_into(&s, self.u, self.m, i, self.segments, &mut out);
        Some(out)
    }

    /// The measured output on the segments' rows.
    fn target(&self) -> Vec<f64> {
        self.segments.iter().flat_map(|&(a, b)| self.y[a..b].iter().copied()).collect()
    }

    /// The model's output, NaN outside the segments, for parameters `x`.
    ///
    /// # Errors
    /// `NotConverged` when a model cannot be sampled (non-finite parameters or exponential).
    pub fn simulate(&self, x: &[f64]) -> Result<Vec<f64>> {
        self.check()?;
        if x.len() != self.n_params() {
            return Err(ArxError::ShapeMismatch { what: "parameters".into(), expected: self.n_params(), got: x.len() });
        }
        let mut sum = vec![0.0; self.n_rows()];
        for (i, o) in self.offsets().into_iter().enumerate() {
            let part = self.part(i, &x[o..o + self.processes[i].n_params()]).ok_or_else(|| {
                ArxError::NotConverged(format!("the process model of input {i} cannot be sampled (parameters {x:?})"))
            })?;
            sum.iter_mut().zip(&part).for_each(|(s, p)| *s += p);
        }
        let mut out = vec![f64::NAN; self.y.len()];
        let mut row = 0;
        for &(a, b) in self.segments {
            out[a..b].copy_from_slice(&sum[row..row + b - a]);
            row += b - a;
        }
        Ok(out)
    }

    /// Physical bounds intersected with the caller's: time constants (and `Tw`) >= `1e-6·ts`,
    /// `Zeta` >= 1e-6, `Td` >= 0.
    pub fn bounds(&self, lower: &[f64], upper: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let p = self.n_params();
        for (what, v) in [("lower bounds", lower), ("upper bounds", upper)] {
            if v.len() != p {
                return Err(ArxError::ShapeMismatch { what: what.into(), expected: p, got: v.len() });
            }
        }
        let kinds: Vec<Kind> = self.processes.iter().flat_map(Process::kinds).collect();
        let mut lo = lower.to_vec();
        for (l, k) in lo.iter_mut().zip(&kinds) {
            let floor = match k {
                Kind::TimeConstant => 1e-6 * self.ts,
                Kind::Zeta => 1e-6,
                Kind::DeadTime => 0.0,
                Kind::Gain | Kind::Zero => f64::NEG_INFINITY,
            };
            *l = l.max(floor);
        }
        for (j, (l, h)) in lo.iter().zip(upper).enumerate() {
            if l.is_nan() || h.is_nan() || l > h {
                return Err(ArxError::InvalidStructure(format!(
                    "the bounds of parameter {j} are empty or not numbers ({l} to {h}); give a lower bound below the \
                     upper one (time constants and Zeta above 0, the dead time at least 0)"
                )));
            }
        }
        Ok((lo, upper.to_vec()))
    }
}

/// Options of the refinement.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Cap on the Levenberg–Marquardt iterations (Jacobian evaluations).
    pub max_iterations: usize,
    /// Relative decrease of the cost that counts as none.
    pub ftol: f64,
    /// Relative step that counts as none.
    pub xtol: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self { max_iterations: 100, ftol: 1e-12, xtol: 1e-10 }
    }
}

/// What the refinement found.
#[derive(Debug, Clone)]
pub struct Refined {
    pub x: Vec<f64>,
    /// `JᵀJ` at `x` (row-major p × p), for the covariance `σ² (JᵀJ)⁻¹`.
    pub jtj: Vec<f64>,
    /// The residual `y − ŷ` on the segments' rows.
    pub residual: Vec<f64>,
    pub iterations: usize,
    pub evaluations: usize,
    pub converged: bool,
    /// Which parameters ended on a bound.
    pub on_bound: Vec<bool>,
}

struct State {
    parts: Vec<Vec<f64>>,
    r: Vec<f64>,
    cost: f64,
}

fn residual(target: &[f64], parts: &[Vec<f64>]) -> (Vec<f64>, f64) {
    let mut r = target.to_vec();
    for p in parts {
        r.iter_mut().zip(p).for_each(|(r, p)| *r -= p);
    }
    let cost = r.iter().map(|v| v * v).sum::<f64>();
    (r, if cost.is_finite() { cost } else { f64::INFINITY })
}

/// The bounded prediction-error refinement from `x0` (projected onto the bounds): see the module
/// documentation.
///
/// # Errors
/// Shape and structure errors of [`Problem::check`] and [`Problem::bounds`]; `NotConverged` when
/// the starting model cannot be simulated; `Interrupted` once `cancel` is set (checked before
/// every simulation).
pub fn refine(
    pb: &Problem<'_>,
    x0: &[f64],
    lower: &[f64],
    upper: &[f64],
    opts: Options,
    cancel: &AtomicBool,
) -> Result<Refined> {
    pb.check()?;
    let p = pb.n_params();
    if x0.len() != p {
        return Err(ArxError::ShapeMismatch { what: "starting parameters".into(), expected: p, got: x0.len() });
    }
    let (lo, hi) = pb.bounds(lower, upper)?;
    let kinds: Vec<Kind> = pb.processes.iter().flat_map(Process::kinds).collect();
    let owner: Vec<usize> = pb.processes.iter().enumerate().flat_map(|(i, s)| vec![i; s.n_params()]).collect();
    let offsets = pb.offsets();
    let target = pb.target();
    let mut evaluations = 0usize;
    let stop = || if cancel.load(Ordering::Relaxed) { Err(ArxError::Interrupted) } else { Ok(()) };
    let mut eval_part = |i: usize, x: &[f64], evals: &mut usize| -> Result<Option<Vec<f64>>> {
        stop()?;
        *evals += 1;
        let o = offsets[i];
        Ok(pb.part(i, &x[o..o + pb.processes[i].n_params()]))
    };
    let mut x: Vec<f64> = x0.iter().zip(lo.iter().zip(&hi)).map(|(v, (l, h))| v.clamp(*l, *h)).collect();
    let mut parts = Vec::with_capacity(pb.m);
    for i in 0..pb.m {
        parts.push(eval_part(i, &x, &mut evaluations)?.ok_or_else(|| {
            ArxError::NotConverged(format!("the starting process model of input {i} cannot be simulated"))
        })?);
    }
    let (r, cost) = residual(&target, &parts);
    if !cost.is_finite() {
        return Err(ArxError::NotConverged("the starting process model's simulation diverged".into()));
    }
    let mut st = State { parts, r, cost };
    let mut lambda = 1e-3;
    let mut scale = vec![0.0f64; p];
    let mut converged = false;
    let mut iterations = 0;
    let (mut g, mut h) = jacobian(pb, &st, &x, &hi, &kinds, &owner, &mut eval_part, &mut evaluations)?;
    while iterations < opts.max_iterations {
        iterations += 1;
        for j in 0..p {
            scale[j] = scale[j].max(h[j * p + j]).max(1e-300);
        }
        let free: Vec<usize> =
            (0..p).filter(|&j| !((x[j] <= lo[j] && g[j] > 0.0) || (x[j] >= hi[j] && g[j] < 0.0))).collect();
        if free.is_empty() {
            converged = true;
            break;
        }
        let mut accepted = None;
        while lambda < 1e16 {
            let k = free.len();
            let mut a = vec![0.0; k * k];
            for (r, &jr) in free.iter().enumerate() {
                for (c, &jc) in free.iter().enumerate() {
                    a[r * k + c] = h[jr * p + jc];
                }
                a[r * k + r] += lambda * scale[jr];
            }
            let rhs: Vec<f64> = free.iter().map(|&j| -g[j]).collect();
            let Some(step) = solve(a, rhs, k, 1) else {
                lambda *= 4.0;
                continue;
            };
            let mut trial = x.clone();
            for (&j, d) in free.iter().zip(&step) {
                trial[j] = (x[j] + d).clamp(lo[j], hi[j]);
            }
            let mut tparts = Vec::with_capacity(pb.m);
            for i in 0..pb.m {
                let changed = free.iter().any(|&j| owner[j] == i && trial[j] != x[j]);
                let part = if changed { eval_part(i, &trial, &mut evaluations)? } else { Some(st.parts[i].clone()) };
                tparts.push(part);
            }
            let tparts: Option<Vec<Vec<f64>>> = tparts.into_iter().collect();
            let (tr, tcost) = tparts.as_ref().map_or((Vec::new(), f64::INFINITY), |tp| residual(&target, tp));
            if tcost < st.cost {
                accepted = Some((trial, State { parts: tparts.unwrap_or_default(), r: tr, cost: tcost }));
                lambda = (lambda / 3.0).max(1e-12);
                break;
            }
            lambda *= 4.0;
        }
        let Some((trial, new)) = accepted else {
            converged = true; // no damped step lowers the cost: a (bounded) minimum to rounding
            break;
        };
        let dx = trial.iter().zip(&x).map(|(a, b)| ((a - b) / b.abs().max(1e-12)).powi(2)).sum::<f64>().sqrt();
        let df = (st.cost - new.cost) / st.cost.max(1e-300);
        x = trial;
        st = new;
        (g, h) = jacobian(pb, &st, &x, &hi, &kinds, &owner, &mut eval_part, &mut evaluations)?;
        if df < opts.ftol || dx < opts.xtol {
            converged = true;
            break;
        }
    }
    let on_bound = (0..p).map(|j| x[j] <= lo[j] || x[j] >= hi[j]).collect();
    Ok(Refined { x, jtj: h, residual: st.r, iterations, evaluations, converged, on_bound })
}

type Jac = (Vec<f64>, Vec<f64>);

/// Gradient `Jᵀ r` and `JᵀJ` of the forward-difference Jacobian `J` of the residual; a column whose perturbed model cannot be simulated is zero.
#[allow(clippy::too_many_arguments)]
fn jacobian(
    pb: &Problem<'_>,
    st: &State,
    x: &[f64],
    hi: &[f64],
    kinds: &[Kind],
    owner: &[usize],
    eval_part: &mut impl FnMut(usize, &[f64], &mut usize) -> Result<Option<Vec<f64>>>,
    evaluations: &mut usize,
) -> Result<Jac> {
    let p = x.len();
    let rows = st.r.len();
    let mut jac = vec![0.0; rows * p];
    for j in 0..p {
        let typical = match kinds[j] {
            Kind::TimeConstant | Kind::DeadTime | Kind::Zero => pb.ts,
            Kind::Gain => 1e-3,
            Kind::Zeta => 1e-2,
        };
        let mut step = 1e-7 * x[j].abs().max(typical);
        if x[j] + step > hi[j] {
            step = -step;
        }
        let mut t = x.to_vec();
        t[j] += step;
        let step = t[j] - x[j];
        let i = owner[j];
        if let Some(part) = eval_part(i, &t, evaluations)? {
            // r(t) − r(x) = −(part(t) − part(x)).
            let col = &mut jac[j * rows..(j + 1) * rows];
            for ((c, a), b) in col.iter_mut().zip(&part).zip(&st.parts[i]) {
                *c = -(a - b) / step;
            }
        }
    }
    let g: Vec<f64> =
        (0..p).map(|j| jac[j * rows..(j + 1) * rows].iter().zip(&st.r).map(|(a, b)| a * b).sum()).collect();
    let mut h = vec![0.0; p * p];
    for a in 0..p {
        for b in a..p {
            let v: f64 =
                jac[a * rows..(a + 1) * rows].iter().zip(&jac[b * rows..(b + 1) * rows]).map(|(x, y)| x * y).sum();
            h[a * p + b] = v;
            h[b * p + a] = v;
        }
    }
    Ok((g, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_with_fractional_delay_is_sampled_exactly() {
        // K/(T s + 1), τ = 1.3 ts: step response y(k ts) = K (1 − e^{−(k ts − τ)/T}) for k ts > τ.
        let (k, t, ts, tau) = (2.0, 0.7, 0.1, 0.13);
        let pr = Process::new(1, false, false, false, true).unwrap();
        let u = vec![1.0; 40];
        let y = vec![0.0; 40];
        let pb = Problem { y: &y, u: &u, m: 1, ts, segments: &[(0, 40)], processes: &[pr] };
        let out = pb.simulate(&[k, t, tau]).unwrap();
        for (i, v) in out.iter().enumerate() {
            let time = i as f64 * ts;
            let exact = if time > tau { k * (1.0 - (-(time - tau) / t).exp()) } else { 0.0 };
            assert!((v - exact).abs() < 1e-13, "{i}: {v} vs {exact}");
        }
    }

    #[test]
    fn refinement_recovers_a_p1d_and_stops_on_a_bound() {
        let (ts, len) = (0.1, 600);
        let u: Vec<f64> = (0..len).map(|k| if (k / 23 + k / 7) % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let pr = Process::new(1, false, false, false, true).unwrap();
        let zeros = vec![0.0; len];
        let truth = [2.0, 1.5, 0.47];
        let y =
            Problem { y: &zeros, u: &u, m: 1, ts, segments: &[(0, len)], processes: &[pr] }.simulate(&truth).unwrap();
        let pb = Problem { y: &y, u: &u, m: 1, ts, segments: &[(0, len)], processes: &[pr] };
        let never = AtomicBool::new(false);
        let inf = f64::INFINITY;
        let fit = refine(&pb, &[1.0, 1.0, 0.3], &[-inf; 3], &[inf, inf, 2.0], Options::default(), &never).unwrap();
        for (a, b) in fit.x.iter().zip(truth) {
            assert!((a - b).abs() < 1e-6, "{:?}", fit.x);
        }
        assert!(fit.converged);
        // Td capped at 0.3 s: stops on the bound.
        let fit = refine(&pb, &[1.0, 1.0, 0.1], &[-inf; 3], &[inf, inf, 0.3], Options::default(), &never).unwrap();
        assert_eq!(fit.x[2], 0.3);
        assert_eq!(fit.on_bound, vec![false, false, true]);
        // Cancelled: Interrupted.
        let err = refine(&pb, &[1.0, 1.0, 0.3], &[-inf; 3], &[inf; 3], Options::default(), &AtomicBool::new(true));
        assert_eq!(err.unwrap_err(), ArxError::Interrupted);
        // Empty bounds: a typed error.
        assert!(refine(&pb, &[1.0, 1.0, 0.3], &[0.0, 5.0, 0.0], &[inf, 1.0, 1.0], Options::default(), &never).is_err());
    }

    #[test]
    fn structures_are_checked() {
        assert!(Process::new(4, false, false, false, false).is_err());
        assert!(Process::new(1, false, true, false, false).is_err());
        let p = Process::new(3, true, true, true, true).unwrap();
        assert_eq!(p.n_params(), 6); // K, Tw, Zeta, Tp3, Tz, Td
        let (num, den, tau) = p.transfer(&[2.0, 0.5, 0.3, 0.2, 0.1, 0.05]);
        assert_eq!(tau, 0.05);
        assert_eq!(den.len(), 5);
        assert!((den[0] - 1.0).abs() < 1e-15 && den[4] == 0.0);
        assert_eq!(num.len(), 2);
    }
}
