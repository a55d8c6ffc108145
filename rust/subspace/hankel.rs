//! The lower-triangular factor L of the block-Hankel data (its LQ factor; L Lᵀ = MᵀM/N).
//!
//! Row t of the (never formed) matrix M holds, in this column order,
//! `U_f = u(t) … u(t+f−1)`, `W_p = [u(t−p) … u(t−1), y(t−p) … y(t−1)]` and
//! `Y_f = y(t) … y(t+f−1)`; Mᵀ is the block-Hankel matrix of Van Overschee & De Moor (1996) with
//! the future inputs first, so `Mᵀ = L Qᵀ` is its LQ factorisation. Only L is needed, and L is
//! the Cholesky factor of MᵀM up to the signs of its columns (which change no projection, singular
//! value or left singular vector downstream). MᵀM comes from the Toeplitz structure of the lagged
//! columns ([`crate::linalg::lagged_gram`], 40× less work than a QR of M), and its Cholesky factor
//! is kept when every pivot holds at least
//! [`crate::linalg::lagged_gram::PIVOT_FLOOR`] of its column's size: the factor is
//! then as accurate as the QR's to about 1e-10 relative. Otherwise (noise-free data, where the
//! future outputs are exact functions of the rest, or a column that repeats another) M is reduced
//! by the crate's Householder TSQR ([`crate::linalg::lagged_qr`]), which keeps the zeros exact.
//! Memory is one block of rows per thread either way, whatever N. Several experiments (or
//! NaN-free segments) each contribute their own rows: their products add.

use std::sync::atomic::AtomicBool;

use faer::Mat;

use crate::error::{ArxError, Result};
use crate::linalg::lagged_gram::{cholesky_if_well_conditioned, lagged_gram};
use crate::linalg::lagged_qr::{lagged_r, LaggedColumn, Source};

/// The signals of several experiments laid end to end: `u` is N × nu and `y` is N × ny, both
/// row-major; `segments` are the `[start, end)` sample ranges of the experiments.
#[derive(Clone, Copy, Debug)]
pub struct Signals<'a> {
    pub u: &'a [f64],
    pub y: &'a [f64],
    pub n_inputs: usize,
    pub n_outputs: usize,
    pub segments: &'a [(usize, usize)],
}

impl Signals<'_> {
    /// Number of samples N.
    pub fn n_samples(&self) -> usize {
        self.y.len() / self.n_outputs.max(1)
    }

    /// Checks the array lengths, the segments and that every sample is finite.
    ///
    /// # Errors
    /// `ShapeMismatch` for arrays of the wrong length, `InvalidStructure` for a segment outside
    /// the data or reversed, `ShapeMismatch` naming a non-finite sample.
    pub fn check(&self) -> Result<()> {
        if self.n_outputs == 0 {
            return Err(ArxError::InvalidStructure("a state-space model needs at least one output".into()));
        }
        let n = self.n_samples();
        if self.y.len() != n * self.n_outputs {
            return Err(ArxError::ShapeMismatch {
                what: "the outputs".into(),
                expected: n * self.n_outputs,
                got: self.y.len(),
            });
        }
        if self.u.len() != n * self.n_inputs {
            return Err(ArxError::ShapeMismatch {
                what: "the inputs".into(),
                expected: n * self.n_inputs,
                got: self.u.len(),
            });
        }
        for &(a, b) in self.segments {
            if a > b || b > n {
                return Err(ArxError::InvalidStructure(format!("segment {a}..{b} lies outside the {n} samples")));
            }
        }
        if !self.u.iter().chain(self.y).all(|v| v.is_finite()) {
            return Err(ArxError::InvalidStructure(
                "the signals hold a NaN or infinite sample; split the data into segments without them".into(),
            ));
        }
        Ok(())
    }
}

/// Past and future horizons (block rows) of the Hankel matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Horizons {
    pub past: usize,
    pub future: usize,
}

