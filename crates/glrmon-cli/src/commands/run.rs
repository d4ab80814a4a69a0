//! `glrmon run`: the daemon. One Zenoh session; a subscriber per channel feeds the
//! runtime's workers; results go back on Zenoh (and to the log); SIGINT/SIGTERM stop
//! intake, drain, publish what is pending and close the session within a bounded time.
//! Under systemd (`Type=notify`, `NOTIFY_SOCKET` set) it reports READY=1 once intake is
//! open, RELOADING=1 … READY=1 around a SIGHUP reload and STOPPING=1 when the drain
//! starts, and pings the watchdog while every worker runs (`WatchdogSec=`).

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Args;
use glrmon_runtime::{ChannelSetup, Output, Runtime, RuntimeSettings, Sink, SinkError};
use glrmon_wire::Record;
use glrmon_zenoh::{ConnectivityWatch, Ownership, Presence, StatusSource, ZenohSink, ZenohSource};

use glrmon_record::{Recorder, RecorderSettings};

use crate::common::load_config;
use crate::flags::ZenohArgs;
use crate::log::LogEvents;
use crate::print;

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
    /// Monitor only shard I of N of the configured channels (`I/N`, 0 ≤ I < N; a stable
    /// hash of the channel name), overriding `daemon.shard`.
    #[arg(long, value_name = "I/N")]
    shard: Option<glrmon_spec::Shard>,
    /// Monitor only the channels whose input key intersects this key expression
    /// (e.g. `plant/line2/**`); applied before `--shard`.
    #[arg(long, value_name = "KEYEXPR")]
    channels: Option<String>,
    /// Serve Prometheus `/metrics`, `/healthz` and `/readyz` on this local address
    /// (e.g. 127.0.0.1:9464), overriding `daemon.metrics`.
    #[arg(long, value_name = "ADDR")]
    metrics: Option<String>,
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
            Record::Alarm(_) | Record::Isolation(_) | Record::AlarmEnd(_) => {
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
                    let what = if e.code.rejects_input() {
                        "Rejected input"
                    } else {
                        "Input stream"
                    };
                    tracing::warn!(channel = %e.channel, code = e.code.as_str(), suppressed = entry.1, "{what}: {}.", e.message);
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

pub(crate) fn run(args: &RunArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args.config)?;
    // What `glrmon validate` prints as warnings, e.g. a rounded covariance the model
    // replaced by its nearest PSD matrix: the daemon's log says so too.
    for w in &cfg.warnings {
        tracing::warn!(path = %w.path, "Configuration: {}.", w.message);
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(daemon(cfg, args))
}

async fn daemon(cfg: glrmon_spec::Config, args: &RunArgs) -> anyhow::Result<()> {
    let shard = match (args.shard, &cfg.daemon.shard) {
        (Some(s), _) => Some(s),
        // Checked when the configuration was loaded.
        (None, Some(text)) => text.parse().ok(),
        (None, None) => None,
    };
    let configured = cfg.channels.len();
    let mut cfg = cfg;
    if let Some(expr) = &args.channels {
        let selector = zenoh::key_expr::KeyExpr::new(expr.as_str()).map_err(|e| {
            crate::common::InvalidInput(format!(
                "--channels \"{expr}\" is not a key expression: {e}"
            ))
        })?;
        cfg.channels.retain(|c| {
            zenoh::key_expr::KeyExpr::new(c.key.as_str()).is_ok_and(|k| k.intersects(&selector))
        });
        tracing::info!(keyexpr = %expr, channels = cfg.channels.len(), of = configured, "Monitoring the channels whose key intersects the selection.");
        if cfg.channels.is_empty() {
            tracing::warn!(keyexpr = %expr, "No configured channel's key intersects the selection.");
        }
    }
    let cfg = cfg.into_shard(shard);
    if let Some(s) = shard {
        tracing::info!(shard = %s, channels = cfg.channels.len(), of = configured, "Monitoring one shard of the configured channels.");
        if cfg.channels.is_empty() {
            tracing::warn!(shard = %s, "No configured channel falls in this shard.");
        }
    }
    if let Some(name) = &args.instance
        && let Err(e) = glrmon_spec::validate_instance(name)
    {
        return Err(crate::common::InvalidInput(format!("--instance {e}")).into());
    }
    let instance = args
        .instance
        .clone()
        .or_else(|| cfg.daemon.instance.clone())
        .unwrap_or_else(|| format!("glrmon-{}", std::process::id()));
    let mut settings = args.zenoh.settings(Some(&cfg.zenoh));
    if settings.config_file.is_none() && settings.listen.is_empty() && settings.connect.is_empty() {
        settings.listen = vec![crate::common::DEFAULT_ENDPOINT.to_owned()];
    }
    let session = open_session(&settings).await?;
    let endpoints = glrmon_zenoh::Endpoints::of(&settings)?;
    let status_overlaps = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let names: Vec<String> = cfg.channels.iter().map(|c| c.name.clone()).collect();
    let overlaps = Arc::clone(&status_overlaps);
    let ownership = Ownership::claim(
        &session,
        &instance,
        &names,
        Duration::from_secs(3),
        move |channel, other| {
            overlaps.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            tracing::error!(channel, other, "Another instance claims a channel this one monitors: both publish its results. Give each instance a disjoint set of channels (daemon.shard).");
        },
    )
    .await
    .map_err(|e| match e {
        glrmon_zenoh::ZenohError::Overlap(m) => anyhow::Error::new(crate::common::InvalidInput(m)),
        other => other.into(),
    })?;
    let connectivity = ConnectivityWatch::start(
        session.clone(),
        Duration::from_millis(100),
        |connected, state| {
            let reconnections = state
                .reconnections
                .load(std::sync::atomic::Ordering::Relaxed);
            if !connected {
                tracing::warn!(
                    "Lost every Zenoh connection (routers and peers); retrying. Channels keep their state."
                );
            } else if reconnections > 0 {
                tracing::info!(reconnections, "Reconnected to the Zenoh network.");
            } else {
                tracing::info!("Connected to the Zenoh network.");
            }
        },
    )?;
    // A daemon that listens can be reached by publishers as soon as its listener is up
    // (the session would not have opened otherwise): readiness does not wait for one.
    connectivity.state().listening.store(
        !endpoints.listen.is_empty(),
        std::sync::atomic::Ordering::Relaxed,
    );
    let monitors = cfg
        .channels
        .iter()
        .map(ChannelSetup::from_channel)
        .collect::<Result<Vec<_>, _>>()?;
    let mut sinks: Vec<Box<dyn Sink>> = vec![
        Box::new(ZenohSink::new(session.clone())),
        Box::new(LogSink::new()),
    ];
    let mut recorder_stats = None;
    if cfg.recording.enabled {
        let settings = RecorderSettings::from_spec(&cfg.recording);
        for f in glrmon_record::leftovers(&settings.directory) {
            tracing::warn!(
                file = %f.display(),
                "An unfinished recording from an earlier run: `glrmon recover {}` rewrites it as a finished file.",
                f.display()
            );
        }
        let directory = settings.directory.clone();
        let recorder = Recorder::start(settings, glrmon_record::file_header(&cfg, &instance))
            .map_err(|e| anyhow::anyhow!("starting the recorder: {e}"))?;
        recorder_stats = Some(recorder.stats());
        tracing::info!(directory = %directory.display(), "Recording inputs and results (MCAP).");
        sinks.push(Box::new(recorder));
    }
    let runtime = Runtime::start(
        monitors,
        sinks,
        &RuntimeSettings::from_spec(&cfg.daemon),
        Arc::new(LogEvents),
    );
    let ready = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let metrics_server = match args.metrics.as_ref().or(cfg.daemon.metrics.as_ref()) {
        Some(addr) => {
            let runtime_metrics = runtime.metrics();
            let source = glrmon_metrics::MetricsSource {
                instance: instance.clone(),
                channels: runtime.channel_names().to_vec(),
                stats: runtime.stats(),
                workers: runtime_metrics
                    .workers_alive
                    .load(std::sync::atomic::Ordering::Relaxed),
                runtime: runtime_metrics,
                connectivity: connectivity.state(),
                recorder: recorder_stats.clone(),
                started: Instant::now(),
                ready: Arc::clone(&ready),
            };
            {
                let (bound, task) = glrmon_metrics::serve(addr, Arc::new(source)).await?;
                tracing::info!(address = %bound, "Serving /metrics, /healthz and /readyz.");
                if let Some(warning) = glrmon_metrics::exposure_warning(bound) {
                    tracing::warn!(address = %bound, "{warning}");
                }
                Some(task)
            }
        }
        None => None,
    };
    let keys: Vec<String> = cfg.channels.iter().map(|c| c.key.clone()).collect();
    let source = ZenohSource::declare(&session, &keys, &runtime.intake()).await?;
    let presence = Presence::declare(&session, {
        let mut status = StatusSource::new(
            instance.clone(),
            runtime.channel_names().to_vec(),
            runtime.stats(),
        );
        status.connectivity = Some(connectivity.state());
        status.shard = shard.map(|s| s.to_string());
        status.overlaps = status_overlaps;
        status
    })
    .await?;
    ready.store(true, std::sync::atomic::Ordering::Relaxed);
    let zenoh_line = format!(
        "zenoh {} {}, listen {}, connect {}",
        endpoints.mode,
        session.zid(),
        list_or_none(&endpoints.listen),
        list_or_none(&endpoints.connect)
    );
    tracing::info!(
        instance = %instance,
        channels = cfg.channels.len(),
        mode = %endpoints.mode,
        zid = %session.zid(),
        listen = %list_or_none(&endpoints.listen),
        connect = %list_or_none(&endpoints.connect),
        "Monitoring started."
    );
    // The signal handlers go in before the readiness line: a SIGHUP (systemctl reload)
    // or SIGTERM that follows it at once must be handled, not take the default action
    // (which ends the process without a drain).
    #[cfg(unix)]
    let signals = {
        use tokio::signal::unix::{SignalKind, signal};
        (
            signal(SignalKind::hangup()).ok(),
            signal(SignalKind::terminate()).ok(),
            signal(SignalKind::interrupt()).ok(),
        )
    };
    // Lets tests and supervisors know intake is open.
    let monitoring = format!(
        "instance {instance} monitoring {} channel(s){}",
        cfg.channels.len(),
        shard.map_or(String::new(), |s| format!(" (shard {s} of {configured})"))
    );
    println!("glrmon run: {monitoring}; {zenoh_line}");
    notify::ready(&monitoring);
    let watchdog = notify::watchdog(runtime.metrics());
    let timeout = Duration::from_secs_f64(cfg.daemon.shutdown_timeout);
    let mut applied = cfg;
    #[cfg(unix)]
    {
        let (mut hup, mut term, mut int) = signals;
        // A stream that could not be made waits forever (its signal keeps its default).
        async fn next(s: &mut Option<tokio::signal::unix::Signal>) {
            match s {
                Some(s) => {
                    s.recv().await;
                }
                None => std::future::pending().await,
            }
        }
        loop {
            tokio::select! {
                () = next(&mut term) => break,
                () = next(&mut int) => break,
                () = next(&mut hup) => {
                    notify::reloading();
                    applied = tokio::task::block_in_place(|| {
                        reload(&args.config, applied, shard, &runtime)
                    });
                    notify::ready(&monitoring);
                }
            }
        }
    }
    #[cfg(not(unix))]
    wait_for_signal().await;
    drop(applied);
    let started = Instant::now();
    notify::stopping();
    drop(watchdog);
    tracing::info!("Stopping: intake closed, draining.");
    drop(source);
    ready.store(false, std::sync::atomic::Ordering::Relaxed);
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
    if let Some(server) = metrics_server {
        server.abort();
    }
    drop(ownership);
    drop(connectivity);
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

/// Endpoints for the start line: comma-separated, or "none".
fn list_or_none(v: &[String]) -> String {
    if v.is_empty() {
        "none".to_owned()
    } else {
        v.join(",")
    }
}

/// The systemd notification protocol (sd_notify(3)) through the `sd-notify` crate: each
/// call does nothing when `NOTIFY_SOCKET` is unset (not started by systemd, or not
/// `Type=notify`), and a failure to send is logged, never fatal.
mod notify {
    use std::sync::Arc;

    use glrmon_runtime::RuntimeMetrics;

    #[cfg(unix)]
    fn send(what: &str, states: &[sd_notify::NotifyState<'_>]) {
        if let Err(e) = sd_notify::notify(states) {
            tracing::warn!(error = %e, "Could not tell systemd {what} (NOTIFY_SOCKET).");
        }
    }

    /// READY=1 with a STATUS= line: intake is open (at start, and after a reload).
    pub(super) fn ready(status: &str) {
        #[cfg(unix)]
        send(
            "READY=1",
            &[
                sd_notify::NotifyState::Ready,
                sd_notify::NotifyState::Status(status),
            ],
        );
        #[cfg(not(unix))]
        let _ = status;
    }

    /// RELOADING=1 with MONOTONIC_USEC= (systemd ≥ 253 needs it to match the reload to
    /// its `ExecReload=`), before a SIGHUP reload; [`ready`] follows it.
    pub(super) fn reloading() {
        #[cfg(unix)]
        {
            let mut states = vec![sd_notify::NotifyState::Reloading];
            if let Ok(now) = sd_notify::NotifyState::monotonic_usec_now() {
                states.push(now);
            }
            send("RELOADING=1", &states);
        }
    }

    /// STOPPING=1: the drain starts.
    pub(super) fn stopping() {
        #[cfg(unix)]
        send("STOPPING=1", &[sd_notify::NotifyState::Stopping]);
    }

    /// With `WatchdogSec=` set (WATCHDOG_USEC for this process), WATCHDOG=1 every half
    /// period while every worker thread runs: a stopped worker (or a hung runtime) lets
    /// systemd restart the service. `None` without a watchdog; the pings stop when the
    /// returned task is dropped (at STOPPING=1: systemd does not watch a stopping
    /// service).
    pub(super) fn watchdog(metrics: Arc<RuntimeMetrics>) -> Option<WatchdogTask> {
        #[cfg(unix)]
        {
            let period = sd_notify::watchdog_enabled()? / 2;
            use std::sync::atomic::Ordering;
            let workers = metrics.workers_alive.load(Ordering::Relaxed);
            Some(WatchdogTask(tokio::spawn(async move {
                let mut tick = tokio::time::interval(period);
                loop {
                    tick.tick().await;
                    if metrics.workers_alive.load(Ordering::Relaxed) == workers {
                        send("WATCHDOG=1", &[sd_notify::NotifyState::Watchdog]);
                    }
                }
            })))
        }
        #[cfg(not(unix))]
        {
            let _ = metrics;
            None
        }
    }

    /// The watchdog's ping task, aborted when dropped.
    #[derive(Debug)]
    pub(super) struct WatchdogTask(tokio::task::JoinHandle<()>);

    impl Drop for WatchdogTask {
        fn drop(&mut self) {
            self.0.abort();
        }
    }
}

/// SIGHUP: reads the configuration file again and applies each channel's new
/// thresholds and alarm settings to its running monitor; refuses (logging why, changing
/// nothing) an invalid file or any change that needs a restart. Returns the
/// configuration in force.
fn reload(
    path: &std::path::Path,
    current: glrmon_spec::Config,
    shard: Option<glrmon_spec::Shard>,
    runtime: &Runtime,
) -> glrmon_spec::Config {
    let new = match load_config(path) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!(config = %path.display(), "Reload refused, nothing changed: {e}");
            return current;
        }
    };
    let blockers = current.restart_needed(&new);
    if !blockers.is_empty() {
        tracing::error!(
            config = %path.display(),
            "Reload refused, nothing changed: {}. Restart glrmon to apply these.",
            blockers.join("; ")
        );
        return current;
    }
    let new = new.into_shard(shard);
    let retuned = runtime.retune_from(&new);
    tracing::info!(
        config = %path.display(),
        channels = retuned,
        "Configuration reloaded: thresholds and alarm settings applied; the filters go on."
    );
    new
}

/// Opens the session; in client mode, retries until a router answers (the daemon may
/// start before its router), logging each failure, until SIGINT/SIGTERM.
async fn open_session(settings: &glrmon_zenoh::SessionSettings) -> anyhow::Result<zenoh::Session> {
    let client = settings.mode.as_deref() == Some("client");
    let mut delay = Duration::from_millis(250);
    loop {
        match glrmon_zenoh::open(settings).await {
            Ok(s) => return Ok(s),
            Err(e) if client => {
                tracing::warn!(error = %e, retry_in_ms = delay.as_millis() as u64, connect = ?settings.connect, "No Zenoh router reachable yet; retrying.");
                tokio::select! {
                    () = tokio::time::sleep(delay) => {}
                    () = wait_for_signal() => anyhow::bail!("stopped before a Zenoh router was reachable"),
                }
                delay = (delay * 2).min(Duration::from_secs(2));
            }
            Err(e) => return Err(e.into()),
        }
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
