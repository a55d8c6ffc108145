//! B, D and each segment's initial state by linear least squares on the data, A and C held fixed.
//!
//! With A and C known, the simulated output is linear in B, D and x0 (Verhaegen & Verdult 2007,
//! §9.2.4): `y(t) = C Aᵗ x0 + Σ_{k<t} C A^{t−1−k} B u(k) + D u(t) + v(t)`. Each output sample is one
//! regression row; its x0 and B columns are the rows of `C_o Aᵗ` and `Σ_k C_o A^{t−1−k} u_j(k)`,
//! run as the transposed filters `ξ(t+1) = Aᵀ ξ(t) + C_oᵀ u_j(t)` (n states per output and input:
//! n²·ny·nu operations a sample, where the state sensitivities ∂x/∂B would take n³·nu and a
//! product with C on top). Rows are reduced block by block, so N never sets the memory: to their
//! Gram (one matrix product a block), whose Cholesky factor is the segment's R when it is well
//! conditioned (noisy data), else by Householder QR (exact zeros for noise-free data). A segment's x0 columns touch only its own rows: each segment is reduced on
//! its own, its x0 rows kept for the back substitution, the rest stacked into the shared problem.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

use super::hankel::Signals;
use super::pseudo_inverse;
use crate::error::{ArxError, Result};
use crate::linalg::dense::{self, rows_product};
use crate::linalg::lagged_gram::cholesky_if_well_conditioned;
use crate::linalg::qr::{reduce_appended, stack_and_reduce, BLOCK_ROWS};

/// What [`input_matrices`] estimates.
#[derive(Debug)]
pub struct InputFit {
    /// n × nu.
    pub b: Mat<f64>,
    /// ny × nu (zero when D is not estimated).
    pub d: Mat<f64>,
    /// One initial state (length n) per segment (zero when not estimated).
    pub x0: Vec<Vec<f64>>,
}

/// Which matrices [`input_matrices`] estimates besides B.
#[derive(Clone, Copy, Debug)]
pub struct Unknowns {
    pub feedthrough: bool,
    pub initial_state: bool,
}

/// The regressor filters at a sample, row-major n × w: for each output o, `(Aᵀ)ᵗ C_oᵀ` (the x0
/// columns, when estimated: the first `f·ny` columns, f = 1) and, for each input j,
/// `Σ_k (Aᵀ)^{t−1−k} C_oᵀ u_j(k)` (column `f·ny + o·nu + j`). Row-major, so each update is n²
/// contiguous axpys; the x0 filters are dropped (zero) once they have died out.
#[derive(Clone)]
struct Sensitivity {
    s: Vec<f64>,
    /// First column still changing (f·ny once the x0 filters have died out).
    live: usize,
}

/// A matrix as row-major values, for the sample loops.
fn row_major(m: MatRef<'_, f64>) -> Vec<f64> {
    (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)])).collect()
}

impl Sensitivity {
    /// At a segment's first sample (`c` row-major ny × n).
    fn start(n: usize, nu: usize, ny: usize, x0: bool, c: &[f64]) -> Self {
        let free = if x0 { ny } else { 0 };
        let w = free + ny * nu;
        let mut s = vec![0.0; n * w];
        for o in 0..free {
            for i in 0..n {
                s[i * w + o] = c[o * n + i];
            }
        }
        Self { s, live: 0 }
    }

    /// One sample on: `ξ ← Aᵀ ξ + C_oᵀ u_j` (`at` = Aᵀ row-major n × n, `c` row-major ny × n).
    fn step(&mut self, at: &[f64], c: &[f64], free: usize, u: &[f64], scratch: &mut Vec<f64>) {
        let n = at.len().isqrt();
        let w = self.s.len() / n;
        let nu = u.len();
        scratch.resize(self.s.len(), 0.0);
        rows_product(at, &self.s, n, self.live, scratch);
        for (i, out) in scratch.chunks_exact_mut(w).enumerate().filter(|_| nu > 0) {
            for (o, forced) in out[free..].chunks_exact_mut(nu).enumerate() {
                let weight = c[o * n + i];
                for (f, &uj) in forced.iter_mut().zip(u) {
                    *f += weight * uj;
                }
            }
        }
        std::mem::swap(&mut self.s, scratch);
        self.settle(n, free);
    }