/// The lower-triangular factor L (q × q, q = f·nu + p·(nu+ny) + f·ny) of the block-Hankel data,
/// scaled by 1/√rows so its size does not grow with N, and the number of Hankel columns used.
#[derive(Debug)]
pub struct HankelFactor {
    pub l: Mat<f64>,
    pub n_rows: usize,
    /// Sizes of the blocks U_f, W_p and Y_f.
    pub blocks: (usize, usize, usize),
}

/// L of the block-Hankel data of `signals` with horizons `h`.
///
/// # Errors
/// `TooFewSamples` when the segments give fewer Hankel columns than L has rows (the factor would
/// be singular), `Interrupted` on Ctrl-C, and the errors of [`crate::linalg::lagged_qr::lagged_r`] (the
/// same read checks as [`crate::linalg::lagged_gram::lagged_gram`]).
pub fn hankel_factor(signals: &Signals<'_>, h: Horizons, parallel: bool, cancel: &AtomicBool) -> Result<HankelFactor> {
    let (nu, ny) = (signals.n_inputs, signals.n_outputs);
    let (p, f) = (h.past as isize, h.future as isize);
    let n = signals.n_samples();
    let sources = [
        Source { values: signals.u, rows: n, columns: nu, row_stride: nu, col_stride: 1 },
        Source { values: signals.y, rows: n, columns: ny, row_stride: ny, col_stride: 1 },
    ];
    let block = |source: usize, width: usize, lags: Vec<isize>| {
        lags.into_iter().flat_map(move |lag| (0..width).map(move |column| LaggedColumn { source, column, lag }))
    };
    let columns: Vec<LaggedColumn> = block(0, nu, (0..f).map(|k| -k).collect())
        .chain(block(0, nu, (0..p).map(|k| p - k).collect()))
        .chain(block(1, ny, (0..p).map(|k| p - k).collect()))
        .chain(block(1, ny, (0..f).map(|k| -k).collect()))
        .collect();
    let ranges: Vec<(usize, usize)> =
        signals.segments.iter().map(|&(a, b)| (a + h.past, (b + 1).saturating_sub(h.future).max(a + h.past))).collect();
    let n_rows: usize = ranges.iter().map(|(lo, hi)| hi - lo).sum();
    let q = columns.len();
    if n_rows < q {
        return Err(ArxError::TooFewSamples { needed: q + h.past + h.future, got: n_rows + h.past + h.future });
    }
    let gram = lagged_gram(&sources, &columns, &ranges, parallel, cancel)?;
    let l = match cholesky_if_well_conditioned(&gram) {
        Some(l) => Mat::from_fn(q, q, |i, j| l[(i, j)] / (n_rows as f64).sqrt()),
        None => householder_factor(&sources, &columns, &ranges, parallel, cancel)?,
    };
    let (uf, wp) = (h.future * nu, h.past * (nu + ny));
    Ok(HankelFactor { l, n_rows, blocks: (uf, wp, h.future * ny) })
}

