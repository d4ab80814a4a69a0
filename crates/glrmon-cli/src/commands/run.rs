//! `glrmon run`: the daemon ([`glrmon_daemon`]) in a process: flags, the Zenoh session,
//! the log, signals. A subscriber per channel feeds the runtime's workers; results go
//! back on Zenoh (and to the log); SIGINT/SIGTERM stop
//! intake, drain, publish what is pending and close the session within a bounded time.
//! Under systemd (`Type=notify`, `NOTIFY_SOCKET` set) it reports READY=1 once intake is
//! open, RELOADING=1 … READY=1 around a SIGHUP reload and STOPPING=1 when the drain
//! starts, and pings the watchdog while every worker runs (`WatchdogSec=`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;
use glrmon_daemon::{Daemon, DaemonBuilder};
use glrmon_wire::text::Escaped;

use crate::common::load_config;
use crate::flags::ZenohArgs;
use crate::log::{LogEvents, LogSink};

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
    /// hash of the channel name), or `auto`: the instances started from this
    /// configuration split its channels among the live ones and take over those of an
    /// instance that is lost (docs/OPERATIONS.md). Overrides `daemon.shard`.
    #[arg(long, value_name = "I/N|auto")]
    shard: Option<glrmon_spec::ShardMode>,
    /// Monitor only the channels whose input key intersects this key expression
    /// (e.g. `plant/line2/**`); applied before `--shard`.
    #[arg(long, value_name = "KEYEXPR")]
    channels: Option<String>,
    /// Serve Prometheus `/metrics`, `/healthz` and `/readyz` on this local address
    /// (e.g. 127.0.0.1:9464), overriding `daemon.metrics`.
    #[arg(long, value_name = "ADDR")]
    metrics: Option<String>,
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
    let cfg = glrmon_daemon::select_channels(
        cfg,
        args.channels.as_deref(),
        shard.and_then(glrmon_spec::ShardMode::fixed),
    )
    .map_err(daemon_error)?;
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
    settings.connect_hint = Some(endpoint_hint(args, &cfg.zenoh, "connect"));
    settings.listen_hint = Some(endpoint_hint(args, &cfg.zenoh, "listen"));
    let session = open_session(&settings).await?;
    let endpoints = glrmon_zenoh::Endpoints::of(&settings)?;
    warn_if_unconnected(&session, &endpoints, &settings).await;
    let channels = cfg.channels.len();
    let timeout = Duration::from_secs_f64(cfg.daemon.shutdown_timeout);
    let metrics = args.metrics.clone().or_else(|| cfg.daemon.metrics.clone());
    let mut daemon = DaemonBuilder::new(cfg, &instance)
        .shard(shard)
        .metrics(metrics)
        .sink(Box::new(LogSink::new()))
        .events(Arc::new(LogEvents))
        .start(&session, &endpoints)
        .await
        .map_err(daemon_error)?;
    let zenoh_line = format!(
        "zenoh {} {}, listen {}, connect {}",
        endpoints.mode,
        session.zid(),
        list_or_none(&endpoints.listen),
        list_or_none(&endpoints.connect)
    );
    tracing::info!(
        instance = %instance,
        channels,
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
    let monitoring = match shard {
        Some(glrmon_spec::ShardMode::Auto) => format!(
            "instance {instance} monitoring {} channel(s) (shard auto of {configured}, generation {})",
            daemon.monitored(),
            daemon.assignment().map_or(0, |a| a.generation)
        ),
        _ => format!(
            "instance {instance} monitoring {channels} channel(s){}",
            shard.map_or(String::new(), |s| format!(" (shard {s} of {configured})"))
        ),
    };
    println!("glrmon run: {monitoring}; {zenoh_line}");
    notify::ready(&monitoring);
    let watchdog = notify::watchdog(daemon.runtime().metrics());
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
        // A reload reads and validates the file on its own thread, at a lower priority
        // than intake and the workers; SIGHUPs that arrive meanwhile are coalesced into
        // one more reload after it.
        let mut reloading: Option<tokio::sync::oneshot::Receiver<Reread>> = None;
        let mut again = false;
        loop {
            tokio::select! {
                () = next(&mut term) => break,
                () = next(&mut int) => break,
                () = next(&mut hup) => {
                    if reloading.is_some() {
                        again = true;
                    } else {
                        notify::reloading();
                        reloading = Some(reread(&args.config, daemon.config()));
                    }
                }
                done = async {
                    match reloading.as_mut() {
                        Some(r) => r.await,
                        None => std::future::pending().await,
                    }
                }, if reloading.is_some() => {
                    reloading = None;
                    if let Ok(done) = done {
                        apply(&args.config, done, &mut daemon);
                    }
                    if std::mem::take(&mut again) {
                        reloading = Some(reread(&args.config, daemon.config()));
                    } else {
                        notify::ready(&monitoring);
                    }
                }
            }
        }
    }
    #[cfg(not(unix))]
    wait_for_signal().await;
    let started = Instant::now();
    notify::stopping();
    drop(watchdog);
    tracing::info!("Stopping: intake closed, draining.");
    let stopped = daemon.shutdown(timeout).await;
    if let Some(stats) = stopped.recorder {
        let finished = stats.finished.lock().map(|f| f.clone()).unwrap_or_default();
        tracing::info!(
            messages = stats.messages.load(std::sync::atomic::Ordering::Relaxed),
            files = finished.len(),
            last = %finished.last().map(|p| p.display().to_string()).unwrap_or_default(),
            "Recording finished."
        );
    }
    if let Err(e) = tokio::time::timeout(Duration::from_secs(2), session.close()).await {
        tracing::warn!(error = %e, "The Zenoh session did not close in time.");
    }
    if stopped.in_time {
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

/// A daemon that could not start: the user's fault (exit code 2) or the machine's.
fn daemon_error(e: glrmon_daemon::DaemonError) -> anyhow::Error {
    if e.is_invalid_input() {
        crate::common::InvalidInput(e.to_string()).into()
    } else {
        e.into()
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

/// The configuration file as a reload read it.
enum Reread {
    /// The same text as the configuration in force: nothing to validate or apply.
    Unchanged,
    /// A valid configuration, to apply.
    Changed(Box<glrmon_spec::Config>),
    /// Unreadable or invalid: why.
    Refused(String),
}

/// SIGHUP: reads the configuration file again on a thread of its own, at a lower
/// scheduling priority than intake and the workers (validating a large configuration
/// takes a second of CPU), and validates it unless its text is the one in force.
fn reread(
    path: &std::path::Path,
    current: &glrmon_spec::Config,
) -> tokio::sync::oneshot::Receiver<Reread> {
    let (tx, rx) = tokio::sync::oneshot::channel();
    let path = path.to_owned();
    let current = current.source.clone();
    let spawned = std::thread::Builder::new()
        .name("glrmon-reload".into())
        .spawn(move || {
            crate::common::lower_thread_priority(RELOAD_NICE);
            let reread = match std::fs::read_to_string(&path) {
                Ok(text) if text == current => Reread::Unchanged,
                Ok(_) => match load_config(&path) {
                    Ok(c) => Reread::Changed(Box::new(c)),
                    Err(e) => Reread::Refused(e.to_string()),
                },
                Err(e) => Reread::Refused(format!("cannot read {}: {e}", path.display())),
            };
            let _ = tx.send(reread);
        });
    if let Err(e) = spawned {
        tracing::error!("Reload refused, nothing changed: no thread to read the file: {e}");
    }
    rx
}

/// How much lower than the daemon's other threads a reload runs (a nice increment).
const RELOAD_NICE: i32 = 10;

/// Applies a reread configuration: each channel's new thresholds and alarm settings go
/// to its running monitor; an invalid file, or any change that needs a restart, is
/// refused (logging why, changing nothing).
fn apply(path: &std::path::Path, reread: Reread, daemon: &mut Daemon) {
    let new = match reread {
        Reread::Unchanged => {
            tracing::info!(
                config = %path.display(),
                "Configuration reloaded: unchanged, nothing to apply."
            );
            return;
        }
        Reread::Changed(c) => *c,
        Reread::Refused(e) => {
            tracing::error!(config = %path.display(), "Reload refused, nothing changed: {e}");
            return;
        }
    };
    match daemon.reload(new) {
        Ok(retuned) => tracing::info!(
            config = %path.display(),
            channels = retuned,
            "Configuration reloaded: thresholds and alarm settings applied; the filters go on."
        ),
        Err(refused) => tracing::error!(
            config = %path.display(),
            "Reload refused, nothing changed: {refused}. Restart glrmon to apply these."
        ),
    }
}

/// How the user sets the endpoints `which` (`connect` or `listen`) of this run, for the
/// message of a failure: the flag, and the configuration's key (`[zenoh] connect in
/// plant.toml`, or the Zenoh JSON5 file's `connect/endpoints` when one is used).
fn endpoint_hint(args: &RunArgs, zenoh: &glrmon_spec::schema::ZenohSpec, which: &str) -> String {
    let flag = format!("--{which}");
    let given = if which == "connect" {
        &args.zenoh.connect
    } else {
        &args.zenoh.listen
    };
    if !given.is_empty() {
        return flag;
    }
    let json5 = args.zenoh.zenoh_config.as_ref().or(zenoh.config.as_ref());
    let in_file = |key: &str, file: &std::path::Path| {
        format!("{flag} or {key} in {}", Escaped(&file.to_string_lossy()))
    };
    let listed = if which == "connect" {
        &zenoh.connect
    } else {
        &zenoh.listen
    };
    match json5 {
        Some(file) if listed.is_empty() => in_file(&format!("{which}/endpoints"), file),
        _ => in_file(&format!("[zenoh] {which}"), &args.config),
    }
}

/// Opens the session; in client mode, retries until a router answers (the daemon may
/// start before its router), logging each failure in one line (the endpoints, why, the
/// setting to check), until SIGINT/SIGTERM.
async fn open_session(settings: &glrmon_zenoh::SessionSettings) -> anyhow::Result<zenoh::Session> {
    let client = settings.mode.as_deref() == Some("client");
    let mut delay = Duration::from_millis(250);
    loop {
        match glrmon_zenoh::open(settings).await {
            Ok(s) => return Ok(s),
            Err(e @ glrmon_zenoh::ZenohError::Connect { .. }) if client => {
                tracing::warn!(
                    retry_in_ms = delay.as_millis() as u64,
                    "No Zenoh router reachable yet, retrying: {e}."
                );
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

/// A peer (or router) session opens without its connect endpoints when none answers
/// (Zenoh goes on trying in the background): says so once, with why and the setting to
/// check, instead of Zenoh's `Scouting delay elapsed before start conditions are met.`
async fn warn_if_unconnected(
    session: &zenoh::Session,
    endpoints: &glrmon_zenoh::Endpoints,
    settings: &glrmon_zenoh::SessionSettings,
) {
    if endpoints.mode == "client" || endpoints.connect.is_empty() {
        return;
    }
    let info = session.info();
    if info.routers_zid().await.next().is_some() || info.peers_zid().await.next().is_some() {
        return;
    }
    let connect = endpoints.connect.clone();
    let Ok(reasons) = tokio::task::spawn_blocking(move || {
        connect
            .iter()
            .map(|e| format!("{} ({})", Escaped(e), glrmon_zenoh::unreachable_reason(e)))
            .collect::<Vec<_>>()
            .join(", ")
    })
    .await
    else {
        return;
    };
    tracing::warn!(
        mode = %endpoints.mode,
        "Not connected to {reasons}: monitoring starts, and Zenoh keeps trying in the background. \
         Is `glrmon run` or a Zenoh router listening there? Check {}.",
        settings.connect_hint.as_deref().unwrap_or("the endpoints to connect to")
    );
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
