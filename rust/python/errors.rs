//! Errors across the boundary, converted in this one place: each `ArxError` to its `arxid.exceptions`
//! class, a panic's payload to an internal error (or `MemoryError` when an allocation failed).

use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError};
use pyo3::prelude::*;

use crate::error::{panic_message, ArxError};

pyo3::import_exception!(arxid.exceptions, ArxidError);

pyo3::import_exception!(arxid.exceptions, DataError);

pyo3::import_exception!(arxid.exceptions, OrderError);

pyo3::import_exception!(arxid.exceptions, IdentifiabilityError);

pyo3::import_exception!(arxid.exceptions, ConvergenceError);

pub(super) fn to_pyerr(py: Python<'_>, e: ArxError) -> PyErr {
    let msg = e.to_string();
    match e {
        ArxError::RankDeficient { column, .. } => {
            let err = IdentifiabilityError::new_err(msg);
            let _ = err.value(py).setattr("column", column);
            err
        }
        ArxError::TooFewSamples { .. } | ArxError::ShapeMismatch { .. } => DataError::new_err(msg),
        ArxError::InvalidStructure(_) => OrderError::new_err(msg),
        ArxError::NotExciting(_) => IdentifiabilityError::new_err(msg),
        ArxError::NotConverged(_) => ConvergenceError::new_err(msg),
        ArxError::OutOfMemory { .. } => PyMemoryError::new_err(msg),
        ArxError::Interrupted => PyKeyboardInterrupt::new_err(msg),
    }
}

/// The message of a panic payload, or the error the core unwound with (see `arx::reduce::reduce`).
pub(super) fn from_panic(py: Python<'_>, panic: Box<dyn std::any::Any + Send>) -> PyErr {
    if let Some(e) = panic.downcast_ref::<ArxError>() {
        return to_pyerr(py, e.clone());
    }
    let what = panic_message(panic.as_ref());
    if what.contains("AllocError") {
        // faer's matrices panic (not abort) when their allocation fails.
        return PyMemoryError::new_err(format!(
            "out of memory in the arxid core ({what}); use fewer samples, lower orders or a smaller grid"
        ));
    }
    ArxidError::new_err(format!("internal error in the arxid core (please report it): {what}"))
}
