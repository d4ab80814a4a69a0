//! `glrmon calibrate`: the detection threshold of a channel for a target mean time
//! between false alarms or a per-sample false-alarm fraction, found on fault-free data
//! (recordings, each an independent run, or data simulated from the channel's model)
//! with the channel's own monitor, so that gaps, restarts and the hysteresis count as
//! they do live. See [`glrmon_core::threshold::calibration`].

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use clap::Args;

use glrmon_core::threshold::calibration::{Calibration, MIN_EVENTS, Target};
use glrmon_eval::calibrate::{
    CalibrateError, ChannelCalibration, IsolationCalibration, RunRate, Statistics,
    calibrate_channel, skip_summary,
};
use glrmon_spec::edit::EditError;
use serde::Serialize;

use glrmon_input::embedded_config;

use crate::common::pick;
use crate::common::{InvalidInput, input_error, load_config};
use crate::span::{Span, samples_and_time};

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["mtbfa", "sample_far"])))]
pub(crate) struct CalibrateArgs {
    /// Configuration file (optional when the first input is an MCAP recording: its
    /// recorded one is used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Channel to calibrate (optional when the configuration has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// Fault-free recorded samples: CSV or MCAP files, each an independent run (the
    /// monitor starts afresh at each file; no episode spans two).
    #[arg(conflicts_with = "simulate", required_unless_present = "simulate")]
    input: Vec<PathBuf>,
    /// Simulate this many fault-free samples from the channel's model instead (split
    /// over the cores, each part with its own seed).
    #[arg(long)]
    simulate: Option<u64>,
    /// Seed of the first simulated part.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Target mean time between false-alarm episodes: a time (`1d`, `8h`, `90min`,
    /// `1w`; needs the channel's `period`) or a number of samples (`4320`). An
    /// operator's target: one false alarm a day at most (or --sample-far).
    #[arg(long, value_name = "TIME|SAMPLES", value_parser = crate::span::parse)]
    mtbfa: Option<Span>,
    /// Target fraction of fault-free samples whose l_k exceeds the threshold, e.g. 0.01:
    /// the (1 − f) quantile of l_k (or --mtbfa).
    #[arg(long)]
    sample_far: Option<f64>,
    /// Write the result into the configuration file as `[channels.glr.calibrated]`
    /// (comments and layout kept).
    #[arg(long)]
    write: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let embedded = match (&args.config, args.input.first()) {
        (None, Some(input)) => embedded_config(input).map_err(input_error)?,
        _ => None,
    };
    let cfg = match (&args.config, embedded) {
        (Some(path), _) => load_config(path)?,
        (None, Some(cfg)) => cfg,
        (None, None) => {
            return Err(InvalidInput(
                "give --config (only an MCAP recording carries its configuration)".into(),
            )
            .into());
        }
    };
    if args.write && args.config.is_none() {
        return Err(InvalidInput("--write needs --config: the file to update".into()).into());
    }
    let channel = pick(&cfg, args.channel.as_deref())?;
    let target = match (args.mtbfa, args.sample_far) {
        (Some(m), None) => Target::Mtbfa(m.samples(channel.period).ok_or_else(|| {
            InvalidInput(format!(
                "--mtbfa {m} is a time, and channel \"{}\" has no `period` (seconds per \
                 sample) to turn it into samples: set `period` in its configuration, or give \
                 the number of samples",
                channel.name
            ))
        })?),
        (None, Some(f)) => Target::SampleFar(f),
        _ => unreachable!("clap requires exactly one of --mtbfa and --sample-far"),
    };
    if let Some(config) = &args.config {
        for w in identification_overlap(config, &args.input) {
            eprintln!("glrmon calibrate: warning: {w}");
        }
    }
    let (stats, source) = match args.simulate {
        Some(n) => (
            simulated(channel, n, args.seed)?,
            format!("{n} samples simulated from seed {}", args.seed),
        ),
        None => (
            recorded(channel, &args.input)?,
            args.input
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        ),
    };
    let g = &channel.alarm;
    let calibration = calibrate_channel(channel, stats, target).map_err(calibrate_error)?;
    let ChannelCalibration {
        alarm: c,
        current_episodes,
        isolation,
        runs,
    } = &calibration;
    let alpha = channel.isolation_alpha;
    let warning = support_warning(&channel.name, c);
    if let Some(w) = &warning {
        eprintln!("glrmon calibrate: warning: {w}");
    }
    for r in runs.iter().filter(|r| !r.skipped.is_empty()) {
        eprintln!("glrmon calibrate: warning: {}", skipped_line(r));
    }
    let disagreement = disagreement_warning(&channel.name, &calibration);
    if let Some(w) = &disagreement {
        eprintln!("glrmon calibrate: warning: {w}");
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&calibration_json(
                &channel.name,
                &calibration,
                g.threshold,
                alpha,
                Warnings {
                    support: warning.as_deref(),
                    disagreement: disagreement.as_deref(),
                },
            ))?
        );
    } else {
        print!(
            "{}",
            text(
                &channel.name,
                c,
                g.threshold,
                *current_episodes,
                &source,
                channel.period
            )
        );
        print!("{}", runs_text(runs, c));
        print!("{}", isolation_text(isolation, alpha, args.write));
    }
    if args.write
        && let Some(path) = &args.config
    {
        write(path, &channel.name, c, isolation, &source)?;
        let written = isolation.iter().filter(|i| i.threshold().is_some()).count();
        eprintln!(
            "glrmon calibrate: {} updated: the detection threshold and {written} of {} \
             isolation thresholds written{}",
            path.display(),
            isolation.len(),
            if written < isolation.len() {
                " (the others are not calibrated: see why above)"
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// The files `glrmon identify` fitted the model of `config` to (its header line
/// "Identified by … from a.csv, b.csv.") that are among `inputs`, each as a warning: a
/// model's innovations are smaller on the data it was fitted to than on new data, so a
/// threshold calibrated there gives more false alarms on new data than it promises.
/// A listed file is the same as an input when both paths name one file, or, when the
/// listed path does not exist from here, when their file names are equal.
fn identification_overlap(config: &Path, inputs: &[PathBuf]) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(config) else {
        return Vec::new();
    };
    // The two notes identify writes: the subspace path's header, and `--model`'s
    // note on the noise it estimated.
    let listed: Vec<String> = text
        .lines()
        .filter_map(|l| {
            let files = if let Some(rest) = l.strip_prefix("# Identified by `glrmon identify") {
                rest.split_once("` from ")?.1
            } else {
                let rest = l.trim_start().strip_prefix('#')?;
                rest.split_once("(autocovariance least squares) on ")?.1
            };
            Some(
                files
                    .trim()
                    .strip_suffix('.')
                    .unwrap_or(files.trim())
                    .to_owned(),
            )
        })
        .collect();
    let same = |listed: &Path, input: &Path| match (listed.canonicalize(), input.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        (Err(_), _) => listed.file_name().is_some() && listed.file_name() == input.file_name(),
        _ => false,
    };
    let used: Vec<&PathBuf> = inputs
        .iter()
        .filter(|input| {
            listed
                .iter()
                .flat_map(|files| files.split(", "))
                .any(|l| same(Path::new(l), input))
        })
        .collect();
    if used.is_empty() {
        return Vec::new();
    }
    vec![format!(
        "{} {} the model of {} was identified from: its innovations are smaller there than \
         on new data, so a threshold calibrated on {} gives more false alarms on new data \
         than it promises; calibrate on other fault-free recordings (other days) for a \
         rate you can trust",
        used.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        if used.len() == 1 {
            "is data"
        } else {
            "are data"
        },
        config.display(),
        if used.len() == 1 { "it" } else { "them" },
    )]
}

/// A run's skipped rows: how many of its rows, by reason with the first of each.
fn skipped_line(r: &RunRate) -> String {
    let n: u64 = r.skipped.iter().map(|s| s.count).sum();
    format!(
        "{}: {n} of {} rows skipped: {}",
        r.name,
        r.rows,
        skip_summary(&r.skipped)
    )
}

/// A run's rate at the threshold in the target's unit, with its interval.
fn rate_text(r: &RunRate, target: Target) -> String {
    match target {
        Target::Mtbfa(_) => format!(
            "{}: one per {:.0} samples (95 % interval {:.0}–{:.0})",
            episodes(r.events),
            r.rate,
            r.interval.0,
            r.interval.1
        ),
        Target::SampleFar(_) => format!(
            "{:.3} % above the threshold (95 % interval {:.3}–{:.3} %), {} samples in {} \
             clusters",
            100.0 * r.rate,
            100.0 * r.interval.0,
            100.0 * r.interval.1,
            r.exceedances,
            r.events
        ),
    }
}

/// The runs that disagree beyond their 95 % intervals, named with their rates; `None`
/// when every pair's intervals overlap.
fn disagreement_warning(channel: &str, c: &ChannelCalibration) -> Option<String> {
    let pairs = c.disagreements();
    if pairs.is_empty() {
        return None;
    }
    let short = |r: &RunRate| match c.alarm.target {
        Target::Mtbfa(_) => format!(
            "{} (one episode per {:.0} samples, {:.0}–{:.0})",
            r.name, r.rate, r.interval.0, r.interval.1
        ),
        Target::SampleFar(_) => format!(
            "{} ({:.3} % above, {:.3}–{:.3} %)",
            r.name,
            100.0 * r.rate,
            100.0 * r.interval.0,
            100.0 * r.interval.1
        ),
    };
    let list: Vec<String> = pairs
        .iter()
        .map(|&(i, j)| format!("{} and {}", short(&c.runs[i]), short(&c.runs[j])))
        .collect();
    Some(format!(
        "channel \"{channel}\": runs disagree beyond their 95 % intervals at the threshold \
         {:.4}: {}; the rate varies from run to run more than sampling explains, so a new \
         run may see a rate outside the pooled interval",
        c.alarm.threshold,
        list.join("; ")
    ))
}

/// Each run's samples and rate at the threshold; nothing for a single run without
/// skipped rows (the pooled figures are its own).
fn runs_text(runs: &[RunRate], c: &Calibration) -> String {
    if runs.len() < 2 && runs.iter().all(|r| r.skipped.is_empty()) {
        return String::new();
    }
    let mut s = format!("\nruns at the threshold {:.4}:\n", c.threshold);
    for r in runs {
        let skipped: u64 = r.skipped.iter().map(|s| s.count).sum();
        let skipped = if skipped > 0 {
            format!(", {skipped} rows skipped")
        } else {
            String::new()
        };
        s.push_str(&format!(
            "  {}: {} samples{skipped}, {}\n",
            r.name,
            r.samples,
            rate_text(r, c.target)
        ));
    }
    s
}

/// Samples per independent event at the target: per expected episode or exceedance,
/// and for a per-sample target per cluster found, whichever is scarcer.
fn samples_per_event(c: &Calibration) -> f64 {
    let per_event = c.samples as f64 / c.expected.max(f64::MIN_POSITIVE);
    match c.target {
        Target::SampleFar(_) if c.episodes > 0 => {
            per_event.max(c.samples as f64 / c.episodes as f64)
        }
        _ => per_event,
    }
}

/// How loosely the data support λ when they hold fewer than [`MIN_EVENTS`] events at
/// the target: the count, the 95 % interval of the rate, and how much data 10 events
/// need. `None` when the support is enough.
fn support_warning(channel: &str, c: &Calibration) -> Option<String> {
    if c.well_supported() {
        return None;
    }
    let needed = (MIN_EVENTS * samples_per_event(c)).ceil();
    Some(match c.target {
        Target::Mtbfa(m) => format!(
            "channel \"{channel}\": {} fault-free samples hold {} false-alarm episodes at the \
             threshold, the target of one per {m} samples expects {:.1}: fewer than {MIN_EVENTS}, \
             so the threshold is loosely supported (95 % interval of the mean samples between \
             false alarms {:.0}–{:.0}, threshold {:.4}–{:.4}); {needed} samples would hold 10",
            c.samples,
            c.episodes,
            c.expected,
            c.rate_interval.0,
            c.rate_interval.1,
            c.threshold_interval.0,
            c.threshold_interval.1,
        ),
        Target::SampleFar(f) => format!(
            "channel \"{channel}\": {} fault-free samples hold {} samples above the threshold \
             in {} clusters, the target fraction {f} expects {:.1}: fewer than {MIN_EVENTS} \
             clusters, so the \
             threshold is loosely supported (95 % interval of the fraction {:.2e}–{:.2e}, \
             threshold {:.4}–{:.4}); about {needed} samples would hold 10 clusters",
            c.samples,
            c.exceedances,
            c.episodes,
            c.expected,
            c.rate_interval.0,
            c.rate_interval.1,
            c.threshold_interval.0,
            c.threshold_interval.1,
        ),
    })
}

/// The warnings of a calibration, as the `--json` line carries them.
struct Warnings<'a> {
    /// Fewer than 10 events at the target ([`support_warning`]).
    support: Option<&'a str>,
    /// Runs that disagree ([`disagreement_warning`]).
    disagreement: Option<&'a str>,
}

/// The `--json` line: the calibrated alarm threshold with its intervals, the target,
/// the data's event counts, each run's rate, and one entry per isolation test.
#[derive(Debug, Serialize)]
struct CalibrationJson<'a> {
    channel: &'a str,
    threshold: f64,
    /// The uncertainty of the threshold (low, high); an unbounded end is `null`.
    interval: [Option<f64>; 2],
    /// `mtbfa` or `sample_far`: which of the next two is set.
    target: &'static str,
    mtbfa: Option<f64>,
    sample_far: Option<f64>,
    /// The 95 % interval of the rate at the threshold in the target's unit (mean
    /// samples between false alarms, or the fraction of samples above it); an unbounded
    /// end is `null`, as JSON has no infinity.
    rate_interval: [Option<f64>; 2],
    samples: u64,
    /// Episodes at the threshold (for `sample_far`, clusters of exceedances).
    episodes: u64,
    exceedances: u64,
    /// Events (episodes, or exceedances) the target expects on the data.
    expected: f64,
    /// The support warning (fewer than 10 expected events), or `null`.
    warning: Option<&'a str>,
    /// The runs-disagree warning, or `null`.
    disagreement: Option<&'a str>,
    current_threshold: f64,
    current_episodes: u64,
    /// Each run (file, or simulated part) at the threshold.
    runs: Vec<RunJson<'a>>,
    isolation_alpha: f64,
    isolation: Vec<IsolationJson<'a>>,
}

