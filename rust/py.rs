//! The one place Rust meets Python: borrow numpy arrays, call the pure core with the GIL released,
//! convert results and errors back. Panics are caught here and never reach Python.

use std::panic::{catch_unwind, AssertUnwindSafe};

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::ArxError;
use crate::structure::{Data, OutputKind, OutputTerm, Structure};
use crate::sweep::SweepOptions;

pyo3::import_exception!(arxid.exceptions, ArxidError);
pyo3::import_exception!(arxid.exceptions, DataError);
pyo3::import_exception!(arxid.exceptions, OrderError);
pyo3::import_exception!(arxid.exceptions, IdentifiabilityError);

fn to_pyerr(py: Python<'_>, e: ArxError) -> PyErr {
    let msg = e.to_string();
    match e {
        ArxError::RankDeficient { column, .. } => {
            let err = IdentifiabilityError::new_err(msg);
            let _ = err.value(py).setattr("column", column);
            err
        }
        ArxError::TooFewSamples { .. } | ArxError::ShapeMismatch { .. } | ArxError::TooLarge { .. } => {
            DataError::new_err(msg)
        }
        ArxError::InvalidStructure(_) => OrderError::new_err(msg),
    }
}

/// Runs `f` without the GIL on `n_threads` threads (0 = all), turning a panic into an error.
/// Results do not depend on the thread count, so more than 4 threads per core are not started.
fn run<T: Send>(py: Python<'_>, n_threads: usize, f: impl FnOnce() -> Result<T, ArxError> + Send) -> PyResult<T> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let n_threads = n_threads.min(4 * cores);
    let out = py.detach(move || {
        catch_unwind(AssertUnwindSafe(|| {
            if n_threads == 0 {
                Ok(f())
            } else {
                match rayon::ThreadPoolBuilder::new().num_threads(n_threads).build() {
                    Ok(pool) => Ok(pool.install(f)),
                    Err(e) => {
                        Err(format!("cannot start n_threads = {n_threads} threads ({e}); use n_threads=0 (all cores)"))
                    }
                }
            }
        }))
    });
    match out {
        Ok(Ok(Ok(v))) => Ok(v),
        Ok(Ok(Err(e))) => Err(to_pyerr(py, e)),
        Ok(Err(msg)) => Err(ArxidError::new_err(msg)),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown".into());
            Err(ArxidError::new_err(format!("internal error in the arxid core (please report it): {what}")))
        }
    }
}

fn slices<'a>(
    y: &'a PyReadonlyArray1<'_, f64>,
    u: &'a PyReadonlyArray2<'_, f64>,
) -> PyResult<(&'a [f64], &'a [f64], usize)> {
    let m = u.shape()[1];
    if u.shape()[0] != y.len() {
        return Err(DataError::new_err(format!("y has {} samples but u has {} rows", y.len(), u.shape()[0])));
    }
    Ok((y.as_slice()?, u.as_slice()?, m))
}

fn parse_output_terms(spec: Vec<(String, i32, i64)>) -> PyResult<Vec<OutputTerm>> {
    spec.into_iter()
        .map(|(kind, power, mult)| {
            let kind = match kind.as_str() {
                "pow" => OutputKind::Pow(power),
                "abs" => OutputKind::Abs,
                "signdiff" => OutputKind::SignDiff,
                other => return Err(OrderError::new_err(format!("unknown output term kind {other:?}"))),
            };
            Ok(OutputTerm { kind, multiplier: if mult < 0 { None } else { Some(mult as usize) } })
        })
        .collect()
}

fn structure(
    py: Python<'_>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    terms: Vec<(String, i32, i64)>,
) -> PyResult<Structure> {
    let terms = parse_output_terms(terms)?;
    Structure::new(na, nb, nk, terms).map_err(|e| to_pyerr(py, e))
}

/// Least-squares ARX fit by Householder QR. Returns a dict with theta, rss, n_rows, n_skipped, inv_gram.
///
/// `rows_like = (na, nb, nk)` fits on the rows where that larger structure's regressors are finite
/// too (a sweep's grid envelope), so that a refit uses exactly the sweep's rows.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, output_terms, first_lag = 0, n_threads = 0, rows_like = None))]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
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
) -> PyResult<Bound<'py, PyDict>> {
    let env = match rows_like {
        Some((ena, enb, enk)) => Some(structure(py, ena, enb, enk, output_terms.clone())?),
        None => None,
    };
    let s = structure(py, na, nb, nk, output_terms)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let f = run(py, n_threads, || crate::fit::fit_rows_like(&d, &s, first_lag, true, env.as_ref()))?;
    let p = f.theta.len();
    let out = PyDict::new(py);
    out.set_item("theta", f.theta.into_pyarray(py))?;
    out.set_item("rss", f.rss)?;
    out.set_item("n_rows", f.n_rows)?;
    out.set_item("n_skipped", f.n_skipped)?;
    out.set_item("inv_gram", PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?)?;
    Ok(out)
}

