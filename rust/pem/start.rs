//! The start of the prediction-error iterations: B/F by SRIV, A/B by ARX, the noise model C/D by
//! Hannan–Rissanen.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{ArxError, Result};
use crate::pem::polynomial::{is_stable, monic, reflect_into_unit_circle, PolyStructure, Polys, Segments};
use crate::pem::regression::{iv_solve, lagged, least_squares, residual_of, Column};

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
/// As [`pem`](crate::pem::pem) (`Interrupted` between refinement rounds once `cancel` is set).
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
