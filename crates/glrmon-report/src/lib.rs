#![doc = include_str!("../README.md")]

mod channel;
pub mod clock;
mod decimate;
mod escape;
mod evaluation;
mod histogram;
mod html;
mod labels;
mod sink;
mod svg;

pub use evaluation::{
    ComparedKind, Comparison, DecisionError, Evaluation, FaultEvaluation, MinmaxEvaluation,
};
pub use histogram::Histogram;
pub use labels::{ChannelLabels, FaultLabel, MagnitudeUnit, ResidualBound, SignalLabel};
pub use sink::ReportSink;

use std::collections::BTreeMap;

use glrmon_wire::Record;

use crate::channel::ChannelState;

/// Channels reported on; records of further channels are only counted, so that a flood
/// of `unknown_channel` errors with made-up names cannot grow the report without bound.
pub const MAX_CHANNELS: usize = 64;

/// What the report looks like.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReportOptions {
    /// The page title (`<title>` and heading).
    pub title: String,
    /// Most points drawn per series (l_k, each ε_k component, …) after decimation; at
    /// least 4. About twice the figure width in pixels keeps every spike visible.
    pub width_points: usize,
    /// The zone wall-clock sample times are shown in ([`clock`]).
    pub zone: clock::Zone,
    /// Where the report comes from, shown under its title; none when `None`.
    pub provenance: Option<Provenance>,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            title: "glrmon replay report".to_owned(),
            width_points: 2000,
            zone: clock::Zone::Utc,
            provenance: None,
        }
    }
}

/// Where a report comes from: which glrmon made it, from which configuration and data,
/// and when. A report read weeks later, or passed on, says what it shows. The caller
/// knows all of it (`glrmon replay` passes its own).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Provenance {
    /// The glrmon that made it, e.g. `0.1.0 (git 1a2b3c4)`.
    pub version: String,
    /// The configuration: its path, or where it came from (`recorded in run.mcap`).
    pub config: String,
    /// The data files replayed.
    pub data: Vec<String>,
    /// When the report was made; shown in UTC, ISO 8601.
    pub made: jiff::Timestamp,
}

/// A report under construction: feed it every record of a replay with [`Report::add`],
/// then write it with [`Report::write_html`].
///
/// Memory is bounded independently of the replay's length: per channel, each per-sample
/// series is kept as at most `width_points` points (streaming min/max decimation), and
/// alarms, isolation updates, diagnoses and error records are kept up to fixed caps and
/// counted beyond.
///
/// # Examples
///
/// ```
/// use glrmon_report::{Report, ReportOptions};
/// use glrmon_wire::{AlarmEnd, Record};
///
/// let mut report = Report::new(ReportOptions::default());
/// report.add(&Record::from(AlarmEnd {
///     channel: "pump3".into(), k: 140, t: None, onset: 101, duration: 39, peak_glr: 87.5,
/// }));
/// let mut html = Vec::new();
/// report.write_html(&mut html)?;
/// assert!(String::from_utf8_lossy(&html).contains("pump3"));
/// # Ok::<(), std::io::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Report {
    options: ReportOptions,
    channels: BTreeMap<String, ChannelState>,
    records: u64,
    /// Records of channels beyond [`MAX_CHANNELS`].
    dropped_records: u64,
    /// Records of a type this version does not know (the enum is non-exhaustive).
    unknown_records: u64,
}

impl Report {
    /// An empty report.
    #[must_use]
    pub fn new(options: ReportOptions) -> Self {
        let options = ReportOptions {
            width_points: options.width_points.max(4),
            ..options
        };
        Report {
            options,
            channels: BTreeMap::new(),
            records: 0,
            dropped_records: 0,
            unknown_records: 0,
        }
    }

    /// Names the signals and faults of channel `name` and gives their units
    /// ([`ChannelLabels`]): the figures then show `LI201 [cm]` where they would show
    /// `ε_k[0]` in model units, innovations in raw units, and each fault's θ̂ on an axis
    /// of its unit. Call it before or while adding records; a channel beyond
    /// [`MAX_CHANNELS`] is not reported.
    pub fn label_channel(&mut self, name: &str, labels: ChannelLabels) {
        if let Some(ch) = self.channel_mut(name) {
            ch.labels = Some(labels);
        }
    }

    /// The state of channel `name`, created if there is room for it.
    fn channel_mut(&mut self, name: &str) -> Option<&mut ChannelState> {
        if !self.channels.contains_key(name) {
            if self.channels.len() >= MAX_CHANNELS {
                return None;
            }
            self.channels.insert(
                name.to_owned(),
                ChannelState::new(self.options.width_points),
            );
        }
        self.channels.get_mut(name)
    }

    /// Takes one record into account. Call it once per record, in the order of the
    /// replay; a `stat` costs O(1) amortised time and no lasting memory.
    pub fn add(&mut self, record: &Record) {
        self.records = self.records.saturating_add(1);
        let name = record.channel();
        if self.channel_mut(name).is_none() {
            self.dropped_records = self.dropped_records.saturating_add(1);
            return;
        }
        let Some(ch) = self.channels.get_mut(name) else {
            return;
        };
        match record {
            Record::Stat(s) => ch.add_stat(s),
            Record::Alarm(a) => ch.add_alarm(a),
            Record::Isolation(u) => ch.add_isolation(u),
            Record::AlarmEnd(e) => ch.add_alarm_end(e),
            Record::Diagnosis(d) => ch.add_diagnosis(d),
            Record::Error(e) => ch.add_error(e),
            Record::Consistency(c) => ch.add_consistency(c),
            _ => self.unknown_records = self.unknown_records.saturating_add(1),
        }
    }

    /// Writes the report as one self-contained HTML page: inline CSS and SVG, no
    /// JavaScript, no external resources. Channels with alarms come first, then the
    /// others, each by name.
    ///
    /// # Errors
    ///
    /// Any error of `out`.
    pub fn write_html<W: std::io::Write>(&self, out: W) -> std::io::Result<()> {
        html::write_page(self, out)
    }

    /// The channels in the order the page shows them: those with alarms (or an ended
    /// episode) first, then the others, each group by name.
    pub(crate) fn ordered_channels(&self) -> Vec<(&String, &ChannelState)> {
        let mut channels: Vec<(&String, &ChannelState)> = self.channels.iter().collect();
        channels.sort_by_key(|(name, ch)| (!ch.alarmed(), *name));
        channels
    }
}

#[cfg(test)]
mod tests;
