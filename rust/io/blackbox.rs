//! Betaflight and INAV blackbox logs (`.bbl`, `.bfl`, `.txt`) on the `blackbox-log` crate.
//!
//! A file holds one or more logs (one per arming), each a text header (`H name:value` lines)
//! then binary frames. [`read`] decodes the main frames of one log into columns, in the units of
//! the firmware: gyro in deg/s (the raw value times the header's `gyro_scale`, 1 deg/s for
//! Betaflight), battery voltage in V (the firmware logs 0.01 V), current in A (0.01 A),
//! acceleration in g (`acc_1G`); every other field as the firmware logged it (setpoints in deg/s,
//! PID terms, motor outputs in the range of the header's `motorOutput`).

use std::fmt;

use blackbox_log::frame::{Frame, FrameDef, MainUnit};
use blackbox_log::{Event, ParserEvent};

use super::without_panic;

/// The first line of every log in a blackbox file.
const MARKER: &[u8] = b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n";

/// The text of the end-of-log event the firmware writes when it stops logging.
const END_OF_LOG: &[u8] = b"End of log";

/// What can make a blackbox file unreadable.
#[derive(Debug, Clone, PartialEq)]
pub enum BlackboxError {
    /// The file holds no log start marker: not a blackbox log.
    NotBlackbox,
    /// Log `log` (1-based) was asked for but the file holds `n_logs`.
    NoSuchLog { log: usize, n_logs: usize },
    /// The header of log `log` cannot be used (unsupported firmware, missing field definitions).
    Header { log: usize, reason: String },
    /// A field that the main frames do not hold.
    UnknownField { field: String, available: Vec<String> },
    /// Log `log` holds no readable main frame.
    NoFrames { log: usize },
    /// The parser stopped on data it could not handle.
    Corrupt { log: usize, reason: String },
}

impl fmt::Display for BlackboxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BlackboxError::NotBlackbox => {
                write!(f, "is not a Betaflight/INAV blackbox log (no line 'H Product:Blackbox flight data recorder')")
            }
            BlackboxError::NoSuchLog { log, n_logs } => {
                write!(f, "holds {n_logs} log(s) (one per arming); there is no log {log} (log counts from 1)")
            }
            BlackboxError::Header { log, reason } => write!(f, "log {log}: its header cannot be read ({reason})"),
            BlackboxError::UnknownField { field, available } => {
                write!(
                    f,
                    "has no field '{field}' in its main frames; they hold {}",
                    super::dataflash::quoted(available)
                )
            }
            BlackboxError::NoFrames { log } => write!(f, "log {log} holds no readable frame"),
            BlackboxError::Corrupt { log, reason } => write!(f, "log {log} is corrupt ({reason})"),
        }
    }
}

impl std::error::Error for BlackboxError {}

/// The main frames of one log as columns.
#[derive(Debug, Clone, PartialEq)]
pub struct BlackboxLog {
    /// How many logs the file holds.
    pub n_logs: usize,
    /// The text header of the log, `(name, value)` in file order.
    pub headers: Vec<(String, String)>,
    /// Every field of the main frames (`loopIteration` first), as the firmware names them.
    pub fields: Vec<String>,
    /// Time of each frame in microseconds since power-on.
    pub time_us: Vec<f64>,
    /// `loopIteration` of each frame. The decoder does not count the loop iterations between two
    /// logged P frames, so this is not a frame counter: count lost frames from [`Self::time_us`].
    pub iteration: Vec<f64>,
    /// The wanted fields, one column each, in the order asked.
    pub columns: Vec<Vec<f64>>,
    /// Unit of each wanted field (`""` when the firmware gives none).
    pub units: Vec<&'static str>,
    /// Whether the log ends with the firmware's end-of-log event (false: cut short).
    pub complete: bool,
}

/// The `H name:value` lines of a log's text header, in file order.
pub type TextHeader = Vec<(String, String)>;

/// The header of one log: how many logs the file holds, its text header and its main-frame fields.
#[derive(Debug, Clone, PartialEq)]
pub struct LogHeader {
    pub n_logs: usize,
    pub headers: TextHeader,
    pub fields: Vec<String>,
}

