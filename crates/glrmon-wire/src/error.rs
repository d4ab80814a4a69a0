//! Errors of the wire crate and the bounded catalogue of error codes.
//!
//! Three error types, one per direction, because their context differs: [`DecodeError`]
//! (bytes from outside → wire types; carries the offending field), [`EncodeError`] (wire
//! types → bytes; only a non-finite float can fail) and [`ChannelNameError`] (a config
//! value that would break Zenoh key expressions). All three share the one code catalogue,
//! [`ErrorCode`], that labels rejection counters and `error` records.

use std::fmt;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::text::Escaped;

/// The bounded set of snake_case error codes used as the `error_type` counter label and
/// as the `code` of an `error` record.
///
/// The set is closed on purpose: metrics backends pay per label value, so a code never
/// carries data. Decoding in this crate raises the first eight; the rest belong to the
/// same catalogue but are raised by the monitor (order, duplicates, gaps, numerics) and
/// the runtime (routing).
///
/// Serialized as its [`as_str`](Self::as_str) string.
///
/// # Examples
///
/// ```
/// use glrmon_wire::ErrorCode;
///
/// assert_eq!(ErrorCode::NonFinite.as_str(), "non_finite");
/// assert_eq!(serde_json::to_string(&ErrorCode::Gap).unwrap(), "\"gap\"");
/// assert!(ErrorCode::ALL.iter().all(|c| !c.as_str().is_empty()));
/// ```
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum ErrorCode {
    /// The payload is not JSON: a syntax error, truncated input or trailing characters.
    InvalidJson,
    /// A value has the wrong JSON type (a string where a number belongs, a negative or
    /// fractional `k`, an unknown record `type`, …).
    WrongType,
    /// A required field is absent.
    MissingField,
    /// A sample object has a field that is not part of the format.
    UnknownField,
    /// A vector has a different length from what the channel's model expects.
    WrongDimension,
    /// A number is NaN, infinite, or too large for an `f64` (e.g. `1e999`).
    NonFinite,
    /// The payload, a batch or a vector exceeds a configured [`DecodeLimits`](crate::DecodeLimits) bound.
    TooLarge,
    /// A sample's index `k` is lower than one already processed (raised by the monitor).
    OutOfOrder,
    /// The same sample index arrived twice (monitor), or the same field appears twice in
    /// one sample object (decoder); the `stage` label tells the two apart.
    Duplicate,
    /// Samples are missing between two indices (raised by the monitor).
    Gap,
    /// A payload arrived on a key that maps to no configured channel (raised by the runtime).
    UnknownChannel,
    /// A numerical failure inside the monitor, such as a covariance that lost positive
    /// definiteness.
    Numerical,
    /// A sample's index is further behind the expected one than the channel's
    /// `max_reorder`: the publisher started numbering again (a restart), and the monitor
    /// restarts its filter at that sample instead of refusing every later one (raised by
    /// the monitor).
    SequenceReset,
}

impl ErrorCode {
    /// Every code, in declaration order: for pre-registering counters and for docs.
    pub const ALL: [ErrorCode; 13] = [
        ErrorCode::InvalidJson,
        ErrorCode::WrongType,
        ErrorCode::MissingField,
        ErrorCode::UnknownField,
        ErrorCode::WrongDimension,
        ErrorCode::NonFinite,
        ErrorCode::TooLarge,
        ErrorCode::OutOfOrder,
        ErrorCode::Duplicate,
        ErrorCode::Gap,
        ErrorCode::UnknownChannel,
        ErrorCode::Numerical,
        ErrorCode::SequenceReset,
    ];

