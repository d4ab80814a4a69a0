//! The glrmon daemon as a library: the runtime (workers, fan-out), the Zenoh source
//! and publisher sink, the MCAP recorder, the Prometheus endpoint, channel ownership
//! and the status queryable, assembled from a validated configuration.
//!
//! `glrmon run` and `glrmon demo` configure a [`DaemonBuilder`]; a program that
//! embeds glrmon does the same. The caller opens the Zenoh session (and decides what
//! to do while no router answers), adds sinks of its own (a log, a file), and owns
//! the process concerns: signals, systemd notification, exit codes.
//!
//! ```no_run
//! # async fn f() -> Result<(), Box<dyn std::error::Error>> {
//! use std::sync::Arc;
//! use std::time::Duration;
//! use glrmon_daemon::{DaemonBuilder, NoEvents};
//!
//! let cfg = glrmon_spec::load(std::path::Path::new("plant.toml"))?;
//! let settings = glrmon_zenoh::SessionSettings::default();
//! let session = glrmon_zenoh::open(&settings).await?;
//! let daemon = DaemonBuilder::new(cfg, "plant-a")
//!     .start(&session, &glrmon_zenoh::Endpoints::of(&settings)?)
//!     .await?;
//! // … until the process is told to stop:
//! let stopped = daemon.shutdown(Duration::from_secs(10)).await;
//! assert!(stopped.in_time);
//! # Ok(()) }
//! ```
#![warn(missing_docs)]

mod auto;

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use glrmon_record::{Recorder, RecorderSettings, RecorderStats};
use glrmon_runtime::{ChannelSetup, Runtime, RuntimeEvents, RuntimeSettings, Sink, SinkError};
use glrmon_spec::{Config, Shard, ShardMode};
use glrmon_zenoh::{
    ConnectivityWatch, Endpoints, Ownership, Presence, StatusSource, ZenohError, ZenohSink,
    ZenohSource,
};

/// How long a starting instance waits for other instances' claims on its channels.
const CLAIM_WAIT: Duration = Duration::from_secs(3);

/// The longest a leaving instance of an automatic shard waits for its channels to be
/// claimed elsewhere (it keeps monitoring them meanwhile).
const HANDOVER_WAIT: Duration = Duration::from_secs(5);

