//! ROS 2 messages in CDR, as rmw_zenoh publishes them: a 4-byte encapsulation header
//! (`00 01` little-endian or `00 00` big-endian CDR, two option bytes), then the
//! message. The codec (alignment, byte order, sequence lengths, strings) is
//! `cdr-encoding`'s; this module says which field of which message goes where, through
//! serde seeds that write into the sample's reused vectors, so that a message is
//! decoded without allocating.

use std::fmt;

use byteorder::{BigEndian, ByteOrder, LittleEndian};
use cdr_encoding::CdrDeserializer;
use glrmon_spec::{CdrMessage, PayloadFormat};
use glrmon_wire::{DecodeError, DecodeErrorKind, DecodeLimits, Sample, SizeLimit};
use serde::de::{self, DeserializeSeed, SeqAccess, Visitor};

use super::{Arrival, Declared, PayloadDecoder, single, within_limit};

/// The decoder of a `cdr` channel: `message` with `dims` (inputs, outputs, signals)
/// values.
#[derive(Debug, Clone)]
pub struct CdrDecoder {
    message: CdrMessage,
    dims: [usize; 3],
}

impl CdrDecoder {
    /// A decoder of `message` for a channel of `inputs`, `outputs` and `signals` values.
    #[must_use]
    pub fn new(message: CdrMessage, inputs: usize, outputs: usize, signals: usize) -> Self {
        Self {
            message,
            dims: [inputs, outputs, signals],
        }
    }
}

impl PayloadDecoder for CdrDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Cdr(self.message).name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        self.decode_message(self.message, channel, payload, limits, out)
    }

    /// The type the Zenoh encoding names (`application/cdr;<type>`) is decoded, else the
    /// configured one; a CDR type glrmon does not read is refused.
    fn decode_tag(
        &mut self,
        channel: &str,
        _tag: usize,
        arrival: Arrival,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        let message = match arrival.declared {
            Declared::Nothing => self.message,
            Declared::Cdr(message) => message,
            Declared::OtherCdr => {
                out.clear();
                return Err(DecodeError::new(
                    channel,
                    Some("encoding".to_owned()),
                    DecodeErrorKind::WrongType {
                        expected: format!(
                            "a CDR message type glrmon reads ({}), as the Zenoh encoding \
                             application/cdr;<type> names it",
                            CdrMessage::NAMES.join(", ")
                        ),
                    },
                ));
            }
        };
        self.decode_message(message, channel, payload, limits, out)
    }
}

impl CdrDecoder {
    /// Decodes `payload` as a `message`.
    fn decode_message(
        &self,
        message: CdrMessage,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        let fail = |out: &mut Vec<Sample>, field: Option<&str>, kind| {
            out.clear();
            Err(DecodeError::new(channel, field.map(str::to_owned), kind))
        };
        if let Err(e) = within_limit(channel, None, payload, limits) {
            out.clear();
            return Err(e);
        }
        let (little, body) = match payload {
            [0, 1, _, _, body @ ..] => (true, body),
            [0, 0, _, _, body @ ..] => (false, body),
            _ => {
                return fail(
                    out,
                    Some("encapsulation"),
                    DecodeErrorKind::WrongType {
                        expected: "the CDR header 00 01 (little-endian) or 00 00 \
                                   (big-endian): plain CDR"
                            .into(),
                    },
                );
            }
        };
        let sample = single(out);
        let mut state = State {
            error: None,
            dims: self.dims,
            limit: limits.max_vector_len,
        };
        let result = if little {
            read::<LittleEndian>(message, body, &mut state, sample)
        } else {
            read::<BigEndian>(message, body, &mut state, sample)
        };
        match result {
            Ok(()) => Ok(()),
            Err(e) => {
                let (field, kind) = state.error.take().unwrap_or_else(|| {
                    (
                        None,
                        DecodeErrorKind::WrongType {
                            expected: format!("a {} message: {e}", message.name()),
                        },
                    )
                });
                fail(out, field, kind)
            }
        }
    }
}

