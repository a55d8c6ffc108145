//! The products a batch of added-variable tests needs: for each block of candidate columns `z`,
//! `[A | e]'z` and `z'z`, with `A` the model's regressors (row-major) and `e` its residual.
//!
//! A block is either a matrix (row-major, as numpy builds it) or the lags of one series: column j
//! of row r is `series[r + width − 1 − j]`, the usual shape of a lagged candidate, which is never
//! written out. The rows are taken a chunk at a time, each operand read where it lies (a lagged
//! block is a view with a column stride of −1), and the products of a chunk are faer's
//! register-blocked matrix products. Chunks are summed in order, so the result does not depend on
//! the threads; it agrees with numpy's products to rounding, not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::error::{ArxError, Result};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// Rows per chunk: long enough for the matrix products to pay for packing their operands.
const CHUNK: usize = 8192;

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
    let len = hi - lo;
    // The chunk of [A | e] where it is (A row-major), and each block's columns where they are:
    // the products are register-blocked matrix products that read each value once for many sums.
    let am = MatRef::from_row_major_slice(&a[lo * k..hi * k], len, k);
    let em = MatRef::from_column_major_slice(&e[lo..hi], len, 1);
    let mut out = Vec::with_capacity(blocks.len());
    for b in blocks {
        let w = b.width();
        let zm = match b {
            // column j of row r is series[r + w − 1 − j]: a column stride of −1
            // SAFETY: rows lo..hi of every column lie inside `series` (checked by `fits`).
            Block::Lagged { series, width } => unsafe {
                MatRef::from_raw_parts(series.as_ptr().add(lo + width - 1), len, *width, 1, -1)
            },
            Block::Matrix { values, width } => {
                MatRef::from_row_major_slice(&values[lo * width..hi * width], len, *width)
            }
        };
        let mut cross = Mat::<f64>::zeros(k + 1, w);
        matmul(cross.as_mut().subrows_mut(0, k), Accum::Replace, am.transpose(), zm, 1.0, Par::Seq);
        matmul(cross.as_mut().subrows_mut(k, 1), Accum::Replace, em.transpose(), zm, 1.0, Par::Seq);
        let mut zz = Mat::<f64>::zeros(w, w);
        matmul(zz.as_mut(), Accum::Replace, zm.transpose(), zm, 1.0, Par::Seq);
        let cross = (0..(k + 1) * w).map(|q| cross[(q / w, q % w)]).collect();
        let zz = (0..w * w).map(|q| zz[(q / w, q % w)]).collect();
        out.push(Products { cross, zz });
    }
    out
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
