//! glrmon's black box: every input and every result in MCAP files that Foxglove and the
//! `mcap` CLI open as they are, and that `glrmon replay` re-runs to the same numbers.
//!
//! ```text
//!  runtime output stage ──▶ Recorder (Sink) ──bounded queue──▶ file thread ──▶ McapFile
//!                                                              (rotation, cap, capture)
//!  McapReader (streaming, damage-tolerant) ──▶ replay / recover / diagnose
//! ```
//!
//! - [`McapFile`]: one file; the configuration in a `glrmon` metadata record up front,
//!   each topic declared with its first message, messages in zstd chunks closed at
//!   least every [`RecorderSettings::flush_interval`]; alarms and errors also as
//!   `foxglove.Log` messages on [`LOG_TOPIC`] ([`log_message`]).
//! - [`summarize`]: what a recording holds (`glrmon info`).
//! - [`Recorder`]: the [`glrmon_runtime::Sink`] the daemon and the demo use.
//! - [`McapReader`]: reads what a crash or a bad disk leaves; [`recover`] rewrites such
//!   a file as a finished one.
#![warn(missing_docs)]

mod config;
mod file_sink;
mod log;
mod messages;
mod reader;
mod recorder;
mod schema;
mod summary;
mod writer;

use std::collections::BTreeMap;
use std::path::Path;

pub use config::{file_header, leftovers};
pub use file_sink::McapFileSink;
pub use log::{LOG_ERROR, LOG_WARNING, log_message};
pub use reader::{Damage, Event, Lost, McapReader, Message, ReadEnd, ReadError, Salvage, Topic};
pub use recorder::{
    Capture, PARTIAL_SUFFIX, Recorder, RecorderSettings, RecorderStats, finished_name,
};
pub use schema::{LOG_TOPIC, TopicKind, topic};
pub use summary::{RecordingSummary, SummaryError, TopicSummary, iso8601_utc, summarize};
pub use writer::{
    FileHeader, FileOptions, METADATA_CONFIG, METADATA_NAME, McapFile, RecordError, sample_time_ns,
};

/// What [`recover`] found and wrote.
#[derive(Debug, Clone)]
pub struct Recovery {
    /// Messages copied.
    pub messages: u64,
    /// Chunks read whole.
    pub chunks: u64,
    /// Damaged parts skipped.
    pub damage: Vec<Damage>,
    /// How the input ended.
    pub end: ReadEnd,
    /// The salvage totals: damaged regions, bytes skipped, messages read and known.
    pub salvage: Salvage,
}

impl Recovery {
    /// Whether data was lost to damage ([`Salvage::lost_data`], or a read that ended
    /// [`ReadEnd::Unreadable`]); an unfinished file alone is not.
    #[must_use]
    pub fn lost_data(&self) -> bool {
        self.salvage.lost_data() || matches!(self.end, ReadEnd::Unreadable { .. })
    }
}

/// Errors of [`recover`].
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// The input could not be opened or is not MCAP.
    #[error("{path}: {source}")]
    Read {
        /// The input.
        path: String,
        /// Why.
        source: ReadError,
    },
    /// Writing the output failed.
    #[error(transparent)]
    Write(#[from] RecordError),
}

/// Reads every readable message of `input` (a file cut short or with damaged chunks)
/// and writes them, with the `glrmon` metadata, as a finished MCAP file `output`.
/// Damaged records are skipped by resynchronising on the next valid chunk (see
/// [`McapReader`]); [`Recovery::salvage`] and [`Recovery::damage`] say what was lost.
///
/// # Errors
/// [`RecoverError`] when the input is not MCAP or the output cannot be written.
pub fn recover(input: &Path, output: &Path) -> Result<Recovery, RecoverError> {
    let read_err = |source| RecoverError::Read {
        path: input.display().to_string(),
        source,
    };
    let file = std::fs::File::open(input).map_err(|e| read_err(ReadError::Io(e)))?;
    let mut reader =
        McapReader::new(std::io::BufReader::with_capacity(1 << 16, file)).map_err(read_err)?;
    let mut out: Option<McapFile> = None;
    let mut header = FileHeader::default();
    let ensure = |out: &mut Option<McapFile>, header: &FileHeader| -> Result<(), RecordError> {
        if out.is_none() {
            *out = Some(McapFile::create(output, FileOptions::default(), header)?);
        }
        Ok(())
    };
    while let Some(event) = reader
        .next_event()
        .map_err(|e| read_err(ReadError::Io(e)))?
    {
        match event {
            Event::Metadata { name, entries } if name == METADATA_NAME && out.is_none() => {
                header = header_from_metadata(&entries);
            }
            Event::Metadata { .. } => {}
            Event::Message(m) => {
                ensure(&mut out, &header)?;
                // The log topic has no channel of its own.
                let channel = m
                    .topic
                    .channel
                    .as_deref()
                    .or((m.topic.kind == Some(TopicKind::Log)).then_some(""));
                if let (Some(f), Some(channel), Some(kind)) = (&mut out, channel, m.topic.kind) {
                    f.write(channel, kind, m.log_time, m.publish_time, &m.data)?;
                }
            }
        }
    }
    ensure(&mut out, &header)?;
    let messages = out.as_ref().map_or(0, McapFile::messages);
    if let Some(f) = out {
        f.finish()?;
    }
    Ok(Recovery {
        messages,
        chunks: reader.chunks(),
        damage: reader.damage().to_vec(),
        end: reader.end().clone(),
        salvage: reader.salvage(),
    })
}

/// The [`FileHeader`] recorded in a `glrmon` metadata record.
#[must_use]
pub fn header_from_metadata(entries: &BTreeMap<String, String>) -> FileHeader {
    let mut extra = entries.clone();
    let config = extra.remove(METADATA_CONFIG).unwrap_or_default();
    let channels = extra
        .remove("channels")
        .map(|c| {
            c.split(',')
                .filter(|s| !s.is_empty())
                .map(str::to_owned)
                .collect()
        })
        .unwrap_or_default();
    FileHeader {
        config,
        channels,
        extra,
    }
}
