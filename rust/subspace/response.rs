//! The response of a discrete state-space model `x(t+1) = A x(t) + B u(t)`, `y(t) = C x(t) + D u(t)`.
//!
//! The one-step predictor of the innovation form is the same recursion with A − KC, [B − KD, K]
//! and the measured outputs as extra inputs, so simulation and prediction share this loop.

use std::sync::atomic::{AtomicBool, Ordering};

use faer::MatRef;

use crate::error::{try_vec, ArxError, Result};

/// The matrices of a state-space model (any shapes that agree: n states, nu inputs, ny outputs).
#[derive(Clone, Copy, Debug)]
pub struct StateSpaceRef<'a> {
    pub a: MatRef<'a, f64>,
    pub b: MatRef<'a, f64>,
    pub c: MatRef<'a, f64>,
    pub d: MatRef<'a, f64>,
}

impl StateSpaceRef<'_> {
    /// Checks that the four matrices agree.
    ///
    /// # Errors
    /// `ShapeMismatch` naming the matrix that does not fit.
    pub fn check(&self) -> Result<()> {
        let (n, nu, ny) = (self.a.nrows(), self.b.ncols(), self.c.nrows());
        let shapes = [
            ("A's columns", self.a.ncols(), n),
            ("B's rows", self.b.nrows(), n),
            ("C's columns", self.c.ncols(), n),
            ("D's rows", self.d.nrows(), ny),
            ("D's columns", self.d.ncols(), nu),
        ];
        for (what, got, expected) in shapes {
            if got != expected {
                return Err(ArxError::ShapeMismatch { what: what.into(), expected, got });
            }
        }
        Ok(())
    }
}

/// `(y, x)`: outputs (N × ny) and states (N × n, the state at each sample before its input acts),
/// both row-major, from state `x0` driven by `u` (N × nu, row-major). A state that grows past
/// 1e150 stops the loop: the rest is NaN (the model is unstable on these data).
///
/// # Errors
/// `ShapeMismatch` when the matrices, `x0` or `u` disagree; `Interrupted` on Ctrl-C.
pub fn respond(m: StateSpaceRef<'_>, x0: &[f64], u: &[f64], cancel: &AtomicBool) -> Result<(Vec<f64>, Vec<f64>)> {
    m.check()?;
    let (n, nu, ny) = (m.a.nrows(), m.b.ncols(), m.c.nrows());
    if x0.len() != n {
        return Err(ArxError::ShapeMismatch { what: "the initial state".into(), expected: n, got: x0.len() });
    }
    let samples = u.len().checked_div(nu).unwrap_or(0);
    if samples * nu != u.len() {
        return Err(ArxError::ShapeMismatch { what: "the inputs".into(), expected: samples * nu, got: u.len() });
    }
    let mut y = try_vec(samples * ny, f64::NAN, "the simulated outputs")?;
    let mut states = try_vec(samples * n, f64::NAN, "the simulated states")?;
    let mut x = x0.to_vec();
    let mut next = vec![0.0; n];
    for t in 0..samples {
        if t % 65536 == 0 && cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let ut = &u[t * nu..(t + 1) * nu];
        states[t * n..(t + 1) * n].copy_from_slice(&x);
        for o in 0..ny {
            let cx: f64 = (0..n).map(|i| m.c[(o, i)] * x[i]).sum();
            y[t * ny + o] = cx + (0..nu).map(|j| m.d[(o, j)] * ut[j]).sum::<f64>();
        }
        for (i, v) in next.iter_mut().enumerate() {
            *v = (0..n).map(|k| m.a[(i, k)] * x[k]).sum::<f64>() + (0..nu).map(|j| m.b[(i, j)] * ut[j]).sum::<f64>();
        }
        std::mem::swap(&mut x, &mut next);
        if x.iter().any(|v| v.is_nan() || v.abs() >= 1e150) {
            break;
        }
    }
    Ok((y, states))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_first_order_model_matches_its_recursion() {
        let (a, b, c, d) = (faer::mat![[0.5]], faer::mat![[1.0]], faer::mat![[2.0]], faer::mat![[0.25]]);
        let m = StateSpaceRef { a: a.as_ref(), b: b.as_ref(), c: c.as_ref(), d: d.as_ref() };
        let never = AtomicBool::new(false);
        let (y, x) = respond(m, &[1.0], &[1.0, 0.0, 2.0], &never).unwrap();
        assert_eq!(x, vec![1.0, 1.5, 0.75]);
        assert_eq!(y, vec![2.25, 3.0, 2.0]);
        assert!(respond(m, &[1.0, 2.0], &[1.0], &never).is_err());
    }
}