    /// The snake_case label, identical to the serialized form.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            ErrorCode::InvalidJson => "invalid_json",
            ErrorCode::WrongType => "wrong_type",
            ErrorCode::MissingField => "missing_field",
            ErrorCode::UnknownField => "unknown_field",
            ErrorCode::WrongDimension => "wrong_dimension",
            ErrorCode::NonFinite => "non_finite",
            ErrorCode::TooLarge => "too_large",
            ErrorCode::OutOfOrder => "out_of_order",
            ErrorCode::Duplicate => "duplicate",
            ErrorCode::Gap => "gap",
            ErrorCode::UnknownChannel => "unknown_channel",
            ErrorCode::Numerical => "numerical",
            ErrorCode::SequenceReset => "sequence_reset",
        }
    }

    /// Whether the payload or sample the record is about was refused. A `gap` (samples
    /// missing before this one), a `sequence_reset` (the filter restarts at this sample)
    /// and a `numerical` restart report on the stream while the sample itself is
    /// processed.
    #[must_use]
    pub fn rejects_input(self) -> bool {
        !matches!(
            self,
            ErrorCode::Gap | ErrorCode::SequenceReset | ErrorCode::Numerical
        )
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where in the data flow a rejection happened: the `stage` counter label and the
/// `stage` of an `error` record.
///
/// Serialized as `"receiving"`, `"processing"` or `"sending"`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Decoding a payload from a source (Zenoh, CSV, MCAP).
    Receiving,
    /// Checking and processing a decoded sample in the monitor.
    Processing,
    /// Encoding or publishing a result record.
    Sending,
}

impl Stage {
    /// The snake_case label, identical to the serialized form.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Stage::Receiving => "receiving",
            Stage::Processing => "processing",
            Stage::Sending => "sending",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Which [`DecodeLimits`](crate::DecodeLimits) bound a payload exceeded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SizeLimit {
    /// `max_payload_bytes`: the payload's length in bytes.
    PayloadBytes,
    /// `max_batch`: the number of sample objects in a batch array.
    BatchLen,
    /// `max_vector_len`: the number of values in one `u`, `y` or `p` array.
    VectorLen,
}

impl SizeLimit {
    /// The unit counted, as used in messages ("bytes", "samples", "values").
    #[must_use]
    pub const fn unit(self) -> &'static str {
        match self {
            SizeLimit::PayloadBytes => "bytes",
            SizeLimit::BatchLen => "samples",
            SizeLimit::VectorLen => "values",
        }
    }
}

/// Why a payload or sample was rejected. The *where* is in [`DecodeError`].
///
/// Each message is a predicate that reads after its subject, e.g. "field y" + "has 3
/// values, model expects 4".
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeErrorKind {
    /// The bytes are not JSON: a syntax error, truncated input, invalid UTF-8, trailing
    /// characters after the value, or nesting deeper than serde_json's limit of 128.
    /// Holds serde_json's reason, which ends with the line and column; shown escaped,
    /// since it may quote the payload.
    #[error("is not valid JSON: {}", Escaped(.0))]
    InvalidJson(String),
    /// A value has the wrong JSON type: a string instead of a number, a negative,
    /// fractional or float-literal `k`, `null` in `y`, an unknown record `type`, …
    #[error("has the wrong type: expected {}", Escaped(expected))]
    WrongType {
        /// What the format expects at this place, in words ("a non-negative integer");
        /// shown escaped, since serde's words may quote the payload.
        expected: String,
    },
    /// A required field is absent (`y` in a sample; any non-optional record field).
    #[error("is missing")]
    MissingField,
    /// A sample object has a field outside `k`, `t`, `u`, `y`, `p`. Unknown fields are
    /// errors so that a misspelt `"Y"` is not silently read as "no outputs".
    #[error("is not a field of a sample (k, t, u, y, p)")]
    UnknownField,
    /// The same field appears twice in one object. JSON parsers disagree on which copy
    /// wins, so neither is trusted. Code `duplicate`.
    #[error("appears more than once in one object")]
    DuplicateField,
    /// A vector's length differs from the channel model's dimension.
    #[error("has {got} values, model expects {expected}")]
    WrongDimension {
        /// The length the model expects.
        expected: usize,
        /// The length received.
        got: usize,
    },
    /// A number is not finite: NaN or ±∞ in an in-memory sample, or a JSON number beyond
    /// the `f64` range such as `1e999`, which serde_json reports as "number out of range".
    /// (JSON itself has no NaN or Infinity literals; those are `InvalidJson`.)
    #[error("is not a finite number")]
    NonFinite,
    /// A tag's value is timed at or before one it already gave (a channel assembled
    /// from tags): it is not used. Code `out_of_order`.
    #[error("is timed at {} s, not after its previous value at {} s", seconds(*t_ns), seconds(*previous_ns))]
    NotAfter {
        /// The value's time, in nanoseconds (of the tag's clock).
        t_ns: i64,
        /// The time of the tag's latest value, in nanoseconds.
        previous_ns: i64,
    },
    /// A tag sent nothing for longer than it may be held (a channel assembled from
    /// tags): samples are gaps until it sends again. Reported once, when it goes
    /// stale, on the stream; no payload is refused. Code `gap`.
    #[error(
        "(key {}) sent no value for more than {hold} {unit}: samples are gaps until it sends again",
        Escaped(key)
    )]
    Stale {
        /// The tag's key expression.
        key: String,
        /// How long a value is held.
        hold: u32,
        /// `periods` or `triggers`.
        unit: &'static str,
    },
    /// The payload, the batch or a vector is longer than its configured limit.
    #[error("has {got} {}, more than the limit of {limit}", what.unit())]
    TooLarge {
        /// Which limit.
        what: SizeLimit,
        /// The configured limit.
        limit: usize,
        /// The size received (the whole array is counted, so this is exact).
        got: usize,
    },
}

