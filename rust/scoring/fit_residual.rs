//! The residual of a linear least-squares fit and its products with the regressors, for the
//! added-variable tests' base fit (`diagnosis/added_variable.py`): `e = y − Aθ` with `A'e`, then
//! the refined residual `e − Aδ` with `e'e`. Each is one pass over the rows of `A` (row-major), where
//! numpy takes a product, a subtraction and another product, each a pass with its own temporary.
//!
//! Rows are taken a chunk at a time and the chunks' sums added in order, so the result does not
//! depend on the threads; it agrees with numpy's to rounding, not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::error::{ArxError, Result};
use crate::linalg::simd::{avx2_fma, madd};

/// Rows per chunk.
const CHUNK: usize = 8192;

fn check(a: &[f64], k: usize, n: usize, coefficients: &[f64]) -> Result<()> {
    if a.len() != n * k {
        return Err(ArxError::ShapeMismatch {
            what: "regressor values of the fitted rows".into(),
            expected: n * k,
            got: a.len(),
        });
    }
    if coefficients.len() != k {
        return Err(ArxError::ShapeMismatch {
            what: "coefficients of the fit".into(),
            expected: k,
            got: coefficients.len(),
        });
    }
    Ok(())
}

/// Runs `chunk(lo, hi, e_chunk)` over the chunks of `e` (in parallel when asked) and adds their
/// sums in chunk order.
fn by_chunks(
    e: &mut [f64],
    width: usize,
    parallel: bool,
    cancel: &AtomicBool,
    chunk: impl Fn(usize, &mut [f64]) -> Vec<f64> + Sync,
) -> Result<Vec<f64>> {
    let work = |(i, part): (usize, &mut [f64])| -> Result<Vec<f64>> {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(chunk(i * CHUNK, part))
    };
    let partials: Vec<Vec<f64>> = if parallel {
        e.par_chunks_mut(CHUNK).enumerate().map(work).collect::<Result<_>>()?
    } else {
        e.chunks_mut(CHUNK).enumerate().map(work).collect::<Result<_>>()?
    };
    let mut total = vec![0.0; width];
    for p in &partials {
        total.iter_mut().zip(p).for_each(|(s, v)| *s += v);
    }
    Ok(total)
}

