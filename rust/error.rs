//! The one error type of the Rust core; converted to Python exceptions in `python/errors.rs` only.

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
    /// A buffer of `bytes` bytes for `what` could not be allocated.
    OutOfMemory { what: String, bytes: usize },
    /// The data do not determine the model (an input too poor for it); says why and what to do.
    NotExciting(String),
    /// The caller asked the computation to stop (Ctrl-C); nothing was computed.
    Interrupted,
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
            ArxError::OutOfMemory { what, bytes } => write!(
                f,
                "out of memory: {what} needs {:.1} MiB that could not be allocated; use fewer samples, \
                 lower orders or a smaller grid",
                *bytes as f64 / 1048576.0
            ),
            ArxError::NotExciting(msg) => write!(f, "{msg}"),
            ArxError::Interrupted => write!(f, "interrupted"),
        }
    }
}

impl std::error::Error for ArxError {}

/// The message a panic carried (its `String` or `&str` payload), or "unknown".
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "unknown".into())
}

pub type Result<T> = std::result::Result<T, ArxError>;

/// `n` copies of `value` in a vector whose allocation may fail: an [`ArxError::OutOfMemory`] naming
/// `what` instead of the abort of `vec![value; n]`.
///
/// # Errors
/// `OutOfMemory` when the allocator refuses (address-space or cgroup limits, or an absurd size).
pub fn try_vec<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| ArxError::OutOfMemory {
        what: what.to_string(),
        bytes: n.saturating_mul(std::mem::size_of::<T>()),
    })?;
    v.resize(n, value);
    Ok(v)
}

/// Checks that `bytes` can be allocated now (allocates and frees them), before a computation whose
/// buffers come from an infallible allocator (faer's matrices) starts.
///
/// # Errors
/// `OutOfMemory` naming `what` when the allocator refuses.
pub fn ensure_memory(bytes: usize, what: &str) -> Result<()> {
    let mut probe: Vec<u8> = Vec::new();
    // black_box: an allocation nobody looks at may be elided by the optimiser, which then assumes
    // it succeeded.
    std::hint::black_box(&mut probe)
        .try_reserve_exact(bytes)
        .map_err(|_| ArxError::OutOfMemory { what: what.to_string(), bytes })?;
    std::hint::black_box(&probe);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impossible_allocations_are_errors_not_aborts() {
        assert!(matches!(try_vec(usize::MAX / 4, 0.0f64, "a test buffer"), Err(ArxError::OutOfMemory { .. })));
        assert!(matches!(ensure_memory(usize::MAX / 2, "a test buffer"), Err(ArxError::OutOfMemory { .. })));
        assert_eq!(try_vec(3, 1.5f64, "x").unwrap(), vec![1.5; 3]);
        assert!(ensure_memory(1 << 20, "x").is_ok());
    }
}
