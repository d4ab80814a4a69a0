//! What a recording holds, read once through [`McapReader`] (`glrmon info`): its size,
//! whether it was finished (and what damage cost), its time range, each topic's
//! messages and the `glrmon` metadata.

use std::collections::BTreeMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::reader::{Damage, Event, McapReader, ReadEnd, ReadError, Salvage};
use crate::schema::TopicKind;
use crate::writer::{FileHeader, METADATA_NAME};

/// Errors of [`summarize`]: the file cannot be read, is not MCAP, or is not a glrmon
/// recording. Each names the file.
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// The file cannot be opened or read, or is not MCAP.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: ReadError,
    },
    /// An MCAP file without the `glrmon` metadata record (not written by glrmon, or
    /// damaged before it).
    #[error(
        "{path}: not a glrmon recording: no readable \"glrmon\" metadata record ({messages} message(s) on {topics} topic(s) read)"
    )]
    NotGlrmon {
        /// The file.
        path: PathBuf,
        /// Messages read.
        messages: u64,
        /// Topics seen.
        topics: usize,
        /// Each topic with its schema and messages, in name order: what a mapping of a
        /// foreign recording's topics (`[channels.topics]`) needs to know.
        found: Vec<TopicSummary>,
        /// The writer's `library` string.
        library: Option<String>,
    },
}

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicSummary {
    /// The topic name.
    pub topic: String,
    /// Its schema's name.
    pub schema: String,
    /// Its schema's encoding (`jsonschema` for glrmon's topics, `ros2msg`, `protobuf`).
    pub schema_encoding: String,
    /// Its messages' encoding (`json`, `cdr`, `protobuf`).
    pub message_encoding: String,
    /// The glrmon channel (none for the log topic).
    pub channel: Option<String>,
    /// The glrmon kind.
    pub kind: Option<TopicKind>,
    /// Messages read.
    pub messages: u64,
    /// Log time (ns since the Unix epoch) of the first message read.
    pub first_ns: Option<u64>,
    /// Log time of the last message read.
    pub last_ns: Option<u64>,
}

/// What [`summarize`] found.
#[derive(Debug, Clone)]
pub struct RecordingSummary {
    /// The file.
    pub path: PathBuf,
    /// Its size in bytes.
    pub bytes: u64,
    /// The MCAP header's `library` (glrmon writes `glrmon <version>`), if readable.
    pub library: Option<String>,
    /// The `glrmon` metadata: configuration, channels, instance, version.
    pub header: FileHeader,
    /// How the read ended: [`ReadEnd::Finished`] for a file closed properly.
    pub end: ReadEnd,
    /// The salvage totals (damage, messages read and known).
    pub salvage: Salvage,
    /// The damaged parts skipped.
    pub damage: Vec<Damage>,
    /// Messages read.
    pub messages: u64,
    /// Log time (ns) of the earliest message.
    pub start_ns: Option<u64>,
    /// Log time (ns) of the latest message.
    pub end_ns: Option<u64>,
    /// Every topic the file declares, in topic order; those without a readable message
    /// have a count of 0.
    pub topics: Vec<TopicSummary>,
}

impl RecordingSummary {
    /// Whether the file was finished (footer and closing magic).
    #[must_use]
    pub fn finished(&self) -> bool {
        self.end == ReadEnd::Finished
    }

    /// Whether data was lost to damage (an unfinished file alone is not).
    #[must_use]
    pub fn lost_data(&self) -> bool {
        self.salvage.lost_data() || matches!(self.end, ReadEnd::Unreadable { .. })
    }

    /// The glrmon version that wrote the file: the metadata's `glrmon_version`, else
    /// the MCAP library string's version.
    #[must_use]
    pub fn glrmon_version(&self) -> Option<String> {
        self.header
            .extra
            .get("glrmon_version")
            .cloned()
            .or_else(|| {
                self.library
                    .as_deref()
                    .and_then(|l| l.strip_prefix("glrmon "))
                    .map(str::to_owned)
            })
    }

    /// `end_ns - start_ns` (0 without messages).
    #[must_use]
    pub fn duration_ns(&self) -> u64 {
        match (self.start_ns, self.end_ns) {
            (Some(a), Some(b)) => b.saturating_sub(a),
            _ => 0,
        }
    }
}

