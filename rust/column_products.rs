//! The products a batch of added-variable tests needs: for each block of candidate columns `z`,
//! `[A | e]'z` and `z'z`, with `A` the model's regressors (row-major) and `e` its residual.
//!
//! A block is either a matrix (row-major, as numpy builds it) or the lags of one series: column j
//! of row r is `series[r + width − 1 − j]`, the usual shape of a lagged candidate, which is never
//! written out. The rows are taken a chunk at a time: the chunk of `A` is transposed once into
//! columns, and every product is then a dot product of two contiguous runs, summed eight lanes at
//! a time. Chunks are summed in order, so the result does not depend on the threads; it agrees
//! with numpy's products to rounding, not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::error::{ArxError, Result};
use crate::linear_predict::{avx2_fma, madd};

/// Rows per chunk (its columns of `A` and of a matrix block stay in cache).
const CHUNK: usize = 2048;

/// Lanes of a dot product's partial sums.
const LANES: usize = 8;

/// One block of candidate columns over the rows.
pub enum Block<'a> {
    /// Row-major `rows × width`.
    Matrix { values: &'a [f64], width: usize },
    /// Column j of row r is `series[r + width − 1 − j]` (`series` has `rows + width − 1` values).
    Lagged { series: &'a [f64], width: usize },
}

impl Block<'_> {
    fn width(&self) -> usize {
        match self {
            Block::Matrix { width, .. } | Block::Lagged { width, .. } => *width,
        }
    }

    fn fits(&self, n: usize) -> bool {
        match self {
            Block::Matrix { values, width } => values.len() == n * width,
            Block::Lagged { series, width } => *width > 0 && series.len() + 1 == n + width,
        }
    }
}

/// A block's products: `cross[i·width + j]` is column i of `[A | e]` times column j, `zz[j·width + l]`
/// column j times column l.
#[derive(Clone, Debug, PartialEq)]
pub struct Products {
    pub cross: Vec<f64>,
    pub zz: Vec<f64>,
}

