//! Prediction-error estimation of polynomial models (output-error, ARMAX, Box–Jenkins) in MATLAB's
//! form $A(q) y(t) = \sum_i B_i(q)/F_i(q)\, u_i(t - n_{k,i}) + C(q)/D(q)\, e(t)$.
//!
//! The prediction error is $\varepsilon = (D/C)\,(A y - \sum_i B_i/F_i\, u_i)$. Its gradient comes
//! from filtering; Gauss–Newton steps with Levenberg–Marquardt damping are solved by QR of the
//! Jacobian (TSQR in fixed row blocks, as the ARX fit), never by normal equations. The start is ARX
//! refined by simplified refined instrumental variables (SRIV) for B/F and by Hannan–Rissanen for
//! the noise model. F, C and D are kept stable by reflecting roots into the unit circle.
//!
//! Data are given as finite segments `[start, end)`. With [`Initial::Zero`] the filters start at
//! rest at each segment's first sample and the first [`PolyStructure::max_lag`] samples of a segment
//! are not scored. With [`Initial::Estimate`] every sample is scored and each segment's unknown
//! initial state is estimated with the parameters: the prediction error is affine in it, so it is
//! projected out of every Gauss–Newton step (variable projection with Kaufman's Jacobian).

use faer::c64;

use crate::arx::structure::MAX_ORDER;
use crate::error::{ArxError, Result};

/// Orders of a polynomial model. `nb[i] == 0` leaves input `i` out (then `nf[i]` must be 0).
#[derive(Debug, Clone, PartialEq)]
pub struct PolyStructure {
    pub na: usize,
    pub nb: Vec<usize>,
    pub nc: usize,
    pub nd: usize,
    pub nf: Vec<usize>,
    pub nk: Vec<usize>,
}

impl PolyStructure {
    /// # Errors
    /// `ShapeMismatch` when `nb`, `nf`, `nk` differ in length; `InvalidStructure` for an F without
    /// a B, no parameters at all, or orders above 2^40.
    pub fn new(na: usize, nb: Vec<usize>, nc: usize, nd: usize, nf: Vec<usize>, nk: Vec<usize>) -> Result<Self> {
        for (what, v) in [("nf (one order per input)", &nf), ("nk (one delay per input)", &nk)] {
            if v.len() != nb.len() {
                return Err(ArxError::ShapeMismatch { what: what.into(), expected: nb.len(), got: v.len() });
            }
        }
        let all =
            [na, nc, nd].into_iter().chain(nb.iter().copied()).chain(nf.iter().copied()).chain(nk.iter().copied());
        if all.clone().any(|v| v > MAX_ORDER) {
            return Err(ArxError::InvalidStructure("orders and delays must stay below 2^40 samples".into()));
        }
        if let Some(i) = (0..nb.len()).find(|&i| nb[i] == 0 && nf[i] > 0) {
            return Err(ArxError::InvalidStructure(format!(
                "input {i} has nf = {} but nb = 0: a denominator without a numerator cannot be identified; \
                 set nf = 0 for that input or give it nb >= 1",
                nf[i]
            )));
        }
        let s = PolyStructure { na, nb, nc, nd, nf, nk };
        if s.n_params() == 0 {
            return Err(ArxError::InvalidStructure("the model has no parameters: give nb >= 1".into()));
        }
        Ok(s)
    }

    /// Number of parameters: $n_a + \sum n_b + n_c + n_d + \sum n_f$.
    pub fn n_params(&self) -> usize {
        self.na + self.nb.iter().sum::<usize>() + self.nc + self.nd + self.nf.iter().sum::<usize>()
    }

    /// Samples at the start of each segment treated as initial conditions (not scored).
    pub fn max_lag(&self) -> usize {
        let mut lag = self.na.max(self.nc).max(self.nd);
        for i in 0..self.nb.len() {
            if self.nb[i] > 0 {
                lag = lag.max(self.nb[i] + self.nk[i] - 1).max(self.nf[i]);
            }
        }
        lag
    }

    pub(super) fn m(&self) -> usize {
        self.nb.len()
    }

    /// Inputs that enter the model (`nb > 0`) with their past-dependence $\max(n_b + n_k - 1, n_f)$.
    fn input_memory(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.m()).filter(|&i| self.nb[i] > 0).map(|i| (i, (self.nb[i] + self.nk[i] - 1).max(self.nf[i])))
    }

    /// Initial-state parameters of one segment with [`Initial::Estimate`]: the number of
    /// coefficients of the numerator $N$ of the free response $N(q)/(C \prod_i F_i)\,\delta(t - t_0)$
    /// that an unknown past of y, of the inputs and of the noise filter adds to the prediction error.
    pub fn n_initial(&self) -> usize {
        let nf: usize = self.nf.iter().sum();
        let noise = self.nc.max(self.nd);
        let mut n = if noise > 0 { noise + nf } else { 0 };
        if self.na > 0 {
            n = n.max(self.nd + self.na + nf);
        }
        self.input_memory().fold(n, |n, (i, mem)| n.max(self.nd + mem + nf - self.nf[i]))
    }

    /// Initial-state parameters of one segment of the free run $\sum_i B_i/(A F_i)\, u_i$: the
    /// numerator order of its free response over $A \prod_i F_i$.
    pub fn n_initial_free_run(&self) -> usize {
        let nf: usize = self.nf.iter().sum();
        self.input_memory().fold(0, |n, (i, _)| {
            let own = (self.nb[i] + self.nk[i] - 1).max(self.na + self.nf[i]);
            n.max(own + nf - self.nf[i])
        })
    }
}

