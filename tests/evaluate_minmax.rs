//! Zhang & Basseville 2014, §6.2, Fig. 8 through the real binary: `glrmon evaluate` on
//! `config/examples/paper2014-gas-pipeline.toml` with Table 1's two inlet leaks records,
//! for every run, each isolation test's minmax statistic l_a (eq. (41)) at the isolation
//! the confusion matrix counts, and states each test's type-I or type-II error rate
//! (eq. (42)) in its JSON, its table and its report (Fig. 8: a histogram per injected
//! fault and test, with the χ² density and the threshold).
//!
//! As in the paper each fault has its own test with one degree of freedom (`g0_leak`,
//! `gp_leak`, `outlet_leak`): for an injected inlet leak its own test can make a type-II
//! error and the two others a type-I error.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};

use serde_json::Value;
use support::{Scratch, evaluate_gas_pipeline_table1, glrmon, run_ok};

const RUNS: usize = 40;
/// The χ²(1) upper 1 % quantile: the threshold at `isolation_alpha = 0.01`.
const THRESHOLD_1: f64 = 6.634_896_601_021_21;

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/examples")
        .join(name)
}

/// `glrmon evaluate` of Table 1's faults, 40 runs each: its text output, its JSON file
/// and its HTML report.
fn evaluate(dir: &Path) -> (String, Value, String) {
    let (json, html) = (dir.join("eval.json"), dir.join("eval.html"));
    let out = run_ok(
        evaluate_gas_pipeline_table1(RUNS)
            .arg("--json-out")
            .arg(&json)
            .arg("--report")
            .arg(&html)
            .arg("--minmax-histograms"),
    );
    (
        String::from_utf8(out.stdout).unwrap(),
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap(),
        std::fs::read_to_string(html).unwrap(),
    )
}

/// The type-I or type-II rate of a test recomputed from its statistics and threshold:
/// the fraction above the threshold (fired) or not above it.
fn recomputed(test: &Value) -> (&'static str, f64) {
    let h = test["threshold"].as_f64().unwrap();
    let stats = test["statistics"].as_array().unwrap();
    let fired = stats
        .iter()
        .filter(|s| s.as_f64().is_some_and(|s| s > h))
        .count();
    let n = stats.len() as f64;
    if test.get("type_ii_rate").is_some() {
        ("type_ii_rate", (stats.len() - fired) as f64 / n)
    } else {
        ("type_i_rate", fired as f64 / n)
    }
}

#[test]
fn json_has_each_runs_minmax_statistic_and_the_rates_they_give() {
    let dir = Scratch::new("evaluate-minmax-json");
    let (_, v, _) = evaluate(&dir.0);
    let results = v["results"].as_array().unwrap();
    assert_eq!(results.len(), 2);
    for r in results {
        let fault = r["fault"].as_str().unwrap();
        let runs = r["runs"].as_array().unwrap();
        assert_eq!(runs.len(), RUNS);
        // The runs keep their keys: the statistics are added per test, not per run.
        let mut keys: Vec<&str> = runs[0]
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        keys.sort_unstable();
        assert_eq!(
            keys,
            [
                "ambiguous",
                "crossing",
                "false_alarms",
                "isolated",
                "isolated_at",
                "onset_estimate"
            ]
        );
        let isolating: Vec<&Value> = runs
            .iter()
            .filter(|x| !x["isolated_at"].is_null())
            .collect();
        assert!(
            isolating.len() >= RUNS * 9 / 10,
            "{fault}: {}",
            isolating.len()
        );
        let tests = r["minmax"].as_array().unwrap();
        let names: Vec<&str> = tests.iter().map(|t| t["test"].as_str().unwrap()).collect();
        assert_eq!(names, ["g0_leak", "gp_leak", "outlet_leak"], "{fault}");
        for t in tests {
            let test = t["test"].as_str().unwrap();
            let (dof, h) = (1, THRESHOLD_1);
            let rate_key = if test == fault {
                "type_ii_rate"
            } else {
                "type_i_rate"
            };
            let stats = t["statistics"].as_array().unwrap();
            assert_eq!(stats.len(), isolating.len(), "{fault}/{test}");
            assert!(stats.iter().all(|s| s.as_f64().is_some_and(|s| s >= 0.0)));
            assert_eq!(t["dof"], dof, "{fault}/{test}");
            assert!((t["threshold"].as_f64().unwrap() - h).abs() < 1e-9);
            // Exactly one rate, the one that applies, equal to the recomputed fraction.
            let (key, rate) = recomputed(t);
            assert_eq!(key, rate_key, "{fault}/{test}");
            assert!(
                t.get(["type_i_rate", "type_ii_rate"][usize::from(key == "type_i_rate")])
                    .is_none()
            );
            let stated = t[key].as_f64().unwrap();
            assert!(
                (stated - rate).abs() < 1e-12,
                "{fault}/{test}: {stated} vs {rate}"
            );
            // The statistics are those of the isolation the confusion matrix counts: a
            // run isolated the test only when its statistic exceeds the threshold (the
            // test fired); a test that fired is left out when another fault alone, at
            // its own onset, explains the data as well (onset-free isolation).
            let fired = stats.iter().filter(|s| s.as_f64().unwrap() > h).count();
            assert_eq!(t["fired"], fired, "{fault}/{test}");
            for (run, s) in isolating.iter().zip(stats) {
                let named = run["isolated"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|n| n == test);
                assert!(!named || s.as_f64().unwrap() > h, "{fault}/{test}: {run}");
            }
        }
    }
}

