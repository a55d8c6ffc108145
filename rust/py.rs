//! The one place Rust meets Python: borrow numpy arrays, call the pure core with the GIL released,
//! convert results and errors back. Panics are caught here and never reach Python.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError};
use pyo3::prelude::*;
use pyo3::types::{PyInt, PyTuple};
use rayon::ThreadPool;

use crate::columns::envelope;
use crate::error::ArxError;
use crate::structure::{Data, OutputKind, OutputTerm, Structure};
use crate::sweep::{clamp_threads, effective_threads, SweepOptions};
use crate::sweep_columns::{envelope_rows, release, structures_of_rows, SweepColumns};

#[path = "py_lagged.rs"]
mod py_lagged;
#[path = "py_procest.rs"]
mod py_procest;
#[path = "py_scoring.rs"]
mod py_scoring;
#[path = "py_srivc.rs"]
mod py_srivc;

pyo3::import_exception!(arxid.exceptions, ArxidError);
pyo3::import_exception!(arxid.exceptions, DataError);
pyo3::import_exception!(arxid.exceptions, OrderError);
pyo3::import_exception!(arxid.exceptions, IdentifiabilityError);
pyo3::import_exception!(arxid.exceptions, ConvergenceError);

fn to_pyerr(py: Python<'_>, e: ArxError) -> PyErr {
    let msg = e.to_string();
    match e {
        ArxError::RankDeficient { column, .. } => {
            let err = IdentifiabilityError::new_err(msg);
            let _ = err.value(py).setattr("column", column);
            err
        }
        ArxError::TooFewSamples { .. } | ArxError::ShapeMismatch { .. } => DataError::new_err(msg),
        ArxError::InvalidStructure(_) => OrderError::new_err(msg),
        ArxError::NotExciting(_) => IdentifiabilityError::new_err(msg),
        ArxError::NotConverged(_) => ConvergenceError::new_err(msg),
        ArxError::OutOfMemory { .. } => PyMemoryError::new_err(msg),
        ArxError::Interrupted => PyKeyboardInterrupt::new_err(msg),
    }
}

/// The pool for `n_threads = 0` (all cores) and the process it was built in. rayon's worker
/// threads do not survive `fork`: a child that used the parent's pool would wait for ever, so a
/// child (another pid) builds its own.
static ALL_CORES: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// How often the thread that waits for the core looks for a pending signal (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// A rayon pool of `n_threads` threads (0 = all cores, shared by the calls of this process).
fn pool(n_threads: usize) -> Result<Arc<ThreadPool>, String> {
    let build = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map(Arc::new)
            .map_err(|e| format!("cannot start {n} threads ({e}); use n_threads=1 or raise the process limit"))
    };
    if n_threads != 0 {
        return build(n_threads);
    }
    let pid = std::process::id();
    let mut slot = ALL_CORES.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((owner, p)) = slot.as_ref() {
        if *owner == pid {
            return Ok(p.clone());
        }
    }
    let fresh = build(0)?;
    if let Some((_, inherited)) = slot.replace((pid, fresh.clone())) {
        // The parent's pool: its threads are not in this process, so dropping it could wait for them.
        std::mem::forget(inherited);
    }
    Ok(fresh)
}

/// The message of a panic payload, or the error the core unwound with (see `qr::reduce`).
fn from_panic(py: Python<'_>, panic: Box<dyn std::any::Any + Send>) -> PyErr {
    if let Some(e) = panic.downcast_ref::<ArxError>() {
        return to_pyerr(py, e.clone());
    }
    let what = panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "unknown".into());
    if what.contains("AllocError") {
        // faer's matrices panic (not abort) when their allocation fails.
        return PyMemoryError::new_err(format!(
            "out of memory in the arxid core ({what}); use fewer samples, lower orders or a smaller grid"
        ));
    }
    ArxidError::new_err(format!("internal error in the arxid core (please report it): {what}"))
}

