#![doc = include_str!("../README.md")]

pub mod calibrate;
pub mod compare;
pub mod identify;
pub mod noise;
pub mod validation;

use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_monitor::{IsolationGroup, Monitor};
use glrmon_report::{DecisionError, FaultEvaluation, MinmaxEvaluation};
use glrmon_sim::SimSample;
use glrmon_spec::Channel;
use glrmon_wire::{Record, Sample};
use serde::Serialize;

/// What one run gave (an element of `runs` in `glrmon evaluate --json`).
///
/// The detection is the first alarm at or after the onset; the monitor raises it at
/// the crossing (the first sample of its episode with l_k > λ), so `crossing` minus
/// the onset is the detection delay a consumer of the `alarm` records sees. Onset and
/// isolation are that alarm's last ones: from its `isolation` update,
/// `isolation_delay` samples later, if its episode lasted that long, else from the
/// alarm itself (`isolated_at` tells which).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Run {
    /// k of the first alarm at or after the onset: its crossing of the threshold.
    pub crossing: Option<u64>,
    /// r̂ of that alarm's last isolation.
    pub onset_estimate: Option<u64>,
    /// Faults isolated by that alarm's last isolation.
    pub isolated: Vec<String>,
    /// Faults that isolation reported ambiguous (not told apart once the onset is
    /// free; none of them isolated).
    pub ambiguous: Vec<String>,
    /// The sample of that isolation: the alarm's `k`, or its update's.
    pub isolated_at: Option<u64>,
    /// Alarms raised before the onset.
    pub false_alarms: u64,
    /// Each isolation test's minmax statistic at that isolation, in the order of the
    /// channel's tests; in the JSON only as [`FaultResult::minmax`], per test.
    #[serde(skip)]
    pub minmax: Vec<MinmaxOutcome>,
}

/// One isolation test at a run's isolation: its minmax statistic l_a (Zhang & Basseville
/// 2014, eq. (41)), the threshold it was compared with and the decision.
#[derive(Debug, Clone, PartialEq)]
pub struct MinmaxOutcome {
    /// The test (a fault, or an isolation group).
    pub test: String,
    /// l_a at the isolation's onset estimate r̂.
    pub statistic: f64,
    /// The threshold in force: calibrated, or the χ²(dof) upper α quantile.
    pub threshold: f64,
    /// Degrees of freedom of l_a's centred χ² under θ_a = 0: the numerical rank of the
    /// test's Fisher information F*_a, as the monitor took it for the threshold.
    pub dof: u32,
    /// Whether the test declared θ_a ≠ 0 (l_a above the threshold; whether the fault
    /// was then isolated also depends on the onset-free check, [`Run::ambiguous`]).
    pub fired: bool,
}

/// Results for one injected fault (an element of `results` in `glrmon evaluate --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultResult {
    /// The injected fault.
    pub fault: String,
    /// Its magnitude θ.
    pub magnitude: f64,
    /// One entry per run, in seed order.
    pub runs: Vec<Run>,
    /// Per isolation test, its minmax statistics over the runs and its error rate
    /// (Zhang & Basseville 2014, Fig. 8 and eq. (42)).
    pub minmax: Vec<MinmaxTest>,
}

/// One isolation test over the runs of one injected fault (an element of `minmax` in
/// `glrmon evaluate --json`): the data of a Zhang & Basseville 2014 Fig. 8 histogram
/// and the empirical error rate of eq. (42).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MinmaxTest {
    /// The test (a fault, or an isolation group).
    pub test: String,
    /// The faults it focuses on (θ_a).
    pub faults: Vec<String>,
    /// The threshold of the runs (the most common one should they differ, as the rank
    /// of F*_a can); without runs, the one the monitor would start from.
    pub threshold: f64,
    /// Degrees of freedom of the centred χ² of l_a under θ_a = 0, chosen as `threshold`.
    pub dof: u32,
    /// l_a of each run that isolated (`isolated_at` set), in seed order; `null` in the
    /// JSON for a statistic that is not finite.
    pub statistics: Vec<f64>,
    /// Runs in which the test fired.
    pub fired: u64,
    /// The fraction of `statistics` that made the test's error.
    #[serde(flatten)]
    pub error_rate: ErrorRate,
}