impl DecodeErrorKind {
    /// The catalogue code of this kind.
    #[must_use]
    pub const fn code(&self) -> ErrorCode {
        match self {
            DecodeErrorKind::InvalidJson(_) => ErrorCode::InvalidJson,
            DecodeErrorKind::WrongType { .. } => ErrorCode::WrongType,
            DecodeErrorKind::MissingField => ErrorCode::MissingField,
            DecodeErrorKind::UnknownField => ErrorCode::UnknownField,
            DecodeErrorKind::DuplicateField => ErrorCode::Duplicate,
            DecodeErrorKind::WrongDimension { .. } => ErrorCode::WrongDimension,
            DecodeErrorKind::NonFinite => ErrorCode::NonFinite,
            DecodeErrorKind::TooLarge { .. } => ErrorCode::TooLarge,
            DecodeErrorKind::NotAfter { .. } => ErrorCode::OutOfOrder,
            DecodeErrorKind::Stale { .. } => ErrorCode::Gap,
        }
    }
}

/// Nanoseconds as seconds, for messages.
#[allow(clippy::cast_precision_loss)]
fn seconds(ns: i64) -> f64 {
    ns as f64 / 1e9
}

/// A rejected payload, sample or record: which channel, which field, and why.
///
/// `field` is a path into the payload: `y[2]` (third value of `y`), `k`, `[3].u` (field
/// `u` of batch element 3), `[3]` (batch element 3 itself). It is `None` when the whole
/// payload is at fault (not JSON, too large, not an object or array).
///
/// Displayed as `channel "pump3": field y has 3 values, model expects 4`; the channel
/// prefix is left out when the channel is unknown (empty), as for a record that failed
/// before its `channel` could be read. The field is a name from the payload and the
/// channel may be a record's: both are shown escaped ([`crate::text`]; the channel as
/// a Rust string literal), so the message is one line that is safe to print or log.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{decode_samples, DecodeLimits, ErrorCode};
///
/// let mut out = Vec::new();
/// let err = decode_samples("pump3", br#"{"y": [1.0, "2"]}"#, &DecodeLimits::default(), &mut out)
///     .unwrap_err();
/// assert_eq!(err.code(), ErrorCode::WrongType);
/// assert_eq!(err.field.as_deref(), Some("y[1]"));
/// assert_eq!(err.to_string(), r#"channel "pump3": field y[1] has the wrong type: expected a number"#);
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError {
    /// The channel the payload was meant for; empty if unknown.
    pub channel: String,
    /// Path of the offending field inside the payload, if the fault is local to one.
    pub field: Option<String>,
    /// Why it was rejected.
    pub kind: DecodeErrorKind,
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.channel.is_empty() {
            write!(f, "channel {:?}: ", self.channel)?;
        }
        match &self.field {
            Some(field) => write!(f, "field {} {}", Escaped(field), self.kind),
            None => write!(f, "payload {}", self.kind),
        }
    }
}

