//! From closed-loop recordings to a calibrated monitor with the real binary, the user
//! never naming a method: a three-state plant (two inputs, two outputs, raw units around
//! an operating point) whose input u0 a PI controller computes from the previous sample
//! of y0 (a one-sample delay in the loop, a white dither on the reference, so that PBSID
//! applies: Chiuso 2007), u1 open-loop white noise. The loop is tight (the dither's
//! standard deviation is a third of the innovation's), so that PO-MOESP's model is
//! biased: its innovations on y0 are coloured.
//!
//! `glrmon identify` (default `--method auto`) must find the feedback and choose PBSID,
//! saying so in one line; `glrmon calibrate --write` on other fault-free runs; the file
//! validates; `glrmon replay` of independent fault-free runs exceeds the threshold on a
//! fraction of the samples inside calibrate's interval; injected faults are detected.

#[path = "support.rs"]
mod support;

use std::path::Path;

use glrmon_sim::Rng;
use support::{Scratch, glrmon, run_ok};

const SAMPLES: usize = 3000;
const ONSET: usize = 1500;

/// A fault of the plant: a bias on a sensor (what the controller sees too) or on the
/// input u1 actually applied (the recorded u1 is the commanded one).
#[derive(Clone, Copy)]
enum Fault {
    None,
    Sensor(usize, f64),
    Actuator1(f64),
}

