//! One-step prediction and free run of a linear structure (no output terms) over one experiment:
//! the paths [`crate::simulate::predict::predict_cancellable`] takes when no output term and (for the free
//! run) no missing sample calls for its general step; after a gap, the free run restarts here too.
//!
//! The input part $\sum_i \sum_j b_{ij} u_i(t - n_{k,i} - j)$ is computed first, a chunk of samples
//! at a time, by passes over contiguous input columns that the compiler vectorises. The one-step
//! prediction adds the AR part on the measured outputs the same way (no recursion at all); the free
//! run adds it in a recursion that keeps the last outputs in registers and adds the $y(t-1)$ term
//! last, so that the dependency chain from one sample to the next is a single multiply-add. The
//! sums run in another order than the general step's, so the numbers agree with it to rounding
//! (relative 1e-12 of the output's scale for stable models), not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::arx::structure::{Data, Structure};
use crate::error::{ArxError, Result};
use crate::linalg::simd::{all_finite, avx2_fma, madd};

/// Samples per chunk: the chunk of predictions and the chunk's input columns stay in cache. The
/// cancel flag is read once per chunk.
pub(crate) const CHUNK: usize = 2048;

/// Predictions computed side by side in registers by [`sums`].
const WIDTH: usize = 8;

/// The input part's terms as `(b, offset)`: `b · column[τ + offset]` for the prediction τ of a
/// chunk, where the columns of [`Chunk`] start `reach` samples before the chunk. Each input's
/// terms in order j = 0, 1, ….
pub(crate) struct Taps {
    pub(crate) taps: Vec<(f64, usize)>,
    /// Largest lag any input term reads (nk + nb − 1).
    reach: usize,
}

impl Taps {
    pub(crate) fn new(s: &Structure, theta: &[f64]) -> Self {
        let reach = s.nb.iter().zip(&s.nk).filter(|(&b, _)| b > 0).map(|(&b, &k)| k + b - 1).max().unwrap_or(0);
        let stride = CHUNK + reach;
        let mut taps = Vec::with_capacity(theta.len());
        let mut c = s.na;
        for (i, (&nb, &nk)) in s.nb.iter().zip(&s.nk).enumerate() {
            for j in 0..nb {
                taps.push((theta[c + j], i * stride + reach - nk - j));
            }
            c += nb;
        }
        Taps { taps, reach }
    }

    /// The inputs of samples `[t0 − reach, t1)` as one column per input (`stride` apart in
    /// `scratch`), or the input itself when there is only one.
    pub(crate) fn columns<'a>(&self, d: &'a Data, (t0, t1): (usize, usize), scratch: &'a mut Vec<f64>) -> &'a [f64] {
        let first = t0 - self.reach;
        if self.taps.is_empty() {
            return &[]; // a pure AR model reads no input
        }
        if d.m == 1 {
            return &d.u[first..t1];
        }
        let stride = CHUNK + self.reach;
        scratch.resize(stride * d.m, 0.0);
        let rows = &d.u[first * d.m..t1 * d.m];
        match d.m {
            2 => split::<2>(rows, stride, scratch),
            3 => split::<3>(rows, stride, scratch),
            4 => split::<4>(rows, stride, scratch),
            m => {
                for (q, row) in rows.chunks_exact(m).enumerate() {
                    for (i, &v) in row.iter().enumerate() {
                        scratch[i * stride + q] = v;
                    }
                }
            }
        }
        scratch
    }
}

/// Rows of `M` inputs into one column per input, `stride` apart in `cols`: with `M` known, the
/// compiler unrolls the row and drops the bounds checks.
#[inline(always)]
fn split<const M: usize>(rows: &[f64], stride: usize, cols: &mut [f64]) {
    let n = rows.len() / M;
    let mut parts: [&mut [f64]; M] = std::array::from_fn(|_| &mut [][..]);
    for (part, col) in parts.iter_mut().zip(cols.chunks_exact_mut(stride)) {
        *part = &mut col[..n];
    }
    for (q, row) in rows.chunks_exact(M).enumerate() {
        for i in 0..M {
            parts[i][q] = row[i];
        }
    }
}

