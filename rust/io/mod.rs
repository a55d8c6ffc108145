//! Measured data read from files into columns of `f64`: CSV files with a header row (`csv_read`),
//! and flight logs: Betaflight/INAV blackbox (`blackbox`, on the `blackbox-log` crate) and
//! ArduPilot DataFlash (`dataflash`, on the `ardupilot-binlog` crate).
//!
//! Plain Rust: the readers take a path or the file's bytes and return columns (and the logs' time
//! stamps), with no resampling (that is one Python function for every log, `arxid.data.resample`).
//! The Python boundary is `python/csv.rs` and `python/flight_log.rs`. A panic inside a log parser
//! (a corrupt file the crate did not expect) is caught here and becomes an error of the reader, so
//! it never reaches Python.

pub mod blackbox;
mod csv_plain;
pub mod csv_read;
pub mod dataflash;

use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::error::panic_message;

/// Runs `f`, turning a panic into `Err(message)`.
pub(crate) fn without_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|panic| panic_message(panic.as_ref()))
}
