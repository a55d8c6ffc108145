//! Reading numeric columns of a CSV file with a header row: the `csv` crate splits records (quoted
//! fields, CR / LF / CRLF line endings, blank lines), `fast-float2` parses the cells. A file without
//! a quote, the usual log, is split with `memchr` instead, to the same records (three times faster).
//!
//! The reader is strict where a silent guess would change the data: the text must be UTF-8 (a
//! byte order mark is skipped), hold no NUL byte, and every record must have as many fields as
//! the header. A wanted cell must be a number or a missing-sample marker (empty, `nan`, `na`,
//! `null` in any letter case, surrounded by spaces or not). Each error says where: the byte offset
//! and line of a bad byte, the line of a short or long record, the line and column of a bad cell.

use std::sync::atomic::{AtomicBool, Ordering};

/// The UTF-8 byte order mark, skipped at the start of the file.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Records between two looks at the cancel flag.
const CANCEL_EVERY: usize = 1 << 14;

/// What is wrong with a CSV file, and where. Lines count from 1 (the header) and end at LF, CRLF
/// or a lone CR; byte offsets count from the start of the file (a byte order mark included).
#[derive(Debug, Clone, PartialEq)]
pub enum CsvError {
    /// The bytes at `offset` are not UTF-8; `reason` in the words of Python's codec.
    NotUtf8 { offset: usize, line: usize, reason: &'static str },
    /// A NUL byte at `offset`: a binary file.
    Nul { offset: usize, line: usize },
    /// The record starting on `line` has `got` fields, not the header's `expected`.
    FieldCount { line: usize, got: usize, expected: usize },
    /// The cell of column `column` (0-based) of the record starting on `line` is not a number.
    NotANumber { line: usize, column: usize, cell: String },
    /// The csv reader failed (cannot happen on a byte slice; kept so that no error is lost).
    Malformed { line: usize, what: String },
    /// The caller asked the read to stop (Ctrl-C).
    Interrupted,
}

/// What a successful read gives.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvColumns {
    /// One vector per wanted column, in the order asked for.
    pub columns: Vec<Vec<f64>>,
    /// Whether any field below the header was quoted.
    pub quoted: bool,
}

/// The line (from 1) of byte `offset` of `bytes`: line ends are LF, CRLF and a lone CR.
pub fn line_of(bytes: &[u8], offset: usize) -> usize {
    let head = &bytes[..offset.min(bytes.len())];
    let lf = memchr_count(b'\n', head);
    let lone_cr = head.windows(2).filter(|w| w[0] == b'\r' && w[1] != b'\n').count()
        + usize::from(head.last() == Some(&b'\r') && bytes.get(head.len()) != Some(&b'\n'));
    1 + lf + lone_cr
}

fn memchr_count(needle: u8, hay: &[u8]) -> usize {
    memchr::memchr_iter(needle, hay).count()
}

/// Python's reason for the UTF-8 error that starts at `bytes[0]` (`None` when the text ends in
/// the middle of a character).
fn utf8_reason(bytes: &[u8], error_len: Option<usize>) -> &'static str {
    match (error_len, bytes.first()) {
        (None, _) => "unexpected end of data",
        (Some(_), Some(&b)) if (0x80..0xC2).contains(&b) || b >= 0xF5 => "invalid start byte",
        _ => "invalid continuation byte",
    }
}

/// The UTF-8 problem of `bytes` (whose first `base` bytes, a byte order mark, were cut off), or
/// else its first NUL byte, if any (a binary file is reported as not UTF-8 when it is not).
fn check_text(bytes: &[u8], base: usize) -> Result<(), CsvError> {
    if let Err(e) = std::str::from_utf8(bytes) {
        let at = e.valid_up_to();
        let reason = utf8_reason(&bytes[at..], e.error_len());
        return Err(CsvError::NotUtf8 { offset: base + at, line: line_of(bytes, at), reason });
    }
    match memchr::memchr(0, bytes) {
        Some(at) => Err(CsvError::Nul { offset: base + at, line: line_of(bytes, at) }),
        None => Ok(()),
    }
}

