//! Python bindings of the candidate scoring's products ([`crate::scoring::threshold_scan`],
//! [`crate::scoring::column_products`], the base fit's residual, the model's regressors).

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray1,
    PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::arguments::{slices, structure};
use super::errors::{to_pyerr, DataError};
use super::run::{run, run_short, SHORT_CALL};
use crate::arx::structure::Data;
use crate::scoring::column_products::{column_products, Block};
use crate::scoring::fit_residual::{refine_residual, residual_products};
use crate::scoring::regressor_rows::regressor_rows as write_rows;
use crate::scoring::threshold_scan::{scan_products, ScanRows, Shape};

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
    let shape = if dead_zone { Shape::DeadZone } else { Shape::Saturation };
    products(py, a, e, lagged, thresholds, shape, n_threads)
}

/// `(cross, zz)` as [`threshold_products`] gives them for a dead zone at `thresholds[0]`
/// (`[..., 0]`) and a saturation at `thresholds[1]` (`[..., 1]`), in one pass over the rows: each
/// the same bits as alone.
#[pyfunction]
#[pyo3(signature = (a, e, lagged, thresholds, n_threads = 0))]
pub(super) fn dead_zone_and_saturation_products<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    e: PyReadonlyArray1<'py, f64>,
    lagged: PyReadonlyArray2<'py, f64>,
    thresholds: PyReadonlyArray1<'py, f64>,
    n_threads: usize,
) -> PyResult<Products<'py>> {
    products(py, a, e, lagged, thresholds, Shape::DeadZoneAndSaturation, n_threads)
}

fn products<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    e: PyReadonlyArray1<'py, f64>,
    lagged: PyReadonlyArray2<'py, f64>,
    thresholds: PyReadonlyArray1<'py, f64>,
    shape: Shape,
    n_threads: usize,
) -> PyResult<Products<'py>> {
    let (k, b, m) = (a.shape()[1], lagged.shape()[1], thresholds.len());
    let rows = ScanRows { a: a.as_slice()?, k, e: e.as_slice()?, lagged: lagged.as_slice()?, b };
    let cs = thresholds.as_slice()?;
    let out = run(py, n_threads, |cancel| scan_products(&rows, cs, shape, n_threads != 1, cancel))?;
    let cross = PyArray1::from_vec(py, out.cross).reshape([k + 1, b, m])?;
    let zz = PyArray1::from_vec(py, out.zz).reshape([b, b, m])?;
    Ok((cross, zz))
}

/// A tested block as Python gives it: `(values, width, lagged)`; see [`Block`].
type PyBlock<'py> = (PyReadonlyArray1<'py, f64>, usize, bool);

/// `(cross, zz)` of one block: `[a | e]'z` (`(k + 1) × width`) and `z'z`.
type BlockProducts<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);

/// `[a | e]'z` and `z'z` of every block, in one pass over the rows. A block is
/// `(values, width, lagged)`: `lagged` False, `values` holds the rows × width matrix row by row;
/// True, column j of row r is `values[r + width − 1 − j]` (a lagged signal, never written out).
/// `a` is C-contiguous. Runs with the GIL released on `n_threads` (0 = all cores), stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (a, e, blocks, n_threads = 0))]
pub(super) fn tested_products<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    e: PyReadonlyArray1<'py, f64>,
    blocks: Vec<PyBlock<'py>>,
    n_threads: usize,
) -> PyResult<Vec<BlockProducts<'py>>> {
    let k = a.shape()[1];
    let mut views = Vec::with_capacity(blocks.len());
    for (values, width, lagged) in &blocks {
        let values = values.as_slice()?;
        if *width == 0 {
            return Err(DataError::new_err("a tested block has no column"));
        }
        views.push(if *lagged {
            Block::Lagged { series: values, width: *width }
        } else {
            Block::Matrix { values, width: *width }
        });
    }
    let (av, ev) = (a.as_slice()?, e.as_slice()?);
    let out = run(py, n_threads, |cancel| column_products(av, k, ev, &views, n_threads != 1, cancel))?;
    out.into_iter()
        .zip(&blocks)
        .map(|(p, (_, w, _))| {
            let cross = PyArray1::from_vec(py, p.cross).reshape([k + 1, *w])?;
            let zz = PyArray1::from_vec(py, p.zz).reshape([*w, *w])?;
            Ok((cross, zz))
        })
        .collect()
}

/// `(e, a'e)`: see [`fit_residual`].
type Residual<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// `(e, a'e)`: the residual `y − aθ` of a linear fit and its products with the regressors `a`
/// (C-contiguous rows × k), in one pass over the rows. Runs with the GIL released on `n_threads`
/// (0 = all cores) and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (a, y, theta, n_threads = 0))]
pub(super) fn fit_residual<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    theta: PyReadonlyArray1<'py, f64>,
    n_threads: usize,
) -> PyResult<Residual<'py>> {
    let k = a.shape()[1];
    let (av, yv, tv) = (a.as_slice()?, y.as_slice()?, theta.as_slice()?);
    let (e, products) = run(py, n_threads, |cancel| residual_products(av, k, yv, tv, n_threads != 1, cancel))?;
    Ok((PyArray1::from_vec(py, e), PyArray1::from_vec(py, products)))
}

/// `e ← e − aδ` in place (a residual of [`fit_residual`] refined by a correction δ of the
/// coefficients) and the new `e'e`, in one pass; as [`fit_residual`].
#[pyfunction]
#[pyo3(signature = (a, e, delta, n_threads = 0))]
pub(super) fn refine_fit_residual<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    mut e: PyReadwriteArray1<'py, f64>,
    delta: PyReadonlyArray1<'py, f64>,
    n_threads: usize,
) -> PyResult<f64> {
    let k = a.shape()[1];
    let (av, dv) = (a.as_slice()?, delta.as_slice()?);
    let ev = e.as_slice_mut()?;
    run(py, n_threads, |cancel| refine_residual(av, k, ev, dv, n_threads != 1, cancel))
}

/// Writes the regressors of the structure `(na, nb, nk, output_terms)` on `(y, u)` at the samples
/// `rows` into the first columns of `out` (C-contiguous, a row per sample of `rows`), the output
/// lags negated when `negate_output`; returns whether each row is finite. The values are numpy's
/// (`models/regressors.py`) to the last bit. Runs with the GIL released, a short call on this thread,
/// a long one on `n_threads` (0 = all cores), and stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (y, u, na, nb, nk, output_terms, rows, out, negate_output = true, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn regressor_rows<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray2<'py, f64>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    output_terms: Vec<(String, i32, i64)>,
    rows: PyReadonlyArray1<'py, i64>,
    mut out: PyReadwriteArray2<'py, f64>,
    negate_output: bool,
    n_threads: usize,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (ys, us, m) = slices(&y, &u)?;
    let s = structure(py, na, nb, nk, output_terms)?;
    s.check(m).map_err(|e| to_pyerr(py, e))?;
    let d = Data::new(ys, us, m, &[0]).map_err(|e| to_pyerr(py, e))?;
    let width = out.shape()[1];
    let (at, values) = (rows.as_slice()?, out.as_slice_mut()?);
    let mut finite = vec![false; at.len()];
    let finite_ref = &mut finite;
    if at.len() * width <= SHORT_CALL {
        run_short(py, |cancel| write_rows(&d, &s, at, negate_output, values, width, finite_ref, false, cancel))?;
    } else {
        let parallel = n_threads != 1;
        run(py, n_threads, |cancel| {
            write_rows(&d, &s, at, negate_output, values, width, finite_ref, parallel, cancel)
        })?;
    }
    Ok(PyArray1::from_vec(py, finite))
}
