//! The report as a sink: every record into a [`Report`], written as one
//! self-contained HTML file when the sink is closed (at the end of a replay).

use std::path::{Path, PathBuf};

use glrmon_runtime::{Interest, Output, Sink, SinkError};

use crate::clock::Zone;
use crate::{Report, ReportOptions};

/// Collects the records it is handed and writes the HTML report on
/// [`Sink::close`].
#[derive(Debug)]
pub struct ReportSink {
    path: PathBuf,
    report: Option<Report>,
}

impl ReportSink {
    /// A report titled after `input` (the replayed file), to be written to `path`, with
    /// wall-clock times in `zone`.
    #[must_use]
    pub fn new(path: &Path, input: &Path, zone: Zone) -> Self {
        Self::with_report(
            path,
            Report::new(ReportOptions {
                title: format!("glrmon replay of {}", input.display()),
                zone,
                ..ReportOptions::default()
            }),
        )
    }

    /// `report` (its options, provenance and channel labels set by the caller), to be
    /// written to `path`.
    #[must_use]
    pub fn with_report(path: &Path, report: Report) -> Self {
        Self {
            path: path.to_owned(),
            report: Some(report),
        }
    }
}

impl Sink for ReportSink {
    fn name(&self) -> &str {
        "report"
    }

    /// Every `stat` record: the report decimates its series itself.
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

    /// Writes the report (once).
    fn close(&mut self) -> Result<(), SinkError> {
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
