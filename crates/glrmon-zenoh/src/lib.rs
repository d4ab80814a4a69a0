//! The Zenoh adapter: the session, a subscriber source feeding the runtime's intake, a
//! publisher sink for results, the status queryable and the instance's liveliness token.
//!
//! Key expressions (docs/WIRE.md): inputs on each channel's key (default
//! `plant/<channel>`); results on `glrmon/<channel>/<type>`; status at
//! `glrmon/@status/<instance>`; liveliness tokens at `glrmon/@instances/<instance>` and,
//! one per monitored channel, `glrmon/@owners/<channel>/<instance>` (so that two
//! instances never monitor the same channel, [`Ownership`]).
//! (`@` chunks are verbatim in Zenoh: `glrmon/**` does not match them, so watchers of
//! results never see status traffic.)
#![warn(missing_docs)]

mod fleet;
mod results;
mod source;

pub use fleet::{Claims, LiveInstances, Membership, Ownership, owner_key, unclaimed};
pub use results::{Results, stored_results};
pub use source::{ZenohSource, plant_publisher};

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_runtime::{ChannelStats, Output, Sink, SinkError};
use glrmon_wire::text::Escaped;
use glrmon_wire::{InstanceStatus, RECORD_KINDS, ZenohSessions, status};
use zenoh::bytes::Encoding;
use zenoh::liveliness::LivelinessToken;

use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::{QueryTarget, Queryable};
use zenoh::sample::Locality;
use zenoh::{Config, Session, Wait};

/// Where a session comes from: a JSON5 file passed through untouched, and/or the
/// settings users expect on the command line (Zenoh's own flag names).
#[derive(Debug, Clone, Default)]
pub struct SessionSettings {
    /// A Zenoh JSON5 configuration file (TLS, authentication, access control…).
    pub config_file: Option<PathBuf>,
    /// `peer` or `client` (default `peer`).
    pub mode: Option<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Multicast scouting; off unless set to true.
    pub multicast_scouting: Option<bool>,
    /// How the user sets the endpoints to connect to, as the message of a failure to
    /// connect names it (`--connect`, or `--connect or [zenoh] connect in plant.toml`):
    /// the fix is in the message. Without it, the message says to check the endpoints.
    pub connect_hint: Option<String>,
    /// How the user sets the endpoints to listen on, likewise (`--listen`, …).
    pub listen_hint: Option<String>,
}

/// Errors of the Zenoh adapter.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ZenohError {
    /// The configuration could not be built or loaded.
    #[error("zenoh configuration: {0}")]
    Config(String),
    /// The session could not be opened or a declaration failed.
    #[error("zenoh {what}: {message}")]
    Session {
        /// What was being done.
        what: &'static str,
        /// Zenoh's message.
        message: String,
    },
    /// Another live instance already monitors a channel of this one, or has its name.
    #[error("{0}")]
    Overlap(String),
    /// No endpoint to connect to could be reached when the session opened (a client
    /// session, which needs one; a peer goes on and keeps trying).
    #[error("{}", connect_message(failures, hint))]
    Connect {
        /// Each endpoint with why it could not be reached ("connection refused", …).
        failures: Vec<(String, String)>,
        /// How the user sets the endpoints ([`SessionSettings::connect_hint`]).
        hint: Option<String>,
    },
    /// An endpoint could not be listened on (a session listens on all of its
    /// endpoints or does not open).
    #[error("{}", listen_message(endpoint, reason, hint))]
    Listen {
        /// The endpoint.
        endpoint: String,
        /// Why ("address already in use", …).
        reason: String,
        /// How the user sets the endpoints ([`SessionSettings::listen_hint`]).
        hint: Option<String>,
    },
}

/// "cannot connect to tcp/127.0.0.1:1 (connection refused): is `glrmon run` or a
/// Zenoh router listening there? Give its endpoint with --connect": what failed, why,
/// and what to check, in one line (endpoints from a file are escaped).
fn connect_message(failures: &[(String, String)], hint: &Option<String>) -> String {
    let list = failures
        .iter()
        .map(|(e, why)| format!("{} ({why})", Escaped(e)))
        .collect::<Vec<_>>()
        .join(", ");
    let (any, there) = if failures.len() > 1 {
        ("any of ", "at one of them")
    } else {
        ("", "there")
    };
    let fix = hint.as_deref().map_or_else(
        || "Check the endpoints to connect to".to_owned(),
        |h| format!("Give its endpoint with {h}"),
    );
    format!(
        "cannot connect to {any}{list}: is `glrmon run` or a Zenoh router listening {there}? {fix}"
    )
}

/// "cannot listen on tcp/127.0.0.1:7447 (address already in use): another process
/// listens there (a `glrmon run` or a Zenoh router?); choose another endpoint with
/// --listen".
fn listen_message(endpoint: &str, reason: &str, hint: &Option<String>) -> String {
    let lower = reason.to_ascii_lowercase();
    let why = if lower.contains("already in use") {
        "another process listens there (a `glrmon run` or a Zenoh router?); "
    } else if lower.contains("assign requested address") {
        "that address is not one of this machine's; "
    } else if lower.contains("permission denied") {
        "ports below 1024 need privileges; "
    } else {
        ""
    };
    let fix = hint
        .as_deref()
        .map_or_else(|| " to listen on".to_owned(), |h| format!(" with {h}"));
    format!(
        "cannot listen on {} ({reason}): {why}choose another endpoint{fix}",
        Escaped(endpoint)
    )
}

fn session_err(what: &'static str) -> impl Fn(zenoh::Error) -> ZenohError {
    move |e| ZenohError::Session {
        what,
        message: without_source_locations(&e.to_string()),
    }
}