/// How the filters start at the first sample of each segment (MATLAB's `InitialCondition`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Initial {
    /// At rest; the first [`PolyStructure::max_lag`] samples of each segment are not scored.
    #[default]
    Zero,
    /// The initial state of each segment is estimated (nuisance parameters); every sample is scored.
    Estimate,
}

/// The polynomials of a parameter vector: A, C, D, F_i monic (leading 1), B_i without the delay.
#[derive(Debug, Clone)]
pub struct Polys {
    pub a: Vec<f64>,
    pub b: Vec<Vec<f64>>,
    pub c: Vec<f64>,
    pub d: Vec<f64>,
    pub f: Vec<Vec<f64>>,
}

pub(super) fn monic(coefs: &[f64]) -> Vec<f64> {
    std::iter::once(1.0).chain(coefs.iter().copied()).collect()
}

impl Polys {
    /// Splits θ, ordered A, B (per input), C, D, F (per input) as MATLAB's `getpvec`.
    pub fn of(s: &PolyStructure, theta: &[f64]) -> Polys {
        let mut at = 0;
        let mut take = |n: usize| {
            let v = theta[at..at + n].to_vec();
            at += n;
            v
        };
        let a = monic(&take(s.na));
        let b = s.nb.iter().map(|&n| take(n)).collect();
        let c = monic(&take(s.nc));
        let d = monic(&take(s.nd));
        let f = s.nf.iter().map(|&n| monic(&take(n))).collect();
        Polys { a, b, c, d, f }
    }

    /// θ in `getpvec` order.
    pub fn theta(&self) -> Vec<f64> {
        let mut out = self.a[1..].to_vec();
        self.b.iter().for_each(|b| out.extend_from_slice(b));
        out.extend_from_slice(&self.c[1..]);
        out.extend_from_slice(&self.d[1..]);
        self.f.iter().for_each(|f| out.extend_from_slice(&f[1..]));
        out
    }

    /// Reflects roots of C, D and every F_i outside the unit circle to 1/r̄ (stable predictor).
    pub fn stabilise(&mut self) {
        for p in std::iter::once(&mut self.c).chain(std::iter::once(&mut self.d)).chain(self.f.iter_mut()) {
            if !is_stable(p) {
                *p = reflect_into_unit_circle(p);
            }
        }
    }
}

/// Product of two polynomials in $q^{-1}$.
pub fn conv(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// $\mathrm{out} = (\mathrm{num}/\mathrm{den})\, x$ from rest; `den[0]` must be 1.
#[allow(clippy::needless_range_loop)]
pub fn filter(num: &[f64], den: &[f64], x: &[f64], out: &mut [f64]) {
    for t in 0..x.len() {
        let mut acc = 0.0;
        for (j, &n) in num.iter().enumerate().take(t + 1) {
            acc += n * x[t - j];
        }
        for (i, &d) in den.iter().enumerate().take(t + 1).skip(1) {
            acc -= d * out[t - i];
        }
        out[t] = acc;
    }
}

/// All roots of the monic polynomial $z^n + p_1 z^{n-1} + \dots + p_n$ (`p[0] = 1`) by
/// Aberth–Ehrlich iteration.
pub fn roots(p: &[f64]) -> Vec<c64> {
    let n = p.len() - 1;
    if n == 0 {
        return vec![];
    }
    let radius = 1.0 + p[1..].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut z: Vec<c64> =
        (0..n).map(|k| c64::from_polar(radius, 2.0 * std::f64::consts::PI * k as f64 / n as f64 + 0.4)).collect();
    let eval = |x: c64| -> (c64, c64) {
        let (mut v, mut dv) = (c64::new(p[0], 0.0), c64::new(0.0, 0.0));
        for &c in &p[1..] {
            dv = dv * x + v;
            v = v * x + c;
        }
        (v, dv)
    };
    for _ in 0..500 {
        let mut moved = 0.0_f64;
        for k in 0..n {
            let (v, dv) = eval(z[k]);
            if v.norm() == 0.0 {
                continue;
            }
            let ratio = v / dv;
            let repulsion: c64 = (0..n).filter(|&j| j != k).map(|j| (z[k] - z[j]).inv()).sum();
            let step = ratio / (c64::new(1.0, 0.0) - ratio * repulsion);
            if step.norm().is_finite() {
                z[k] -= step;
                moved = moved.max(step.norm() / z[k].norm().max(1e-300));
            }
        }
        if moved < 1e-15 {
            break;
        }
    }
    z
}

/// True when every root of the monic polynomial lies strictly inside the unit circle (Schur–Cohn
/// step-down: every reflection coefficient below 1 in magnitude).
pub fn is_stable(p: &[f64]) -> bool {
    let mut a = p.to_vec();
    while a.len() > 1 {
        let n = a.len() - 1;
        let k = a[n] / a[0];
        // NaN coefficients count as unstable too.
        if k.abs().partial_cmp(&1.0) != Some(std::cmp::Ordering::Less) {
            return false;
        }
        let next: Vec<f64> = (0..n).map(|i| (a[i] - k * a[n - i]) / (1.0 - k * k)).collect();
        a = next;
    }
    true
}

/// The monic polynomial whose roots are those of `p` with every root outside the unit circle
/// replaced by $1/\bar r$ (and roots on it pulled just inside).
pub fn reflect_into_unit_circle(p: &[f64]) -> Vec<f64> {
    let mut out = vec![c64::new(1.0, 0.0)];
    for r in roots(p) {
        let mag = r.norm();
        let r = if mag > 1.0 { r.conj().inv() } else { r };
        let r = if r.norm() >= 1.0 - 1e-9 { r * ((1.0 - 1e-6) / r.norm()) } else { r };
        let mut next = vec![c64::new(0.0, 0.0); out.len() + 1];
        for (i, &c) in out.iter().enumerate() {
            next[i] += c;
            next[i + 1] -= c * r;
        }
        out = next;
    }
    out.iter().map(|c| c.re).collect()
}

/// Measured data: output, row-major inputs (`u[t * m + i]`), finite segments `[start, end)`.
#[derive(Debug, Clone, Copy)]
pub struct Segments<'a> {
    pub y: &'a [f64],
    pub u: &'a [f64],
    pub m: usize,
    pub segments: &'a [(usize, usize)],
}