// The kind is part of the message rather than a `source`, so that `{err}` alone says
// what, where and why; a source would repeat it under `{err:#}`.
impl std::error::Error for DecodeError {}

impl DecodeError {
    /// An error for `channel` at `field`.
    #[must_use]
    pub fn new(channel: &str, field: Option<String>, kind: DecodeErrorKind) -> Self {
        DecodeError {
            channel: channel.to_owned(),
            field,
            kind,
        }
    }

    /// The catalogue code, for the `error_type` counter label and `error` records.
    #[must_use]
    pub const fn code(&self) -> ErrorCode {
        self.kind.code()
    }
}

/// Why a value could not be encoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeErrorKind {
    /// A float is NaN or infinite. JSON has no literal for it, and serde_json would write
    /// `null` silently, which on this wire means something else (e.g. `glr: null` is "no
    /// admissible onset"). Callers map "no value" to `None` explicitly instead.
    #[error("is {value}, and JSON cannot carry a non-finite number")]
    NonFinite {
        /// The offending value (NaN, inf or -inf).
        value: f64,
    },
    /// serde_json refused the value. Cannot happen for this crate's types (a `Vec<u8>`
    /// writer does not fail and every map key is a string); kept so that no `unwrap` is
    /// needed.
    #[error("could not be serialized: {0}")]
    Serialize(String),
}

/// A value that cannot be written to the wire, with the channel and field at fault.
///
/// Displayed as `channel "pump3": field magnitude[1] is NaN, and JSON cannot carry a
/// non-finite number`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("channel {channel:?}: field {field} {kind}")]
pub struct EncodeError {
    /// The record's or sample's channel.
    pub channel: String,
    /// Path of the offending field: `glr`, `magnitude[1]`, `isolation[0].minmax`,
    /// `estimate.leak`, `[2].y[0]`.
    pub field: String,
    /// Why it failed.
    pub kind: EncodeErrorKind,
}

impl EncodeError {
    /// The catalogue code: `non_finite` for a non-finite float.
    #[must_use]
    pub const fn code(&self) -> ErrorCode {
        match self.kind {
            EncodeErrorKind::NonFinite { .. } => ErrorCode::NonFinite,
            EncodeErrorKind::Serialize(_) => ErrorCode::InvalidJson,
        }
    }
}

/// Why a string cannot be a channel name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ChannelNameErrorKind {
    /// The name is empty; a key expression chunk cannot be.
    #[error("is empty")]
    Empty,
    /// The name contains a character that breaks a Zenoh key expression: `/` (chunk
    /// separator), `*` and `$` (wildcards), `?` and `#` (selector syntax), whitespace or a
    /// control character.
    #[error("contains {ch:?} at byte {byte_offset}, which breaks Zenoh key expressions")]
    ForbiddenChar {
        /// The character.
        ch: char,
        /// Its byte offset in the name.
        byte_offset: usize,
    },
    /// The name starts with `@`. Zenoh treats such a chunk as verbatim: wildcards never
    /// match it, so `glrmon/*/alarm` would not see the channel's alarms.
    #[error("starts with '@', which Zenoh wildcards never match")]
    LeadingAt,
}