/// Whether a trimmed cell marks a missing sample: empty, `nan`, `na` or `null`, any letter case.
fn is_missing(cell: &[u8]) -> bool {
    cell.is_empty()
        || cell.eq_ignore_ascii_case(b"nan")
        || cell.eq_ignore_ascii_case(b"na")
        || cell.eq_ignore_ascii_case(b"null")
}

/// The number in a cell (spaces around it allowed), NaN for a missing-sample marker, `None` when
/// it is neither.
#[inline]
pub fn parse_cell(cell: &[u8]) -> Option<f64> {
    if let Ok(v) = fast_float2::parse::<f64, _>(cell) {
        return Some(v);
    }
    let cell = cell.trim_ascii();
    if is_missing(cell) {
        return Some(f64::NAN);
    }
    fast_float2::parse::<f64, _>(cell)
        .ok()
        .or_else(|| std::str::from_utf8(cell).ok().and_then(|s| s.parse::<f64>().ok()))
}

/// Reads the columns `wanted` (0-based positions) of CSV text `bytes` with a header row of
/// `n_fields` fields separated by `delimiter`. With `wanted` empty it only checks the file.
///
/// # Errors
/// The first problem met, in file order (see [`CsvError`]); `Interrupted` once `cancel` is set.
pub fn read_columns(
    bytes: &[u8],
    delimiter: u8,
    n_fields: usize,
    wanted: &[usize],
    cancel: &AtomicBool,
) -> Result<CsvColumns, CsvError> {
    let base = if bytes.starts_with(BOM) { BOM.len() } else { 0 };
    let text = &bytes[base..];
    check_text(text, base)?;
    let quoted = memchr::memchr(b'"', text).is_some();
    let rows_guess = 1 + memchr_count(b'\n', text).max(memchr_count(b'\r', text));
    let mut columns: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::with_capacity(rows_guess)).collect();
    if quoted {
        read_records(text, delimiter, n_fields, wanted, cancel, &mut columns)?;
    } else {
        read_unquoted(text, delimiter, n_fields, wanted, cancel, &mut columns)?;
    }
    Ok(CsvColumns { columns, quoted })
}

/// The records of `text` split by the csv crate (quoted fields); each wanted cell parsed into its
/// column. The errors are [`read_columns`]'s.
fn read_records(
    text: &[u8],
    delimiter: u8,
    n_fields: usize,
    wanted: &[usize],
    cancel: &AtomicBool,
    columns: &mut [Vec<f64>],
) -> Result<(), CsvError> {
    let mut reader = csv::ReaderBuilder::new().delimiter(delimiter).has_headers(false).flexible(true).from_reader(text);
    let mut record = csv::ByteRecord::new();
    let mut first = true;
    let mut count = 0usize;
    loop {
        let start = reader.position().byte() as usize;
        match reader.read_byte_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(CsvError::Malformed { line: line_of(text, start), what: e.to_string() }),
        }
        count += 1;
        if count.is_multiple_of(CANCEL_EVERY) && cancel.load(Ordering::Relaxed) {
            return Err(CsvError::Interrupted);
        }
        if first {
            first = false; // the header, read by the caller
            continue;
        }
        if record.len() == 1 && record[0].trim_ascii().is_empty() {
            continue; // a blank line (or one of spaces)
        }
        // The record starts after the line ends (and blank lines) the reader passed over first.
        let at = || {
            let skipped = text[start.min(text.len())..].iter().take_while(|&&b| b == b'\r' || b == b'\n').count();
            line_of(text, start + skipped)
        };
        if record.len() != n_fields {
            return Err(CsvError::FieldCount { line: at(), got: record.len(), expected: n_fields });
        }
        for (column, &j) in columns.iter_mut().zip(wanted) {
            match parse_cell(&record[j]) {
                Some(v) => column.push(v),
                None => {
                    let cell = String::from_utf8_lossy(record[j].trim_ascii()).into_owned();
                    return Err(CsvError::NotANumber { line: at(), column: j, cell });
                }
            }
        }
    }
    Ok(())
}

