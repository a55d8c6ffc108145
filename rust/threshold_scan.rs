//! The cross products of a threshold scan. A dead zone `dz(x, c) = sign(x)·max(|x| − c, 0)` or a
//! saturation `sat(x, c) = sign(x)·min(|x|, c)` of a few lagged samples of one signal is tried with
//! dozens of thresholds c; the diagnosis needs, for each c, the products of its columns `z_c` with
//! the model's regressors and residual (`A'z_c`) and with themselves (`z_c'z_c`).
//!
//! Formed by numpy, every `z_c` is written to memory and read back. Here each row's thresholded
//! samples are formed in registers, for all thresholds side by side, and added into the products
//! at once: one pass over the rows, nothing the size of the data allocated. The sums run in
//! another order than numpy's, so they agree with it to rounding, not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::error::{ArxError, Result};
use crate::linear_predict::{avx2_fma, madd};
use crate::structure::sign;

/// Rows per chunk: one chunk's partial products are summed in chunk order, so the result does not
/// depend on the number of threads. The cancel flag is read once per chunk.
const CHUNK: usize = 8192;

/// The shape applied to the signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// `sign(x)·max(|x| − c, 0)`
    DeadZone,
    /// `sign(x)·min(|x|, c)`
    Saturation,
}

/// The rows of a scan: `a` (`n × k`, row-major) and `e` (`n`) are the columns the thresholded
/// ones are multiplied with; `lagged` (`n × b`, row-major) holds the signal's samples each
/// thresholded column takes, row by row.
pub struct ScanRows<'a> {
    pub a: &'a [f64],
    pub k: usize,
    pub e: &'a [f64],
    pub lagged: &'a [f64],
    pub b: usize,
}

impl ScanRows<'_> {
    fn n(&self) -> usize {
        self.e.len()
    }

    /// Columns of `[A | e]`.
    fn width(&self) -> usize {
        self.k + 1
    }
}

/// The products of a scan, threshold index last: `cross[(i·b + j)·m + t]` is column i of `[A | e]`
/// times lag j's column at threshold t; `zz[(j·b + l)·m + t]` is lag j's column times lag l's at
/// threshold t (symmetric in j, l).
#[derive(Clone, Debug, PartialEq)]
pub struct ScanProducts {
    pub cross: Vec<f64>,
    pub zz: Vec<f64>,
}

impl ScanProducts {
    fn zeros(width: usize, b: usize, m: usize) -> Self {
        ScanProducts { cross: vec![0.0; width * b * m], zz: vec![0.0; b * b * m] }
    }

    fn add(&mut self, other: &ScanProducts) {
        for (s, o) in self.cross.iter_mut().zip(&other.cross) {
            *s += o;
        }
        for (s, o) in self.zz.iter_mut().zip(&other.zz) {
            *s += o;
        }
    }
}

