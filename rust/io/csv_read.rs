//! Reading numeric columns of a CSV file with a header row: the `csv` crate splits records with
//! quoted fields, and everything else (the usual log has no quote) is split with `memchr`, to the
//! same records, in tasks of whole lines that run side by side and write straight into the final
//! columns. A cell that is a plain decimal number is parsed in the same pass; any other line (a
//! missing sample, spaces, a short record) goes through the general rules of one line, and the
//! cells through `fast-float2`, so that every number and every error is the same either way.
//!
//! The reader is strict where a silent guess would change the data: the text must be UTF-8 (a
//! byte order mark is skipped), hold no NUL byte, and every record must have as many fields as
//! the header. A wanted cell must be a number or a missing-sample marker (empty, `nan`, `na`,
//! `null` in any letter case, surrounded by spaces or not). Each error says where: the byte offset
//! and line of a bad byte, the line of a short or long record, the line and column of a bad cell.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::csv_plain::FastLine;

/// The UTF-8 byte order mark, skipped at the start of the file.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Records between two looks at the cancel flag.
const CANCEL_EVERY: usize = 1 << 14;

/// Bytes of text per parallel task (cut at the next line end): 20 tasks for a 10 MB log, so a
/// worker that the system deschedules leaves the rest to the others.
const TASK_BYTES: usize = 1 << 19;

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
/// `n_fields` fields separated by `delimiter`. With `wanted` empty it only checks the file. The
/// text is read in tasks of whole lines on the current rayon pool; the result does not depend on
/// the number of threads.
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
    read_in_tasks(bytes, delimiter, n_fields, wanted, cancel, TASK_BYTES)
}

/// [`read_columns`] in tasks of about `task_bytes`.
fn read_in_tasks(
    bytes: &[u8],
    delimiter: u8,
    n_fields: usize,
    wanted: &[usize],
    cancel: &AtomicBool,
    task_bytes: usize,
) -> Result<CsvColumns, CsvError> {
    let base = if bytes.starts_with(BOM) { BOM.len() } else { 0 };
    let text = &bytes[base..];
    check_text(text, base, task_bytes)?;
    let mut body = Body { text, delimiter, n_fields, wanted, cancel, task_bytes, header_seen: false };
    let mut columns: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::new()).collect();
    // Only the records from the first quote's line to the one holding the last quote need the csv
    // crate: before and after them the text splits as lines.
    let quotes = memchr::memchr(b'"', text).zip(memchr::memrchr(b'"', text));
    if let Some((first, last)) = quotes {
        let from = memchr::memrchr2(b'\n', b'\r', &text[..first]).map_or(0, |i| i + 1);
        body.read_lines(0, from, &mut columns)?;
        let resume = body.read_records(from, last, &mut columns)?;
        body.read_lines(resume, text.len(), &mut columns)?;
    } else {
        body.read_lines(0, text.len(), &mut columns)?;
    }
    Ok(CsvColumns { columns, quoted: quotes.is_some() })
}

/// The spans of `text[from..to]` cut into tasks of about `size` bytes, each after a line end
/// (never between the CR and LF of one).
fn task_spans(text: &[u8], from: usize, to: usize, size: usize) -> Vec<(usize, usize)> {
    let mut spans = Vec::with_capacity(1 + (to - from) / size);
    let mut a = from;
    while to - a > size {
        let Some(i) = memchr::memchr2(b'\n', b'\r', &text[a + size..to]) else { break };
        let end = a + size + i;
        let cut = end + 1 + usize::from(text[end] == b'\r' && text.get(end + 1) == Some(&b'\n'));
        if cut >= to {
            break;
        }
        spans.push((a, cut));
        a = cut;
    }
    spans.push((a, to));
    spans
}

/// The UTF-8 problem of `bytes` (whose first `base` bytes, a byte order mark, were cut off), or
/// else its first NUL byte, if any (a binary file is reported as not UTF-8 when it is not). The
/// tasks end after a line end, an ASCII byte, so each decodes as it would inside the whole text.
fn check_text(bytes: &[u8], base: usize, task_bytes: usize) -> Result<(), CsvError> {
    let look = |&(a, b): &(usize, usize)| {
        let bad = std::str::from_utf8(&bytes[a..b]).err().map(|e| (a + e.valid_up_to(), e.error_len()));
        (bad, memchr::memchr(0, &bytes[a..b]).map(|i| a + i))
    };
    let found: Vec<_> = task_spans(bytes, 0, bytes.len(), task_bytes).par_iter().map(look).collect();
    if let Some((at, len)) = found.iter().find_map(|f| f.0) {
        let reason = utf8_reason(&bytes[at..], len);
        return Err(CsvError::NotUtf8 { offset: base + at, line: line_of(bytes, at), reason });
    }
    match found.iter().find_map(|f| f.1) {
        Some(at) => Err(CsvError::Nul { offset: base + at, line: line_of(bytes, at) }),
        None => Ok(()),
    }
}

