//! `glrmon calibrate`: the detection threshold of a channel for a target mean time
//! between false alarms, found on fault-free data (a recording, or data simulated from
//! the channel's model) with the channel's own monitor, so that gaps, restarts and the
//! hysteresis count as they do live. See [`glrmon_core::calibration`].

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use clap::Args;
use std::collections::BTreeMap;

use glrmon_core::calibration::{
    Calibration, CalibrationError, Quantile, calibrate, count_episodes, upper_quantile,
};
use glrmon_monitor::Monitor;
use glrmon_sim::SimSample;
use glrmon_wire::{Record, Sample};
use serde::Serialize;

use glrmon_input::{Samples, is_mcap, recorded_config};

use crate::common::pick;
use crate::common::simulator;
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
    let current_episodes = count_episodes(&stats.glr, *g);
    let c =
        calibrate(&stats.glr, args.mtbfa, g.hysteresis, g.clear_samples).map_err(|e| match e {
            CalibrationError::TooLittleData { .. } | CalibrationError::Invalid(_) => {
                InvalidInput(format!("channel \"{}\": {e}", channel.name))
            }
        })?;
    let alpha = channel.isolation_alpha;
    let mut isolation = Vec::new();
    for (test, mut values) in stats.isolation {
        let current = current_isolation_threshold(channel, &test);
        let exceeded =
            values.iter().filter(|&&v| v > current).count() as f64 / values.len().max(1) as f64;
        let q = upper_quantile(&mut values, alpha);
        isolation.push(IsolationCalibration {
            test,
            quantile: q,
            current,
            current_rate: exceeded,
        });
    }
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
    if args.write {
        if let Some(path) = &args.config {
            write(path, &channel.name, &c, &isolation, &source)?;
            eprintln!("glrmon calibrate: {} updated", path.display());
        }
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

/// The isolation threshold of one test.
struct IsolationCalibration {
    test: String,
    /// The (1 − α) quantile of its minmax statistic at r̂ on the data.
    quantile: Option<Quantile>,
    /// The threshold in force and the fraction of the data above it.
    current: f64,
    current_rate: f64,
}

/// The isolation threshold the channel uses now for `test`.
fn current_isolation_threshold(channel: &glrmon_spec::Channel, test: &str) -> f64 {
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

/// What the channel's monitor gave on the fault-free data.
#[derive(Debug, Default)]
struct Statistics {
    /// l_k of every sample (NaN where no onset is admissible).
    glr: Vec<f64>,
    /// The minmax statistic of each isolation test at r̂, by test.
    isolation: BTreeMap<String, Vec<f64>>,
}

/// The statistics of the channel's monitor fed with `samples`; a sample the monitor
/// rejects contributes nothing.
fn monitor_glr(
    channel: &glrmon_spec::Channel,
    mut next: impl FnMut(&mut Sample) -> anyhow::Result<bool>,
    progress: Option<&indicatif::ProgressBar>,
) -> anyhow::Result<Statistics> {
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
        if n % 65_536 == 0 {
            if let Some(p) = progress {
                p.inc(65_536);
            }
        }
    }
    Ok(stats)
}

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

/// `n` fault-free samples from the model, in one part per core (seeds seed, seed+1, …).
fn simulated(channel: &glrmon_spec::Channel, n: u64, seed: u64) -> anyhow::Result<Statistics> {
    let parts = std::thread::available_parallelism()
        .map_or(1, std::num::NonZero::get)
        .min(usize::try_from(n / 10_000).unwrap_or(1).max(1)) as u64;
    let progress = bar(n);
    let results: Vec<anyhow::Result<Statistics>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..parts)
            .map(|i| {
                let len = n / parts + u64::from(i < n % parts);
                let progress = progress.as_ref();
                scope.spawn(move || {
                    let mut sim = simulator(channel, seed + i, &[], 0, &[])?;
                    let mut x = SimSample {
                        k: 0,
                        u: vec![],
                        y: vec![],
                        p: vec![],
                    };
                    let mut left = len;
                    monitor_glr(
                        channel,
                        |s| {
                            if left == 0 {
                                return Ok(false);
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
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("a calibration thread panicked")))
            })
            .collect()
    });
    if let Some(b) = progress {
        b.finish_and_clear();
    }
    let mut all = Statistics::default();
    for r in results {
        // The parts are independent runs: joined, one sample with no admissible onset
        // between them keeps an episode from spanning two parts.
        let r = r?;
        all.glr.extend(r.glr);
        all.glr.push(f64::NAN);
        for (test, values) in r.isolation {
            all.isolation.entry(test).or_default().extend(values);
        }
    }
    Ok(all)
}

fn recorded(channel: &glrmon_spec::Channel, input: &Path) -> anyhow::Result<Statistics> {
    let mut samples = Samples::open(input, &channel.name, channel.dims).map_err(input_error)?;
    let progress = bar(0);
    let stats = monitor_glr(
        channel,
        |s| loop {
            match samples.next_into(s).map_err(input_error)? {
                None => return Ok(false),
                Some(Ok(())) => return Ok(true),
                // A row or payload the monitor never saw: skipped, as live.
                Some(Err(_)) => {}
            }
        },
        progress.as_ref(),
    )?;
    if let Some(b) = progress {
        b.finish_and_clear();
    }
    Ok(stats)
}

/// Sets `[channels.glr.calibrated]` of `channel` in the file, removing the other ways of
/// setting the threshold; everything else (comments, order) is kept.
fn write(
    path: &Path,
    channel: &str,
    c: &Calibration,
    isolation: &[IsolationCalibration],
    source: &str,
) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path)?;
    let mut doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e| InvalidInput(format!("{}: {e}", path.display())))?;
    let channels = doc
        .get_mut("channels")
        .and_then(toml_edit::Item::as_array_of_tables_mut)
        .ok_or_else(|| InvalidInput(format!("{}: no [[channels]]", path.display())))?;
    let table = channels
        .iter_mut()
        .find(|t| t.get("name").and_then(|v| v.as_str()) == Some(channel))
        .ok_or_else(|| InvalidInput(format!("{}: no channel \"{channel}\"", path.display())))?;
    if table.get("glr").is_none() {
        table.insert("glr", toml_edit::table());
    }
    let glr = table
        .get_mut("glr")
        .and_then(toml_edit::Item::as_table_mut)
        .ok_or_else(|| InvalidInput(format!("{}: channels.glr is not a table", path.display())))?;
    for key in ["threshold", "false_alarm", "threshold_mode"] {
        glr.remove(key);
    }
    let mut cal = toml_edit::Table::new();
    cal.insert("threshold", toml_edit::value(c.threshold));
    cal.insert("mtbfa", toml_edit::value(c.mtbfa));
    cal.insert(
        "samples",
        toml_edit::value(i64::try_from(c.samples).unwrap_or(i64::MAX)),
    );
    cal.insert(
        "episodes",
        toml_edit::value(i64::try_from(c.episodes).unwrap_or(i64::MAX)),
    );
    let mut interval = toml_edit::Array::new();
    interval.push(c.threshold_interval.0);
    interval.push(c.threshold_interval.1);
    cal.insert("interval", toml_edit::value(interval));
    cal.insert("source", toml_edit::value(source));
    let mut iso = toml_edit::InlineTable::new();
    for i in isolation {
        if let Some(q) = i.quantile {
            iso.insert(&i.test, q.value.into());
        }
    }
    if !iso.is_empty() {
        cal.insert("isolation", toml_edit::value(iso));
    }
    glr.insert("calibrated", toml_edit::Item::Table(cal));
    let updated = doc.to_string();
    glrmon_spec::parse(&updated)
        .map_err(|e| InvalidInput(format!("the updated configuration would be invalid:\n{e}")))?;
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