/// One run in the `--json` line.
#[derive(Debug, Serialize)]
struct RunJson<'a> {
    name: &'a str,
    rows: u64,
    /// Skipped rows by reason: `{ reason, count, first }`.
    skipped: Vec<SkipJson<'a>>,
    samples: u64,
    exceedances: u64,
    /// Episodes (`mtbfa`) or clusters of exceedances (`sample_far`) at the threshold.
    events: u64,
    /// In the target's unit; `null` when unbounded.
    rate: Option<f64>,
    rate_interval: [Option<f64>; 2],
}

#[derive(Debug, Serialize)]
struct SkipJson<'a> {
    reason: &'a str,
    count: u64,
    first: &'a str,
}

/// One isolation test in the `--json` line.
#[derive(Debug, Serialize)]
struct IsolationJson<'a> {
    test: &'a str,
    /// The calibrated threshold; `null` when the test is not calibrated.
    threshold: Option<f64>,
    samples: u64,
    /// Why the test is not calibrated, or `null`.
    not_calibrated: Option<String>,
    /// The χ² threshold, in force for a test without a calibrated one.
    chi2_threshold: Option<f64>,
    current_threshold: f64,
    current_rate: f64,
}

/// A float as JSON writes it: `None` (`null`) when it is not finite.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn calibration_json<'a>(
    channel: &'a str,
    cal: &'a ChannelCalibration,
    current_threshold: f64,
    isolation_alpha: f64,
    warnings: Warnings<'a>,
) -> CalibrationJson<'a> {
    let c = &cal.alarm;
    let (target, mtbfa, sample_far) = match c.target {
        Target::Mtbfa(m) => ("mtbfa", Some(m), None),
        Target::SampleFar(f) => ("sample_far", None, Some(f)),
    };
    CalibrationJson {
        channel,
        threshold: c.threshold,
        interval: [
            finite(c.threshold_interval.0),
            finite(c.threshold_interval.1),
        ],
        target,
        mtbfa,
        sample_far,
        rate_interval: [finite(c.rate_interval.0), finite(c.rate_interval.1)],
        samples: c.samples,
        episodes: c.episodes,
        exceedances: c.exceedances,
        expected: c.expected,
        warning: warnings.support,
        disagreement: warnings.disagreement,
        current_threshold,
        current_episodes: cal.current_episodes,
        runs: cal
            .runs
            .iter()
            .map(|r| RunJson {
                name: &r.name,
                rows: r.rows,
                skipped: r
                    .skipped
                    .iter()
                    .map(|s| SkipJson {
                        reason: &s.reason,
                        count: s.count,
                        first: &s.first,
                    })
                    .collect(),
                samples: r.samples,
                exceedances: r.exceedances,
                events: r.events,
                rate: finite(r.rate),
                rate_interval: [finite(r.interval.0), finite(r.interval.1)],
            })
            .collect(),
        isolation_alpha,
        isolation: cal
            .isolation
            .iter()
            .map(|i| IsolationJson {
                test: &i.test,
                threshold: i.threshold(),
                samples: i.samples,
                not_calibrated: i.not_calibrated(isolation_alpha).map(|w| w.to_string()),
                chi2_threshold: finite(i.chi2),
                current_threshold: i.current,
                current_rate: i.current_rate,
            })
            .collect(),
    }
}