    /// Once Aᵗ has died out, stops the x0 filters before they turn subnormal (100x slower arithmetic).
    fn settle(&mut self, n: usize, free: usize) {
        let w = self.s.len() / n;
        if self.live < free && self.s.chunks_exact(w).all(|row| row[..free].iter().all(|v| v.abs() < 1e-150)) {
            self.s.chunks_exact_mut(w).for_each(|row| row[..free].fill(0.0));
            self.live = free;
        }
    }
}

/// The filters at each chunk's first sample, from `first` at the segment's. They are linear: a
/// chunk's last state is `(Aᵀ)^len` times its first plus its response from zero, and those
/// responses are found for every chunk at once (in parallel); the first states then follow in
/// order, one n × n by n × w product each, where stepping through every sample in order would
/// leave the other cores idle.
fn chunk_starts(
    at: &[f64],
    c: &[f64],
    s: &Signals<'_>,
    bounds: &[(usize, usize)],
    first: Sensitivity,
    free: usize,
) -> Vec<Sensitivity> {
    let (n, nu) = (at.len().isqrt(), s.n_inputs);
    let forced: Vec<Vec<f64>> = bounds[..bounds.len().saturating_sub(1)]
        .par_iter()
        .map(|&(t0, t1)| {
            let (mut zero, mut scratch) = (Sensitivity { s: vec![0.0; first.s.len()], live: free }, Vec::new());
            for t in t0..t1 {
                zero.step(at, c, free, &s.u[t * nu..(t + 1) * nu], &mut scratch);
            }
            zero.s
        })
        .collect();
    let power = bounds.first().map_or_else(Vec::new, |&(t0, t1)| matrix_power(at, n, t1 - t0));
    let mut starts = vec![first];
    for response in forced {
        let previous = &starts[starts.len() - 1];
        let mut next = Sensitivity { s: response, live: previous.live };
        let mut homogeneous = vec![0.0; next.s.len()];
        rows_product(&power, &previous.s, n, previous.live, &mut homogeneous);
        next.s.iter_mut().zip(&homogeneous).for_each(|(x, h)| *x += h);
        next.settle(n, free);
        starts.push(next);
    }
    starts
}

/// `m^k` of a row-major n × n matrix, by squaring.
fn matrix_power(m: &[f64], n: usize, mut k: usize) -> Vec<f64> {
    let (mut result, mut base): (Vec<f64>, _) =
        ((0..n * n).map(|i| if i / n == i % n { 1.0 } else { 0.0 }).collect(), m.to_vec());
    while k > 0 {
        if k & 1 == 1 {
            result = dense::matmul(&result, &base, n);
        }
        base = dense::matmul(&base, &base, n);
        k >>= 1;
    }
    result
}

/// Samples per chunk of a segment: chunks are reduced in parallel, each from the filters at its
/// first sample ([`chunk_starts`]), and their Grams added (or R's stacked) in order, so the result
/// does not depend on the number of threads.
const CHUNK_SAMPLES: usize = 8192;

/// How a chunk's rows are reduced: to their Gram MᵀM (one matrix product per block of rows), or to
/// R by Householder QR (which keeps the zeros of noise-free data and rank-deficient inputs exact).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reduction {
    Gram,
    Householder,
}

