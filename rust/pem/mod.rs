//! Iterative estimation beyond ARX: prediction-error fits of polynomial models (OE, ARMAX, BJ),
//! process models refined by a bounded search, and the state-variable filter of SRIVC.

mod gradient;
pub mod polynomial;
mod predict;
pub mod procest;
mod regression;
mod search;
pub mod srivc;
mod start;

// The face of the prediction-error method; `polynomial` says what it estimates and how.
pub use gradient::gradient;
pub use polynomial::{Initial, PolyStructure, Polys, Segments};
pub use predict::{predict, predict_cancellable};
pub use search::{pem, PemFit, PemOptions, Termination};
pub use start::start;

/// Uniform numbers in [-0.5, 0.5) from a fixed seed, for the tests.
#[cfg(test)]
fn lcg(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
}
