//! `glrmon evaluate`: Monte-Carlo fault injection through the simulator and the
//! channel's monitor, as live: per injected fault, the detection rate, the detection
//! delay (samples from the onset to the first crossing of the threshold), the error of
//! the onset estimate r̂ at the alarm, false alarms before the onset, and which faults
//! the isolation tests named (a confusion matrix) — what a user tunes w, s and the
//! thresholds with (Zhang & Basseville 2014, §6: Figures 7-8 are such histograms).
//! `--report` hands the summaries to `glrmon-report`, which draws those histograms.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_report::{Evaluation, FaultEvaluation};
use glrmon_sim::SimSample;
use glrmon_wire::{Record, Sample};
use serde::Serialize;

use crate::common::pick;
use crate::common::simulator;
use crate::common::{InvalidInput, load_config};

#[derive(Debug, Args)]
pub(crate) struct EvaluateArgs {
    /// Configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Channel (optional when the configuration has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// A fault to inject and its magnitude, `NAME:MAGNITUDE`; repeat for several
    /// (evaluated one at a time). Default: every fault of the dictionary at magnitude 1.
    #[arg(long = "fault")]
    faults: Vec<String>,
    /// Runs per fault.
    #[arg(long, default_value_t = 200)]
    runs: u64,
    /// Onset of the fault (default 3·w, after the filter has converged).
    #[arg(long)]
    onset: Option<u64>,
    /// Samples per run (default onset + 2·w).
    #[arg(long)]
    samples: Option<u64>,
    /// Seed of the first run (run i uses seed + i).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also write a self-contained HTML report here: per injected fault, histograms of
    /// the detection delay and of the onset error r̂ − r, the summary and the confusion
    /// matrix.
    #[arg(long, value_name = "OUT.html")]
    report: Option<PathBuf>,
}

/// What one run gave (an element of `runs` in the `--json` file).
#[derive(Debug, Clone, Default, Serialize)]
struct Run {
    /// First crossing of the threshold at or after the onset.
    crossing: Option<u64>,
    /// r̂ of the first alarm at or after the onset.
    onset_estimate: Option<u64>,
    /// Faults isolated by that alarm.
    isolated: Vec<String>,
    /// Alarms raised before the onset.
    false_alarms: u64,
}

/// Results for one injected fault (an element of `results` in the `--json` file).
#[derive(Debug, Clone, Serialize)]
struct FaultResult {
    fault: String,
    magnitude: f64,
    runs: Vec<Run>,
}

pub(crate) fn run(args: &EvaluateArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args.config)?;
    let channel = pick(&cfg, args.channel.as_deref())?;
    let injected: Vec<(String, f64)> = if args.faults.is_empty() {
        channel
            .fault_names
            .iter()
            .map(|f| (f.clone(), 1.0))
            .collect()
    } else {
        args.faults
            .iter()
            .map(|f| {
                let (name, mag) = f
                    .split_once(':')
                    .ok_or_else(|| InvalidInput(format!("--fault {f}: expected NAME:MAGNITUDE")))?;
                let mag: f64 = mag
                    .parse()
                    .ok()
                    .filter(|m: &f64| m.is_finite())
                    .ok_or_else(|| {
                        InvalidInput(format!("--fault {f}: \"{mag}\" is not a finite number"))
                    })?;
                if !channel.fault_names.iter().any(|n| n == name) {
                    return Err(InvalidInput(format!(
                        "--fault {f}: channel \"{}\" has no fault \"{name}\" (faults: {})",
                        channel.name,
                        channel.fault_names.join(", ")
                    )));
                }
                Ok((name.to_owned(), mag))
            })
            .collect::<Result<_, _>>()?
    };
    if args.runs == 0 {
        return Err(InvalidInput("--runs must be at least 1".into()).into());
    }
    let w = channel.window.window as u64;
    let onset = args.onset.unwrap_or(3 * w);
    let samples = args.samples.unwrap_or(onset + 2 * w);
    if samples <= onset {
        return Err(
            InvalidInput(format!("--samples {samples} ends before the onset {onset}")).into(),
        );
    }
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get) as u64;
    let mut results = Vec::new();
    for (fault, magnitude) in &injected {
        let runs: Vec<anyhow::Result<Run>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || {
                        (0..args.runs)
                            .filter(|i| i % threads == t)
                            .map(|i| {
                                one_run(channel, args.seed + i, fault, *magnitude, onset, samples)
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| {
                    h.join().unwrap_or_else(|_| {
                        vec![Err(anyhow::anyhow!("an evaluation thread panicked"))]
                    })
                })
                .collect()
        });
        results.push(FaultResult {
            fault: fault.clone(),
            magnitude: *magnitude,
            runs: runs.into_iter().collect::<Result<_, _>>()?,
        });
    }
    let columns = outcome_columns(&channel.fault_names, &results);
    let summaries: Vec<FaultEvaluation> = results
        .iter()
        .map(|r| summarize(r, onset, &columns))
        .collect();
    print!(
        "{}",
        text(&channel.name, &columns, &summaries, onset, samples)
    );
    if let Some(path) = &args.json {
        std::fs::write(
            path,
            json(&channel.name, &channel.fault_names, &results, onset)?,
        )?;
    }
    if let Some(path) = &args.report {
        let detector = if channel.chi2_detector {
            "χ² test of εᵀΣ⁻¹ε per sample".to_owned()
        } else {
            format!(
                "GLR, window w = {}, s = {}",
                channel.window.window, channel.window.min_lag
            )
        };
        let evaluation = Evaluation {
            title: format!("glrmon evaluate: channel {}", channel.name),
            config: args.config.display().to_string(),
            channel: channel.name.clone(),
            detector,
            threshold: channel.alarm.threshold,
            onset,
            samples,
            runs: args.runs,
            seed: args.seed,
            outcomes: columns,
            faults: summaries,
        };
        let write = || -> std::io::Result<()> {
            let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
            evaluation.write_html(&mut out)?;
            out.flush()
        };
        write().with_context(|| format!("writing the report {}", path.display()))?;
    }
    Ok(())
}

