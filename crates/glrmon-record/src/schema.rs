//! Topics and JSON Schemas of a recording.
//!
//! Every message is JSON (`message_encoding = "json"`) with a `jsonschema` schema, so
//! Foxglove and the `mcap` CLI open a recording without plugins. Topics mirror the Zenoh
//! result keys: `glrmon/<channel>/<kind>`. Each MCAP channel carries the metadata
//! `channel` (the glrmon channel name) and `kind`, by which a reader maps it back.
//!
//! The schemas of glrmon's own messages (inputs, intake events, result records) are
//! derived from the wire types ([`glrmon_wire::sample_schema`],
//! [`glrmon_wire::intake_schema`], [`glrmon_wire::record_schema`]); the tests validate
//! every recorded message against the schema its file carries.

use std::sync::OnceLock;

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

    /// The JSON Schema of the messages: glrmon's (draft 7, derived from the wire types)
    /// pretty-printed once per process, or Foxglove's `foxglove.Log`.
    #[must_use]
    pub fn schema(self) -> &'static str {
        static TEXT: [OnceLock<String>; TopicKind::ALL.len()] =
            [const { OnceLock::new() }; TopicKind::ALL.len()];
        let schema = match self {
            TopicKind::Log => return LOG,
            TopicKind::Inputs => glrmon_wire::sample_schema(),
            TopicKind::Intake => glrmon_wire::intake_schema(),
            // Every other kind is a record type (tested).
            _ => match glrmon_wire::record_schema(self.as_str()) {
                Some(schema) => schema,
                None => return "",
            },
        };
        // Serialising a `serde_json::Value` cannot fail.
        TEXT[self as usize].get_or_init(|| serde_json::to_string_pretty(schema).unwrap_or_default())
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

/// Foxglove's `foxglove.Log` message (its fields and level numbers), by hand as it is no
/// glrmon type: `level` is 0 unknown, 1 debug, 2 info, 3 warning, 4 error, 5 fatal.
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

#[cfg(test)]
mod tests {
    //! Every schema a recording carries against the messages glrmon writes under it: a
    //! file with every kind of message (optional fields present and absent) is written,
    //! read back by glrmon's reader and by the `mcap` crate, and each message validated
    //! against its topic's schema.

    use std::collections::BTreeMap;
    use std::sync::Arc;

    use glrmon_runtime::{InputItem, InputOutput, Output, Sink};
    use glrmon_wire::{
        Alarm, AlarmEnd, Consistency, Diagnosis, ErrorCode, ErrorRecord, IntakeEvent,
        IsolationResult, IsolationUpdate, Record, Sample, Stage, Stat,
    };
    use serde_json::Value;

    use super::*;
    use crate::{Event, FileHeader, McapFileSink, McapReader};

    /// The errors of `value` against `schema`, each with its JSON path. Knows the
    /// keywords glrmon's schemas use; any other fails the test, so that a schema change
    /// this validator does not check cannot pass unnoticed.
    fn check(schema: &Value, value: &Value, path: &str, errors: &mut Vec<String>) {
        let Some(obj) = schema.as_object() else {
            errors.push(format!("{path}: schema is not an object"));
            return;
        };
        for (key, rule) in obj {
            match key.as_str() {
                "$schema" | "title" | "description" | "format" | "default" => {}
                "type" => {
                    let types: Vec<&str> = match rule {
                        Value::String(t) => vec![t.as_str()],
                        Value::Array(a) => a.iter().filter_map(Value::as_str).collect(),
                        _ => panic!("{path}: bad type {rule}"),
                    };
                    if !types.iter().any(|t| has_type(value, t)) {
                        errors.push(format!("{path}: {value} is not of type {types:?}"));
                    }
                }
                "enum" => {
                    if !rule.as_array().unwrap().contains(value) {
                        errors.push(format!("{path}: {value} is not one of {rule}"));
                    }
                }
                "const" => {
                    if rule != value {
                        errors.push(format!("{path}: {value} is not {rule}"));
                    }
                }
                "properties" => {
                    for (k, sub) in rule.as_object().unwrap() {
                        if let Some(x) = value.get(k) {
                            check(sub, x, &format!("{path}.{k}"), errors);
                        }
                    }
                }
                "required" => {
                    for k in rule.as_array().unwrap() {
                        if value.is_object() && value.get(k.as_str().unwrap()).is_none() {
                            errors.push(format!("{path}: missing {k}"));
                        }
                    }
                }
                "additionalProperties" => {
                    let known = obj.get("properties").and_then(Value::as_object);
                    for (k, x) in value.as_object().into_iter().flatten() {
                        if known.is_some_and(|p| p.contains_key(k)) {
                        } else if rule == &Value::Bool(false) {
                            errors.push(format!("{path}: unknown key {k}"));
                        } else {
                            check(rule, x, &format!("{path}.{k}"), errors);
                        }
                    }
                }
                "items" => {
                    for (i, x) in value.as_array().into_iter().flatten().enumerate() {
                        check(rule, x, &format!("{path}[{i}]"), errors);
                    }
                }
                "minItems" | "maxItems" => {
                    if let Some(a) = value.as_array() {
                        let n = rule.as_u64().unwrap() as usize;
                        if (key == "minItems" && a.len() < n) || (key == "maxItems" && a.len() > n)
                        {
                            errors.push(format!("{path}: {} items, {key} {n}", a.len()));
                        }
                    }
                }
                "minimum" => {
                    if let Some(x) = value.as_f64()
                        && x < rule.as_f64().unwrap()
                    {
                        errors.push(format!("{path}: {x} below {rule}"));
                    }
                }
                "oneOf" => {
                    let matching = rule
                        .as_array()
                        .unwrap()
                        .iter()
                        .filter(|s| {
                            let mut e = Vec::new();
                            check(s, value, path, &mut e);
                            e.is_empty()
                        })
                        .count();
                    if matching != 1 {
                        errors.push(format!("{path}: {value} matches {matching} of oneOf"));
                    }
                }
                other => panic!("{path}: the test's validator does not know `{other}`"),
            }
        }
    }

