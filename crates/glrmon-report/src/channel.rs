//! What the report keeps of one channel: decimated per-sample series and the rare
//! records (alarms, episodes, diagnoses, errors), each kept up to a cap and counted.

use std::collections::BTreeMap;

use glrmon_wire::{Alarm, AlarmEnd, Consistency, Diagnosis, ErrorRecord, IsolationUpdate, Stat};

use crate::decimate::{ColumnId, Grid};
use crate::labels::ChannelLabels;

/// Alarms kept in full (markers, isolation, table), and as many isolation updates;
/// later ones are only counted.
pub(crate) const MAX_ALARMS: usize = 256;
/// Diagnoses kept in full (with their regularisation path).
pub(crate) const MAX_DIAGNOSES: usize = 16;
/// Error records kept verbatim; all are counted by code.
pub(crate) const MAX_ERRORS: usize = 100;
/// Components of ε_k and θ̂ decimated per channel; wider vectors are truncated.
pub(crate) const MAX_COMPONENTS: usize = 32;

/// An alarm episode, from the alarm to its `alarm_end` (open while `end` is `None`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Episode {
    pub(crate) start: u64,
    pub(crate) end: Option<u64>,
}

/// Accumulated content of one channel.
#[derive(Debug, Clone)]
pub(crate) struct ChannelState {
    pub(crate) stats: u64,
    /// Smallest and largest k of any record.
    pub(crate) k_range: Option<(u64, u64)>,
    pub(crate) grid: Grid,
    pub(crate) glr: ColumnId,
    pub(crate) onset: ColumnId,
    pub(crate) time: ColumnId,
    pub(crate) threshold: ColumnId,
    pub(crate) innovation: Vec<ColumnId>,
    pub(crate) magnitude: Vec<ColumnId>,
    /// The kind's own residual (`stat.residual`), first [`MAX_COMPONENTS`] values.
    pub(crate) residual: Vec<ColumnId>,
    /// The episode's θ̂ (`stat.episode.magnitude`), a gap outside episodes.
    pub(crate) episode_magnitude: Vec<ColumnId>,
    /// Largest ε_k / θ̂ length seen, including components beyond [`MAX_COMPONENTS`].
    pub(crate) innovation_len: usize,
    pub(crate) magnitude_len: usize,
    /// The names and units of the signals and faults, when the caller gave them.
    pub(crate) labels: Option<ChannelLabels>,
    pub(crate) alarms: Vec<Alarm>,
    pub(crate) alarms_total: u64,
    /// Isolation updates (`isolation` records), matched to their alarm by `alarm_k`.
    pub(crate) updates: Vec<IsolationUpdate>,
    pub(crate) updates_total: u64,
    pub(crate) episodes: Vec<Episode>,
    pub(crate) alarm_ends: u64,
    pub(crate) diagnoses: Vec<Diagnosis>,
    pub(crate) diagnoses_total: u64,
    pub(crate) errors: Vec<ErrorRecord>,
    pub(crate) error_counts: BTreeMap<&'static str, u64>,
    /// Changes of the filter-consistency verdict (the first ones kept) and their count.
    pub(crate) consistency: Vec<Consistency>,
    pub(crate) consistency_total: u64,
}

impl ChannelState {
    pub(crate) fn new(max_points: usize) -> Self {
        let mut grid = Grid::new(max_points);
        let glr = grid.add_column();
        let onset = grid.add_column();
        let time = grid.add_column();
        let threshold = grid.add_column();
        ChannelState {
            stats: 0,
            k_range: None,
            grid,
            glr,
            onset,
            time,
            threshold,
            innovation: Vec::new(),
            magnitude: Vec::new(),
            residual: Vec::new(),
            episode_magnitude: Vec::new(),
            innovation_len: 0,
            magnitude_len: 0,
            labels: None,
            alarms: Vec::new(),
            alarms_total: 0,
            updates: Vec::new(),
            updates_total: 0,
            episodes: Vec::new(),
            alarm_ends: 0,
            diagnoses: Vec::new(),
            diagnoses_total: 0,
            errors: Vec::new(),
            error_counts: BTreeMap::new(),
            consistency: Vec::new(),
            consistency_total: 0,
        }
    }

    fn see_k(&mut self, k: u64) {
        self.k_range = Some(match self.k_range {
            None => (k, k),
            Some((lo, hi)) => (lo.min(k), hi.max(k)),
        });
    }