/// The error an isolation test can make for an injected fault, and its empirical rate
/// over the runs that isolated (`None`, `null` in the JSON, without any): the JSON key
/// names the type (Zhang & Basseville 2014, eq. (42)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum ErrorRate {
    /// The test's faults exclude the injected one (θ_a = 0): the fraction of runs in
    /// which it fired.
    #[serde(rename = "type_i_rate")]
    TypeI(Option<f64>),
    /// The test's faults include the injected one (θ_a ≠ 0): the fraction of runs in
    /// which it did not fire.
    #[serde(rename = "type_ii_rate")]
    TypeII(Option<f64>),
}

impl ErrorRate {
    /// The type of error.
    #[must_use]
    pub fn kind(self) -> DecisionError {
        match self {
            Self::TypeI(_) => DecisionError::TypeI,
            Self::TypeII(_) => DecisionError::TypeII,
        }
    }

    /// The rate, `None` without runs.
    #[must_use]
    pub fn rate(self) -> Option<f64> {
        match self {
            Self::TypeI(r) | Self::TypeII(r) => r,
        }
    }
}

/// How a Monte-Carlo evaluation runs: `runs` seeds from `seed` per injected fault, the
/// fault at `onset`, `samples` samples per run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Protocol {
    /// Sample index of every injection.
    pub onset: u64,
    /// Samples per run.
    pub samples: u64,
    /// Runs per injected fault.
    pub runs: u64,
    /// Seed of the first run (run i uses `seed + i`).
    pub seed: u64,
    /// The sample from which the injected fault is gone again (a fault that ends: the
    /// survey's actuator stuck from 2.5 s to 3.5 s), or `None` for a fault that lasts.
    pub end: Option<u64>,
}

impl Protocol {
    /// The protocol for `channel`: the onset defaults to 3w (a full window of fault-free
    /// samples twice over before it) and the length to onset + 2w (w the window).
    ///
    /// # Errors
    /// [`EvalError::Protocol`] for no runs or a run that ends before the onset.
    pub fn for_channel(
        channel: &Channel,
        onset: Option<u64>,
        samples: Option<u64>,
        runs: u64,
        seed: u64,
    ) -> Result<Self, EvalError> {
        if runs == 0 {
            return Err(EvalError::Protocol("--runs must be at least 1".into()));
        }
        let w = channel.window.window as u64;
        let onset = onset.unwrap_or(3 * w);
        let samples = samples.unwrap_or(onset + 2 * w);
        if samples <= onset {
            return Err(EvalError::Protocol(format!(
                "--samples {samples} ends before the onset {onset}"
            )));
        }
        Ok(Self {
            onset,
            samples,
            runs,
            seed,
            end: None,
        })
    }

    /// The protocol with the injected fault gone from sample `end` on.
    ///
    /// # Errors
    /// [`EvalError::Protocol`] when `end` is not after the onset.
    pub fn with_end(self, end: Option<u64>) -> Result<Self, EvalError> {
        if let Some(end) = end
            && end <= self.onset
        {
            return Err(EvalError::Protocol(format!(
                "--end {end} is not after the onset {}",
                self.onset
            )));
        }
        Ok(Self { end, ..self })
    }
}

/// Why an evaluation could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// The protocol is impossible (the message names the flag).
    #[error("{0}")]
    Protocol(String),
    /// The channel's simulator could not be built or the fault injected.
    #[error(transparent)]
    Simulator(#[from] glrmon_sim::ChannelError),
    /// The channel's monitor could not be built.
    #[error(transparent)]
    Monitor(#[from] glrmon_core::ModelError),
    /// A worker thread panicked.
    #[error("an evaluation thread panicked")]
    Panicked,
}

impl EvalError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub fn is_invalid_input(&self) -> bool {
        matches!(self, Self::Protocol(_))
    }
}

