#![doc = include_str!("../README.md")]
//! `/metrics` (Prometheus text format 0.0.4), `/healthz` and `/readyz` of a glrmon
//! daemon (`glrmon run --metrics ADDR` or `[daemon] metrics`). A minimal HTTP/1.1
//! responder: one GET per connection, no keep-alive, bounded request size and time;
//! it reads only the daemon's counters ([`MetricsSource`]), never the data path.
//!
//! The instance is the label `glrmon_instance`, not `instance`: Prometheus sets
//! `instance` on every scraped sample itself (the target's address) and would rename
//! ours `exported_instance`.

mod process;

use std::fmt::Write as _;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glrmon_record::RecorderStats;
use glrmon_runtime::{ChannelStats, LATENCY_BUCKETS, LatencyHistogram, RuntimeMetrics};
use glrmon_wire::ChannelStatus;
use glrmon_zenoh::Connectivity;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

/// The version of this build (the workspace's `version`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The short git commit this build was made from, or "unknown" outside a git checkout
/// (build.rs: `GLRMON_GIT_HASH` from the environment, else `git rev-parse --short HEAD`).
pub const GIT_HASH: &str = env!("GLRMON_GIT_HASH");

/// Reads one counter of a channel's status.
type ChannelCounter = fn(&ChannelStatus) -> u64;

/// What the endpoints report.
#[derive(Debug)]
pub struct MetricsSource {
    /// The instance's name (the `glrmon_instance` label).
    pub instance: String,
    /// Channel names, by index.
    pub channels: Vec<String>,
    /// The channels' counters ([`glrmon_runtime::Runtime::stats`]).
    pub stats: Arc<Vec<Arc<ChannelStats>>>,
    /// Queue, worker and latency metrics of the runtime.
    pub runtime: Arc<RuntimeMetrics>,
    /// Worker threads started: fewer alive means unhealthy.
    pub workers: u64,
    /// The Zenoh session's sessions with other nodes, and whether it listens.
    pub connectivity: Arc<Connectivity>,
    /// The recorder's counters, when recording.
    pub recorder: Option<Arc<RecorderStats>>,
    /// When the instance started (uptime).
    pub started: Instant,
    /// Set once intake is open (subscribers declared, channels claimed).
    pub ready: Arc<AtomicBool>,
    /// An automatic shard's assignment (`None` for a static shard or none).
    pub assignment: Option<Arc<std::sync::Mutex<glrmon_wire::Assignment>>>,
}

impl MetricsSource {
    /// Alive: every worker thread runs.
    fn healthy(&self) -> bool {
        self.runtime.workers_alive.load(Ordering::Relaxed) == self.workers
    }

