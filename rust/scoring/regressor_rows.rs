//! A model's regressors written out at given sample rows, row by row, for the added-variable tests
//! (`diagnosis/scoring.py` reads them as a row-major matrix): numpy wrote them a column at a time,
//! each column one more pass over the matrix with a temporary per block of rows, and a further pass
//! to find the rows touching a missing sample. Here each row is written once, its finiteness noted.
//!
//! The values are those of `models/regressors.py` to the last bit: the output lags negated (or not),
//! the input columns copied, an output term evaluated as numpy evaluates it (an integer power by
//! squaring, as `integer_power`; `sign` of NaN is NaN, not the core's 0, so a row that reads a
//! missing output through a sign is found missing as numpy finds it).

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::arx::structure::{fill_lags, Data, OutputKind, Structure};
use crate::error::{ArxError, Result};

/// Rows per chunk of work.
const CHUNK: usize = 4096;

/// Writes the regressors of `s` on `d` at the samples `rows` into the first `s.n_params()` columns of
/// `out` (row-major, `width` columns per row) and sets `finite[r]` to whether every value of row r
/// is finite. The output lags are `-y(t-i)` when `negate_output`, else `y(t-i)`.
///
/// # Errors
/// `ShapeMismatch` when `out` or `finite` does not fit the rows or `width` is below the parameters;
/// `InvalidStructure` when a row is closer than the structure's lag to the start of the samples or
/// beyond their end; `Interrupted` once `cancel` is set.
#[allow(clippy::too_many_arguments)]
pub fn regressor_rows(
    d: &Data,
    s: &Structure,
    rows: &[i64],
    negate_output: bool,
    out: &mut [f64],
    width: usize,
    finite: &mut [bool],
    parallel: bool,
    cancel: &AtomicBool,
) -> Result<()> {
    let p = s.n_params();
    if width < p || out.len() != rows.len() * width {
        return Err(ArxError::ShapeMismatch {
            what: "regressor rows".into(),
            expected: rows.len() * p,
            got: out.len(),
        });
    }
    if finite.len() != rows.len() {
        return Err(ArxError::ShapeMismatch { what: "finite flags".into(), expected: rows.len(), got: finite.len() });
    }
    let lag = s.max_lag() as i64;
    if let Some(&t) = rows.iter().find(|&&t| t < lag || t >= d.len() as i64) {
        return Err(ArxError::InvalidStructure(format!(
            "regression row {t} is outside samples {lag} to {} (the structure reads {lag} back)",
            d.len()
        )));
    }
    let work = |(i, (part, ok)): (usize, (&mut [f64], &mut [bool]))| -> Result<()> {
        if cancel.load(Ordering::Relaxed) {
            return Err(ArxError::Interrupted);
        }
        let at = &rows[i * CHUNK..i * CHUNK + ok.len()];
        for ((row, flag), &t) in part.chunks_exact_mut(width).zip(ok.iter_mut()).zip(at) {
            *flag = write_row(d, s, t as usize, negate_output, &mut row[..p]);
        }
        Ok(())
    };
    let chunks = out.chunks_mut(CHUNK * width).zip(finite.chunks_mut(CHUNK));
    if parallel {
        let chunks: Vec<_> = chunks.collect();
        chunks.into_par_iter().enumerate().try_for_each(work)
    } else {
        chunks.enumerate().try_for_each(work)
    }
}

/// One row at sample `t` (at least the structure's lag): whether every value is finite.
#[inline]
fn write_row(d: &Data, s: &Structure, t: usize, negate_output: bool, row: &mut [f64]) -> bool {
    let (mut c, mut finite) = fill_lags(d, s, t, negate_output, row);
    for term in &s.output_terms {
        let y1 = d.y[t - 1];
        let g = match term.kind {
            OutputKind::Pow(power) => integer_power(y1, power),
            OutputKind::Abs => y1.abs(),
            OutputKind::Sign => numpy_sign(y1),
            OutputKind::SignDiff => numpy_sign(y1 - d.y[t - 2]),
        };
        let v = term.multiplier.map_or(g, |m| g * d.u_at(t - 1, m));
        finite &= v.is_finite();
        row[c] = v;
        c += 1;
    }
    finite
}

