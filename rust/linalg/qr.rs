//! Householder QR: a tall matrix to its triangular factor R (TSQR in fixed row blocks, so results
//! do not depend on the thread count), small re-triangularisations, back substitution, rank checks.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor::{qr_in_place, qr_in_place_scratch, recommended_block_size};
use faer::{Mat, MatMut, Par};

use crate::error::{ArxError, Result};
use crate::linalg::tall_qr::{tall_r_into, MAX_COLUMNS};

/// Rows per TSQR block. Fixed (not derived from the thread count) so that the reduction tree,
/// and therefore every bit of R, is the same for any number of threads.
pub const BLOCK_ROWS: usize = 4096;

/// Overwrites the upper triangle of `a` with R of its Householder QR (ignore the entries below the
/// diagonal: Householder vectors, zeros or the input). Tall matrices of up to
/// [`MAX_COLUMNS`] columns are factored by [`tall_r_into`], others by faer's blocked QR.
pub fn qr_r_in_place(mut a: MatMut<'_, f64>) {
    let (m, n) = (a.nrows(), a.ncols());
    if m == 0 || n == 0 {
        return;
    }
    if m >= n && n <= MAX_COLUMNS && a.row_stride() == 1 {
        // Tall and narrow (a TSQR block): reflections of a panel of rows at a time into R, in cache.
        // On the stack: no allocation between a worker's block buffers.
        let mut r = [0.0; MAX_COLUMNS * MAX_COLUMNS];
        let r = &mut r[..n * n];
        let mut exponents = [0i32; MAX_COLUMNS];
        for (j, e) in exponents.iter_mut().enumerate().take(n) {
            let col = a.as_mut().col_mut(j).try_as_col_major_mut().expect("unit row stride").as_slice_mut();
            *e = into_tall_range(col);
        }
        {
            let view = a.as_ref();
            let mut columns: [&[f64]; MAX_COLUMNS] = [&[]; MAX_COLUMNS];
            for (j, c) in columns.iter_mut().enumerate().take(n) {
                *c = view.col(j).try_as_col_major().expect("unit row stride").as_slice();
            }
            tall_r_into(&columns[..n], r);
        }
        for j in 0..n {
            for i in 0..n {
                a[(i, j)] = times_power_of_two(r[i + j * n], -exponents[j]); // R(A D) D⁻¹ = R(A)
            }
        }
        return;
    }
    let bs = recommended_block_size::<f64>(m, n);
    let mut q_coeff = Mat::<f64>::zeros(bs, m.min(n));
    let mut buf = MemBuffer::new(qr_in_place_scratch::<f64>(m, n, bs, Par::Seq, Default::default()));
    qr_in_place(a, q_coeff.as_mut(), Par::Seq, MemStack::new(&mut buf), Default::default());
}

/// A column's largest |entry| the tall kernel factors as it is: its sums of squares stay inside the
/// float range (2^±400 squared is 2^±800). The kernel does not scale its norms as faer's QR does.
const TALL_LOW: f64 = 3.872591914849318e-121; // 2^-400
const TALL_HIGH: f64 = 2.5822498780869086e120; // 2^400

/// Scales `col` by the power of two `2^e` that brings its largest |entry| near 1 when that lies
/// outside `[TALL_LOW, TALL_HIGH]`, and returns `e` (0, the column untouched, when it lies inside or
/// the column is zero or holds an infinity). A power of two scales every rounding with it, so R of
/// the scaled columns is R's columns times `2^e` exactly: the same bits once scaled back.
fn into_tall_range(col: &mut [f64]) -> i32 {
    let largest = col.iter().fold(0.0f64, |m, &x| m.max(x.abs())); // NaN is passed over
    if largest == 0.0 || !largest.is_finite() || (TALL_LOW..=TALL_HIGH).contains(&largest) {
        return 0;
    }
    let e = -(largest.log2().floor() as i32);
    for x in col.iter_mut() {
        *x = times_power_of_two(*x, e);
    }
    e
}

/// `x · 2^e`, exact while the result is a normal number (in steps: `2^e` alone may not be one).
fn times_power_of_two(mut x: f64, mut e: i32) -> f64 {
    while e != 0 {
        let step = e.clamp(-1000, 1000);
        x *= f64::from_bits(((1023 + step) as u64) << 52);
        e -= step;
    }
    x
}

/// Upper-triangular (q × q) copy of the first q rows of `a`'s R, zero-padded when `a` had fewer rows.
pub fn take_r(a: &Mat<f64>, q: usize) -> Mat<f64> {
    let rows = a.nrows().min(q);
    Mat::from_fn(q, q, |i, j| if i < rows && i <= j { a[(i, j)] } else { 0.0 })
}