/// `e = y − Aθ` and `A'e`; `a` is row-major `n × k`, `n = y.len()`.
///
/// # Errors
/// `ShapeMismatch` when the lengths disagree; `Interrupted` once `cancel` is set.
pub fn residual_products(
    a: &[f64],
    k: usize,
    y: &[f64],
    theta: &[f64],
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<(Vec<f64>, Vec<f64>)> {
    check(a, k, y.len(), theta)?;
    let mut e = y.to_vec();
    let products = by_chunks(&mut e, k, parallel, cancel, |lo, part| chunk_residual(a, k, theta, lo, part))?;
    Ok((e, products))
}

/// `e ← e − Aδ` in place, and the new `e'e`.
///
/// # Errors
/// As [`residual_products`].
pub fn refine_residual(
    a: &[f64],
    k: usize,
    e: &mut [f64],
    delta: &[f64],
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<f64> {
    check(a, k, e.len(), delta)?;
    let sum = by_chunks(e, 1, parallel, cancel, |lo, part| vec![chunk_refine(a, k, delta, lo, part)])?;
    Ok(sum[0])
}

/// One chunk of [`residual_products`]: `part` holds y on entry and e on return; its part of `A'e`.
fn chunk_residual(a: &[f64], k: usize, theta: &[f64], lo: usize, part: &mut [f64]) -> Vec<f64> {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { chunk_residual_avx2(a, k, theta, lo, part) };
    }
    chunk_residual_with::<false>(a, k, theta, lo, part)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_residual_avx2(a: &[f64], k: usize, theta: &[f64], lo: usize, part: &mut [f64]) -> Vec<f64> {
    chunk_residual_with::<true>(a, k, theta, lo, part)
}

#[inline(always)]
fn chunk_residual_with<const FMA: bool>(a: &[f64], k: usize, theta: &[f64], lo: usize, part: &mut [f64]) -> Vec<f64> {
    let mut products = vec![0.0; k];
    for (r, v) in part.iter_mut().enumerate() {
        let row = &a[(lo + r) * k..(lo + r + 1) * k];
        *v -= dot::<FMA>(row, theta);
        for (p, &x) in products.iter_mut().zip(row) {
            *p = madd::<FMA>(x, *v, *p);
        }
    }
    products
}

/// One chunk of [`refine_residual`]: `part` holds e, refined in place; its part of `e'e`.
fn chunk_refine(a: &[f64], k: usize, delta: &[f64], lo: usize, part: &mut [f64]) -> f64 {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { chunk_refine_avx2(a, k, delta, lo, part) };
    }
    chunk_refine_with::<false>(a, k, delta, lo, part)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_refine_avx2(a: &[f64], k: usize, delta: &[f64], lo: usize, part: &mut [f64]) -> f64 {
    chunk_refine_with::<true>(a, k, delta, lo, part)
}

#[inline(always)]
fn chunk_refine_with<const FMA: bool>(a: &[f64], k: usize, delta: &[f64], lo: usize, part: &mut [f64]) -> f64 {
    let mut sum = 0.0;
    for (r, v) in part.iter_mut().enumerate() {
        *v -= dot::<FMA>(&a[(lo + r) * k..(lo + r + 1) * k], delta);
        sum = madd::<FMA>(*v, *v, sum);
    }
    sum
}

#[inline(always)]
fn dot<const FMA: bool>(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).fold(0.0, |s, (&p, &q)| madd::<FMA>(p, q, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(n: usize, k: usize) -> (Vec<f64>, Vec<f64>) {
        let mut state = 99u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        ((0..n * k).map(|_| next()).collect(), (0..n).map(|_| next()).collect())
    }

    #[test]
    fn residual_and_products_equal_the_direct_sums() {
        let (n, k) = (3 * CHUNK + 5, 4);
        let (a, y) = data(n, k);
        let theta = [0.5, -1.0, 0.25, 2.0];
        let cancel = AtomicBool::new(false);
        let (e, p) = residual_products(&a, k, &y, &theta, true, &cancel).unwrap();
        for r in 0..n {
            let want = y[r] - (0..k).map(|j| a[r * k + j] * theta[j]).sum::<f64>();
            assert!((e[r] - want).abs() <= 1e-14);
        }
        for j in 0..k {
            let want: f64 = (0..n).map(|r| a[r * k + j] * e[r]).sum();
            assert!((p[j] - want).abs() <= 1e-10 * (1.0 + want.abs()), "{} against {want}", p[j]);
        }
        let serial = residual_products(&a, k, &y, &theta, false, &cancel).unwrap();
        assert_eq!((e.clone(), p), serial, "the sums do not depend on the threads");

        let delta = [0.1, 0.0, -0.2, 0.3];
        let (mut once, mut twice) = (e.clone(), e);
        let rss = refine_residual(&a, k, &mut once, &delta, true, &cancel).unwrap();
        assert_eq!(rss, refine_residual(&a, k, &mut twice, &delta, false, &cancel).unwrap());
        let want: f64 = once.iter().map(|v| v * v).sum();
        assert!((rss - want).abs() <= 1e-10 * want);
    }

    #[test]
    fn mismatched_lengths_and_cancel_are_errors() {
        let (a, y) = data(100, 3);
        let cancel = AtomicBool::new(false);
        assert!(matches!(
            residual_products(&a[..290], 3, &y, &[1.0; 3], false, &cancel),
            Err(ArxError::ShapeMismatch { .. })
        ));
        assert!(matches!(residual_products(&a, 3, &y, &[1.0; 2], false, &cancel), Err(ArxError::ShapeMismatch { .. })));
        let mut e = y.clone();
        assert!(matches!(
            refine_residual(&a, 3, &mut e[..50], &[1.0; 3], false, &cancel),
            Err(ArxError::ShapeMismatch { .. })
        ));
        cancel.store(true, Ordering::Relaxed);
        assert!(matches!(residual_products(&a, 3, &y, &[1.0; 3], false, &cancel), Err(ArxError::Interrupted)));
    }
}
