//! Records collected in memory (tests, tools that post-process a run).

use std::sync::{Arc, Mutex};

use crate::sink::{Output, Sink, SinkError};

/// A sink that collects records in memory (tests, replay into a buffer).
#[derive(Debug, Clone, Default)]
pub struct MemorySink {
    records: Arc<Mutex<Vec<Output>>>,
}

impl MemorySink {
    /// A shared handle to the collected records.
    #[must_use]
    pub fn records(&self) -> Arc<Mutex<Vec<Output>>> {
        self.records.clone()
    }
}

impl Sink for MemorySink {
    fn name(&self) -> &str {
        "memory"
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        self.records
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(output.clone());
        Ok(())
    }
}