    fn has_type(value: &Value, t: &str) -> bool {
        match t {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "number" => value.is_number(),
            "integer" => value.is_u64() || value.is_i64(),
            "boolean" => value.is_boolean(),
            "null" => value.is_null(),
            _ => panic!("unknown type {t}"),
        }
    }

    fn errors_of(schema: &Value, value: &Value) -> Vec<String> {
        let mut errors = Vec::new();
        check(schema, value, "$", &mut errors);
        errors
    }

    fn samples() -> Vec<Sample> {
        vec![
            Sample {
                k: Some(0),
                t: Some(0.5),
                u: vec![1.0],
                y: vec![0.25, -0.0],
                p: vec![3.0],
            },
            Sample {
                y: vec![1.0],
                ..Sample::default()
            },
        ]
    }

    fn intake_events() -> Vec<IntakeEvent> {
        vec![
            IntakeEvent::Dropped { count: 3 },
            IntakeEvent::Rejected {
                code: ErrorCode::InvalidJson,
                message: "payload is not valid JSON".into(),
                payload: Some("{\"y\":[1,".into()),
            },
            IntakeEvent::Rejected {
                code: ErrorCode::TooLarge,
                message: "too large".into(),
                payload: None,
            },
        ]
    }

    /// Records of every type, each `Option` field both `Some` and `None` somewhere.
    fn records() -> Vec<Record> {
        let isolation = vec![IsolationResult {
            excluded: None,
            fault: "leak".into(),
            minmax: 30.0,
            sensitivity: 10.0,
            threshold: 5.0,
            isolated: true,
            ambiguous_with: Vec::new(),
        }];
        let stat = Stat {
            channel: "a".into(),
            k: 10,
            t: Some(0.1),
            glr: Some(3.5),
            onset: Some(7),
            magnitude: vec![0.5],
            rank: 1,
            innovation: vec![0.1, -0.2],
            residual: Vec::new(),
            threshold: Some(20.0),
            episode: Some(glrmon_wire::EpisodeEstimate {
                onset: 5,
                magnitude: vec![1.25],
            }),
        };
        let alarm = Alarm {
            channel: "a".into(),
            k: 40,
            t: Some(0.4),
            glr: 42.5,
            threshold: 20.0,
            onset: 37,
            magnitude: vec![1.5],
            isolation: isolation.clone(),
            faults: vec!["leak".into()],
            update_k: Some(45),
        };
        let error = ErrorRecord {
            channel: "a".into(),
            k: Some(3),
            code: ErrorCode::Gap,
            message: "2 samples missing".into(),
            stage: Stage::Processing,
        };
        vec![
            stat.clone().into(),
            Stat {
                t: None,
                glr: None,
                onset: None,
                magnitude: vec![],
                rank: 0,
                threshold: None,
                episode: None,
                ..stat
            }
            .into(),
            alarm.clone().into(),
            Alarm {
                t: None,
                update_k: None,
                ..alarm
            }
            .into(),
            IsolationUpdate {
                channel: "a".into(),
                k: 45,
                t: None,
                alarm_k: 40,
                glr: 18.0,
                threshold: 20.0,
                onset: 36,
                magnitude: vec![1.25],
                isolation,
                faults: vec!["leak".into()],
            }
            .into(),
            AlarmEnd {
                channel: "a".into(),
                k: 60,
                t: None,
                onset: 36,
                duration: 20,
                peak_glr: 50.0,
            }
            .into(),
            Diagnosis {
                channel: "a".into(),
                k: 60,
                from: 36,
                to: 60,
                support: vec!["leak".into()],
                estimate: BTreeMap::from([("leak".into(), 1.25)]),
                lambda: 0.05,
                plateau: [0.01, 0.2],
                residual: Diagnosis::RESIDUAL_KALMAN.into(),
                path_support_sizes: vec![0, 1],
                faults: vec!["leak".into(), "bias".into()],
                path_lambda: vec![0.4, 0.05],
                path_coefficients: vec![vec![0.0, 0.0], vec![1.2, 0.0]],
            }
            .into(),
            error.clone().into(),
            ErrorRecord { k: None, ..error }.into(),
            Consistency {
                channel: "a".into(),
                k: 99,
                t: Some(0.99),
                state: "too_large".into(),
                nis_mean: 3.0,
                expected: 1.0,
                band: [0.5, 1.5],
                window: 100,
            }
            .into(),
        ]
    }

