//! Topics and JSON Schemas of a recording.
//!
//! Every message is JSON (`message_encoding = "json"`) with a `jsonschema` schema, so
//! Foxglove and the `mcap` CLI open a recording without plugins. Topics mirror the Zenoh
//! result keys: `glrmon/<channel>/<kind>`. Each MCAP channel carries the metadata
//! `channel` (the glrmon channel name) and `kind`, by which a reader maps it back.
//!
//! The schemas use only `type`, `properties`, `required`, `additionalProperties`,
//! `items`, `enum` and `description` (checked by the tests, which validate every
//! recorded message against its schema).

/// What a topic holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum TopicKind {
    /// Decoded input samples, in the order the monitor saw them.
    Inputs,
    /// Intake events between samples (drops, rejected payloads).
    Intake,
    /// `stat` records.
    Stat,
    /// `alarm` records.
    Alarm,
    /// `isolation` records (an alarm's refined isolation).
    Isolation,
    /// `alarm_end` records.
    AlarmEnd,
    /// `diagnosis` records.
    Diagnosis,
    /// `error` records.
    Error,
    /// `consistency` records.
    Consistency,
    /// Alarms and errors as `foxglove.Log` messages, for Foxglove's Log panel: one
    /// topic for every channel, [`LOG_TOPIC`] (the message's `name` is the channel).
    /// Output, never input: replay ignores it.
    Log,
}

impl TopicKind {
    /// Every kind, in topic order.
    pub const ALL: [TopicKind; 10] = [
        TopicKind::Inputs,
        TopicKind::Intake,
        TopicKind::Stat,
        TopicKind::Alarm,
        TopicKind::Isolation,
        TopicKind::AlarmEnd,
        TopicKind::Diagnosis,
        TopicKind::Error,
        TopicKind::Consistency,
        TopicKind::Log,
    ];

    /// The last part of the topic and the `kind` metadata value.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            TopicKind::Inputs => "inputs",
            TopicKind::Intake => "intake",
            TopicKind::Stat => "stat",
            TopicKind::Alarm => "alarm",
            TopicKind::Isolation => "isolation",
            TopicKind::AlarmEnd => "alarm_end",
            TopicKind::Diagnosis => "diagnosis",
            TopicKind::Error => "error",
            TopicKind::Consistency => "consistency",
            TopicKind::Log => "log",
        }
    }

    /// The kind named `s`.
    #[must_use]
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.as_str() == s)
    }

    /// The kind of a result record's topic.
    #[must_use]
    pub fn of_record(record: &glrmon_wire::Record) -> Option<Self> {
        use glrmon_wire::Record;
        Some(match record {
            Record::Stat(_) => TopicKind::Stat,
            Record::Alarm(_) => TopicKind::Alarm,
            Record::Isolation(_) => TopicKind::Isolation,
            Record::AlarmEnd(_) => TopicKind::AlarmEnd,
            Record::Diagnosis(_) => TopicKind::Diagnosis,
            Record::Error(_) => TopicKind::Error,
            Record::Consistency(_) => TopicKind::Consistency,
            _ => return None,
        })
    }

    /// The schema's name.
    #[must_use]
    pub const fn schema_name(self) -> &'static str {
        match self {
            TopicKind::Inputs => "glrmon.Sample",
            TopicKind::Intake => "glrmon.Intake",
            TopicKind::Stat => "glrmon.Stat",
            TopicKind::Alarm => "glrmon.Alarm",
            TopicKind::Isolation => "glrmon.Isolation",
            TopicKind::AlarmEnd => "glrmon.AlarmEnd",
            TopicKind::Diagnosis => "glrmon.Diagnosis",
            TopicKind::Error => "glrmon.Error",
            TopicKind::Consistency => "glrmon.Consistency",
            TopicKind::Log => "foxglove.Log",
        }
    }

    /// The JSON Schema of the messages.
    #[must_use]
    pub const fn schema(self) -> &'static str {
        match self {
            TopicKind::Inputs => SAMPLE,
            TopicKind::Intake => INTAKE,
            TopicKind::Stat => STAT,
            TopicKind::Alarm => ALARM,
            TopicKind::Isolation => ISOLATION,
            TopicKind::AlarmEnd => ALARM_END,
            TopicKind::Diagnosis => DIAGNOSIS,
            TopicKind::Error => ERROR,
            TopicKind::Consistency => CONSISTENCY,
            TopicKind::Log => LOG,
        }
    }
}

/// The topic of the `foxglove.Log` messages of every channel ([`TopicKind::Log`]).
pub const LOG_TOPIC: &str = "glrmon/log";

