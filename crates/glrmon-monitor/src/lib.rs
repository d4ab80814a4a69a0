//! The per-channel engine: decoded samples in, result records out.
//!
//! For each sample the monitor checks its index (duplicates and samples from the past are
//! rejected; a jump forward is a gap, filled with predict-only steps), runs the channel's
//! [`Detector`], keeps the alarm episode state, and at an alarm runs the isolation tests.
//! It never asks where its records go (data flows one way, docs/ARCHITECTURE.md):
//! callers hand them to sinks.
//!
//! # Alarm at the crossing, isolation refined later
//!
//! The `alarm` record is emitted at the crossing: the first sample k of an episode with
//! l_k > λ, carrying that sample's onset r̂, magnitude θ̂ and the isolation tests run
//! at r̂ then. Detection latency is thus the crossing itself, however large the state
//! dimension n. The isolation tests are run again `isolation_delay` samples later
//! (default n) and published as an `isolation` record naming the alarm (`alarm_k`):
//! at the crossing few samples carry the fault, and faults whose signatures differ
//! only after a few steps cannot be told apart yet (in the §6.1 plant a jump of x0 at
//! 201 and a jump of x1 at 200 give the same first innovation). The alarm announces
//! that sample in `update_k`.
//!
//! The update comes only while the episode is still on at that sample. An episode
//! that ends earlier (l_k below λ·(1 − h), a restart after a gap) gets no update: its
//! alarm at the crossing, where l_k > λ, stays the episode's only isolation, and its
//! `alarm_end` tells a consumer waiting for `update_k` that none will come. Tests run
//! on a statistic that has fallen back towards noise would describe the noise, not the
//! fault, and reporting them would read as an alarm below the threshold.
//!
//! # The episode's estimate
//!
//! From the alarm on, the monitor asks the detector to follow the alarm's onset r̂ past
//! the window ([`Detector::follow`]; the isolation update's r̂ from that sample on),
//! whatever ends the episode. While the episode lasts, each `stat` record carries in
//! `episode` that onset and θ̂ = C_k(r̂)⁺d_k(r̂) over every sample from r̂ on
//! ([`Detector::followed_magnitude`]): the window's own θ̂ (`magnitude`) fits a fault
//! older than the window with the transient of one starting inside it and shrinks while
//! the fault persists, so a dashboard that plots it reads a constant fault as a fading
//! one. At the crossing itself the follow has not begun, and `episode` is the alarm's
//! onset and magnitude. A detector that follows no onset (`chi2`) gives none. Nothing
//! is allocated for it but the record's own vector.
//!
//! # Sparse diagnosis
//!
//! When the channel's `[channels.diagnosis]` table enables it, a [`DiagnosisEngine`]
//! runs the residual filter of Zhang 2021 (Kalman, §III-A, or Kitanidis, §III-B)
//! alongside the detector and keeps a ring of the last `history` samples' filter
//! quantities. Every `alarm` and every `isolation` record is followed, in the same
//! `records` vector, by a `diagnosis` record with the same `k`: the Lasso regression
//! (Zhang 2021, eqs. (36), (39)) rebuilt from that record's onset r̂ (clamped to the
//! ring and to `span`) to its sample, its support, least-squares refit, λ and plateau
//! (see [`diagnosis`]). The diagnosis at the crossing spans the few samples since r̂
//! and is the plant's first answer; the one with the isolation update spans
//! `isolation_delay` more samples and supersedes it, as the update supersedes the
//! alarm's isolation. An episode shorter than the delay keeps its crossing diagnosis.
//!
//! The diagnosis is computed synchronously, when its record is emitted. This keeps the
//! output deterministic (replay reproduces live results and record order exactly) and
//! still keeps it off every other channel's path: the runtime gives each worker thread
//! its own shard of monitors, so a diagnosis delays only the samples of the channels in
//! the same shard, at most twice per alarm, by the cost of one Lasso path — under 5 ms for
//! m = 50 faults and N = 100 samples (2.3-4.4 ms measured on Example 1 data,
//! crates/glrmon-core/benches/diagnose.rs), O(m²) per λ and coordinate sweep, and
//! independent of N beyond the O(N·p·m²) Gram accumulation. A worker thread per
//! diagnosis was not used: its result would arrive at a sample that depends on thread
//! timing, and replay would no longer reproduce live output. The per-sample cost is
//! one residual-filter step (without fault columns) and a copy of Ψ̃_k, Φ̃_k into the
//! ring, without allocation.
#![warn(missing_docs)]

pub mod diagnosis;

pub use diagnosis::{DiagnosisEngine, DiagnosisError, SpanDiagnosis};

use glrmon_core::filter::consistency::Consistency;
use glrmon_core::isolation::{FisherStatistics, ambiguity};
use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{
    AlarmSettings, AlarmState, AlarmTransition, Detector, EpisodeEnd, ResidualIsolation,
    SignalScaling, StepError, StepOutput,
};
use glrmon_wire::{
    Alarm, AlarmEnd, EpisodeEstimate, ErrorCode, ErrorRecord, IsolationResult, IsolationUpdate,
    Record, Sample, Stage, Stat,
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
    /// What a configuration reload may change: thresholds, alarm and isolation
    /// settings.
    pub tuning: Tuning,
    /// The isolation tests; empty means one per fault against all others.
    pub groups: Vec<IsolationGroup>,
    /// Largest gap (missing samples) filled with predict-only steps; after a longer one
    /// the filter restarts from its initial state at the sample that follows it
    /// (reported as `gap`), so that an outage never leaves a channel dead.
    pub max_gap: u64,
    /// A sample repeating the last processed index, or up to this many indices before
    /// it, is refused alone (`duplicate`, `out_of_order`); one further back means the
    /// publisher started numbering again (it restarted): the filter restarts at that
    /// sample (reported as `sequence_reset`) instead of refusing every later sample.
    pub max_reorder: u64,
    /// Samples of settling after each restart (`None`: [`Detector::memory`]): the
    /// estimate converges from (x̂₀, P₀) with alarms held off (the `stat` records carry
    /// no l_k), then the detector forgets the evidence gathered meanwhile
    /// ([`Detector::forget_evidence`]). A restart follows a long outage, a publisher
    /// numbering anew or a numerical failure, when the plant's state is far from x̂₀:
    /// the filter's transient would otherwise look like a fault at the restart.
    pub settle: Option<u64>,
}

