//! The log: its format (`--log-format`), colour (`--color`, `NO_COLOR`), time zone
//! (`--local-time`), and what the binary logs for the libraries' events.

use std::io::IsTerminal as _;

use clap::ValueEnum;
use glrmon_report::clock::{Zone, format_time};
use std::collections::HashMap;
use std::time::{Duration, Instant};

use glrmon_runtime::{Output, RuntimeEvents, Sink, SinkError};
use glrmon_wire::Record;
use glrmon_wire::text::Escaped;

use crate::print;
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::time::FormatTime;
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;

/// How log lines are written to standard error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum LogFormat {
    /// `2026-12-02T16:22:05.250Z  INFO message key=value`, for people.
    Text,
    /// One JSON object per line (`timestamp`, `level`, `target`, `message` and the
    /// event's fields), for journald, Loki, Vector or jq.
    Json,
}

/// When log lines carry ANSI colour codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum ColorChoice {
    /// Only when standard error is a terminal and `NO_COLOR` is unset or empty.
    Auto,
    /// Always, even into a file or a pipe.
    Always,
    /// Never.
    Never,
}

impl ColorChoice {
    /// Whether to colour, given whether stderr is a terminal and the value of
    /// `NO_COLOR` (<https://no-color.org>: any non-empty value turns colour off).
    fn colors(self, terminal: bool, no_color: Option<&str>) -> bool {
        match self {
            ColorChoice::Always => true,
            ColorChoice::Never => false,
            ColorChoice::Auto => terminal && no_color.is_none_or(str::is_empty),
        }
    }
}

/// Log timestamps: ISO-8601 to the millisecond, in UTC or the local zone.
struct Timestamps(Zone);

impl FormatTime for Timestamps {
    fn format_time(&self, w: &mut Writer<'_>) -> std::fmt::Result {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        w.write_str(&format_time(now, self.0))
    }
}

/// The log's filter when neither `GLRMON_LOG` nor `RUST_LOG` sets one.
const DEFAULT_FILTER: &str = "info,zenoh=warn";

/// Installs the log: `GLRMON_LOG` filters it, else `RUST_LOG`, else
/// [`DEFAULT_FILTER`]. Under the default filter, Zenoh's own WARN lines about an endpoint
/// it cannot connect to or listen on are left out ([`ReportedByGlrmon`]): glrmon says
/// the same in one line with the reason and the flag to change. A filter the user sets
/// (`GLRMON_LOG=info,zenoh=debug`) shows them as Zenoh writes them.
pub(crate) fn init(format: LogFormat, color: ColorChoice, zone: Zone) {
    let user = ["GLRMON_LOG", "RUST_LOG"]
        .into_iter()
        .find_map(|var| tracing_subscriber::EnvFilter::try_from_env(var).ok());
    let replaced = user.is_none().then_some(ReportedByGlrmon);
    let filter = user.unwrap_or_else(|| tracing_subscriber::EnvFilter::new(DEFAULT_FILTER));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_timer(Timestamps(zone));
    match format {
        LogFormat::Text => {
            let no_color = std::env::var("NO_COLOR").ok();
            let ansi = color.colors(std::io::stderr().is_terminal(), no_color.as_deref());
            builder.with_ansi(ansi).finish().with(replaced).init();
        }
        LogFormat::Json => builder
            .json()
            .flatten_event(true)
            .with_current_span(false)
            .with_span_list(false)
            .finish()
            .with(replaced)
            .init(),
    }
}

/// Leaves out Zenoh's WARN events that glrmon reports itself, better: an endpoint it
/// cannot connect to (`Unable to connect to tcp/…! … at ~/.cargo/registry/…`, then
/// `Unable to connect to any of [Single(tcp/…)]!`), a listener it cannot open (whose
/// reason the error then repeats), and a peer's start without its connect endpoints
/// (`Scouting delay elapsed before start conditions are met.`). glrmon's own line names
/// the endpoint, the reason and the flag; Zenoh's name its source files and Rust's debug
/// notation, and a client that retries writes them at every try.
#[derive(Debug, Clone, Copy)]
struct ReportedByGlrmon;

/// The beginnings of the messages [`ReportedByGlrmon`] leaves out.
const REPORTED_BY_GLRMON: [&str; 4] = [
    "Unable to connect to ",
    "Unable to open listener ",
    "Error connecting to ",
    "Scouting delay elapsed before start conditions are met",
];

