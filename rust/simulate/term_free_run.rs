//! Free run of a structure with output terms (`y^3`, `|y|`, `sign(y)`, `sign(dy)`, each perhaps
//! times a logged signal) over one experiment without missing samples: the path
//! [`crate::simulate::predict::predict_cancellable`] takes for such a structure instead of its general step.
//!
//! The input part is summed first, a chunk at a time, as in [`crate::simulate::linear_predict`]; the
//! recursion then adds the AR part (older outputs first) and the output terms on the simulated
//! outputs kept in a short history. The general step reads each past output through a closure and
//! checks every sample for a restart; on complete data it never restarts, so this is the same
//! recursion with the sums in another order: equal to rounding, not to the last bit.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::arx::structure::{sign, Data, OutputKind, OutputTerm, Structure};
use crate::error::{ArxError, Result};
use crate::linalg::simd::{avx2_fma, madd};
use crate::simulate::linear_predict::{sums, Taps, CHUNK};

/// Free run of `s` for `t` in `[start, end)` into `out[t]`, from the measured outputs before
/// `start`. The caller has checked that the experiment's inputs and initial outputs are finite; a
/// simulation that overflows keeps its inf/NaN, as in the general step.
///
/// Returns false, having done nothing, for an AR part longer than 30: the general step runs it.
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
    debug_assert!(theta.len() == s.n_params());
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    if avx2_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { free_run_avx2(d, s, theta, rows, out, cancel) };
    }
    free_run_impl::<false>(d, s, theta, rows, out, cancel)
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
    free_run_impl::<true>(d, s, theta, rows, out, cancel)
}

/// [`recursion`] with the history in an array of a size known at compile time and the terms' sum
/// specialised for the usual single term, so that the history stays in registers and no `match`
/// on the kind of term runs per sample (a history in memory and a per-sample dispatch took three
/// times as long).
#[inline(always)]
fn free_run_impl<const FMA: bool>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<bool> {
    match s.na {
        0..=2 => with_terms::<FMA, 4>(d, s, theta, rows, out, cancel).map(|()| true),
        3..=6 => with_terms::<FMA, 8>(d, s, theta, rows, out, cancel).map(|()| true),
        na if na + 2 <= LONG => with_terms::<FMA, LONG>(d, s, theta, rows, out, cancel).map(|()| true),
        _ => Ok(false),
    }
}

/// The history kept for na from 7 to `LONG` − 2 (a longer AR part takes the general step).
const LONG: usize = 32;

/// [`recursion`] with the output terms' contribution `acc + Σ c·g(y(t−1), y(t−2))·s(t−1)` as a
/// closure, one per kind of single term, and a loop over the terms otherwise.
#[inline(always)]
fn with_terms<const FMA: bool, const H: usize>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    rows: (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
) -> Result<()> {
    let first_term = theta.len() - s.output_terms.len();
    let terms: Vec<(f64, OutputTerm)> =
        theta[first_term..].iter().copied().zip(s.output_terms.iter().copied()).collect();
    macro_rules! run {
        ($c:ident, $by:ident, |$y1:ident, $y2:ident| $g:expr) => {
            recursion::<FMA, H, _>(d, s, theta, rows, out, cancel, |acc, $y1, $y2, t| {
                madd::<FMA>($c, $g * $by.map_or(1.0, |m| d.u_at(t - 1, m)), acc)
            })
        };
    }
    match terms.as_slice() {
        &[(c, OutputTerm { kind, multiplier })] => match kind {
            OutputKind::Pow(1) => run!(c, multiplier, |y1, _y2| y1),
            OutputKind::Pow(2) => run!(c, multiplier, |y1, _y2| y1 * y1),
            OutputKind::Pow(3) => run!(c, multiplier, |y1, _y2| y1 * y1 * y1),
            OutputKind::Pow(p) => run!(c, multiplier, |y1, _y2| y1.powi(p)),
            OutputKind::Abs => run!(c, multiplier, |y1, _y2| y1.abs()),
            OutputKind::Sign => run!(c, multiplier, |y1, _y2| sign(y1)),
            OutputKind::SignDiff => run!(c, multiplier, |y1, y2| sign(y1 - y2)),
        },
        _ => recursion::<FMA, H, _>(d, s, theta, rows, out, cancel, |mut acc, y1, y2, t| {
            for &(c, term) in &terms {
                let s1 = term.multiplier.map_or(1.0, |m| d.u_at(t - 1, m));
                acc = madd::<FMA>(c, term.eval(y1, y2, s1), acc);
            }
            acc
        }),
    }
}

