//! The daemon's topology, independent of the transport: sources → monitors → sinks.
//!
//! ```text
//!  source callbacks ──try_send──▶ worker 0 (channels 0, W, 2W, …) ──▶ output stage ──▶ sinks
//!  (never block)   ──try_send──▶ worker 1 (channels 1, W+1, …)   ──▶ (one thread)  ──▶ …
//! ```
//!
//! - **Intake** ([`Intake::offer`]) never blocks: a full worker queue drops the payload,
//!   counts it for its channel, and the channel's next sample fills the hole with
//!   predict-only steps (a `gap`), so a missing sample is never silently skipped.
//! - **Workers** are threads, each owning the monitors of a fixed shard of channels, so
//!   a slow channel delays only its shard's queue, never another worker.
//! - **Output**: every record is encoded once and handed to each [`Sink`]. Records that
//!   must arrive (alarms, alarm ends, diagnoses, errors) wait for room in the output
//!   queue; decimated `stat` records are dropped (and counted) when it is full.
//! - **Shutdown** ([`Runtime::shutdown`]): stop intake, drain every worker queue, then the
//!   output queue, then flush and close the sinks, within a bounded time.
#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use glrmon_monitor::Monitor;
use glrmon_wire::{
    DecodeLimits, ErrorCode, ErrorRecord, IntakeEvent, Record, Sample, Stage, decode_samples,
    encode_intake, encode_json, encode_sample,
};

mod status;
pub use status::channel_statuses;

/// Index of a channel in the runtime (its position in the configuration).
pub type ChannelIndex = usize;

/// A payload as received from a source.
#[derive(Debug)]
pub struct Payload {
    /// Bytes of the sample or batch (JSON).
    pub bytes: Vec<u8>,
    /// When it was received.
    pub received: Instant,
    /// The transport's source timestamp (seconds since the Unix epoch), used as the
    /// samples' `t` where they carry none.
    pub source_time: Option<f64>,
}

/// A record on its way to the sinks, encoded once.
#[derive(Debug, Clone)]
pub struct Output {
    /// The record.
    pub record: Record,
    /// Its JSON encoding (INTERFACE.md), without a trailing newline.
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

/// What a sink wants besides the alarm, end, diagnosis and error records.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Interest {
    /// Every input ([`Sink::write_input`]): what recorders need to replay a run.
    pub inputs: bool,
    /// One `stat` record in this many per channel (0: none); `None`: the runtime's
    /// [`RuntimeSettings::stat_every`].
    pub stat_every: Option<u64>,
}

/// Errors of a sink; the output stage logs them through [`RuntimeEvents`] and goes on.
#[derive(Debug, thiserror::Error)]
#[error("sink {sink}: {message}")]
pub struct SinkError {
    /// The sink's name.
    pub sink: String,
    /// What failed.
    pub message: String,
}

/// Where results go: a Zenoh publisher, a recorder, standard output…
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
    /// Flushes buffered records (called at shutdown and when the output queue is idle).
    ///
    /// # Errors
    /// [`SinkError`] when the flush failed.
    fn flush(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

/// Callbacks for events the operator should hear about (the binary logs them).
pub trait RuntimeEvents: Send + Sync + 'static {
    /// A sink failed.
    fn sink_error(&self, error: &SinkError);
}

/// Per-channel counters, updated by the workers and read by status queries.
#[derive(Debug, Default)]
pub struct ChannelStats {
    /// Samples processed.
    pub samples: AtomicU64,
    /// Payloads dropped at intake because the worker queue was full.
    pub dropped: AtomicU64,
    /// Drops not yet reported to the monitor: carried by the next accepted payload, so
    /// that the gap lands exactly where the samples went missing.
    pending_drops: AtomicU64,
    /// Alarms raised.
    pub alarms: AtomicU64,
    /// 1 while an alarm episode is going on.
    pub alarm_active: AtomicU64,
    /// Index of the last processed sample + 1 (0 before the first).
    pub next_k: AtomicU64,
    /// Rejections by code.
    pub errors: Mutex<BTreeMap<&'static str, u64>>,
}

