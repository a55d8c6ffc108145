//! Python binding of [`crate::subspace`]: subspace identification, the least-squares B, D and
//! initial states, and the state-space response. Errors go through `py::run`, the one conversion.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods, ToPyArray};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::run::run;
use crate::subspace::innovation::Innovation;
use crate::subspace::input_matrices::{input_matrices, Unknowns};
use crate::subspace::kalman_gain::kalman_gain;
use crate::subspace::refine::{refine, RefineOptions};
use crate::subspace::response::{respond, StateSpaceRef};
use crate::subspace::{identify, Horizons, Signals, SubspaceOptions, Weighting};

pyo3::import_exception!(arxid.exceptions, DataError);

fn view<'a>(a: &'a PyReadonlyArray2<'_, f64>) -> PyResult<faer::MatRef<'a, f64>> {
    let (rows, cols) = (a.shape()[0], a.shape()[1]);
    let values = a.as_slice().map_err(|_| DataError::new_err("a matrix must be C-contiguous"))?;
    Ok(faer::MatRef::from_row_major_slice(values, rows, cols))
}

fn matrix<'py>(py: Python<'py>, m: &faer::Mat<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if m.nrows() == 0 {
        return Ok(PyArray2::zeros(py, [0, m.ncols()], false));
    }
    Ok(PyArray2::from_vec2(py, &rows(m.as_ref()))?)
}

/// The rows of `m` (for the initial states: one per segment).
fn rows(m: faer::MatRef<'_, f64>) -> Vec<Vec<f64>> {
    (0..m.nrows()).map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect()).collect()
}

fn signals<'a>(
    u: &'a PyReadonlyArray2<'_, f64>,
    y: &'a PyReadonlyArray2<'_, f64>,
    segments: &'a [(usize, usize)],
) -> PyResult<Signals<'a>> {
    if u.shape()[0] != y.shape()[0] {
        return Err(DataError::new_err(format!("u has {} samples but y has {}", u.shape()[0], y.shape()[0])));
    }
    let (u_values, y_values) = (u.as_slice()?, y.as_slice()?);
    Ok(Signals { u: u_values, y: y_values, n_inputs: u.shape()[1], n_outputs: y.shape()[1], segments })
}

/// A and C of a state-space model of the segments of `u` (N × nu) and `y` (N × ny), by
/// `method` ("n4sid", "moesp" or "cva") with horizons `past` and `future`; `order` None chooses
/// among 1..=max_order by the singular value criterion. Returns a dict: `a`, `c`,
/// `singular_values`, `canonical_correlations`, `criterion`, `order`, `n_rows`.
#[pyfunction]
#[pyo3(signature = (u, y, segments, past, future, method, order, max_order, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub fn subspace_identify<'py>(
    py: Python<'py>,
    u: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    past: usize,
    future: usize,
    method: &str,
    order: Option<usize>,
    max_order: usize,
    n_threads: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let s = signals(&u, &y, &segments)?;
    let weighting = run(py, 1, |_| Weighting::parse(method))?;
    let options = SubspaceOptions { horizons: Horizons { past, future }, weighting, order, max_order };
    let id = run(py, n_threads, |cancel| identify(&s, options, n_threads != 1, cancel))?;
    let out = PyDict::new(py);
    out.set_item("a", matrix(py, &id.a)?)?;
    out.set_item("c", matrix(py, &id.c)?)?;
    out.set_item("singular_values", PyArray1::from_vec(py, id.singular_values))?;
    out.set_item("canonical_correlations", PyArray1::from_vec(py, id.canonical_correlations))?;
    out.set_item("criterion", PyArray1::from_vec(py, id.criterion))?;
    out.set_item("order", id.order)?;
    out.set_item("n_rows", id.n_rows)?;
    Ok(out)
}

/// `(B, D, x0)`: the B (n × nu), D (ny × nu, zero unless `feedthrough`) and one initial state per
/// segment (rows of x0, zero unless `initial_state`) that minimise the simulation error of the
/// model with state matrices `a` and `c` on the segments of `u` and `y`.
#[pyfunction]
#[pyo3(signature = (a, c, u, y, segments, feedthrough = true, initial_state = true))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn subspace_input_matrices<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    feedthrough: bool,
    initial_state: bool,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
    let s = signals(&u, &y, &segments)?;
    let (a, c) = (view(&a)?, view(&c)?);
    let n = a.nrows();
    if a.ncols() != n || c.ncols() != n || c.nrows() != s.n_outputs {
        return Err(DataError::new_err(format!(
            "A must be square and C have {} rows and as many columns as A, got A {}×{} and C {}×{}",
            s.n_outputs,
            a.nrows(),
            a.ncols(),
            c.nrows(),
            c.ncols()
        )));
    }
    let unknowns = Unknowns { feedthrough, initial_state };
    let fit = run(py, 0, |cancel| {
        s.check()?;
        input_matrices(a, c, &s, unknowns, cancel)
    })?;
    let x0 = faer::Mat::from_fn(fit.x0.len(), n, |i, j| fit.x0[i][j]);
    Ok((matrix(py, &fit.b)?, matrix(py, &fit.d)?, matrix(py, &x0)?))
}

