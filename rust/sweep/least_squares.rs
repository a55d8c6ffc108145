//! Exhaustive order sweep: one QR reduction of the largest regressor, then every structure solved
//! from its columns of R at a cost independent of the number of samples, and simulated in parallel.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::arx::columns::columns_in;
// Re-exported: the grid envelope is part of the sweep's interface (the benches call
// `arxid::sweep::envelope`).
pub use crate::arx::columns::envelope;
use crate::arx::fit::solve_subset;
use crate::arx::reduce::reduce;
use crate::arx::structure::{Data, Structure};
use crate::error::{ArxError, Result};
use crate::linalg::qr::{to_col_major, BLOCK_ROWS};
use crate::simulate::lanes::{free_run_rms_lanes, input_columns, LANES};
use crate::simulate::predict::{predict, predict_k_linear};
use crate::simulate::score::{divergence_limit, score, SimScore};
use crate::sweep::grid_factors::{factor_grid, rows_of, GridFactors};
use crate::sweep::one_step::{one_step_all, Factors, OneStep};
use crate::sweep::validation_gram::ValidationLoss;

/// How a sweep validates its structures. A simulation is stopped as diverged by the core's one
/// rule, [`divergence_limit`] of the measured output of the data set it runs on.
#[derive(Debug, Clone, Copy)]
pub struct SweepOptions {
    /// Also simulate every structure on the estimation data.
    pub simulate_estimation: bool,
    /// `None`: free-run simulation; `Some(k)`: k-step-ahead prediction (integrating plants).
    pub horizon: Option<usize>,
    /// Parallel across structures and TSQR blocks.
    pub parallel: bool,
    /// Structures per progress report.
    pub chunk: usize,
    /// Two stages: rank every structure by its one-step loss from the R factors (validation rows,
    /// else estimation rows), then fit exactly and simulate only the best `top`. `None`: every
    /// structure is fitted exactly and simulated.
    pub top: Option<usize>,
}

/// Structures per parallel task of exact fits (a few microseconds each): fine enough that idle
/// workers take over the fits of a descheduled one, coarse enough that scheduling costs nothing.
const FIT_TASK: usize = 16;

/// At most this many threads per core are started for an explicit `n_threads`: results do not
/// depend on the thread count, so more would only cost memory (every thread has its own buffers).
pub const MAX_THREADS_PER_CORE: usize = 4;

/// The thread count the Python boundary starts for a request of `n_threads`: capped at
/// [`MAX_THREADS_PER_CORE`] per core; 0 stays 0 (run on the global rayon pool, all cores).
pub fn clamp_threads(n_threads: usize) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    n_threads.min(MAX_THREADS_PER_CORE.saturating_mul(cores))
}

/// Threads a sweep requested with `n_threads` (0 = all cores) actually runs on.
pub fn effective_threads(n_threads: usize) -> usize {
    match clamp_threads(n_threads) {
        0 => rayon::current_num_threads(),
        n => n,
    }
}

/// Bytes a sweep needs beyond the data arrays: the results (Rust vectors and their numpy copies,
/// the Python table), the TSQR block factors ([`BLOCK_ROWS`] rows per block) and per-thread block
/// buffers, column copies of the inputs, and per-thread simulation buffers.
///
/// `n_structures` structures with up to `p_max` parameters, a largest regressor of `q` columns
/// (output included), `n_est` / `n_val` samples of estimation and validation data, `n_cols` input
/// columns of the effect layout, `n_threads` as requested (0 = all cores, clamped as the boundary
/// clamps it). Saturates at `usize::MAX` instead of overflowing.
pub fn sweep_memory(
    n_structures: usize,
    p_max: usize,
    q: usize,
    n_est: usize,
    n_val: usize,
    n_cols: usize,
    n_threads: usize,
) -> usize {
    let threads = effective_threads(n_threads);
    let mul = |factors: &[usize]| factors.iter().fold(1usize, |a, &b| a.saturating_mul(b));
    let sum = |terms: &[usize]| terms.iter().fold(0usize, |a, &b| a.saturating_add(b));
    let f = std::mem::size_of::<f64>();
    let n_all = n_est.saturating_add(n_val);
    let per_structure = sum(&[mul(&[2, f, p_max]), f * 16, 600]);
    let blocks = (n_all / BLOCK_ROWS).saturating_add(2);
    let tsqr = sum(&[mul(&[2, blocks, q, q, f]), mul(&[threads, BLOCK_ROWS, q, f])]);
    let inputs = mul(&[2, n_all, n_cols, f]);
    let sim = mul(&[threads, 2, n_est.max(n_val), f]);
    sum(&[mul(&[n_structures, per_structure]), tsqr, inputs, sim])
}

