//! Calibration of a channel's thresholds on fault-free data, with the channel's own
//! monitor, so that gaps, restarts and the hysteresis count as they do live: what
//! `glrmon calibrate` prints and writes.
//!
//! The data are recorded ([`recorded`], several files with [`recorded_files`]) or
//! simulated from the channel's model ([`simulated`]); either gives the monitor's
//! [`Statistics`]. Independent runs (files, simulated parts) are separate segments: each
//! gets a fresh monitor, as a new run of the plant gets a fresh start live, and a NaN
//! between their l_k keeps an episode from spanning two of them. [`calibrate_channel`]
//! then finds the detection threshold for a [`Target`] (a mean time between false-alarm
//! episodes, [`glrmon_core::threshold::calibration::calibrate`], or a per-sample false-alarm
//! fraction, [`glrmon_core::threshold::calibration::calibrate_sample_far`]) and each isolation
//! test's threshold for the channel's type-I probability α ([`calibrate_isolation`]).
//!
//! Every run keeps its name, its range of l_k and the rows it skipped, by reason
//! ([`Run`]): the calibration reports each run's rate at the pooled threshold with its
//! interval ([`RunRate`]), and [`ChannelCalibration::disagreements`] names the runs whose
//! intervals do not overlap (run-to-run variation that a threshold pooled over them
//! hides). An isolation test whose fault-free statistic has no degree of freedom is not
//! calibrated ([`NotCalibrated`]): its χ² threshold stays in force.
//!
//! l_k does not depend on the threshold in force: the monitor restarts its detector at a
//! gap or a numerical failure, never at an alarm, so statistics gathered at one
//! threshold serve any other. A recording made in capture mode (`[recording.capture]`)
//! is the exception, as its inputs were kept only around alarms: [`recorded`] refuses it.
//!
//! ```
//! use glrmon_core::threshold::calibration::Target;
//!
//! let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
//! let channel = cfg.pick_channel(Some("unstable")).unwrap();
//! let stats = glrmon_eval::calibrate::simulated(channel, 20_000, 1, None).unwrap();
//! let c = glrmon_eval::calibrate::calibrate_channel(channel, stats, Target::Mtbfa(1_000.0))
//!     .unwrap();
//! assert!(c.alarm.threshold > 0.0);
//! ```

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use glrmon_core::alarm::AlarmSettings;
use glrmon_core::threshold::calibration::{
    self, Calibration, CalibrationError, Quantile, Target, calibrate, calibrate_sample_far,
    count_episodes, upper_quantile,
};
use glrmon_input::{InputError, InputFormat, McapInput, Samples, Skipped};
use glrmon_monitor::Monitor;
use glrmon_sim::SimSample;
use glrmon_spec::Channel;
use glrmon_wire::{Record, Sample};

/// How often (in samples of one part) the progress callback is called.
const PROGRESS_STEP: u64 = 65_536;

/// A progress callback: called, possibly from several threads at once, with the number
/// of samples processed since its previous call.
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

/// Why a calibration could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrateError {
    /// The recorded samples could not be read; [`InputError::is_invalid_input`] tells
    /// whether the file is at fault.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The channel's simulator could not be built.
    #[error(transparent)]
    Simulator(#[from] glrmon_sim::SimError),
    /// The channel's monitor could not be built.
    #[error(transparent)]
    Monitor(#[from] glrmon_core::ModelError),
    /// The data do not allow the calibration asked for (too few samples or episodes for
    /// the target, or an impossible target).
    #[error("channel \"{channel}\": {reason}")]
    Calibration {
        /// The channel calibrated.
        channel: String,
        /// What is wrong.
        reason: CalibrationError,
    },
    /// A recorded file holds no sample that gives the channel an l_k: every row was
    /// skipped (each reason counted), or none of the samples the monitor processed had
    /// an admissible onset.
    #[error(
        "{}: no usable sample of channel \"{channel}\": {}",
        path.display(),
        no_sample_reason(*rows, *processed, skipped)
    )]
    NoUsableSample {
        /// The file.
        path: PathBuf,
        /// The channel calibrated.
        channel: String,
        /// Rows (or recorded inputs) of the channel read.
        rows: u64,
        /// The rows skipped, by reason.
        skipped: Vec<Skips>,
        /// Samples the monitor processed (each without an admissible onset).
        processed: u64,
    },
    /// A recording made in capture mode: its inputs were kept only around alarms.
    #[error(
        "{}: recorded in capture mode ([recording.capture]): its inputs were kept only \
         around alarms at the threshold then in force, so its l_k are not a fault-free \
         sample; calibrate on a continuous recording",
        .0.display()
    )]
    Captured(PathBuf),
    /// A worker thread panicked.
    #[error("a calibration thread panicked")]
    Panicked,
}

impl CalibrateError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub fn is_invalid_input(&self) -> bool {
        match self {
            Self::Input(e) => e.is_invalid_input(),
            Self::Calibration { .. } | Self::NoUsableSample { .. } | Self::Captured(_) => true,
            Self::Simulator(_) | Self::Monitor(_) | Self::Panicked => false,
        }
    }
}