/// Byte offsets of the logs in `data`.
fn log_starts(data: &[u8]) -> Vec<usize> {
    let mut starts = Vec::new();
    let mut i = 0;
    while i + MARKER.len() <= data.len() {
        match data[i..].windows(MARKER.len()).position(|w| w == MARKER) {
            Some(k) => {
                starts.push(i + k);
                i += k + MARKER.len();
            }
            None => break,
        }
    }
    starts
}

/// The `H name:value` lines at the start of a log.
fn text_headers(log: &[u8]) -> TextHeader {
    let mut out = Vec::new();
    for line in log.split(|&b| b == b'\n') {
        let Some(rest) = line.strip_prefix(b"H ") else { break };
        let text = String::from_utf8_lossy(rest);
        if let Some((name, value)) = text.split_once(':') {
            out.push((name.to_string(), value.trim_end_matches('\r').to_string()));
        }
    }
    out
}

/// The header's `gyro_scale` in deg/s per unit (a float written as hex bits, or a number).
fn gyro_scale(headers: &[(String, String)]) -> f64 {
    headers
        .iter()
        .find(|(n, _)| n == "gyro_scale" || n == "gyro.scale")
        .and_then(|(_, v)| match v.strip_prefix("0x") {
            Some(hex) => u32::from_str_radix(hex, 16).ok().map(|b| f64::from(f32::from_bits(b))),
            None => v.parse::<f64>().ok(),
        })
        .unwrap_or(1.0)
}

fn header_number(headers: &[(String, String)], name: &str) -> Option<f64> {
    headers.iter().find(|(n, _)| n == name).and_then(|(_, v)| v.parse().ok())
}

/// How a raw field value becomes a number in the firmware's units.
#[derive(Debug, Clone, Copy)]
struct Scale {
    signed: bool,
    factor: f64,
    unit: &'static str,
}

impl Scale {
    fn apply(self, raw: u32) -> f64 {
        let v = if self.signed { f64::from(raw as i32) } else { f64::from(raw) };
        v * self.factor
    }
}

/// Reads log `log` (1-based) of the blackbox file `data`: the time, `loopIteration` and the
/// main-frame fields `wanted` (names as the firmware writes them, e.g. `gyroADC[0]`).
///
/// # Errors
/// [`BlackboxError`] when the file is not a blackbox log, has no such log or field, its header
/// cannot be used, or no frame can be read. Frames the parser cannot decode are skipped (see
/// [`BlackboxLog::iteration`] to count them).
pub fn read(data: &[u8], log: usize, wanted: &[String]) -> Result<BlackboxLog, BlackboxError> {
    let (n_logs, bytes, text) = select_log(data, log)?;
    without_panic(|| decode(bytes, log, n_logs, text, wanted))
        .unwrap_or_else(|reason| Err(BlackboxError::Corrupt { log, reason }))
}

/// The header of log `log` (1-based) of `data`: how many logs the file holds, the `H` lines and
/// the main-frame fields, without decoding a frame.
///
/// # Errors
/// As [`read`], for the header.
pub fn fields(data: &[u8], log: usize) -> Result<LogHeader, BlackboxError> {
    let (n_logs, bytes, text) = select_log(data, log)?;
    let parsed = without_panic(|| match blackbox_log::File::new(bytes).parse(0) {
        Some(Ok(h)) => Ok(h.main_frame_def().iter().map(|d| d.name.to_string()).collect()),
        Some(Err(e)) => Err(BlackboxError::Header { log, reason: e.to_string() }),
        None => Err(BlackboxError::NotBlackbox),
    });
    let names = parsed.unwrap_or_else(|reason| Err(BlackboxError::Corrupt { log, reason }))?;
    Ok(LogHeader { n_logs, headers: text, fields: names })
}

/// The bytes of log `log` (1-based), the number of logs and the log's text header.
fn select_log(data: &[u8], log: usize) -> Result<(usize, &[u8], TextHeader), BlackboxError> {
    let starts = log_starts(data);
    if starts.is_empty() {
        return Err(BlackboxError::NotBlackbox);
    }
    let n_logs = starts.len();
    if log == 0 || log > n_logs {
        return Err(BlackboxError::NoSuchLog { log, n_logs });
    }
    let end = starts.get(log).copied().unwrap_or(data.len());
    let bytes = &data[starts[log - 1]..end];
    Ok((n_logs, bytes, text_headers(bytes)))
}

