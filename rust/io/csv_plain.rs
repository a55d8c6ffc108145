//! The one-pass reading of the usual line of a CSV log: fields as many as the header's, the
//! wanted cells plain decimal numbers. Anything else is left to the general rules of
//! [`csv_read`](super::csv_read), which give every number and error; this pass gives the same
//! numbers, to the bit, or declines the line.

use super::csv_read::parse_cell;

/// A column no cell of which is wanted.
const SKIP: usize = usize::MAX;

/// Exact powers of ten: a number of at most 2⁵³ times or over one of them is rounded once, the
/// correctly rounded value (Clinger 1990), the same that `fast-float2` gives.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// The one-pass reading of a line whose fields are as the header's and whose wanted cells are
/// plain decimal numbers (`-1.25`, `3e-5`), the usual line of a log.
pub(crate) struct FastLine {
    /// For each field, the wanted column it goes to, or [`SKIP`].
    slots: Vec<usize>,
    delimiter: u8,
}

impl FastLine {
    /// `None` where the one-pass reading does not apply: a column wanted twice, or a delimiter
    /// that can be part of a number.
    pub(crate) fn new(n_fields: usize, wanted: &[usize], delimiter: u8) -> Option<Self> {
        if b"0123456789+-.eE".contains(&delimiter) {
            return None;
        }
        let mut slots = vec![SKIP; n_fields];
        for (k, &j) in wanted.iter().enumerate() {
            if slots[j] != SKIP {
                return None;
            }
            slots[j] = k;
        }
        Some(FastLine { slots, delimiter })
    }

    /// Reads `line` into row `row` of `out` and says true, or says false (some values may be
    /// written) where the general rules must decide.
    #[inline]
    pub(crate) fn read(&self, line: &[u8], out: &mut [&mut [f64]], row: usize) -> bool {
        let n = self.slots.len();
        let mut pos = 0;
        for (j, &slot) in self.slots.iter().enumerate() {
            let last = j + 1 == n;
            let end = if slot != SKIP {
                let Some((end, value)) = plain_number(line, pos) else { return false };
                let Some(v) = value.or_else(|| parse_cell(&line[pos..end])) else { return false };
                out[slot][row] = v;
                end
            } else if last {
                if memchr::memchr(self.delimiter, &line[pos..]).is_some() {
                    return false;
                }
                line.len()
            } else {
                match memchr::memchr(self.delimiter, &line[pos..]) {
                    Some(i) => pos + i,
                    None => return false,
                }
            };
            let closed = if last { end == line.len() } else { line.get(end) == Some(&self.delimiter) };
            if !closed {
                return false;
            }
            pos = end + 1;
        }
        // A lone unwanted field of spaces is a blank line, not a record.
        !(n == 1 && self.slots[0] == SKIP && line.trim_ascii().is_empty())
    }
}

/// The plain decimal number at `line[pos..]` (`[+-]digits[.digits][(e|E)[+-]digits]`, a digit
/// before or after the point): where it ends and, when exact in one rounding (at most 2⁵³ times or
/// over 10^22 at most), its value; `None` when no number starts there.
#[inline]
fn plain_number(line: &[u8], pos: usize) -> Option<(usize, Option<f64>)> {
    let digit = |i: usize| line.get(i).map(|&c| c.wrapping_sub(b'0')).filter(|&d| d < 10);
    let mut i = pos;
    let negative = line.get(i) == Some(&b'-');
    i += usize::from(matches!(line.get(i), Some(b'-' | b'+')));
    let (mut mantissa, mut digits) = (0u64, 0usize);
    let int_start = i;
    while let Some(d) = digit(i) {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
        i += 1;
    }
    digits += i - int_start;
    let mut after_point = 0;
    if line.get(i) == Some(&b'.') {
        i += 1;
        let frac_start = i;
        while let Some(d) = digit(i) {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
            i += 1;
        }
        after_point = i - frac_start;
        digits += after_point;
    }
    if digits == 0 {
        return None;
    }
    let mut exponent = 0i64;
    if matches!(line.get(i), Some(b'e' | b'E')) {
        let mut j = i + 1;
        let negative_exponent = line.get(j) == Some(&b'-');
        j += usize::from(matches!(line.get(j), Some(b'-' | b'+')));
        let exp_start = j;
        while let Some(d) = digit(j) {
            exponent = (exponent * 10 + i64::from(d)).min(1 << 20);
            j += 1;
        }
        if j == exp_start {
            return None;
        }
        exponent = if negative_exponent { -exponent } else { exponent };
        i = j;
    }
    // At most 19 digits cannot wrap a u64; the value is exact below 2^53.
    let power = exponent - after_point as i64;
    if digits > 19 || mantissa > 1 << 53 || !(-22..=22).contains(&power) {
        return Some((i, None));
    }
    let m = mantissa as f64;
    let v = if power >= 0 { m * POW10[power as usize] } else { m / POW10[(-power) as usize] };
    Some((i, Some(if negative { -v } else { v })))
}
