//! Zhang & Basseville 2014, §6.2 (leak detection in a gas transportation network), the
//! single-run protocol of Figs. 5, 6 and 9 and the Monte-Carlo isolation of Fig. 8 through
//! the real binary on `config/examples/paper2014-gas-pipeline.toml`: `glrmon simulate`
//! (fixed seed), then `glrmon replay`; `glrmon evaluate --json` (fixed seeds). The model
//! is a plausible stand-in (the paper does not print its matrices), so the test checks the
//! shape of the paper's results, not its numbers:
//!
//! * Table 1's fault 1 (G_0(1) − 2·10⁻⁵ from minute 600 = sample 300): no alarm before the
//!   onset, an alarm 50-250 min after it, an onset estimate within 60 min of minute 600
//!   (at the alarm and at the isolation update), and fault 1 isolated, fault 2 not, at the
//!   alarm and at the update (Fig. 5); fault 2 (G_p(1) − 10⁻⁵) likewise the other way;
//! * the doubled fault is detected at least 1.5 times faster on the same noise (Fig. 6:
//!   186 → 88 min);
//! * the outlet bias of −43 980 Nm³ from minute 700 is detected at once, drives l_k to at
//!   least 100 times the threshold of 50 (Fig. 9: about 50 times) and is isolated as
//!   `outlet_leak` alone;
//! * Fig. 8 over 200 runs per inlet fault: each fault has its own minmax test (one degree
//!   of freedom, threshold 6.6349); the other inlet fault's test fires (type I) in at most
//!   10 % of the runs and the fault's own test misses (type II) in at most 5 % (the
//!   paper: 1.7 % and 1.3 % type I, 0 % type II over 1000 runs).
//!
//! Measured with seed 1: fault 1 alarm at sample 361 (minute 722, delay 122 min), r̂ = 288
//! at the alarm and 318 at the update; doubled fault alarm at 322 (delay 44 min); fault 2
//! alarm at 398 (delay 196 min), r̂ = 295; outlet bias peak l_k ≈ 2.85·10⁴. Fig. 8 over
//! 200 runs: fault 1, type I 6.5 % (gp_leak's test), type II 0.0 %; fault 2, type I 2.0 %
//! (g0_leak's test), type II 1.5 %.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};
use support::{Scratch, evaluate_gas_pipeline_table1, glrmon, run_ok};

const THRESHOLD: f64 = 50.0;

fn config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2014-gas-pipeline.toml")
}

/// The records of `glrmon replay` on a run simulated with `fault` from `onset`.
fn simulate_and_replay(dir: &Path, fault: &str, onset: u64) -> Vec<serde_json::Value> {
    let csv = dir.join(format!("{}.csv", fault.replace([':', '-', '.'], "_")));
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(config())
            .args([
                "--samples",
                "500",
                "--seed",
                "1",
                "--fault",
                fault,
                "--onset",
                &onset.to_string(),
                "--output",
            ])
            .arg(&csv),
    );
    let out = run_ok(
        glrmon()
            .args(["replay", "--quiet", "--config"])
            .arg(config())
            .arg(&csv),
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn of_type<'a>(records: &'a [serde_json::Value], kind: &str) -> Vec<&'a serde_json::Value> {
    records.iter().filter(|r| r["type"] == kind).collect()
}

/// The names whose minmax test isolated them in an alarm or isolation record.
fn isolated(record: &serde_json::Value) -> Vec<String> {
    record["isolation"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["isolated"] == true)
        .map(|t| {
            t.get("fault")
                .or_else(|| t.get("group"))
                .and_then(|n| n.as_str())
                .unwrap()
                .to_owned()
        })
        .collect()
}

/// The isolation update of the alarm raised at `alarm_k` (the alarm itself when no update
/// was sent).
fn isolation_of<'a>(
    records: &'a [serde_json::Value],
    alarm: &'a serde_json::Value,
) -> &'a serde_json::Value {
    of_type(records, "isolation")
        .into_iter()
        .find(|r| r["alarm_k"] == alarm["k"])
        .unwrap_or(alarm)
}

