//! Sparkplug B payloads (the Eclipse Tahu protobuf `org.eclipse.tahu.protobuf.Payload`,
//! Sparkplug 3.0 §6.4): the channel's signals are the metrics named as its columns.
//!
//! The protobuf wire format (tags, varints, lengths, unknown fields) is read by
//! `quick-protobuf`'s `BytesReader`, which borrows strings and sub-messages from the
//! payload: a message is decoded without allocating. Sparkplug's own rules are here:
//! - a metric is found by `name`, or by the `alias` a birth certificate (a payload
//!   carrying both, on the channel's key) gave that name;
//! - its number is read by its `datatype` (given in the metric, or learned from the
//!   birth): `Int8`…`Int32` from the low bits of `int_value` as two's complement,
//!   `Int64` from `long_value`, unsigned types as they are, `Float`, `Double`,
//!   `Boolean` (0 or 1), `DateTime` (milliseconds);
//! - data messages report by exception: a signal missing from a payload keeps the
//!   value it last had, and a payload without any of the channel's metrics is no
//!   sample; a signal never seen yet is a `missing_field` error;
//! - the sample's time is the payload's `timestamp` (milliseconds since the Unix
//!   epoch), else the transport's; metrics of other names are not read.

use std::collections::HashMap;

use glrmon_spec::{Columns, PayloadFormat};
use glrmon_wire::{DecodeError, DecodeErrorKind, DecodeLimits, Sample};
use quick_protobuf::BytesReader;

use super::{PayloadDecoder, single, within_limit};

/// Wire types of a protobuf tag (the low 3 bits).
const VARINT: u32 = 0;
const FIXED64: u32 = 1;
const LENGTH_DELIMITED: u32 = 2;
const FIXED32: u32 = 5;

/// Sparkplug B data types (§6.4.16) that carry a number.
mod datatype {
    pub(super) const INT8: u32 = 1;
    pub(super) const INT16: u32 = 2;
    pub(super) const INT32: u32 = 3;
    pub(super) const INT64: u32 = 4;
}

/// The decoder of a `sparkplug` channel, with what birth certificates taught it.
#[derive(Debug, Clone)]
pub struct SparkplugDecoder {
    /// The metric names of the inputs, outputs and signals, in the sample's order.
    names: Vec<String>,
    index: HashMap<String, usize>,
    dims: [usize; 3],
    /// Each signal's alias and datatype, once a birth (or a metric) gave them.
    alias: Vec<Option<u64>>,
    datatype: Vec<Option<u32>>,
    /// Each signal's last value (`None`: never seen).
    last: Vec<Option<f64>>,
    /// The values of the payload being read, committed once all of it is valid.
    update: Vec<Option<f64>>,
}

impl SparkplugDecoder {
    /// A decoder reading the metrics named as `columns`.
    #[must_use]
    pub fn new(columns: &Columns) -> Self {
        let names: Vec<String> = [&columns.u, &columns.y, &columns.p]
            .into_iter()
            .flatten()
            .cloned()
            .collect();
        let index = names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), i))
            .collect();
        let n = names.len();
        Self {
            names,
            index,
            dims: [columns.u.len(), columns.y.len(), columns.p.len()],
            alias: vec![None; n],
            datatype: vec![None; n],
            last: vec![None; n],
            update: vec![None; n],
        }
    }
}

/// One metric as the payload gives it (borrowed).
#[derive(Debug, Default)]
struct Metric<'a> {
    name: Option<&'a str>,
    alias: Option<u64>,
    datatype: Option<u32>,
    is_null: bool,
    value: Option<Value>,
}

#[derive(Debug, Clone, Copy)]
enum Value {
    Int(u32),
    Long(u64),
    Float(f32),
    Double(f64),
    Bool(bool),
    /// A string, bytes, data set, template or extension value.
    NotANumber,
}

/// Why a payload could not be read: the field (a metric's name) and the kind.
type Failure = (Option<String>, DecodeErrorKind);

fn malformed(what: &str, e: &quick_protobuf::Error) -> Failure {
    (
        None,
        DecodeErrorKind::WrongType {
            expected: format!("a Sparkplug B payload (protobuf): {what}: {e}"),
        },
    )
}