/// Runtime settings.
#[derive(Debug, Clone)]
pub struct RuntimeSettings {
    /// Worker threads (channels are sharded over them by index).
    pub workers: usize,
    /// Capacity of each worker's queue, in payloads.
    pub worker_queue: usize,
    /// Capacity of the output queue, in records.
    pub output_queue: usize,
    /// Forward one `stat` record in this many (0: none) to the sinks.
    pub stat_every: u64,
    /// Decoding limits.
    pub limits: DecodeLimits,
}

impl Default for RuntimeSettings {
    fn default() -> Self {
        Self {
            workers: 2,
            worker_queue: 4096,
            output_queue: 16384,
            stat_every: 10,
            limits: DecodeLimits::default(),
        }
    }
}

enum Job {
    /// A payload and the number of payloads of its channel dropped just before it.
    Payload(ChannelIndex, Payload, u64),
    /// A payload refused at intake, reported as an `error` record by its worker.
    Reject(ChannelIndex, ErrorCode, String, Instant),
    /// New thresholds and alarm settings for a channel (a configuration reload).
    Retune(ChannelIndex, Box<glrmon_monitor::Tuning>),
    /// Queued behind every accepted payload at shutdown.
    Stop,
}

enum OutMsg {
    Record(Output),
    Input(InputOutput),
    Flush,
}

/// Converts receive instants to wall-clock nanoseconds since the Unix epoch, from one
/// reference pair taken at start (monotonic in between, unlike the wall clock).
#[derive(Debug, Clone, Copy)]
struct Clock {
    instant: Instant,
    unix_ns: u64,
}

impl Clock {
    fn now() -> Self {
        Self {
            instant: Instant::now(),
            unix_ns: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
        }
    }

    fn unix_ns(&self, at: Instant) -> u64 {
        let delta = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        match at.checked_duration_since(self.instant) {
            Some(after) => self.unix_ns.saturating_add(delta(after)),
            None => self
                .unix_ns
                .saturating_sub(delta(self.instant.duration_since(at))),
        }
    }
}

/// What the workers send on, worked out once from the sinks' [`Interest`]s.
#[derive(Debug, Clone, Copy)]
struct Forwarding {
    inputs: bool,
    /// The smallest non-zero decimation over the sinks (0: no sink wants `stat`).
    stat_every: u64,
    clock: Clock,
}

/// The handle sources use to hand payloads in; cheap to clone, never blocks.
#[derive(Clone)]
pub struct Intake {
    queues: Arc<Vec<SyncSender<Job>>>,
    stats: Arc<Vec<Arc<ChannelStats>>>,
    open: Arc<AtomicBool>,
    limits: DecodeLimits,
    metrics: Arc<RuntimeMetrics>,
}

/// Upper bounds (seconds) of the latency histograms' buckets (the last is +∞).
pub const LATENCY_BUCKETS: [f64; 14] = [
    1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 2.5e-2, 5e-2, 0.1, 0.25, 0.5, 1.0, 2.5,
];

/// A latency histogram with fixed buckets ([`LATENCY_BUCKETS`]), lock-free.
#[derive(Debug, Default)]
pub struct LatencyHistogram {
    /// Observations per bucket (not cumulative); the last is above every bound.
    pub counts: [AtomicU64; LATENCY_BUCKETS.len() + 1],
    /// Sum of the observations in nanoseconds.
    pub sum_ns: AtomicU64,
}

impl LatencyHistogram {
    /// Counts one observation.
    pub fn observe(&self, d: Duration) {
        let s = d.as_secs_f64();
        let i = LATENCY_BUCKETS
            .iter()
            .position(|b| s <= *b)
            .unwrap_or(LATENCY_BUCKETS.len());
        self.counts[i].fetch_add(1, Ordering::Relaxed);
        self.sum_ns.fetch_add(
            u64::try_from(d.as_nanos()).unwrap_or(u64::MAX),
            Ordering::Relaxed,
        );
    }
}

