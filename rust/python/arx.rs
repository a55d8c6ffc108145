//! Bindings of the ARX fit (`crate::arx`): one structure fitted on data, or from a grid's factor.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

use super::arguments::{factor_array, factor_from, saturating_usize, slices, structure};
use super::errors::{to_pyerr, DataError, OrderError};
use super::run::{run, run_short, SHORT_CALL};
use crate::arx::fit::fit_rows_like;
use crate::arx::reduce::reduce_series;
use crate::arx::structure::Data;
use crate::linalg::qr::to_col_major;
use crate::sweep::grid_factors::rows_of;
use crate::sweep::least_squares::effective_threads;

/// What `fit` returns.
#[pyclass(frozen, get_all, module = "arxid._core")]
pub struct FitOutput {
    /// Parameters, shape (p,): the a's, each input's b's, the output terms.
    theta: Py<PyArray1<f64>>,
    /// Residual sum of squares on the regression rows.
    rss: f64,
    /// Number of regression rows used.
    n_rows: usize,
    /// Rows left out because a regressor or the output touched a NaN or inf.
    n_skipped: usize,
    /// (Φᵀ Φ)⁻¹, shape (p, p); times the noise variance it is the parameter covariance.
    inv_gram: Py<PyArray2<f64>>,
}

/// Least-squares ARX fit by Householder QR (returns a `FitOutput`).
///
/// `rows_like = (na, nb, nk)` fits on the rows where that larger structure's regressors are finite
/// too (a sweep's grid envelope), so that a refit uses exactly the sweep's rows.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, output_terms, first_lag = 0, n_threads = 0, rows_like = None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn fit<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    output_terms: Vec<(String, i32, i64)>,
    first_lag: usize,
    n_threads: usize,
    rows_like: Option<(usize, Vec<usize>, Vec<usize>)>,
) -> PyResult<FitOutput> {
    let env = match rows_like {
        Some((ena, enb, enk)) => Some(structure(py, ena, enb, enk, output_terms.clone())?),
        None => None,
    };
    let s = structure(py, na, nb, nk, output_terms)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    // A short record is one block of rows or a few: the same factor as in parallel, on this thread.
    let short = ys.len() * (s.n_params() + 1) <= SHORT_CALL;
    let fit = |cancel: &AtomicBool| fit_rows_like(&d, &s, first_lag, !short, env.as_ref(), cancel);
    let f = if short { run_short(py, fit)? } else { run(py, n_threads, fit)? };
    let p = f.theta.len();
    Ok(FitOutput {
        theta: f.theta.into_pyarray(py).unbind(),
        rss: f.rss,
        n_rows: f.n_rows,
        n_skipped: f.n_skipped,
        inv_gram: PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?.unbind(),
    })
}

/// The fit of one structure of a grid from the grid envelope's factor (returns a `FitOutput`): the
/// same parameters, loss and (Φᵀ Φ)⁻¹ as `fit` on the sweep's rows, to rounding, without the data.
/// `envelope` and `structure` are `(na, nb, nk)` per layout column.
#[pyfunction]
pub(super) fn fit_from_factor<'py>(
    py: Python<'py>,
    r_est: PyReadonlyArray2<'py, f64>,
    n_rows: usize,
    envelope: (usize, Vec<usize>, Vec<usize>),
    structure: (usize, Vec<usize>, Vec<usize>),
    output_terms: Vec<(String, i32, i64)>,
) -> PyResult<FitOutput> {
    let env = self::structure(py, envelope.0, envelope.1, envelope.2, output_terms.clone())?;
    let s = self::structure(py, structure.0, structure.1, structure.2, output_terms)?;
    let r = factor_from(&r_est)?;
    if r.len() != (env.n_params() + 1).pow(2) {
        return Err(DataError::new_err("the factor does not match the envelope (q = its parameters + 1)"));
    }
    if !crate::arx::columns::inside(&env, &s) {
        return Err(OrderError::new_err("the structure reads columns outside the envelope"));
    }
    let cols = crate::arx::columns::columns_in(&env, &s);
    let q = env.n_params() + 1;
    let f = run_short(py, |_| crate::arx::fit::fit_from_factor(&r, q, &cols, n_rows))?; // no data: a few columns
    let p = f.theta.len();
    Ok(FitOutput {
        theta: f.theta.into_pyarray(py).unbind(),
        rss: f.rss,
        n_rows: f.n_rows,
        n_skipped: 0,
        inv_gram: PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?.unbind(),
    })
}