/// Zenoh's message without the source locations its errors carry (`… at
/// /root/.cargo/registry/src/…/unicast.rs:338.`): they tell an operator nothing and
/// show the build machine's paths.
fn without_source_locations(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(i) = rest.find(" at ") {
        let after = &rest[i + 4..];
        let end = after
            .find(|c: char| c.is_whitespace() || c == ']')
            .unwrap_or(after.len());
        let token = &after[..end];
        let location = token.trim_end_matches('.');
        let is_location = location
            .rsplit_once(".rs:")
            .is_some_and(|(_, line)| !line.is_empty() && line.bytes().all(|b| b.is_ascii_digit()));
        if is_location {
            out.push_str(&rest[..i]);
            rest = &after[end..];
        } else {
            out.push_str(&rest[..i + 4]);
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

/// Builds the Zenoh configuration: the file if given, then the explicit settings on top.
/// Defaults: peer mode, multicast scouting off, timestamping on (so that every sample
/// carries a source timestamp), and no listening on all interfaces by accident.
///
/// # Errors
/// [`ZenohError::Config`] for an unreadable file or a rejected value.
pub fn build_config(s: &SessionSettings) -> Result<Config, ZenohError> {
    let cfg_err = |e: Box<dyn std::error::Error + Send + Sync>| {
        ZenohError::Config(without_source_locations(&e.to_string()))
    };
    let mut c = match &s.config_file {
        Some(p) => {
            Config::from_file(p).map_err(|e| ZenohError::Config(format!("{}: {e}", p.display())))?
        }
        None => Config::default(),
    };
    let from_file = s.config_file.is_some();
    if let Some(mode) = &s.mode {
        if !matches!(mode.as_str(), "peer" | "client") {
            return Err(ZenohError::Config(format!(
                "mode \"{mode}\" is not peer or client"
            )));
        }
        c.insert_json5("mode", &json_string(mode))
            .map_err(cfg_err)?;
    } else if !from_file {
        c.insert_json5("mode", "\"peer\"").map_err(cfg_err)?;
    }
    if !s.connect.is_empty() {
        c.insert_json5("connect/endpoints", &serde_json_list(&s.connect))
            .map_err(cfg_err)?;
    }
    if !s.listen.is_empty() || !from_file {
        // Zenoh's default peer listener is tcp/[::]:0 on every interface: never implicit.
        c.insert_json5("listen/endpoints", &serde_json_list(&s.listen))
            .map_err(cfg_err)?;
    }
    match s.multicast_scouting {
        Some(on) => c
            .insert_json5(
                "scouting/multicast/enabled",
                if on { "true" } else { "false" },
            )
            .map_err(cfg_err)?,
        None if !from_file => c
            .insert_json5("scouting/multicast/enabled", "false")
            .map_err(cfg_err)?,
        None => {}
    }
    if !from_file {
        c.insert_json5("timestamping/enabled", "true")
            .map_err(cfg_err)?;
        // A client that loses its router retries the connection: quickly at first, then
        // at most every 2 s (Zenoh's default reaches 4 s), so a restarted router is
        // back in use within about a second of listening again.
        c.insert_json5(
            "connect/retry",
            "{period_init_ms: 250, period_max_ms: 2000, period_increase_factor: 2}",
        )
        .map_err(cfg_err)?;
    }
    Ok(c)
}

/// The mode and endpoints a session opens with: those of the configuration file (if
/// any) with the explicit settings on top, as [`build_config`] hands them to Zenoh.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Endpoints {
    /// `peer` or `client` (or `router`, from a file).
    pub mode: String,
    /// Endpoints listened on (a listener that cannot be bound makes the session fail to
    /// open, so those of an open session are in use).
    pub listen: Vec<String>,
    /// Endpoints connected to.
    pub connect: Vec<String>,
}

impl Endpoints {
    /// What the settings give (the file read again, as [`open`] reads it).
    ///
    /// # Errors
    /// As [`build_config`].
    pub fn of(s: &SessionSettings) -> Result<Self, ZenohError> {
        Ok(Self::from_config(&build_config(s)?))
    }

    /// What a configuration gives. Zenoh's endpoint lists may be one list or one per
    /// mode (`{router: [...], peer: [...], client: [...]}`): the mode's list is taken.
    #[must_use]
    pub fn from_config(c: &Config) -> Self {
        let json = |key: &str| {
            c.get_json(key)
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .unwrap_or(serde_json::Value::Null)
        };
        let mode = json("mode")
            .as_str()
            .map_or_else(|| "peer".to_owned(), str::to_owned);
        let list = |key: &str| {
            let v = json(key);
            let v = if v.is_object() {
                v.get(mode.as_str()).cloned().unwrap_or_default()
            } else {
                v
            };
            v.as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|e| e.as_str().map(str::to_owned))
                        .collect()
                })
                .unwrap_or_default()
        };
        let (listen, connect) = (list("listen/endpoints"), list("connect/endpoints"));
        Self {
            mode,
            listen,
            connect,
        }
    }
}

/// A list of strings as JSON (which JSON5 reads as is), escaped by serde_json.
fn serde_json_list(v: &[String]) -> String {
    // Serialising strings into a `String` cannot fail; "[]" is never reached.
    serde_json::to_string(v).unwrap_or_else(|_| "[]".to_owned())
}

/// A string as JSON (which JSON5 reads as is), escaped by serde_json.
fn json_string(v: &str) -> String {
    // As above: cannot fail.
    serde_json::to_string(v).unwrap_or_else(|_| "\"\"".to_owned())
}