/// Counters of the whole runtime, for metrics and health checks.
#[derive(Debug, Default)]
pub struct RuntimeMetrics {
    /// Payloads accepted by intake and not yet taken by a worker.
    pub queued_payloads: AtomicI64,
    /// Worker threads running (a worker that ends or panics leaves this count).
    pub workers_alive: AtomicU64,
    /// From a payload's receipt to its records handed to the output stage.
    pub processing: LatencyHistogram,
    /// From a payload's receipt to its alarm, end, diagnosis or error record written
    /// by every sink.
    pub delivery: LatencyHistogram,
}

/// Leaves [`RuntimeMetrics::workers_alive`] when its worker ends, panicking or not.
struct AliveGuard(Arc<RuntimeMetrics>);

impl Drop for AliveGuard {
    fn drop(&mut self) {
        self.0.workers_alive.fetch_sub(1, Ordering::Relaxed);
    }
}

impl std::fmt::Debug for Intake {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Intake")
            .field("workers", &self.queues.len())
            .finish_non_exhaustive()
    }
}

/// What happened to an offered payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Offer {
    /// Queued for its worker.
    Accepted,
    /// Dropped: the worker queue was full (counted; the channel will see a gap).
    Dropped,
    /// Dropped: the payload is larger than the limit (counted as `too_large`).
    TooLarge,
    /// Refused: the runtime is shutting down.
    Closed,
    /// No such channel.
    UnknownChannel,
}

impl Intake {
    /// Offers a payload for `channel` without blocking.
    pub fn offer(&self, channel: ChannelIndex, payload: Payload) -> Offer {
        if !self.open.load(Ordering::Acquire) {
            return Offer::Closed;
        }
        let Some(stats) = self.stats.get(channel) else {
            return Offer::UnknownChannel;
        };
        if payload.bytes.len() > self.limits.max_payload_bytes {
            // Reported as an `error` record by the channel's worker (which counts it);
            // if even that cannot be queued, counted here.
            let msg = format!(
                "payload of {} bytes exceeds the limit of {} bytes: dropped",
                payload.bytes.len(),
                self.limits.max_payload_bytes
            );
            let job = Job::Reject(channel, ErrorCode::TooLarge, msg, payload.received);
            let queued = self
                .queues
                .get(channel % self.queues.len().max(1))
                .is_some_and(|q| q.try_send(job).is_ok());
            if !queued {
                let mut e = stats
                    .errors
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                *e.entry(ErrorCode::TooLarge.as_str()).or_insert(0) += 1;
            }
            return Offer::TooLarge;
        }
        let Some(queue) = self.queues.get(channel % self.queues.len().max(1)) else {
            return Offer::Closed;
        };
        let before = stats.pending_drops.swap(0, Ordering::AcqRel);
        match queue.try_send(Job::Payload(channel, payload, before)) {
            Ok(()) => {
                self.metrics.queued_payloads.fetch_add(1, Ordering::Relaxed);
                Offer::Accepted
            }
            Err(TrySendError::Full(_)) => {
                stats.pending_drops.fetch_add(before + 1, Ordering::AcqRel);
                stats.dropped.fetch_add(1, Ordering::Relaxed);
                Offer::Dropped
            }
            Err(TrySendError::Disconnected(_)) => {
                stats.pending_drops.fetch_add(before, Ordering::AcqRel);
                Offer::Closed
            }
        }
    }
}

/// The running topology.
pub struct Runtime {
    intake: Intake,
    workers: Vec<JoinHandle<()>>,
    output: Option<JoinHandle<Vec<Box<dyn Sink>>>>,
    out_tx: Option<SyncSender<OutMsg>>,
    stats: Arc<Vec<Arc<ChannelStats>>>,
    names: Vec<String>,
    stat_drops: Arc<AtomicU64>,
    metrics: Arc<RuntimeMetrics>,
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime")
            .field("channels", &self.names)
            .finish_non_exhaustive()
    }
}

struct WorkerChannel {
    index: ChannelIndex,
    monitor: Monitor,
    name: Arc<str>,
    stats: Arc<ChannelStats>,
    stat_count: u64,
}

