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
/// them, in the file's order.
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
    let bytes = std::fs::read(path)
        .map_err(|e| ReplayError::Input(InputError::new(path, InputErrorKind::OpenRecording(e))))?;
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
    let summary = ::mcap::Summary::read(&bytes)
        .map_err(|e| foreign(format!("not a readable MCAP file: {e}")))?;
    let present: Vec<&str> = summary
        .as_ref()
        .map(|s| s.channels.values().map(|c| c.topic.as_str()).collect())
        .unwrap_or_default();
    if summary.is_some() {
        for topic in routes.keys() {
            if !present.contains(topic) {
                let mut known = present.clone();
                known.sort_unstable();
                known.dedup();
                return Err(foreign(format!(
                    "topic \"{topic}\" is not in the recording (its topics: {})",
                    known.join(", ")
                )));
            }
        }
    }
    let mut readers: HashMap<u16, Reader> = HashMap::new();
    let mut out = ForeignReplayed::default();
    let stream = ::mcap::MessageStream::new(&bytes)
        .map_err(|e| foreign(format!("not an MCAP file: {e}")))?;
    for message in stream {
        let message = message
            .map_err(|e| foreign(format!("damaged after {} messages: {e}", out.messages)))?;
        out.messages += 1;
        let topic = message.channel.topic.as_str();
        let Some(route) = routes.get(topic) else {
            continue;
        };
        *out.by_topic.entry(topic.to_owned()).or_insert(0) += 1;
        let reader = readers
            .entry(message.channel.id)
            .or_insert_with(|| reader_of(&message.channel));
        let json = match reader {
            Reader::Json => Ok(message.data.to_vec()),
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
    Ok(out)
}

fn reader_of(channel: &::mcap::Channel<'_>) -> Reader {
    let schema = channel.schema.as_ref();
    match (
        channel.message_encoding.as_str(),
        schema.map(|s| s.encoding.as_str()),
    ) {
        ("json", _) => Reader::Json,
        ("cdr", Some("ros2msg")) => {
            let s = schema.expect("matched Some");
            match std::str::from_utf8(&s.data)
                .map_err(|e| e.to_string())
                .and_then(|text| ros2::Schema::parse(&s.name, text))
            {
                Ok(parsed) => Reader::Ros2(Box::new(parsed)),
                Err(e) => Reader::Unreadable(format!("its ros2msg schema {}: {e}", s.name)),
            }
        }
        (encoding, schema) => Reader::Unreadable(format!(
            "messages encoded as \"{encoding}\" (schema encoding {}) are not read: JSON, and \
             ROS 2 CDR with a ros2msg schema, are",
            schema.unwrap_or("none")
        )),
    }
}