/// `x[τ] = Σ c · u[τ + offset] + Σ c · y[τ + offset]` over `u_taps` then `y_taps`, in that order,
/// [`WIDTH`] predictions at a time in registers (one store per prediction, not one per term).
#[inline(always)]
pub(crate) fn sums<const FMA: bool>(
    x: &mut [f64],
    u: &[f64],
    u_taps: &[(f64, usize)],
    y: &[f64],
    y_taps: &[(f64, usize)],
) {
    let done = x.len() - x.len() % WIDTH;
    for (b, block) in x.chunks_exact_mut(WIDTH).enumerate() {
        let tau = b * WIDTH;
        let mut acc = [0.0; WIDTH];
        for (src, taps) in [(u, u_taps), (y, y_taps)] {
            for &(c, off) in taps {
                let v = &src[off + tau..off + tau + WIDTH];
                for l in 0..WIDTH {
                    acc[l] = madd::<FMA>(c, v[l], acc[l]);
                }
            }
        }
        block.copy_from_slice(&acc);
    }
    for (tau, xv) in x.iter_mut().enumerate().skip(done) {
        let mut acc = 0.0;
        for (src, taps) in [(u, u_taps), (y, y_taps)] {
            for &(c, off) in taps {
                acc = madd::<FMA>(c, src[off + tau], acc);
            }
        }
        *xv = acc;
    }
}