/// The records of `text` without a quote, as the csv crate splits them: lines end at LF, CRLF or a
/// lone CR, empty lines are skipped, the first record is the header; fields are the spans between
/// delimiters. Each wanted cell is parsed into its column; the errors are [`read_columns`]'s.
fn read_unquoted(
    text: &[u8],
    delimiter: u8,
    n_fields: usize,
    wanted: &[usize],
    cancel: &AtomicBool,
    columns: &mut [Vec<f64>],
) -> Result<(), CsvError> {
    let mut fields: Vec<(usize, usize)> = Vec::with_capacity(n_fields + 1);
    let (mut pos, mut count) = (0usize, 0usize);
    while pos < text.len() {
        let start = pos;
        let end = memchr::memchr2(b'\n', b'\r', &text[pos..]).map_or(text.len(), |i| pos + i);
        pos = end + 1 + usize::from(text.get(end) == Some(&b'\r') && text.get(end + 1) == Some(&b'\n'));
        let line = &text[start..end];
        if line.is_empty() {
            continue; // the csv crate skips empty lines
        }
        count += 1;
        if count.is_multiple_of(CANCEL_EVERY) && cancel.load(Ordering::Relaxed) {
            return Err(CsvError::Interrupted);
        }
        if count == 1 {
            continue; // the header, read by the caller
        }
        fields.clear();
        let mut from = 0;
        for at in memchr::memchr_iter(delimiter, line) {
            fields.push((from, at));
            from = at + 1;
        }
        fields.push((from, line.len()));
        if fields.len() == 1 && line.trim_ascii().is_empty() {
            continue; // a line of spaces
        }
        if fields.len() != n_fields {
            return Err(CsvError::FieldCount { line: line_of(text, start), got: fields.len(), expected: n_fields });
        }
        for (column, &j) in columns.iter_mut().zip(wanted) {
            let cell = &line[fields[j].0..fields[j].1];
            match parse_cell(cell) {
                Some(v) => column.push(v),
                None => {
                    let cell = String::from_utf8_lossy(cell.trim_ascii()).into_owned();
                    return Err(CsvError::NotANumber { line: line_of(text, start), column: j, cell });
                }
            }
        }
    }
    Ok(())
}

