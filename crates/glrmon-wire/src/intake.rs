//! Intake events: what happened at a channel's intake besides a decoded sample.
//!
//! A recording holds every decoded sample (in the sample format) and, in order between
//! them, these events, so that a replay feeds each monitor exactly what the live run fed
//! it: the same samples, the same gaps where payloads were dropped, the same rejections.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::{EncodeError, ErrorCode};

/// One intake event of a channel (`{"type": "dropped", …}` or `{"type": "rejected", …}`).
///
/// # Examples
///
/// ```
/// use glrmon_wire::{IntakeEvent, encode_intake};
///
/// let mut out = Vec::new();
/// encode_intake("pump3", &IntakeEvent::Dropped { count: 3 }, &mut out)?;
/// assert_eq!(out, br#"{"type":"dropped","count":3}"#);
/// # Ok::<(), glrmon_wire::EncodeError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
#[schemars(title = "glrmon intake event")]
pub enum IntakeEvent {
    /// `count` payloads were dropped at intake (a full queue) just before the next
    /// payload: the monitor sees the next sample after a gap.
    Dropped {
        /// Payloads dropped.
        count: u64,
    },
    /// A payload was refused (too large, or not a valid sample or batch); the monitor's
    /// state is unchanged and an `error` record with this code and message was emitted.
    Rejected {
        /// The error code reported.
        code: ErrorCode,
        /// The error message reported.
        message: String,
        /// The payload as text when it is UTF-8 (JSON), else `0x` and its bytes in
        /// hexadecimal (the binary formats), when it was small enough to keep: what the
        /// publisher actually sent, for the post-mortem.
        payload: Option<String>,
    },
    /// The instance took the channel over from another one (an automatic shard): the
    /// monitor starts afresh at the next sample, whatever its index, and settles with
    /// alarms held off.
    Resumed {
        /// The instance that took the channel over.
        instance: String,
        /// Its assignment generation then.
        generation: u64,
    },
}

/// Appends the JSON of an intake event to `out`.
///
/// # Errors
/// [`EncodeError`] if serialisation fails (it cannot for these types; the signature
/// matches the other encoders).
pub fn encode_intake(
    channel: &str,
    event: &IntakeEvent,
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    crate::sample::write_json(channel, event, out)
}

/// Parses an intake event.
///
/// # Errors
/// serde_json's error when the bytes are not an intake event.
pub fn decode_intake(payload: &[u8]) -> Result<IntakeEvent, serde_json::Error> {
    serde_json::from_slice(payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intake_events_round_trip_and_reject_unknown_fields() {
        let events = [
            IntakeEvent::Dropped { count: 7 },
            IntakeEvent::Rejected {
                code: ErrorCode::InvalidJson,
                message: "channel \"a\": payload is not valid JSON".into(),
                payload: Some("{\"y\":[1,".into()),
            },
            IntakeEvent::Rejected {
                code: ErrorCode::TooLarge,
                message: "too large".into(),
                payload: None,
            },
        ];
        for e in &events {
            let mut out = Vec::new();
            encode_intake("a", e, &mut out).unwrap();
            assert_eq!(&decode_intake(&out).unwrap(), e);
        }
        assert!(decode_intake(br#"{"type":"dropped","count":1,"extra":2}"#).is_err());
        assert!(decode_intake(br#"{"type":"gone"}"#).is_err());
    }
}
