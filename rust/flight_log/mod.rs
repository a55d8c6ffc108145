//! Flight logs read into columns of `f64`: Betaflight/INAV blackbox (`blackbox`, on the
//! `blackbox-log` crate) and ArduPilot DataFlash (`dataflash`, on the `ardupilot-binlog` crate).
//!
//! Plain Rust: the readers take the file's bytes and return time stamps and columns, with no
//! resampling (that is one Python function for every log, `arxid.data.resample`). The Python
//! boundary is `py_flight_log.rs`. A panic inside a parser (a corrupt file the crate did not
//! expect) is caught here and becomes an error of the reader, so it never reaches Python.

pub mod blackbox;
pub mod dataflash;

use std::panic::{catch_unwind, AssertUnwindSafe};

/// Runs `f`, turning a panic into `Err(message)`.
pub(crate) fn without_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|panic| {
        panic
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown".into())
    })
}