/// What went wrong, where (a field of the message), kept aside while serde unwinds.
struct State {
    error: Option<(Option<&'static str>, DecodeErrorKind)>,
    dims: [usize; 3],
    limit: usize,
}

impl State {
    /// Records the first error and gives serde one to stop with.
    fn fail<E: de::Error>(&mut self, field: &'static str, kind: DecodeErrorKind) -> E {
        let message = kind.to_string();
        self.error.get_or_insert((Some(field), kind));
        E::custom(message)
    }
}

fn read<BO: ByteOrder>(
    message: CdrMessage,
    body: &[u8],
    state: &mut State,
    sample: &mut Sample,
) -> Result<(), cdr_encoding::Error> {
    let mut de = CdrDeserializer::<BO>::new(body);
    match message {
        CdrMessage::Float64MultiArray => {
            MultiArraySeed { state, sample }.deserialize(&mut de)?;
        }
        CdrMessage::Sample => {
            SampleSeed { state, sample }.deserialize(&mut de)?;
        }
    }
    Ok(())
}

/// `std_msgs/msg/Float64MultiArray`: `MultiArrayLayout layout` (`MultiArrayDimension[]
/// dim`, `uint32 data_offset`), `float64[] data`.
struct MultiArraySeed<'a> {
    state: &'a mut State,
    sample: &'a mut Sample,
}

impl<'de> DeserializeSeed<'de> for MultiArraySeed<'_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_tuple(2, self)
    }
}

impl<'de> Visitor<'de> for MultiArraySeed<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a std_msgs/msg/Float64MultiArray")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let offset = seq
            .next_element_seed(LayoutSeed)?
            .ok_or_else(|| de::Error::missing_field("layout"))?;
        let data = DataSeed {
            state: self.state,
            sample: self.sample,
            offset: offset as usize,
        };
        seq.next_element_seed(data)?
            .ok_or_else(|| de::Error::missing_field("data"))
    }
}

/// `MultiArrayLayout`: its dimensions are read past; `data_offset` is returned.
struct LayoutSeed;

impl<'de> DeserializeSeed<'de> for LayoutSeed {
    type Value = u32;

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<u32, D::Error> {
        d.deserialize_tuple(2, self)
    }
}

impl<'de> Visitor<'de> for LayoutSeed {
    type Value = u32;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a std_msgs/msg/MultiArrayLayout")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<u32, A::Error> {
        seq.next_element_seed(Dimensions)?
            .ok_or_else(|| de::Error::missing_field("dim"))?;
        seq.next_element::<u32>()?
            .ok_or_else(|| de::Error::missing_field("data_offset"))
    }
}

/// `MultiArrayDimension[]`: each `string label`, `uint32 size`, `uint32 stride` read
/// and dropped (the label borrowed, never copied).
struct Dimensions;

impl<'de> DeserializeSeed<'de> for Dimensions {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Dimensions {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of std_msgs/msg/MultiArrayDimension")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        while seq.next_element::<(Label, u32, u32)>()?.is_some() {}
        Ok(())
    }
}

/// A string read and dropped.
struct Label;

impl<'de> de::Deserialize<'de> for Label {
    fn deserialize<D: de::Deserializer<'de>>(d: D) -> Result<Label, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Label;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a string")
            }
            fn visit_str<E: de::Error>(self, _: &str) -> Result<Label, E> {
                Ok(Label)
            }
        }
        d.deserialize_str(V)
    }
}

/// `float64[] data`: the first `offset` values skipped, then the inputs, the outputs
/// and the scheduling signals, exactly.
struct DataSeed<'a> {
    state: &'a mut State,
    sample: &'a mut Sample,
    offset: usize,
}