/// The settings a configuration reload changes in a running monitor (the part of
/// [`MonitorSettings`] that does not shape the filter; the configuration's keys are
/// `glrmon_spec::RELOADABLE_GLR_KEYS`).
#[derive(Debug, Clone, PartialEq)]
pub struct Tuning {
    /// Detection threshold and episode hysteresis.
    pub alarm: AlarmSettings,
    /// How an episode ends: when the fault followed from the alarm's onset is gone
    /// from the data, or when l_k falls below the threshold ([`EpisodeEnd`]).
    pub episode_end: EpisodeEnd,
    /// Samples between the alarm (the crossing) and its `isolation` update; 0: the
    /// alarm's isolation is final.
    pub isolation_delay: u32,
    /// Type-I probability of each isolation test; the threshold is the χ²(dim a) upper
    /// quantile at `isolation_alpha`/`isolation_onsets`.
    pub isolation_alpha: f64,
    /// The onsets the isolation level is divided among (Bonferroni): the tests run at
    /// the onset r̂ the data chose among w − s, where the χ² quantile at α is exceeded
    /// far more often than α under no fault of the tested group; 1 for the nominal law.
    pub isolation_onsets: u64,
    /// Calibrated isolation thresholds by test (group or fault) name, replacing the χ²
    /// quantile for those tests (found by `glrmon calibrate`).
    pub isolation_thresholds: Vec<(String, f64)>,
}

impl Tuning {
    /// The tuning of a validated channel of the configuration.
    #[must_use]
    pub fn from_channel(channel: &glrmon_spec::Channel) -> Self {
        Self {
            alarm: channel.alarm,
            episode_end: channel.episode_end,
            isolation_delay: channel.isolation_delay,
            isolation_alpha: channel.isolation_alpha,
            isolation_onsets: channel.isolation_onsets,
            isolation_thresholds: channel.isolation_thresholds.clone(),
        }
    }
}

/// Counters of a channel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MonitorCounters {
    /// Samples processed by the detector.
    pub samples: u64,
    /// Samples filled by predict-only steps.
    pub gap_samples: u64,
    /// Alarms raised (one per episode, at its crossing).
    pub alarms: u64,
    /// `isolation` records: alarms whose episode lasted `isolation_delay` samples.
    pub isolation_updates: u64,
    /// Sparse diagnoses emitted (with alarms and with isolation updates).
    pub diagnoses: u64,
    /// Restarts of the filter from its initial state (after a gap longer than
    /// `max_gap`, or a numerical failure).
    pub restarts: u64,
}

/// One channel's monitor.
#[derive(Debug)]
pub struct Monitor {
    channel: String,
    detector: Box<dyn Detector>,
    alarm: AlarmState,
    settings: MonitorSettings,
    groups: Vec<IsolationGroup>,
    fault_names: Vec<String>,
    out: StepOutput,
    /// The isolation update the current episode's alarm announced.
    pending: Option<PendingUpdate>,
    /// The crossing k of the episode going on, whose alarm updates name.
    episode_alarm: Option<u64>,
    /// [`Detector::isolation_revision`] when last published.
    isolation_revision: u64,
    reported_onset: u64,
    /// The onset the detector follows for the episode going on (the last reported r̂
    /// it could follow), whose estimate the `stat` records carry.
    episode_onset: Option<u64>,
    counters: MonitorCounters,
    arrivals: u64,
    /// The time of the last processed sample, for an episode cut by a sequence reset.
    last_t: Option<f64>,
    diagnosis: Option<DiagnosisEngine>,
    /// The residual filter must restart from the detector's prediction before the next
    /// sample (after a gap or a filter failure).
    diagnosis_restart: bool,
    /// The residual filter is failing (reported once per run of failures, not at every
    /// sample).
    diagnosis_failing: bool,
    /// The filter-consistency test, when enabled.
    consistency: Option<Consistency>,
    /// Whether a `stat` record is appended for each processed sample.
    stat_records: bool,
    /// After a restart: the first sample at which alarms may be raised again, and
    /// whether the detector is still to forget the settling's evidence then.
    settling: Option<Settling>,
    /// Raw plant units → model units, when the channel has `[channels.scaling]`.
    intake: Option<Intake>,
    /// [`Monitor::resume`] was called: the next admitted sample starts a settling.
    resumed: bool,
}

/// The intake scaling and its buffers of model-unit U_k, Y_k.
#[derive(Debug)]
struct Intake {
    scaling: SignalScaling,
    u: Vec<f64>,
    y: Vec<f64>,
}

#[derive(Debug, Clone, Copy)]
struct Settling {
    until: u64,
    forget: bool,
}

#[derive(Debug, Clone, Copy)]
struct PendingUpdate {
    /// The alarm's sample (the crossing).
    alarm_k: u64,
    /// The sample of the update: `alarm_k` + `isolation_delay`.
    update_k: u64,
}

impl Monitor {
    /// A monitor of channel `channel` around `detector`, of any kind.
    #[must_use]
    pub fn new(channel: &str, detector: Box<dyn Detector>, settings: MonitorSettings) -> Self {
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
        let out = StepOutput::for_detector(detector.as_ref());
        Self {
            channel: channel.to_owned(),
            alarm: {
                let mut alarm = AlarmState::new(settings.tuning.alarm);
                alarm.set_end(settings.tuning.episode_end);
                alarm
            },
            detector,
            settings,
            groups,
            fault_names,
            out,
            pending: None,
            episode_alarm: None,
            isolation_revision: 0,
            reported_onset: 0,
            episode_onset: None,
            counters: MonitorCounters::default(),
            arrivals: 0,
            last_t: None,
            diagnosis: None,
            diagnosis_restart: false,
            diagnosis_failing: false,
            consistency: None,
            stat_records: true,
            settling: None,
            intake: None,
            resumed: false,
        }
    }