/// The text being read and what is asked of it.
struct Body<'a> {
    text: &'a [u8],
    delimiter: u8,
    n_fields: usize,
    wanted: &'a [usize],
    cancel: &'a AtomicBool,
    /// Bytes per parallel task ([`TASK_BYTES`]; a few in the tests, to cut small texts).
    task_bytes: usize,
    /// Whether the first record, the header (read by the caller), was passed.
    header_seen: bool,
}

impl Body<'_> {
    /// The records of `text[from..]` up to the first that starts after byte `last` (the last
    /// quote), split by the csv crate, each wanted cell pushed onto its column. Returns where
    /// the next record starts. The errors are [`read_columns`]'s.
    fn read_records(&mut self, from: usize, last: usize, columns: &mut [Vec<f64>]) -> Result<usize, CsvError> {
        let text = self.text;
        let mut reader = csv::ReaderBuilder::new()
            .delimiter(self.delimiter)
            .has_headers(false)
            .flexible(true)
            .from_reader(&text[from..]);
        let mut record = csv::ByteRecord::new();
        let mut count = 0usize;
        loop {
            let start = from + reader.position().byte() as usize;
            if start > last {
                return Ok(start);
            }
            match reader.read_byte_record(&mut record) {
                Ok(true) => {}
                Ok(false) => return Ok(text.len()),
                Err(e) => return Err(CsvError::Malformed { line: line_of(text, start), what: e.to_string() }),
            }
            count += 1;
            if count.is_multiple_of(CANCEL_EVERY) && self.cancel.load(Ordering::Relaxed) {
                return Err(CsvError::Interrupted);
            }
            if !self.header_seen {
                self.header_seen = true; // the header, read by the caller
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
            if record.len() != self.n_fields {
                return Err(CsvError::FieldCount { line: at(), got: record.len(), expected: self.n_fields });
            }
            for (column, &j) in columns.iter_mut().zip(self.wanted) {
                match parse_cell(&record[j]) {
                    Some(v) => column.push(v),
                    None => {
                        let cell = String::from_utf8_lossy(record[j].trim_ascii()).into_owned();
                        return Err(CsvError::NotANumber { line: at(), column: j, cell });
                    }
                }
            }
        }
    }

    /// The records of `text[from..to]`, which holds no quote, as the csv crate splits them: lines
    /// end at LF, CRLF or a lone CR, empty lines are skipped, the first record is the header;
    /// fields are the spans between delimiters. `from` and `to` are line starts (or the end).
    /// The lines are read in tasks side by side, each writing its rows into its own part of the
    /// columns (as long as its count of line ends), then the parts are closed up. The errors are
    /// [`read_columns`]'s: the first task's with one.
    fn read_lines(&mut self, mut from: usize, to: usize, columns: &mut [Vec<f64>]) -> Result<(), CsvError> {
        while !self.header_seen && from < to {
            let (start, end, next) = line_at(self.text, from, to);
            self.header_seen = end > start;
            from = next;
        }
        if from >= to {
            return Ok(());
        }
        let spans = task_spans(self.text, from, to, self.task_bytes);
        let bounds: Vec<usize> = spans.par_iter().map(|&(a, b)| records_bound(&self.text[a..b])).collect();
        let base = columns.first().map_or(0, Vec::len);
        for column in columns.iter_mut() {
            column.resize(base + bounds.iter().sum::<usize>(), 0.0);
        }
        let mut parts: Vec<Vec<&mut [f64]>> = spans.iter().map(|_| Vec::with_capacity(columns.len())).collect();
        for column in columns.iter_mut() {
            let mut rest = &mut column[base..];
            for (part, &bound) in parts.iter_mut().zip(&bounds) {
                let (head, tail) = rest.split_at_mut(bound);
                part.push(head);
                rest = tail;
            }
        }
        let this = &*self;
        let rows: Vec<Result<usize, CsvError>> =
            spans.par_iter().zip(parts.par_iter_mut()).map(|(&(a, b), part)| this.read_task(a, b, part)).collect();
        drop(parts);
        let rows = rows.into_iter().collect::<Result<Vec<usize>, CsvError>>()?;
        let (mut at, mut src) = (base, base);
        for (&n, &bound) in rows.iter().zip(&bounds) {
            if src != at {
                columns.iter_mut().for_each(|c| c.copy_within(src..src + n, at));
            }
            (at, src) = (at + n, src + bound);
        }
        columns.iter_mut().for_each(|c| c.truncate(at));
        Ok(())
    }

    /// The records of the lines of `text[a..b]` into rows 0, 1, ... of `out` (one slice per wanted
    /// column); returns the number of rows.
    fn read_task(&self, a: usize, b: usize, out: &mut [&mut [f64]]) -> Result<usize, CsvError> {
        let fast = FastLine::new(self.n_fields, self.wanted, self.delimiter);
        let mut fields: Vec<(usize, usize)> = Vec::with_capacity(self.n_fields + 1);
        let (mut pos, mut count, mut row) = (a, 0usize, 0usize);
        while pos < b {
            let (start, end, next) = line_at(self.text, pos, b);
            pos = next;
            if start == end {
                continue; // the csv crate skips empty lines
            }
            count += 1;
            if count.is_multiple_of(CANCEL_EVERY) && self.cancel.load(Ordering::Relaxed) {
                return Err(CsvError::Interrupted);
            }
            let line = &self.text[start..end];
            if fast.as_ref().is_some_and(|f| f.read(line, out, row))
                || self.read_line(start, line, &mut fields, out, row)?
            {
                row += 1;
            }
        }
        Ok(row)
    }

    /// One line by the general rules into row `row` of `out`: whether it is a record (a line of
    /// spaces is not).
    fn read_line(
        &self,
        start: usize,
        line: &[u8],
        fields: &mut Vec<(usize, usize)>,
        out: &mut [&mut [f64]],
        row: usize,
    ) -> Result<bool, CsvError> {
        fields.clear();
        let mut from = 0;
        for at in memchr::memchr_iter(self.delimiter, line) {
            fields.push((from, at));
            from = at + 1;
        }
        fields.push((from, line.len()));
        if fields.len() == 1 && line.trim_ascii().is_empty() {
            return Ok(false); // a line of spaces
        }
        if fields.len() != self.n_fields {
            return Err(CsvError::FieldCount {
                line: line_of(self.text, start),
                got: fields.len(),
                expected: self.n_fields,
            });
        }
        for (column, &j) in out.iter_mut().zip(self.wanted) {
            let cell = &line[fields[j].0..fields[j].1];
            match parse_cell(cell) {
                Some(v) => column[row] = v,
                None => {
                    let cell = String::from_utf8_lossy(cell.trim_ascii()).into_owned();
                    return Err(CsvError::NotANumber { line: line_of(self.text, start), column: j, cell });
                }
            }
        }
        Ok(true)
    }
}