impl<'de> DeserializeSeed<'de> for DataSeed<'_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for DataSeed<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of float64")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let [l, m, q] = self.state.dims;
        let want = self.offset.saturating_add(l + m + q);
        let mut got = 0usize;
        while let Some(v) = seq.next_element::<f64>()? {
            if got >= self.offset && got < want {
                if !v.is_finite() {
                    return Err(self.state.fail("data", DecodeErrorKind::NonFinite));
                }
                let j = got - self.offset;
                if j < l {
                    self.sample.u.push(v);
                } else if j < l + m {
                    self.sample.y.push(v);
                } else {
                    self.sample.p.push(v);
                }
            }
            got += 1;
        }
        if got != want {
            let (expected, got) = (l + m + q, got.saturating_sub(self.offset));
            return Err(self
                .state
                .fail("data", DecodeErrorKind::WrongDimension { expected, got }));
        }
        Ok(())
    }
}

/// `glrmon_msgs/msg/Sample`: `int64 k` (−1: none), `float64 t` (NaN: none),
/// `float64[] u`, `float64[] y`, `float64[] p`.
struct SampleSeed<'a> {
    state: &'a mut State,
    sample: &'a mut Sample,
}

impl<'de> DeserializeSeed<'de> for SampleSeed<'_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_tuple(5, self)
    }
}

impl<'de> Visitor<'de> for SampleSeed<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a glrmon_msgs/msg/Sample")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let missing = |name| de::Error::missing_field(name);
        let k = seq.next_element::<i64>()?.ok_or_else(|| missing("k"))?;
        self.sample.k = match k {
            -1 => None,
            k => Some(u64::try_from(k).map_err(|_| {
                self.state.fail(
                    "k",
                    DecodeErrorKind::WrongType {
                        expected: "a non-negative index, or -1 for none".into(),
                    },
                )
            })?),
        };
        let t = seq.next_element::<f64>()?.ok_or_else(|| missing("t"))?;
        self.sample.t = match t {
            t if t.is_nan() => None,
            t if t.is_finite() => Some(t),
            _ => return Err(self.state.fail("t", DecodeErrorKind::NonFinite)),
        };
        let Sample { u, y, p, .. } = self.sample;
        for (field, values) in [("u", u), ("y", y), ("p", p)] {
            let seed = Values {
                state: &mut *self.state,
                field,
                values,
            };
            seq.next_element_seed(seed)?.ok_or_else(|| missing(field))?;
        }
        Ok(())
    }
}

/// A `float64[]` into a vector, each value finite, at most `max_vector_len` of them.
struct Values<'a> {
    state: &'a mut State,
    field: &'static str,
    values: &'a mut Vec<f64>,
}

