//! One channel's path: payload → decoder → sample → monitor → encoded records → an
//! [`Emit`]ter.
//!
//! The daemon's workers hand raw payloads ([`ChannelPipeline::payload`]), `glrmon
//! replay` the samples a recording or CSV file holds ([`ChannelPipeline::sample`],
//! [`ChannelPipeline::feed`]); from the sample on they drive the same code and differ
//! only in the emitter: a worker sends to the output thread's [`Fanout`], a replay
//! hands to its [`Fanout`] directly. The records a replay writes therefore equal
//! the live ones by construction: the same code counts, decimates and encodes them.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use glrmon_monitor::Monitor;
use glrmon_wire::{
    DecodeLimits, EncodeError, ErrorCode, ErrorRecord, IntakeEvent, Record, Sample, Stage,
    encode_intake, encode_json, encode_sample,
};

use crate::ChannelStats;
use crate::decode::{Arrival, Declared, JsonDecoder, PayloadDecoder};
use crate::fanout::{DeliveryPlan, Fanout};
use crate::sink::{ChannelIndex, InputItem, InputOutput, Output, SinkError};

/// Capacity of a fresh buffer for one record's JSON.
const RECORD_JSON_CAPACITY: usize = 256;
/// Capacity of a fresh buffer for one input's JSON.
const INPUT_JSON_CAPACITY: usize = 128;
/// Longest refused payload kept, as text, in its [`IntakeEvent::Rejected`].
const MAX_KEPT_PAYLOAD: usize = 64 * 1024;

/// A refused payload as text for the post-mortem: as it is when it is UTF-8, else
/// (a binary format) `0x` and its bytes in hexadecimal, so that nothing is lost.
fn kept_text(payload: &[u8]) -> String {
    use std::fmt::Write;
    match std::str::from_utf8(payload) {
        Ok(text) => text.to_owned(),
        Err(_) => {
            let mut hex = String::with_capacity(2 + 2 * payload.len());
            hex.push_str("0x");
            for b in payload {
                let _ = write!(hex, "{b:02x}");
            }
            hex
        }
    }
}

/// Where a pipeline hands its inputs and records, in order: each input before the
/// records it produced.
pub trait Emit {
    /// Hands over one input (called only when the plan asks for inputs).
    ///
    /// # Errors
    /// [`SinkError`] when a sink failed.
    fn input(&mut self, input: InputOutput) -> Result<(), SinkError>;
    /// Hands over one record.
    ///
    /// # Errors
    /// [`SinkError`] when a sink failed.
    fn record(&mut self, output: Output) -> Result<(), SinkError>;
    /// An empty buffer to encode the next record into: an emitter that is done with
    /// the records it was handed gives their buffers back here, so a replay encodes
    /// without allocating.
    fn buffer(&mut self) -> Vec<u8> {
        Vec::with_capacity(RECORD_JSON_CAPACITY)
    }
}

/// Hands everything to the sinks at once (a replay): the first sink error is returned
/// after every sink had its turn.
impl Emit for Fanout {
    fn input(&mut self, input: InputOutput) -> Result<(), SinkError> {
        let mut first = None;
        Fanout::input(self, &input, &mut |e| {
            first.get_or_insert(e);
        });
        first.map_or(Ok(()), Err)
    }

    fn record(&mut self, output: Output) -> Result<(), SinkError> {
        let mut first = None;
        Fanout::record(self, &output, &mut |e| {
            first.get_or_insert(e);
        });
        self.give_back(output.json);
        first.map_or(Ok(()), Err)
    }

    fn buffer(&mut self) -> Vec<u8> {
        self.take_buffer(RECORD_JSON_CAPACITY)
    }
}

/// Why a pipeline could not hand on everything it produced.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// A record or input could not be encoded (it was not handed on; the pipeline
    /// went on with the next one).
    #[error("channel \"{channel}\": {what} could not be encoded: {source}")]
    Encode {
        /// The channel.
        channel: String,
        /// `record` or `input`.
        what: &'static str,
        /// Why.
        source: EncodeError,
    },
    /// A sink failed (the pipeline stopped handing on this input's records).
    #[error(transparent)]
    Sink(#[from] SinkError),
}

