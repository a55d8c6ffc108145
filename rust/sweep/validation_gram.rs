//! The one-step validation loss of every structure of a grid from one Gram matrix of the envelope's
//! regressor `[Φ | y]` on the validation rows, built from lagged products of the signals instead of
//! a QR reduction of the validation record.
//!
//! With $v = [-\theta; 1]$ on a structure's columns and the output, the loss is $v^\top G v$. The
//! entries of $G$ are sums $\sum_t a(t - l_a)\, b(t - l_b)$ over the rows; the entries that read the
//! same two signals at the same lag difference share one dot product and differ only by a few
//! samples at the ends of each experiment. Where $v^\top G v$ is the small difference of large
//! terms (a fit so good that forming $G$ has lost the digits that matter), the loss comes from the
//! QR factor of the validation rows instead, reduced once on first need.

use std::collections::HashMap;
use std::sync::OnceLock;

use rayon::prelude::*;

use crate::arx::reduce::reduce;
use crate::arx::structure::{Data, Structure};
use crate::linalg::lagged_products::dot_product;
use crate::linalg::qr::to_col_major;
use crate::sweep::grid_factors::rows_of;

/// Below this ratio of the loss to $\sum |v_a| |G_{ab}| |v_b|$ the Gram evaluation keeps fewer than
/// about ten digits of the loss, and the QR factor gives it.
const MIN_LOSS_RATIO: f64 = 1e-5;

/// One column of the envelope's regressor: signal `signal` (0 the output, 1 + i input i) read
/// `lag` samples back, times `sign`.
#[derive(Debug, Clone, Copy)]
struct Column {
    signal: usize,
    lag: usize,
    sign: f64,
}

/// How a sweep computes one-step losses on the validation rows.
pub(crate) enum ValidationLoss<'a> {
    /// Column-major R of `[Φ_env | y]` on the validation rows (a fleet's combined partials, or data
    /// with missing samples or output terms).
    Factor(Vec<f64>),
    /// The Gram matrix of the same regressor (complete data, linear structures).
    Gram(Box<ValidationGram<'a>>),
}

/// Row-major q × q Gram matrix of `[Φ_env | y]` on the validation rows, and what the QR factor of
/// the same rows is reduced from where the Gram matrix is not accurate enough.
pub(crate) struct ValidationGram<'a> {
    g: Vec<f64>,
    q: usize,
    signals: Vec<std::borrow::Cow<'a, [f64]>>,
    columns: Vec<Column>,
    ranges: Vec<(usize, usize)>,
    data: Data<'a>,
    env: Structure,
    first_lag: usize,
    factor: OnceLock<Vec<f64>>,
}

/// Whether the Gram path applies: linear envelope and no missing sample.
pub(crate) fn gram_applies(d: &Data, env: &Structure) -> bool {
    env.output_terms.is_empty() && d.y.iter().all(|v| v.is_finite()) && d.u.iter().all(|v| v.is_finite())
}

impl<'a> ValidationGram<'a> {
    /// The Gram matrix of the envelope `env` (linear, see [`gram_applies`]) on the rows from
    /// `first_lag` into each experiment of `d`, the rows [`rows_of`](super::least_squares) gives.
    pub(crate) fn new(d: &Data<'a>, env: &Structure, first_lag: usize, parallel: bool) -> Self {
        let mut signals: Vec<std::borrow::Cow<'a, [f64]>> = vec![d.y.into()];
        for i in 0..d.m {
            signals.push(if d.m == 1 { d.u.into() } else { d.u.iter().skip(i).step_by(d.m).copied().collect() });
        }
        let mut columns: Vec<Column> = (1..=env.na).map(|lag| Column { signal: 0, lag, sign: -1.0 }).collect();
        for (i, (&b, &k)) in env.nb.iter().zip(&env.nk).enumerate() {
            columns.extend((0..b).map(|j| Column { signal: 1 + i, lag: k + j, sign: 1.0 }));
        }
        columns.push(Column { signal: 0, lag: 0, sign: 1.0 });
        let lag = first_lag.max(env.max_lag());
        let ranges: Vec<(usize, usize)> = d.segments().into_iter().map(|(a, b)| ((a + lag).min(b), b)).collect();
        let q = columns.len();
        let mut gram = ValidationGram {
            g: vec![0.0; q * q],
            q,
            signals,
            columns,
            ranges,
            data: *d,
            env: env.clone(),
            first_lag,
            factor: OnceLock::new(),
        };
        gram.fill(parallel);
        gram
    }

