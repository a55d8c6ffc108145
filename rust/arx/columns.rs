//! The regressor layout of a grid: its envelope (the largest regressor, holding every column any
//! structure of the grid needs) and where each structure's columns sit inside it. Shared by the
//! exact sweep and the one-step ranking, which both solve structures from the envelope's factor.

use crate::arx::structure::Structure;
use crate::error::{ArxError, Result};

/// The regressor holding every column any structure of the grid needs: `na_max` output lags and,
/// for input i, lags from the smallest nk to the largest nk + nb − 1.
pub fn envelope(structures: &[Structure]) -> Result<Structure> {
    let first = structures.first().ok_or_else(|| ArxError::InvalidStructure("the grid is empty".into()))?;
    let m = first.nb.len();
    let mut na = 0;
    let mut lo = vec![usize::MAX; m];
    let mut hi = vec![0usize; m];
    let mut used = vec![false; m];
    for s in structures {
        if s.nb.len() != m || s.output_terms != first.output_terms {
            return Err(ArxError::InvalidStructure(
                "all structures of a grid need the same inputs and output terms".into(),
            ));
        }
        na = na.max(s.na);
        for i in 0..m {
            if s.nb[i] > 0 {
                used[i] = true;
                lo[i] = lo[i].min(s.nk[i]);
                hi[i] = hi[i].max(s.nk[i] + s.nb[i] - 1);
            }
        }
    }
    let nb = (0..m).map(|i| if used[i] { hi[i] - lo[i] + 1 } else { 0 }).collect();
    let nk = (0..m).map(|i| if used[i] { lo[i] } else { 0 }).collect();
    Structure::new(na, nb, nk, first.output_terms.clone())
}

/// Whether every column `s` reads is a column of the envelope `env` (same inputs, output lags and
/// each input's lags within the envelope's).
pub fn inside(env: &Structure, s: &Structure) -> bool {
    s.na <= env.na
        && s.nb.len() == env.nb.len()
        && (0..s.nb.len()).all(|i| s.nb[i] == 0 || (s.nk[i] >= env.nk[i] && s.nk[i] + s.nb[i] <= env.nk[i] + env.nb[i]))
}

/// Column indices of `s` inside the envelope `env`'s regressor.
pub fn columns_in(env: &Structure, s: &Structure) -> Vec<usize> {
    let mut cols = Vec::with_capacity(s.n_params());
    columns_into(env, s, &mut cols);
    cols
}

/// [`columns_in`] into a reused buffer.
pub fn columns_into(env: &Structure, s: &Structure, cols: &mut Vec<usize>) {
    cols.clear();
    cols.extend(0..s.na);
    let mut off = env.na;
    for i in 0..s.nb.len() {
        for j in 0..s.nb[i] {
            cols.push(off + s.nk[i] - env.nk[i] + j);
        }
        off += env.nb[i];
    }
    for l in 0..s.output_terms.len() {
        cols.push(off + l);
    }
}
