//! The weighted projection of the future outputs on the past, its SVD, and the order criterion.
//!
//! With L's blocks named after the Hankel rows (1 = U_f, 2 = W_p, 3 = Y_f), the unifying theorem
//! of Van Overschee & De Moor (1996, §4.3) gives the three methods as weightings W1·O·W2 of the
//! oblique projection O = Y_f /_{U_f} W_p = L32 L22⁺ [L21 L22] Q:
//! - N4SID: W1 = I, W2 = I — the SVD of L32 L22⁺ [L21 L22];
//! - MOESP (PO-MOESP, Verhaegen 1994): W2 = Π_{U_f⊥}, which leaves L32 (the orthogonal factor Q
//!   changes no singular value or left vector);
//! - CVA: also W1 = (Y_f Π_{U_f⊥} Y_fᵀ)^{-1/2} = Ly⁻¹ with Ly Lyᵀ = L32 L32ᵀ + L33 L33ᵀ; its
//!   singular values are the canonical correlations of future outputs and past data given the
//!   future inputs (between 0 and 1).
//!
//! The extended observability matrix is Γ = W1⁻¹ U₁ S₁^{1/2}.

use faer::{Mat, MatRef, Side};

use super::hankel::HankelFactor;
use super::pseudo_inverse;
use crate::error::{ArxError, Result};

/// The weighting of the projection: N4SID, MOESP or CVA.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weighting {
    N4sid,
    Moesp,
    Cva,
}

impl Weighting {
    /// The weighting named `name` (`"n4sid"`, `"moesp"` or `"cva"`).
    ///
    /// # Errors
    /// `InvalidStructure` for another name.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "n4sid" => Ok(Self::N4sid),
            "moesp" => Ok(Self::Moesp),
            "cva" => Ok(Self::Cva),
            other => Err(ArxError::InvalidStructure(format!(
                "unknown subspace method {other:?}; use \"n4sid\", \"moesp\" or \"cva\""
            ))),
        }
    }
}

/// The SVD of the weighted projection: left vectors, singular values, and W1⁻¹ (to undo the
/// weighting when Γ is formed).
pub struct Decomposition {
    pub left: Mat<f64>,
    pub singular_values: Vec<f64>,
    pub unweight: Mat<f64>,
}

fn blocks(h: &HankelFactor) -> (usize, usize, usize) {
    let (uf, wp, yf) = h.blocks;
    (uf, uf + wp, uf + wp + yf)
}

fn svd_of(m: MatRef<'_, f64>) -> Result<(Mat<f64>, Vec<f64>)> {
    let svd =
        m.thin_svd().map_err(|_| ArxError::NotConverged("the SVD of the projected data did not converge".into()))?;
    let s = svd.S().column_vector();
    Ok((svd.U().to_owned(), (0..s.nrows()).map(|i| s[i]).collect()))
}

/// Lower Cholesky factor of `L32 L32ᵀ + L33 L33ᵀ` (the covariance of the future outputs once the
/// future inputs are projected out), regularised by a relative 1e-12 so noise-free data (where it
/// is singular) still give one.
fn output_factor(h: &HankelFactor) -> Result<Mat<f64>> {
    let (i1, i2, i3) = blocks(h);
    let rows = h.l.as_ref().submatrix(i2, i1, i3 - i2, i3 - i1);
    let mut cov = rows * rows.transpose();
    let trace: f64 = (0..cov.nrows()).map(|i| cov[(i, i)]).sum();
    let ridge = 1e-12 * trace.max(f64::MIN_POSITIVE) / cov.nrows() as f64;
    for i in 0..cov.nrows() {
        cov[(i, i)] += ridge;
    }
    let llt = cov.llt(Side::Lower).map_err(|_| {
        ArxError::NotConverged("the future outputs' covariance is not positive definite (non-finite data?)".into())
    })?;
    Ok(llt.L().to_owned())
}

/// Solves `Ly X = B` for lower-triangular `Ly` (forward substitution, column by column).
fn solve_lower(ly: &Mat<f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let n = ly.nrows();
    let mut x = b.to_owned();
    for c in 0..x.ncols() {
        for i in 0..n {
            let mut acc = x[(i, c)];
            for k in 0..i {
                acc -= ly[(i, k)] * x[(k, c)];
            }
            x[(i, c)] = acc / ly[(i, i)];
        }
    }
    x
}

