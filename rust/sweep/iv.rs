//! Instrumental variables for ARX structures: the IV normal equations
//! $\sum_t z(t)\,\varphi(t)^T \theta = \sum_t z(t)\, y(t)$ with the instrument vector $z(t)$ built
//! exactly as the regressor $\varphi(t)$ but from instrument signals (a noise-free output and
//! input, simulated by the caller from the input or from a measured reference).
//!
//! A grid of structures shares one pass over the data: the cross moments of the grid's envelope
//! (the largest regressor, [`envelope`]) are accumulated once, in parallel blocks of rows, and each
//! structure solves the small square system on its columns ([`columns_in`]). Its one-step losses
//! come from the sweep's least-squares factor of `[Φ | y]`, which gives the residual of any θ.

use rayon::prelude::*;

use crate::arx::columns::{columns_in, envelope};
use crate::arx::structure::{fill_row, Data, Structure};
use crate::error::{ArxError, Result};
use crate::sweep::grid_factors::{factor_grid, rows_of, rss_from_r};
use crate::sweep::least_squares::{simulate_all, StructureResult, SweepOptions, Swept, NAN_SCORE};

/// Rows per block of the moment accumulation (fixed, so results do not depend on the threads).
const BLOCK: usize = 4096;

/// Cross moments of the envelope's instruments with its regressor and output on a set of rows.
#[derive(Debug, Clone)]
pub struct Moments {
    /// Columns of the envelope's regressor.
    pub p: usize,
    /// $\sum z \,[\varphi^T \; y]$, row-major p × (p + 1).
    pub zphi: Vec<f64>,
    /// $\sum z z^T$, row-major p × p.
    pub zz: Vec<f64>,
    /// Rows accumulated (rows whose instruments are not finite are left out).
    pub n_rows: usize,
}

/// Accumulates [`Moments`] of `env` on `rows` of the data `d` and instruments `inst`.
///
/// `heartbeat` is called before each block of rows (a caller stops by unwinding from it).
pub fn moments(
    d: &Data,
    inst: &Data,
    env: &Structure,
    rows: &[usize],
    parallel: bool,
    heartbeat: &(dyn Fn() + Sync),
) -> Moments {
    let p = env.n_params();
    let block = |chunk: &[usize]| {
        heartbeat();
        let mut zphi = vec![0.0; p * (p + 1)];
        let mut zz = vec![0.0; p * p];
        let (mut phi, mut z) = (vec![0.0; p + 1], vec![0.0; p]);
        let mut n = 0;
        for &t in chunk {
            let ok_phi = fill_row(d, env, t, &mut phi[..p]);
            phi[p] = d.y[t];
            if !(ok_phi && phi[p].is_finite() && fill_row(inst, env, t, &mut z)) {
                continue;
            }
            n += 1;
            for i in 0..p {
                let zi = z[i];
                let dst = &mut zphi[i * (p + 1)..(i + 1) * (p + 1)];
                for (o, v) in dst.iter_mut().zip(&phi) {
                    *o += zi * v;
                }
                for (o, v) in zz[i * p..(i + 1) * p].iter_mut().zip(&z) {
                    *o += zi * v;
                }
            }
        }
        (zphi, zz, n)
    };
    let parts: Vec<(Vec<f64>, Vec<f64>, usize)> =
        if parallel { rows.par_chunks(BLOCK).map(block).collect() } else { rows.chunks(BLOCK).map(block).collect() };
    let mut out = Moments { p, zphi: vec![0.0; p * (p + 1)], zz: vec![0.0; p * p], n_rows: 0 };
    for (a, b, n) in parts {
        out.zphi.iter_mut().zip(a).for_each(|(o, v)| *o += v);
        out.zz.iter_mut().zip(b).for_each(|(o, v)| *o += v);
        out.n_rows += n;
    }
    out
}

