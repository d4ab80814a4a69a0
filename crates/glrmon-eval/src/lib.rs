#![doc = include_str!("../README.md")]

pub mod calibrate;
pub mod identify;
pub mod noise;

use glrmon_monitor::Monitor;
use glrmon_report::FaultEvaluation;
use glrmon_sim::{Injection, SimSample};
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
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Run {
    /// k of the first alarm at or after the onset: its crossing of the threshold.
    pub crossing: Option<u64>,
    /// r̂ of that alarm's last isolation.
    pub onset_estimate: Option<u64>,
    /// Faults isolated by that alarm's last isolation.
    pub isolated: Vec<String>,
    /// The sample of that isolation: the alarm's `k`, or its update's.
    pub isolated_at: Option<u64>,
    /// Alarms raised before the onset.
    pub false_alarms: u64,
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
        })
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
    } = protocol;
    let mut results = Vec::new();
    for (fault, magnitude) in injected {
        let outcomes: Vec<Result<Run, EvalError>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || {
                        (0..runs)
                            .filter(|i| i % threads == t)
                            .map(|i| one_run(channel, seed + i, fault, *magnitude, onset, samples))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_else(|_| vec![Err(EvalError::Panicked)]))
                .collect()
        });
        results.push(FaultResult {
            fault: fault.clone(),
            magnitude: *magnitude,
            runs: outcomes.into_iter().collect::<Result<_, _>>()?,
        });
    }
    Ok(results)
}

/// One run: the channel simulated with `seed`, `fault` of `magnitude` injected at
/// `onset`, `samples` samples through the channel's monitor as live.
///
/// # Errors
/// [`EvalError`] when the simulator or the monitor cannot be built for the channel.
pub fn one_run(
    channel: &Channel,
    seed: u64,
    fault: &str,
    magnitude: f64,
    onset: u64,
    samples: u64,
) -> Result<Run, EvalError> {
    let mut sim = simulator(channel, seed, fault, magnitude, onset)?;
    let mut mon = Monitor::from_channel(channel)?;
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
                    run.isolated_at = Some(a.k);
                }
                Record::Isolation(u) if run.crossing == Some(u.alarm_k) => {
                    run.onset_estimate = Some(u.onset);
                    run.isolated = isolated(&u.isolation);
                    run.isolated_at = Some(u.k);
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
    let sim = glrmon_sim::from_channel(channel, seed).map_err(glrmon_sim::ChannelError::from)?;
    let magnitude = glrmon_sim::fault_magnitudes(channel, &[fault.to_owned()], &[magnitude])?;
    Ok(glrmon_sim::inject(
        sim,
        channel,
        Injection { magnitude, onset },
    )?)
}

fn isolated(tests: &[glrmon_wire::IsolationResult]) -> Vec<String> {
    tests
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.clone())
        .collect()
}

/// Columns of the confusion matrix: the dictionary's faults, any other isolated name
/// (an isolation group), then the outcomes without a single isolated fault.
#[must_use]
pub fn outcome_columns(faults: &[String], results: &[FaultResult]) -> Vec<String> {
    let mut columns: Vec<String> = faults.to_vec();
    let fixed = ["none", "several", "undetected"];
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
        minmax: Vec::new(),
    }
}

/// The median (mean of the middle two for an even count); `None` when empty.
fn median(mut v: Vec<f64>) -> Option<f64> {
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

/// Column of the confusion matrix for a run: the isolated fault, `none`, or
/// `several`.
fn isolated_label(r: &Run) -> String {
    match r.isolated.as_slice() {
        [] if r.onset_estimate.is_none() => "undetected".into(),
        [] => "none".into(),
        [one] => one.clone(),
        _ => "several".into(),
    }
}

/// The `--json` file: the channel, the onset, the channel's fault dictionary and every
/// run of every injected fault, `{"channel", "onset", "faults", "results": [{"fault",
/// "magnitude", "runs": [{"crossing", "onset_estimate", "isolated", "isolated_at",
/// "false_alarms"}]}]}`.
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
    // Every magnitude is finite (checked when parsed), so no float becomes `null`.
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
                    isolated_at: Some(14),
                    false_alarms: 0,
                },
                Run::default(),
            ],
        }];
        let text = json("m\u{1}é", &["a\"b".into()], &results, 10).unwrap();
        assert_eq!(
            text,
            concat!(
                r#"{"channel":"m\u0001é","onset":10,"faults":["a\"b"],"results":[{"fault":"a\"b","magnitude":0.5,"runs":["#,
                r#"{"crossing":12,"onset_estimate":10,"isolated":["a\"b","c\\d"],"isolated_at":14,"false_alarms":0},"#,
                r#"{"crossing":null,"onset_estimate":null,"isolated":[],"isolated_at":null,"false_alarms":0}]}]}"#,
                "\n"
            )
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["results"][0]["runs"][0]["isolated"][1], "c\\d");
    }

    /// Issue 19: the run's detection is the crossing itself: the first sample at or
    /// after the onset whose l_k exceeds λ, as the `stat` records of the same run show
    /// it (before, the alarm, and with it the run's onset estimate and isolation, came
    /// `isolation_delay` samples later). The isolation is the update's, that delay on.
    #[test]
    fn issue_19_a_run_detects_at_the_crossing_and_isolates_at_the_update() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/paper2014-unstable.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let delay = u64::from(channel.isolation_delay);
        assert!(delay > 0);
        for seed in 1..6 {
            let run = one_run(channel, seed, "x0_jump", 4.0, 201, 400).unwrap();
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
