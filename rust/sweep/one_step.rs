//! Stage 1 of a large sweep: every structure's parameters and one-step prediction losses straight
//! from the triangular factors of the grid's largest regressor, with no simulation (the ranking of
//! MATLAB's `arxstruc`), at a cost of about a microsecond per structure.
//!
//! A structure reads a subset $C$ of the envelope's columns. Its normal equations
//! $G_{CC}\,\theta = g_{Cy}$, with $G = R^\top R$, are solved by a Cholesky factor that is shared
//! between structures: structures are visited in the order of their column lists, and the rows of
//! the factor belonging to a common prefix of columns (the output lags and the first inputs' lags)
//! are kept from the previous structure. One step of iterative refinement against $R$ itself
//! (corrected semi-normal equations, Björck 1987) brings θ to least-squares accuracy, and the losses
//! are $\|R_{[:,C\cup y]}\,[-\theta; 1]\|^2$ without cancellation. A structure whose regressor is
//! nearly collinear in the Cholesky sense is solved by the exact QR path instead
//! ([`solve_subset`]), which also decides rank deficiency exactly as the exhaustive sweep does.

use rayon::prelude::*;

use crate::arx::columns::columns_into;
use crate::arx::fit::solve_subset;
use crate::arx::structure::Structure;
use crate::error::{ArxError, Result};
use crate::sweep::validation_gram::ValidationLoss;

/// Below this squared sine of the angle between a new column and the span of the columns before
/// it, the normal equations lose too many digits and the structure is solved by QR instead.
const CHOLESKY_MIN_SIN2: f64 = 1e-8;

/// Structures per parallel task (visited in column order inside a task, sharing factor rows).
const TASK: usize = 2048;

/// The one-step fit of one structure from the R factors.
#[derive(Debug, Clone)]
pub struct OneStep {
    pub theta: Vec<f64>,
    /// Residual sum of squares of the one-step predictor on the estimation rows.
    pub rss_est: f64,
    /// Same on the validation rows (NaN without validation data).
    pub rss_val: f64,
    /// Set when the structure could not be fitted (rank deficient); the numbers are then NaN.
    pub error: Option<ArxError>,
}

/// The two factors and their Gram matrix: what every structure is solved from.
pub struct Factors<'a> {
    /// Column-major (q × q) R of `[Φ_env | y]` on the estimation rows.
    pub r_est: &'a [f64],
    /// What the validation losses come from: the same factor on the validation rows, or their Gram
    /// matrix.
    pub(crate) val: Option<&'a ValidationLoss<'a>>,
    pub q: usize,
    pub n_est: usize,
    /// Row-major q × q $R^\top R$.
    gram: Vec<f64>,
}

impl<'a> Factors<'a> {
    pub(crate) fn new(r_est: &'a [f64], val: Option<&'a ValidationLoss<'a>>, q: usize, n_est: usize) -> Self {
        let mut gram = vec![0.0; q * q];
        for a in 0..q {
            for b in a..q {
                let (ca, cb) = (&r_est[a * q..a * q + a + 1], &r_est[b * q..b * q + a + 1]);
                let v: f64 = ca.iter().zip(cb).map(|(x, y)| x * y).sum();
                gram[a * q + b] = v;
                gram[b * q + a] = v;
            }
        }
        Factors { r_est, val, q, n_est, gram }
    }
}

/// Dot product with four partial sums: the additions of one sum no longer wait for each other
/// (the serial chain of a plain loop is four times longer), in a fixed order (deterministic).
/// Plain multiply and add: `mul_add` is a library call where the build does not assume FMA.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail += x * y;
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `‖R[:, cols] θ − R[:, q−1]‖²` for an upper-triangular column-major R, and the residual itself.
#[inline(always)]
fn residual(r: &[f64], q: usize, cols: &[usize], theta: &[f64], res: &mut [f64]) -> f64 {
    res.copy_from_slice(&r[(q - 1) * q..q * q]);
    for (&j, &t) in cols.iter().zip(theta) {
        for (x, &rij) in res[..=j].iter_mut().zip(&r[j * q..j * q + j + 1]) {
            *x -= rij * t;
        }
    }
    dot(res, res)
}

/// A Cholesky factor of $G_{CC}$ (row-major, `kmax` wide) and the forward-solved $L^{-1} g_{Cy}$,
/// valid for the first `valid` columns of `cols`.
struct SharedCholesky {
    cols: Vec<usize>,
    valid: usize,
    l: Vec<f64>,
    z: Vec<f64>,
    kmax: usize,
}

impl SharedCholesky {
    fn new(kmax: usize) -> Self {
        SharedCholesky { cols: Vec::new(), valid: 0, l: vec![0.0; kmax * kmax], z: vec![0.0; kmax], kmax }
    }

