//! Python bindings of the process-model refinement (`crate::pem::procest`).

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::errors::{to_pyerr, DataError};
use super::run::run;
use crate::pem::procest::{refine, Options, Problem, Process};

/// One structure per input: `(n_poles, zero, underdamped, integrator, delay)`.
type Spec = (usize, bool, bool, bool, bool);

fn processes(py: Python<'_>, specs: &[Spec]) -> PyResult<Vec<Process>> {
    specs.iter().map(|&(n, z, u, i, d)| Process::new(n, z, u, i, d).map_err(|e| to_pyerr(py, e))).collect()
}

fn check_rows(y_len: usize, u: &PyReadonlyArray2<'_, f64>) -> PyResult<usize> {
    if u.shape()[0] != y_len {
        return Err(DataError::new_err(format!("y has {y_len} samples but u has {} rows", u.shape()[0])));
    }
    Ok(u.shape()[1])
}

/// The process models' summed output (exact ZOH, fractional dead time), from rest in each segment,
/// NaN outside them. Runs without the GIL.
#[pyfunction]
pub(super) fn procest_simulate<'py>(
    py: Python<'py>,
    u: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    ts: f64,
    structures: Vec<Spec>,
    x: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let len = u.shape()[0];
    let m = check_rows(len, &u)?;
    let procs = processes(py, &structures)?;
    let zeros = vec![0.0; len];
    let (us, xs) = (u.as_slice()?, x.as_slice()?);
    let pb = Problem { y: &zeros, u: us, m, ts, segments: &segments, processes: &procs };
    let out = run(py, 1, |_| pb.simulate(xs))?;
    Ok(out.into_pyarray(py))
}

/// Bounded prediction-error refinement of process models (projected Levenberg–Marquardt, see
/// `crate::pem::procest`). Returns `(x, jtj, residual, iterations, evaluations, converged, on_bound)`.
/// Runs without the GIL; Ctrl-C stops it.
#[pyfunction]
#[pyo3(signature = (y, u, segments, ts, structures, x0, lower, upper, max_iterations = 100))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(super) fn procest_refine<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    segments: Vec<(usize, usize)>,
    ts: f64,
    structures: Vec<Spec>,
    x0: PyReadonlyArray1<'py, f64>,
    lower: PyReadonlyArray1<'py, f64>,
    upper: PyReadonlyArray1<'py, f64>,
    max_iterations: usize,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    usize,
    usize,
    bool,
    Vec<bool>,
)> {
    let m = check_rows(y.len(), &u)?;
    let procs = processes(py, &structures)?;
    let (ys, us) = (y.as_slice()?, u.as_slice()?);
    let (x0, lo, hi) = (x0.as_slice()?, lower.as_slice()?, upper.as_slice()?);
    let pb = Problem { y: ys, u: us, m, ts, segments: &segments, processes: &procs };
    let opts = Options { max_iterations, ..Options::default() };
    let r = run(py, 1, |cancel| refine(&pb, x0, lo, hi, opts, cancel))?;
    let p = r.x.len();
    let jtj = PyArray1::from_vec(py, r.jtj).reshape([p, p])?;
    Ok((r.x.into_pyarray(py), jtj, r.residual.into_pyarray(py), r.iterations, r.evaluations, r.converged, r.on_bound))
}