impl ReportedByGlrmon {
    fn leaves_out(target: &str, level: tracing::Level, message: &str) -> bool {
        level == tracing::Level::WARN
            && (target == "zenoh" || target.starts_with("zenoh::") || target.starts_with("zenoh_"))
            && REPORTED_BY_GLRMON.iter().any(|m| message.starts_with(m))
    }
}

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for ReportedByGlrmon {
    fn event_enabled(
        &self,
        event: &tracing::Event<'_>,
        _: tracing_subscriber::layer::Context<'_, S>,
    ) -> bool {
        let meta = event.metadata();
        if *meta.level() != tracing::Level::WARN || !meta.target().starts_with("zenoh") {
            return true;
        }
        struct Message(String);
        impl tracing::field::Visit for Message {
            fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
                if field.name() == "message" {
                    value.clone_into(&mut self.0);
                }
            }
            fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
                if field.name() == "message" {
                    self.0 = format!("{value:?}");
                }
            }
        }
        let mut message = Message(String::new());
        event.record(&mut message);
        !Self::leaves_out(meta.target(), *meta.level(), &message.0)
    }
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
///
/// A rejection's message quotes the payload (an unknown field's name), so it and the
/// channel are written through [`Escaped`]: a hostile name cannot forge a log line or
/// drive the terminal that shows the log.
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
                    tracing::info!(channel = %Escaped(output.record.channel()), "{line}");
                }
            }
            Record::Consistency(c) => {
                let line = print::line(&output.record).unwrap_or_default();
                if c.state == "consistent" {
                    tracing::info!(channel = %Escaped(&c.channel), "The model fits again: {line}");
                } else {
                    tracing::warn!(channel = %Escaped(&c.channel), "The model no longer fits the plant: {line}");
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
                    tracing::warn!(
                        channel = %Escaped(&e.channel),
                        code = e.code.as_str(),
                        suppressed = entry.1,
                        "{what}: {}.",
                        Escaped(&e.message)
                    );
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_colours_a_terminal_unless_no_color_is_set() {
        assert!(ColorChoice::Auto.colors(true, None));
        assert!(ColorChoice::Auto.colors(true, Some("")));
        assert!(!ColorChoice::Auto.colors(true, Some("1")));
        assert!(!ColorChoice::Auto.colors(false, None));
        assert!(ColorChoice::Always.colors(false, Some("1")));
        assert!(!ColorChoice::Never.colors(true, None));
    }

    /// Zenoh's WARN lines about an endpoint glrmon reports itself are left out, and
    /// nothing else: not glrmon's own, not Zenoh's other warnings, nor its ERROR lines.
    #[test]
    fn only_zenohs_endpoint_warnings_are_left_out() {
        use std::sync::{Arc, Mutex};

        #[derive(Clone, Default)]
        struct Captured(Arc<Mutex<Vec<u8>>>);
        impl std::io::Write for Captured {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(buf);
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let captured = Captured::default();
        let writer = captured.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_ansi(false)
            .with_writer(move || writer.clone())
            .finish()
            .with(Some(ReportedByGlrmon));
        tracing::subscriber::with_default(subscriber, || {
            tracing::warn!(target: "zenoh::net::runtime::orchestrator", "Unable to connect to tcp/127.0.0.1:1! refused");
            tracing::warn!(target: "zenoh::net::runtime::orchestrator", "Unable to connect to any of [Single(tcp/127.0.0.1:1)]! ");
            tracing::warn!(target: "zenoh::net::runtime::orchestrator", "Unable to open listener tcp/127.0.0.1:1: busy");
            tracing::warn!(target: "zenoh::net::runtime::orchestrator", "Scouting delay elapsed before start conditions are met.");
            tracing::warn!(target: "zenoh::net::runtime::orchestrator", "kept: another warning");
            tracing::error!(target: "zenoh::net::runtime::orchestrator", "Unable to connect to kept, an error");
            tracing::warn!(target: "glrmon::commands::run", "Unable to connect to kept, glrmon's own");
        });
        let log = String::from_utf8(captured.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = log.lines().collect();
        assert_eq!(lines.len(), 3, "{log}");
        assert!(lines.iter().all(|l| l.contains("kept")), "{log}");
    }

    /// A rejection whose channel and message hold control sequences and a line break
    /// (an `error` record made from anything but glrmon-wire's escaped decode errors)
    /// is still one log line with visible escapes.
    #[test]
    fn rejections_are_logged_escaped() {
        use std::sync::{Arc, Mutex};

        #[derive(Clone, Default)]
        struct Captured(Arc<Mutex<Vec<u8>>>);
        impl std::io::Write for Captured {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(buf);
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }

        let captured = Captured::default();
        let writer = captured.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_ansi(false)
            .with_writer(move || writer.clone())
            .finish();
        let record = Record::Error(glrmon_wire::ErrorRecord {
            channel: "c\u{1b}]0;pwned\u{7}".into(),
            k: None,
            code: glrmon_wire::ErrorCode::UnknownField,
            message: "x\u{1b}[2J\n2026-12-03T10:00:00.000Z  INFO ALARM forged\u{202e}".into(),
            stage: glrmon_wire::Stage::Receiving,
        });
        tracing::subscriber::with_default(subscriber, || {
            let output = Output {
                record,
                json: Vec::new(),
                log_time_ns: 0,
                stat_index: None,
            };
            LogSink::new().write(&output).unwrap();
        });
        let log = String::from_utf8(captured.0.lock().unwrap().clone()).unwrap();
        assert_eq!(log.lines().count(), 1, "{log}");
        assert!(
            !log.trim_end().chars().any(glrmon_wire::text::needs_escape),
            "{log:?}"
        );
        assert!(
            log.contains(
                r"Rejected input: x\x1b[2J\n2026-12-03T10:00:00.000Z  INFO ALARM forged\u{202e}."
            ),
            "{log}"
        );
        assert!(log.contains(r"channel=c\x1b]0;pwned\x07"), "{log}");
    }
}