    /// Extends the factor to `cols`, keeping the rows of the common prefix. False when a pivot is
    /// too small for the normal equations (the factor is then valid up to that column only).
    #[inline(always)]
    fn factor(&mut self, f: &Factors, cols: &[usize]) -> bool {
        let keep = self.cols.iter().zip(cols).take(self.valid).take_while(|(a, b)| a == b).count();
        self.cols.clear();
        self.cols.extend_from_slice(cols);
        self.valid = keep;
        let (q, w, g) = (f.q, self.kmax, &f.gram);
        for i in keep..cols.len() {
            let gi = &g[cols[i] * q..cols[i] * q + q];
            let (done, row) = self.l.split_at_mut(i * w);
            let row = &mut row[..i + 1];
            for j in 0..i {
                let lj = &done[j * w..j * w + j + 1];
                row[j] = (gi[cols[j]] - dot(&row[..j], &lj[..j])) / lj[j];
            }
            let d = gi[cols[i]] - dot(&row[..i], &row[..i]);
            // NaN pivots fail too, hence the negated comparison.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            if !(d > CHOLESKY_MIN_SIN2 * gi[cols[i]]) {
                return false;
            }
            row[i] = d.sqrt();
            self.z[i] = (gi[q - 1] - dot(&row[..i], &self.z[..i])) / row[i];
            self.valid = i + 1;
        }
        true
    }

    /// Solves $L L^\top x = b$ in place (k = `b.len()`).
    #[inline(always)]
    fn solve(&self, b: &mut [f64]) {
        let (k, w) = (b.len(), self.kmax);
        for i in 0..k {
            b[i] = (b[i] - dot(&self.l[i * w..i * w + i], &b[..i])) / self.l[i * w + i];
        }
        self.back(b);
    }

    /// Solves $L^\top x = b$ in place.
    #[inline(always)]
    fn back(&self, b: &mut [f64]) {
        let (k, w) = (b.len(), self.kmax);
        // Column by column (rows of L are contiguous): each step is an axpy, not a serial sum.
        for i in (0..k).rev() {
            b[i] /= self.l[i * w + i];
            let bi = b[i];
            for (x, &lij) in b[..i].iter_mut().zip(&self.l[i * w..i * w + i]) {
                *x -= lij * bi;
            }
        }
    }
}

/// Scratch of one worker: the shared factor, a residual and a correction.
struct Scratch {
    chol: SharedCholesky,
    res: Vec<f64>,
    grad: Vec<f64>,
    step: Vec<f64>,
    cols: Vec<usize>,
}

/// One structure through the shared factor, or through QR when the factor refuses it.
#[inline(always)]
fn one(f: &Factors, w: &mut Scratch) -> OneStep {
    let q = f.q;
    let Scratch { chol, res, grad, step, cols } = w;
    let k = cols.len();
    let (theta, rss_est) = if chol.factor(f, cols) {
        let mut theta = chol.z[..k].to_vec();
        chol.back(&mut theta);
        // One refinement step: δ = (AᵀA)⁻¹ Aᵀ r with A = R[:, C], r = R[:, y] − A θ. The loss at
        // θ + δ is ‖r‖² − δᵀ Aᵀ r exactly (normal equations of δ), without another residual.
        let rr = residual(f.r_est, q, cols, &theta, res);
        grad.clear();
        grad.extend(cols.iter().map(|&j| dot(&f.r_est[j * q..j * q + j + 1], &res[..=j])));
        step.clear();
        step.extend_from_slice(grad);
        chol.solve(step);
        let g_dot_step = dot(grad, step);
        theta.iter_mut().zip(step.iter()).for_each(|(t, d)| *t += d);
        (theta, (rr - g_dot_step).max(0.0))
    } else {
        match solve_subset(f.r_est, q, cols, f.n_est) {
            Ok((theta, rss, _)) => (theta, rss),
            Err(e) => {
                return OneStep { theta: vec![f64::NAN; k], rss_est: f64::NAN, rss_val: f64::NAN, error: Some(e) };
            }
        }
    };
    let rss_val = match f.val {
        None => f64::NAN,
        Some(ValidationLoss::Factor(rv)) => residual(rv, q, cols, &theta, res),
        Some(ValidationLoss::Gram(g)) => {
            g.rss(cols, &theta).unwrap_or_else(|| residual(g.factor(), q, cols, &theta, res))
        }
    };
    OneStep { theta, rss_est, rss_val, error: None }
}

/// Structures between two heartbeats inside a task: a task of wide structures (hundreds of delays)
/// runs for a second or more, and a Ctrl-C should not wait for its end.
const BEAT: usize = 64;