/// The next tag of `r`, split into field number and wire type.
fn tag(r: &mut BytesReader, bytes: &[u8], what: &str) -> Result<(u32, u32), Failure> {
    let tag = r.next_tag(bytes).map_err(|e| malformed(what, &e))?;
    Ok((tag >> 3, tag & 7))
}

fn metric(bytes: &[u8]) -> Result<Metric<'_>, quick_protobuf::Error> {
    let mut r = BytesReader::from_bytes(bytes);
    let mut m = Metric::default();
    while !r.is_eof() {
        let tag = r.next_tag(bytes)?;
        match (tag >> 3, tag & 7) {
            (1, LENGTH_DELIMITED) => m.name = Some(r.read_string(bytes)?),
            (2, VARINT) => m.alias = Some(r.read_uint64(bytes)?),
            (4, VARINT) => m.datatype = Some(r.read_uint32(bytes)?),
            (7, VARINT) => m.is_null = r.read_bool(bytes)?,
            (10, VARINT) => m.value = Some(Value::Int(r.read_uint32(bytes)?)),
            (11, VARINT) => m.value = Some(Value::Long(r.read_uint64(bytes)?)),
            (12, FIXED32) => m.value = Some(Value::Float(r.read_float(bytes)?)),
            (13, FIXED64) => m.value = Some(Value::Double(r.read_double(bytes)?)),
            (14, VARINT) => m.value = Some(Value::Bool(r.read_bool(bytes)?)),
            (15..=19, LENGTH_DELIMITED) => {
                r.read_unknown(bytes, tag)?;
                m.value = Some(Value::NotANumber);
            }
            _ => r.read_unknown(bytes, tag)?,
        }
    }
    Ok(m)
}

/// The number a value stands for, read by the metric's data type.
#[allow(clippy::cast_possible_truncation, clippy::cast_possible_wrap)]
fn number(value: Value, datatype: Option<u32>) -> Option<f64> {
    Some(match (value, datatype) {
        (Value::Int(v), Some(datatype::INT8)) => f64::from(v as u8 as i8),
        (Value::Int(v), Some(datatype::INT16)) => f64::from(v as u16 as i16),
        (Value::Int(v), Some(datatype::INT32)) => f64::from(v as i32),
        (Value::Int(v), _) => f64::from(v),
        // Beyond 2⁵³ an i64 or u64 is rounded, as any JSON number is.
        #[allow(clippy::cast_precision_loss)]
        (Value::Long(v), Some(datatype::INT64)) => v as i64 as f64,
        #[allow(clippy::cast_precision_loss)]
        (Value::Long(v), _) => v as f64,
        (Value::Float(v), _) => f64::from(v),
        (Value::Double(v), _) => v,
        (Value::Bool(v), _) => f64::from(u8::from(v)),
        (Value::NotANumber, _) => return None,
    })
}

impl SparkplugDecoder {
    /// Reads the payload's metrics into `update`; the payload's timestamp.
    fn read(&mut self, payload: &[u8]) -> Result<Option<u64>, Failure> {
        self.update.fill(None);
        let mut timestamp = None;
        let mut r = BytesReader::from_bytes(payload);
        while !r.is_eof() {
            let (field, wire) = tag(&mut r, payload, "payload")?;
            match (field, wire) {
                (1, VARINT) => {
                    timestamp = Some(
                        r.read_uint64(payload)
                            .map_err(|e| malformed("timestamp", &e))?,
                    );
                }
                (2, LENGTH_DELIMITED) => {
                    let bytes = r.read_bytes(payload).map_err(|e| malformed("metric", &e))?;
                    let m = metric(bytes).map_err(|e| malformed("metric", &e))?;
                    self.metric(&m)?;
                }
                _ => r
                    .read_unknown(payload, (field << 3) | wire)
                    .map_err(|e| malformed("payload", &e))?,
            }
        }
        Ok(timestamp)
    }

