//! Sparse fault diagnosis (Zhang 2021) end to end: `glrmon simulate` and
//! `glrmon diagnose` on the paper's Example 1 (config/examples/paper2021-example1.toml),
//! and its Table I rate at q = 5 through the library (the code of the `table1` example).

use std::process::Command;

#[allow(dead_code)]
#[path = "../crates/glrmon-cli/examples/table1.rs"]
mod table1;

fn glrmon() -> Command {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Five faults of magnitude 1 among 50 injected by `glrmon simulate` (known-profile
/// faults act from the first sample) are exactly what `glrmon diagnose --json` finds,
/// with least-squares magnitudes near 1; the plain Kalman residual, which ignores the
/// unknown input, does not find them.
#[test]
fn simulate_then_diagnose_finds_exactly_the_injected_faults() {
    let dir = std::env::temp_dir().join(format!("glrmon-diagnose-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("example1.csv");
    let config = table1::example1_path();
    let injected = ["f03", "f11", "f20", "f33", "f47"];
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--channel", "ltv3", "--samples", "101", "--seed", "7"])
            .args(["--fault", &injected.map(|f| format!("{f}:1")).join(",")])
            .arg("--output")
            .arg(&csv),
    );
    let json = run_ok(
        glrmon()
            .args(["diagnose", "--config"])
            .arg(&config)
            .args(["--channel", "ltv3", "--json"])
            .arg(&csv),
    );
    let record = glrmon_wire::decode_record(json.trim().as_bytes()).unwrap();
    let glrmon_wire::Record::Diagnosis(d) = record else {
        panic!("not a diagnosis: {json}");
    };
    assert_eq!(d.support, injected, "{json}");
    assert_eq!(
        (d.channel.as_str(), d.from, d.to, d.k),
        ("ltv3", 0, 100, 100)
    );
    assert_eq!(d.residual, "kitanidis");
    for name in injected {
        let v = d.estimate[name];
        assert!((v - 1.0).abs() < 0.1, "{name}: θ̂ = {v}");
    }
    assert!(d.plateau[0] <= d.lambda && d.lambda <= d.plateau[1]);
    assert_eq!(d.path_support_sizes.len(), 100);

    // The paper's span k = 1…100, as text.
    let text = run_ok(
        glrmon()
            .args(["diagnose", "--config"])
            .arg(&config)
            .args(["--from", "1", "--to", "100"])
            .arg(&csv),
    );
    assert!(
        text.contains("over k = 1..=100 (100 samples), kitanidis residual, 50 candidate faults"),
        "{text}"
    );
    assert!(
        text.contains("support:   f03, f11, f20, f33, f47 (5 faults)"),
        "{text}"
    );

    // A Kalman residual that ignores d_k = 10 sin(0.1k) + ε + 100 isolates nonsense.
    let json = run_ok(
        glrmon()
            .args(["diagnose", "--config"])
            .arg(&config)
            .args(["--residual", "kalman", "--json"])
            .arg(&csv),
    );
    let glrmon_wire::Record::Diagnosis(naive) =
        glrmon_wire::decode_record(json.trim().as_bytes()).unwrap()
    else {
        panic!("not a diagnosis: {json}");
    };
    assert_eq!(naive.residual, "kalman");
    assert_ne!(naive.support, injected);

    // A span outside the file is invalid input (exit code 1).
    let out = glrmon()
        .args(["diagnose", "--config"])
        .arg(&config)
        .args(["--from", "50", "--to", "200"])
        .arg(&csv)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("span 50..=200 is not within"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 19: on fault-free Example 1 data `glrmon diagnose` says "no fault": an
/// empty support and estimate in the record, and the text names the χ² test. (The
/// paper's rule alone always selected some of the 50 faults.)
#[test]
fn issue19_diagnose_on_fault_free_data_reports_no_fault() {
    let dir = std::env::temp_dir().join(format!("glrmon-nofault-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("example1-clean.csv");
    let config = table1::example1_path();
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--channel", "ltv3", "--samples", "101", "--seed", "7"])
            .arg("--output")
            .arg(&csv),
    );
    let json = run_ok(
        glrmon()
            .args(["diagnose", "--config"])
            .arg(&config)
            .args(["--channel", "ltv3", "--json"])
            .arg(&csv),
    );
    let glrmon_wire::Record::Diagnosis(d) =
        glrmon_wire::decode_record(json.trim().as_bytes()).unwrap()
    else {
        panic!("not a diagnosis: {json}");
    };
    assert!(d.support.is_empty(), "{json}");
    assert!(d.estimate.is_empty(), "{json}");
    assert_eq!(d.plateau, [d.lambda, d.lambda]);
    assert_eq!(Some(&d.lambda), d.path_lambda.first());
    let text = run_ok(
        glrmon()
            .args(["diagnose", "--config"])
            .arg(&config)
            .arg(&csv),
    );
    assert!(text.contains("support:   (none)"), "{text}");
    assert!(
        text.contains("the χ²(50) upper quantile at α = 0.01: no fault in the span"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Online: with `[channels.diagnosis] enabled = true` (and an isolation delay that
/// lets 100 samples accumulate), `glrmon replay` emits a `diagnosis` record right after
/// the alarm (at the crossing) and another right after its isolation update, 100
/// samples later, which isolates exactly the injected faults.
#[test]
fn replay_emits_the_diagnosis_right_after_the_alarm() {
    let dir = std::env::temp_dir().join(format!("glrmon-diagnosis-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(table1::example1_path()).unwrap();
    let text = text.replacen(
        "false_alarm = 1e-4\n",
        "false_alarm = 1e-4\nisolation_delay = 100\n\n[channels.diagnosis]\nenabled = true\n",
        1,
    );
    assert!(text.contains("[channels.diagnosis]"));
    let config = dir.join("example1-diagnosis.toml");
    std::fs::write(&config, text).unwrap();
    let csv = dir.join("example1.csv");
    let injected = ["f05", "f16", "f28", "f39", "f42"];
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--samples", "200", "--seed", "11"])
            .args(["--fault", &injected.map(|f| format!("{f}:1")).join(",")])
            .arg("--output")
            .arg(&csv),
    );
    let jsonl = run_ok(glrmon().args(["replay", "--config"]).arg(&config).arg(&csv));
    let records: Vec<glrmon_wire::Record> = jsonl
        .lines()
        .map(|l| glrmon_wire::decode_record(l.as_bytes()).unwrap())
        .filter(|r| !matches!(r, glrmon_wire::Record::Stat(_)))
        .collect();
    let alarm = records
        .iter()
        .position(|r| matches!(r, glrmon_wire::Record::Alarm(_)))
        .expect("an alarm");
    let glrmon_wire::Record::Alarm(a) = &records[alarm] else {
        unreachable!()
    };
    let Some(glrmon_wire::Record::Diagnosis(d)) = records.get(alarm + 1) else {
        panic!("no diagnosis after the alarm: {records:?}");
    };
    assert_eq!((d.k, d.to, d.from), (a.k, a.k, 0));
    let update = records
        .iter()
        .position(|r| matches!(r, glrmon_wire::Record::Isolation(_)))
        .expect("an isolation update");
    let glrmon_wire::Record::Isolation(u) = &records[update] else {
        unreachable!()
    };
    assert_eq!((u.alarm_k, u.k), (a.k, a.k + 100));
    let Some(glrmon_wire::Record::Diagnosis(d)) = records.get(update + 1) else {
        panic!("no diagnosis after the isolation update: {records:?}");
    };
    assert_eq!((d.k, d.to, d.from), (u.k, u.k, 0));
    assert_eq!(d.support, injected);
    assert!(
        !records
            .iter()
            .any(|r| matches!(r, glrmon_wire::Record::Error(_)))
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Zhang 2021, Table I at q = 5 (the paper: 99.5 % over 1000 trials): at least 95 % of
/// 200 seeded trials recover the exact support. `cargo run --release -p glrmon-cli
/// --example table1` runs the whole table.
#[test]
fn table_1_exact_support_rate_at_q5() {
    let channel = table1::example1_channel(
        &table1::example1_path(),
        glrmon_spec::ResidualKind::Kitanidis,
    )
    .unwrap();
    let trials = 200;
    let mut ok = 0;
    for t in 0..trials {
        let (truth, found) =
            table1::trial(&channel, 5, table1::trial_seed(2021, 5, t), false).unwrap();
        ok += u64::from(truth == found);
    }
    let (lo, hi) = table1::wilson(ok, trials);
    println!(
        "Table I, q = 5: {ok}/{trials} exact supports, 95 % CI [{:.1}, {:.1}] %",
        100.0 * lo,
        100.0 * hi
    );
    assert!(ok >= 190, "{ok}/{trials}");
}
