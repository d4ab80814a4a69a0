//! Payload decoders: a channel's raw payloads → samples, inside its pipeline.
//!
//! Each channel's [`ChannelPipeline`](crate::ChannelPipeline) owns the decoder its
//! configuration names (`[[channels]] payload`), built by [`decoder`]; the daemon's
//! workers hand it the payloads as received. A new format is a type implementing
//! [`PayloadDecoder`] in a module of its own here, one arm of [`decoder`] and one
//! variant of `glrmon_spec::PayloadFormat`. The binary formats decode without
//! allocating once a channel's first payload has sized the sample's vectors.

mod cdr;
mod raw;
mod sparkplug;
mod tags;

pub use cdr::CdrDecoder;
pub use raw::RawDecoder;
pub use sparkplug::SparkplugDecoder;
pub use tags::TagDecoder;

use glrmon_spec::{CdrMessage, Channel, PayloadFormat};
use glrmon_wire::{
    DecodeError, DecodeErrorKind, DecodeLimits, Sample, SignalNames, SizeLimit, decode_samples,
    decode_samples_named,
};

/// Turns one payload into the samples it carries.
pub trait PayloadDecoder: Send + std::fmt::Debug {
    /// The format's name, as the configuration writes it.
    fn format(&self) -> &'static str;

    /// Decodes `payload` for `channel` into `out` (cleared first; its samples'
    /// buffers are reused), within `limits`.
    ///
    /// # Errors
    /// [`DecodeError`] naming the channel, the field and the reason; `out` holds no
    /// sample of a payload that failed.
    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError>;

    /// Decodes the payload of the channel's tag number `tag` (its input key, in the
    /// order of `glrmon_spec::Channel::input_keys`), which arrived as `arrival` says.
    /// A decoder of whole samples on one key reads it as [`PayloadDecoder::decode`];
    /// a channel assembled from tags forms its samples here.
    ///
    /// # Errors
    /// As [`PayloadDecoder::decode`].
    fn decode_tag(
        &mut self,
        channel: &str,
        tag: usize,
        arrival: Arrival,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        let _ = (tag, arrival);
        self.decode(channel, payload, limits, out)
    }

    /// Something the last payload revealed about the stream without refusing it (a tag
    /// gone silent), reported as an `error` record after the payload's samples.
    fn take_notice(&mut self) -> Option<DecodeError> {
        None
    }
}

/// When a payload arrived: the transport's timestamp, if it has one, and glrmon's
/// receipt, in seconds since the Unix epoch; and the type the transport declared.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Arrival {
    /// The publication's timestamp (Zenoh's), if any.
    pub source_time: Option<f64>,
    /// When glrmon received it.
    pub received: f64,
    /// The message type its Zenoh encoding names.
    pub declared: Declared,
}

/// The message type a payload's transport declares (Zenoh's encoding and its schema,
/// e.g. `application/cdr;glrmon_msgs/msg/Sample`), where it names one a decoder reads:
/// a `cdr` channel then decodes that type, whatever its configured one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Declared {
    /// Nothing: no encoding, one without a schema, or not one of the below.
    #[default]
    Nothing,
    /// `application/cdr` with the schema of a ROS 2 type glrmon reads
    /// (`std_msgs/msg/Float64MultiArray` or `glrmon_msgs/msg/Sample`, also in the
    /// `pkg/Type` form).
    Cdr(CdrMessage),
    /// `application/cdr` with the schema of a type glrmon does not read.
    OtherCdr,
}

impl Declared {
    /// Every schema that `application/cdr;<schema>` may carry for a type glrmon reads
    /// (`pkg/msg/Type` and `pkg/Type`), with what it declares.
    #[must_use]
    pub fn cdr_schemas() -> Vec<(String, Declared)> {
        CdrMessage::ALL
            .into_iter()
            .flat_map(|m| {
                [m.name().to_owned(), m.name().replacen("/msg/", "/", 1)]
                    .map(|schema| (schema, Declared::Cdr(m)))
            })
            .collect()
    }
}

/// The JSON sample format of docs/WIRE.md: one object or an array of them.
#[derive(Debug, Clone, Copy, Default)]
pub struct JsonDecoder;

impl PayloadDecoder for JsonDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Json.name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        decode_samples(channel, payload, limits, out)
    }
}

/// The JSON sample format of a channel whose signals have names (`[channels.columns]`):
/// positional arrays as [`JsonDecoder`] reads them, or values by name, flat
/// (`{"t": 1.5, "FIC101": 2.1, "LI201": 62.3, …}`) or grouped (`{"u": {"FIC101": 2.1},
/// "y": {…}}`), put in the order of the names ([`decode_samples_named`]). The names are
/// indexed once, when the decoder is built, so that decoding allocates no more than the
/// positional path.
#[derive(Debug, Clone)]
pub(crate) struct NamedJsonDecoder {
    names: SignalNames,
}

impl NamedJsonDecoder {
    /// The decoder of a channel with these signal names.
    pub(crate) fn new(names: SignalNames) -> Self {
        Self { names }
    }
}

impl PayloadDecoder for NamedJsonDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Json.name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        decode_samples_named(channel, payload, limits, &self.names, out)
    }
}