/// Bytes a TSQR reduction (as `arx::reduce::reduce_checked`) allocates for `n_rows` rows of a
/// `q`-column matrix on `threads` threads: one block buffer per thread, every block's R, their
/// stack, and the final R.
pub fn reduce_memory(n_rows: usize, q: usize, threads: usize) -> usize {
    let f = std::mem::size_of::<f64>();
    let blocks = (n_rows / BLOCK_ROWS).saturating_add(1);
    let per_block = q.saturating_mul(q).saturating_mul(f);
    let block_buffers = threads.saturating_mul(BLOCK_ROWS.min(n_rows.max(1))).saturating_mul(q).saturating_mul(f);
    blocks.saturating_mul(per_block).saturating_mul(2).saturating_add(block_buffers).saturating_add(per_block)
}

/// Writes `values[at(t)]` for each of the block's samples t into `dst`, where the values of
/// consecutive samples lie `stride` apart: a strided copy when the samples are consecutive (a gap
/// or an experiment's edge breaks them), else a gather. The TSQR blocks of the regressors and of
/// lagged signals are filled so.
pub fn fill_from_samples(dst: &mut [f64], values: &[f64], block: &[usize], stride: usize, at: impl Fn(usize) -> usize) {
    match (block.first(), block.last()) {
        (Some(&first), Some(&last)) if last - first + 1 == block.len() => {
            let start = at(first);
            if stride == 1 {
                dst.copy_from_slice(&values[start..start + block.len()]);
            } else {
                for (i, v) in dst.iter_mut().enumerate() {
                    *v = values[start + i * stride];
                }
            }
        }
        _ => {
            for (v, &t) in dst.iter_mut().zip(block) {
                *v = values[at(t)];
            }
        }
    }
}

/// Reduces the first `q + filled` rows of `work` (q × q R so far on top, `filled` new rows below,
/// q = its columns) to R on top, zero below the diagonal: one step of a streamed QR.
pub fn reduce_appended(work: &mut Mat<f64>, filled: usize) {
    let q = work.ncols();
    qr_r_in_place(work.as_mut().subrows_mut(0, q + filled));
    for j in 0..q {
        for i in (j + 1)..q {
            work[(i, j)] = 0.0; // Householder vectors, not R
        }
    }
}

/// Stacks square upper-triangular factors and returns the R of the stack.
pub fn stack_and_reduce(blocks: &[Mat<f64>], q: usize) -> Mat<f64> {
    match blocks.len() {
        0 => Mat::zeros(q, q),
        1 => blocks[0].clone(),
        nb => {
            let mut a = Mat::<f64>::zeros(nb * q, q);
            for (b, r) in blocks.iter().enumerate() {
                for j in 0..q {
                    for i in 0..=j {
                        a[(b * q + i, j)] = r[(i, j)];
                    }
                }
            }
            qr_r_in_place(a.as_mut());
            take_r(&a, q)
        }
    }
}

/// In-place Householder triangularisation of a small column-major `m × n` matrix (`m >= n` not
/// required). Afterwards `a[i + j*m]` for `i <= j` holds R. Cost O(m n²), no allocation.
pub fn small_qr(a: &mut [f64], m: usize, n: usize) {
    for k in 0..n.min(m) {
        let col = k * m;
        let mut norm2 = 0.0;
        for i in k..m {
            norm2 += a[col + i] * a[col + i];
        }
        if norm2 == 0.0 {
            continue;
        }
        let alpha = a[col + k];
        let norm = norm2.sqrt();
        let beta = if alpha >= 0.0 { -norm } else { norm };
        // v = x - beta e1, stored in place; H = I - v vᵀ / (vᵀ v / 2)... use tau form.
        let v0 = alpha - beta;
        a[col + k] = v0;
        let vnorm2 = norm2 - alpha * alpha + v0 * v0;
        for j in (k + 1)..n {
            let cj = j * m;
            let mut dot = 0.0;
            for i in k..m {
                dot += a[col + i] * a[cj + i];
            }
            let f = 2.0 * dot / vnorm2;
            for i in k..m {
                a[cj + i] -= f * a[col + i];
            }
        }
        a[col + k] = beta;
        for i in (k + 1)..m {
            a[col + i] = 0.0;
        }
    }
}

/// Solves the upper-triangular system `R θ = rhs` (R given column-major with leading dimension `ld`).
pub fn back_substitute(r: &[f64], ld: usize, rhs: &[f64], theta: &mut [f64]) {
    let p = theta.len();
    for i in (0..p).rev() {
        let mut acc = rhs[i];
        for j in (i + 1)..p {
            acc -= r[i + j * ld] * theta[j];
        }
        theta[i] = acc / r[i + i * ld];
    }
}