type Outcome<T> = std::thread::Result<Result<T, ArxError>>;

/// Runs `f(cancel)` without the GIL on `n_threads` threads (0 = all), turning a panic into an
/// error. Results do not depend on the thread count, so the count is capped by [`clamp_threads`].
///
/// The calling thread waits and polls for signals every [`SIGNAL_POLL`]: on Ctrl-C it sets
/// `cancel`, which the core checks between blocks of work, and raises `KeyboardInterrupt` once
/// the core has stopped.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    n_threads: usize,
    f: impl FnOnce(&AtomicBool) -> Result<T, ArxError> + Send,
) -> PyResult<T> {
    let pool = pool(clamp_threads(n_threads)).map_err(ArxidError::new_err)?;
    let cancel = AtomicBool::new(false);
    let (out, interrupt) = py.detach(|| {
        std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel::<Outcome<T>>();
            let (cancel, pool) = (&cancel, &pool);
            let spawned = std::thread::Builder::new().spawn_scoped(scope, move || {
                let _ = tx.send(catch_unwind(AssertUnwindSafe(|| pool.install(|| f(cancel)))));
            });
            if let Err(e) = spawned {
                return (Err(Box::new(format!("cannot start a thread ({e})")) as Box<dyn std::any::Any + Send>), None);
            }
            let mut interrupt = None;
            loop {
                match rx.recv_timeout(SIGNAL_POLL) {
                    Ok(outcome) => return (outcome, interrupt),
                    Err(mpsc::RecvTimeoutError::Timeout) if interrupt.is_none() => {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            cancel.store(true, Ordering::Relaxed);
                            interrupt = Some(e);
                        }
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        let lost: Box<dyn std::any::Any + Send> = Box::new("the worker thread ended without a result");
                        return (Err(lost), interrupt);
                    }
                }
            }
        })
    });
    if let Some(e) = interrupt {
        return Err(e);
    }
    match out {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_pyerr(py, e)),
        Err(panic) => Err(from_panic(py, panic)),
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
                "sign" => OutputKind::Sign,
                "signdiff" => OutputKind::SignDiff,
                other => return Err(OrderError::new_err(format!("unknown output term kind {other:?}"))),
            };
            Ok(OutputTerm { kind, multiplier: if mult < 0 { None } else { Some(mult as usize) } })
        })
        .collect()
}

/// Rows `(na, nb_1..nb_m, nk_1..nk_m)` of an (S, 1 + 2m) integer array as structures.
fn parse_grid(
    py: Python<'_>,
    structures: &PyReadonlyArray2<'_, i64>,
    m: usize,
    terms: &[OutputTerm],
) -> PyResult<Vec<Structure>> {
    let shape = structures.shape();
    if shape[1] != 1 + 2 * m {
        return Err(OrderError::new_err(format!("structures need 1 + 2·{m} columns, got {}", shape[1])));
    }
    parse_rows(py, structures.as_slice()?, m, terms)
}

/// Structures from rows `(na, nb_1..nb_m, nk_1..nk_m)`, laid out one after the other.
fn parse_rows(py: Python<'_>, raw: &[i64], m: usize, terms: &[OutputTerm]) -> PyResult<Vec<Structure>> {
    if raw.iter().any(|&v| v < 0) {
        return Err(OrderError::new_err("orders must be non-negative"));
    }
    let usize_of = |v: &[i64]| v.iter().map(|&x| x as usize).collect::<Vec<usize>>();
    raw.chunks(1 + 2 * m)
        .map(|r| {
            Structure::new(r[0] as usize, usize_of(&r[1..1 + m]), usize_of(&r[1 + m..]), terms.to_vec())
                .map_err(|e| to_pyerr(py, e))
        })
        .collect()
}

