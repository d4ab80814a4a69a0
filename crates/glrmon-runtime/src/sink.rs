//! The output side of a pipeline: what a [`Sink`] receives and what it asks for.

use std::sync::Arc;

use glrmon_wire::{IntakeEvent, Record, Sample};

/// Index of a channel in the runtime (its position in the configuration).
pub type ChannelIndex = usize;

/// A record on its way to the sinks, encoded once.
#[derive(Debug, Clone)]
pub struct Output {
    /// The record.
    pub record: Record,
    /// Its JSON encoding (docs/WIRE.md), without a trailing newline.
    pub json: Vec<u8>,
    /// When the payload that produced it was received: nanoseconds since the Unix epoch.
    pub log_time_ns: u64,
    /// For a `stat` record, its position among the channel's `stat` records (0, 1, …),
    /// by which each sink applies its own decimation ([`Interest::stat_every`]).
    pub stat_index: Option<u64>,
}

/// What a channel's monitor was fed: a decoded sample or an [`IntakeEvent`].
#[derive(Debug, Clone, PartialEq)]
pub enum InputItem {
    /// A decoded sample, its `t` filled from the transport's timestamp where absent.
    Sample(Sample),
    /// Payloads dropped before the next one, or a refused payload.
    Intake(IntakeEvent),
}

/// An input on its way to the sinks that asked for inputs (recorders), in the order
/// the monitor saw it, before the records it produced.
#[derive(Debug, Clone)]
pub struct InputOutput {
    /// The channel's index in the configuration.
    pub channel: ChannelIndex,
    /// The channel's name.
    pub name: Arc<str>,
    /// What the monitor was fed.
    pub item: InputItem,
    /// Its JSON: a sample in the sample format, or the intake event.
    pub json: Vec<u8>,
    /// When its payload was received: nanoseconds since the Unix epoch.
    pub log_time_ns: u64,
}

/// What a sink wants besides the records every sink receives (all but `stat`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Interest {
    /// Every input ([`Sink::write_input`]): what recorders need to replay a run.
    pub inputs: bool,
    /// One `stat` record in this many per channel (0: none); `None`: the default of
    /// whoever drives the sinks ([`crate::RuntimeSettings::stat_every`] for the daemon).
    pub stat_every: Option<u64>,
}

/// Errors of a sink: the daemon logs them and goes on, a replay stops.
#[derive(Debug, thiserror::Error)]
#[error("sink {sink}: {message}")]
pub struct SinkError {
    /// The sink's name.
    pub sink: String,
    /// What failed.
    pub message: String,
}

/// Where results go: a Zenoh publisher, a recorder, a file, standard output…
///
/// A sink receives every record but `stat` (alarm, isolation, alarm end, diagnosis,
/// error, consistency), the `stat` records its [`Interest::stat_every`] keeps, and, if
/// [`Interest::inputs`] is set, every input before the records it produced. The same sink works in the daemon
/// (called from its output thread) and in `glrmon replay` (called in order on the
/// replay's thread): both feed it through a [`crate::Fanout`].
///
/// # Examples
///
/// A sink that counts alarms:
///
/// ```
/// use glrmon_runtime::{Output, Sink, SinkError};
/// use glrmon_wire::Record;
///
/// #[derive(Debug, Default)]
/// struct AlarmCounter(u64);
///
/// impl Sink for AlarmCounter {
///     fn name(&self) -> &str {
///         "alarm-counter"
///     }
///     fn write(&mut self, output: &Output) -> Result<(), SinkError> {
///         if matches!(output.record, Record::Alarm(_)) {
///             self.0 += 1;
///         }
///         Ok(())
///     }
/// }
/// ```
pub trait Sink: Send + 'static {
    /// A short name for messages.
    fn name(&self) -> &str;
    /// What the sink wants beyond the default (asked once, at start).
    fn interest(&self) -> Interest {
        Interest::default()
    }
    /// Delivers one input (only to sinks whose [`Interest::inputs`] is set).
    ///
    /// # Errors
    /// [`SinkError`] when the input could not be delivered.
    fn write_input(&mut self, _input: &InputOutput) -> Result<(), SinkError> {
        Ok(())
    }
    /// Delivers one record.
    ///
    /// # Errors
    /// [`SinkError`] when the record could not be delivered.
    fn write(&mut self, output: &Output) -> Result<(), SinkError>;
    /// Flushes buffered records (called when the daemon's output queue is idle, at
    /// least once a second under load).
    ///
    /// # Errors
    /// [`SinkError`] when the flush failed.
    fn flush(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    /// Called once after the last record: writes what only the end can write (a
    /// file's summary, a report). The default flushes.
    ///
    /// # Errors
    /// [`SinkError`] when closing failed.
    fn close(&mut self) -> Result<(), SinkError> {
        self.flush()
    }
}