/// Opens a session.
///
/// # Errors
/// [`ZenohError::Connect`] when no endpoint to connect to answers (client mode),
/// [`ZenohError::Listen`] when an endpoint cannot be listened on (e.g. already in use),
/// each naming the endpoint, the reason and the setting to change; [`ZenohError`]
/// otherwise when the configuration is invalid or the session cannot open.
pub async fn open(s: &SessionSettings) -> Result<Session, ZenohError> {
    let cfg = build_config(s)?;
    let endpoints = Endpoints::from_config(&cfg);
    match zenoh::open(cfg).await {
        Ok(session) => Ok(session),
        Err(e) => Err(open_error(&e.to_string(), &endpoints, s)),
    }
}

/// Zenoh's error of a session that did not open, made into what an operator can act on.
/// Zenoh's own text (`Unable to connect to any of [Single(tcp/…)]!`) names the endpoints
/// in Rust's debug notation and without the reason, which only its WARN log lines give:
/// a connect failure is told by probing each endpoint ([`unreachable_reason`]), a listen
/// failure by the system's reason in Zenoh's message.
fn open_error(message: &str, endpoints: &Endpoints, s: &SessionSettings) -> ZenohError {
    let message = without_source_locations(message);
    if message.starts_with("Unable to connect to any of") && !endpoints.connect.is_empty() {
        return ZenohError::Connect {
            failures: endpoints
                .connect
                .iter()
                .map(|e| (e.clone(), unreachable_reason(e)))
                .collect(),
            hint: s.connect_hint.clone(),
        };
    }
    let listen_failure = message.contains("listener") || message.contains("not supported for");
    if listen_failure && !endpoints.listen.is_empty() {
        let named = endpoints
            .listen
            .iter()
            .find(|e| message.contains(e.as_str()))
            .or_else(|| {
                // "Unicast not supported for udp protocol": the endpoint of that protocol.
                endpoints.listen.iter().find(|e| {
                    e.split_once('/')
                        .is_some_and(|(p, _)| message.contains(&format!(" {p} protocol")))
                })
            })
            .or(endpoints.listen.first());
        if let Some(endpoint) = named {
            return ZenohError::Listen {
                endpoint: endpoint.clone(),
                reason: listen_reason(&message, endpoint),
                hint: s.listen_hint.clone(),
            };
        }
    }
    ZenohError::Session {
        what: "open",
        message,
    }
}

/// The system's reason in Zenoh's message of a listener that could not be opened
/// (`…: [127.0.0.1:7447: Address already in use (os error 98)]` → "address already in
/// use"), or a transport this build lacks.
fn listen_reason(message: &str, endpoint: &str) -> String {
    if let Some(end) = message.find(" (os error") {
        let start = message[..end].rfind(": ").map_or(0, |i| i + 2);
        return lower_first(&message[start..end]);
    }
    if message.contains("not supported for") {
        return unsupported_transport(endpoint);
    }
    lower_first(message.trim().trim_end_matches(['!', '.']))
}

/// "the udp transport is not built into glrmon (tcp and tls only)".
fn unsupported_transport(endpoint: &str) -> String {
    let protocol = endpoint.split_once('/').map_or(endpoint, |(p, _)| p);
    format!(
        "the {} transport is not built into glrmon (tcp and tls only)",
        Escaped(protocol)
    )
}

fn lower_first(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(first) => first.to_lowercase().chain(c).collect(),
        None => String::new(),
    }
}

/// How long [`unreachable_reason`] waits for a TCP connection.
const PROBE_TIMEOUT: Duration = Duration::from_secs(1);

/// Why `endpoint` cannot be reached, found by trying it as Zenoh did: its name resolved,
/// then a TCP connection (closed at once) with a 1 s timeout to its first
/// address. "connection refused" (nothing listens there), "no answer within 1 s" (a
/// firewall, a host that is down), "cannot resolve …", or, when the connection opens, that
/// the node there is no Zenoh node or refused the session. It blocks for at most the
/// name look-up and 1 s.
#[must_use]
pub fn unreachable_reason(endpoint: &str) -> String {
    use std::net::ToSocketAddrs as _;
    let Ok(parsed) = endpoint.parse::<zenoh::config::EndPoint>() else {
        return "not a Zenoh endpoint (PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447)".to_owned();
    };
    // TLS runs over TCP: the same probe tells whether anything listens.
    if !matches!(parsed.protocol().as_str(), "tcp" | "tls") {
        return unsupported_transport(endpoint);
    }
    let address = parsed.address();
    let address = address.as_str();
    let first = match address.to_socket_addrs() {
        Ok(mut addrs) => addrs.next(),
        Err(e) => {
            return format!("cannot resolve {}: {}", Escaped(address), system_reason(&e));
        }
    };
    let Some(addr) = first else {
        return format!("{} resolves to no address", Escaped(address));
    };
    match std::net::TcpStream::connect_timeout(&addr, PROBE_TIMEOUT) {
        Ok(_) => "a TCP connection opens, but no Zenoh session: not a Zenoh node, or one \
                  that refused this session"
            .to_owned(),
        Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
            format!("no answer within {} s", PROBE_TIMEOUT.as_secs())
        }
        Err(e) => system_reason(&e),
    }
}

/// An I/O error as a reason within a sentence: "connection refused", without Rust's
/// " (os error 111)" or "failed to lookup address information: ".
fn system_reason(e: &std::io::Error) -> String {
    let text = e.to_string();
    let text = text
        .split(" (os error")
        .next()
        .unwrap_or(&text)
        .trim_start_matches("failed to lookup address information: ");
    lower_first(text)
}