/// Everything a sweep learns about one structure.
#[derive(Debug, Clone)]
pub struct StructureResult {
    pub theta: Vec<f64>,
    /// Residual sum of squares of the one-step predictor on estimation rows.
    pub rss_est: f64,
    /// Same on validation rows (NaN without validation data).
    pub rss_val: f64,
    pub sim_est: SimScore,
    pub sim_val: SimScore,
    /// Set when the structure could not be fitted (rank deficient); the numbers are then NaN.
    pub error: Option<ArxError>,
    /// 2: fitted by QR and simulated (stage 2, or every structure without `top`); 1: ranked by its
    /// one-step loss only (parameters from the normal equations refined against R), not simulated.
    pub stage: u8,
}

/// Whether the lane kernel applies: free run of linear structures on finite data.
fn lanes_apply(d: &Data, env: &Structure, opts: &SweepOptions) -> bool {
    opts.horizon.is_none()
        && env.output_terms.is_empty()
        && d.y.iter().all(|v| v.is_finite())
        && d.u.iter().all(|v| v.is_finite())
}

/// One structure on the general path (k-step prediction, output terms, missing samples). The k-step
/// prediction of a linear structure on complete data runs as a filter ([`predict_k_linear`]).
fn simulate_one(d: &Data, s: &Structure, theta: &[f64], first_lag: usize, limit: f64, opts: &SweepOptions) -> SimScore {
    let pred = match opts.horizon {
        Some(k) if k >= 1 && s.output_terms.is_empty() && complete(d) => predict_k_linear(d, s, theta, k, first_lag),
        _ => predict(d, s, theta, opts.horizon, first_lag),
    };
    score(d, &pred, limit)
}

/// No missing (non-finite) sample in the data.
fn complete(d: &Data) -> bool {
    d.y.iter().all(|v| v.is_finite()) && d.u.iter().all(|v| v.is_finite())
}

/// Simulates the fitted members of one lane group on `d`; `ucol` is `Some` on the lane path.
/// A simulation beyond `limit` (the [`divergence_limit`] of `d.y`) is stopped as diverged.
fn simulate_group(
    d: &Data,
    ucol: Option<&[f64]>,
    members: &[(usize, &Structure, &[f64])],
    first_lag: usize,
    limit: f64,
    opts: &SweepOptions,
) -> Vec<SimScore> {
    match ucol {
        Some(uc) => {
            let models: Vec<(&Structure, &[f64])> = members.iter().map(|&(_, s, th)| (s, th)).collect();
            free_run_rms_lanes(d, uc, &models, first_lag, limit)
        }
        None => members.iter().map(|&(_, s, th)| simulate_one(d, s, th, first_lag, limit, opts)).collect(),
    }
}

pub(crate) const NAN_SCORE: SimScore =
    SimScore { rms: f64::NAN, n: 0, diverged: false, norm: f64::NAN, mean: f64::NAN };

/// Exact QR solve of one structure from the factors, with its one-step losses (stage 2).
fn fit_exact(f: &GridFactors<'_>, s: &Structure) -> StructureResult {
    let cols = columns_in(&f.env, s);
    match solve_subset(&f.r_est, f.q, &cols, f.n_est) {
        Ok((theta, rss_est, _)) => {
            let rss_val = f.rss_val(&cols, &theta);
            StructureResult { theta, rss_est, rss_val, sim_est: NAN_SCORE, sim_val: NAN_SCORE, error: None, stage: 2 }
        }
        Err(e) => StructureResult {
            theta: vec![f64::NAN; cols.len()],
            rss_est: f64::NAN,
            rss_val: f64::NAN,
            sim_est: NAN_SCORE,
            sim_val: NAN_SCORE,
            error: Some(e),
            stage: 2,
        },
    }
}

