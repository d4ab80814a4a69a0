//! JSON lines: one record per line, as `glrmon replay` writes them.

use std::io::Write;

use crate::sink::{Interest, Output, Sink, SinkError};

/// Writes each record's JSON and a newline to `W` (`stat` records decimated: one in
/// `stat_every`, 0 for none).
#[derive(Debug)]
pub struct JsonLinesSink<W: Write + Send> {
    out: W,
    stat_every: u64,
}

impl<W: Write + Send> JsonLinesSink<W> {
    /// Lines to `out`, keeping one `stat` record in `stat_every` (0: none).
    pub fn new(out: W, stat_every: u64) -> Self {
        Self { out, stat_every }
    }

    fn error(e: &std::io::Error) -> SinkError {
        SinkError {
            sink: "jsonl".into(),
            message: e.to_string(),
        }
    }
}

impl<W: Write + Send + 'static> Sink for JsonLinesSink<W> {
    fn name(&self) -> &str {
        "jsonl"
    }
    fn interest(&self) -> Interest {
        Interest {
            inputs: false,
            stat_every: Some(self.stat_every),
        }
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        self.out
            .write_all(&output.json)
            .and_then(|()| self.out.write_all(b"\n"))
            .map_err(|e| Self::error(&e))
    }
    fn flush(&mut self) -> Result<(), SinkError> {
        self.out.flush().map_err(|e| Self::error(&e))
    }
}