/// `(na, (nb per input column), (nk per input column))` of a structure, as Python tuples.
fn orders_tuple<'py>(py: Python<'py>, s: &Structure) -> PyResult<Bound<'py, PyTuple>> {
    (s.na, PyTuple::new(py, s.nb.iter().copied())?, PyTuple::new(py, s.nk.iter().copied())?).into_pyobject(py)
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
) -> PyResult<FitOutput> {
    let env = match rows_like {
        Some((ena, enb, enk)) => Some(structure(py, ena, enb, enk, output_terms.clone())?),
        None => None,
    };
    let s = structure(py, na, nb, nk, output_terms)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = Data::new(ys, us, m, &starts).map_err(|e| to_pyerr(py, e))?;
    let f = run(py, n_threads, |cancel| crate::fit::fit_rows_like(&d, &s, first_lag, true, env.as_ref(), cancel))?;
    let p = f.theta.len();
    Ok(FitOutput {
        theta: f.theta.into_pyarray(py).unbind(),
        rss: f.rss,
        n_rows: f.n_rows,
        n_skipped: f.n_skipped,
        inv_gram: PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?.unbind(),
    })
}

/// The first-order band's variance of a free run (see [`crate::band::free_run_variance`]): `thetas`
/// holds θ⁺_0, θ⁻_0, θ⁺_1, … one per row; None when an experiment has a missing sample. Runs with the
/// GIL released and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (y, u, starts, na, nb, nk, thetas, step, first_lag = 0))]
#[allow(clippy::too_many_arguments)]
fn free_run_variance<'py>(
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
    let out = run(py, 1, |cancel| crate::band::free_run_variance(&d, &s, &rows, step, first_lag, cancel))?;
    Ok(out.map(|v| v.into_pyarray(py)))
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
    // Scanned only for a k-step prediction (a pass over all the data).
    let linear_complete = || s.output_terms.is_empty() && ys.iter().chain(us).all(|v| v.is_finite());
    // The k-step predictor of a linear structure is a filter: O(N (na + nb)) for any k.
    if let Some(k) = horizon.filter(|&k| k >= 2 && linear_complete()) {
        let out = run(py, 1, |_| Ok(crate::kstep::predict_k(&d, &s, th, k, first_lag)))?;
        return Ok(out.into_pyarray(py));
    }
    // Written in place into numpy's zeroed memory (large blocks in huge pages): no page-by-page
    // faults on a fresh Rust buffer.
    let out = PyArray1::<f64>::zeros(py, ys.len(), false);
    {
        let mut rw = out.readwrite();
        let buf = rw.as_slice_mut()?;
        run(py, 1, |cancel| crate::simulate::predict_into(&d, &s, th, horizon, first_lag, cancel, buf))?;
    }
    Ok(out)
}

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

/// The rows of a grid's layout, checked: `1 + 2·m` non-negative integers each.
fn layout_rows<'a>(structures: &'a PyReadonlyArray2<'_, i64>, m: usize) -> PyResult<&'a [i64]> {
    let shape = structures.shape();
    if shape[1] != 1 + 2 * m {
        return Err(OrderError::new_err(format!("structures need 1 + 2·{m} columns, got {}", shape[1])));
    }
    let raw = structures.as_slice()?;
    if raw.iter().any(|&v| v < 0) {
        return Err(OrderError::new_err("orders must be non-negative"));
    }
    Ok(raw)
}

/// The Python view of a sweep's results (grid order).
fn sweep_output(py: Python<'_>, swept: crate::sweep::Swept, grid: &[Structure]) -> PyResult<SweepOutput> {
    // The same envelope the sweep built (it succeeded, so this cannot fail).
    let env = envelope(grid).map_err(|e| to_pyerr(py, e))?;
    columns_output(py, SweepColumns::new(swept, false), &env)
}

