//! `glrmon evaluate`: Monte-Carlo fault injection through the simulator and the
//! channel's monitor, as live: per injected fault, the detection rate, the detection
//! delay (samples from the onset to the first alarm, raised at the crossing of the
//! threshold), the error of the onset estimate r̂ and which faults the isolation tests
//! named (a confusion matrix), both at the alarm's isolation update (else at the
//! alarm), false alarms before the onset — what a user tunes w, s and the
//! thresholds with (Zhang & Basseville 2014, §6: Figures 7-8 are such histograms); and
//! at that isolation each test's minmax statistic with its type-I or type-II error rate
//! (eq. (41), (42), Fig. 8). `--report` hands the summaries to `glrmon-report`, which
//! draws those histograms (Fig. 8's with `--minmax-histograms`).

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_eval::{EvalError, Protocol, outcome_columns, summarize};
use glrmon_report::{DecisionError, Evaluation, FaultEvaluation};

use crate::common::pick;
use crate::common::{InvalidInput, load_config};
use crate::flags::FaultArg;

#[derive(Debug, Args)]
pub(crate) struct EvaluateArgs {
    /// Configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Channel (optional when the configuration has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// A fault to inject and its magnitude θ, `NAME:MAGNITUDE`; repeat (or separate
    /// with commas) for several, evaluated one at a time. Default: every fault of the
    /// dictionary at magnitude 1.
    #[arg(
        long = "fault",
        value_name = "NAME:MAGNITUDE",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    faults: Vec<FaultArg>,
    /// Runs per fault.
    #[arg(long, default_value_t = 200)]
    runs: u64,
    /// Onset of the fault (default 3·w, after the filter has converged).
    #[arg(long)]
    onset: Option<u64>,
    /// Samples per run (default onset + 2·w).
    #[arg(long)]
    samples: Option<u64>,
    /// The sample from which the injected fault is gone again (a fault that ends, such
    /// as an actuator stuck for a while); default: it lasts to the end of the run.
    #[arg(long, value_name = "K")]
    end: Option<u64>,
    /// Seed of the first run (run i uses seed + i).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Compare detector kinds side by side on the same injected faults and noise:
    /// `glr`, `chi2`, `cusum`, `parity`, `fdf`, `uio`, `rls` (comma-separated; a `cusum` without `[channels.cusum]` is tuned for the injected magnitudes). Each runs at the channel's
    /// `false_alarm` per sample (10⁻⁴ when the configuration sets a threshold another
    /// way) and one table gives each kind's detection rate, median delay, false alarms
    /// per 10⁴ fault-free samples and correct isolations (for the kinds that isolate);
    /// with `--report`, one page with each kind's figures and delay histograms.
    #[arg(long, value_name = "KIND,…", value_delimiter = ',', conflicts_with_all = ["json", "json_out", "minmax_histograms"])]
    detector: Vec<String>,
    /// With `--detector`: the false-alarm probability per sample every kind's threshold
    /// is set for (the survey's DC motor comparison uses 0.1); default the channel's
    /// `false_alarm`.
    #[arg(long, value_name = "P", requires = "detector")]
    false_alarm: Option<f64>,
    /// Print the results as JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Also write the results as JSON to this file.
    #[arg(long, value_name = "PATH")]
    json_out: Option<PathBuf>,
    /// Arguments left over; `--json PATH` of earlier versions lands here (see
    /// `Command::old_spelling`).
    #[arg(hide = true)]
    pub(crate) stray: Vec<String>,
    /// Also write a self-contained HTML report here: per injected fault, histograms of
    /// the detection delay and of the onset error r̂ − r, the summary and the confusion
    /// matrix, and the type-I/II rates of the isolation tests (Zhang & Basseville 2014,
    /// eq. (42)).
    #[arg(long, value_name = "OUT.html")]
    report: Option<PathBuf>,
    /// With `--report`: also draw, per injected fault and isolation test, the histogram
    /// of its minmax statistic with the χ² density and the threshold (Zhang & Basseville
    /// 2014, Fig. 8); faults × tests figures, so off by default (the report always has
    /// the table of type-I/II rates).
    #[arg(long, requires = "report")]
    minmax_histograms: bool,
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
                if !channel.fault_names.contains(&f.name) {
                    return Err(InvalidInput(format!(
                        "--fault {}: channel \"{}\" has no fault \"{}\" (faults: {})",
                        f.name,
                        channel.name,
                        f.name,
                        channel.fault_names.join(", ")
                    )));
                }
                Ok((f.name.clone(), f.magnitude))
            })
            .collect::<Result<_, _>>()?
    };
    let eval_error = |e: EvalError| -> anyhow::Error {
        if e.is_invalid_input() {
            InvalidInput(e.to_string()).into()
        } else {
            e.into()
        }
    };
    if !args.detector.is_empty() {
        let kinds = args
            .detector
            .iter()
            .map(|name| {
                glrmon_spec::DetectorKind::from_name(name).ok_or_else(|| {
                    InvalidInput(format!(
                        "--detector {name}: not a detector kind (kinds: {})",
                        glrmon_spec::DetectorKind::NAMES.join(", ")
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let text = std::fs::read_to_string(&args.config)
            .with_context(|| format!("reading {}", args.config.display()))?;
        let glrmon_eval::compare::Compared {
            protocol,
            kinds,
            skipped,
        } = glrmon_eval::compare::compare(
            &text,
            &channel.name,
            &kinds,
            &injected,
            (args.onset, args.samples, args.runs, args.seed),
            args.end,
            args.false_alarm,
        )
        .map_err(eval_error)?;
        for (kind, why) in &skipped {
            eprintln!(
                "glrmon evaluate: detector `{}` cannot run on channel \"{}\", left out: {}",
                kind.name(),
                channel.name,
                why.lines().collect::<Vec<_>>().join(" ")
            );
        }
        print!(
            "{}",
            side_by_side(&channel.name, protocol, &kinds, channel.period)
        );
        if let Some(path) = &args.report {
            let comparison = glrmon_report::Comparison {
                title: format!(
                    "glrmon evaluate: detector kinds on channel {}",
                    channel.name
                ),
                kinds: kinds
                    .iter()
                    .map(|k| glrmon_report::ComparedKind {
                        name: k.kind.name().to_owned(),
                        isolates: k.isolates,
                        evaluation: Evaluation {
                            title: String::new(),
                            config: args.config.display().to_string(),
                            channel: channel.name.clone(),
                            detector: k.describe.clone(),
                            threshold: k.threshold,
                            onset: protocol.onset,
                            samples: protocol.samples,
                            runs: protocol.runs,
                            seed: protocol.seed,
                            outcomes: k.columns.clone(),
                            faults: k.faults.clone(),
                            minmax_histograms: false,
                        },
                    })
                    .collect(),
                end: protocol.end,
            };
            let write = || -> std::io::Result<()> {
                let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
                comparison.write_html(&mut out)?;
                out.flush()
            };
            write().with_context(|| format!("writing the report {}", path.display()))?;
        }
        return Ok(());
    }
    let protocol = Protocol::for_channel(channel, args.onset, args.samples, args.runs, args.seed)
        .and_then(|p| p.with_end(args.end))
        .map_err(eval_error)?;
    let Protocol { onset, samples, .. } = protocol;
    let results = glrmon_eval::evaluate(channel, &injected, protocol).map_err(eval_error)?;
    let columns = outcome_columns(&channel.fault_names, &results);
    let summaries: Vec<FaultEvaluation> = results
        .iter()
        .map(|r| summarize(r, onset, &columns))
        .collect();
    let json = || glrmon_eval::json(&channel.name, &channel.fault_names, &results, onset);
    if args.json {
        println!("{}", json()?);
    } else {
        print!(
            "{}",
            text(
                &channel.name,
                &columns,
                &summaries,
                (onset, samples, protocol.end),
                channel.period
            )
        );
    }
    if let Some(path) = &args.json_out {
        std::fs::write(path, json()?)?;
    }
    if let Some(path) = &args.report {
        let detector = channel.detector()?.describe();
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
            minmax_histograms: args.minmax_histograms,
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

/// The kinds of `glrmon evaluate --detector` in one table.
fn side_by_side(
    channel: &str,
    protocol: Protocol,
    kinds: &[glrmon_eval::compare::KindEvaluation],
    period: Option<f64>,
) -> String {
    let until = protocol
        .end
        .map_or_else(String::new, |e| format!(" until k = {e}"));
    let mut s = format!(
        "channel \"{channel}\": fault injected at k = {}{until}, {} samples per run, {} runs \
         per fault, seeds {}…, the same for every kind\n\n",
        protocol.onset, protocol.samples, protocol.runs, protocol.seed
    );
    for k in kinds {
        let _ = writeln!(
            s,
            "  {:<7} {} (threshold {:.4})",
            k.kind.name(),
            k.describe,
            k.threshold
        );
    }
    let delay_head = if period.is_some_and(|p| p.is_finite() && p > 0.0) {
        "delay p50 (time)"
    } else {
        "delay p50"
    };
    let _ = writeln!(
        s,
        "\n{:<7} {:<28} {:>9} {:>18} {:>17} {:>10}",
        "kind", "fault (magnitude)", "detected", delay_head, "false alarms/10⁴", "isolated"
    );
    for k in kinds {
        let far = k.false_alarms_per_10k(protocol.onset);
        for f in &k.faults {
            let delay = f.delay_quantiles.map_or("–".to_owned(), |q| {
                match period.filter(|p| p.is_finite() && *p > 0.0) {
                    Some(p) => format!("{:.0} ({})", q[1], crate::span::duration(q[1] * p)),
                    None => format!("{:.0}", q[1]),
                }
            });
            let isolated = k
                .isolated_correctly(f)
                .map_or("–".to_owned(), |r| format!("{:.1}%", 100.0 * r));
            let _ = writeln!(
                s,
                "{:<7} {:<28} {:>8.1}% {:>18} {:>17.2} {:>10}",
                k.kind.name(),
                format!("{} ({})", f.fault, crate::print::magnitude(f.magnitude)),
                100.0 * f.detected as f64 / f.runs.max(1) as f64,
                delay,
                far,
                isolated
            );
        }
    }
    s.push_str(
        "\ndelay in samples from the onset to the first alarm; false alarms before the onset, \
         over all runs; isolated: runs whose isolation named the injected fault alone (– for \
         kinds that only detect)\n",
    );
    s
}

/// The evaluation as text: detection table (and, when the channel's sampling period is
/// known, the delays in time), confusion matrix, Fig. 8 table. `protocol` is the onset,
/// the samples per run and the fault's end.
fn text(
    channel: &str,
    columns: &[String],
    results: &[FaultEvaluation],
    protocol: (u64, u64, Option<u64>),
    period: Option<f64>,
) -> String {
    let (onset, samples, end) = protocol;
    let until = end.map_or_else(String::new, |e| format!(" until k = {e}"));
    let mut s = format!(
        "channel \"{channel}\": fault injected at k = {onset}{until}, {samples} samples per run\n\n"
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
            format!("{} ({})", r.fault, crate::print::magnitude(r.magnitude)),
            100.0 * r.detected as f64 / r.runs.max(1) as f64,
            r.runs,
            q(1),
            format!("{}–{}", q(0), q(2)),
            fmt(r.onset_error_median_abs),
            r.false_alarms
        );
    }
    if let Some(period) = period.filter(|p| p.is_finite() && *p > 0.0) {
        let _ = writeln!(
            s,
            "\ndelays in time (period {} s):",
            crate::print::magnitude(period)
        );
        for r in results {
            if let Some(q) = r.delay_quantiles {
                let _ = writeln!(
                    s,
                    "  {}: p50 {}, p10–p90 {}–{}",
                    r.fault,
                    crate::span::duration(q[1] * period),
                    crate::span::duration(q[0] * period),
                    crate::span::duration(q[2] * period)
                );
            }
        }
    }
    // Confusion matrix: rows injected, columns isolated.
    let _ = writeln!(
        s,
        "\nisolation at the first alarm, as updated isolation_delay samples on (rows: injected, columns: isolated)"
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
    s.push_str(&minmax_table(results));
    s
}

/// Zhang & Basseville 2014, Fig. 8 in numbers: per injected fault and isolation test,
/// the runs that isolated, the median minmax statistic l_a (eq. (41)), the threshold and
/// the type-I or type-II error rate (eq. (42)).
fn minmax_table(results: &[FaultEvaluation]) -> String {
    let mut s = String::new();
    if results.iter().all(|r| r.minmax.is_empty()) {
        return s;
    }
    let width = results
        .iter()
        .flat_map(|r| r.minmax.iter().map(|t| t.test.chars().count()))
        .max()
        .unwrap_or(4)
        .max(4);
    let _ = writeln!(
        s,
        "\nminmax isolation (Fig. 8): l_a at that isolation (type I: fired though not injected; type II: injected, not fired)"
    );
    let _ = writeln!(
        s,
        "{:<24} {:<width$} {:>6} {:>10} {:>15} {:>8} {:>8}",
        "fault", "test", "runs", "l_a p50", "threshold (dof)", "type I", "type II"
    );
    for r in results {
        for t in &r.minmax {
            let median = glrmon_eval::median(t.statistics.clone())
                .map_or("–".to_owned(), |m| format!("{m:.2}"));
            let rate = t
                .error_rate
                .map_or("–".to_owned(), |r| format!("{:.1}%", 100.0 * r));
            let (type_i, type_ii) = match t.error {
                DecisionError::TypeI => (rate, "–".to_owned()),
                DecisionError::TypeII => ("–".to_owned(), rate),
            };
            let _ = writeln!(
                s,
                "{:<24} {:<width$} {:>6} {:>10} {:>15} {:>8} {:>8}",
                r.fault,
                t.test,
                t.statistics.len(),
                median,
                format!("{:.4} ({})", t.threshold, t.dof),
                type_i,
                type_ii
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With the sampling period known, the delays are given in time too (the
    /// evaluation once spoke only in samples).
    #[test]
    fn delays_are_given_in_time_when_the_period_is_known() {
        let r = FaultEvaluation {
            fault: "leak".into(),
            magnitude: 1.0,
            runs: 10,
            detected: 10,
            delays: vec![58; 10],
            delay_quantiles: Some([40.0, 58.0, 85.0]),
            onset_errors: vec![9; 10],
            onset_error_median_abs: Some(9.0),
            false_alarms: 0,
            runs_with_false_alarms: 0,
            isolated: vec![10],
            minmax: Vec::new(),
        };
        let columns = ["leak".to_owned()];
        let with = text(
            "pipe",
            &columns,
            std::slice::from_ref(&r),
            (300, 500, None),
            Some(120.0),
        );
        assert!(
            with.contains(
                "delays in time (period 120.0 s):\n  leak: p50 116.0 min, p10–p90 80.0 min–2.83 h"
            ),
            "{with}"
        );
        let without = text("pipe", &columns, &[r], (300, 500, None), None);
        assert!(!without.contains("delays in time"), "{without}");
        assert_eq!(crate::span::duration(0.58), "0.5800 s");
    }
}
