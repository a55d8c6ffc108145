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

use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};

use faer::{c64, Mat};
use rayon::prelude::*;

use crate::error::{ArxError, Result};
use crate::fit::{inverse_gram, solve_subset};
use crate::qr::{back_substitute, check_rank, qr_r_in_place, rank_tolerance, small_qr, stack_and_reduce, take_r};
use crate::qr::{to_col_major, BLOCK_ROWS};
use crate::structure::MAX_ORDER;

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

    fn m(&self) -> usize {
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

fn monic(coefs: &[f64]) -> Vec<f64> {
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
    fn delayed(&self, i: usize, nk: usize) -> Vec<f64> {
        let mut x = vec![0.0; self.y.len()];
        for &(a, b) in self.segments {
            for (t, v) in x.iter_mut().enumerate().take(b).skip((a + nk).min(b)) {
                *v = self.u[(t - nk) * self.m + i];
            }
        }
        x
    }

    /// `num/den` applied to `x` within each segment from rest, full length.
    fn filter(&self, num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        for &(a, b) in self.segments {
            filter(num, den, &x[a..b], &mut out[a..b]);
        }
        out
    }
}

/// One column of a Jacobian or regressor: `sign · signal[t − lag]`.
#[derive(Debug, Clone, Copy)]
struct Column {
    signal: usize,
    lag: usize,
    sign: f64,
}

/// R factor ((p+1) × (p+1), column-major) of `[columns | target]` over `rows`, by TSQR. Lagged
/// values from before sample `floor` read as zero (the filters' rest before a segment).
fn reduce_columns(
    signals: &[Vec<f64>],
    cols: &[Column],
    target: &[f64],
    rows: &[usize],
    floor: usize,
    parallel: bool,
) -> Vec<f64> {
    let q = cols.len() + 1;
    let block_r = |block: &[usize]| -> Mat<f64> {
        let mut a = Mat::<f64>::zeros(block.len(), q);
        for (c, col) in cols.iter().enumerate() {
            let s = &signals[col.signal];
            for (dst, &t) in a.col_as_slice_mut(c).iter_mut().zip(block) {
                *dst = if t >= floor + col.lag { col.sign * s[t - col.lag] } else { 0.0 };
            }
        }
        for (dst, &t) in a.col_as_slice_mut(q - 1).iter_mut().zip(block) {
            *dst = target[t];
        }
        qr_r_in_place(a.as_mut());
        take_r(&a, q)
    };
    let blocks: Vec<Mat<f64>> = if parallel {
        rows.par_chunks(BLOCK_ROWS).map(block_r).collect()
    } else {
        rows.chunks(BLOCK_ROWS).map(block_r).collect()
    };
    to_col_major(&stack_and_reduce(&blocks, q))
}

/// Least squares of `target` on `cols` over `rows` by QR: θ and the residual sum of squares.
fn least_squares(
    signals: &[Vec<f64>],
    cols: &[Column],
    target: &[f64],
    rows: &[usize],
    parallel: bool,
) -> Result<(Vec<f64>, f64)> {
    let q = cols.len() + 1;
    let r = reduce_columns(signals, cols, target, rows, 0, parallel);
    let idx: Vec<usize> = (0..cols.len()).collect();
    let (theta, rss, _) = solve_subset(&r, q, &idx, rows.len())?;
    Ok((theta, rss))
}

/// Instrumental-variable estimate: solves $\sum \zeta \varphi^T \theta = \sum \zeta\, \mathrm{target}$
/// (square, solved by QR).
fn iv_solve(signals: &[Vec<f64>], phi: &[Column], zeta: &[Column], target: &[f64], rows: &[usize]) -> Result<Vec<f64>> {
    let p = phi.len();
    let at = |c: &Column, t: usize| c.sign * signals[c.signal][t - c.lag];
    // [Σ ζ φᵀ | Σ ζ target], column-major p × (p + 1).
    let mut a = vec![0.0; p * (p + 1)];
    for &t in rows {
        for (i, z) in zeta.iter().enumerate() {
            let zi = at(z, t);
            for (j, f) in phi.iter().enumerate() {
                a[i + j * p] += zi * at(f, t);
            }
            a[i + p * p] += zi * target[t];
        }
    }
    small_qr(&mut a, p, p + 1);
    check_rank(&a, p, p, rank_tolerance(rows.len(), p))?;
    let rhs: Vec<f64> = (0..p).map(|i| a[i + p * p]).collect();
    let mut theta = vec![0.0; p];
    back_substitute(&a, p, &rhs, &mut theta);
    Ok(theta)
}

/// Columns `sign · signal[t − k]` for k in `lags`.
fn lagged(signal: usize, lags: std::ops::Range<usize>, sign: f64) -> Vec<Column> {
    lags.map(|lag| Column { signal, lag, sign }).collect()
}

/// SISO output-error start: ARX least squares, then SRIV (Steiglitz–McBride with noise-free
/// instruments) for `iterations` rounds. Returns B and monic F.
#[allow(clippy::too_many_arguments)]
fn sriv(
    data: &Segments<'_>,
    z: &[f64],
    x: &[f64],
    nb: usize,
    nf: usize,
    rows: &[usize],
    iterations: usize,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<(Vec<f64>, Vec<f64>)> {
    // Signals: 0 z, 1 x (ARX); afterwards 0 zf, 1 xf, 2 instrument ẑf.
    let phi: Vec<Column> = lagged(0, 1..nf + 1, -1.0).into_iter().chain(lagged(1, 0..nb, 1.0)).collect();
    let (theta, _) = least_squares(&[z.to_vec(), x.to_vec()], &phi, z, rows, parallel)?;
    let mut f = monic(&theta[..nf]);
    let mut b = theta[nf..].to_vec();
    if nf == 0 {
        return Ok((b, f));
    }
    let zeta: Vec<Column> = lagged(2, 1..nf + 1, -1.0).into_iter().chain(lagged(1, 0..nb, 1.0)).collect();
    for _ in 0..iterations {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        if !is_stable(&f) {
            f = reflect_into_unit_circle(&f);
        }
        let zhat = data.filter(&b, &f, x);
        let one = [1.0];
        let signals = [data.filter(&one, &f, z), data.filter(&one, &f, x), data.filter(&one, &f, &zhat)];
        let theta = iv_solve(&signals, &phi, &zeta, &signals[0], rows)?;
        let change = theta[..nf].iter().zip(&f[1..]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        f = monic(&theta[..nf]);
        b = theta[nf..].to_vec();
        if change < 1e-10 {
            break;
        }
    }
    if !is_stable(&f) {
        f = reflect_into_unit_circle(&f);
    }
    Ok((b, f))
}

/// Orders of the high-order ARX / AR models of the Hannan–Rissanen noise start.
fn long_order(s: &PolyStructure, n_rows: usize) -> usize {
    let wanted = (4 * (s.na + s.nc + s.nd)).max(20);
    wanted.min(n_rows / (4 * (s.m() + 1)).max(1)).max(1)
}

/// The start of the iterations: B/F by SRIV (backfitting over inputs), A/B by ARX, the noise model
/// C/D by Hannan–Rissanen (long AR residuals, then least squares).
///
/// # Errors
/// As [`pem`] (`Interrupted` between refinement rounds once `cancel` is set).
pub fn start(
    data: &Segments<'_>,
    s: &PolyStructure,
    sriv_iterations: usize,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Vec<f64>> {
    let rows = data.rows(s.max_lag());
    let xs: Vec<Vec<f64>> = (0..s.m()).map(|i| data.delayed(i, s.nk[i])).collect();
    let mut p = Polys::of(s, &vec![0.0; s.n_params()]);
    if s.na > 0 {
        start_armax(data, s, &xs, &mut p, parallel)?;
    } else {
        let rounds = if s.m() > 1 { 3 } else { 1 };
        let mut w: Vec<Vec<f64>> = vec![vec![0.0; data.y.len()]; s.m()];
        for _ in 0..rounds {
            for i in (0..s.m()).filter(|&i| s.nb[i] > 0) {
                let z: Vec<f64> = (0..data.y.len())
                    .map(|t| data.y[t] - (0..s.m()).filter(|&j| j != i).map(|j| w[j][t]).sum::<f64>())
                    .collect();
                let (b, f) = sriv(data, &z, &xs[i], s.nb[i], s.nf[i], &rows, sriv_iterations, parallel, cancel)?;
                w[i] = data.filter(&b, &f, &xs[i]);
                p.b[i] = b;
                p.f[i] = f;
            }
        }
    }
    if s.nd > 0 || (s.nc > 0 && s.na == 0) {
        start_noise(data, s, &xs, &mut p, &rows, parallel)?;
    }
    p.stabilise();
    Ok(p.theta())
}

/// ARX (and, with C, the Hannan–Rissanen two-stage ARMAX) start for A and B.
fn start_armax(data: &Segments<'_>, s: &PolyStructure, xs: &[Vec<f64>], p: &mut Polys, parallel: bool) -> Result<()> {
    let mut signals = vec![data.y.to_vec()];
    signals.extend(xs.iter().cloned());
    let mut cols = lagged(0, 1..s.na + 1, -1.0);
    for i in 0..s.m() {
        cols.extend(lagged(1 + i, 0..s.nb[i], 1.0));
    }
    let lag = s.max_lag();
    let mut first = lag;
    if s.nc > 0 {
        let n = long_order(s, data.rows(lag).len());
        let mut long = lagged(0, 1..n + 1, -1.0);
        for i in 0..s.m() {
            long.extend(lagged(1 + i, 0..s.nb[i].max(n), 1.0));
        }
        let long_lag = n.max((0..s.m()).map(|i| s.nk[i] + s.nb[i].max(n) - 1).max().unwrap_or(0));
        let r = data.rows(long_lag);
        let (theta, _) = least_squares(&signals, &long, data.y, &r, parallel)?;
        signals.push(residual_of(&signals, &long, &theta, data.y, &r));
        cols.extend(lagged(signals.len() - 1, 1..s.nc + 1, 1.0));
        first = lag.max(long_lag + s.nc);
    }
    let rows = data.rows(first);
    let (theta, _) = least_squares(&signals, &cols, data.y, &rows, parallel)?;
    p.a = monic(&theta[..s.na]);
    let mut at = s.na;
    for i in 0..s.m() {
        p.b[i] = theta[at..at + s.nb[i]].to_vec();
        at += s.nb[i];
    }
    p.c = monic(&theta[at..at + s.nc]);
    Ok(())
}

/// `target − Σ θ_j col_j` on `rows`, zero elsewhere.
fn residual_of(signals: &[Vec<f64>], cols: &[Column], theta: &[f64], target: &[f64], rows: &[usize]) -> Vec<f64> {
    let mut e = vec![0.0; target.len()];
    for &t in rows {
        e[t] =
            target[t] - cols.iter().zip(theta).map(|(c, th)| th * c.sign * signals[c.signal][t - c.lag]).sum::<f64>();
    }
    e
}

/// Hannan–Rissanen start of C and D from the deterministic residual v = A y − Σ B/F u.
fn start_noise(
    data: &Segments<'_>,
    s: &PolyStructure,
    xs: &[Vec<f64>],
    p: &mut Polys,
    rows: &[usize],
    parallel: bool,
) -> Result<()> {
    let mut v = data.filter(&p.a, &[1.0], data.y);
    for ((b, f), x) in p.b.iter().zip(&p.f).zip(xs) {
        let w = data.filter(b, f, x);
        v.iter_mut().zip(&w).for_each(|(a, b)| *a -= b);
    }
    let n = long_order(s, rows.len());
    let lag = s.max_lag();
    let long_rows = data.rows(lag + n);
    let long = lagged(0, 1..n + 1, -1.0);
    let (theta, _) = least_squares(&[v.clone()], &long, &v, &long_rows, parallel)?;
    let e = residual_of(&[v.clone()], &long, &theta, &v, &long_rows);
    let cols: Vec<Column> = lagged(0, 1..s.nd + 1, -1.0).into_iter().chain(lagged(1, 1..s.nc + 1, 1.0)).collect();
    let hr_rows = data.rows(lag + n + s.nc);
    let (theta, _) = least_squares(&[v.clone(), e], &cols, &v, &hr_rows, parallel)?;
    p.d = monic(&theta[..s.nd]);
    p.c = monic(&theta[s.nd..]);
    Ok(())
}

/// The part of a signal an unknown initial state explains, per segment.
struct InitialFit {
    /// Segments it was fitted on (those longer than `n`).
    segments: Vec<(usize, usize)>,
    /// Parameters per segment.
    n: usize,
    /// $g$: in each segment, the impulse response of $1/\mathrm{den}$ from its first sample.
    basis: Vec<f64>,
    /// $\eta$ per segment: the fitted part is $\sum_{k<n} \eta_k\, g(t - k)$.
    states: Vec<Vec<f64>>,
    /// The fitted part, full length (zero outside the segments).
    response: Vec<f64>,
}

/// Least-squares fit of `target` by the free responses $q^{-k}/\mathrm{den}\;\delta(t - t_0)$,
/// $k < n$, within each segment longer than `n` ($t_0$ its first sample).
fn fit_initial(data: &Segments<'_>, den: &[f64], n: usize, target: &[f64], parallel: bool) -> InitialFit {
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
struct Evaluation {
    eps: Vec<f64>,
    signals: Vec<Vec<f64>>,
    columns: Vec<Column>,
    /// With [`Initial::Estimate`]: the initial states, already taken out of `eps`.
    initial: Option<InitialFit>,
}

fn evaluate(
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
fn jacobian_r(ev: &Evaluation, rows: &[usize], parallel: bool) -> Vec<f64> {
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

fn sum_squares(e: &[f64], rows: &[usize]) -> f64 {
    rows.iter().map(|&t| e[t] * e[t]).sum()
}

/// Why the iterations stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The full Gauss–Newton step would lower the loss by less than the tolerance (a minimum).
    Converged,
    /// An accepted step lowered the loss by less than the tolerance.
    SmallImprovement,
    /// The iteration limit was reached first.
    MaxIterations,
    /// No damped step lowered the loss although the gradient is not negligible.
    Stalled,
}

impl Termination {
    /// True when the end point is a (local) minimum by the first-order test.
    pub fn converged(self) -> bool {
        matches!(self, Termination::Converged | Termination::SmallImprovement)
    }
}

impl fmt::Display for Termination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Termination::Converged => {
                "converged: a Gauss-Newton step would improve the loss by less than the tolerance"
            }
            Termination::SmallImprovement => "converged: the last step improved the loss by less than the tolerance",
            Termination::MaxIterations => "stopped at the iteration limit before converging",
            Termination::Stalled => {
                "stalled: no damped step lowered the loss although the gradient is not negligible (poor scaling or a \
                 non-smooth point)"
            }
        })
    }
}

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

/// Levenberg–Marquardt step: minimises $\|R_{11}\delta + r\|^2 + \lambda \|\mathrm{diag}(s)\,\delta\|^2$
/// by QR of the stacked $[R_{11}, r; \sqrt\lambda\,\mathrm{diag}(s), 0]$.
fn damped_step(r: &[f64], p: usize, lambda: f64, scale: &[f64]) -> Vec<f64> {
    let (q, m) = (p + 1, 2 * p);
    let mut a = vec![0.0; m * q];
    for j in 0..q {
        for i in 0..=j.min(p - 1) {
            a[i + j * m] = r[i + j * q];
        }
    }
    for j in 0..p {
        a[p + j + j * m] = lambda.sqrt() * scale[j];
    }
    small_qr(&mut a, m, q);
    let rhs: Vec<f64> = (0..p).map(|i| a[i + p * m]).collect();
    let mut delta = vec![0.0; p];
    back_substitute(&a, m, &rhs, &mut delta);
    delta.iter().map(|d| -d).collect()
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

#[cfg(test)]
mod tests {
    use super::*;

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

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    #[test]
    fn reflection_keeps_stable_roots_and_mirrors_unstable_ones() {
        // (1 - 2 q^-1)(1 - 0.5 q^-1) = 1 - 2.5 q^-1 + q^-2  ->  (1 - 0.5 q^-1)^2
        assert!(!is_stable(&[1.0, -2.5, 1.0]));
        let p = reflect_into_unit_circle(&[1.0, -2.5, 1.0]);
        assert!((p[1] + 1.0).abs() < 1e-9 && (p[2] - 0.25).abs() < 1e-9, "{p:?}");
        assert!(is_stable(&[1.0, -1.5, 0.7]));
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
