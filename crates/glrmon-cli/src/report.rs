//! The `--report` sink: every record into a [`glrmon_report::Report`], written as one
//! self-contained HTML file when the replay ends.

use std::path::{Path, PathBuf};

use glrmon_report::{Report, ReportOptions};
use glrmon_runtime::{Interest, Output, Sink, SinkError};

/// Collects the records of a replay and writes the HTML report on flush.
pub(crate) struct ReportSink {
    path: PathBuf,
    report: Option<Report>,
}

impl ReportSink {
    pub(crate) fn new(path: &Path, input: &Path) -> Self {
        Self {
            path: path.to_owned(),
            report: Some(Report::new(ReportOptions {
                title: format!("glrmon replay of {}", input.display()),
                ..ReportOptions::default()
            })),
        }
    }
}

impl Sink for ReportSink {
    fn name(&self) -> &str {
        "report"
    }

    fn interest(&self) -> Interest {
        Interest {
            inputs: false,
            stat_every: Some(1),
        }
    }

    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        if let Some(r) = &mut self.report {
            r.add(&output.record);
        }
        Ok(())
    }

    /// Writes the report (once: the replay flushes its sinks only at the end).
    fn flush(&mut self) -> Result<(), SinkError> {
        let Some(report) = self.report.take() else {
            return Ok(());
        };
        let err = |e: std::io::Error| SinkError {
            sink: "report".into(),
            message: format!("{}: {e}", self.path.display()),
        };
        let file = std::fs::File::create(&self.path).map_err(err)?;
        let mut out = std::io::BufWriter::new(file);
        report.write_html(&mut out).map_err(err)?;
        std::io::Write::flush(&mut out).map_err(err)
    }
}
