//! The regressor `[Φ | y]` of a structure reduced to its triangular factor R, block by block
//! (TSQR in fixed row blocks of [`BLOCK_ROWS`], so results do not depend on the thread count).

use faer::Mat;
use rayon::prelude::*;

use crate::arx::structure::{fill_row, Data, Structure};
use crate::error::{ensure_memory, ArxError, Result};
use crate::linalg::qr::{fill_from_samples, qr_r_in_place, reduce_memory, stack_and_reduce, take_r, BLOCK_ROWS};

/// R factor ((p+1) × (p+1), last column the output) of the regressor `[Φ | y]` of `s` over `rows`.
/// Blocks of rows are factored in parallel when `parallel`; the block R's are stacked and factored
/// again in block order.
///
/// `keep_going()` is asked before each block of [`BLOCK_ROWS`] rows (a caller may also unwind
/// from it).
///
/// # Errors
/// `OutOfMemory` when the buffers ([`reduce_memory`]) cannot be allocated; `Interrupted` when
/// `keep_going()` says no.
pub fn reduce_checked(
    d: &Data,
    s: &Structure,
    rows: &[usize],
    parallel: bool,
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Result<Mat<f64>> {
    let p = s.n_params();
    let q = p + 1;
    let threads = if parallel { rayon::current_num_threads() } else { 1 };
    ensure_memory(reduce_memory(rows.len(), q, threads), "the QR reduction of the regressor")?;
    // One block buffer per worker, reused: a fresh 4096-row buffer per block is a large
    // allocation, which an allocator told to return memory eagerly (Dask workers set
    // MALLOC_TRIM_THRESHOLD_) maps and faults in anew every time, doubling the reduction's cost.
    let block_r = |a: &mut Mat<f64>, block: &[usize]| -> Option<Mat<f64>> {
        if !keep_going() {
            return None;
        }
        // Every entry is written below, so the values the resize leaves do not matter.
        a.resize_with(block.len(), q, |_, _| 0.0);
        if s.output_terms.is_empty() {
            // Column by column: every column is the output or an input read at a fixed lag.
            fill_block_columns(d, s, block, a);
        } else {
            let mut row = vec![0.0; p];
            for (r, &t) in block.iter().enumerate() {
                fill_row(d, s, t, &mut row);
                for (c, &v) in row.iter().enumerate() {
                    a[(r, c)] = v;
                }
                a[(r, p)] = d.y[t];
            }
        }
        qr_r_in_place(a.as_mut());
        Some(take_r(a, q))
    };
    let blocks: Option<Vec<Mat<f64>>> = if parallel {
        rows.par_chunks(BLOCK_ROWS).map_init(|| Mat::<f64>::zeros(0, q), block_r).collect()
    } else {
        let mut a = Mat::<f64>::zeros(0, q);
        rows.chunks(BLOCK_ROWS).map(|block| block_r(&mut a, block)).collect()
    };
    Ok(stack_and_reduce(&blocks.ok_or(ArxError::Interrupted)?, q))
}

/// [`reduce_checked`] for callers without an error path: its error unwinds, with the [`ArxError`]
/// as payload, to the boundary that runs the computation (`python::errors` turns it back into the error).
pub fn reduce(d: &Data, s: &Structure, rows: &[usize], parallel: bool) -> Mat<f64> {
    reduce_with(d, s, rows, parallel, &|| true)
}

/// [`reduce`] asking `keep_going()` before each block (a sweep passes its progress heartbeat).
pub fn reduce_with(
    d: &Data,
    s: &Structure,
    rows: &[usize],
    parallel: bool,
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Mat<f64> {
    reduce_checked(d, s, rows, parallel, keep_going).unwrap_or_else(|e| std::panic::resume_unwind(Box::new(e)))
}

/// Writes `[Φ | y]` of a linear structure for the rows `block` into `a`, one contiguous column at a
/// time (the same values [`fill_row`] gives, without a per-element gather into a column-major matrix).
fn fill_block_columns(d: &Data, s: &Structure, block: &[usize], a: &mut Mat<f64>) {
    // Column c is sign · series[(t − lag) · stride] over the block's samples t.
    let put = |a: &mut Mat<f64>, c: usize, series: &[f64], stride: usize, lag: usize, sign: f64| {
        let dst = a.col_as_slice_mut(c);
        fill_from_samples(dst, series, block, stride, |t| (t - lag) * stride);
        if sign < 0.0 {
            dst.iter_mut().for_each(|v| *v = -*v);
        }
    };
    let mut c = 0;
    for i in 1..=s.na {
        put(a, c, d.y, 1, i, -1.0);
        c += 1;
    }
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            put(a, c, &d.u[i..], d.m, k + j, 1.0);
            c += 1;
        }
    }
    put(a, c, d.y, 1, 0, 1.0);
}