/// L by the Householder TSQR of M's rows, scaled by 1/√rows.
fn householder_factor(
    sources: &[Source<'_>],
    columns: &[LaggedColumn],
    ranges: &[(usize, usize)],
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<Mat<f64>> {
    let rows: Vec<usize> = ranges.iter().flat_map(|&(lo, hi)| lo..hi).collect();
    let factor = lagged_r(sources, columns, &rows, false, parallel, cancel)?;
    let (q, scale) = (columns.len(), 1.0 / (factor.n_rows as f64).sqrt());
    Ok(Mat::from_fn(q, q, |i, j| if j <= i { factor.r[j + i * q] * scale } else { 0.0 }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_factor_reproduces_the_products_of_the_hankel_rows() {
        let n = 300;
        let u: Vec<f64> = (0..n).map(|t| ((t * 37) % 11) as f64 - 5.0).collect();
        let y: Vec<f64> = (0..2 * n).map(|i| ((i * 13) % 7) as f64 * 0.5).collect();
        let segments = [(0, 120), (120, n)];
        let s = Signals { u: &u, y: &y, n_inputs: 1, n_outputs: 2, segments: &segments };
        let h = Horizons { past: 2, future: 3 };
        let never = AtomicBool::new(false);
        let f = hankel_factor(&s, h, false, &never).unwrap();
        assert_eq!(f.blocks, (3, 6, 6));
        // Row of M at t, built directly.
        let row = |t: usize| -> Vec<f64> {
            let mut r: Vec<f64> = (0..3).map(|k| u[t + k]).collect();
            r.extend((0..2).map(|k| u[t - 2 + k]));
            r.extend((0..2).flat_map(|k| [y[2 * (t - 2 + k)], y[2 * (t - 2 + k) + 1]]));
            r.extend((0..3).flat_map(|k| [y[2 * (t + k)], y[2 * (t + k) + 1]]));
            r
        };
        let ts: Vec<usize> = (2..118).chain(122..n - 2).collect();
        assert_eq!(f.n_rows, ts.len());
        let q = 15;
        for i in 0..q {
            for j in 0..q {
                let direct: f64 = ts.iter().map(|&t| row(t)[i] * row(t)[j]).sum::<f64>() / ts.len() as f64;
                let from_l: f64 = (0..q).map(|k| f.l[(i, k)] * f.l[(j, k)]).sum();
                assert!((direct - from_l).abs() < 1e-10 * direct.abs().max(1.0), "{i} {j}");
            }
        }
    }

    /// On noisy data the factor comes from the Gram (every pivot above the floor) and agrees with
    /// the Householder factor in its products, L Lᵀ, to rounding.
    #[test]
    fn the_gram_factor_agrees_with_the_householder_factor_on_noisy_data() {
        let n = 3000;
        let mut seed = 7u64;
        let mut noise = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let u: Vec<f64> = (0..2 * n).map(|_| noise()).collect();
        let mut y = vec![0.0; n];
        for t in 1..n {
            y[t] = 0.8 * y[t - 1] + u[2 * (t - 1)] - 0.5 * u[2 * (t - 1) + 1] + 0.1 * noise();
        }
        let segments = [(0, 1700), (1700, n)];
        let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 1, segments: &segments };
        let h = Horizons { past: 3, future: 4 };
        let never = AtomicBool::new(false);
        let f = hankel_factor(&s, h, true, &never).unwrap();
        let sources = [
            Source { values: &u, rows: n, columns: 2, row_stride: 2, col_stride: 1 },
            Source { values: &y, rows: n, columns: 1, row_stride: 1, col_stride: 1 },
        ];
        let block = |source, width, lags: Vec<isize>| {
            lags.into_iter().flat_map(move |lag| (0..width).map(move |column| LaggedColumn { source, column, lag }))
        };
        let columns: Vec<LaggedColumn> = block(0, 2, vec![0, -1, -2, -3])
            .chain(block(0, 2, vec![3, 2, 1]))
            .chain(block(1, 1, vec![3, 2, 1]))
            .chain(block(1, 1, vec![0, -1, -2, -3]))
            .collect();
        let ranges = [(3, 1697), (1703, n - 3)];
        let gram = lagged_gram(&sources, &columns, &ranges, true, &never).unwrap();
        assert!(cholesky_if_well_conditioned(&gram).is_some());
        let qr = householder_factor(&sources, &columns, &ranges, true, &never).unwrap();
        let q = columns.len();
        for i in 0..q {
            for j in 0..q {
                let (from_gram, from_qr): (f64, f64) =
                    (0..q).fold((0.0, 0.0), |(g, r), k| (g + f.l[(i, k)] * f.l[(j, k)], r + qr[(i, k)] * qr[(j, k)]));
                assert!((from_gram - from_qr).abs() < 1e-12 * from_qr.abs().max(1.0), "{i} {j}");
            }
        }
    }
}
