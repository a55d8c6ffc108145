//! Linear algebra on long series, knowing nothing of models: Householder QR (TSQR), the factor and Gram
//! of lagged signals, lagged cross-products, one-pass finite sums, small dense matrices, the
//! Levenberg–Marquardt step, SIMD helpers.

pub mod dense;
pub mod finite_sums;
pub mod lagged_gram;
pub mod lagged_products;
pub mod lagged_qr;
pub mod levenberg;
pub mod projected_qr;
pub mod qr;
pub mod simd;
pub mod tall_qr;