impl Runtime {
    /// Starts the workers and the output stage for `monitors` (in channel index order)
    /// writing to `sinks`.
    #[must_use]
    pub fn start(
        monitors: Vec<Monitor>,
        sinks: Vec<Box<dyn Sink>>,
        settings: &RuntimeSettings,
        events: Arc<dyn RuntimeEvents>,
    ) -> Self {
        let workers_n = settings.workers.clamp(1, monitors.len().max(1));
        let names: Vec<String> = monitors.iter().map(|m| m.channel().to_owned()).collect();
        let stats: Arc<Vec<Arc<ChannelStats>>> = Arc::new(
            monitors
                .iter()
                .map(|_| Arc::new(ChannelStats::default()))
                .collect(),
        );
        let (out_tx, out_rx) = mpsc::sync_channel::<OutMsg>(settings.output_queue.max(16));
        let stat_drops = Arc::new(AtomicU64::new(0));
        let metrics = Arc::new(RuntimeMetrics::default());
        let interests: Vec<Interest> = sinks.iter().map(|s| s.interest()).collect();
        let forwarding = Forwarding {
            inputs: interests.iter().any(|i| i.inputs),
            stat_every: interests
                .iter()
                .map(|i| i.stat_every.unwrap_or(settings.stat_every))
                .filter(|&e| e > 0)
                .min()
                .unwrap_or(0),
            clock: Clock::now(),
        };
        let default_stat_every = settings.stat_every;
        let out_metrics = metrics.clone();
        let output = std::thread::Builder::new()
            .name("glrmon-output".into())
            .spawn(move || {
                output_stage(
                    out_rx,
                    sinks,
                    default_stat_every,
                    events.as_ref(),
                    &out_metrics,
                )
            })
            .ok();
        let mut shards: Vec<Vec<(ChannelIndex, WorkerChannel)>> =
            (0..workers_n).map(|_| Vec::new()).collect();
        for (i, m) in monitors.into_iter().enumerate() {
            shards[i % workers_n].push((
                i,
                WorkerChannel {
                    index: i,
                    name: Arc::from(m.channel()),
                    monitor: m,
                    stats: stats[i].clone(),
                    stat_count: 0,
                },
            ));
        }
        let mut queues = Vec::new();
        let mut workers = Vec::new();
        for (w, shard) in shards.into_iter().enumerate() {
            let (tx, rx) = mpsc::sync_channel::<Job>(settings.worker_queue.max(1));
            queues.push(tx);
            let out = out_tx.clone();
            let limits = settings.limits;
            let drops = stat_drops.clone();
            let m = metrics.clone();
            m.workers_alive.fetch_add(1, Ordering::Relaxed);
            let spawned = std::thread::Builder::new()
                .name(format!("glrmon-worker-{w}"))
                .spawn(move || {
                    let _alive = AliveGuard(m.clone());
                    worker(rx, shard, out, limits, forwarding, drops, &m);
                });
            match spawned {
                Ok(h) => workers.push(h),
                Err(_) => {
                    metrics.workers_alive.fetch_sub(1, Ordering::Relaxed);
                }
            }
        }
        Self {
            intake: Intake {
                queues: Arc::new(queues),
                stats: stats.clone(),
                open: Arc::new(AtomicBool::new(true)),
                limits: settings.limits,
                metrics: metrics.clone(),
            },
            workers,
            output,
            out_tx: Some(out_tx),
            stats,
            names,
            stat_drops,
            metrics,
        }
    }

    /// Hands new thresholds and alarm settings to the worker of channel `index`, behind
    /// the payloads already queued (waits for room in that queue). False when there is
    /// no such channel or the runtime is stopping.
    pub fn retune(&self, index: ChannelIndex, tuning: glrmon_monitor::Tuning) -> bool {
        if index >= self.names.len() || !self.intake.open.load(Ordering::Acquire) {
            return false;
        }
        self.intake
            .queues
            .get(index % self.intake.queues.len().max(1))
            .is_some_and(|q| q.send(Job::Retune(index, Box::new(tuning))).is_ok())
    }

