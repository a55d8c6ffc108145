//! arxid core: exact ARX least squares by Householder QR (faer), exhaustive order sweeps from one
//! factorization, and fast free-run simulation. Pure Rust; the Python boundary lives in `py`.

pub mod ar_filter;
pub mod band;
pub mod column_products;
pub mod columns;
pub mod csv_read;
pub mod error;
pub mod finite_sums;
pub mod fit;
pub mod fit_residual;
pub mod flight_log;
pub mod group_sums;
pub mod iv;
pub mod kstep;
pub mod lagged_products;
pub mod lagged_qr;
pub mod linear_predict;
pub mod one_step;
pub mod pem;
pub mod procest;
pub mod qr;
pub mod simulate;
pub mod srivc;
pub mod structure;
pub mod subspace;
pub mod sweep;
pub mod sweep_columns;
pub mod term_free_run;
pub mod threshold_scan;

#[cfg(feature = "python")]
mod py;
#[cfg(feature = "python")]
mod py_csv;
#[cfg(feature = "python")]
mod py_flight_log;
#[cfg(feature = "python")]
mod py_subspace;

pub use error::{ArxError, Result};
pub use fit::{fit, Fit};
pub use structure::{Data, OutputKind, OutputTerm, Structure};
pub use sweep::{sweep, StructureResult, SweepOptions};
