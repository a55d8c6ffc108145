//! Prediction and free-run simulation of a fitted structure.
//!
//! Horizon 1 is the one-step predictor (measured past outputs), horizon k runs the model k steps
//! from measured outputs up to t−k, and free run (no horizon) feeds back only simulated outputs.
//! Output-derived effect terms are evaluated on the same outputs the AR part uses, so in free run
//! `y^3` reads the simulated output, never the measured one.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{ArxError, Result};
use crate::structure::{Data, Structure};

/// Sum of the input (FIR) part and effect inputs at time `t` plus the AR and output-term parts
/// evaluated on `hist(i)` = the output i steps back.
#[inline]
fn step(d: &Data, s: &Structure, theta: &[f64], t: usize, hist: &dyn Fn(usize) -> f64) -> f64 {
    let mut acc = 0.0;
    let mut c = 0;
    for i in 1..=s.na {
        acc -= theta[c] * hist(i);
        c += 1;
    }
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            acc += theta[c] * d.u_at(t - k - j, i);
            c += 1;
        }
    }
    for term in &s.output_terms {
        let y2 = if term.lag() >= 2 { hist(2) } else { 0.0 };
        let s1 = term.multiplier.map_or(1.0, |m| d.u_at(t - 1, m));
        acc += theta[c] * term.eval(hist(1), y2, s1);
        c += 1;
    }
    acc
}

/// Whether every input sample the structure reads at time `t` is finite.
fn inputs_finite(d: &Data, s: &Structure, t: usize) -> bool {
    for (i, (&b, &k)) in s.nb.iter().zip(&s.nk).enumerate() {
        for j in 0..b {
            if !d.u_at(t - k - j, i).is_finite() {
                return false;
            }
        }
    }
    s.output_terms.iter().all(|term| term.multiplier.is_none_or(|m| d.u_at(t - 1, m).is_finite()))
}

/// Predicted output for every sample (NaN for the first `max(first_lag, lag)` samples of each
/// experiment, which only serve as initial conditions).
///
/// `horizon = None` is free-run simulation; `Some(k)` the k-step-ahead prediction. Samples whose
/// inputs are missing (NaN) predict NaN, and the simulation restarts from measured outputs after them.
pub fn predict(d: &Data, s: &Structure, theta: &[f64], horizon: Option<usize>, first_lag: usize) -> Vec<f64> {
    let never = AtomicBool::new(false);
    predict_cancellable(d, s, theta, horizon, first_lag, &never).unwrap_or_else(|_| vec![f64::NAN; d.len()])
}

/// Whether experiment `[a, b)` has finite inputs and finite initial outputs `[a, start)`: then the
/// free run never restarts from measurements and is a plain recursion.
pub(crate) fn complete(d: &Data, a: usize, start: usize, b: usize) -> bool {
    d.y[a..start].iter().all(|v| v.is_finite()) && d.u[a * d.m..b * d.m].iter().all(|v| v.is_finite())
}

/// Samples (or k-step windows) between two looks at the cancel flag of [`predict_cancellable`].
const CANCEL_EVERY: usize = 4096;

/// As [`predict`], checking `cancel` every [`CANCEL_EVERY`] samples (a k-step prediction with a
/// long horizon costs O(N k p) and may run for minutes).
///
/// # Errors
/// `Interrupted` once `cancel` is set.
pub fn predict_cancellable(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
) -> Result<Vec<f64>> {
    // Zero pages from the system, not a NaN pass: every sample is written.
    let mut out = vec![0.0; d.len()];
    predict_paths(d, s, theta, horizon, first_lag, cancel, true, &mut out)?;
    Ok(out)
}

/// As [`predict_cancellable`], into `out` (`d.len()` long; every sample is written), so that the
/// caller chooses the allocation (Python's numpy array).
///
/// # Errors
/// `Interrupted` once `cancel` is set.
///
/// # Panics
/// When `out.len() != d.len()`.
pub fn predict_into(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
    out: &mut [f64],
) -> Result<()> {
    predict_paths(d, s, theta, horizon, first_lag, cancel, true, out)
}