/// The line starting at `pos` (before `to`): its start, its end (before the line end) and where
/// the next one starts.
#[inline]
fn line_at(text: &[u8], pos: usize, to: usize) -> (usize, usize, usize) {
    match memchr::memchr2(b'\n', b'\r', &text[pos..to]) {
        Some(i) => {
            let end = pos + i;
            (pos, end, end + 1 + usize::from(text[end] == b'\r' && text.get(end + 1) == Some(&b'\n')))
        }
        None => (pos, to, to),
    }
}

/// At least the number of records in `span` (which ends after a line end or at the text's end):
/// its line ends, plus one for a last line without one.
fn records_bound(span: &[u8]) -> usize {
    let lf = memchr_count(b'\n', span);
    let lone_cr = if memchr::memchr(b'\r', span).is_some() {
        memchr::memchr_iter(b'\r', span).filter(|&i| span.get(i + 1) != Some(&b'\n')).count()
    } else {
        0
    };
    lf + lone_cr + usize::from(span.last().is_some_and(|&b| b != b'\n' && b != b'\r'))
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

    /// The csv crate alone over the whole text: what every reading must give.
    fn by_csv_crate(text: &[u8], n: usize, wanted: &[usize]) -> Result<Vec<Vec<f64>>, CsvError> {
        let never = AtomicBool::new(false);
        check_text(text, 0, TASK_BYTES)?;
        let mut body =
            Body { text, delimiter: b',', n_fields: n, wanted, cancel: &never, task_bytes: 1, header_seen: false };
        let mut columns: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::new()).collect();
        body.read_records(0, text.len(), &mut columns)?;
        Ok(columns)
    }

    fn bits(r: &Result<Vec<Vec<f64>>, CsvError>) -> Result<Vec<Vec<u64>>, CsvError> {
        r.clone().map(|c| c.iter().map(|c| c.iter().map(|v| v.to_bits()).collect()).collect())
    }

    /// Every reading of `text` (tasks of 1 to 64 bytes and the default; columns none, one, two)
    /// gives the csv crate's records, numbers (to the bit) and first error.
    fn assert_as_csv_crate(text: &str) {
        let n = text.trim_start().split(['\r', '\n']).next().unwrap().split(',').count();
        let never = AtomicBool::new(false);
        for wanted in [&[][..], &[0], &[1, 0], &[0, 0]] {
            let wanted: Vec<usize> = wanted.iter().copied().filter(|&j| j < n).collect();
            let expected = by_csv_crate(text.as_bytes(), n, &wanted);
            for task_bytes in [1, 2, 3, 7, 64, TASK_BYTES] {
                let got = read_in_tasks(text.as_bytes(), b',', n, &wanted, &never, task_bytes).map(|t| t.columns);
                assert_eq!(bits(&got), bits(&expected), "{text:?} {wanted:?} {task_bytes}");
            }
        }
    }

    #[test]
    fn every_reading_gives_the_records_and_errors_of_the_csv_crate() {
        let texts = [
            "t,y\n0,1\n\n1,2\r\n\r\n2,3\r3, 4 \n   \n4,nan\n",
            "t,y\r\n0,1\r\n1,\r\n",
            "t,y\n0,1\n1,2,3\n",
            "t,y\n0,1\n\n\r\n1\n",
            "t,y\r\r0,1\r1,x\r",
            "t\n1\n  \n2\n",
            "t,y\n,\n1,2",
            "\n\nt,y\n1,2\n",
            "t,y\n0,1\n\"1\",2\r\n2,3\n\n3,4\r\n4,5",
            "\"t\",y\n1,2\n3,4\n",
            "t,y\n1,2\n3,\"4\n5\"\n6,7\n",
            "t,y\n1,2\n3,\"4\"\n6,x\n",
            "t,y\n1,2,3\n\"3\",4\n",
            "t,y\n1,2\r\"3\",\"4\"\r\r5,6\r",
            "t\n\n1\n\"2\"\n  \n3",
        ];
        for text in texts {
            assert_as_csv_crate(text);
        }
    }

    #[test]
    fn cells_of_every_kind_read_as_the_csv_crate_reads_them() {
        let cells = [
            "-1.5e-3",
            "+2",
            "1.",
            ".5",
            "1e400",
            "0.1",
            "123456789012345678901",
            "-0",
            " 1",
            "1 ",
            "nan",
            "",
            "1e",
            "e5",
            ".",
            "-",
            "0x10",
            "4.2E+01",
            "9007199254740993",
            "1e22",
            "1e23",
            "3e-22",
            "3e-23",
            "0.000001",
            "inf",
            "-.5e1",
            "1e-0000000000000000000005",
            "2.5e99999999999999999999",
        ];
        let mut seed = 11u64;
        for _ in 0..300 {
            let mut text = String::from("t,y,z\n");
            for _ in 0..(seed % 5) {
                let mut pick = || {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    cells[(seed >> 33) as usize % cells.len()]
                };
                let (a, b, c) = (pick(), pick(), pick());
                let eol = ["\n", "\r\n", "\r"][(seed >> 40) as usize % 3];
                text.push_str(&format!("{a},{b},{c}{eol}"));
            }
            assert_as_csv_crate(&text);
        }
    }

    #[test]
    fn log_numbers_read_exactly_as_rust_parses_them() {
        let mut seed = 5u64;
        let mut text = String::from("a,b,c\n");
        let mut expected = Vec::new();
        for i in 0..20_000 {
            let x = lcg_normal(&mut seed) * 10f64.powi((i % 13) - 6);
            let cells = [format!("{x:.9}"), format!("{:.8e}", x), format!("{}", x as f32)];
            expected.push(cells.clone().map(|c| c.parse::<f64>().unwrap()));
            text.push_str(&cells.join(","));
            text.push('\n');
        }
        let got = read(&text, &[0, 1, 2]).unwrap();
        for (k, column) in got.columns.iter().enumerate() {
            for (v, e) in column.iter().zip(&expected) {
                assert_eq!(v.to_bits(), e[k].to_bits(), "{v} {}", e[k]);
            }
        }
    }

    /// A roughly normal pseudo-random number (sum of four uniforms).
    fn lcg_normal(seed: &mut u64) -> f64 {
        (0..4)
            .map(|_| {
                *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .sum()
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