/// Runs `protocol` for each `(fault, magnitude)` of `injected`, the runs of each fault
/// spread over the machine's cores; results in seed order, whatever the thread count.
///
/// # Errors
/// The first [`EvalError`] of a run.
pub fn evaluate(
    channel: &Channel,
    injected: &[(String, f64)],
    protocol: Protocol,
) -> Result<Vec<FaultResult>, EvalError> {
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get) as u64;
    let Protocol {
        onset,
        samples,
        runs,
        seed,
        end,
    } = protocol;
    let groups = Monitor::from_channel(channel)?.isolation_groups().to_vec();
    let mut results = Vec::new();
    for (fault, magnitude) in injected {
        let outcomes: Vec<Result<Run, EvalError>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || {
                        (0..runs)
                            .filter(|i| i % threads == t)
                            .map(|i| {
                                one_run(channel, seed + i, fault, *magnitude, (onset, end), samples)
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_else(|_| vec![Err(EvalError::Panicked)]))
                .collect()
        });
        let runs: Vec<Run> = outcomes.into_iter().collect::<Result<_, _>>()?;
        results.push(FaultResult {
            fault: fault.clone(),
            magnitude: *magnitude,
            minmax: minmax_tests(channel, &groups, fault, &runs),
            runs,
        });
    }
    Ok(results)
}

/// One run: the channel simulated with `seed`, `fault` of `magnitude` injected at
/// `onset` (until `end`, when given), `samples` samples through the channel's monitor
/// as live.
///
/// # Errors
/// [`EvalError`] when the simulator or the monitor cannot be built for the channel.
pub fn one_run(
    channel: &Channel,
    seed: u64,
    fault: &str,
    magnitude: f64,
    (onset, end): (u64, Option<u64>),
    samples: u64,
) -> Result<Run, EvalError> {
    let mut sim = simulator(channel, seed, fault, magnitude, onset)?;
    if let Some(end) = end {
        sim = sim.with_fault_end(end);
    }
    let mut mon = Monitor::from_channel(channel)?;
    let tests = mon.isolation_groups().to_vec();
    // Detection, onset and isolation come from the alarm and isolation records.
    mon.set_stat_records(false);
    let mut x = SimSample {
        k: 0,
        u: vec![],
        y: vec![],
        p: vec![],
    };
    let mut sample = Sample::default();
    let mut records = Vec::new();
    let mut run = Run::default();
    for _ in 0..samples {
        sim.next_into(&mut x);
        sample.k = Some(x.k);
        sample.u.clone_from(&x.u);
        sample.y.clone_from(&x.y);
        sample.p.clone_from(&x.p);
        mon.on_sample(&sample, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Alarm(a) if a.k < onset => run.false_alarms += 1,
                Record::Alarm(a) if run.crossing.is_none() => {
                    run.crossing = Some(a.k);
                    run.onset_estimate = Some(a.onset);
                    run.isolated = isolated(&a.isolation);
                    run.ambiguous = ambiguous(&a.isolation);
                    run.isolated_at = Some(a.k);
                    run.minmax = minmax_outcomes(&mon, &tests, a.onset, &a.isolation);
                }
                Record::Isolation(u) if run.crossing == Some(u.alarm_k) => {
                    run.onset_estimate = Some(u.onset);
                    run.isolated = isolated(&u.isolation);
                    run.ambiguous = ambiguous(&u.isolation);
                    run.isolated_at = Some(u.k);
                    run.minmax = minmax_outcomes(&mon, &tests, u.onset, &u.isolation);
                }
                _ => {}
            }
        }
    }
    Ok(run)
}

/// The channel's simulator with `fault` of `magnitude` injected from `onset`, the noise
/// seeded with `seed`: what [`one_run`] feeds its monitor.
///
/// # Errors
/// [`EvalError::Simulator`] when the simulator cannot be built or the fault injected.
pub fn simulator(
    channel: &Channel,
    seed: u64,
    fault: &str,
    magnitude: f64,
    onset: u64,
) -> Result<glrmon_sim::Simulator, EvalError> {
    Ok(glrmon_sim::faulty_simulator(
        channel,
        seed,
        &[(fault.to_owned(), magnitude)],
        onset,
    )?)
}