/// The topic of `kind` for `channel` (for [`TopicKind::Log`], [`LOG_TOPIC`] whatever
/// the channel).
#[must_use]
pub fn topic(channel: &str, kind: TopicKind) -> String {
    match kind {
        TopicKind::Log => LOG_TOPIC.to_owned(),
        _ => format!("glrmon/{channel}/{}", kind.as_str()),
    }
}

const SAMPLE: &str = r#"{
  "title": "glrmon sample",
  "description": "A decoded input sample as the monitor saw it (docs/WIRE.md).",
  "type": "object",
  "properties": {
    "k": {"type": "integer", "description": "sample index (absent: arrival order)"},
    "t": {"type": "number", "description": "time in seconds"},
    "u": {"type": "array", "items": {"type": "number"}, "description": "known inputs"},
    "y": {"type": "array", "items": {"type": "number"}, "description": "measured outputs"},
    "p": {"type": "array", "items": {"type": "number"}, "description": "scheduling signals"}
  },
  "required": ["y"],
  "additionalProperties": false
}"#;

const INTAKE: &str = r#"{
  "title": "glrmon intake event",
  "description": "Payloads dropped before the next sample, or a refused payload.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["dropped", "rejected"]},
    "count": {"type": "integer", "description": "payloads dropped"},
    "code": {"type": "string"},
    "message": {"type": "string"},
    "payload": {"type": ["string", "null"], "description": "the refused payload"}
  },
  "required": ["type"],
  "additionalProperties": false
}"#;

const STAT: &str = r#"{
  "title": "glrmon stat",
  "description": "Per-sample statistics: the windowed GLR l_k, onset r, magnitude, innovation.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["stat"]},
    "channel": {"type": "string"},
    "k": {"type": "integer"},
    "t": {"type": ["number", "null"]},
    "glr": {"type": ["number", "null"], "description": "l_k, Zhang & Basseville 2014 eq. (30)"},
    "onset": {"type": ["integer", "null"], "description": "onset estimate r"},
    "magnitude": {"type": "array", "items": {"type": "number"}, "description": "theta estimate"},
    "rank": {"type": "integer"},
    "innovation": {"type": "array", "items": {"type": "number"}, "description": "innovation epsilon_k"},
    "threshold": {"type": ["number", "null"]}
  },
  "required": ["type", "channel", "k", "magnitude", "rank", "innovation"],
  "additionalProperties": false
}"#;

const ALARM: &str = r#"{
  "title": "glrmon alarm",
  "description": "An alarm, published at the crossing: the first sample of the episode with l_k above the threshold, with the onset, magnitude and isolation computed there.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["alarm"]},
    "channel": {"type": "string"},
    "k": {"type": "integer", "description": "the crossing: first sample with l_k above the threshold"},
    "t": {"type": ["number", "null"]},
    "glr": {"type": "number"},
    "threshold": {"type": "number"},
    "onset": {"type": "integer"},
    "magnitude": {"type": "array", "items": {"type": "number"}},
    "isolation": {"type": "array", "items": {
      "type": "object",
      "properties": {
        "fault": {"type": "string"},
        "minmax": {"type": "number"},
        "sensitivity": {"type": "number"},
        "threshold": {"type": "number"},
        "isolated": {"type": "boolean"}
      },
      "required": ["fault", "minmax", "sensitivity", "threshold", "isolated"],
      "additionalProperties": false
    }},
    "faults": {"type": "array", "items": {"type": "string"}},
    "update_k": {"type": ["integer", "null"], "description": "sample of the isolation record that refines this alarm if the episode is still on then (k + isolation_delay); null: none scheduled"}
  },
  "required": ["type", "channel", "k", "glr", "threshold", "onset", "magnitude", "isolation", "faults"],
  "additionalProperties": false
}"#;

const ISOLATION: &str = r#"{
  "title": "glrmon isolation",
  "description": "An alarm's isolation refined isolation_delay samples after its crossing, while its episode is still on. Not a new alarm.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["isolation"]},
    "channel": {"type": "string"},
    "k": {"type": "integer", "description": "sample at which the isolation was computed"},
    "t": {"type": ["number", "null"]},
    "alarm_k": {"type": "integer", "description": "k of the alarm refined (its crossing)"},
    "glr": {"type": "number", "description": "l_k at k"},
    "threshold": {"type": "number"},
    "onset": {"type": "integer", "description": "onset estimate r at k"},
    "magnitude": {"type": "array", "items": {"type": "number"}},
    "isolation": {"type": "array", "items": {
      "type": "object",
      "properties": {
        "fault": {"type": "string"},
        "minmax": {"type": "number"},
        "sensitivity": {"type": "number"},
        "threshold": {"type": "number"},
        "isolated": {"type": "boolean"}
      },
      "required": ["fault", "minmax", "sensitivity", "threshold", "isolated"],
      "additionalProperties": false
    }},
    "faults": {"type": "array", "items": {"type": "string"}}
  },
  "required": ["type", "channel", "k", "alarm_k", "glr", "threshold", "onset", "magnitude", "isolation", "faults"],
  "additionalProperties": false
}"#;