/// Prediction with `horizon` steps (None = free-run simulation); NaN where no prediction exists.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, output_terms, theta, horizon = None, first_lag = 0))]
#[allow(clippy::too_many_arguments)]
fn predict<'py>(
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
    let out = run(py, 1, || Ok(crate::simulate::predict(&d, &s, th, horizon, first_lag)))?;
    Ok(out.into_pyarray(py))
}

/// Fits and validates every structure of a grid from one factorization.
///
/// `structures` is an (S, 1 + 2m) integer array of rows (na, nb_1..nb_m, nk_1..nk_m).
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, yv = None, uv = None, starts_v = None,
                    simulate_estimation = true, horizon = None, divergence_limit = 1e6, n_threads = 0,
                    chunk = 64, progress = None))]
#[allow(clippy::too_many_arguments)]
fn sweep<'py>(
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
    divergence_limit: f64,
    n_threads: usize,
    chunk: usize,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let terms = parse_output_terms(output_terms)?;
    let shape = structures.shape();
    if shape[1] != 1 + 2 * m {
        return Err(OrderError::new_err(format!("structures need 1 + 2·{m} columns, got {}", shape[1])));
    }
    let raw = structures.as_slice()?;
    let mut grid = Vec::with_capacity(shape[0]);
    for row in raw.chunks(shape[1]) {
        if row.iter().any(|&v| v < 0) {
            return Err(OrderError::new_err("orders must be non-negative"));
        }
        let r: Vec<usize> = row.iter().map(|&v| v as usize).collect();
        grid.push(
            Structure::new(r[0], r[1..1 + m].to_vec(), r[1 + m..].to_vec(), terms.clone())
                .map_err(|e| to_pyerr(py, e))?,
        );
    }
    let val_slices = match (&yv, &uv) {
        (Some(yv), Some(uv)) => Some(slices(yv, uv)?),
        _ => None,
    };
    let sv = starts_v.unwrap_or_else(|| vec![0]);
    let vd = match val_slices {
        Some((a, b, mv)) => Some(Data::new(a, b, mv, &sv).map_err(|e| to_pyerr(py, e))?),
        None => None,
    };
    let opts = SweepOptions { simulate_estimation, horizon, divergence_limit, parallel: n_threads != 1, chunk };
    let report = |done: usize| {
        if let Some(cb) = &progress {
            Python::attach(|py| {
                let _ = cb.call1(py, (done,));
            });
        }
    };
    let (res, n_est, n_val) = run(py, n_threads, || crate::sweep::sweep(&d, vd.as_ref(), &grid, &opts, &report))?;
    let s = res.len();
    let pmax = res.iter().map(|r| r.theta.len()).max().unwrap_or(0);
    let mut theta = vec![f64::NAN; s * pmax];
    let mut cols: [Vec<f64>; 8] = Default::default();
    let mut diverged_est = Vec::with_capacity(s);
    let mut diverged_val = Vec::with_capacity(s);
    let mut errors: Vec<Option<String>> = Vec::with_capacity(s);
    for (i, r) in res.into_iter().enumerate() {
        theta[i * pmax..i * pmax + r.theta.len()].copy_from_slice(&r.theta);
        cols[0].push(r.rss_est);
        cols[1].push(r.rss_val);
        cols[2].push(r.sim_est.rms);
        cols[3].push(r.sim_val.rms);
        cols[4].push(r.sim_est.n as f64);
        cols[5].push(r.sim_val.n as f64);
        cols[6].push(r.sim_est.norm);
        cols[7].push(r.sim_val.norm);
        diverged_est.push(r.sim_est.diverged);
        diverged_val.push(r.sim_val.diverged);
        errors.push(r.error.map(|e| e.to_string()));
    }
    let out = PyDict::new(py);
    out.set_item("theta", PyArray1::from_vec(py, theta).reshape([s, pmax])?)?;
    let names =
        ["rss_est", "rss_val", "rms_sim_est", "rms_sim_val", "n_sim_est", "n_sim_val", "norm_sim_est", "norm_sim_val"];
    for (name, col) in names.iter().zip(cols) {
        out.set_item(*name, col.into_pyarray(py))?;
    }
    out.set_item("diverged_est", PyArray1::from_vec(py, diverged_est))?;
    out.set_item("diverged_val", PyArray1::from_vec(py, diverged_val))?;
    out.set_item("errors", errors)?;
    out.set_item("n_est", n_est)?;
    out.set_item("n_val", n_val)?;
    Ok(out)
}

#[pymodule(name = "_core", gil_used = false)]
mod core_module {
    #[pymodule_export]
    use super::{fit, predict, sweep};
}