    /// The runtime's queue, worker and latency metrics.
    #[must_use]
    pub fn metrics(&self) -> Arc<RuntimeMetrics> {
        self.metrics.clone()
    }

    /// The handle for sources.
    #[must_use]
    pub fn intake(&self) -> Intake {
        self.intake.clone()
    }

    /// Channel names, by index.
    #[must_use]
    pub fn channel_names(&self) -> &[String] {
        &self.names
    }

    /// The counters of every channel.
    #[must_use]
    pub fn stats(&self) -> Arc<Vec<Arc<ChannelStats>>> {
        self.stats.clone()
    }

    /// `stat` records dropped because the output queue was full.
    #[must_use]
    pub fn stat_drops(&self) -> u64 {
        self.stat_drops.load(Ordering::Relaxed)
    }

    /// Asks the output stage to flush its sinks (e.g. periodically).
    pub fn flush(&self) {
        if let Some(tx) = &self.out_tx {
            let _ = tx.try_send(OutMsg::Flush);
        }
    }

    /// Stops intake, drains every queue, flushes and returns the sinks. Returns `false`
    /// when the drain did not finish within `deadline` (the rest is abandoned).
    pub fn shutdown(mut self, deadline: Duration) -> (bool, Vec<Box<dyn Sink>>) {
        let start = Instant::now();
        self.intake.open.store(false, Ordering::Release);
        // Sources may still hold intake handles: stop each worker with a message queued
        // behind the payloads it accepted, so that they are all processed.
        for q in self.intake.queues.iter() {
            let _ = q.send(Job::Stop);
        }
        let mut in_time = true;
        for h in self.workers.drain(..) {
            in_time &= join_until(h, start + deadline).is_some();
        }
        self.out_tx = None;
        let sinks = match self.output.take() {
            Some(h) => join_until(h, start + deadline).unwrap_or_else(|| {
                in_time = false;
                Vec::new()
            }),
            None => Vec::new(),
        };
        (in_time, sinks)
    }
}

