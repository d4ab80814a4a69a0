//! `glrmon calibrate` end to end with the real binary: calibrated on 10⁶
//! fault-free samples of the §6.1 plant (Zhang & Basseville 2014) for one false-alarm
//! episode per 10⁴ samples, the threshold written into the config gives that rate,
//! within ±30 %, on an independent 10⁶-sample run replayed through the monitor. Also:
//! isolation tests that are not isolable are named and left out of the written file,
//! runs that disagree are named, skipped rows are counted by reason.

use std::path::Path;
use std::process::{Command, Output};

#[path = "support.rs"]
mod support;

fn glrmon(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn calibrated_threshold_gives_its_false_alarm_rate_on_an_independent_run() {
    let dir = std::env::temp_dir().join(format!("glrmon-calibrate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("unstable.toml");
    let original =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2014-unstable.toml");
    let text = std::fs::read_to_string(original).unwrap();
    std::fs::write(&config, &text).unwrap();
    let cfg = config.to_str().unwrap();

    let out = glrmon(&[
        "calibrate",
        "--config",
        cfg,
        "--simulate",
        "1000000",
        "--seed",
        "1",
        "--mtbfa",
        "10000",
        "--write",
    ]);
    let said = String::from_utf8_lossy(&out.stdout).into_owned();
    let written = std::fs::read_to_string(&config).unwrap();
    assert!(written.contains("[channels.glr.calibrated]"), "{written}");
    // Everything else of the file is kept (comments included).
    let first_comment = text.lines().find(|l| l.starts_with('#')).unwrap_or("");
    assert!(written.contains(first_comment));
    let validate =
        String::from_utf8_lossy(&glrmon(&["validate", "--config", cfg]).stdout).into_owned();
    assert!(
        validate.contains("calibrated for one false-alarm episode per 10000 samples"),
        "{validate}"
    );

    // An independent fault-free run, through the monitor as live.
    let data = dir.join("independent.mcap");
    glrmon(&[
        "simulate",
        "--config",
        cfg,
        "--samples",
        "1000000",
        "--seed",
        "77",
        "--output",
        data.to_str().unwrap(),
    ]);
    let out = glrmon(&[
        "replay",
        "--config",
        cfg,
        data.to_str().unwrap(),
        "--output",
        "/dev/null",
    ]);
    let summary = String::from_utf8_lossy(&out.stderr).into_owned();
    let line = summary
        .lines()
        .find(|l| l.contains("channel \"unstable\": 1000000 samples"))
        .unwrap_or_else(|| panic!("{summary}"));
    let alarms: f64 = line
        .split(", ")
        .find_map(|p| p.strip_suffix(" alarms"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    eprintln!(
        "{}\nindependent run: {alarms} alarm episodes in 10^6 samples (target 100)",
        said.lines().take(3).collect::<Vec<_>>().join("\n")
    );
    assert!(
        (70.0..=130.0).contains(&alarms),
        "{alarms} episodes: {said}"
    );

    // The isolation thresholds written with it: on independent fault-free data the
    // minmax statistic at r̂ exceeds each of them with the channel's α = 1 % (±30 %),
    // where the χ²(1) quantile (6.63) is exceeded far more often.
    assert!(written.contains("isolation = {"), "{written}");
    let out = glrmon(&[
        "calibrate",
        "--config",
        cfg,
        "--simulate",
        "1000000",
        "--seed",
        "77",
        "--mtbfa",
        "10000",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let episodes = v["current_episodes"].as_u64().unwrap();
    assert!((70..=130).contains(&episodes), "{v}");
    for test in v["isolation"].as_array().unwrap() {
        let rate = test["current_rate"].as_f64().unwrap();
        eprintln!(
            "isolation test {}: calibrated threshold {} exceeded by {:.2} % of independent fault-free samples (target 1 %)",
            test["test"],
            test["current_threshold"],
            100.0 * rate
        );
        assert!((0.007..=0.013).contains(&rate), "{test}");
    }
    let before: Vec<f64> = said
        .lines()
        .filter_map(|l| l.split("is exceeded by ").nth(1))
        .filter_map(|r| r.split(" %").next()?.parse().ok())
        .collect();
    assert_eq!(before.len(), 2, "{said}");
    assert!(
        before.iter().all(|&p| p > 5.0),
        "χ²(1) thresholds over-isolate: {before:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Runs the binary, whatever its exit status.
fn glrmon_status(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap()
}

/// Two fault-free recordings calibrated together for a 1 % per-sample
/// false-alarm fraction; the target is written into the file, and `glrmon validate`
/// shows it. Usage errors (both targets, neither) and a file with no usable sample
/// are refused, naming what is wrong.
#[test]
fn two_recordings_and_a_sample_far_target_are_written_and_validated() {
    let dir = std::env::temp_dir().join(format!("glrmon-calibrate-20-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("unstable.toml");
    let original =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2014-unstable.toml");
    std::fs::copy(original, &config).unwrap();
    let cfg = config.to_str().unwrap();
    let (a, b) = (dir.join("a.csv"), dir.join("b.csv"));
    for (path, seed) in [(&a, "1"), (&b, "2")] {
        glrmon(&[
            "simulate",
            "--config",
            cfg,
            "--samples",
            "2000",
            "--seed",
            seed,
            "--output",
            path.to_str().unwrap(),
        ]);
    }
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());
    let one = glrmon(&[
        "calibrate",
        "--config",
        cfg,
        a,
        "--sample-far",
        "0.01",
        "--json",
    ]);
    let one: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    let out = glrmon(&[
        "calibrate",
        "--config",
        cfg,
        a,
        b,
        "--sample-far",
        "0.01",
        "--write",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("{v}\n{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(v["target"], "sample_far", "{v}");
    assert_eq!(v["sample_far"], 0.01, "{v}");
    assert!(v["mtbfa"].is_null(), "{v}");
    // Both files, each from its own start: twice the admissible samples of one.
    let samples = v["samples"].as_u64().unwrap();
    assert_eq!(samples, 2 * one["samples"].as_u64().unwrap(), "{v} {one}");
    assert!(samples > 3_900, "{v}");
    // About N·f = 40 exceedances: l_k ties in blocks (the window's maximum persists),
    // and λ sits at the block edge nearer 40. They fall in a few clusters, so the
    // answer is loosely supported, and calibrate says so.
    let exceedances = v["exceedances"].as_u64().unwrap();
    assert!((10..=80).contains(&exceedances), "{v}");
    let warning = v["warning"].as_str().unwrap_or_default();
    assert!(
        warning.contains("loosely supported") && warning.contains("clusters"),
        "{v}"
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning: channel \"unstable\""));
    let threshold = v["threshold"].as_f64().unwrap();

    let written = std::fs::read_to_string(&config).unwrap();
    assert!(
        written.contains("sample_far = 0.01\n") && !written.contains("mtbfa"),
        "{written}"
    );
    assert!(
        written.contains(&format!("source = \"{a}, {b}\"")),
        "{written}"
    );
    let validate =
        String::from_utf8_lossy(&glrmon(&["validate", "--config", cfg]).stdout).into_owned();
    let shown = format!(
        "threshold {threshold:.4} (calibrated for a fraction 0.01 of fault-free samples above \
         it on {samples} fault-free samples, {exceedances} above in"
    );
    assert!(validate.contains(&shown), "{shown}\n{validate}");

    // Both targets, or neither: usage errors (exit 2) naming the flags.
    let both = glrmon_status(&[
        "calibrate",
        "--config",
        cfg,
        a,
        "--mtbfa",
        "100",
        "--sample-far",
        "0.01",
    ]);
    let said = String::from_utf8_lossy(&both.stderr);
    assert_eq!(both.status.code(), Some(2), "{said}");
    assert!(
        said.contains("--mtbfa") && said.contains("--sample-far"),
        "{said}"
    );
    let neither = glrmon_status(&["calibrate", "--config", cfg, a]);
    let said = String::from_utf8_lossy(&neither.stderr);
    assert_eq!(neither.status.code(), Some(2), "{said}");
    assert!(
        said.contains("--mtbfa") && said.contains("--sample-far"),
        "{said}"
    );

    // A file with no usable sample: invalid input (exit 1), naming the file and why.
    let empty = dir.join("empty.csv");
    std::fs::write(&empty, "k,u0,y0\n3,0.5,oops\n").unwrap();
    let out = glrmon_status(&[
        "calibrate",
        "--config",
        cfg,
        a,
        empty.to_str().unwrap(),
        "--sample-far",
        "0.01",
    ]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains(&format!(
            "{}: no usable sample of channel \"unstable\": all 1 rows skipped: 1 wrong_type (first: row 2: ",
            empty.display()
        )),
        "{said}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A channel with fewer states (2) than inputs (3) and a feedthrough J, as `glrmon
/// identify` can give for a closed-loop plant: an actuator bias in the null space of G
/// shows only through J, exactly as a combination of sensor biases does, so every
/// fault's signature lies in the span of the others' and every minmax statistic is 0
/// on fault-free data. `--write` still writes the detection threshold, names each
/// isolation test it could not calibrate and why, writes no isolation threshold, and
/// the file validates.
const SPANNED: &str = include_str!("data/spanned.toml");

#[test]
fn isolation_tests_that_are_not_isolable_are_named_and_the_rest_is_written() {
    let dir = support::Scratch::new("calibrate-spanned");
    let config = dir.0.join("plant.toml");
    std::fs::write(&config, SPANNED).unwrap();
    let cfg = config.to_str().unwrap();
    let mut files = Vec::new();
    for seed in ["1", "2"] {
        let path = dir.0.join(format!("run{seed}.csv"));
        glrmon(&[
            "simulate",
            "--config",
            cfg,
            "--samples",
            "3000",
            "--seed",
            seed,
            "--output",
            path.to_str().unwrap(),
        ]);
        files.push(path.to_str().unwrap().to_owned());
    }
    let out = glrmon(&[
        "calibrate",
        "--config",
        cfg,
        &files[0],
        &files[1],
        "--sample-far",
        "0.01",
        "--write",
    ]);
    let said = String::from_utf8_lossy(&out.stdout).into_owned();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    eprintln!("{said}\n{err}");
    for fault in [
        "y0_bias", "y1_bias", "y2_bias", "y3_bias", "u0_bias", "u1_bias", "u2_bias",
    ] {
        let line = said
            .lines()
            .find(|l| l.starts_with(&format!("  isolation {fault}: not calibrated: ")))
            .unwrap_or_else(|| panic!("{fault}: {said}"));
        assert!(
            line.contains("its statistic is 0 on every fault-free sample")
                && line.contains("its signature lies in the span of the other faults'")
                // χ²(1) at 0.01/(w − s) = 0.01/19: the law in force (Bonferroni).
                && line.ends_with("the χ² threshold 12.02 stays in force"),
            "{line}"
        );
    }
    assert!(!said.contains("threshold 0.0000"), "{said}");
    assert!(
        err.contains("updated: the detection threshold and 0 of 7 isolation thresholds written"),
        "{err}"
    );
    let written = std::fs::read_to_string(&config).unwrap();
    assert!(written.starts_with("# identified, n < l\n"), "{written}");
    assert!(written.contains("[channels.glr.calibrated]"), "{written}");
    assert!(!written.contains("isolation ="), "{written}");
    let threshold: f64 = written
        .lines()
        .find_map(|l| l.strip_prefix("threshold = "))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{written}"));
    assert!(threshold > 0.0 && threshold.is_finite(), "{written}");
    let validate =
        String::from_utf8_lossy(&glrmon(&["validate", "--config", cfg]).stdout).into_owned();
    assert!(
        validate.contains(&format!(
            "threshold {threshold:.4} (calibrated for a fraction 0.01 of fault-free samples"
        )),
        "{validate}"
    );
    // validate's isolability section finds the same dependence.
    assert!(validate.contains("linearly dependent"), "{validate}");
}

/// A scalar channel (w = 5) for the run-to-run tests: short memory, so that 20 000
/// samples hold enough clusters for tight per-run intervals.
const SCALAR: &str = r#"[[channels]]
name = "level"

[channels.model]
F = [[0.5]]
H = [[1.0]]
Q = 0.01
R = 0.01

[[channels.faults]]
kind = "all_sensors"

[channels.glr]
window = 5
"#;

/// Each file's rate at the pooled threshold is shown with its interval; two runs from
/// one law agree, a run with twice the noise standard deviation disagrees with one at
/// the configured noise, and calibrate names both in a warning (and in `--json`).
#[test]
fn runs_with_different_noise_levels_are_named_as_disagreeing() {
    let dir = support::Scratch::new("calibrate-runs");
    let config = dir.0.join("level.toml");
    std::fs::write(&config, SCALAR).unwrap();
    let noisy = dir.0.join("noisy.toml");
    std::fs::write(&noisy, SCALAR.replace("= 0.01", "= 0.04")).unwrap();
    let simulate = |cfg: &Path, seed: &str, name: &str| {
        let path = dir.0.join(name);
        glrmon(&[
            "simulate",
            "--config",
            cfg.to_str().unwrap(),
            "--samples",
            "20000",
            "--seed",
            seed,
            "--output",
            path.to_str().unwrap(),
        ]);
        path.to_str().unwrap().to_owned()
    };
    let a = simulate(&config, "1", "a.csv");
    let b = simulate(&config, "2", "b.csv");
    let loud = simulate(&noisy, "3", "loud.csv");
    let cfg = config.to_str().unwrap();
    let run = |files: &[&str]| {
        let mut args = vec!["calibrate", "--config", cfg];
        args.extend(files);
        args.extend(["--sample-far", "0.01"]);
        let text = glrmon(&args);
        args.push("--json");
        let json: serde_json::Value = serde_json::from_slice(&glrmon(&args).stdout).unwrap();
        (
            String::from_utf8_lossy(&text.stdout).into_owned(),
            String::from_utf8_lossy(&text.stderr).into_owned(),
            json,
        )
    };

    let (said, err, v) = run(&[&a, &b]);
    eprintln!("{said}\n{err}");
    assert!(v["disagreement"].is_null(), "{v}");
    assert!(!err.contains("disagree"), "{err}");
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2, "{v}");
    for (r, name) in runs.iter().zip([&a, &b]) {
        assert_eq!(r["name"].as_str(), Some(name.as_str()), "{r}");
        let rate = r["rate"].as_f64().unwrap();
        let [lo, hi] = [0, 1].map(|i| r["rate_interval"][i].as_f64().unwrap());
        assert!(lo <= rate && rate <= hi && lo < 0.01 && 0.01 < hi, "{r}");
        assert!(
            said.contains(&format!("  {name}: {} samples, ", r["samples"])),
            "{said}"
        );
    }

    let (said, err, v) = run(&[&a, &loud]);
    eprintln!("{said}\n{err}");
    let warning = v["disagreement"].as_str().unwrap_or_else(|| panic!("{v}"));
    assert!(
        warning.contains(&format!("{a} (")) && warning.contains(&format!("{loud} (")),
        "{warning}"
    );
    assert!(
        err.lines().any(|l| l.starts_with("glrmon calibrate: warning: channel \"level\": runs disagree beyond their 95 % intervals")),
        "{err}"
    );
    let rates: Vec<f64> = v["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["rate"].as_f64().unwrap())
        .collect();
    assert!(rates[1] > 5.0 * rates[0], "{rates:?}");
}

/// Rows calibrate skips are counted per reason and file with the first row of each:
/// NaN (the reader's `non_finite`) and values beyond 10¹⁰⁰ (the monitor's `too_large`);
/// a file whose every row is refused is an error naming it and the reason.
#[test]
fn skipped_rows_are_reported_by_reason_and_an_unusable_file_is_an_error() {
    let dir = support::Scratch::new("calibrate-skipped");
    let config = dir.0.join("level.toml");
    std::fs::write(&config, SCALAR).unwrap();
    let cfg = config.to_str().unwrap();
    let path = dir.0.join("run.csv");
    glrmon(&[
        "simulate",
        "--config",
        cfg,
        "--samples",
        "2000",
        "--output",
        path.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&path).unwrap();
    let header = text.lines().next().unwrap().to_owned();
    assert_eq!(header, "k,y0");
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for k in [10usize, 20] {
        lines[k + 1] = format!("{k},NaN");
    }
    for k in [30usize, 40, 50] {
        lines[k + 1] = format!("{k},1e200");
    }
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let file = path.to_str().unwrap();
    let out = glrmon(&["calibrate", "--config", cfg, file, "--sample-far", "0.01"]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let said = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        err.contains(&format!(
            "glrmon calibrate: warning: {file}: 5 of 2000 rows skipped: 2 non_finite (first: \
             row 12: column y0: \"NaN\" is not finite); 3 too_large (first: row 32: field \
             y[0] = 1e200 is beyond the accepted magnitude 1e100"
        )),
        "{err}"
    );
    assert!(
        said.contains(&format!("  {file}: 1994 samples, 5 rows skipped, ")),
        "{said}"
    );

    let large = dir.0.join("large.csv");
    let rows: String = (0..2_000).map(|k| format!("{k},1e200\n")).collect();
    std::fs::write(&large, format!("{header}\n{rows}")).unwrap();
    let out = glrmon_status(&[
        "calibrate",
        "--config",
        cfg,
        file,
        large.to_str().unwrap(),
        "--sample-far",
        "0.01",
    ]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains(&format!(
            "{}: no usable sample of channel \"level\": all 2000 rows skipped: 2000 too_large \
             (first: row 2: field y[0] = 1e200",
            large.display()
        )),
        "{said}"
    );
}

/// The residual kinds' windowed energy (survey eq. (12)) has no χ² law: `calibrate`
/// sets its threshold from fault-free data like the GLR's. The survey's DC motor with
/// the parity residual of order 2 evaluated by its energy over 10 samples, calibrated
/// on 4·10⁵ simulated samples for one false-alarm episode per 2000 samples (given a
/// placeholder threshold of 1), raises 200 episodes ±30 % on an independent 4·10⁵-sample
/// run.
#[test]
fn calibrate_sets_the_parity_energy_threshold() {
    let dir = std::env::temp_dir().join(format!("glrmon-calibrate-energy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("parity.toml");
    let original =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor-parity.toml");
    let text = std::fs::read_to_string(original)
        .unwrap()
        .replace("false_alarm = 1e-4", "threshold = 1.0")
        .replace(
            "evaluation = \"chi2\"",
            "evaluation = \"energy\"\nenergy_window = 10",
        );
    std::fs::write(&config, &text).unwrap();
    let cfg = config.to_str().unwrap();
    glrmon(&[
        "calibrate",
        "--config",
        cfg,
        "--simulate",
        "400000",
        "--seed",
        "3",
        "--mtbfa",
        "2000",
        "--write",
    ]);
    let written = std::fs::read_to_string(&config).unwrap();
    assert!(written.contains("[channels.glr.calibrated]"), "{written}");
    let data = dir.join("independent.csv");
    glrmon(&[
        "simulate",
        "--config",
        cfg,
        "--samples",
        "400000",
        "--seed",
        "91",
        "--output",
        data.to_str().unwrap(),
    ]);
    let out = glrmon(&[
        "replay",
        "--config",
        cfg,
        data.to_str().unwrap(),
        "--output",
        "/dev/null",
    ]);
    let summary = String::from_utf8_lossy(&out.stderr).into_owned();
    let line = summary
        .lines()
        .find(|l| l.contains("channel \"dc_motor\": 400000 rows, 400000 samples"))
        .unwrap_or_else(|| panic!("{summary}"));
    let alarms: f64 = line
        .split(", ")
        .find_map(|p| p.strip_suffix(" alarms"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    eprintln!("independent run: {alarms} alarm episodes in 4·10^5 samples (target 200)");
    assert!(
        (140.0..=260.0).contains(&alarms),
        "{alarms} episodes: {summary}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