/// The decoder of a configured channel: the one factory the runtime builds decoders
/// with. A JSON channel that names its signals (`columns.named`) also reads values by
/// name.
#[must_use]
pub fn decoder(channel: &Channel) -> Box<dyn PayloadDecoder> {
    let c = &channel.columns;
    let d = channel.dims;
    if let Some(tags) = &channel.tags {
        return Box::new(TagDecoder::new(
            tags.clone(),
            d.inputs,
            d.outputs,
            d.signals,
        ));
    }
    match &channel.payload {
        PayloadFormat::Json if c.named => {
            Box::new(NamedJsonDecoder::new(SignalNames::new(&c.u, &c.y, &c.p)))
        }
        PayloadFormat::Json => Box::new(JsonDecoder),
        PayloadFormat::Cdr(message) => {
            Box::new(CdrDecoder::new(*message, d.inputs, d.outputs, d.signals))
        }
        PayloadFormat::Sparkplug => Box::new(SparkplugDecoder::new(c)),
        PayloadFormat::Raw(layout) => Box::new(RawDecoder::new(layout.clone(), c)),
    }
}

/// The payload-size limit every decoder checks first: a `too_large` error for
/// `channel` (at `field`, if the payload is one field's) beyond `limits`.
pub(crate) fn within_limit(
    channel: &str,
    field: Option<&str>,
    payload: &[u8],
    limits: &DecodeLimits,
) -> Result<(), DecodeError> {
    if payload.len() <= limits.max_payload_bytes {
        return Ok(());
    }
    Err(DecodeError::new(
        channel,
        field.map(str::to_owned),
        DecodeErrorKind::TooLarge {
            what: SizeLimit::PayloadBytes,
            limit: limits.max_payload_bytes,
            got: payload.len(),
        },
    ))
}

/// `out` as one sample, its buffers kept and emptied.
pub(crate) fn single(out: &mut Vec<Sample>) -> &mut Sample {
    out.truncate(1);
    slot(out, 0)
}

/// The `i`-th sample of `out` (pushed if `out` is shorter, `i ≤ out.len()`), its
/// buffers kept and emptied.
pub(crate) fn slot(out: &mut Vec<Sample>, i: usize) -> &mut Sample {
    if out.len() == i {
        out.push(Sample::default());
    }
    let s = &mut out[i];
    s.k = None;
    s.t = None;
    s.u.clear();
    s.y.clear();
    s.p.clear();
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::ErrorCode;

    /// A channel of two inputs and two outputs, its columns named or numbered.
    fn channel(named: bool) -> Channel {
        let columns = if named {
            "\n[channels.columns]\nu = [\"FIC101\", \"FIC102\"]\ny = [\"LI201\", \"LI202\"]\n"
        } else {
            ""
        };
        let text = format!(
            r#"
[[channels]]
name = "tanks"
model = {{ F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0, 0.0], [0.0, 1.0]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }}
faults = [{{ name = "level_bias", kind = "sensor_bias", output = 0 }}]
{columns}"#
        );
        let mut cfg = glrmon_spec::parse(&text).unwrap();
        cfg.channels.remove(0)
    }

    fn decode(decoder: &mut dyn PayloadDecoder, payload: &str) -> Result<Vec<Sample>, DecodeError> {
        let mut out = Vec::new();
        decoder
            .decode(
                "tanks",
                payload.as_bytes(),
                &DecodeLimits::default(),
                &mut out,
            )
            .map(|()| out)
    }

    /// A channel that names its signals reads both named shapes and positional arrays;
    /// a numbered one reads positional arrays only, as before.
    #[test]
    fn a_named_channels_decoder_reads_values_by_name() {
        let mut named = decoder(&channel(true));
        assert_eq!(named.format(), "json");
        let want = Sample {
            k: None,
            t: Some(1.5),
            u: vec![2.1, 1.0],
            y: vec![62.3, 48.1],
            p: vec![],
        };
        for payload in [
            r#"{"t":1.5,"FIC101":2.1,"FIC102":1.0,"LI201":62.3,"LI202":48.1}"#,
            r#"{"t":1.5,"u":{"FIC102":1.0,"FIC101":2.1},"y":{"LI201":62.3,"LI202":48.1}}"#,
            r#"{"t":1.5,"u":[2.1,1.0],"y":[62.3,48.1]}"#,
        ] {
            assert_eq!(
                decode(named.as_mut(), payload).unwrap(),
                std::slice::from_ref(&want),
                "{payload}"
            );
        }
        let e = decode(
            named.as_mut(),
            r#"{"FIC101":2.1,"FIC102":1.0,"LI201":62.3}"#,
        )
        .unwrap_err();
        assert_eq!(
            (e.code(), e.field.as_deref()),
            (ErrorCode::MissingField, Some("LI202"))
        );
        assert_eq!(e.to_string(), r#"channel "tanks": field LI202 is missing"#);
        let e = decode(named.as_mut(), r#"{"FIC101":2.1,"FIC103":1.0}"#).unwrap_err();
        assert_eq!(
            (e.code(), e.field.as_deref()),
            (ErrorCode::UnknownField, Some("FIC103"))
        );

        let mut numbered = decoder(&channel(false));
        assert_eq!(
            decode(
                numbered.as_mut(),
                r#"{"t":1.5,"u":[2.1,1.0],"y":[62.3,48.1]}"#
            )
            .unwrap(),
            [want]
        );
        let e = decode(numbered.as_mut(), r#"{"u0":2.1,"y":[1,2]}"#).unwrap_err();
        assert_eq!(e.code(), ErrorCode::UnknownField);
    }
}
