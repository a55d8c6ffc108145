//! Bindings of the one-pass sums (`crate::linalg::finite_sums`, `crate::scoring::group_sums`): each
//! reads its series once, with the GIL released.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;

use super::arguments::same_length;
use super::errors::to_pyerr;

/// `(Σ x², n)` over the `n` finite samples of a contiguous `x`, in one pass (GIL released).
#[pyfunction]
pub(super) fn finite_squares(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<(f64, usize)> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::linalg::finite_sums::finite_squares(x)))
}

/// `(Σ (y − p)², n)` over the `n` samples where the difference of two contiguous series of equal
/// length is finite, in one pass without forming it (GIL released).
#[pyfunction]
pub(super) fn finite_squares_of_difference(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
) -> PyResult<(f64, usize)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    Ok(py.detach(|| crate::linalg::finite_sums::finite_squares_of_difference(y, p)))
}

/// `(n, peak_y, peak_p, p_infinite, peak_both, sum_both)` of a prediction `p` of `y` (contiguous,
/// equal length) in one pass (see [`crate::linalg::finite_sums::FitPass`]; GIL released).
#[pyfunction]
pub(super) fn fit_pass(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
) -> PyResult<(usize, f64, f64, bool, f64, f64)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    let f = py.detach(|| crate::linalg::finite_sums::fit_pass(y, p));
    Ok((f.n, f.peak_y, f.peak_p, f.p_infinite, f.peak_both, f.sum_both))
}

/// `(Σ ((y − p)·scale)², Σ ((y − mean)·scale)²)` where both are finite, in one pass (GIL released).
#[pyfunction]
pub(super) fn fit_squares(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
    mean: f64,
    scale: f64,
) -> PyResult<(f64, f64)> {
    let (y, p) = (y.as_slice()?, p.as_slice()?);
    same_length(y, p)?;
    Ok(py.detach(|| crate::linalg::finite_sums::fit_squares(y, p, mean, scale)))
}

/// Largest |x| over the samples of a contiguous `x` that are not NaN (inf when one is infinite,
/// NaN when none is a number), in one pass (GIL released).
#[pyfunction]
pub(super) fn peak_magnitude(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::linalg::finite_sums::peak_magnitude(x)))
}

/// Largest |x| over the finite samples of a contiguous `x` (0 when there are none), in one pass
/// (GIL released).
#[pyfunction]
pub(super) fn finite_peak(py: Python<'_>, x: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    let x = x.as_slice()?;
    Ok(py.detach(|| crate::linalg::finite_sums::finite_peak(x)))
}

/// `(counts, sums, varies)` per group of `group` (uint8, below `groups`): the samples, the sum of
/// each series (`sums[s, g]`, in sample order as `numpy.bincount`) and whether a group holds two
/// different values of the first series; one pass (GIL released).
#[pyfunction]
pub(super) fn group_sums<'py>(
    py: Python<'py>,
    group: PyReadonlyArray1<'py, u8>,
    groups: usize,
    series: Vec<PyReadonlyArray1<'py, f64>>,
) -> PyResult<GroupSumsOutput<'py>> {
    let group = group.as_slice()?;
    let views = series.iter().map(|s| s.as_slice()).collect::<Result<Vec<_>, _>>()?;
    let out =
        py.detach(|| crate::scoring::group_sums::group_sums(group, groups, &views)).map_err(|e| to_pyerr(py, e))?;
    let sums = PyArray1::from_vec(py, out.sums).reshape([series.len(), groups])?;
    Ok((PyArray1::from_vec(py, out.counts), sums, PyArray1::from_vec(py, out.varies)))
}

/// `(counts, sums, varies)`: see [`group_sums`].
pub(super) type GroupSumsOutput<'py> =
    (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<bool>>);