/// The free run with a history of `H` outputs (`H` >= na + 2); `terms(acc, y(t−1), y(t−2), t)`
/// adds the output terms at sample t.
#[inline(always)]
fn recursion<const FMA: bool, const H: usize, F: Fn(f64, f64, f64, usize) -> f64>(
    d: &Data,
    s: &Structure,
    theta: &[f64],
    (start, end): (usize, usize),
    out: &mut [f64],
    cancel: &AtomicBool,
    terms: F,
) -> Result<()> {
    let na = s.na;
    // h[i]: the simulated (at first, measured) output i + 1 steps back. The structure reads
    // `reach` of them (`start` is at least that far into the experiment); the rest stay 0, so that
    // every term may read h[1], which only sign(dy) uses.
    let reach = s.output_terms.iter().map(OutputTerm::lag).fold(na, usize::max);
    let mut h = [0.0f64; H];
    for (i, v) in h.iter_mut().enumerate().take(reach) {
        *v = d.y[start - 1 - i];
    }
    let mut neg_a = [0.0f64; H];
    for (n, a) in neg_a.iter_mut().zip(&theta[..na]) {
        *n = -a;
    }
    let taps = Taps::new(s, theta);
    let mut scratch = Vec::new();
    let mut t0 = start;
    while t0 < end {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let t1 = (t0 + CHUNK).min(end);
        let x = &mut out[t0..t1];
        sums::<FMA>(x, taps.columns(d, (t0, t1), &mut scratch), &taps.taps, &[], &[]);
        for (t, xv) in (t0..t1).zip(x.iter_mut()) {
            // The older outputs first; −a·0 for the unused entries of the history adds nothing.
            let mut acc = *xv;
            for i in (0..H).rev() {
                acc = madd::<FMA>(neg_a[i], h[i], acc);
            }
            acc = terms(acc, h[0], h[1], t);
            for i in (1..H).rev() {
                h[i] = h[i - 1];
            }
            h[0] = acc;
            *xv = acc;
        }
        t0 = t1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::linear_predict::tests::Lcg;
    use crate::simulate::predict::{predict, step_reference};

    /// The free run with output terms agrees with the general step to 1e-12 of the output's scale
    /// on random stable structures (every kind of term, with and without a multiplier, several
    /// inputs and experiments, a first lag beyond the structure's); an experiment with a missing
    /// input still takes the general step and predicts NaN where it does.
    #[test]
    fn agrees_with_the_general_step() {
        let kinds = [OutputKind::Pow(2), OutputKind::Pow(3), OutputKind::Abs, OutputKind::Sign, OutputKind::SignDiff];
        let mut rng = Lcg(11);
        for case in 0..80 {
            let m = 1 + rng.below(3);
            let na = rng.below(5);
            let nb: Vec<usize> = (0..m).map(|_| rng.below(4)).collect();
            let nk: Vec<usize> = (0..m).map(|_| rng.below(3)).collect();
            let terms: Vec<OutputTerm> = (0..1 + rng.below(2))
                .map(|_| OutputTerm {
                    kind: kinds[rng.below(kinds.len())],
                    multiplier: if rng.below(2) == 0 { None } else { Some(rng.below(m)) },
                })
                .collect();
            let s = Structure::new(na, nb.clone(), nk, terms.clone()).unwrap();
            // A small AR part (sum of |a| < 0.6) and small term coefficients keep y^2, y^3 bounded.
            let mut theta: Vec<f64> = (0..na).map(|_| 0.6 / na as f64 * 2.0 * rng.next()).collect();
            theta.extend((0..nb.iter().sum::<usize>()).map(|_| rng.next()));
            theta.extend(terms.iter().map(|_| 0.1 * rng.next()));
            let n = 4000 + rng.below(200);
            let mut u: Vec<f64> = (0..n * m).map(|_| rng.next()).collect();
            let y: Vec<f64> = (0..n).map(|_| rng.next()).collect();
            let starts = [0, 1300, 3100 + rng.below(400)];
            if case % 4 == 0 {
                u[(starts[1] + 500) * m] = f64::NAN; // the second experiment has a gap
            }
            let d = Data::new(&y, &u, m, &starts).unwrap();
            let first_lag = s.max_lag() + rng.below(3);
            let fast = predict(&d, &s, &theta, None, first_lag);
            let general = step_reference(&d, &s, &theta, None, first_lag);
            let scale = general.iter().filter(|v| v.is_finite()).fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(scale > 0.0 && scale < 10.0, "case {case}: scale {scale}");
            for (t, (f, g)) in fast.iter().zip(&general).enumerate() {
                assert_eq!(f.is_nan(), g.is_nan(), "case {case} t={t}");
                if g.is_finite() {
                    assert!((f - g).abs() <= 1e-12 * scale, "case {case} t={t}: {f} vs {g}");
                }
            }
        }
    }

    #[test]
    fn stops_when_cancelled() {
        let n = 3 * CHUNK;
        let u: Vec<f64> = (0..n).map(|t| (t % 7) as f64).collect();
        let y = vec![0.1; n];
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        let s =
            Structure::new(1, vec![1], vec![1], vec![OutputTerm { kind: OutputKind::Sign, multiplier: None }]).unwrap();
        let mut out = vec![0.0; n];
        let got = free_run(&d, &s, &[-0.5, 0.1, 0.2], (2, n), &mut out, &AtomicBool::new(true));
        assert!(matches!(got, Err(ArxError::Interrupted)));
    }
}

#[cfg(test)]
mod perf_probe {
    use super::*;

    /// Timing on 2M samples (ignored by default; `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn free_run_timing() {
        let n = 2_000_000;
        let mut seed = 5u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let y: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        for kind in [OutputKind::Pow(3), OutputKind::Sign, OutputKind::SignDiff] {
            let s = Structure::new(3, vec![3], vec![1], vec![OutputTerm { kind, multiplier: None }]).unwrap();
            let theta = [-0.5, 0.1, 0.05, 1.0, 0.5, 0.2, 0.01];
            let mut out = vec![0.0; n];
            let mut best = f64::INFINITY;
            for _ in 0..5 {
                let t = std::time::Instant::now();
                free_run(&d, &s, &theta, (3, n), &mut out, &AtomicBool::new(false)).unwrap();
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!("{kind:?}: {:.2} ms", best * 1e3);
        }
    }
}