/// `x^power` (power at least 1) by squaring and multiplying in the order of Python's
/// `integer_power`: the same bits.
#[inline]
fn integer_power(x: f64, power: i32) -> f64 {
    let (mut base, mut power, mut result) = (x, power, None::<f64>);
    loop {
        if power & 1 == 1 {
            result = Some(result.map_or(base, |r| r * base));
        }
        power >>= 1;
        if power <= 0 {
            return result.unwrap_or(1.0);
        }
        base *= base;
    }
}

/// numpy's sign: 1, -1, 0 for zero, NaN for NaN.
#[inline]
fn numpy_sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else if x == 0.0 {
        0.0 // numpy's sign of -0.0 too
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::structure::OutputTerm;

    fn rows_of(d: &Data, s: &Structure, rows: &[i64], negate: bool) -> (Vec<f64>, Vec<bool>) {
        let p = s.n_params();
        let (mut out, mut ok) = (vec![0.0; rows.len() * p], vec![false; rows.len()]);
        regressor_rows(d, s, rows, negate, &mut out, p, &mut ok, true, &AtomicBool::new(false)).unwrap();
        (out, ok)
    }

    #[test]
    fn writes_lags_inputs_and_terms() {
        let y = [1.0, -2.0, 3.0, 0.5, f64::NAN, 2.0, 1.0];
        let u = [0.1, 1.0, 0.2, 2.0, 0.3, 3.0, 0.4, 4.0, 0.5, 5.0, 0.6, 6.0, 0.7, 7.0]; // two inputs
        let d = Data::new(&y, &u, 2, &[0]).unwrap();
        let terms = vec![
            OutputTerm { kind: OutputKind::Pow(3), multiplier: Some(1) },
            OutputTerm { kind: OutputKind::SignDiff, multiplier: None },
        ];
        let s = Structure::new(1, vec![2, 0], vec![1, 0], terms).unwrap();
        let (out, ok) = rows_of(&d, &s, &[3, 4, 5], true);
        // t = 3: -y2, u1(2), u1(1), y2^3 u2(2), sign(y2 - y1)
        assert_eq!(&out[..5], &[-3.0, 0.3, 0.2, 27.0 * 3.0, 1.0]);
        assert_eq!(ok, vec![true, true, false]);
        assert!(out[14].is_nan()); // sign of a difference with NaN is NaN, as numpy's
        let (plus, _) = rows_of(&d, &s, &[3], false);
        assert_eq!(plus[0], 3.0);
    }

    #[test]
    fn powers_are_those_of_squaring() {
        for x in [1.1_f64, -0.7, 3.3] {
            assert_eq!(integer_power(x, 1), x);
            assert_eq!(integer_power(x, 2), x * x);
            assert_eq!(integer_power(x, 3), x * (x * x));
            assert_eq!(integer_power(x, 5), x * ((x * x) * (x * x)));
        }
        assert_eq!(numpy_sign(-0.0).to_bits(), 0.0_f64.to_bits());
        assert!(numpy_sign(f64::NAN).is_nan());
    }

    #[test]
    fn refuses_rows_before_the_lag() {
        let y = [1.0; 5];
        let d = Data::new(&y, &y, 1, &[0]).unwrap();
        let s = Structure::new(2, vec![1], vec![1], vec![]).unwrap();
        let (mut out, mut ok) = (vec![0.0; 3], vec![false; 1]);
        let got = regressor_rows(&d, &s, &[1], true, &mut out, 3, &mut ok, false, &AtomicBool::new(false));
        assert!(matches!(got, Err(ArxError::InvalidStructure(_))));
    }
}
