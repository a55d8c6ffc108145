//! B, D and each segment's initial state by linear least squares on the data, A and C held fixed.
//!
//! With A and C known, the simulated output is linear in B, D and x0 (Verhaegen & Verdult 2007,
//! §9.2.4): `y(t) = C Aᵗ x0 + Σ_{k<t} C A^{t−1−k} B u(k) + D u(t) + v(t)`. Each output sample is one
//! regression row; its B columns come from the state sensitivity `S(t+1) = A S(t) + u(t)ᵀ ⊗ I`,
//! its x0 columns from `C Aᵗ`. Rows are reduced by Householder QR block by block, so N never
//! sets the memory. A segment's x0 columns touch only its own rows: each segment is reduced on
//! its own, its x0 rows kept for the back substitution, the rest stacked into the shared problem.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::{Mat, MatRef};
use rayon::prelude::*;

use super::hankel::Signals;
use super::pseudo_inverse;
use crate::error::{ArxError, Result};
use crate::linalg::qr::{qr_r_in_place, stack_and_reduce, BLOCK_ROWS};

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

/// Reduces the first `q + filled` rows of `work` (R so far on top, new rows below) to R on top.
fn reduce(work: &mut Mat<f64>, filled: usize) {
    let q = work.ncols();
    qr_r_in_place(work.as_mut().subrows_mut(0, q + filled));
    for j in 0..q {
        for i in (j + 1)..q {
            work[(i, j)] = 0.0; // Householder vectors, not R
        }
    }
}

/// `dst = a · src` for column-major `n × m` blocks (`a` n × n): the sensitivity recursion, without
/// allocation.
fn propagate(a: MatRef<'_, f64>, src: &[f64], dst: &mut [f64], n: usize) {
    for (s, d) in src.chunks_exact(n).zip(dst.chunks_exact_mut(n)) {
        for (i, v) in d.iter_mut().enumerate() {
            *v = (0..n).map(|k| a[(i, k)] * s[k]).sum();
        }
    }
}

/// The sensitivities at a sample: `sens` (∂x/∂B, column-major n × (n·nu), column j·n + i for
/// B[i, j]) and `free` (Aᵗ, n × n, zero once it has died out).
#[derive(Clone)]
struct Sensitivity {
    sens: Vec<f64>,
    free: Vec<f64>,
    decaying: bool,
}

impl Sensitivity {
    fn start(n: usize, nu: usize) -> Self {
        let free = (0..n * n).map(|k| if k % (n + 1) == 0 { 1.0 } else { 0.0 }).collect();
        Self { sens: vec![0.0; n * n * nu], free, decaying: true }
    }

    /// One sample on: `S ← A S + u ⊗ I`, `Aᵗ ← A Aᵗ` (while `initial_state`).
    fn step(&mut self, a: MatRef<'_, f64>, u: &[f64], initial_state: bool, scratch: &mut Vec<f64>) {
        let n = a.nrows();
        scratch.resize(self.sens.len(), 0.0);
        propagate(a, &self.sens, scratch, n);
        std::mem::swap(&mut self.sens, scratch);
        for (j, &uj) in u.iter().enumerate() {
            for i in 0..n {
                self.sens[(j * n + i) * n + i] += uj;
            }
        }
        if initial_state && self.decaying {
            scratch.resize(self.free.len(), 0.0);
            propagate(a, &self.free, &mut scratch[..n * n], n);
            self.free.copy_from_slice(&scratch[..n * n]);
            // Once Aᵗ has died out, stop before it turns subnormal (100x slower arithmetic).
            if self.free.iter().all(|v| v.abs() < 1e-150) {
                self.free.fill(0.0);
                self.decaying = false;
            }
        }
    }
}

/// Samples per chunk of a segment: chunks are reduced in parallel, each from the sensitivities
/// at its first sample (found by a cheap sequential pass), and their R's stacked in order, so the
/// result does not depend on the number of threads.
const CHUNK_SAMPLES: usize = 8192;

/// R over the columns `[x0 | B | D | y]` of the rows of samples `t0..t1`, from `state` at `t0`.
#[allow(clippy::too_many_arguments)]
fn chunk_factor(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    s: &Signals<'_>,
    (t0, t1): (usize, usize),
    mut state: Sensitivity,
    unknowns: Unknowns,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let (n, nu, ny) = (a.nrows(), s.n_inputs, s.n_outputs);
    let nx0 = if unknowns.initial_state { n } else { 0 };
    let nd = if unknowns.feedthrough { ny * nu } else { 0 };
    let q = nx0 + n * nu + nd + 1;
    let mut work = Mat::<f64>::zeros(q + BLOCK_ROWS, q);
    let mut filled = 0;
    let mut scratch = Vec::new();
    for t in t0..t1 {
        let u = &s.u[t * nu..(t + 1) * nu];
        for o in 0..ny {
            if filled == BLOCK_ROWS {
                if cancel.load(Ordering::Relaxed) {
                    return Err(ArxError::Interrupted);
                }
                reduce(&mut work, filled);
                filled = 0;
            }
            let row = q + filled;
            let c_row = |col: &[f64]| (0..n).map(|k| c[(o, k)] * col[k]).sum::<f64>();
            for (i, col) in state.free.chunks_exact(n).take(nx0).enumerate() {
                work[(row, i)] = c_row(col);
            }
            for (k, col) in state.sens.chunks_exact(n).enumerate() {
                work[(row, nx0 + k)] = c_row(col);
            }
            for j in 0..nd / ny.max(1) {
                for oo in 0..ny {
                    work[(row, nx0 + n * nu + j * ny + oo)] = if oo == o { u[j] } else { 0.0 };
                }
            }
            work[(row, q - 1)] = s.y[t * ny + o];
            filled += 1;
        }
        state.step(a, u, unknowns.initial_state, &mut scratch);
    }
    reduce(&mut work, filled);
    Ok(work.as_ref().subrows(0, q).to_owned())
}

/// The segment's R over the columns `[x0 | B | D | y]`.
fn segment_factor(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    s: &Signals<'_>,
    (start, end): (usize, usize),
    unknowns: Unknowns,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let nu = s.n_inputs;
    let mut state = Sensitivity::start(a.nrows(), nu);
    let mut scratch = Vec::new();
    let mut chunks = Vec::new();
    for t0 in (start..end).step_by(CHUNK_SAMPLES) {
        let t1 = (t0 + CHUNK_SAMPLES).min(end);
        chunks.push(((t0, t1), state.clone()));
        for t in t0..t1 {
            state.step(a, &s.u[t * nu..(t + 1) * nu], unknowns.initial_state, &mut scratch);
        }
    }
    let factors = chunks
        .into_par_iter()
        .map(|(range, at)| chunk_factor(a, c, s, range, at, unknowns, cancel))
        .collect::<Result<Vec<_>>>()?;
    let nx0 = if unknowns.initial_state { a.nrows() } else { 0 };
    let nd = if unknowns.feedthrough { s.n_outputs * nu } else { 0 };
    Ok(stack_and_reduce(&factors, nx0 + a.nrows() * nu + nd + 1))
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
