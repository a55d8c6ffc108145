//! Bindings of the simulation (`crate::simulate`): prediction and free run of one structure, its
//! band, the divergence rule, the machine's multiply-add limit.

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use std::sync::atomic::AtomicBool;

use super::arguments::{slices, structure};
use super::errors::{to_pyerr, OrderError};
use super::run::{run, run_short, SHORT_CALL};
use crate::arx::structure::Data;

/// The first-order band's variance of a free run (see [`crate::simulate::band::free_run_variance`]): `thetas`
/// holds θ⁺_0, θ⁻_0, θ⁺_1, … one per row; None when an experiment has a missing sample. Runs with the
/// GIL released and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, thetas, step, first_lag = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn free_run_variance<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    thetas: PyReadonlyArray2<'py, f64>,
    step: f64,
    first_lag: usize,
) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
    let s = structure(py, na, nb, nk, Vec::new())?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    s.check(m).map_err(|e| to_pyerr(py, e))?;
    let th = thetas.as_array();
    let rows: Vec<Vec<f64>> = th.rows().into_iter().map(|r| r.to_vec()).collect();
    let out = run(py, 1, |cancel| crate::simulate::band::free_run_variance(&d, &s, &rows, step, first_lag, cancel))?;
    Ok(out.map(|v| v.into_pyarray(py)))
}

/// Prediction with `horizon` steps (None = free-run simulation); NaN where no prediction exists.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, output_terms, theta, horizon = None, first_lag = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn predict<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    output_terms: Vec<(String, i32, i64)>,
    theta: PyReadonlyArray1<'py, f64>,
    horizon: Option<usize>,
    first_lag: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let s = structure(py, na, nb, nk, output_terms)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    s.check(m).map_err(|e| to_pyerr(py, e))?;
    let th = theta.as_slice()?;
    if th.len() != s.n_params() {
        return Err(OrderError::new_err(format!(
            "theta has {} entries, the structure has {} parameters",
            th.len(),
            s.n_params()
        )));
    }
    if let Some(k) = horizon.filter(|&k| k >= 2) {
        if let Some(out) = run(py, 1, |_| Ok(crate::simulate::kstep::predict_k_by_filter(&d, &s, th, k, first_lag)))? {
            return Ok(out.into_pyarray(py));
        }
    }
    // Written in place into numpy's zeroed memory (large blocks in huge pages): no page-by-page
    // faults on a fresh Rust buffer.
    let out = PyArray1::<f64>::zeros(py, ys.len(), false);
    {
        let mut rw = out.readwrite();
        let buf = rw.as_slice_mut()?;
        let predict =
            |cancel: &AtomicBool| crate::simulate::predict::predict_into(&d, &s, th, horizon, first_lag, cancel, buf);
        if ys.len() * th.len().max(1) <= SHORT_CALL {
            run_short(py, predict)?;
        } else {
            run(py, 1, predict)?;
        }
    }
    Ok(out)
}

/// Magnitude beyond which a prediction of `y` counts as diverged (the core's one divergence rule).
#[pyfunction]
pub(super) fn divergence_limit(y: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    Ok(crate::simulate::score::divergence_limit(y.as_slice()?))
}

/// Seconds for `n_vectors` multiply-adds of eight lanes each at the machine's throughput (many
/// independent chains, on every core): the limit a free-run sweep of the same work could reach.
#[pyfunction]
#[pyo3(signature = (n_vectors, n_threads = 0))]
pub(super) fn fma_limit(py: Python<'_>, n_vectors: u64, n_threads: usize) -> PyResult<f64> {
    run(py, n_threads, |_| Ok(crate::simulate::lanes::fma_throughput_seconds(n_vectors)))
}