fn one_run(
    channel: &glrmon_spec::Channel,
    seed: u64,
    fault: &str,
    magnitude: f64,
    onset: u64,
    samples: u64,
) -> anyhow::Result<Run> {
    let mut sim = simulator(channel, seed, &[fault.to_owned()], onset, &[magnitude])?;
    let mut mon = Monitor::from_channel(channel)?;
    let threshold = channel.alarm.threshold;
    let mut x = SimSample {
        k: 0,
        u: vec![],
        y: vec![],
        p: vec![],
    };
    let mut sample = Sample::default();
    let mut records = Vec::new();
    let mut run = Run::default();
    let mut alarmed = false;
    for _ in 0..samples {
        sim.next_into(&mut x);
        sample.k = Some(x.k);
        sample.u.clone_from(&x.u);
        sample.y.clone_from(&x.y);
        sample.p.clone_from(&x.p);
        mon.on_sample(&sample, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Stat(s)
                    if run.crossing.is_none()
                        && s.k >= onset
                        && s.glr.is_some_and(|l| l > threshold) =>
                {
                    run.crossing = Some(s.k);
                }
                Record::Alarm(a) if a.k < onset => run.false_alarms += 1,
                Record::Alarm(a) if !alarmed => {
                    alarmed = true;
                    run.onset_estimate = Some(a.onset);
                    run.isolated = a
                        .isolation
                        .iter()
                        .filter(|i| i.isolated)
                        .map(|i| i.fault.clone())
                        .collect();
                }
                _ => {}
            }
        }
    }
    Ok(run)
}

/// Columns of the confusion matrix: the dictionary's faults, any other isolated name
/// (an isolation group), then the outcomes without a single isolated fault.
fn outcome_columns(faults: &[String], results: &[FaultResult]) -> Vec<String> {
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

/// The figures of one injected fault that the text output and the HTML report state.
fn summarize(r: &FaultResult, onset: u64, columns: &[String]) -> FaultEvaluation {
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
    }
}

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

fn text(
    channel: &str,
    columns: &[String],
    results: &[FaultEvaluation],
    onset: u64,
    samples: u64,
) -> String {
    let mut s = format!(
        "channel \"{channel}\": fault injected at k = {onset}, {samples} samples per run\n\n"
    );
    let _ = writeln!(
        s,
        "{:<24} {:>9} {:>6} {:>9} {:>15} {:>16} {:>12}",
        "fault (magnitude)",
        "detected",
        "runs",
        "delay p50",
        "delay p10–p90",
        "onset error p50",
        "false alarms"
    );
    for r in results {
        let fmt = |v: Option<f64>| v.map_or("–".to_owned(), |v| format!("{v:.0}"));
        let q = |i: usize| fmt(r.delay_quantiles.map(|q| q[i]));
        let _ = writeln!(
            s,
            "{:<24} {:>8.1}% {:>6} {:>9} {:>15} {:>16} {:>12}",
            format!("{} ({})", r.fault, r.magnitude),
            100.0 * r.detected as f64 / r.runs.max(1) as f64,
            r.runs,
            q(1),
            format!("{}–{}", q(0), q(2)),
            fmt(r.onset_error_median_abs),
            r.false_alarms
        );
    }
    // Confusion matrix: rows injected, columns isolated.
    let _ = writeln!(
        s,
        "\nisolation at the first alarm (rows: injected, columns: isolated)"
    );
    let width = columns.iter().map(String::len).max().unwrap_or(8).max(8);
    let _ = write!(s, "{:<24}", "");
    for c in columns {
        let _ = write!(s, " {c:>width$}");
    }
    s.push('\n');
    for r in results {
        let _ = write!(s, "{:<24}", r.fault);
        for n in &r.isolated {
            let _ = write!(s, " {n:>width$}");
        }
        s.push('\n');
    }
    s
}

/// The `--json` file: the channel, the onset, the channel's fault dictionary and every
/// run of every injected fault, `{"channel", "onset", "faults", "results": [{"fault",
/// "magnitude", "runs": [{"crossing", "onset_estimate", "isolated", "false_alarms"}]}]}`.
#[derive(Debug, Serialize)]
struct EvaluationRuns<'a> {
    channel: &'a str,
    onset: u64,
    faults: &'a [String],
    results: &'a [FaultResult],
}

/// The `--json` file's text, one line.
fn json(
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
                r#"{"crossing":12,"onset_estimate":10,"isolated":["a\"b","c\\d"],"false_alarms":0},"#,
                r#"{"crossing":null,"onset_estimate":null,"isolated":[],"false_alarms":0}]}]}"#,
                "\n"
            )
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["results"][0]["runs"][0]["isolated"][1], "c\\d");
    }
}
