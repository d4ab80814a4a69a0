//! The quadruple-tank detection table of docs/IDENTIFY.md: a nonlinear plant
//! (`glrmon_sim::tank`, Johansson 2000, set P−) identified from three fault-free runs,
//! calibrated on them, and monitored on independent fault-free and faulty runs.
//!
//! ```text
//! cargo run --release -p glrmon-eval --example quadruple_tank_table [-- RUNS]
//! ```
//!
//! Each step is the library call behind the CLI command a user runs:
//! `glrmon identify` ([`identify_channel`]), `glrmon calibrate` ([`recorded`],
//! [`calibrate_channel`]) and `glrmon replay` (the channel's [`Monitor`]).

use std::path::PathBuf;

use glrmon_core::threshold::calibration::{Target, count_episodes};
use glrmon_eval::calibrate::{Statistics, calibrate_channel, recorded};
use glrmon_eval::identify::{IdentifyRequest, identify_channel};
use glrmon_monitor::Monitor;
use glrmon_sim::tank::{TankFault, TankFaultKind, TankRecording, TankRun};
use glrmon_spec::Channel;
use glrmon_wire::{Record, Sample};

const SAMPLES: usize = 2000;
const ONSET: u64 = 1000;
/// An alarm later than this after the onset is not counted as a detection.
const HORIZON: u64 = 500;
const MTBFA: f64 = 2000.0;

fn samples(rec: &TankRecording) -> Vec<Sample> {
    (0..rec.k.len())
        .map(|i| Sample {
            k: Some(rec.k[i]),
            t: Some(rec.t[i]),
            u: rec.u[i].clone(),
            y: rec.y[i].clone(),
            p: vec![],
        })
        .collect()
}

struct Outcome {
    glr: Vec<f64>,
    /// (alarm k, isolated faults of its last isolation, θ̂ then)
    alarms: Vec<(u64, Vec<String>, Vec<f64>)>,
}

