//! The instance status: what a running instance answers on its status queryable
//! (`glrmon/@status/<instance>`, docs/WIRE.md) and what `glrmon status` reads back.
//!
//! One compact JSON object, keys in this order:
//!
//! ```json
//! {"instance":"a","uptime":3725.2,"shard":"0/2","connected":true,"reconnections":1,
//!  "overlaps":0,"samples_per_second":1500.0,
//!  "channels":[{"channel":"c1","samples":10,"alarms":2,"alarm_active":true,
//!               "dropped":3,"last_k":9,"errors":{"non_finite":4}}],
//!  "sessions":{"routers":0,"peers":0,"clients":2},
//!  "assignment":{"generation":4,"instances":["a","b"],"takeovers":3,"handovers":1}}
//! ```
//!
//! Decoding is strict, as for samples: every field must be present (`null` where the
//! value is absent), of its type, and no other field may appear, so that a reader never
//! shows a zero for a counter it failed to read. The writer and the reader ship in the
//! same binary; a new field is a change of this format. The one exception is
//! `sessions` and `assignment`, added last: a status without them (from an instance of an
//! earlier release, during a rolling upgrade) reads as `None`, shown as unknown, never
//! as zeros. `assignment` is `null` but for an automatic shard.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::ErrorCode;
use crate::sample::is_out_of_range;

/// The status of one instance: who it is, how long it has run, its connection to the
/// Zenoh network and the counters of every channel it monitors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceStatus {
    /// The instance's name (the last chunk of its status key).
    pub instance: String,
    /// Seconds since the instance started, to the millisecond.
    pub uptime: f64,
    /// The shard of the configured channels it monitors (`"i/N"`), `null` when it
    /// monitors all of them.
    #[serde(deserialize_with = "required")]
    pub shard: Option<String>,
    /// Whether at least one Zenoh session with another node (router, peer or client) is
    /// open.
    pub connected: bool,
    /// Times the session got a connection back after losing its last one.
    pub reconnections: u64,
    /// Other instances seen claiming a channel of this one since it started.
    pub overlaps: u64,
    /// Samples processed per second over all channels, recently (to 0.1).
    pub samples_per_second: f64,
    /// Every monitored channel, in configuration order.
    pub channels: Vec<ChannelStatus>,
    /// The Zenoh sessions open with other nodes, by kind; `None` when the writer did not
    /// say (an instance of an earlier release, whose status has no such field).
    #[serde(default)]
    pub sessions: Option<ZenohSessions>,
    /// The automatic shard's assignment as this instance sees it; `None` for a static
    /// shard or none (and from an instance of an earlier release, whose status has no
    /// such field).
    #[serde(default)]
    pub assignment: Option<Assignment>,
}

/// An automatic shard's view of the fleet: the live instances the channels are
/// assigned among, and how the assignment changed since the instance started.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Assignment {
    /// Increases by one each time this instance's view of the live instances changes
    /// (from 1, the first view); records and recordings name it.
    pub generation: u64,
    /// The live instances, this one included, sorted.
    pub instances: Vec<String>,
    /// Channels taken over from an instance that left (or at a view change).
    pub takeovers: u64,
    /// Channels handed over to an instance that joined, or at a clean shutdown.
    pub handovers: u64,
}

/// The Zenoh sessions an instance has open with other nodes, by the other node's kind
/// (its mode): a daemon in peer mode that listens sees the publishers, `glrmon watch`
/// and `glrmon status` connected to it in client mode as clients.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohSessions {
    /// Sessions with routers.
    pub routers: u64,
    /// Sessions with peers.
    pub peers: u64,
    /// Sessions with clients.
    pub clients: u64,
}

impl ZenohSessions {
    /// Sessions of every kind.
    #[must_use]
    pub const fn total(&self) -> u64 {
        self.routers + self.peers + self.clients
    }
}

/// The counters of one monitored channel.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelStatus {
    /// The channel's name.
    pub channel: String,
    /// Samples processed.
    pub samples: u64,
    /// Alarm episodes started.
    pub alarms: u64,
    /// Whether an alarm episode is going on.
    pub alarm_active: bool,
    /// Payloads dropped at intake because the worker's queue was full.
    pub dropped: u64,
    /// Index k of the last processed sample; `null` before the first.
    #[serde(deserialize_with = "required")]
    pub last_k: Option<u64>,
    /// Rejected input by error code (an [`ErrorCode`] label); codes never seen are
    /// absent. Strings rather than [`ErrorCode`], so that a code added later still reads.
    pub errors: BTreeMap<String, u64>,
}

impl ChannelStatus {
    /// Rejected inputs of every code.
    #[must_use]
    pub fn error_total(&self) -> u64 {
        self.errors.values().sum()
    }
}

/// An `Option` field that must be present, as `null` when `None`. (serde reads a missing
/// `Option` field as `None` unless the field has a deserializer of its own.)
fn required<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::deserialize(d)
}

