//! Python binding of the SRIVC state-variable filter (`crate::srivc`); part of the `py` module.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::{run, to_pyerr};
use crate::srivc::{state_filter, StateFilter};

/// States (filtered signal and its derivatives, shape (len, n)) of `signal` shifted by `shift`
/// samples through the discretised filter `phi` (n × n) with input taps `prev`, `cur`, `next`, from
/// rest in each segment; NaN outside the segments. Runs without the GIL; Ctrl-C stops it.
#[pyfunction]
#[pyo3(signature = (signal, segments, phi, prev, cur, next, shift = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn srivc_filter<'py>(
    py: Python<'py>,
    signal: PyReadonlyArray1<'py, f64>,
    segments: Vec<(usize, usize)>,
    phi: PyReadonlyArray2<'py, f64>,
    prev: PyReadonlyArray1<'py, f64>,
    cur: PyReadonlyArray1<'py, f64>,
    next: PyReadonlyArray1<'py, f64>,
    shift: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = phi.shape()[0];
    let f = StateFilter::new(
        n,
        phi.as_array().iter().copied().collect(),
        prev.as_slice()?.to_vec(),
        cur.as_slice()?.to_vec(),
        next.as_slice()?.to_vec(),
    )
    .map_err(|e| to_pyerr(py, e))?;
    let s = signal.as_slice()?;
    let len = s.len();
    let out = run(py, 1, |cancel| state_filter(s, &segments, &f, shift, cancel))?;
    PyArray1::from_vec(py, out).reshape([len, n])
}