fn monitor(channel: &Channel, run: &[Sample]) -> Outcome {
    let mut mon = Monitor::from_channel(channel).expect("monitor");
    let (mut records, mut glr, mut alarms) = (Vec::new(), Vec::new(), Vec::new());
    for s in run {
        mon.on_sample(s, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Stat(s) => glr.push(s.glr.unwrap_or(f64::NAN)),
                Record::Alarm(a) => alarms.push((
                    a.k,
                    a.isolation
                        .iter()
                        .filter(|i| i.isolated)
                        .map(|i| i.fault.clone())
                        .collect(),
                    a.magnitude.clone(),
                )),
                Record::Isolation(u) => {
                    if let Some(last) = alarms.iter_mut().rev().find(|a| a.0 == u.alarm_k) {
                        last.1 = u
                            .isolation
                            .iter()
                            .filter(|i| i.isolated)
                            .map(|i| i.fault.clone())
                            .collect();
                        last.2.clone_from(&u.magnitude);
                    }
                }
                _ => {}
            }
        }
    }
    Outcome { glr, alarms }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let runs: u64 = std::env::args()
        .nth(1)
        .map_or(50, |a| a.parse().expect("RUNS is a number"));
    let dir = std::env::temp_dir().join(format!("glrmon-tank-table-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    let base = TankRun {
        samples: SAMPLES,
        ..TankRun::default()
    };
    let files: Vec<PathBuf> = (1..=3)
        .map(|seed| {
            let rec = TankRun {
                seed,
                ..base.clone()
            }
            .simulate()
            .expect("tank");
            let path = dir.join(format!("fault_free_{seed}.csv"));
            std::fs::write(&path, rec.csv()).expect("write");
            path
        })
        .collect();
    let channel = identify_and_calibrate(&files);
    fault_free(&channel, runs, &base);
    println!(
        "| fault (from k = {ONSET}) | magnitude | detected | median delay | false alarms before | isolated alone | θ̂ median |"
    );
    println!("|---|---|---|---|---|---|---|");
    let faults: Vec<(String, TankFault, f64, &str)> = (0..4)
        .map(|i| {
            (
                format!("y{i}_bias"),
                TankFault::sensor_bias(i, ONSET),
                0.125,
                "V",
            )
        })
        .chain((0..2).map(|j| {
            (
                format!("u{j}_bias"),
                TankFault::actuator_bias(j, ONSET),
                0.25,
                "V",
            )
        }))
        .chain((0..4).map(|i| {
            (
                format!("leak tank {i}"),
                TankFault::leak(i, ONSET),
                0.003,
                "cm²",
            )
        }))
        .collect();
    for (index, fault) in faults.iter().enumerate() {
        fault_row(&channel, runs, &base, index, fault);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The channel identified from `files` and calibrated on them for one false-alarm
/// episode per [`MTBFA`] samples, with a line saying so.
fn identify_and_calibrate(files: &[PathBuf]) -> Channel {
    let started = std::time::Instant::now();
    let identified = identify_channel(&IdentifyRequest {
        channel: "tank".into(),
        files: files.to_vec(),
        inputs: None,
        outputs: None,
        settings: glrmon_ident::IdentSettings::default(),
        window: 50,
        topics: None,
        notes: vec![],
    })
    .expect("identify");
    let identify_time = started.elapsed().as_secs_f64();
    let mut channel = glrmon_spec::parse(&identified.config)
        .expect("config")
        .channels[0]
        .clone();
    let mut stats = Statistics::default();
    for f in files {
        stats.append(recorded(&channel, f, None).expect("statistics"));
    }
    let cal = calibrate_channel(&channel, stats, Target::Mtbfa(MTBFA)).expect("calibrate");
    channel.alarm.threshold = cal.alarm.threshold;
    let v = &identified.identification.validation;
    println!(
        "Identified from 3 × {SAMPLES} fault-free samples in {identify_time:.2} s: order {}, \
         held-out NRMSE {:.3?}, NIS mean {:.3} (expected 4); threshold λ = {:.2} for one \
         false-alarm episode per {MTBFA} samples.\n",
        identified.identification.model.order(),
        v.nrmse.as_slice(),
        v.nis_mean.unwrap_or(f64::NAN),
        channel.alarm.threshold
    );
    channel
}

/// False-alarm episodes and the fraction of samples above λ on `runs` fault-free runs.
fn fault_free(channel: &Channel, runs: u64, base: &TankRun) {
    let (mut episodes, mut above, mut counted) = (0u64, 0usize, 0usize);
    for seed in 0..runs {
        let rec = TankRun {
            seed: 5000 + seed,
            ..base.clone()
        }
        .simulate()
        .expect("tank");
        let out = monitor(channel, &samples(&rec));
        episodes += count_episodes(&out.glr, channel.alarm);
        above += out
            .glr
            .iter()
            .filter(|l| **l > channel.alarm.threshold)
            .count();
        counted += out.glr.iter().filter(|l| !l.is_nan()).count();
    }
    println!(
        "Fault-free: {runs} runs × {SAMPLES} samples: {episodes} false-alarm episodes \
         (one per {:.0} samples; target {MTBFA}), {:.2} % of samples above λ.\n",
        counted as f64 / episodes.max(1) as f64,
        100.0 * above as f64 / counted as f64
    );
}

/// One row of the table: a fault (its name, profile, magnitude and unit) injected in
/// `runs` runs.
fn fault_row(
    channel: &Channel,
    runs: u64,
    base: &TankRun,
    index: usize,
    (name, fault, magnitude, unit): &(String, TankFault, f64, &str),
) {
    let fault = *fault;
    let (mut detected, mut delays, mut early, mut alone, mut theta) =
        (0, Vec::new(), 0, 0, Vec::new());
    let mut isolated_as: std::collections::BTreeMap<String, u32> = Default::default();
    for seed in 0..runs {
        let rec = TankRun {
            seed: 10_000 * (index as u64 + 1) + seed,
            faults: vec![fault],
            ..base.clone()
        }
        .simulate()
        .expect("tank");
        let out = monitor(channel, &samples(&rec));
        early += out.alarms.iter().filter(|a| a.0 < ONSET).count();
        let Some((k, isolated, magnitudes)) = out
            .alarms
            .iter()
            .find(|a| a.0 >= ONSET && a.0 < ONSET + HORIZON)
        else {
            continue;
        };
        detected += 1;
        delays.push((k - ONSET) as f64);
        *isolated_as
            .entry(if isolated.is_empty() {
                "none".into()
            } else {
                isolated.join("+")
            })
            .or_default() += 1;
        if isolated.len() == 1 && isolated[0] == *name {
            alone += 1;
        }
        if let Some(i) = channel.fault_names.iter().position(|f| f == name) {
            theta.push(magnitudes[i]);
        }
    }
    let delay = median(delays);
    let isolation = if matches!(fault.kind, TankFaultKind::Leak { .. }) {
        let top = isolated_as.iter().max_by_key(|(_, n)| **n);
        top.map_or("—".into(), |(f, n)| format!("(as {f}: {n}/{detected})"))
    } else {
        format!("{alone}/{detected}")
    };
    let theta = if theta.is_empty() {
        "—".into()
    } else {
        format!("{:.3} {unit}", median(theta))
    };
    println!(
        "| {name} | {magnitude} {unit} | {detected}/{runs} | {delay} samples ({} s) | {early} | {isolation} | {theta} |",
        delay * base.sample_period
    );
}