/// Records of each kind but `stat` that an instance keeps per channel for the readers
/// that were away (`glrmon watch --since`, any zenoh-ext advanced subscriber with
/// history): the last 32 alarms, isolation updates, alarm ends, diagnoses, errors and
/// consistency changes of each channel, for as long as the instance runs.
pub const RESULT_HISTORY: usize = 32;

/// Publishes records on `glrmon/<channel>/<type>`: alarms, alarm ends, diagnoses and
/// errors reliably (congestion control Block, high priority, express), each kind's last
/// [`RESULT_HISTORY`] kept for readers that were away (zenoh-ext advanced publishers
/// with a cache); `stat` may be dropped under congestion.
///
/// A publisher is declared once per key and kept. [`ZenohSink::declaring`] declares
/// those of the records that must arrive for every channel up front: declaring one
/// takes tens of microseconds, which a plant-wide fault would otherwise pay a thousand
/// times over, on the first alarm of each channel, the one that matters most.
pub struct ZenohSink {
    session: Session,
    /// The instance and its assignment generation, attached to every put.
    source: Option<SourceAttachment>,
    /// Each channel's publishers, by record kind ([`glrmon_wire::Record::kind_index`]).
    publishers:
        HashMap<String, [Option<zenoh_ext::AdvancedPublisher<'static>>; RECORD_KINDS.len()]>,
}

impl std::fmt::Debug for ZenohSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohSink")
            .field("channels", &self.publishers.len())
            .finish()
    }
}

impl ZenohSink {
    /// A sink on `session` (publishers are declared on first use of each key).
    #[must_use]
    pub fn new(session: Session) -> Self {
        Self {
            session,
            source: None,
            publishers: HashMap::new(),
        }
    }

    /// Attaches `{"instance":…,"generation":…}` ([`glrmon_wire::Source`]) to every
    /// record put, the generation read from `generation` (an automatic shard's, which
    /// moves; 0 otherwise).
    #[must_use]
    pub fn with_source(mut self, instance: &str, generation: Arc<AtomicU64>) -> Self {
        self.source = Some(SourceAttachment {
            instance: instance.to_owned(),
            generation,
            current: None,
        });
        self
    }

    /// A sink on `session` with the publishers of every record kind but `stat`
    /// declared now for each of `channels`.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when a declaration fails.
    pub fn declaring(session: Session, channels: &[String]) -> Result<Self, ZenohError> {
        let mut sink = Self::new(session);
        for channel in channels {
            for (slot, kind) in RECORD_KINDS.iter().enumerate().skip(1) {
                sink.publisher(channel, slot, kind)
                    .map_err(session_err("declare publisher"))?;
            }
        }
        Ok(sink)
    }

    /// The publisher of `kind` (slot `slot` of [`RECORD_KINDS`]) for `channel`, declared on
    /// first use.
    fn publisher(
        &mut self,
        channel: &str,
        slot: usize,
        kind: &str,
    ) -> Result<&zenoh_ext::AdvancedPublisher<'static>, zenoh::Error> {
        if !self.publishers.contains_key(channel) {
            self.publishers
                .insert(channel.to_owned(), std::array::from_fn(|_| None));
        }
        let slots = self
            .publishers
            .get_mut(channel)
            .ok_or_else(|| zenoh::Error::from("no publisher slots"))?;
        let entry = &mut slots[slot];
        if entry.is_none() {
            let builder = self
                .session
                .declare_publisher(glrmon_wire::result_key(channel, kind))
                .encoding(Encoding::APPLICATION_JSON);
            use zenoh_ext::AdvancedPublisherBuilderExt as _;
            let builder = if kind == "stat" {
                builder
                    .congestion_control(CongestionControl::Drop)
                    .priority(Priority::DataLow)
                    .advanced()
            } else {
                builder
                    .congestion_control(CongestionControl::Block)
                    .priority(Priority::InteractiveHigh)
                    .express(true)
                    .cache(zenoh_ext::CacheConfig::default().max_samples(RESULT_HISTORY))
                    .sample_miss_detection(zenoh_ext::MissDetectionConfig::default())
            };
            *entry = Some(builder.wait()?);
        }
        entry
            .as_ref()
            .ok_or_else(|| zenoh::Error::from("publisher not declared"))
    }
}

impl Sink for ZenohSink {
    fn name(&self) -> &str {
        "zenoh"
    }

    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        let kind = output.record.kind_str();
        let channel = output.record.channel();
        let err = |what: &str, e: zenoh::Error| SinkError {
            sink: "zenoh".into(),
            message: format!("{what} {}: {e}", glrmon_wire::result_key(channel, kind)),
        };
        let attachment = self.source.as_mut().map(SourceAttachment::bytes);
        let publisher = self
            .publisher(channel, output.record.kind_index(), kind)
            .map_err(|e| err("declare publisher", e))?;
        publisher
            .put(output.json.clone())
            .attachment(attachment)
            .wait()
            .map_err(|e| err("put", e))
    }
}

/// The attachment of a sink's puts, encoded again only when the generation moves.
struct SourceAttachment {
    instance: String,
    generation: Arc<AtomicU64>,
    current: Option<(u64, zenoh::bytes::ZBytes)>,
}

impl SourceAttachment {
    fn bytes(&mut self) -> zenoh::bytes::ZBytes {
        let g = self.generation.load(Ordering::Relaxed);
        match &self.current {
            Some((at, bytes)) if *at == g => bytes.clone(),
            _ => {
                let bytes = zenoh::bytes::ZBytes::from(
                    glrmon_wire::Source {
                        instance: self.instance.clone(),
                        generation: g,
                    }
                    .encode(),
                );
                self.current = Some((g, bytes.clone()));
                bytes
            }
        }
    }
}