/// `[A | e]'z` and `z'z` of every block; `a` is row-major `rows × k`.
///
/// # Errors
/// `ShapeMismatch` when an array's length does not fit the rows; `Interrupted` once `cancel` is set.
pub fn column_products(
    a: &[f64],
    k: usize,
    e: &[f64],
    blocks: &[Block<'_>],
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Vec<Products>> {
    let n = e.len();
    if a.len() != n * k {
        return Err(ArxError::ShapeMismatch {
            what: "regressor values of the tested rows".into(),
            expected: n * k,
            got: a.len(),
        });
    }
    if let Some(b) = blocks.iter().find(|b| !b.fits(n)) {
        let (what, got) = match b {
            Block::Matrix { values, .. } => ("values of a tested block", values.len()),
            Block::Lagged { series, .. } => ("samples of a lagged tested block", series.len()),
        };
        let expected = if matches!(b, Block::Matrix { .. }) { n * b.width() } else { n + b.width().max(1) - 1 };
        return Err(ArxError::ShapeMismatch { what: what.into(), expected, got });
    }
    let chunk = |lo: usize| -> Result<Vec<Products>> {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(chunk_products(a, k, e, blocks, lo, (lo + CHUNK).min(n)))
    };
    let starts: Vec<usize> = (0..n).step_by(CHUNK).collect();
    let partials: Vec<Vec<Products>> = if parallel {
        starts.par_iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    } else {
        starts.iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    };
    let mut total: Vec<Products> = blocks
        .iter()
        .map(|b| Products { cross: vec![0.0; (k + 1) * b.width()], zz: vec![0.0; b.width() * b.width()] })
        .collect();
    for part in &partials {
        for (t, p) in total.iter_mut().zip(part) {
            t.cross.iter_mut().zip(&p.cross).for_each(|(s, v)| *s += v);
            t.zz.iter_mut().zip(&p.zz).for_each(|(s, v)| *s += v);
        }
    }
    Ok(total)
}

fn chunk_products(a: &[f64], k: usize, e: &[f64], blocks: &[Block<'_>], lo: usize, hi: usize) -> Vec<Products> {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { chunk_products_avx2(a, k, e, blocks, lo, hi) };
    }
    chunk_products_with::<false>(a, k, e, blocks, lo, hi)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_products_avx2(
    a: &[f64],
    k: usize,
    e: &[f64],
    blocks: &[Block<'_>],
    lo: usize,
    hi: usize,
) -> Vec<Products> {
    chunk_products_with::<true>(a, k, e, blocks, lo, hi)
}

#[inline(always)]
fn chunk_products_with<const FMA: bool>(
    a: &[f64],
    k: usize,
    e: &[f64],
    blocks: &[Block<'_>],
    lo: usize,
    hi: usize,
) -> Vec<Products> {
    let len = hi - lo;
    // The chunk of [A | e] as columns.
    let mut left = vec![0.0; (k + 1) * len];
    for (r, row) in a[lo * k..hi * k].chunks_exact(k.max(1)).enumerate() {
        for (i, &v) in row.iter().enumerate() {
            left[i * len + r] = v;
        }
    }
    left[k * len..].copy_from_slice(&e[lo..hi]);
    // A loop, not a closure: a closure would not inherit the caller's target features, and its
    // multiply-adds would become calls to libm's fma.
    let mut scratch = Vec::new();
    let mut out = Vec::with_capacity(blocks.len());
    for b in blocks {
        let w = b.width();
        let cols: Vec<&[f64]> = match b {
            Block::Lagged { series, width } => {
                (0..*width).map(|j| &series[lo + width - 1 - j..hi + width - 1 - j]).collect()
            }
            Block::Matrix { values, width } => {
                scratch.clear();
                scratch.resize(width * len, 0.0);
                for (r, row) in values[lo * width..hi * width].chunks_exact(*width).enumerate() {
                    for (j, &v) in row.iter().enumerate() {
                        scratch[j * len + r] = v;
                    }
                }
                scratch.chunks_exact(len).collect()
            }
        };
        let mut cross = vec![0.0; (k + 1) * w];
        for (i, li) in left.chunks_exact(len).enumerate() {
            for (j, zj) in cols.iter().enumerate() {
                cross[i * w + j] = dot::<FMA>(li, zj);
            }
        }
        let mut zz = vec![0.0; w * w];
        for j in 0..w {
            for l in j..w {
                let v = dot::<FMA>(cols[j], cols[l]);
                zz[j * w + l] = v;
                zz[l * w + j] = v;
            }
        }
        out.push(Products { cross, zz });
    }
    out
}

/// `x · y` with [`LANES`] partial sums (vectorised), added in a fixed order.
#[inline(always)]
fn dot<const FMA: bool>(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0; LANES];
    let (xc, yc) = (x.chunks_exact(LANES), y.chunks_exact(LANES));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (xs, ys) in xc.zip(yc) {
        for q in 0..LANES {
            acc[q] = madd::<FMA>(xs[q], ys[q], acc[q]);
        }
    }
    let mut tail = 0.0;
    for (&p, &q) in xr.iter().zip(yr) {
        tail = madd::<FMA>(p, q, tail);
    }
    let half = [acc[0] + acc[4], acc[1] + acc[5], acc[2] + acc[6], acc[3] + acc[7]];
    (half[0] + half[2]) + (half[1] + half[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed;
        (0..n)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn products_equal_the_columns_multiplied_one_by_one() {
        let (n, k) = (2 * CHUNK + 13, 3);
        let (a, e) = (values(n * k, 1), values(n, 2));
        let series = values(n + 2, 3);
        let matrix = values(n * 2, 4);
        let blocks = [Block::Lagged { series: &series, width: 3 }, Block::Matrix { values: &matrix, width: 2 }];
        let column = |b: &Block<'_>, r: usize, j: usize| match b {
            Block::Lagged { series, width } => series[r + width - 1 - j],
            Block::Matrix { values, width } => values[r * width + j],
        };
        let left = |r: usize, i: usize| if i < k { a[r * k + i] } else { e[r] };
        let cancel = AtomicBool::new(false);
        for parallel in [false, true] {
            let got = column_products(&a, k, &e, &blocks, parallel, &cancel).unwrap();
            for (b, p) in blocks.iter().zip(&got) {
                let w = b.width();
                for j in 0..w {
                    for i in 0..=k {
                        let want: f64 = (0..n).map(|r| left(r, i) * column(b, r, j)).sum();
                        assert!((p.cross[i * w + j] - want).abs() < 1e-10, "{} against {want}", p.cross[i * w + j]);
                    }
                    for l in 0..w {
                        let want: f64 = (0..n).map(|r| column(b, r, j) * column(b, r, l)).sum();
                        assert!((p.zz[j * w + l] - want).abs() < 1e-10);
                    }
                }
            }
        }
        let one = column_products(&a, k, &e, &blocks, false, &cancel).unwrap();
        assert_eq!(one, column_products(&a, k, &e, &blocks, true, &cancel).unwrap());
    }

    #[test]
    fn wrong_lengths_and_cancel_are_errors() {
        let (a, e, s) = (values(20, 1), values(10, 2), values(11, 3));
        let cancel = AtomicBool::new(false);
        let lagged = [Block::Lagged { series: &s, width: 3 }];
        assert!(matches!(column_products(&a, 2, &e, &lagged, false, &cancel), Err(ArxError::ShapeMismatch { .. })));
        let fine = [Block::Lagged { series: &s, width: 2 }];
        assert!(column_products(&a, 2, &e, &fine, false, &cancel).is_ok());
        cancel.store(true, Ordering::Relaxed);
        assert!(matches!(column_products(&a, 2, &e, &fine, false, &cancel), Err(ArxError::Interrupted)));
    }
}
