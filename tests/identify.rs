//! From recordings to a calibrated monitor with the real binary, on a plant
//! the project simulates itself: the nonlinear quadruple-tank process (Johansson 2000,
//! minimum-phase set P−; `glrmon_sim::tank`), two pump voltages in, four level-sensor
//! voltages out around an operating point of 0.7–6.4 V.
//!
//! `glrmon identify` on three fault-free runs → `glrmon calibrate` on the same runs →
//! `glrmon replay` of independent faulty runs: the four-tank plant gives an order-4
//! model, its Kalman filter is the identified predictor (Σ = Re), and biases are
//! detected at the crossing, isolated, and estimated in volts (the signals' raw units).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glrmon_sim::tank::{TankFault, TankRun};

fn glrmon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = glrmon(args);
    assert!(
        out.status.success(),
        "{args:?}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("glrmon-identify-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 2000-sample run of the tank (seed `seed`) with `faults`, written as CSV.
fn record(dir: &Path, name: &str, seed: u64, faults: Vec<TankFault>) -> String {
    let rec = TankRun {
        seed,
        samples: 2000,
        faults,
        ..TankRun::default()
    }
    .simulate()
    .unwrap();
    let path = dir.join(name);
    std::fs::write(&path, rec.csv()).unwrap();
    path.to_str().unwrap().to_owned()
}

/// The first alarm at or after `onset` and the isolation update that follows it.
fn first_detection(jsonl: &str, onset: u64) -> (u64, Vec<String>, serde_json::Value) {
    let records: Vec<serde_json::Value> = jsonl
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let alarm = records
        .iter()
        .find(|r| r["type"] == "alarm" && r["k"].as_u64().unwrap() >= onset)
        .expect("an alarm after the onset");
    let k = alarm["k"].as_u64().unwrap();
    let update = records
        .iter()
        .find(|r| r["type"] == "isolation" && r["alarm_k"].as_u64() == Some(k))
        .unwrap_or(alarm);
    let isolated = update["isolation"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|i| i["isolated"] == true)
        .map(|i| i["fault"].as_str().unwrap().to_owned())
        .collect();
    (k, isolated, update["magnitude"].clone())
}

#[test]
fn identify_calibrate_replay_on_the_quadruple_tank() {
    let d = dir("tank");
    let runs: Vec<String> = (1..=3)
        .map(|s| record(&d, &format!("fault_free_{s}.csv"), s, vec![]))
        .collect();
    let config = d.join("tank.toml");
    let cfg = config.to_str().unwrap();
    let mut args = vec!["identify", "--channel", "tank", "--output", cfg, "--json"];
    args.extend(runs.iter().map(String::as_str));
    let report: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
    // Four tanks, four states: BIC picks 4 among 1..=10.
    assert_eq!(report["order"], 4, "{report:#}");
    assert!(
        report["sigma_mismatch"].as_f64().unwrap() < 1e-9,
        "{report:#}"
    );
    // NIS mean on 1200 held-out samples of χ²(4): σ of the mean √(8/1200) = 0.08.
    let nis = report["validation"]["nis_mean"].as_f64().unwrap();
    assert!(
        (nis - 4.0).abs() < 4.0 * (8.0f64 / 1200.0).sqrt(),
        "NIS {nis}"
    );
    assert_eq!(report["period"], 5.0);
    let validate = ok(&["validate", "--config", cfg]);
    assert!(validate.contains("tank"), "{validate}");

    // Writing over it needs --force.
    let again = glrmon(&args);
    assert_eq!(again.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));

    let mut args = vec![
        "calibrate",
        "--config",
        cfg,
        "--channel",
        "tank",
        "--mtbfa",
        "2000",
    ];
    args.extend(runs.iter().map(String::as_str));
    args.push("--write");
    ok(&args);

    // Independent faulty runs, fault from k = 1000; magnitudes are in volts.
    for (name, fault, theta, seed) in [
        ("y2_bias", TankFault::sensor_bias(2, 1000), 0.125, 11),
        ("y3_bias", TankFault::sensor_bias(3, 1000), 0.125, 12),
        ("u0_bias", TankFault::actuator_bias(0, 1000), 0.25, 13),
    ] {
        let data = record(&d, &format!("{name}.csv"), seed, vec![fault]);
        let out = d.join(format!("{name}.jsonl"));
        ok(&[
            "replay",
            "--config",
            cfg,
            &data,
            "--output",
            out.to_str().unwrap(),
        ]);
        let (k, isolated, magnitude) =
            first_detection(&std::fs::read_to_string(&out).unwrap(), 1000);
        assert!(k <= 1020, "{name}: first alarm after the onset at k = {k}");
        assert_eq!(isolated, [name], "{name} at k = {k}");
        let faults = [
            "y0_bias", "y1_bias", "y2_bias", "y3_bias", "u0_bias", "u1_bias",
        ];
        let i = faults.iter().position(|f| *f == name).unwrap();
        let estimate = magnitude[i].as_f64().unwrap();
        assert!(
            (estimate - theta).abs() < 0.35 * theta,
            "{name}: θ̂ = {estimate} V, injected {theta} V"
        );
    }
}

