//! Model structure (orders, delays, output nonlinearities) and the measured data it is applied to.
//!
//! ARX in MATLAB's sign convention:
//! $y(t) + a_1 y(t-1) + \dots + a_{n_a} y(t-n_a) = \sum_i \sum_{j=1}^{n_{b,i}} b_{ij} u_i(t-n_{k,i}-j+1)
//!  + \sum_l c_l g_l(y(t-1), y(t-2)) s_l(t-1) + e(t)$.
//!
//! The regressor row is therefore $[-y(t-1), \dots, -y(t-n_a), u_i(\cdot)\dots, g_l\dots]$.

use crate::error::{ArxError, Result};

/// A nonlinear function of the past output, the part of an effect that must be re-evaluated on
/// the simulated output in free run (`y^3`, `abs(y)`, `sign(y)`, `sign(dy)`, `y*u1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OutputKind {
    /// $y(t-1)^p$
    Pow(i32),
    /// $|y(t-1)|$
    Abs,
    /// $\mathrm{sign}(y(t-1))$, Coulomb friction when the output is a speed.
    Sign,
    /// $\mathrm{sign}(y(t-1) - y(t-2))$, Coulomb-type friction.
    SignDiff,
}

/// One output-derived regressor: $g(y(t-1), y(t-2)) \cdot s(t-1)$, `s` an optional input column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputTerm {
    pub kind: OutputKind,
    pub multiplier: Option<usize>,
}

impl OutputTerm {
    /// Number of past outputs the term reads.
    pub fn lag(&self) -> usize {
        match self.kind {
            OutputKind::SignDiff => 2,
            _ => 1,
        }
    }

    /// Value of the term from the two previous outputs and the multiplier sample $s(t-1)$.
    #[inline]
    pub fn eval(&self, y1: f64, y2: f64, s1: f64) -> f64 {
        let g = match self.kind {
            OutputKind::Pow(p) => y1.powi(p),
            OutputKind::Abs => y1.abs(),
            OutputKind::Sign => sign(y1),
            OutputKind::SignDiff => sign(y1 - y2),
        };
        g * s1
    }
}

/// Sign with sign(0) = 0 (numpy's convention, so Python and the core build the same regressors).
#[inline]
pub(crate) fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Orders of one ARX structure. `nb[i] == 0` means input `i` is not used.
#[derive(Debug, Clone, PartialEq)]
pub struct Structure {
    pub na: usize,
    pub nb: Vec<usize>,
    pub nk: Vec<usize>,
    pub output_terms: Vec<OutputTerm>,
}

/// Largest order or delay accepted (about 10^12 samples): beyond any data set that fits in memory,
/// and small enough that no lag or parameter count computed from the orders can overflow.
pub const MAX_ORDER: usize = 1 << 40;

impl Structure {
    /// # Errors
    /// `ShapeMismatch` when `nb` and `nk` differ in length, `InvalidStructure` for an order or delay
    /// above [`MAX_ORDER`].
    pub fn new(na: usize, nb: Vec<usize>, nk: Vec<usize>, output_terms: Vec<OutputTerm>) -> Result<Self> {
        if nb.len() != nk.len() {
            return Err(ArxError::ShapeMismatch {
                what: "nk (one delay per input)".into(),
                expected: nb.len(),
                got: nk.len(),
            });
        }
        let total = nb.iter().try_fold(na, |acc, &b| acc.checked_add(b));
        if na > MAX_ORDER || nb.iter().chain(&nk).any(|&v| v > MAX_ORDER) || total.is_none_or(|t| t > MAX_ORDER) {
            return Err(ArxError::InvalidStructure(format!(
                "orders too large (na = {na}, nb = {nb:?}, nk = {nk:?}): orders and delays must stay below 2^40 \
                 samples; use orders much smaller than the number of samples"
            )));
        }
        Ok(Structure { na, nb, nk, output_terms })
    }

    /// Number of parameters: $n_a + \sum n_b + $ output terms.
    pub fn n_params(&self) -> usize {
        self.na + self.nb.iter().sum::<usize>() + self.output_terms.len()
    }

    /// Largest lag any regressor reads; the first usable row of an experiment is this far in.
    pub fn max_lag(&self) -> usize {
        let mut lag = self.na;
        for (&b, &k) in self.nb.iter().zip(&self.nk) {
            if b > 0 {
                lag = lag.max(b + k - 1);
            }
        }
        for t in &self.output_terms {
            lag = lag.max(t.lag());
        }
        lag
    }

    pub fn check(&self, n_inputs: usize) -> Result<()> {
        if self.nb.len() != n_inputs {
            return Err(ArxError::ShapeMismatch {
                what: "nb (one order per input)".into(),
                expected: n_inputs,
                got: self.nb.len(),
            });
        }
        for t in &self.output_terms {
            if let Some(m) = t.multiplier {
                if m >= n_inputs {
                    return Err(ArxError::InvalidStructure(format!(
                        "output term multiplies input {m}, but there are {n_inputs} inputs"
                    )));
                }
            }
            if let OutputKind::Pow(p) = t.kind {
                if p < 1 {
                    return Err(ArxError::InvalidStructure(format!("output power must be >= 1, got {p}")));
                }
            }
        }
        if self.n_params() == 0 {
            return Err(ArxError::InvalidStructure("the model has no parameters (na = 0 and all nb = 0)".into()));
        }
        Ok(())
    }
}

/// Measured signals: output `y` (N), inputs `u` row-major (N × m), experiments starting at `starts`.
#[derive(Debug, Clone, Copy)]
pub struct Data<'a> {
    pub y: &'a [f64],
    pub u: &'a [f64],
    pub m: usize,
    /// Start index of each experiment, ascending, first one 0. Regressors never cross a start.
    pub starts: &'a [usize],
}

