//! The regressor `[Φ | y]` of a structure reduced to its triangular factor R, block by block
//! (TSQR in fixed row blocks of [`BLOCK_ROWS`], so results do not depend on the thread count).

use faer::Mat;
use rayon::prelude::*;

use crate::arx::structure::{fill_row, Data, Structure};
use crate::error::{ensure_memory, ArxError, Result};
use crate::linalg::qr::{fill_from_samples, qr_r_in_place, reduce_memory, stack_and_reduce, take_r, BLOCK_ROWS};

/// Block factors stacked and reduced this many at a time, level by level (a tree fixed by the
/// number of blocks). One QR of all the stacked factors (26 of 611 columns at 100k rows) ran for a
/// second or more without a look at Ctrl-C; a group costs about half of one block's QR, and the
/// groups of a level run side by side.
const STACK_GROUP: usize = 4;

/// Blocks of rows per parallel task of the reduction (each task allocates one block buffer).
const BLOCKS_PER_TASK: usize = 4;

/// R factor ((p+1) × (p+1), last column the output) of the regressor `[Φ | y]` of `s` over `rows`.
/// Blocks of rows are factored in parallel when `parallel`; the block R's are stacked and factored
/// again in block order, [`STACK_GROUP`] at a time ([`reduce_factors`]).
///
/// `keep_going()` is asked before each block of [`BLOCK_ROWS`] rows and each group of stacked
/// factors (a caller may also unwind from it).
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
    let inputs: Vec<(&[f64], usize)> = (0..d.m).map(|i| (&d.u[i..], d.m)).collect();
    let fill = |block: &[usize], a: &mut Mat<f64>| {
        if s.output_terms.is_empty() {
            // Column by column: every column is the output or an input read at a fixed lag.
            fill_block_columns(d.y, &inputs, s, block, a);
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
    };
    reduce_filled(p + 1, rows, parallel, keep_going, &fill)
}

/// [`reduce_checked`] of a linear structure whose inputs are separate series, each read with its
/// own stride (`inputs[i] = (samples, stride)`, sample t of input i at `samples[t * stride]`): the
/// same blocks, so the same R to the bit as from the inputs side by side in one row-major matrix.
///
/// # Errors
/// As [`reduce_checked`]; `InvalidStructure` when the structure has output terms.
pub fn reduce_series(
    y: &[f64],
    inputs: &[(&[f64], usize)],
    s: &Structure,
    rows: &[usize],
    parallel: bool,
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Result<Mat<f64>> {
    if !s.output_terms.is_empty() {
        return Err(ArxError::InvalidStructure("output terms need the inputs side by side".into()));
    }
    let fill = |block: &[usize], a: &mut Mat<f64>| fill_block_columns(y, inputs, s, block, a);
    reduce_filled(s.n_params() + 1, rows, parallel, keep_going, &fill)
}

/// The TSQR reduction of the `q` columns `fill(block, a)` writes for each block of `rows`.
fn reduce_filled(
    q: usize,
    rows: &[usize],
    parallel: bool,
    keep_going: &(dyn Fn() -> bool + Sync),
    fill: &(dyn Fn(&[usize], &mut Mat<f64>) + Sync),
) -> Result<Mat<f64>> {
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
        fill(block, a);
        qr_r_in_place(a.as_mut());
        Some(take_r(a, q))
    };
    let blocks: Option<Vec<Mat<f64>>> = if parallel {
        // At most BLOCKS_PER_TASK blocks per task, each with its buffer: a few milliseconds, so
        // that idle workers take over the blocks of one the system deschedules.
        rows.par_chunks(BLOCK_ROWS)
            .with_max_len(BLOCKS_PER_TASK)
            .map_init(|| Mat::<f64>::zeros(0, q), block_r)
            .collect()
    } else {
        let mut a = Mat::<f64>::zeros(0, q);
        rows.chunks(BLOCK_ROWS).map(|block| block_r(&mut a, block)).collect()
    };
    reduce_factors(blocks.ok_or(ArxError::Interrupted)?, q, parallel, keep_going).ok_or(ArxError::Interrupted)
}

/// The R of the stacked upper-triangular factors `rs` (in their order), reduced [`STACK_GROUP`] at a
/// time, level by level; None once `keep_going()` says no (asked before each group).
fn reduce_factors(
    mut rs: Vec<Mat<f64>>,
    q: usize,
    parallel: bool,
    keep_going: &(dyn Fn() -> bool + Sync),
) -> Option<Mat<f64>> {
    let group = |g: &[Mat<f64>]| keep_going().then(|| stack_and_reduce(g, q));
    while rs.len() > STACK_GROUP {
        rs = if parallel {
            rs.par_chunks(STACK_GROUP).with_max_len(1).map(group).collect::<Option<Vec<_>>>()?
        } else {
            rs.chunks(STACK_GROUP).map(group).collect::<Option<Vec<_>>>()?
        };
    }
    group(&rs)
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
/// time (the same values [`fill_row`] gives, without a per-element gather into a column-major matrix);
/// input i's sample t is `inputs[i].0[t * inputs[i].1]`.
fn fill_block_columns(y: &[f64], inputs: &[(&[f64], usize)], s: &Structure, block: &[usize], a: &mut Mat<f64>) {
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
        put(a, c, y, 1, i, -1.0);
        c += 1;
    }
    for (&(series, stride), (&b, &k)) in inputs.iter().zip(s.nb.iter().zip(&s.nk)) {
        for j in 0..b {
            put(a, c, series, stride, k + j, 1.0);
            c += 1;
        }
    }
    put(a, c, y, 1, 0, 1.0);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eleven 5 × 5 triangular factors of a deterministic pseudo-random matrix (three levels of groups).
    fn factors() -> Vec<Mat<f64>> {
        let mut x = 0.5_f64;
        (0..11)
            .map(|_| {
                let mut a = Mat::from_fn(9, 5, |_, _| {
                    x = (x * 3.9 * (1.0 - x)).clamp(1e-3, 1.0 - 1e-3);
                    x - 0.5
                });
                qr_r_in_place(a.as_mut());
                take_r(&a, 5)
            })
            .collect()
    }

    #[test]
    fn grouped_reduction_gives_the_r_of_the_whole_stack_up_to_row_signs() {
        let whole = stack_and_reduce(&factors(), 5);
        for parallel in [false, true] {
            let grouped = reduce_factors(factors(), 5, parallel, &|| true).unwrap();
            for i in 0..5 {
                for j in 0..5 {
                    assert!((grouped[(i, j)].abs() - whole[(i, j)].abs()).abs() < 1e-12, "{i} {j}");
                }
            }
        }
    }

    #[test]
    fn grouped_reduction_stops_when_told() {
        let asked = std::sync::atomic::AtomicUsize::new(0);
        let keep_going = || asked.fetch_add(1, std::sync::atomic::Ordering::Relaxed) < 2;
        assert!(reduce_factors(factors(), 5, false, &keep_going).is_none());
        assert_eq!(asked.load(std::sync::atomic::Ordering::Relaxed), 3);
    }
}
