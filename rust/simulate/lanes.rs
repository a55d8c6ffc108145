//! Free-run RMS of up to [`LANES`] linear structures at once, one SIMD lane each: the hot loop of a
//! sweep, and the machine's multiply-add throughput it is measured against.

use crate::arx::structure::{Data, Structure};
use crate::linalg::simd::madd;
use crate::simulate::score::SimScore;

/// Structures simulated side by side by [`free_run_rms_lanes`] (one SIMD lane each).
pub const LANES: usize = 8;

/// Samples per divergence check.
const BLOCK: usize = 1024;

/// Time steps whose input part is computed together ([`LaneState::input_steps`]).
const STEPS: usize = 8; // [`LaneState::input_steps`] names its eight accumulators

/// `acc += c · x` in every lane.
#[inline(always)]
fn lanes_madd<const FMA: bool>(acc: &mut [f64; LANES], c: &[f64; LANES], x: f64) {
    for l in 0..LANES {
        acc[l] = madd::<FMA>(c[l], x, acc[l]);
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
    /// The accumulators are separate variables: held as one `[[f64; LANES]; 4]`, the compiler split
    /// one of them into scalar pieces and shuffles, a third of the kernel's time. Eight steps rather
    /// than four halve the loop's overhead and coefficient loads per step (the free run of the
    /// benchmark grid 8-13 % faster).
    #[inline(always)]
    fn input_steps<const FMA: bool>(&self, ucol: &[f64], n: usize, t: usize) -> [[f64; LANES]; STEPS] {
        let (mut v0, mut v1, mut v2, mut v3) = ([0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
        let (mut v4, mut v5, mut v6, mut v7) = ([0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
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
                lanes_madd::<FMA>(&mut v4, cl, x[4]);
                lanes_madd::<FMA>(&mut v5, cl, x[5]);
                lanes_madd::<FMA>(&mut v6, cl, x[6]);
                lanes_madd::<FMA>(&mut v7, cl, x[7]);
            }
        }
        [v0, v1, v2, v3, v4, v5, v6, v7]
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

/// Error and (with `PEAK`) peak bookkeeping of one simulated sample.
#[inline(always)]
fn account<const FMA: bool, const PEAK: bool>(
    yk: f64,
    v: &[f64; LANES],
    sse: &mut [f64; LANES],
    mx: &mut [f64; LANES],
) {
    for l in 0..LANES {
        let e = yk - v[l];
        sse[l] = madd::<FMA>(e, e, sse[l]);
        if PEAK {
            let av = v[l].abs();
            mx[l] = if av > mx[l] { av } else { mx[l] };
        }
    }
}

/// Simulates one block of `len` samples from `t0` for every lane, from the history `hl` (newest
/// first, updated): the block's sums of squared errors and, with `PEAK`, its peak |output| per lane
/// (zero without).
#[inline(always)]
fn lanes_block<const NA: usize, const FMA: bool, const PEAK: bool>(
    st: &LaneState,
    y: &[f64],
    ucol: &[f64],
    (t0, len): (usize, usize),
    hl: &mut [[f64; LANES]; NA],
) -> ([f64; LANES], [f64; LANES]) {
    let n = y.len();
    // The coefficients are read from memory by the multiply-adds (a copy in registers too left
    // too few of them for na around 10, and the compiler split the recursion into half and
    // quarter vectors spilled to the stack).
    let a: &[[f64; LANES]; NA] = st.neg_a.as_slice().try_into().expect("na coefficient vectors");
    let mut sse = [0.0; LANES];
    let mut mx = [0.0; LANES];
    // The recursion of one step from its input part (a macro, so that the history and the sums
    // stay in registers).
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
            account::<FMA, PEAK>(y[$t], &v, &mut sse, &mut mx);
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
    #[allow(clippy::needless_range_loop)] // the step reads the inputs of t too
    for t in t..end {
        ar_step!(st.input_part::<FMA>(ucol, n, t), t);
    }
    (sse, mx)
}

#[inline(always)]
fn lanes_kernel<const NA: usize, const FMA: bool>(
    d: &Data,
    ucol: &[f64],
    models: &[(&Structure, &[f64])],
    lag: usize,
    limit: f64,
) -> Vec<SimScore> {
    let mut st = LaneState::new(models, NA, d.m);
    let quiet = quiet_block_bound(d.y, limit);
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
            // First without the peak of |output|: a block whose every active lane keeps its sum
            // of squared errors below `quiet` cannot have left [-limit, limit] (see
            // [`quiet_block_bound`]), and the same multiply-adds gave the same sums. Only another
            // block is simulated again with its peaks.
            let mut hl = h;
            let (mut sse, mut mx) = lanes_block::<NA, FMA, false>(&st, d.y, ucol, (t0, len), &mut hl);
            if !(0..LANES).all(|l| !st.active[l] || sse[l] <= quiet) {
                hl = h;
                (sse, mx) = lanes_block::<NA, FMA, true>(&st, d.y, ucol, (t0, len), &mut hl);
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

/// A bound on a block's sum of squared errors below which no simulated output of the block left
/// `[-limit, limit]`: an output beyond the limit is at least `limit - max|y|` from the measured
/// one, so its squared error alone exceeds the bound (with a factor 2 in hand for rounding).
/// Negative (no block qualifies) when the limit is not well above the measured output.
fn quiet_block_bound(y: &[f64], limit: f64) -> f64 {
    let peak = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let margin = 0.5 * (limit - peak);
    if margin > 0.0 && margin.is_finite() {
        margin * margin
    } else {
        -1.0
    }
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
                account::<FMA, true>(d.y[t], &v, &mut sse, &mut mx);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::score::free_run_rms_linear;

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

    /// Blocks judged by their error sums alone (no peak of the output) stop the same lanes, in the
    /// same block, as the one-structure path, for limits on either side of the outputs.
    #[test]
    fn quiet_blocks_stop_the_same_lanes_as_the_peak_test() {
        let n = 6000;
        let u: Vec<f64> = (0..n).map(|t| (((t * 7919) % 23) as f64 - 11.0) / 7.0).collect();
        let mut y = vec![0.0; n];
        for t in 2..n {
            y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1];
        }
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        let s = Structure::new(1, vec![1], vec![1], vec![]).unwrap();
        // A slow pole, a fast one (outputs about 5 times the measured ones), and a growing one.
        let thetas = [[-0.8, 0.5], [-0.96, 0.5], [-1.0005, 0.5]];
        let models: Vec<(&Structure, &[f64])> = thetas.iter().map(|th| (&s, th.as_slice())).collect();
        let ucol = input_columns(&d);
        let peak = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut fir = Vec::new();
        for factor in [0.9, 1.5, 3.0, 5.0, 8.0, 1e3] {
            let lanes = free_run_rms_lanes(&d, &ucol, &models, 2, factor * peak);
            for ((s, th), got) in models.iter().zip(&lanes) {
                let want = free_run_rms_linear(&d, s, th, 2, factor * peak, &mut fir);
                // A diverged lane counts the samples of the blocks before the one it left in.
                let n = if want.diverged { want.n / BLOCK * BLOCK } else { want.n };
                assert_eq!((want.diverged, n), (got.diverged, got.n), "limit {factor} x peak");
            }
        }
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