/// What stays in force for a test that is not calibrated: the χ² threshold, which
/// `--write` puts in place of a calibrated one of before.
fn instead(i: &IsolationCalibration, write: bool) -> String {
    if i.current == i.chi2 {
        format!("the χ² threshold {:.2} stays in force", i.chi2)
    } else if write {
        format!(
            "the χ² threshold {:.2} replaces the calibrated {:.2}",
            i.chi2, i.current
        )
    } else {
        format!(
            "the threshold in force {:.2} stays (--write would put the χ² threshold {:.2} in \
             its place)",
            i.current, i.chi2
        )
    }
}

fn isolation_text(isolation: &[IsolationCalibration], alpha: f64, write: bool) -> String {
    let mut s = format!("\nisolation tests at r̂ (type-I probability α = {alpha}):\n");
    let mut spanned = false;
    for i in isolation {
        if let Some(why) = i.not_calibrated(alpha) {
            spanned |= matches!(
                why,
                glrmon_eval::calibrate::NotCalibrated::NotIsolable { .. }
            );
            s.push_str(&format!(
                "  isolation {}: not calibrated: {why}; {}\n",
                i.test,
                instead(i, write)
            ));
            continue;
        }
        let q = i.quantile.map_or_else(String::new, |q| {
            format!(
                "threshold {:.4} (95 % interval {:.4}–{:.4}, {} samples)",
                q.value, q.interval.0, q.interval.1, q.samples
            )
        });
        s.push_str(&format!(
            "  {}: {q}; the current threshold {:.4} is exceeded by {:.2} % of the fault-free samples\n",
            i.test,
            i.current,
            100.0 * i.current_rate
        ));
    }
    if spanned {
        s.push_str(
            "  (a test that is not isolable can never isolate its fault alone: `glrmon \
             validate` names the faults it cannot be told from; a [[channels.glr.groups]] \
             group of them is tested as one)\n",
        );
    }
    s
}

