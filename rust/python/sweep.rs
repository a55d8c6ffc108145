//! Bindings of the order sweep (`crate::sweep`): the sweep itself, its memory, the fleet's partial
//! factors and fits from them, and the simulation of fitted grids.

use std::sync::atomic::{AtomicUsize, Ordering};

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use super::arguments::{
    factor_array, factor_from, layout_rows, orders_tuple, parse_grid, parse_output_terms, parse_rows, saturating_usize,
    slices,
};
use super::errors::{to_pyerr, DataError, OrderError};
use super::run::run;
use crate::arx::columns::envelope;
use crate::arx::structure::{Data, Structure};
use crate::error::ArxError;
use crate::sweep::least_squares::SweepOptions;
use crate::sweep::sweep_columns::{envelope_rows, release, structures_of_rows, SweepColumns};

/// What `sweep` returns: one entry per structure of the grid, in grid order.
#[pyclass(frozen, get_all, module = "arxid._core")]
pub struct SweepOutput {
    /// Parameters, shape (S, p_max), NaN-padded after each structure's own p.
    theta: Py<PyArray2<f64>>,
    /// One-step residual sum of squares on the estimation rows.
    rss_est: Py<PyArray1<f64>>,
    /// Same on the validation rows (NaN without validation data).
    rss_val: Py<PyArray1<f64>>,
    /// RMS of the simulation (free run or k-step) on the estimation data.
    rms_sim_est: Py<PyArray1<f64>>,
    /// Same on the validation data.
    rms_sim_val: Py<PyArray1<f64>>,
    /// Samples scored by the estimation simulation.
    n_sim_est: Py<PyArray1<f64>>,
    /// Samples scored by the validation simulation.
    n_sim_val: Py<PyArray1<f64>>,
    /// ‖y − ȳ‖ over the samples the estimation simulation scored.
    norm_sim_est: Py<PyArray1<f64>>,
    /// Same for the validation simulation.
    norm_sim_val: Py<PyArray1<f64>>,
    /// The estimation simulation left the divergence limit of the estimation output.
    diverged_est: Py<PyArray1<bool>>,
    /// The validation simulation left the divergence limit of the validation output.
    diverged_val: Py<PyArray1<bool>>,
    /// Why a structure could not be fitted, else None.
    errors: Vec<Option<String>>,
    /// Regression rows of the estimation data.
    n_est: usize,
    /// Regression rows of the validation data (0 without them).
    n_val: usize,
    /// The grid envelope's largest lag: every structure's rows and simulations start here.
    first_lag: usize,
    /// `(na, nb, nk)` of the grid envelope (the largest regressor), per layout column.
    envelope: Py<PyTuple>,
    /// 2: fitted by QR and simulated; 1: ranked by its one-step loss only (sweeps with `top`).
    stage: Py<PyArray1<u8>>,
    /// (q, q) upper-triangular factor of the envelope's regressor on the estimation rows, output
    /// column last: `fit_from_factor` solves any structure of the grid from it.
    r_est: Py<PyArray2<f64>>,
}

/// Fits and validates every structure of a grid from one factorization (returns a `SweepOutput`).
///
/// `structures` is an (S, 1 + 2m) integer array of rows (na, nb_1..nb_m, nk_1..nk_m). A simulation
/// beyond `divergence_limit` of the measured output of its data set is stopped as diverged.
/// `top = k` ranks every structure by its one-step loss first and fits exactly and simulates only
/// the k best (`stage` says which).
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, yv = None, uv = None, starts_v = None,
                    simulate_estimation = true, horizon = None, n_threads = 0, chunk = 64, progress = None,
                    top = None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn sweep<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    structures: PyReadonlyArray2<'py, i64>,
    output_terms: Vec<(String, i32, i64)>,
    yv: Option<PyReadonlyArray1<'py, f64>>,
    uv: Option<PyReadonlyArray2<'py, f64>>,
    starts_v: Option<Vec<usize>>,
    simulate_estimation: bool,
    horizon: Option<usize>,
    n_threads: usize,
    chunk: usize,
    progress: Option<Py<PyAny>>,
    top: Option<usize>,
) -> PyResult<SweepOutput> {
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let terms = parse_output_terms(output_terms)?;
    let raw = layout_rows(&structures, m)?;
    let n_structures = structures.shape()[0];
    let val_slices = match (&yv, &uv) {
        (Some(yv), Some(uv)) => Some(slices(yv, uv)?),
        _ => None,
    };
    let sv = starts_v.unwrap_or_else(|| vec![0]);
    let vd = match val_slices {
        Some((a, b, mv)) => Some(Data::new(a, b, mv, &sv).map_err(|e| to_pyerr(py, e))?),
        None => None,
    };
    // The core reports after every group (chunk 1) so that a Ctrl-C stops it within one group;
    // Python's callback still hears about every `chunk` structures.
    let opts = SweepOptions { simulate_estimation, horizon, parallel: n_threads != 1, chunk: 1, top };
    let (chunk, reported) = (chunk.max(1), AtomicUsize::new(0));
    let (columns, env) = run(py, n_threads, |cancel| {
        // Parsed, swept and turned into columns with the GIL released, on the sweep's threads.
        let grid = structures_of_rows(raw, m, &terms, opts.parallel)?;
        let report = |done: usize| {
            if cancel.load(Ordering::Relaxed) {
                // Unwinds out of the sweep's parallel loop to `run`, which raises KeyboardInterrupt.
                std::panic::resume_unwind(Box::new(ArxError::Interrupted));
            }
            let before = reported.fetch_max(done, Ordering::Relaxed);
            if done / chunk > before / chunk || done == n_structures {
                if let Some(cb) = &progress {
                    Python::attach(|py| {
                        let _ = cb.call1(py, (done,));
                    });
                }
            }
        };
        let swept = crate::sweep::sweep(&d, vd.as_ref(), &grid, &opts, &report)?;
        let env = envelope(&grid)?;
        release(grid, opts.parallel);
        Ok((SweepColumns::new(swept, opts.parallel), env))
    })?;
    columns_output(py, columns, &env)
}

