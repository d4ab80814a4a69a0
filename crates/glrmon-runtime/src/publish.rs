//! A channel's samples as its plant publishes them: the inverse of the channel's
//! decoder, for `glrmon simulate --publish` and programs that feed a channel. Each
//! sample becomes one publication per input key (`glrmon_spec::Channel::input_keys`):
//! the JSON sample, the CDR message (`cdr-encoding`), the Sparkplug B payload
//! (`quick-protobuf`'s writer; metrics by name, `Double`), the raw record, or for a
//! channel assembled from tags one bare number (or JSON object at the tag's field path,
//! with its time field) per tag.

use glrmon_spec::{CdrMessage, Channel, PayloadFormat, RawField};
use glrmon_wire::Sample;
use serde::Serialize;

/// One publication of a sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Publication {
    /// The index of its key in the channel's input keys.
    pub key: usize,
    /// The payload.
    pub bytes: Vec<u8>,
    /// Its Zenoh encoding (`application/json`, `application/cdr`, …).
    pub encoding: &'static str,
}

/// Why a sample could not be encoded for its channel.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PublishError {
    /// The sample's vectors do not have the channel's dimensions.
    #[error("channel \"{channel}\": the sample has {got} values, the channel {expected}")]
    Dimensions {
        /// The channel.
        channel: String,
        /// The channel's inputs + outputs + signals.
        expected: usize,
        /// The sample's.
        got: usize,
    },
    /// The encoder failed.
    #[error("channel \"{channel}\": {what} could not be encoded: {reason}")]
    Encode {
        /// The channel.
        channel: String,
        /// The format.
        what: &'static str,
        /// Why.
        reason: String,
    },
}

/// Sparkplug B's `Double` data type.
const SPARKPLUG_DOUBLE: u32 = 10;

/// The publications of `sample` on `channel`'s input keys, appended to `out`.
///
/// # Errors
/// [`PublishError`] when the sample does not fit the channel, or its encoder fails.
pub fn publications(
    channel: &Channel,
    sample: &Sample,
    out: &mut Vec<Publication>,
) -> Result<(), PublishError> {
    let d = channel.dims;
    let values: Vec<f64> = sample
        .u
        .iter()
        .chain(&sample.y)
        .chain(&sample.p)
        .copied()
        .collect();
    let expected = d.inputs + d.outputs + d.signals;
    if (sample.u.len(), sample.y.len(), sample.p.len()) != (d.inputs, d.outputs, d.signals) {
        return Err(PublishError::Dimensions {
            channel: channel.name.clone(),
            expected,
            got: values.len(),
        });
    }
    let fail = |what: &'static str, reason: String| PublishError::Encode {
        channel: channel.name.clone(),
        what,
        reason,
    };
    if let Some(tags) = &channel.tags {
        for (key, (_, group)) in tags.keys().into_iter().enumerate() {
            let bytes = match group.as_slice() {
                [i] if tags.tags[*i].field.is_empty() => format!("{:?}", values[*i]).into_bytes(),
                _ => {
                    let mut object = serde_json::Map::new();
                    for &i in &group {
                        let tag = &tags.tags[i];
                        insert(&mut object, &tag.field, serde_json::json!(values[i]));
                        if let (Some(path), Some(t)) = (&tag.time_field, sample.t) {
                            insert(&mut object, path, serde_json::json!(t));
                        }
                    }
                    serde_json::to_vec(&object).map_err(|e| fail("tag", e.to_string()))?
                }
            };
            out.push(Publication {
                key,
                bytes,
                encoding: "application/json",
            });
        }
        return Ok(());
    }
    let (bytes, encoding) = match &channel.payload {
        PayloadFormat::Json => {
            let mut bytes = Vec::new();
            glrmon_wire::encode_sample(&channel.name, sample, &mut bytes)
                .map_err(|e| fail("json", e.to_string()))?;
            (bytes, "application/json")
        }
        PayloadFormat::Cdr(message) => (
            cdr(*message, sample, &values).map_err(|e| fail("cdr", e))?,
            "application/cdr",
        ),
        PayloadFormat::Sparkplug => (
            sparkplug(channel, sample, &values).map_err(|e| fail("sparkplug", e))?,
            "application/protobuf",
        ),
        PayloadFormat::Raw(layout) => {
            let mut bytes = Vec::with_capacity(layout.record_bytes());
            for field in &layout.fields {
                #[allow(clippy::cast_precision_loss)]
                let v = match *field {
                    RawField::K => sample.k.unwrap_or(0) as f64,
                    RawField::T => sample.t.unwrap_or(0.0),
                    RawField::U(i) => sample.u[i],
                    RawField::Y(i) => sample.y[i],
                    RawField::P(i) => sample.p[i],
                    RawField::Skip => 0.0,
                };
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            (bytes, "application/octet-stream")
        }
    };
    out.push(Publication {
        key: 0,
        bytes,
        encoding,
    });
    Ok(())
}

