//! Bindings of the prediction-error method (`crate::pem`): fit, prediction and gradient of
//! polynomial models (OE, ARMAX, BJ).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::arguments::slices;
use super::errors::{to_pyerr, ArxidError, OrderError};
use super::run::run;

/// Orders `(na, nb, nc, nd, nf, nk)` of a polynomial model, as passed from Python.
pub(super) type PolyOrders = (usize, Vec<usize>, usize, usize, Vec<usize>, Vec<usize>);

pub(super) fn poly_structure(py: Python<'_>, o: PolyOrders) -> PyResult<crate::pem::PolyStructure> {
    crate::pem::PolyStructure::new(o.0, o.1, o.2, o.3, o.4, o.5).map_err(|e| to_pyerr(py, e))
}

/// MATLAB's `InitialCondition` names: "zero" or "estimate".
pub(super) fn initial_condition(name: &str) -> PyResult<crate::pem::Initial> {
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
pub(super) fn pem_fit<'py>(
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
pub(super) fn pem_predict<'py>(
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
pub(super) type ErrorsAndJacobian<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// Prediction errors of a polynomial model (NaN outside the scored samples of `segments`) and
/// their Jacobian ∂ε/∂θ, shape (n, p), in `getpvec` order.
#[pyfunction]
pub(super) fn pem_gradient<'py>(
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
pub(super) fn pem_max_lag(py: Python<'_>, orders: PolyOrders) -> PyResult<usize> {
    Ok(poly_structure(py, orders)?.max_lag())
}
