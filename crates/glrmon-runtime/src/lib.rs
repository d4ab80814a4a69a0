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
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glrmon_monitor::Monitor;
use glrmon_wire::{
    DecodeLimits, ErrorCode, ErrorRecord, Record, Sample, Stage, decode_samples, encode_json,
};

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
    Reject(ChannelIndex, ErrorCode, String),
    /// Queued behind every accepted payload at shutdown.
    Stop,
}

enum OutMsg {
    Record(Output),
    Flush,
}

/// The handle sources use to hand payloads in; cheap to clone, never blocks.
#[derive(Clone)]
pub struct Intake {
    queues: Arc<Vec<SyncSender<Job>>>,
    stats: Arc<Vec<Arc<ChannelStats>>>,
    open: Arc<AtomicBool>,
    limits: DecodeLimits,
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
            let job = Job::Reject(channel, ErrorCode::TooLarge, msg);
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
            Ok(()) => Offer::Accepted,
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
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime")
            .field("channels", &self.names)
            .finish_non_exhaustive()
    }
}

struct WorkerChannel {
    monitor: Monitor,
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
        let output = std::thread::Builder::new()
            .name("glrmon-output".into())
            .spawn(move || output_stage(out_rx, sinks, events.as_ref()))
            .ok();
        let mut shards: Vec<Vec<(ChannelIndex, WorkerChannel)>> =
            (0..workers_n).map(|_| Vec::new()).collect();
        for (i, m) in monitors.into_iter().enumerate() {
            shards[i % workers_n].push((
                i,
                WorkerChannel {
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
            let stat_every = settings.stat_every;
            let drops = stat_drops.clone();
            if let Ok(h) = std::thread::Builder::new()
                .name(format!("glrmon-worker-{w}"))
                .spawn(move || worker(rx, shard, out, limits, stat_every, drops))
            {
                workers.push(h);
            }
        }
        Self {
            intake: Intake {
                queues: Arc::new(queues),
                stats: stats.clone(),
                open: Arc::new(AtomicBool::new(true)),
                limits: settings.limits,
            },
            workers,
            output,
            out_tx: Some(out_tx),
            stats,
            names,
            stat_drops,
        }
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

fn worker(
    rx: Receiver<Job>,
    mut shard: Vec<(ChannelIndex, WorkerChannel)>,
    out: SyncSender<OutMsg>,
    limits: DecodeLimits,
    stat_every: u64,
    stat_drops: Arc<AtomicU64>,
) {
    let mut samples = Vec::new();
    let mut records = Vec::new();
    loop {
        let (channel, payload, dropped_before) = match rx.recv() {
            Ok(Job::Payload(c, p, d)) => (c, Some(p), d),
            Ok(Job::Reject(c, code, message)) => {
                if let Some((_, ch)) = shard.iter_mut().find(|(i, _)| *i == c) {
                    records.push(Record::Error(ErrorRecord {
                        channel: ch.monitor.channel().to_owned(),
                        k: None,
                        code,
                        message: format!("channel \"{}\": {message}", ch.monitor.channel()),
                        stage: Stage::Receiving,
                    }));
                }
                (c, None, 0)
            }
            // `Job::Stop`, or every sender gone: all accepted payloads are processed.
            Ok(Job::Stop) | Err(_) => return,
        };
        let Some((_, ch)) = shard.iter_mut().find(|(i, _)| *i == channel) else {
            continue;
        };
        // Payloads dropped at intake just before this one: advance the arrival count so
        // that this sample is seen after a gap.
        if dropped_before > 0 {
            ch.monitor.note_missing(dropped_before);
        }
        if let Some(payload) = payload {
            match decode_samples(ch.monitor.channel(), &payload.bytes, &limits, &mut samples) {
                Ok(()) => {
                    for s in &mut samples {
                        if s.t.is_none() {
                            s.t = payload.source_time;
                        }
                        ch.monitor.on_sample(s, &mut records);
                    }
                }
                Err(e) => records.push(Record::Error(ErrorRecord::from_decode_error(
                    &e,
                    None,
                    Stage::Receiving,
                ))),
            }
        }
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
        for r in records.drain(..) {
            if let Record::Error(e) = &r {
                let mut errs = ch
                    .stats
                    .errors
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                *errs.entry(e.code.as_str()).or_insert(0) += 1;
            }
            let is_stat = matches!(r, Record::Stat(_));
            if is_stat {
                ch.stat_count += 1;
                if stat_every == 0 || (ch.stat_count - 1) % stat_every != 0 {
                    continue;
                }
            }
            let mut json = Vec::with_capacity(256);
            if encode_json(&r, &mut json).is_err() {
                continue;
            }
            let msg = OutMsg::Record(Output { record: r, json });
            if is_stat {
                if out.try_send(msg).is_err() {
                    stat_drops.fetch_add(1, Ordering::Relaxed);
                }
            } else if out.send(msg).is_err() {
                return;
            }
        }
    }
}

fn output_stage(
    rx: Receiver<OutMsg>,
    mut sinks: Vec<Box<dyn Sink>>,
    events: &dyn RuntimeEvents,
) -> Vec<Box<dyn Sink>> {
    let flush_all = |sinks: &mut Vec<Box<dyn Sink>>| {
        for s in sinks.iter_mut() {
            if let Err(e) = s.flush() {
                events.sink_error(&e);
            }
        }
    };
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(OutMsg::Record(o)) => {
                for s in &mut sinks {
                    if let Err(e) = s.write(&o) {
                        events.sink_error(&e);
                    }
                }
            }
            Ok(OutMsg::Flush) | Err(mpsc::RecvTimeoutError::Timeout) => flush_all(&mut sinks),
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
