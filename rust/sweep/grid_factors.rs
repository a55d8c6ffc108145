//! The factors every structure of a grid is solved from: the triangular factor R of the grid
//! envelope's regressor on the estimation rows, and on the validation rows its Gram matrix or its R.

use rayon::prelude::*;

use crate::arx::columns::envelope;
use crate::arx::reduce::reduce_with;
use crate::arx::structure::{usable_rows, Data, Structure};
use crate::error::{ArxError, Result};
use crate::linalg::qr::to_col_major;
use crate::sweep::validation_gram::{gram_applies, ValidationGram, ValidationLoss};

/// `‖R[:, cols ∪ y] · [−θ; 1]‖²`: the residual sum of squares of θ on the rows that produced R.
pub(crate) fn rss_from_r(r: &[f64], q: usize, cols: &[usize], theta: &[f64]) -> f64 {
    let mut v = vec![0.0; q];
    for (c, &j) in cols.iter().enumerate() {
        for i in 0..q {
            v[i] -= r[i + j * q] * theta[c];
        }
    }
    for i in 0..q {
        v[i] += r[i + (q - 1) * q];
    }
    v.iter().map(|x| x * x).sum()
}

/// Regression rows of the envelope: every sample from `first_lag` into each experiment when the data
/// are complete (no per-row check needed), else the rows [`usable_rows`] keeps.
pub(crate) fn rows_of(d: &Data, env: &Structure, first_lag: usize) -> Vec<usize> {
    if env.output_terms.is_empty() && d.y.iter().all(|v| v.is_finite()) && d.u.iter().all(|v| v.is_finite()) {
        let lag = first_lag.max(env.max_lag());
        d.segments().into_iter().flat_map(|(a, b)| (a + lag).min(b)..b).collect()
    } else {
        usable_rows(d, env, first_lag).0
    }
}

/// The triangular factor every structure of a grid is solved from, and what its validation losses
/// come from.
pub(crate) struct GridFactors<'a> {
    pub(crate) env: Structure,
    pub(crate) first_lag: usize,
    pub(crate) q: usize,
    pub(crate) r_est: Vec<f64>,
    pub(crate) n_est: usize,
    pub(crate) val: Option<ValidationLoss<'a>>,
    pub(crate) n_val: usize,
}

impl GridFactors<'_> {
    /// One-step residual sum of squares of θ (on the envelope's columns `cols`) on the validation
    /// rows; NaN without validation data.
    pub(crate) fn rss_val(&self, cols: &[usize], theta: &[f64]) -> f64 {
        match &self.val {
            None => f64::NAN,
            Some(ValidationLoss::Factor(r)) => rss_from_r(r, self.q, cols, theta),
            Some(ValidationLoss::Gram(g)) => {
                g.rss(cols, theta).unwrap_or_else(|| rss_from_r(g.factor(), self.q, cols, theta))
            }
        }
    }
}

/// Checks the grid and reduces the envelope's regressor on the estimation data to R; on the
/// validation data to its Gram matrix (complete data, linear structures) or else to R.
pub(crate) fn factor_grid<'a>(
    est: &Data,
    val: Option<&Data<'a>>,
    structures: &[Structure],
    parallel: bool,
    heartbeat: &(dyn Fn() + Sync),
) -> Result<GridFactors<'a>> {
    let keep_going = || {
        heartbeat();
        true
    };
    let env = envelope(structures)?;
    env.check(est.m)?;
    check_all(structures, est.m, parallel)?;
    let first_lag = env.max_lag();
    let q = env.n_params() + 1;
    let bound = est.max_rows(first_lag);
    if bound < q {
        return Err(ArxError::TooFewSamples { needed: q, got: bound });
    }
    let rows = rows_of(est, &env, first_lag);
    if rows.len() < q {
        return Err(ArxError::TooFewSamples { needed: q, got: rows.len() });
    }
    let n_est = rows.len();
    let r_est = to_col_major(&reduce_with(est, &env, &rows, parallel, &keep_going));
    drop(rows);
    let (val, n_val) = match val {
        Some(v) => {
            if v.m != est.m {
                return Err(ArxError::ShapeMismatch { what: "validation inputs".into(), expected: est.m, got: v.m });
            }
            let vrows = rows_of(v, &env, first_lag);
            let n = vrows.len();
            if gram_applies(v, &env) {
                heartbeat();
                (Some(ValidationLoss::Gram(Box::new(ValidationGram::new(v, &env, first_lag, parallel)))), n)
            } else {
                (Some(ValidationLoss::Factor(to_col_major(&reduce_with(v, &env, &vrows, parallel, &keep_going)))), n)
            }
        }
        None => (None, 0),
    };
    Ok(GridFactors { env, first_lag, q, r_est, n_est, val, n_val })
}

/// Checks every structure against `m` inputs; the error is the first structure's in grid order,
/// however many threads look.
fn check_all(structures: &[Structure], m: usize, parallel: bool) -> Result<()> {
    if parallel && structures.par_iter().all(|s| s.check(m).is_ok()) {
        return Ok(());
    }
    structures.iter().try_for_each(|s| s.check(m))
}