/// [`predict_into`]; `fast = false` sends every structure through the general step (the
/// reference the tests hold the fast paths of [`crate::linear_predict`] to).
#[allow(clippy::too_many_arguments)]
fn predict_paths(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
    cancel: &AtomicBool,
    fast: bool,
    out: &mut [f64],
) -> Result<()> {
    assert_eq!(out.len(), d.len(), "one prediction per sample");
    let stop = |t: usize, work: usize| {
        t.is_multiple_of((CANCEL_EVERY / work.clamp(1, CANCEL_EVERY)).max(1)) && cancel.load(Ordering::Relaxed)
    };
    let lag = first_lag.max(s.max_lag());
    // Every path below writes each sample it predicts; the samples before each experiment's first
    // prediction are set to NaN here.
    for (a, b) in d.segments() {
        let start = a + lag;
        out[a..start.min(b)].fill(f64::NAN);
        if start >= b {
            continue;
        }
        let linear = fast && s.output_terms.is_empty();
        match horizon {
            // Without output terms: vectorised passes (and a one-multiply-add chain in free run).
            Some(k) if k <= 1 && linear => crate::linear_predict::one_step(d, s, theta, (start, b), out, cancel)?,
            // A free run that stays finite read no missing sample; otherwise the data are scanned,
            // and a missing sample calls for the general step (which restarts after it).
            None if linear
                && (crate::linear_predict::free_run(d, s, theta, (start, b), out, cancel)?
                    || complete(d, a, start, b)) => {}
            // With output terms, complete data never restart the simulation: a plain recursion.
            None if fast
                && complete(d, a, start, b)
                && crate::term_free_run::free_run(d, s, theta, (start, b), out, cancel)? => {}
            Some(k) if k <= 1 => {
                for (t, o) in out.iter_mut().enumerate().take(b).skip(start) {
                    if stop(t, 1) {
                        return Err(ArxError::Interrupted);
                    }
                    *o = step(d, s, theta, t, &|i| d.y[t - i]);
                }
            }
            None => {
                // `from_measurement[t]`: take y(t) from the data (initial conditions, and samples whose
                // inputs or measured initial outputs are missing, after which the simulation restarts
                // from the measurements). A simulation that overflows is not restarted: its NaN/inf
                // propagate so the divergence stays visible.
                let mut sim = vec![f64::NAN; b - a];
                let mut from_measurement = vec![true; b - a];
                let reach = s.max_lag().max(1);
                for t in start..b {
                    if stop(t, 1) {
                        return Err(ArxError::Interrupted);
                    }
                    let v = {
                        let (sim_ref, meas) = (&sim, &from_measurement);
                        step(d, s, theta, t, &|i| if meas[t - i - a] { d.y[t - i] } else { sim_ref[t - i - a] })
                    };
                    sim[t - a] = v;
                    let missing_history =
                        (1..=reach.min(t - a)).any(|i| from_measurement[t - i - a] && d.y[t - i].is_nan());
                    from_measurement[t - a] = v.is_nan() && (missing_history || !inputs_finite(d, s, t));
                    out[t] = v;
                }
            }
            Some(k) => {
                // Beyond the segment every prediction starts from the measured initial outputs, so a
                // longer horizon changes nothing (and must not size the buffer).
                let k = k.min(b - start);
                let mut local = vec![0.0f64; k];
                for t in start..b {
                    if stop(t, k) {
                        return Err(ArxError::Interrupted);
                    }
                    let t0 = (t + 1).saturating_sub(k).max(start);
                    for tau in t0..=t {
                        let v = {
                            let loc = &local;
                            step(d, s, theta, tau, &|i| {
                                if tau >= t0 + i {
                                    let v = loc[tau - i - t0];
                                    if v.is_nan() {
                                        d.y[tau - i]
                                    } else {
                                        v
                                    }
                                } else {
                                    d.y[tau - i]
                                }
                            })
                        };
                        local[tau - t0] = v;
                    }
                    out[t] = local[t - t0];
                }
            }
        }
    }
    Ok(())
}

/// [`predict`] through the general step only, whatever the structure: the reference for the fast
/// linear paths.
#[cfg(test)]
pub(crate) fn step_reference(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    horizon: Option<usize>,
    first_lag: usize,
) -> Vec<f64> {
    let mut out = vec![0.0; d.len()];
    predict_paths(d, s, theta, horizon, first_lag, &AtomicBool::new(false), false, &mut out).unwrap();
    out
}