/// `(R, n_rows)`: the triangular factor (q × q, output last) of the regressor `[Φ | y]` of the
/// structure `envelope = (na, nb, nk)` on the rows from `first_lag` into each experiment (at least
/// its own largest lag), to fit its sub-structures from (`fit_from_factor`). Unlike `grid_factor`,
/// rows that start later than the envelope needs cost no output lags of their own. Its inputs are
/// `columns`, one array of samples each (never written side by side into one matrix); the data
/// must have no missing sample.
#[pyfunction]
#[pyo3(signature = (y, columns, starts, envelope, first_lag, n_threads = 0))]
pub(super) fn envelope_factor<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    columns: Vec<PyReadonlyArray1<'py, f64>>,
    starts: Vec<usize>,
    envelope: (usize, Vec<usize>, Vec<usize>),
    first_lag: usize,
    n_threads: usize,
) -> PyResult<(Bound<'py, PyArray2<f64>>, usize)> {
    let env = structure(py, envelope.0, envelope.1, envelope.2, Vec::new())?;
    let ys = y.as_slice()?;
    let cols = columns.iter().map(|c| c.as_slice()).collect::<Result<Vec<_>, _>>()?;
    if let Some(c) = cols.iter().find(|c| c.len() != ys.len()) {
        return Err(DataError::new_err(format!("y has {} samples but a column has {}", ys.len(), c.len())));
    }
    let d = Data::new(ys, &[], 0, &starts).map_err(|e| to_pyerr(py, e))?;
    if !py.detach(|| ys.iter().chain(cols.iter().flat_map(|c| c.iter())).all(|v| v.is_finite())) {
        return Err(DataError::new_err("the envelope's factor needs data without missing samples"));
    }
    let (r, n) = run(py, n_threads, |cancel| {
        env.check(cols.len())?;
        let rows = rows_of(&d, &env, first_lag); // every row from first_lag: the data are finite
        let inputs: Vec<(&[f64], usize)> = cols.iter().map(|&c| (c, 1)).collect();
        let r = reduce_series(ys, &inputs, &env, &rows, n_threads != 1, &|| !cancel.load(Ordering::Relaxed))?;
        Ok((to_col_major(&r), rows.len()))
    })?;
    Ok((factor_array(py, r)?, n))
}

/// Largest lag any regressor of the structure reads: its first usable row is this far into each
/// experiment.
#[pyfunction]
pub(super) fn max_lag(
    py: Python<'_>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    output_terms: Vec<(String, i32, i64)>,
) -> PyResult<usize> {
    Ok(structure(py, na, nb, nk, output_terms)?.max_lag())
}

/// Bytes a fit of `n_rows` regression rows and `n_params` parameters allocates on `n_threads`
/// threads as passed to `fit` (0 = all cores); saturates at 2^64 − 1 for absurd sizes.
#[pyfunction]
pub(super) fn fit_memory(
    n_rows: &Bound<'_, PyAny>,
    n_params: &Bound<'_, PyAny>,
    n_threads: &Bound<'_, PyAny>,
) -> PyResult<usize> {
    let threads = effective_threads(saturating_usize(n_threads)?);
    Ok(crate::arx::fit::fit_memory(saturating_usize(n_rows)?, saturating_usize(n_params)?, threads))
}
