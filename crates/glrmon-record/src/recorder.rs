//! The recording sink: blocking file I/O on its own thread behind a bounded queue,
//! rotation by size and duration, files finished under their final name only, an
//! optional cap on disk use and an optional pre/post-fault capture.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use glrmon_runtime::{InputOutput, Interest, Output, Sink, SinkError};

use crate::messages::{input_topic, record_messages};
use crate::schema::TopicKind;
use crate::writer::{FileHeader, FileOptions, McapFile, RecordError};

/// Suffix of a file being written; renamed to `.mcap` when finished.
pub const PARTIAL_SUFFIX: &str = ".mcap.tmp";

/// Recording settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderSettings {
    /// Directory of the files (created if missing).
    pub directory: PathBuf,
    /// File name prefix: `<prefix>-<UTC time>-<sequence>.mcap`.
    pub prefix: String,
    /// Record every input (needed for replay).
    pub inputs: bool,
    /// Record one `stat` record in this many per channel (0: none).
    pub stat_every: u64,
    /// Start a new file when the current one reaches this size.
    pub max_file_bytes: Option<u64>,
    /// Start a new file when the current one is this old.
    pub max_file_duration: Option<Duration>,
    /// Delete the oldest finished files while the recordings exceed this size.
    pub max_total_bytes: Option<u64>,
    /// Close the current chunk and flush at least this often.
    pub flush_interval: Duration,
    /// Chunking and compression.
    pub file: FileOptions,
    /// Capacity of the queue to the file thread, in messages; when full, the output
    /// stage waits (and intake drops, counted, upstream) rather than losing recorded
    /// data silently.
    pub queue: usize,
    /// Keep inputs only around alarms.
    pub capture: Option<Capture>,
}

impl Default for RecorderSettings {
    fn default() -> Self {
        Self {
            directory: PathBuf::from("recordings"),
            prefix: "glrmon".into(),
            inputs: true,
            stat_every: 1,
            max_file_bytes: Some(1 << 30),
            max_file_duration: Some(Duration::from_secs(3600)),
            max_total_bytes: None,
            flush_interval: Duration::from_secs(1),
            file: FileOptions::default(),
            queue: 65536,
            capture: None,
        }
    }
}

/// Pre/post-fault capture: the last `before` of each channel's inputs are kept in
/// memory and written when the channel raises an alarm, then its inputs are written for
/// `after` (extended by every further alarm). Results are always recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Capture {
    /// Inputs kept before an alarm.
    pub before: Duration,
    /// Inputs written after an alarm.
    pub after: Duration,
}

/// Counters of a recorder, shared with status queries.
#[derive(Debug, Default)]
pub struct RecorderStats {
    /// Messages written.
    pub messages: AtomicU64,
    /// Files finished (renamed to `.mcap`).
    pub files: AtomicU64,
    /// Files deleted by the disk cap.
    pub deleted: AtomicU64,
    /// Write failures (each also logged by the runtime).
    pub errors: AtomicU64,
    /// Bytes on disk of the finished files (including those the cap deleted since) and
    /// of the current file at its last flush.
    pub bytes: AtomicU64,
    /// The file being written.
    pub current: Mutex<Option<PathBuf>>,
    /// The files finished so far, oldest first (less those deleted by the cap).
    pub finished: Mutex<Vec<PathBuf>>,
}

enum Msg {
    Write {
        channel: Arc<str>,
        kind: TopicKind,
        log_time: u64,
        publish_time: u64,
        json: Vec<u8>,
        alarm: bool,
    },
    Stop,
}