/// Why [`CalibrateError::NoUsableSample`]: no rows, every row skipped, or no
/// admissible onset among the samples processed.
fn no_sample_reason(rows: u64, processed: u64, skipped: &[Skips]) -> String {
    let skipped_rows: u64 = skipped.iter().map(|s| s.count).sum();
    if rows == 0 {
        "the file holds no rows, so 0 samples processed by the monitor".to_owned()
    } else if processed == 0 {
        format!("all {rows} rows skipped: {}", skip_summary(skipped))
    } else if skipped_rows == 0 {
        format!("{processed} samples processed by the monitor, none with an admissible onset")
    } else {
        format!(
            "{processed} samples processed by the monitor, none with an admissible onset; \
             {skipped_rows} rows skipped: {}",
            skip_summary(skipped)
        )
    }
}

/// `count reason (first: message)` per reason, in the order the reasons first occurred.
#[must_use]
pub fn skip_summary(skipped: &[Skips]) -> String {
    skipped
        .iter()
        .map(|s| format!("{} {} (first: {})", s.count, s.reason, s.first))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The rows (or samples) of one run skipped for one reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skips {
    /// The reason: the wire's error code of the row or of the monitor's refusal
    /// (`non_finite`, `wrong_type`, `too_large`, `duplicate`, …), `dropped` for payloads
    /// lost at intake.
    pub reason: String,
    /// How many.
    pub count: u64,
    /// The first one: where it is (`row <n>` of a CSV file, `input <n>` of a
    /// recording, or the sample index) and what is wrong.
    pub first: String,
}

/// Counts one skip of `reason` into `skips`, keeping the first message of each reason.
fn count_skip(skips: &mut Vec<Skips>, reason: &str, first: impl FnOnce() -> String) {
    match skips.iter_mut().find(|s| s.reason == reason) {
        Some(s) => s.count += 1,
        None => skips.push(Skips {
            reason: reason.to_owned(),
            count: 1,
            first: first(),
        }),
    }
}

/// One independent run of the data (a file, or a simulated part).
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The file, or the simulated part and its seed.
    pub name: String,
    /// Its l_k in [`Statistics::glr`] (without the NaN that ends it).
    pub range: Range<usize>,
    /// Rows (or recorded inputs, or simulated samples) of the channel read.
    pub rows: u64,
    /// The rows that gave the monitor no sample, and the samples it refused, by reason.
    pub skipped: Vec<Skips>,
}

/// What the channel's monitor gave on fault-free data.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Statistics {
    /// The GLR statistic l_k (Zhang & Basseville 2014, eq. (35)) of every sample the
    /// monitor produced a statistic for, in order; NaN where no onset is admissible.
    pub glr: Vec<f64>,
    /// The minmax isolation statistic at r̂ (§5) of each isolation test, by test name,
    /// one value per sample with an admissible onset.
    pub isolation: BTreeMap<String, Vec<f64>>,
    /// By test, the samples at which its minmax statistic had no degree of freedom:
    /// the Schur complement F*_a = F_aa − F_ab F_bb⁻¹ F_ba of eq. (41) was 0 at r̂, i.e.
    /// the test's signature over the window lay in the span of the other faults'. The
    /// statistic is then 0 whatever the data: the test cannot isolate.
    pub spanned: BTreeMap<String, u64>,
    /// The independent runs, in order; empty for statistics built by hand, which
    /// [`Statistics::append`] then counts as one run.
    pub runs: Vec<Run>,
}

impl Statistics {
    /// Appends the statistics of an independent run as a separate segment: its l_k,
    /// then a NaN so that no episode spans the two; its isolation statistics pooled;
    /// its runs kept (an unnamed one, or statistics without runs, becomes `run <i>`).
    pub fn append(&mut self, run: Statistics) {
        let offset = self.glr.len();
        let len = run.glr.len();
        self.glr.extend(run.glr);
        self.glr.push(f64::NAN);
        for (test, values) in run.isolation {
            self.isolation.entry(test).or_default().extend(values);
        }
        for (test, n) in run.spanned {
            *self.spanned.entry(test).or_default() += n;
        }
        let runs = if run.runs.is_empty() {
            vec![Run {
                name: String::new(),
                range: 0..len,
                rows: len as u64,
                skipped: Vec::new(),
            }]
        } else {
            run.runs
        };
        for r in runs {
            let name = if r.name.is_empty() {
                format!("run {}", self.runs.len() + 1)
            } else {
                r.name
            };
            self.runs.push(Run {
                name,
                range: r.range.start + offset..r.range.end + offset,
                ..r
            });
        }
    }
}