fn decode(
    bytes: &[u8],
    log: usize,
    n_logs: usize,
    text: Vec<(String, String)>,
    wanted: &[String],
) -> Result<BlackboxLog, BlackboxError> {
    let file = blackbox_log::File::new(bytes);
    let headers = match file.parse(0) {
        Some(Ok(h)) => h,
        Some(Err(e)) => return Err(BlackboxError::Header { log, reason: e.to_string() }),
        None => return Err(BlackboxError::NotBlackbox),
    };
    let def = headers.main_frame_def();
    let fields: Vec<String> = def.iter().map(|d| d.name.to_string()).collect();
    let gyro = gyro_scale(&text);
    let acc_1g = header_number(&text, "acc_1G").unwrap_or(1.0);
    let mut picks = Vec::with_capacity(wanted.len());
    for name in wanted {
        let Some(index) = fields.iter().position(|f| f == name) else {
            return Err(BlackboxError::UnknownField { field: name.clone(), available: fields });
        };
        let Some(d) = def.get(index) else { return Err(BlackboxError::NoFrames { log }) };
        let (factor, unit) = match d.unit {
            MainUnit::Rotation => (gyro, "deg/s"),
            MainUnit::Voltage => (0.01, "V"),
            MainUnit::Amperage => (0.01, "A"),
            MainUnit::Acceleration => (1.0 / acc_1g, "g"),
            MainUnit::Unitless => (1.0, ""),
        };
        picks.push((index, Scale { signed: d.signed, factor, unit }));
    }
    let mut time_us = Vec::new();
    let mut iteration = Vec::new();
    let mut columns = vec![Vec::new(); picks.len()];
    let mut complete = false;
    let mut parser = headers.data_parser();
    while let Some(event) = parser.next() {
        match event {
            ParserEvent::Main(frame) => {
                time_us.push(frame.time_raw() as f64);
                iteration.push(frame.get_raw(0).map_or(f64::NAN, f64::from));
                for (column, (index, scale)) in columns.iter_mut().zip(&picks) {
                    column.push(frame.get_raw(*index).map_or(f64::NAN, |raw| scale.apply(raw)));
                }
            }
            ParserEvent::Event(Event::End { .. }) => complete = true,
            _ => {}
        }
    }
    if time_us.is_empty() {
        return Err(BlackboxError::NoFrames { log });
    }
    // The decoder only reports the end-of-log event when a frame or the end of the file follows
    // it; on flash the rest of the erased page (0xFF bytes) follows, so look for its text too.
    complete = complete || bytes.windows(END_OF_LOG.len()).any(|w| w == END_OF_LOG);
    Ok(BlackboxLog {
        n_logs,
        headers: text,
        fields,
        time_us,
        iteration,
        columns,
        units: picks.iter().map(|(_, s)| s.unit).collect(),
        complete,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn not_a_log() {
        assert_eq!(read(b"hello", 1, &[]), Err(BlackboxError::NotBlackbox));
        assert_eq!(read(b"", 1, &[]), Err(BlackboxError::NotBlackbox));
    }

    #[test]
    fn header_only_is_an_error_not_a_panic() {
        let mut data = MARKER.to_vec();
        data.extend_from_slice(b"H Data version:2\nH Firmware revision:Betaflight 4.2.0 (x) F7\n");
        assert!(matches!(read(&data, 1, &[]), Err(BlackboxError::Header { log: 1, .. })));
        assert_eq!(read(&data, 2, &[]), Err(BlackboxError::NoSuchLog { log: 2, n_logs: 1 }));
    }

    #[test]
    fn headers_and_scales() {
        let h = text_headers(b"H gyro_scale:0x3f800000\nH acc_1G:2048\nIxx");
        assert_eq!(h.len(), 2);
        assert_eq!(gyro_scale(&h), 1.0);
        assert_eq!(header_number(&h, "acc_1G"), Some(2048.0));
        assert_eq!(log_starts(&[MARKER, b"abc", MARKER].concat()), vec![0, MARKER.len() + 3]);
    }
}