impl<'a> Segments<'a> {
    /// # Errors
    /// `ShapeMismatch` when `u` is not `len(y) × m`; `InvalidStructure` for a segment outside the data.
    pub fn new(y: &'a [f64], u: &'a [f64], m: usize, segments: &'a [(usize, usize)]) -> Result<Self> {
        if u.len() != y.len() * m {
            return Err(ArxError::ShapeMismatch {
                what: "u (samples × inputs)".into(),
                expected: y.len() * m,
                got: u.len(),
            });
        }
        if let Some(&(a, b)) = segments.iter().find(|&&(a, b)| a >= b || b > y.len()) {
            return Err(ArxError::InvalidStructure(format!("segment [{a}, {b}) is empty or outside the data")));
        }
        if let Some(w) = segments.windows(2).find(|w| w[1].0 < w[0].1) {
            return Err(ArxError::InvalidStructure(format!(
                "segments [{}, {}) and [{}, {}) overlap or are out of order: give them sorted and disjoint",
                w[0].0, w[0].1, w[1].0, w[1].1
            )));
        }
        Ok(Segments { y, u, m, segments })
    }

    /// Scored samples: every segment's samples after its first `lag`.
    pub fn rows(&self, lag: usize) -> Vec<usize> {
        self.segments.iter().flat_map(|&(a, b)| (a + lag).min(b)..b).collect()
    }

    /// Segments longer than `n` samples (those that say something beyond `n` initial-state parameters).
    pub fn longer_than(&self, n: usize) -> Vec<(usize, usize)> {
        self.segments.iter().copied().filter(|&(a, b)| b - a > n).collect()
    }

    /// Scored samples of `s`: from each segment's `max_lag`-th sample on with [`Initial::Zero`],
    /// every sample of the segments longer than [`PolyStructure::n_initial`] with [`Initial::Estimate`].
    pub fn scored(&self, s: &PolyStructure, initial: Initial) -> Vec<usize> {
        match initial {
            Initial::Zero => self.rows(s.max_lag()),
            Initial::Estimate => self.longer_than(s.n_initial()).into_iter().flat_map(|(a, b)| a..b).collect(),
        }
    }

    /// Input `i` delayed by `nk` within each segment (zero before), full length.
    pub(super) fn delayed(&self, i: usize, nk: usize) -> Vec<f64> {
        let mut x = vec![0.0; self.y.len()];
        for &(a, b) in self.segments {
            for (t, v) in x.iter_mut().enumerate().take(b).skip((a + nk).min(b)) {
                *v = self.u[(t - nk) * self.m + i];
            }
        }
        x
    }

    /// `num/den` applied to `x` within each segment from rest, full length.
    pub(super) fn filter(&self, num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        for &(a, b) in self.segments {
            filter(num, den, &x[a..b], &mut out[a..b]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflection_keeps_stable_roots_and_mirrors_unstable_ones() {
        // (1 - 2 q^-1)(1 - 0.5 q^-1) = 1 - 2.5 q^-1 + q^-2  ->  (1 - 0.5 q^-1)^2
        assert!(!is_stable(&[1.0, -2.5, 1.0]));
        let p = reflect_into_unit_circle(&[1.0, -2.5, 1.0]);
        assert!((p[1] + 1.0).abs() < 1e-9 && (p[2] - 0.25).abs() < 1e-9, "{p:?}");
        assert!(is_stable(&[1.0, -1.5, 0.7]));
    }
}