/// A channel name that cannot be one chunk of a Zenoh key expression.
///
/// Displayed as `channel name "a/b" contains '/' at byte 1, which breaks Zenoh key expressions`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("channel name {name:?} {kind}")]
pub struct ChannelNameError {
    /// The rejected name.
    pub name: String,
    /// Why.
    pub kind: ChannelNameErrorKind,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `sequence_reset`, a `gap` and a `numerical` restart do not refuse the sample
    /// (the daemon's log must not say "Rejected input" for them); every other code does.
    #[test]
    fn only_stream_events_keep_their_sample() {
        let kept: Vec<&str> = ErrorCode::ALL
            .iter()
            .filter(|c| !c.rejects_input())
            .map(|c| c.as_str())
            .collect();
        assert_eq!(kept, ["gap", "numerical", "sequence_reset"]);
    }

    #[test]
    fn every_code_serializes_as_its_label_and_back() {
        for code in ErrorCode::ALL {
            let json = serde_json::to_string(&code).unwrap();
            assert_eq!(json, format!("\"{}\"", code.as_str()));
            assert_eq!(serde_json::from_str::<ErrorCode>(&json).unwrap(), code);
            assert_eq!(code.to_string(), code.as_str());
        }
    }

    #[test]
    fn codes_are_distinct_snake_case() {
        let mut labels: Vec<&str> = ErrorCode::ALL.iter().map(|c| c.as_str()).collect();
        assert!(
            labels
                .iter()
                .all(|l| l.chars().all(|c| c.is_ascii_lowercase() || c == '_'))
        );
        labels.sort_unstable();
        labels.dedup();
        assert_eq!(labels.len(), ErrorCode::ALL.len());
    }

    #[test]
    fn stages_serialize_as_labels() {
        for stage in [Stage::Receiving, Stage::Processing, Stage::Sending] {
            let json = serde_json::to_string(&stage).unwrap();
            assert_eq!(json, format!("\"{stage}\""));
            assert_eq!(serde_json::from_str::<Stage>(&json).unwrap(), stage);
        }
    }

    #[test]
    fn decode_error_message_names_channel_and_field() {
        let err = DecodeError::new(
            "pump3",
            Some("y".into()),
            DecodeErrorKind::WrongDimension {
                expected: 4,
                got: 3,
            },
        );
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field y has 3 values, model expects 4"#
        );
        assert_eq!(err.code(), ErrorCode::WrongDimension);
    }

    /// A field name or a serde reason quoting the payload reaches the message only as
    /// visible escapes; the channel is quoted as a Rust literal, which escapes too.
    #[test]
    fn decode_error_messages_escape_text_from_the_payload() {
        let err = DecodeError::new(
            "p\u{202e}1",
            Some("y\u{1b}]0;pwned\u{7}\nWARN forged".into()),
            DecodeErrorKind::UnknownField,
        );
        assert_eq!(
            err.to_string(),
            r#"channel "p\u{202e}1": field y\x1b]0;pwned\x07\nWARN forged is not a field of a sample (k, t, u, y, p)"#
        );
        let kind = DecodeErrorKind::WrongType {
            expected: "a valid record (unknown variant `\u{1b}[2J`)".into(),
        };
        assert_eq!(
            kind.to_string(),
            r"has the wrong type: expected a valid record (unknown variant `\x1b[2J`)"
        );
        let kind = DecodeErrorKind::InvalidJson("\u{9b}2J at line 1".into());
        assert_eq!(kind.to_string(), r"is not valid JSON: \u{9b}2J at line 1");
    }

    #[test]
    fn decode_error_without_channel_or_field() {
        let err = DecodeError::new(
            "",
            None,
            DecodeErrorKind::TooLarge {
                what: SizeLimit::PayloadBytes,
                limit: 10,
                got: 11,
            },
        );
        assert_eq!(
            err.to_string(),
            "payload has 11 bytes, more than the limit of 10"
        );
    }

    #[test]
    fn encode_error_message_names_value() {
        let err = EncodeError {
            channel: "pump3".into(),
            field: "magnitude[1]".into(),
            kind: EncodeErrorKind::NonFinite { value: f64::NAN },
        };
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field magnitude[1] is NaN, and JSON cannot carry a non-finite number"#
        );
        assert_eq!(err.code(), ErrorCode::NonFinite);
    }
}