/// The statistics of `channel`'s monitor fed with the samples `next` writes into its
/// argument, until it returns `Ok(false)`, as one run (unnamed). A sample the monitor
/// refuses contributes nothing but a count of its reason (the code of the monitor's
/// `error` record), located by its index `k`. `progress` is called every 65 536
/// samples.
///
/// # Errors
/// The first error of `next`, or the monitor's [`glrmon_core::ModelError`] when it
/// cannot be built.
pub fn statistics<E: From<glrmon_core::ModelError>>(
    channel: &Channel,
    next: impl FnMut(&mut Sample) -> Result<bool, E>,
    progress: Option<Progress<'_>>,
) -> Result<Statistics, E> {
    monitor_statistics(
        channel,
        next,
        |s: &Sample| match s.k {
            Some(k) => format!("sample k = {k}"),
            None => "a sample".to_owned(),
        },
        progress,
    )
}

/// [`statistics`], with `locate` naming where a sample the monitor refuses came from.
fn monitor_statistics<E: From<glrmon_core::ModelError>>(
    channel: &Channel,
    mut next: impl FnMut(&mut Sample) -> Result<bool, E>,
    locate: impl Fn(&Sample) -> String,
    progress: Option<Progress<'_>>,
) -> Result<Statistics, E> {
    let mut mon = Monitor::from_channel(channel)?;
    let groups: Vec<(String, Vec<usize>)> = mon
        .isolation_groups()
        .iter()
        .map(|g| (g.name.clone(), g.faults.clone()))
        .collect();
    let mut isolation: Vec<Vec<f64>> = vec![Vec::new(); groups.len()];
    let mut spanned = vec![0u64; groups.len()];
    let mut sample = Sample::default();
    let mut records = Vec::new();
    let mut stats = Statistics::default();
    let mut skipped = Vec::new();
    let mut n = 0u64;
    while next(&mut sample)? {
        mon.on_sample(&sample, &mut records);
        let mut processed = false;
        let mut refusal = None;
        for r in records.drain(..) {
            match r {
                Record::Stat(s) => {
                    processed = true;
                    stats.glr.push(s.glr.unwrap_or(f64::NAN));
                    let Some(onset) = s.onset.filter(|_| s.glr.is_some()) else {
                        continue;
                    };
                    // The monitor's own isolation tests at r̂ (eq. (41)), with their
                    // degrees of freedom.
                    let Some(fisher) = mon.detector().fisher_statistics(onset) else {
                        continue;
                    };
                    for (i, (_, faults)) in groups.iter().enumerate() {
                        if let Ok(t) = fisher.minmax(faults) {
                            isolation[i].push(t.value);
                            spanned[i] += u64::from(t.dof == 0);
                        }
                    }
                }
                Record::Error(e) => refusal = Some(e),
                _ => {}
            }
        }
        if !processed && let Some(e) = refusal {
            let prefix = format!("channel \"{}\": ", channel.name);
            count_skip(&mut skipped, e.code.as_str(), || {
                format!(
                    "{}: {}",
                    locate(&sample),
                    e.message.strip_prefix(&prefix).unwrap_or(&e.message)
                )
            });
        }
        n += 1;
        if n.is_multiple_of(PROGRESS_STEP)
            && let Some(p) = progress
        {
            p(PROGRESS_STEP);
        }
    }
    for ((name, _), (values, zero)) in groups.into_iter().zip(isolation.into_iter().zip(spanned)) {
        if !values.is_empty() {
            stats.spanned.insert(name.clone(), zero);
            stats.isolation.insert(name, values);
        }
    }
    stats.runs.push(Run {
        name: String::new(),
        range: 0..stats.glr.len(),
        rows: n,
        skipped,
    });
    Ok(stats)
}

/// The statistics of `n` fault-free samples simulated from `channel`'s model
/// ([`glrmon_sim::from_channel`]), in one part per core (at most one per 10 000
/// samples), part i from seed `seed + i`. The parts are independent runs: in the
/// result, a NaN follows each part's l_k so that no episode spans two parts.
///
/// # Errors
/// [`CalibrateError::Simulator`], [`CalibrateError::Monitor`] or
/// [`CalibrateError::Panicked`].
pub fn simulated(
    channel: &Channel,
    n: u64,
    seed: u64,
    progress: Option<Progress<'_>>,
) -> Result<Statistics, CalibrateError> {
    let parts = std::thread::available_parallelism()
        .map_or(1, std::num::NonZero::get)
        .min(usize::try_from(n / 10_000).unwrap_or(1).max(1)) as u64;
    let results: Vec<Result<Statistics, CalibrateError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..parts)
            .map(|i| {
                let len = n / parts + u64::from(i < n % parts);
                scope.spawn(move || {
                    let mut sim = glrmon_sim::from_channel(channel, seed + i)?;
                    let mut x = SimSample {
                        k: 0,
                        u: vec![],
                        y: vec![],
                        p: vec![],
                    };
                    let mut left = len;
                    statistics(
                        channel,
                        |s| {
                            if left == 0 {
                                return Ok::<_, CalibrateError>(false);
                            }
                            left -= 1;
                            sim.next_into(&mut x);
                            s.k = Some(x.k);
                            s.t = None;
                            s.u.clone_from(&x.u);
                            s.y.clone_from(&x.y);
                            s.p.clone_from(&x.p);
                            Ok(true)
                        },
                        progress,
                    )
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or(Err(CalibrateError::Panicked)))
            .collect()
    });
    let mut all = Statistics::default();
    for (i, r) in (0..).zip(results) {
        let mut part = r?;
        for run in &mut part.runs {
            run.name = format!("part {} (seed {})", i + 1, seed + i);
        }
        all.append(part);
    }
    Ok(all)
}