    /// One metric: learns its alias and data type, then notes its value if it is one
    /// of the channel's.
    fn metric(&mut self, m: &Metric<'_>) -> Result<(), Failure> {
        let signal = match (m.name, m.alias) {
            (Some(name), alias) => {
                let Some(&i) = self.index.get(name) else {
                    return Ok(());
                };
                if alias.is_some() {
                    self.alias[i] = alias;
                }
                i
            }
            (None, Some(alias)) => match self.alias.iter().position(|&a| a == Some(alias)) {
                Some(i) => i,
                None => return Ok(()),
            },
            (None, None) => return Ok(()),
        };
        if m.datatype.is_some() {
            self.datatype[signal] = m.datatype;
        }
        let name = || Some(self.names[signal].clone());
        if m.is_null {
            let expected = "a value (the metric is null)".into();
            return Err((name(), DecodeErrorKind::WrongType { expected }));
        }
        let Some(value) = m.value else {
            return Ok(());
        };
        let Some(v) = number(value, self.datatype[signal]) else {
            let expected = "a number (an int, long, float, double or boolean value)".into();
            return Err((name(), DecodeErrorKind::WrongType { expected }));
        };
        if !v.is_finite() {
            return Err((name(), DecodeErrorKind::NonFinite));
        }
        self.update[signal] = Some(v);
        Ok(())
    }
}

