//! Python binding of the threshold scan's products ([`crate::threshold_scan`]); a child of `py`,
//! so it shares its thread pool and its Ctrl-C handling.

use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::run;
use crate::threshold_scan::{scan_products, ScanRows, Shape};

/// `(cross, zz)`: see [`threshold_products`].
type Products<'py> = (Bound<'py, PyArray3<f64>>, Bound<'py, PyArray3<f64>>);

/// `(cross, zz)` of a threshold scan: `cross[i, j, t]` is column i of `[a | e]` times
/// `shape(lagged[:, j], thresholds[t])`, `zz[j, l, t]` the product of lags j and l at threshold t,
/// with `shape` a dead zone (`dead_zone`) or a saturation. `a` and `lagged` are C-contiguous
/// (rows × columns). Runs with the GIL released on `n_threads` (0 = all cores) and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (a, e, lagged, thresholds, dead_zone, n_threads = 0))]
pub(super) fn threshold_products<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    e: PyReadonlyArray1<'py, f64>,
    lagged: PyReadonlyArray2<'py, f64>,
    thresholds: PyReadonlyArray1<'py, f64>,
    dead_zone: bool,
    n_threads: usize,
) -> PyResult<Products<'py>> {
    let (k, b, m) = (a.shape()[1], lagged.shape()[1], thresholds.len());
    let rows = ScanRows { a: a.as_slice()?, k, e: e.as_slice()?, lagged: lagged.as_slice()?, b };
    let shape = if dead_zone { Shape::DeadZone } else { Shape::Saturation };
    let cs = thresholds.as_slice()?;
    let out = run(py, n_threads, |cancel| scan_products(&rows, cs, shape, n_threads != 1, cancel))?;
    let cross = PyArray1::from_vec(py, out.cross).reshape([k + 1, b, m])?;
    let zz = PyArray1::from_vec(py, out.zz).reshape([b, b, m])?;
    Ok((cross, zz))
}