/// The statistics of `channel`'s recorded samples in `path` (CSV or MCAP, read with
/// [`glrmon_input::Samples`]) through a fresh monitor; a row or payload that cannot be
/// used is skipped, as the monitor never sees it live.
///
/// # Errors
/// [`CalibrateError::Input`] when the file cannot be opened or read,
/// [`CalibrateError::Captured`] for a recording made in capture mode,
/// [`CalibrateError::NoUsableSample`] when no sample gives an l_k,
/// [`CalibrateError::Monitor`] when the monitor cannot be built.
pub fn recorded(
    channel: &Channel,
    path: &Path,
    progress: Option<Progress<'_>>,
) -> Result<Statistics, CalibrateError> {
    // Capture mode keeps inputs only around alarms: the data were chosen by the
    // threshold in force, and would bias l_k's tail upwards. Only the daemon's
    // recorder captures; it alone names its `instance` in the file's header
    // (`glrmon simulate` and `replay` write whole runs, whatever the configuration).
    if InputFormat::of(path) == InputFormat::Mcap {
        let input = McapInput::open(path)?;
        let by_daemon = input
            .header
            .as_ref()
            .is_some_and(|h| h.extra.contains_key("instance"));
        if by_daemon
            && input
                .recorded_config()
                .is_ok_and(|c| c.recording.capture.is_some())
        {
            return Err(CalibrateError::Captured(path.to_owned()));
        }
    }
    let samples = RefCell::new(Samples::for_channel(path, channel)?);
    let mut skipped = Vec::new();
    let mut rows = 0u64;
    let mut stats = monitor_statistics(
        channel,
        |s| loop {
            let next = samples.borrow_mut().next_checked(s)?;
            match next {
                None => return Ok::<_, CalibrateError>(false),
                Some(Ok(())) => {
                    rows += 1;
                    return Ok(true);
                }
                Some(Err(Skipped { reason, message })) => {
                    rows += 1;
                    count_skip(&mut skipped, reason, || message);
                }
            }
        },
        |_| samples.borrow().position(),
        progress,
    )?;
    let Some(run) = stats.runs.first_mut() else {
        unreachable!("monitor_statistics gives one run");
    };
    // The reader's skips first: they come before the monitor in each row's path.
    for refused in std::mem::take(&mut run.skipped) {
        match skipped
            .iter_mut()
            .find(|s: &&mut Skips| s.reason == refused.reason)
        {
            Some(s) => s.count += refused.count,
            None => skipped.push(refused),
        }
    }
    run.name = path.display().to_string();
    run.rows = rows;
    run.skipped = skipped;
    if stats.glr.iter().all(|l| l.is_nan()) {
        let run = stats.runs.swap_remove(0);
        return Err(CalibrateError::NoUsableSample {
            path: path.to_owned(),
            channel: channel.name.clone(),
            rows: run.rows,
            skipped: run.skipped,
            processed: stats.glr.len() as u64,
        });
    }
    Ok(stats)
}

/// The statistics of several independent recordings of `channel` ([`recorded`] on
/// each, in order), pooled as separate segments: each file starts a fresh monitor, and
/// a NaN follows each file's l_k so that no episode spans two files. Two fault-free runs
/// joined in one file would instead meet at a jump of the state, which the monitor
/// rightly reads as a fault.
///
/// # Errors
/// The first file's error of [`recorded`] (each names its file).
pub fn recorded_files(
    channel: &Channel,
    paths: &[PathBuf],
    progress: Option<Progress<'_>>,
) -> Result<Statistics, CalibrateError> {
    let mut all = Statistics::default();
    for path in paths {
        all.append(recorded(channel, path, progress)?);
    }
    Ok(all)
}

/// The calibrated threshold of one isolation test.
#[derive(Debug, Clone, PartialEq)]
pub struct IsolationCalibration {
    /// The test: a fault, or a group's name.
    pub test: String,
    /// The (1 − α) quantile of its minmax statistic at r̂ (§5) on the data; `None` when
    /// the data are too few for α.
    pub quantile: Option<Quantile>,
    /// Fault-free samples of the test (those with an admissible onset).
    pub samples: u64,
    /// Of them, those at which the test had no degree of freedom
    /// ([`Statistics::spanned`]).
    pub spanned: u64,
    /// The threshold in force ([`current_isolation_threshold`]).
    pub current: f64,
    /// The fraction of the data above `current`.
    pub current_rate: f64,
    /// The χ² (1 − α) quantile with the test's degrees of freedom: the threshold a
    /// configuration without a calibrated one uses ([`chi2_isolation_threshold`]).
    pub chi2: f64,
}