/// What the status queryable reports about the instance.
#[derive(Debug, Clone)]
pub struct StatusSource {
    /// Instance name.
    pub instance: String,
    /// Channel names by index.
    pub channels: Vec<String>,
    /// Counters by channel index.
    pub stats: Arc<Vec<Arc<ChannelStats>>>,
    /// Start time.
    pub started: Instant,
    /// The session's connections, if watched.
    pub connectivity: Option<Arc<Connectivity>>,
    /// The shard this instance monitors (`"i/N"`), if any.
    pub shard: Option<String>,
    /// Other instances seen declaring a channel of this one since start.
    pub overlaps: Arc<AtomicU64>,
    /// An automatic shard's assignment, as its instance updates it.
    pub assignment: Option<Arc<Mutex<glrmon_wire::Assignment>>>,
    /// (time, total samples) at the last rate estimate.
    rate: Arc<Mutex<(Instant, u64, f64)>>,
}

impl StatusSource {
    /// The status of `instance` with these channels and counters, started now.
    #[must_use]
    pub fn new(
        instance: String,
        channels: Vec<String>,
        stats: Arc<Vec<Arc<ChannelStats>>>,
    ) -> Self {
        let now = Instant::now();
        Self {
            instance,
            channels,
            stats,
            started: now,
            connectivity: None,
            shard: None,
            overlaps: Arc::new(AtomicU64::new(0)),
            assignment: None,
            rate: Arc::new(Mutex::new((now, 0, 0.0))),
        }
    }

    /// Samples per second over the time since the last estimate that is at least one
    /// second old (the mean since start before that).
    fn samples_per_second(&self, total: u64) -> f64 {
        let Ok(mut r) = self.rate.lock() else {
            return 0.0;
        };
        let now = Instant::now();
        let dt = now.duration_since(r.0).as_secs_f64();
        if dt >= 1.0 {
            r.2 = total.saturating_sub(r.1) as f64 / dt;
            *r = (now, total, r.2);
        } else if r.1 == 0 && dt > 0.0 {
            return total as f64 / dt.max(1e-3);
        }
        r.2
    }
}

impl StatusSource {
    /// The status now: instance, uptime, connection, and every channel's counters (read
    /// by [`glrmon_runtime::channel_statuses`], as the other views of them are).
    /// Uptime is rounded to the millisecond and the rate to 0.1 sample/s.
    #[must_use]
    pub fn snapshot(&self) -> InstanceStatus {
        let channels = glrmon_runtime::channel_statuses(&self.channels, &self.stats);
        let total: u64 = channels.iter().map(|c| c.samples).sum();
        let (connected, reconnections, sessions) =
            self.connectivity.as_ref().map_or((true, 0, None), |c| {
                (
                    c.connected.load(Ordering::Relaxed),
                    c.reconnections.load(Ordering::Relaxed),
                    Some(c.sessions()),
                )
            });
        let round = |v: f64, scale: f64| (v * scale).round() / scale;
        InstanceStatus {
            instance: self.instance.clone(),
            uptime: round(self.started.elapsed().as_secs_f64(), 1e3),
            shard: self.shard.clone(),
            connected,
            reconnections,
            overlaps: self.overlaps.load(Ordering::Relaxed),
            samples_per_second: round(self.samples_per_second(total), 10.0),
            channels,
            sessions,
            assignment: self.assignment.as_ref().map(|a| {
                a.lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .clone()
            }),
        }
    }
}

/// The status queryable and the liveliness token of an instance; dropping undeclares.
#[derive(Debug)]
pub struct Presence {
    _queryable: Queryable<()>,
    token: Option<LivelinessToken>,
}

/// Key of an instance's status queryable.
#[must_use]
pub fn status_key(instance: &str) -> String {
    format!("glrmon/@status/{instance}")
}

/// Key of an instance's liveliness token.
#[must_use]
pub fn liveliness_key(instance: &str) -> String {
    format!("glrmon/@instances/{instance}")
}

impl Presence {
    /// Declares the status queryable and the liveliness token.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when a declaration fails.
    pub async fn declare(session: &Session, status: StatusSource) -> Result<Self, ZenohError> {
        let key = status_key(&status.instance);
        let reply_key = key.clone();
        let queryable = session
            .declare_queryable(key.as_str())
            .callback(move |query| {
                // Encoding fails only for a non-finite float, which the snapshot never
                // holds; the querier is then told why rather than left waiting.
                let _ = match status::encode(&status.snapshot()) {
                    Ok(json) => query
                        .reply(reply_key.as_str(), json)
                        .encoding(Encoding::APPLICATION_JSON)
                        .wait(),
                    Err(e) => query.reply_err(e.to_string()).wait(),
                };
            })
            .await
            .map_err(session_err("declare queryable"))?;
        let instance = key.trim_start_matches("glrmon/@status/").to_owned();
        let token = session
            .liveliness()
            .declare_token(liveliness_key(&instance))
            .await
            .map_err(session_err("declare liveliness token"))?;
        Ok(Self {
            _queryable: queryable,
            token: Some(token),
        })
    }

    /// Withdraws the instance's liveliness token, keeping the status queryable: the
    /// other instances of an automatic shard then take its channels over (a clean
    /// shutdown's hand-over).
    pub fn withdraw(&mut self) {
        self.token = None;
    }
}