/// [`SweepOutput`] of a sweep's columns: the vectors become numpy arrays without a copy.
fn columns_output(py: Python<'_>, c: SweepColumns, env: &Structure) -> PyResult<SweepOutput> {
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
fn grid_envelope<'py>(
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

/// Largest lag any regressor of the structure reads: its first usable row is this far into each
/// experiment.
#[pyfunction]
fn max_lag(
    py: Python<'_>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    output_terms: Vec<(String, i32, i64)>,
) -> PyResult<usize> {
    Ok(structure(py, na, nb, nk, output_terms)?.max_lag())
}

/// A non-negative Python int as usize, saturating at `usize::MAX` (sizes only compared to a limit).
fn saturating_usize(v: &Bound<'_, PyAny>) -> PyResult<usize> {
    match v.extract::<usize>() {
        Ok(n) => Ok(n),
        Err(_) if v.is_instance_of::<PyInt>() && v.gt(0)? => Ok(usize::MAX),
        Err(e) => Err(e),
    }
}

/// Bytes a sweep needs beyond the data arrays (saturates at 2^64 − 1 for absurd sizes).
///
/// `n_structures` structures with up to `p_max` parameters, a largest regressor of `q` columns
/// (output included), `n_est` / `n_val` samples, `n_cols` input columns of the effect layout,
/// `n_threads` as passed to `sweep` (0 = all cores).
#[pyfunction]
fn sweep_memory(
    n_structures: &Bound<'_, PyAny>,
    p_max: &Bound<'_, PyAny>,
    q: &Bound<'_, PyAny>,
    n_est: &Bound<'_, PyAny>,
    n_val: &Bound<'_, PyAny>,
    n_cols: &Bound<'_, PyAny>,
    n_threads: &Bound<'_, PyAny>,
) -> PyResult<usize> {
    Ok(crate::sweep::sweep_memory(
        saturating_usize(n_structures)?,
        saturating_usize(p_max)?,
        saturating_usize(q)?,
        saturating_usize(n_est)?,
        saturating_usize(n_val)?,
        saturating_usize(n_cols)?,
        saturating_usize(n_threads)?,
    ))
}

/// Bytes a fit of `n_rows` regression rows and `n_params` parameters allocates on `n_threads`
/// threads as passed to `fit` (0 = all cores); saturates at 2^64 − 1 for absurd sizes.
#[pyfunction]
fn fit_memory(n_rows: &Bound<'_, PyAny>, n_params: &Bound<'_, PyAny>, n_threads: &Bound<'_, PyAny>) -> PyResult<usize> {
    let threads = effective_threads(saturating_usize(n_threads)?);
    Ok(crate::fit::fit_memory(saturating_usize(n_rows)?, saturating_usize(n_params)?, threads))
}

/// Magnitude beyond which a prediction of `y` counts as diverged (the core's one divergence rule).
#[pyfunction]
fn divergence_limit(y: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    Ok(crate::simulate::divergence_limit(y.as_slice()?))
}

/// `(Σ x², n)` over the `n` finite samples of a contiguous `x`, in one pass (GIL released).
#[pyfunction]
fn finite_squares(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<(f64, usize)> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::finite_sums::finite_squares(x)))
}

/// `(Σ (y − p)², n)` over the `n` samples where the difference of two contiguous series of equal
/// length is finite, in one pass without forming it (GIL released).
#[pyfunction]
fn finite_squares_of_difference(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
) -> PyResult<(f64, usize)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    Ok(py.detach(|| crate::finite_sums::finite_squares_of_difference(y, p)))
}

/// `(counts, sums, varies)` per group of `group` (uint8, below `groups`): the samples, the sum of
/// each series (`sums[s, g]`, in sample order as `numpy.bincount`) and whether a group holds two
/// different values of the first series; one pass (GIL released).
#[pyfunction]
fn group_sums<'py>(
    py: Python<'py>,
    group: PyReadonlyArray1<'py, u8>,
    groups: usize,
    series: Vec<PyReadonlyArray1<'py, f64>>,
) -> PyResult<GroupSumsOutput<'py>> {
    let group = group.as_slice()?;
    let views = series.iter().map(|s| s.as_slice()).collect::<Result<Vec<_>, _>>()?;
    let out = py.detach(|| crate::group_sums::group_sums(group, groups, &views)).map_err(|e| to_pyerr(py, e))?;
    let sums = PyArray1::from_vec(py, out.sums).reshape([series.len(), groups])?;
    Ok((PyArray1::from_vec(py, out.counts), sums, PyArray1::from_vec(py, out.varies)))
}