/// Solves `a x = b` for the k columns of `b` (row-major k × k and k × c) by Gaussian elimination
/// with partial pivoting, in place.
///
/// # Errors
/// `RankDeficient` when a pivot is below `1e-12` times the largest entry of its column (the
/// instruments do not determine that parameter).
fn lu_solve(a: &mut [f64], k: usize, b: &mut [f64], c: usize) -> Result<()> {
    for col in 0..k {
        let scale = (0..k).map(|r| a[r * k + col].abs()).fold(0.0, f64::max);
        let piv = (col..k).max_by(|&i, &j| a[i * k + col].abs().total_cmp(&a[j * k + col].abs())).unwrap_or(col);
        let ratio = if scale > 0.0 { a[piv * k + col].abs() / scale } else { 0.0 };
        if ratio.is_nan() || ratio <= 1e-12 {
            return Err(ArxError::RankDeficient { column: col, ratio });
        }
        if piv != col {
            for j in 0..k {
                a.swap(piv * k + j, col * k + j);
            }
            for j in 0..c {
                b.swap(piv * c + j, col * c + j);
            }
        }
        for r in col + 1..k {
            let f = a[r * k + col] / a[col * k + col];
            if f == 0.0 {
                continue;
            }
            for j in col..k {
                a[r * k + j] -= f * a[col * k + j];
            }
            for j in 0..c {
                b[r * c + j] -= f * b[col * c + j];
            }
        }
    }
    for col in (0..k).rev() {
        for j in 0..c {
            let mut s = b[col * c + j];
            for i in col + 1..k {
                s -= a[col * k + i] * b[i * c + j];
            }
            b[col * c + j] = s / a[col * k + col];
        }
    }
    Ok(())
}

/// θ of the structure whose envelope columns are `cols`, and its unscaled covariance
/// $(Z^T\Phi)^{-1} Z^T Z (Z^T\Phi)^{-T}$ (row-major k × k; times the noise variance it is the
/// basic IV's parameter covariance).
///
/// # Errors
/// `RankDeficient` (naming the structure's column) when the instruments do not determine θ.
pub fn solve(m: &Moments, cols: &[usize]) -> Result<(Vec<f64>, Vec<f64>)> {
    let (p, k) = (m.p, cols.len());
    let mut a = vec![0.0; k * k];
    // right-hand sides: the output column, then Z^T Z[cols, cols] for the covariance
    let mut b = vec![0.0; k * (1 + k)];
    for (r, &i) in cols.iter().enumerate() {
        for (c, &j) in cols.iter().enumerate() {
            a[r * k + c] = m.zphi[i * (p + 1) + j];
            b[r * (1 + k) + 1 + c] = m.zz[i * p + j];
        }
        b[r * (1 + k)] = m.zphi[i * (p + 1) + p];
    }
    let mut at = vec![0.0; k * k];
    for r in 0..k {
        for c in 0..k {
            at[c * k + r] = a[r * k + c];
        }
    }
    lu_solve(&mut a, k, &mut b, 1 + k)?;
    let theta: Vec<f64> = (0..k).map(|r| b[r * (1 + k)]).collect();
    // X = A^-1 ZZ (k × k); covariance = X A^-T = (A^-1 X^T)^T, and X A^-T is symmetric.
    let mut xt = vec![0.0; k * k];
    for r in 0..k {
        for c in 0..k {
            xt[c * k + r] = b[r * (1 + k) + 1 + c];
        }
    }
    let mut a2 = vec![0.0; k * k];
    for r in 0..k {
        for c in 0..k {
            a2[r * k + c] = at[c * k + r];
        }
    }
    lu_solve(&mut a2, k, &mut xt, k)?;
    Ok((theta, xt))
}

/// What [`iv_sweep`] returns besides the sweep: each structure's unscaled covariance and the rows
/// the instruments were accumulated on.
pub struct IvSwept {
    pub swept: Swept,
    /// Row-major k × k per structure (empty for a structure that could not be solved).
    pub covariance: Vec<Vec<f64>>,
    /// Rows of the IV moments.
    pub n_rows: usize,
}