/// Why a daemon could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DaemonError {
    /// The channel selection is not a key expression.
    #[error("--channels \"{selector}\" is not a key expression: {reason}")]
    Selector {
        /// The selection as given.
        selector: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// Another live instance has this name or claims a channel of this one.
    #[error("{0}")]
    Overlap(String),
    /// A Zenoh declaration failed.
    #[error(transparent)]
    Zenoh(ZenohError),
    /// A channel's monitor could not be built (not expected after validation).
    #[error(transparent)]
    Model(#[from] glrmon_core::ModelError),
    /// The recorder could not start.
    #[error("starting the recorder: {0}")]
    Recorder(String),
    /// The metrics endpoint could not be bound.
    #[error(transparent)]
    Metrics(#[from] glrmon_metrics::MetricsError),
}

impl DaemonError {
    /// Whether the user's input (flags, configuration, instance names) is at fault
    /// rather than the machine.
    #[must_use]
    pub fn is_invalid_input(&self) -> bool {
        matches!(self, Self::Selector { .. } | Self::Overlap(_))
    }
}

impl From<ZenohError> for DaemonError {
    fn from(e: ZenohError) -> Self {
        match e {
            ZenohError::Overlap(m) => Self::Overlap(m),
            other => Self::Zenoh(other),
        }
    }
}

/// Runtime events nobody listens to.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoEvents;

impl RuntimeEvents for NoEvents {
    fn sink_error(&self, _: &SinkError) {}
}

/// The channels of `cfg` whose input key intersects the key expression `selector`
/// (all of them without one), then those of `shard`: the channels one instance
/// monitors. Logs what it kept.
///
/// # Errors
/// [`DaemonError::Selector`] when `selector` is not a key expression.
pub fn select_channels(
    mut cfg: Config,
    selector: Option<&str>,
    shard: Option<Shard>,
) -> Result<Config, DaemonError> {
    let configured = cfg.channels.len();
    if let Some(expr) = selector {
        let keys = zenoh::key_expr::KeyExpr::new(expr).map_err(|e| DaemonError::Selector {
            selector: expr.to_owned(),
            reason: e.to_string(),
        })?;
        cfg.channels.retain(|c| {
            c.input_keys().iter().any(|key| {
                zenoh::key_expr::KeyExpr::new(key.as_str()).is_ok_and(|k| k.intersects(&keys))
            })
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
    Ok(cfg)
}

/// What a daemon is made of; [`DaemonBuilder::start`] starts it.
pub struct DaemonBuilder {
    config: Config,
    instance: String,
    shard: Option<ShardMode>,
    sinks: Vec<Box<dyn Sink>>,
    recorder: Option<RecorderSettings>,
    runtime: RuntimeSettings,
    metrics: Option<String>,
    announce: bool,
    events: Arc<dyn RuntimeEvents>,
}

impl std::fmt::Debug for DaemonBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DaemonBuilder")
            .field("instance", &self.instance)
            .field("channels", &self.config.channels.len())
            .finish_non_exhaustive()
    }
}

impl DaemonBuilder {
    /// A daemon named `instance` for the channels of `config` (already selected: see
    /// [`select_channels`]), as the configuration asks: its `[daemon]` runtime
    /// settings and metrics address, its `[recording]`, results published on Zenoh,
    /// channel ownership and the status queryable announced.
    #[must_use]
    pub fn new(config: Config, instance: &str) -> Self {
        let recorder = config
            .recording
            .enabled
            .then(|| RecorderSettings::from_spec(&config.recording));
        Self {
            runtime: RuntimeSettings::from_spec(&config.daemon),
            metrics: config.daemon.metrics.clone(),
            recorder,
            config,
            instance: instance.to_owned(),
            shard: None,
            sinks: Vec::new(),
            announce: true,
            events: Arc::new(NoEvents),
        }
    }

    /// The shard this instance monitors: for a static one, its status (the channels
    /// must already be the shard's); `auto`, the channels are assigned among the live
    /// instances as they come and go (it needs [`DaemonBuilder::announce`]).
    #[must_use]
    pub fn shard(mut self, shard: Option<ShardMode>) -> Self {
        self.shard = shard;
        self
    }

    /// Adds a sink after the Zenoh publisher (a log, a file).
    #[must_use]
    pub fn sink(mut self, sink: Box<dyn Sink>) -> Self {
        self.sinks.push(sink);
        self
    }

    /// Records with these settings instead of the configuration's (`None`: no
    /// recording).
    #[must_use]
    pub fn recorder(mut self, settings: Option<RecorderSettings>) -> Self {
        self.recorder = settings;
        self
    }

    /// The runtime's settings instead of the configuration's `[daemon]` ones.
    #[must_use]
    pub fn runtime_settings(mut self, settings: RuntimeSettings) -> Self {
        self.runtime = settings;
        self
    }

    /// Serves `/metrics`, `/healthz` and `/readyz` on `addr` instead of the
    /// configuration's `daemon.metrics` (`None`: not at all).
    #[must_use]
    pub fn metrics(mut self, addr: Option<String>) -> Self {
        self.metrics = addr;
        self
    }

    /// Whether the instance claims its channels (liveliness tokens, refusing a
    /// name or channel another live instance holds), watches its connectivity and
    /// answers status queries. On by default; a self-contained demo turns it off.
    #[must_use]
    pub fn announce(mut self, announce: bool) -> Self {
        self.announce = announce;
        self
    }

    /// Where the runtime reports sink failures.
    #[must_use]
    pub fn events(mut self, events: Arc<dyn RuntimeEvents>) -> Self {
        self.events = events;
        self
    }

    /// Starts the daemon on `session` (whose endpoints are `endpoints`): claims the
    /// channels, starts the recorder, the runtime and the metrics endpoint, then
    /// opens intake (the subscribers) and announces the instance.
    ///
    /// # Errors
    /// [`DaemonError`] naming what could not start; nothing is left running then.
    pub async fn start(
        self,
        session: &zenoh::Session,
        endpoints: &Endpoints,
    ) -> Result<Daemon, DaemonError> {
        let Self {
            config,
            instance,
            shard,
            sinks: extra,
            recorder,
            runtime: settings,
            metrics,
            announce,
            events,
        } = self;
        let overlaps = Arc::new(AtomicU64::new(0));
        let auto = announce && shard == Some(ShardMode::Auto);
        let network = if announce {
            Some(Network::start(session, &instance, &config, endpoints, &overlaps, auto).await?)
        } else {
            None
        };
        let generation = Arc::new(AtomicU64::new(0));
        let channels = config
            .channels
            .iter()
            .map(ChannelSetup::from_channel)
            .collect::<Result<Vec<_>, _>>()?;
        // A channel taken over asks the publishers' caches for twice its settling:
        // it settles on the first half and fills its window with the second, so that
        // it is warm when the live samples come.
        let history: Vec<usize> = channels
            .iter()
            .map(|c| {
                usize::try_from(c.monitor.settle_samples().saturating_mul(2)).unwrap_or(usize::MAX)
            })
            .collect();
        let names: Vec<String> = config.channels.iter().map(|c| c.name.clone()).collect();
        let mut sinks: Vec<Box<dyn Sink>> = vec![Box::new(
            ZenohSink::declaring(session.clone(), &names)?
                .with_source(&instance, Arc::clone(&generation)),
        )];
        sinks.extend(extra);
        let mut recorder_stats = None;
        if let Some(settings) = recorder {
            for f in glrmon_record::leftovers(&settings.directory) {
                tracing::warn!(
                    file = %f.display(),
                    "An unfinished recording from an earlier run: `glrmon recover {}` rewrites it as a finished file.",
                    f.display()
                );
            }
            let directory = settings.directory.clone();
            let recorder =
                Recorder::start(settings, glrmon_record::file_header(&config, &instance))
                    .map_err(|e| DaemonError::Recorder(e.to_string()))?;
            recorder_stats = Some(recorder.stats());
            tracing::info!(directory = %directory.display(), "Recording inputs and results (MCAP).");
            sinks.push(Box::new(recorder));
        }
        let runtime = Runtime::start(channels, sinks, &settings, events);
        let switch = runtime.switch();
        if auto {
            // Idle until the first assignment takes this instance's share.
            for index in 0..names.len() {
                switch.release(index);
            }
        }
        let ready = Arc::new(AtomicBool::new(false));
        let assignment = Arc::new(Mutex::new(glrmon_wire::Assignment {
            generation: 0,
            instances: Vec::new(),
            takeovers: 0,
            handovers: 0,
        }));
        let metrics_server = match (&metrics, &network) {
            (Some(addr), Some(network)) => {
                let runtime_metrics = runtime.metrics();
                let source = glrmon_metrics::MetricsSource {
                    instance: instance.clone(),
                    channels: runtime.channel_names().to_vec(),
                    stats: runtime.stats(),
                    workers: runtime_metrics.workers_alive.load(Ordering::Relaxed),
                    runtime: runtime_metrics,
                    connectivity: network.connectivity.state(),
                    recorder: recorder_stats.clone(),
                    started: Instant::now(),
                    ready: Arc::clone(&ready),
                    assignment: auto.then(|| Arc::clone(&assignment)),
                };
                let (bound, task) = glrmon_metrics::serve(addr, Arc::new(source)).await?;
                tracing::info!(address = %bound, "Serving /metrics, /healthz and /readyz.");
                if let Some(warning) = glrmon_metrics::exposure_warning(bound) {
                    tracing::warn!(address = %bound, "{warning}");
                }
                Some(task)
            }
            _ => None,
        };
        let keys: Vec<Vec<String>> = config
            .channels
            .iter()
            .map(glrmon_spec::Channel::input_keys)
            .collect();
        let source = Arc::new(if auto {
            ZenohSource::idle(session, &keys, &runtime.intake(), history)
        } else {
            ZenohSource::declare(session, &keys, &runtime.intake()).await?
        });
        let presence = match &network {
            Some(network) => {
                let mut status = StatusSource::new(
                    instance.clone(),
                    runtime.channel_names().to_vec(),
                    runtime.stats(),
                );
                status.connectivity = Some(network.connectivity.state());
                status.shard = shard.map(|s| s.to_string());
                status.overlaps = overlaps;
                status.assignment = auto.then(|| Arc::clone(&assignment));
                Some(Presence::declare(session, status).await?)
            }
            None => None,
        };
        let auto_shard = if auto {
            Some(
                auto::AutoShard::start(
                    session,
                    &instance,
                    names.clone(),
                    switch.clone(),
                    Arc::clone(&source),
                    Arc::clone(&generation),
                    Arc::clone(&assignment),
                )
                .await?,
            )
        } else {
            None
        };
        ready.store(true, Ordering::Relaxed);
        Ok(Daemon {
            config,
            instance,
            shard,
            session: session.clone(),
            switch,
            auto: auto_shard,
            runtime,
            source,
            presence,
            network,
            metrics_server,
            recorder: recorder_stats,
            ready,
        })
    }
}

/// The instance's place on the network: its channel claims and its connectivity.
struct Network {
    /// Held for its liveliness tokens: dropping it withdraws the claims.
    _claims: Ownership,
    connectivity: ConnectivityWatch,
}

impl Network {
    async fn start(
        session: &zenoh::Session,
        instance: &str,
        config: &Config,
        endpoints: &Endpoints,
        overlaps: &Arc<AtomicU64>,
        auto: bool,
    ) -> Result<Self, DaemonError> {
        // An automatic shard claims its channels as its assignment moves (auto.rs):
        // here only its name is checked.
        let names: Vec<String> = if auto {
            Vec::new()
        } else {
            config.channels.iter().map(|c| c.name.clone()).collect()
        };
        let counted = Arc::clone(overlaps);
        let ownership = Ownership::claim(session, instance, &names, CLAIM_WAIT, move |channel, other| {
            counted.fetch_add(1, Ordering::Relaxed);
            tracing::error!(channel, other, "Another instance claims a channel this one monitors: both publish its results. Give each instance a disjoint set of channels (daemon.shard).");
        })
        .await?;
        let connectivity = ConnectivityWatch::start(
            session.clone(),
            Duration::from_millis(100),
            |connected, state| {
                let reconnections = state.reconnections.load(Ordering::Relaxed);
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
        // A daemon that listens can be reached by publishers as soon as its listener
        // is up (the session would not have opened otherwise): readiness does not
        // wait for one.
        connectivity
            .state()
            .listening
            .store(!endpoints.listen.is_empty(), Ordering::Relaxed);
        Ok(Self {
            _claims: ownership,
            connectivity,
        })
    }
}

/// A running daemon: intake open, results flowing to the sinks.
pub struct Daemon {
    config: Config,
    instance: String,
    shard: Option<ShardMode>,
    session: zenoh::Session,
    switch: glrmon_runtime::ChannelSwitch,
    auto: Option<auto::AutoShard>,
    runtime: Runtime,
    source: Arc<ZenohSource>,
    presence: Option<Presence>,
    network: Option<Network>,
    metrics_server: Option<tokio::task::JoinHandle<()>>,
    recorder: Option<Arc<RecorderStats>>,
    ready: Arc<AtomicBool>,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon")
            .field("instance", &self.instance)
            .field("channels", &self.runtime.channel_names())
            .finish_non_exhaustive()
    }
}

/// Why a reload changed nothing.
#[derive(Debug, thiserror::Error)]
#[error("{}", .0.join("; "))]
pub struct ReloadRefused(pub Vec<String>);

/// How a daemon stopped.
#[derive(Debug)]
pub struct Stopped {
    /// Whether every accepted payload was processed and its records handed to the
    /// sinks within the deadline.
    pub in_time: bool,
    /// The recorder's counters and finished files, when it recorded.
    pub recorder: Option<Arc<RecorderStats>>,
}

impl Daemon {
    /// The instance's name.
    #[must_use]
    pub fn instance(&self) -> &str {
        &self.instance
    }

    /// The configuration in force (its channels are the ones monitored).
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The runtime: counters, metrics, channel names.
    #[must_use]
    pub fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The recorder's counters, when it records.
    #[must_use]
    pub fn recorder(&self) -> Option<&Arc<RecorderStats>> {
        self.recorder.as_ref()
    }

    /// How many channels the instance monitors now (an automatic shard's share moves).
    #[must_use]
    pub fn monitored(&self) -> usize {
        (0..self.runtime.channel_names().len())
            .filter(|i| self.switch.is_monitored(*i))
            .count()
    }

    /// An automatic shard's assignment now: its generation, the live instances, the
    /// takeovers and hand-overs so far.
    #[must_use]
    pub fn assignment(&self) -> Option<glrmon_wire::Assignment> {
        self.auto.as_ref().map(|a| {
            a.assignment
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .clone()
        })
    }

    /// Applies a new configuration's thresholds and alarm settings to the running
    /// monitors (its channels cut to this instance's shard); the filters go on.
    /// Returns the number of channels retuned.
    ///
    /// # Errors
    /// [`ReloadRefused`], naming each change that needs a restart (a model, a fault,
    /// a window…); nothing is applied then.
    pub fn reload(&mut self, new: Config) -> Result<usize, ReloadRefused> {
        let blockers = self.config.restart_needed(&new);
        if !blockers.is_empty() {
            return Err(ReloadRefused(blockers));
        }
        let new = new.into_shard(self.shard.and_then(ShardMode::fixed));
        let retuned = self.runtime.retune_from(&new);
        self.config = new;
        Ok(retuned)
    }

    /// Stops: intake closes, every accepted payload is processed and its records
    /// reach the sinks (within `timeout`), the sinks close (the recorder finishes its
    /// file), then the status queryable, the metrics endpoint and the channel claims
    /// go. The session stays open for the caller to close.
    pub async fn shutdown(self, timeout: Duration) -> Stopped {
        let Self {
            instance,
            session,
            switch,
            auto,
            runtime,
            source,
            mut presence,
            network,
            metrics_server,
            recorder,
            ready,
            ..
        } = self;
        if let Some(auto) = auto {
            if auto.others_alive() {
                hand_over(
                    &session,
                    &instance,
                    &auto,
                    &switch,
                    presence.as_mut(),
                    timeout,
                )
                .await;
            }
            auto.stop();
        }
        drop(source);
        ready.store(false, Ordering::Relaxed);
        let (in_time, sinks) = tokio::task::spawn_blocking(move || runtime.shutdown(timeout))
            .await
            .unwrap_or((false, Vec::new()));
        // Dropping the recorder finishes its file (summary, index, final name).
        drop(sinks);
        drop(presence);
        if let Some(server) = metrics_server {
            server.abort();
        }
        drop(network);
        Stopped { in_time, recorder }
    }
}

/// A clean shutdown's hand-over: the instance withdraws its token, so that the
/// others take its channels over, and goes on monitoring them until each is claimed
/// elsewhere (at most [`HANDOVER_WAIT`] or half of `timeout`): the channels are then
/// monitored by both for that time, never by none.
async fn hand_over(
    session: &zenoh::Session,
    instance: &str,
    auto: &auto::AutoShard,
    switch: &glrmon_runtime::ChannelSwitch,
    presence: Option<&mut Presence>,
    timeout: Duration,
) {
    let Some(presence) = presence else {
        return;
    };
    let started = Instant::now();
    let limit = HANDOVER_WAIT.min(timeout / 2);
    let mine = auto.monitored(switch);
    presence.withdraw();
    let mut left = mine.clone();
    while !left.is_empty() && started.elapsed() < limit {
        tokio::time::sleep(Duration::from_millis(20)).await;
        match glrmon_zenoh::unclaimed(session, instance, &left, Duration::from_millis(500)).await {
            Ok(still) => left = still,
            Err(e) => {
                tracing::warn!(error = %e, "Could not ask who claims the channels; stopping without waiting.");
                break;
            }
        }
    }
    if let Ok(mut a) = auto.assignment.lock() {
        a.handovers += (mine.len() - left.len()) as u64;
    }
    if left.is_empty() {
        tracing::info!(
            channels = mine.len(),
            elapsed_ms = started.elapsed().as_secs_f64() * 1e3,
            "Handed every channel over before stopping."
        );
    } else {
        tracing::warn!(channels = %left.join(", "), waited_ms = started.elapsed().as_secs_f64() * 1e3, "No other instance claimed these channels in time; they are unmonitored until one does.");
    }
}