/// One channel's decoder and monitor with the bookkeeping around them: the inputs and
/// records it hands on, the decimation of `stat` records, the channel's counters.
///
/// # Examples
///
/// A replay of two samples into an in-memory sink:
///
/// ```
/// use glrmon_monitor::Monitor;
/// use glrmon_runtime::{ChannelPipeline, Fanout, MemorySink, Sink};
/// use glrmon_wire::Sample;
///
/// let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
/// let monitor = Monitor::from_channel(&cfg.channels[0]).unwrap();
/// let memory = MemorySink::default();
/// let records = memory.records();
/// let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
/// let mut pipeline = ChannelPipeline::new(0, monitor, fanout.plan());
/// let dims = cfg.channels[0].dims;
/// for k in 0..2 {
///     let sample = Sample {
///         k: Some(k),
///         t: None,
///         u: vec![0.0; dims.inputs],
///         y: vec![0.0; dims.outputs],
///         p: vec![0.0; dims.signals],
///     };
///     pipeline.sample(&sample, 0, &mut fanout).unwrap();
/// }
/// fanout.close(&mut |e| panic!("{e}"));
/// assert_eq!(records.lock().unwrap().len(), 2); // one `stat` per sample
/// assert_eq!(pipeline.stats().errors.lock().unwrap().len(), 0);
/// ```
#[derive(Debug)]
pub struct ChannelPipeline {
    index: ChannelIndex,
    name: Arc<str>,
    monitor: Monitor,
    decoder: Box<dyn PayloadDecoder>,
    /// The samples of the payload being processed (buffers reused).
    samples: Vec<Sample>,
    stats: Arc<ChannelStats>,
    plan: DeliveryPlan,
    /// `stat` records produced so far (a sink's decimation counts them).
    stat_count: u64,
    records: Vec<Record>,
}

/// What came with a payload besides its bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Envelope {
    /// The channel's input key it arrived on (`glrmon_spec::Channel::input_keys`): 0
    /// unless the channel is assembled from tags.
    pub tag: usize,
    /// The transport's timestamp (seconds since the Unix epoch), if any.
    pub source_time: Option<f64>,
    /// The message type the transport declared.
    pub declared: Declared,
}

impl ChannelPipeline {
    /// A pipeline for the channel at `index` feeding sinks with this `plan`
    /// ([`Fanout::plan`]); the monitor builds `stat` records only if a sink keeps some.
    /// Its payloads are JSON until [`ChannelPipeline::with_decoder`] says otherwise.
    #[must_use]
    pub fn new(index: ChannelIndex, mut monitor: Monitor, plan: DeliveryPlan) -> Self {
        monitor.set_stat_records(plan.wants_stats());
        Self {
            index,
            name: Arc::from(monitor.channel()),
            monitor,
            decoder: Box::new(JsonDecoder),
            samples: Vec::new(),
            stats: Arc::new(ChannelStats::default()),
            plan,
            stat_count: 0,
            records: Vec::new(),
        }
    }

    /// Uses `stats` as the channel's counters (shared with intake and status queries).
    #[must_use]
    pub fn with_stats(mut self, stats: Arc<ChannelStats>) -> Self {
        self.stats = stats;
        self
    }

    /// Decodes this channel's payloads with `decoder` ([`crate::decoder`] builds the
    /// one a configuration names).
    #[must_use]
    pub fn with_decoder(mut self, decoder: Box<dyn PayloadDecoder>) -> Self {
        self.decoder = decoder;
        self
    }

    /// The payload decoder.
    #[must_use]
    pub fn decoder(&self) -> &dyn PayloadDecoder {
        self.decoder.as_ref()
    }