    /// Ready: healthy, intake open, and reachable by publishers: listening, or with a
    /// session open with a router, peer or client
    /// ([`glrmon_zenoh::Connectivity::reachable`]).
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.healthy() && self.ready.load(Ordering::Relaxed) && self.connectivity.reachable()
    }

    /// The Prometheus exposition.
    #[must_use]
    pub fn render(&self) -> String {
        let mut o = String::new();
        let inst = label(&self.instance);
        self.render_channels(&mut o, &inst);
        self.render_instance(&mut o, &inst);
        let r = &self.runtime;
        histogram(
            &mut o,
            "glrmon_processing_seconds",
            "From a payload's receipt to its records handed to the output stage.",
            &inst,
            &r.processing,
        );
        histogram(
            &mut o,
            "glrmon_delivery_seconds",
            "From a payload's receipt to its alarm, end, diagnosis or error record written by every sink.",
            &inst,
            &r.delivery,
        );
        process::render(&mut o);
        o
    }

    /// The per-channel families: samples, drops, alarms, the active flag, rejections
    /// by code.
    fn render_channels(&self, o: &mut String, inst: &str) {
        let family = |o: &mut String, name: &str, kind: &str, help: &str| {
            let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} {kind}");
            name.to_owned()
        };
        let mut lines = Vec::new();
        // One reading of the channels' counters for every family, the same reading as
        // the status queryable's.
        let channels = glrmon_runtime::channel_statuses(&self.channels, &self.stats);
        let per_channel: [(&str, &str, &str, ChannelCounter); 4] = [
            (
                "glrmon_samples_total",
                "counter",
                "Samples processed.",
                |s| s.samples,
            ),
            (
                "glrmon_dropped_payloads_total",
                "counter",
                "Payloads dropped at intake (worker queue full); the gap is filled by predict-only steps.",
                |s| s.dropped,
            ),
            (
                "glrmon_alarms_total",
                "counter",
                "Alarm episodes started.",
                |s| s.alarms,
            ),
            (
                "glrmon_alarm_active",
                "gauge",
                "1 while an alarm episode is going on.",
                |s| u64::from(s.alarm_active),
            ),
        ];
        for (name, kind, help, get) in per_channel {
            let n = family(o, name, kind, help);
            for c in &channels {
                lines.push(format!(
                    "{n}{{glrmon_instance={inst},channel={}}} {}",
                    label(&c.channel),
                    get(c)
                ));
            }
            o.push_str(&lines.join("\n"));
            o.push('\n');
            lines.clear();
        }
        let n = family(
            o,
            "glrmon_rejected_total",
            "counter",
            "Rejected input by error code (docs/WIRE.md).",
        );
        for c in &channels {
            for (code, count) in &c.errors {
                let _ = writeln!(
                    o,
                    "{n}{{glrmon_instance={inst},channel={},code={}}} {count}",
                    label(&c.channel),
                    label(code)
                );
            }
        }
    }

    /// The instance's families: queues, workers, readiness, Zenoh, uptime, recording,
    /// the build.
    fn render_instance(&self, o: &mut String, inst: &str) {
        let r = &self.runtime;
        let mut gauge = |name: &str, help: &str, kind: &str, v: String| {
            let _ = writeln!(
                o,
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name}{{glrmon_instance={inst}}} {v}"
            );
        };
        gauge(
            "glrmon_queued_payloads",
            "Payloads accepted and waiting for a worker.",
            "gauge",
            r.queued_payloads.load(Ordering::Relaxed).max(0).to_string(),
        );
        gauge(
            "glrmon_queued_bytes",
            "Bytes of the payloads waiting for a worker (bounded by daemon.intake_mb).",
            "gauge",
            r.queued_bytes.load(Ordering::Relaxed).max(0).to_string(),
        );
        gauge(
            "glrmon_workers_alive",
            "Worker threads running.",
            "gauge",
            r.workers_alive.load(Ordering::Relaxed).to_string(),
        );
        gauge(
            "glrmon_ready",
            "1 while /readyz answers 200: workers running, intake open, and listening or connected.",
            "gauge",
            u8::from(self.is_ready()).to_string(),
        );
        gauge(
            "glrmon_zenoh_connected",
            "1 while at least one Zenoh session with a router, peer or client is open.",
            "gauge",
            u8::from(self.connectivity.connected.load(Ordering::Relaxed)).to_string(),
        );
        gauge(
            "glrmon_zenoh_reconnections_total",
            "Connections regained after a loss.",
            "counter",
            self.connectivity
                .reconnections
                .load(Ordering::Relaxed)
                .to_string(),
        );
        gauge(
            "glrmon_uptime_seconds",
            "Seconds since start.",
            "gauge",
            format!("{:.3}", self.started.elapsed().as_secs_f64()),
        );
        if let Some(a) = &self.assignment {
            let a = a
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .clone();
            gauge(
                "glrmon_assignment_generation",
                "The automatic shard's generation: changes of this instance's view of the live instances, from 1.",
                "gauge",
                a.generation.to_string(),
            );
            gauge(
                "glrmon_live_instances",
                "Live instances in this instance's view, itself included.",
                "gauge",
                a.instances.len().to_string(),
            );
            gauge(
                "glrmon_takeovers_total",
                "Channels taken over from an instance that left.",
                "counter",
                a.takeovers.to_string(),
            );
            gauge(
                "glrmon_handovers_total",
                "Channels handed over to an instance that joined, or at a clean shutdown.",
                "counter",
                a.handovers.to_string(),
            );
        }
        if let Some(rec) = &self.recorder {
            gauge(
                "glrmon_recording_messages_total",
                "MCAP messages written.",
                "counter",
                rec.messages.load(Ordering::Relaxed).to_string(),
            );
            gauge(
                "glrmon_recording_bytes_total",
                "Bytes of finished and current MCAP files written.",
                "counter",
                rec.bytes.load(Ordering::Relaxed).to_string(),
            );
            gauge(
                "glrmon_recording_errors_total",
                "MCAP write failures.",
                "counter",
                rec.errors.load(Ordering::Relaxed).to_string(),
            );
        }
        let sessions = self.connectivity.sessions();
        let _ = writeln!(
            o,
            "# HELP glrmon_zenoh_sessions Open Zenoh sessions with other nodes, by the other node's kind.\n# TYPE glrmon_zenoh_sessions gauge"
        );
        for (kind, n) in [
            ("router", sessions.routers),
            ("peer", sessions.peers),
            ("client", sessions.clients),
        ] {
            let _ = writeln!(
                o,
                "glrmon_zenoh_sessions{{glrmon_instance={inst},kind=\"{kind}\"}} {n}"
            );
        }
        let _ = writeln!(
            o,
            "# HELP glrmon_build_info The version and git commit of this build.\n# TYPE glrmon_build_info gauge\nglrmon_build_info{{version={},git={}}} 1",
            label(VERSION),
            label(GIT_HASH)
        );
    }
}