/// Fits every structure by instrumental variables with the instrument signals `inst` (same
/// length, inputs and experiments as `est`), and validates it as [`crate::sweep::sweep`] does:
/// one-step losses from the least-squares factor of each data set, free-run (or k-step)
/// simulations in lanes. `opts.top` is ignored (every structure is solved and simulated).
///
/// # Errors
/// As [`crate::sweep::sweep`]; `ShapeMismatch` when the instruments do not match the data.
pub fn iv_sweep(
    est: &Data,
    inst: &Data,
    val: Option<&Data>,
    structures: &[Structure],
    opts: &SweepOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<IvSwept> {
    if inst.len() != est.len() || inst.m != est.m || inst.starts != est.starts {
        return Err(ArxError::ShapeMismatch { what: "instruments".into(), expected: est.len(), got: inst.len() });
    }
    let heartbeat = || progress(0);
    let f = factor_grid(est, val, structures, opts.parallel, &heartbeat)?;
    let env = envelope(structures)?;
    let rows = rows_of(est, &env, f.first_lag);
    let mom = moments(est, inst, &env, &rows, opts.parallel, &heartbeat);
    drop(rows);
    if mom.n_rows < mom.p {
        return Err(ArxError::TooFewSamples { needed: mom.p, got: mom.n_rows });
    }
    let solve_one = |s: &Structure| {
        progress(0);
        let cols = columns_in(&env, s);
        match solve(&mom, &cols) {
            Ok((theta, cov)) => {
                let rss_est = rss_from_r(&f.r_est, f.q, &cols, &theta);
                let rss_val = f.rss_val(&cols, &theta);
                let r = StructureResult {
                    theta,
                    rss_est,
                    rss_val,
                    sim_est: NAN_SCORE,
                    sim_val: NAN_SCORE,
                    error: None,
                    stage: 2,
                };
                (r, cov)
            }
            Err(e) => {
                let e = match e {
                    ArxError::RankDeficient { column, ratio } => {
                        ArxError::RankDeficient { column: cols[column], ratio }
                    }
                    other => other,
                };
                let r = StructureResult {
                    theta: vec![f64::NAN; cols.len()],
                    rss_est: f64::NAN,
                    rss_val: f64::NAN,
                    sim_est: NAN_SCORE,
                    sim_val: NAN_SCORE,
                    error: Some(e),
                    stage: 2,
                };
                (r, Vec::new())
            }
        }
    };
    let solved: Vec<(StructureResult, Vec<f64>)> = if opts.parallel {
        structures.par_iter().map(solve_one).collect()
    } else {
        structures.iter().map(solve_one).collect()
    };
    let (mut out, covariance): (Vec<StructureResult>, Vec<Vec<f64>>) = solved.into_iter().unzip();
    if opts.simulate_estimation || val.is_some() {
        let order: Vec<usize> = (0..structures.len()).filter(|&i| out[i].error.is_none()).collect();
        let scores = simulate_all(est, val, structures, &out, order, (&env, f.first_lag, None), opts, progress);
        for (i, se, sv) in scores {
            out[i].sim_est = se;
            out[i].sim_val = sv;
        }
    }
    progress(structures.len());
    let swept = Swept { results: out, n_est: f.n_est, n_val: f.n_val, r_est: f.r_est };
    Ok(IvSwept { swept, covariance, n_rows: mom.n_rows })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y(t) = 0.7 y(t-1) + 0.5 u(t-1) + v(t) with v coloured, u white: IV with the noise-free
    /// output as instrument recovers θ; on noise-free data it equals least squares exactly.
    #[test]
    fn recovers_parameters_of_a_first_order_system() {
        let n = 20000;
        let mut state = 12345u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let mut x = vec![0.0; n];
        let mut y = vec![0.0; n];
        let mut v = 0.0;
        for t in 1..n {
            x[t] = 0.7 * x[t - 1] + 0.5 * u[t - 1];
            v = 0.9 * v + 0.1 * rnd();
            y[t] = x[t] + v;
        }
        let starts = [0usize];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let inst = Data::new(&x, &u, 1, &starts).unwrap();
        let s = Structure::new(1, vec![1], vec![1], vec![]).unwrap();
        let opts = SweepOptions { simulate_estimation: true, horizon: None, parallel: false, chunk: 1, top: None };
        let out = iv_sweep(&d, &inst, None, std::slice::from_ref(&s), &opts, &|_| {}).unwrap();
        let th = &out.swept.results[0].theta;
        assert!((th[0] + 0.7).abs() < 0.02, "{th:?}");
        assert!((th[1] - 0.5).abs() < 0.02, "{th:?}");
        assert_eq!(out.covariance[0].len(), 4);
        // noise-free: IV with the output itself as instrument is least squares
        let clean = Data::new(&x, &u, 1, &starts).unwrap();
        let exact = iv_sweep(&clean, &clean, None, std::slice::from_ref(&s), &opts, &|_| {}).unwrap();
        let th = &exact.swept.results[0].theta;
        assert!((th[0] + 0.7).abs() < 1e-10 && (th[1] - 0.5).abs() < 1e-10, "{th:?}");
        assert!(exact.swept.results[0].rss_est < 1e-20);
    }

    #[test]
    fn constant_instruments_are_rank_deficient() {
        let n = 200;
        let y: Vec<f64> = (0..n).map(|t| (t as f64 * 0.1).sin()).collect();
        let u: Vec<f64> = (0..n).map(|t| (t as f64 * 0.37).cos()).collect();
        let z = vec![1.0; n];
        let starts = [0usize];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let inst = Data::new(&z, &z, 1, &starts).unwrap();
        let s = Structure::new(2, vec![1], vec![1], vec![]).unwrap();
        let opts = SweepOptions { simulate_estimation: false, horizon: None, parallel: false, chunk: 1, top: None };
        let out = iv_sweep(&d, &inst, None, std::slice::from_ref(&s), &opts, &|_| {}).unwrap();
        assert!(matches!(out.swept.results[0].error, Some(ArxError::RankDeficient { .. })));
    }
}
