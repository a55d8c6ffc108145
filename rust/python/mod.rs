//! The one place Rust meets Python: borrow numpy arrays, call the pure core with the GIL released,
//! convert results and errors back. Panics are caught here and never reach Python.
//!
//! One file per concept of the core (`arx.rs` binds `crate::arx`, `pem.rs` binds `crate::pem` ...),
//! sharing how a call runs (`run`), its errors (`errors`) and argument conversions (`arguments`).
//! No numerics here: what computes lives in the concept's folder. A new binding is registered in
//! `core_module` below and typed in `python/arxid/_base/_core.pyi`.

mod arguments;
mod array_memory;
mod arx;
mod csv;
mod errors;
mod flight_log;
mod iv;
mod lagged;
mod pem;
mod procest;
mod run;
mod scoring;
mod simulate;
mod srivc;
mod subspace;
mod sums;
mod sweep;

use pyo3::prelude::*;

#[pymodule(name = "_core", gil_used = false)]
mod core_module {
    #[pymodule_export]
    use super::array_memory::{keep_array_blocks, kept_array_blocks, release_array_blocks};
    #[pymodule_export]
    use super::arx::{envelope_factor, fit, fit_from_factor, fit_memory, max_lag, FitOutput};
    #[pymodule_export]
    use super::csv::csv_read;
    #[pymodule_export]
    use super::flight_log::{blackbox_fields, blackbox_read, dataflash_read};
    #[pymodule_export]
    use super::iv::iv_sweep;
    #[pymodule_export]
    use super::lagged::{
        ar_filter_rows, lagged_products, lagged_r, lfilter, loss_difference, projected_r, shaped_projected_r,
    };
    #[pymodule_export]
    use super::pem::{pem_fit, pem_gradient, pem_max_lag, pem_predict, PemOutput};
    #[pymodule_export]
    use super::procest::{procest_refine, procest_simulate};
    #[pymodule_export]
    use super::scoring::{
        dead_zone_and_saturation_products, fit_residual, refine_fit_residual, regressor_rows, tested_products,
        threshold_products,
    };
    #[pymodule_export]
    use super::simulate::{divergence_limit, fma_limit, free_run_variance, predict};
    #[pymodule_export]
    use super::srivc::srivc_filter;
    #[pymodule_export]
    use super::subspace::{
        state_space_response, subspace_identify, subspace_input_matrices, subspace_kalman_gain, subspace_refine,
    };
    #[pymodule_export]
    use super::sums::{
        finite_peak, finite_squares, finite_squares_of_difference, fit_pass, fit_squares, group_sums, peak_magnitude,
    };
    #[pymodule_export]
    use super::sweep::{
        grid_envelope, grid_factor, simulate_structures, sweep, sweep_factors, sweep_memory, SweepOutput,
    };

    #[pymodule_init]
    fn init(m: &pyo3::Bound<'_, pyo3::types::PyModule>) -> pyo3::PyResult<()> {
        use pyo3::types::PyModuleMethods;
        m.add("DIVERGENCE_FACTOR", crate::simulate::score::DIVERGENCE_FACTOR)
    }
}
