//! Recordings glrmon did not write (ROS 2 bags, Foxglove MCAP): each channel's
//! `[channels.topics]` says which topic and field give each of its signals, and how
//! samples are formed from them (a period, or each message of a trigger topic), as
//! `[channels.tags]` does for live keys. A message is read by its encoding: JSON as it
//! is; ROS 2 CDR by the `ros2msg` schema in the file ([`ros2`]); every message of a
//! mapped topic then goes, as a JSON document, to the channel's tag decoder, timed by
//! its publish time (`time = "zenoh"`) or its log time (`time = "arrival"`). The
//! pipeline and everything after it are the live ones.

mod ros2;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glrmon_record::{Event, McapReader, ReadEnd, Topic};
use glrmon_runtime::{ChannelPipeline, Fanout, PayloadDecoder, TagDecoder};
use glrmon_spec::Channel;
use glrmon_wire::{DecodeLimits, ErrorCode};

use crate::{InputError, InputErrorKind, ReplayError};

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
        let reader = readers
            .entry(message.topic.id)
            .or_insert_with(|| reader_of(&message.topic));
        let json = match reader {
            Reader::Json => Ok(message.data),
            Reader::Ros2(schema) => schema
                .decode(&message.data)
                .map(|v| serde_json::to_vec(&v).unwrap_or_default()),
            Reader::Unreadable(why) => Err(why.clone()),
        };
        #[allow(clippy::cast_precision_loss)]
        let publish_time = message.publish_time as f64 / 1e9;
        for &(c, tag) in route {
            let pipeline = &mut pipelines[c];
            match &json {
                Ok(json) => {
                    pipeline.payload(
                        json,
                        tag,
                        Some(publish_time),
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

fn reader_of(topic: &Topic) -> Reader {
    match (
        topic.message_encoding.as_str(),
        topic.schema_encoding.as_str(),
    ) {
        ("json", _) => Reader::Json,
        ("cdr", "ros2msg") => {
            match std::str::from_utf8(&topic.schema_data)
                .map_err(|e| e.to_string())
                .and_then(|text| ros2::Schema::parse(&topic.schema, text))
            {
                Ok(parsed) => Reader::Ros2(Box::new(parsed)),
                Err(e) => Reader::Unreadable(format!("its ros2msg schema {}: {e}", topic.schema)),
            }
        }
        (encoding, schema) => Reader::Unreadable(format!(
            "messages encoded as \"{encoding}\" (schema encoding {}) are not read: JSON, and \
             ROS 2 CDR with a ros2msg schema, are",
            if schema.is_empty() { "none" } else { schema }
        )),
    }
}