fn isolated(tests: &[glrmon_wire::IsolationResult]) -> Vec<String> {
    tests
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.clone())
        .collect()
}

fn ambiguous(tests: &[glrmon_wire::IsolationResult]) -> Vec<String> {
    tests
        .iter()
        .filter(|i| !i.ambiguous_with.is_empty())
        .map(|i| i.fault.clone())
        .collect()
}

/// The minmax outcomes of an isolation the monitor just made at onset estimate `onset`:
/// statistic, threshold and decision from its record, the degrees of freedom from the
/// detector, still at the sample of that isolation (the record does not carry them).
fn minmax_outcomes(
    mon: &Monitor,
    tests: &[IsolationGroup],
    onset: u64,
    isolation: &[glrmon_wire::IsolationResult],
) -> Vec<MinmaxOutcome> {
    // Exclusion tests (the kernel kind) are no minmax tests: a residual above its
    // threshold rules its fault out instead of naming it.
    if isolation.iter().any(|r| r.excluded.is_some()) {
        return Vec::new();
    }
    let fisher = mon.detector().fisher_statistics(onset);
    isolation
        .iter()
        .map(|r| {
            let faults = tests.iter().find(|g| g.name == r.fault).map(|g| &g.faults);
            let dof = match (&fisher, faults) {
                (Some(fisher), Some(faults)) => {
                    fisher.minmax(faults).map_or(faults.len(), |m| m.dof.max(1))
                }
                (None, Some(faults)) => faults.len(),
                (_, None) => 1,
            };
            MinmaxOutcome {
                test: r.fault.clone(),
                statistic: r.minmax,
                threshold: r.threshold,
                dof: u32::try_from(dof).unwrap_or(u32::MAX),
                // The minmax test's own decision (Fig. 8), before the onset-free check
                // that may leave a fault ambiguous.
                fired: r.minmax > r.threshold,
            }
        })
        .collect()
}

/// Each isolation test (`groups`, as the channel's monitor runs them:
/// [`Monitor::isolation_groups`]) with its statistics over `runs` of the injected
/// `fault`, with the
/// type-II rate (the test's faults include `fault`: runs in which it did not fire) or
/// the type-I rate (they do not: runs in which it fired), as Zhang & Basseville 2014
/// report them for Fig. 8 (eq. (42)).
#[must_use]
pub fn minmax_tests(
    channel: &Channel,
    groups: &[IsolationGroup],
    fault: &str,
    runs: &[Run],
) -> Vec<MinmaxTest> {
    // A kind that isolates by exclusion (kernel) has no minmax tests to tabulate.
    if channel.detector_kind == glrmon_spec::DetectorKind::Kernel {
        return Vec::new();
    }
    let injected = channel.fault_names.iter().position(|f| f == fault);
    groups
        .iter()
        .map(|IsolationGroup { name: test, faults }| {
            let outcomes: Vec<&MinmaxOutcome> = runs
                .iter()
                .filter_map(|r| r.minmax.iter().find(|o| o.test == *test))
                .collect();
            let (threshold, dof) = most_common(outcomes.iter().map(|o| (o.threshold, o.dof)))
                .unwrap_or_else(|| {
                    let dof = faults.len().max(1);
                    let calibrated = channel
                        .isolation_thresholds
                        .iter()
                        .find(|(name, _)| *name == *test)
                        .map(|t| t.1);
                    let threshold = calibrated.unwrap_or_else(|| {
                        chi2_upper_quantile(dof as f64, channel.isolation_alpha).unwrap_or(f64::NAN)
                    });
                    (threshold, u32::try_from(dof).unwrap_or(u32::MAX))
                });
            let n = outcomes.len() as u64;
            let fired = outcomes.iter().filter(|o| o.fired).count() as u64;
            let fraction = |k: u64| (n > 0).then(|| k as f64 / n as f64);
            let error_rate = if injected.is_some_and(|j| faults.contains(&j)) {
                ErrorRate::TypeII(fraction(n - fired))
            } else {
                ErrorRate::TypeI(fraction(fired))
            };
            MinmaxTest {
                faults: faults
                    .iter()
                    .filter_map(|j| channel.fault_names.get(*j).cloned())
                    .collect(),
                test: test.clone(),
                threshold,
                dof,
                statistics: outcomes.iter().map(|o| o.statistic).collect(),
                fired,
                error_rate,
            }
        })
        .collect()
}

