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

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glrmon_core::threshold::calibration::{
    Calibration, CalibrationError, Quantile, Target, calibrate, calibrate_sample_far,
    count_episodes, upper_quantile,
};
use glrmon_input::{InputError, InputFormat, McapInput, Samples};
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
    /// A recorded file holds no sample that gives the channel an l_k.
    #[error(
        "{}: no usable sample of channel \"{channel}\": {skipped} rows or payloads could not \
         be used{}, {processed} samples processed by the monitor, none with an admissible \
         onset",
        path.display(),
        first_skip.as_ref().map_or_else(String::new, |r| format!(" (first: {r})"))
    )]
    NoUsableSample {
        /// The file.
        path: PathBuf,
        /// The channel calibrated.
        channel: String,
        /// Rows or payloads of the channel that could not be used.
        skipped: u64,
        /// Why the first of them could not be used.
        first_skip: Option<String>,
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

/// What the channel's monitor gave on fault-free data.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Statistics {
    /// The GLR statistic l_k (Zhang & Basseville 2014, eq. (35)) of every sample the
    /// monitor produced a statistic for, in order; NaN where no onset is admissible.
    pub glr: Vec<f64>,
    /// The minmax isolation statistic at r̂ (§5) of each isolation test, by test name,
    /// one value per sample with an admissible onset.
    pub isolation: BTreeMap<String, Vec<f64>>,
}

impl Statistics {
    /// Appends the statistics of an independent run as a separate segment: its l_k,
    /// then a NaN so that no episode spans the two; its isolation statistics pooled.
    pub fn append(&mut self, run: Statistics) {
        self.glr.extend(run.glr);
        self.glr.push(f64::NAN);
        for (test, values) in run.isolation {
            self.isolation.entry(test).or_default().extend(values);
        }
    }
}

/// The statistics of `channel`'s monitor fed with the samples `next` writes into its
/// argument, until it returns `Ok(false)`. A sample the monitor rejects contributes
/// nothing. `progress` is called every 65 536 samples.
///
/// # Errors
/// The first error of `next`, or the monitor's [`glrmon_core::ModelError`] when it
/// cannot be built.
pub fn statistics<E: From<glrmon_core::ModelError>>(
    channel: &Channel,
    mut next: impl FnMut(&mut Sample) -> Result<bool, E>,
    progress: Option<Progress<'_>>,
) -> Result<Statistics, E> {
    let mut mon = Monitor::from_channel(channel)?;
    let mut sample = Sample::default();
    let mut records = Vec::new();
    let mut stats = Statistics::default();
    let mut n = 0u64;
    while next(&mut sample)? {
        mon.on_sample(&sample, &mut records);
        for r in records.drain(..) {
            if let Record::Stat(s) = r {
                stats.glr.push(s.glr.unwrap_or(f64::NAN));
                for (test, value) in mon.isolation_statistics() {
                    stats.isolation.entry(test).or_default().push(value);
                }
            }
        }
        n += 1;
        if n.is_multiple_of(PROGRESS_STEP)
            && let Some(p) = progress
        {
            p(PROGRESS_STEP);
        }
    }
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
    for r in results {
        all.append(r?);
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
    let mut samples = Samples::for_channel(path, channel)?;
    let (mut skipped, mut first_skip) = (0u64, None);
    let stats = statistics(
        channel,
        |s| loop {
            match samples.next_into(s)? {
                None => return Ok::<_, CalibrateError>(false),
                Some(Ok(())) => return Ok(true),
                Some(Err(why)) => {
                    skipped += 1;
                    first_skip.get_or_insert(why);
                }
            }
        },
        progress,
    )?;
    if stats.glr.iter().all(|l| l.is_nan()) {
        return Err(CalibrateError::NoUsableSample {
            path: path.to_owned(),
            channel: channel.name.clone(),
            skipped,
            first_skip,
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
    /// The threshold in force ([`current_isolation_threshold`]).
    pub current: f64,
    /// The fraction of the data above `current`.
    pub current_rate: f64,
}

/// The isolation threshold `channel` uses now for `test`: its calibrated one, else the
/// χ² (1 − α) quantile with the test's degrees of freedom (a group's size, 1 for a
/// fault); NaN when that quantile cannot be computed.
#[must_use]
pub fn current_isolation_threshold(channel: &Channel, test: &str) -> f64 {
    if let Some(&(_, t)) = channel.isolation_thresholds.iter().find(|(n, _)| n == test) {
        return t;
    }
    let dof = channel
        .groups
        .iter()
        .find(|(n, _)| n == test)
        .map_or(1, |(_, f)| f.len().max(1));
    glrmon_core::threshold::chi2_upper_quantile(dof as f64, channel.isolation_alpha)
        .unwrap_or(f64::NAN)
}

/// Each isolation test's threshold for `channel`'s type-I probability
/// `isolation_alpha`: the upper quantile of its fault-free minmax statistics
/// (`isolation`, as in [`Statistics::isolation`]; sorted in the process), with how
/// the threshold in force does on them. In test-name order.
#[must_use]
pub fn calibrate_isolation(
    channel: &Channel,
    isolation: BTreeMap<String, Vec<f64>>,
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
                test,
                quantile,
                current,
                current_rate: exceeded,
            }
        })
        .collect()
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
}

/// Calibrates `channel` on its fault-free `stats`: the detection threshold for the
/// `target` (episodes as the channel's hysteresis and clearing make them, or
/// exceedances clustered within the window) and each isolation test's threshold.
/// Fewer than 10 events expected at the target still give a threshold: see
/// [`Calibration::well_supported`].
///
/// # Errors
/// [`CalibrateError::Calibration`] when the target is impossible, no sample has an
/// admissible onset, or no false alarm can be formed on the data.
pub fn calibrate_channel(
    channel: &Channel,
    stats: Statistics,
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
    Ok(ChannelCalibration {
        alarm,
        current_episodes,
        isolation: calibrate_isolation(channel, stats.isolation),
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
            isolation: BTreeMap::new(),
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
        let iso = calibrate_isolation(&channel, BTreeMap::from([(test.clone(), values)]));
        assert_eq!(iso.len(), 1);
        assert_eq!(iso[0].test, test);
        assert_eq!(iso[0].current, current);
        let above = (0..10_000).filter(|&v| f64::from(v) > current).count();
        assert_eq!(iso[0].current_rate, above as f64 / 10_000.0);
        let q = iso[0].quantile.unwrap();
        let alpha = channel.isolation_alpha;
        assert!((q.value - 10_000.0 * (1.0 - alpha)).abs() <= 2.0, "{q:?}");
    }
}
