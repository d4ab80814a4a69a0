//! The file's top-level tables: `[zenoh]`, `[daemon]` and `[recording]`.

use super::Validator;
use crate::schema::{DaemonSpec, RecordingSpec, ZenohSpec};
use crate::{ShardMode, check_endpoint, limits, locate, validate_instance};

impl Validator {
    /// `[zenoh]`: the mode, and the syntax of each endpoint.
    pub(super) fn zenoh(&mut self, z: &ZenohSpec) {
        if let Some(mode) = &z.mode
            && !matches!(mode.as_str(), "peer" | "client" | "router")
        {
            self.error(
                "zenoh.mode".into(),
                locate::not_one_of(mode, &["peer", "client", "router"]),
            );
        }
        for (field, endpoints) in [("zenoh.connect", &z.connect), ("zenoh.listen", &z.listen)] {
            for (i, e) in endpoints.iter().enumerate() {
                if let Err(why) = check_endpoint(e) {
                    self.error(format!("{field}[{i}]"), why);
                }
            }
        }
    }

    /// `[daemon]`: positive sizes within [`limits`], the instance name, the shard and
    /// the metrics address.
    pub(super) fn daemon(&mut self, d: &DaemonSpec) {
        if d.workers == Some(0)
            || d.worker_queue == 0
            || d.output_queue == 0
            || d.max_payload_bytes == 0
        {
            self.error(
                "daemon".into(),
                "workers, worker_queue, output_queue and max_payload_bytes must be positive".into(),
            );
        }
        for (field, mb) in [
            ("worker_queue_mb", d.worker_queue_mb),
            ("intake_mb", d.intake_mb),
        ] {
            // At least one payload of the largest accepted size must fit.
            let least = d.max_payload_bytes as f64 / (1024.0 * 1024.0);
            if !(mb.is_finite() && mb >= least && mb <= 1024.0 * 1024.0) {
                self.error(
                    format!("daemon.{field}"),
                    format!("{mb} must be between max_payload_bytes ({least} MiB) and 1048576 MiB"),
                );
            }
        }
        for (field, value, max) in [
            ("workers", d.workers.unwrap_or(1), limits::MAX_WORKERS),
            ("worker_queue", d.worker_queue, limits::MAX_QUEUE),
            ("output_queue", d.output_queue, limits::MAX_QUEUE),
            (
                "max_payload_bytes",
                d.max_payload_bytes,
                limits::MAX_PAYLOAD_BYTES,
            ),
        ] {
            if value > max {
                self.error(
                    format!("daemon.{field}"),
                    format!("{value} is more than {max} (glrmon_spec::limits)"),
                );
            }
        }
        if let Some(instance) = &d.instance
            && let Err(e) = validate_instance(instance)
        {
            self.error("daemon.instance".into(), e);
        }
        if !(d.shutdown_timeout.is_finite() && d.shutdown_timeout > 0.0) {
            self.error(
                "daemon.shutdown_timeout".into(),
                format!("{} must be finite and positive", d.shutdown_timeout),
            );
        }
        if let Some(text) = &d.shard
            && let Err(e) = text.parse::<ShardMode>()
        {
            self.error("daemon.shard".into(), e);
        }
        if let Some(addr) = &d.metrics
            && addr.parse::<std::net::SocketAddr>().is_err()
        {
            self.error(
                "daemon.metrics".into(),
                format!("\"{addr}\" is not a local address of the form 127.0.0.1:9464"),
            );
        }
    }

    /// `[recording]`: file sizes and durations, the compression, the queue, the file
    /// name prefix and the capture around alarms.
    pub(super) fn recording(&mut self, r: &RecordingSpec) {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        for (field, value) in [
            ("max_file_mb", r.max_file_mb),
            ("max_file_seconds", r.max_file_seconds),
            ("flush_seconds", r.flush_seconds),
        ] {
            if !positive(value) {
                self.error(
                    format!("recording.{field}"),
                    format!("{value} must be finite and positive"),
                );
            }
        }
        if let Some(cap) = r.max_total_mb {
            if !positive(cap) {
                self.error(
                    "recording.max_total_mb".into(),
                    format!("{cap} must be finite and positive"),
                );
            } else if cap < r.max_file_mb {
                self.error(
                    "recording.max_total_mb".into(),
                    format!(
                        "{cap} MB is less than one file (max_file_mb = {} MB): the cap would \
                         delete every finished recording",
                        r.max_file_mb
                    ),
                );
            }
        }
        if r.flush_seconds > 60.0 {
            self.error(
                "recording.flush_seconds".into(),
                format!(
                    "{} s: at most 60, so that a crash loses little",
                    r.flush_seconds
                ),
            );
        }
        if !(1..=1 << 20).contains(&r.chunk_kb) {
            self.error(
                "recording.chunk_kb".into(),
                format!("{} is not in 1..=1048576", r.chunk_kb),
            );
        }
        if !matches!(r.compression.as_str(), "zstd" | "none") {
            self.error(
                "recording.compression".into(),
                locate::not_one_of(&r.compression, &["zstd", "none"]),
            );
        }
        if r.queue == 0 {
            self.error("recording.queue".into(), "must be positive".into());
        }
        if r.queue > limits::MAX_QUEUE {
            self.error(
                "recording.queue".into(),
                format!(
                    "{} is more than {} (limits::MAX_QUEUE)",
                    r.queue,
                    limits::MAX_QUEUE
                ),
            );
        }
        if r.prefix.is_empty() || r.prefix.contains(['/', '\\']) {
            self.error(
                "recording.prefix".into(),
                format!("\"{}\" must be a non-empty file name part", r.prefix),
            );
        }
        if let Some(c) = r.capture {
            for (field, value) in [
                ("before_seconds", c.before_seconds),
                ("after_seconds", c.after_seconds),
            ] {
                if !(value.is_finite() && value >= 0.0) {
                    self.error(
                        format!("recording.capture.{field}"),
                        format!("{value} must be finite and non-negative"),
                    );
                } else if value > limits::MAX_CAPTURE_SECONDS {
                    self.error(
                        format!("recording.capture.{field}"),
                        format!(
                            "{value} s is more than {} s (limits::MAX_CAPTURE_SECONDS)",
                            limits::MAX_CAPTURE_SECONDS
                        ),
                    );
                }
            }
        }
    }
}