impl PayloadDecoder for SparkplugDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Sparkplug.name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        let fail = |out: &mut Vec<Sample>, (field, kind): Failure| {
            out.clear();
            Err(DecodeError::new(channel, field, kind))
        };
        if let Err(e) = within_limit(channel, None, payload, limits) {
            out.clear();
            return Err(e);
        }
        let timestamp = match self.read(payload) {
            Ok(t) => t,
            Err(failure) => return fail(out, failure),
        };
        if self.update.iter().all(Option::is_none) {
            out.clear();
            return Ok(());
        }
        if let Some(i) = (0..self.names.len()).find(|&i| self.update[i].or(self.last[i]).is_none())
        {
            let name = Some(self.names[i].clone());
            return fail(out, (name, DecodeErrorKind::MissingField));
        }
        for (last, update) in self.last.iter_mut().zip(&self.update) {
            if update.is_some() {
                *last = *update;
            }
        }
        let [l, m, _] = self.dims;
        let sample = single(out);
        // Milliseconds since the epoch: exact in an f64 for 285 000 years.
        #[allow(clippy::cast_precision_loss)]
        let t = timestamp.map(|ms| ms as f64 / 1000.0);
        sample.t = t;
        let values = self.last.iter().map(|v| v.unwrap_or_default());
        for (i, v) in values.enumerate() {
            match i {
                i if i < l => sample.u.push(v),
                i if i < l + m => sample.y.push(v),
                _ => sample.p.push(v),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::ErrorCode;
    use prost::Message;

    /// `org.eclipse.tahu.protobuf.Payload` as prost derives it from the schema's field
    /// numbers: an encoder independent of the reader under test.
    #[derive(Clone, PartialEq, prost::Message)]
    struct Payload {
        #[prost(uint64, optional, tag = "1")]
        timestamp: Option<u64>,
        #[prost(message, repeated, tag = "2")]
        metrics: Vec<Metric>,
        #[prost(uint64, optional, tag = "3")]
        seq: Option<u64>,
        #[prost(string, optional, tag = "4")]
        uuid: Option<String>,
    }

    #[derive(Clone, PartialEq, prost::Message)]
    struct Metric {
        #[prost(string, optional, tag = "1")]
        name: Option<String>,
        #[prost(uint64, optional, tag = "2")]
        alias: Option<u64>,
        #[prost(uint64, optional, tag = "3")]
        timestamp: Option<u64>,
        #[prost(uint32, optional, tag = "4")]
        datatype: Option<u32>,
        #[prost(bool, optional, tag = "7")]
        is_null: Option<bool>,
        #[prost(oneof = "Value", tags = "10, 11, 12, 13, 14, 15")]
        value: Option<Value>,
    }

    #[derive(Clone, PartialEq, prost::Oneof)]
    enum Value {
        #[prost(uint32, tag = "10")]
        Int(u32),
        #[prost(uint64, tag = "11")]
        Long(u64),
        #[prost(float, tag = "12")]
        Float(f32),
        #[prost(double, tag = "13")]
        Double(f64),
        #[prost(bool, tag = "14")]
        Bool(bool),
        #[prost(string, tag = "15")]
        Text(String),
    }

    fn metric(
        name: Option<&str>,
        alias: Option<u64>,
        datatype: Option<u32>,
        value: Option<Value>,
    ) -> Metric {
        Metric {
            name: name.map(str::to_owned),
            alias,
            timestamp: Some(1_700_000_000_123),
            datatype,
            is_null: None,
            value,
        }
    }

    fn decoder() -> SparkplugDecoder {
        SparkplugDecoder::new(&Columns {
            u: vec!["Motor/Voltage".into()],
            y: vec!["Motor/Current".into(), "Motor/Speed".into()],
            p: vec![],
            named: true,
            u_units: vec![],
            y_units: vec![],
            p_units: vec![],
        })
    }

    fn decode(d: &mut SparkplugDecoder, p: &Payload) -> Result<Vec<Sample>, DecodeError> {
        let mut out = Vec::new();
        d.decode(
            "dc_motor",
            &p.encode_to_vec(),
            &DecodeLimits::default(),
            &mut out,
        )
        .map(|()| out)
    }

    /// A birth names the metrics and gives aliases and data types; data messages then
    /// carry aliases only, and only what changed (Sparkplug 3.0 §6.4.1, report by
    /// exception).
    #[test]
    fn a_birth_teaches_aliases_and_data_reports_by_exception() {
        let mut d = decoder();
        let birth = Payload {
            timestamp: Some(1_700_000_000_000),
            metrics: vec![
                metric(
                    Some("Motor/Voltage"),
                    Some(1),
                    Some(10),
                    Some(Value::Double(12.0)),
                ),
                metric(
                    Some("Motor/Current"),
                    Some(2),
                    Some(3),
                    Some(Value::Int((-3i32) as u32)),
                ),
                metric(
                    Some("Motor/Speed"),
                    Some(3),
                    Some(9),
                    Some(Value::Float(120.5)),
                ),
                metric(
                    Some("Motor/Label"),
                    Some(4),
                    Some(12),
                    Some(Value::Text("M1".into())),
                ),
            ],
            seq: Some(0),
            uuid: None,
        };
        let s = decode(&mut d, &birth).unwrap();
        assert_eq!(
            (s[0].t, &s[0].u[..], &s[0].y[..]),
            (Some(1_700_000_000.0), &[12.0][..], &[-3.0, 120.5][..])
        );
        let data = Payload {
            timestamp: Some(1_700_000_000_010),
            metrics: vec![metric(None, Some(3), None, Some(Value::Float(121.0)))],
            seq: Some(1),
            uuid: None,
        };
        let s = decode(&mut d, &data).unwrap();
        assert_eq!(
            (s[0].t, &s[0].u[..], &s[0].y[..]),
            (Some(1_700_000_000.01), &[12.0][..], &[-3.0, 121.0][..])
        );
        // The learnt Int32 reads a negative current from the alias too.
        let data = Payload {
            timestamp: None,
            metrics: vec![metric(
                None,
                Some(2),
                None,
                Some(Value::Int((-7i32) as u32)),
            )],
            seq: Some(2),
            uuid: None,
        };
        let s = decode(&mut d, &data).unwrap();
        assert_eq!((s[0].t, &s[0].y[..]), (None, &[-7.0, 121.0][..]));
        // Other metrics only: no sample.
        let other = Payload {
            timestamp: Some(1),
            metrics: vec![metric(None, Some(4), None, Some(Value::Text("M2".into())))],
            seq: Some(3),
            uuid: None,
        };
        assert!(decode(&mut d, &other).unwrap().is_empty());
    }

    #[test]
    fn every_numeric_type_reads_as_its_datatype_says() {
        for (datatype, value, want) in [
            (1, Value::Int(0xff), -1.0),
            (2, Value::Int(0xfffe), -2.0),
            (3, Value::Int(u32::MAX), -1.0),
            (4, Value::Long(u64::MAX - 4), -5.0),
            (5, Value::Int(200), 200.0),
            (7, Value::Int(u32::MAX), 4_294_967_295.0),
            (8, Value::Long(1 << 40), 1_099_511_627_776.0),
            (9, Value::Float(0.5), 0.5),
            (10, Value::Double(-2.25), -2.25),
            (11, Value::Bool(true), 1.0),
            (13, Value::Long(1_700_000_000_000), 1.7e12),
        ] {
            let mut d = SparkplugDecoder::new(&Columns {
                u: vec![],
                y: vec!["x".into()],
                p: vec![],
                named: true,
                u_units: vec![],
                y_units: vec![],
                p_units: vec![],
            });
            let p = Payload {
                timestamp: None,
                metrics: vec![metric(Some("x"), None, Some(datatype), Some(value))],
                seq: None,
                uuid: None,
            };
            assert_eq!(
                decode(&mut d, &p).unwrap()[0].y,
                [want],
                "datatype {datatype}"
            );
        }
    }

    #[test]
    fn a_bad_payload_names_the_metric_and_keeps_the_last_values() {
        let mut d = decoder();
        let partial = Payload {
            timestamp: None,
            metrics: vec![metric(
                Some("Motor/Voltage"),
                None,
                Some(10),
                Some(Value::Double(1.0)),
            )],
            seq: None,
            uuid: None,
        };
        let e = decode(&mut d, &partial).unwrap_err();
        assert_eq!(
            (e.code(), e.field.as_deref()),
            (ErrorCode::MissingField, Some("Motor/Current"))
        );
        let text = Payload {
            timestamp: None,
            metrics: vec![metric(
                Some("Motor/Speed"),
                None,
                Some(12),
                Some(Value::Text("fast".into())),
            )],
            seq: None,
            uuid: None,
        };
        let e = decode(&mut d, &text).unwrap_err();
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field Motor/Speed has the wrong type: expected a number \
             (an int, long, float, double or boolean value)"
        );
        let mut null = metric(Some("Motor/Speed"), None, None, None);
        null.is_null = Some(true);
        let p = Payload {
            timestamp: None,
            metrics: vec![null],
            seq: None,
            uuid: None,
        };
        assert_eq!(decode(&mut d, &p).unwrap_err().code(), ErrorCode::WrongType);
        let nan = metric(
            Some("Motor/Speed"),
            None,
            None,
            Some(Value::Double(f64::NAN)),
        );
        let p = Payload {
            timestamp: None,
            metrics: vec![nan],
            seq: None,
            uuid: None,
        };
        assert_eq!(decode(&mut d, &p).unwrap_err().code(), ErrorCode::NonFinite);
        // Truncated: every prefix of a valid payload is refused or read, never a panic,
        // and a refused one leaves no value behind.
        let full = Payload {
            timestamp: Some(5),
            metrics: vec![
                metric(Some("Motor/Voltage"), None, None, Some(Value::Double(1.0))),
                metric(Some("Motor/Current"), None, None, Some(Value::Double(2.0))),
                metric(Some("Motor/Speed"), None, None, Some(Value::Double(3.0))),
            ],
            seq: None,
            uuid: None,
        }
        .encode_to_vec();
        let mut refused = 0;
        for n in 0..full.len() {
            let mut fresh = decoder();
            let mut out = Vec::new();
            if fresh
                .decode("dc_motor", &full[..n], &DecodeLimits::default(), &mut out)
                .is_err()
            {
                refused += 1;
                assert!(out.is_empty() && fresh.last.iter().all(Option::is_none));
            }
        }
        assert!(refused > full.len() / 2, "{refused} of {}", full.len());
    }

    /// After the first payload, decoding allocates nothing: the sample's vectors and
    /// the decoder's tables are reused, names and sub-messages borrowed.
    #[test]
    fn decoding_reuses_every_buffer() {
        let mut d = decoder();
        let p = Payload {
            timestamp: Some(7),
            metrics: vec![
                metric(
                    Some("Motor/Voltage"),
                    Some(1),
                    Some(10),
                    Some(Value::Double(1.0)),
                ),
                metric(
                    Some("Motor/Current"),
                    Some(2),
                    Some(10),
                    Some(Value::Double(2.0)),
                ),
                metric(
                    Some("Motor/Speed"),
                    Some(3),
                    Some(10),
                    Some(Value::Double(3.0)),
                ),
            ],
            seq: None,
            uuid: None,
        }
        .encode_to_vec();
        let mut out = Vec::new();
        d.decode("dc_motor", &p, &DecodeLimits::default(), &mut out)
            .unwrap();
        let before = (out.as_ptr(), out[0].u.as_ptr(), out[0].y.as_ptr());
        for _ in 0..100 {
            d.decode("dc_motor", &p, &DecodeLimits::default(), &mut out)
                .unwrap();
        }
        assert_eq!(before, (out.as_ptr(), out[0].u.as_ptr(), out[0].y.as_ptr()));
    }
}