/// Sets `value` at `path` in `object`, creating the objects on the way.
fn insert(
    object: &mut serde_json::Map<String, serde_json::Value>,
    path: &[String],
    value: serde_json::Value,
) {
    let Some((last, parents)) = path.split_last() else {
        return;
    };
    let mut at = object;
    for name in parents {
        let next = at
            .entry(name.clone())
            .or_insert_with(|| serde_json::Value::Object(serde_json::Map::new()));
        if !next.is_object() {
            *next = serde_json::Value::Object(serde_json::Map::new());
        }
        let serde_json::Value::Object(map) = next else {
            return;
        };
        at = map;
    }
    at.insert(last.clone(), value);
}

#[derive(Serialize)]
struct Dimension<'a> {
    label: &'a str,
    size: u32,
    stride: u32,
}

#[derive(Serialize)]
struct MultiArray<'a> {
    dim: Vec<Dimension<'a>>,
    data_offset: u32,
    data: &'a [f64],
}

#[derive(Serialize)]
struct SampleMessage<'a> {
    k: i64,
    t: f64,
    u: &'a [f64],
    y: &'a [f64],
    p: &'a [f64],
}

/// The message in little-endian plain CDR, after its encapsulation header.
fn cdr(message: CdrMessage, sample: &Sample, values: &[f64]) -> Result<Vec<u8>, String> {
    let body = match message {
        CdrMessage::Float64MultiArray => {
            let n = u32::try_from(values.len()).map_err(|e| e.to_string())?;
            let array = MultiArray {
                dim: vec![Dimension {
                    label: "u_y_p",
                    size: n,
                    stride: n,
                }],
                data_offset: 0,
                data: values,
            };
            cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&array)
        }
        CdrMessage::Sample => {
            let k = match sample.k {
                Some(k) => i64::try_from(k).map_err(|e| e.to_string())?,
                None => -1,
            };
            let msg = SampleMessage {
                k,
                t: sample.t.unwrap_or(f64::NAN),
                u: &sample.u,
                y: &sample.y,
                p: &sample.p,
            };
            cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&msg)
        }
    }
    .map_err(|e| e.to_string())?;
    Ok([&[0u8, 1, 0, 0][..], &body].concat())
}

