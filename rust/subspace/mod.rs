//! Subspace identification of MIMO state-space models: N4SID, MOESP and CVA on one LQ
//! factorisation of the block-Hankel data (Van Overschee & De Moor 1996; Verhaegen & Verdult 2007).
//!
//! The steps, each in its own file: the Hankel factor L built block by block ([`hankel`]); the
//! weighted projection, its SVD and the order criterion ([`projection`]); A and C from the
//! observability matrix ([`realization`]); B, D and the initial states by least squares on the data
//! ([`input_matrices`]); the Kalman gain from the output error ([`kalman_gain`]); and the model's
//! response ([`response`]). The prediction-error refinement
//! ([`refine`]) starts from the result, on the innovation form's predictor ([`innovation`]).

pub mod hankel;
pub mod innovation;
pub mod input_matrices;
pub mod kalman_gain;
pub mod projection;
pub mod realization;
pub mod refine;
pub mod response;

use std::sync::atomic::AtomicBool;

use faer::{Mat, MatRef};

pub use hankel::{Horizons, Signals};
pub use projection::Weighting;

use crate::error::{ArxError, Result};

/// How [`identify`] works: horizons, weighting, and the order (`None`: chosen by the criterion
/// among 1..=`max_order`).
#[derive(Clone, Copy, Debug)]
pub struct SubspaceOptions {
    pub horizons: Horizons,
    pub weighting: Weighting,
    pub order: Option<usize>,
    pub max_order: usize,
}

/// A and C of the identified model, and what the order choice saw.
#[derive(Debug)]
pub struct Subspace {
    pub a: Mat<f64>,
    pub c: Mat<f64>,
    /// Singular values of the weighted projection (the method's own), largest first.
    pub singular_values: Vec<f64>,
    /// Canonical correlations of future outputs and past data (the CVA singular values).
    pub canonical_correlations: Vec<f64>,
    /// The singular value criterion for orders 0..=max_order.
    pub criterion: Vec<f64>,
    pub order: usize,
    /// Hankel columns used.
    pub n_rows: usize,
}

/// A and C of a state-space model of `signals`, with the order fixed or chosen.
///
/// # Errors
/// `InvalidStructure` for an order the horizons cannot hold or bad segments, `TooFewSamples` when
/// the data are shorter than the horizons need, `NotConverged` when an SVD fails, `Interrupted` on
/// Ctrl-C, and the shape errors of [`Signals::check`].
pub fn identify(
    signals: &Signals<'_>,
    options: SubspaceOptions,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Subspace> {
    signals.check()?;
    let Horizons { past, future } = options.horizons;
    let ny = signals.n_outputs;
    if past == 0 || future < 2 {
        return Err(ArxError::InvalidStructure(format!(
            "the horizons must be at least 1 (past) and 2 (future) samples, got {past} and {future}"
        )));
    }
    let ceiling = (future - 1) * ny;
    let max_order = options.max_order.min(ceiling);
    if let Some(n) = options.order {
        if n == 0 || n > ceiling {
            return Err(ArxError::InvalidStructure(format!(
                "order {n} is outside 1..={ceiling}, what a future horizon of {future} samples and {ny} output(s) can hold; \
                 raise the horizon"
            )));
        }
    }
    let factor = hankel::hankel_factor(signals, options.horizons, parallel, cancel)?;
    let decomposition = projection::decompose(&factor, options.weighting)?;
    let canonical_correlations = projection::canonical_correlations(&factor)?;
    let criterion =
        projection::singular_value_criterion(&canonical_correlations, factor.n_rows, signals.n_inputs, ny, max_order);
    let order = options.order.unwrap_or_else(|| projection::best_order(&criterion).max(1));
    let largest = decomposition.singular_values.first().copied().unwrap_or(0.0);
    if largest.is_nan() || largest <= 1e-10 * output_size(&factor) {
        return Err(ArxError::NotExciting(format!(
            "the future inputs explain all of the outputs, so the past data say nothing about the state: the \
             inputs are not rich enough for a horizon of {future} samples (a few sines, or a constant?); use a \
             random binary or multisine input with more frequencies, or a shorter horizon"
        )));
    }
    let gamma = projection::observability(&decomposition, order);
    let (a, c) = realization::state_matrices(&gamma, ny)?;
    if !a.col_iter().flat_map(|col| col.iter().copied().collect::<Vec<_>>()).all(f64::is_finite) {
        return Err(ArxError::NotExciting(format!(
            "the data determine fewer than {order} states; choose a lower order or a richer input"
        )));
    }
    Ok(Subspace {
        a,
        c,
        singular_values: decomposition.singular_values,
        canonical_correlations,
        criterion,
        order,
        n_rows: factor.n_rows,
    })
}

/// The size of the future outputs in L (Frobenius norm of its Y_f rows): the scale against which a
/// singular value counts as zero.
fn output_size(factor: &hankel::HankelFactor) -> f64 {
    let (uf, wp, yf) = factor.blocks;
    let rows = factor.l.as_ref().subrows(uf + wp, yf);
    rows.norm_l2()
}

/// The Moore–Penrose pseudo-inverse of `m` by its SVD, singular values below `1e-12·σ_max` taken
/// as zero (a rank-deficient block gives the minimum-norm solution, not infinities).
pub fn pseudo_inverse(m: MatRef<'_, f64>) -> Mat<f64> {
    let Ok(svd) = m.thin_svd() else {
        return Mat::from_fn(m.ncols(), m.nrows(), |_, _| f64::NAN);
    };
    let s = svd.S().column_vector();
    let largest = (0..s.nrows()).map(|i| s[i]).fold(0.0, f64::max);
    let inverse =
        Mat::from_fn(s.nrows(), s.nrows(), |i, j| if i == j && s[i] > 1e-12 * largest { 1.0 / s[i] } else { 0.0 });
    svd.V() * inverse * svd.U().transpose()
}

#[cfg(test)]
mod tests;