/// `(counts, sums, varies)`: see [`group_sums`].
type GroupSumsOutput<'py> = (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<bool>>);

/// `(n, peak_y, peak_p, p_infinite, peak_both, sum_both)` of a prediction `p` of `y` (contiguous,
/// equal length) in one pass (see [`crate::finite_sums::FitPass`]; GIL released).
#[pyfunction]
fn fit_pass(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
) -> PyResult<(usize, f64, f64, bool, f64, f64)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    let f = py.detach(|| crate::finite_sums::fit_pass(y, p));
    Ok((f.n, f.peak_y, f.peak_p, f.p_infinite, f.peak_both, f.sum_both))
}

/// `(Σ ((y − p)·scale)², Σ ((y − mean)·scale)²)` where both are finite, in one pass (GIL released).
#[pyfunction]
fn fit_squares(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
    mean: f64,
    scale: f64,
) -> PyResult<(f64, f64)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    Ok(py.detach(|| crate::finite_sums::fit_squares(y, p, mean, scale)))
}

fn same_length(y: &[f64], p: &[f64]) -> PyResult<()> {
    if y.len() != p.len() {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "the two series differ in length ({} and {} samples)",
            y.len(),
            p.len()
        )));
    }
    Ok(())
}

/// Largest |x| over the samples of a contiguous `x` that are not NaN (inf when one is infinite,
/// NaN when none is a number), in one pass (GIL released).
#[pyfunction]
fn peak_magnitude(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::finite_sums::peak_magnitude(x)))
}

/// Largest |x| over the finite samples of a contiguous `x` (0 when there are none), in one pass
/// (GIL released).
#[pyfunction]
fn finite_peak(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::finite_sums::finite_peak(x)))
}

// ---- Sweeps at scale (issue 15): fleet partials, fits from factors, simulation of groups, limit kernel.

/// `(R, n_rows)`: the triangular factor (q × q, output last) of the grid envelope's regressor on
/// these data, a partial of a fleet sweep (combine partials by QR of their stacked factors).
/// `n_threads` (default 1: a fleet's workers already run one log per core; 0 = all cores) reduce
/// blocks of rows in parallel.
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, n_threads = 1))]
fn grid_factor<'py>(
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
    let (r, n) = run(py, n_threads, |_| crate::sweep::grid_factor(&d, &grid, n_threads != 1))?;
    Ok((factor_array(py, r)?, n))
}

/// A column-major square factor as a (q, q) numpy array.
fn factor_array(py: Python<'_>, r: Vec<f64>) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let q = (r.len() as f64).sqrt() as usize;
    // Column-major q × q as a (q, q) array: the transpose of the row-major reading.
    let a = PyArray1::from_vec(py, r).reshape([q, q])?;
    Ok(a.transpose()?.cast_into::<PyArray2<f64>>()?)
}

/// The fit of one structure of a grid from the grid envelope's factor (returns a `FitOutput`): the
/// same parameters, loss and (Φᵀ Φ)⁻¹ as `fit` on the sweep's rows, to rounding, without the data.
/// `envelope` and `structure` are `(na, nb, nk)` per layout column.
#[pyfunction]
fn fit_from_factor<'py>(
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
    let inside = s.na <= env.na
        && s.nb.len() == env.nb.len()
        && (0..s.nb.len())
            .all(|i| s.nb[i] == 0 || (s.nk[i] >= env.nk[i] && s.nk[i] + s.nb[i] <= env.nk[i] + env.nb[i]));
    if !inside {
        return Err(OrderError::new_err("the structure reads columns outside the envelope"));
    }
    let cols = crate::columns::columns_in(&env, &s);
    let q = env.n_params() + 1;
    let f = run(py, 1, |_| crate::fit::fit_from_factor(&r, q, &cols, n_rows))?;
    let p = f.theta.len();
    Ok(FitOutput {
        theta: f.theta.into_pyarray(py).unbind(),
        rss: f.rss,
        n_rows: f.n_rows,
        n_skipped: 0,
        inv_gram: PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?.unbind(),
    })
}

