//! `glrmon calibrate`: the detection threshold of a channel for a target mean time
//! between false alarms, found on fault-free data (a recording, or data simulated from
//! the channel's model) with the channel's own monitor, so that gaps, restarts and the
//! hysteresis count as they do live. See [`glrmon_core::calibration`].

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use clap::Args;

use glrmon_core::calibration::Calibration;
use glrmon_eval::calibrate::{
    CalibrateError, ChannelCalibration, IsolationCalibration, Statistics, calibrate_channel,
};
use glrmon_spec::edit::EditError;
use serde::Serialize;

use glrmon_input::{is_mcap, recorded_config};

use crate::common::pick;
use crate::common::{InvalidInput, input_error, load_config};

#[derive(Debug, Args)]
pub(crate) struct CalibrateArgs {
    /// Configuration file (optional for MCAP input: the recorded one is used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Channel to calibrate (optional when the configuration has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// Fault-free recorded samples: CSV or MCAP.
    #[arg(conflicts_with = "simulate", required_unless_present = "simulate")]
    input: Option<PathBuf>,
    /// Simulate this many fault-free samples from the channel's model instead (split
    /// over the cores, each part with its own seed).
    #[arg(long)]
    simulate: Option<u64>,
    /// Seed of the first simulated part.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Target mean number of samples between false-alarm episodes.
    #[arg(long)]
    mtbfa: f64,
    /// Write the result into the configuration file as `[channels.glr.calibrated]`
    /// (comments and layout kept).
    #[arg(long)]
    write: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

pub(crate) fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let cfg = match (&args.config, &args.input) {
        (Some(path), _) => load_config(path)?,
        (None, Some(input)) if is_mcap(input) => recorded_config(input).map_err(input_error)?,
        _ => {
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
    let (stats, source) = match (args.simulate, &args.input) {
        (Some(n), _) => (
            simulated(channel, n, args.seed)?,
            format!("{n} samples simulated from seed {}", args.seed),
        ),
        (None, Some(input)) => (recorded(channel, input)?, format!("{}", input.display())),
        (None, None) => unreachable!("clap requires one"),
    };
    let g = &channel.alarm;
    let ChannelCalibration {
        alarm: c,
        current_episodes,
        isolation,
    } = calibrate_channel(channel, stats, args.mtbfa).map_err(calibrate_error)?;
    let alpha = channel.isolation_alpha;
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&calibration_json(
                &channel.name,
                &c,
                g.threshold,
                current_episodes,
                alpha,
                &isolation
            ))?
        );
    } else {
        print!(
            "{}",
            text(&channel.name, &c, g.threshold, current_episodes, &source)
        );
        print!("{}", isolation_text(&isolation, alpha));
    }
    if args.write
        && let Some(path) = &args.config
    {
        write(path, &channel.name, &c, &isolation, &source)?;
        eprintln!("glrmon calibrate: {} updated", path.display());
    }
    Ok(())
}

/// The `--json` line: the calibrated alarm threshold with its intervals, the data's
/// episode counts, and one entry per isolation test.
#[derive(Debug, Serialize)]
struct CalibrationJson<'a> {
    channel: &'a str,
    threshold: f64,
    /// The uncertainty of the threshold (low, high).
    interval: [Option<f64>; 2],
    mtbfa: f64,
    /// The 95 % interval of the mean samples between false alarms; an unbounded end
    /// (no episode on the data) is `null`, as JSON has no infinity.
    mtbfa_interval: [Option<f64>; 2],
    samples: u64,
    episodes: u64,
    expected_episodes: f64,
    current_threshold: f64,
    current_episodes: u64,
    isolation_alpha: f64,
    isolation: Vec<IsolationJson<'a>>,
}

/// One isolation test in the `--json` line.
#[derive(Debug, Serialize)]
struct IsolationJson<'a> {
    test: &'a str,
    /// The calibrated threshold; `null` without data for the test.
    threshold: Option<f64>,
    samples: u64,
    current_threshold: f64,
    current_rate: f64,
}