/// A Sparkplug B payload: `timestamp` (ms) from `t`, each signal a `Double` metric by
/// its column name.
fn sparkplug(channel: &Channel, sample: &Sample, values: &[f64]) -> Result<Vec<u8>, String> {
    use quick_protobuf::Writer;
    let c = &channel.columns;
    let names = c.u.iter().chain(&c.y).chain(&c.p);
    let mut bytes = Vec::new();
    let mut w = Writer::new(&mut bytes);
    let err = |e: quick_protobuf::Error| e.to_string();
    if let Some(t) = sample.t {
        // Milliseconds since the epoch.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let ms = (t * 1000.0).round() as u64;
        w.write_with_tag(8, |w| w.write_uint64(ms)).map_err(err)?;
    }
    for (name, v) in names.zip(values) {
        let mut metric = Vec::new();
        let mut m = Writer::new(&mut metric);
        m.write_with_tag(10, |w| w.write_string(name))
            .map_err(err)?;
        m.write_with_tag(32, |w| w.write_uint32(SPARKPLUG_DOUBLE))
            .map_err(err)?;
        m.write_with_tag(105, |w| w.write_double(*v)).map_err(err)?;
        w.write_with_tag(18, |w| w.write_bytes(&metric))
            .map_err(err)?;
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::DecodeLimits;

    const MODEL: &str = r#"model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]"#;

    /// Every format's publication decodes, by the channel's own decoder, to the sample.
    #[test]
    fn each_publication_decodes_to_its_sample() {
        let sample = Sample {
            k: Some(7),
            t: Some(1_700_000_000.25),
            u: vec![12.0],
            y: vec![-0.5, 101.25],
            p: vec![],
        };
        for (payload, keeps_k, keeps_t) in [
            ("", true, true),
            ("payload = \"cdr\"", false, false),
            (
                "payload = \"cdr\"\ncdr = { message = \"glrmon_msgs/msg/Sample\" }",
                true,
                true,
            ),
            ("payload = \"sparkplug\"", false, true),
            (
                "payload = \"raw\"\nraw = { layout = [\"k\", \"t\", \"y1\", \"_\", \"u0\", \"y0\"] }",
                true,
                true,
            ),
        ] {
            let text = format!("[[channels]]\nname = \"m\"\n{payload}\n{MODEL}\n");
            let cfg = glrmon_spec::parse(&text).unwrap();
            let channel = &cfg.channels[0];
            let mut out = Vec::new();
            publications(channel, &sample, &mut out).unwrap();
            assert_eq!(out.len(), 1);
            let mut decoder = crate::decoder(channel);
            let mut samples = Vec::new();
            decoder
                .decode("m", &out[0].bytes, &DecodeLimits::default(), &mut samples)
                .unwrap();
            let want = Sample {
                k: sample.k.filter(|_| keeps_k),
                t: sample.t.filter(|_| keeps_t),
                ..sample.clone()
            };
            assert_eq!(samples, [want], "{payload}");
        }
    }

    #[test]
    fn a_tag_channel_publishes_each_signal_on_its_key() {
        let text = format!(
            "[[channels]]\nname = \"m\"\n{MODEL}\n[channels.tags]\nperiod = 0.5\n[channels.tags.keys]\n\
             u0 = \"plant/u\"\ny0 = {{ key = \"plant/y\", field = \"a.b\", time_field = \"a.ts\" }}\ny1 = \"plant/z\"\n"
        );
        let cfg = glrmon_spec::parse(&text).unwrap();
        let sample = Sample {
            k: Some(3),
            t: Some(1.5),
            u: vec![12.0],
            y: vec![-0.5, 7.0],
            p: vec![],
        };
        let mut out = Vec::new();
        publications(&cfg.channels[0], &sample, &mut out).unwrap();
        let texts: Vec<(usize, String)> = out
            .iter()
            .map(|p| (p.key, String::from_utf8(p.bytes.clone()).unwrap()))
            .collect();
        assert_eq!(
            texts,
            [
                (0, "12.0".to_owned()),
                (1, r#"{"a":{"b":-0.5,"ts":1.5}}"#.to_owned()),
                (2, "7.0".to_owned()),
            ]
        );
        let wrong = Sample {
            y: vec![1.0],
            ..sample
        };
        assert!(matches!(
            publications(&cfg.channels[0], &wrong, &mut out),
            Err(PublishError::Dimensions {
                expected: 3,
                got: 2,
                ..
            })
        ));
    }
}
