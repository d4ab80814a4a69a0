//! Writes quadruple-tank recordings (Johansson 2000, P−) as glrmon CSV sample files.
//!
//! ```text
//! cargo run -p glrmon-sim --example quadruple_tank -- OUTDIR [--samples N] [--seed S] [--experiments E]
//! ```
//!
//! OUTDIR receives `fault_free_<i>.csv` (E fault-free experiments, default 3, seeds S + i),
//! one faulty file per fault (`sensor_bias_y<i>.csv`, `actuator_bias_u<j>.csv`,
//! `leak_tank<i>.csv`, seeds S + 100 + file number, onset at N/2 with the default
//! magnitudes of `glrmon_sim::tank`) and `faults.txt` listing each faulty file's onset and
//! magnitude. Columns `k,t,u0,u1,y0,y1,y2,y3`: k from 0, t in s, u the commanded pump
//! voltages (V), y the level sensors (V, kc = 0.5 V/cm), around the operating point.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glrmon_sim::tank::{TankFault, TankFaultKind, TankRecording, TankRun};

fn usage() -> ! {
    eprintln!("usage: quadruple_tank OUTDIR [--samples N] [--seed S] [--experiments E]");
    std::process::exit(2)
}

fn write(dir: &Path, name: &str, text: &str) {
    let path = dir.join(name);
    if let Err(e) = std::fs::write(&path, text) {
        eprintln!("quadruple_tank: cannot write {}: {e}", path.display());
        std::process::exit(1);
    }
    println!("{} ({} bytes)", path.display(), text.len());
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut dir: Option<PathBuf> = None;
    let (mut samples, mut seed, mut experiments) = (2000_usize, 1_u64, 3_u64);
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or_else(|| usage())
        };
        match a.as_str() {
            "--samples" => samples = value() as usize,
            "--seed" => seed = value(),
            "--experiments" => experiments = value(),
            "-h" | "--help" => usage(),
            _ if dir.is_none() && !a.starts_with("--") => dir = Some(PathBuf::from(a)),
            _ => usage(),
        }
    }
    let dir = dir.unwrap_or_else(|| usage());
    if samples < 2 {
        usage();
    }
    if let Err(e) = std::fs::create_dir_all(&dir) {
        eprintln!("quadruple_tank: cannot create {}: {e}", dir.display());
        std::process::exit(1);
    }
    let base = TankRun {
        samples,
        ..TankRun::default()
    };
    let run = |run: TankRun| {
        run.simulate().unwrap_or_else(|e| {
            eprintln!("quadruple_tank: {e}");
            std::process::exit(1)
        })
    };
    for i in 0..experiments {
        let rec = run(TankRun {
            seed: seed + i,
            ..base.clone()
        });
        write(
            &dir,
            &format!("fault_free_{i}.csv"),
            &TankRecording::csv(&rec),
        );
    }
    let onset = (samples / 2) as u64;
    let mut faults: Vec<(String, TankFault)> = Vec::new();
    faults.extend((0..4).map(|i| {
        (
            format!("sensor_bias_y{i}.csv"),
            TankFault::sensor_bias(i, onset),
        )
    }));
    faults.extend((0..2).map(|j| {
        (
            format!("actuator_bias_u{j}.csv"),
            TankFault::actuator_bias(j, onset),
        )
    }));
    faults.extend((0..4).map(|i| (format!("leak_tank{i}.csv"), TankFault::leak(i, onset))));
    let mut list = format!(
        "# quadruple tank (Johansson 2000, P-), Ts = {} s, {samples} samples per file, onset k = {onset} (t = {} s)\n\
         # fault-free: fault_free_0..{} (seeds {seed}..{})\n\
         # file onset_k onset_t_s kind target magnitude unit seed\n",
        base.sample_period,
        onset as f64 * base.sample_period,
        experiments.saturating_sub(1),
        seed + experiments.saturating_sub(1),
    );
    for (n, (name, fault)) in faults.into_iter().enumerate() {
        let fseed = seed + 100 + n as u64;
        let rec = run(TankRun {
            seed: fseed,
            faults: vec![fault],
            ..base.clone()
        });
        write(&dir, &name, &TankRecording::csv(&rec));
        let (kind, target, magnitude, unit) = match fault.kind {
            TankFaultKind::SensorBias { output, magnitude } => {
                ("sensor_bias", format!("y{output}"), magnitude, "V")
            }
            TankFaultKind::ActuatorBias { input, magnitude } => {
                ("actuator_bias", format!("u{input}"), magnitude, "V")
            }
            TankFaultKind::Leak { tank, area } => ("leak", format!("tank{tank}"), area, "cm2"),
        };
        let _ = writeln!(
            list,
            "{name} {onset} {} {kind} {target} {magnitude} {unit} {fseed}",
            onset as f64 * base.sample_period
        );
    }
    write(&dir, "faults.txt", &list);
}