/// The Zenoh sessions of this session with other nodes, and whether publishers can
/// reach it: what readiness, the status and the metrics report.
#[derive(Debug, Default)]
pub struct Connectivity {
    /// At least one session with another node (router, peer or client) is open.
    pub connected: AtomicBool,
    /// Times the session went from no router or peer session to one, after the first.
    pub reconnections: AtomicU64,
    /// Times it lost its last router or peer session.
    pub losses: AtomicU64,
    /// Open sessions with routers.
    pub routers: AtomicU64,
    /// Open sessions with peers.
    pub peers: AtomicU64,
    /// Open sessions with clients (publishers, `glrmon watch` and `glrmon status` in client
    /// mode connected to a listening daemon).
    pub clients: AtomicU64,
    /// The session listens on at least one endpoint (set by its owner, see
    /// [`Connectivity::reachable`]).
    pub listening: AtomicBool,
    stop: AtomicBool,
}

impl Connectivity {
    /// The open sessions by kind now.
    #[must_use]
    pub fn sessions(&self) -> ZenohSessions {
        ZenohSessions {
            routers: self.routers.load(Ordering::Relaxed),
            peers: self.peers.load(Ordering::Relaxed),
            clients: self.clients.load(Ordering::Relaxed),
        }
    }

    /// Whether publishers can reach this session: it listens (a publisher can connect to
    /// it, as to a zenohd whose listener is up), or it has a session with another node.
    /// A daemon that only connects is reachable only while one of its sessions is open.
    #[must_use]
    pub fn reachable(&self) -> bool {
        self.listening.load(Ordering::Relaxed) || self.connected.load(Ordering::Relaxed)
    }
}

/// The kind of node at the other end of one session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Router,
    Peer,
    Client,
}

/// The session's unicast transports as (other node's id, its kind). Zenoh 1.10's stable
/// `SessionInfo` lists routers and peers only (`routers_zid`, `peers_zid`), not clients;
/// the transports, clients included, are in the session's own admin space
/// (`@/<zid>/session/transport/unicast/<other zid>`, JSON `{"zid", "whatami", …}`), which
/// every session answers for itself (a session-local queryable; the router admin space,
/// off by default, is not involved). `None` when the query could not be made.
fn transports(session: &Session, key: &str) -> Option<Vec<(String, Kind)>> {
    let replies = session
        .get(key)
        .allowed_destination(Locality::SessionLocal)
        .timeout(Duration::from_secs(1))
        .wait()
        .ok()?;
    let mut out = Vec::new();
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else { continue };
        let Ok(v) = serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
        else {
            continue;
        };
        let kind = match v.get("whatami").and_then(serde_json::Value::as_str) {
            Some("router") => Kind::Router,
            Some("peer") => Kind::Peer,
            Some("client") => Kind::Client,
            _ => continue,
        };
        let zid = v
            .get("zid")
            .and_then(serde_json::Value::as_str)
            .map_or_else(|| sample.key_expr().as_str().to_owned(), str::to_owned);
        out.push((zid, kind));
    }
    Some(out)
}