impl<'de> DeserializeSeed<'de> for Values<'_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Values<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence of float64")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut got = 0usize;
        while let Some(v) = seq.next_element::<f64>()? {
            got += 1;
            if got > self.state.limit {
                continue;
            }
            if !v.is_finite() {
                return Err(self.state.fail(self.field, DecodeErrorKind::NonFinite));
            }
            self.values.push(v);
        }
        if got > self.state.limit {
            let limit = self.state.limit;
            return Err(self.state.fail(
                self.field,
                DecodeErrorKind::TooLarge {
                    what: SizeLimit::VectorLen,
                    limit,
                    got,
                },
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::ErrorCode;
    use serde::Serialize;

    #[derive(Serialize)]
    struct Dimension {
        label: String,
        size: u32,
        stride: u32,
    }

    #[derive(Serialize)]
    struct MultiArray {
        dim: Vec<Dimension>,
        data_offset: u32,
        data: Vec<f64>,
    }

    #[derive(Serialize)]
    struct SampleMsg {
        k: i64,
        t: f64,
        u: Vec<f64>,
        y: Vec<f64>,
        p: Vec<f64>,
    }

    /// The message in CDR with its encapsulation header, little- or big-endian.
    fn cdr<T: Serialize>(value: &T, little: bool) -> Vec<u8> {
        let (header, body) = if little {
            ([0, 1, 0, 0], cdr_encoding::to_vec::<T, LittleEndian>(value))
        } else {
            ([0, 0, 0, 0], cdr_encoding::to_vec::<T, BigEndian>(value))
        };
        [&header[..], &body.unwrap()].concat()
    }

    fn array(data_offset: u32, data: &[f64]) -> MultiArray {
        MultiArray {
            dim: vec![Dimension {
                label: "signals".into(),
                size: data.len() as u32,
                stride: data.len() as u32,
            }],
            data_offset,
            data: data.to_vec(),
        }
    }

    fn decode(d: &mut CdrDecoder, payload: &[u8]) -> Result<Vec<Sample>, DecodeError> {
        let mut out = Vec::new();
        d.decode("dc_motor", payload, &DecodeLimits::default(), &mut out)
            .map(|()| out)
    }

    #[test]
    fn a_float64_multi_array_splits_into_inputs_outputs_and_signals() {
        let mut d = CdrDecoder::new(CdrMessage::Float64MultiArray, 1, 2, 1);
        for little in [true, false] {
            let s = decode(&mut d, &cdr(&array(0, &[12.0, 0.8, 120.5, 3.0]), little)).unwrap();
            assert_eq!(
                (s[0].k, s[0].t, &s[0].u[..], &s[0].y[..], &s[0].p[..]),
                (None, None, &[12.0][..], &[0.8, 120.5][..], &[3.0][..])
            );
            let s = decode(
                &mut d,
                &cdr(&array(2, &[9.0, 9.0, 1.0, 2.0, 3.0, 4.0]), little),
            )
            .unwrap();
            assert_eq!((&s[0].u[..], &s[0].p[..]), (&[1.0][..], &[4.0][..]));
        }
        let e = decode(&mut d, &cdr(&array(0, &[1.0, 2.0, 3.0]), true)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field data has 3 values, model expects 4"
        );
        let e = decode(&mut d, &cdr(&array(0, &[1.0, f64::NAN, 3.0, 4.0]), true)).unwrap_err();
        assert_eq!(
            (e.code(), e.field.as_deref()),
            (ErrorCode::NonFinite, Some("data"))
        );
    }

    #[test]
    fn a_glrmon_sample_message_carries_index_and_time() {
        let mut d = CdrDecoder::new(CdrMessage::Sample, 1, 2, 0);
        let msg = SampleMsg {
            k: 42,
            t: 0.42,
            u: vec![12.0],
            y: vec![0.8, 120.5],
            p: vec![],
        };
        let s = decode(&mut d, &cdr(&msg, true)).unwrap();
        assert_eq!(
            (s[0].k, s[0].t, &s[0].y[..]),
            (Some(42), Some(0.42), &[0.8, 120.5][..])
        );
        let none = SampleMsg {
            k: -1,
            t: f64::NAN,
            ..msg
        };
        let s = decode(&mut d, &cdr(&none, false)).unwrap();
        assert_eq!((s[0].k, s[0].t), (None, None));
        let bad = SampleMsg { k: -2, ..none };
        let e = decode(&mut d, &cdr(&bad, true)).unwrap_err();
        assert_eq!(
            (e.code(), e.field.as_deref()),
            (ErrorCode::WrongType, Some("k"))
        );
    }

    #[test]
    fn hostile_bytes_are_refused_never_a_panic() {
        let mut d = CdrDecoder::new(CdrMessage::Float64MultiArray, 1, 2, 1);
        let e = decode(&mut d, b"{\"y\":[1]}").unwrap_err();
        assert_eq!(e.field.as_deref(), Some("encapsulation"));
        let full = cdr(&array(0, &[12.0, 0.8, 120.5, 3.0]), true);
        for n in 0..full.len() {
            assert!(decode(&mut d, &full[..n]).is_err(), "prefix of {n} bytes");
        }
        // A sequence length of 2³² − 1 with nothing behind it.
        let mut huge = vec![0, 1, 0, 0];
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode(&mut d, &huge).is_err());
        let mut s = CdrDecoder::new(CdrMessage::Sample, 1, 1, 0);
        let long = SampleMsg {
            k: 1,
            t: 0.0,
            u: vec![0.0; 5000],
            y: vec![1.0],
            p: vec![],
        };
        let e = decode(&mut s, &cdr(&long, true)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field u has 5000 values, more than the limit of 4096"
        );
    }
}