impl<'a> Data<'a> {
    pub fn new(y: &'a [f64], u: &'a [f64], m: usize, starts: &'a [usize]) -> Result<Self> {
        let n = y.len();
        if u.len() != n * m {
            return Err(ArxError::ShapeMismatch {
                what: "inputs u (n_samples × n_inputs)".into(),
                expected: n * m,
                got: u.len(),
            });
        }
        if starts.first() != Some(&0) && n > 0 {
            return Err(ArxError::InvalidStructure("experiment starts must begin with 0".into()));
        }
        if starts.windows(2).any(|w| w[0] >= w[1]) || starts.iter().any(|&s| s >= n.max(1)) {
            return Err(ArxError::InvalidStructure(
                "experiment starts must be strictly increasing and inside the data".into(),
            ));
        }
        Ok(Data { y, u, m, starts })
    }

    pub fn len(&self) -> usize {
        self.y.len()
    }

    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    #[inline]
    pub fn u_at(&self, t: usize, i: usize) -> f64 {
        self.u[t * self.m + i]
    }

    /// Upper bound on the regression rows that start `lag` samples into each experiment (before any
    /// NaN is left out): lets callers refuse too-short data before allocating per-parameter buffers.
    pub fn max_rows(&self, lag: usize) -> usize {
        self.segments().iter().map(|&(a, b)| (b - a).saturating_sub(lag)).sum()
    }

    /// Half-open sample ranges of the experiments.
    pub fn segments(&self) -> Vec<(usize, usize)> {
        let n = self.len();
        let mut out = Vec::with_capacity(self.starts.len());
        for (j, &s) in self.starts.iter().enumerate() {
            let e = self.starts.get(j + 1).copied().unwrap_or(n);
            out.push((s, e));
        }
        if self.starts.is_empty() && n > 0 {
            out.push((0, n));
        }
        out
    }
}

/// Writes the lagged outputs (negated with `negate_output`, as in `A(q)`) and inputs of `s` at time
/// `t` into the first entries of `row`; returns how many it wrote and whether all are finite.
#[inline]
pub fn fill_lags(d: &Data, s: &Structure, t: usize, negate_output: bool, row: &mut [f64]) -> (usize, bool) {
    let mut c = 0;
    let mut finite = true;
    for i in 1..=s.na {
        let v = if negate_output { -d.y[t - i] } else { d.y[t - i] };
        finite &= v.is_finite();
        row[c] = v;
        c += 1;
    }
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            let v = d.u_at(t - k - j, i);
            finite &= v.is_finite();
            row[c] = v;
            c += 1;
        }
    }
    (c, finite)
}

/// Fills `row` with the regressor of `s` at time `t` (followed by nothing else) and returns whether
/// every value is finite. The caller guarantees `t` is at least `s.max_lag()` into its experiment.
#[inline]
pub fn fill_row(d: &Data, s: &Structure, t: usize, row: &mut [f64]) -> bool {
    let (mut c, mut finite) = fill_lags(d, s, t, true, row);
    for term in &s.output_terms {
        let y1 = d.y[t - 1];
        let y2 = if term.lag() >= 2 { d.y[t - 2] } else { 0.0 };
        let s1 = term.multiplier.map_or(1.0, |m| d.u_at(t - 1, m));
        let v = term.eval(y1, y2, s1);
        finite &= v.is_finite();
        row[c] = v;
        c += 1;
    }
    finite
}

/// Regression rows of `s` on `d`: rows start `first_lag` into each experiment (at least the
/// structure's own lag); rows whose regressor or output touch a non-finite value are skipped.
/// Returns the row indices and how many rows were skipped for NaN/inf.
pub fn usable_rows(d: &Data, s: &Structure, first_lag: usize) -> (Vec<usize>, usize) {
    let lag = first_lag.max(s.max_lag());
    let mut row = vec![0.0; s.n_params()];
    let mut rows = Vec::new();
    let mut skipped = 0;
    for (a, b) in d.segments() {
        for t in (a + lag)..b {
            if fill_row(d, s, t, &mut row) && d.y[t].is_finite() {
                rows.push(t);
            } else {
                skipped += 1;
            }
        }
    }
    (rows, skipped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_power_term_is_squaring_and_multiplying() {
        // The Python layer writes y^p regressors the same way (arxid.models.effects.integer_power),
        // so a term has the same bits in the regression and in the simulation.
        let square_and_multiply = |mut a: f64, mut p: i32| {
            let mut r = 1.0;
            loop {
                if p & 1 == 1 {
                    r *= a;
                }
                p /= 2;
                if p == 0 {
                    return r;
                }
                a *= a;
            }
        };
        let mut state = 7u64;
        for _ in 0..10_000 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let x = ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 9.7;
            for p in 1..8 {
                let p = std::hint::black_box(p);
                assert_eq!(x.powi(p).to_bits(), square_and_multiply(x, p).to_bits(), "{x}^{p}");
            }
        }
    }

    #[test]
    fn sign_terms_follow_numpy_sign_with_zero_at_zero() {
        let t = |kind| OutputTerm { kind, multiplier: None };
        assert_eq!(t(OutputKind::Sign).eval(-0.3, 5.0, 1.0), -1.0);
        assert_eq!(t(OutputKind::Sign).eval(0.0, 5.0, 1.0), 0.0);
        assert_eq!(t(OutputKind::SignDiff).eval(-0.3, -0.5, 2.0), 2.0);
        assert_eq!(t(OutputKind::Sign).lag(), 1);
        assert_eq!(t(OutputKind::SignDiff).lag(), 2);
    }
}