/// [`read_columns`] of the file at `path`.
///
/// # Errors
/// `Err(Ok(message))` when the file cannot be read; `Err(Err(e))` for a problem in its content.
pub fn read_file(
    path: &std::path::Path,
    delimiter: u8,
    n_fields: usize,
    wanted: &[usize],
    cancel: &AtomicBool,
) -> Result<CsvColumns, Result<String, CsvError>> {
    let bytes = std::fs::read(path).map_err(|e| Ok(e.to_string()))?;
    read_columns(&bytes, delimiter, n_fields, wanted, cancel).map_err(Err)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str, wanted: &[usize]) -> Result<CsvColumns, CsvError> {
        let n = text.split(['\r', '\n']).next().unwrap().split(',').count();
        read_columns(text.as_bytes(), b',', n, wanted, &AtomicBool::new(false))
    }

    #[test]
    fn line_endings_quotes_and_markers() {
        for eol in ["\n", "\r\n", "\r"] {
            let text = ["t,y", "0, 1.5", "1,NaN", "", "2,\"-3e-3\"", "3, null ", "4,"].join(eol);
            let got = read(&text, &[1, 0]).unwrap();
            assert_eq!(got.columns[1], vec![0.0, 1.0, 2.0, 3.0, 4.0]);
            let y = &got.columns[0];
            assert_eq!((y[0], y[2]), (1.5, -3e-3));
            assert!(y[1].is_nan() && y[3].is_nan() && y[4].is_nan());
            assert!(got.quoted);
        }
    }

    #[test]
    fn every_cell_exactly_as_rust_parses_it() {
        let mut seed = 3u64;
        let mut values = Vec::new();
        let mut text = String::from("a,b\n");
        for _ in 0..2000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let v = f64::from_bits(seed >> 2) * if seed & 1 == 1 { -1.0 } else { 1.0 };
            let v = if v.is_finite() { v } else { 1.0 };
            values.push(v);
            text.push_str(&format!("{v:e},{v}\n"));
        }
        let got = read(&text, &[0, 1]).unwrap();
        assert_eq!(got.columns[0], values);
        assert_eq!(got.columns[1], values);
    }

    #[test]
    fn errors_say_where() {
        assert_eq!(read("y,u\n1,2\r\n\n3\n", &[0]), Err(CsvError::FieldCount { line: 4, got: 1, expected: 2 }));
        assert_eq!(
            read("y,u\r1,2\r3,x\r", &[0, 1]),
            Err(CsvError::NotANumber { line: 3, column: 1, cell: "x".into() })
        );
        assert_eq!(read("y,u\n1,2\n3\0,4\n", &[]), Err(CsvError::Nul { offset: 9, line: 3 }));
        let latin1 = b"y,u\n1,2\n3,caf\xe9\n";
        let err = read_columns(latin1, b',', 2, &[], &AtomicBool::new(false));
        assert_eq!(err, Err(CsvError::NotUtf8 { offset: 13, line: 3, reason: "invalid continuation byte" }));
        let bom_then_bad = b"\xEF\xBB\xBFy\n\xff\n";
        let err = read_columns(bom_then_bad, b',', 1, &[], &AtomicBool::new(false));
        assert_eq!(err, Err(CsvError::NotUtf8 { offset: 5, line: 2, reason: "invalid start byte" }));
    }

    #[test]
    fn both_splitters_give_the_same_records_and_errors() {
        let texts = [
            "t,y\n0,1\n\n1,2\r\n\r\n2,3\r3, 4 \n   \n4,nan\n",
            "t,y\r\n0,1\r\n1,\r\n",
            "t,y\n0,1\n1,2,3\n",
            "t,y\n0,1\n\n\r\n1\n",
            "t,y\r\r0,1\r1,x\r",
            "t\n1\n  \n2\n",
            "t,y\n,\n1,2",
            "\n\nt,y\n1,2\n",
        ];
        for text in texts {
            let n = text.trim_start().split(['\r', '\n']).next().unwrap().split(',').count();
            let never = AtomicBool::new(false);
            for wanted in [&[][..], &[0], &[1, 0]] {
                let wanted: Vec<usize> = wanted.iter().copied().filter(|&j| j < n).collect();
                let wanted = &wanted[..];
                let mut fast: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::new()).collect();
                let mut slow = fast.clone();
                let a = read_unquoted(text.as_bytes(), b',', n, wanted, &never, &mut fast);
                let b = read_records(text.as_bytes(), b',', n, wanted, &never, &mut slow);
                assert_eq!(a, b, "{text:?}");
                let same = |x: &Vec<Vec<f64>>, y: &Vec<Vec<f64>>| format!("{x:?}") == format!("{y:?}");
                assert!(same(&fast, &slow), "{text:?}: {fast:?} != {slow:?}");
            }
        }
    }

    #[test]
    fn a_set_cancel_flag_stops_the_read() {
        let text = "y\n".to_string() + &"1\n".repeat(3 * CANCEL_EVERY);
        let cancel = AtomicBool::new(true);
        assert_eq!(read_columns(text.as_bytes(), b',', 1, &[0], &cancel), Err(CsvError::Interrupted));
    }

    #[test]
    fn line_of_counts_every_kind_of_line_end() {
        let text = b"a\nb\r\nc\rd";
        assert_eq!([0, 2, 5, 7].map(|o| line_of(text, o)), [1, 2, 3, 4]);
    }
}
