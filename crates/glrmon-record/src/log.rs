//! Alarms and errors as `foxglove.Log` messages ([`TopicKind::Log`]): Foxglove's Log
//! panel lists a recording's alarms next to its plots.

use glrmon_wire::Record;

use crate::schema::{TopicKind, topic};

/// `foxglove.Log` level of an alarm.
pub const LOG_WARNING: u8 = 3;
/// `foxglove.Log` level of an error record.
pub const LOG_ERROR: u8 = 4;

/// The `foxglove.Log` message (JSON) of a result record, `None` for records that are
/// not logged (only alarms, at level [`LOG_WARNING`], and error records, at
/// [`LOG_ERROR`], are). `timestamp` is `log_time_ns` (the record's MCAP log time),
/// `name` the channel, `file` the record's own topic and `line` its sample index k.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{ErrorCode, ErrorRecord, Record, Stage};
///
/// let rec = Record::Error(ErrorRecord {
///     channel: "pump3".into(),
///     k: Some(7),
///     code: ErrorCode::MissingField,
///     message: "field y is missing".into(),
///     stage: Stage::Receiving,
/// });
/// let json = glrmon_record::log_message(&rec, 1_500_000_000).unwrap();
/// let v: serde_json::Value = serde_json::from_slice(&json).unwrap();
/// assert_eq!(v["level"], 4);
/// assert_eq!(v["timestamp"]["sec"], 1);
/// assert_eq!(v["timestamp"]["nsec"], 500_000_000);
/// assert_eq!(v["name"], "pump3");
/// ```
#[must_use]
pub fn log_message(record: &Record, log_time_ns: u64) -> Option<Vec<u8>> {
    let (level, kind, line, message) = match record {
        Record::Alarm(a) => {
            let isolated: Vec<&str> = a
                .isolation
                .iter()
                .filter(|i| i.isolated)
                .map(|i| i.fault.as_str())
                .collect();
            let faults = if isolated.is_empty() {
                "none isolated".to_owned()
            } else {
                isolated.join(", ")
            };
            (
                LOG_WARNING,
                TopicKind::Alarm,
                a.k,
                format!(
                    "alarm on channel \"{}\" at k={}: GLR {:.4} > threshold {:.4}, onset {}, fault: {faults}",
                    a.channel, a.k, a.glr, a.threshold, a.onset
                ),
            )
        }
        Record::Error(e) => (
            LOG_ERROR,
            TopicKind::Error,
            e.k.unwrap_or(0),
            format!("{}: {}", e.code.as_str(), e.message),
        ),
        _ => return None,
    };
    let value = serde_json::json!({
        "timestamp": {
            "sec": log_time_ns / 1_000_000_000,
            "nsec": log_time_ns % 1_000_000_000,
        },
        "level": level,
        "message": message,
        "name": record.channel(),
        "file": topic(record.channel(), kind),
        "line": line,
    });
    serde_json::to_vec(&value).ok()
}