    pub(crate) fn add_stat(&mut self, s: &Stat) {
        self.stats = self.stats.saturating_add(1);
        self.see_k(s.k);
        let slot = self.grid.slot(s.k);
        self.grid.push(self.glr, slot, s.k, s.glr);
        self.grid
            .push(self.onset, slot, s.k, s.onset.map(|r| r as f64));
        self.grid.push(self.time, slot, s.k, s.t);
        self.grid.push(self.threshold, slot, s.k, s.threshold);
        self.innovation_len = self.innovation_len.max(s.innovation.len());
        self.magnitude_len = self.magnitude_len.max(s.magnitude.len());
        push_vector(
            &mut self.grid,
            &mut self.innovation,
            slot,
            s.k,
            &s.innovation,
        );
        push_vector(&mut self.grid, &mut self.magnitude, slot, s.k, &s.magnitude);
        push_vector(&mut self.grid, &mut self.residual, slot, s.k, &s.residual);
        let episode = s.episode.as_ref().map_or(&[][..], |e| &e.magnitude[..]);
        if !episode.is_empty() || !self.episode_magnitude.is_empty() {
            push_vector(
                &mut self.grid,
                &mut self.episode_magnitude,
                slot,
                s.k,
                episode,
            );
        }
    }

    /// Whether the channel had an alarm episode (an alarm, or the end of one whose
    /// alarm came before the replay began).
    pub(crate) fn alarmed(&self) -> bool {
        self.alarms_total > 0 || self.alarm_ends > 0
    }

    pub(crate) fn add_alarm(&mut self, a: &Alarm) {
        self.alarms_total = self.alarms_total.saturating_add(1);
        self.see_k(a.k);
        if self.alarms.len() < MAX_ALARMS {
            self.alarms.push(a.clone());
            self.episodes.push(Episode {
                start: a.k,
                end: None,
            });
        }
    }

    pub(crate) fn add_isolation(&mut self, u: &IsolationUpdate) {
        self.updates_total = self.updates_total.saturating_add(1);
        self.see_k(u.k);
        if self.updates.len() < MAX_ALARMS {
            self.updates.push(u.clone());
        }
    }

    /// The isolation update of alarm `a`, if one came (and was kept).
    pub(crate) fn update_of(&self, a: &Alarm) -> Option<&IsolationUpdate> {
        self.updates.iter().find(|u| u.alarm_k == a.k)
    }

    pub(crate) fn add_alarm_end(&mut self, e: &AlarmEnd) {
        self.alarm_ends = self.alarm_ends.saturating_add(1);
        self.see_k(e.k);
        if let Some(open) = self.episodes.iter_mut().rev().find(|ep| ep.end.is_none()) {
            open.end = Some(e.k.max(open.start));
        } else if self.episodes.len() < MAX_ALARMS {
            // An end without its alarm (the replay began mid-episode, or the alarm was
            // past the cap): the duration says where it began.
            self.episodes.push(Episode {
                start: e.k.saturating_sub(e.duration),
                end: Some(e.k),
            });
        }
    }

    pub(crate) fn add_diagnosis(&mut self, d: &Diagnosis) {
        self.diagnoses_total = self.diagnoses_total.saturating_add(1);
        self.see_k(d.k);
        if self.diagnoses.len() < MAX_DIAGNOSES {
            self.diagnoses.push(d.clone());
        }
    }

    pub(crate) fn add_consistency(&mut self, c: &Consistency) {
        self.see_k(c.k);
        self.consistency_total = self.consistency_total.saturating_add(1);
        if self.consistency.len() < MAX_DIAGNOSES {
            self.consistency.push(c.clone());
        }
    }

    pub(crate) fn add_error(&mut self, e: &ErrorRecord) {
        if let Some(k) = e.k {
            self.see_k(k);
        }
        let count = self.error_counts.entry(e.code.as_str()).or_insert(0);
        *count = count.saturating_add(1);
        if self.errors.len() < MAX_ERRORS {
            self.errors.push(e.clone());
        }
    }

    pub(crate) fn errors_total(&self) -> u64 {
        self.error_counts
            .values()
            .fold(0, |a, b| a.saturating_add(*b))
    }

    /// Names of the θ̂ components: the labels' faults, else the fault dictionary of an
    /// alarm or a diagnosis of this channel, when its length matches; `θ̂[i]`
    /// otherwise.
    pub(crate) fn fault_names(&self) -> Vec<String> {
        let n = self.magnitude_len;
        let labelled = self
            .labels
            .as_ref()
            .map(|l| l.faults.iter().map(|f| f.name.clone()).collect::<Vec<_>>());
        let known = labelled.into_iter().find(|f| f.len() == n).or_else(|| {
            self.alarms
                .iter()
                .map(|a| &a.faults)
                .chain(self.updates.iter().map(|u| &u.faults))
                .chain(self.diagnoses.iter().map(|d| &d.faults))
                .find(|f| f.len() == n)
                .cloned()
        });
        known.unwrap_or_else(|| (0..n).map(|i| format!("θ̂[{i}]")).collect())
    }
}

/// Pushes each component of `values` to its column, creating columns up to
/// [`MAX_COMPONENTS`]; columns beyond the vector's length get a gap.
fn push_vector(grid: &mut Grid, cols: &mut Vec<ColumnId>, slot: usize, k: u64, values: &[f64]) {
    while cols.len() < values.len().min(MAX_COMPONENTS) {
        cols.push(grid.add_column());
    }
    for (i, col) in cols.iter().enumerate() {
        grid.push(*col, slot, k, values.get(i).copied());
    }
}
