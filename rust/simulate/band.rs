//! The first-order band of a free run (`arxid.checks.bands`): the variance of the free run along
//! the principal directions of the parameters' covariance, by central differences. Each pair of
//! free runs goes into two buffers reused for every direction and is summed into the variance at
//! once: no array per run handed to Python and no temporaries, the same numbers to the bit (the
//! same free runs, the differences and squares summed in the same order).

use std::sync::atomic::AtomicBool;

use crate::arx::structure::{Data, Structure};
use crate::error::{ArxError, Result};
use crate::simulate::linear_predict::free_run;
use crate::simulate::predict::complete;

/// `Σ_k ((ŷ(θ⁺_k) − ŷ(θ⁻_k)) / (2·step))²` per sample, `thetas` holding θ⁺_0, θ⁻_0, θ⁺_1, …; NaN
/// before each experiment's first prediction. `None` when an experiment has a missing sample (its
/// free run restarts from the measurements: the caller predicts each run instead).
///
/// # Errors
/// `InvalidStructure` for output terms or an odd number of parameter vectors; `ShapeMismatch` when a
/// vector's length is not the structure's; `Interrupted` once `cancel` is set.
pub fn free_run_variance(
    d: &Data,
    s: &Structure,
    thetas: &[Vec<f64>],
    step: f64,
    first_lag: usize,
    cancel: &AtomicBool,
) -> Result<Option<Vec<f64>>> {
    if !s.output_terms.is_empty() || thetas.len() % 2 == 1 {
        return Err(ArxError::InvalidStructure("a band needs pairs of parameters of a linear structure".into()));
    }
    if let Some(t) = thetas.iter().find(|t| t.len() != s.n_params()) {
        return Err(ArxError::ShapeMismatch {
            what: "parameters of a band's run".into(),
            expected: s.n_params(),
            got: t.len(),
        });
    }
    let lag = first_lag.max(s.max_lag());
    let mut rows = Vec::new();
    for (a, b) in d.segments() {
        let start = a + lag;
        if start >= b {
            continue;
        }
        if !complete(d, a, start, b) {
            return Ok(None);
        }
        rows.push((start, b));
    }
    let mut var = vec![f64::NAN; d.len()];
    for &(start, end) in &rows {
        var[start..end].fill(0.0);
    }
    let (mut hi, mut lo) = (vec![0.0; d.len()], vec![0.0; d.len()]);
    let two_step = 2.0 * step;
    for pair in thetas.chunks_exact(2) {
        for &rows in &rows {
            free_run(d, s, &pair[0], rows, &mut hi, cancel)?;
            free_run(d, s, &pair[1], rows, &mut lo, cancel)?;
            let (start, end) = rows;
            for ((v, &h), &l) in var[start..end].iter_mut().zip(&hi[start..end]).zip(&lo[start..end]) {
                let q = (h - l) / two_step;
                *v += q * q;
            }
        }
    }
    Ok(Some(var))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::predict::predict;

    #[test]
    fn the_variance_is_the_sum_over_the_pairs_of_predictions() {
        let n = 3000;
        let u: Vec<f64> = (0..n).map(|t| ((t * 37) % 101) as f64 / 50.0 - 1.0).collect();
        let y: Vec<f64> = (0..n).map(|t| ((t * 13) % 29) as f64 / 10.0).collect();
        let starts = [0, 1200];
        let d = Data::new(&y, &u, 1, &starts).unwrap();
        let s = Structure::new(2, vec![2], vec![1], vec![]).unwrap();
        let base = [-1.2, 0.5, 0.3, 0.1];
        let thetas: Vec<Vec<f64>> = (0..6)
            .map(|i| {
                base.iter()
                    .enumerate()
                    .map(|(j, b)| {
                        b + if (i / 2 + j) % 3 == 0 { 1e-3 } else { -5e-4 } * if i % 2 == 0 { 1.0 } else { -1.0 }
                    })
                    .collect()
            })
            .collect();
        let got = free_run_variance(&d, &s, &thetas, 0.01, 4, &AtomicBool::new(false)).unwrap().unwrap();
        let mut want = vec![0.0; n];
        for pair in thetas.chunks_exact(2) {
            let (h, l) = (predict(&d, &s, &pair[0], None, 4), predict(&d, &s, &pair[1], None, 4));
            for t in 0..n {
                let q = (h[t] - l[t]) / 0.02;
                want[t] += q * q;
            }
        }
        for t in 0..n {
            assert!(
                got[t].to_bits() == want[t].to_bits() || (got[t].is_nan() && want[t].is_nan()),
                "{t}: {} {}",
                got[t],
                want[t]
            );
        }
        assert!(got[3].is_nan() && got[1203].is_nan() && got[4].is_finite());
    }

    #[test]
    fn missing_samples_and_bad_parameters_are_said() {
        let (mut y, u) = (vec![1.0; 100], vec![0.5; 100]);
        let s = Structure::new(1, vec![1], vec![1], vec![]).unwrap();
        let never = AtomicBool::new(false);
        let pair = vec![vec![-0.5, 1.0], vec![-0.4, 1.0]];
        y[50] = f64::NAN; // a measured output after the start: the free run never reads it
        let d = Data::new(&y, &u, 1, &[0]).unwrap();
        assert!(free_run_variance(&d, &s, &pair, 0.01, 0, &never).unwrap().is_some());
        let u2 = {
            let mut v = u.clone();
            v[10] = f64::NAN;
            v
        };
        let d2 = Data::new(&y, &u2, 1, &[0]).unwrap();
        assert!(free_run_variance(&d2, &s, &pair, 0.01, 0, &never).unwrap().is_none());
        assert!(matches!(free_run_variance(&d2, &s, &pair[..1], 0.01, 0, &never), Err(ArxError::InvalidStructure(_))));
        assert!(matches!(
            free_run_variance(&d2, &s, &[vec![1.0], vec![1.0]], 0.01, 0, &never),
            Err(ArxError::ShapeMismatch { .. })
        ));
    }
}