/// k-step-ahead prediction of a linear structure (no output terms) on complete data: the same
/// numbers as [`predict`] with `Some(k)` (up to rounding) at a cost of O(N (na + nb)) for any k,
/// computed as a filter by [`crate::kstep::predict_k`].
///
/// # Panics
/// When `s` has output terms or `k == 0`.
pub fn predict_k_linear(d: &Data, s: &Structure, theta: &[f64], k: usize, first_lag: usize) -> Vec<f64> {
    crate::kstep::predict_k(d, s, theta, k, first_lag)
}

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

/// Structures simulated side by side by [`free_run_rms_lanes`] (one SIMD lane each).
pub const LANES: usize = 8;

/// Samples per divergence check.
const BLOCK: usize = 1024;

/// Time steps whose input part is computed together ([`LaneState::input_steps`]).
const STEPS: usize = 4; // [`LaneState::input_steps`] names its four accumulators

/// `acc += c · x` in every lane.
#[inline(always)]
fn lanes_madd<const FMA: bool>(acc: &mut [f64; LANES], c: &[f64; LANES], x: f64) {
    for l in 0..LANES {
        acc[l] = madd::<FMA>(c[l], x, acc[l]);
    }
}

#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Inputs as one contiguous column per input (`ucol[i * N + t]`), the layout the FIR pass streams.
pub fn input_columns(d: &Data) -> Vec<f64> {
    let n = d.len();
    let mut out = vec![0.0; n * d.m];
    for t in 0..n {
        for i in 0..d.m {
            out[i * n + t] = d.u[t * d.m + i];
        }
    }
    out
}

/// Free-run RMS of up to [`LANES`] linear structures, simulated side by side: lane `l` is structure
/// `models[l]`, each with its own output history, so the latency of the AR recursion is shared by
/// all lanes. The recursion runs over the largest `na` of the lanes (the others multiply zeros). The input (FIR) part is computed per time block in a
/// vectorised pass first.
///
/// Every lane starts at `max(first_lag, largest lag of the lanes)` into each experiment (a sweep
/// passes its grid lag, which is at least every structure's own lag). `ucol` is
/// [`input_columns`]`(d)`. A lane whose output leaves `[-limit, limit]` (or turns NaN) within a block
/// is stopped and reported as diverged, with `n` the samples scored before that block.
///
/// # Panics
/// When `models` is empty or longer than [`LANES`], a structure has output terms, or the data hold non-finite values (use [`predict`] and [`score`] for those).
pub fn free_run_rms_lanes(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    first_lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    assert!(!models.is_empty() && models.len() <= LANES, "1..={LANES} structures per lane group");
    // Lanes with fewer poles than the largest carry zero coefficients for the extra lags: adding
    // 0 · (a finite output) leaves every lane's numbers exactly as if it ran alone.
    let na = models.iter().map(|(s, _)| s.na).max().unwrap_or(0);
    assert!(models.iter().all(|(s, th)| s.output_terms.is_empty() && th.len() == s.n_params()));
    assert_eq!(ucol.len(), d.len() * d.m);
    let lag = models.iter().map(|(s, _)| s.max_lag()).fold(first_lag, usize::max);
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { lanes_avx512(d, ucol, models, na, lag, limit) };
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { lanes_avx2(d, ucol, models, na, lag, limit) };
        }
    }
    lanes_dispatch::<false>(d, ucol, models, na, lag, limit)
}

/// AVX-512: one register holds all lanes, and 32 registers keep the output history of
/// every lane out of memory.
#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn lanes_avx512(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    na: usize,
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    lanes_dispatch::<true>(d, ucol, models, na, lag, limit)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn lanes_avx2(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    na: usize,
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    lanes_dispatch::<true>(d, ucol, models, na, lag, limit)
}

