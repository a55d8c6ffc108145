//! ARX models: the structure (orders, delays, output terms) and its data, the regressor's layout
//! in a grid's envelope, its reduction to R by QR, and the least-squares fit of one structure.

pub mod columns;
pub mod fit;
pub mod reduce;
pub mod structure;