/// Joins a thread, waiting at most until `until`.
fn join_until<T>(h: JoinHandle<T>, until: Instant) -> Option<T> {
    while !h.is_finished() {
        if Instant::now() >= until {
            return None;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    h.join().ok()
}

/// The longest time records wait in a sink's buffers under continuous load.
const FLUSH_INTERVAL: Duration = Duration::from_secs(1);

/// Longest refused payload kept, as text, in its [`IntakeEvent::Rejected`].
const MAX_KEPT_PAYLOAD: usize = 64 * 1024;

fn worker(
    rx: Receiver<Job>,
    mut shard: Vec<(ChannelIndex, WorkerChannel)>,
    out: SyncSender<OutMsg>,
    limits: DecodeLimits,
    fwd: Forwarding,
    stat_drops: Arc<AtomicU64>,
    metrics: &RuntimeMetrics,
) {
    let mut samples = Vec::new();
    let mut records = Vec::new();
    let mut inputs: Vec<InputItem> = Vec::new();
    loop {
        let job = match rx.recv() {
            // `Job::Stop`, or every sender gone: all accepted payloads are processed.
            Ok(Job::Stop) | Err(_) => return,
            Ok(job) => job,
        };
        let (channel, received) = match &job {
            Job::Payload(c, p, _) => {
                metrics.queued_payloads.fetch_sub(1, Ordering::Relaxed);
                (*c, p.received)
            }
            Job::Reject(c, _, _, at) => (*c, *at),
            Job::Retune(c, tuning) => {
                if let Some((_, ch)) = shard.iter_mut().find(|(i, _)| i == c) {
                    ch.monitor.retune(tuning);
                }
                continue;
            }
            Job::Stop => return,
        };
        let Some((_, ch)) = shard.iter_mut().find(|(i, _)| *i == channel) else {
            continue;
        };
        let log_time_ns = fwd.clock.unix_ns(received);
        match job {
            Job::Payload(_, payload, dropped_before) => {
                // Payloads dropped at intake just before this one: advance the arrival
                // count so that this sample is seen after a gap.
                if dropped_before > 0 {
                    ch.monitor.note_missing(dropped_before);
                    if fwd.inputs {
                        inputs.push(InputItem::Intake(IntakeEvent::Dropped {
                            count: dropped_before,
                        }));
                    }
                }
                match decode_samples(ch.monitor.channel(), &payload.bytes, &limits, &mut samples) {
                    Ok(()) => {
                        for s in &mut samples {
                            if s.t.is_none() {
                                s.t = payload.source_time;
                            }
                            if fwd.inputs {
                                inputs.push(InputItem::Sample(s.clone()));
                                // Inputs precede the records they produce.
                                send_inputs(&out, ch, &mut inputs, log_time_ns);
                            }
                            ch.monitor.on_sample(s, &mut records);
                            forward_records(&out, ch, &mut records, fwd, log_time_ns, &stat_drops);
                        }
                    }
                    Err(e) => {
                        let record = ErrorRecord::from_decode_error(&e, None, Stage::Receiving);
                        if fwd.inputs {
                            let kept = (payload.bytes.len() <= MAX_KEPT_PAYLOAD)
                                .then(|| String::from_utf8_lossy(&payload.bytes).into_owned());
                            inputs.push(InputItem::Intake(IntakeEvent::Rejected {
                                code: record.code,
                                message: record.message.clone(),
                                payload: kept,
                            }));
                        }
                        records.push(Record::Error(record));
                    }
                }
            }
            Job::Reject(_, code, message, _) => {
                let message = format!("channel \"{}\": {message}", ch.monitor.channel());
                if fwd.inputs {
                    inputs.push(InputItem::Intake(IntakeEvent::Rejected {
                        code,
                        message: message.clone(),
                        payload: None,
                    }));
                }
                records.push(Record::Error(ErrorRecord {
                    channel: ch.monitor.channel().to_owned(),
                    k: None,
                    code,
                    message,
                    stage: Stage::Receiving,
                }));
            }
            Job::Retune(..) | Job::Stop => return,
        }
        send_inputs(&out, ch, &mut inputs, log_time_ns);
        forward_records(&out, ch, &mut records, fwd, log_time_ns, &stat_drops);
        metrics.processing.observe(received.elapsed());
        let c = ch.monitor.counters();
        ch.stats.samples.store(c.samples, Ordering::Relaxed);
        ch.stats.alarms.store(c.alarms, Ordering::Relaxed);
        ch.stats
            .alarm_active
            .store(u64::from(ch.monitor.alarm_active()), Ordering::Relaxed);
        ch.stats.next_k.store(
            ch.monitor.detector().next_index().unwrap_or(0),
            Ordering::Relaxed,
        );
    }
}

/// Sends the pending inputs of a channel; they wait for room (a recording must hold
/// every input for the replay to be exact).
fn send_inputs(
    out: &SyncSender<OutMsg>,
    ch: &WorkerChannel,
    inputs: &mut Vec<InputItem>,
    log_time_ns: u64,
) {
    for item in inputs.drain(..) {
        let mut json = Vec::with_capacity(128);
        let encoded = match &item {
            InputItem::Sample(s) => encode_sample(&ch.name, s, &mut json),
            InputItem::Intake(e) => encode_intake(&ch.name, e, &mut json),
        };
        if encoded.is_err() {
            continue;
        }
        let _ = out.send(OutMsg::Input(InputOutput {
            channel: ch.index,
            name: ch.name.clone(),
            item,
            json,
            log_time_ns,
        }));
    }
}

/// Counts errors, decimates `stat` records and sends the records of a channel.
fn forward_records(
    out: &SyncSender<OutMsg>,
    ch: &mut WorkerChannel,
    records: &mut Vec<Record>,
    fwd: Forwarding,
    log_time_ns: u64,
    stat_drops: &AtomicU64,
) {
    for r in records.drain(..) {
        if let Record::Error(e) = &r {
            let mut errs = ch
                .stats
                .errors
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            *errs.entry(e.code.as_str()).or_insert(0) += 1;
        }
        let stat_index = if matches!(r, Record::Stat(_)) {
            let index = ch.stat_count;
            ch.stat_count += 1;
            if fwd.stat_every == 0 || index % fwd.stat_every != 0 {
                continue;
            }
            Some(index)
        } else {
            None
        };
        let mut json = Vec::with_capacity(256);
        if encode_json(&r, &mut json).is_err() {
            continue;
        }
        let msg = OutMsg::Record(Output {
            record: r,
            json,
            log_time_ns,
            stat_index,
        });
        if stat_index.is_some() && !fwd.inputs {
            // Without a recorder, decimated statistics may be shed under load.
            if out.try_send(msg).is_err() {
                stat_drops.fetch_add(1, Ordering::Relaxed);
            }
        } else {
            let _ = out.send(msg);
        }
    }
}

fn output_stage(
    rx: Receiver<OutMsg>,
    mut sinks: Vec<Box<dyn Sink>>,
    default_stat_every: u64,
    events: &dyn RuntimeEvents,
    metrics: &RuntimeMetrics,
) -> Vec<Box<dyn Sink>> {
    let interests: Vec<Interest> = sinks.iter().map(|s| s.interest()).collect();
    let flush_all = |sinks: &mut Vec<Box<dyn Sink>>| {
        for s in sinks.iter_mut() {
            if let Err(e) = s.flush() {
                events.sink_error(&e);
            }
        }
    };
    let mut last_flush = Instant::now();
    loop {
        // Sinks are flushed when the queue is idle and at least every second under load.
        if last_flush.elapsed() >= FLUSH_INTERVAL {
            flush_all(&mut sinks);
            last_flush = Instant::now();
        }
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(OutMsg::Record(o)) => {
                for (s, interest) in sinks.iter_mut().zip(&interests) {
                    if let Some(index) = o.stat_index {
                        let every = interest.stat_every.unwrap_or(default_stat_every);
                        if every == 0 || index % every != 0 {
                            continue;
                        }
                    }
                    if let Err(e) = s.write(&o) {
                        events.sink_error(&e);
                    }
                }
                if o.stat_index.is_none() {
                    let now = SystemTime::now()
                        .duration_since(UNIX_EPOCH)
                        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
                    metrics
                        .delivery
                        .observe(Duration::from_nanos(now.saturating_sub(o.log_time_ns)));
                }
            }
            Ok(OutMsg::Input(i)) => {
                for (s, interest) in sinks.iter_mut().zip(&interests) {
                    if interest.inputs {
                        if let Err(e) = s.write_input(&i) {
                            events.sink_error(&e);
                        }
                    }
                }
            }
            Ok(OutMsg::Flush) | Err(mpsc::RecvTimeoutError::Timeout) => {
                flush_all(&mut sinks);
                last_flush = Instant::now();
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
    }
    flush_all(&mut sinks);
    sinks
}

/// A sink that collects records in memory (tests, replay into a buffer).
#[derive(Debug, Clone, Default)]
pub struct MemorySink {
    records: Arc<Mutex<Vec<Output>>>,
}

impl MemorySink {
    /// A shared handle to the collected records.
    #[must_use]
    pub fn records(&self) -> Arc<Mutex<Vec<Output>>> {
        self.records.clone()
    }
}

impl Sink for MemorySink {
    fn name(&self) -> &str {
        "memory"
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        self.records
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(output.clone());
        Ok(())
    }
}

/// A sink calling a closure for each record (e.g. print alarms).
pub struct FnSink<F>(pub &'static str, pub F);

impl<F> std::fmt::Debug for FnSink<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("FnSink").field(&self.0).finish()
    }
}

impl<F: FnMut(&Output) + Send + 'static> Sink for FnSink<F> {
    fn name(&self) -> &str {
        self.0
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        (self.1)(output);
        Ok(())
    }
}

/// Decodes one sample payload for tests and tools that feed samples directly.
///
/// # Errors
/// As [`decode_samples`].
pub fn decode_one(channel: &str, bytes: &[u8]) -> Result<Vec<Sample>, glrmon_wire::DecodeError> {
    let mut out = Vec::new();
    decode_samples(channel, bytes, &DecodeLimits::default(), &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests;
