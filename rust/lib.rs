//! arxid core: exact ARX least squares by Householder QR (faer), exhaustive order sweeps from one
//! factorization, and fast free-run simulation. Pure Rust; the Python boundary lives in `python`.
//!
//! One folder per concept, lowest layer first (a module uses only its own folder and the layers
//! below it; `make lint` checks this with `tools/check_crate_layers.py`, see docs/architecture.md):
//! `error`, `linalg`, `arx`, `simulate`, `sweep`, then `pem`, `scoring`, `io` and `subspace` side by side, and
//! `python` on top.

pub mod arx;
pub mod error;
pub mod io;
pub mod linalg;
pub mod pem;
pub mod scoring;
pub mod simulate;
pub mod subspace;
pub mod sweep;

#[cfg(feature = "python")]
mod python;

pub use arx::fit::{fit, Fit};
pub use arx::structure::{Data, OutputKind, OutputTerm, Structure};
pub use error::{ArxError, Result};
pub use sweep::{sweep, StructureResult, SweepOptions};
