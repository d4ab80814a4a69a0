//! The per-channel engine: decoded samples in, result records out.
//!
//! For each sample the monitor checks its index (duplicates and samples from the past are
//! rejected; a jump forward is a gap, filled with predict-only steps), runs the channel's
//! [`Detector`], keeps the alarm episode state, and at an alarm runs the isolation tests.
//! It never asks where its records go (STYLE principle 3): callers hand them to sinks.
//!
//! Isolation runs `isolation_delay` samples after the crossing (default n, the number of
//! states): at the crossing itself few samples carry the fault, and faults whose
//! signatures differ only after a few steps cannot be told apart yet (in the §6.1 plant
//! a jump of x0 at 201 and a jump of x1 at 200 give the same first innovation).
#![warn(missing_docs)]

use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{AlarmSettings, AlarmState, AlarmTransition, Detector, StepError, StepOutput};
use glrmon_wire::{
    Alarm, AlarmEnd, ErrorCode, ErrorRecord, IsolationResult, Record, Sample, Stage, Stat,
};

/// An isolation test: a named group of faults tested against all others (minmax,
/// Zhang & Basseville 2014 eq. (41)).
#[derive(Debug, Clone, PartialEq)]
pub struct IsolationGroup {
    /// Name reported in the alarm (the fault's name for a single fault).
    pub name: String,
    /// Indices of the faults in the group (θ_a).
    pub faults: Vec<usize>,
}

/// Settings of a channel's monitor.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorSettings {
    /// Detection threshold and episode hysteresis.
    pub alarm: AlarmSettings,
    /// Samples between the crossing and the isolation tests.
    pub isolation_delay: u32,
    /// Type-I probability of each isolation test; the threshold is the χ²(dim a) upper
    /// quantile.
    pub isolation_alpha: f64,
    /// The isolation tests; empty means one per fault against all others.
    pub groups: Vec<IsolationGroup>,
    /// Largest gap (missing samples) filled with predict-only steps; a larger jump is
    /// rejected as `gap` and the sample dropped.
    pub max_gap: u64,
}

/// Counters of a channel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MonitorCounters {
    /// Samples processed by the detector.
    pub samples: u64,
    /// Samples filled by predict-only steps.
    pub gap_samples: u64,
    /// Alarms raised.
    pub alarms: u64,
    /// Rejections by code.
    pub errors: std::collections::BTreeMap<&'static str, u64>,
}

/// One channel's monitor.
#[derive(Debug)]
pub struct Monitor {
    channel: String,
    detector: Detector,
    alarm: AlarmState,
    settings: MonitorSettings,
    groups: Vec<IsolationGroup>,
    fault_names: Vec<String>,
    out: StepOutput,
    pending: Option<PendingAlarm>,
    reported_onset: u64,
    counters: MonitorCounters,
    arrivals: u64,
}

#[derive(Debug, Clone, Copy)]
struct PendingAlarm {
    isolate_at: u64,
}

impl Monitor {
    /// A monitor of channel `channel` around `detector`.
    #[must_use]
    pub fn new(channel: &str, detector: Detector, settings: MonitorSettings) -> Self {
        let fault_names: Vec<String> = detector
            .faults()
            .faults()
            .iter()
            .map(|f| f.name.clone())
            .collect();
        let groups = if settings.groups.is_empty() {
            fault_names
                .iter()
                .enumerate()
                .map(|(j, n)| IsolationGroup {
                    name: n.clone(),
                    faults: vec![j],
                })
                .collect()
        } else {
            settings.groups.clone()
        };
        let dims = detector.dims();
        let out = StepOutput::new(dims.outputs, detector.fault_count());
        Self {
            channel: channel.to_owned(),
            alarm: AlarmState::new(settings.alarm),
            detector,
            settings,
            groups,
            fault_names,
            out,
            pending: None,
            reported_onset: 0,
            counters: MonitorCounters::default(),
            arrivals: 0,
        }
    }

    /// The monitor of a validated channel of the configuration.
    ///
    /// # Errors
    /// As [`glrmon_spec::Channel::detector`] (not expected after validation).
    pub fn from_channel(channel: &glrmon_spec::Channel) -> Result<Self, glrmon_core::ModelError> {
        let settings = MonitorSettings {
            alarm: channel.alarm,
            isolation_delay: channel.isolation_delay,
            isolation_alpha: channel.isolation_alpha,
            groups: channel
                .groups
                .iter()
                .map(|(name, faults)| IsolationGroup {
                    name: name.clone(),
                    faults: faults.clone(),
                })
                .collect(),
            max_gap: channel.max_gap,
        };
        Ok(Self::new(&channel.name, channel.detector()?, settings))
    }

    /// The channel's name.
    #[must_use]
    pub fn channel(&self) -> &str {
        &self.channel
    }

    /// The counters.
    #[must_use]
    pub fn counters(&self) -> &MonitorCounters {
        &self.counters
    }

    /// The detector.
    #[must_use]
    pub fn detector(&self) -> &Detector {
        &self.detector
    }

    /// Whether an alarm episode is going on.
    #[must_use]
    pub fn alarm_active(&self) -> bool {
        self.alarm.is_active()
    }

