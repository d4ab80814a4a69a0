//! `glrmon demo`: built-in simulated channels, one with an injected fault, through the
//! monitors; alarms printed as `watch` prints them, then a summary.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_core::AlarmSettings;
use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_monitor::{Monitor, MonitorSettings};
use glrmon_sim::{SimSample, Simulator, scenarios};
use glrmon_wire::{Sample, encode_json};

use crate::print;

/// Simulated samples per second of demo time.
const RATE_HZ: u64 = 100;

#[derive(Debug, Args)]
pub(crate) struct DemoArgs {
    /// Simulated duration in seconds (100 samples per second per channel).
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    /// Seed of the simulated noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write every record (stat, alarm, alarm_end, error) as JSON lines here.
    #[arg(long)]
    output: Option<PathBuf>,
}

struct Channel {
    monitor: Monitor,
    sim: Simulator,
    fault: Option<(&'static str, u64, f64)>,
}

fn channel(
    name: &str,
    sc: &scenarios::Scenario,
    seed: u64,
    fault: Option<(&'static str, u64, f64)>,
) -> anyhow::Result<Channel> {
    let w = sc.window;
    let m = sc.faults.len() as f64;
    // Bonferroni over the window's w − s onsets: a conservative per-sample rate of 10⁻⁴.
    let threshold = chi2_upper_quantile(m, 1e-4 / (w.window - w.min_lag) as f64)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let sim = match fault {
        Some((f, onset, mag)) => sc.faulty_simulator(seed, f, onset, mag)?,
        None => sc.simulator(seed)?,
    };
    let settings = MonitorSettings {
        alarm: AlarmSettings::with_threshold(threshold),
        isolation_delay: sc.model_states() as u32,
        isolation_alpha: 0.01,
        groups: vec![],
        max_gap: 100,
    };
    Ok(Channel {
        monitor: Monitor::new(name, sc.detector()?, settings),
        sim,
        fault,
    })
}

pub(crate) fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let samples = args.seconds * RATE_HZ;
    let mut channels = vec![
        channel(
            "unstable",
            &scenarios::paper2014_unstable(),
            args.seed,
            Some(("x0_jump", 201, 4.0)),
        )?,
        channel("lpv", &scenarios::bench_a(), args.seed + 1, Some(("sensor_bias", 301, 1.0)))?,
        channel("lpv_clean", &scenarios::bench_a(), args.seed + 2, None)?,
    ];
    println!(
        "glrmon demo: {} channels, {samples} samples each ({} s at {RATE_HZ} Hz), offline",
        channels.len(),
        args.seconds
    );
    for c in &channels {
        match c.fault {
            Some((f, k, v)) => println!("  {}: fault {f} of magnitude {v} injected at k = {k}", c.monitor.channel()),
            None => println!("  {}: no fault", c.monitor.channel()),
        }
    }
    let mut out = match &args.output {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?,
        )),
        None => None,
    };
    let mut records = Vec::new();
    let mut buf = Vec::new();
    let mut x = SimSample {
        k: 0,
        u: vec![],
        y: vec![],
        p: vec![],
    };
    for k in 0..samples {
        for c in &mut channels {
            c.sim.next_into(&mut x);
            let sample = Sample {
                k: Some(x.k),
                t: Some(k as f64 / RATE_HZ as f64),
                u: x.u.clone(),
                y: x.y.clone(),
                p: x.p.clone(),
            };
            c.monitor.on_sample(&sample, &mut records);
        }
        for r in records.drain(..) {
            if let Some(line) = print::line(&r) {
                println!("{line}");
            }
            if let Some(w) = &mut out {
                buf.clear();
                encode_json(&r, &mut buf)?;
                buf.push(b'\n');
                w.write_all(&buf)?;
            }
        }
    }
    if let Some(mut w) = out {
        w.flush()?;
    }
    println!("summary:");
    for c in &channels {
        let n = c.monitor.counters();
        let errors: u64 = n.errors.values().sum();
        println!(
            "  {:<10} samples={} alarms={} errors={} active={}",
            c.monitor.channel(),
            n.samples,
            n.alarms,
            errors,
            c.monitor.alarm_active()
        );
    }
    if let Some(p) = &args.output {
        println!("records written to {}", p.display());
    }
    Ok(())
}