/// Why an instance status could not be encoded or decoded.
///
/// Displayed as `instance status is not valid: missing field \`uptime\` at line 1
/// column 20`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StatusError {
    /// The bytes are not JSON (syntax error, truncated, invalid UTF-8, trailing
    /// characters). Holds serde_json's reason, which ends with the line and column.
    #[error("instance status is not valid JSON: {0}")]
    InvalidJson(String),
    /// JSON, but not an instance status: a missing, unknown or repeated field, a value
    /// of the wrong type, or a number beyond the `f64` range.
    #[error("instance status is not valid: {message}")]
    Invalid {
        /// The catalogue code of the fault (`missing_field`, `unknown_field`,
        /// `duplicate`, `non_finite` or `wrong_type`).
        code: ErrorCode,
        /// serde_json's description, naming the field, with the line and column.
        message: String,
    },
    /// A float to encode is NaN or infinite: JSON has no literal for it, and serde_json
    /// would write `null`, which a strict reader then refuses.
    #[error("instance status field {field} is {value}, and JSON cannot carry a non-finite number")]
    NonFinite {
        /// The field (`uptime` or `samples_per_second`).
        field: &'static str,
        /// The offending value.
        value: f64,
    },
}

impl StatusError {
    /// The catalogue code, as for the other wire errors.
    #[must_use]
    pub const fn code(&self) -> ErrorCode {
        match self {
            StatusError::InvalidJson(_) => ErrorCode::InvalidJson,
            StatusError::Invalid { code, .. } => *code,
            StatusError::NonFinite { .. } => ErrorCode::NonFinite,
        }
    }
}

/// The JSON of an instance status (compact, keys in declaration order).
///
/// # Errors
/// [`StatusError::NonFinite`] when `uptime` or `samples_per_second` is NaN or infinite.
pub fn encode(status: &InstanceStatus) -> Result<String, StatusError> {
    for (field, value) in [
        ("uptime", status.uptime),
        ("samples_per_second", status.samples_per_second),
    ] {
        if !value.is_finite() {
            return Err(StatusError::NonFinite { field, value });
        }
    }
    // Only strings, integers, booleans, finite floats and string-keyed maps: writing
    // them to a `String` cannot fail, but the error is mapped rather than unwrapped.
    serde_json::to_string(status).map_err(|e| StatusError::Invalid {
        code: ErrorCode::WrongType,
        message: e.to_string(),
    })
}