/// One task of structures (visited in `chunk`'s order, sharing factor rows) with its own scratch,
/// calling `heartbeat()` every [`BEAT`] structures.
#[inline(always)]
fn task(
    f: &Factors,
    env: &Structure,
    structures: &[Structure],
    chunk: &[usize],
    kmax: usize,
    heartbeat: &(dyn Fn() + Sync),
) -> Vec<(usize, OneStep)> {
    let mut w = Scratch {
        chol: SharedCholesky::new(kmax),
        res: vec![0.0; f.q],
        grad: Vec::new(),
        step: Vec::new(),
        cols: Vec::new(),
    };
    chunk
        .iter()
        .enumerate()
        .map(|(n, &i)| {
            if n > 0 && n % BEAT == 0 {
                heartbeat();
            }
            columns_into(env, &structures[i], &mut w.cols);
            (i, one(f, &mut w))
        })
        .collect()
}

/// [`task`] in 256-bit vectors. No fused multiply-add is enabled, so every number is the one the
/// 128-bit build computes (the four partial sums of [`dot`] and each axpy element keep their
/// operations and order; only more of them run per instruction).
#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2")]
unsafe fn task_avx2(
    f: &Factors,
    env: &Structure,
    structures: &[Structure],
    chunk: &[usize],
    kmax: usize,
    heartbeat: &(dyn Fn() + Sync),
) -> Vec<(usize, OneStep)> {
    task(f, env, structures, chunk, kmax, heartbeat)
}

/// Whether [`task_avx2`] can run on this CPU.
fn wide_vectors() -> bool {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "x86")))]
    {
        false
    }
}

/// Orders (na, then per input the delay and the order) in which neighbours share most columns.
/// The visiting order changes no number, only how many factor rows are shared.
fn column_order(structures: &[Structure]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..structures.len()).collect();
    let Some(first) = structures.first() else {
        return order;
    };
    let n_fields = 1 + 2 * first.nb.len();
    let bits = |v: usize| (usize::BITS - v.leading_zeros()).max(1);
    let widths: Vec<u32> =
        (0..n_fields).map(|f| structures.iter().map(|s| bits(field(s, f))).max().unwrap_or(1)).collect();
    if widths.iter().sum::<u32>() <= 64 {
        // One integer key per structure: a fast sort of a million structures.
        let key = |s: &Structure| widths.iter().enumerate().fold(0u64, |k, (f, &w)| (k << w) | field(s, f) as u64);
        let keys: Vec<u64> = structures.iter().map(key).collect();
        order.sort_unstable_by_key(|&i| keys[i]);
    } else {
        order.sort_unstable_by(|&i, &j| {
            (0..n_fields).map(|f| field(&structures[i], f)).cmp((0..n_fields).map(|f| field(&structures[j], f)))
        });
    }
    order
}

/// Field `f` of the visiting order: 0 is na, then the delay and the order of each input.
#[inline]
fn field(s: &Structure, f: usize) -> usize {
    match f {
        0 => s.na,
        f if f % 2 == 1 => s.nk[(f - 1) / 2],
        f => s.nb[(f - 2) / 2],
    }
}