#[test]
fn named_columns_constant_columns_and_missing_ones() {
    let d = dir("columns");
    // The plant's export: other names, a constant setpoint column, a spare column.
    let rec = TankRun {
        seed: 4,
        samples: 1500,
        ..TankRun::default()
    }
    .simulate()
    .unwrap();
    let mut text = String::from("k,t,P1,P2,SP,L1,L2,L3,L4,spare\n");
    for i in 0..rec.k.len() {
        let (u, y) = (&rec.u[i], &rec.y[i]);
        text.push_str(&format!(
            "{},{},{},{},12.5,{},{},{},{},{}\n",
            rec.k[i],
            rec.t[i],
            u[0],
            u[1],
            y[0],
            y[1],
            y[2],
            y[3],
            i % 7
        ));
    }
    let data = d.join("export.csv");
    std::fs::write(&data, text).unwrap();
    let config = d.join("named.toml");
    let (data, cfg) = (data.to_str().unwrap(), config.to_str().unwrap());
    let said = ok(&[
        "identify",
        "--channel",
        "tank",
        "--inputs",
        "P1,P2,SP",
        "--outputs",
        "L1,L2,L3,L4",
        "--output",
        cfg,
        data,
    ]);
    assert!(
        said.contains("SP is constant (12.5): left out of the model"),
        "{said}"
    );
    let written = std::fs::read_to_string(&config).unwrap();
    assert!(written.contains("u = [\"P1\", \"P2\"]"), "{written}");
    let validate = ok(&["validate", "--config", cfg]);
    assert!(validate.contains("L3_bias"), "{validate}");
    // The export replays as it is: SP and spare are skipped.
    let out = ok(&["replay", "--config", cfg, data]);
    assert_eq!(
        out.lines()
            .filter(|l| l.contains("\"type\":\"stat\""))
            .count(),
        1500
    );

    let missing = glrmon(&[
        "identify",
        "--channel",
        "tank",
        "--inputs",
        "P1,P9",
        "--outputs",
        "L1",
        "--output",
        d.join("x.toml").to_str().unwrap(),
        data,
    ]);
    assert_eq!(missing.status.code(), Some(1));
    let e = String::from_utf8_lossy(&missing.stderr);
    assert!(e.contains("no column \"P9\""), "{e}");
}