/// The regression rows `[x0 | B | D | y]` of samples `t0..t1`, from `state` at `t0`, handed to
/// `take` a block (row-major, at most [`BLOCK_ROWS`] rows) at a time.
#[allow(clippy::too_many_arguments)]
fn chunk_rows(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    s: &Signals<'_>,
    (t0, t1): (usize, usize),
    mut state: Sensitivity,
    unknowns: Unknowns,
    cancel: &AtomicBool,
    mut take: impl FnMut(&[f64]),
) -> Result<()> {
    let (n, nu, ny) = (a.nrows(), s.n_inputs, s.n_outputs);
    let nx0 = if unknowns.initial_state { n } else { 0 };
    let nd = if unknowns.feedthrough { ny * nu } else { 0 };
    let q = nx0 + n * nu + nd + 1;
    let free = if unknowns.initial_state { ny } else { 0 };
    let w = free + ny * nu;
    let (at, c) = (row_major(a.transpose()), row_major(c));
    let mut block = vec![0.0; BLOCK_ROWS * q];
    let (mut filled, mut scratch) = (0, Vec::new());
    for t in t0..t1 {
        let u = &s.u[t * nu..(t + 1) * nu];
        for o in 0..ny {
            if filled == BLOCK_ROWS {
                if cancel.load(Ordering::Relaxed) {
                    return Err(ArxError::Interrupted);
                }
                take(&block);
                filled = 0;
            }
            let row = &mut block[filled * q..(filled + 1) * q];
            for (i, xi) in state.s.chunks_exact(w).enumerate() {
                if nx0 > 0 {
                    row[i] = xi[o];
                }
                for j in 0..nu {
                    row[nx0 + j * n + i] = xi[free + o * nu + j];
                }
            }
            if nd > 0 {
                let d = &mut row[nx0 + n * nu..q - 1];
                d.fill(0.0);
                for (j, &uj) in u.iter().enumerate() {
                    d[j * ny + o] = uj;
                }
            }
            row[q - 1] = s.y[t * ny + o];
            filled += 1;
        }
        state.step(&at, &c, free, u, &mut scratch);
    }
    take(&block[..filled * q]);
    Ok(())
}

/// The rows of samples `t0..t1` (from `state` at `t0`) reduced as `reduction` says: their Gram, or
/// their R, over the columns `[x0 | B | D | y]`.
#[allow(clippy::too_many_arguments)]
fn chunk_factor(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    s: &Signals<'_>,
    range: (usize, usize),
    state: Sensitivity,
    unknowns: Unknowns,
    reduction: Reduction,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let q = columns(a.nrows(), s, unknowns);
    let mut work = Mat::<f64>::zeros(if reduction == Reduction::Gram { q } else { q + BLOCK_ROWS }, q);
    chunk_rows(a, c, s, range, state, unknowns, cancel, |rows| {
        let m = MatRef::from_row_major_slice(rows, rows.len() / q, q);
        if reduction == Reduction::Gram {
            matmul(work.as_mut(), Accum::Add, m.transpose(), m, 1.0, Par::Seq);
        } else {
            work.as_mut().submatrix_mut(q, 0, m.nrows(), q).copy_from(m);
            reduce_appended(&mut work, m.nrows());
        }
    })?;
    Ok(work.as_ref().subrows(0, q).to_owned())
}

/// Columns of the regression `[x0 | B | D | y]`.
fn columns(n: usize, s: &Signals<'_>, unknowns: Unknowns) -> usize {
    let nx0 = if unknowns.initial_state { n } else { 0 };
    let nd = if unknowns.feedthrough { s.n_outputs * s.n_inputs } else { 0 };
    nx0 + n * s.n_inputs + nd + 1
}

/// The segment's R over the columns `[x0 | B | D | y]`: the Cholesky factor of the rows' Gram when
/// it is well conditioned ([`cholesky_if_well_conditioned`]: noisy data), else their Householder
/// QR (noise-free data, rank-deficient inputs, a short segment that does not see every mode).
fn segment_factor(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    s: &Signals<'_>,
    (start, end): (usize, usize),
    unknowns: Unknowns,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let (n, nu, ny) = (a.nrows(), s.n_inputs, s.n_outputs);
    let free = if unknowns.initial_state { ny } else { 0 };
    let (at, c_rows) = (row_major(a.transpose()), row_major(c));
    let bounds: Vec<(usize, usize)> =
        (start..end).step_by(CHUNK_SAMPLES).map(|t0| (t0, (t0 + CHUNK_SAMPLES).min(end))).collect();
    let first = Sensitivity::start(n, nu, ny, unknowns.initial_state, &c_rows);
    let chunks: Vec<_> = bounds.iter().copied().zip(chunk_starts(&at, &c_rows, s, &bounds, first, free)).collect();
    let reduce = |reduction: Reduction| {
        chunks
            .par_iter()
            .map(|(range, at)| chunk_factor(a, c, s, *range, at.clone(), unknowns, reduction, cancel))
            .collect::<Result<Vec<_>>>()
    };
    let q = columns(n, s, unknowns);
    let mut gram = Mat::<f64>::zeros(q, q);
    for part in reduce(Reduction::Gram)? {
        gram += part;
    }
    if let Some(l) = cholesky_if_well_conditioned(&gram) {
        return Ok(l.transpose().to_owned());
    }
    Ok(stack_and_reduce(&reduce(Reduction::Householder)?, q))
}