/// Polls the session's transports (routers, peers and clients) every `period` on a
/// thread of its own, and calls `on_change(connected, connectivity)` at each change of
/// "at least one router or peer session open" (the first connection included; clients
/// are counted but do not make connections, losses or reconnections); stops when the
/// returned handle is dropped.
#[derive(Debug)]
pub struct ConnectivityWatch {
    state: Arc<Connectivity>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ConnectivityWatch {
    /// Starts the watch.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when the thread cannot be started.
    pub fn start(
        session: Session,
        period: Duration,
        on_change: impl Fn(bool, &Connectivity) + Send + 'static,
    ) -> Result<Self, ZenohError> {
        let state = Arc::new(Connectivity::default());
        let st = Arc::clone(&state);
        let key = format!("@/{}/session/transport/unicast/*", session.zid());
        let thread = std::thread::Builder::new()
            .name("glrmon-connectivity".into())
            .spawn(move || {
                let mut ever = false;
                let mut was = false;
                let mut routers: Vec<String> = Vec::new();
                while !st.stop.load(Ordering::Relaxed) {
                    let mut sessions = transports(&session, &key).unwrap_or_default();
                    // The stable listing (routers and peers) too, should the admin space
                    // not answer.
                    let info = session.info();
                    let r = info.routers_zid().wait().map(|z| (z, Kind::Router));
                    let p = info.peers_zid().wait().map(|z| (z, Kind::Peer));
                    for (zid, kind) in r.chain(p) {
                        let zid = zid.to_string();
                        if !sessions.iter().any(|s| s.0 == zid) {
                            sessions.push((zid, kind));
                        }
                    }
                    let count = |k: Kind| sessions.iter().filter(|s| s.1 == k).count() as u64;
                    st.routers.store(count(Kind::Router), Ordering::Relaxed);
                    st.peers.store(count(Kind::Peer), Ordering::Relaxed);
                    st.clients.store(count(Kind::Client), Ordering::Relaxed);
                    let mut now_routers: Vec<String> = sessions
                        .iter()
                        .filter(|s| s.1 == Kind::Router)
                        .map(|s| s.0.clone())
                        .collect();
                    now_routers.sort_unstable();
                    st.connected.store(!sessions.is_empty(), Ordering::Relaxed);
                    // Losses and reconnections are those of the network this session
                    // joins (routers and peers, which Zenoh reconnects); clients come
                    // and go on their own and are only counted.
                    let now = sessions.iter().any(|s| s.1 != Kind::Client);
                    // A router that restarted between two polls comes back with a new
                    // identity: a loss and a reconnection the polls did not see apart.
                    let replaced = was
                        && now
                        && !routers.is_empty()
                        && !now_routers.is_empty()
                        && !now_routers.iter().any(|z| routers.contains(z));
                    if replaced {
                        st.losses.fetch_add(1, Ordering::Relaxed);
                        on_change(false, &st);
                        was = false;
                    }
                    if now != was {
                        if now && ever {
                            st.reconnections.fetch_add(1, Ordering::Relaxed);
                        }
                        if !now {
                            st.losses.fetch_add(1, Ordering::Relaxed);
                        }
                        ever |= now;
                        on_change(now, &st);
                        was = now;
                    }
                    routers = now_routers;
                    std::thread::park_timeout(period);
                }
            })
            .map_err(|e| ZenohError::Session {
                what: "start the connectivity watch",
                message: e.to_string(),
            })?;
        Ok(Self {
            state,
            thread: Some(thread),
        })
    }

    /// The shared state (for the status).
    #[must_use]
    pub fn state(&self) -> Arc<Connectivity> {
        Arc::clone(&self.state)
    }
}

impl Drop for ConnectivityWatch {
    fn drop(&mut self) {
        self.state.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

/// Queries the status of every instance matching `instances` (a key expression over
/// instance names, `*` for all): (instance, status JSON) pairs, in name order. Waits at
/// most `timeout`, less when every instance has answered.
///
/// # Errors
/// [`ZenohError::Session`] when the query cannot be sent.
pub async fn query_status(
    session: &Session,
    instances: &str,
    timeout: Duration,
) -> Result<Vec<(String, String)>, ZenohError> {
    let replies = session
        .get(status_key(instances))
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(session_err("status query"))?;
    let mut out = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            let name = sample
                .key_expr()
                .as_str()
                .trim_start_matches("glrmon/@status/")
                .to_owned();
            let json = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
            out.push((name, json));
        }
    }
    out.sort();
    out.dedup_by(|a, b| a.0 == b.0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_messages_lose_their_source_locations() {
        let raw = "Can not create a new TCP listener bound to tcp/127.0.0.1:17998: \
                   [127.0.0.1:17998: Address already in use (os error 98) at \
                   /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-commons-1.10.2/src/tcp.rs:61.] \
                   at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-tcp-1.10.2/src/unicast.rs:338.";
        assert_eq!(
            without_source_locations(raw),
            "Can not create a new TCP listener bound to tcp/127.0.0.1:17998: \
             [127.0.0.1:17998: Address already in use (os error 98)]"
        );
        assert_eq!(
            without_source_locations("look at the router at tcp/10.0.0.1:7447"),
            "look at the router at tcp/10.0.0.1:7447"
        );
    }

    /// A free loopback port (bound, then released).
    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    /// A client whose endpoint has nothing listening fails with the endpoint, the
    /// system's reason and the setting to change, in one line without Zenoh's debug
    /// notation or source paths.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_dead_endpoint_is_named_with_its_reason_and_hint() {
        let endpoint = format!("tcp/127.0.0.1:{}", free_port());
        let e = open(&SessionSettings {
            mode: Some("client".into()),
            connect: vec![endpoint.clone()],
            connect_hint: Some("--connect".into()),
            ..SessionSettings::default()
        })
        .await
        .unwrap_err();
        assert!(matches!(e, ZenohError::Connect { .. }), "{e:?}");
        let m = e.to_string();
        assert_eq!(
            m,
            format!(
                "cannot connect to {endpoint} (connection refused): is `glrmon run` or a \
                 Zenoh router listening there? Give its endpoint with --connect"
            )
        );
    }

    /// A listen endpoint in use fails once, naming it, the reason and the setting.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_busy_listen_endpoint_is_named_with_its_reason_and_hint() {
        let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let endpoint = format!("tcp/{}", busy.local_addr().unwrap());
        let e = open(&SessionSettings {
            listen: vec![endpoint.clone()],
            listen_hint: Some("--listen".into()),
            ..SessionSettings::default()
        })
        .await
        .unwrap_err();
        assert!(matches!(e, ZenohError::Listen { .. }), "{e:?}");
        assert_eq!(
            e.to_string(),
            format!(
                "cannot listen on {endpoint} (address already in use): another process \
                 listens there (a `glrmon run` or a Zenoh router?); choose another endpoint \
                 with --listen"
            )
        );
    }

    #[test]
    fn open_errors_are_classified() {
        let endpoints = Endpoints {
            mode: "client".into(),
            listen: vec!["tcp/127.0.0.1:7448".into(), "udp/127.0.0.1:7449".into()],
            connect: vec!["udp/127.0.0.1:1".into()],
        };
        let s = SessionSettings::default();
        let e = open_error(
            "Unable to connect to any of [Single(udp/127.0.0.1:1)]! ",
            &endpoints,
            &s,
        );
        assert_eq!(
            e.to_string(),
            "cannot connect to udp/127.0.0.1:1 (the udp transport is not built into glrmon \
             (tcp and tls only)): is `glrmon run` or a Zenoh router listening there? Check the \
             endpoints to connect to"
        );
        let e = open_error("Unicast not supported for udp protocol", &endpoints, &s);
        assert_eq!(
            e.to_string(),
            "cannot listen on udp/127.0.0.1:7449 (the udp transport is not built into \
             glrmon (tcp and tls only)): choose another endpoint to listen on"
        );
        let e = open_error(
            "Can not create a new TCP listener bound to tcp/127.0.0.1:7448: [127.0.0.1:7448: \
             Cannot assign requested address (os error 99)]",
            &endpoints,
            &s,
        );
        assert!(
            e.to_string().starts_with(
                "cannot listen on tcp/127.0.0.1:7448 (cannot assign requested address): \
                 that address is not one of this machine's"
            ),
            "{e}"
        );
        let e = open_error("something else entirely", &endpoints, &s);
        assert!(matches!(e, ZenohError::Session { .. }), "{e:?}");
    }

