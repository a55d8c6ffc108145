//! The pieces of a Levenberg–Marquardt search shared by the prediction-error fits (polynomial and
//! state-space): the damped Gauss–Newton step solved by QR, and why the iterations stopped.

use std::fmt;

use crate::linalg::qr::{back_substitute, small_qr};

/// Why the iterations stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// The full Gauss–Newton step would lower the loss by less than the tolerance (a minimum).
    Converged,
    /// An accepted step lowered the loss by less than the tolerance.
    SmallImprovement,
    /// The iteration limit was reached first.
    MaxIterations,
    /// No damped step lowered the loss although the gradient is not negligible.
    Stalled,
}

impl Termination {
    /// True when the end point is a (local) minimum by the first-order test.
    pub fn converged(self) -> bool {
        matches!(self, Termination::Converged | Termination::SmallImprovement)
    }
}

impl fmt::Display for Termination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Termination::Converged => {
                "converged: a Gauss-Newton step would improve the loss by less than the tolerance"
            }
            Termination::SmallImprovement => "converged: the last step improved the loss by less than the tolerance",
            Termination::MaxIterations => "stopped at the iteration limit before converging",
            Termination::Stalled => {
                "stalled: no damped step lowered the loss although the gradient is not negligible (poor scaling or a \
                 non-smooth point)"
            }
        })
    }
}

/// Levenberg–Marquardt step: minimises $\|R_{11}\delta + r\|^2 + \lambda \|\mathrm{diag}(s)\,\delta\|^2$
/// by QR of the stacked $[R_{11}, r; \sqrt\lambda\,\mathrm{diag}(s), 0]$.
pub fn damped_step(r: &[f64], p: usize, lambda: f64, scale: &[f64]) -> Vec<f64> {
    let (q, m) = (p + 1, 2 * p);
    let mut a = vec![0.0; m * q];
    for j in 0..q {
        for i in 0..=j.min(p - 1) {
            a[i + j * m] = r[i + j * q];
        }
    }
    for j in 0..p {
        a[p + j + j * m] = lambda.sqrt() * scale[j];
    }
    small_qr(&mut a, m, q);
    let rhs: Vec<f64> = (0..p).map(|i| a[i + p * m]).collect();
    let mut delta = vec![0.0; p];
    back_substitute(&a, m, &rhs, &mut delta);
    delta.iter().map(|d| -d).collect()
}
