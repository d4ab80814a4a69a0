//! A synchronous sink writing one MCAP file: for offline tools (replay), where the
//! caller's thread may block on the disk.

use std::path::{Path, PathBuf};

use glrmon_runtime::{InputOutput, Interest, Output, Sink, SinkError};

use crate::messages::{input_topic, record_messages};
use crate::schema::TopicKind;
use crate::writer::{FileHeader, FileOptions, McapFile, RecordError};

/// Writes every input and every result into one MCAP file, on the caller's thread.
#[derive(Debug)]
pub struct McapFileSink {
    file: Option<McapFile>,
    stat_every: u64,
}

impl McapFileSink {
    /// Creates the file.
    ///
    /// # Errors
    /// [`RecordError`] when it cannot be created.
    pub fn create(path: &Path, header: &FileHeader) -> Result<Self, RecordError> {
        Ok(Self {
            file: Some(McapFile::create(path, FileOptions::default(), header)?),
            stat_every: 1,
        })
    }

    /// The same sink keeping one `stat` record in `stat_every` (0: none; default 1).
    /// Inputs are always written, so the file can be replayed.
    #[must_use]
    pub fn with_stat_every(mut self, stat_every: u64) -> Self {
        self.stat_every = stat_every;
        self
    }

    /// Writes the summary and footer.
    ///
    /// # Errors
    /// [`RecordError`] when writing fails.
    pub fn finish(mut self) -> Result<Option<PathBuf>, RecordError> {
        self.file.take().map(McapFile::finish).transpose()
    }

    fn put(
        &mut self,
        channel: &str,
        kind: TopicKind,
        log_time: u64,
        publish: u64,
        json: &[u8],
    ) -> Result<(), SinkError> {
        let Some(f) = &mut self.file else {
            return Ok(());
        };
        f.write(channel, kind, log_time, publish, json)
            .map_err(|e| SinkError {
                sink: "mcap".into(),
                message: e.to_string(),
            })
    }
}

impl Sink for McapFileSink {
    fn name(&self) -> &str {
        "mcap"
    }

    fn interest(&self) -> Interest {
        Interest {
            inputs: true,
            stat_every: Some(self.stat_every),
        }
    }

    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        let log_time = output.log_time_ns;
        for (kind, json) in record_messages(output).into_iter().flatten() {
            self.put(output.record.channel(), kind, log_time, log_time, &json)?;
        }
        Ok(())
    }

    fn write_input(&mut self, input: &InputOutput) -> Result<(), SinkError> {
        let t = input.log_time_ns;
        self.put(&input.name, input_topic(&input.item), t, t, &input.json)
    }

    fn flush(&mut self) -> Result<(), SinkError> {
        match &mut self.file {
            Some(f) => f.flush().map_err(|e| SinkError {
                sink: "mcap".into(),
                message: e.to_string(),
            }),
            None => Ok(()),
        }
    }

    /// Writes the summary and footer (a file closed here reports its errors; one
    /// dropped unclosed is finished silently).
    fn close(&mut self) -> Result<(), SinkError> {
        self.close_file()
    }
}

impl McapFileSink {
    fn close_file(&mut self) -> Result<(), SinkError> {
        match self.file.take() {
            Some(f) => f.finish().map(|_| ()).map_err(|e| SinkError {
                sink: "mcap".into(),
                message: e.to_string(),
            }),
            None => Ok(()),
        }
    }
}

impl Drop for McapFileSink {
    fn drop(&mut self) {
        let _ = self.close_file();
    }
}
