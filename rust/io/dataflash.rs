//! ArduPilot DataFlash logs (`.bin`) on the `ardupilot-binlog` crate.
//!
//! A DataFlash log is a stream of messages, each `0xA3 0x95`, a type byte and a fixed-size
//! payload. `FMT` messages define each type's name, field names and binary layout; `UNIT` and
//! `FMTU` messages give the fields' units. [`read`] decodes the wanted fields of the wanted
//! messages into columns with their time stamps (`TimeUS`), the instance number of messages that
//! have one (`BAT`'s `Inst`, `IMU`'s `I`), the units, and how many bytes could not be decoded.
//! Values are as ArduPilot defines them: the crate divides the centi-unit types (`c`, `C`, `e`,
//! `E`) by 100, as ArduPilot's own tools do.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::io::Cursor;

use ardupilot_binlog::{FieldValue, Reader};

use super::without_panic;

const MAGIC: [u8; 2] = [0xA3, 0x95];
/// Field names that may number the instances of a message (two batteries, three IMUs). `I` is
/// also the integrator term of `PIDR`, so a field is the instance only when the log's `FMTU`
/// gives it the instance unit `#`, or, in a log without `FMTU`, when it is named `Inst`/`Instance`.
const INSTANCE_FIELDS: [&str; 3] = ["I", "Inst", "Instance"];
/// The `FMTU` unit of an instance number.
const INSTANCE_UNIT: char = '#';

/// What can make a DataFlash file unreadable.
#[derive(Debug, Clone, PartialEq)]
pub enum DataflashError {
    /// The file does not start with a DataFlash message (`0xA3 0x95`).
    NotDataflash,
    /// The log never defines message `message`.
    UnknownMessage { message: String, available: Vec<String> },
    /// Message `message` has no field `field`.
    UnknownField { message: String, field: String, available: Vec<String> },
    /// Field `field` of `message` holds text or an array, not a number.
    NotNumeric { message: String, field: String },
    /// The parser stopped on data it could not handle.
    Corrupt(String),
}

impl fmt::Display for DataflashError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DataflashError::NotDataflash => {
                write!(f, "is not an ArduPilot DataFlash log (it does not start with the bytes 0xA3 0x95)")
            }
            DataflashError::UnknownMessage { message, available } => {
                write!(f, "logs no message '{message}'; it logs {}", quoted(available))
            }
            DataflashError::UnknownField { message, field, available } => {
                write!(f, "message '{message}' has no field '{field}'; its fields are {}", quoted(available))
            }
            DataflashError::NotNumeric { message, field } => {
                write!(f, "field '{field}' of message '{message}' is text, not a number")
            }
            DataflashError::Corrupt(reason) => write!(f, "is corrupt ({reason})"),
        }
    }
}

impl std::error::Error for DataflashError {}

/// Names as a list a reader can copy from: `['RATE', 'BAT']`.
pub(crate) fn quoted(names: &[String]) -> String {
    let inner: Vec<String> = names.iter().map(|n| format!("'{n}'")).collect();
    format!("[{}]", inner.join(", "))
}

/// The wanted fields of one message type.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MessageColumns {
    /// Time of each message in microseconds since boot (NaN when it has no `TimeUS`/`TimeMS`).
    pub time_us: Vec<f64>,
    /// The instance number of each message, for types that have one.
    pub instance: Option<Vec<f64>>,
    /// One column per wanted field, in the order asked.
    pub columns: Vec<Vec<f64>>,
    /// Unit of each wanted field from the log's `UNIT`/`FMTU` messages (`""` when not given).
    pub units: Vec<String>,
}

/// The wanted messages of a DataFlash log.
#[derive(Debug, Clone, PartialEq)]
pub struct DataflashLog {
    /// The messages asked for, by name.
    pub messages: BTreeMap<String, MessageColumns>,
    /// Bytes of the file that are not part of a decoded message (corrupt or cut short).
    pub bytes_lost: usize,
    /// Messages decoded (all types).
    pub n_messages: usize,
    /// Every message type the log defines, with its field names and how many messages of it the
    /// log holds (0: defined, never logged), sorted by name.
    pub formats: Vec<(String, Vec<String>, usize)>,
}