    /// One payload as received with `envelope` (its input key, the transport's
    /// timestamp and declared type): decoded within `limits`, then each of its samples
    /// as by [`ChannelPipeline::sample`], with the transport's timestamp as the time of
    /// those that carry none. A payload that cannot be decoded is
    /// [`ChannelPipeline::rejected`] whole, with its text if short enough; what the
    /// decoder noticed about the stream (a tag gone silent) follows the samples as an
    /// `error` record.
    ///
    /// # Errors
    /// As [`ChannelPipeline::sample`]; the first error, after every sample had its turn.
    pub fn payload(
        &mut self,
        payload: &[u8],
        envelope: Envelope,
        limits: &DecodeLimits,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let Envelope {
            tag,
            source_time,
            declared,
        } = envelope;
        let mut samples = std::mem::take(&mut self.samples);
        #[allow(clippy::cast_precision_loss)]
        let arrival = Arrival {
            source_time,
            received: log_time_ns as f64 / 1e9,
            declared,
        };
        let decoded =
            self.decoder
                .decode_tag(&self.name, tag, arrival, payload, limits, &mut samples);
        let mut first = None;
        match decoded {
            Ok(()) => {
                for s in &mut samples {
                    if s.t.is_none() {
                        s.t = source_time;
                    }
                    keep_first(&mut first, self.sample(s, log_time_ns, emit));
                }
            }
            Err(e) => {
                let kept = (payload.len() <= MAX_KEPT_PAYLOAD).then(|| kept_text(payload));
                keep_first(
                    &mut first,
                    self.rejected(e.code(), e.to_string(), None, kept, log_time_ns, emit),
                );
            }
        }
        if let Some(notice) = self.decoder.take_notice() {
            keep_first(
                &mut first,
                self.rejected(
                    notice.code(),
                    notice.to_string(),
                    None,
                    None,
                    log_time_ns,
                    emit,
                ),
            );
        }
        self.samples = samples;
        first.map_or(Ok(()), Err)
    }

    /// One decoded sample: the input (if wanted), then the monitor's records.
    ///
    /// # Errors
    /// [`PipelineError`] when something could not be encoded or a sink failed.
    pub fn sample(
        &mut self,
        sample: &Sample,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let mut first = None;
        if self.plan.inputs {
            keep_first(
                &mut first,
                self.input(InputItem::Sample(sample.clone()), log_time_ns, emit),
            );
        }
        self.monitor.on_sample(sample, &mut self.records);
        keep_first(&mut first, self.hand_on_records(log_time_ns, emit));
        first.map_or(Ok(()), Err)
    }

    /// `count` payloads went missing before the next one: the monitor sees the next
    /// sample after a gap.
    ///
    /// # Errors
    /// As [`ChannelPipeline::sample`].
    pub fn dropped(
        &mut self,
        count: u64,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        self.monitor.note_missing(count);
        if self.plan.inputs {
            self.input(
                InputItem::Intake(IntakeEvent::Dropped { count }),
                log_time_ns,
                emit,
            )?;
        }
        Ok(())
    }

    /// This instance took the channel over (assignment `generation`): the monitor
    /// resumes ([`Monitor::resume`]: the filter restarts at the next sample and
    /// settles), and a recording holds the event so that a replay resumes there too.
    ///
    /// # Errors
    /// As [`ChannelPipeline::sample`]; the monitor resumes even then.
    pub fn resumed(
        &mut self,
        instance: &str,
        generation: u64,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let mut first = None;
        if self.plan.inputs {
            let event = IntakeEvent::Resumed {
                instance: instance.to_owned(),
                generation,
            };
            keep_first(
                &mut first,
                self.input(InputItem::Intake(event), log_time_ns, emit),
            );
        }
        if let Err(e) = self.monitor.resume() {
            self.records.push(Record::Error(ErrorRecord {
                channel: self.monitor.channel().to_owned(),
                k: None,
                code: ErrorCode::Numerical,
                message: format!(
                    "channel \"{}\": taking the channel over: {e}",
                    self.monitor.channel()
                ),
                stage: Stage::Processing,
            }));
            keep_first(&mut first, self.hand_on_records(log_time_ns, emit));
        }
        first.map_or(Ok(()), Err)
    }