/// The Python view of a sweep's results (grid order).
pub(super) fn sweep_output(
    py: Python<'_>,
    swept: crate::sweep::least_squares::Swept,
    grid: &[Structure],
) -> PyResult<SweepOutput> {
    // The same envelope the sweep built (it succeeded, so this cannot fail).
    let env = envelope(grid).map_err(|e| to_pyerr(py, e))?;
    columns_output(py, SweepColumns::new(swept, false), &env)
}

/// [`SweepOutput`] of a sweep's columns: the vectors become numpy arrays without a copy.
pub(super) fn columns_output(py: Python<'_>, c: SweepColumns, env: &Structure) -> PyResult<SweepOutput> {
    let s = c.stage.len();
    let arr = |v: Vec<f64>| v.into_pyarray(py).unbind();
    Ok(SweepOutput {
        theta: PyArray1::from_vec(py, c.theta).reshape([s, c.p_max])?.unbind(),
        rss_est: arr(c.rss_est),
        rss_val: arr(c.rss_val),
        rms_sim_est: arr(c.rms_sim_est),
        rms_sim_val: arr(c.rms_sim_val),
        n_sim_est: arr(c.n_sim_est),
        n_sim_val: arr(c.n_sim_val),
        norm_sim_est: arr(c.norm_sim_est),
        norm_sim_val: arr(c.norm_sim_val),
        diverged_est: PyArray1::from_vec(py, c.diverged_est).unbind(),
        diverged_val: PyArray1::from_vec(py, c.diverged_val).unbind(),
        errors: c.errors,
        n_est: c.n_est,
        n_val: c.n_val,
        first_lag: env.max_lag(),
        envelope: orders_tuple(py, env)?.unbind(),
        stage: PyArray1::from_vec(py, c.stage).unbind(),
        r_est: factor_array(py, c.r_est)?.unbind(),
    })
}

/// `(first_lag, (na, nb, nk))` of a grid: the largest lag of its envelope (where every structure's
/// rows start) and the envelope's orders per layout column, exactly as `sweep` builds them.
///
/// `structures` is an (S, 1 + 2m) integer array of rows (na, nb_1..nb_m, nk_1..nk_m).
#[pyfunction]
pub(super) fn grid_envelope<'py>(
    py: Python<'py>,
    structures: PyReadonlyArray2<'py, i64>,
    output_terms: Vec<(String, i32, i64)>,
) -> PyResult<(usize, Bound<'py, PyTuple>)> {
    let width = structures.shape()[1];
    if width % 2 == 0 {
        return Err(OrderError::new_err(format!(
            "structures need 1 + 2·m columns (na, nb_1..nb_m, nk_1..nk_m), got {width}"
        )));
    }
    let terms = parse_output_terms(output_terms)?;
    let m = (width - 1) / 2;
    let raw = structures.as_slice()?;
    if raw.iter().any(|&v| v < 0) {
        return Err(OrderError::new_err("orders must be non-negative"));
    }
    let grid = parse_rows(py, &envelope_rows(raw, m), m, &terms)?;
    let env = envelope(&grid).map_err(|e| to_pyerr(py, e))?;
    Ok((env.max_lag(), orders_tuple(py, &env)?))
}

/// Bytes a sweep needs beyond the data arrays (saturates at 2^64 − 1 for absurd sizes).
///
/// `n_structures` structures with up to `p_max` parameters, a largest regressor of `q` columns
/// (output included), `n_est` / `n_val` samples, `n_cols` input columns of the effect layout,
/// `n_threads` as passed to `sweep` (0 = all cores).
#[pyfunction]
pub(super) fn sweep_memory(
    n_structures: &Bound<'_, PyAny>,
    p_max: &Bound<'_, PyAny>,
    q: &Bound<'_, PyAny>,
    n_est: &Bound<'_, PyAny>,
    n_val: &Bound<'_, PyAny>,
    n_cols: &Bound<'_, PyAny>,
    n_threads: &Bound<'_, PyAny>,
) -> PyResult<usize> {
    Ok(crate::sweep::least_squares::sweep_memory(
        saturating_usize(n_structures)?,
        saturating_usize(p_max)?,
        saturating_usize(q)?,
        saturating_usize(n_est)?,
        saturating_usize(n_val)?,
        saturating_usize(n_cols)?,
        saturating_usize(n_threads)?,
    ))
}

