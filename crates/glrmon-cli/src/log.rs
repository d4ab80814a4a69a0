//! What the binary logs for the libraries' events.

use glrmon_runtime::{RuntimeEvents, SinkError};

/// Logs sink failures (data lost: ERROR).
pub(crate) struct LogEvents;

impl RuntimeEvents for LogEvents {
    fn sink_error(&self, error: &SinkError) {
        tracing::error!(error = %error, "A result could not be delivered.");
    }
}
