//! Bindings of the kernels on lagged signals: the triangular factor of a matrix of lagged signals
//! ([`crate::linalg::lagged_qr`]), lagged cross-products and the prewhitening filter of rows.

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray1,
    PyReadwriteArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::errors::{to_pyerr, DataError};
use super::run::{run, run_short, SHORT_CALL};
use crate::linalg::lagged_qr::{lagged_r as factor, LaggedColumn, Source};

/// `(R, n_rows)`: R (q × q upper triangular, R'R = M'M) of the matrix M whose column j is
/// `columns[j] = (source, column, lag)`: that column of `sources[source]` (2-D arrays, any
/// non-negative strides; a signal is passed as one column) read `lag` samples back, on the rows
/// `a + back <= t < b - ahead` of each segment `(a, b)`. Rows with a non-finite value are left out
/// when `skip_missing`. Runs with the GIL released on `n_threads` (0 = all cores), stops on Ctrl-C.
#[pyfunction]
#[pyo3(signature = (sources, columns, segments, back, ahead, skip_missing = true, n_threads = 0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn lagged_r<'py>(
    py: Python<'py>,
    sources: Vec<PyReadonlyArray2<'py, f64>>,
    columns: Vec<(usize, usize, isize)>,
    segments: Vec<(usize, usize)>,
    back: usize,
    ahead: usize,
    skip_missing: bool,
    n_threads: usize,
) -> PyResult<(Bound<'py, PyArray2<f64>>, usize)> {
    let views = sources.iter().map(source).collect::<PyResult<Vec<_>>>()?;
    let cols: Vec<LaggedColumn> =
        columns.iter().map(|&(source, column, lag)| LaggedColumn { source, column, lag }).collect();
    let rows: Vec<usize> =
        segments.iter().flat_map(|&(a, b)| (a + back)..b.saturating_sub(ahead).max(a + back)).collect();
    let out = run(py, n_threads, |cancel| factor(&views, &cols, &rows, skip_missing, n_threads != 1, cancel))?;
    let q = cols.len();
    let r = PyArray1::from_vec(py, out.r).reshape([q, q])?; // column-major q × q read row-major: Rᵀ
    Ok((r.transpose()?.cast_into::<PyArray2<f64>>()?, out.n_rows))
}

/// R and the columns' sums of squares, as numpy arrays.
type Projected<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>);

/// `(R, squares)`: R ((k + 1) × (k + 1) upper triangular) of [Z − Q(QᵀZ) | y] for a basis Q
/// (n × p, orthonormal columns), columns Z (n × k) and a residual y (n), and Σ z² per column of Z
/// (see [`crate::linalg::projected_qr`]). Short calls run on the calling thread, long ones on every
/// core (the same R for any number); the GIL is released.
#[pyfunction]
pub(super) fn projected_r<'py>(
    py: Python<'py>,
    q: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    z: PyReadonlyArray2<'py, f64>,
) -> PyResult<Projected<'py>> {
    let (qs, zs) = (source(&q)?, source(&z)?);
    let y = y.as_array();
    let owned;
    let y = match y.as_slice() {
        Some(y) => y,
        None => {
            owned = y.to_vec();
            &owned
        }
    };
    let work = y.len() * (qs.columns + zs.columns + 1);
    let out = if work <= SHORT_CALL {
        run_short(py, |cancel| crate::linalg::projected_qr::projected_r(&qs, y, &zs, false, cancel))?
    } else {
        run(py, 0, |cancel| crate::linalg::projected_qr::projected_r(&qs, y, &zs, true, cancel))?
    };
    let m = zs.columns + 1;
    let r = PyArray1::from_vec(py, out.r).reshape([m, m])?; // column-major read row-major: Rᵀ
    Ok((r.transpose()?.cast_into::<PyArray2<f64>>()?, PyArray1::from_vec(py, out.squares)))
}

/// R of each value, the lags' sums of squares and whether the lags are finite, as numpy arrays.
type ShapedProjected<'py> = (Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<bool>>);

/// `(R, squares, finite)`: for each row v of `series` (values × samples, C-contiguous), R[v]
/// ((k + 1) × (k + 1)) and Σ z² per column as [`projected_r`] gives them for the lags
/// Z[t, c] = series[v, index[t, c]] (`index`: rows × k, C-contiguous), and whether every Z[t, c] is
/// finite (R[v] is zero where not); see [`crate::scoring::shape_scan`]. Short calls run on the
/// calling thread, long ones on every core (the same R for any number); the GIL is released.
#[pyfunction]
pub(super) fn shaped_projected_r<'py>(
    py: Python<'py>,
    q: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    series: PyReadonlyArray2<'py, f64>,
    index: PyReadonlyArray2<'py, i64>,
) -> PyResult<ShapedProjected<'py>> {
    let qs = source(&q)?;
    let (n_values, len, k) = (series.shape()[0], series.shape()[1], index.shape()[1]);
    let (y, values, index) = (y.as_slice()?, series.as_slice()?, index.as_slice()?);
    let parallel = y.len() * (qs.columns + k + 1) > SHORT_CALL;
    let scan = |cancel: &std::sync::atomic::AtomicBool| {
        crate::scoring::shape_scan::shaped_projected_r(&qs, y, values, len, index, k, parallel, cancel)
    };
    let out = if parallel { run(py, 0, scan)? } else { run_short(py, scan)? };
    let m = k + 1;
    let (mut r, mut squares) = (Vec::with_capacity(n_values * m * m), Vec::with_capacity(n_values * k));
    for f in &out {
        match f {
            Some(f) => {
                r.extend((0..m * m).map(|e| f.r[(e % m) * m + e / m])); // column-major to row-major
                squares.extend(&f.squares);
            }
            None => {
                r.extend(std::iter::repeat_n(0.0, m * m));
                squares.extend(std::iter::repeat_n(0.0, k));
            }
        }
    }
    let finite: Vec<bool> = out.iter().map(Option::is_some).collect();
    Ok((
        PyArray1::from_vec(py, r).reshape([n_values, m, m])?,
        PyArray1::from_vec(py, squares).reshape([n_values, k])?,
        PyArray1::from_vec(py, finite),
    ))
}