    /// A payload or row refused before the monitor (undecodable, too large): the
    /// refusal as an input, then its `error` record (`k` if the refused input named
    /// one).
    ///
    /// # Errors
    /// As [`ChannelPipeline::sample`].
    pub fn rejected(
        &mut self,
        code: ErrorCode,
        message: String,
        k: Option<u64>,
        payload: Option<String>,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let mut first = None;
        if self.plan.inputs {
            let event = IntakeEvent::Rejected {
                code,
                message: message.clone(),
                payload,
            };
            keep_first(
                &mut first,
                self.input(InputItem::Intake(event), log_time_ns, emit),
            );
        }
        self.records.push(Record::Error(ErrorRecord {
            channel: self.monitor.channel().to_owned(),
            k,
            code,
            message,
            stage: Stage::Receiving,
        }));
        keep_first(&mut first, self.hand_on_records(log_time_ns, emit));
        first.map_or(Ok(()), Err)
    }

    /// A recorded input, as the monitor first saw it (replay of a recording).
    ///
    /// # Errors
    /// As [`ChannelPipeline::sample`].
    pub fn feed(
        &mut self,
        item: &InputItem,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        match item {
            InputItem::Sample(s) => self.sample(s, log_time_ns, emit),
            InputItem::Intake(IntakeEvent::Dropped { count }) => {
                self.dropped(*count, log_time_ns, emit)
            }
            InputItem::Intake(IntakeEvent::Rejected {
                code,
                message,
                payload,
            }) => self.rejected(
                *code,
                message.clone(),
                None,
                payload.clone(),
                log_time_ns,
                emit,
            ),
            InputItem::Intake(IntakeEvent::Resumed {
                instance,
                generation,
            }) => self.resumed(instance, *generation, log_time_ns, emit),
        }
    }

    /// Copies the monitor's counters into the shared [`ChannelStats`] (the daemon
    /// does it once per payload, for status queries and metrics).
    pub fn publish_counters(&self) {
        let c = self.monitor.counters();
        self.stats.samples.store(c.samples, Ordering::Relaxed);
        self.stats.alarms.store(c.alarms, Ordering::Relaxed);
        self.stats
            .alarm_active
            .store(u64::from(self.monitor.alarm_active()), Ordering::Relaxed);
        self.stats.next_k.store(
            self.monitor.detector().next_index().unwrap_or(0),
            Ordering::Relaxed,
        );
    }

    /// The channel's index.
    #[must_use]
    pub fn index(&self) -> ChannelIndex {
        self.index
    }

    /// The channel's name.
    #[must_use]
    pub fn name(&self) -> &Arc<str> {
        &self.name
    }

    /// The monitor.
    #[must_use]
    pub fn monitor(&self) -> &Monitor {
        &self.monitor
    }

    /// The monitor, to retune it.
    pub fn monitor_mut(&mut self) -> &mut Monitor {
        &mut self.monitor
    }

    /// Every `error` record of the channel so far: the monitor's rejections and the
    /// payloads or rows refused before it.
    #[must_use]
    pub fn error_total(&self) -> u64 {
        self.stats
            .errors
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .values()
            .sum()
    }

    /// The channel's counters; `errors` counts every `error` record by code.
    #[must_use]
    pub fn stats(&self) -> &Arc<ChannelStats> {
        &self.stats
    }

    fn input(
        &mut self,
        item: InputItem,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let mut json = Vec::with_capacity(INPUT_JSON_CAPACITY);
        let encoded = match &item {
            InputItem::Sample(s) => encode_sample(&self.name, s, &mut json),
            InputItem::Intake(e) => encode_intake(&self.name, e, &mut json),
        };
        encoded.map_err(|source| PipelineError::Encode {
            channel: self.name.to_string(),
            what: "input",
            source,
        })?;
        emit.input(InputOutput {
            channel: self.index,
            name: self.name.clone(),
            item,
            json,
            log_time_ns,
        })?;
        Ok(())
    }