/// The MCAP recording [`Sink`].
pub struct Recorder {
    tx: Option<SyncSender<Msg>>,
    thread: Option<JoinHandle<Vec<PathBuf>>>,
    stats: Arc<RecorderStats>,
    errors: Arc<Mutex<Vec<RecordError>>>,
    interest: Interest,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates the directory and the first file, and starts the file thread. The
    /// recorder is a [`glrmon_runtime::Sink`]: hand it to the runtime (or a
    /// [`glrmon_runtime::Fanout`]); [`Recorder::finish`] closes the last file.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_record::{FileHeader, Recorder, RecorderSettings};
    ///
    /// let dir = std::env::temp_dir().join(format!("glrmon-doc-recorder-{}", std::process::id()));
    /// let settings = RecorderSettings { directory: dir.clone(), ..RecorderSettings::default() };
    /// let header = FileHeader { config: String::new(), channels: vec!["pump3".into()], extra: Default::default() };
    /// let recorder = Recorder::start(settings, header).unwrap();
    /// let files = recorder.finish();
    /// assert_eq!(files.len(), 1);
    /// assert!(files[0].extension().is_some_and(|e| e == "mcap"));
    /// std::fs::remove_dir_all(dir).unwrap();
    /// ```
    ///
    /// # Errors
    /// [`RecordError`] when the directory or the first file cannot be created.
    pub fn start(settings: RecorderSettings, header: FileHeader) -> Result<Self, RecordError> {
        std::fs::create_dir_all(&settings.directory).map_err(|source| RecordError::Io {
            path: settings.directory.clone(),
            source,
        })?;
        let stats = Arc::new(RecorderStats::default());
        let mut files = Files {
            settings: settings.clone(),
            header,
            sequence: 0,
            current: None,
            opened: Instant::now(),
            finished: Vec::new(),
            finished_bytes: 0,
            stats: stats.clone(),
        };
        files.open()?;
        let (tx, rx) = mpsc::sync_channel(settings.queue.max(1));
        let errors = Arc::new(Mutex::new(Vec::new()));
        let thread_errors = errors.clone();
        let thread = std::thread::Builder::new()
            .name("glrmon-recorder".into())
            .spawn(move || file_thread(&rx, files, &thread_errors))
            .map_err(|source| RecordError::Io {
                path: settings.directory.clone(),
                source,
            })?;
        Ok(Self {
            tx: Some(tx),
            thread: Some(thread),
            stats,
            errors,
            interest: Interest {
                inputs: settings.inputs || settings.capture.is_some(),
                stat_every: Some(settings.stat_every),
            },
        })
    }

    /// The counters.
    #[must_use]
    pub fn stats(&self) -> Arc<RecorderStats> {
        self.stats.clone()
    }

    /// Finishes the current file (summary, index, rename) and returns every file
    /// finished by this recorder, oldest first.
    pub fn finish(mut self) -> Vec<PathBuf> {
        self.stop()
    }

    fn stop(&mut self) -> Vec<PathBuf> {
        if let Some(tx) = self.tx.take() {
            let _ = tx.send(Msg::Stop);
        }
        self.thread
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default()
    }

    fn send(&self, msg: Msg) -> Result<(), SinkError> {
        let failed = self.tx.as_ref().is_none_or(|tx| tx.send(msg).is_err());
        let pending = std::mem::take(
            &mut *self
                .errors
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        );
        if let Some(e) = pending.into_iter().next() {
            return Err(SinkError {
                sink: "mcap".into(),
                message: e.to_string(),
            });
        }
        if failed {
            return Err(SinkError {
                sink: "mcap".into(),
                message: "the recorder thread has stopped".into(),
            });
        }
        Ok(())
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Sink for Recorder {
    fn name(&self) -> &str {
        "mcap"
    }

    fn interest(&self) -> Interest {
        self.interest
    }

    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        let log_time = output.log_time_ns;
        let mut channel: Option<Arc<str>> = None;
        for (kind, json) in record_messages(output).into_iter().flatten() {
            let channel = channel.get_or_insert_with(|| Arc::from(output.record.channel()));
            self.send(Msg::Write {
                channel: channel.clone(),
                kind,
                log_time,
                publish_time: log_time,
                json: json.into_owned(),
                alarm: kind == TopicKind::Alarm,
            })?;
        }
        Ok(())
    }

    fn write_input(&mut self, input: &InputOutput) -> Result<(), SinkError> {
        self.send(Msg::Write {
            channel: input.name.clone(),
            kind: input_topic(&input.item),
            log_time: input.log_time_ns,
            publish_time: input.log_time_ns,
            json: input.json.clone(),
            alarm: false,
        })
    }
}

/// The sequence of files of one recorder.
struct Files {
    settings: RecorderSettings,
    header: FileHeader,
    sequence: u64,
    current: Option<McapFile>,
    opened: Instant,
    finished: Vec<PathBuf>,
    /// Bytes of the files finished so far.
    finished_bytes: u64,
    stats: Arc<RecorderStats>,
}

impl Files {
    fn open(&mut self) -> Result<(), RecordError> {
        // Never over an existing recording (e.g. of an earlier run in the same second).
        let stamp = utc_stamp(SystemTime::now());
        let path = loop {
            let stem = format!("{}-{stamp}-{:04}", self.settings.prefix, self.sequence);
            self.sequence += 1;
            let partial = self
                .settings
                .directory
                .join(format!("{stem}{PARTIAL_SUFFIX}"));
            if !partial.exists() && !finished_name(&partial).exists() {
                break partial;
            }
        };
        let file = McapFile::create(&path, self.settings.file, &self.header)?;
        *self
            .stats
            .current
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(path);
        self.current = Some(file);
        self.opened = Instant::now();
        Ok(())
    }