/// Why an isolation test gets no calibrated threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum NotCalibrated {
    /// The statistic had no degree of freedom at any fault-free sample: the test's
    /// signature lies in the span of the other faults' over the window, so once they
    /// are rejected (eq. (41)) nothing is left, the statistic is 0 whatever the data
    /// and the fault can never be isolated alone.
    NotIsolable {
        /// Fault-free samples of the test.
        samples: u64,
    },
    /// Too few samples for α: the (1 − α) quantile needs 10 exceedances.
    TooFewSamples {
        /// Fault-free samples of the test.
        samples: u64,
        /// Samples the quantile needs (10 / α).
        needed: u64,
    },
    /// The (1 − α) quantile is not a finite positive number: the statistic had no
    /// degree of freedom (value 0) at more than a fraction 1 − α of the samples.
    NotPositive {
        /// The quantile.
        value: f64,
        /// Fault-free samples of the test.
        samples: u64,
        /// Of them, those without a degree of freedom.
        spanned: u64,
    },
}

impl std::fmt::Display for NotCalibrated {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Self::NotIsolable { samples } => write!(
                f,
                "its statistic is 0 on every fault-free sample ({samples}) because its \
                 signature lies in the span of the other faults' over the window (not \
                 isolable: nothing is left once they are rejected)"
            ),
            Self::TooFewSamples { samples, needed } => write!(
                f,
                "{samples} fault-free samples are too few: its (1 − α) quantile needs \
                 {needed} (10 above it)"
            ),
            Self::NotPositive {
                value,
                samples,
                spanned,
            } => write!(
                f,
                "its (1 − α) quantile is {value}, not a positive threshold: its signature \
                 lies in the span of the other faults' over the window (statistic 0) at \
                 {spanned} of {samples} fault-free samples"
            ),
        }
    }
}

impl IsolationCalibration {
    /// The calibrated threshold to write: the quantile, when it is finite and positive.
    #[must_use]
    pub fn threshold(&self) -> Option<f64> {
        self.quantile
            .map(|q| q.value)
            .filter(|v| v.is_finite() && *v > 0.0)
    }

    /// Why the test is not calibrated; `None` when [`IsolationCalibration::threshold`]
    /// is some.
    #[must_use]
    pub fn not_calibrated(&self, alpha: f64) -> Option<NotCalibrated> {
        if self.threshold().is_some() {
            return None;
        }
        Some(if self.samples > 0 && self.spanned == self.samples {
            NotCalibrated::NotIsolable {
                samples: self.samples,
            }
        } else {
            match self.quantile {
                None => NotCalibrated::TooFewSamples {
                    samples: self.samples,
                    needed: (10.0 / alpha).ceil() as u64,
                },
                Some(q) => NotCalibrated::NotPositive {
                    value: q.value,
                    samples: self.samples,
                    spanned: self.spanned,
                },
            }
        })
    }
}

/// The χ² upper quantile with the degrees of freedom of `test` (a group's size, 1 for
/// a fault) at `channel`'s `isolation_alpha` divided among its `isolation_onsets` (the
/// law `isolation_law` puts in force, as the monitor applies it): the isolation
/// threshold without a calibrated one; NaN when it cannot be computed.
#[must_use]
pub fn chi2_isolation_threshold(channel: &Channel, test: &str) -> f64 {
    let dof = channel
        .groups
        .iter()
        .find(|(n, _)| n == test)
        .map_or(1, |(_, f)| f.len().max(1));
    let alpha = channel.isolation_alpha / channel.isolation_onsets.max(1) as f64;
    glrmon_core::threshold::chi2_upper_quantile(dof as f64, alpha).unwrap_or(f64::NAN)
}

/// The isolation threshold `channel` uses now for `test`: its calibrated one, else
/// [`chi2_isolation_threshold`].
#[must_use]
pub fn current_isolation_threshold(channel: &Channel, test: &str) -> f64 {
    if let Some(&(_, t)) = channel.isolation_thresholds.iter().find(|(n, _)| n == test) {
        return t;
    }
    chi2_isolation_threshold(channel, test)
}

/// Each isolation test's threshold for `channel`'s type-I probability
/// `isolation_alpha`: the upper quantile of its fault-free minmax statistics
/// (`isolation`, as in [`Statistics::isolation`]; sorted in the process), with how
/// the threshold in force does on them. `spanned` counts, by test, the samples without
/// a degree of freedom ([`Statistics::spanned`]): a test with none at every sample is
/// not isolable ([`IsolationCalibration::not_calibrated`]). In test-name order.
#[must_use]
pub fn calibrate_isolation(
    channel: &Channel,
    isolation: BTreeMap<String, Vec<f64>>,
    spanned: &BTreeMap<String, u64>,
) -> Vec<IsolationCalibration> {
    let alpha = channel.isolation_alpha;
    isolation
        .into_iter()
        .map(|(test, mut values)| {
            let current = current_isolation_threshold(channel, &test);
            let exceeded =
                values.iter().filter(|&&v| v > current).count() as f64 / values.len().max(1) as f64;
            let quantile = upper_quantile(&mut values, alpha);
            IsolationCalibration {
                spanned: spanned.get(&test).copied().unwrap_or(0),
                chi2: chi2_isolation_threshold(channel, &test),
                samples: values.len() as u64,
                test,
                quantile,
                current,
                current_rate: exceeded,
            }
        })
        .collect()
}