    /// Turns every sample's raw U_k, Y_k into model units, (raw − offset) / scale,
    /// before the detector and the diagnosis see them (`[channels.scaling]`). Records
    /// carry model-unit innovations; magnitudes are in the units the fault columns were
    /// written in (raw units for the `sensor_*`/`actuator_*` kinds of a configuration).
    #[must_use]
    pub fn with_scaling(mut self, scaling: SignalScaling) -> Self {
        self.intake = Some(Intake {
            u: vec![0.0; scaling.inputs()],
            y: vec![0.0; scaling.outputs()],
            scaling,
        });
        self
    }

    /// Whether [`Monitor::on_sample`] appends a `stat` record per processed sample (the
    /// default). A consumer that keeps none of them (a replay for its alarms only)
    /// turns them off and saves building and dropping one record per sample; every
    /// other record and every number are unchanged.
    pub fn set_stat_records(&mut self, enabled: bool) {
        self.stat_records = enabled;
    }

    /// Adds the filter-consistency test (see [`glrmon_core::filter::consistency`]): a
    /// `consistency` record whenever a block's verdict changes.
    #[must_use]
    pub fn with_consistency(mut self, consistency: Consistency) -> Self {
        self.consistency = Some(consistency);
        self
    }

    /// Runs `engine` alongside the detector and emits a `diagnosis` record after every
    /// alarm and isolation update (see the [crate
    /// documentation](crate#sparse-diagnosis)). The engine must be fresh (no sample
    /// processed) and built for the same channel.
    #[must_use]
    pub fn with_diagnosis(mut self, engine: DiagnosisEngine) -> Self {
        self.diagnosis = Some(engine);
        self
    }

    /// The sparse diagnosis engine, when enabled.
    #[must_use]
    pub fn diagnosis(&self) -> Option<&DiagnosisEngine> {
        self.diagnosis.as_ref()
    }

    /// The monitor of a validated channel of the configuration, with sparse diagnosis
    /// when its `[channels.diagnosis]` table enables it.
    ///
    /// # Errors
    /// As [`glrmon_spec::Channel::detector`] and [`DiagnosisEngine::new`] (reported as
    /// [`glrmon_core::ModelError::Setting`]); not expected after validation.
    pub fn from_channel(channel: &glrmon_spec::Channel) -> Result<Self, glrmon_core::ModelError> {
        let settings = MonitorSettings {
            tuning: Tuning::from_channel(channel),
            groups: channel
                .groups
                .iter()
                .map(|(name, faults)| IsolationGroup {
                    name: name.clone(),
                    faults: faults.clone(),
                })
                .collect(),
            max_gap: channel.max_gap,
            max_reorder: channel.max_reorder,
            settle: channel.settle,
        };
        let mut monitor = Self::new(&channel.name, channel.detector()?, settings);
        if let Some(scaling) = &channel.scaling {
            monitor = monitor.with_scaling(scaling.clone());
        }
        if let Some(c) = channel.consistency {
            monitor = monitor.with_consistency(Consistency::new(channel.innovation_dof(), c)?);
        }
        if !channel.diagnosis.enabled {
            return Ok(monitor);
        }
        let engine = DiagnosisEngine::new(channel, channel.diagnosis.history).map_err(|e| {
            glrmon_core::ModelError::Setting {
                what: "diagnosis",
                detail: e.to_string(),
            }
        })?;
        Ok(monitor.with_diagnosis(engine))
    }

    /// Applies new thresholds and alarm settings (a configuration reload) without
    /// touching the filter: the detection threshold and episode hysteresis take effect
    /// at the next sample (an episode going on continues under them); the isolation
    /// level and calibrated thresholds at the next isolation (an alarm or a pending
    /// update); the isolation delay at the next alarm (an update already announced
    /// keeps its sample).
    pub fn retune(&mut self, tuning: &Tuning) {
        self.alarm.set_settings(tuning.alarm);
        self.alarm.set_end(tuning.episode_end);
        self.settings.tuning.clone_from(tuning);
    }

    /// Starts the channel afresh after a pause whose samples it never saw: another
    /// instance monitored it meanwhile (this instance takes it over), or the plant ran
    /// before this monitor started. The next sample, whatever its index, restarts the
    /// filter from (x̂₀, P₀) and alarms are held off while it settles
    /// ([`MonitorSettings::settle`]), as after a restart: the plant's state is then far
    /// from x̂₀ and the filter's transient would otherwise look like a fault. An episode
    /// going on is dropped without an `alarm_end` (this monitor did not see it end; the
    /// instance that saw it go on ends it, or a new one is raised after the settling).
    /// Nothing is reported: the caller knows why it resumes.
    ///
    /// # Errors
    /// [`glrmon_core::ModelError`] when the initial state cannot be rebuilt (not
    /// expected of a validated model); the monitor is unchanged then.
    pub fn resume(&mut self) -> Result<(), glrmon_core::ModelError> {
        self.detector.restart()?;
        let _ = self.alarm.reset();
        self.pending = None;
        self.episode_alarm = None;
        self.episode_onset = None;
        if let Some(c) = &mut self.consistency {
            c.reset_block();
        }
        self.diagnosis_restart = true;
        self.settling = None;
        self.resumed = true;
        Ok(())
    }