    /// Fills G: the entries of one (signal, signal, lag difference) family from one dot product per
    /// experiment, plus the samples at its ends where their windows differ.
    fn fill(&mut self, parallel: bool) {
        let q = self.q;
        let mut families: HashMap<(usize, usize, isize), Vec<(usize, usize)>> = HashMap::new();
        for i in 0..q {
            for j in i..q {
                let (a, b) = (self.columns[i], self.columns[j]);
                families.entry((a.signal, b.signal, b.lag as isize - a.lag as isize)).or_default().push((i, j));
            }
        }
        let families: Vec<_> = families.into_values().collect();
        let this = &*self;
        let sums = |entries: &Vec<(usize, usize)>| -> Vec<(usize, usize, f64)> {
            let mut out: Vec<(usize, usize, f64)> = entries.iter().map(|&(i, j)| (i, j, 0.0)).collect();
            for &(t0, t1) in &this.ranges {
                this.family_sums(&mut out, t0, t1);
            }
            out
        };
        let filled: Vec<Vec<(usize, usize, f64)>> = if parallel {
            families.par_iter().with_max_len(1).map(sums).collect()
        } else {
            families.iter().map(sums).collect()
        };
        for (i, j, v) in filled.into_iter().flatten() {
            let v = v * self.columns[i].sign * self.columns[j].sign;
            self.g[i * q + j] = v;
            self.g[j * q + i] = v;
        }
    }

    /// Adds to each entry (i, j) of one family $\sum_{t_0 \le t < t_1} a(t - l_i)\, b(t - l_j)$.
    fn family_sums(&self, out: &mut [(usize, usize, f64)], t0: usize, t1: usize) {
        let (ci, cj) = (self.columns[out[0].0], self.columns[out[0].1]);
        let (a, b) = (&self.signals[ci.signal][..], &self.signals[cj.signal][..]);
        // In s = t − l_i the sum runs over [t0 − l_i, t1 − l_i) of a(s) b(s − d), d = l_j − l_i.
        let d = cj.lag as isize - ci.lag as isize;
        let term = |s: usize| a[s] * b[(s as isize - d) as usize];
        let lo_lag = out.iter().map(|&(i, _, _)| self.columns[i].lag).min().unwrap_or(0);
        let hi_lag = out.iter().map(|&(i, _, _)| self.columns[i].lag).max().unwrap_or(0);
        // The window every entry shares: [t0 − lo_lag, t1 − hi_lag).
        let (c0, c1) = (t0 - lo_lag, (t1 - hi_lag).max(t0 - lo_lag));
        let core = if c1 > c0 {
            let shift = (c0 as isize - d) as usize;
            dot_product(&a[c0..c1], &b[shift..shift + (c1 - c0)])
        } else {
            0.0
        };
        for e in out.iter_mut() {
            let l = self.columns[e.0].lag;
            let (w0, w1) = (t0 - l, t1 - l);
            e.2 += if c1 > c0 {
                // the entry's window less the shared one: its head before c0 and its tail from c1
                core + (w0..c0).map(term).sum::<f64>() + (c1..w1).map(term).sum::<f64>()
            } else {
                (w0..w1).map(term).sum::<f64>()
            };
        }
    }