/// One run's rate at the pooled calibrated threshold λ: is this run like the others?
#[derive(Debug, Clone, PartialEq)]
pub struct RunRate {
    /// The run ([`Run::name`]).
    pub name: String,
    /// Rows read and skipped, as in [`Run`].
    pub rows: u64,
    /// The rows skipped, by reason.
    pub skipped: Vec<Skips>,
    /// Samples with an admissible onset.
    pub samples: u64,
    /// Samples with l_k > λ.
    pub exceedances: u64,
    /// Episodes at λ (with the channel's hysteresis) for a [`Target::Mtbfa`];
    /// clusters of exceedances within the window for a [`Target::SampleFar`].
    pub events: u64,
    /// The rate in the target's unit: mean samples between episodes (infinite without
    /// one), or the fraction of samples above λ.
    pub rate: f64,
    /// Its 95 % interval, computed as the calibration's own ([`Calibration::rate_interval`]):
    /// Garwood on the episode count, or on the equivalent clusters of the compound
    /// Poisson count of exceedances.
    pub interval: (f64, f64),
}

/// A channel's calibration: [`calibrate_channel`]'s result.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelCalibration {
    /// The detection threshold for the target.
    pub alarm: Calibration,
    /// False-alarm episodes of the data at the channel's current threshold.
    pub current_episodes: u64,
    /// The isolation tests' thresholds ([`calibrate_isolation`]).
    pub isolation: Vec<IsolationCalibration>,
    /// Each run's rate at the calibrated threshold, in the order of the data.
    pub runs: Vec<RunRate>,
}

impl ChannelCalibration {
    /// The pairs of runs (i, j), i < j, whose 95 % rate intervals do not overlap: the
    /// runs differ by more than sampling explains (another noise level, another
    /// operating point), so a new run may see a rate outside the pooled interval.
    #[must_use]
    pub fn disagreements(&self) -> Vec<(usize, usize)> {
        let mut pairs = Vec::new();
        for (i, a) in self.runs.iter().enumerate() {
            for (j, b) in self.runs.iter().enumerate().skip(i + 1) {
                if a.interval.1 < b.interval.0 || b.interval.1 < a.interval.0 {
                    pairs.push((i, j));
                }
            }
        }
        pairs
    }
}

/// Each run's rate at `threshold` with its 95 % interval (see [`RunRate`]).
fn run_rates(
    runs: &[Run],
    glr: &[f64],
    threshold: f64,
    target: Target,
    alarm: AlarmSettings,
    memory: usize,
) -> Vec<RunRate> {
    runs.iter()
        .map(|run| {
            let l = &glr[run.range.clone()];
            let samples = l.iter().filter(|v| !v.is_nan()).count() as u64;
            let n = samples.max(1) as f64;
            let (exceedances, clusters, squares) = calibration::clusters(l, threshold, memory);
            let (events, rate, interval) = match target {
                Target::Mtbfa(_) => {
                    let episodes = count_episodes(l, AlarmSettings { threshold, ..alarm });
                    let (low, high) = calibration::garwood_events(episodes as f64);
                    let rate = if episodes == 0 {
                        f64::INFINITY
                    } else {
                        n / episodes as f64
                    };
                    let slow = if low > 0.0 { n / low } else { f64::INFINITY };
                    (episodes, rate, (n / high, slow))
                }
                Target::SampleFar(_) => {
                    let effective = if clusters == 0 {
                        0.0
                    } else {
                        (exceedances as f64).powi(2) / squares
                    };
                    let (low, high) = calibration::garwood_events(effective);
                    let per_event = if clusters == 0 {
                        1.0 / n
                    } else {
                        exceedances as f64 / effective / n
                    };
                    (
                        clusters,
                        exceedances as f64 / n,
                        ((per_event * low).min(1.0), (per_event * high).min(1.0)),
                    )
                }
            };
            RunRate {
                name: run.name.clone(),
                rows: run.rows,
                skipped: run.skipped.clone(),
                samples,
                exceedances,
                events,
                rate,
                interval,
            }
        })
        .collect()
}