fn peak_glr(records: &[serde_json::Value]) -> f64 {
    of_type(records, "stat")
        .iter()
        .filter_map(|r| r["glr"].as_f64())
        .fold(0.0, f64::max)
}

#[test]
fn inlet_and_outlet_leaks_have_the_papers_shape() {
    let dir = Scratch::new("gas-pipeline");
    let onset = 300; // minute 600

    // Fig. 5: Table 1's fault 1.
    let records = simulate_and_replay(&dir.0, "g0_leak:-2e-5", onset);
    let k = first_alarm(&records, onset, "g0_leak", "gp_leak");
    println!(
        "fault 1: alarm at sample {k} (delay {} min)",
        2 * (k - onset)
    );

    // Table 1's fault 2: the same shape, the other test.
    let records2 = simulate_and_replay(&dir.0, "gp_leak:-1e-5", onset);
    let k_p = first_alarm(&records2, onset, "gp_leak", "g0_leak");
    println!(
        "fault 2: alarm at sample {k_p} (delay {} min)",
        2 * (k_p - onset)
    );

    // Fig. 6: the doubled fault, same noise: detected at least 1.5 times faster (the paper:
    // 186 → 88 min).
    let doubled = simulate_and_replay(&dir.0, "g0_leak:-4e-5", onset);
    let alarms2 = of_type(&doubled, "alarm");
    assert!(
        !alarms2.is_empty(),
        "the doubled inlet leak is never detected"
    );
    let k2 = alarms2[0]["k"].as_u64().unwrap();
    println!(
        "doubled fault 1: alarm at sample {k2} (delay {} min)",
        2 * (k2 - onset)
    );
    assert!(
        k2 >= onset && 3 * (k2 - onset) <= 2 * (k - onset),
        "doubled fault alarm at {k2}, single at {k}"
    );

    // Fig. 9: the outlet leak at minute 700.
    let outlet_onset = 350;
    let outlet = simulate_and_replay(&dir.0, "outlet_leak:-43980", outlet_onset);
    let alarms3 = of_type(&outlet, "alarm");
    assert!(!alarms3.is_empty(), "the outlet leak is never detected");
    let k3 = alarms3[0]["k"].as_u64().unwrap();
    assert!(
        (outlet_onset..=outlet_onset + 2).contains(&k3),
        "outlet leak alarm at {k3}: {}",
        alarms3[0]
    );
    let peak = peak_glr(&outlet);
    println!(
        "outlet leak: alarm at {k3}, peak l_k = {peak:.0} ({:.0} × the threshold)",
        peak / THRESHOLD
    );
    assert!(peak >= 100.0 * THRESHOLD, "outlet leak: peak l_k = {peak}");
    let update = isolation_of(&outlet, alarms3[0]);
    assert_eq!(isolated(update), ["outlet_leak"], "{update}");
    // Before the onset, l_k stays below the threshold.
    let before = of_type(&outlet, "stat")
        .iter()
        .filter(|r| r["k"].as_u64().unwrap() < outlet_onset)
        .filter_map(|r| r["glr"].as_f64())
        .fold(0.0, f64::max);
    assert!(before < THRESHOLD, "l_k = {before} before the outlet leak");
}

