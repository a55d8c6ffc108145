//! How well a simulation of a structure follows the measured output: its RMS error, the samples
//! it scored, and the one divergence rule that stops it.

use crate::arx::structure::{Data, Structure};

/// Outcome of a free-run (or k-step) check of one structure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimScore {
    /// Root mean square of measured − simulated output over the scored samples (NaN if diverged).
    pub rms: f64,
    /// Number of samples scored.
    pub n: usize,
    /// The simulation left any plausible range and was stopped.
    pub diverged: bool,
    /// ‖y − ȳ‖ over the scored samples, for the fit percent, when [`score`] scored a subset of the
    /// samples (missing data); NaN on the paths that score every sample from the first lag on.
    pub norm: f64,
    /// Mean of y over the same samples as `norm` (NaN where `norm` is), so that the norms of parts of
    /// a fleet scored apart can be pooled.
    pub mean: f64,
}

/// Free-run RMS of a linear structure (no output terms), the hot loop of a sweep.
///
/// The input part is accumulated first in a vectorisable pass; only the AR recursion is sequential.
/// A simulation whose output exceeds `limit` in magnitude is stopped and reported as diverged.
pub fn free_run_rms_linear(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    first_lag: usize,
    limit: f64,
    fir: &mut Vec<f64>,
) -> SimScore {
    debug_assert!(s.output_terms.is_empty());
    let lag = first_lag.max(s.max_lag());
    let na = s.na;
    let a = &theta[..na];
    let mut sse = 0.0;
    let mut count = 0usize;
    for (sa, sb) in d.segments() {
        let start = sa + lag;
        if start >= sb {
            continue;
        }
        let len = sb - start;
        fir.clear();
        fir.resize(len, 0.0);
        let mut c = na;
        for (i, (&nb, &nk)) in s.nb.iter().zip(&s.nk).enumerate() {
            for j in 0..nb {
                let bj = theta[c];
                c += 1;
                let off = start - nk - j;
                let m = d.m;
                for (idx, f) in fir.iter_mut().enumerate() {
                    *f += bj * d.u[(off + idx) * m + i];
                }
            }
        }
        // AR recursion with a small history buffer of simulated outputs (initial: measured).
        let mut hist = [0.0f64; 64];
        let big = na > 64;
        let mut hist_vec = if big { vec![0.0; na] } else { Vec::new() };
        let h: &mut [f64] = if big { &mut hist_vec } else { &mut hist[..na] };
        for (i, hv) in h.iter_mut().enumerate() {
            *hv = d.y[start - 1 - i];
        }
        for (idx, &f) in fir.iter().enumerate() {
            let mut v = f;
            for i in 0..na {
                v -= a[i] * h[i];
            }
            // NaN must count as diverged, hence the negated comparison.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            if !(v.abs() <= limit) {
                return SimScore { rms: f64::NAN, n: count, diverged: true, norm: f64::NAN, mean: f64::NAN };
            }
            if na > 0 {
                h.copy_within(0..na - 1, 1);
                h[0] = v;
            }
            let e = d.y[start + idx] - v;
            if e.is_finite() {
                sse += e * e;
                count += 1;
            }
        }
    }
    SimScore {
        rms: if count > 0 { (sse / count as f64).sqrt() } else { f64::NAN },
        n: count,
        diverged: false,
        norm: f64::NAN,
        mean: f64::NAN,
    }
}

/// A prediction whose magnitude exceeds this many times the largest measured |y| has diverged.
///
/// The one divergence rule of arxid: the sweep's free-run lanes stop there, and the Python layer
/// (`arxid._metrics`) reads it from here, so every table, comparison and ladder agrees.
pub const DIVERGENCE_FACTOR: f64 = 1e3;

/// Magnitude beyond which a prediction of the measured output `y` counts as diverged:
/// [`DIVERGENCE_FACTOR`] times the largest finite |y| (at least the smallest normal float, so that
/// an all-zero or all-missing output still has a limit).
pub fn divergence_limit(y: &[f64]) -> f64 {
    DIVERGENCE_FACTOR * crate::linalg::finite_sums::finite_peak(y).max(f64::MIN_POSITIVE)
}

/// RMS of measured − predicted over the samples where both are finite; diverged when a prediction
/// exceeds `limit` or is infinite. `norm` is ‖y − ȳ‖ over the same samples.
pub fn score(d: &Data, pred: &[f64], limit: f64) -> SimScore {
    let mut sse = 0.0;
    let mut sum_y = 0.0;
    let mut n = 0;
    for (yt, pt) in d.y.iter().zip(pred) {
        if pt.is_infinite() || pt.abs() > limit {
            return SimScore { rms: f64::NAN, n, diverged: true, norm: f64::NAN, mean: f64::NAN };
        }
        let e = yt - pt;
        if e.is_finite() {
            sse += e * e;
            sum_y += yt;
            n += 1;
        }
    }
    if n == 0 {
        return SimScore { rms: f64::NAN, n, diverged: false, norm: f64::NAN, mean: f64::NAN };
    }
    let mean = sum_y / n as f64;
    let centred: f64 =
        d.y.iter().zip(pred).filter(|(y, p)| (*y - *p).is_finite()).map(|(y, _)| (y - mean) * (y - mean)).sum();
    SimScore { rms: (sse / n as f64).sqrt(), n, diverged: false, norm: centred.sqrt(), mean }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn divergence_limit_is_the_factor_times_the_largest_finite_output() {
        assert_eq!(divergence_limit(&[1.0, -3.0, f64::NAN, 2.0]), 3.0 * DIVERGENCE_FACTOR);
        assert_eq!(divergence_limit(&[0.5, f64::INFINITY, f64::NEG_INFINITY]), 0.5 * DIVERGENCE_FACTOR);
        // No finite or only zero outputs: still a positive limit, so any nonzero prediction diverges.
        for y in [&[][..], &[0.0, -0.0][..], &[f64::NAN, f64::NAN][..]] {
            let lim = divergence_limit(y);
            assert!(lim > 0.0 && lim == DIVERGENCE_FACTOR * f64::MIN_POSITIVE, "{y:?}: {lim}");
        }
    }
}