#[test]
fn text_prints_the_fig8_table_with_the_json_rates() {
    let dir = Scratch::new("evaluate-minmax-text");
    let (text, v, _) = evaluate(&dir.0);
    let table = text
        .split("minmax isolation (Fig. 8)")
        .nth(1)
        .unwrap_or_else(|| panic!("no Fig. 8 table in:\n{text}"));
    let rows: Vec<Vec<&str>> = table
        .lines()
        .skip(2)
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 6, "{table}");
    for r in v["results"].as_array().unwrap() {
        for t in r["minmax"].as_array().unwrap() {
            let (fault, test) = (r["fault"].as_str().unwrap(), t["test"].as_str().unwrap());
            let row = rows
                .iter()
                .find(|row| row[0] == fault && row[1] == test)
                .unwrap_or_else(|| panic!("no row {fault}/{test} in:\n{table}"));
            // fault, test, runs, median, threshold, (dof), type I, type II
            assert_eq!(
                row[2],
                t["statistics"].as_array().unwrap().len().to_string()
            );
            assert_eq!(row[4], format!("{:.4}", t["threshold"].as_f64().unwrap()));
            assert_eq!(row[5], format!("({})", t["dof"]));
            let (key, rate) = recomputed(t);
            let (stated, other) = if key == "type_i_rate" {
                (row[6], row[7])
            } else {
                (row[7], row[6])
            };
            assert_eq!(stated, format!("{:.1}%", 100.0 * rate), "{fault}/{test}");
            assert_eq!(other, "–");
        }
    }
}

#[test]
fn report_draws_fig8_with_chi2_density_threshold_and_rates() {
    let dir = Scratch::new("evaluate-minmax-html");
    let (_, v, html) = evaluate(&dir.0);
    let section = html
        .split("<section id=\"minmax\">")
        .nth(1)
        .expect("a Fig. 8 section");
    assert!(section.contains("Minmax isolation statistics (Fig. 8)"));
    assert_eq!(section.matches("class=\"fig minmax-histogram\"").count(), 6);
    assert_eq!(
        section
            .matches("<path class=\"chi2-density\" d=\"M")
            .count(),
        6
    );
    assert_eq!(section.matches("<line class=\"threshold\"").count(), 6);
    assert!(section.contains("χ²(1) density"));
    for r in v["results"].as_array().unwrap() {
        for t in r["minmax"].as_array().unwrap() {
            let (key, rate) = recomputed(t);
            let kind = if key == "type_i_rate" {
                "type I"
            } else {
                "type II"
            };
            let caption = format!(
                "<code>{}</code>: {kind} error rate {:.1} %",
                r["fault"].as_str().unwrap(),
                100.0 * rate
            );
            assert!(section.contains(&caption), "no caption {caption}");
        }
    }
    assert!(!html.contains("NaN"));
}

/// Without isolation groups each fault is its own test (one degree of freedom): the
/// test of the injected fault can make a type-II error, every other test a type-I error.
#[test]
fn one_test_per_fault_without_groups() {
    let dir = Scratch::new("evaluate-minmax-faults");
    let json = dir.0.join("eval.json");
    run_ok(
        glrmon()
            .args(["evaluate", "--config"])
            .arg(config("paper2014-unstable.toml"))
            .args(["--runs", "20", "--fault", "x1_jump:4", "--json-out"])
            .arg(&json),
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    let tests = v["results"][0]["minmax"].as_array().unwrap();
    let names: Vec<&str> = tests.iter().map(|t| t["test"].as_str().unwrap()).collect();
    assert_eq!(names, ["x0_jump", "x1_jump"]);
    assert!(tests[0].get("type_i_rate").is_some());
    assert!(tests[1].get("type_ii_rate").is_some());
    for t in tests {
        assert_eq!(t["dof"], 1);
        assert_eq!(t["faults"], serde_json::json!([t["test"]]));
        let (key, rate) = recomputed(t);
        assert!((t[key].as_f64().unwrap() - rate).abs() < 1e-12);
    }
}