    /// Residual sum of squares of θ (on the envelope's columns `cols`) over the validation rows,
    /// from G; `None` where G has lost too many of its digits (use [`Self::factor`]).
    pub(crate) fn rss(&self, cols: &[usize], theta: &[f64]) -> Option<f64> {
        let q = self.q;
        let k = cols.len();
        let at = |a: usize| if a < k { (cols[a], -theta[a]) } else { (q - 1, 1.0) };
        let (mut loss, mut size) = (0.0, 0.0);
        for a in 0..=k {
            let (ca, va) = at(a);
            let row = &self.g[ca * q..ca * q + q];
            let (mut s, mut m) = (0.0, 0.0);
            for b in 0..=k {
                let (cb, vb) = at(b);
                s += row[cb] * vb;
                m += (row[cb] * vb).abs();
            }
            loss += va * s;
            size += va.abs() * m;
        }
        // NaN (a diverging θ) also takes the factor, hence the negated comparison.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(loss > MIN_LOSS_RATIO * size) {
            return None;
        }
        Some(loss)
    }

    /// Column-major R of `[Φ_env | y]` on the validation rows, reduced on first need. Sequential:
    /// the callers are rayon workers, and a parallel reduction inside the once-cell could steal
    /// another caller's task and wait on itself.
    pub(crate) fn factor(&self) -> &[f64] {
        self.factor.get_or_init(|| {
            let rows = rows_of(&self.data, &self.env, self.first_lag);
            to_col_major(&reduce(&self.data, &self.env, &rows, false))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::columns::{columns_in, envelope};
    use crate::sweep::grid_factors::rss_from_r;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    /// Two inputs, three experiments (one shorter than the envelope's lag spread): the Gram loss
    /// equals the loss from the QR factor of the same rows to 1e-10, for fitted and arbitrary θ;
    /// a noise-free fit (loss and G cancelling) is refused and its factor is the QR one.
    #[test]
    fn gram_loss_equals_factor_loss() {
        for noise in [0.05, 0.0] {
            let mut refused = 0;
            let n = 4000;
            let mut seed = 11;
            let u: Vec<f64> = (0..2 * n).map(|_| lcg(&mut seed)).collect();
            let mut y = vec![0.0; n];
            for t in 4..n {
                y[t] = 1.2 * y[t - 1] - 0.4 * y[t - 2] + 0.5 * u[2 * (t - 2)] - 0.3 * u[2 * (t - 1) + 1]
                    + noise * lcg(&mut seed);
            }
            let starts = [0, 1700, 1712];
            let d = Data::new(&y, &u, 2, &starts).unwrap();
            let mut grid = Vec::new();
            for na in 0..=3 {
                for nb1 in 1..=2 {
                    for nk1 in 0..=3 {
                        grid.push(Structure::new(na, vec![nb1, 2], vec![nk1, 1], vec![]).unwrap());
                    }
                }
            }
            let env = envelope(&grid).unwrap();
            let lag = env.max_lag();
            let rows = rows_of(&d, &env, lag);
            let q = env.n_params() + 1;
            let r = to_col_major(&reduce(&d, &env, &rows, false));
            let gram = ValidationGram::new(&d, &env, lag, true);
            for (i, s) in grid.iter().enumerate() {
                let cols = columns_in(&env, s);
                let exact = crate::arx::fit::solve_subset(&r, q, &cols, rows.len()).unwrap().0;
                let other: Vec<f64> = (0..cols.len()).map(|c| (i + c) as f64 * 0.1 - 0.3).collect();
                for theta in [exact, other] {
                    let want = rss_from_r(&r, q, &cols, &theta);
                    match gram.rss(&cols, &theta) {
                        Some(got) => {
                            assert!((got - want).abs() <= 1e-10 * want, "{s:?} noise {noise}: {got} vs {want}")
                        }
                        None => refused += 1,
                    }
                }
            }
            // Noise-free, the structures that hold the plant (na >= 2, input 1 at delay 2) fit exactly.
            assert_eq!(refused > 0, noise == 0.0, "noise {noise}: {refused} refused");
            assert_eq!(gram.factor(), r.as_slice());
        }
    }
}