/// Reads the fields `wanted` (`(message, field)` pairs such as `("RATE", "R")`) from the
/// DataFlash log `data`.
///
/// # Errors
/// [`DataflashError`] when the file is not a DataFlash log, a message or field is not in it or
/// not numeric. Damaged messages are skipped and counted in [`DataflashLog::bytes_lost`].
pub fn read(data: &[u8], wanted: &[(String, String)]) -> Result<DataflashLog, DataflashError> {
    if data.len() < 3 || data[..2] != MAGIC {
        return Err(DataflashError::NotDataflash);
    }
    without_panic(|| decode(data, wanted)).unwrap_or_else(|reason| Err(DataflashError::Corrupt(reason)))
}

/// Per wanted message: its field names in the order asked.
fn wanted_fields(wanted: &[(String, String)]) -> BTreeMap<String, Vec<String>> {
    let mut by_message: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (message, field) in wanted {
        by_message.entry(message.clone()).or_default().push(field.clone());
    }
    by_message
}

fn decode(data: &[u8], wanted: &[(String, String)]) -> Result<DataflashLog, DataflashError> {
    let by_message = wanted_fields(wanted);
    let mut messages: BTreeMap<String, MessageColumns> = by_message
        .iter()
        .map(|(name, fields)| {
            let columns = vec![Vec::new(); fields.len()];
            (name.clone(), MessageColumns { columns, ..Default::default() })
        })
        .collect();
    let mut unit_names: HashMap<char, String> = HashMap::new();
    let mut unit_ids: HashMap<u8, String> = HashMap::new();
    let mut candidates: HashMap<String, (String, Vec<f64>)> = HashMap::new();
    let mut counts: HashMap<u8, usize> = HashMap::new();
    let mut reader = Reader::new(Cursor::new(data));
    let (mut decoded_bytes, mut n_messages) = (0usize, 0usize);
    while let Some(entry) = reader.next() {
        let Ok(entry) = entry else { continue };
        n_messages += 1;
        *counts.entry(entry.msg_type).or_insert(0usize) += 1;
        decoded_bytes += reader.formats().get(&entry.msg_type).map_or(0, |f| usize::from(f.msg_len));
        match entry.name.as_str() {
            "UNIT" => {
                if let (Some(id), Some(label)) = (entry.get_i64("Id"), entry.get_str("Label")) {
                    unit_names.insert(char::from(id as u8), label.to_string());
                }
            }
            "FMTU" => {
                if let (Some(t), Some(ids)) = (entry.get_i64("FmtType"), entry.get_str("UnitIds")) {
                    unit_ids.insert(t as u8, ids.to_string());
                }
            }
            _ => {}
        }
        let (Some(fields), Some(out)) = (by_message.get(&entry.name), messages.get_mut(&entry.name)) else {
            continue;
        };
        out.time_us.push(entry.timestamp_usec.map_or(f64::NAN, |t| t as f64));
        if let Some(label) = INSTANCE_FIELDS.iter().find(|l| entry.labels().iter().any(|x| x == *l)) {
            let (_, values) = candidates.entry(entry.name.clone()).or_insert_with(|| (label.to_string(), Vec::new()));
            values.push(entry.get_f64(label).unwrap_or(f64::NAN));
        }
        for (column, field) in out.columns.iter_mut().zip(fields) {
            match entry.get(field) {
                Some(value) => match value {
                    FieldValue::String(_) | FieldValue::Array(_) => {
                        return Err(DataflashError::NotNumeric { message: entry.name.clone(), field: field.clone() })
                    }
                    v => column.push(v.as_f64().unwrap_or(f64::NAN)),
                },
                None => {
                    return Err(DataflashError::UnknownField {
                        message: entry.name.clone(),
                        field: field.clone(),
                        available: entry.labels().to_vec(),
                    })
                }
            }
        }
    }
    // Messages asked for but never logged: name them against what the log defines.
    let formats = reader.formats();
    for (name, fields) in &by_message {
        let Some(format) = formats.values().find(|f| &f.name == name) else {
            let mut available: Vec<String> = formats.values().map(|f| f.name.clone()).filter(|n| n != "FMT").collect();
            available.sort();
            available.dedup();
            return Err(DataflashError::UnknownMessage { message: name.clone(), available });
        };
        if let Some(field) = fields.iter().find(|f| !format.labels.contains(f)) {
            return Err(DataflashError::UnknownField {
                message: name.clone(),
                field: field.clone(),
                available: format.labels.to_vec(),
            });
        }
        let ids = unit_ids.get(&format.msg_type).map(|s| s.chars().collect::<Vec<_>>()).unwrap_or_default();
        if let Some(out) = messages.get_mut(name) {
            if let Some((label, values)) = candidates.remove(name) {
                let j = format.labels.iter().position(|l| *l == label);
                let is_instance = match j.and_then(|j| ids.get(j)) {
                    Some(&unit) => unit == INSTANCE_UNIT,
                    None => ids.is_empty() && label != "I",
                };
                out.instance = is_instance.then_some(values);
            }
            out.units = fields
                .iter()
                .map(|f| {
                    let j = format.labels.iter().position(|l| l == f).unwrap_or(usize::MAX);
                    ids.get(j).and_then(|c| unit_names.get(c)).cloned().unwrap_or_default()
                })
                .collect();
        }
    }
    let mut formats: Vec<(String, Vec<String>, usize)> = formats
        .values()
        .filter(|f| f.name != "FMT")
        .map(|f| (f.name.clone(), f.labels.to_vec(), counts.get(&f.msg_type).copied().unwrap_or(0)))
        .collect();
    formats.sort();
    Ok(DataflashLog { messages, bytes_lost: data.len().saturating_sub(decoded_bytes), n_messages, formats })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmt_message(msg_type: u8, len: u8, name: &[u8], format: &str, labels: &str) -> Vec<u8> {
        let mut m = vec![0xA3, 0x95, 0x80];
        let mut p = [0u8; 86];
        p[0] = msg_type;
        p[1] = len;
        p[2..2 + name.len()].copy_from_slice(name);
        p[6..6 + format.len()].copy_from_slice(format.as_bytes());
        p[22..22 + labels.len()].copy_from_slice(labels.as_bytes());
        m.extend_from_slice(&p);
        m
    }

    fn log() -> Vec<u8> {
        let mut d = fmt_message(0x80, 89, b"FMT", "BBnNZ", "Type,Length,Name,Format,Labels");
        d.extend(fmt_message(0x81, 3 + 8 + 4 + 4, b"RATE", "Qff", "TimeUS,R,ROut"));
        for (t, r, o) in [(1000u64, 1.5f32, 0.25f32), (2000, -2.0, 0.5)] {
            d.extend_from_slice(&[0xA3, 0x95, 0x81]);
            d.extend_from_slice(&t.to_le_bytes());
            d.extend_from_slice(&r.to_le_bytes());
            d.extend_from_slice(&o.to_le_bytes());
        }
        d
    }

    fn want(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect()
    }

    #[test]
    fn reads_columns_exactly() {
        let out = read(&log(), &want(&[("RATE", "ROut"), ("RATE", "R")])).unwrap();
        let rate = &out.messages["RATE"];
        assert_eq!(rate.time_us, vec![1000.0, 2000.0]);
        assert_eq!(rate.columns, vec![vec![0.25, 0.5], vec![1.5, -2.0]]);
        assert_eq!(out.bytes_lost, 0);
        assert!(rate.instance.is_none());
    }

    #[test]
    fn damage_is_counted_or_named() {
        let mut d = log();
        d.truncate(d.len() - 5);
        let out = read(&d, &want(&[("RATE", "R")])).unwrap();
        assert_eq!(out.messages["RATE"].columns[0], vec![1.5]);
        assert_eq!(out.bytes_lost, 19 - 5);
        assert_eq!(read(b"\x00\x01\x02", &[]), Err(DataflashError::NotDataflash));
        assert!(matches!(read(&log(), &want(&[("BAT", "Volt")])), Err(DataflashError::UnknownMessage { .. })));
        assert!(matches!(read(&log(), &want(&[("RATE", "P")])), Err(DataflashError::UnknownField { .. })));
    }

    #[test]
    fn a_format_shorter_than_its_header_is_an_error_not_a_panic() {
        let mut d = fmt_message(0x80, 89, b"FMT", "BBnNZ", "Type,Length,Name,Format,Labels");
        d.extend(fmt_message(0x81, 1, b"BAD", "Q", "TimeUS"));
        d.extend_from_slice(&[0xA3, 0x95, 0x81, 0, 0]);
        let out = read(&d, &[]);
        assert!(matches!(out, Ok(_) | Err(DataflashError::Corrupt(_))));
    }
}
