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

/// Installs the log: `GLRMON_LOG` filters it (default `info,zenoh=warn`).
pub(crate) fn init(format: LogFormat, color: ColorChoice, zone: Zone) {
    let filter = tracing_subscriber::EnvFilter::try_from_env("GLRMON_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,zenoh=warn"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_timer(Timestamps(zone));
    match format {
        LogFormat::Text => {
            let no_color = std::env::var("NO_COLOR").ok();
            let ansi = color.colors(std::io::stderr().is_terminal(), no_color.as_deref());
            builder.with_ansi(ansi).init();
        }
        LogFormat::Json => builder
            .json()
            .flatten_event(true)
            .with_current_span(false)
            .with_span_list(false)
            .init(),
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