/// A column-major copy of a square (q × q) factor given as a numpy array.
fn factor_from(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<f64>> {
    let shape = a.shape();
    if shape[0] != shape[1] {
        return Err(DataError::new_err(format!("a factor must be square, got {} × {}", shape[0], shape[1])));
    }
    let v = a.as_array();
    Ok((0..shape[1]).flat_map(|j| (0..shape[0]).map(move |i| (i, j))).map(|(i, j)| v[[i, j]]).collect())
}

/// Every structure solved from combined factors (one or two stages as `sweep`, nothing simulated):
/// a `SweepOutput` whose simulation columns are NaN, and the indices a sweep would simulate.
#[pyfunction]
#[pyo3(signature = (r_est, n_est, structures, output_terms, r_val = None, n_val = 0, top = None, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
fn sweep_factors<'py>(
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
    let (results, simulate) =
        run(py, n_threads, |_| crate::sweep::fits_from_factors(&grid, to_fit, n_est, rv, n_val, top, parallel))?;
    let swept = crate::sweep::Swept { results, n_est, n_val, r_est: re };
    Ok((sweep_output(py, swept, &grid)?, simulate.into_pyarray(py)))
}

/// `(rms, n, norm, mean, diverged)` of fitted structures simulated on these data from `first_lag` on (free run,
/// or `horizon`-step prediction), exactly as `sweep` simulates them. `theta` is (S, p_max), NaN-padded;
/// `limit` replaces the divergence limit of these data.
#[pyfunction]
#[pyo3(signature = (y, u, starts, structures, output_terms, theta, first_lag, horizon = None, n_threads = 0,
                    limit = None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn simulate_structures<'py>(
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
        crate::sweep::simulate_structures_cancellable(&d, &grid, thetas, first_lag, limit, &opts, cancel)
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

/// Seconds for `n_vectors` multiply-adds of eight lanes each at the machine's throughput (many
/// independent chains, on every core): the limit a free-run sweep of the same work could reach.
#[pyfunction]
#[pyo3(signature = (n_vectors, n_threads = 0))]
fn fma_limit(py: Python<'_>, n_vectors: u64, n_threads: usize) -> PyResult<f64> {
    run(py, n_threads, |_| Ok(crate::simulate::fma_throughput_seconds(n_vectors)))
}

// ---------------------------------------------------------------- prediction-error models (pem.rs)

/// Orders `(na, nb, nc, nd, nf, nk)` of a polynomial model, as passed from Python.
type PolyOrders = (usize, Vec<usize>, usize, usize, Vec<usize>, Vec<usize>);

fn poly_structure(py: Python<'_>, o: PolyOrders) -> PyResult<crate::pem::PolyStructure> {
    crate::pem::PolyStructure::new(o.0, o.1, o.2, o.3, o.4, o.5).map_err(|e| to_pyerr(py, e))
}

/// MATLAB's `InitialCondition` names: "zero" or "estimate".
fn initial_condition(name: &str) -> PyResult<crate::pem::Initial> {
    match name {
        "zero" => Ok(crate::pem::Initial::Zero),
        "estimate" => Ok(crate::pem::Initial::Estimate),
        other => Err(ArxidError::new_err(format!("initial must be 'zero' or 'estimate', got {other:?}"))),
    }
}

