//! Python bindings of the instrumental-variable sweep ([`crate::sweep::iv`]).

use std::sync::atomic::{AtomicUsize, Ordering};

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::arguments::{parse_grid, slices};
use super::errors::to_pyerr;
use super::run::run;
use super::sweep::{sweep_output, SweepOutput};
use crate::arx::structure::Data;
use crate::error::ArxError;
use crate::sweep::least_squares::SweepOptions;

/// Fits every structure of a grid by instrumental variables and validates it as `sweep` does.
///
/// `xy` and `xu` are the instrument signals (same shape as `y` and `u`): the instrument vector of
/// each structure is its regressor built from them. Returns `(SweepOutput, covariances, n_rows)`:
/// the sweep's results (grid order), each structure's unscaled covariance
/// `(ZᵀΦ)⁻¹ ZᵀZ (ZᵀΦ)⁻ᵀ` (an empty array when it could not be solved) and the rows of the IV
/// moments. Runs with the GIL released and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (y, u, starts, xy, xu, structures, yv = None, uv = None, starts_v = None,
                    simulate_estimation = true, horizon = None, n_threads = 0, chunk = 64, progress = None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(super) fn iv_sweep<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    starts: Vec<usize>,
    xy: PyReadonlyArray1<'py, f64>,
    xu: PyReadonlyArray2<'py, f64>,
    structures: PyReadonlyArray2<'py, i64>,
    yv: Option<PyReadonlyArray1<'py, f64>>,
    uv: Option<PyReadonlyArray2<'py, f64>>,
    starts_v: Option<Vec<usize>>,
    simulate_estimation: bool,
    horizon: Option<usize>,
    n_threads: usize,
    chunk: usize,
    progress: Option<Py<PyAny>>,
) -> PyResult<(SweepOutput, Vec<Bound<'py, PyArray2<f64>>>, usize)> {
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let (xs, xus, mx) = slices(&xy, &xu)?;
    let inst = Data::new(xs, xus, mx, &starts).map_err(|e| to_pyerr(py, e))?;
    let grid = parse_grid(py, &structures, m, &[])?;
    let val_slices = match (&yv, &uv) {
        (Some(yv), Some(uv)) => Some(slices(yv, uv)?),
        _ => None,
    };
    let sv = starts_v.unwrap_or_else(|| vec![0]);
    let vd = match val_slices {
        Some((a, b, mv)) => Some(Data::new(a, b, mv, &sv).map_err(|e| to_pyerr(py, e))?),
        None => None,
    };
    let opts = SweepOptions { simulate_estimation, horizon, parallel: n_threads != 1, chunk: 1, top: None };
    let (chunk, reported) = (chunk.max(1), AtomicUsize::new(0));
    let out = run(py, n_threads, |cancel| {
        let report = |done: usize| {
            if cancel.load(Ordering::Relaxed) {
                // Unwinds to `run`, which raises KeyboardInterrupt (as the sweep does).
                std::panic::resume_unwind(Box::new(ArxError::Interrupted));
            }
            let before = reported.fetch_max(done, Ordering::Relaxed);
            if done / chunk > before / chunk || done == grid.len() {
                if let Some(cb) = &progress {
                    Python::attach(|py| {
                        let _ = cb.call1(py, (done,));
                    });
                }
            }
        };
        crate::sweep::iv::iv_sweep(&d, &inst, vd.as_ref(), &grid, &opts, &report)
    })?;
    let crate::sweep::iv::IvSwept { swept, covariance, n_rows } = out;
    let mut covs = Vec::with_capacity(covariance.len());
    for c in covariance {
        let k = (c.len() as f64).sqrt() as usize;
        covs.push(PyArray1::from_vec(py, c).reshape([k, k])?);
    }
    Ok((sweep_output(py, swept, &grid)?, covs, n_rows))
}