/// A power of two that brings the largest magnitude of `col` near 1 (1 for a zero or non-finite
/// column). Multiplying by it is exact, so scaled and unscaled solutions agree to the last bit
/// whenever neither overflows; it keeps sums of squares of columns near 1e154 or 1e-200 in range.
pub fn column_scale(col: &[f64]) -> f64 {
    let big = col.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if big == 0.0 || !big.is_finite() {
        return 1.0;
    }
    let e = big.log2().floor().clamp(-1000.0, 1000.0) as i32;
    2f64.powi(-e)
}

/// Relative tolerance below which a diagonal entry of R marks a dependent column.
pub fn rank_tolerance(n_rows: usize, p: usize) -> f64 {
    (n_rows.max(p) as f64) * f64::EPSILON * 10.0
}

/// Checks the first `p` columns of a column-major upper-triangular R: column j is dependent when
/// |R_jj| is tiny against its own norm (the sine of its angle to the span of the columns before it).
pub fn check_rank(r: &[f64], ld: usize, p: usize, tol: f64) -> Result<()> {
    for j in 0..p {
        let mut norm2 = 0.0;
        for i in 0..=j {
            norm2 += r[i + j * ld] * r[i + j * ld];
        }
        let norm = norm2.sqrt();
        let ratio = if norm > 0.0 { r[j + j * ld].abs() / norm } else { 0.0 };
        // NaN ratios (a column of NaN or zero norm) count as dependent too.
        if ratio.is_nan() || ratio <= tol {
            return Err(ArxError::RankDeficient { column: j, ratio });
        }
    }
    Ok(())
}

/// Column-major copy of a faer matrix.
pub fn to_col_major(m: &Mat<f64>) -> Vec<f64> {
    let mut out = Vec::with_capacity(m.nrows() * m.ncols());
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            out.push(m[(i, j)]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_qr_preserves_column_norms_and_solves() {
        // A = [[1,2],[3,4],[5,6]], y = [1,2,4]; least squares via [A | y].
        let mut a = vec![1.0, 3.0, 5.0, 2.0, 4.0, 6.0, 1.0, 2.0, 4.0];
        small_qr(&mut a, 3, 3);
        let mut theta = [0.0; 2];
        let rhs = [a[6], a[7]];
        back_substitute(&a, 3, &rhs, &mut theta);
        // Normal-equation answer computed by hand: θ = [0.5, 0.25]... verify residual orthogonality.
        let resid: Vec<f64> = (0..3)
            .map(|i| [1.0, 2.0, 4.0][i] - [1.0, 3.0, 5.0][i] * theta[0] - [2.0, 4.0, 6.0][i] * theta[1])
            .collect();
        let g0: f64 = resid.iter().zip([1.0, 3.0, 5.0]).map(|(r, x)| r * x).sum();
        let g1: f64 = resid.iter().zip([2.0, 4.0, 6.0]).map(|(r, x)| r * x).sum();
        assert!(g0.abs() < 1e-12 && g1.abs() < 1e-12);
        let rss: f64 = resid.iter().map(|r| r * r).sum();
        assert!((a[8] * a[8] - rss).abs() < 1e-12);
    }

    #[test]
    fn check_rank_names_duplicate_column() {
        let mut a = vec![1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 0.5, 0.1, 0.9];
        small_qr(&mut a, 3, 3);
        assert!(matches!(check_rank(&a, 3, 2, 1e-12), Err(ArxError::RankDeficient { column: 1, .. })));
    }

    /// R of `scale · A` is `scale · R(A)` up to row signs, at scales whose squares leave the float
    /// range (such columns are scaled by a power of two around the tall kernel) as at ordinary ones.
    #[test]
    fn r_scales_with_the_matrix_near_the_float_range_limits() {
        let a = Mat::from_fn(300, 3, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0 + (i as f64 * 0.37 + j as f64).sin());
        let r_of = |scale: f64| {
            let mut b = Mat::from_fn(300, 3, |i, j| a[(i, j)] * scale);
            qr_r_in_place(b.as_mut());
            take_r(&b, 3)
        };
        let r1 = r_of(1.0);
        for scale in [1e154, 1e-200, 1e200] {
            let r = r_of(scale);
            for j in 0..3 {
                for i in 0..=j {
                    let (want, got) = (r1[(i, j)].abs() * scale, r[(i, j)].abs());
                    assert!((got - want).abs() <= 1e-12 * want.max(r1[(0, 0)].abs() * scale), "{scale}: R[{i},{j}]");
                }
            }
            assert!(r[(2, 2)] != 0.0, "{scale}: the last column must not look dependent");
        }
        // Scaled by a power of two, R is scaled to the bit, inside the kernel's range and beyond it.
        for e in [3, 600, -700, 1000] {
            let r = r_of(times_power_of_two(1.0, e));
            let scaled = Mat::from_fn(3, 3, |i, j| times_power_of_two(r1[(i, j)], e));
            assert_eq!(r, scaled, "2^{e}");
        }
    }
}