/// `Z = L32 L22⁺`: L22 is singular when the past data are not persistently exciting.
fn oblique_gain(h: &HankelFactor) -> Mat<f64> {
    let (i1, i2, i3) = blocks(h);
    let l22 = h.l.as_ref().submatrix(i1, i1, i2 - i1, i2 - i1);
    let l32 = h.l.as_ref().submatrix(i2, i1, i3 - i2, i2 - i1);
    l32 * pseudo_inverse(l22)
}

/// The SVD of the projection weighted as `weighting` says.
///
/// # Errors
/// `NotConverged` when an SVD or Cholesky factorisation fails (non-finite data).
pub fn decompose(h: &HankelFactor, weighting: Weighting) -> Result<Decomposition> {
    let (i1, i2, i3) = blocks(h);
    let ny_f = i3 - i2;
    let l32 = h.l.as_ref().submatrix(i2, i1, ny_f, i2 - i1);
    match weighting {
        Weighting::Moesp => {
            let (left, singular_values) = svd_of(l32)?;
            Ok(Decomposition { left, singular_values, unweight: Mat::identity(ny_f, ny_f) })
        }
        Weighting::N4sid => {
            let z = oblique_gain(h);
            let past_rows = h.l.as_ref().submatrix(i1, 0, i2 - i1, i2);
            let (left, singular_values) = svd_of((z * past_rows).as_ref())?;
            Ok(Decomposition { left, singular_values, unweight: Mat::identity(ny_f, ny_f) })
        }
        Weighting::Cva => {
            let ly = output_factor(h)?;
            let (left, singular_values) = svd_of(solve_lower(&ly, l32).as_ref())?;
            Ok(Decomposition { left, singular_values, unweight: ly })
        }
    }
}

/// The canonical correlations of future outputs and past data given the future inputs (the CVA
/// singular values, whatever the method): scale-free, so one order criterion serves all methods.
///
/// # Errors
/// As [`decompose`].
pub fn canonical_correlations(h: &HankelFactor) -> Result<Vec<f64>> {
    let (i1, i2, i3) = blocks(h);
    let l32 = h.l.as_ref().submatrix(i2, i1, i3 - i2, i2 - i1);
    let ly = output_factor(h)?;
    Ok(svd_of(solve_lower(&ly, l32).as_ref())?.1.into_iter().map(|s| s.min(1.0)).collect())
}

/// Bauer's singular value criterion (SVC, Automatica 37, 2001) for orders 0..=`max_order`:
/// `SVC(n) = ρ²_{n+1} + d(n)·ln(N)/N` with ρ the canonical correlations, N the number of Hankel
/// columns and `d(n) = n·(2·ny + nu)` the free parameters of an order-n innovation-form model.
/// The chosen order minimises it.
pub fn singular_value_criterion(
    rho: &[f64],
    n_rows: usize,
    n_inputs: usize,
    n_outputs: usize,
    max_order: usize,
) -> Vec<f64> {
    let penalty = (n_rows as f64).ln() / n_rows as f64 * (2 * n_outputs + n_inputs) as f64;
    (0..=max_order).map(|n| rho.get(n).map_or(0.0, |r| r * r) + penalty * n as f64).collect()
}

/// The order that minimises `criterion` (the smallest in a tie).
pub fn best_order(criterion: &[f64]) -> usize {
    criterion.iter().enumerate().fold((0, f64::INFINITY), |(bn, bv), (n, &v)| if v < bv { (n, v) } else { (bn, bv) }).0
}

/// Γ = W1⁻¹ U₁ S₁^{1/2} for order `n` (f·ny × n).
pub fn observability(d: &Decomposition, n: usize) -> Mat<f64> {
    let u1 = d.left.as_ref().subcols(0, n);
    let scaled = Mat::from_fn(u1.nrows(), n, |i, j| u1[(i, j)] * d.singular_values[j].sqrt());
    &d.unweight * scaled
}