    /// Records that `n` samples were lost before reaching the monitor (dropped at
    /// intake): the next sample without an explicit `k` is then seen after a gap and
    /// the filter takes predict-only steps for the missing ones.
    pub fn note_missing(&mut self, n: u64) {
        self.arrivals += n;
    }

    /// Processes one decoded sample and appends the resulting records: a `stat` per
    /// processed sample, `alarm` / `alarm_end` at episode edges, `error` for a rejected
    /// sample (the channel's state is then unchanged) and for each filled gap.
    pub fn on_sample(&mut self, sample: &Sample, records: &mut Vec<Record>) {
        let k = sample.k.unwrap_or(self.arrivals);
        self.arrivals = self.arrivals.max(k + 1);
        if let Some(next) = self.detector.next_index() {
            if k < next {
                let (code, why) = if k + 1 == next {
                    (ErrorCode::Duplicate, "repeats the last sample's index")
                } else {
                    (
                        ErrorCode::OutOfOrder,
                        "is older than the last processed sample",
                    )
                };
                self.reject(
                    records,
                    Some(k),
                    code,
                    format!("sample k = {k} {why} (expected {next})"),
                );
                return;
            }
            if k > next {
                let missing = k - next;
                if missing > self.settings.max_gap {
                    self.reject(
                        records,
                        Some(k),
                        ErrorCode::Gap,
                        format!(
                            "{missing} samples missing before k = {k}, more than max_gap = {}; sample dropped",
                            self.settings.max_gap
                        ),
                    );
                    return;
                }
                for gap_k in next..k {
                    if let Err(e) = self.detector.predict_only(gap_k) {
                        self.reject(records, Some(gap_k), ErrorCode::Numerical, e.to_string());
                        return;
                    }
                    self.counters.gap_samples += 1;
                }
                self.reject(
                    records,
                    Some(k),
                    ErrorCode::Gap,
                    format!(
                        "samples {next}..{} missing: filled by predict-only steps",
                        k - 1
                    ),
                );
            }
        }
        let core_sample = glrmon_core::Sample {
            k,
            u: &sample.u,
            y: &sample.y,
            p: &sample.p,
        };
        if let Err(e) = self.detector.step(&core_sample, &mut self.out) {
            let code = match e {
                StepError::WrongDimension { .. } => ErrorCode::WrongDimension,
                StepError::NonFinite { .. } => ErrorCode::NonFinite,
                StepError::OutOfOrder { .. } => ErrorCode::OutOfOrder,
                _ => ErrorCode::Numerical,
            };
            self.reject(records, Some(k), code, e.to_string());
            return;
        }
        self.counters.samples += 1;
        records.push(Record::Stat(Stat {
            channel: self.channel.clone(),
            k,
            t: sample.t,
            glr: self.out.glr,
            onset: self.out.onset,
            magnitude: if self.out.glr.is_some() {
                self.out.magnitude.iter().copied().collect()
            } else {
                Vec::new()
            },
            rank: self.out.rank,
            innovation: self.out.innovation.iter().copied().collect(),
            threshold: Some(self.settings.alarm.threshold),
        }));
        match self.alarm.update(k, self.out.glr) {
            AlarmTransition::Started => {
                self.pending = Some(PendingAlarm {
                    isolate_at: k + u64::from(self.settings.isolation_delay),
                });
            }
            AlarmTransition::Ended { started, peak } => {
                if self.pending.is_some() {
                    // The episode ended before the isolation delay ran out.
                    self.emit_alarm(k, sample.t, records);
                }
                records.push(Record::AlarmEnd(AlarmEnd {
                    channel: self.channel.clone(),
                    k,
                    t: sample.t,
                    onset: self.reported_onset,
                    duration: k - started,
                    peak_glr: peak,
                }));
            }
            AlarmTransition::Active | AlarmTransition::Quiet => {}
        }
        if self.pending.is_some_and(|p| k >= p.isolate_at) {
            self.emit_alarm(k, sample.t, records);
        }
    }

    fn emit_alarm(&mut self, k: u64, t: Option<f64>, records: &mut Vec<Record>) {
        self.pending = None;
        let (Some(glr), Some(onset)) = (self.out.glr, self.out.onset) else {
            return;
        };
        self.counters.alarms += 1;
        self.reported_onset = onset;
        let isolation = self.isolate(onset);
        records.push(Record::Alarm(Alarm {
            channel: self.channel.clone(),
            k,
            t,
            glr,
            threshold: self.settings.alarm.threshold,
            onset,
            magnitude: self.out.magnitude.iter().copied().collect(),
            isolation,
            faults: self.fault_names.clone(),
        }));
    }