/// Reads the recording at `path` once, start to end, with the damage-tolerant
/// [`McapReader`]: an unfinished or damaged file is summarised as far as it is readable
/// ([`RecordingSummary::end`], [`RecordingSummary::salvage`]).
///
/// # Errors
/// [`SummaryError::Read`] when the file cannot be opened or is not MCAP,
/// [`SummaryError::NotGlrmon`] when it has no `glrmon` metadata record.
pub fn summarize(path: &Path) -> Result<RecordingSummary, SummaryError> {
    let err = |source| SummaryError::Read {
        path: path.to_owned(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(|e| err(ReadError::Io(e)))?;
    let bytes = file.metadata().map_err(|e| err(ReadError::Io(e)))?.len();
    let library = read_library(&mut file);
    file.seek(SeekFrom::Start(0))
        .map_err(|e| err(ReadError::Io(e)))?;
    let mut reader =
        McapReader::new(std::io::BufReader::with_capacity(1 << 16, file)).map_err(err)?;
    let mut header = None;
    // By MCAP channel id: (messages, first, last).
    let mut counts: BTreeMap<u16, (u64, u64, u64)> = BTreeMap::new();
    let (mut start, mut end) = (None::<u64>, None::<u64>);
    while let Some(event) = reader.next_event().map_err(|e| err(ReadError::Io(e)))? {
        match event {
            Event::Metadata { name, entries } if name == METADATA_NAME && header.is_none() => {
                header = Some(crate::header_from_metadata(&entries));
            }
            Event::Metadata { .. } => {}
            Event::Message(m) => {
                let t = m.log_time;
                let c = counts.entry(m.topic.id).or_insert((0, t, t));
                c.0 += 1;
                c.1 = c.1.min(t);
                c.2 = c.2.max(t);
                start = Some(start.map_or(t, |s| s.min(t)));
                end = Some(end.map_or(t, |e| e.max(t)));
            }
        }
    }
    let topics: Vec<TopicSummary> = reader
        .topics()
        .iter()
        .map(|t| {
            let c = counts.get(&t.id);
            TopicSummary {
                topic: t.topic.clone(),
                schema: t.schema.clone(),
                schema_encoding: t.schema_encoding.clone(),
                message_encoding: t.message_encoding.clone(),
                channel: t.channel.clone(),
                kind: t.kind,
                messages: c.map_or(0, |c| c.0),
                first_ns: c.map(|c| c.1),
                last_ns: c.map(|c| c.2),
            }
        })
        .collect();
    let messages = reader.messages();
    let mut topics = topics;
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    let Some(header) = header else {
        return Err(SummaryError::NotGlrmon {
            path: path.to_owned(),
            messages,
            topics: topics.len(),
            found: topics,
            library,
        });
    };
    Ok(RecordingSummary {
        path: path.to_owned(),
        bytes,
        library,
        header,
        end: reader.end().clone(),
        salvage: reader.salvage(),
        damage: reader.damage().to_vec(),
        messages,
        start_ns: start,
        end_ns: end,
        topics,
    })
}

/// The `library` string of the MCAP header record (the first record), if it is whole
/// and plausible.
fn read_library(file: &mut std::fs::File) -> Option<String> {
    let mut head = [0u8; 8 + 9];
    file.seek(SeekFrom::Start(0)).ok()?;
    file.read_exact(&mut head).ok()?;
    if head[8] != mcap::records::op::HEADER {
        return None;
    }
    let len = u64::from_le_bytes(head[9..17].try_into().ok()?);
    if len > 1 << 16 {
        return None;
    }
    let mut body = vec![0u8; usize::try_from(len).ok()?];
    file.read_exact(&mut body).ok()?;
    // profile (u32 length, bytes), library (u32 length, bytes)
    let string = |at: usize| -> Option<(String, usize)> {
        let n = u32::from_le_bytes(body.get(at..at + 4)?.try_into().ok()?) as usize;
        let s = body.get(at + 4..at.checked_add(4)?.checked_add(n)?)?;
        Some((String::from_utf8_lossy(s).into_owned(), at + 4 + n))
    };
    let (_, next) = string(0)?;
    let (library, _) = string(next)?;
    (!library.is_empty()).then_some(library)
}

/// Calendar date and time (UTC) of `secs` seconds since the Unix epoch: (year, month,
/// day, hour, minute, second). Beyond jiff's range (year 9999) the last second it holds.
pub(crate) fn civil(secs: u64) -> (i64, i64, i64, u64, u64, u64) {
    let ts = i64::try_from(secs)
        .ok()
        .and_then(|s| jiff::Timestamp::from_second(s).ok())
        .unwrap_or(jiff::Timestamp::MAX);
    let t = ts.to_zoned(jiff::tz::TimeZone::UTC).datetime();
    let small = |v: i8| u64::try_from(v).unwrap_or(0);
    (
        i64::from(t.year()),
        i64::from(t.month()),
        i64::from(t.day()),
        small(t.hour()),
        small(t.minute()),
        small(t.second()),
    )
}

/// ISO-8601 UTC time of `ns` nanoseconds since the Unix epoch, to the nanosecond:
/// `2026-12-02T16:24:19.123456789Z`.
///
/// # Examples
///
/// ```
/// assert_eq!(glrmon_record::iso8601_utc(0), "1970-01-01T00:00:00.000000000Z");
/// assert_eq!(
///     glrmon_record::iso8601_utc(951_825_600_500_000_000),
///     "2000-02-29T12:00:00.500000000Z"
/// );
/// ```
#[must_use]
pub fn iso8601_utc(ns: u64) -> String {
    let (y, m, d, hh, mm, ss) = civil(ns / 1_000_000_000);
    format!(
        "{y:04}-{m:02}-{d:02}T{hh:02}:{mm:02}:{ss:02}.{:09}Z",
        ns % 1_000_000_000
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FileHeader, FileOptions, McapFile, McapFileSink, log_message};
    use glrmon_runtime::{InputItem, InputOutput, Output, Sink};
    use std::sync::Arc;

    fn scratch(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("glrmon-summary-{tag}-{}.mcap", std::process::id()))
    }

    #[test]
    fn iso8601_utc_covers_the_whole_u64_range() {
        assert_eq!(iso8601_utc(u64::MAX), "2554-07-21T23:34:33.709551615Z");
        assert_eq!(
            iso8601_utc(1_796_191_746_296_000_000),
            "2026-12-02T06:09:06.296000000Z"
        );
    }

    fn header(channels: &[&str]) -> FileHeader {
        FileHeader {
            config: "cfg".into(),
            channels: channels.iter().map(|c| (*c).to_owned()).collect(),
            extra: BTreeMap::from([("glrmon_version".to_owned(), "9.9.9".to_owned())]),
        }
    }

    fn input(channel: &str, k: u64, log_ns: u64) -> InputOutput {
        let s = glrmon_wire::Sample {
            k: Some(k),
            t: Some(k as f64 * 0.01),
            u: vec![],
            y: vec![k as f64],
            p: vec![],
        };
        let mut json = Vec::new();
        glrmon_wire::encode_sample(channel, &s, &mut json).unwrap();
        InputOutput {
            channel: 0,
            name: Arc::from(channel),
            item: InputItem::Sample(s),
            json,
            log_time_ns: log_ns,
        }
    }

    fn alarm(channel: &str, k: u64) -> glrmon_wire::Record {
        glrmon_wire::Record::Alarm(glrmon_wire::Alarm {
            channel: channel.into(),
            k,
            t: Some(k as f64 * 0.01),
            glr: 42.5,
            threshold: 20.0,
            onset: k - 3,
            magnitude: vec![1.5],
            isolation: vec![glrmon_wire::IsolationResult {
                excluded: None,
                fault: "leak".into(),
                minmax: 30.0,
                sensitivity: 10.0,
                threshold: 5.0,
                isolated: true,
                ambiguous_with: Vec::new(),
            }],
            faults: vec!["leak".into()],
            update_k: None,
        })
    }

    fn output(record: glrmon_wire::Record, log_ns: u64) -> Output {
        let mut json = Vec::new();
        glrmon_wire::encode_json(&record, &mut json).unwrap();
        Output {
            record,
            json,
            log_time_ns: log_ns,
            stat_index: None,
        }
    }

    /// Lazy declaration: a recording of one channel (of two configured) without an
    /// alarm has only the topics it wrote to; an empty one has none.
    #[test]
    fn only_topics_with_messages_are_declared() {
        let path = scratch("lazy");
        let mut sink = McapFileSink::create(&path, &header(&["a", "b"])).unwrap();
        for k in 0..10 {
            sink.write_input(&input("a", k, 1_000 + k)).unwrap();
        }
        sink.close().unwrap();
        let s = summarize(&path).unwrap();
        assert!(s.finished());
        assert_eq!(s.messages, 10);
        let topics: Vec<(&str, u64)> = s
            .topics
            .iter()
            .map(|t| (t.topic.as_str(), t.messages))
            .collect();
        assert_eq!(topics, [("glrmon/a/inputs", 10)]);
        assert_eq!(s.header.channels, ["a", "b"]);
        assert_eq!(s.glrmon_version().as_deref(), Some("9.9.9"));
        assert_eq!((s.start_ns, s.end_ns), (Some(1_000), Some(1_009)));
        assert!(
            s.library
                .as_deref()
                .is_some_and(|l| l.starts_with("glrmon "))
        );

        McapFile::create(&path, FileOptions::default(), &header(&["a"]))
            .unwrap()
            .finish()
            .unwrap();
        let s = summarize(&path).unwrap();
        assert!(s.topics.is_empty(), "{:?}", s.topics);
        assert_eq!(s.messages, 0);
        std::fs::remove_file(&path).unwrap();
    }

    /// An alarm is also a `foxglove.Log` message on the log topic: level warning, the
    /// channel as name, the log time as timestamp, the record's topic and k as file and
    /// line.
    #[test]
    fn alarms_are_also_foxglove_log_messages() {
        let path = scratch("log");
        let mut sink = McapFileSink::create(&path, &header(&["a"])).unwrap();
        sink.write(&output(alarm("a", 40), 3_000_000_123)).unwrap();
        sink.close().unwrap();
        let mut r = McapReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        let mut logs = Vec::new();
        while let Some(e) = r.next_event().unwrap() {
            if let Event::Message(m) = e
                && m.topic.kind == Some(TopicKind::Log)
            {
                assert_eq!(m.topic.topic, crate::LOG_TOPIC);
                assert_eq!(m.topic.schema, "foxglove.Log");
                assert_eq!(m.topic.schema_encoding, "jsonschema");
                assert_eq!(m.topic.message_encoding, "json");
                assert_eq!(m.topic.channel, None);
                let schema: serde_json::Value =
                    serde_json::from_slice(&m.topic.schema_data).unwrap();
                assert_eq!(schema["title"], "foxglove.Log");
                logs.push(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
            }
        }
        assert_eq!(logs.len(), 1);
        let v = &logs[0];
        assert_eq!(v["timestamp"]["sec"], 3);
        assert_eq!(v["timestamp"]["nsec"], 123);
        assert_eq!(v["level"], 3);
        assert_eq!(v["name"], "a");
        assert_eq!(v["file"], "glrmon/a/alarm");
        assert_eq!(v["line"], 40);
        let message = v["message"].as_str().unwrap();
        assert!(message.contains("k=40"), "{message}");
        assert!(message.contains("onset 37"), "{message}");
        assert!(message.contains("leak"), "{message}");
        // Only alarms and errors are logged.
        let end = glrmon_wire::Record::AlarmEnd(glrmon_wire::AlarmEnd {
            channel: "a".into(),
            k: 50,
            t: None,
            onset: 37,
            duration: 10,
            peak_glr: 50.0,
        });
        assert!(log_message(&end, 0).is_none());
        std::fs::remove_file(&path).unwrap();
    }

    /// One rule on every topic: publish time = log time (inputs, results, logs), even
    /// where the sample has a time of its own.
    #[test]
    fn publish_time_is_the_log_time_on_every_topic() {
        let path = scratch("publish");
        let mut sink = McapFileSink::create(&path, &header(&["a"])).unwrap();
        sink.write_input(&input("a", 5, 7_000_000_001)).unwrap();
        sink.write(&output(alarm("a", 5), 7_000_000_002)).unwrap();
        let consistency = glrmon_wire::Record::Consistency(glrmon_wire::Consistency {
            channel: "a".into(),
            k: 5,
            t: Some(0.05),
            state: "too_large".into(),
            nis_mean: 3.0,
            expected: 1.0,
            band: [0.5, 1.5],
            window: 100,
        });
        sink.write(&output(consistency, 7_000_000_003)).unwrap();
        sink.close().unwrap();
        let mut r = McapReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        let mut kinds = Vec::new();
        while let Some(e) = r.next_event().unwrap() {
            if let Event::Message(m) = e {
                assert_eq!(m.publish_time, m.log_time, "{}", m.topic.topic);
                kinds.push(m.topic.kind.unwrap());
            }
        }
        kinds.sort();
        assert_eq!(
            kinds,
            [
                TopicKind::Inputs,
                TopicKind::Alarm,
                TopicKind::Consistency,
                TopicKind::Log
            ]
        );
        std::fs::remove_file(&path).unwrap();
    }

    /// Not MCAP, or MCAP without glrmon metadata: an error naming the file.
    #[test]
    fn a_file_that_is_not_a_glrmon_recording_is_an_error() {
        let path = scratch("bad");
        std::fs::write(&path, b"hello, not mcap").unwrap();
        let e = summarize(&path).unwrap_err().to_string();
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        assert!(e.contains("not an MCAP file"), "{e}");
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&path).unwrap(),
        ))
        .unwrap();
        w.finish().unwrap();
        drop(w);
        let e = summarize(&path).unwrap_err().to_string();
        assert!(e.contains("not a glrmon recording"), "{e}");
        std::fs::remove_file(&path).unwrap();
    }
}