/// What `pem_fit` returns.
#[pyclass(frozen, get_all, module = "arxid._core")]
pub struct PemOutput {
    /// Parameters in MATLAB's `getpvec` order (A, B, C, D, F), shape (p,).
    theta: Py<PyArray1<f64>>,
    /// The start (ARX / SRIV / Hannan–Rissanen, stabilised), shape (p,).
    start: Py<PyArray1<f64>>,
    /// Sum of squared prediction errors on the scored samples.
    rss: f64,
    /// Same at the start.
    start_rss: f64,
    /// Number of scored samples.
    n_rows: usize,
    /// (Jᵀ J)⁻¹ at the estimate, shape (p, p); times the noise variance it is the covariance.
    inv_gram: Py<PyArray2<f64>>,
    /// Accepted Gauss–Newton steps.
    iterations: usize,
    /// Loss after each accepted step, the start first.
    losses: Py<PyArray1<f64>>,
    /// Why the iterations stopped, in words.
    termination: String,
    /// True when they stopped at a (local) minimum.
    converged: bool,
    /// With initial="estimate": the segments `(start, end)` whose initial state was estimated.
    initial_segments: Vec<(usize, usize)>,
    /// Their initial states, one row per segment (empty with initial="zero").
    initial_states: Vec<Vec<f64>>,
}

/// Prediction-error fit of a polynomial model on finite `segments` `[start, end)` of the data.
#[pyfunction]
#[pyo3(signature = (
    y, u, segments, orders, start = None, max_iterations = 100, tolerance = 1e-6, n_threads = 0, initial = "zero"
))]
#[allow(clippy::too_many_arguments)]
fn pem_fit<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    orders: PolyOrders,
    start: Option<PyReadonlyArray1<'py, f64>>,
    max_iterations: usize,
    tolerance: f64,
    n_threads: usize,
    initial: &str,
) -> PyResult<PemOutput> {
    let initial = initial_condition(initial)?;
    let s = poly_structure(py, orders)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = crate::pem::Segments::new(ys, us, m, &segments).map_err(|e| to_pyerr(py, e))?;
    let start = match &start {
        Some(a) => Some(a.as_slice()?),
        None => None,
    };
    let opts =
        crate::pem::PemOptions { max_iterations, tolerance, parallel: n_threads != 1, initial, ..Default::default() };
    let f = run(py, n_threads, |cancel| crate::pem::pem(&d, &s, &opts, start, cancel))?;
    let (initial_segments, initial_states) = f.initial_states.into_iter().unzip();
    let p = f.theta.len();
    Ok(PemOutput {
        theta: f.theta.into_pyarray(py).unbind(),
        start: f.start.into_pyarray(py).unbind(),
        rss: f.rss,
        start_rss: f.start_rss,
        n_rows: f.n_rows,
        inv_gram: PyArray1::from_vec(py, f.inv_gram).reshape([p, p])?.unbind(),
        iterations: f.iterations,
        losses: f.losses.into_pyarray(py).unbind(),
        termination: f.termination.to_string(),
        converged: f.termination.converged(),
        initial_segments,
        initial_states,
    })
}

/// Prediction of a polynomial model: `horizon` k steps ahead, None the free run; NaN outside the
/// scored samples of `segments`; `initial` "zero" or "estimate" (fitted to these data first).
#[pyfunction]
#[pyo3(signature = (y, u, segments, orders, theta, horizon = None, initial = "zero"))]
#[allow(clippy::too_many_arguments)]
fn pem_predict<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    orders: PolyOrders,
    theta: PyReadonlyArray1<'py, f64>,
    horizon: Option<usize>,
    initial: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let initial = initial_condition(initial)?;
    let s = poly_structure(py, orders)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = crate::pem::Segments::new(ys, us, m, &segments).map_err(|e| to_pyerr(py, e))?;
    let th = theta.as_slice()?;
    if th.len() != s.n_params() || s.nb.len() != m || horizon == Some(0) {
        return Err(OrderError::new_err(format!(
            "theta has {} entries and nb {} inputs; the structure has {} parameters and the data {m} inputs \
             (horizon must be >= 1 or None)",
            th.len(),
            s.nb.len(),
            s.n_params()
        )));
    }
    let out = run(py, 1, |cancel| crate::pem::predict_cancellable(&d, &s, th, horizon, initial, cancel))?;
    Ok(out.into_pyarray(py))
}

