//! The one error type of the Rust core; converted to Python exceptions in `py.rs` only.

use std::fmt;

/// What can go wrong in the numerical core. Each variant carries what a user needs to fix it.
#[derive(Debug, Clone, PartialEq)]
pub enum ArxError {
    /// Array lengths that must agree do not.
    ShapeMismatch { what: String, expected: usize, got: usize },
    /// Fewer usable regression rows than parameters.
    TooFewSamples { needed: usize, got: usize },
    /// A column of the regressor is (numerically) a combination of the columns before it.
    RankDeficient { column: usize, ratio: f64 },
    /// An order or lag is invalid (for example an input index out of range).
    InvalidStructure(String),
    /// Prediction-error iterations could not proceed (non-finite loss); says why.
    NotConverged(String),
}

impl fmt::Display for ArxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ArxError::ShapeMismatch { what, expected, got } => {
                write!(f, "{what}: expected length {expected}, got {got}")
            }
            ArxError::TooFewSamples { needed, got } => write!(
                f,
                "too few usable samples: the orders need at least {needed} regression rows, the data give {got} \
                 (rows whose regressors touch a NaN are left out); lower the orders (na, nb, nk) or use more data"
            ),
            ArxError::RankDeficient { column, ratio } => write!(
                f,
                "regressor column {column} is a linear combination of the columns before it (relative residual {ratio:.3e})"
            ),
            ArxError::InvalidStructure(msg) => write!(f, "invalid model structure: {msg}"),
            ArxError::NotConverged(msg) => write!(f, "the prediction-error iterations failed: {msg}"),
        }
    }
}

impl std::error::Error for ArxError {}

pub type Result<T> = std::result::Result<T, ArxError>;