/// Calibrates `channel` on its fault-free `stats`: the detection threshold for the
/// `target` (episodes as the channel's hysteresis and clearing make them, or
/// exceedances clustered within the window), each isolation test's threshold, and
/// each run's rate at the threshold. Fewer than 10 events expected at the target still
/// give a threshold: see [`Calibration::well_supported`].
///
/// # Errors
/// [`CalibrateError::Calibration`] when the target is impossible, no sample has an
/// admissible onset, or no false alarm can be formed on the data.
pub fn calibrate_channel(
    channel: &Channel,
    mut stats: Statistics,
    target: Target,
) -> Result<ChannelCalibration, CalibrateError> {
    let g = &channel.alarm;
    let current_episodes = count_episodes(&stats.glr, *g);
    // The GLR's l_k shares the innovations of its window with its neighbours; the
    // plain χ² detector's statistic has no memory.
    let memory = channel.detector()?.memory();
    let alarm = match target {
        Target::Mtbfa(m) => calibrate(&stats.glr, m, g.hysteresis, g.clear_samples),
        Target::SampleFar(f) => calibrate_sample_far(&stats.glr, f, memory),
    }
    .map_err(|reason| CalibrateError::Calibration {
        channel: channel.name.clone(),
        reason,
    })?;
    if stats.runs.is_empty() {
        stats.runs.push(Run {
            name: "run 1".to_owned(),
            range: 0..stats.glr.len(),
            rows: stats.glr.len() as u64,
            skipped: Vec::new(),
        });
    }
    let alarm_settings = AlarmSettings {
        clear_samples: g.clear_samples.max(1),
        ..*g
    };
    let runs = run_rates(
        &stats.runs,
        &stats.glr,
        alarm.threshold,
        target,
        alarm_settings,
        memory,
    );
    Ok(ChannelCalibration {
        alarm,
        current_episodes,
        isolation: calibrate_isolation(channel, stats.isolation, &stats.spanned),
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel() -> Channel {
        let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
        cfg.pick_channel(Some("unstable")).unwrap().clone()
    }

    #[test]
    fn a_short_simulated_run_has_one_statistic_per_sample_and_test() {
        let channel = channel();
        let calls = std::sync::atomic::AtomicU64::new(0);
        let count = |d: u64| {
            calls.fetch_add(d, std::sync::atomic::Ordering::Relaxed);
        };
        let stats = simulated(&channel, 500, 3, Some(&count)).unwrap();
        // One part (under 10 000 samples), then the NaN that ends it.
        assert_eq!(stats.glr.len(), 501);
        assert!(stats.glr[500].is_nan());
        assert!(stats.glr[..500].iter().any(|l| l.is_finite()));
        // The isolation tests run where an onset is admissible, i.e. where l_k is.
        let admissible = stats.glr.iter().filter(|l| !l.is_nan()).count();
        assert!(admissible > 400, "{admissible}");
        assert_eq!(stats.isolation.len(), channel.fault_names.len());
        for values in stats.isolation.values() {
            assert_eq!(values.len(), admissible);
        }
        // Fewer samples than one progress step.
        assert_eq!(calls.into_inner(), 0);
        // The same seed gives the same statistics (NaN compared by bits).
        let again = simulated(&channel, 500, 3, None).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&stats.glr), bits(&again.glr));
    }

    /// Too few episodes for the target give a loosely supported threshold;
    /// no admissible sample is the user's error, naming the channel.
    #[test]
    fn too_little_data_warns_and_no_sample_is_an_error_naming_the_channel() {
        let channel = channel();
        let stats = simulated(&channel, 2_000, 1, None).unwrap();
        let c = calibrate_channel(&channel, stats, Target::Mtbfa(1_000.0)).unwrap();
        assert!(!c.alarm.well_supported(), "{c:?}");
        assert!(c.alarm.expected < 2.1, "{c:?}");
        let stats = Statistics {
            glr: vec![f64::NAN; 10],
            ..Statistics::default()
        };
        let e = calibrate_channel(&channel, stats, Target::SampleFar(0.01)).unwrap_err();
        assert!(e.is_invalid_input(), "{e:?}");
        assert!(
            e.to_string()
                .starts_with("channel \"unstable\": no fault-free sample"),
            "{e}"
        );
    }

    #[test]
    fn the_isolation_threshold_is_the_upper_quantile_and_the_rate_that_of_the_current() {
        let channel = channel();
        let test = channel.fault_names[0].clone();
        let values: Vec<f64> = (0..10_000).map(f64::from).collect();
        let current = current_isolation_threshold(&channel, &test);
        let iso = calibrate_isolation(
            &channel,
            BTreeMap::from([(test.clone(), values)]),
            &BTreeMap::new(),
        );
        assert_eq!(iso.len(), 1);
        assert_eq!(iso[0].test, test);
        assert_eq!(iso[0].current, current);
        let above = (0..10_000).filter(|&v| f64::from(v) > current).count();
        assert_eq!(iso[0].current_rate, above as f64 / 10_000.0);
        let q = iso[0].quantile.unwrap();
        let alpha = channel.isolation_alpha;
        assert!((q.value - 10_000.0 * (1.0 - alpha)).abs() <= 2.0, "{q:?}");
        assert_eq!(iso[0].threshold(), Some(q.value));
        assert_eq!(iso[0].not_calibrated(alpha), None);
    }

    /// A channel identified with fewer states (2) than inputs (3) and a feedthrough J:
    /// an actuator bias b in the null space of G moves no state and shows only as J·b
    /// at the outputs, exactly as the sensor biases J·b would. Every fault of the
    /// dictionary is in such a dependence, so every minmax statistic is 0 (no degree
    /// of freedom) on every sample: none is calibrated, each says why, and the χ²
    /// threshold is what stays.
    const SPANNED: &str = include_str!("../../../tests/data/spanned.toml");

    #[test]
    fn a_test_spanned_by_the_other_faults_is_not_calibrated_and_says_why() {
        let cfg = glrmon_spec::parse(SPANNED).unwrap();
        let channel = cfg.pick_channel(None).unwrap();
        let stats = simulated(channel, 3_000, 1, None).unwrap();
        assert_eq!(stats.isolation.len(), 7);
        let c = calibrate_channel(channel, stats, Target::SampleFar(0.01)).unwrap();
        assert!(c.alarm.threshold > 0.0, "{c:?}");
        let alpha = channel.isolation_alpha;
        for i in &c.isolation {
            assert_eq!(i.spanned, i.samples, "{i:?}");
            assert!(i.samples > 2_900, "{i:?}");
            assert_eq!(i.quantile.map(|q| q.value), Some(0.0), "{i:?}");
            assert_eq!(i.threshold(), None, "{i:?}");
            let why = i.not_calibrated(alpha).unwrap();
            assert_eq!(why, NotCalibrated::NotIsolable { samples: i.samples });
            assert!(
                why.to_string().contains("span of the other faults'"),
                "{why}"
            );
            // The law in force: χ²(1) at α/(w − s) (Bonferroni over the window).
            let onsets = channel.isolation_onsets as f64;
            let want = glrmon_core::threshold::chi2_upper_quantile(1.0, alpha / onsets).unwrap();
            assert!((i.chi2 - want).abs() < 1e-9, "{i:?}: {want}");
        }
        // Without the actuators (n = 2 ≥ 0 inputs under test) the sensors are isolable.
        let text = SPANNED.replace("[[channels.faults]]\nkind = \"all_actuators\"\n", "");
        let cfg = glrmon_spec::parse(&text).unwrap();
        let channel = cfg.pick_channel(None).unwrap();
        let stats = simulated(channel, 3_000, 1, None).unwrap();
        let c = calibrate_channel(channel, stats, Target::SampleFar(0.01)).unwrap();
        assert_eq!(c.isolation.len(), 4);
        for i in &c.isolation {
            assert_eq!(i.spanned, 0, "{i:?}");
            assert!(i.threshold().is_some_and(|t| t > 1.0), "{i:?}");
        }
    }

    /// Too few samples for α, and a quantile of 0 where some samples keep a degree of
    /// freedom, are told apart from a test that is never isolable.
    #[test]
    fn too_few_samples_and_a_zero_quantile_are_other_reasons() {
        let channel = channel();
        let test = channel.fault_names[0].clone();
        let few = calibrate_isolation(
            &channel,
            BTreeMap::from([(test.clone(), vec![1.0; 50])]),
            &BTreeMap::new(),
        );
        assert_eq!(
            few[0].not_calibrated(0.01),
            Some(NotCalibrated::TooFewSamples {
                samples: 50,
                needed: 1_000
            })
        );
        let mut values = vec![0.0; 2_000];
        values[..10].fill(3.0);
        let zero = calibrate_isolation(
            &channel,
            BTreeMap::from([(test.clone(), values)]),
            &BTreeMap::from([(test, 1_990)]),
        );
        assert_eq!(
            zero[0].not_calibrated(0.01),
            Some(NotCalibrated::NotPositive {
                value: 0.0,
                samples: 2_000,
                spanned: 1_990
            })
        );
    }

    /// Each run's rate at the pooled threshold, with its interval; runs whose
    /// intervals do not overlap are named, runs from one law are not.
    #[test]
    fn runs_that_differ_beyond_their_intervals_are_named() {
        let channel = channel();
        let mut stats = simulated(&channel, 5_000, 1, None).unwrap();
        stats.append(simulated(&channel, 5_000, 2, None).unwrap());
        let c = calibrate_channel(&channel, stats.clone(), Target::SampleFar(0.05)).unwrap();
        assert_eq!(c.runs.len(), 2);
        assert_eq!(c.runs[0].name, "part 1 (seed 1)");
        assert_eq!(c.runs[1].name, "part 1 (seed 2)");
        for r in &c.runs {
            assert!(r.interval.0 <= r.rate && r.rate <= r.interval.1, "{r:?}");
            assert_eq!(r.rows, 5_000);
        }
        let total: u64 = c.runs.iter().map(|r| r.exceedances).sum();
        assert_eq!(total, c.alarm.exceedances);
        assert_eq!(
            c.disagreements(),
            Vec::<(usize, usize)>::new(),
            "{:?}",
            c.runs
        );
        // A third run whose l_k are all far above: it disagrees with both.
        let mut loud = Statistics {
            glr: vec![1e3; 5_000],
            ..Statistics::default()
        };
        loud.glr[0] = f64::NAN;
        stats.append(loud);
        let c = calibrate_channel(&channel, stats, Target::Mtbfa(500.0)).unwrap();
        assert_eq!(c.runs[2].name, "run 3");
        assert_eq!(c.disagreements(), vec![(0, 2), (1, 2)], "{:?}", c.runs);
    }
}
