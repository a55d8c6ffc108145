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

use super::hankel::Signals;
use super::pseudo_inverse;
use crate::error::{ArxError, Result};
use crate::qr::{qr_r_in_place, stack_and_reduce, take_r, BLOCK_ROWS};

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

/// Adds `block` under `r` and re-triangularises: `r` becomes the R of everything seen so far.
fn absorb(r: &mut Mat<f64>, block: &[Vec<f64>]) {
    let q = r.ncols();
    let mut a = Mat::<f64>::zeros(q + block.len(), q);
    a.as_mut().subrows_mut(0, q).copy_from(r.as_ref());
    for (i, row) in block.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            a[(q + i, j)] = *v;
        }
    }
    qr_r_in_place(a.as_mut());
    *r = take_r(&a, q);
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
    let (n, nu, ny) = (a.nrows(), s.n_inputs, s.n_outputs);
    let nx0 = if unknowns.initial_state { n } else { 0 };
    let nd = if unknowns.feedthrough { ny * nu } else { 0 };
    let q = nx0 + n * nu + nd + 1;
    let mut r = Mat::<f64>::zeros(q, q);
    let mut sens = Mat::<f64>::zeros(n, n * nu); // column j·n + i: ∂x/∂B[i, j]
    let mut free = Mat::<f64>::identity(n, n); // Aᵗ
    let mut block: Vec<Vec<f64>> = Vec::with_capacity(BLOCK_ROWS);
    for t in start..end {
        let cs = c * &sens;
        let cz = c * &free;
        let u = &s.u[t * nu..(t + 1) * nu];
        for o in 0..ny {
            let mut row = Vec::with_capacity(q);
            row.extend((0..nx0).map(|i| cz[(o, i)]));
            row.extend((0..n * nu).map(|k| cs[(o, k)]));
            if unknowns.feedthrough {
                row.extend((0..nu).flat_map(|j| (0..ny).map(move |oo| if oo == o { u[j] } else { 0.0 })));
            }
            row.push(s.y[t * ny + o]);
            block.push(row);
        }
        sens = a * &sens;
        for (j, &uj) in u.iter().enumerate() {
            for i in 0..n {
                sens[(i, j * n + i)] += uj;
            }
        }
        if unknowns.initial_state {
            free = a * &free;
        }
        if block.len() >= BLOCK_ROWS {
            if cancel.load(Ordering::Relaxed) {
                return Err(ArxError::Interrupted);
            }
            absorb(&mut r, &block);
            block.clear();
        }
    }
    absorb(&mut r, &block);
    Ok(r)
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
    if let Some(column) = (0..nb).find(|&j| !(r[(j, j)].abs() > 1e-10 * column_size(j))) {
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
