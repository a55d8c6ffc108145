//! The two ends of a sweep at the Python boundary, in parallel: the grid's structures from rows of
//! integers, and the results as columns (one vector per quantity, grid order) that numpy takes
//! over without another copy. On a grid of a million structures the serial versions cost as much
//! as the one-step ranking itself.

use rayon::prelude::*;

use crate::arx::structure::{OutputTerm, Structure};
use crate::error::Result;
use crate::sweep::least_squares::Swept;

/// Structures from rows `(na, nb_1..nb_m, nk_1..nk_m)` laid out one after the other (every value
/// non-negative: the caller checks). On an invalid row the error is the first invalid row's,
/// however many threads parse.
///
/// # Errors
/// As [`Structure::new`] for the first invalid row.
pub fn structures_of_rows(raw: &[i64], m: usize, terms: &[OutputTerm], parallel: bool) -> Result<Vec<Structure>> {
    let one = |r: &[i64]| {
        let orders = |v: &[i64]| v.iter().map(|&x| x as usize).collect::<Vec<usize>>();
        Structure::new(r[0] as usize, orders(&r[1..1 + m]), orders(&r[1 + m..]), terms.to_vec())
    };
    let width = 1 + 2 * m;
    if parallel {
        if let Ok(grid) = raw.par_chunks(width).map(one).collect::<Result<Vec<_>>>() {
            return Ok(grid);
        }
    }
    raw.chunks(width).map(one).collect()
}

/// The rows that decide a grid's envelope, in one pass: a row of the largest `na` and, per input
/// column, a row of the smallest delay and a row of the largest last lag among the rows that use
/// the input. The envelope of these rows is the envelope of the grid, without building a structure
/// per row.
pub fn envelope_rows(raw: &[i64], m: usize) -> Vec<i64> {
    let width = 1 + 2 * m;
    let (mut na, mut lo, mut hi) = (None::<usize>, vec![None::<usize>; m], vec![None::<usize>; m]);
    let row = |i: usize| &raw[i * width..(i + 1) * width];
    for (i, r) in raw.chunks_exact(width).enumerate() {
        if na.is_none_or(|j| r[0] > row(j)[0]) {
            na = Some(i);
        }
        for c in 0..m {
            if r[1 + c] > 0 {
                if lo[c].is_none_or(|j| r[1 + m + c] < row(j)[1 + m + c]) {
                    lo[c] = Some(i);
                }
                if hi[c].is_none_or(|j| r[1 + m + c] + r[1 + c] > row(j)[1 + m + c] + row(j)[1 + c]) {
                    hi[c] = Some(i);
                }
            }
        }
    }
    let picked = na.into_iter().chain((0..m).flat_map(|c| lo[c].into_iter().chain(hi[c])));
    picked.flat_map(|i| row(i).iter().copied()).collect()
}

/// A sweep's results as columns, grid order.
pub struct SweepColumns {
    /// Row-major `S × p_max` parameters, NaN-padded.
    pub theta: Vec<f64>,
    pub p_max: usize,
    pub rss_est: Vec<f64>,
    pub rss_val: Vec<f64>,
    pub rms_sim_est: Vec<f64>,
    pub rms_sim_val: Vec<f64>,
    pub n_sim_est: Vec<f64>,
    pub n_sim_val: Vec<f64>,
    pub norm_sim_est: Vec<f64>,
    pub norm_sim_val: Vec<f64>,
    pub diverged_est: Vec<bool>,
    pub diverged_val: Vec<bool>,
    pub errors: Vec<Option<String>>,
    pub stage: Vec<u8>,
    pub n_est: usize,
    pub n_val: usize,
    pub r_est: Vec<f64>,
}

impl SweepColumns {
    /// The columns of `swept` (on the current rayon pool when `parallel`).
    pub fn new(swept: Swept, parallel: bool) -> Self {
        let Swept { results: res, n_est, n_val, r_est } = swept;
        let p_max = res.iter().map(|r| r.theta.len()).max().unwrap_or(0);
        let mut theta = vec![f64::NAN; res.len() * p_max];
        macro_rules! column {
            ($f:expr) => {
                if parallel {
                    res.par_iter().map($f).collect()
                } else {
                    res.iter().map($f).collect()
                }
            };
        }
        if p_max > 0 {
            let copy = |(row, r): (&mut [f64], &crate::sweep::least_squares::StructureResult)| {
                row[..r.theta.len()].copy_from_slice(&r.theta)
            };
            if parallel {
                theta.par_chunks_mut(p_max).zip(res.par_iter()).for_each(copy);
            } else {
                theta.chunks_mut(p_max).zip(res.iter()).for_each(copy);
            }
        }
        let out = SweepColumns {
            theta,
            p_max,
            rss_est: column!(|r| r.rss_est),
            rss_val: column!(|r| r.rss_val),
            rms_sim_est: column!(|r| r.sim_est.rms),
            rms_sim_val: column!(|r| r.sim_val.rms),
            n_sim_est: column!(|r| r.sim_est.n as f64),
            n_sim_val: column!(|r| r.sim_val.n as f64),
            norm_sim_est: column!(|r| r.sim_est.norm),
            norm_sim_val: column!(|r| r.sim_val.norm),
            diverged_est: column!(|r| r.sim_est.diverged),
            diverged_val: column!(|r| r.sim_val.diverged),
            errors: column!(|r| r.error.as_ref().map(|e| e.to_string())),
            stage: column!(|r| r.stage),
            n_est,
            n_val,
            r_est,
        };
        release(res, parallel);
        out
    }
}

/// Drops a large vector of owners of heap memory, in parallel when asked (a million frees).
pub fn release<T: Send>(v: Vec<T>, parallel: bool) {
    if parallel {
        v.into_par_iter().for_each(drop);
    } else {
        drop(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::columns::envelope;

    /// The one-pass envelope rows give the envelope of the whole grid, and the parallel parse the
    /// serial one, errors included.
    #[test]
    fn envelope_rows_and_parse_agree_with_the_grid() {
        let mut raw = Vec::new();
        for na in 0..3i64 {
            for nb1 in 0..3 {
                for nk1 in 1..4 {
                    for nb2 in 1..3 {
                        for nk2 in 0..5 {
                            raw.extend([na, nb1, nb2, nk1, nk2]);
                        }
                    }
                }
            }
        }
        let grid = structures_of_rows(&raw, 2, &[], true).unwrap();
        let serial = structures_of_rows(&raw, 2, &[], false).unwrap();
        assert_eq!(grid, serial);
        let picked = structures_of_rows(&envelope_rows(&raw, 2), 2, &[], false).unwrap();
        assert_eq!(envelope(&picked).unwrap(), envelope(&grid).unwrap());
        let mut bad = raw.clone();
        bad.extend([1, 1 << 41, 1, 0, 0]);
        bad.extend([1, 1, 1 << 42, 0, 0]);
        let a = structures_of_rows(&bad, 2, &[], true).unwrap_err().to_string();
        assert_eq!(a, structures_of_rows(&bad, 2, &[], false).unwrap_err().to_string());
        assert!(a.contains("2199023255552"), "{a}");
    }
}
