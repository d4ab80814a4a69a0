//! A configuration's `[recording]` table → the recorder's settings, and what every
//! file of a recording repeats (the configuration, its channels).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use glrmon_spec::Config;
use glrmon_spec::schema::RecordingSpec;

use crate::{Capture, FileHeader, FileOptions, PARTIAL_SUFFIX, RecorderSettings};

impl RecorderSettings {
    /// The recorder settings a `[recording]` table asks for (sizes in MB of 10⁶ bytes,
    /// durations in seconds; the directory defaults to `recordings`).
    #[must_use]
    pub fn from_spec(r: &RecordingSpec) -> RecorderSettings {
        let mb = |x: f64| (x * 1e6) as u64;
        RecorderSettings {
            directory: r
                .directory
                .clone()
                .unwrap_or_else(|| PathBuf::from("recordings")),
            prefix: r.prefix.clone(),
            inputs: r.inputs,
            stat_every: r.stat_every,
            max_file_bytes: Some(mb(r.max_file_mb)),
            max_file_duration: Some(Duration::from_secs_f64(r.max_file_seconds)),
            max_total_bytes: r.max_total_mb.map(mb),
            flush_interval: Duration::from_secs_f64(r.flush_seconds),
            file: FileOptions {
                chunk_bytes: r.chunk_kb * 1024,
                zstd: r.compression == "zstd",
            },
            queue: r.queue,
            capture: r.capture.map(|c| Capture {
                before: Duration::from_secs_f64(c.before_seconds),
                after: Duration::from_secs_f64(c.after_seconds),
            }),
        }
    }
}

/// What every file of a recording repeats: the configuration, its channels, the
/// instance that recorded it and glrmon's version.
#[must_use]
pub fn file_header(cfg: &Config, instance: &str) -> FileHeader {
    FileHeader {
        config: cfg.source.clone(),
        channels: cfg.channels.iter().map(|c| c.name.clone()).collect(),
        extra: BTreeMap::from([
            ("instance".to_owned(), instance.to_owned()),
            (
                "glrmon_version".to_owned(),
                env!("CARGO_PKG_VERSION").to_owned(),
            ),
        ]),
    }
}

/// Unfinished recordings (`*.mcap.tmp`) left in `dir` by an earlier crash, sorted by
/// name (`glrmon recover` finishes them).
#[must_use]
pub fn leftovers(dir: &Path) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.path())
                .filter(|p| p.to_string_lossy().ends_with(PARTIAL_SUFFIX))
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    found
}