    #[test]
    fn unreachable_reasons() {
        assert_eq!(
            unreachable_reason(&format!("tcp/127.0.0.1:{}", free_port())),
            "connection refused"
        );
        assert!(
            unreachable_reason("tcp/nonexistent.invalid:7447")
                .starts_with("cannot resolve nonexistent.invalid:7447: "),
        );
        let open = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let r = unreachable_reason(&format!("tcp/{}", open.local_addr().unwrap()));
        assert!(r.contains("not a Zenoh node"), "{r}");
    }

    #[test]
    fn config_defaults_are_loopback_safe() {
        let c = build_config(&SessionSettings::default()).unwrap();
        assert_eq!(c.get_json("mode").unwrap(), "\"peer\"");
        assert_eq!(c.get_json("listen/endpoints").unwrap(), "[]");
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(c.get_json("timestamping/enabled").unwrap(), "true");
    }

    #[test]
    fn explicit_settings_are_applied_and_bad_mode_rejected() {
        let s = SessionSettings {
            mode: Some("client".into()),
            connect: vec!["tcp/127.0.0.1:7447".into()],
            ..SessionSettings::default()
        };
        let c = build_config(&s).unwrap();
        assert_eq!(c.get_json("mode").unwrap(), "\"client\"");
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            "[\"tcp/127.0.0.1:7447\"]"
        );
        let bad = SessionSettings {
            mode: Some("router-ish".into()),
            ..SessionSettings::default()
        };
        assert!(
            build_config(&bad)
                .unwrap_err()
                .to_string()
                .contains("router-ish")
        );
    }

    #[test]
    fn endpoints_are_read_back_from_the_config() {
        let s = SessionSettings {
            connect: vec!["tcp/127.0.0.1:7447".into()],
            listen: vec!["tcp/127.0.0.1:7448".into()],
            ..SessionSettings::default()
        };
        assert_eq!(
            Endpoints::of(&s).unwrap(),
            Endpoints {
                mode: "peer".into(),
                listen: vec!["tcp/127.0.0.1:7448".into()],
                connect: vec!["tcp/127.0.0.1:7447".into()],
            }
        );
        let mut c = Config::default();
        c.insert_json5("mode", "\"client\"").unwrap();
        c.insert_json5(
            "connect/endpoints",
            "{router: [\"tcp/10.0.0.1:7447\"], client: [\"tcp/10.0.0.2:7447\"]}",
        )
        .unwrap();
        let e = Endpoints::from_config(&c);
        assert_eq!(e.mode, "client");
        assert_eq!(e.connect, ["tcp/10.0.0.2:7447"]);
    }

    /// A listening peer sees a client-mode session as a client (Zenoh's stable
    /// `SessionInfo` lists routers and peers only), and counts it gone once it closes.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_session_is_counted_as_a_client() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let daemon = open(&SessionSettings {
            listen: vec![endpoint.clone()],
            ..SessionSettings::default()
        })
        .await
        .unwrap();
        let watch =
            ConnectivityWatch::start(daemon.clone(), Duration::from_millis(20), |_, _| {}).unwrap();
        let state = watch.state();
        state.listening.store(true, Ordering::Relaxed);
        assert!(state.reachable() && !state.connected.load(Ordering::Relaxed));
        let client = open(&SessionSettings {
            mode: Some("client".into()),
            connect: vec![endpoint],
            ..SessionSettings::default()
        })
        .await
        .unwrap();
        let wait = |want: ZenohSessions| {
            let t = Instant::now();
            while state.sessions() != want {
                assert!(
                    t.elapsed() < Duration::from_secs(10),
                    "{:?}",
                    state.sessions()
                );
                std::thread::sleep(Duration::from_millis(10));
            }
        };
        wait(ZenohSessions {
            routers: 0,
            peers: 0,
            clients: 1,
        });
        assert!(state.connected.load(Ordering::Relaxed));
        client.close().await.unwrap();
        wait(ZenohSessions::default());
        assert!(!state.connected.load(Ordering::Relaxed));
        // A client leaving is not a loss of the network.
        assert_eq!(state.losses.load(Ordering::Relaxed), 0);
        drop(watch);
        daemon.close().await.unwrap();
    }

    #[test]
    fn config_values_are_escaped() {
        assert_eq!(
            serde_json_list(&["a\"b\\c".into(), "é".into()]),
            r#"["a\"b\\c","é"]"#
        );
        assert_eq!(serde_json_list(&[]), "[]");
        assert_eq!(json_string("pe\"er"), r#""pe\"er""#);
    }

    #[test]
    fn status_reply_is_the_typed_status_with_names_escaped() {
        let stats = Arc::new(vec![
            Arc::new(ChannelStats::default()),
            Arc::new(ChannelStats::default()),
        ]);
        stats[1].samples.store(5, Ordering::Relaxed);
        stats[1].next_k.store(5, Ordering::Relaxed);
        let st = StatusSource::new("a\"b".into(), vec!["c1".into(), "c\\2".into()], stats);
        let j = status::encode(&st.snapshot()).unwrap();
        assert!(j.starts_with("{\"instance\":\"a\\\"b\""), "{j}");
        assert!(j.contains("\"last_k\":null"), "{j}");
        assert!(j.contains("{\"channel\":\"c\\\\2\",\"samples\":5,"), "{j}");
        let back = status::decode(j.as_bytes()).unwrap();
        assert_eq!(back.instance, "a\"b");
        assert_eq!(back.shard, None);
        assert!(back.connected);
        assert_eq!(back.channels[1].channel, "c\\2");
        assert_eq!(back.channels[1].last_k, Some(4));
        assert_eq!(back.uptime, (back.uptime * 1e3).round() / 1e3);
    }
}