/// The (threshold, dof) pair most runs had; the first of equally common ones.
fn most_common(pairs: impl Iterator<Item = (f64, u32)>) -> Option<(f64, u32)> {
    let mut counts: Vec<((f64, u32), usize)> = Vec::new();
    for p in pairs {
        match counts
            .iter_mut()
            .find(|(q, _)| q.0.to_bits() == p.0.to_bits() && q.1 == p.1)
        {
            Some((_, c)) => *c += 1,
            None => counts.push((p, 1)),
        }
    }
    counts.iter().rev().max_by_key(|(_, c)| *c).map(|(p, _)| *p)
}

/// Columns of the confusion matrix: the dictionary's faults, any other isolated name
/// (an isolation group), then the outcomes without a single isolated fault.
#[must_use]
pub fn outcome_columns(faults: &[String], results: &[FaultResult]) -> Vec<String> {
    let mut columns: Vec<String> = faults.to_vec();
    let fixed = ["ambiguous", "none", "several", "undetected"];
    let mut others: Vec<String> = results
        .iter()
        .flat_map(|r| r.runs.iter().map(isolated_label))
        .filter(|l| !columns.contains(l) && !fixed.contains(&l.as_str()))
        .collect();
    others.sort_unstable();
    others.dedup();
    columns.extend(others);
    columns.extend(fixed.map(str::to_owned));
    columns
}

/// The figures of one injected fault that `glrmon evaluate`'s table and HTML report
/// state: detection rate, delay quantiles, onset errors, false alarms, the confusion
/// row over `columns` ([`outcome_columns`]).
#[must_use]
pub fn summarize(r: &FaultResult, onset: u64, columns: &[String]) -> FaultEvaluation {
    let delays: Vec<u64> = r
        .runs
        .iter()
        .filter_map(|x| x.crossing.map(|c| c - onset))
        .collect();
    let delays_f64: Vec<f64> = delays.iter().map(|d| *d as f64).collect();
    let delay_quantiles = match (
        quantile(delays_f64.clone(), 0.1),
        median(delays_f64.clone()),
        quantile(delays_f64, 0.9),
    ) {
        (Some(p10), Some(p50), Some(p90)) => Some([p10, p50, p90]),
        _ => None,
    };
    let onset_errors: Vec<i64> = r
        .runs
        .iter()
        .filter_map(|x| x.onset_estimate)
        .map(|e| i64::try_from(i128::from(e) - i128::from(onset)).unwrap_or(i64::MAX))
        .collect();
    let mut isolated = vec![0; columns.len()];
    for run in &r.runs {
        let label = isolated_label(run);
        if let Some(i) = columns.iter().position(|c| *c == label) {
            isolated[i] += 1;
        }
    }
    FaultEvaluation {
        fault: r.fault.clone(),
        magnitude: r.magnitude,
        runs: r.runs.len() as u64,
        detected: delays.len() as u64,
        delays,
        delay_quantiles,
        onset_error_median_abs: median(
            onset_errors
                .iter()
                .map(|e| e.unsigned_abs() as f64)
                .collect(),
        ),
        onset_errors,
        false_alarms: r.runs.iter().map(|x| x.false_alarms).sum(),
        runs_with_false_alarms: r.runs.iter().filter(|x| x.false_alarms > 0).count() as u64,
        isolated,
        minmax: r
            .minmax
            .iter()
            .map(|t| MinmaxEvaluation {
                test: t.test.clone(),
                faults: t.faults.clone(),
                error: t.error_rate.kind(),
                statistics: t.statistics.clone(),
                threshold: t.threshold,
                dof: t.dof,
                error_rate: t.error_rate.rate(),
            })
            .collect(),
    }
}

