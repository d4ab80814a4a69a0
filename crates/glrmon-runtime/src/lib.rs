//! The daemon's topology, independent of the transport: sources → pipelines → sinks.
//!
//! ```text
//!  source callbacks ──try_send──▶ worker 0 (pipelines 0, W, 2W, …) ──▶ output stage ──▶ sinks
//!  (never block)   ──try_send──▶ worker 1 (pipelines 1, W+1, …)   ──▶ (one thread,  ──▶ …
//!                                                                      a Fanout)
//!  glrmon replay:  recorded inputs ──▶ ChannelPipeline ──▶ Fanout ──▶ sinks (one thread)
//! ```
//!
//! - **Pipeline** ([`ChannelPipeline`]): one channel's decoded input → monitor →
//!   counted, decimated, encoded records, handed to an [`Emit`]ter. Workers and
//!   `glrmon replay` drive the same pipeline, so a replay's records equal the live ones
//!   by construction.
//! - **Fan-out** ([`Fanout`]): every input to the sinks that asked for inputs, every
//!   record to each [`Sink`] that keeps it; the one copy, used by the output stage and
//!   by replay.
//! - **Intake** ([`Intake::offer`]) never blocks: a full worker queue drops the payload,
//!   counts it for its channel, and the channel's next sample fills the hole with
//!   predict-only steps (a `gap`), so a missing sample is never silently skipped.
//! - **Workers** are threads, each owning the pipelines of a fixed shard of channels,
//!   so a slow channel delays only its shard's queue, never another worker.
//! - **Output**: records that must arrive (alarms, isolation updates, alarm ends,
//!   diagnoses, errors) wait for room in the urgent output queue, which the output stage
//!   always empties first, so that they overtake statistics and inputs; decimated `stat`
//!   records take the bulk queue and are dropped (and counted) when it is full, unless a
//!   recorder needs every input and record.
//! - **Shutdown** ([`Runtime::shutdown`]): stop intake, drain every worker queue, then the
//!   output queue, then close the sinks, within a bounded time.
#![warn(missing_docs)]

mod decode;
mod fanout;
mod pipeline;
mod publish;
mod sink;
mod sinks;
mod status;

pub use decode::{
    Arrival, CdrDecoder, Declared, JsonDecoder, PayloadDecoder, RawDecoder, SparkplugDecoder,
    TagDecoder, decoder,
};
pub use fanout::{DeliveryPlan, Fanout};
pub use pipeline::{ChannelPipeline, Emit, Envelope, PipelineError};
pub use publish::{Publication, PublishError, publications};
pub use sink::{ChannelIndex, InputItem, InputOutput, Interest, Output, Sink, SinkError};
pub use sinks::{FnSink, JsonLinesSink, MemorySink};
pub use status::channel_statuses;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use glrmon_monitor::Monitor;
use glrmon_wire::{DecodeLimits, ErrorCode, Sample, decode_samples};

/// A payload as received from a source.
#[derive(Debug)]
pub struct Payload {
    /// Bytes of the sample or batch, as the channel's decoder reads them.
    pub bytes: Vec<u8>,
    /// When it was received.
    pub received: Instant,
    /// The transport's source timestamp (seconds since the Unix epoch), used as the
    /// samples' `t` where they carry none.
    pub source_time: Option<f64>,
    /// Which of the channel's input keys it arrived on (`glrmon_spec::Channel::
    /// input_keys`): 0 for a channel of whole samples on one key, the signal's tag for
    /// a channel assembled from tags.
    pub tag: usize,
    /// The message type the transport declared for it.
    pub declared: Declared,
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
    /// True while this instance does not monitor the channel: another instance of an
    /// automatic shard owns it ([`ChannelSwitch`]). Its payloads are not taken then.
    pub idle: AtomicBool,
}

