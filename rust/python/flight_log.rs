//! Python binding of the flight-log readers (`crate::io::blackbox`, `crate::io::dataflash`): the
//! file is read and decoded without the GIL; a reader's error becomes one `DataError` that names
//! the file.

use std::path::{Path, PathBuf};

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;

use super::errors::DataError;
use super::run::run;
use crate::io::{blackbox, dataflash};

/// What `blackbox_read` returns: `(n_logs, headers, fields, time_us, iteration, columns, units,
/// complete)`.
type BlackboxOut<'py> = (
    usize,
    Vec<(String, String)>,
    Vec<String>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Vec<Bound<'py, PyArray1<f64>>>,
    Vec<&'static str>,
    bool,
);

/// What `blackbox_fields` returns: `(n_logs, headers, fields)`.
type BlackboxHeader = (usize, Vec<(String, String)>, Vec<String>);

/// One message of `dataflash_read`: `(time_us, instance or None, columns, units)`.
type MessageOut<'py> =
    (Bound<'py, PyArray1<f64>>, Option<Bound<'py, PyArray1<f64>>>, Vec<Bound<'py, PyArray1<f64>>>, Vec<String>);

/// What `dataflash_read` returns.
type DataflashOut<'py> = (Vec<(String, MessageOut<'py>)>, usize, usize, usize, Vec<(String, Vec<String>, usize)>);

fn name_of(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

fn read_bytes(path: &Path) -> PyResult<Vec<u8>> {
    std::fs::read(path).map_err(|e| DataError::new_err(format!("cannot read the flight log {}: {e}", path.display())))
}

/// Main-frame fields `wanted` of log `log` (1-based) of the blackbox file at `path`.
#[pyfunction]
pub fn blackbox_read<'py>(
    py: Python<'py>,
    path: PathBuf,
    log: usize,
    wanted: Vec<String>,
) -> PyResult<BlackboxOut<'py>> {
    let bytes = read_bytes(&path)?;
    let out = run(py, 1, |_| Ok(blackbox::read(&bytes, log, &wanted)))?;
    let out = out.map_err(|e| DataError::new_err(format!("{} {e}", name_of(&path))))?;
    Ok((
        out.n_logs,
        out.headers,
        out.fields,
        out.time_us.into_pyarray(py),
        out.iteration.into_pyarray(py),
        out.columns.into_iter().map(|c| c.into_pyarray(py)).collect(),
        out.units,
        out.complete,
    ))
}

/// The header of log `log` (1-based) of the blackbox file at `path`: `(n_logs, headers, fields)`.
#[pyfunction]
pub fn blackbox_fields(py: Python<'_>, path: PathBuf, log: usize) -> PyResult<BlackboxHeader> {
    let bytes = read_bytes(&path)?;
    let out = run(py, 1, |_| Ok(blackbox::fields(&bytes, log)))?;
    let out = out.map_err(|e| DataError::new_err(format!("{} {e}", name_of(&path))))?;
    Ok((out.n_logs, out.headers, out.fields))
}

/// Fields `wanted` (`(message, field)` pairs) of the DataFlash log at `path`: the messages by
/// name, the bytes that could not be decoded, the messages decoded, the file's size and the
/// message types the log defines (with their fields and how many it holds).
#[pyfunction]
pub fn dataflash_read<'py>(
    py: Python<'py>,
    path: PathBuf,
    wanted: Vec<(String, String)>,
) -> PyResult<DataflashOut<'py>> {
    let bytes = read_bytes(&path)?;
    let out = run(py, 1, |_| Ok(dataflash::read(&bytes, &wanted)))?;
    let out = out.map_err(|e| DataError::new_err(format!("{} {e}", name_of(&path))))?;
    let messages = out
        .messages
        .into_iter()
        .map(|(name, m)| {
            let columns = m.columns.into_iter().map(|c| c.into_pyarray(py)).collect();
            (name, (m.time_us.into_pyarray(py), m.instance.map(|i| i.into_pyarray(py)), columns, m.units))
        })
        .collect();
    Ok((messages, out.bytes_lost, out.n_messages, bytes.len(), out.formats))
}