/// A float as JSON writes it: `None` (`null`) when it is not finite.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn calibration_json<'a>(
    channel: &'a str,
    c: &Calibration,
    current_threshold: f64,
    current_episodes: u64,
    isolation_alpha: f64,
    isolation: &'a [IsolationCalibration],
) -> CalibrationJson<'a> {
    CalibrationJson {
        channel,
        threshold: c.threshold,
        interval: [
            finite(c.threshold_interval.0),
            finite(c.threshold_interval.1),
        ],
        mtbfa: c.mtbfa,
        mtbfa_interval: [finite(c.mtbfa_interval.0), finite(c.mtbfa_interval.1)],
        samples: c.samples,
        episodes: c.episodes,
        expected_episodes: c.expected_episodes,
        current_threshold,
        current_episodes,
        isolation_alpha,
        isolation: isolation
            .iter()
            .map(|i| IsolationJson {
                test: &i.test,
                threshold: i.quantile.map(|q| q.value),
                samples: i.quantile.map_or(0, |q| q.samples),
                current_threshold: i.current,
                current_rate: i.current_rate,
            })
            .collect(),
    }
}

fn isolation_text(isolation: &[IsolationCalibration], alpha: f64) -> String {
    let mut s = format!("\nisolation tests at r̂ (type-I probability α = {alpha}):\n");
    for i in isolation {
        let q = i.quantile.map_or_else(
            || "too little data for this α".to_owned(),
            |q| {
                format!(
                    "threshold {:.4} (95 % interval {:.4}–{:.4}, {} samples)",
                    q.value, q.interval.0, q.interval.1, q.samples
                )
            },
        );
        s.push_str(&format!(
            "  {}: {q}; the current threshold {:.4} is exceeded by {:.2} % of the fault-free samples\n",
            i.test,
            i.current,
            100.0 * i.current_rate
        ));
    }
    s
}

fn text(
    channel: &str,
    c: &Calibration,
    current: f64,
    current_episodes: u64,
    source: &str,
) -> String {
    let precision = 1.96 / (c.episodes.max(1) as f64).sqrt();
    format!(
        "channel \"{channel}\": threshold {:.4} for one false-alarm episode per {} samples\n  \
         data: {} fault-free samples ({source}), {} episodes at the threshold (the target \
         expects {:.1})\n  95 % interval: threshold {:.4}–{:.4}, mean samples between false \
         alarms {:.0}–{:.0} (about ±{:.0} % on the rate; {} samples would give ±30 %)\n  \
         current threshold {current:.4}: {current_episodes} episodes on this data\n\n[channels.glr.calibrated]\nthreshold = {:?}\nmtbfa = {:?}\nsamples = {}\nepisodes = {}\ninterval = [{:?}, {:?}]\n",
        c.threshold,
        c.mtbfa,
        c.samples,
        c.episodes,
        c.expected_episodes,
        c.threshold_interval.0,
        c.threshold_interval.1,
        c.mtbfa_interval.0,
        c.mtbfa_interval.1,
        precision * 100.0,
        (43.0 * c.mtbfa).ceil(),
        c.threshold,
        c.mtbfa,
        c.samples,
        c.episodes,
        c.threshold_interval.0,
        c.threshold_interval.1,
    )
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

/// [`glrmon_eval::calibrate::recorded`] with a progress bar.
fn recorded(channel: &glrmon_spec::Channel, input: &Path) -> anyhow::Result<Statistics> {
    let progress = bar(0);
    let inc = |d: u64| {
        if let Some(b) = &progress {
            b.inc(d);
        }
    };
    let stats = glrmon_eval::calibrate::recorded(channel, input, Some(&inc));
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
    let thresholds: Vec<(&str, f64)> = isolation
        .iter()
        .filter_map(|i| i.quantile.map(|q| (i.test.as_str(), q.value)))
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
            samples: 1000,
            episodes: 0,
            mtbfa: 10000.0,
            mtbfa_interval: (270.0, f64::INFINITY),
            threshold_interval: (11.0, 14.0),
            expected_episodes: 0.1,
        };
        let isolation = [IsolationCalibration {
            test: "a\"b".into(),
            quantile: None,
            current: 6.63,
            current_rate: 0.5,
        }];
        let text =
            serde_json::to_string(&calibration_json("m", &c, 13.0, 2, 0.01, &isolation)).unwrap();
        assert_eq!(
            text,
            concat!(
                r#"{"channel":"m","threshold":12.5,"interval":[11.0,14.0],"mtbfa":10000.0,"#,
                r#""mtbfa_interval":[270.0,null],"samples":1000,"episodes":0,"expected_episodes":0.1,"#,
                r#""current_threshold":13.0,"current_episodes":2,"isolation_alpha":0.01,"#,
                r#""isolation":[{"test":"a\"b","threshold":null,"samples":0,"current_threshold":6.63,"current_rate":0.5}]}"#
            )
        );
    }
}
