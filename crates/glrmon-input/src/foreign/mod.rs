//! Recordings glrmon did not write (ROS 2 bags, Foxglove MCAP): each channel's
//! `[channels.topics]` says which topic and field give each of its signals, and how
//! samples are formed from them (a period, or each message of a trigger topic), as
//! `[channels.tags]` does for live keys. A message is read by its encoding: JSON as it
//! is; ROS 2 CDR by the `ros2msg` schema in the file ([`ros2`]); protobuf by the
//! `FileDescriptorSet` in the file ([`protobuf`]); every message of a mapped topic
//! then goes, as a JSON document, to the channel's tag decoder, timed by
//! its publish time (`time = "zenoh"`) or its log time (`time = "arrival"`). The
//! pipeline and everything after it are the live ones.

mod protobuf;
mod ros2;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glrmon_record::{Event, McapReader, ReadEnd};
use glrmon_runtime::{ChannelPipeline, Fanout, PayloadDecoder, TagDecoder};
use glrmon_spec::Channel;
use glrmon_wire::{DecodeLimits, ErrorCode};

use crate::{InputError, InputErrorKind, ReplayError, Skipped};

/// The decoder of a channel read from a foreign recording (`[channels.topics]`).
#[must_use]
pub fn topics_decoder(channel: &Channel) -> Option<Box<dyn PayloadDecoder>> {
    let d = channel.dims;
    channel.topics.as_ref().map(|t| {
        Box::new(TagDecoder::new(t.clone(), d.inputs, d.outputs, d.signals))
            as Box<dyn PayloadDecoder>
    })
}

/// What a foreign replay went through.
#[derive(Debug, Default)]
pub struct ForeignReplayed {
    /// Messages in the file.
    pub messages: u64,
    /// Messages of each mapped topic.
    pub by_topic: BTreeMap<String, u64>,
    /// Messages that could not be read by their schema, by topic, with the first reason.
    pub unreadable: BTreeMap<String, (u64, String)>,
    /// What damage the file had and what it cost (one line each), empty for a sound
    /// file: the streaming reader skips a damaged region and reads on.
    pub damage: Vec<String>,
}

/// How one topic's messages are read.
enum Reader {
    Json,
    Ros2(Box<ros2::Schema>),
    Protobuf(Box<protobuf::Schema>),
    /// Why they cannot be.
    Unreadable(String),
}