const ALARM_END: &str = r#"{
  "title": "glrmon alarm end",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["alarm_end"]},
    "channel": {"type": "string"},
    "k": {"type": "integer"},
    "t": {"type": ["number", "null"]},
    "onset": {"type": "integer"},
    "duration": {"type": "integer"},
    "peak_glr": {"type": "number"}
  },
  "required": ["type", "channel", "k", "onset", "duration", "peak_glr"],
  "additionalProperties": false
}"#;

const DIAGNOSIS: &str = r#"{
  "title": "glrmon diagnosis",
  "description": "Sparse diagnosis (Zhang 2021): Lasso support, refitted estimates and the path.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["diagnosis"]},
    "channel": {"type": "string"},
    "k": {"type": "integer"},
    "from": {"type": "integer"},
    "to": {"type": "integer"},
    "support": {"type": "array", "items": {"type": "string"}},
    "estimate": {"type": "object", "additionalProperties": {"type": "number"}},
    "lambda": {"type": "number"},
    "plateau": {"type": "array", "items": {"type": "number"}},
    "residual": {"type": "string", "enum": ["kalman", "kitanidis"]},
    "path_support_sizes": {"type": "array", "items": {"type": "integer"}},
    "faults": {"type": "array", "items": {"type": "string"}},
    "path_lambda": {"type": "array", "items": {"type": "number"}},
    "path_coefficients": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}}
  },
  "required": ["type", "channel", "k", "from", "to", "support", "estimate", "lambda", "plateau", "residual", "path_support_sizes", "faults", "path_lambda", "path_coefficients"],
  "additionalProperties": false
}"#;

const ERROR: &str = r#"{
  "title": "glrmon error",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["error"]},
    "channel": {"type": "string"},
    "k": {"type": ["integer", "null"]},
    "code": {"type": "string"},
    "message": {"type": "string"},
    "stage": {"type": "string", "enum": ["receiving", "processing", "sending"]}
  },
  "required": ["type", "channel", "code", "message", "stage"],
  "additionalProperties": false
}"#;

/// Foxglove's `foxglove.Log` message (its fields and level numbers), in the keywords
/// above: `level` is 0 unknown, 1 debug, 2 info, 3 warning, 4 error, 5 fatal.
const LOG: &str = r#"{
  "title": "foxglove.Log",
  "description": "A log message (Foxglove's Log panel): a glrmon alarm (warning) or error record (error).",
  "type": "object",
  "properties": {
    "timestamp": {
      "type": "object",
      "description": "The record's log time",
      "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer"}
      },
      "required": ["sec", "nsec"]
    },
    "level": {"type": "integer", "enum": [0, 1, 2, 3, 4, 5], "description": "0 unknown, 1 debug, 2 info, 3 warning, 4 error, 5 fatal"},
    "message": {"type": "string", "description": "What happened"},
    "name": {"type": "string", "description": "The glrmon channel"},
    "file": {"type": "string", "description": "The record's topic"},
    "line": {"type": "integer", "description": "The record's sample index k (0 when it has none)"}
  },
  "required": ["timestamp", "level", "message", "name", "file", "line"]
}"#;

const CONSISTENCY: &str = r#"{
  "title": "glrmon consistency",
  "description": "Filter consistency: block mean of the normalised innovation squared against its chi-square band.",
  "type": "object",
  "properties": {
    "type": {"type": "string", "enum": ["consistency"]},
    "channel": {"type": "string"},
    "k": {"type": "integer"},
    "t": {"type": ["number", "null"]},
    "state": {"type": "string", "enum": ["consistent", "too_large", "too_small"]},
    "nis_mean": {"type": "number"},
    "expected": {"type": "number"},
    "band": {"type": "array", "items": {"type": "number"}},
    "window": {"type": "integer"}
  },
  "required": ["type", "channel", "k", "state", "nis_mean", "expected", "band", "window"],
  "additionalProperties": false
}"#;
