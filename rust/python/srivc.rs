//! Python binding of the SRIVC state-variable filter (`crate::pem::srivc`).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::AtomicBool;

use super::errors::{from_panic, to_pyerr};
use super::run::run;
use crate::pem::srivc::{state_filter, StateFilter};

/// Below this many state updates (samples × order) the filter runs on the calling thread without
/// the GIL: a worker thread, its pool and the Ctrl-C polling cost more than the filtering (about a
/// millisecond), and so short a run ends before a Ctrl-C would be noticed anyway.
const INLINE_WORK: usize = 1 << 18;

/// States (filtered signal and its derivatives, shape (len, n)) of `signal` shifted by `shift`
/// samples through the discretised filter `phi` (n × n) with input taps `prev`, `cur`, `next`, from
/// rest in each segment; NaN outside the segments. Runs without the GIL; Ctrl-C stops a long one.
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
    let out = if len * n < INLINE_WORK {
        let never = AtomicBool::new(false);
        match py.detach(|| catch_unwind(AssertUnwindSafe(|| state_filter(s, &segments, &f, shift, &never)))) {
            Ok(r) => r.map_err(|e| to_pyerr(py, e))?,
            Err(panic) => return Err(from_panic(py, panic)),
        }
    } else {
        run(py, 1, |cancel| state_filter(s, &segments, &f, shift, cancel))?
    };
    PyArray1::from_vec(py, out).reshape([len, n])
}