fn text(
    channel: &str,
    c: &Calibration,
    current: f64,
    current_episodes: u64,
    source: &str,
    period: Option<f64>,
) -> String {
    let events = match c.target {
        Target::Mtbfa(_) => c.episodes,
        Target::SampleFar(_) => c.episodes.min(c.exceedances),
    };
    let precision = 1.96 / (events.max(1) as f64).sqrt();
    let per_event = samples_per_event(c);
    let (head, found, rate, target_line) = match c.target {
        Target::Mtbfa(m) => (
            format!(
                "one false-alarm episode per {}",
                samples_and_time(m, period)
            ),
            format!(
                "{} at the threshold (the target expects {:.1})",
                episodes(c.episodes),
                c.expected
            ),
            format!(
                "mean time between false alarms {}–{}",
                samples_and_time(c.rate_interval.0, period),
                samples_and_time(c.rate_interval.1, period)
            ),
            format!("mtbfa = {m:?}\n"),
        ),
        Target::SampleFar(f) => (
            format!("a fraction {f} of the samples above it"),
            format!(
                "{} samples above the threshold in {} clusters within the window (the target \
                 expects {:.1})",
                c.exceedances, c.episodes, c.expected
            ),
            format!(
                "fraction of samples above it {:.3e}–{:.3e}",
                c.rate_interval.0, c.rate_interval.1
            ),
            format!("sample_far = {f:?}\n"),
        ),
    };
    let exceedances = match c.target {
        Target::Mtbfa(_) => String::new(),
        Target::SampleFar(_) => format!("exceedances = {}\n", c.exceedances),
    };
    format!(
        "channel \"{channel}\": threshold {:.4} for {head}\n  \
         data: {} fault-free samples ({source}), {found}\n  95 % interval: threshold \
         {:.4}–{:.4}, {rate} (about ±{:.0} % on the rate; {} samples would give ±30 %)\n  \
         current threshold {current:.4}: {} on this data\n\n\
         [channels.glr.calibrated]\nthreshold = {:?}\n{target_line}samples = {}\n\
         episodes = {}\n{exceedances}interval = [{:?}, {:?}]\n",
        c.threshold,
        c.samples,
        c.threshold_interval.0,
        c.threshold_interval.1,
        precision * 100.0,
        (43.0 * per_event).ceil(),
        episodes(current_episodes),
        c.threshold,
        c.samples,
        c.episodes,
        c.threshold_interval.0,
        c.threshold_interval.1,
    )
}

