//! `glrmon demo`: the channels of the embedded `config/demo.toml` simulated, one fault
//! injected a few seconds in, through the monitors; alarms printed as `watch` prints
//! them, then a summary.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_sim::{SimSample, Simulator};
use glrmon_wire::{Sample, encode_json};

use crate::{print, simulate};

/// The demo's channels, embedded so the demo needs no file.
pub(crate) const DEMO_CONFIG: &str = include_str!("../../../config/demo.toml");

/// Simulated samples per second of demo time.
const RATE_HZ: u64 = 100;

/// The injected fault: channel, fault, onset, magnitude.
const FAULT: (&str, &str, u64, f64) = ("unstable", "x0_jump", 201, 4.0);

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
}

pub(crate) fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let cfg = glrmon_spec::parse(DEMO_CONFIG)
        .map_err(|e| anyhow::anyhow!("embedded demo config: {e}"))?;
    let samples = args.seconds * RATE_HZ;
    let mut channels = Vec::new();
    for (i, c) in cfg.channels.iter().enumerate() {
        let seed = args.seed.wrapping_add(i as u64);
        let sim = if c.name == FAULT.0 {
            simulate::simulator(c, seed, &[FAULT.1.to_owned()], FAULT.2, &[FAULT.3])?
        } else {
            simulate::simulator(c, seed, &[], 0, &[])?
        };
        channels.push(Channel {
            monitor: Monitor::from_channel(c)?,
            sim,
        });
    }
    println!(
        "glrmon demo: {} channels ({}), {samples} samples each ({} s at {RATE_HZ} Hz), offline",
        channels.len(),
        cfg.channels
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        args.seconds
    );
    println!(
        "  injected: fault {} of magnitude {} on channel {} at k = {} ({:.2} s)",
        FAULT.1,
        FAULT.3,
        FAULT.0,
        FAULT.2,
        FAULT.2 as f64 / RATE_HZ as f64
    );
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
    let mut sample = Sample::default();
    for k in 0..samples {
        for c in &mut channels {
            c.sim.next_into(&mut x);
            sample.k = Some(x.k);
            sample.t = Some(k as f64 / RATE_HZ as f64);
            sample.u.clone_from(&x.u);
            sample.y.clone_from(&x.y);
            sample.p.clone_from(&x.p);
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