/// One-step-ahead prediction of `s` (no output terms) for `t` in `[start, end)` into `out[t]`,
/// from the measured outputs. `start` is at least the structure's lag into its experiment. A
/// missing (NaN) sample makes the predictions that read it NaN.
///
/// # Errors
/// `Interrupted` once `cancel` is set (read every [`CHUNK`] samples).
pub fn one_step(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<()> {
    debug_assert!(s.output_terms.is_empty() && theta.len() == s.n_params());
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { one_step_avx2(d, s, theta, rows, out, cancel) };
    }
    one_step_impl::<false>(d, s, theta, rows, out, cancel)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn one_step_avx2(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<()> {
    one_step_impl::<true>(d, s, theta, rows, out, cancel)
}

#[inline(always)]
fn one_step_impl<const FMA: bool>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    (start, end): (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<()> {
    let taps = Taps::new(s, theta);
    // −a_i · y(t − i), read from the outputs starting na samples before the chunk.
    let y_taps: Vec<(f64, usize)> = theta[..s.na].iter().enumerate().map(|(i, &a)| (-a, s.na - 1 - i)).collect();
    let mut scratch = Vec::new();
    let mut t0 = start;
    while t0 < end {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let t1 = (t0 + CHUNK).min(end);
        let u = taps.columns(d, (t0, t1), &mut scratch);
        sums::<FMA>(&mut out[t0..t1], u, &taps.taps, &d.y[t0 - s.na..t1], &y_taps);
        t0 = t1;
    }
    Ok(())
}

/// Free run of `s` (no output terms) for `t` in `[start, end)` into `out[t]`, from the measured
/// outputs before `start` as initial conditions; whether every simulated output is finite.
///
/// When one is not, either the simulation diverged (overflow to inf/NaN, which stays) or it read a
/// missing sample: the caller tells them apart and sends the latter through the general step,
/// which restarts from the measurements after the gap.
///
/// # Errors
/// `Interrupted` once `cancel` is set (read every [`CHUNK`] samples).
pub fn free_run(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<bool> {
    debug_assert!(s.output_terms.is_empty() && theta.len() == s.n_params());
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { free_run_avx2(d, s, theta, rows, out, cancel) };
    }
    free_run_sized::<false>(d, s, theta, rows, out, cancel)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn free_run_avx2(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<bool> {
    free_run_sized::<true>(d, s, theta, rows, out, cancel)
}

/// [`free_run_with`] with the history in an array of a size known at compile time for small na,
/// so that it stays in registers.
#[inline(always)]
fn free_run_sized<const FMA: bool>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<bool> {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match s.na {
                $($n => {
                    let mut neg_a = [0.0; $n];
                    let mut h = [0.0; $n];
                    free_run_with::<FMA>(d, s, theta, rows, out, cancel, &mut neg_a, &mut h)
                })*
                na => free_run_with::<FMA>(d, s, theta, rows, out, cancel, &mut vec![0.0; na], &mut vec![0.0; na]),
            }
        };
    }
    fixed!(0 1 2 3 4 5 6 7 8)
}

/// [`free_run`] with `neg_a` and `h` (na long each) as room for −a and the history (`h[i]` = the
/// output i + 1 steps back).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn free_run_with<const FMA: bool>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    (start, end): (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
    neg_a: &mut [f64],
    h: &mut [f64],
) -> Result<bool> {
    let na = neg_a.len();
    for i in 0..na {
        neg_a[i] = -theta[i];
        h[i] = d.y[start - 1 - i];
    }
    let taps = Taps::new(s, theta);
    let mut scratch = Vec::new();
    let mut finite = true;
    let mut t0 = start;
    while t0 < end {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let t1 = (t0 + CHUNK).min(end);
        let x = &mut out[t0..t1];
        sums::<FMA>(x, taps.columns(d, (t0, t1), &mut scratch), &taps.taps, &[], &[]);
        if na > 0 {
            for xv in x.iter_mut() {
                // The older outputs first: only the y(t − 1) term waits for the previous sample.
                let mut acc = *xv;
                for i in (1..na).rev() {
                    acc = madd::<FMA>(neg_a[i], h[i], acc);
                }
                acc = madd::<FMA>(neg_a[0], h[0], acc);
                for i in (1..na).rev() {
                    h[i] = h[i - 1];
                }
                h[0] = acc;
                *xv = acc;
            }
        }
        finite &= all_finite(x);
        t0 = t1;
    }
    Ok(finite)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::simulate::predict::{predict, predict_cancellable, step_reference};

    /// Uniform numbers in [-0.5, 0.5) from a fixed seed (also the output-term free run's tests).
    pub(crate) struct Lcg(pub(crate) u64);
    impl Lcg {
        pub(crate) fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        }
        pub(crate) fn below(&mut self, n: usize) -> usize {
            ((self.next() + 0.5) * n as f64) as usize % n
        }
    }

    /// A(q) = Π (1 − p q⁻¹) for real poles |p| < 0.95: the a coefficients of a stable model.
    fn stable_a(rng: &mut Lcg, na: usize) -> Vec<f64> {
        let mut poly = vec![1.0];
        for _ in 0..na {
            let p = 1.9 * rng.next();
            let mut next = poly.clone();
            next.push(0.0);
            for (k, c) in poly.iter().enumerate() {
                next[k + 1] -= p * c;
            }
            poly = next;
        }
        poly[1..].to_vec()
    }

    /// A random stable structure of 1 to `max_inputs` inputs, na below `na_below`, nb below 4 and nk
    /// below 3 per input, with its θ and number of inputs (None when it has no parameter).
    fn random_stable(rng: &mut Lcg, max_inputs: usize, na_below: usize) -> Option<(Structure, Vec<f64>, usize)> {
        let m = 1 + rng.below(max_inputs);
        let na = rng.below(na_below);
        let nb: Vec<usize> = (0..m).map(|_| rng.below(4)).collect();
        let nk: Vec<usize> = (0..m).map(|_| rng.below(3)).collect();
        let n_b = nb.iter().sum::<usize>();
        if na + n_b == 0 {
            return None;
        }
        let s = Structure::new(na, nb, nk, vec![]).unwrap();
        let mut theta = stable_a(rng, na);
        theta.extend((0..n_b).map(|_| 2.0 * rng.next()));
        Some((s, theta, m))
    }

    /// The fast paths agree with the general step (run sample by sample on the same history) to
    /// 1e-12 of the output's scale, on random stable structures with several inputs, several
    /// experiments and a first lag beyond the structure's; an experiment with a missing input
    /// takes the general path in free run and predicts NaN in the same samples one step ahead.
    #[test]
    fn fast_paths_agree_with_the_general_step() {
        let mut rng = Lcg(7);
        for case in 0..60 {
            // na 9 and 10 take the general-size history
            let Some((s, theta, m)) = random_stable(&mut rng, 3, 11) else { continue };
            let n = 5000 + rng.below(200);
            let mut u: Vec<f64> = (0..n * m).map(|_| 10.0 * rng.next()).collect();
            let y: Vec<f64> = (0..n).map(|_| 100.0 * rng.next()).collect();
            let starts = [0, 1300, 4100 + rng.below(400)];
            if case % 4 == 0 {
                u[(starts[1] + 500) * m] = f64::NAN; // the second experiment has a gap
            }
            let d = Data::new(&y, &u, m, &starts).unwrap();
            let first_lag = s.max_lag() + rng.below(3);
            for horizon in [None, Some(1)] {
                let fast = predict(&d, &s, &theta, horizon, first_lag);
                let general = step_reference(&d, &s, &theta, horizon, first_lag);
                let scale = general.iter().filter(|v| v.is_finite()).fold(0.0f64, |a, v| a.max(v.abs()));
                assert!(scale > 0.0);
                for (t, (f, g)) in fast.iter().zip(&general).enumerate() {
                    assert_eq!(f.is_nan(), g.is_nan(), "case {case} {horizon:?} t={t}");
                    if g.is_finite() {
                        assert!((f - g).abs() <= 1e-12 * scale, "case {case} {horizon:?} t={t}: {f} vs {g}");
                    }
                }
            }
        }
    }

    /// Records with gaps (every signal missing over a stretch, the output alone, one input alone,
    /// gaps shorter than the lags, at an experiment's start and end): the free run restarts after
    /// each gap in the fast recursion, and agrees with the general step sample by sample (NaN in the
    /// same samples, the rest to 1e-12 of the output's scale).
    #[test]
    fn free_run_restarts_after_gaps_as_the_general_step_does() {
        let mut rng = Lcg(11);
        for case in 0..80 {
            let Some((s, theta, m)) = random_stable(&mut rng, 2, 10) else { continue };
            let n = 6000;
            let mut u: Vec<f64> = (0..n * m).map(|_| 10.0 * rng.next()).collect();
            let mut y: Vec<f64> = (0..n).map(|_| 100.0 * rng.next()).collect();
            for _ in 0..12 {
                let at = rng.below(n - 30);
                let len = 1 + rng.below(if case % 2 == 0 { 4 } else { 25 });
                let which = rng.below(3);
                for t in at..at + len {
                    if which != 1 {
                        y[t] = f64::NAN; // the output (and, for 0, every signal)
                    }
                    if which != 2 {
                        u[t * m + rng.below(m)] = f64::NAN;
                    }
                    if which == 0 {
                        u[t * m..(t + 1) * m].fill(f64::NAN);
                    }
                }
            }
            let d = Data::new(&y, &u, m, &[0, 2500]).unwrap();
            let first_lag = s.max_lag() + rng.below(2);
            let fast = predict(&d, &s, &theta, None, first_lag);
            let general = step_reference(&d, &s, &theta, None, first_lag);
            let scale = general.iter().filter(|v| v.is_finite()).fold(0.0f64, |a, v| a.max(v.abs()));
            for (t, (f, g)) in fast.iter().zip(&general).enumerate() {
                assert_eq!((f.is_nan(), f.is_infinite()), (g.is_nan(), g.is_infinite()), "case {case} t={t}");
                if g.is_finite() {
                    assert!((f - g).abs() <= 1e-12 * scale, "case {case} t={t}: {f} vs {g}");
                }
            }
        }
    }

    /// A diverging free run keeps its overflow (no restart), and a missing sample in an input the
    /// structure does not read leaves the plain recursion in place: both as the general step does.
    #[test]
    fn free_run_overflow_and_unread_gaps_match_the_general_step() {
        let n = 3000;
        let mut rng = Lcg(3);
        let mut u: Vec<f64> = (0..2 * n).map(|_| rng.next()).collect();
        let y: Vec<f64> = (0..n).map(|_| rng.next()).collect();
        u[2 * 1000 + 1] = f64::NAN; // input 2, which nb = 0 leaves unread
        let d = Data::new(&y, &u, 2, &[0, 1500]).unwrap();
        let s = Structure::new(1, vec![2, 0], vec![1, 0], vec![]).unwrap();
        for (theta, diverges) in [([-3.0, 1.0, 0.5], true), ([-0.5, 1.0, 0.5], false)] {
            let fast = predict(&d, &s, &theta, None, 0);
            let general = step_reference(&d, &s, &theta, None, 0);
            assert_eq!(fast.iter().any(|v| v.is_infinite()), diverges);
            for (t, (f, g)) in fast.iter().zip(&general).enumerate() {
                assert_eq!((f.is_nan(), f.is_infinite()), (g.is_nan(), g.is_infinite()), "t={t}");
                if g.is_finite() {
                    assert!((f - g).abs() <= 1e-12 * g.abs().max(1.0), "t={t}: {f} vs {g}");
                }
            }
        }
    }

    #[test]
    fn fast_paths_stop_when_cancelled() {
        let n = 3 * CHUNK;
        let u: Vec<f64> = (0..n).map(|t| (t % 7) as f64).collect();
        let y = vec![1.0; n];
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        let s = Structure::new(2, vec![2], vec![1], vec![]).unwrap();
        let theta = [-0.5, 0.1, 1.0, 0.5];
        let cancel = AtomicBool::new(true);
        for horizon in [None, Some(1)] {
            let got = predict_cancellable(&d, &s, &theta, horizon, 0, &cancel);
            assert!(matches!(got, Err(ArxError::Interrupted)), "{horizon:?}");
        }
    }
}

#[cfg(test)]
mod perf_probe {
    use super::*;

    /// Timing of the fast paths on 2M samples (ignored by default; `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn fast_paths_timing() {
        let n = 2_000_000;
        let mut seed = 5u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..2 * n).map(|_| rnd()).collect();
        let y: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let never = AtomicBool::new(false);
        for m in [1usize, 2] {
            let d = Data::new(&y, &u[..n * m], m, &[0]).unwrap();
            let s = Structure::new(3, vec![3; m], vec![1; m], vec![]).unwrap();
            let theta = vec![0.01; 3 + 3 * m];
            for horizon in [None, Some(1)] {
                let mut best = f64::INFINITY;
                for _ in 0..5 {
                    let t = std::time::Instant::now();
                    let out =
                        crate::simulate::predict::predict_cancellable(&d, &s, &theta, horizon, 0, &never).unwrap();
                    best = best.min(t.elapsed().as_secs_f64());
                    assert!(out[n - 1].is_finite());
                }
                let mut out = vec![0.0; n];
                let mut best_inner = f64::INFINITY;
                for _ in 0..5 {
                    let t = std::time::Instant::now();
                    match horizon {
                        None => assert!(free_run(&d, &s, &theta, (3, n), &mut out, &never).unwrap()),
                        _ => one_step(&d, &s, &theta, (3, n), &mut out, &never).unwrap(),
                    }
                    best_inner = best_inner.min(t.elapsed().as_secs_f64());
                }
                println!(
                    "m={m} {horizon:?}: predict {:.2} ms, kernel into a warm buffer {:.2} ms",
                    best * 1e3,
                    best_inner * 1e3
                );
            }
        }
    }
}