/// One run of the loop (seed `seed`) as CSV `k,u0,u1,y0,y1` in raw units, after a
/// 300-sample burn-in. Innovations e ~ N(0, diag(0.3², 0.2²)) drive both states and
/// outputs; the third state sees the inputs only.
fn record(dir: &Path, name: &str, seed: u64, fault: Fault) -> String {
    let mut rng = Rng::new(seed);
    let (kp, ki, dither) = (1.2, 0.2, 0.1);
    let mut x = [0.0f64; 3];
    let (mut integral, mut y0_prev) = (0.0, 0.0);
    let mut text = String::from("k,u0,u1,y0,y1\n");
    for k in 0..300 + SAMPLES {
        let error = dither * rng.normal() - y0_prev;
        let u0 = kp * error + integral;
        integral += ki * error;
        let u1 = rng.normal();
        let e = [0.3 * rng.normal(), 0.2 * rng.normal()];
        let mut y = [x[0] + 0.5 * x[2] + e[0], x[1] + 0.3 * x[0] + e[1]];
        let faulty = k >= 300 + ONSET;
        let mut u1_applied = u1;
        match fault {
            Fault::Sensor(j, b) if faulty => y[j] += b,
            Fault::Actuator1(b) if faulty => u1_applied += b,
            _ => {}
        }
        y0_prev = y[0];
        x = [
            0.8 * x[0] + 0.1 * x[1] + 0.5 * u0 + 0.3 * e[0],
            -0.1 * x[0] + 0.7 * x[1] + 0.4 * u1_applied + 0.2 * e[1],
            0.5 * x[2] + 0.3 * u0 - 0.2 * u1_applied,
        ];
        if k >= 300 {
            text.push_str(&format!(
                "{},{},{},{},{}\n",
                k - 300,
                50.0 + u0,
                10.0 + u1,
                100.0 + y[0],
                20.0 + y[1]
            ));
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_owned()
}

fn stdout(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// (samples with a GLR, samples above the threshold) of a replay's stat records, and
/// the first alarm at or after `from`.
fn replayed(jsonl: &str, from: u64) -> (usize, usize, Option<u64>) {
    let (mut scored, mut above, mut alarm) = (0, 0, None);
    for line in jsonl.lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        match r["type"].as_str() {
            Some("stat") => {
                if let (Some(g), Some(t)) = (r["glr"].as_f64(), r["threshold"].as_f64()) {
                    scored += 1;
                    above += usize::from(g > t);
                }
            }
            Some("alarm") => {
                let k = r["k"].as_u64().unwrap();
                if k >= from && alarm.is_none() {
                    alarm = Some(k);
                }
            }
            _ => {}
        }
    }
    (scored, above, alarm)
}

/// `glrmon calibrate --write --sample-far 0.01` of `config` on the `calib` runs, its
/// written file validated, then `glrmon replay` of the `free` runs: calibrate's 95 %
/// interval of the fraction of samples above the threshold, and the fraction seen.
fn calibrate_and_replay(
    dir: &Path,
    config: &str,
    calib: &[String],
    free: &[String],
) -> ([f64; 2], f64) {
    let mut cmd = glrmon();
    cmd.args(["calibrate", "--config", config, "--channel", "loop"])
        .args(["--sample-far", "0.01", "--json", "--write"])
        .args(calib);
    let cal: serde_json::Value = serde_json::from_str(&stdout(&run_ok(&mut cmd))).unwrap();
    let interval = [
        cal["rate_interval"][0].as_f64().unwrap(),
        cal["rate_interval"][1].as_f64().unwrap(),
    ];
    run_ok(glrmon().args(["validate", "--config", config]));
    let (mut scored, mut above) = (0, 0);
    for (i, data) in free.iter().enumerate() {
        let out = dir.join(format!("free_{i}.jsonl"));
        run_ok(
            glrmon()
                .args(["replay", "--config", config, data, "--output"])
                .arg(&out),
        );
        let (n, a, _) = replayed(&std::fs::read_to_string(&out).unwrap(), 0);
        scored += n;
        above += a;
    }
    (interval, above as f64 / scored as f64)
}

#[test]
fn identify_finds_the_feedback_chooses_pbsid_and_the_monitor_holds_its_rate() {
    let d = Scratch::new("closed-loop");
    let ident: Vec<String> = (1..=3)
        .map(|s| record(&d.0, &format!("ident_{s}.csv"), s, Fault::None))
        .collect();
    let calib: Vec<String> = (4..=6)
        .map(|s| record(&d.0, &format!("calib_{s}.csv"), s, Fault::None))
        .collect();
    let config = d.0.join("loop.toml");
    let cfg = config.to_str().unwrap();

    // 1. identify, no method named.
    let mut cmd = glrmon();
    cmd.args(["identify", "--channel", "loop", "--output", cfg])
        .args(&ident);
    let said = stdout(&run_ok(&mut cmd));
    let line = said
        .lines()
        .find(|l| l.starts_with("method: "))
        .unwrap_or_else(|| panic!("no method line:\n{said}"));
    println!("{line}");
    assert!(line.starts_with("method: PBSID (closed loop)"), "{said}");
    assert!(line.contains("Granger test of y → u"), "{line}");
    assert!(line.contains("most: u0"), "{line}");
    let mut cmd = glrmon();
    cmd.args([
        "identify",
        "--channel",
        "loop",
        "--force",
        "--json",
        "--output",
        cfg,
    ])
    .args(&ident);
    let report: serde_json::Value = serde_json::from_str(&stdout(&run_ok(&mut cmd))).unwrap();
    assert_eq!(report["method"]["requested"], "auto", "{report:#}");
    assert_eq!(report["method"]["used"], "pbsid", "{report:#}");
    assert_eq!(report["method"]["feedback"]["feedback"], true, "{report:#}");
    let v = &report["validation"];
    let num = |x: &serde_json::Value| x.as_f64().unwrap_or(f64::NAN);
    println!(
        "PBSID (auto): order {}, held-out NIS {:.3} in [{:.3}, {:.3}] for 2 outputs, \
         validation passed: {}, not white: {}",
        report["order"],
        num(&v["nis_mean"]),
        num(&v["nis_interval"][0]),
        num(&v["nis_interval"][1]),
        v["passed"],
        v["not_white"]
    );
    assert_eq!(v["passed"], true, "{report:#}");

    // PO-MOESP on the same data, asked for explicitly: it is used, its y0 innovations are
    // coloured by the feedback, and the model is written with a loud warning naming that.
    let other = d.0.join("moesp.toml");
    let mut cmd = glrmon();
    cmd.args([
        "identify",
        "--channel",
        "loop",
        "--method",
        "moesp",
        "--json",
    ])
    .args(["--output", other.to_str().unwrap()])
    .args(&ident);
    let out = run_ok(&mut cmd);
    let moesp: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let warned = String::from_utf8_lossy(&out.stderr);
    assert_eq!(moesp["method"]["used"], "moesp");
    println!(
        "PO-MOESP (asked for): order {}, held-out NIS {:.3}, validation passed: {}, not white: {}",
        moesp["order"],
        num(&moesp["validation"]["nis_mean"]),
        moesp["validation"]["passed"],
        moesp["validation"]["not_white"]
    );
    println!("{}", warned.trim());
    assert_eq!(moesp["validation"]["passed"], false, "{moesp:#}");
    assert!(
        warned.contains("WARNING: the identified model FAILS its held-out validation"),
        "{warned}"
    );
    assert!(
        warned.contains("→ y0 innovations not white (at 1 % over 2 outputs"),
        "{warned}"
    );
    // A failed check comes with what to do about it.
    assert!(
        warned.contains("WARNING: what to do: innovations that are not white")
            && warned.contains("--method pbsid if a controller acts on these outputs"),
        "{warned}"
    );
    assert!(other.exists());
    let written = std::fs::read_to_string(&other).unwrap();
    assert!(written.contains("# WARNING: this model fails"), "{written}");

    // 2. calibrate --write on other fault-free runs; the written file validates.
    // 3. Independent fault-free runs: the fraction of samples above the threshold.
    let free: Vec<String> = (7..=9)
        .map(|s| record(&d.0, &format!("free_{s}.csv"), s, Fault::None))
        .collect();
    let mut figures = Vec::new();
    for (name, file) in [("PBSID", cfg), ("PO-MOESP", other.to_str().unwrap())] {
        let (interval, rate) = calibrate_and_replay(&d.0, file, &calib, &free);
        println!(
            "{name}: independent fault-free runs {rate:.4} of the samples above the threshold \
             (calibrate's 95 % interval [{:.4}, {:.4}])",
            interval[0], interval[1]
        );
        figures.push((interval, rate));
    }
    let (interval, rate) = figures[0];
    assert!(
        (interval[0]..=interval[1]).contains(&rate),
        "false-alarm fraction {rate} outside [{}, {}]",
        interval[0],
        interval[1]
    );

    // 4. Faults from k = ONSET: detected within 50 samples.
    for (name, fault, seed) in [
        ("y0_bias", Fault::Sensor(0, 1.5), 21),
        ("y1_bias", Fault::Sensor(1, 1.0), 22),
        ("u1_bias", Fault::Actuator1(1.5), 23),
    ] {
        let data = record(&d.0, &format!("{name}.csv"), seed, fault);
        let out = d.0.join(format!("{name}.jsonl"));
        run_ok(
            glrmon()
                .args(["replay", "--config", cfg, &data, "--output"])
                .arg(&out),
        );
        let (_, _, alarm) = replayed(&std::fs::read_to_string(&out).unwrap(), ONSET as u64);
        println!("{name}: first alarm at or after the onset {ONSET}: {alarm:?}");
        let k = alarm.unwrap_or_else(|| panic!("{name}: no alarm after the onset"));
        assert!(k <= ONSET as u64 + 50, "{name}: first alarm at k = {k}");
    }
}