#[inline(always)]
fn lanes_dispatch<const FMA: bool>(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    na: usize,
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    macro_rules! fixed {
        ($($n:literal)*) => {
            match na {
                $($n => lanes_kernel::<$n, FMA>(d, ucol, models, lag, limit),)*
                _ => lanes_kernel_dyn::<FMA>(d, ucol, models, na, lag, limit),
            }
        };
    }
    fixed!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

/// Lane coefficients and bookkeeping shared by the fixed-na and the general kernel.
struct LaneState {
    /// `-a_i` per lane.
    neg_a: Vec<[f64; LANES]>,
    /// Per input: the smallest lag any lane reads and, for each lag from there, the lanes' b
    /// coefficient (zero where a lane does not use that lag).
    fir: Vec<(usize, Vec<[f64; LANES]>)>,
    active: [bool; LANES],
    sse: [f64; LANES],
    n: [usize; LANES],
    diverged: [bool; LANES],
}

impl LaneState {
    fn new(models: &[(&Structure, &[f64])], na: usize, m: usize) -> Self {
        let mut neg_a = vec![[0.0; LANES]; na];
        let mut active = [false; LANES];
        for (l, (_, th)) in models.iter().enumerate() {
            active[l] = true;
            for (i, a) in neg_a.iter_mut().take(models[l].0.na).enumerate() {
                a[l] = -th[i];
            }
        }
        let mut fir = Vec::with_capacity(m);
        let mut offset: Vec<usize> = models.iter().map(|(s, _)| s.na).collect();
        for i in 0..m {
            let used = models.iter().filter(|(s, _)| s.nb[i] > 0);
            let lo = used.clone().map(|(s, _)| s.nk[i]).min();
            let hi = used.map(|(s, _)| s.nk[i] + s.nb[i] - 1).max();
            let (Some(lo), Some(hi)) = (lo, hi) else {
                fir.push((0, Vec::new()));
                continue;
            };
            let mut c = vec![[0.0; LANES]; hi - lo + 1];
            for (l, (s, th)) in models.iter().enumerate() {
                for j in 0..s.nb[i] {
                    c[s.nk[i] + j - lo][l] = th[offset[l] + j];
                }
                offset[l] += s.nb[i];
            }
            fir.push((lo, c));
        }
        LaneState { neg_a, fir, active, sse: [0.0; LANES], n: [0; LANES], diverged: [false; LANES] }
    }

    /// Input (FIR) part at time `t` for every lane: lags in ascending order, as in the one-structure
    /// path, so each lane computes exactly what it would alone.
    #[inline(always)]
    fn input_part<const FMA: bool>(&self, ucol: &[f64], n: usize, t: usize) -> [f64; LANES] {
        let mut v = [0.0; LANES];
        for (i, (lo, c)) in self.fir.iter().enumerate() {
            if c.is_empty() {
                continue;
            }
            // u_i(t - hi) ..= u_i(t - lo), read newest first.
            let window = &ucol[i * n + t + 1 - lo - c.len()..i * n + t + 1 - lo];
            for (cl, &x) in c.iter().zip(window.iter().rev()) {
                for l in 0..LANES {
                    v[l] = madd::<FMA>(cl[l], x, v[l]);
                }
            }
        }
        v
    }

    /// [`Self::input_part`] for the [`STEPS`] steps `t..t + STEPS` at once: each coefficient is
    /// loaded once for all of them, and the steps are independent chains of multiply-adds (a single
    /// step's chain runs one multiply-add after the other and leaves the FMA units waiting on its
    /// latency). Every step sums in the same order as [`Self::input_part`]: the same numbers.
    ///
    /// The four accumulators are separate variables: held as one `[[f64; LANES]; 4]`, the compiler
    /// split one of them into scalar pieces and shuffles, a third of the kernel's time.
    #[inline(always)]
    fn input_steps<const FMA: bool>(&self, ucol: &[f64], n: usize, t: usize) -> [[f64; LANES]; STEPS] {
        let (mut v0, mut v1, mut v2, mut v3) = ([0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
        for (i, (lo, c)) in self.fir.iter().enumerate() {
            if c.is_empty() {
                continue;
            }
            // u_i(t - hi) ..= u_i(t + STEPS - 1 - lo); lag lo + j at step t + s is w[len - 1 - j + s].
            let len = c.len();
            let w = &ucol[i * n + t + 1 - lo - len..i * n + t + STEPS - lo];
            for (cl, x) in c.iter().zip(w.windows(STEPS).rev()) {
                lanes_madd::<FMA>(&mut v0, cl, x[0]);
                lanes_madd::<FMA>(&mut v1, cl, x[1]);
                lanes_madd::<FMA>(&mut v2, cl, x[2]);
                lanes_madd::<FMA>(&mut v3, cl, x[3]);
            }
        }
        [v0, v1, v2, v3]
    }

    /// Folds one block's per-lane sums in; stops lanes that diverged (their coefficients are zeroed
    /// so they idle at 0). Returns the lanes stopped.
    fn close_block(&mut self, sse: &[f64; LANES], mx: &[f64; LANES], len: usize, limit: f64) -> Vec<usize> {
        let mut stopped = Vec::new();
        for l in 0..LANES {
            if !self.active[l] {
                continue;
            }
            // NaN must count as diverged, hence the negated comparison.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            let diverged = !(mx[l] <= limit) || !sse[l].is_finite();
            if diverged {
                self.active[l] = false;
                self.diverged[l] = true;
                for a in self.neg_a.iter_mut() {
                    a[l] = 0.0;
                }
                for (_, c) in self.fir.iter_mut() {
                    for cl in c.iter_mut() {
                        cl[l] = 0.0;
                    }
                }
                stopped.push(l);
            } else {
                self.sse[l] += sse[l];
                self.n[l] += len;
            }
        }
        stopped
    }

    fn any_active(&self) -> bool {
        self.active.iter().any(|&a| a)
    }

    fn scores(&self, k: usize) -> Vec<SimScore> {
        (0..k)
            .map(|l| {
                if self.diverged[l] {
                    SimScore { rms: f64::NAN, n: self.n[l], diverged: true, norm: f64::NAN, mean: f64::NAN }
                } else {
                    let rms = if self.n[l] > 0 { (self.sse[l] / self.n[l] as f64).sqrt() } else { f64::NAN };
                    SimScore { rms, n: self.n[l], diverged: false, norm: f64::NAN, mean: f64::NAN }
                }
            })
            .collect()
    }
}

/// Error and peak bookkeeping of one simulated sample.
#[inline(always)]
fn account<const FMA: bool>(yk: f64, v: &[f64; LANES], sse: &mut [f64; LANES], mx: &mut [f64; LANES]) {
    for l in 0..LANES {
        let e = yk - v[l];
        sse[l] = madd::<FMA>(e, e, sse[l]);
        let av = v[l].abs();
        mx[l] = if av > mx[l] { av } else { mx[l] };
    }
}

#[inline(always)]
fn lanes_kernel<const NA: usize, const FMA: bool>(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    let n = d.len();
    let mut st = LaneState::new(models, NA, d.m);
    'segments: for (sa, sb) in d.segments() {
        let start = sa + lag;
        if start >= sb {
            continue;
        }
        // History of simulated outputs, newest first; initially the measured outputs.
        let mut h = [[0.0; LANES]; NA];
        for (i, hi) in h.iter_mut().enumerate() {
            *hi = [d.y[start - 1 - i]; LANES];
        }
        let mut t0 = start;
        while t0 < sb {
            let len = BLOCK.min(sb - t0);
            // The history as a local copy with constant indices only: it lives in registers. The
            // coefficients are read from memory by the multiply-adds (a copy in registers too
            // left too few of them for na around 10, and the compiler split the recursion into
            // half and quarter vectors spilled to the stack).
            let mut hl = h;
            let a: &[[f64; LANES]; NA] = st.neg_a.as_slice().try_into().expect("na coefficient vectors");
            let mut sse = [0.0; LANES];
            let mut mx = [0.0; LANES];
            // The recursion of one step from its input part (a macro, so that the history and the
            // sums stay in registers).
            macro_rules! ar_step {
                ($v:expr, $t:expr) => {{
                    let mut v = $v;
                    // Oldest lags first: only the last multiply-add waits for the newest output.
                    for i in (0..NA).rev() {
                        for l in 0..LANES {
                            v[l] = madd::<FMA>(a[i][l], hl[i][l], v[l]);
                        }
                    }
                    for i in (1..NA).rev() {
                        hl[i] = hl[i - 1];
                    }
                    if NA > 0 {
                        hl[0] = v;
                    }
                    account::<FMA>(d.y[$t], &v, &mut sse, &mut mx);
                }};
            }
            let end = t0 + len;
            let mut t = t0;
            while t + STEPS <= end {
                let vs = st.input_steps::<FMA>(ucol, n, t);
                for (s, v) in vs.into_iter().enumerate() {
                    ar_step!(v, t + s);
                }
                t += STEPS;
            }
            for t in t..end {
                ar_step!(st.input_part::<FMA>(ucol, n, t), t);
            }
            h = hl;
            for l in st.close_block(&sse, &mx, len, limit) {
                for hi in h.iter_mut() {
                    hi[l] = 0.0;
                }
            }
            if !st.any_active() {
                break 'segments;
            }
            t0 += len;
        }
    }
    st.scores(models.len())
}

/// The same kernel for large `na` (history in a slice instead of registers).
#[inline(always)]
fn lanes_kernel_dyn<const FMA: bool>(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    na: usize,
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    let n = d.len();
    let mut st = LaneState::new(models, na, d.m);
    'segments: for (sa, sb) in d.segments() {
        let start = sa + lag;
        if start >= sb {
            continue;
        }
        let mut h = vec![[0.0; LANES]; na];
        for (i, hi) in h.iter_mut().enumerate() {
            *hi = [d.y[start - 1 - i]; LANES];
        }
        let mut t0 = start;
        while t0 < sb {
            let len = BLOCK.min(sb - t0);
            let mut sse = [0.0; LANES];
            let mut mx = [0.0; LANES];
            for t in t0..t0 + len {
                let mut v = st.input_part::<FMA>(ucol, n, t);
                for i in (0..na).rev() {
                    for l in 0..LANES {
                        v[l] = madd::<FMA>(st.neg_a[i][l], h[i][l], v[l]);
                    }
                }
                h.copy_within(0..na - 1, 1);
                h[0] = v;
                account::<FMA>(d.y[t], &v, &mut sse, &mut mx);
            }
            for l in st.close_block(&sse, &mx, len, limit) {
                for hi in h.iter_mut() {
                    hi[l] = 0.0;
                }
            }
            if !st.any_active() {
                break 'segments;
            }
            t0 += len;
        }
    }
    st.scores(models.len())
}

/// Seconds for `n_vectors` multiply-adds of [`LANES`] lanes each, at the machine's throughput:
/// many independent chains (no latency to wait on), on every thread of the current pool, with no
/// memory traffic. The limit a free-run sweep doing the same number of multiply-adds could reach.
pub fn fma_throughput_seconds(n_vectors: u64) -> f64 {
    use rayon::prelude::*;
    let threads = rayon::current_num_threads() as u64;
    let per_thread = n_vectors.div_ceil(threads.max(1));
    let t = std::time::Instant::now();
    let total: f64 = (0..threads).into_par_iter().map(|_| fma_chains(per_thread)).sum();
    let seconds = t.elapsed().as_secs_f64();
    std::hint::black_box(total);
    seconds
}

fn fma_chains(n: u64) -> f64 {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { fma_chains_avx512(n) };
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: as above.
            return unsafe { fma_chains_avx2(n) };
        }
    }
    fma_chains_impl::<false>(n)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn fma_chains_avx512(n: u64) -> f64 {
    fma_chains_impl::<true>(n)
}

