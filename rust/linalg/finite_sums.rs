//! One-pass sums over the samples of a long series that exist: the sum of squares behind every
//! RMS of a validation error, and the largest magnitude behind the divergence rule.
//!
//! numpy takes each in two to four passes over the series (a finiteness mask, a copy of the
//! finite samples, their squares, the mean); an analysis takes a hundred of them on the validation
//! record. Here each is one pass, summed in [`LANES`] independent lanes so that the additions do not
//! wait on each other (the sums then agree with numpy's pairwise sums to rounding, not to the bit).

/// Independent partial sums: one running sum would wait on each addition.
const LANES: usize = 8;

/// `(Σ x², n)` over the `n` finite samples of `x` (an overflowing square sums to inf).
pub fn finite_squares(x: &[f64]) -> (f64, usize) {
    lane_squares(x, x, |a, _| a)
}

/// [`finite_squares`] of `y − p` (equal length), without forming the difference: the same lanes
/// and the same sum to the bit as over the array of differences.
pub fn finite_squares_of_difference(y: &[f64], p: &[f64]) -> (f64, usize) {
    assert_eq!(y.len(), p.len(), "the two series differ in length");
    lane_squares(y, p, |a, b| a - b)
}

#[inline(always)]
fn lane_squares(a: &[f64], b: &[f64], value: impl Fn(f64, f64) -> f64) -> (f64, usize) {
    let mut sums = [0.0f64; LANES];
    let mut counts = [0usize; LANES];
    let mut add = |l: usize, v: f64| {
        let finite = v.abs() <= f64::MAX; // false for ±inf and NaN
        sums[l] += if finite { v * v } else { 0.0 };
        counts[l] += usize::from(finite);
    };
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ta, tb) = (ca.remainder(), cb.remainder());
    for (x, z) in ca.zip(cb) {
        for l in 0..LANES {
            add(l, value(x[l], z[l]));
        }
    }
    for (l, (&x, &z)) in ta.iter().zip(tb).enumerate() {
        add(l, value(x, z));
    }
    (sums.iter().sum(), counts.iter().sum())
}

/// Largest |x| over the finite samples of `x` (0 when there are none).
pub fn finite_peak(x: &[f64]) -> f64 {
    lane_max(x, |v| if v.abs() <= f64::MAX { v.abs() } else { 0.0 }, 0.0)
}

/// Largest |x| over the samples of `x` that are not NaN (inf when one is infinite; NaN when every
/// sample is NaN or there are none): `max(fmax.reduce(x), -fmin.reduce(x))` in numpy's words.
pub fn peak_magnitude(x: &[f64]) -> f64 {
    lane_max(x, f64::abs, f64::NAN) // f64::max ignores a NaN operand
}

#[inline(always)]
fn lane_max(x: &[f64], magnitude: impl Fn(f64) -> f64, empty: f64) -> f64 {
    let mut peaks = [empty; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail = chunks.remainder();
    for c in chunks {
        for l in 0..LANES {
            peaks[l] = peaks[l].max(magnitude(c[l]));
        }
    }
    for (l, &v) in tail.iter().enumerate() {
        peaks[l] = peaks[l].max(magnitude(v));
    }
    peaks.iter().fold(empty, |m, &p| m.max(p))
}

/// What the fit percent of a prediction needs of one pass over `y` and `p` (equal length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitPass {
    /// Samples where both are finite.
    pub n: usize,
    /// Largest finite |y| and |p| ([`finite_peak`]).
    pub peak_y: f64,
    pub peak_p: f64,
    /// Whether `p` is infinite somewhere.
    pub p_infinite: bool,
    /// Largest |y| and the sum of y where both are finite.
    pub peak_both: f64,
    pub sum_both: f64,
}

/// [`FitPass`] of `y` and `p`, in one pass.
pub fn fit_pass(y: &[f64], p: &[f64]) -> FitPass {
    assert_eq!(y.len(), p.len(), "the two series differ in length");
    let finite = |v: f64| v.abs() <= f64::MAX;
    let (mut n, mut py, mut pp, mut pb, mut sum) =
        ([0usize; LANES], [0.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES]);
    let mut infinite = false;
    for (i, (&a, &b)) in y.iter().zip(p).enumerate() {
        let l = i % LANES;
        let (fa, fb) = (finite(a), finite(b));
        py[l] = py[l].max(if fa { a.abs() } else { 0.0 });
        pp[l] = pp[l].max(if fb { b.abs() } else { 0.0 });
        infinite |= b.is_infinite();
        let both = fa && fb;
        n[l] += usize::from(both);
        pb[l] = pb[l].max(if both { a.abs() } else { 0.0 });
        sum[l] += if both { a } else { 0.0 };
    }
    let max = |v: [f64; LANES]| v.iter().fold(0.0f64, |m, &x| m.max(x));
    FitPass {
        n: n.iter().sum(),
        peak_y: max(py),
        peak_p: max(pp),
        p_infinite: infinite,
        peak_both: max(pb),
        sum_both: sum.iter().sum(),
    }
}

