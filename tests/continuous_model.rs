//! A model written in continuous time (config/examples/two-tanks.toml: `A`, `B`, `Qc`
//! with `period = 20`), through the real binary: it validates; a level-sensor bias
//! simulated from it is detected at its onset and isolated by `replay`; and a model
//! with both `F` and `A` is refused with a message naming both.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};

use serde_json::Value;
use support::{Scratch, glrmon, run_ok};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/two-tanks.toml")
}

#[test]
fn the_two_tanks_example_validates() {
    let out = run_ok(glrmon().args(["validate", "--config"]).arg(example()));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("valid, 1 channel(s)"), "{text}");
    assert!(
        text.contains("n = 2 states, l = 2 inputs, p = 3 outputs"),
        "{text}"
    );
    for fault in [
        "LI201_bias",
        "LI202_bias",
        "FI301_bias",
        "FIC101_bias",
        "FIC102_bias",
    ] {
        assert!(text.contains(fault), "{fault} in {text}");
    }
    assert!(text.contains("every pair of faults is separable"), "{text}");
}

/// LI202 reads 1.5 cm high from sample 1200 of 2000 (20 s each): the alarm comes within
/// a few samples of the onset (none before), its onset estimate is the injected one, and
/// the isolation names LI202_bias alone.
#[test]
fn a_sensor_bias_is_detected_at_its_onset_and_isolated() {
    let dir = Scratch::new("continuous-model");
    let csv = dir.0.join("faulty.csv");
    let records = dir.0.join("records.jsonl");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(example())
            .args(["--samples", "2000", "--seed", "1"])
            .args(["--fault", "LI202_bias:1.5", "--onset", "1200", "--output"])
            .arg(&csv),
    );
    let header = std::fs::read_to_string(&csv).unwrap();
    assert!(
        header.starts_with("k,t,FIC101,FIC102,LI201,LI202,FI301\n"),
        "{}",
        &header[..80]
    );
    run_ok(
        glrmon()
            .args(["replay", "--quiet", "--stat-every", "0", "--config"])
            .arg(example())
            .arg(&csv)
            .arg("--output")
            .arg(&records),
    );
    let lines: Vec<Value> = std::fs::read_to_string(&records)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let alarms: Vec<&Value> = lines.iter().filter(|r| r["type"] == "alarm").collect();
    assert_eq!(alarms.len(), 1, "{lines:#?}");
    let alarm = alarms[0];
    let k = alarm["k"].as_u64().unwrap();
    let onset = alarm["onset"].as_u64().unwrap();
    assert!((1200..=1210).contains(&k), "alarm at {k}");
    assert!(onset.abs_diff(1200) <= 3, "onset estimate {onset}");
    // The isolation (at the alarm, or at its update n samples later) names LI202 alone.
    let isolated = |r: &Value| -> Vec<String> {
        r["isolation"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|t| t["isolated"] == true)
            .map(|t| t["fault"].as_str().unwrap().to_owned())
            .collect()
    };
    let last = lines
        .iter()
        .rfind(|r| r["type"] == "alarm" || r["type"] == "isolation")
        .unwrap();
    assert_eq!(isolated(last), ["LI202_bias"], "{last:#}");
    // Its magnitude is the injected 1.5 cm, give or take the noise.
    let names: Vec<&str> = last["isolation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["fault"].as_str().unwrap())
        .collect();
    let at = names.iter().position(|n| *n == "LI202_bias").unwrap();
    let magnitude = last["magnitude"][at].as_f64().unwrap();
    assert!((magnitude - 1.5).abs() < 0.3, "θ̂ = {magnitude}");
}

#[test]
fn a_model_with_both_f_and_a_is_refused_naming_both() {
    let dir = Scratch::new("continuous-model-conflict");
    let text = std::fs::read_to_string(example()).unwrap().replacen(
        "[channels.model]\n",
        "[channels.model]\nF = [[0.98, 0.0], [0.018, 0.98]]\n",
        1,
    );
    let line = 1 + text.lines().position(|l| l.starts_with("A = ")).unwrap();
    let path = dir.0.join("both.toml");
    std::fs::write(&path, text).unwrap();
    let out = glrmon()
        .args(["validate", "--config"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    let expected = format!(
        "both.toml:{line}:1: channels[0] \"two_tanks\": model.A is given with model.F: write \
         the state equation either in discrete time (F, G, Q) or in continuous time"
    );
    assert!(text.contains(&expected), "{expected}\nnot in\n{text}");
}