    /// Writes every message of [`samples`], [`intake_events`] and [`records`] for
    /// channel `a` into an MCAP file (named after `tag`), and returns its bytes.
    fn recording(tag: &str) -> Vec<u8> {
        let path =
            std::env::temp_dir().join(format!("glrmon-schema-{tag}-{}.mcap", std::process::id()));
        let header = FileHeader {
            config: "cfg".into(),
            channels: vec!["a".into()],
            extra: BTreeMap::new(),
        };
        let mut sink = McapFileSink::create(&path, &header).unwrap();
        let mut log_time_ns = 1_000;
        let mut input = |item: InputItem, json: Vec<u8>| {
            log_time_ns += 1;
            InputOutput {
                channel: 0,
                name: Arc::from("a"),
                item,
                json,
                log_time_ns,
            }
        };
        for s in samples() {
            let mut json = Vec::new();
            glrmon_wire::encode_sample("a", &s, &mut json).unwrap();
            sink.write_input(&input(InputItem::Sample(s), json))
                .unwrap();
        }
        for e in intake_events() {
            let mut json = Vec::new();
            glrmon_wire::encode_intake("a", &e, &mut json).unwrap();
            sink.write_input(&input(InputItem::Intake(e), json))
                .unwrap();
        }
        for (i, record) in records().into_iter().enumerate() {
            let mut json = Vec::new();
            glrmon_wire::encode_json(&record, &mut json).unwrap();
            let output = Output {
                record,
                json,
                log_time_ns: 2_000 + i as u64,
                stat_index: Some(i as u64),
            };
            sink.write(&output).unwrap();
        }
        sink.close().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        bytes
    }

    /// Every message glrmon records validates against the schema its file carries for
    /// its topic, as read by glrmon's reader; glrmon's own messages have exactly the
    /// properties their schema lists.
    #[test]
    fn every_recorded_message_validates_against_its_topics_schema() {
        let bytes = recording("validate");
        let mut reader = McapReader::new(std::io::Cursor::new(&bytes)).unwrap();
        let mut seen = BTreeMap::<TopicKind, usize>::new();
        while let Some(event) = reader.next_event().unwrap() {
            let Event::Message(m) = event else { continue };
            let kind = m.topic.kind.unwrap();
            assert_eq!(m.topic.schema, kind.schema_name());
            assert_eq!(m.topic.schema_encoding, "jsonschema");
            assert_eq!(m.topic.message_encoding, "json");
            assert_eq!(&*m.topic.schema_data, kind.schema().as_bytes());
            let schema: Value = serde_json::from_slice(&m.topic.schema_data).unwrap();
            let message: Value = serde_json::from_slice(&m.data).unwrap();
            let errors = errors_of(&schema, &message);
            assert!(
                errors.is_empty(),
                "{}: {message}: {errors:#?}",
                m.topic.topic
            );
            if kind != TopicKind::Log {
                let listed = schema["properties"].as_object().unwrap();
                for key in message.as_object().unwrap().keys() {
                    assert!(listed.contains_key(key), "{}: {key}", m.topic.topic);
                }
            }
            *seen.entry(kind).or_default() += 1;
        }
        let kinds: Vec<TopicKind> = seen.keys().copied().collect();
        assert_eq!(kinds, TopicKind::ALL);
        assert_eq!(seen[&TopicKind::Inputs], samples().len());
        assert_eq!(seen[&TopicKind::Intake], intake_events().len());
        assert_eq!(seen[&TopicKind::Error], 2);
    }