    /// Samples of settling after a restart or a [`Monitor::resume`]:
    /// [`MonitorSettings::settle`], else the detector's memory.
    #[must_use]
    pub fn settle_samples(&self) -> u64 {
        self.settings
            .settle
            .unwrap_or(self.detector.memory() as u64)
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
    pub fn detector(&self) -> &dyn Detector {
        self.detector.as_ref()
    }

    /// The isolation tests this monitor runs at an alarm: the configured groups, else
    /// one test per fault.
    #[must_use]
    pub fn isolation_groups(&self) -> &[IsolationGroup] {
        &self.groups
    }

    /// Whether an alarm episode is going on.
    #[must_use]
    pub fn alarm_active(&self) -> bool {
        self.alarm.is_active()
    }

    /// θ̂ of the step just taken, one value per fault; empty for a kind that estimates
    /// none (its zeros are not an estimate).
    fn estimated_magnitude(&self) -> Vec<f64> {
        if self.detector.estimates_magnitude() {
            self.out.magnitude.iter().copied().collect()
        } else {
            Vec::new()
        }
    }

    /// The `stat` record of the step just taken at k, with the estimate of the episode
    /// going on, if any.
    fn push_stat(&self, k: u64, t: Option<f64>, records: &mut Vec<Record>) {
        let episode = self
            .episode_onset
            .filter(|_| self.alarm.is_active())
            .zip(self.detector.followed_magnitude())
            .map(|(onset, magnitude)| EpisodeEstimate {
                onset,
                magnitude: magnitude.to_vec(),
            });
        records.push(Record::Stat(Stat {
            channel: self.channel.clone(),
            k,
            t,
            glr: self.out.glr,
            onset: self.out.onset,
            magnitude: if self.out.glr.is_some() && self.detector.estimates_magnitude() {
                self.out.magnitude.iter().copied().collect()
            } else {
                Vec::new()
            },
            rank: self.out.rank,
            innovation: self.out.innovation.iter().copied().collect(),
            residual: self.out.residual.iter().copied().collect(),
            threshold: Some(self.settings.tuning.alarm.threshold),
            episode,
        }));
    }

    /// Records that `n` samples were lost before reaching the monitor (dropped at
    /// intake): the next sample without an explicit `k` is then seen after a gap and
    /// the filter takes predict-only steps for the missing ones.
    pub fn note_missing(&mut self, n: u64) {
        self.arrivals += n;
    }

    /// Processes one decoded sample and appends the resulting records: a `stat` per
    /// processed sample, `alarm` at the crossing that starts an episode and `alarm_end`
    /// where it ends, `isolation` `isolation_delay` samples after the alarm if the
    /// episode is still on, a `diagnosis` after each alarm and isolation record when
    /// enabled, `error` for a rejected sample (the channel's state is then unchanged)
    /// and for each filled gap.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_monitor::Monitor;
    /// use glrmon_wire::{Record, Sample};
    ///
    /// let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
    /// let channel = &cfg.channels[0];
    /// let mut monitor = Monitor::from_channel(channel).unwrap();
    /// let (l, p, q) = (channel.dims.inputs, channel.dims.outputs, channel.dims.signals);
    /// let mut records = Vec::new();
    /// let sample = |k| Sample { k: Some(k), t: None, u: vec![0.0; l], y: vec![0.0; p], p: vec![0.0; q] };
    /// monitor.on_sample(&sample(0), &mut records);
    /// monitor.on_sample(&sample(0), &mut records); // the same index again
    /// assert!(matches!(records[0], Record::Stat(_)));
    /// let Record::Error(e) = &records[1] else { panic!("{:?}", records[1]) };
    /// assert_eq!(e.code.as_str(), "duplicate");
    /// assert_eq!(monitor.counters().samples, 1);
    /// ```
    pub fn on_sample(&mut self, sample: &Sample, records: &mut Vec<Record>) {
        // The scaled values live in the monitor (no allocation per sample); they are
        // taken out for the step so that the step may borrow the monitor mutably.
        match self.intake.take() {
            None => self.process(sample, &sample.u, &sample.y, records),
            Some(mut intake) => {
                if sample.u.len() == intake.u.len() && sample.y.len() == intake.y.len() {
                    let Intake { scaling, u, y } = &mut intake;
                    scaling.to_model(&sample.u, &sample.y, u, y);
                    self.process(sample, &intake.u, &intake.y, records);
                } else {
                    // Wrong dimensions: the detector names them on the raw sample.
                    self.process(sample, &sample.u, &sample.y, records);
                }
                self.intake = Some(intake);
            }
        }
    }

    /// [`Monitor::on_sample`] with U_k, Y_k already in model units: the index checked
    /// (and a gap bridged), the values checked, one detector step, then the records
    /// it gives rise to.
    fn process(&mut self, sample: &Sample, u: &[f64], y: &[f64], records: &mut Vec<Record>) {
        let k = sample.k.unwrap_or(self.arrivals);
        if !self.admit_index(k, sample.t, records) {
            return;
        }
        if let Some(why) = too_large(u, y, &sample.p) {
            self.reject(records, Some(k), ErrorCode::TooLarge, why);
            return;
        }
        let core_sample = glrmon_core::Sample {
            k,
            u,
            y,
            p: &sample.p,
        };
        if std::mem::take(&mut self.resumed) {
            let settle = self.settle_samples();
            self.settling = (settle > 0).then_some(Settling {
                until: k.saturating_add(settle),
                forget: true,
            });
        }
        self.restart_diagnosis_if_due(k, records);
        if !self.step_detector(&core_sample, sample.t, records) {
            return;
        }
        self.counters.samples += 1;
        self.last_t = sample.t;
        let settling = self.settle(k);
        if !settling {
            self.check_consistency(k, sample.t, records);
        }
        self.step_diagnosis(&core_sample, records);
        let stat_at = self.stat_records.then(|| {
            self.push_stat(k, sample.t, records);
            records.len() - 1
        });
        if let Some(onset) = self.follow_alarm(k, sample.t, records)
            && self.episode_onset == Some(onset)
            && let Some(Record::Stat(stat)) = stat_at.and_then(|i| records.get_mut(i))
        {
            // An episode began at this sample, after its stat, and its onset is
            // followed: the crossing's estimate is the alarm's (the follow measures from
            // the next sample on).
            stat.episode = Some(EpisodeEstimate {
                onset,
                magnitude: stat.magnitude.clone(),
            });
        }
    }

    /// Checks sample index k against the last processed one: a restart of the
    /// publisher's numbering restarts the filter, a duplicate or late sample is
    /// refused (false), a gap is bridged by predict-only steps or, past `max_gap` (or
    /// with an unknown input), restarts the filter.
    fn admit_index(&mut self, k: u64, t: Option<f64>, records: &mut Vec<Record>) -> bool {
        if k == u64::MAX {
            self.reject(
                records,
                Some(k),
                ErrorCode::TooLarge,
                format!(
                    "sample index k = {k} is the largest 64-bit index: no sample could follow it"
                ),
            );
            return false;
        }
        self.arrivals = self.arrivals.max(k + 1);
        if let Some(next) = self.detector.next_index()
            && k < next
            && next - k > self.settings.max_reorder.saturating_add(1)
        {
            let why = format!(
                "sample k = {k} is {} before the last processed k = {}, more than \
                 max_reorder = {}: the publisher numbers anew (a restart?); the filter \
                 restarts from its initial state at k = {k}",
                next - 1 - k,
                next - 1,
                self.settings.max_reorder
            );
            // An episode going on ran to the last processed sample, not to the new k.
            if let Some((started, peak)) = self.alarm.reset() {
                self.end_episode(next - 1, self.last_t, started, peak, records);
            }
            self.restart(k, t, ErrorCode::SequenceReset, why, records);
            self.arrivals = k + 1;
        }
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
                return false;
            }
            if k > next {
                let missing = k - next;
                if missing > self.settings.max_gap {
                    let why = format!(
                        "{missing} samples missing before k = {k}, more than max_gap = {}: \
                         the filter restarts from its initial state at k = {k}",
                        self.settings.max_gap
                    );
                    self.restart(k, t, ErrorCode::Gap, why, records);
                } else if self.detector.unknown_inputs() > 0 {
                    let why = format!(
                        "{missing} samples missing before k = {k} and the model has an \
                         unknown input (model.E), which moves the state unobserved over a \
                         gap: the filter restarts from its initial state at k = {k}"
                    );
                    self.restart(k, t, ErrorCode::Gap, why, records);
                } else {
                    let mut failed = None;
                    for gap_k in next..k {
                        if let Err(e) = self.detector.predict_only(gap_k) {
                            failed = Some((gap_k, e));
                            break;
                        }
                        self.counters.gap_samples += 1;
                    }
                    if let Some((gap_k, e)) = failed {
                        let why = format!(
                            "predict-only step at k = {gap_k} failed ({e}): the filter \
                             restarts from its initial state at k = {k}"
                        );
                        self.restart(k, t, ErrorCode::Numerical, why, records);
                    } else {
                        self.diagnosis_restart = true;
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
            }
        }
        true
    }

    /// Holds the decision statistic back while the detector settles after a restart
    /// (true then): its l_k is not published and raises no alarm, and the filter
    /// consistency test is not fed the transient. At the last sample of the settling
    /// the detector forgets the evidence gathered since the restart; a kind that cannot
    /// settles for its memory more, until that evidence has left it.
    fn settle(&mut self, k: u64) -> bool {
        let Some(s) = self.settling else {
            return false;
        };
        self.out.glr = None;
        self.out.onset = None;
        if k + 1 >= s.until {
            self.settling = match s.forget {
                true if !self.detector.forget_evidence() => Some(Settling {
                    until: k + 1 + self.detector.memory() as u64,
                    forget: false,
                }),
                _ => None,
            };
        }
        true
    }

    /// After a gap or a filter failure, the residual filter of sparse diagnosis starts
    /// again from the detector's prediction for k.
    fn restart_diagnosis_if_due(&mut self, k: u64, records: &mut Vec<Record>) {
        if self.diagnosis_restart {
            if let Some(engine) = &mut self.diagnosis {
                // The detector's prediction for k is the residual filter's new prior.
                let restarted = match self.detector.innovation_filter() {
                    Some(filter) => engine.restart(filter).map_err(|e| e.to_string()),
                    None => Err(format!(
                        "the {} detector runs no Kalman filter to restart the residual \
                         filter from",
                        self.detector.kind()
                    )),
                };
                if let Err(e) = restarted {
                    self.reject(
                        records,
                        Some(k),
                        ErrorCode::Numerical,
                        format!("sparse diagnosis disabled: {e}"),
                    );
                    self.diagnosis = None;
                }
            }
            self.diagnosis_restart = false;
        }
    }

    /// One detector step; false when the sample was refused or the statistics are
    /// not finite (the filter then restarts).
    fn step_detector(
        &mut self,
        core_sample: &glrmon_core::Sample<'_>,
        t: Option<f64>,
        records: &mut Vec<Record>,
    ) -> bool {
        let k = core_sample.k;
        if let Err(e) = self.detector.step(core_sample, &mut self.out) {
            let code = match e {
                StepError::WrongDimension { got: 0, .. } => ErrorCode::MissingField,
                StepError::WrongDimension { .. } => ErrorCode::WrongDimension,
                StepError::NonFinite { .. } => ErrorCode::NonFinite,
                StepError::OutOfOrder { .. } => ErrorCode::OutOfOrder,
                _ => ErrorCode::Numerical,
            };
            if code == ErrorCode::Numerical {
                // The filter cannot go on from this state (e.g. Σ_k lost definiteness):
                // the next sample starts a new run.
                let why = format!(
                    "{e}: sample dropped; the filter restarts from its initial state at the \
                     next sample"
                );
                self.restart(k, t, code, why, records);
            } else {
                self.reject(records, Some(k), code, e.to_string());
            }
            return false;
        }
        if !self.out.normalized_innovation.is_finite()
            || self.out.glr.is_some_and(|l| !l.is_finite())
            || self.out.magnitude.iter().any(|v| !v.is_finite())
        {
            // Detected where it arises: a statistic that overflowed would make records
            // no one can encode, and the filter state behind it is no better.
            let why = format!(
                "the statistics at k = {k} are not finite (εᵀΣ⁻¹ε = {:e}, l_k = {:?}): \
                 sample dropped; the filter restarts from its initial state at the next \
                 sample",
                self.out.normalized_innovation, self.out.glr
            );
            self.restart(k, t, ErrorCode::Numerical, why, records);
            return false;
        }
        true
    }

    /// Feeds the filter-consistency test; a `consistency` record when a block's
    /// verdict changes.
    fn check_consistency(&mut self, k: u64, t: Option<f64>, records: &mut Vec<Record>) {
        if let Some(block) = self
            .consistency
            .as_mut()
            .and_then(|c| c.update(self.out.normalized_innovation))
            && block.changed
        {
            records.push(Record::Consistency(glrmon_wire::Consistency {
                channel: self.channel.clone(),
                k,
                t,
                state: block.verdict.as_str().to_owned(),
                nis_mean: block.mean,
                expected: (self.detector.dims().outputs - self.detector.unknown_inputs()) as f64,
                band: [block.band.0, block.band.1],
                window: self
                    .consistency
                    .as_ref()
                    .map_or(0, |c| c.settings().window as u64),
            }));
        }
    }

    /// One step of the residual filter of sparse diagnosis, reporting the first of a
    /// run of failures.
    fn step_diagnosis(&mut self, core_sample: &glrmon_core::Sample<'_>, records: &mut Vec<Record>) {
        let k = core_sample.k;
        if let Some(engine) = &mut self.diagnosis {
            match engine.step(core_sample) {
                // A success right after a restart (a plain Kalman update, no unknown
                // input yet) does not end a run of failures.
                Ok(()) => {
                    if engine
                        .held()
                        .is_some_and(|(oldest, newest)| newest > oldest)
                    {
                        self.diagnosis_failing = false;
                    }
                }
                Err(e) => {
                    self.diagnosis_restart = true;
                    if !std::mem::replace(&mut self.diagnosis_failing, true) {
                        self.reject(
                            records,
                            Some(k),
                            ErrorCode::Numerical,
                            format!(
                                "sparse diagnosis: the residual filter failed and restarts at \
                                 the next sample (further failures in a row are not reported): {e}"
                            ),
                        );
                    }
                }
            }
        }
    }

    /// The alarm episode after the step at k: `alarm` at the crossing, `alarm_end`,
    /// and the announced isolation update when its sample has come. The onset of an
    /// alarm raised at k, if one was.
    fn follow_alarm(&mut self, k: u64, t: Option<f64>, records: &mut Vec<Record>) -> Option<u64> {
        let followed = if self.alarm.is_active() {
            self.detector.followed()
        } else {
            None
        };
        // An onset at the window's oldest slot says the change is older than the window
        // (a fault going on), not that a new one began: the alarm state sees none.
        let w = self.detector.memory() as u64;
        let onset = self.out.onset.filter(|&r| k.saturating_sub(r) + 1 < w);
        let mut alarm = None;
        match (self.alarm).update_followed(k, self.out.glr, onset, followed) {
            AlarmTransition::Started => alarm = self.emit_alarm(k, t, records),
            AlarmTransition::Replaced { started, peak } => {
                // A new change while the episode's fault had no evidence left: the
                // episode ends here and the crossing is the next one's alarm.
                self.end_episode(k, t, started, peak, records);
                alarm = self.emit_alarm(k, t, records);
            }
            AlarmTransition::Ended { started, peak } => {
                self.end_episode(k, t, started, peak, records);
            }
            AlarmTransition::Active | AlarmTransition::Quiet => {}
        }
        // With `clear_samples` > 1 an episode survives samples without an admissible
        // onset, where there is nothing to test: the update then waits for the next
        // sample with one.
        if let (Some(p), Some(glr), Some(onset)) = (
            self.pending.filter(|p| k >= p.update_k),
            self.out.glr,
            self.out.onset,
        ) {
            self.pending = None;
            self.emit_update(p, k, t, glr, onset, records);
        }
        // A kind that isolates by its own tests (exclusion) publishes an update at each
        // change of its verdict during the episode.
        let revision = self.detector.isolation_revision();
        if revision != self.isolation_revision {
            self.isolation_revision = revision;
            if let (Some(alarm_k), Some(glr), Some(onset), None) =
                (self.episode_alarm, self.out.glr, self.out.onset, alarm)
                && self.detector.residual_isolation().is_some()
            {
                let p = PendingUpdate {
                    alarm_k,
                    update_k: k,
                };
                self.emit_update(p, k, t, glr, onset, records);
            }
        }
        alarm
    }

    /// The `alarm_end` of the episode that started at `started` with peak l_k `peak`,
    /// ending at k. An episode shorter than the isolation delay: its alarm, raised at
    /// the crossing, stays its isolation (see the crate documentation).
    fn end_episode(
        &mut self,
        k: u64,
        t: Option<f64>,
        started: u64,
        peak: f64,
        records: &mut Vec<Record>,
    ) {
        self.detector.follow(None);
        self.episode_onset = None;
        self.pending = None;
        self.episode_alarm = None;
        records.push(Record::AlarmEnd(AlarmEnd {
            channel: self.channel.clone(),
            k,
            t,
            onset: self.reported_onset,
            duration: k.saturating_sub(started),
            peak_glr: peak,
        }));
    }

    /// The `alarm` record of the crossing at k (l_k > λ just started an episode), its
    /// isolation at the current r̂, and the update it announces; its onset r̂.
    fn emit_alarm(&mut self, k: u64, t: Option<f64>, records: &mut Vec<Record>) -> Option<u64> {
        self.pending = None;
        let (Some(glr), Some(onset)) = (self.out.glr, self.out.onset) else {
            return None;
        };
        self.counters.alarms += 1;
        self.episode_alarm = Some(k);
        self.isolation_revision = self.detector.isolation_revision();
        self.reported_onset = onset;
        self.follow_fault(onset);
        let delay = u64::from(self.settings.tuning.isolation_delay);
        let update_k = (delay > 0).then(|| k.saturating_add(delay));
        self.pending = update_k.map(|update_k| PendingUpdate {
            alarm_k: k,
            update_k,
        });
        let isolation = self.isolate(onset);
        records.push(Record::Alarm(Alarm {
            channel: self.channel.clone(),
            k,
            t,
            glr,
            threshold: self.settings.tuning.alarm.threshold,
            onset,
            magnitude: self.estimated_magnitude(),
            isolation,
            faults: self.fault_names.clone(),
            update_k,
        }));
        self.diagnose(k, onset, records);
        Some(onset)
    }

    /// Follows the fault from onset r̂ past the window: episodes end on its evidence
    /// under [`EpisodeEnd::FaultGone`] (a kind that cannot follow one ends them on
    /// l_k), and under either rule the `stat` records carry its estimate. The
    /// evidence does not change an episode that ends below the threshold.
    fn follow_fault(&mut self, onset: u64) {
        if self.detector.follow(Some(onset)) {
            self.episode_onset = Some(onset);
        }
    }

    /// The `isolation` record of the alarm `p` at k (its `update_k`), the episode still
    /// on, l_k = `glr` and r̂ = `onset`: magnitude and isolation tests as they are now.
    fn emit_update(
        &mut self,
        p: PendingUpdate,
        k: u64,
        t: Option<f64>,
        glr: f64,
        onset: u64,
        records: &mut Vec<Record>,
    ) {
        self.counters.isolation_updates += 1;
        // The episode's `alarm_end` reports the latest estimate of its onset.
        self.reported_onset = onset;
        self.follow_fault(onset);
        let isolation = self.isolate(onset);
        records.push(Record::Isolation(IsolationUpdate {
            channel: self.channel.clone(),
            k,
            t,
            alarm_k: p.alarm_k,
            glr,
            threshold: self.settings.tuning.alarm.threshold,
            onset,
            magnitude: self.estimated_magnitude(),
            isolation,
            faults: self.fault_names.clone(),
        }));
        self.diagnose(k, onset, records);
    }

    /// The `diagnosis` record at k with onset r̂, right after the alarm or isolation
    /// record of k (or an `error` record when the regression cannot be made, e.g. no
    /// signal).
    fn diagnose(&mut self, k: u64, onset: u64, records: &mut Vec<Record>) {
        let Some(engine) = &self.diagnosis else {
            return;
        };
        match engine.diagnose_alarm(k, onset) {
            Ok(d) => {
                self.counters.diagnoses += 1;
                records.push(Record::Diagnosis(d.record));
            }
            Err(e) => self.reject(
                records,
                Some(k),
                ErrorCode::Numerical,
                format!("sparse diagnosis at k = {k}: {e}"),
            ),
        }
    }

    /// Minmax and sensitivity tests of every group at onset r̂ (eq. (41), Basseville
    /// 1996 §3.2), from C_k(r̂), d_k(r̂): O(m³) per test, independent of the window.
    /// A group isolated at r̂ stays isolated only if no other group, alone and at its
    /// own best onset in the window, explains the data as well as every fault at r̂
    /// within the group's threshold ([`ambiguity`]); the two are reported ambiguous
    /// with each other when the group alone explains them as well: O(w·m³) more, at
    /// alarms and updates only.
    fn isolate(&self, onset: u64) -> Vec<IsolationResult> {
        if let Some(tests) = self.detector.residual_isolation() {
            return self.isolate_by_exclusion(&tests);
        }
        let Some(fisher) = self.detector.fisher_statistics(onset) else {
            return Vec::new();
        };
        let mut tested: Vec<(usize, IsolationResult)> = self
            .groups
            .iter()
            .enumerate()
            .filter_map(|(gi, g)| {
                let minmax = fisher.minmax(&g.faults).ok()?;
                let sensitivity = fisher.sensitivity(&g.faults).ok()?;
                let threshold = self.isolation_threshold(&g.name, minmax.dof)?;
                Some((
                    gi,
                    IsolationResult {
                        excluded: None,
                        fault: g.name.clone(),
                        minmax: minmax.value,
                        sensitivity: sensitivity.value,
                        threshold,
                        isolated: minmax.value > threshold,
                        ambiguous_with: Vec::new(),
                    },
                ))
            })
            .collect();
        if tested.iter().any(|(_, r)| r.isolated) {
            self.mark_ambiguous(&fisher, &mut tested);
        }
        tested.into_iter().map(|(_, r)| r).collect()
    }

    /// Isolation by the detector's own exclusion tests (the kernel method, Li, Boem,
    /// Pin & Parisini, Prop. 4.2), per group: the group's residual and threshold are
    /// those of its member closest to exclusion (smallest residual/threshold), it is
    /// excluded when all its members are, and isolated when every fault outside it is
    /// excluded and one inside is not.
    fn isolate_by_exclusion(&self, tests: &[ResidualIsolation]) -> Vec<IsolationResult> {
        let excluded = |i: usize| tests.get(i).is_some_and(|t| t.excluded);
        self.groups
            .iter()
            .filter_map(|g| {
                let best = g
                    .faults
                    .iter()
                    .filter_map(|&i| tests.get(i))
                    .min_by(|a, b| {
                        (a.statistic / a.threshold).total_cmp(&(b.statistic / b.threshold))
                    })?;
                let all_excluded = g.faults.iter().all(|&i| excluded(i));
                let others_excluded =
                    (0..tests.len()).all(|i| g.faults.contains(&i) || excluded(i));
                Some(IsolationResult {
                    excluded: Some(all_excluded),
                    fault: g.name.clone(),
                    minmax: best.statistic,
                    sensitivity: best.statistic,
                    threshold: best.threshold,
                    isolated: others_excluded && !all_excluded,
                    ambiguous_with: Vec::new(),
                })
            })
            .collect()
    }

    /// The threshold of isolation test `name` with `dof` degrees of freedom: its
    /// calibrated value, else the χ² upper quantile at the isolation level divided
    /// among `isolation_onsets`.
    fn isolation_threshold(&self, name: &str, dof: usize) -> Option<f64> {
        let tuning = &self.settings.tuning;
        match tuning.isolation_thresholds.iter().find(|(n, _)| n == name) {
            Some(&(_, t)) => Some(t),
            None => chi2_upper_quantile(
                dof.max(1) as f64,
                tuning.isolation_alpha / tuning.isolation_onsets.max(1) as f64,
            )
            .ok(),
        }
    }

    /// Onset-free check of the isolated groups (see [`ambiguity`]): an isolated group
    /// that another, alone at its own onset, explains the data without is no longer
    /// isolated; it and those of its alternatives it competes with name each other in
    /// `ambiguous_with`.
    ///
    /// Each group's best onset is searched among the onsets whose GLR statistic could
    /// hold it ([`ambiguity::best_onsets_bounded`]): at an alarm the Fisher statistics of
    /// a few onsets are built instead of the window's w.
    fn mark_ambiguous(&self, fisher: &FisherStatistics, tested: &mut [(usize, IsolationResult)]) {
        if !tested.iter().any(|(_, r)| r.isolated) {
            return;
        }
        let k = self.out.k;
        let first = k.saturating_sub(self.detector.memory().saturating_sub(1) as u64);
        let onsets: Vec<u64> = (first..=k).collect();
        let groups: Vec<&[usize]> = self.groups.iter().map(|g| g.faults.as_slice()).collect();
        let global = fisher.global().value;
        let mut thresholds = vec![f64::INFINITY; self.groups.len()];
        for (gi, result) in tested.iter() {
            thresholds[*gi] = result.threshold;
        }
        // No verdict reads a group's best below min_g(G − τ_g) − max_h τ_h (g isolated,
        // h with a finite threshold: an infinite one makes `competes` true whatever).
        let lowest = (tested.iter())
            .filter(|(_, r)| r.isolated)
            .map(|(_, r)| global - r.threshold)
            .fold(f64::INFINITY, f64::min);
        let widest = (thresholds.iter())
            .copied()
            .filter(|t| t.is_finite())
            .fold(0.0, f64::max);
        let best = ambiguity::best_onsets_bounded(
            &onsets,
            ambiguity::window_bounds(self.detector.as_ref(), &groups),
            |r| self.detector.fisher_statistics(r),
            &groups,
            lowest - widest,
        );
        let mut pairs = Vec::new();
        for (gi, result) in tested.iter_mut() {
            if !result.isolated {
                continue;
            }
            let alternatives =
                ambiguity::alternatives(&best, &groups, *gi, global, result.threshold);
            if !alternatives.is_empty() {
                result.isolated = false;
                pairs.extend(
                    (alternatives.into_iter())
                        .filter(|&h| ambiguity::competes(&best, *gi, h, thresholds[h]))
                        .map(|h| (*gi, h)),
                );
            }
        }
        for (g, h) in pairs {
            for (a, b) in [(g, h), (h, g)] {
                if let Some((_, r)) = tested.iter_mut().find(|(gi, _)| *gi == a) {
                    let name = &self.groups[b].name;
                    if !r.ambiguous_with.contains(name) {
                        r.ambiguous_with.push(name.clone());
                    }
                }
            }
        }
    }

    /// The minmax statistic of every isolation test at the current onset estimate r̂
    /// (after the last sample), by test name: what isolation would compare with its
    /// thresholds if an alarm were raised now. Empty while no onset is admissible. For
    /// calibrating the isolation thresholds on fault-free data (off the per-sample path:
    /// it allocates).
    #[must_use]
    pub fn isolation_statistics(&self) -> Vec<(String, f64)> {
        let Some(onset) = self.out.onset.filter(|_| self.out.glr.is_some()) else {
            return Vec::new();
        };
        let Some(fisher) = self.detector.fisher_statistics(onset) else {
            return Vec::new();
        };
        self.groups
            .iter()
            .filter_map(|g| Some((g.name.clone(), fisher.minmax(&g.faults).ok()?.value)))
            .collect()
    }

    /// Restarts the detector from its initial state (see [`Detector::restart`]): an
    /// ongoing alarm episode ends here (`alarm_end`), a pending isolation update is
    /// dropped,
    /// the residual filter of sparse diagnosis restarts too; reported as an `error`.
    fn restart(
        &mut self,
        k: u64,
        t: Option<f64>,
        code: ErrorCode,
        why: String,
        records: &mut Vec<Record>,
    ) {
        if let Some((started, peak)) = self.alarm.reset() {
            self.end_episode(k, t, started, peak, records);
        }
        self.pending = None;
        self.episode_alarm = None;
        self.episode_onset = None;
        self.counters.restarts += 1;
        if let Some(c) = &mut self.consistency {
            c.reset_block();
        }
        self.diagnosis_restart = true;
        if let Err(e) = self.detector.restart() {
            self.reject(records, Some(k), ErrorCode::Numerical, e.to_string());
        }
        let settle = self.settle_samples();
        self.settling = (settle > 0).then_some(Settling {
            until: k.saturating_add(settle),
            forget: true,
        });
        self.reject(
            records,
            Some(k),
            code,
            format!("{why}; alarms are held off for {settle} samples while it settles"),
        );
    }

    fn reject(&mut self, records: &mut Vec<Record>, k: Option<u64>, code: ErrorCode, why: String) {
        records.push(Record::Error(ErrorRecord {
            channel: self.channel.clone(),
            k,
            code,
            message: format!("channel \"{}\": {why}", self.channel),
            stage: Stage::Processing,
        }));
    }
}

/// The largest magnitude of an input, output or signal value (in model units, after
/// `[channels.scaling]`) that the monitor accepts. The filter squares innovations and
/// sums them over the window; values beyond 10¹⁰⁰ could overflow those quadratic forms
/// (10³⁰⁸), so they are refused at intake (`too_large`) instead of poisoning the
/// channel's statistics.
pub const MAX_MAGNITUDE: f64 = 1e100;

/// Why a sample's values are refused as too large, if they are.
fn too_large(u: &[f64], y: &[f64], p: &[f64]) -> Option<String> {
    for (field, values) in [("u", u), ("y", y), ("p", p)] {
        if let Some(i) = values.iter().position(|v| v.abs() > MAX_MAGNITUDE) {
            return Some(format!(
                "field {field}[{i}] = {:e} is beyond the accepted magnitude {MAX_MAGNITUDE:e} \
                 (in model units): it would overflow the filter's statistics",
                values[i]
            ));
        }
    }
    None
}

#[cfg(test)]
mod tests;
