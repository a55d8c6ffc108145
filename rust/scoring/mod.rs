//! The diagnostic tests' kernels, one pass over the rows each: threshold scans, added-variable
//! products, the base fit's residual, sums per operating-point bin, the prewhitening filter, the
//! sums of a test of two models' errors, the model's regressors written out for the tests.

pub mod ar_filter;
pub mod column_products;
pub mod fit_residual;
pub mod group_sums;
pub mod loss_difference;
pub mod regressor_rows;
pub mod shape_scan;
pub mod threshold_scan;
