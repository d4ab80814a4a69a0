//! One MCAP file being written: the configuration in a `glrmon` metadata record up
//! front, each topic (and its schema) declared with its first message, messages in zstd
//! chunks.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::schema::{TopicKind, topic};

/// Errors of recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A file operation failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("{path}: MCAP: {message}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The failure.
        message: String,
    },
}

/// How files are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileOptions {
    /// Uncompressed chunk size in bytes at which a chunk is closed.
    pub chunk_bytes: u64,
    /// Compress chunks with zstd.
    pub zstd: bool,
}

impl Default for FileOptions {
    fn default() -> Self {
        Self {
            chunk_bytes: 1 << 20,
            zstd: true,
        }
    }
}

/// What makes a recording self-describing; repeated in every file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FileHeader {
    /// The configuration in force (TOML text): `glrmon replay FILE.mcap` needs no
    /// `--config`.
    pub config: String,
    /// The channels, in configuration order (a topic is declared only when its first
    /// message is written).
    pub channels: Vec<String>,
    /// Free-form entries (instance, version, start time…).
    pub extra: BTreeMap<String, String>,
}

/// Name of the metadata record holding [`FileHeader`].
pub const METADATA_NAME: &str = "glrmon";
/// Its entry holding the configuration text.
pub const METADATA_CONFIG: &str = "config";

/// An MCAP file being written.
pub struct McapFile {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    ids: HashMap<(String, TopicKind), u16>,
    schema_ids: HashMap<TopicKind, u16>,
    sequence: u32,
    messages: u64,
}

impl std::fmt::Debug for McapFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

impl McapFile {
    /// Creates `path` (truncating it) and writes the header and the `glrmon` metadata,
    /// flushed so that even a file killed at once is readable. Topics are declared
    /// lazily: a topic and its schema are written with the first message on it, so a
    /// file has no topic without messages.
    ///
    /// # Errors
    /// [`RecordError`] when the file cannot be created or written.
    pub fn create(
        path: &Path,
        options: FileOptions,
        header: &FileHeader,
    ) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_owned(),
            source,
        })?;
        let opts = mcap::WriteOptions::new()
            .compression(options.zstd.then_some(mcap::Compression::Zstd))
            .chunk_size(Some(options.chunk_bytes))
            .compression_threads(0)
            .library(format!("glrmon {}", env!("CARGO_PKG_VERSION")));
        let writer = opts
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|e| mcap_err(path, &e))?;
        let mut f = Self {
            writer,
            path: path.to_owned(),
            ids: HashMap::new(),
            schema_ids: HashMap::new(),
            sequence: 0,
            messages: 0,
        };
        let mut entries = header.extra.clone();
        entries.insert(METADATA_CONFIG.into(), header.config.clone());
        entries.insert("channels".into(), header.channels.join(","));
        f.writer
            .write_metadata(&mcap::records::Metadata {
                name: METADATA_NAME.into(),
                metadata: entries,
            })
            .map_err(|e| mcap_err(path, &e))?;
        f.flush()?;
        Ok(f)
    }

    /// The file's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written.
    #[must_use]
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Declares `channel`'s topic of `kind` (and its schema) before its first message,
    /// in the current chunk ([`McapFile::write`] declares a topic it has not seen in a
    /// chunk of its own); nothing if it is declared already.
    ///
    /// # Errors
    /// [`RecordError`] when writing fails.
    pub fn declare(&mut self, channel: &str, kind: TopicKind) -> Result<(), RecordError> {
        let channel = if kind == TopicKind::Log { "" } else { channel };
        self.topic_id(channel, kind).map(|_| ())
    }

    fn topic_id(&mut self, channel: &str, kind: TopicKind) -> Result<u16, RecordError> {
        if let Some(&id) = self.ids.get(&(channel.to_owned(), kind)) {
            return Ok(id);
        }
        let schema = match self.schema_ids.get(&kind) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_schema(kind.schema_name(), "jsonschema", kind.schema().as_bytes())
                    .map_err(|e| mcap_err(&self.path, &e))?;
                self.schema_ids.insert(kind, id);
                id
            }
        };
        let mut metadata = BTreeMap::from([("kind".to_owned(), kind.as_str().to_owned())]);
        // The log topic is every channel's: its messages name the channel.
        if kind != TopicKind::Log {
            metadata.insert("channel".to_owned(), channel.to_owned());
        }
        let id = self
            .writer
            .add_channel(schema, &topic(channel, kind), "json", &metadata)
            .map_err(|e| mcap_err(&self.path, &e))?;
        self.ids.insert((channel.to_owned(), kind), id);
        Ok(id)
    }

    /// Writes one JSON message on `channel`'s topic of `kind` (declaring the topic if
    /// it is its first message; `channel` is ignored for [`TopicKind::Log`], whose
    /// topic is every channel's). glrmon writes `publish_time` = `log_time` on every
    /// topic (docs/WIRE.md, "Timestamps in recordings").
    ///
    /// # Errors
    /// [`RecordError`] when writing fails.
    pub fn write(
        &mut self,
        channel: &str,
        kind: TopicKind,
        log_time: u64,
        publish_time: u64,
        json: &[u8],
    ) -> Result<(), RecordError> {
        let channel = if kind == TopicKind::Log { "" } else { channel };
        let channel_id = match self.ids.get(&(channel.to_owned(), kind)) {
            Some(&id) => id,
            None => {
                // The declaration in a chunk of its own, on disk at once: a crash or a
                // damaged data chunk later leaves the topic readable, as when every
                // topic was declared up front.
                self.flush()?;
                let id = self.topic_id(channel, kind)?;
                self.flush()?;
                id
            }
        };
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time,
                    publish_time,
                },
                json,
            )
            .map_err(|e| mcap_err(&self.path, &e))?;
        self.sequence = self.sequence.wrapping_add(1);
        self.messages += 1;
        Ok(())
    }

    /// Closes the current chunk and flushes it to the OS: everything written so far
    /// survives a crash of the process.
    ///
    /// # Errors
    /// [`RecordError`] when writing fails.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| mcap_err(&self.path, &e))
    }

    /// Writes the summary, index and footer.
    ///
    /// # Errors
    /// [`RecordError`] when writing fails.
    pub fn finish(mut self) -> Result<PathBuf, RecordError> {
        self.writer.finish().map_err(|e| mcap_err(&self.path, &e))?;
        let path = self.path.clone();
        let inner = self.writer.into_inner();
        inner
            .into_inner()
            .map_err(|e| RecordError::Io {
                path: path.clone(),
                source: e.into_error(),
            })?
            .sync_all()
            .map_err(|source| RecordError::Io {
                path: path.clone(),
                source,
            })?;
        Ok(path)
    }
}

fn mcap_err(path: &Path, e: &mcap::McapError) -> RecordError {
    RecordError::Mcap {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// A sample time `t` in seconds as nanoseconds, or `fallback` when `t` is absent,
/// negative or too large: the log time the offline tools give samples that have no
/// receive time (a CSV file, `glrmon simulate`), so that their output is the same on
/// every run.
#[must_use]
pub fn sample_time_ns(t: Option<f64>, fallback: u64) -> u64 {
    match t {
        Some(t) if (0.0..1.8e10).contains(&t) => (t * 1e9) as u64,
        _ => fallback,
    }
}
