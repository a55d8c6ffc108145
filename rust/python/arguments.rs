//! Python arguments as the core's values and back: data arrays as slices, orders and output terms
//! as structures, grids from integer rows, square factors to and from numpy.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyInt, PyTuple};

use super::errors::{to_pyerr, DataError, OrderError};
use crate::arx::structure::{OutputKind, OutputTerm, Structure};

/// `(y, u, m)` as slices, `m` the number of input columns; y and u must have as many rows.
pub(super) fn slices<'a>(
    y: &'a PyReadonlyArray1<'_, f64>,
    u: &'a PyReadonlyArray2<'_, f64>,
) -> PyResult<(&'a [f64], &'a [f64], usize)> {
    let m = u.shape()[1];
    if u.shape()[0] != y.len() {
        return Err(DataError::new_err(format!("y has {} samples but u has {} rows", y.len(), u.shape()[0])));
    }
    Ok((y.as_slice()?, u.as_slice()?, m))
}

/// Output terms from `(kind, power, multiplier column or −1)`, as the Python layer passes them.
pub(super) fn parse_output_terms(spec: Vec<(String, i32, i64)>) -> PyResult<Vec<OutputTerm>> {
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
pub(super) fn parse_grid(
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
pub(super) fn parse_rows(py: Python<'_>, raw: &[i64], m: usize, terms: &[OutputTerm]) -> PyResult<Vec<Structure>> {
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
pub(super) fn orders_tuple<'py>(py: Python<'py>, s: &Structure) -> PyResult<Bound<'py, PyTuple>> {
    (s.na, PyTuple::new(py, s.nb.iter().copied())?, PyTuple::new(py, s.nk.iter().copied())?).into_pyobject(py)
}

/// A structure from its orders and output terms, as the Python layer passes them.
pub(super) fn structure(
    py: Python<'_>,
    na: usize,
    nb: Vec<usize>,
    nk: Vec<usize>,
    terms: Vec<(String, i32, i64)>,
) -> PyResult<Structure> {
    let terms = parse_output_terms(terms)?;
    Structure::new(na, nb, nk, terms).map_err(|e| to_pyerr(py, e))
}

/// The rows of a grid's layout, checked: `1 + 2·m` non-negative integers each.
pub(super) fn layout_rows<'a>(structures: &'a PyReadonlyArray2<'_, i64>, m: usize) -> PyResult<&'a [i64]> {
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

/// A non-negative Python int as usize, saturating at `usize::MAX` (sizes only compared to a limit).
pub(super) fn saturating_usize(v: &Bound<'_, PyAny>) -> PyResult<usize> {
    match v.extract::<usize>() {
        Ok(n) => Ok(n),
        Err(_) if v.is_instance_of::<PyInt>() && v.gt(0)? => Ok(usize::MAX),
        Err(e) => Err(e),
    }
}

/// Two series of equal length, else a `ValueError` that gives both lengths.
pub(super) fn same_length(y: &[f64], p: &[f64]) -> PyResult<()> {
    if y.len() != p.len() {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "the two series differ in length ({} and {} samples)",
            y.len(),
            p.len()
        )));
    }
    Ok(())
}

/// A column-major square factor as a (q, q) numpy array.
pub(super) fn factor_array(py: Python<'_>, r: Vec<f64>) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let q = (r.len() as f64).sqrt() as usize;
    // Column-major q × q as a (q, q) array: the transpose of the row-major reading.
    let a = PyArray1::from_vec(py, r).reshape([q, q])?;
    Ok(a.transpose()?.cast_into::<PyArray2<f64>>()?)
}

/// A column-major copy of a square (q × q) factor given as a numpy array.
pub(super) fn factor_from(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<f64>> {
    let shape = a.shape();
    if shape[0] != shape[1] {
        return Err(DataError::new_err(format!("a factor must be square, got {} × {}", shape[0], shape[1])));
    }
    let v = a.as_array();
    Ok((0..shape[1]).flat_map(|j| (0..shape[0]).map(move |i| (i, j))).map(|(i, j)| v[[i, j]]).collect())
}
