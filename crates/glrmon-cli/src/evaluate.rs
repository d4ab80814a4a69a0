//! `glrmon evaluate`: Monte-Carlo fault injection through the simulator and the
//! channel's monitor, as live: per injected fault, the detection rate, the detection
//! delay (samples from the onset to the first crossing of the threshold), the error of
//! the onset estimate r̂ at the alarm, false alarms before the onset, and which faults
//! the isolation tests named (a confusion matrix) — what a user tunes w, s and the
//! thresholds with (Zhang & Basseville 2014, §6: Figures 7-8 are such histograms).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_sim::SimSample;
use glrmon_wire::{Record, Sample};

use crate::simulate::{pick, simulator};
use crate::{InvalidInput, load_config};

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
}

/// What one run gave.
#[derive(Debug, Clone, Default)]
struct Run {
    /// First crossing of the threshold at or after the onset.
    crossing: Option<u64>,
    /// r̂ of the first alarm at or after the onset.
    onset_estimate: Option<u64>,
    /// Faults isolated by that alarm.
    isolated: Vec<String>,
    false_alarms: u64,
}

/// Results for one injected fault.
#[derive(Debug, Clone)]
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
    print!(
        "{}",
        text(
            &channel.name,
            &channel.fault_names,
            &results,
            onset,
            samples
        )
    );
    if let Some(path) = &args.json {
        std::fs::write(
            path,
            json(&channel.name, &channel.fault_names, &results, onset),
        )?;
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
    faults: &[String],
    results: &[FaultResult],
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
        let n = r.runs.len();
        let detected = r.runs.iter().filter(|x| x.crossing.is_some()).count();
        let delays: Vec<f64> = r
            .runs
            .iter()
            .filter_map(|x| x.crossing.map(|c| (c - onset) as f64))
            .collect();
        let errors: Vec<f64> = r
            .runs
            .iter()
            .filter_map(|x| x.onset_estimate.map(|e| (e as f64 - onset as f64).abs()))
            .collect();
        let fa: u64 = r.runs.iter().map(|x| x.false_alarms).sum();
        let fmt = |v: Option<f64>| v.map_or("–".to_owned(), |v| format!("{v:.0}"));
        let _ = writeln!(
            s,
            "{:<24} {:>8.1}% {:>6} {:>9} {:>15} {:>16} {:>12}",
            format!("{} ({})", r.fault, r.magnitude),
            100.0 * detected as f64 / n as f64,
            n,
            fmt(median(delays.clone())),
            format!(
                "{}–{}",
                fmt(quantile(delays.clone(), 0.1)),
                fmt(quantile(delays, 0.9))
            ),
            fmt(median(errors)),
            fa
        );
    }
    // Confusion matrix: rows injected, columns isolated.
    let mut columns: Vec<String> = faults.to_vec();
    columns.extend(["none", "several", "undetected"].map(str::to_owned));
    let _ = writeln!(
        s,
        "\nisolation at the first alarm (rows: injected, columns: isolated)"
    );
    let width = columns.iter().map(String::len).max().unwrap_or(8).max(8);
    let _ = write!(s, "{:<24}", "");
    for c in &columns {
        let _ = write!(s, " {c:>width$}");
    }
    s.push('\n');
    for r in results {
        let mut counts: BTreeMap<String, u64> = BTreeMap::new();
        for run in &r.runs {
            *counts.entry(isolated_label(run)).or_insert(0) += 1;
        }
        let _ = write!(s, "{:<24}", r.fault);
        for c in &columns {
            let _ = write!(s, " {:>width$}", counts.get(c).copied().unwrap_or(0));
        }
        s.push('\n');
    }
    s
}

fn json(channel: &str, faults: &[String], results: &[FaultResult], onset: u64) -> String {
    let mut out =
        format!("{{\"channel\":{channel:?},\"onset\":{onset},\"faults\":{faults:?},\"results\":[");
    for (i, r) in results.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let opt = |v: Option<u64>| v.map_or("null".to_owned(), |v| v.to_string());
        let runs: Vec<String> = r
            .runs
            .iter()
            .map(|x| {
                format!(
                    "{{\"crossing\":{},\"onset_estimate\":{},\"isolated\":{:?},\"false_alarms\":{}}}",
                    opt(x.crossing),
                    opt(x.onset_estimate),
                    x.isolated,
                    x.false_alarms
                )
            })
            .collect();
        let _ = write!(
            out,
            "{{\"fault\":{:?},\"magnitude\":{:?},\"runs\":[{}]}}",
            r.fault,
            r.magnitude,
            runs.join(",")
        );
    }
    out.push_str("]}\n");
    out
}