/// Parameters and one-step losses of every structure of a grid from the factors of its envelope
/// `env` (every structure's columns lie inside it), in grid order.
///
/// Results do not depend on the number of threads: each structure's numbers are computed by the
/// same operations whichever structure computed the shared rows first. `heartbeat()` is called
/// before each task of structures and every [`BEAT`] structures within one (a caller stops the
/// ranking by unwinding from it).
///
/// # Errors
/// `InvalidStructure` when a structure reads columns outside `env` or `q` does not match it.
pub fn one_step_all(
    f: &Factors,
    env: &Structure,
    structures: &[Structure],
    parallel: bool,
    heartbeat: &(dyn Fn() + Sync),
) -> Result<Vec<OneStep>> {
    if f.q != env.n_params() + 1
        || f.r_est.len() != f.q * f.q
        || matches!(f.val, Some(ValidationLoss::Factor(r)) if r.len() != f.q * f.q)
    {
        return Err(ArxError::InvalidStructure("the factors do not match the grid's envelope".into()));
    }
    let kmax = structures.iter().map(Structure::n_params).max().unwrap_or(0);
    let order = column_order(structures);
    let wide = wide_vectors();
    let run = |chunk: &[usize]| -> Vec<(usize, OneStep)> {
        heartbeat();
        if wide {
            // SAFETY: `wide_vectors` found the CPU features the function is compiled for.
            #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
            return unsafe { task_avx2(f, env, structures, chunk, kmax, heartbeat) };
        }
        task(f, env, structures, chunk, kmax, heartbeat)
    };
    let parts: Vec<Vec<(usize, OneStep)>> = if parallel {
        order.par_chunks(TASK).with_max_len(1).map(run).collect()
    } else {
        order.chunks(TASK).map(run).collect()
    };
    let mut out: Vec<Option<OneStep>> = vec![None; structures.len()];
    for (i, r) in parts.into_iter().flatten() {
        out[i] = Some(r);
    }
    Ok(out.into_iter().map(|r| r.expect("every structure is visited once")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::columns::{columns_in, envelope};
    use crate::arx::reduce::reduce;
    use crate::arx::structure::{usable_rows, Data};
    use crate::linalg::qr::to_col_major;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    /// Stage 1 equals the exact QR solve of every structure (parameters and both losses), and
    /// a duplicated input column is reported rank deficient as the exhaustive sweep reports it.
    #[test]
    fn one_step_equals_qr_solve_of_every_structure() {
        let n = 3000;
        let mut seed = 3;
        let mut u = vec![0.0; 2 * n];
        for x in u.iter_mut() {
            *x = lcg(&mut seed);
        }
        let mut y = vec![0.0; n];
        for t in 4..n {
            y[t] = 1.2 * y[t - 1] - 0.4 * y[t - 2] + 0.5 * u[2 * (t - 2)] - 0.3 * u[2 * (t - 1) + 1]
                + 0.05 * lcg(&mut seed);
        }
        let starts = [0, 1700];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let mut grid = Vec::new();
        for na in 0..=3 {
            for nb1 in 0..=2 {
                for nk1 in 0..=3 {
                    for nb2 in 1..=3 {
                        for nk2 in 0..=2 {
                            if na + nb1 > 0 {
                                grid.push(Structure::new(na, vec![nb1, nb2], vec![nk1, nk2], vec![]).unwrap());
                            }
                        }
                    }
                }
            }
        }
        let env = envelope(&grid).unwrap();
        let lag = env.max_lag();
        let rows = usable_rows(&d, &env, lag).0;
        let q = env.n_params() + 1;
        let r = to_col_major(&reduce(&d, &env, &rows, false));
        let rv = ValidationLoss::Factor(r.clone());
        let f = Factors::new(&r, Some(&rv), q, rows.len());
        let got = one_step_all(&f, &env, &grid, true, &|| {}).unwrap();
        let serial = one_step_all(&f, &env, &grid, false, &|| {}).unwrap();
        for ((s, a), b) in grid.iter().zip(&got).zip(&serial) {
            let cols = columns_in(&env, s);
            let (theta, rss, _) = solve_subset(&r, q, &cols, rows.len()).unwrap();
            for (x, y) in theta.iter().zip(&a.theta) {
                assert!((x - y).abs() <= 1e-10 * x.abs().max(1.0), "{s:?}: {x} vs {y}");
            }
            assert!((a.rss_est - rss).abs() <= 1e-10 * rss, "{s:?}");
            assert!((a.rss_val - rss).abs() <= 1e-10 * rss, "{s:?}");
            assert_eq!(a.theta, b.theta);
        }
        // The 256-bit path gives every number of the 128-bit one, to the bit.
        let kmax = grid.iter().map(Structure::n_params).max().unwrap();
        let all: Vec<usize> = (0..grid.len()).collect();
        let beats = std::sync::atomic::AtomicUsize::new(0);
        let beat = || {
            beats.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        for (i, r) in task(&f, &env, &grid, &all, kmax, &beat) {
            assert_eq!(r.theta, got[i].theta);
            assert_eq!(r.rss_est.to_bits(), got[i].rss_est.to_bits());
            assert_eq!(r.rss_val.to_bits(), got[i].rss_val.to_bits());
        }
        // A Ctrl-C is looked for every BEAT structures inside a task, not only between tasks.
        assert_eq!(beats.into_inner(), (grid.len() - 1) / BEAT);
        // u2 copied into u1: ARX(1,[1,1],[1,1]) reads the same column twice.
        let mut u2 = u.clone();
        for t in 0..n {
            u2[2 * t] = u2[2 * t + 1];
        }
        let d2 = Data::new(&y, &u2, 2, &starts).unwrap();
        let r2 = to_col_major(&reduce(&d2, &env, &rows, false));
        let f2 = Factors::new(&r2, None, q, rows.len());
        let dup = Structure::new(1, vec![1, 1], vec![1, 1], vec![]).unwrap();
        let out = one_step_all(&f2, &env, std::slice::from_ref(&dup), false, &|| {}).unwrap();
        assert!(matches!(out[0].error, Some(ArxError::RankDeficient { .. })), "{:?}", out[0].error);
        assert!(out[0].rss_est.is_nan() && out[0].rss_val.is_nan());
    }
}