/// Stage 1 for every structure, then stage 2 (exact fit) for the `top` best by one-step loss on
/// the validation rows (estimation rows without validation data). Returns the results and the
/// structures of stage 2.
fn two_stage_fits(
    f: &GridFactors,
    structures: &[Structure],
    top: usize,
    parallel: bool,
    heartbeat: &(dyn Fn() + Sync),
) -> Result<(Vec<StructureResult>, Vec<usize>)> {
    let factors = Factors::new(&f.r_est, f.val.as_ref(), f.q, f.n_est);
    let stage1 = one_step_all(&factors, &f.env, structures, parallel, heartbeat)?;
    let key = |r: &OneStep| {
        let v = if f.val.is_some() { r.rss_val } else { r.rss_est };
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    // The `top` smallest keys, ties to the lower index: a total order, so selecting them (linear
    // time) gives the same set as sorting every structure would.
    let keys: Vec<f64> = stage1.iter().map(key).collect();
    let mut ranked: Vec<usize> = (0..structures.len()).collect();
    if top > 0 && top < ranked.len() {
        ranked.select_nth_unstable_by(top - 1, |&i, &j| keys[i].total_cmp(&keys[j]).then(i.cmp(&j)));
    }
    ranked.truncate(top);
    ranked.sort_unstable();
    let stage_one = |r: OneStep| StructureResult {
        theta: r.theta,
        rss_est: r.rss_est,
        rss_val: r.rss_val,
        sim_est: NAN_SCORE,
        sim_val: NAN_SCORE,
        error: r.error,
        stage: 1,
    };
    let mut out: Vec<StructureResult> = if parallel {
        stage1.into_par_iter().map(stage_one).collect()
    } else {
        stage1.into_iter().map(stage_one).collect()
    };
    let fit_one = |&i: &usize| {
        heartbeat();
        fit_exact(f, &structures[i])
    };
    let exact: Vec<StructureResult> = if parallel {
        ranked.par_iter().with_max_len(FIT_TASK).map(fit_one).collect()
    } else {
        ranked.iter().map(fit_one).collect()
    };
    for (&i, r) in ranked.iter().zip(exact) {
        out[i] = r;
    }
    Ok((out, ranked))
}

/// What [`sweep`] returns.
pub struct Swept {
    /// One result per structure, in grid order.
    pub results: Vec<StructureResult>,
    /// Regression rows of the estimation data.
    pub n_est: usize,
    /// Regression rows of the validation data (0 without them).
    pub n_val: usize,
    /// Column-major q × q factor of the envelope's regressor on the estimation rows: any
    /// structure's fit, with its parameter covariance, follows from it
    /// ([`fit_from_factor`](crate::arx::fit::fit_from_factor)).
    pub r_est: Vec<f64>,
}

/// Fits and validates every structure. All structures use the rows from the grid's largest lag on,
/// so their losses compare on the same samples (as MATLAB `arxstruc`).
///
/// Every structure is solved from the triangular factor of the grid's largest regressor (cost
/// independent of N), then simulated: linear structures on complete data in groups of
/// [`LANES`](crate::simulate::lanes::LANES) of neighbouring `na` side by side, the others one by one.
/// Groups are formed from the grid alone, so results do not depend on the number of threads.
///
/// With `opts.top = Some(k)` (and more than k structures) the sweep runs in two stages: every
/// structure is ranked by its one-step loss from the factors ([`one_step_all`], stage 1), and only
/// the k best are fitted by QR and simulated (stage 2); [`StructureResult::stage`] tells which.
///
/// Each data set's simulations are judged against its own measured output: a prediction beyond
/// [`divergence_limit`]`(y)` of that data set is stopped and reported as diverged.
///
/// `progress(done)` is called about every `opts.chunk` simulated structures (from a worker thread,
/// possibly out of order) and once at the end with the total; `progress(0)` before each structure
/// is solved and before each block of rows is reduced. A caller stops the sweep by unwinding from
/// `progress` (Ctrl-C, see `python/sweep.rs`).
///
/// # Errors
/// `InvalidStructure` for an empty or inconsistent grid, `ShapeMismatch` when the validation data
/// have other inputs, `TooFewSamples` when the estimation data are shorter than the largest regressor.
pub fn sweep(
    est: &Data,
    val: Option<&Data>,
    structures: &[Structure],
    opts: &SweepOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Swept> {
    let heartbeat = || progress(0);
    let f = factor_grid(est, val, structures, opts.parallel, &heartbeat)?;
    let (n_est, n_val) = (f.n_est, f.n_val);

    // 1. Parameters and one-step losses of every structure, from R alone. `progress(0)` before each
    //    structure is a heartbeat: the caller may stop the sweep there (see `progress` above).
    let (mut out, simulated) = match opts.top {
        Some(top) if top < structures.len() => two_stage_fits(&f, structures, top, opts.parallel, &heartbeat)?,
        _ => {
            let fit_one = |s: &Structure| {
                progress(0);
                fit_exact(&f, s)
            };
            let all: Vec<StructureResult> = if opts.parallel {
                structures.par_iter().with_max_len(FIT_TASK).map(fit_one).collect()
            } else {
                structures.iter().map(fit_one).collect()
            };
            (all, (0..structures.len()).collect())
        }
    };

    // 2. Simulation, in lane groups of neighbouring na (fitted ones only).
    if !opts.simulate_estimation && val.is_none() {
        progress(structures.len());
        return Ok(Swept { results: out, n_est, n_val, r_est: f.r_est });
    }
    let order: Vec<usize> = simulated.into_iter().filter(|&i| out[i].error.is_none()).collect();
    let scores = simulate_all(est, val, structures, &out, order, (&f.env, f.first_lag, None), opts, progress);
    for (i, se, sv) in scores {
        out[i].sim_est = se;
        out[i].sim_val = sv;
    }
    progress(structures.len());
    Ok(Swept { results: out, n_est, n_val, r_est: f.r_est })
}

/// The triangular factor (column-major q × q, output last) of the grid envelope's regressor on one
/// part of a data set, and its number of rows: a partial of a fleet sweep. Partials of disjoint
/// experiments combine by QR of their stacked factors ([`crate::linalg::qr::stack_and_reduce`]); a part
/// may have fewer rows than columns.
///
/// # Errors
/// As [`sweep`] for the grid.
pub fn grid_factor(d: &Data, structures: &[Structure], parallel: bool) -> Result<(Vec<f64>, usize)> {
    let env = envelope(structures)?;
    env.check(d.m)?;
    for s in structures {
        s.check(d.m)?;
    }
    let rows = rows_of(d, &env, env.max_lag());
    Ok((to_col_major(&reduce(d, &env, &rows, parallel)), rows.len()))
}

/// Parameters and one-step losses of every structure from the factors of the grid's envelope
/// (as [`grid_factor`] gives them, combined over all parts), in one or two stages as [`sweep`];
/// nothing is simulated. Returns the results and the structures a sweep would simulate.
///
/// # Errors
/// `InvalidStructure` for factors that do not match the grid, `TooFewSamples` when the
/// estimation rows are fewer than the envelope's columns.
pub fn fits_from_factors(
    structures: &[Structure],
    r_est: Vec<f64>,
    n_est: usize,
    r_val: Option<Vec<f64>>,
    n_val: usize,
    top: Option<usize>,
    parallel: bool,
) -> Result<(Vec<StructureResult>, Vec<usize>)> {
    let env = envelope(structures)?;
    let q = env.n_params() + 1;
    if r_est.len() != q * q || r_val.as_ref().is_some_and(|r| r.len() != q * q) {
        return Err(ArxError::InvalidStructure(format!("the factors must be {q} × {q}, the grid envelope's size")));
    }
    if n_est < q {
        return Err(ArxError::TooFewSamples { needed: q, got: n_est });
    }
    let f =
        GridFactors { first_lag: env.max_lag(), env, q, r_est, n_est, val: r_val.map(ValidationLoss::Factor), n_val };
    match top {
        Some(top) if top < structures.len() => two_stage_fits(&f, structures, top, parallel, &|| {}),
        _ => {
            let all: Vec<StructureResult> = if parallel {
                structures.par_iter().with_max_len(FIT_TASK).map(|s| fit_exact(&f, s)).collect()
            } else {
                structures.iter().map(|s| fit_exact(&f, s)).collect()
            };
            Ok((all, (0..structures.len()).collect()))
        }
    }
}

/// Free-run (or k-step) scores of fitted structures on `d`, from `first_lag` (the whole grid's) on,
/// exactly as [`sweep`] simulates them: a fleet's simulation, spread over the workers. `limit`
/// replaces the divergence limit of `d` (a part of a fleet is judged by the whole fleet's output).
///
/// # Errors
/// As [`sweep`] for the structures; `ShapeMismatch` when a parameter vector has the wrong length.
pub fn simulate_structures(
    d: &Data,
    structures: &[Structure],
    thetas: Vec<Vec<f64>>,
    first_lag: usize,
    limit: Option<f64>,
    opts: &SweepOptions,
) -> Result<Vec<SimScore>> {
    simulate_structures_cancellable(d, structures, thetas, first_lag, limit, opts, &AtomicBool::new(false))
}

/// As [`simulate_structures`], stopping between groups of structures once `cancel` is set.
///
/// # Errors
/// As [`simulate_structures`]; `Interrupted` once `cancel` is set.
pub fn simulate_structures_cancellable(
    d: &Data,
    structures: &[Structure],
    thetas: Vec<Vec<f64>>,
    first_lag: usize,
    limit: Option<f64>,
    opts: &SweepOptions,
    cancel: &AtomicBool,
) -> Result<Vec<SimScore>> {
    let env = envelope(structures)?;
    env.check(d.m)?;
    let mut out = Vec::with_capacity(structures.len());
    for (s, theta) in structures.iter().zip(thetas) {
        s.check(d.m)?;
        if theta.len() != s.n_params() {
            return Err(ArxError::ShapeMismatch {
                what: "parameters".into(),
                expected: s.n_params(),
                got: theta.len(),
            });
        }
        out.push(StructureResult {
            theta,
            rss_est: f64::NAN,
            rss_val: f64::NAN,
            sim_est: NAN_SCORE,
            sim_val: NAN_SCORE,
            error: None,
            stage: 2,
        });
    }
    let lag = first_lag.max(env.max_lag());
    let opts = SweepOptions { simulate_estimation: false, ..*opts };
    let order = (0..structures.len()).filter(|&i| out[i].theta.iter().all(|v| v.is_finite())).collect();
    let mut scores = vec![NAN_SCORE; structures.len()];
    let stop = |_: usize| {
        if cancel.load(Ordering::Relaxed) {
            // Unwinds out of the parallel loop; caught by the caller's `catch_unwind` (see `python/run.rs`).
            std::panic::resume_unwind(Box::new(ArxError::Interrupted));
        }
    };
    let opts = SweepOptions { chunk: 1, ..opts };
    for (i, _, sv) in simulate_all(d, Some(d), structures, &out, order, (&env, lag, limit), &opts, &stop) {
        scores[i] = sv;
    }
    Ok(scores)
}

/// Poles a lane group may span: its lanes all run the recursion of its largest `na`.
const NA_SPAN: usize = 4;

/// Simulates the structures `order` (fitted ones) on the estimation data (when asked) and the
/// validation data, in lane groups of neighbouring `na`; returns `(index, estimation, validation)`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate_all(
    est: &Data,
    val: Option<&Data>,
    structures: &[Structure],
    out: &[StructureResult],
    mut order: Vec<usize>,
    (env, first_lag, limit): (&Structure, usize, Option<f64>),
    opts: &SweepOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<(usize, SimScore, SimScore)> {
    let sim_est = opts.simulate_estimation;
    let nan = NAN_SCORE;
    let lanes_est = sim_est && lanes_apply(est, env, opts);
    let lanes_val = val.is_some_and(|v| lanes_apply(v, env, opts));
    let ucol_est = if lanes_est { Some(input_columns(est)) } else { None };
    let ucol_val = if lanes_val { Some(input_columns(val.unwrap_or(est))) } else { None };
    let limit_est = limit.unwrap_or_else(|| divergence_limit(est.y));
    let limit_val = limit.unwrap_or_else(|| val.map_or(f64::NAN, |v| divergence_limit(v.y)));
    // A lane group pays for its largest na and for the union of its lanes' input lags. Groups of
    // up to four neighbouring na (NA_SPAN) and neighbouring delays and orders cost 13 % fewer
    // multiply-adds on the benchmark grid than groups of one na with eight delays and orders.
    let na_band = |s: &Structure| s.na.saturating_sub(1) / NA_SPAN;
    order.sort_by(|&i, &j| {
        let (a, b) = (&structures[i], &structures[j]);
        (na_band(a), &a.nk, &a.nb, a.na, i).cmp(&(na_band(b), &b.nk, &b.nb, b.na, j))
    });
    let width = if lanes_est || lanes_val { LANES } else { 1 };
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for &i in &order {
        match groups.last_mut() {
            Some(g) if g.len() < width && na_band(&structures[g[0]]) == na_band(&structures[i]) => g.push(i),
            _ => groups.push(vec![i]),
        }
    }
    let run_group = |g: &Vec<usize>| -> Vec<(SimScore, SimScore)> {
        let members: Vec<(usize, &Structure, &[f64])> =
            g.iter().map(|&i| (i, &structures[i], out[i].theta.as_slice())).collect();
        let se = if sim_est {
            simulate_group(est, ucol_est.as_deref(), &members, first_lag, limit_est, opts)
        } else {
            vec![nan; g.len()]
        };
        let sv = match val {
            Some(v) => simulate_group(v, ucol_val.as_deref(), &members, first_lag, limit_val, opts),
            None => vec![nan; g.len()],
        };
        se.into_iter().zip(sv).collect()
    };
    // No barrier between progress reports: each group adds to a counter when it finishes, and the
    // group that crosses a multiple of `chunk` reports (from whichever thread ran it).
    let chunk = opts.chunk.max(1);
    let done = AtomicUsize::new(structures.len() - order.len());
    let run_and_report = |g: &Vec<usize>| {
        let r = run_group(g);
        let before = done.fetch_add(g.len(), Ordering::Relaxed);
        let after = before + g.len();
        if after / chunk > before / chunk && after < structures.len() {
            progress(after);
        }
        r
    };
    let res: Vec<Vec<(SimScore, SimScore)>> = if opts.parallel {
        // One task per group: rayon would otherwise cut the groups into a few runs of dozens, and a
        // run whose thread the system deschedules (another process on the cores) cannot be shared.
        groups.par_iter().with_max_len(1).map(run_and_report).collect()
    } else {
        groups.iter().map(run_and_report).collect()
    };
    let mut scores = Vec::with_capacity(order.len());
    for (g, r) in groups.iter().zip(res) {
        for (&i, (se, sv)) in g.iter().zip(r) {
            scores.push((i, se, sv));
        }
    }
    scores
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::fit::fit;

    #[test]
    fn sweep_structure_equals_direct_fit_on_same_rows() {
        let n = 4000;
        let mut seed = 11u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let mut y = vec![0.0; n];
        for t in 3..n {
            y[t] = 0.9 * y[t - 1] - 0.2 * y[t - 2] + u[t - 1] + 0.5 * u[t - 3] + 0.05 * rnd();
        }
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let mut grid = Vec::new();
        for na in 1..=3 {
            for nb in 1..=3 {
                for nk in 0..=3 {
                    grid.push(Structure::new(na, vec![nb], vec![nk], vec![]).unwrap());
                }
            }
        }
        let opts = SweepOptions { simulate_estimation: true, horizon: None, parallel: true, chunk: 7, top: None };
        let res = sweep(&d, Some(&d), &grid, &opts, &|_| {}).unwrap().results;
        let lag = envelope(&grid).unwrap().max_lag();
        for (s, r) in grid.iter().zip(&res) {
            let f = fit(&d, s, lag, false).unwrap();
            for (a, b) in f.theta.iter().zip(&r.theta) {
                assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{s:?}: {a} vs {b}");
            }
            assert!((f.rss - r.rss_est).abs() <= 1e-9 * f.rss);
            assert!((r.rss_val - r.rss_est).abs() <= 1e-8 * f.rss);
        }
        let serial = SweepOptions { parallel: false, ..opts };
        let res1 = sweep(&d, Some(&d), &grid, &serial, &|_| {}).unwrap().results;
        for (a, b) in res.iter().zip(&res1) {
            assert_eq!(a.theta, b.theta);
            assert_eq!(a.sim_val.rms.to_bits(), b.sim_val.rms.to_bits());
        }
    }

    /// Each data set's simulation is judged against its own measured output.
    #[test]
    fn divergence_is_judged_per_data_set() {
        let n = 2000;
        let mut seed = 5u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let mut y = vec![0.0; n];
        for t in 1..n {
            y[t] = 0.5 * y[t - 1] + u[t - 1] + 0.01 * rnd();
        }
        // Validation output measured 10^-4 times smaller: the model's free run on these inputs is
        // about 10^4 times the measured output, beyond the limit of 10^3 times max |y_val|.
        let yv: Vec<f64> = y.iter().map(|v| v * 1e-4).collect();
        let starts = [0];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let v = Data::new(&yv, &u, 1, &starts).unwrap();
        let grid = vec![Structure::new(1, vec![1], vec![1], vec![]).unwrap()];
        let opts = SweepOptions { simulate_estimation: true, horizon: None, parallel: false, chunk: 1, top: None };
        let res = sweep(&d, Some(&v), &grid, &opts, &|_| {}).unwrap().results;
        assert!(!res[0].sim_est.diverged && res[0].sim_est.rms < 0.1, "{:?}", res[0].sim_est);
        assert!(res[0].sim_val.diverged, "{:?}", res[0].sim_val);
        // The same data as validation do not diverge.
        let res = sweep(&d, Some(&d), &grid, &opts, &|_| {}).unwrap().results;
        assert!(!res[0].sim_val.diverged);
    }

    #[test]
    fn sweep_memory_follows_the_formula_and_saturates() {
        let f = 8;
        let expected = |threads: usize| {
            let per_structure = 2 * f * 10 + f * 16 + 600;
            let blocks = 15_000 / BLOCK_ROWS + 2;
            let tsqr = 2 * blocks * 21 * 21 * f + threads * BLOCK_ROWS * 21 * f;
            100 * per_structure + tsqr + 2 * 15_000 * 2 * f + threads * 2 * 10_000 * f
        };
        assert_eq!(sweep_memory(100, 10, 21, 10_000, 5_000, 2, 1), expected(1));
        assert_eq!(sweep_memory(100, 10, 21, 10_000, 5_000, 2, 2), expected(2));
        // n_threads = 0 means all cores; an absurd request is capped per core like the boundary does.
        assert_eq!(sweep_memory(100, 10, 21, 10_000, 5_000, 2, 0), expected(rayon::current_num_threads()));
        assert_eq!(sweep_memory(100, 10, 21, 10_000, 5_000, 2, usize::MAX), expected(clamp_threads(usize::MAX)));
        assert!(clamp_threads(usize::MAX) >= MAX_THREADS_PER_CORE);
        assert_eq!(clamp_threads(0), 0);
        assert_eq!(clamp_threads(1), 1);
        // Absurd sizes saturate instead of overflowing.
        assert_eq!(sweep_memory(usize::MAX, 10, 21, 10, 0, 1, 1), usize::MAX);
        assert_eq!(sweep_memory(1, 1, usize::MAX, 10, 0, 1, 1), usize::MAX);
        assert_eq!(sweep_memory(1, 1, 3, usize::MAX, usize::MAX, usize::MAX, 1), usize::MAX);
    }
}