    /// Counts errors, decimates `stat` records, encodes and hands on the records of
    /// one input.
    fn hand_on_records(
        &mut self,
        log_time_ns: u64,
        emit: &mut dyn Emit,
    ) -> Result<(), PipelineError> {
        let mut first = None;
        let mut records = std::mem::take(&mut self.records);
        for record in records.drain(..) {
            if let Record::Error(e) = &record {
                let mut errors = self
                    .stats
                    .errors
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                *errors.entry(e.code.as_str()).or_insert(0) += 1;
            }
            let stat_index = if matches!(record, Record::Stat(_)) {
                let index = self.stat_count;
                self.stat_count += 1;
                if !self.plan.wants_stat(index) {
                    continue;
                }
                Some(index)
            } else {
                None
            };
            let mut json = emit.buffer();
            let record = match encode_json(&record, &mut json) {
                Ok(()) => record,
                Err(source) => {
                    // Never a silent loss: the record that cannot be encoded (a number
                    // JSON cannot hold) is replaced by an error record saying so, which
                    // is counted and goes wherever the record would have gone.
                    let error = ErrorRecord {
                        channel: self.name.to_string(),
                        k: record.k(),
                        code: ErrorCode::Numerical,
                        message: format!(
                            "channel \"{}\": the {} record at k = {} could not be encoded \
                             and is replaced by this error: {source}",
                            self.name,
                            record.kind_str(),
                            record.k().map_or_else(|| "?".to_owned(), |k| k.to_string())
                        ),
                        stage: Stage::Sending,
                    };
                    *self
                        .stats
                        .errors
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .entry(ErrorCode::Numerical.as_str())
                        .or_insert(0) += 1;
                    let error = Record::Error(error);
                    json.clear();
                    if let Err(source) = encode_json(&error, &mut json) {
                        first.get_or_insert(PipelineError::Encode {
                            channel: self.name.to_string(),
                            what: "record",
                            source,
                        });
                        continue;
                    }
                    error
                }
            };
            let handed = emit.record(Output {
                record,
                json,
                log_time_ns,
                stat_index,
            });
            if let Err(e) = handed {
                first.get_or_insert(e.into());
                break;
            }
        }
        records.clear();
        self.records = records;
        first.map_or(Ok(()), Err)
    }
}

fn keep_first(first: &mut Option<PipelineError>, result: Result<(), PipelineError>) {
    if let Err(e) = result {
        first.get_or_insert(e);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MemorySink, Sink};

    /// A record that cannot be encoded (a non-finite number) used to be
    /// skipped without a trace; it is now replaced by a counted `numerical` error record
    /// that reaches every sink the record would have reached.
    #[test]
    fn a_record_that_cannot_be_encoded_becomes_a_counted_error_record() {
        let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
        let monitor = Monitor::from_channel(&cfg.channels[0]).unwrap();
        let memory = MemorySink::default();
        let records = memory.records();
        let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
        let mut pipeline = ChannelPipeline::new(0, monitor, fanout.plan());
        pipeline.records.push(Record::Stat(glrmon_wire::Stat {
            channel: pipeline.name.to_string(),
            k: 7,
            t: None,
            glr: Some(f64::INFINITY),
            onset: Some(3),
            magnitude: vec![f64::NAN],
            rank: 1,
            innovation: vec![0.0],
            residual: Vec::new(),
            threshold: None,
            episode: None,
        }));
        pipeline.hand_on_records(0, &mut fanout).unwrap();
        fanout.close(&mut |e| panic!("{e}"));
        let got = records.lock().unwrap();
        assert_eq!(got.len(), 1);
        let Record::Error(e) = &got[0].record else {
            panic!("{:?}", got[0].record);
        };
        assert_eq!(
            (e.k, e.code, e.stage),
            (Some(7), ErrorCode::Numerical, Stage::Sending)
        );
        assert!(
            e.message
                .contains("the stat record at k = 7 could not be encoded"),
            "{}",
            e.message
        );
        assert!(String::from_utf8_lossy(&got[0].json).contains("\"code\":\"numerical\""));
        assert_eq!(
            pipeline.stats().errors.lock().unwrap().get("numerical"),
            Some(&1)
        );
    }
}
