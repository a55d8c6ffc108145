//! Python binding of the CSV reader (`crate::io::csv_read`): the file is read and parsed without the GIL
//! on every core, polling for Ctrl-C; problems come back as plain values that `arxid.data.csvio` words.

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;

use super::errors::DataError;
use super::run::run;
use crate::error::ArxError;
use crate::io::csv_read::{read_file, CsvError};

/// A problem in a CSV file, as Python sees it: `(kind, line, offset, got, column, text)` with kind
/// `"not_utf8"` (text: Python's reason), `"nul"`, `"fields"` (got: fields of the record),
/// `"number"` (column: 0-based; text: the cell), `"malformed"` or `"io"` (text: what).
type Problem = (&'static str, usize, usize, usize, usize, String);

/// What `csv_read` returns: the wanted columns and whether a field was quoted, or a problem.
type Outcome<'py> = (Option<Vec<Bound<'py, PyArray1<f64>>>>, bool, Option<Problem>);

/// Columns `wanted` (0-based) of the CSV file at `path`, whose header has `n_fields` fields
/// separated by `delimiter` (one ASCII character); `wanted` empty only checks the file.
#[pyfunction]
pub fn csv_read<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    delimiter: char,
    n_fields: usize,
    wanted: Vec<usize>,
) -> PyResult<Outcome<'py>> {
    let delimiter = u8::try_from(delimiter)
        .ok()
        .filter(u8::is_ascii)
        .ok_or_else(|| DataError::new_err(format!("the delimiter {delimiter:?} is not one ASCII character")))?;
    if let Some(&j) = wanted.iter().find(|&&j| j >= n_fields) {
        return Err(DataError::new_err(format!("column {j} is not among the {n_fields} of the header")));
    }
    let out = run(py, 0, |cancel| match read_file(&path, delimiter, n_fields, &wanted, cancel) {
        Err(Err(CsvError::Interrupted)) => Err(ArxError::Interrupted),
        other => Ok(other),
    })?;
    Ok(match out {
        Ok(table) => (Some(table.columns.into_iter().map(|c| c.into_pyarray(py)).collect()), table.quoted, None),
        Err(problem) => (None, false, Some(describe(problem))),
    })
}

fn describe(problem: Result<String, CsvError>) -> Problem {
    match problem {
        Ok(io) => ("io", 0, 0, 0, 0, io),
        Err(CsvError::NotUtf8 { offset, line, reason }) => ("not_utf8", line, offset, 0, 0, reason.to_string()),
        Err(CsvError::Nul { offset, line }) => ("nul", line, offset, 0, 0, String::new()),
        Err(CsvError::FieldCount { line, got, .. }) => ("fields", line, 0, got, 0, String::new()),
        Err(CsvError::NotANumber { line, column, cell }) => ("number", line, 0, 0, column, cell),
        Err(CsvError::Malformed { line, what }) => ("malformed", line, 0, 0, 0, what),
        Err(CsvError::Interrupted) => ("malformed", 0, 0, 0, 0, "interrupted".into()),
    }
}