/// K (n × ny) of the innovation form of the model (a, b, c, d) started from the rows of `x0` (one
/// per segment), by two regressions on its output error with an autoregression of `lags` samples
/// (see `rust/subspace/kalman_gain.rs`); not yet halved for stability.
#[pyfunction]
#[pyo3(signature = (a, b, c, d, x0, u, y, segments, lags, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub fn subspace_kalman_gain<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    d: PyReadonlyArray2<'py, f64>,
    x0: PyReadonlyArray2<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    lags: usize,
    n_threads: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let s = signals(&u, &y, &segments)?;
    let m = StateSpaceRef { a: view(&a)?, b: view(&b)?, c: view(&c)?, d: view(&d)? };
    let x0 = rows(view(&x0)?);
    let gain = run(py, n_threads, |cancel| {
        s.check()?;
        kalman_gain(m, &x0, &s, lags, n_threads != 1, cancel)
    })?;
    matrix(py, &gain)
}

/// `(y, x)`: the outputs (N × ny) and states (N × n) of the model (a, b, c, d) from state `x0`
/// driven by `u` (N × nu); NaN from where a state passed 1e150 on.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn state_space_response<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    d: PyReadonlyArray2<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
    let m = StateSpaceRef { a: view(&a)?, b: view(&b)?, c: view(&c)?, d: view(&d)? };
    if u.shape()[1] != m.b.ncols() {
        return Err(DataError::new_err(format!("u has {} columns but B has {}", u.shape()[1], m.b.ncols())));
    }
    let (x0, u_values, samples) = (x0.as_slice()?, u.as_slice()?, u.shape()[0]);
    let (n, ny) = (m.a.nrows(), m.c.nrows());
    let (y, x) = run(py, 1, |cancel| respond(m, x0, u_values, cancel))?;
    let y = y.to_pyarray(py).reshape([samples, ny])?;
    let x = x.to_pyarray(py).reshape([samples, n])?;
    Ok((y, x))
}

/// The prediction-error refinement of the innovation-form model (a, b, c, d, k) with one initial
/// state per segment (rows of `x0`) on the segments of `u` and `y`. Returns a dict: `a`, `b`, `c`,
/// `d`, `k`, `x0`, `start_loss`, `loss` (mean squared one-step errors), `losses`, `iterations`,
/// `termination`, `converged`, `n_free`.
#[pyfunction]
#[pyo3(signature = (a, b, c, d, k, x0, u, y, segments, estimate_initial = true, stable = false, max_iterations = 50, tolerance = 1e-7, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub fn subspace_refine<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    d: PyReadonlyArray2<'py, f64>,
    k: PyReadonlyArray2<'py, f64>,
    x0: PyReadonlyArray2<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    estimate_initial: bool,
    stable: bool,
    max_iterations: usize,
    tolerance: f64,
    n_threads: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let s = signals(&u, &y, &segments)?;
    let x0 = view(&x0)?;
    let start = Innovation {
        a: view(&a)?.to_owned(),
        b: view(&b)?.to_owned(),
        c: view(&c)?.to_owned(),
        d: view(&d)?.to_owned(),
        k: view(&k)?.to_owned(),
        x0: rows(x0),
    };
    let options = RefineOptions { max_iterations, tolerance, estimate_initial, stable, parallel: n_threads != 1 };
    let fit = run(py, n_threads, |cancel| refine(&start, &s, options, cancel))?;
    let m = &fit.model;
    let out = PyDict::new(py);
    for (name, matrix_value) in [("a", &m.a), ("b", &m.b), ("c", &m.c), ("d", &m.d), ("k", &m.k)] {
        out.set_item(name, matrix(py, matrix_value)?)?;
    }
    let n = m.a.nrows();
    out.set_item("x0", matrix(py, &faer::Mat::from_fn(m.x0.len(), n, |i, j| m.x0[i][j]))?)?;
    out.set_item("start_loss", fit.start_loss)?;
    out.set_item("loss", fit.loss)?;
    out.set_item("losses", PyArray1::from_vec(py, fit.losses))?;
    out.set_item("iterations", fit.iterations)?;
    out.set_item("termination", fit.termination.to_string())?;
    out.set_item("converged", fit.termination.converged())?;
    out.set_item("n_free", fit.n_free)?;
    Ok(out)
}