/// Feeds the messages of every topic the channels of `pipelines` map
/// (`channels[i]` configures `pipelines[i]`, whose decoder is [`topics_decoder`]'s) to
/// them, in the file's order. The file is streamed (one chunk in memory at a time) by
/// the damage-tolerant reader of glrmon's own recordings: a damaged region is skipped
/// and reported in [`ForeignReplayed::damage`], and the samples it held are gaps.
///
/// # Errors
/// [`ReplayError`] when the file cannot be read or is not MCAP, a mapped topic is not
/// in it, or a sink fails.
pub fn replay_foreign_mcap(
    path: &Path,
    channels: &[&Channel],
    pipelines: &mut [ChannelPipeline],
    limits: &DecodeLimits,
    fanout: &mut Fanout,
) -> Result<ForeignReplayed, ReplayError> {
    let foreign = |m: String| ReplayError::Input(InputError::new(path, InputErrorKind::Foreign(m)));
    // Each topic's (pipeline, key index) pairs.
    let mut routes: HashMap<&str, Vec<(usize, usize)>> = HashMap::new();
    for (c, channel) in channels.iter().enumerate() {
        let Some(topics) = &channel.topics else {
            return Err(foreign(format!(
                "channel \"{}\" has no [channels.topics]: which topics of this recording \
                 give its signals?",
                channel.name
            )));
        };
        for (key, (topic, _)) in topics.keys().into_iter().enumerate() {
            routes.entry(topic).or_default().push((c, key));
        }
    }
    let file = std::fs::File::open(path)
        .map_err(|e| ReplayError::Input(InputError::new(path, InputErrorKind::OpenRecording(e))))?;
    let mut reader = McapReader::new(std::io::BufReader::new(file))
        .map_err(|e| foreign(format!("not a readable MCAP file: {e}")))?;
    // A file with a summary lists its topics up front.
    let listed: Vec<String> = reader.topics().iter().map(|t| t.topic.clone()).collect();
    let missing = |present: &[String]| {
        let mut absent: Vec<&str> = routes
            .keys()
            .copied()
            .filter(|t| !present.iter().any(|p| p == t))
            .collect();
        absent.sort_unstable();
        absent.first().map(|topic| {
            let mut known: Vec<&str> = present.iter().map(String::as_str).collect();
            known.sort_unstable();
            known.dedup();
            foreign(format!(
                "topic \"{topic}\" is not in the recording (its topics: {})",
                known.join(", ")
            ))
        })
    };
    if !listed.is_empty()
        && let Some(e) = missing(&listed)
    {
        return Err(e);
    }
    let mut readers: HashMap<u16, Reader> = HashMap::new();
    let mut out = ForeignReplayed::default();
    while let Some(event) = reader
        .next_event()
        .map_err(|e| ReplayError::Input(InputError::new(path, InputErrorKind::Read(e))))?
    {
        let Event::Message(message) = event else {
            continue;
        };
        out.messages += 1;
        let topic = message.topic.topic.as_str();
        let Some(route) = routes.get(topic) else {
            continue;
        };
        *out.by_topic.entry(topic.to_owned()).or_insert(0) += 1;
        let t = &message.topic;
        let json = readers
            .entry(t.id)
            .or_insert_with(|| {
                reader_of(
                    &t.message_encoding,
                    &t.schema_encoding,
                    &t.schema,
                    &t.schema_data,
                )
            })
            .json(message.data);
        #[allow(clippy::cast_precision_loss)]
        let publish_time = message.publish_time as f64 / 1e9;
        for &(c, tag) in route {
            let pipeline = &mut pipelines[c];
            match &json {
                Ok(json) => {
                    pipeline.payload(
                        json,
                        glrmon_runtime::Envelope {
                            tag,
                            source_time: Some(publish_time),
                            ..Default::default()
                        },
                        limits,
                        message.log_time,
                        fanout,
                    )?;
                }
                Err(why) => {
                    let entry = out
                        .unreadable
                        .entry(topic.to_owned())
                        .or_insert_with(|| (0, why.clone()));
                    entry.0 += 1;
                    let text = format!(
                        "channel \"{}\": topic {topic}: message {} cannot be read: {why}",
                        pipeline.name(),
                        out.messages
                    );
                    pipeline.rejected(
                        ErrorCode::WrongType,
                        text,
                        None,
                        None,
                        message.log_time,
                        fanout,
                    )?;
                }
            }
        }
    }
    if listed.is_empty() {
        // No summary: a topic never seen is one the file does not have.
        let seen: Vec<String> = reader.topics().iter().map(|t| t.topic.clone()).collect();
        if let Some(e) = missing(&seen) {
            return Err(e);
        }
    }
    out.damage = reader
        .damage()
        .iter()
        .map(|d| format!("damaged: {d}"))
        .collect();
    match reader.end() {
        ReadEnd::Finished | ReadEnd::Reading => {}
        ReadEnd::Truncated { at, .. } => out.damage.push(format!(
            "the file is unfinished (no footer): read up to byte {at}"
        )),
        ReadEnd::Unreadable { at, reason } => {
            out.damage
                .push(format!("unreadable from byte {at}: {reason}"));
        }
    }
    Ok(out)
}

/// One channel's samples from a recording glrmon did not write, formed by its
/// `[channels.topics]` as a replay forms them, one at a time, for the batch tools
/// (calibration, identification, diagnosis). A message that cannot be read, a payload
/// the tag decoder refuses and a stale tag (a gap) are [`Skipped`] items in their
/// place; the file is streamed as by [`replay_foreign_mcap`].
#[derive(Debug)]
pub struct ForeignSamples {
    path: std::path::PathBuf,
    channel: String,
    reader: McapReader<std::io::BufReader<std::fs::File>>,
    /// The tag numbers of each mapped topic.
    routes: HashMap<String, Vec<usize>>,
    readers: HashMap<u16, Reader>,
    decoder: TagDecoder,
    limits: DecodeLimits,
    formed: Vec<glrmon_wire::Sample>,
    pending: std::collections::VecDeque<Result<glrmon_wire::Sample, Skipped>>,
    messages: u64,
}

