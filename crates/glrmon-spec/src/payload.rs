//! How a channel's payloads are encoded (`[[channels]] payload`, with `[channels.cdr]`
//! and `[channels.raw]` for the binary formats).
//!
//! A new format is one variant here with its name, and one arm of the runtime's
//! decoder factory (`glrmon_runtime::decoder`).

/// The encoding of the payloads a channel receives on its key.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum PayloadFormat {
    /// A JSON sample object or an array of them (docs/WIRE.md).
    #[default]
    Json,
    /// A ROS 2 message in CDR (`[channels.cdr] message`), as rmw_zenoh publishes it.
    Cdr(CdrMessage),
    /// A Sparkplug B payload (Eclipse Tahu protobuf): the channel's signals are the
    /// metrics named as its columns (`[channels.columns]`, else `u0`, `y0`, …).
    Sparkplug,
    /// Records of little-endian f64 values in the order `[channels.raw] layout` gives;
    /// a payload holds one or more records.
    Raw(RawLayout),
}

impl PayloadFormat {
    /// The names the configuration accepts, in declaration order.
    pub const NAMES: [&'static str; 4] = ["json", "cdr", "sparkplug", "raw"];

    /// The configuration's name of the format.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Self::Json => Self::NAMES[0],
            Self::Cdr(_) => Self::NAMES[1],
            Self::Sparkplug => Self::NAMES[2],
            Self::Raw(_) => Self::NAMES[3],
        }
    }
}

/// The ROS 2 message type a `cdr` channel receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CdrMessage {
    /// `std_msgs/msg/Float64MultiArray`: `data` (from `layout.data_offset` on) holds the
    /// inputs, then the outputs, then the scheduling signals; the layout's dimensions
    /// are not read. The sample's time is the transport's.
    #[default]
    Float64MultiArray,
    /// `glrmon_msgs/msg/Sample` (docs/WIRE.md): `int64 k` (−1: none), `float64 t` (NaN:
    /// none), `float64[] u`, `float64[] y`, `float64[] p`.
    Sample,
}

impl CdrMessage {
    /// Every message type, in declaration order (a type's index is its discriminant).
    pub const ALL: [Self; 2] = [Self::Float64MultiArray, Self::Sample];

    /// The ROS 2 type names the configuration accepts, as [`CdrMessage::ALL`].
    pub const NAMES: [&'static str; 2] =
        ["std_msgs/msg/Float64MultiArray", "glrmon_msgs/msg/Sample"];

    /// The ROS 2 name of the type.
    #[must_use]
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The type named `name` (`pkg/msg/Type`, or the ROS 1 style `pkg/Type`).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == name || m.name().replacen("/msg/", "/", 1) == name)
    }
}

/// One 8-byte little-endian f64 of a raw record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawField {
    /// The sample index (a non-negative integer below 2⁵³).
    K,
    /// The sample time, in seconds.
    T,
    /// Input u_i.
    U(usize),
    /// Output y_i.
    Y(usize),
    /// Scheduling signal p_i.
    P(usize),
    /// Eight bytes not read (`"_"`).
    Skip,
}

/// The record of a `raw` channel: each field an 8-byte little-endian f64, every signal
/// of the channel exactly once.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RawLayout {
    /// The fields in byte order.
    pub fields: Vec<RawField>,
}

impl RawLayout {
    /// Bytes per record.
    #[must_use]
    pub fn record_bytes(&self) -> usize {
        8 * self.fields.len()
    }
}

/// A channel assembled from tags (`[channels.tags]`): each signal on a key of its own.
#[derive(Debug, Clone, PartialEq)]
pub struct Tags {
    /// When a sample is formed.
    pub formation: Formation,
    /// Periods (or triggers) a silent signal keeps its last value; beyond, samples are
    /// gaps.
    pub hold: u32,
    /// The time of a tag's value, where the tag has no `time_field`.
    pub time: TagTime,
    /// One per signal, in the sample's order: the inputs, the outputs, the scheduling
    /// signals.
    pub tags: Vec<Tag>,
}

impl Tags {
    /// The distinct keys, in the order of their first tag, each with the indices of
    /// the tags it carries (several when they read different fields of one payload): a
    /// payload's tag number is its key's index here.
    #[must_use]
    pub fn keys(&self) -> Vec<(&str, Vec<usize>)> {
        let mut keys: Vec<(&str, Vec<usize>)> = Vec::new();
        for (i, tag) in self.tags.iter().enumerate() {
            match keys.iter_mut().find(|(k, _)| *k == tag.key) {
                Some((_, tags)) => tags.push(i),
                None => keys.push((tag.key.as_str(), vec![i])),
            }
        }
        keys
    }
}

/// When a tag channel forms a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Formation {
    /// At every multiple of this period (seconds).
    Period(f64),
    /// At each value of the signal at this index of [`Tags::tags`].
    Trigger(usize),
}

/// Which clock times a tag's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TagTime {
    /// The publication's Zenoh timestamp (its arrival when it has none).
    #[default]
    Zenoh,
    /// Its arrival at glrmon.
    Arrival,
}

impl TagTime {
    /// The names the configuration accepts.
    pub const NAMES: [&'static str; 2] = ["zenoh", "arrival"];
}

/// One signal of a tag channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tag {
    /// The signal's column name (`u0`, or its `[channels.columns]` name).
    pub signal: String,
    /// The key expression it arrives on.
    pub key: String,
    /// The path of its value in a JSON object; empty: the payload is the number.
    pub field: Vec<String>,
    /// The path of its time (seconds since the Unix epoch) in the JSON object.
    pub time_field: Option<Vec<String>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_cdr_message_round_trips_through_its_name() {
        for (message, name) in CdrMessage::ALL.into_iter().zip(CdrMessage::NAMES) {
            assert_eq!(CdrMessage::from_name(name), Some(message));
            assert_eq!(message.name(), name);
        }
        assert_eq!(
            CdrMessage::from_name("std_msgs/Float64MultiArray"),
            Some(CdrMessage::Float64MultiArray)
        );
        assert_eq!(
            CdrMessage::from_name("std_msgs/msg/Float32MultiArray"),
            None
        );
    }

    #[test]
    fn an_unknown_format_is_refused_with_the_names() {
        let cfg = crate::parse(
            r#"
[[channels]]
name = "tank"
payload = "cbor"
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
"#,
        );
        let err = cfg.unwrap_err().to_string();
        assert!(
            err.contains("payload") && err.contains("\"cbor\" is not one of json, cdr, sparkplug"),
            "{err}"
        );
    }
}