/// `[A | e]'z_c` and `z_c'z_c` for every threshold c of `thresholds`, the columns `z_c` being
/// `shape(lagged[:, j], c)`.
///
/// # Errors
/// `ShapeMismatch` when the arrays' lengths disagree; `Interrupted` once `cancel` is set.
pub fn scan_products(
    rows: &ScanRows<'_>,
    thresholds: &[f64],
    shape: Shape,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<ScanProducts> {
    let (n, b, m) = (rows.n(), rows.b, thresholds.len());
    if rows.a.len() != n * rows.k || rows.lagged.len() != n * b {
        let (what, got) = if rows.a.len() != n * rows.k {
            ("values of the regressor rows of a threshold scan", rows.a.len())
        } else {
            ("lagged samples of a threshold scan", rows.lagged.len())
        };
        let expected = if rows.a.len() != n * rows.k { n * rows.k } else { n * b };
        return Err(ArxError::ShapeMismatch { what: what.into(), expected, got });
    }
    let chunk = |lo: usize| -> Result<ScanProducts> {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(chunk_products(rows, lo, (lo + CHUNK).min(n), thresholds, shape))
    };
    let starts: Vec<usize> = (0..n).step_by(CHUNK).collect();
    let partials: Vec<ScanProducts> = if parallel {
        starts.par_iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    } else {
        starts.iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    };
    let mut total = ScanProducts::zeros(rows.width(), b, m);
    for p in &partials {
        total.add(p);
    }
    mirror(&mut total.zz, b, m);
    Ok(total)
}

/// Copies the upper triangle of the lag-by-lag products onto the lower one.
fn mirror(zz: &mut [f64], b: usize, m: usize) {
    for j in 0..b {
        for l in 0..j {
            let (src, dst) = ((l * b + j) * m, (j * b + l) * m);
            zz.copy_within(src..src + m, dst);
        }
    }
}

fn chunk_products(rows: &ScanRows<'_>, lo: usize, hi: usize, thresholds: &[f64], shape: Shape) -> ScanProducts {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { chunk_products_avx2(rows, lo, hi, thresholds, shape) };
    }
    chunk_products_with::<false>(rows, lo, hi, thresholds, shape)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_products_avx2(
    rows: &ScanRows<'_>,
    lo: usize,
    hi: usize,
    thresholds: &[f64],
    shape: Shape,
) -> ScanProducts {
    chunk_products_with::<true>(rows, lo, hi, thresholds, shape)
}

/// Rows added into the products together: each product is loaded and stored once per group.
const GROUP: usize = 4;

#[inline(always)]
fn chunk_products_with<const FMA: bool>(
    rows: &ScanRows<'_>,
    lo: usize,
    hi: usize,
    thresholds: &[f64],
    shape: Shape,
) -> ScanProducts {
    let (k, b, m, w) = (rows.k, rows.b, thresholds.len(), rows.width());
    let bm = b * m;
    let mut cross = vec![0.0; w * bm];
    // diagonals[d·bm + j·m + t]: lag j times lag j + d at threshold t
    let mut diagonals = vec![0.0; b * bm];
    let (mut left, mut z) = (vec![0.0; GROUP * w], vec![0.0; GROUP * bm]);
    let mut r = lo;
    while r < hi {
        let nr = (hi - r).min(GROUP);
        for q in 0..nr {
            let row = r + q;
            left[q * w..q * w + k].copy_from_slice(&rows.a[row * k..(row + 1) * k]);
            left[q * w + k] = rows.e[row];
            for (j, zj) in z[q * bm..(q + 1) * bm].chunks_exact_mut(m).enumerate() {
                shaped(rows.lagged[row * b + j], thresholds, shape, zj);
            }
        }
        if nr == GROUP {
            add_group::<FMA>(&left, &z, w, bm, m, &mut cross, &mut diagonals);
        } else {
            for q in 0..nr {
                add_row::<FMA>(&left[q * w..(q + 1) * w], &z[q * bm..(q + 1) * bm], m, &mut cross, &mut diagonals);
            }
        }
        r += nr;
    }
    let mut zz = vec![0.0; b * bm];
    for d in 0..b {
        for j in 0..b - d {
            let src = d * bm + j * m;
            zz[(j * b + j + d) * m..(j * b + j + d + 1) * m].copy_from_slice(&diagonals[src..src + m]);
        }
    }
    ScanProducts { cross, zz }
}

/// Adds [`GROUP`] rows (`left`: their `[A | e]`, `z`: their thresholded samples) into the products.
#[inline(always)]
fn add_group<const FMA: bool>(
    left: &[f64],
    z: &[f64],
    w: usize,
    bm: usize,
    m: usize,
    cross: &mut [f64],
    diagonals: &mut [f64],
) {
    let (z0, z1, z2, z3) = (&z[..bm], &z[bm..2 * bm], &z[2 * bm..3 * bm], &z[3 * bm..4 * bm]);
    for (i, acc) in cross.chunks_exact_mut(bm).enumerate() {
        let (v0, v1, v2, v3) = (left[i], left[w + i], left[2 * w + i], left[3 * w + i]);
        for ((((s, &a0), &a1), &a2), &a3) in acc.iter_mut().zip(z0).zip(z1).zip(z2).zip(z3) {
            *s = madd::<FMA>(v3, a3, madd::<FMA>(v2, a2, madd::<FMA>(v1, a1, madd::<FMA>(v0, a0, *s))));
        }
    }
    for (d, acc) in diagonals.chunks_exact_mut(bm).enumerate() {
        let (len, off) = (bm - d * m, d * m);
        let pairs = z0[..len].iter().zip(&z0[off..]).zip(z1[..len].iter().zip(&z1[off..]));
        let pairs = pairs.zip(z2[..len].iter().zip(&z2[off..]).zip(z3[..len].iter().zip(&z3[off..])));
        for (s, (((&p0, &q0), (&p1, &q1)), ((&p2, &q2), (&p3, &q3)))) in acc[..len].iter_mut().zip(pairs) {
            *s = madd::<FMA>(p3, q3, madd::<FMA>(p2, q2, madd::<FMA>(p1, q1, madd::<FMA>(p0, q0, *s))));
        }
    }
}

/// Adds one row into the products (the rows left after the groups).
#[inline(always)]
fn add_row<const FMA: bool>(left: &[f64], z: &[f64], m: usize, cross: &mut [f64], diagonals: &mut [f64]) {
    let bm = z.len();
    for (&v, acc) in left.iter().zip(cross.chunks_exact_mut(bm)) {
        for (s, &a) in acc.iter_mut().zip(z) {
            *s = madd::<FMA>(v, a, *s);
        }
    }
    for (d, acc) in diagonals.chunks_exact_mut(bm).enumerate() {
        for ((s, &p), &q) in acc.iter_mut().zip(z).zip(&z[d * m..]) {
            *s = madd::<FMA>(p, q, *s);
        }
    }
}

/// `shape(x, c)` for every threshold c, as numpy's `thresholded` computes it.
#[inline(always)]
fn shaped(x: f64, thresholds: &[f64], shape: Shape, out: &mut [f64]) {
    let (magnitude, sign) = (x.abs(), sign(x));
    match shape {
        Shape::DeadZone => {
            for (o, &c) in out.iter_mut().zip(thresholds) {
                *o = (magnitude - c).max(0.0) * sign;
            }
        }
        Shape::Saturation => {
            for (o, &c) in out.iter_mut().zip(thresholds) {
                *o = magnitude.min(c) * sign;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The products formed column by column, as numpy would.
    fn direct(rows: &ScanRows<'_>, thresholds: &[f64], shape: Shape) -> ScanProducts {
        let (n, k, b, m) = (rows.n(), rows.k, rows.b, thresholds.len());
        let mut out = ScanProducts::zeros(k + 1, b, m);
        for (t, &c) in thresholds.iter().enumerate() {
            let col = |j: usize, r: usize| {
                let x: f64 = rows.lagged[r * b + j];
                let s = sign(x);
                match shape {
                    Shape::DeadZone => s * (x.abs() - c).max(0.0),
                    Shape::Saturation => s * x.abs().min(c),
                }
            };
            for j in 0..b {
                for i in 0..=k {
                    let left = |r: usize| if i < k { rows.a[r * k + i] } else { rows.e[r] };
                    out.cross[(i * b + j) * m + t] = (0..n).map(|r| left(r) * col(j, r)).sum();
                }
                for l in 0..b {
                    out.zz[(j * b + l) * m + t] = (0..n).map(|r| col(j, r) * col(l, r)).sum();
                }
            }
        }
        out
    }

    fn data(n: usize, k: usize, b: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut state = 12345u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        let a = (0..n * k).map(|_| next()).collect();
        let e = (0..n).map(|_| next()).collect();
        let mut lagged: Vec<f64> = (0..n * b).map(|_| next()).collect();
        lagged[3] = 0.0; // sign(0) = 0
        (a, e, lagged)
    }

    #[test]
    fn products_equal_the_columns_formed_one_by_one() {
        let (n, k, b) = (3 * CHUNK + 17, 4, 3);
        let (a, e, lagged) = data(n, k, b);
        let rows = ScanRows { a: &a, k, e: &e, lagged: &lagged, b };
        let thresholds = [0.05, 0.3, 0.7, 1.1, 1.5, 1.9, 2.5];
        let cancel = AtomicBool::new(false);
        for shape in [Shape::DeadZone, Shape::Saturation] {
            let want = direct(&rows, &thresholds, shape);
            for parallel in [false, true] {
                let got = scan_products(&rows, &thresholds, shape, parallel, &cancel).unwrap();
                for (g, w) in got.cross.iter().chain(&got.zz).zip(want.cross.iter().chain(&want.zz)) {
                    assert!((g - w).abs() <= 1e-10 * (1.0 + w.abs()), "{g} against {w}");
                }
            }
            let (one, two) = (
                scan_products(&rows, &thresholds, shape, false, &cancel).unwrap(),
                scan_products(&rows, &thresholds, shape, true, &cancel).unwrap(),
            );
            assert_eq!(one, two, "the sums do not depend on the threads");
        }
    }

    #[test]
    fn mismatched_lengths_and_cancel_are_errors() {
        let (a, e, lagged) = data(100, 2, 2);
        let rows = ScanRows { a: &a[..150], k: 2, e: &e, lagged: &lagged, b: 2 };
        let cancel = AtomicBool::new(false);
        assert!(matches!(
            scan_products(&rows, &[0.5], Shape::DeadZone, false, &cancel),
            Err(ArxError::ShapeMismatch { .. })
        ));
        let rows = ScanRows { a: &a, k: 2, e: &e, lagged: &lagged, b: 2 };
        cancel.store(true, Ordering::Relaxed);
        assert!(matches!(scan_products(&rows, &[0.5], Shape::DeadZone, false, &cancel), Err(ArxError::Interrupted)));
    }
}
