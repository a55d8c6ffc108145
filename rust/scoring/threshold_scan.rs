//! The cross products of a threshold scan. A dead zone `dz(x, c) = sign(x)·max(|x| − c, 0)` or a
//! saturation `sat(x, c) = sign(x)·min(|x|, c)` of a few lagged samples of one signal is tried with
//! dozens of thresholds c; the diagnosis needs, for each c, the products of its columns `z_c` with
//! the model's regressors and residual (`A'z_c`) and with themselves (`z_c'z_c`).
//!
//! Formed by numpy, every `z_c` is written to memory and read back. Here one pass over the rows
//! forms them all, nothing the size of the data allocated, in one of two ways:
//!
//! - a few thresholds: each row's thresholded samples in registers, for all thresholds side by
//!   side, added into the products at once (work ∝ thresholds);
//! - many (a scan's grid): each sample falls between two neighbouring thresholds, and its
//!   contribution to every threshold is a fixed part plus a multiple of the threshold. The rows add
//!   those parts into sums per interval (per pair of intervals for `z_c'z_c`), and each threshold's
//!   products are sums of those: work per row independent of the thresholds. Every part is a
//!   non-negative multiple of the sample's own term, so no subtraction is introduced.
//!
//! The sums run in another order than numpy's, so they agree with it to rounding, not to the last
//! bit.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::arx::structure::sign;
use crate::error::{ArxError, Result};
use crate::linalg::simd::{avx2_fma, madd};

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
    /// Two thresholds: a dead zone at the first and a saturation at the second, side by side in one
    /// pass (each the same bits as alone).
    DeadZoneAndSaturation,
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
    if shape == Shape::DeadZoneAndSaturation && m != 2 {
        return Err(ArxError::ShapeMismatch {
            what: "thresholds of a dead zone and a saturation".into(),
            expected: 2,
            got: m,
        });
    }
    if m >= BY_INTERVALS {
        return by_intervals(rows, thresholds, shape, parallel, cancel);
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

/// Thresholds from which the products are summed by intervals ([`by_intervals`]): below it the
/// thresholds side by side cost less than the intervals' bookkeeping.
const BY_INTERVALS: usize = 4;

/// Rows per chunk of [`by_intervals`]: each chunk's sums per interval pair are a few dozen
/// kilobytes, so chunks are larger than [`CHUNK`].
const INTERVAL_CHUNK: usize = 1 << 16;

/// The sums per interval of one chunk of rows. A sample x falls in interval `T` = the number of
/// (ascending) thresholds below |x|; for a threshold `c_t` with `t < T` it is shaped (dead zone:
/// `s·(|x| − c_t)`, saturation: `s·c_t`, s = sign(x)), for `t ≥ T` it is zero (dead zone) or x
/// (saturation). Below, `a = |x| − c_{T−1}` ≥ 0 is the sample's height above its interval's floor.
struct Intervals {
    /// `[lag][T][column]`: dead zone Σ s·a·w, saturation Σ x·w, `w` the row of `[A | e]`.
    own: Vec<f64>,
    /// `[lag][T][column]`: Σ s·w.
    signed: Vec<f64>,
    /// `[lag pair][T_j][T_l][4]`: dead zone Σ s_j s_l (a_j a_l, a_j, a_l, 1) over rows where both
    /// samples lie above the lowest threshold; saturation Σ (x_j x_l, x_j s_l, s_j x_l, s_j s_l).
    cells: Vec<f64>,
}

impl Intervals {
    fn zeros(b: usize, m: usize, w: usize) -> Self {
        let slots = m + 1;
        Intervals {
            own: vec![0.0; b * slots * w],
            signed: vec![0.0; b * slots * w],
            cells: vec![0.0; b * (b + 1) / 2 * slots * slots * 4],
        }
    }

    fn add(&mut self, other: &Intervals) {
        for (s, o) in self.own.iter_mut().zip(&other.own) {
            *s += o;
        }
        for (s, o) in self.signed.iter_mut().zip(&other.signed) {
            *s += o;
        }
        for (s, o) in self.cells.iter_mut().zip(&other.cells) {
            *s += o;
        }
    }
}

/// [`scan_products`] by sums per interval between neighbouring thresholds (see the module's notes).
fn by_intervals(
    rows: &ScanRows<'_>,
    thresholds: &[f64],
    shape: Shape,
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<ScanProducts> {
    let (n, b, m, w) = (rows.n(), rows.b, thresholds.len(), rows.width());
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| thresholds[i].total_cmp(&thresholds[j]));
    let sorted: Vec<f64> = order.iter().map(|&i| thresholds[i]).collect();
    let chunk = |lo: usize| -> Result<Intervals> {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        Ok(interval_sums(rows, lo, (lo + INTERVAL_CHUNK).min(n), &sorted, shape))
    };
    let starts: Vec<usize> = (0..n).step_by(INTERVAL_CHUNK).collect();
    let partials: Vec<Intervals> = if parallel {
        starts.par_iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    } else {
        starts.iter().map(|&lo| chunk(lo)).collect::<Result<_>>()?
    };
    let mut total = Intervals::zeros(b, m, w);
    for p in &partials {
        total.add(p);
    }
    let mut out = ScanProducts::zeros(w, b, m);
    for (t, &at) in order.iter().enumerate() {
        cross_at(&total, &sorted, t, shape, b, w, |i, j, v| out.cross[(i * b + j) * m + at] = v);
        let mut pair = 0;
        for j in 0..b {
            for l in j..b {
                let v = zz_at(&total.cells[pair * (m + 1) * (m + 1) * 4..], &sorted, t, shape);
                out.zz[(j * b + l) * m + at] = v;
                out.zz[(l * b + j) * m + at] = v;
                pair += 1;
            }
        }
    }
    Ok(out)
}

fn interval_sums(rows: &ScanRows<'_>, lo: usize, hi: usize, sorted: &[f64], shape: Shape) -> Intervals {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { interval_sums_avx2(rows, lo, hi, sorted, shape) };
    }
    interval_sums_with::<false>(rows, lo, hi, sorted, shape)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn interval_sums_avx2(rows: &ScanRows<'_>, lo: usize, hi: usize, sorted: &[f64], shape: Shape) -> Intervals {
    interval_sums_with::<true>(rows, lo, hi, sorted, shape)
}

/// Rows whose samples are placed in their intervals together, before their sums are added.
const PLACED: usize = 256;

#[inline(always)]
fn interval_sums_with<const FMA: bool>(
    rows: &ScanRows<'_>,
    lo: usize,
    hi: usize,
    sorted: &[f64],
    shape: Shape,
) -> Intervals {
    let (k, b, m, w) = (rows.k, rows.b, sorted.len(), rows.width());
    let slots = m + 1;
    let mut sums = Intervals::zeros(b, m, w);
    let mut left = vec![0.0; w];
    let dead_zone = shape == Shape::DeadZone;
    // floor[T]: the threshold just below interval T (T >= 1)
    let floor: Vec<f64> = std::iter::once(0.0).chain(sorted.iter().copied()).collect();
    // per sample of a block of rows: interval, sign, and the value the sums take (dead zone s·a,
    // saturation x)
    let (mut at, mut sg, mut val) = (vec![0usize; PLACED * b], vec![0.0; PLACED * b], vec![0.0; PLACED * b]);
    for block in (lo..hi).step_by(PLACED) {
        let end = (block + PLACED).min(hi);
        let samples = &rows.lagged[block * b..end * b];
        let n = samples.len();
        for (i, &x) in samples.iter().enumerate() {
            let x = if x.is_nan() { 0.0 } else { x }; // shaped to 0 by both shapes, as side by side
            sg[i] = sign(x);
            val[i] = x;
            at[i] = 0;
        }
        for &c in sorted {
            for (t, &x) in at[..n].iter_mut().zip(&val[..n]) {
                *t += usize::from(c < x.abs());
            }
        }
        if dead_zone {
            for ((v, &t), &s) in val[..n].iter_mut().zip(&at[..n]).zip(&sg[..n]) {
                *v = if t == 0 { 0.0 } else { s * (v.abs() - floor[t]) };
            }
        }
        for r in block..end {
            left[..k].copy_from_slice(&rows.a[r * k..(r + 1) * k]);
            left[k] = rows.e[r];
            let i0 = (r - block) * b;
            let (at, sg, val) = (&at[i0..i0 + b], &sg[i0..i0 + b], &val[i0..i0 + b]);
            for j in 0..b {
                if dead_zone && at[j] == 0 {
                    continue; // shaped to zero by every threshold
                }
                let slot = (j * slots + at[j]) * w;
                add_scaled::<FMA>(
                    &mut sums.own[slot..slot + w],
                    &mut sums.signed[slot..slot + w],
                    &left,
                    val[j],
                    sg[j],
                );
            }
            let mut pair = 0;
            for j in 0..b {
                for l in j..b {
                    if !(dead_zone && (at[j] == 0 || at[l] == 0)) {
                        let cell = ((pair * slots + at[j]) * slots + at[l]) * 4;
                        let (p, q) = ([val[j], val[j], sg[j], sg[j]], [val[l], sg[l], val[l], sg[l]]);
                        add_outer::<FMA>(&mut sums.cells[cell..cell + 4], p, q);
                    }
                    pair += 1;
                }
            }
        }
    }
    sums
}

/// `own += first · left` and `signed += sign · left` (slices passed apart, so they are vectorised).
#[inline(always)]
fn add_scaled<const FMA: bool>(own: &mut [f64], signed: &mut [f64], left: &[f64], first: f64, sign: f64) {
    for ((o, s), &v) in own.iter_mut().zip(signed.iter_mut()).zip(left) {
        *o = madd::<FMA>(first, v, *o);
        *s = madd::<FMA>(sign, v, *s);
    }
}

/// `cell += p · q`, four products side by side.
#[inline(always)]
fn add_outer<const FMA: bool>(cell: &mut [f64], p: [f64; 4], q: [f64; 4]) {
    for ((c, p), q) in cell.iter_mut().zip(p).zip(q) {
        *c = madd::<FMA>(p, q, *c);
    }
}

/// `[A | e]'z_c` at the threshold `sorted[t]` for every column i and lag j, given to `put(i, j, v)`.
fn cross_at(
    sums: &Intervals,
    sorted: &[f64],
    t: usize,
    shape: Shape,
    b: usize,
    w: usize,
    mut put: impl FnMut(usize, usize, f64),
) {
    let (m, c) = (sorted.len(), sorted[t]);
    let slots = m + 1;
    for j in 0..b {
        for i in 0..w {
            let at = |arr: &[f64], interval: usize| arr[(j * slots + interval) * w + i];
            let mut v = 0.0;
            for interval in t + 1..=m {
                v += match shape {
                    // s·(|x| − c) = s·a + (c_{T−1} − c)·s
                    Shape::DeadZone => {
                        at(&sums.own, interval) + (sorted[interval - 1] - c) * at(&sums.signed, interval)
                    }
                    Shape::Saturation => c * at(&sums.signed, interval),
                    Shape::DeadZoneAndSaturation => unreachable!("two thresholds are never summed by intervals"),
                };
            }
            if shape == Shape::Saturation {
                for interval in 0..=t {
                    v += at(&sums.own, interval);
                }
            }
            put(i, j, v);
        }
    }
}

/// `z_c'z_c` of one pair of lags at the threshold `sorted[t]` from its cells (see [`Intervals`]).
fn zz_at(cells: &[f64], sorted: &[f64], t: usize, shape: Shape) -> f64 {
    let (m, c) = (sorted.len(), sorted[t]);
    let slots = m + 1;
    let mut v = 0.0;
    for tj in 0..slots {
        for tl in 0..slots {
            let s = &cells[(tj * slots + tl) * 4..(tj * slots + tl) * 4 + 4];
            v += match shape {
                Shape::DeadZone if tj > t && tl > t => {
                    // (a_j + d_j)(a_l + d_l) s_j s_l, d = c_{T−1} − c >= 0
                    let (dj, dl) = (sorted[tj - 1] - c, sorted[tl - 1] - c);
                    s[0] + dl * s[1] + dj * s[2] + dj * dl * s[3]
                }
                Shape::DeadZone => 0.0,
                Shape::Saturation => match (tj > t, tl > t) {
                    (false, false) => s[0],
                    (false, true) => c * s[1],
                    (true, false) => c * s[2],
                    (true, true) => c * c * s[3],
                },
                Shape::DeadZoneAndSaturation => unreachable!("two thresholds are never summed by intervals"),
            };
        }
    }
    v
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
        Shape::DeadZoneAndSaturation => {
            out[0] = (magnitude - thresholds[0]).max(0.0) * sign;
            out[1] = magnitude.min(thresholds[1]) * sign;
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
                    Shape::Saturation | Shape::DeadZoneAndSaturation => s * x.abs().min(c),
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
    fn a_dead_zone_and_a_saturation_side_by_side_are_each_alone_to_the_bit() {
        let (n, k, b) = (2 * CHUNK + 5, 3, 2);
        let (a, e, lagged) = data(n, k, b);
        let rows = ScanRows { a: &a, k, e: &e, lagged: &lagged, b };
        let cancel = AtomicBool::new(false);
        let both = scan_products(&rows, &[0.4, 0.7], Shape::DeadZoneAndSaturation, true, &cancel).unwrap();
        let dz = scan_products(&rows, &[0.4], Shape::DeadZone, true, &cancel).unwrap();
        let sat = scan_products(&rows, &[0.7], Shape::Saturation, true, &cancel).unwrap();
        let lane = |v: &[f64], t: usize| v.iter().skip(t).step_by(2).copied().collect::<Vec<f64>>();
        assert_eq!((lane(&both.cross, 0), lane(&both.zz, 0)), (dz.cross, dz.zz));
        assert_eq!((lane(&both.cross, 1), lane(&both.zz, 1)), (sat.cross, sat.zz));
    }

    #[test]
    fn sums_by_intervals_equal_the_thresholds_side_by_side() {
        let (n, k, b) = (2 * INTERVAL_CHUNK + 1001, 3, 3);
        let (a, e, mut lagged) = data(n, k, b);
        // samples exactly on thresholds, zeros and a missing sample
        for (r, v) in [(10, 0.3), (11, -0.3), (12, 1.5), (13, 0.0), (14, -2.0), (15, 2.5), (16, f64::NAN)] {
            lagged[r * b + 1] = v;
        }
        let rows = ScanRows { a: &a, k, e: &e, lagged: &lagged, b };
        let cancel = AtomicBool::new(false);
        let grids: [&[f64]; 4] = [
            &[0.05, 0.3, 0.7, 1.1, 1.5, 1.9, 2.5],
            &[1.9, 0.3, 1.1, 0.05, 2.5, 0.7, 1.5], // in any order
            &[0.0, 0.3, 0.3, 1.0, 1.0, 1.0, 3.0],  // zero, repeated, above every sample
            &[-0.5, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 1.99, 2.0],
        ];
        for shape in [Shape::DeadZone, Shape::Saturation] {
            for cs in grids {
                let side_by_side = chunk_products(&rows, 0, n, cs, shape);
                let got = scan_products(&rows, cs, shape, true, &cancel).unwrap();
                let scale = |v: &[f64]| v.iter().fold(0.0_f64, |s, x| s.max(x.abs()));
                let (cs_scale, zz_scale) = (scale(&side_by_side.cross), scale(&side_by_side.zz));
                for (g, w) in got.cross.iter().zip(&side_by_side.cross) {
                    assert!((g - w).abs() <= 1e-12 * cs_scale, "{shape:?} {cs:?}: {g} against {w}");
                }
                let mut zz = side_by_side.zz.clone();
                mirror(&mut zz, b, cs.len());
                for (g, w) in got.zz.iter().zip(&zz) {
                    assert!((g - w).abs() <= 1e-12 * zz_scale, "{shape:?} {cs:?}: {g} against {w}");
                }
                let serial = scan_products(&rows, cs, shape, false, &cancel).unwrap();
                assert_eq!(got, serial, "the sums do not depend on the threads");
            }
        }
    }

    #[test]
    fn a_dead_zone_just_below_the_largest_samples_loses_no_digits() {
        // Samples far above zero and a threshold just below them: each shaped value is small
        // against the samples, so sums that subtracted the threshold from the samples' sums would
        // lose digits; the sums per interval do not.
        let n = 5000;
        let lagged: Vec<f64> = (0..n).map(|r| 1000.0 + (r % 7) as f64 * 1e-6).collect();
        let (a, e) = (vec![1.0; n], vec![0.0; n]);
        let rows = ScanRows { a: &a, k: 1, e: &e, lagged: &lagged, b: 1 };
        let cs = [0.0, 10.0, 999.0, 1000.0, 1000.000002, 1000.000005];
        let got = scan_products(&rows, &cs, Shape::DeadZone, false, &AtomicBool::new(false)).unwrap();
        let want = |c: f64| lagged.iter().map(|x| (x - c).max(0.0)).sum::<f64>();
        for (t, &c) in cs.iter().enumerate() {
            let w = want(c);
            assert!(
                (got.cross[t] - w).abs() <= 1e-13 * w.abs().max(1e-300) + 1e-300,
                "{c}: {} against {w}",
                got.cross[t]
            );
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