/// The strided view of a numpy array as a [`Source`] (its strides in elements, not bytes).
fn source<'a>(a: &'a PyReadonlyArray2<'_, f64>) -> PyResult<Source<'a>> {
    let (rows, columns) = (a.shape()[0], a.shape()[1]);
    let item = std::mem::size_of::<f64>() as isize;
    let strides = a.strides();
    if strides.iter().any(|&s| s < 0 || s % item != 0) {
        return Err(DataError::new_err(
            "a lagged signal has negative or unaligned strides; pass np.ascontiguousarray(signal)",
        ));
    }
    let (row_stride, col_stride) = ((strides[0] / item) as usize, (strides[1] / item) as usize);
    let span = if rows == 0 || columns == 0 { 0 } else { (rows - 1) * row_stride + (columns - 1) * col_stride + 1 };
    // SAFETY: numpy guarantees every entry (t, c) = data + t·row_stride + c·col_stride (strides
    // non-negative, checked above) lies in the array's buffer, so the span from `data` to the last
    // entry is initialised memory; the read-only borrow keeps Rust writers away while it is held.
    let values = unsafe { std::slice::from_raw_parts(a.data() as *const f64, span) };
    Ok(Source { values, rows, columns, row_stride, col_stride })
}

/// Filters the rows of `v` (C-contiguous rows × columns) in place by `v(t) − Σ_j a_j v(t − 1 − j)`:
/// each run `(at, first, end)` writes rows `first..end` filtered to rows `at..` (see
/// [`crate::scoring::ar_filter::filter_rows_in_place`]; numpy's numbers to the last bit).
#[pyfunction]
pub(super) fn ar_filter_rows(
    py: Python<'_>,
    mut v: PyReadwriteArray2<'_, f64>,
    a: PyReadonlyArray1<'_, f64>,
    runs: Vec<(usize, usize, usize)>,
) -> PyResult<()> {
    let width = v.shape()[1];
    let coefficients = a.as_slice()?.to_vec();
    let values = v.as_slice_mut()?;
    run(py, 1, |_| crate::scoring::ar_filter::filter_rows_in_place(values, width, &coefficients, &runs))
}

/// `c(k) = Σ_t a(t) b(t − k)` for k = first..=last over the samples where both exist (see
/// [`crate::linalg::lagged_products`]); with the GIL released on every core, stops on Ctrl-C.
#[pyfunction]
pub(super) fn lagged_products<'py>(
    py: Python<'py>,
    a: PyReadonlyArray1<'py, f64>,
    b: PyReadonlyArray1<'py, f64>,
    first: isize,
    last: isize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (a, b) = (a.as_slice()?, b.as_slice()?);
    let out = run(py, 0, |cancel| crate::linalg::lagged_products::lagged_products(a, b, first, last, cancel))?;
    Ok(PyArray1::from_vec(py, out))
}

/// `(n, mean, sums)` of a Diebold–Mariano test of `base` (one model's squared errors, NaN where
/// its error is not finite) against the errors `y − pred` of another (see
/// [`crate::scoring::loss_difference`]); `pred` is overwritten. With the GIL released on every
/// core, stops on Ctrl-C.
#[pyfunction]
pub(super) fn loss_difference<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    base: PyReadonlyArray1<'py, f64>,
    mut pred: PyReadwriteArray1<'py, f64>,
) -> PyResult<(usize, f64, Bound<'py, PyArray1<f64>>)> {
    let (y, base, pred) = (y.as_slice()?, base.as_slice()?, pred.as_slice_mut()?);
    let out = run(py, 0, |cancel| crate::scoring::loss_difference::loss_difference(y, base, pred, cancel))?;
    Ok((out.n, out.mean, PyArray1::from_vec(py, out.sums)))
}

/// `scipy.signal.lfilter(b, a, x)` of a signal from rest (see [`crate::simulate::digital_filter`]; scipy's
/// numbers to the last bit), with the GIL released.
#[pyfunction]
pub(super) fn lfilter<'py>(
    py: Python<'py>,
    b: PyReadonlyArray1<'py, f64>,
    a: PyReadonlyArray1<'py, f64>,
    x: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (b, a) = (b.as_array().to_vec(), a.as_array().to_vec());
    let x = x.as_array();
    let out = match x.as_slice() {
        Some(x) => py.detach(|| crate::simulate::digital_filter::lfilter(&b, &a, x)),
        None => {
            let x = x.to_vec();
            py.detach(|| crate::simulate::digital_filter::lfilter(&b, &a, &x))
        }
    };
    Ok(PyArray1::from_vec(py, out.map_err(|e| to_pyerr(py, e))?))
}
