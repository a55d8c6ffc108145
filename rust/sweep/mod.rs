//! Order sweeps: every structure of a grid fitted from one factorization of the grid's envelope, by
//! least squares or instrumental variables, ranked by one-step loss and scored by simulation.

pub(crate) mod grid_factors;
pub mod iv;
pub mod least_squares;
pub mod one_step;
pub mod sweep_columns;
pub(crate) mod validation_gram;

pub use least_squares::{sweep, StructureResult, SweepOptions};
