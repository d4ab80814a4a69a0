//! One MCAP file being written: schemas and topics registered up front, the
//! configuration in a `glrmon` metadata record, messages in zstd chunks.

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
    /// The channels, in configuration order; their topics are registered up front.
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
    /// Creates `path` (truncating it) and writes the header, the `glrmon` metadata and
    /// every channel's topics, flushed so that even a file killed at once is readable.
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
        for channel in &header.channels {
            for kind in TopicKind::ALL {
                f.topic_id(channel, kind)?;
            }
        }
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
        let metadata = BTreeMap::from([
            ("channel".to_owned(), channel.to_owned()),
            ("kind".to_owned(), kind.as_str().to_owned()),
        ]);
        let id = self
            .writer
            .add_channel(schema, &topic(channel, kind), "json", &metadata)
            .map_err(|e| mcap_err(&self.path, &e))?;
        self.ids.insert((channel.to_owned(), kind), id);
        Ok(id)
    }

    /// Writes one JSON message on `channel`'s topic of `kind`.
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
        let channel_id = match self.ids.get(&(channel.to_owned(), kind)) {
            Some(&id) => id,
            None => self.topic_id(channel, kind)?,
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

/// MCAP publish time for a sample time `t` in seconds: nanoseconds, or `fallback` when
/// `t` is absent, negative or too large.
#[must_use]
pub fn publish_time(t: Option<f64>, fallback: u64) -> u64 {
    match t {
        Some(t) if (0.0..1.8e10).contains(&t) => (t * 1e9) as u64,
        _ => fallback,
    }
}