/// Runtime settings.
#[derive(Debug, Clone)]
pub struct RuntimeSettings {
    /// Worker threads (channels are sharded over them by index).
    pub workers: usize,
    /// Capacity of each worker's queue, in payloads.
    pub worker_queue: usize,
    /// Capacity of each worker's queue, in payload bytes: a payload that would take a
    /// worker's queued bytes beyond it is dropped (counted, a gap for its channel).
    pub worker_queue_bytes: usize,
    /// Capacity of all worker queues together, in payload bytes.
    pub intake_bytes: usize,
    /// Capacity of the output queues together, in records: half for the urgent queue
    /// (alarms, isolation updates, alarm ends, diagnoses, errors, consistency), half
    /// for the bulk one (statistics, inputs).
    pub output_queue: usize,
    /// Forward one `stat` record in this many (0: none) to the sinks.
    pub stat_every: u64,
    /// Decoding limits.
    pub limits: DecodeLimits,
}

impl RuntimeSettings {
    /// The settings a configuration's `[daemon]` table asks for; `workers` defaults
    /// to the machine's available parallelism.
    #[must_use]
    pub fn from_spec(d: &glrmon_spec::schema::DaemonSpec) -> Self {
        Self {
            workers: d.workers.unwrap_or_else(|| {
                std::thread::available_parallelism().map_or(2, std::num::NonZero::get)
            }),
            worker_queue: d.worker_queue,
            worker_queue_bytes: mib(d.worker_queue_mb),
            intake_bytes: mib(d.intake_mb),
            output_queue: d.output_queue,
            stat_every: d.stat_every,
            limits: DecodeLimits {
                max_payload_bytes: d.max_payload_bytes,
                ..DecodeLimits::default()
            },
        }
    }
}

/// `mb` MiB in bytes (saturating; a negative or NaN size is 0).
fn mib(mb: f64) -> usize {
    let bytes = mb * 1024.0 * 1024.0;
    if bytes.is_nan() || bytes <= 0.0 {
        0
    } else if bytes >= usize::MAX as f64 {
        usize::MAX
    } else {
        bytes as usize
    }
}