/// `(R, n_rows)`: the triangular factor (q × q, output last) of the grid envelope's regressor on
/// these data, a partial of a fleet sweep (combine partials by QR of their stacked factors).
/// `n_threads` (default 1: a fleet's workers already run one log per core; 0 = all cores) reduce
/// blocks of rows in parallel.
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, n_threads = 1))]
pub(super) fn grid_factor<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    structures: PyReadonlyArray2<'py, i64>,
    output_terms: Vec<(String, i32, i64)>,
    n_threads: usize,
) -> PyResult<(Bound<'py, PyArray2<f64>>, usize)> {
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let terms = parse_output_terms(output_terms)?;
    let grid = parse_grid(py, &structures, m, &terms)?;
    let (r, n) = run(py, n_threads, |_| crate::sweep::least_squares::grid_factor(&d, &grid, n_threads != 1))?;
    Ok((factor_array(py, r)?, n))
}

/// Every structure solved from combined factors (one or two stages as `sweep`, nothing simulated):
/// a `SweepOutput` whose simulation columns are NaN, and the indices a sweep would simulate.
#[pyfunction]
#[pyo3(signature = (r_est, n_est, structures, output_terms, r_val = None, n_val = 0, top = None, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn sweep_factors<'py>(
    py: Python<'py>,
    r_est: PyReadonlyArray2<'py, f64>,
    n_est: usize,
    structures: PyReadonlyArray2<'py, i64>,
    output_terms: Vec<(String, i32, i64)>,
    r_val: Option<PyReadonlyArray2<'py, f64>>,
    n_val: usize,
    top: Option<usize>,
    n_threads: usize,
) -> PyResult<(SweepOutput, Bound<'py, PyArray1<usize>>)> {
    let width = structures.shape()[1];
    if width % 2 == 0 {
        return Err(OrderError::new_err(format!("structures need 1 + 2·m columns, got {width}")));
    }
    let terms = parse_output_terms(output_terms)?;
    let grid = parse_grid(py, &structures, (width - 1) / 2, &terms)?;
    let re = factor_from(&r_est)?;
    let rv = r_val.as_ref().map(factor_from).transpose()?;
    let parallel = n_threads != 1;
    let to_fit = re.clone();
    let (results, simulate) = run(py, n_threads, |_| {
        crate::sweep::least_squares::fits_from_factors(&grid, to_fit, n_est, rv, n_val, top, parallel)
    })?;
    let swept = crate::sweep::least_squares::Swept { results, n_est, n_val, r_est: re };
    Ok((sweep_output(py, swept, &grid)?, simulate.into_pyarray(py)))
}

/// `(rms, n, norm, mean, diverged)` of fitted structures simulated on these data from `first_lag` on (free run,
/// or `horizon`-step prediction), exactly as `sweep` simulates them. `theta` is (S, p_max), NaN-padded;
/// `limit` replaces the divergence limit of these data.
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, theta, first_lag, horizon = None, n_threads = 0,
                    limit = None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(super) fn simulate_structures<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    structures: PyReadonlyArray2<'py, i64>,
    output_terms: Vec<(String, i32, i64)>,
    theta: PyReadonlyArray2<'py, f64>,
    first_lag: usize,
    horizon: Option<usize>,
    n_threads: usize,
    limit: Option<f64>,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
)> {
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let terms = parse_output_terms(output_terms)?;
    let grid = parse_grid(py, &structures, m, &terms)?;
    let th = theta.as_array();
    if th.shape()[0] != grid.len() {
        return Err(DataError::new_err(format!("theta has {} rows for {} structures", th.shape()[0], grid.len())));
    }
    let thetas: Vec<Vec<f64>> = grid
        .iter()
        .enumerate()
        .map(|(i, s)| (0..s.n_params().min(th.shape()[1])).map(|j| th[[i, j]]).collect())
        .collect();
    let opts = SweepOptions { simulate_estimation: false, horizon, parallel: n_threads != 1, chunk: 64, top: None };
    let scores = run(py, n_threads, |cancel| {
        crate::sweep::least_squares::simulate_structures_cancellable(&d, &grid, thetas, first_lag, limit, &opts, cancel)
    })?;
    let rms: Vec<f64> = scores.iter().map(|s| s.rms).collect();
    let n: Vec<f64> = scores.iter().map(|s| s.n as f64).collect();
    let norm: Vec<f64> = scores.iter().map(|s| s.norm).collect();
    let mean: Vec<f64> = scores.iter().map(|s| s.mean).collect();
    let diverged: Vec<bool> = scores.iter().map(|s| s.diverged).collect();
    Ok((
        rms.into_pyarray(py),
        n.into_pyarray(py),
        norm.into_pyarray(py),
        mean.into_pyarray(py),
        diverged.into_pyarray(py),
    ))
}