    /// Minmax and sensitivity tests of every group at onset r̂ (eq. (41), Basseville
    /// 1996 §3.2), from C_k(r̂), d_k(r̂): O(m³) per test, independent of the window.
    fn isolate(&self, onset: u64) -> Vec<IsolationResult> {
        let Some(fisher) = self.detector.fisher_statistics(onset) else {
            return Vec::new();
        };
        self.groups
            .iter()
            .filter_map(|g| {
                let minmax = fisher.minmax(&g.faults).ok()?;
                let sensitivity = fisher.sensitivity(&g.faults).ok()?;
                let dof = minmax.dof.max(1) as f64;
                let threshold = chi2_upper_quantile(dof, self.settings.isolation_alpha).ok()?;
                Some(IsolationResult {
                    fault: g.name.clone(),
                    minmax: minmax.value,
                    sensitivity: sensitivity.value,
                    threshold,
                    isolated: minmax.value > threshold,
                })
            })
            .collect()
    }

    fn reject(&mut self, records: &mut Vec<Record>, k: Option<u64>, code: ErrorCode, why: String) {
        *self.counters.errors.entry(code.as_str()).or_insert(0) += 1;
        records.push(Record::Error(ErrorRecord {
            channel: self.channel.clone(),
            k,
            code,
            message: format!("channel \"{}\": {why}", self.channel),
            stage: Stage::Processing,
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_sim::scenarios;

    fn monitor() -> Monitor {
        let sc = scenarios::paper2014_unstable();
        let threshold = chi2_upper_quantile(2.0, 1e-4 / 99.0).unwrap();
        Monitor::new(
            "unstable",
            sc.detector().unwrap(),
            MonitorSettings {
                alarm: AlarmSettings::with_threshold(threshold),
                isolation_delay: 2,
                isolation_alpha: 0.01,
                groups: vec![],
                max_gap: 10,
            },
        )
    }

    fn sample(x: &glrmon_sim::SimSample) -> Sample {
        Sample {
            k: Some(x.k),
            t: None,
            u: x.u.clone(),
            y: x.y.clone(),
            p: x.p.clone(),
        }
    }

    #[test]
    fn one_alarm_per_episode_isolating_the_injected_state() {
        let sc = scenarios::paper2014_unstable();
        let mut sim = sc.faulty_simulator(1, "x0_jump", 201, 4.0).unwrap();
        let mut mon = monitor();
        let mut records = Vec::new();
        for _ in 0..450 {
            mon.on_sample(&sample(&sim.next_sample()), &mut records);
        }
        let alarms: Vec<&Alarm> = records
            .iter()
            .filter_map(|r| {
                if let Record::Alarm(a) = r {
                    Some(a)
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(alarms.len(), 1);
        let a = alarms[0];
        assert_eq!((a.k, a.onset), (203, 201));
        let isolated: Vec<&str> = a
            .isolation
            .iter()
            .filter(|i| i.isolated)
            .map(|i| i.fault.as_str())
            .collect();
        assert_eq!(isolated, ["x0_jump"]);
        let ends = records
            .iter()
            .filter(|r| matches!(r, Record::AlarmEnd(_)))
            .count();
        assert_eq!(ends, 1);
    }

    #[test]
    fn bad_samples_are_rejected_and_leave_the_channel_untouched() {
        let sc = scenarios::paper2014_unstable();
        let mut sim = sc.simulator(3).unwrap();
        let (mut clean, mut dirty) = (monitor(), monitor());
        let (mut rc, mut rd) = (Vec::new(), Vec::new());
        for i in 0..60u64 {
            let x = sim.next_sample();
            let s = sample(&x);
            clean.on_sample(&s, &mut rc);
            if i == 20 {
                let mut bad = s.clone();
                bad.y = vec![1.0, 2.0];
                dirty.on_sample(&bad, &mut rd);
                let mut nan = s.clone();
                nan.u = vec![f64::NAN];
                dirty.on_sample(&nan, &mut rd);
            }
            dirty.on_sample(&s, &mut rd);
            if i == 30 {
                dirty.on_sample(&s, &mut rd); // duplicate
            }
        }
        let stats = |r: &[Record]| -> Vec<Stat> {
            r.iter()
                .filter_map(|r| {
                    if let Record::Stat(s) = r {
                        Some(s.clone())
                    } else {
                        None
                    }
                })
                .collect()
        };
        assert_eq!(stats(&rc), stats(&rd));
        let codes: Vec<&str> = rd
            .iter()
            .filter_map(|r| {
                if let Record::Error(e) = r {
                    Some(e.code.as_str())
                } else {
                    None
                }
            })
            .collect();
        assert_eq!(codes, ["wrong_dimension", "non_finite", "duplicate"]);
        assert!(rd.iter().any(|r| matches!(r, Record::Error(e) if e.message.contains("field y has 2 values, model expects 1"))));
    }

    #[test]
    fn gaps_are_filled_by_predict_only_steps() {
        let sc = scenarios::paper2014_unstable();
        let mut sim = sc.simulator(3).unwrap();
        let mut mon = monitor();
        let mut records = Vec::new();
        for i in 0..100u64 {
            let x = sim.next_sample();
            if (40..43).contains(&i) {
                continue;
            }
            mon.on_sample(&sample(&x), &mut records);
        }
        assert_eq!(mon.counters().gap_samples, 3);
        assert_eq!(mon.counters().samples, 97);
        assert!(
            records
                .iter()
                .any(|r| matches!(r, Record::Error(e) if e.code == ErrorCode::Gap))
        );
        assert_eq!(mon.counters().alarms, 0);
    }
}