impl std::fmt::Debug for Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Reader::Json => "json",
            Reader::Ros2(_) => "ros2msg",
            Reader::Protobuf(_) => "protobuf",
            Reader::Unreadable(_) => "unreadable",
        })
    }
}

impl ForeignSamples {
    /// Opens `path` for `channel`, whose `[channels.topics]` maps the recording's topics
    /// to its signals.
    ///
    /// # Errors
    /// [`InputErrorKind::Foreign`] when the channel has no `[channels.topics]`, the file
    /// is not MCAP, or a mapped topic is not in it; [`InputErrorKind::OpenRecording`]
    /// when it cannot be opened.
    pub fn open(path: &Path, channel: &Channel) -> Result<Self, InputError> {
        let foreign = |m: String| InputError::new(path, InputErrorKind::Foreign(m));
        let Some(topics) = &channel.topics else {
            return Err(foreign(format!(
                "channel \"{}\" has no [channels.topics]: which topics of this recording \
                 give its signals?",
                channel.name
            )));
        };
        let mut routes: HashMap<String, Vec<usize>> = HashMap::new();
        for (tag, (topic, _)) in topics.keys().into_iter().enumerate() {
            routes.entry(topic.to_owned()).or_default().push(tag);
        }
        let file = std::fs::File::open(path)
            .map_err(|e| InputError::new(path, InputErrorKind::OpenRecording(e)))?;
        let reader = McapReader::new(std::io::BufReader::new(file))
            .map_err(|e| foreign(format!("not a readable MCAP file: {e}")))?;
        let listed: Vec<String> = reader.topics().iter().map(|t| t.topic.clone()).collect();
        if !listed.is_empty()
            && let Some(topic) = routes.keys().filter(|t| !listed.contains(t)).min()
        {
            let mut known = listed.clone();
            known.sort_unstable();
            known.dedup();
            return Err(foreign(format!(
                "topic \"{topic}\" is not in the recording (its topics: {})",
                known.join(", ")
            )));
        }
        let d = channel.dims;
        Ok(Self {
            path: path.to_owned(),
            channel: channel.name.clone(),
            reader,
            routes,
            readers: HashMap::new(),
            decoder: TagDecoder::new(topics.clone(), d.inputs, d.outputs, d.signals),
            limits: DecodeLimits::default(),
            formed: Vec::new(),
            pending: std::collections::VecDeque::new(),
            messages: 0,
        })
    }

    /// The next sample, or why there is none at its place; `None` at the end.
    ///
    /// # Errors
    /// [`InputErrorKind::Read`] on an I/O error, [`InputErrorKind::Damaged`] at the end
    /// of a file that lost data to damage (its samples would not be consecutive).
    pub fn next_sample(
        &mut self,
    ) -> Result<Option<Result<glrmon_wire::Sample, Skipped>>, InputError> {
        loop {
            if let Some(item) = self.pending.pop_front() {
                return Ok(Some(item));
            }
            let event = self
                .reader
                .next_event()
                .map_err(|e| InputError::new(&self.path, InputErrorKind::Read(e)))?;
            let Some(event) = event else {
                return self.end();
            };
            let Event::Message(message) = event else {
                continue;
            };
            self.messages += 1;
            let t = &message.topic;
            let Some(tags) = self.routes.get(&t.topic) else {
                continue;
            };
            let json = self
                .readers
                .entry(t.id)
                .or_insert_with(|| {
                    reader_of(
                        &t.message_encoding,
                        &t.schema_encoding,
                        &t.schema,
                        &t.schema_data,
                    )
                })
                .json(message.data);
            let json = match json {
                Ok(json) => json,
                Err(why) => {
                    self.pending.push_back(Err(Skipped {
                        reason: ErrorCode::WrongType.as_str(),
                        message: format!(
                            "message {} (topic {}) cannot be read: {why}",
                            self.messages, t.topic
                        ),
                    }));
                    continue;
                }
            };
            #[allow(clippy::cast_precision_loss)]
            let arrival = glrmon_runtime::Arrival {
                source_time: Some(message.publish_time as f64 / 1e9),
                received: message.log_time as f64 / 1e9,
                declared: glrmon_runtime::Declared::Nothing,
            };
            for &tag in tags {
                let decoded = self.decoder.decode_tag(
                    &self.channel,
                    tag,
                    arrival,
                    &json,
                    &self.limits,
                    &mut self.formed,
                );
                match decoded {
                    Ok(()) => {
                        for mut s in self.formed.drain(..) {
                            if s.t.is_none() {
                                s.t = arrival.source_time;
                            }
                            self.pending.push_back(Ok(s));
                        }
                    }
                    Err(e) => self.pending.push_back(Err(Skipped {
                        reason: e.code().as_str(),
                        message: format!("message {}: {e}", self.messages),
                    })),
                }
                if let Some(notice) = self.decoder.take_notice() {
                    self.pending.push_back(Err(Skipped {
                        reason: notice.code().as_str(),
                        message: format!("message {}: {notice}", self.messages),
                    }));
                }
            }
        }
    }

