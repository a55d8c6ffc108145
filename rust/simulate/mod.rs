//! Simulation of fitted ARX structures: one-step, k-step and free-run prediction (general step and
//! fast paths), linear filtering (scipy's lfilter), free runs of many structures in SIMD lanes, their scores, and the free run's band.

pub mod band;
pub mod digital_filter;
pub mod kstep;
pub mod lanes;
pub mod linear_predict;
pub mod predict;
pub mod score;
pub mod term_free_run;