#[test]
fn the_predictor_based_method_identifies_the_tank_too() {
    let d = dir("pbsid");
    let runs: Vec<String> = (1..=3)
        .map(|s| record(&d, &format!("fault_free_{s}.csv"), s, vec![]))
        .collect();
    let config = d.join("tank.toml");
    let mut args = vec![
        "identify",
        "--channel",
        "tank",
        "--method",
        "pbsid",
        "--json",
        "--output",
        config.to_str().unwrap(),
    ];
    args.extend(runs.iter().map(String::as_str));
    let report: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
    assert_eq!(report["method"]["used"], "pbsid", "{report:#}");
    // BIC alone picks the four tanks' order 4, whose held-out innovations of one level
    // are not white (the plant is nonlinear); the order chosen is the lowest-BIC one
    // whose held-out validation passes.
    let bic_order = report["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["bic"].is_number())
        .min_by(|a, b| {
            a["bic"]
                .as_f64()
                .unwrap()
                .total_cmp(&b["bic"].as_f64().unwrap())
        })
        .map(|c| c["order"].as_u64().unwrap());
    assert_eq!(bic_order, Some(4), "{report:#}");
    let order = report["order"].as_u64().unwrap();
    assert!((4..=8).contains(&order), "{report:#}");
    assert_eq!(report["validation"]["passed"], true, "{report:#}");
    let nis = report["validation"]["nis_mean"].as_f64().unwrap();
    assert!(
        (nis - 4.0).abs() < 4.0 * (8.0f64 / 1200.0).sqrt(),
        "NIS {nis}"
    );
}

/// Writes `rows` rows of `inputs` u-columns and `outputs` y-columns of seeded noise.
fn noise_csv(path: &Path, rows: usize, inputs: usize, outputs: usize) {
    let mut rng = glrmon_sim::Rng::new(9);
    let mut text = String::from("k");
    for i in 0..inputs {
        text.push_str(&format!(",u{i}"));
    }
    for j in 0..outputs {
        text.push_str(&format!(",y{j}"));
    }
    text.push('\n');
    for k in 0..rows {
        text.push_str(&k.to_string());
        for _ in 0..inputs + outputs {
            text.push_str(&format!(",{:.5}", rng.normal()));
        }
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

/// Sizes and options a channel or the machine cannot hold are refused before any work:
/// exit 1 (bad usage, not a runtime failure), quickly, naming the option and the limit.
#[test]
fn early_refusals_exit_1_quickly_naming_the_option() {
    let d = dir("refusals");
    let small = d.join("small.csv");
    noise_csv(&small, 2000, 2, 2);
    let wide = d.join("wide.csv");
    noise_csv(&wide, 2000, 70, 100);
    let tiny = d.join("tiny.csv");
    let huge = d.join("huge.csv");
    let mut rng = glrmon_sim::Rng::new(3);
    let (mut t, mut h) = (String::from("k,u0,y0\n"), String::from("k,u0,y0\n"));
    for k in 0..500 {
        let (a, b) = (rng.normal(), rng.normal());
        t.push_str(&format!("{k},{a},{:e}\n", 1e-300 * (1.0 + 0.5 * b)));
        h.push_str(&format!("{k},{a},{:e}\n", 1e50 + 1e45 * b));
    }
    std::fs::write(&tiny, t).unwrap();
    std::fs::write(&huge, h).unwrap();
    // u2 is u1 in other units: the same signal under another name.
    let copy = d.join("copy.csv");
    let text = std::fs::read_to_string(&small).unwrap();
    let mut lines = text.lines();
    let mut c = format!("{},u1f\n", lines.next().unwrap());
    for line in lines {
        let u1: f64 = line.split(',').nth(2).unwrap().parse().unwrap();
        c.push_str(&format!("{line},{}\n", 32.0 + 1.8 * u1));
    }
    std::fs::write(&copy, c).unwrap();
    let big = d.join("big.csv");
    noise_csv(&big, 1_000_000, 1, 1);
    let out = d.join("x.toml");
    let out = out.to_str().unwrap();
    let path = |p: &Path| p.to_str().unwrap().to_owned();
    let cases: Vec<(Vec<String>, &str, f64)> = vec![
        (
            vec!["--window".into(), "0".into(), path(&small)],
            "--window: 0 is not a GLR window: it must be in 1..=100000",
            5.0,
        ),
        (
            vec!["--window".into(), "1000000000".into(), path(&small)],
            "--window: 1000000000",
            5.0,
        ),
        (
            vec!["--order".into(), "300".into(), path(&small)],
            "--order: 300 states cannot be written: a channel has 1..=128",
            5.0,
        ),
        (
            vec!["--max-order".into(), "300".into(), path(&small)],
            "--max-order: 300",
            5.0,
        ),
        (
            vec!["--inputs".into(), "u0,u0".into(), path(&small)],
            "--inputs: column \"u0\" is given twice",
            5.0,
        ),
        (
            vec![path(&wide)],
            "--outputs: 100 columns, but a channel has at most 64",
            5.0,
        ),
        (
            vec!["--outputs".into(), "y0,y1".into(), path(&wide)],
            "--inputs: 70 columns, but a channel has at most 64",
            5.0,
        ),
        (
            vec![
                "--window".into(),
                "100000".into(),
                "--max-order".into(),
                "128".into(),
                path(&small),
            ],
            "--window: the written channel's monitor would need",
            5.0,
        ),
        (
            vec!["--inputs".into(), "u0,u1,u1f".into(), path(&copy)],
            "--inputs: columns \"u1\" and \"u1f\" carry the same signal",
            5.0,
        ),
        (vec![path(&tiny)], "--outputs: column \"y0\" varies by", 5.0),
        (
            vec![path(&huge)],
            "--outputs: column \"y0\" sits at 1.000e50, beyond the offsets a channel can hold, ±1e40",
            5.0,
        ),
        // 10⁶ rows take about 2.5 s to read on a debug build.
        (
            vec!["--horizon".into(), "20000".into(), path(&big)],
            "--horizon: identification would need about",
            15.0,
        ),
    ];
    for (args, expected, seconds) in cases {
        let mut all = vec!["identify", "--channel", "c", "--force", "--output", out];
        all.extend(args.iter().map(String::as_str));
        let started = std::time::Instant::now();
        let o = glrmon(&all);
        let elapsed = started.elapsed().as_secs_f64();
        let e = String::from_utf8_lossy(&o.stderr);
        println!(
            "{args:?}: exit {:?} in {elapsed:.2} s: {}",
            o.status.code(),
            e.trim()
        );
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert!(e.contains(expected), "{args:?}: wanted «{expected}» in {e}");
        assert!(elapsed < seconds, "{args:?} took {elapsed:.1} s");
        assert!(!Path::new(out).exists(), "{args:?} wrote {out}");
    }
}