/// The median (mean of the middle two for an even count); `None` when empty.
#[must_use]
pub fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// The `p`-quantile, nearest rank; `None` when empty.
fn quantile(mut v: Vec<f64>, p: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    v.get(i).copied()
}

/// Column of the confusion matrix for a run: the isolated fault, `ambiguous` (none
/// isolated, some not told apart yet), `none`, or `several`.
fn isolated_label(r: &Run) -> String {
    match r.isolated.as_slice() {
        [] if r.onset_estimate.is_none() => "undetected".into(),
        [] if !r.ambiguous.is_empty() => "ambiguous".into(),
        [] => "none".into(),
        [one] => one.clone(),
        _ => "several".into(),
    }
}

/// The `--json` file: the channel, the onset, the channel's fault dictionary and every
/// run of every injected fault, `{"channel", "onset", "faults", "results": [{"fault",
/// "magnitude", "runs": [{"crossing", "onset_estimate", "isolated", "ambiguous", "isolated_at",
/// "false_alarms"}], "minmax": [{"test", "faults", "threshold", "dof", "statistics",
/// "fired", "type_i_rate" or "type_ii_rate"}]}]}` (`minmax`: [`MinmaxTest`], Zhang &
/// Basseville 2014, Fig. 8).
#[derive(Debug, Serialize)]
pub struct EvaluationRuns<'a> {
    /// The channel.
    pub channel: &'a str,
    /// The onset of every injection.
    pub onset: u64,
    /// The channel's fault dictionary.
    pub faults: &'a [String],
    /// Every injected fault's runs.
    pub results: &'a [FaultResult],
}