    /// The end of the file: an error when damage cost data.
    fn end(&self) -> Result<Option<Result<glrmon_wire::Sample, Skipped>>, InputError> {
        let mut lines: Vec<String> = (self.reader.damage().iter())
            .map(|d| format!("damaged: {d}"))
            .collect();
        match self.reader.end() {
            ReadEnd::Finished | ReadEnd::Reading => {}
            ReadEnd::Truncated { at, .. } => lines.push(format!(
                "the file is unfinished (no footer): read up to byte {at}"
            )),
            ReadEnd::Unreadable { at, reason } => {
                lines.push(format!("unreadable from byte {at}: {reason}"));
            }
        }
        if lines.is_empty() {
            Ok(None)
        } else {
            Err(InputError::new(&self.path, InputErrorKind::Damaged(lines)))
        }
    }

    /// Messages read so far (of every topic).
    #[must_use]
    pub fn messages(&self) -> u64 {
        self.messages
    }
}

/// One message of a recording glrmon did not write, as the JSON document a channel's
/// field paths read: `data` as it is for the `json` message encoding, decoded by the
/// topic's `ros2msg` schema for `cdr`, by its descriptor set for `protobuf`. The schema
/// is parsed anew on each call (a replay parses it once per topic).
///
/// # Errors
/// Why the schema or the message cannot be read.
pub fn foreign_message_json(
    message_encoding: &str,
    schema_encoding: &str,
    schema_name: &str,
    schema: &[u8],
    data: Vec<u8>,
) -> Result<Vec<u8>, String> {
    reader_of(message_encoding, schema_encoding, schema_name, schema).json(data)
}

impl Reader {
    /// A message of the topic as a JSON document.
    fn json(&self, data: Vec<u8>) -> Result<Vec<u8>, String> {
        match self {
            Reader::Json => Ok(data),
            Reader::Ros2(schema) => schema
                .decode(&data)
                .map(|v| serde_json::to_vec(&v).unwrap_or_default()),
            Reader::Protobuf(schema) => schema
                .decode(&data)
                .map(|v| serde_json::to_vec(&v).unwrap_or_default()),
            Reader::Unreadable(why) => Err(why.clone()),
        }
    }
}

fn reader_of(
    message_encoding: &str,
    schema_encoding: &str,
    schema_name: &str,
    schema: &[u8],
) -> Reader {
    match (message_encoding, schema_encoding) {
        ("json", _) => Reader::Json,
        ("cdr", "ros2msg") => {
            match std::str::from_utf8(schema)
                .map_err(|e| e.to_string())
                .and_then(|text| ros2::Schema::parse(schema_name, text))
            {
                Ok(parsed) => Reader::Ros2(Box::new(parsed)),
                Err(e) => Reader::Unreadable(format!("its ros2msg schema {schema_name}: {e}")),
            }
        }
        ("protobuf", "protobuf") => match protobuf::Schema::parse(schema_name, schema) {
            Ok(parsed) => Reader::Protobuf(Box::new(parsed)),
            Err(e) => Reader::Unreadable(format!("its protobuf schema {schema_name}: {e}")),
        },
        (encoding, schema) => Reader::Unreadable(format!(
            "messages encoded as \"{encoding}\" (schema encoding {}) are not read: JSON, and \
             ROS 2 CDR with a ros2msg schema, and protobuf with a protobuf schema, are",
            if schema.is_empty() { "none" } else { schema }
        )),
    }
}
