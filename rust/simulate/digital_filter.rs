//! The digital filter $y = (b / a)\, x$ from rest, computed as `scipy.signal.lfilter` computes it
//! (direct form II transposed, the coefficients divided by $a_0$ and padded with zeros to one
//! length), so its numbers are scipy's to the last bit. The analysis filters step responses and
//! signals with it without importing scipy.signal, which takes most of a short analysis's time.

use crate::error::{ArxError, Result};

/// $y(t)$ with $\sum_i a_i\, y(t - i) = \sum_j b_j\, x(t - j)$, from rest.
///
/// # Errors
/// `InvalidStructure` when `b` or `a` is empty or $a_0 = 0$.
pub fn lfilter(b: &[f64], a: &[f64], x: &[f64]) -> Result<Vec<f64>> {
    let a0 = a.first().copied().unwrap_or(0.0);
    if b.is_empty() || a0 == 0.0 {
        return Err(ArxError::InvalidStructure("a filter needs a numerator and a[0] != 0".into()));
    }
    let n = a.len().max(b.len());
    let padded = |c: &[f64]| (0..n).map(|i| c.get(i).copied().unwrap_or(0.0) / a0).collect::<Vec<f64>>();
    let (b, a) = (padded(b), padded(a));
    let mut state = vec![0.0; n - 1];
    Ok(x.iter()
        .map(|&xn| {
            if n == 1 {
                return xn * b[0];
            }
            let yn = state[0] + b[0] * xn;
            for i in 0..n - 2 {
                state[i] = state[i + 1] + xn * b[i + 1] - yn * a[i + 1];
            }
            state[n - 2] = xn * b[n - 1] - yn * a[n - 1];
            yn
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_recursion_and_normalisation() {
        // y(t) = 0.5 y(t-1) + x(t-1), written with a0 = 2.
        let y = lfilter(&[0.0, 2.0], &[2.0, -1.0], &[1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(y, vec![0.0, 1.0, 0.5, 0.25]);
        let fir = lfilter(&[1.0, -1.0, 0.5], &[1.0], &[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(fir, vec![1.0, 1.0, 1.5]);
        assert_eq!(lfilter(&[3.0], &[2.0], &[1.0, -2.0]).unwrap(), vec![1.5, -3.0]);
    }

    #[test]
    fn a_zero_leading_denominator_is_refused() {
        assert!(lfilter(&[1.0], &[0.0, 1.0], &[1.0]).is_err());
        assert!(lfilter(&[], &[1.0], &[1.0]).is_err());
    }
}