    fn close(&mut self) -> Result<(), RecordError> {
        let Some(file) = self.current.take() else {
            return Ok(());
        };
        let partial = file.finish()?;
        let done = finished_name(&partial);
        std::fs::rename(&partial, &done).map_err(|source| RecordError::Io {
            path: partial.clone(),
            source,
        })?;
        self.stats.files.fetch_add(1, Ordering::Relaxed);
        self.finished_bytes += std::fs::metadata(&done).map_or(0, |m| m.len());
        self.stats
            .bytes
            .store(self.finished_bytes, Ordering::Relaxed);
        self.finished.push(done);
        self.enforce_cap();
        self.stats
            .finished
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone_from(&self.finished);
        Ok(())
    }

    fn write(
        &mut self,
        channel: &str,
        kind: TopicKind,
        log_time: u64,
        publish: u64,
        json: &[u8],
    ) -> Result<(), RecordError> {
        if let Some(f) = &mut self.current {
            f.write(channel, kind, log_time, publish, json)?;
            self.stats.messages.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }

    /// Flushes; rotates when the file is too big or too old.
    fn tick(&mut self) -> Result<(), RecordError> {
        let Some(f) = &mut self.current else {
            return Ok(());
        };
        f.flush()?;
        let size = std::fs::metadata(f.path()).map_or(0, |m| m.len());
        self.stats
            .bytes
            .store(self.finished_bytes + size, Ordering::Relaxed);
        let too_big = self.settings.max_file_bytes.is_some_and(|max| size >= max);
        let too_old = self
            .settings
            .max_file_duration
            .is_some_and(|max| self.opened.elapsed() >= max);
        if too_big || too_old {
            self.close()?;
            self.open()?;
        }
        Ok(())
    }

    /// Deletes the oldest finished recordings of this prefix while the directory's
    /// recordings exceed the cap; never the file being written.
    fn enforce_cap(&mut self) {
        let Some(cap) = self.settings.max_total_bytes else {
            return;
        };
        let Ok(dir) = std::fs::read_dir(&self.settings.directory) else {
            return;
        };
        let prefix = format!("{}-", self.settings.prefix);
        let mut files: Vec<(SystemTime, PathBuf, u64)> = Vec::new();
        let mut total = 0;
        for entry in dir.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if !name.starts_with(&prefix) {
                continue;
            }
            let Ok(meta) = entry.metadata() else { continue };
            total += meta.len();
            if name.ends_with(".mcap") {
                let modified = meta.modified().unwrap_or(UNIX_EPOCH);
                files.push((modified, entry.path(), meta.len()));
            }
        }
        // Oldest last write first (names sort by start time only within one run).
        files.sort();
        for (_, path, size) in files {
            if total <= cap {
                break;
            }
            if std::fs::remove_file(&path).is_ok() {
                total = total.saturating_sub(size);
                self.stats.deleted.fetch_add(1, Ordering::Relaxed);
                self.finished.retain(|p| p != &path);
            }
        }
    }
}

/// The final name of a partial file (`x.mcap.tmp` → `x.mcap`).
#[must_use]
pub fn finished_name(partial: &Path) -> PathBuf {
    let s = partial.to_string_lossy();
    PathBuf::from(s.strip_suffix(".tmp").unwrap_or(&s).to_owned())
}

/// Per-channel inputs held back in capture mode.
#[derive(Default)]
struct Held {
    inputs: VecDeque<(TopicKind, u64, u64, Vec<u8>)>,
    /// Inputs are written directly until this log time (after an alarm).
    open_until: Option<u64>,
}

fn file_thread(
    rx: &Receiver<Msg>,
    mut files: Files,
    errors: &Mutex<Vec<RecordError>>,
) -> Vec<PathBuf> {
    let interval = files.settings.flush_interval.max(Duration::from_millis(10));
    let capture = files.settings.capture;
    let record_inputs = files.settings.inputs;
    let mut held: HashMap<Arc<str>, Held> = HashMap::new();
    let mut last_tick = Instant::now();
    let report = |files: &Files, e: RecordError| {
        files.stats.errors.fetch_add(1, Ordering::Relaxed);
        let mut errs = errors
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if errs.len() < 16 {
            errs.push(e);
        }
    };
    loop {
        let wait = interval.saturating_sub(last_tick.elapsed());
        match rx.recv_timeout(wait) {
            Ok(Msg::Write {
                channel,
                kind,
                log_time,
                publish_time,
                json,
                alarm,
            }) => {
                let is_input = matches!(kind, TopicKind::Inputs | TopicKind::Intake);
                let result = match capture {
                    Some(c) if is_input => {
                        let h = held.entry(channel.clone()).or_default();
                        if h.open_until.is_some_and(|until| log_time <= until) {
                            files.write(&channel, kind, log_time, publish_time, &json)
                        } else {
                            h.inputs.push_back((kind, log_time, publish_time, json));
                            let horizon = log_time.saturating_sub(nanos(c.before));
                            while h.inputs.front().is_some_and(|i| i.1 < horizon) {
                                h.inputs.pop_front();
                            }
                            Ok(())
                        }
                    }
                    _ if is_input && !record_inputs => Ok(()),
                    _ => {
                        let mut r = Ok(());
                        if let (Some(c), true) = (capture, alarm) {
                            // The alarm: the inputs before it, then keep writing.
                            let h = held.entry(channel.clone()).or_default();
                            for (k, l, p, j) in h.inputs.drain(..) {
                                r = r.and(files.write(&channel, k, l, p, &j));
                            }
                            h.open_until = Some(log_time.saturating_add(nanos(c.after)));
                        }
                        r.and(files.write(&channel, kind, log_time, publish_time, &json))
                    }
                };
                if let Err(e) = result {
                    report(&files, e);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Ok(Msg::Stop) | Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_tick.elapsed() >= interval {
            if let Err(e) = files.tick() {
                report(&files, e);
            }
            last_tick = Instant::now();
        }
    }
    if let Err(e) = files.close() {
        report(&files, e);
    }
    files.finished
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// `YYYYMMDDTHHMMSSZ` for a time (UTC).
fn utc_stamp(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (y, m, d, hh, mm, ss) = crate::summary::civil(secs);
    format!("{y:04}{m:02}{d:02}T{hh:02}{mm:02}{ss:02}Z")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Event, McapReader, ReadEnd};
    use glrmon_runtime::InputItem;
    use glrmon_wire::{IntakeEvent, Sample};

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("glrmon-recorder-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn input(k: u64, log_ms: u64) -> InputOutput {
        let s = Sample {
            k: Some(k),
            t: None,
            u: vec![],
            y: vec![k as f64 * 0.1, -1.0 / (k as f64 + 3.0)],
            p: vec![],
        };
        let mut json = Vec::new();
        glrmon_wire::encode_sample("a", &s, &mut json).unwrap();
        InputOutput {
            channel: 0,
            name: Arc::from("a"),
            item: InputItem::Sample(s),
            json,
            log_time_ns: log_ms * 1_000_000,
        }
    }

    /// (k of every input, how the file ended) of each file, in name order.
    fn read_dir(dir: &Path) -> Vec<(PathBuf, Vec<u64>, ReadEnd)> {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        paths.sort();
        paths
            .into_iter()
            .map(|p| {
                let mut r = McapReader::new(std::fs::File::open(&p).unwrap()).unwrap();
                let mut ks = Vec::new();
                let mut config = false;
                while let Some(e) = r.next_event().unwrap() {
                    match e {
                        Event::Metadata { entries, .. } => {
                            config = entries.get("config").is_some_and(|c| c == "cfg");
                        }
                        Event::Message(m) if m.topic.kind == Some(TopicKind::Inputs) => {
                            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                            ks.push(v["k"].as_u64().unwrap());
                        }
                        Event::Message(_) => {}
                    }
                }
                assert!(
                    config,
                    "{}: the configuration is repeated in every file",
                    p.display()
                );
                (p, ks, r.end().clone())
            })
            .collect()
    }

    fn header() -> FileHeader {
        FileHeader {
            config: "cfg".into(),
            channels: vec!["a".into()],
            extra: std::collections::BTreeMap::new(),
        }
    }

    /// Rotation by size: every file finished under its final name, with the schemas and
    /// the configuration; together they hold every input once, in order. Then a disk
    /// cap deletes the oldest files only.
    #[test]
    fn rotation_by_size_keeps_every_input_once_and_the_cap_deletes_the_oldest() {
        let dir = scratch("rotate");
        let settings = RecorderSettings {
            directory: dir.clone(),
            max_file_bytes: Some(20_000),
            flush_interval: Duration::from_millis(10),
            file: FileOptions {
                chunk_bytes: 4096,
                zstd: true,
            },
            ..RecorderSettings::default()
        };
        let mut rec = Recorder::start(settings.clone(), header()).unwrap();
        let n = 20_000;
        for k in 0..n {
            rec.write_input(&input(k, k)).unwrap();
            if k % 2000 == 1999 {
                // Rotation is checked at each flush (at least every flush interval).
                let t = Instant::now();
                let before = rec.stats().files.load(Ordering::Relaxed);
                while rec.stats().files.load(Ordering::Relaxed) == before
                    && t.elapsed() < Duration::from_secs(10)
                {
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
        }
        let files = rec.finish();
        assert!(files.len() >= 5, "{} files", files.len());
        let read = read_dir(&dir);
        assert_eq!(read.len(), files.len(), "no .tmp file is left");
        let all: Vec<u64> = read.iter().flat_map(|(_, ks, _)| ks.clone()).collect();
        assert_eq!(all, (0..n).collect::<Vec<_>>());
        assert!(read.iter().all(|(_, _, end)| *end == ReadEnd::Finished));

        // The cap: a recorder over the same directory, with room for the two newest
        // files of the first recorder and its own (empty) file, whose size (schemas,
        // configuration, footer) is measured rather than assumed, plus 1 kB of slack.
        let size = |p: &Path| std::fs::metadata(p).unwrap().len();
        let empty_dir = scratch("rotate-empty");
        let empty = Recorder::start(
            RecorderSettings {
                directory: empty_dir.clone(),
                ..settings.clone()
            },
            header(),
        )
        .unwrap()
        .finish();
        let empty_size = size(&empty[0]);
        std::fs::remove_dir_all(&empty_dir).unwrap();
        let newest: Vec<&PathBuf> = files.iter().rev().take(2).collect();
        let cap = newest.iter().map(|p| size(p)).sum::<u64>() + empty_size + 1_000;
        let capped = RecorderSettings {
            max_total_bytes: Some(cap),
            max_file_bytes: Some(1_000_000),
            ..settings
        };
        let rec = Recorder::start(capped, header()).unwrap();
        let stats = rec.stats();
        let _ = rec.finish();
        let left = read_dir(&dir);
        let total: u64 = left.iter().map(|(p, _, _)| size(p)).sum();
        assert!(total <= cap, "{total} bytes left, cap {cap}");
        assert_eq!(left.len(), 3, "the two newest and the new file");
        assert_eq!(
            stats.deleted.load(Ordering::Relaxed),
            files.len() as u64 - 2
        );
        for p in newest {
            assert!(
                left.iter().any(|(q, _, _)| q == p),
                "{} deleted",
                p.display()
            );
        }
        // The last input recorded is still there.
        assert!(left.iter().any(|(_, ks, _)| ks.contains(&(n - 1))));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Rotation by age: a file older than `max_file_duration` is finished at the next
    /// flush and a new one begun; no input is lost or repeated across the files.
    #[test]
    fn rotation_by_duration_finishes_files_as_they_age() {
        let dir = scratch("age");
        let settings = RecorderSettings {
            directory: dir.clone(),
            max_file_duration: Some(Duration::from_millis(30)),
            flush_interval: Duration::from_millis(10),
            ..RecorderSettings::default()
        };
        let mut rec = Recorder::start(settings, header()).unwrap();
        let stats = rec.stats();
        let mut k = 0;
        // Until three files are finished (bounded), one input at a time.
        let t = Instant::now();
        while stats.files.load(Ordering::Relaxed) < 3 && t.elapsed() < Duration::from_secs(20) {
            rec.write_input(&input(k, k)).unwrap();
            k += 1;
            std::thread::sleep(Duration::from_millis(1));
        }
        let files = rec.finish();
        assert!(files.len() >= 4, "{files:?}");
        let read = read_dir(&dir);
        let all: Vec<u64> = read.iter().flat_map(|(_, ks, _)| ks.clone()).collect();
        assert_eq!(all, (0..k).collect::<Vec<_>>());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Capture mode: without an alarm no input is written; at an alarm the last
    /// `before` of inputs are, then `after` more.
    #[test]
    fn capture_writes_inputs_only_around_an_alarm() {
        let dir = scratch("capture");
        let settings = RecorderSettings {
            directory: dir.clone(),
            capture: Some(Capture {
                before: Duration::from_millis(100),
                after: Duration::from_millis(50),
            }),
            ..RecorderSettings::default()
        };
        let mut rec = Recorder::start(settings, header()).unwrap();
        for k in 0..1000 {
            rec.write_input(&input(k, k)).unwrap();
            if k == 500 {
                let alarm = glrmon_wire::Record::AlarmEnd(glrmon_wire::AlarmEnd {
                    channel: "a".into(),
                    k,
                    t: None,
                    onset: k,
                    duration: 0,
                    peak_glr: 0.0,
                });
                // An alarm_end does not open the capture; the alarm below does.
                rec.write(&Output {
                    record: alarm,
                    json: b"{}".to_vec(),
                    log_time_ns: k * 1_000_000,
                    stat_index: None,
                })
                .unwrap();
                rec.write(&Output {
                    record: glrmon_wire::Record::Alarm(glrmon_wire::Alarm {
                        channel: "a".into(),
                        k,
                        t: None,
                        glr: 1.0,
                        threshold: 0.5,
                        onset: k,
                        magnitude: vec![],
                        isolation: vec![],
                        faults: vec![],
                        update_k: None,
                    }),
                    json: b"{}".to_vec(),
                    log_time_ns: k * 1_000_000,
                    stat_index: None,
                })
                .unwrap();
            }
        }
        let _ = rec.write_input(&InputOutput {
            item: InputItem::Intake(IntakeEvent::Dropped { count: 1 }),
            ..input(1000, 1000)
        });
        rec.finish();
        let read = read_dir(&dir);
        assert_eq!(read.len(), 1);
        assert_eq!(read[0].1, (400..=550).collect::<Vec<_>>());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn utc_stamp_matches_known_dates() {
        assert_eq!(utc_stamp(UNIX_EPOCH), "19700101T000000Z");
        let t = UNIX_EPOCH + Duration::from_secs(1_732_200_000);
        assert_eq!(utc_stamp(t), "20241121T144000Z");
        let leap = UNIX_EPOCH + Duration::from_secs(951_825_600); // 2000-02-29 12:00
        assert_eq!(utc_stamp(leap), "20000229T120000Z");
    }
}