fn histogram(o: &mut String, name: &str, help: &str, inst: &str, h: &LatencyHistogram) {
    let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} histogram");
    let mut cumulative = 0;
    for (i, c) in h.counts.iter().enumerate() {
        cumulative += c.load(Ordering::Relaxed);
        let le = LATENCY_BUCKETS
            .get(i)
            .map_or_else(|| "+Inf".to_owned(), |b| format!("{b}"));
        let _ = writeln!(
            o,
            "{name}_bucket{{glrmon_instance={inst},le=\"{le}\"}} {cumulative}"
        );
    }
    let sum = h.sum_ns.load(Ordering::Relaxed) as f64 * 1e-9;
    let _ = writeln!(o, "{name}_sum{{glrmon_instance={inst}}} {sum}");
    let _ = writeln!(o, "{name}_count{{glrmon_instance={inst}}} {cumulative}");
}

/// A label value, quoted and escaped (Prometheus text format).
fn label(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The endpoint could not be started.
#[derive(Debug, thiserror::Error)]
#[error("metrics endpoint {addr}: {source}")]
pub struct MetricsError {
    /// The address asked for.
    pub addr: String,
    /// Why binding it failed.
    pub source: std::io::Error,
}

/// The warning to log when the endpoint listens beyond this host: `None` for a loopback
/// address (127.0.0.0/8, ::1), otherwise a sentence saying that the endpoint is
/// reachable from the network, unauthenticated, and how to protect it.
///
/// # Examples
///
/// ```
/// assert!(glrmon_metrics::exposure_warning("127.0.0.1:9464".parse().unwrap()).is_none());
/// assert!(glrmon_metrics::exposure_warning("0.0.0.0:9464".parse().unwrap()).is_some());
/// ```
#[must_use]
pub fn exposure_warning(bound: std::net::SocketAddr) -> Option<String> {
    if bound.ip().is_loopback() {
        return None;
    }
    let scope = if bound.ip().is_unspecified() {
        "every network interface of this host"
    } else {
        "a non-loopback address"
    };
    Some(format!(
        "The metrics endpoint {bound} listens on {scope}: /metrics, /healthz and /readyz are \
         served without authentication or TLS to anyone who can reach it. Bind it to \
         127.0.0.1 and scrape through a reverse proxy or an SSH tunnel, or restrict the port \
         with a firewall (docs/OPERATIONS.md, \"Metrics\")."
    ))
}

/// Binds `addr` and serves on the current tokio runtime until the returned task is
/// aborted; returns the bound address (the port, if `addr` asked for port 0) and the
/// task.
///
/// # Errors
/// [`MetricsError`] when `addr` cannot be bound.
pub async fn serve(
    addr: &str,
    source: Arc<MetricsSource>,
) -> Result<(std::net::SocketAddr, tokio::task::JoinHandle<()>), MetricsError> {
    let error = |source| MetricsError {
        addr: addr.to_owned(),
        source,
    };
    let listener = TcpListener::bind(addr).await.map_err(error)?;
    let bound = listener.local_addr().map_err(error)?;
    Ok((
        bound,
        tokio::spawn(async move {
            loop {
                let Ok((mut stream, _)) = listener.accept().await else {
                    continue;
                };
                let source = source.clone();
                tokio::spawn(async move {
                    let mut buf = vec![0u8; 4096];
                    let mut len = 0;
                    // Read up to the end of the request head (or 4 KiB, or 2 s).
                    let read = tokio::time::timeout(std::time::Duration::from_secs(2), async {
                        while len < buf.len() {
                            match stream.read(&mut buf[len..]).await {
                                Ok(0) | Err(_) => break,
                                Ok(n) => len += n,
                            }
                            if buf[..len].windows(4).any(|w| w == b"\r\n\r\n") {
                                break;
                            }
                        }
                    })
                    .await;
                    if read.is_err() {
                        return;
                    }
                    let head = String::from_utf8_lossy(&buf[..len]);
                    let (status, ctype, body) = respond(&head, &source);
                    let reply = format!(
                        "HTTP/1.1 {status}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                        body.len()
                    );
                    let _ = stream.write_all(reply.as_bytes()).await;
                    let _ = stream.shutdown().await;
                });
            }
        }),
    ))
}

/// (status line, content type, body) for a request head.
fn respond(head: &str, s: &MetricsSource) -> (&'static str, &'static str, String) {
    let mut parts = head.split_whitespace();
    let (method, path) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let text = "text/plain; charset=utf-8";
    if method != "GET" {
        return ("405 Method Not Allowed", text, "only GET\n".into());
    }
    match path {
        "/metrics" => (
            "200 OK",
            "text/plain; version=0.0.4; charset=utf-8",
            s.render(),
        ),
        "/healthz" if s.healthy() => ("200 OK", text, "ok\n".into()),
        "/healthz" => (
            "503 Service Unavailable",
            text,
            "a worker thread has stopped\n".into(),
        ),
        "/readyz" if s.is_ready() => ("200 OK", text, "ready\n".into()),
        "/readyz" => (
            "503 Service Unavailable",
            text,
            if !s.healthy() {
                "a worker thread has stopped\n".into()
            } else if !s.ready.load(Ordering::Relaxed) {
                "starting\n".into()
            } else {
                "not listening, and not connected to any Zenoh router, peer or client\n".into()
            },
        ),
        _ => (
            "404 Not Found",
            text,
            "try /metrics, /healthz or /readyz\n".into(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_channel_families_read_the_channel_status() {
        let stats = Arc::new(vec![
            Arc::new(ChannelStats::default()),
            Arc::new(ChannelStats::default()),
        ]);
        stats[1].samples.store(400, Ordering::Relaxed);
        stats[1].alarms.store(2, Ordering::Relaxed);
        stats[1].alarm_active.store(1, Ordering::Relaxed);
        stats[1].dropped.store(3, Ordering::Relaxed);
        stats[1].errors.lock().unwrap().insert("gap", 5);
        let source = MetricsSource {
            instance: "i\"1".into(),
            channels: vec!["a".into(), "b\\c".into()],
            stats,
            runtime: Arc::new(RuntimeMetrics::default()),
            workers: 0,
            connectivity: Arc::new(Connectivity::default()),
            recorder: None,
            started: Instant::now(),
            ready: Arc::new(AtomicBool::new(false)),
            assignment: None,
        };
        let body = source.render();
        assert!(
            !body.contains("{instance="),
            "Prometheus would rename the label exported_instance:\n{body}"
        );
        assert!(
            body.lines()
                .any(|l| l.starts_with("glrmon_build_info{version=\"")
                    && l.ends_with("\"} 1")
                    && l.contains(&format!(",git={}}}", label(GIT_HASH)))),
            "{body}"
        );
        for line in [
            r#"glrmon_samples_total{glrmon_instance="i\"1",channel="a"} 0"#,
            r#"glrmon_samples_total{glrmon_instance="i\"1",channel="b\\c"} 400"#,
            r#"glrmon_dropped_payloads_total{glrmon_instance="i\"1",channel="b\\c"} 3"#,
            r#"glrmon_alarms_total{glrmon_instance="i\"1",channel="b\\c"} 2"#,
            r#"glrmon_alarm_active{glrmon_instance="i\"1",channel="a"} 0"#,
            r#"glrmon_alarm_active{glrmon_instance="i\"1",channel="b\\c"} 1"#,
            r#"glrmon_rejected_total{glrmon_instance="i\"1",channel="b\\c",code="gap"} 5"#,
            r#"glrmon_zenoh_sessions{glrmon_instance="i\"1",kind="client"} 0"#,
            r#"glrmon_ready{glrmon_instance="i\"1"} 0"#,
            "# TYPE glrmon_alarm_active gauge",
            "# TYPE glrmon_rejected_total counter",
        ] {
            assert!(body.lines().any(|l| l == line), "{line} not in\n{body}");
        }
    }
}
