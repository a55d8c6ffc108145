//! A and C from the extended observability matrix Γ (shift invariance, least squares).

use faer::prelude::*;
use faer::Mat;

use crate::error::{ArxError, Result};

/// `(A, C)`: C is the first block row of Γ, A the least-squares solution of Γ↑ A = Γ↓ (Γ without
/// its last, respectively first, block row of `ny` rows).
///
/// # Errors
/// `InvalidStructure` when Γ has fewer than two block rows or fewer rows than needed for A.
pub fn state_matrices(gamma: &Mat<f64>, n_outputs: usize) -> Result<(Mat<f64>, Mat<f64>)> {
    let (rows, n) = (gamma.nrows(), gamma.ncols());
    if rows < n + n_outputs || rows < 2 * n_outputs {
        return Err(ArxError::InvalidStructure(format!(
            "order {n} needs a future horizon of more than {} samples with {n_outputs} output(s)",
            n / n_outputs.max(1)
        )));
    }
    let c = gamma.as_ref().subrows(0, n_outputs).to_owned();
    let upper = gamma.as_ref().subrows(0, rows - n_outputs);
    let lower = gamma.as_ref().subrows(n_outputs, rows - n_outputs);
    let a = upper.col_piv_qr().solve_lstsq(lower);
    Ok((a, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shift_invariance_recovers_a_from_an_exact_observability_matrix() {
        let a = faer::mat![[0.9, 0.2], [-0.1, 0.7]];
        let c = faer::mat![[1.0, 0.5]];
        let mut gamma = Mat::zeros(5, 2);
        let mut power = Mat::<f64>::identity(2, 2);
        for k in 0..5 {
            let row = &c * &power;
            for j in 0..2 {
                gamma[(k, j)] = row[(0, j)];
            }
            power = &power * &a;
        }
        let (a_hat, c_hat) = state_matrices(&gamma, 1).unwrap();
        for i in 0..2 {
            assert!((c_hat[(0, i)] - c[(0, i)]).abs() < 1e-14);
            for j in 0..2 {
                assert!((a_hat[(i, j)] - a[(i, j)]).abs() < 1e-12);
            }
        }
        assert!(state_matrices(&gamma.as_ref().subrows(0, 2).to_owned(), 1).is_err());
    }
}