impl Default for RuntimeSettings {
    fn default() -> Self {
        Self {
            workers: 2,
            worker_queue: 4096,
            worker_queue_bytes: 64 << 20,
            intake_bytes: 256 << 20,
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
    /// The channel was taken over by this instance (name, assignment generation): its
    /// monitor resumes before the next payload.
    Resume(ChannelIndex, Arc<str>, u64, Instant),
    /// New thresholds and alarm settings for a channel (a configuration reload).
    Retune(ChannelIndex, Box<glrmon_monitor::Tuning>),
    /// Queued behind every accepted payload at shutdown.
    Stop,
}

/// What the output stage's bulk queue carries (its urgent queue carries the records
/// that must arrive, which overtake these).
enum OutMsg {
    Record(Output),
    Input(InputOutput),
    Flush,
}

/// The two queues to the output stage. Alarms, isolation updates, alarm ends,
/// diagnoses and errors take the urgent one, which the output stage always empties
/// first: under a burst of statistics and inputs (a plant-wide fault, a recorder on)
/// they overtake everything queued before them. Each record type keeps one queue, so
/// the records of a type (a recording's topic) stay in order.
#[derive(Clone)]
struct OutputQueues {
    urgent: crossbeam_channel::Sender<Output>,
    bulk: crossbeam_channel::Sender<OutMsg>,
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

/// The handle sources use to hand payloads in; cheap to clone, never blocks.
#[derive(Clone)]
pub struct Intake {
    queues: Arc<Vec<SyncSender<Job>>>,
    /// Payload bytes queued for each worker.
    queued_bytes: Arc<Vec<Arc<AtomicUsize>>>,
    worker_queue_bytes: usize,
    intake_bytes: usize,
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
    /// Their bytes.
    pub queued_bytes: AtomicI64,
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
    /// Not taken: another instance monitors the channel ([`ChannelStats::idle`]).
    Idle,
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
        if stats.idle.load(Ordering::Acquire) {
            return Offer::Idle;
        }
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
        let worker = channel % self.queues.len().max(1);
        let (Some(queue), Some(queued)) = (self.queues.get(worker), self.queued_bytes.get(worker))
        else {
            return Offer::Closed;
        };
        // Memory is bounded in bytes as well as in payloads: reserve this payload's
        // bytes, and give them back if it cannot be queued.
        let len = payload.bytes.len();
        let in_worker = queued.fetch_add(len, Ordering::AcqRel).saturating_add(len);
        let total = self
            .metrics
            .queued_bytes
            .fetch_add(len as i64, Ordering::AcqRel)
            .saturating_add(len as i64);
        let release = || {
            queued.fetch_sub(len, Ordering::AcqRel);
            self.metrics
                .queued_bytes
                .fetch_sub(len as i64, Ordering::AcqRel);
        };
        let before = stats.pending_drops.swap(0, Ordering::AcqRel);
        if in_worker > self.worker_queue_bytes || total > self.intake_bytes as i64 {
            release();
            stats.pending_drops.fetch_add(before + 1, Ordering::AcqRel);
            stats.dropped.fetch_add(1, Ordering::Relaxed);
            return Offer::Dropped;
        }
        match queue.try_send(Job::Payload(channel, payload, before)) {
            Ok(()) => {
                self.metrics.queued_payloads.fetch_add(1, Ordering::Relaxed);
                Offer::Accepted
            }
            Err(TrySendError::Full(_)) => {
                release();
                stats.pending_drops.fetch_add(before + 1, Ordering::AcqRel);
                stats.dropped.fetch_add(1, Ordering::Relaxed);
                Offer::Dropped
            }
            Err(TrySendError::Disconnected(_)) => {
                release();
                stats.pending_drops.fetch_add(before, Ordering::AcqRel);
                Offer::Closed
            }
        }
    }
}

/// Turns the monitoring of channels on and off while the runtime runs: the channels of
/// an automatic shard move between instances as instances come and go. Cheap to clone.
#[derive(Clone, Debug)]
pub struct ChannelSwitch {
    intake: Intake,
}

impl ChannelSwitch {
    /// Stops taking channel `channel`'s payloads (those already queued are
    /// processed). False when it was already idle or there is no such channel.
    pub fn release(&self, channel: ChannelIndex) -> bool {
        let Some(stats) = self.intake.stats.get(channel) else {
            return false;
        };
        let was_idle = stats.idle.swap(true, Ordering::AcqRel);
        // Drops before the release belong to the time another instance covers.
        stats.pending_drops.store(0, Ordering::Release);
        !was_idle
    }

    /// Takes channel `channel` over as instance `instance` at assignment `generation`:
    /// its monitor resumes ([`ChannelPipeline::resumed`]: the filter restarts at the
    /// next sample, whatever its index, and settles) and its payloads are taken again.
    /// Waits for room in the channel's worker queue. False when the channel was not
    /// idle, there is no such channel or the runtime is stopping.
    pub fn take(&self, channel: ChannelIndex, instance: &Arc<str>, generation: u64) -> bool {
        let Some(stats) = self.intake.stats.get(channel) else {
            return false;
        };
        if !stats.idle.load(Ordering::Acquire) || !self.intake.open.load(Ordering::Acquire) {
            return false;
        }
        let queued = self
            .intake
            .queues
            .get(channel % self.intake.queues.len().max(1))
            .is_some_and(|q| {
                q.send(Job::Resume(
                    channel,
                    Arc::clone(instance),
                    generation,
                    Instant::now(),
                ))
                .is_ok()
            });
        // Payloads accepted from here on are queued behind the resumption.
        queued && stats.idle.swap(false, Ordering::AcqRel)
    }

    /// Whether channel `channel` is monitored now.
    #[must_use]
    pub fn is_monitored(&self, channel: ChannelIndex) -> bool {
        self.intake
            .stats
            .get(channel)
            .is_some_and(|s| !s.idle.load(Ordering::Acquire))
    }
}

/// The running topology.
pub struct Runtime {
    intake: Intake,
    workers: Vec<JoinHandle<()>>,
    output: Option<JoinHandle<Vec<Box<dyn Sink>>>>,
    out_tx: Option<OutputQueues>,
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

/// One channel as the runtime runs it: its monitor and the decoder of its payloads.
#[derive(Debug)]
pub struct ChannelSetup {
    /// The channel's monitor.
    pub monitor: Monitor,
    /// The decoder of the payloads on its key.
    pub decoder: Box<dyn PayloadDecoder>,
}

impl ChannelSetup {
    /// A validated channel of the configuration: its monitor
    /// ([`Monitor::from_channel`]) and the decoder of its `payload` format, which reads
    /// values by name when the channel names its signals.
    ///
    /// # Errors
    /// As [`Monitor::from_channel`].
    pub fn from_channel(channel: &glrmon_spec::Channel) -> Result<Self, glrmon_core::ModelError> {
        Ok(Self {
            monitor: Monitor::from_channel(channel)?,
            decoder: decode::decoder(channel),
        })
    }
}

/// A monitor whose payloads are JSON.
impl From<Monitor> for ChannelSetup {
    fn from(monitor: Monitor) -> Self {
        Self {
            monitor,
            decoder: Box::new(JsonDecoder),
        }
    }
}

impl Runtime {
    /// Starts the workers and the output stage for `channels` (in channel index order:
    /// [`ChannelSetup`]s, or monitors of JSON channels) writing to `sinks`.
    #[must_use]
    pub fn start(
        channels: Vec<impl Into<ChannelSetup>>,
        sinks: Vec<Box<dyn Sink>>,
        settings: &RuntimeSettings,
        events: Arc<dyn RuntimeEvents>,
    ) -> Self {
        let channels: Vec<ChannelSetup> = channels.into_iter().map(Into::into).collect();
        let workers_n = settings.workers.clamp(1, channels.len().max(1));
        let names: Vec<String> = channels
            .iter()
            .map(|c| c.monitor.channel().to_owned())
            .collect();
        let stats: Arc<Vec<Arc<ChannelStats>>> = Arc::new(
            channels
                .iter()
                .map(|_| Arc::new(ChannelStats::default()))
                .collect(),
        );
        let capacity = (settings.output_queue / 2).max(8);
        let (urgent_tx, urgent_rx) = crossbeam_channel::bounded::<Output>(capacity);
        let (bulk_tx, bulk_rx) = crossbeam_channel::bounded::<OutMsg>(capacity);
        let out_tx = OutputQueues {
            urgent: urgent_tx,
            bulk: bulk_tx,
        };
        let stat_drops = Arc::new(AtomicU64::new(0));
        let metrics = Arc::new(RuntimeMetrics::default());
        let fanout = Fanout::new(sinks, settings.stat_every);
        let plan = fanout.plan();
        let clock = Clock::now();
        let out_metrics = metrics.clone();
        let output = std::thread::Builder::new()
            .name("glrmon-output".into())
            .spawn(move || {
                output_stage(&urgent_rx, &bulk_rx, fanout, events.as_ref(), &out_metrics)
            })
            .ok();
        let mut shards: Vec<Vec<ChannelPipeline>> = (0..workers_n).map(|_| Vec::new()).collect();
        for (i, c) in channels.into_iter().enumerate() {
            shards[i % workers_n].push(
                ChannelPipeline::new(i, c.monitor, plan.clone())
                    .with_decoder(c.decoder)
                    .with_stats(stats[i].clone()),
            );
        }
        let mut queues = Vec::new();
        let mut queued_bytes = Vec::new();
        let mut workers = Vec::new();
        for (w, shard) in shards.into_iter().enumerate() {
            let (tx, rx) = mpsc::sync_channel::<Job>(settings.worker_queue.max(1));
            queues.push(tx);
            let bytes = Arc::new(AtomicUsize::new(0));
            queued_bytes.push(bytes.clone());
            let out = out_tx.clone();
            let m = metrics.clone();
            m.workers_alive.fetch_add(1, Ordering::Relaxed);
            let context = WorkerContext {
                emit: QueueEmit {
                    out,
                    inputs: plan.inputs,
                    stat_drops: stat_drops.clone(),
                },
                workers: workers_n,
                limits: settings.limits,
                clock,
            };
            let spawned = std::thread::Builder::new()
                .name(format!("glrmon-worker-{w}"))
                .spawn(move || {
                    let _alive = AliveGuard(m.clone());
                    worker(rx, shard, context, &m, &bytes);
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
                queued_bytes: Arc::new(queued_bytes),
                worker_queue_bytes: settings.worker_queue_bytes,
                intake_bytes: settings.intake_bytes,
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

    /// Hands every channel of `config` that this runtime monitors (found by name) its
    /// thresholds and alarm settings, behind the payloads already queued; the filters
    /// go on. Returns how many channels were retuned. What needs a restart (models,
    /// windows, channels added or removed) is for the caller to refuse first
    /// ([`glrmon_spec::Config::restart_needed`]).
    pub fn retune_from(&self, config: &glrmon_spec::Config) -> usize {
        self.names
            .iter()
            .enumerate()
            .filter(|(index, name)| {
                config
                    .channel(name)
                    .is_some_and(|c| self.retune(*index, glrmon_monitor::Tuning::from_channel(c)))
            })
            .count()
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

    /// The handle that turns the monitoring of channels on and off (an automatic
    /// shard's assignment).
    #[must_use]
    pub fn switch(&self) -> ChannelSwitch {
        ChannelSwitch {
            intake: self.intake.clone(),
        }
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
            let _ = tx.bulk.try_send(OutMsg::Flush);
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

/// What a worker needs besides its queue and pipelines.
struct WorkerContext {
    emit: QueueEmit,
    /// Number of workers W (channel i is worker i mod W's).
    workers: usize,
    limits: DecodeLimits,
    clock: Clock,
}

/// A worker's emitter: hands inputs and records to the output stage's queue.
struct QueueEmit {
    out: OutputQueues,
    /// A sink records every input: then every record must arrive too.
    inputs: bool,
    stat_drops: Arc<AtomicU64>,
}

impl Emit for QueueEmit {
    /// Inputs wait for room (a recording must hold every input for the replay to be
    /// exact).
    fn input(&mut self, input: InputOutput) -> Result<(), SinkError> {
        let _ = self.out.bulk.send(OutMsg::Input(input));
        Ok(())
    }

    fn record(&mut self, output: Output) -> Result<(), SinkError> {
        if output.stat_index.is_none() {
            let _ = self.out.urgent.send(output);
        } else if self.inputs {
            // A recording holds every statistic: wait for room.
            let _ = self.out.bulk.send(OutMsg::Record(output));
        } else if self.out.bulk.try_send(OutMsg::Record(output)).is_err() {
            // Without a recorder, decimated statistics may be shed under load.
            self.stat_drops.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }
}

/// Channel `channel`'s pipeline in its worker's shard: channel i is the (i / W)-th of
/// worker i mod W (a direct index: a search would walk every pipeline of the shard
/// for every payload).
fn pipeline_of(
    shard: &mut [ChannelPipeline],
    channel: ChannelIndex,
    workers: usize,
) -> Option<&mut ChannelPipeline> {
    shard
        .get_mut(channel / workers.max(1))
        .filter(|p| p.index() == channel)
}

fn worker(
    rx: Receiver<Job>,
    mut shard: Vec<ChannelPipeline>,
    mut cx: WorkerContext,
    metrics: &RuntimeMetrics,
    queued_bytes: &AtomicUsize,
) {
    loop {
        let job = match rx.recv() {
            // `Job::Stop`, or every sender gone: all accepted payloads are processed.
            Ok(Job::Stop) | Err(_) => return,
            Ok(job) => job,
        };
        let (channel, received) = match &job {
            Job::Payload(c, p, _) => {
                metrics.queued_payloads.fetch_sub(1, Ordering::Relaxed);
                queued_bytes.fetch_sub(p.bytes.len(), Ordering::AcqRel);
                metrics
                    .queued_bytes
                    .fetch_sub(p.bytes.len() as i64, Ordering::AcqRel);
                (*c, p.received)
            }
            Job::Reject(c, _, _, at) | Job::Resume(c, _, _, at) => (*c, *at),
            Job::Retune(c, tuning) => {
                if let Some(pipeline) = pipeline_of(&mut shard, *c, cx.workers) {
                    pipeline.monitor_mut().retune(tuning);
                }
                continue;
            }
            Job::Stop => return,
        };
        let Some(pipeline) = pipeline_of(&mut shard, channel, cx.workers) else {
            continue;
        };
        let log_time_ns = cx.clock.unix_ns(received);
        // The queue emitter never fails; a record that cannot be encoded is replaced by
        // an error record saying so (the pipeline goes on with the next one).
        match job {
            Job::Payload(_, payload, dropped_before) => {
                // Payloads dropped at intake just before this one: advance the arrival
                // count so that this sample is seen after a gap.
                if dropped_before > 0 {
                    let _ = pipeline.dropped(dropped_before, log_time_ns, &mut cx.emit);
                }
                let _ = pipeline.payload(
                    &payload.bytes,
                    Envelope {
                        tag: payload.tag,
                        source_time: payload.source_time,
                        declared: payload.declared,
                    },
                    &cx.limits,
                    log_time_ns,
                    &mut cx.emit,
                );
            }
            Job::Reject(_, code, message, _) => {
                let message = format!("channel \"{}\": {message}", pipeline.name());
                let _ = pipeline.rejected(code, message, None, None, log_time_ns, &mut cx.emit);
            }
            Job::Resume(_, instance, generation, _) => {
                let _ = pipeline.resumed(&instance, generation, log_time_ns, &mut cx.emit);
            }
            Job::Retune(..) | Job::Stop => return,
        }
        metrics.processing.observe(received.elapsed());
        pipeline.publish_counters();
    }
}

/// What the output stage takes next.
enum Next {
    Urgent(Output),
    UrgentClosed,
    Bulk(OutMsg),
    BulkClosed,
}

fn output_stage(
    urgent: &crossbeam_channel::Receiver<Output>,
    bulk: &crossbeam_channel::Receiver<OutMsg>,
    mut fanout: Fanout,
    events: &dyn RuntimeEvents,
    metrics: &RuntimeMetrics,
) -> Vec<Box<dyn Sink>> {
    let mut report = |e: SinkError| events.sink_error(&e);
    let mut last_flush = Instant::now();
    let deliver = |fanout: &mut Fanout, o: &Output, report: &mut dyn FnMut(SinkError)| {
        fanout.record(o, report);
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        metrics
            .delivery
            .observe(Duration::from_nanos(now.saturating_sub(o.log_time_ns)));
    };
    let (mut urgent_open, mut bulk_open) = (true, true);
    while urgent_open || bulk_open {
        // Sinks are flushed when the queues are idle and at least every second under
        // load.
        if last_flush.elapsed() >= FLUSH_INTERVAL {
            fanout.flush(&mut report);
            last_flush = Instant::now();
        }
        // Every urgent record first, then one bulk message, then look again.
        match urgent.try_recv() {
            Ok(o) => {
                deliver(&mut fanout, &o, &mut report);
                continue;
            }
            Err(crossbeam_channel::TryRecvError::Disconnected) => urgent_open = false,
            Err(crossbeam_channel::TryRecvError::Empty) => {}
        }
        let next = if urgent_open && bulk_open {
            crossbeam_channel::select_biased! {
                recv(urgent) -> o => o.map_or(Next::UrgentClosed, Next::Urgent),
                recv(bulk) -> m => m.map_or(Next::BulkClosed, Next::Bulk),
                default(Duration::from_millis(200)) => Next::Bulk(OutMsg::Flush),
            }
        } else if bulk_open {
            match bulk.recv_timeout(Duration::from_millis(200)) {
                Ok(m) => Next::Bulk(m),
                Err(crossbeam_channel::RecvTimeoutError::Timeout) => Next::Bulk(OutMsg::Flush),
                Err(crossbeam_channel::RecvTimeoutError::Disconnected) => Next::BulkClosed,
            }
        } else {
            // Only the urgent queue is left: the try_recv above drains it.
            match urgent.recv() {
                Ok(o) => Next::Urgent(o),
                Err(_) => Next::UrgentClosed,
            }
        };
        let msg = match next {
            Next::Urgent(o) => {
                deliver(&mut fanout, &o, &mut report);
                continue;
            }
            Next::UrgentClosed => {
                urgent_open = false;
                continue;
            }
            Next::Bulk(m) => Some(m),
            Next::BulkClosed => None,
        };
        match msg {
            Some(OutMsg::Record(o)) => fanout.record(&o, &mut report),
            Some(OutMsg::Input(i)) => fanout.input(&i, &mut report),
            Some(OutMsg::Flush) => {
                fanout.flush(&mut report);
                last_flush = Instant::now();
            }
            None => bulk_open = false,
        }
    }
    fanout.close(&mut report)
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