/// Prediction errors and their Jacobian, as `pem_gradient` returns them.
type ErrorsAndJacobian<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// Prediction errors of a polynomial model (NaN outside the scored samples of `segments`) and
/// their Jacobian ∂ε/∂θ, shape (n, p), in `getpvec` order.
#[pyfunction]
fn pem_gradient<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    orders: PolyOrders,
    theta: PyReadonlyArray1<'py, f64>,
) -> PyResult<ErrorsAndJacobian<'py>> {
    let s = poly_structure(py, orders)?;
    let (ys, us, m) = slices(&y, &u)?;
    let d = crate::pem::Segments::new(ys, us, m, &segments).map_err(|e| to_pyerr(py, e))?;
    let th = theta.as_slice()?;
    if th.len() != s.n_params() || s.nb.len() != m {
        return Err(OrderError::new_err(format!(
            "theta has {} entries and nb {} inputs; the structure has {} parameters and the data {m} inputs",
            th.len(),
            s.nb.len(),
            s.n_params()
        )));
    }
    let (eps, jac) = run(py, 1, |_| Ok(crate::pem::gradient(&d, &s, th)))?;
    let jac = PyArray1::from_vec(py, jac).reshape([ys.len(), th.len()])?;
    Ok((eps.into_pyarray(py), jac))
}

/// Samples at the start of each run of finite data that a polynomial model treats as initial
/// conditions (not scored).
#[pyfunction]
fn pem_max_lag(py: Python<'_>, orders: PolyOrders) -> PyResult<usize> {
    Ok(poly_structure(py, orders)?.max_lag())
}

// ---------------------------------------------------------------- end of prediction-error models

#[path = "py_iv.rs"]
mod py_iv;

#[pymodule(name = "_core", gil_used = false)]
mod core_module {
    #[pymodule_export]
    use super::py_iv::iv_sweep;
    #[pymodule_export]
    use super::py_lagged::{ar_filter_rows, lagged_products, lagged_r};
    #[pymodule_export]
    use super::py_procest::{procest_refine, procest_simulate};
    #[pymodule_export]
    use super::py_scoring::{fit_residual, refine_fit_residual, tested_products, threshold_products};
    #[pymodule_export]
    use super::py_srivc::srivc_filter;
    #[pymodule_export]
    use super::{
        divergence_limit, fit, fit_memory, free_run_variance, grid_envelope, max_lag, predict, sweep, sweep_memory,
        FitOutput, SweepOutput,
    };
    #[pymodule_export]
    use super::{
        finite_peak, finite_squares, finite_squares_of_difference, fit_pass, fit_squares, group_sums, peak_magnitude,
    };
    #[pymodule_export]
    use super::{fit_from_factor, fma_limit, grid_factor, simulate_structures, sweep_factors};
    #[pymodule_export]
    use super::{pem_fit, pem_gradient, pem_max_lag, pem_predict, PemOutput};
    #[pymodule_export]
    use crate::py_csv::csv_read;
    #[pymodule_export]
    use crate::py_flight_log::{blackbox_fields, blackbox_read, dataflash_read};
    #[pymodule_export]
    use crate::py_subspace::{state_space_response, subspace_identify, subspace_input_matrices};

    #[pymodule_init]
    fn init(m: &pyo3::Bound<'_, pyo3::types::PyModule>) -> pyo3::PyResult<()> {
        use pyo3::types::PyModuleMethods;
        m.add("DIVERGENCE_FACTOR", crate::simulate::DIVERGENCE_FACTOR)
    }
}
