//! `glrmon run`: the daemon. One Zenoh session; a subscriber per channel feeds the
//! runtime's workers; results go back on Zenoh (and to the log); SIGINT/SIGTERM stop
//! intake, drain, publish what is pending and close the session within a bounded time.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_runtime::{Output, Runtime, RuntimeEvents, RuntimeSettings, Sink, SinkError};
use glrmon_wire::{DecodeLimits, Record};
use glrmon_zenoh::{Presence, StatusSource, ZenohSink, ZenohSource};

use glrmon_record::Recorder;

use crate::net::ZenohArgs;
use crate::{load_config, print, recording};

#[derive(Debug, Args)]
pub(crate) struct RunArgs {
    /// Configuration file.
    #[arg(long)]
    config: PathBuf,
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Instance name (default: the config's `daemon.instance`, else `glrmon-<pid>`).
    #[arg(long)]
    instance: Option<String>,
}

/// Logs sink failures (data lost: ERROR).
pub(crate) struct LogEvents;

impl RuntimeEvents for LogEvents {
    fn sink_error(&self, error: &SinkError) {
        tracing::error!(error = %error, "A result could not be delivered.");
    }
}

/// Logs alarms (INFO) and rejected input (WARN, at most one line per channel and code
/// per second, with the number suppressed).
pub(crate) struct LogSink {
    last: HashMap<(String, &'static str), (Instant, u64)>,
}

impl LogSink {
    pub(crate) fn new() -> Self {
        Self {
            last: HashMap::new(),
        }
    }
}

impl Sink for LogSink {
    fn name(&self) -> &str {
        "log"
    }

    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        match &output.record {
            Record::Alarm(_) | Record::AlarmEnd(_) => {
                if let Some(line) = print::line(&output.record) {
                    tracing::info!(channel = output.record.channel(), "{line}");
                }
            }
            Record::Consistency(c) => {
                let line = print::line(&output.record).unwrap_or_default();
                if c.state == "consistent" {
                    tracing::info!(channel = %c.channel, "The model fits again: {line}");
                } else {
                    tracing::warn!(channel = %c.channel, "The model no longer fits the plant: {line}");
                }
            }
            Record::Error(e) => {
                let key = (e.channel.clone(), e.code.as_str());
                let now = Instant::now();
                let entry = self
                    .last
                    .entry(key)
                    .or_insert((now - Duration::from_secs(2), 0));
                if now.duration_since(entry.0) >= Duration::from_secs(1) {
                    tracing::warn!(channel = %e.channel, code = e.code.as_str(), suppressed = entry.1, "Rejected input: {}.", e.message);
                    *entry = (now, 0);
                } else {
                    entry.1 += 1;
                }
            }
            _ => {}
        }
        Ok(())
    }
}

pub(crate) fn runtime_settings(cfg: &glrmon_spec::Config) -> RuntimeSettings {
    let d = &cfg.daemon;
    RuntimeSettings {
        workers: d.workers.unwrap_or_else(|| {
            std::thread::available_parallelism().map_or(2, std::num::NonZero::get)
        }),
        worker_queue: d.worker_queue,
        output_queue: d.output_queue,
        stat_every: d.stat_every,
        limits: DecodeLimits {
            max_payload_bytes: d.max_payload_bytes,
            ..DecodeLimits::default()
        },
    }
}

pub(crate) fn run(args: &RunArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args.config)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(daemon(cfg, args))
}

async fn daemon(cfg: glrmon_spec::Config, args: &RunArgs) -> anyhow::Result<()> {
    let instance = args
        .instance
        .clone()
        .or_else(|| cfg.daemon.instance.clone())
        .unwrap_or_else(|| format!("glrmon-{}", std::process::id()));
    let mut settings = args.zenoh.settings(Some(&cfg.zenoh));
    if settings.config_file.is_none() && settings.listen.is_empty() && settings.connect.is_empty() {
        settings.listen = vec![crate::DEFAULT_ENDPOINT.to_owned()];
    }
    let session = glrmon_zenoh::open(&settings).await?;
    let monitors = cfg
        .channels
        .iter()
        .map(Monitor::from_channel)
        .collect::<Result<Vec<_>, _>>()?;
    let mut sinks: Vec<Box<dyn Sink>> = vec![
        Box::new(ZenohSink::new(session.clone())),
        Box::new(LogSink::new()),
    ];
    let mut recorder_stats = None;
    if cfg.recording.enabled {
        let settings = recording::recorder_settings(&cfg.recording);
        for f in recording::leftovers(&settings.directory) {
            tracing::warn!(
                file = %f.display(),
                "An unfinished recording from an earlier run: `glrmon recover {}` rewrites it as a finished file.",
                f.display()
            );
        }
        let directory = settings.directory.clone();
        let recorder = Recorder::start(settings, recording::file_header(&cfg, &instance))
            .map_err(|e| anyhow::anyhow!("starting the recorder: {e}"))?;
        recorder_stats = Some(recorder.stats());
        tracing::info!(directory = %directory.display(), "Recording inputs and results (MCAP).");
        sinks.push(Box::new(recorder));
    }
    let runtime = Runtime::start(
        monitors,
        sinks,
        &runtime_settings(&cfg),
        Arc::new(LogEvents),
    );
    let keys: Vec<String> = cfg.channels.iter().map(|c| c.key.clone()).collect();
    let source = ZenohSource::declare(&session, &keys, &runtime.intake()).await?;
    let presence = Presence::declare(
        &session,
        StatusSource {
            instance: instance.clone(),
            channels: runtime.channel_names().to_vec(),
            stats: runtime.stats(),
            started: Instant::now(),
        },
    )
    .await?;
    tracing::info!(
        instance = %instance,
        channels = cfg.channels.len(),
        zid = %session.zid(),
        "Monitoring started."
    );
    // Lets tests and supervisors know intake is open.
    println!(
        "glrmon run: instance {instance} monitoring {} channel(s)",
        cfg.channels.len()
    );
    wait_for_signal().await;
    let started = Instant::now();
    tracing::info!("Stopping: intake closed, draining.");
    drop(source);
    let timeout = Duration::from_secs_f64(cfg.daemon.shutdown_timeout);
    let runtime = Mutex::new(Some(runtime));
    let (in_time, sinks) = tokio::task::spawn_blocking(move || {
        runtime
            .lock()
            .ok()
            .and_then(|mut r| r.take())
            .map_or((true, Vec::new()), |r| r.shutdown(timeout))
    })
    .await?;
    // Dropping the recorder finishes its file (summary, index, final name).
    drop(sinks);
    if let Some(stats) = recorder_stats {
        let finished = stats.finished.lock().map(|f| f.clone()).unwrap_or_default();
        tracing::info!(
            messages = stats.messages.load(std::sync::atomic::Ordering::Relaxed),
            files = finished.len(),
            last = %finished.last().map(|p| p.display().to_string()).unwrap_or_default(),
            "Recording finished."
        );
    }
    drop(presence);
    if let Err(e) = tokio::time::timeout(Duration::from_secs(2), session.close()).await {
        tracing::warn!(error = %e, "The Zenoh session did not close in time.");
    }
    if in_time {
        tracing::info!(
            elapsed_ms = started.elapsed().as_millis() as u64,
            "Stopped."
        );
        Ok(())
    } else {
        Err(anyhow::anyhow!(
            "the drain did not finish within {timeout:?}: pending results were lost"
        ))
    }
}

/// SIGINT or SIGTERM.
async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