/// `1 episode`, `2 episodes`.
fn episodes(n: u64) -> String {
    format!("{n} episode{}", if n == 1 { "" } else { "s" })
}

/// A library error with its exit code: [`InvalidInput`] (1) when the user's data or
/// request is at fault, a runtime failure (3) otherwise.
fn calibrate_error(e: CalibrateError) -> anyhow::Error {
    match e {
        CalibrateError::Input(e) => input_error(e),
        e if e.is_invalid_input() => InvalidInput(e.to_string()).into(),
        e => e.into(),
    }
}

/// The progress bar on a terminal (hidden otherwise).
fn bar(len: u64) -> Option<indicatif::ProgressBar> {
    std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(len);
        b.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} samples, eta {eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    })
}

/// [`glrmon_eval::calibrate::simulated`] with a progress bar.
fn simulated(channel: &glrmon_spec::Channel, n: u64, seed: u64) -> anyhow::Result<Statistics> {
    let progress = bar(n);
    let inc = |d: u64| {
        if let Some(b) = &progress {
            b.inc(d);
        }
    };
    let stats = glrmon_eval::calibrate::simulated(channel, n, seed, Some(&inc));
    if let Some(b) = progress {
        b.finish_and_clear();
    }
    stats.map_err(calibrate_error)
}

