//! Zhang & Basseville 2014, §6.2 (leak detection in a gas transportation network), the
//! single-run protocol of Figs. 5, 6 and 9 through the real binary on
//! `config/examples/paper2014-gas-pipeline.toml`: `glrmon simulate` (fixed seed), then
//! `glrmon replay`. The model is a plausible stand-in (the paper does not print its
//! matrices), so the test checks the shape of the paper's results, not its numbers:
//!
//! * Table 1's inlet leak (G_0(1) − 2·10⁻⁵ from minute 600 = sample 300): no alarm before
//!   the onset, an alarm within 350 min of it, an onset estimate within 120 min of
//!   minute 600, and the inlet-leak group isolated at the isolation update (Fig. 5);
//! * the doubled fault is detected earlier than the single one on the same noise (Fig. 6);
//! * the outlet bias of −43 980 Nm³ from minute 700 drives l_k to at least 10 times the
//!   threshold of 50 (Fig. 9: about 50 times), and is isolated as the outlet group.
//!
//! Measured with seed 1: alarm at sample 407 (minute 814), r̂ = 318 (minute 636); doubled
//! fault alarm at 344 (delay 88 min, the paper's figure); outlet bias peak l_k ≈ 1.9·10⁵.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};
use support::{Scratch, glrmon, run_ok};

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
    let alarms = of_type(&records, "alarm");
    assert!(!alarms.is_empty(), "the inlet leak is never detected");
    for a in &alarms {
        assert!(
            a["k"].as_u64().unwrap() >= onset,
            "false alarm before the onset: {a}"
        );
    }
    let first = alarms[0];
    let k = first["k"].as_u64().unwrap();
    let r_hat = first["onset"].as_u64().unwrap();
    assert!(first["glr"].as_f64().unwrap() >= THRESHOLD);
    assert!(
        k - onset <= 175,
        "alarm at minute {} (delay {} min): {first}",
        2 * k,
        2 * (k - onset)
    );
    assert!(
        r_hat.abs_diff(onset) <= 60,
        "onset estimate at minute {}: {first}",
        2 * r_hat
    );
    let update = isolation_of(&records, first);
    let names = isolated(update);
    assert!(
        names.contains(&"inlet_leak".to_owned()),
        "inlet leak not isolated: {update}"
    );

    // Fig. 6: the doubled fault, same noise: detected earlier.
    let doubled = simulate_and_replay(&dir.0, "g0_leak:-4e-5", onset);
    let alarms2 = of_type(&doubled, "alarm");
    assert!(
        !alarms2.is_empty(),
        "the doubled inlet leak is never detected"
    );
    let k2 = alarms2[0]["k"].as_u64().unwrap();
    assert!(
        k2 >= onset && k2 < k,
        "doubled fault alarm at {k2}, single at {k}"
    );

    // Fig. 9: the outlet leak at minute 700.
    let outlet_onset = 350;
    let outlet = simulate_and_replay(&dir.0, "outlet_leak:-43980", outlet_onset);
    let alarms3 = of_type(&outlet, "alarm");
    assert!(!alarms3.is_empty(), "the outlet leak is never detected");
    assert!(
        alarms3[0]["k"].as_u64().unwrap() >= outlet_onset,
        "{}",
        alarms3[0]
    );
    let peak = peak_glr(&outlet);
    assert!(peak >= 10.0 * THRESHOLD, "outlet leak: peak l_k = {peak}");
    let update = isolation_of(&outlet, alarms3[0]);
    assert_eq!(isolated(update), ["outlet"], "{update}");
    // Before the onset, l_k stays below the threshold.
    let before = of_type(&outlet, "stat")
        .iter()
        .filter(|r| r["k"].as_u64().unwrap() < outlet_onset)
        .filter_map(|r| r["glr"].as_f64())
        .fold(0.0, f64::max);
    assert!(before < THRESHOLD, "l_k = {before} before the outlet leak");
}