/// B (and D, and each segment's x0, as `unknowns` asks) minimising the simulation error of the
/// model with state matrices `a` (n × n) and `c` (ny × n) on `signals`.
///
/// # Errors
/// `TooFewSamples` when the data have fewer output samples than unknowns, `RankDeficient` when the
/// inputs do not determine B and D (a constant or repeated input), `Interrupted` on Ctrl-C.
pub fn input_matrices(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    signals: &Signals<'_>,
    unknowns: Unknowns,
    cancel: &AtomicBool,
) -> Result<InputFit> {
    let (n, nu, ny) = (a.nrows(), signals.n_inputs, signals.n_outputs);
    let nx0 = if unknowns.initial_state { n } else { 0 };
    let nd = if unknowns.feedthrough { ny * nu } else { 0 };
    let nb = n * nu + nd;
    let used: usize = signals.segments.iter().map(|&(s, e)| e - s).sum();
    let needed = nb + nx0 * signals.segments.len();
    if used * ny < needed {
        return Err(ArxError::TooFewSamples { needed, got: used * ny });
    }
    let mut shared = Vec::with_capacity(signals.segments.len());
    let mut initial_rows = Vec::with_capacity(signals.segments.len());
    for &segment in signals.segments {
        let r = segment_factor(a, c, signals, segment, unknowns, cancel)?;
        shared.push(r.as_ref().submatrix(nx0, nx0, nb + 1, nb + 1).to_owned());
        initial_rows.push(r.as_ref().subrows(0, nx0).to_owned());
    }
    let r = stack_and_reduce(&shared, nb + 1);
    // Each pivot against its own column's size: the columns' scales differ by orders of magnitude
    // (B's columns grow with slow modes, D's are the inputs).
    let column_size = |j: usize| (0..=j).map(|i| r[(i, j)] * r[(i, j)]).sum::<f64>().sqrt();
    if let Some(column) = (0..nb).find(|&j| r[(j, j)].abs().is_nan() || r[(j, j)].abs() <= 1e-10 * column_size(j)) {
        let ratio = r[(column, column)].abs() / column_size(column).max(f64::MIN_POSITIVE);
        return Err(ArxError::RankDeficient { column, ratio });
    }
    let mut theta = vec![0.0; nb];
    for i in (0..nb).rev() {
        let acc = r[(i, nb)] - ((i + 1)..nb).map(|j| r[(i, j)] * theta[j]).sum::<f64>();
        theta[i] = acc / r[(i, i)];
    }
    let b = Mat::from_fn(n, nu, |i, j| theta[j * n + i]);
    let d = Mat::from_fn(ny, nu, |o, j| if unknowns.feedthrough { theta[n * nu + j * ny + o] } else { 0.0 });
    let x0 = initial_rows
        .iter()
        .map(|rows| {
            if nx0 == 0 {
                return vec![0.0; n];
            }
            // R11 x0 = r1y − R12 θ, solved by pseudo-inverse: a short segment may not see every mode.
            let rhs = faer::Col::from_fn(nx0, |i| {
                rows[(i, nx0 + nb)] - (0..nb).map(|j| rows[(i, nx0 + j)] * theta[j]).sum::<f64>()
            });
            let r11 = rows.as_ref().submatrix(0, 0, nx0, nx0);
            let x = pseudo_inverse(r11) * rhs;
            (0..nx0).map(|i| x[i]).collect()
        })
        .collect();
    Ok(InputFit { b, d, x0 })
}