/// The first alarm of a run with inlet fault `own` injected at `onset`, checked against the
/// paper's shape (no false alarm, a delay of 50-250 min, onset estimates within 30 samples
/// of the onset, `own` isolated and `other` not, at the alarm and at its update): its
/// sample.
fn first_alarm(records: &[serde_json::Value], onset: u64, own: &str, other: &str) -> u64 {
    let alarms = of_type(records, "alarm");
    assert!(!alarms.is_empty(), "{own}: never detected");
    for a in &alarms {
        assert!(
            a["k"].as_u64().unwrap() >= onset,
            "{own}: false alarm before the onset: {a}"
        );
    }
    let first = alarms[0];
    let k = first["k"].as_u64().unwrap();
    assert!(first["glr"].as_f64().unwrap() >= THRESHOLD);
    assert!(
        (onset + 25..=onset + 125).contains(&k),
        "{own}: alarm at minute {} (delay {} min): {first}",
        2 * k,
        2 * (k - onset)
    );
    let update = isolation_of(records, first);
    // At the alarm the two inlet faults (signatures correlated at 0.81) may not yet be
    // told apart once the onset is free: then both are reported ambiguous, neither
    // isolated; the update isolates the injected one.
    let ambiguous = |r: &serde_json::Value| {
        r["isolation"].as_array().unwrap().iter().any(|t| {
            t["fault"] == own
                && (t["ambiguous_with"].as_array().unwrap())
                    .iter()
                    .any(|n| n == other)
        })
    };
    assert!(
        isolated(first).iter().any(|n| n == own) || ambiguous(first),
        "{own} neither isolated nor ambiguous at the alarm: {first}"
    );
    assert!(
        !ambiguous(update),
        "{own}: still ambiguous at the update: {update}"
    );
    for r in [first, update] {
        let r_hat = r["onset"].as_u64().unwrap();
        println!(
            "{own}: r̂ = {r_hat} (minute {}) at k = {}",
            2 * r_hat,
            r["k"]
        );
        assert!(
            r_hat.abs_diff(onset) <= 30,
            "{own}: onset estimate at minute {}: {r}",
            2 * r_hat
        );
        let names = isolated(r);
        assert!(
            names.iter().any(|n| n == own) || ambiguous(r),
            "{own} not isolated: {r}"
        );
        assert!(
            !names.iter().any(|n| n == other),
            "{own} taken for {other}: {r}"
        );
    }
    k
}

/// Fig. 8: `glrmon evaluate --json` of Table 1's two faults, 200 runs each (seeds 1-200):
/// each fault has its own minmax test; the other inlet fault's test fires in at most 10 %
/// of the runs (type I; measured 6.5 % and 2.0 %) and the fault's own test misses in at
/// most 5 % (type II; measured 0.0 % and 1.5 %).
#[test]
fn fig8_each_inlet_fault_is_told_from_the_other() {
    const RUNS: usize = 200;
    let out = run_ok(evaluate_gas_pipeline_table1(RUNS).arg("--json"));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let results = v["results"].as_array().unwrap();
    assert_eq!(results.len(), 2);
    for (r, (own, other)) in results
        .iter()
        .zip([("g0_leak", "gp_leak"), ("gp_leak", "g0_leak")])
    {
        assert_eq!(r["fault"], own);
        let tests = r["minmax"].as_array().unwrap();
        let names: Vec<&str> = tests.iter().map(|t| t["test"].as_str().unwrap()).collect();
        assert_eq!(names, ["g0_leak", "gp_leak", "outlet_leak"], "{own}");
        let test = |name: &str| tests.iter().find(|t| t["test"] == name).unwrap();
        for t in tests {
            assert_eq!(t["dof"], 1, "{own}: {t}");
            assert_eq!(t["statistics"].as_array().unwrap().len(), RUNS, "{own}");
        }
        let type_ii = test(own)["type_ii_rate"].as_f64().unwrap();
        let type_i = test(other)["type_i_rate"].as_f64().unwrap();
        let outlet = test("outlet_leak")["type_i_rate"].as_f64().unwrap();
        println!(
            "Fig. 8, {own} injected: {other}'s test fires in {:.1} % (type I), {own}'s test \
             misses in {:.1} % (type II); outlet_leak's test fires in {:.1} %",
            100.0 * type_i,
            100.0 * type_ii,
            100.0 * outlet
        );
        assert!(type_i <= 0.10, "{own}: type I {type_i}");
        assert!(type_ii <= 0.05, "{own}: type II {type_ii}");
    }
}