/// [`glrmon_eval::calibrate::recorded_files`] with a progress bar.
fn recorded(channel: &glrmon_spec::Channel, inputs: &[PathBuf]) -> anyhow::Result<Statistics> {
    let progress = bar(0);
    let inc = |d: u64| {
        if let Some(b) = &progress {
            b.inc(d);
        }
    };
    let stats = glrmon_eval::calibrate::recorded_files(channel, inputs, Some(&inc));
    if let Some(b) = progress {
        b.finish_and_clear();
    }
    stats.map_err(calibrate_error)
}

/// Sets `[channels.glr.calibrated]` of `channel` in the file
/// ([`glrmon_spec::edit::set_calibrated`]); everything else (comments, order) is kept.
fn write(
    path: &Path,
    channel: &str,
    c: &Calibration,
    isolation: &[IsolationCalibration],
    source: &str,
) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path)?;
    // Only the tests that were calibrated: a test without a finite positive quantile
    // keeps the χ² threshold (its line above says why).
    let thresholds: Vec<(&str, f64)> = isolation
        .iter()
        .filter_map(|i| Some((i.test.as_str(), i.threshold()?)))
        .collect();
    let updated = glrmon_spec::edit::set_calibrated(&text, channel, c, &thresholds, source)
        .map_err(|e| match e {
            EditError::Invalid(_) => InvalidInput(e.to_string()),
            e => InvalidInput(format!("{}: {e}", path.display())),
        })?;
    std::fs::write(path, updated)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_keeps_the_keys_and_writes_an_unbounded_interval_as_null() {
        let c = Calibration {
            threshold: 12.5,
            target: Target::Mtbfa(10000.0),
            samples: 1000,
            episodes: 0,
            exceedances: 0,
            expected: 0.1,
            rate_interval: (270.0, f64::INFINITY),
            threshold_interval: (11.0, f64::INFINITY),
        };
        let cal = ChannelCalibration {
            alarm: c,
            current_episodes: 2,
            isolation: vec![IsolationCalibration {
                test: "a\"b".into(),
                quantile: None,
                samples: 0,
                spanned: 0,
                current: 6.63,
                current_rate: 0.5,
                chi2: 6.63,
            }],
            runs: vec![RunRate {
                name: "a.csv".into(),
                rows: 1001,
                skipped: vec![glrmon_eval::calibrate::Skips {
                    reason: "non_finite".into(),
                    count: 1,
                    first: "row 3: column y0: \"nan\" is not finite".into(),
                }],
                samples: 1000,
                exceedances: 0,
                events: 0,
                rate: f64::INFINITY,
                interval: (270.0, f64::INFINITY),
            }],
        };
        let warning = support_warning("m", &c);
        let text = serde_json::to_string(&calibration_json(
            "m",
            &cal,
            13.0,
            0.01,
            Warnings {
                support: warning.as_deref(),
                disagreement: None,
            },
        ))
        .unwrap();
        assert_eq!(
            text,
            concat!(
                r#"{"channel":"m","threshold":12.5,"interval":[11.0,null],"target":"mtbfa","#,
                r#""mtbfa":10000.0,"sample_far":null,"rate_interval":[270.0,null],"samples":1000,"#,
                r#""episodes":0,"exceedances":0,"expected":0.1,"#,
                r#""warning":"channel \"m\": 1000 fault-free samples hold 0 false-alarm episodes at the threshold, the target of one per 10000 samples expects 0.1: fewer than 10, so the threshold is loosely supported (95 % interval of the mean samples between false alarms 270–inf, threshold 11.0000–inf); 100000 samples would hold 10","#,
                r#""disagreement":null,"current_threshold":13.0,"current_episodes":2,"#,
                r#""runs":[{"name":"a.csv","rows":1001,"skipped":[{"reason":"non_finite","count":1,"first":"row 3: column y0: \"nan\" is not finite"}],"#,
                r#""samples":1000,"exceedances":0,"events":0,"rate":null,"rate_interval":[270.0,null]}],"#,
                r#""isolation_alpha":0.01,"#,
                r#""isolation":[{"test":"a\"b","threshold":null,"samples":0,"#,
                r#""not_calibrated":"0 fault-free samples are too few: its (1 − α) quantile needs 1000 (10 above it)","#,
                r#""chi2_threshold":6.63,"current_threshold":6.63,"current_rate":0.5}]}"#
            )
        );
        let well = Calibration {
            expected: 10.0,
            ..c
        };
        assert_eq!(support_warning("m", &well), None);
        assert_eq!(
            isolation_text(&cal.isolation, 0.01, false),
            "\nisolation tests at r̂ (type-I probability α = 0.01):\n  isolation a\"b: not \
             calibrated: 0 fault-free samples are too few: its (1 − α) quantile needs 1000 (10 \
             above it); the χ² threshold 6.63 stays in force\n"
        );
    }
}