#[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_chains_avx2(n: u64) -> f64 {
    fma_chains_impl::<true>(n)
}

#[inline(always)]
fn fma_chains_impl<const FMA: bool>(n: u64) -> f64 {
    // More chains than the FMA latency times the units: the units never wait.
    const CHAINS: usize = 12;
    let mut acc = [[1.0f64; LANES]; CHAINS];
    let a = std::hint::black_box([0.999_999_9; LANES]);
    let b = std::hint::black_box([1e-9; LANES]);
    for _ in 0..n.div_ceil(CHAINS as u64) {
        for c in acc.iter_mut() {
            for l in 0..LANES {
                c[l] = madd::<FMA>(c[l], a[l], b[l]);
            }
        }
    }
    acc.iter().flatten().sum()
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
    DIVERGENCE_FACTOR * crate::finite_sums::finite_peak(y).max(f64::MIN_POSITIVE)
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
    use crate::kstep::predict_k;

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

    /// The linear paths of [`crate::linear_predict`] give the general step's numbers to rounding
    /// (they sum in another order), and the same bits on every run; the same data with one NaN
    /// input in a later experiment (a restart) still takes the general step there.
    #[test]
    fn linear_paths_match_the_general_step() {
        let n = 400;
        let mut u: Vec<f64> = (0..2 * n).map(|t| (((t * 7919) % 17) as f64 - 8.0) * 0.37).collect();
        let y: Vec<f64> = (0..n).map(|t| ((t * 104_729) % 23) as f64 * 0.11 - 1.2).collect();
        u[2 * 350] = f64::NAN; // experiment 2 has a gap: the general path
        let starts = [0, 200];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let s = Structure::new(3, vec![2, 3], vec![1, 0], vec![]).unwrap();
        let theta = [-0.9, 0.3, -0.05, 0.5, 0.25, 0.1, -0.2, 0.07];
        let never = AtomicBool::new(false);
        for horizon in [None, Some(1)] {
            let fast = predict(&d, &s, &theta, horizon, 4);
            let mut general = vec![f64::NAN; n];
            for t in 4..200 {
                let past = |i: usize| if horizon.is_some() || t - i < 4 { y[t - i] } else { general[t - i] };
                general[t] = step(&d, &s, &theta, t, &past);
            }
            assert!((4..200).all(|t| (fast[t] - general[t]).abs() <= 1e-13 * general[t].abs().max(1.0)), "{horizon:?}");
            assert!((0..4).all(|t| fast[t].is_nan()));
            let again = predict_cancellable(&d, &s, &theta, horizon, 4, &never).unwrap();
            assert!(fast.iter().zip(&again).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

    #[test]
    fn free_run_reproduces_noise_free_system_and_fast_path_agrees() {
        let n = 500;
        let u: Vec<f64> = (0..n).map(|t| ((t * 7919) % 13) as f64 - 6.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.3 * u[t - 2] + 0.1 * u[t - 3];
        }
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![2], vec![]).unwrap();
        let theta = [-1.2, 0.5, 0.3, 0.1];
        let sim = predict(&d, &s, &theta, None, 0);
        for t in 3..n {
            assert!((sim[t] - y[t]).abs() < 1e-9);
        }
        let k5 = predict(&d, &s, &theta, Some(5), 0);
        assert!((k5[100] - y[100]).abs() < 1e-9);
        let mut fir = Vec::new();
        let sc = free_run_rms_linear(&d, &s, &theta, 0, 1e6, &mut fir);
        assert!(sc.rms < 1e-9 && !sc.diverged);
        let bad = [-2.5, 0.5, 0.3, 0.1];
        assert!(free_run_rms_linear(&d, &s, &bad, 0, 1e6, &mut fir).diverged);
    }

    #[test]
    fn lanes_agree_with_single_structure_path_and_stop_diverging_lanes() {
        let n = 5000;
        let u: Vec<f64> = (0..2 * n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.3 * u[2 * (t - 2)] + 0.1 * u[2 * (t - 3) + 1];
        }
        let starts = [0, 2100];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let s1 = Structure::new(2, vec![2, 1], vec![2, 3], vec![]).unwrap();
        let s2 = Structure::new(2, vec![1, 3], vec![0, 1], vec![]).unwrap();
        let s3 = Structure::new(2, vec![3, 0], vec![1, 0], vec![]).unwrap();
        let th1 = [-1.2, 0.5, 0.3, 0.0, 0.1];
        let th2 = [-1.1, 0.4, 0.2, 0.1, -0.3, 0.05];
        let bad = [-2.5, 0.5, 0.3, 0.1, 0.0];
        let models: Vec<(&Structure, &[f64])> = vec![(&s1, &th1), (&s2, &th2), (&s3, &bad)];
        let ucol = input_columns(&d);
        let lanes = free_run_rms_lanes(&d, &ucol, &models, 6, 1e6);
        let mut fir = Vec::new();
        for ((s, th), got) in models.iter().zip(&lanes) {
            let want = free_run_rms_linear(&d, s, th, 6, 1e6, &mut fir);
            assert_eq!(want.diverged, got.diverged);
            if !want.diverged {
                assert_eq!(want.n, got.n);
                assert!((want.rms - got.rms).abs() <= 1e-10 * want.rms.max(1e-6), "{} vs {}", want.rms, got.rms);
            }
        }
        assert!(lanes[0].rms < 1e-9);
        assert!(lanes[2].diverged && lanes[2].rms.is_nan());
    }

    #[test]
    fn lanes_of_different_na_equal_each_lane_alone() {
        let n = 3000;
        let u: Vec<f64> = (0..n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 4..n {
            y[t] = 1.3 * y[t - 1] - 0.6 * y[t - 2] + 0.1 * y[t - 3] + 0.4 * u[t - 1] + 0.2 * u[t - 4];
        }
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        let s1 = Structure::new(1, vec![2], vec![1], vec![]).unwrap();
        let s3 = Structure::new(3, vec![4], vec![1], vec![]).unwrap();
        let s4 = Structure::new(4, vec![1], vec![0], vec![]).unwrap();
        let (th1, th3, th4) = ([-0.9, 0.4, 0.25], [-1.3, 0.6, -0.1, 0.4, 0.0, 0.0, 0.2], [-1.2, 0.5, -0.05, 0.01, 0.3]);
        let models: Vec<(&Structure, &[f64])> = vec![(&s1, &th1), (&s3, &th3), (&s4, &th4)];
        let ucol = input_columns(&d);
        let together = free_run_rms_lanes(&d, &ucol, &models, 6, 1e6);
        for (model, got) in models.iter().zip(&together) {
            let alone = free_run_rms_lanes(&d, &ucol, std::slice::from_ref(model), 6, 1e6);
            assert_eq!((alone[0].rms.to_bits(), alone[0].n), (got.rms.to_bits(), got.n));
        }
        assert!(together[1].rms < 1e-9, "the true structure reproduces the noise-free output");
    }

    #[test]
    fn k_step_filter_equals_step_by_step_prediction() {
        let n = 700;
        let u: Vec<f64> = (0..2 * n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.9 * y[t - 1] - 0.905 * y[t - 2]
                + 0.3 * u[2 * (t - 2)]
                + 0.1 * u[2 * (t - 3) + 1]
                + 0.01 * ((t * 31 % 7) as f64 - 3.0);
        }
        let starts = [0, 300];
        let d = Data::new(&y, &u, 2, &starts).unwrap();
        let s = Structure::new(3, vec![2, 1], vec![1, 3], vec![]).unwrap();
        let theta = [-1.8, 0.85, -0.03, 0.3, 0.05, 0.1];
        for k in [1, 2, 5, 17] {
            let slow = predict(&d, &s, &theta, Some(k), 9);
            let fast = predict_k_linear(&d, &s, &theta, k, 9);
            for (t, (a, b)) in slow.iter().zip(&fast).enumerate() {
                assert_eq!(a.is_nan(), b.is_nan(), "t={t} k={k}");
                if a.is_finite() {
                    assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "t={t} k={k}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn filter_equals_step_by_step_prediction_for_any_horizon() {
        let n = 900;
        let u: Vec<f64> = (0..n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 1.6 * y[t - 1] - 0.8 * y[t - 2] + 0.3 * u[t - 2] + 0.02 * ((t * 31 % 7) as f64 - 3.0);
        }
        let starts = [0, 400];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![2], vec![]).unwrap();
        let theta = [-1.55, 0.78, 0.29, 0.01];
        for k in [1, 2, 3, 7, 64, 399, 500, 10_000] {
            let slow = predict(&d, &s, &theta, Some(k), 4);
            let fast = predict_k(&d, &s, &theta, k, 4);
            for (t, (a, b)) in slow.iter().zip(&fast).enumerate() {
                assert_eq!(a.is_nan(), b.is_nan(), "t={t} k={k}");
                if a.is_finite() {
                    assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "t={t} k={k}: {a} vs {b}");
                }
            }
        }
    }
}

#[cfg(test)]
mod perf_probe {
    use super::*;

    /// Fixed work for `perf stat` comparisons of the lane kernel (ignored by default).
    #[test]
    #[ignore]
    fn lanes_fixed_work() {
        let n = 200_000;
        let mut seed = 5u64;
        let u: Vec<f64> = (0..n)
            .map(|_| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
            })
            .collect();
        let mut y = vec![0.0; n];
        for t in 4..n {
            y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3];
        }
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let ucol = input_columns(&d);
        let mut total = 0.0;
        for na in 1..=10 {
            let grid: Vec<Structure> = (0..=10)
                .flat_map(|k| (1..=10).map(move |b| Structure::new(na, vec![b], vec![k], vec![]).unwrap()))
                .collect();
            let thetas: Vec<Vec<f64>> = grid
                .iter()
                .map(|s| {
                    let mut th = vec![0.0; s.n_params()];
                    th[0] = -0.9;
                    th[na] = 0.1;
                    th
                })
                .collect();
            for chunk in (0..grid.len()).collect::<Vec<_>>().chunks(LANES) {
                let models: Vec<(&Structure, &[f64])> =
                    chunk.iter().map(|&i| (&grid[i], thetas[i].as_slice())).collect();
                for sc in free_run_rms_lanes(&d, &ucol, &models, 20, 1e6) {
                    total += sc.rms;
                }
            }
        }
        assert!(total.is_finite());
    }
}
