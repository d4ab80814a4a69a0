//! What an input or a record becomes in a recording: the one mapping both MCAP sinks
//! (the daemon's [`crate::Recorder`] and [`crate::McapFileSink`]) write by.

use std::borrow::Cow;

use glrmon_runtime::{InputItem, Output};

use crate::log::log_message;
use crate::schema::TopicKind;

/// The messages of one record, in order: on its own topic, then, for the records an
/// operator reads (alarms, isolation updates, ends, errors), a `foxglove.Log` on the
/// log topic. Records with no topic give none. Every message's publish time is its
/// log time (docs/WIRE.md).
pub(crate) fn record_messages(output: &Output) -> [Option<(TopicKind, Cow<'_, [u8]>)>; 2] {
    let Some(kind) = TopicKind::of_record(&output.record) else {
        return [None, None];
    };
    [
        Some((kind, Cow::Borrowed(output.json.as_slice()))),
        log_message(&output.record, output.log_time_ns)
            .map(|json| (TopicKind::Log, Cow::Owned(json))),
    ]
}

/// The topic of a recorded input: samples and intake events.
pub(crate) fn input_topic(item: &InputItem) -> TopicKind {
    match item {
        InputItem::Sample(_) => TopicKind::Inputs,
        InputItem::Intake(_) => TopicKind::Intake,
    }
}