/// `(Σ ((y − p)·scale)², Σ ((y − mean)·scale)²)` over the samples where `y` and `p` are both finite.
pub fn fit_squares(y: &[f64], p: &[f64], mean: f64, scale: f64) -> (f64, f64) {
    assert_eq!(y.len(), p.len(), "the two series differ in length");
    let (mut error, mut spread) = ([0.0f64; LANES], [0.0f64; LANES]);
    for (i, (&a, &b)) in y.iter().zip(p).enumerate() {
        let l = i % LANES;
        let both = a.abs() <= f64::MAX && b.abs() <= f64::MAX;
        let (e, d) = ((a - b) * scale, (a - mean) * scale);
        error[l] += if both { e * e } else { 0.0 };
        spread[l] += if both { d * d } else { 0.0 };
    }
    (error.iter().sum(), spread.iter().sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(n: usize) -> Vec<f64> {
        (0..n).map(|t| ((t * 7919) % 1013) as f64 / 101.3 - 5.0).collect()
    }

    #[test]
    fn sums_and_peaks_agree_with_the_plain_loops_at_every_length() {
        for n in [0, 1, 7, 8, 9, 100, 1001] {
            let mut x = series(n);
            for t in (3..n).step_by(17) {
                x[t] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][t % 3];
            }
            let finite: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
            let (s, k) = finite_squares(&x);
            let direct: f64 = finite.iter().map(|v| v * v).sum();
            assert_eq!(k, finite.len());
            assert!((s - direct).abs() <= 1e-12 * direct.max(1.0), "n = {n}");
            assert_eq!(finite_peak(&x), finite.iter().fold(0.0f64, |m, v| m.max(v.abs())));
            let p: Vec<f64> = series(n).iter().map(|v| 0.5 * v + 1.0).collect();
            let d: Vec<f64> = x.iter().zip(&p).map(|(a, b)| a - b).collect();
            let (sd, kd) = finite_squares_of_difference(&x, &p);
            assert_eq!((sd.to_bits(), kd), (finite_squares(&d).0.to_bits(), finite_squares(&d).1), "n = {n}");
            let has_inf = x.iter().any(|v| v.is_infinite());
            let expected = if has_inf { f64::INFINITY } else { finite.iter().fold(f64::NAN, |m, v| m.max(v.abs())) };
            let got = peak_magnitude(&x);
            assert!(got == expected || (got.is_nan() && expected.is_nan()), "n = {n}: {got} vs {expected}");
        }
    }

    #[test]
    fn the_fit_passes_agree_with_the_plain_loops() {
        for n in [0, 1, 9, 1001] {
            let mut y = series(n);
            let mut p: Vec<f64> = series(n).iter().map(|v| 0.9 * v + 0.1).collect();
            for t in (2..n).step_by(13) {
                y[t] = [f64::NAN, f64::INFINITY, 2.0][t % 3];
                p[(t + 5) % n] = [f64::NAN, f64::NEG_INFINITY, 1.0][t % 3];
            }
            let both: Vec<(f64, f64)> =
                y.iter().zip(&p).filter(|(a, b)| a.is_finite() && b.is_finite()).map(|(&a, &b)| (a, b)).collect();
            let got = fit_pass(&y, &p);
            assert_eq!(got.n, both.len());
            assert_eq!(got.peak_y, finite_peak(&y));
            assert_eq!(got.peak_p, finite_peak(&p));
            assert_eq!(got.p_infinite, p.iter().any(|v| v.is_infinite()));
            assert_eq!(got.peak_both, both.iter().fold(0.0f64, |m, (a, _)| m.max(a.abs())));
            let sum: f64 = both.iter().map(|(a, _)| a).sum();
            assert!((got.sum_both - sum).abs() <= 1e-12 * (1.0 + sum.abs()));
            let (mean, scale) = (0.25, 0.5);
            let (e, d) = fit_squares(&y, &p, mean, scale);
            let we: f64 = both.iter().map(|(a, b)| ((a - b) * scale).powi(2)).sum();
            let wd: f64 = both.iter().map(|(a, _)| ((a - mean) * scale).powi(2)).sum();
            assert!((e - we).abs() <= 1e-12 * we.max(1.0) && (d - wd).abs() <= 1e-12 * wd.max(1.0), "n = {n}");
        }
    }

    #[test]
    fn missing_samples_are_left_out_and_an_all_missing_series_says_so() {
        let x = [f64::NAN, 3.0, f64::NAN, -4.0];
        assert_eq!(finite_squares(&x), (25.0, 2));
        assert_eq!(finite_peak(&x), 4.0);
        assert_eq!(peak_magnitude(&x), 4.0);
        assert!(peak_magnitude(&[f64::NAN; 9]).is_nan());
        assert_eq!(finite_peak(&[f64::NAN, f64::INFINITY]), 0.0);
        assert_eq!(finite_squares(&[1e200, 1e200]).0, f64::INFINITY);
    }
}