/// Reads an instance status, strictly (see the module docs).
///
/// # Errors
/// [`StatusError::InvalidJson`] when the bytes are not JSON, [`StatusError::Invalid`]
/// when they are not an instance status.
pub fn decode(payload: &[u8]) -> Result<InstanceStatus, StatusError> {
    serde_json::from_slice(payload).map_err(|e| {
        let message = e.to_string();
        match e.classify() {
            serde_json::error::Category::Data => {
                let code = if message.starts_with("missing field") {
                    ErrorCode::MissingField
                } else if message.starts_with("unknown field") {
                    ErrorCode::UnknownField
                } else if message.starts_with("duplicate field") {
                    ErrorCode::Duplicate
                } else {
                    ErrorCode::WrongType
                };
                StatusError::Invalid { code, message }
            }
            _ if is_out_of_range(&e) => StatusError::Invalid {
                code: ErrorCode::NonFinite,
                message,
            },
            _ => StatusError::InvalidJson(message),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> InstanceStatus {
        InstanceStatus {
            instance: "a".into(),
            uptime: 3725.2,
            shard: Some("0/2".into()),
            connected: true,
            reconnections: 1,
            overlaps: 0,
            samples_per_second: 1500.0,
            channels: vec![
                ChannelStatus {
                    channel: "c1".into(),
                    samples: 10,
                    alarms: 2,
                    alarm_active: true,
                    dropped: 3,
                    last_k: Some(9),
                    errors: BTreeMap::from([("non_finite".into(), 4), ("gap".into(), 1)]),
                },
                ChannelStatus {
                    channel: "c2".into(),
                    samples: 0,
                    alarms: 0,
                    alarm_active: false,
                    dropped: 0,
                    last_k: None,
                    errors: BTreeMap::new(),
                },
            ],
            sessions: Some(ZenohSessions {
                routers: 1,
                peers: 0,
                clients: 2,
            }),
            assignment: Some(Assignment {
                generation: 4,
                instances: vec!["a".into(), "b".into()],
                takeovers: 3,
                handovers: 1,
            }),
        }
    }

    #[test]
    fn round_trip() {
        let s = sample();
        let json = encode(&s).unwrap();
        assert_eq!(decode(json.as_bytes()).unwrap(), s);
        let empty = InstanceStatus {
            shard: None,
            assignment: None,
            channels: vec![],
            uptime: 0.0,
            samples_per_second: 0.0,
            ..s
        };
        assert_eq!(decode(encode(&empty).unwrap().as_bytes()).unwrap(), empty);
    }

    #[test]
    fn keys_in_the_order_consumers_match() {
        let json = encode(&sample()).unwrap();
        assert!(
            json.starts_with(
                r#"{"instance":"a","uptime":3725.2,"shard":"0/2","connected":true,"reconnections":1,"overlaps":0,"samples_per_second":1500.0,"channels":[{"channel":"c1","samples":10,"#
            ),
            "{json}"
        );
        assert!(json.contains(r#""last_k":null,"errors":{}}"#), "{json}");
        assert!(
            json.ends_with(
                r#"}],"sessions":{"routers":1,"peers":0,"clients":2},"assignment":{"generation":4,"instances":["a","b"],"takeovers":3,"handovers":1}}"#
            ),
            "{json}"
        );
    }

    #[test]
    fn names_with_quotes_backslashes_controls_and_unicode_are_escaped() {
        let mut s = sample();
        s.instance = "a\"b\\c\u{1}é✓".into();
        s.channels[0].channel = "x\"\\\n\u{7f}😀".into();
        let json = encode(&s).unwrap();
        assert!(
            json.starts_with(r#"{"instance":"a\"b\\c\u0001é✓","#),
            "{json}"
        );
        assert!(
            json.contains("\"channel\":\"x\\\"\\\\\\n\u{7f}😀\""),
            "{json}"
        );
        assert_eq!(decode(json.as_bytes()).unwrap(), s);
    }

    /// What the hand-written encoder of glrmon-zenoh wrote before this type: fixed
    /// decimals for the floats and `\u` escapes for control characters.
    #[test]
    fn reads_the_hand_written_format() {
        let old = r#"{"instance":"a\"b","uptime":3725.200,"shard":"0/2","connected":true,"reconnections":1,"overlaps":0,"samples_per_second":1500.0,"channels":[{"channel":"c1","samples":10,"alarms":2,"alarm_active":true,"dropped":3,"last_k":9,"errors":{"gap":1,"non_finite":4}},{"channel":"c\u0007","samples":0,"alarms":0,"alarm_active":false,"dropped":0,"last_k":null,"errors":{}}]}"#;
        let mut want = sample();
        want.sessions = None;
        want.assignment = None;
        want.instance = "a\"b".into();
        want.channels[1].channel = "c\u{7}".into();
        assert_eq!(decode(old.as_bytes()).unwrap(), want);
        assert_eq!(want.channels[0].error_total(), 5);
        let old = r#"{"instance":"b","uptime":5.000,"shard":null,"connected":false,"reconnections":0,"overlaps":2,"samples_per_second":0.0,"channels":[]}"#;
        let s = decode(old.as_bytes()).unwrap();
        assert_eq!(
            (s.uptime, s.shard, s.connected, s.overlaps),
            (5.0, None, false, 2)
        );
    }

    #[test]
    fn decoding_is_strict_and_says_why() {
        let json = encode(&sample()).unwrap();
        let cases = [
            (
                json.replacen(r#""uptime":3725.2,"#, "", 1),
                ErrorCode::MissingField,
                "uptime",
            ),
            (
                json.replacen(r#""shard":"0/2","#, "", 1),
                ErrorCode::MissingField,
                "shard",
            ),
            (
                json.replacen(r#""last_k":9,"#, "", 1),
                ErrorCode::MissingField,
                "last_k",
            ),
            (
                json.replacen(r#""overlaps":0"#, r#""overlaps":0,"extra":1"#, 1),
                ErrorCode::UnknownField,
                "extra",
            ),
            (
                json.replacen(r#""samples":10"#, r#""samples":"10""#, 1),
                ErrorCode::WrongType,
                "string",
            ),
            (
                json.replacen(r#""samples":10"#, r#""samples":-1"#, 1),
                ErrorCode::WrongType,
                "-1",
            ),
            (
                json.replacen(r#""alarm_active":true"#, r#""alarm_active":1"#, 1),
                ErrorCode::WrongType,
                "bool",
            ),
            (
                json.replacen(r#""clients":2"#, r#""clients":2,"others":1"#, 1),
                ErrorCode::UnknownField,
                "others",
            ),
            (
                json.replacen(r#","peers":0"#, "", 1),
                ErrorCode::MissingField,
                "peers",
            ),
            (
                json.replacen("3725.2", "1e999", 1),
                ErrorCode::NonFinite,
                "out of range",
            ),
        ];
        for (payload, code, says) in cases {
            let err = decode(payload.as_bytes()).unwrap_err();
            assert_eq!(err.code(), code, "{payload}: {err}");
            assert!(err.to_string().contains(says), "{payload}: {err}");
        }
        let trailing = format!("{json} x");
        for bad in ["", "{", "[]", "null", &trailing] {
            let err = decode(bad.as_bytes()).unwrap_err();
            assert!(
                matches!(err.code(), ErrorCode::InvalidJson | ErrorCode::WrongType),
                "{bad}: {err}"
            );
        }
    }

    #[test]
    fn non_finite_floats_are_refused_not_written_as_null() {
        let mut s = sample();
        s.samples_per_second = f64::NAN;
        let err = encode(&s).unwrap_err();
        assert_eq!(err.code(), ErrorCode::NonFinite);
        assert_eq!(
            err.to_string(),
            "instance status field samples_per_second is NaN, and JSON cannot carry a non-finite number"
        );
        s.samples_per_second = 0.0;
        s.uptime = f64::INFINITY;
        assert!(matches!(
            encode(&s),
            Err(StatusError::NonFinite {
                field: "uptime",
                ..
            })
        ));
    }
}