/// The `glrmon evaluate --json` file's text, one line.
///
/// # Errors
/// As [`serde_json::to_string`] (not for finite magnitudes).
pub fn json(
    channel: &str,
    faults: &[String],
    results: &[FaultResult],
    onset: u64,
) -> serde_json::Result<String> {
    // Every magnitude is finite (checked when parsed); a minmax statistic that is not
    // finite (a numerical failure) becomes `null`.
    let mut out = serde_json::to_string(&EvaluationRuns {
        channel,
        onset,
        faults,
        results,
    })?;
    out.push('\n');
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_keeps_the_keys_and_escapes_names() {
        let results = [FaultResult {
            fault: "a\"b".into(),
            magnitude: 0.5,
            runs: vec![
                Run {
                    crossing: Some(12),
                    onset_estimate: Some(10),
                    isolated: vec!["a\"b".into(), "c\\d".into()],
                    ambiguous: Vec::new(),
                    isolated_at: Some(14),
                    false_alarms: 0,
                    minmax: Vec::new(),
                },
                Run::default(),
            ],
            minmax: vec![MinmaxTest {
                test: "a\"b".into(),
                faults: vec!["a\"b".into()],
                threshold: 6.5,
                dof: 1,
                statistics: vec![7.25, f64::NAN],
                fired: 1,
                error_rate: ErrorRate::TypeII(Some(0.5)),
            }],
        }];
        let text = json("m\u{1}é", &["a\"b".into()], &results, 10).unwrap();
        assert_eq!(
            text,
            concat!(
                r#"{"channel":"m\u0001é","onset":10,"faults":["a\"b"],"results":[{"fault":"a\"b","magnitude":0.5,"runs":["#,
                r#"{"crossing":12,"onset_estimate":10,"isolated":["a\"b","c\\d"],"ambiguous":[],"isolated_at":14,"false_alarms":0},"#,
                r#"{"crossing":null,"onset_estimate":null,"isolated":[],"ambiguous":[],"isolated_at":null,"false_alarms":0}],"#,
                r#""minmax":[{"test":"a\"b","faults":["a\"b"],"threshold":6.5,"dof":1,"statistics":[7.25,null],"fired":1,"type_ii_rate":0.5}]}]}"#,
                "\n"
            )
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["results"][0]["runs"][0]["isolated"][1], "c\\d");
    }

    /// The minmax outcomes of a run are the tests of its counted isolation, with the dof
    /// the monitor took its threshold from: threshold = χ²(dof) upper α quantile, and
    /// fired = l_a > threshold (Zhang & Basseville 2014, eq. (41)).
    #[test]
    fn minmax_outcomes_carry_the_monitors_dof_and_decision() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/paper2014-gas-pipeline.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let mut seen = 0;
        for seed in 1..4 {
            let run = one_run(channel, seed, "g0_leak", -2e-5, (300, None), 500).unwrap();
            if run.isolated_at.is_none() {
                assert!(run.minmax.is_empty());
                continue;
            }
            let names: Vec<&str> = run.minmax.iter().map(|o| o.test.as_str()).collect();
            assert_eq!(names, ["g0_leak", "gp_leak", "outlet_leak"]);
            for o in &run.minmax {
                let h = chi2_upper_quantile(f64::from(o.dof), channel.isolation_alpha).unwrap();
                assert!(
                    (o.threshold - h).abs() <= 1e-12 * h,
                    "{o:?}: χ² quantile {h}"
                );
                assert_eq!(o.fired, o.statistic > o.threshold, "{o:?}");
                seen += 1;
            }
        }
        assert!(seen > 0);
        let runs: Vec<Run> = (1..4)
            .map(|seed| one_run(channel, seed, "g0_leak", -2e-5, (300, None), 500).unwrap())
            .collect();
        let groups = Monitor::from_channel(channel)
            .unwrap()
            .isolation_groups()
            .to_vec();
        let tests = minmax_tests(channel, &groups, "g0_leak", &runs);
        assert!(matches!(tests[0].error_rate, ErrorRate::TypeII(_)));
        assert!(matches!(tests[1].error_rate, ErrorRate::TypeI(_)));
        assert!(matches!(tests[2].error_rate, ErrorRate::TypeI(_)));
        assert_eq!(tests[0].faults, ["g0_leak"]);
    }

    /// The run's detection is the crossing itself: the first sample at or
    /// after the onset whose l_k exceeds λ, as the `stat` records of the same run show
    /// it (before, the alarm, and with it the run's onset estimate and isolation, came
    /// `isolation_delay` samples later). The isolation is the update's, that delay on.
    #[test]
    fn a_run_detects_at_the_crossing_and_isolates_at_the_update() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/paper2014-unstable.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let delay = u64::from(channel.isolation_delay);
        assert!(delay > 0);
        for seed in 1..6 {
            let run = one_run(channel, seed, "x0_jump", 4.0, (201, None), 400).unwrap();
            // The same run with the per-sample statistics.
            let mut sim = simulator(channel, seed, "x0_jump", 4.0, 201).unwrap();
            let mut mon = Monitor::from_channel(channel).unwrap();
            let mut records = Vec::new();
            for _ in 0..400 {
                let x = sim.next_sample();
                let s = Sample {
                    k: Some(x.k),
                    t: None,
                    u: x.u,
                    y: x.y,
                    p: x.p,
                };
                mon.on_sample(&s, &mut records);
            }
            let crossing = records.iter().find_map(|r| match r {
                Record::Stat(s)
                    if s.k >= 201 && s.glr.is_some_and(|l| l > channel.alarm.threshold) =>
                {
                    Some(s.k)
                }
                _ => None,
            });
            assert!(crossing.is_some(), "seed {seed}: detected");
            assert_eq!(run.crossing, crossing, "seed {seed}");
            assert_eq!(run.isolated_at, crossing.map(|c| c + delay), "seed {seed}");
            assert_eq!(run.isolated, ["x0_jump"], "seed {seed}");
            assert_eq!(run.false_alarms, 0);
        }
    }
}