    /// The `mcap` crate reads the same schemas and messages.
    #[test]
    fn the_mcap_crate_reads_the_schemas() {
        let bytes = recording("mcap-crate");
        let mut topics = 0;
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            let message = message.unwrap();
            let schema = message.channel.schema.as_ref().unwrap();
            assert_eq!(schema.encoding, "jsonschema");
            let kind = TopicKind::parse(&message.channel.metadata["kind"]).unwrap();
            assert_eq!(schema.name, kind.schema_name());
            assert_eq!(&*schema.data, kind.schema().as_bytes());
            topics += 1;
        }
        assert!(topics > TopicKind::ALL.len());
    }

    /// Each schema is JSON with a title and an object type; a record type's lists exactly
    /// the fields of its records and requires the ones that are never `null`; the
    /// decoders that refuse unknown fields (samples, intake events) say so.
    #[test]
    fn schemas_describe_the_records_exactly() {
        for kind in TopicKind::ALL {
            let schema: Value = serde_json::from_str(kind.schema()).unwrap();
            assert!(
                schema["title"].as_str().is_some_and(|t| !t.is_empty()),
                "{kind:?}"
            );
            assert_eq!(schema["type"], "object", "{kind:?}");
            assert!(schema["properties"].is_object(), "{kind:?}");
        }
        for record in records() {
            let kind = TopicKind::of_record(&record).unwrap();
            let schema: Value = serde_json::from_str(kind.schema()).unwrap();
            assert_eq!(
                schema["title"],
                format!("glrmon {}", kind.as_str().replace('_', " "))
            );
            let mut json = Vec::new();
            glrmon_wire::encode_json(&record, &mut json).unwrap();
            let message: Value = serde_json::from_slice(&json).unwrap();
            let fields: Vec<&String> = message.as_object().unwrap().keys().collect();
            // A field left out when empty (a stat's `residual`) is listed but not
            // required.
            let required: Vec<&str> = schema["required"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(Value::as_str)
                .collect();
            let listed: Vec<&String> = schema["properties"]
                .as_object()
                .unwrap()
                .keys()
                .filter(|k| message.get(k.as_str()).is_some() || required.contains(&k.as_str()))
                .collect();
            assert_eq!(fields, listed, "{kind:?}");
            for name in schema["required"].as_array().unwrap() {
                assert!(
                    !message[name.as_str().unwrap()].is_null(),
                    "{kind:?} {name}"
                );
            }
        }
        for kind in [TopicKind::Inputs, TopicKind::Intake] {
            let schema: Value = serde_json::from_str(kind.schema()).unwrap();
            let closed = |s: &Value| s["additionalProperties"] == false;
            let alternatives = schema["oneOf"].as_array();
            assert!(
                closed(&schema) || alternatives.is_some_and(|a| a.iter().all(closed)),
                "{kind:?}"
            );
        }
        let stat: Value = serde_json::from_str(TopicKind::Stat.schema()).unwrap();
        let mut json = Vec::new();
        glrmon_wire::encode_json(&records()[0], &mut json).unwrap();
        let good: Value = serde_json::from_slice(&json).unwrap();
        for (field, bad) in [
            ("k", Value::from(-1)),
            ("glr", "x".into()),
            ("type", "alarm".into()),
        ] {
            let mut message = good.clone();
            message[field] = bad;
            assert!(!errors_of(&stat, &message).is_empty(), "{message}");
        }
        let unknown = serde_json::json!({"y": [1.0], "z": 2});
        let inputs: Value = serde_json::from_str(TopicKind::Inputs.schema()).unwrap();
        assert_eq!(errors_of(&inputs, &unknown), ["$: unknown key z"]);
        let intake: Value = serde_json::from_str(TopicKind::Intake.schema()).unwrap();
        assert!(!errors_of(&intake, &serde_json::json!({"type": "dropped"})).is_empty());
        assert!(
            !errors_of(
                &intake,
                &serde_json::json!({"type": "dropped", "count": 1, "x": 0})
            )
            .is_empty()
        );
    }

    /// Foxglove derives a topic's fields from its schema: an object with `properties`,
    /// each with one `type` (a list is not understood) and arrays of non-arrays. The
    /// input samples, the topic most often plotted, stay within that.
    #[test]
    fn the_inputs_schema_is_within_what_foxglove_reads() {
        let schema: Value = serde_json::from_str(TopicKind::Inputs.schema()).unwrap();
        for (name, property) in schema["properties"].as_object().unwrap() {
            let ty = property["type"].as_str();
            assert!(ty.is_some(), "{name}: {property}");
            if ty == Some("array") {
                assert!(
                    property["items"]["type"]
                        .as_str()
                        .is_some_and(|t| t != "array"),
                    "{name}"
                );
            }
        }
    }
}
