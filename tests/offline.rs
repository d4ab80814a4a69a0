//! End-to-end tests of the offline path with the real binary:
//! `glrmon validate`, `glrmon simulate` → `glrmon replay`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glrmon_wire::{Alarm, IsolationUpdate, Record, decode_record};

fn glrmon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap()
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn config(name: &str) -> String {
    root().join("config").join(name).display().to_string()
}

struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        let p = std::env::temp_dir().join(format!("glrmon-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&p).unwrap();
        Self(p)
    }
    fn file(&self, name: &str) -> String {
        self.0.join(name).display().to_string()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn records(path: &str) -> Vec<Record> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| decode_record(l.as_bytes()).unwrap())
        .collect()
}

fn alarms(records: &[Record]) -> Vec<&Alarm> {
    records
        .iter()
        .filter_map(|r| {
            if let Record::Alarm(a) = r {
                Some(a)
            } else {
                None
            }
        })
        .collect()
}

/// The faults the alarm's episode isolated in the end: by its `isolation` update when
/// one came, else by the alarm at the crossing.
fn isolated<'a>(records: &'a [Record], a: &'a Alarm) -> Vec<&'a str> {
    let update = records.iter().find_map(|r| match r {
        Record::Isolation(u) if u.channel == a.channel && u.alarm_k == a.k => Some(u),
        _ => None,
    });
    update
        .map_or(&a.isolation, |u| &u.isolation)
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.as_str())
        .collect()
}

/// Simulates `samples` samples with a fault and replays them; returns the records.
fn simulate_replay(
    dir: &TempDir,
    cfg: &str,
    fault: &str,
    onset: u64,
    magnitude: &str,
    samples: u64,
    seed: u64,
) -> Vec<Record> {
    let csv = dir.file(&format!("{fault}-{seed}.csv"));
    let jsonl = dir.file(&format!("{fault}-{seed}.jsonl"));
    ok(&glrmon(&[
        "simulate",
        "--config",
        cfg,
        "--samples",
        &samples.to_string(),
        "--seed",
        &seed.to_string(),
        "--fault",
        &format!("{fault}:{magnitude}"),
        "--onset",
        &onset.to_string(),
        "--output",
        &csv,
    ]));
    ok(&glrmon(&[
        "replay", "--config", cfg, &csv, "--output", &jsonl,
    ]));
    records(&jsonl)
}

#[test]
fn every_shipped_config_validates_with_an_isolability_report_or_says_why_not() {
    let mut files = vec![config("demo.toml")];
    for e in std::fs::read_dir(root().join("config/examples")).unwrap() {
        files.push(e.unwrap().path().display().to_string());
    }
    for f in files {
        let out = ok(&glrmon(&["validate", "--config", &f]));
        assert!(out.contains(": valid"), "{out}");
        // The kinds that only detect say so instead of an isolability report.
        let detects_only = ["parity", "fdf", "uio", "rls"]
            .iter()
            .any(|k| out.contains(&format!("detector: {k} — ")));
        if detects_only {
            assert!(out.contains("isolability: not computed (the `"), "{out}");
            assert!(out.contains("detection only"), "{out}");
        } else if out.contains("detector: kernel — ") {
            // The kernel kind isolates by exclusion, without Fisher information.
            assert!(
                out.contains("isolability: not computed (the `kernel`"),
                "{out}"
            );
            assert!(out.contains("excluding candidate fault functions"), "{out}");
        } else {
            assert!(out.contains("isolability over"), "{out}");
            assert!(out.contains("condition number"), "{out}");
        }
    }
}

#[test]
fn validate_lists_every_error_and_exits_1() {
    let dir = TempDir::new("invalid");
    let bad = dir.file("bad.toml");
    let text = std::fs::read_to_string(config("examples/dc-motor.toml"))
        .unwrap()
        .replace("R = 0.0025", "R = -1.0")
        .replace("min_lag = 1", "min_lag = 100");
    std::fs::write(&bad, text).unwrap();
    let out = glrmon(&["validate", "--config", &bad]);
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(r#"channels[0] "dc_motor": model.R is not positive definite"#),
        "{stdout}"
    );
    assert!(
        stdout.contains(r#"channels[0] "dc_motor": glr.min_lag: s = 100 must be below w = 100"#),
        "{stdout}"
    );
}

/// The 2014 paper's §6.2 Q as printed (four decimals, λ_min = −2.5·10⁻⁵) is
/// valid: exit 0, with a warning naming the field, λ_min and the change.
#[test]
fn validate_accepts_paper2014_gas_q_with_a_warning() {
    let dir = TempDir::new("gas-q");
    let file = dir.file("gas-q.toml");
    let text = std::fs::read_to_string(config("examples/paper2014-unstable.toml")).unwrap();
    assert!(text.contains("Q = 0.0025"), "fixture changed");
    let text = text.replacen(
        "Q = 0.0025",
        "Q = [[100.2766, -66.1165], [-66.1165, 43.5933]]",
        1,
    );
    std::fs::write(&file, text).unwrap();
    let out = ok(&glrmon(&["validate", "--config", &file]));
    assert!(out.contains(": valid, 1 channel(s)"), "{out}");
    let warning = out
        .lines()
        .find(|l| l.starts_with("warning: ") && l.contains("model.Q"))
        .unwrap_or_else(|| panic!("no model.Q warning:\n{out}"));
    assert!(
        warning.contains(r#"channels[0] "unstable": model.Q is not positive semi-definite as written (smallest eigenvalue -2.548e-5"#),
        "{warning}"
    );
    assert!(warning.contains("max |ΔQ| = 1."), "{warning}");
}

/// Zhang 2021 §III-B: with an unknown input E, `validate` says the GLR runs
/// on p − q output directions and that a state fault in the range of E is not
/// detectable (its signature is exactly zero), while the sensor bias outside it is; the
/// fault-free replay of 3 000 samples with d ≈ 50 raises no alarm.
#[test]
fn validate_reports_faults_in_the_range_of_e_undetectable() {
    let dir = TempDir::new("unknown-input");
    let file = dir.file("e.toml");
    std::fs::write(
        &file,
        r#"
[[channels]]
name = "tank"
[channels.model]
F = [[0.5, 0.1, 0.0], [0.0, 0.6, 0.1], [0.0, 0.0, 0.7]]
H = [[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]
E = [[1.0], [0.0], [0.0]]
Q = 0.01
R = 0.01
[[channels.faults]]
name = "sensor1"
kind = "sensor_bias"
output = 1
[[channels.faults]]
name = "inflow"
psi = [2.0, 0.0, 0.0]
[channels.simulation]
unknown_input = ["50 + 10*sin(0.05*k)"]
"#,
    )
    .unwrap();
    let out = ok(&glrmon(&["validate", "--config", &file]));
    assert!(
        out.contains("unknown input: E has 1 column(s), decoupled from the innovation: the GLR runs on 1 of the 2 output directions"),
        "{out}"
    );
    assert!(
        out.contains(r#"fault "inflow" is undetectable"#)
            && !out.contains(r#"fault "sensor1" is undetectable"#),
        "{out}"
    );
    let csv = dir.file("e.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &file,
        "--samples",
        "3000",
        "--output",
        &csv,
    ]));
    let replay = ok(&glrmon(&[
        "replay",
        "--config",
        &file,
        &csv,
        "--stat-every",
        "0",
        "--quiet",
    ]));
    assert!(!replay.contains(r#""type":"alarm""#), "{replay}");
}

/// On the §6.1 plant the alarm lands within 5 samples of the injected onset
/// 201 and isolates the right state (both magnitudes of the paper's Figures 3-4).
/// The `alarm` record's k is exactly the first sample whose l_k exceeds the
/// threshold (from the `stat` records of the same replay), and its `isolation` record,
/// which decides the isolation, comes isolation_delay = n = 2 samples later.
#[test]
fn paper2014_simulate_replay_alarm_within_5_samples_of_201_isolates_the_state() {
    let dir = TempDir::new("p2014");
    let cfg = config("examples/paper2014-unstable.toml");
    for (fault, magnitude) in [("x0_jump", "4"), ("x0_jump", "1.5"), ("x1_jump", "1.5")] {
        let recs = simulate_replay(&dir, &cfg, fault, 201, magnitude, 400, 7);
        let a = alarms(&recs);
        assert_eq!(a.len(), 1, "{fault} {magnitude}: {a:#?}");
        let crossing = recs.iter().find_map(|r| match r {
            Record::Stat(s) if s.glr.zip(s.threshold).is_some_and(|(l, h)| l > h) => Some(s.k),
            _ => None,
        });
        assert_eq!(Some(a[0].k), crossing, "{fault} {magnitude}");
        assert!(a[0].glr > a[0].threshold);
        assert!(
            (201..=206).contains(&a[0].k),
            "{fault} {magnitude}: alarm at {}",
            a[0].k
        );
        assert_eq!(a[0].update_k, Some(a[0].k + 2), "{fault} {magnitude}");
        let u: Vec<&IsolationUpdate> = recs
            .iter()
            .filter_map(|r| match r {
                Record::Isolation(u) => Some(u),
                _ => None,
            })
            .collect();
        assert_eq!(u.len(), 1, "{fault} {magnitude}: {u:#?}");
        assert_eq!((u[0].alarm_k, u[0].k), (a[0].k, a[0].k + 2));
        assert!(
            u[0].onset.abs_diff(201) <= 5,
            "{fault} {magnitude}: onset {}",
            u[0].onset
        );
        assert_eq!(
            isolated(&recs, a[0]),
            [fault],
            "{fault} {magnitude}: {:#?}",
            u[0].isolation
        );
        let stats = recs.iter().filter(|r| matches!(r, Record::Stat(_))).count();
        assert_eq!(stats, 400);
    }
}

/// On the DC motor each fault is isolated correctly.
#[test]
fn dc_motor_each_fault_is_detected_and_isolated() {
    let dir = TempDir::new("dcmotor");
    let cfg = config("examples/dc-motor.toml");
    for (fault, magnitude) in [("speed_sensor_drift", "0.01"), ("actuator_bias", "0.5")] {
        let recs = simulate_replay(&dir, &cfg, fault, 300, magnitude, 600, 3);
        let a = alarms(&recs);
        assert_eq!(a.len(), 1, "{fault}: {a:#?}");
        assert!(
            a[0].k >= 300 && a[0].k < 340,
            "{fault}: alarm at {}",
            a[0].k
        );
        let events: Vec<&Record> = recs
            .iter()
            .filter(|r| !matches!(r, Record::Stat(_)))
            .collect();
        assert_eq!(isolated(&recs, a[0]), [fault], "{fault}: {events:#?}");
    }
}

#[test]
fn replaying_the_same_csv_twice_gives_byte_identical_jsonl() {
    let dir = TempDir::new("twice");
    let cfg = config("examples/paper2014-unstable.toml");
    let csv = dir.file("in.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "500",
        "--fault",
        "x1_jump:2",
        "--onset",
        "250",
        "--output",
        &csv,
    ]));
    let (a, b) = (dir.file("a.jsonl"), dir.file("b.jsonl"));
    ok(&glrmon(&["replay", "--config", &cfg, &csv, "--output", &a]));
    ok(&glrmon(&["replay", "--config", &cfg, &csv, "--output", &b]));
    let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(a.len() > 50_000);
    assert_eq!(a, b);
    // Same seed, same file.
    let csv2 = dir.file("in2.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "500",
        "--fault",
        "x1_jump:2",
        "--onset",
        "250",
        "--output",
        &csv2,
    ]));
    assert_eq!(std::fs::read(&csv).unwrap(), std::fs::read(&csv2).unwrap());
}

/// `simulate --output X.mcap` and `--output X.csv` with the same seed replay to the same
/// JSON lines: the MCAP path (recorded configuration, JSON samples) and the CSV path
/// feed the monitor the same bits.
#[test]
fn simulated_mcap_and_csv_replay_to_identical_jsonl() {
    let dir = TempDir::new("mcap-csv");
    let cfg = config("examples/dc-motor.toml");
    let args = |out: &str| -> Vec<String> {
        [
            "simulate",
            "--config",
            &cfg,
            "--samples",
            "3000",
            "--seed",
            "5",
            "--fault",
            "actuator_bias:0.5",
            "--onset",
            "1500",
            "--output",
            out,
        ]
        .map(str::to_owned)
        .to_vec()
    };
    let (csv, mcap) = (dir.file("s.csv"), dir.file("s.mcap"));
    for out in [&csv, &mcap] {
        let a = args(out);
        ok(&glrmon(&a.iter().map(String::as_str).collect::<Vec<_>>()));
    }
    let (a, b) = (dir.file("a.jsonl"), dir.file("b.jsonl"));
    ok(&glrmon(&["replay", "--config", &cfg, &csv, "--output", &a]));
    ok(&glrmon(&["replay", &mcap, "--output", &b]));
    let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(a.len() > 500_000, "{} bytes", a.len());
    assert!(a == b, "CSV and MCAP replays differ");
    assert!(!alarms(&records(&dir.file("b.jsonl"))).is_empty());
}

/// `replay --stat-every N` writes every N-th `stat` line of the full replay and every
/// other record unchanged (CSV and MCAP input, JSON lines and MCAP output); 0 writes
/// no `stat` at all.
#[test]
fn replay_stat_every_decimates_only_the_stat_records() {
    let dir = TempDir::new("stat-every");
    let cfg = config("examples/dc-motor.toml");
    simulate_replay(&dir, &cfg, "actuator_bias", 1000, "0.5", 2000, 9);
    let (csv, full) = (
        dir.file("actuator_bias-9.csv"),
        dir.file("actuator_bias-9.jsonl"),
    );
    let lines = |path: &str| -> Vec<String> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .map(str::to_owned)
            .collect()
    };
    let is_stat = |l: &String| l.starts_with("{\"type\":\"stat\"");
    let all = lines(&full);
    let stats: Vec<&String> = all.iter().filter(|l| is_stat(l)).collect();
    let others: Vec<&String> = all.iter().filter(|l| !is_stat(l)).collect();
    assert_eq!(stats.len(), 2000);
    assert!(others.iter().any(|l| l.starts_with("{\"type\":\"alarm\"")));
    for every in [0_usize, 7] {
        let n = every.to_string();
        // To JSON lines, and through an MCAP file written with the same decimation.
        let (out, mcap) = (
            dir.file(&format!("every{every}.jsonl")),
            dir.file(&format!("every{every}.mcap")),
        );
        for output in [&out, &mcap] {
            ok(&glrmon(&[
                "replay",
                "--stat-every",
                &n,
                "--config",
                &cfg,
                &csv,
                "--output",
                output,
            ]));
        }
        let again = dir.file(&format!("every{every}-again.jsonl"));
        ok(&glrmon(&[
            "replay",
            "--stat-every",
            &n,
            &mcap,
            "--output",
            &again,
        ]));
        for path in [&out, &again] {
            let got = lines(path);
            let got_stats: Vec<&String> = got.iter().filter(|l| is_stat(l)).collect();
            let got_others: Vec<&String> = got.iter().filter(|l| !is_stat(l)).collect();
            let want: Vec<&String> = match every {
                0 => Vec::new(),
                e => stats.iter().step_by(e).copied().collect(),
            };
            assert_eq!(got_stats, want, "--stat-every {every}: {path}");
            assert_eq!(got_others, others, "--stat-every {every}: {path}");
        }
    }
}

#[test]
fn bad_rows_become_error_records_and_the_replay_continues() {
    let dir = TempDir::new("badrows");
    let cfg = config("examples/paper2014-unstable.toml");
    let csv = dir.file("in.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "300",
        "--output",
        &csv,
    ]));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[11] = "10,1.0".into(); // wrong column count
    let parts: Vec<&str> = lines[31].split(',').collect();
    lines[31] = format!("{},{},{},abc", parts[0], parts[1], parts[2]); // not a number
    let parts: Vec<String> = lines[41].split(',').map(str::to_owned).collect();
    lines[41] = format!("{},{},{},inf", parts[0], parts[1], parts[2]); // non-finite
    lines.insert(61, lines[60].clone()); // k repeats
    lines.insert(80, lines[70].clone()); // k goes back by 10 (within max_reorder: refused alone)
    std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
    let out = dir.file("out.jsonl");
    let replay = glrmon(&["replay", "--config", &cfg, &csv, "--output", &out]);
    ok(&replay);
    let recs = records(&out);
    let errors: Vec<(String, String)> = recs
        .iter()
        .filter_map(|r| {
            if let Record::Error(e) = r {
                Some((e.code.as_str().to_owned(), e.message.clone()))
            } else {
                None
            }
        })
        .collect();
    // The summary counts every error record: rejected rows and the monitor's own.
    let summary = String::from_utf8_lossy(&replay.stderr);
    assert!(
        summary.contains(&format!("{} errors", errors.len())),
        "{summary}"
    );
    let codes: Vec<&str> = errors
        .iter()
        .map(|e| e.0.as_str())
        .filter(|c| *c != "gap")
        .collect();
    assert_eq!(
        codes,
        [
            "wrong_dimension",
            "wrong_type",
            "non_finite",
            "duplicate",
            "out_of_order"
        ],
        "{errors:#?}"
    );
    // ... and names each code with its count.
    for code in [
        "wrong_dimension",
        "wrong_type",
        "non_finite",
        "duplicate",
        "out_of_order",
    ] {
        let n = errors.iter().filter(|e| e.0 == code).count();
        assert!(
            summary.contains(&format!("{code} {n}")),
            "{code}: {summary}"
        );
    }
    // Each rejected row leaves a one-sample gap, filled by a predict-only step.
    assert_eq!(
        errors.iter().filter(|e| e.0 == "gap").count(),
        3,
        "{errors:#?}"
    );
    let errors: Vec<_> = errors.into_iter().filter(|e| e.0 != "gap").collect();
    assert!(
        errors[0]
            .1
            .contains("row 12: has 2 columns, the header has 4"),
        "{errors:#?}"
    );
    assert!(
        errors[1]
            .1
            .contains(r#"row 32: column y0: "abc" is not a number"#),
        "{errors:#?}"
    );
    // The three rejected rows were missing samples: filled as gaps; the rest processed.
    let stats = recs.iter().filter(|r| matches!(r, Record::Stat(_))).count();
    assert_eq!(stats, 297);
}

/// Scheduling signals may come from a file instead of expressions of k.
#[test]
fn simulate_takes_scheduling_signals_from_a_file() {
    let dir = TempDir::new("signals");
    let cfg = config("demo.toml");
    let sig = dir.file("p.csv");
    let rows: Vec<String> = (0..50)
        .map(|k| format!("{}", (k as f64 * 0.1).cos()))
        .collect();
    std::fs::write(&sig, format!("p0\n{}\n", rows.join("\n"))).unwrap();
    let out = dir.file("out.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--channel",
        "lpv",
        "--samples",
        "50",
        "--signals",
        &sig,
        "--output",
        &out,
    ]));
    let text = std::fs::read_to_string(&out).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let p0 = header.iter().position(|h| *h == "p0").unwrap();
    for (k, line) in text.lines().skip(1).enumerate() {
        let v: f64 = line.split(',').nth(p0).unwrap().parse().unwrap();
        assert_eq!(v, (k as f64 * 0.1).cos(), "k = {k}");
    }
    // Too few rows is an input error (exit 1) naming the file.
    let short = glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--channel",
        "lpv",
        "--samples",
        "60",
        "--signals",
        &sig,
        "--output",
        &out,
    ]);
    assert_eq!(short.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&short.stderr)
            .contains("has 50 rows of signals, 60 samples requested")
    );
}

/// The HTML of `glrmon evaluate --report` against the JSON of the same runs: one
/// self-contained page; per injected fault its name, a delay and an onset-error histogram
/// (inline SVG) with one bar per distinct delay (the delays span fewer samples than the
/// bin cap, so bins are 1 sample wide), and the detection and isolated-alone counts of
/// the JSON in the summary and confusion tables.
fn evaluate_report_matches_json(html: &str, v: &serde_json::Value) {
    let results = v["results"].as_array().unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(
        !html.contains("<script") && !html.contains("src="),
        "not self-contained"
    );
    assert_eq!(html.matches("<svg").count(), 2 * results.len());
    assert_eq!(
        html.matches("class=\"fig delay-histogram\"").count(),
        results.len()
    );
    let onset = v["onset"].as_u64().unwrap();
    let summary = html
        .split("<h2>Summary</h2>")
        .nth(1)
        .unwrap()
        .split("<h2>")
        .next()
        .unwrap();
    let confusion = html
        .split("<table class=\"confusion\">")
        .nth(1)
        .unwrap()
        .split("</table>")
        .next()
        .unwrap();
    for (i, r) in results.iter().enumerate() {
        let fault = r["fault"].as_str().unwrap();
        let runs = r["runs"].as_array().unwrap();
        let delays: Vec<u64> = runs
            .iter()
            .filter_map(|x| x["crossing"].as_u64())
            .map(|c| c - onset)
            .collect();
        let alone = runs
            .iter()
            .filter(|x| x["isolated"] == serde_json::json!([fault]))
            .count();
        // The row whose first cell names the fault (header rows name every fault).
        let row = |table: &str| -> String {
            table
                .lines()
                .find(|l| {
                    l.starts_with(&format!("<tr><th><code>{fault}</code>"))
                        || l.contains(&format!("\"><code>{fault}</code></a></td>"))
                })
                .unwrap_or_else(|| panic!("no row of {fault}"))
                .to_owned()
        };
        assert!(
            row(summary).contains(&format!("<td class=\"num detected\">{}</td>", delays.len())),
            "{fault}: summary row {} does not state {} detections",
            row(summary),
            delays.len()
        );
        assert!(
            row(confusion).contains(&format!(">{alone}<br><span class=\"pct\">")),
            "{fault}: confusion row {} does not state {alone} isolated alone",
            row(confusion)
        );
        let section = html
            .split(&format!("<section id=\"fault-{i}\">"))
            .nth(1)
            .unwrap();
        assert!(section.contains(&format!("<code>{fault}</code>")));
        let delay_svg = section.split("</svg>").next().unwrap();
        assert!(delay_svg.contains(&format!("runs of {fault} that detected ({})", delays.len())));
        let mut distinct = delays.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(
            delay_svg.matches("class=\"bar\"").count(),
            distinct.len(),
            "{fault}: one bar per distinct delay {distinct:?}"
        );
    }
}

/// `glrmon evaluate` on the DC motor, both faults, 200 seeded runs each: every
/// run detects, the sensor drift within 30 samples (median), the actuator bias within 5,
/// and the isolation names the injected fault alone in at least 90 % of the runs. The
/// `--report` page of the same runs states the JSON's numbers (see
/// `evaluate_report_matches_json`).
#[test]
fn evaluate_dc_motor_reports_detection_delay_and_confusion() {
    let dir = TempDir::new("evaluate");
    let cfg = config("examples/dc-motor.toml");
    let json = dir.file("eval.json");
    let html = dir.file("eval.html");
    let text = ok(&glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--fault",
        "speed_sensor_drift:0.01",
        "--fault",
        "actuator_bias:0.5",
        "--runs",
        "200",
        "--json-out",
        &json,
        "--report",
        &html,
    ]));
    assert!(text.contains("isolation at the first alarm"), "{text}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    evaluate_report_matches_json(&std::fs::read_to_string(&html).unwrap(), &v);
    let onset = v["onset"].as_u64().unwrap();
    for (r, max_delay) in v["results"].as_array().unwrap().iter().zip([30, 5]) {
        let fault = r["fault"].as_str().unwrap();
        let runs = r["runs"].as_array().unwrap();
        assert_eq!(runs.len(), 200);
        let mut delays: Vec<u64> = runs
            .iter()
            .map(|x| x["crossing"].as_u64().expect("every run detects") - onset)
            .collect();
        delays.sort_unstable();
        assert!(
            delays[100] <= max_delay,
            "{fault}: median delay {}",
            delays[100]
        );
        let right = runs
            .iter()
            .filter(|x| x["isolated"] == serde_json::json!([fault]))
            .count();
        assert!(
            right >= 180,
            "{fault}: isolated alone in {right} of 200 runs"
        );
        let false_alarms: u64 = runs
            .iter()
            .map(|x| x["false_alarms"].as_u64().unwrap())
            .sum();
        assert_eq!(false_alarms, 0, "{fault}");
    }
    eprintln!("{text}");

    // The plain χ² test of εᵀΣ⁻¹ε (`detector = "chi2"`, the baseline) on the same runs
    // sees the slow sensor drift later than the windowed GLR.
    let chi2 = dir.file("chi2.toml");
    let base = std::fs::read_to_string(&cfg).unwrap();
    assert!(base.contains("[channels.glr]\n"));
    std::fs::write(
        &chi2,
        base.replacen(
            "[channels.glr]\n",
            "[channels.glr]\ndetector = \"chi2\"\n",
            1,
        ),
    )
    .unwrap();
    let median_delay = |config: &str| -> u64 {
        let json = dir.file("median.json");
        ok(&glrmon(&[
            "evaluate",
            "--config",
            config,
            "--fault",
            "speed_sensor_drift:0.01",
            "--runs",
            "200",
            "--json-out",
            &json,
        ]));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let onset = v["onset"].as_u64().unwrap();
        let mut d: Vec<u64> = v["results"][0]["runs"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|x| x["crossing"].as_u64())
            .map(|c| c - onset)
            .collect();
        d.sort_unstable();
        d[d.len() / 2]
    };
    let (glr, chi2) = (median_delay(&cfg), median_delay(&chi2));
    eprintln!("speed-sensor drift 0.01: median delay GLR {glr} samples, χ² test {chi2} samples");
    assert!(glr < chi2, "GLR {glr} vs χ² {chi2}");
}

/// A channel with `[channels.columns]` names: `simulate` writes the named header, so
/// that `replay` of its own output works (it wrote `u0,y0` and replay refused the file,
/// "column FI101 is missing from the header").
#[test]
fn simulate_writes_the_channels_column_names_and_replay_reads_them() {
    let dir = TempDir::new("columns");
    let cfg = dir.file("tank.toml");
    std::fs::write(
        &cfg,
        r#"
[[channels]]
name = "tank"
model = { F = [[0.9]], G = [[1.0]], H = [[1.0]], J = [[0.0]], Q = [[0.01]], R = [[0.01]] }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
[channels.columns]
u = ["FI101"]
y = ["LI201"]
"#,
    )
    .unwrap();
    let csv = dir.file("run.csv");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "300",
        "--fault",
        "level_bias:1",
        "--onset",
        "150",
        "--output",
        &csv,
    ]));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("k,FI101,LI201\n"), "{}", &text[..40]);
    let out = dir.file("out.jsonl");
    ok(&glrmon(&[
        "replay", "--config", &cfg, &csv, "--quiet", "--output", &out,
    ]));
    let alarms: Vec<Alarm> = records(&out)
        .into_iter()
        .filter_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .collect();
    assert_eq!(alarms.len(), 1, "{alarms:?}");
    assert!((150..=160).contains(&alarms[0].onset), "{alarms:?}");
}

/// Several CSV files in one replay: each a run of its own from a fresh monitor (the
/// same alarms as replaying it alone, at indices moved up after the previous file's),
/// one summary line per file, records in one increasing order of k; an MCAP file among
/// them is refused.
#[test]
fn replay_takes_several_csv_files_each_a_run_of_its_own() {
    let dir = TempDir::new("replay-files");
    let cfg = config("examples/paper2014-unstable.toml");
    let (a, b) = (dir.file("a.csv"), dir.file("b.csv"));
    for (file, seed) in [(&a, "1"), (&b, "2")] {
        ok(&glrmon(&[
            "simulate",
            "--config",
            &cfg,
            "--samples",
            "400",
            "--seed",
            seed,
            "--fault",
            "x0_jump:4",
            "--onset",
            "201",
            "--output",
            file,
        ]));
    }
    let (both, alone) = (dir.file("both.jsonl"), dir.file("b.jsonl"));
    let out = glrmon(&["replay", "--config", &cfg, &a, &b, "--output", &both]);
    ok(&out);
    let summary = String::from_utf8_lossy(&out.stderr);
    assert!(
        summary.contains("a.csv: 400 rows, 400 samples, 1 alarm, 0 errors")
            && summary.contains("b.csv: 400 rows, 400 samples, 1 alarm, 0 errors"),
        "{summary}"
    );
    let both = records(&both);
    let ks: Vec<u64> = both.iter().filter_map(Record::k).collect();
    assert!(ks.windows(2).all(|w| w[0] <= w[1]), "k in one order");
    assert_eq!(ks.last(), Some(&799));
    ok(&glrmon(&[
        "replay", "--config", &cfg, &b, "--output", &alone,
    ]));
    let alone = records(&alone);
    let second: Vec<&Alarm> = alarms(&both).into_iter().filter(|a| a.k >= 400).collect();
    let own = alarms(&alone);
    assert_eq!(second.len(), own.len());
    for (x, y) in second.iter().zip(&own) {
        assert_eq!((x.k - 400, x.onset - 400), (y.k, y.onset));
        assert_eq!(
            x.glr.to_bits(),
            y.glr.to_bits(),
            "a fresh monitor: the same numbers"
        );
    }
    let mixed = glrmon(&["replay", "--config", &cfg, &a, &dir.file("x.mcap")]);
    assert_eq!(mixed.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&mixed.stderr).contains("an MCAP recording is replayed alone"),
        "{}",
        String::from_utf8_lossy(&mixed.stderr)
    );
}

/// `simulate --end`: a fault that ends. A speed-sensor drift from 100 to 200 on the DC
/// motor changes y1 on exactly those samples (same seed, same noise), nothing else; an
/// end before the onset is refused.
#[test]
fn simulate_end_cuts_the_fault_off() {
    let dir = TempDir::new("simulate-end");
    let cfg = config("examples/dc-motor.toml");
    let (clean, ended) = (dir.file("clean.csv"), dir.file("ended.csv"));
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "300",
        "--output",
        &clean,
    ]));
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "300",
        "--fault",
        "speed_sensor_drift:0.01",
        "--onset",
        "100",
        "--end",
        "200",
        "--output",
        &ended,
    ]));
    let rows = |path: &str| -> Vec<Vec<f64>> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let (clean, ended) = (rows(&clean), rows(&ended));
    let changed: Vec<usize> = (0..300).filter(|&k| clean[k] != ended[k]).collect();
    assert_eq!(changed.first(), Some(&100));
    assert_eq!(changed.last(), Some(&199));
    assert_eq!(changed.len(), 100);
    let refused = glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "10",
        "--fault",
        "actuator_bias:1",
        "--onset",
        "5",
        "--end",
        "5",
        "--output",
        &dir.file("x.csv"),
    ]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--end 5 must come after --onset 5"));
}

/// `evaluate --detector glr,chi2,parity` runs the same faults and noise through each
/// kind at the same false-alarm probability and prints one table: every kind detects
/// a speed-sensor drift, the GLR isolates it, and the parity kind (detection only)
/// reports no isolation; the parity threshold is χ²(4)'s at 10⁻⁴ (dimension
/// (s + 1)p − n = 4 at s = 2).
#[test]
fn evaluate_compares_detector_kinds_side_by_side() {
    let cfg = config("examples/dc-motor-parity.toml");
    let dir = TempDir::new("evaluate-kinds");
    let report = dir.file("kinds.html");
    let out = glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--report",
        &report,
        "--detector",
        "glr,chi2,parity",
        "--runs",
        "20",
        "--fault",
        "speed_sensor_drift:0.002",
    ]);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(
            "parity space of order 2 (dimension 4; the smallest order with one is 1), χ²(4) of rᵀΣ_r⁻¹r (threshold 23.5127)"
        ),
        "{text}"
    );
    let row = |kind: &str| {
        text.lines()
            .find(|l| l.starts_with(kind) && l.contains("speed_sensor_drift ("))
            .unwrap_or_else(|| panic!("no {kind} row in\n{text}"))
            .to_owned()
    };
    for kind in ["glr", "chi2", "parity"] {
        assert!(row(kind).contains("100.0%"), "{}", row(kind));
    }
    assert!(row("glr").trim_end().ends_with("100.0%"), "{}", row("glr"));
    assert!(row("parity").trim_end().ends_with('–'), "{}", row("parity"));
    let html = std::fs::read_to_string(&report).unwrap();
    assert_eq!(
        html.matches("<svg").count(),
        3,
        "one delay histogram per kind"
    );
    for kind in ["glr", "chi2", "parity"] {
        assert!(html.contains(&format!("Detection delay, {kind}")), "{kind}");
    }
    assert!(
        html.contains("seeds</th><td>1 … 20, the same for every kind"),
        "{html}"
    );
    let bad = glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--detector",
        "glr,kalman",
        "--runs",
        "2",
    ]);
    assert_eq!(
        bad.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );
    assert!(String::from_utf8_lossy(&bad.stderr).contains(
        "--detector kalman: not a detector kind (kinds: glr, chi2, cusum, parity, fdf, uio, rls, kernel)"
    ));
}

/// The survey's DC motor with a large unknown input through E_d = [−1.5537, 0]ᵀ: the
/// unknown-input observer's residual is decoupled from it and keeps its false-alarm
/// rate, while the fault-detection filter, which does not decouple it, alarms all the
/// time; the UIO detects a current-sensor bias (outside the range of HE).
#[test]
fn evaluate_shows_the_unknown_input_observer_ignoring_the_disturbance() {
    let cfg = config("examples/dc-motor-uio.toml");
    let out = glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--detector",
        "fdf,uio",
        "--runs",
        "20",
        "--fault",
        "current_sensor_bias:0.15",
    ]);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    let far = |kind: &str| -> f64 {
        let row = text
            .lines()
            .find(|l| l.starts_with(kind) && l.contains("current_sensor_bias ("))
            .unwrap_or_else(|| panic!("no {kind} row in\n{text}"));
        let tokens: Vec<&str> = row.split_whitespace().collect();
        tokens[tokens.len() - 2].parse().unwrap()
    };
    assert!(far("uio") < 5.0, "{text}");
    assert!(far("fdf") > 20.0, "{text}");
    assert!(
        text.lines()
            .any(|l| l.starts_with("uio") && l.contains("100.0%")),
        "{text}"
    );
}

/// The survey's DC motor comparison (Ahmad & Mohd-Mokhtar 2021, Figs 3-4, Table 1):
/// a speed-sensor ramp from 2.2 s and the actuator stuck at 0 V from 2.5 s to 3.5 s
/// (with u = 0.5, a bias of −0.5 that ends), through the GLR, the χ² test of the Kalman
/// innovation, the parity space and the optimal FDF, each at 10⁻⁴ per sample. The
/// optimal FDF is the Kalman filter (Table 1), so its row equals the χ² test's figure
/// for figure; every kind catches the stuck actuator; the GLR sees the incipient ramp
/// sooner than the one-sample tests (its window accumulates the drift).
#[test]
fn survey_dc_motor_kinds_side_by_side() {
    let cfg = config("examples/dc-motor-fdf.toml");
    let table = |fault: &str, onset: &str, end: Option<&str>| -> String {
        let mut args = vec![
            "evaluate",
            "--config",
            &cfg,
            "--detector",
            "glr,chi2,parity,fdf",
            "--runs",
            "40",
            "--samples",
            "500",
            "--fault",
            fault,
            "--onset",
            onset,
        ];
        if let Some(end) = end {
            args.extend(["--end", end]);
        }
        let out = glrmon(&args);
        ok(&out);
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let row = |text: &str, kind: &str| -> Vec<String> {
        text.lines()
            .find(|l| l.starts_with(&format!("{kind} ")) && l.contains('%'))
            .unwrap_or_else(|| panic!("no {kind} row in\n{text}"))
            .split_whitespace()
            .skip(1)
            .map(str::to_owned)
            .collect()
    };
    let ramp = table("speed_sensor_drift:0.001", "220", None);
    let stuck = table("actuator_bias:-0.5", "250", Some("350"));
    assert!(
        stuck.contains("fault injected at k = 250 until k = 350"),
        "{stuck}"
    );
    for text in [&ramp, &stuck] {
        let (chi2, fdf) = (row(text, "chi2"), row(text, "fdf"));
        // Everything but the isolation column (the FDF does not isolate).
        assert_eq!(chi2[..chi2.len() - 1], fdf[..fdf.len() - 1], "{text}");
    }
    for kind in ["glr", "chi2", "parity", "fdf"] {
        assert_eq!(row(&stuck, kind)[2], "100.0%", "{stuck}");
    }
    let median = |text: &str, kind: &str| -> u64 { row(text, kind)[3].parse().unwrap() };
    assert!(median(&ramp, "glr") < median(&ramp, "chi2"), "{ramp}");
}

/// `model.Fd`: a disturbance of any size on the speed sensor (the survey's F_d, with
/// E = 0) simulated into the outputs; the parity detector decouples it (order 2, the
/// smallest with M[H_o,s H_d,s] = 0 when the order is not given) and keeps its
/// false-alarm rate while detecting a current-sensor bias, where the FDF, which does
/// not decouple it, alarms all the time.
#[test]
fn the_parity_detector_decouples_an_output_disturbance() {
    let dir = TempDir::new("parity-fd");
    let cfg = dir.file("fd.toml");
    std::fs::write(
        &cfg,
        r#"
[[channels]]
name = "motor"
period = 0.01
[channels.model]
F = [[0.2231, 0.0109], [-0.0022, 0.5488]]
G = [[0.0047], [0.4512]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.0001
R = [[0.0025, 0.0], [0.0, 0.0012]]
E = [[0.0], [0.0]]
Fd = [[1.0], [0.0]]
[[channels.faults]]
name = "current_sensor_bias"
kind = "sensor_bias"
output = 1
[channels.glr]
detector = "parity"
[channels.simulation]
inputs = ["0.5"]
unknown_input = ["3*sin(0.02*k)"]
"#,
    )
    .unwrap();
    let out = glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--detector",
        "parity,fdf",
        "--runs",
        "20",
        "--fault",
        "current_sensor_bias:0.2",
    ]);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("parity space of order 2 (dimension 1, disturbance decoupled; the smallest order with one is 2)"),
        "{text}"
    );
    let far = |kind: &str| -> f64 {
        let row = text
            .lines()
            .find(|l| l.starts_with(kind) && l.contains("current_sensor_bias ("))
            .unwrap_or_else(|| panic!("no {kind} row in\n{text}"));
        let tokens: Vec<&str> = row.split_whitespace().collect();
        tokens[tokens.len() - 2].parse().unwrap()
    };
    assert!(far("parity") < 5.0, "{text}");
    assert!(far("fdf") > 20.0, "{text}");
}

/// Page's CUSUM, tuned for the injected magnitude, is the fastest at the same
/// false-alarm probability (the optimal sequential test for a known magnitude, which
/// the GLR pays for not knowing), and its Siegmund threshold keeps about the target
/// 1 false alarm per 10⁴ samples; the χ² test of one sample misses most of a small
/// sensor bias the two accumulating tests catch.
#[test]
fn evaluate_shows_the_cusum_fastest_for_its_known_magnitude() {
    let cfg = config("examples/dc-motor-cusum.toml");
    let out = glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--detector",
        "glr,chi2,cusum",
        "--runs",
        "100",
        "--fault",
        "speed_sensor_bias:0.1",
    ]);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    let row = |kind: &str| -> Vec<String> {
        text.lines()
            .find(|l| l.starts_with(&format!("{kind} ")) && l.contains('%'))
            .unwrap_or_else(|| panic!("no {kind} row in\n{text}"))
            .split_whitespace()
            .skip(1)
            .map(str::to_owned)
            .collect()
    };
    let detected = |kind: &str| -> f64 { row(kind)[2].trim_end_matches('%').parse().unwrap() };
    let median = |kind: &str| -> u64 { row(kind)[3].parse().unwrap() };
    let far = |kind: &str| -> f64 {
        let r = row(kind);
        r[r.len() - 2].parse().unwrap()
    };
    assert_eq!(detected("cusum"), 100.0, "{text}");
    assert_eq!(detected("glr"), 100.0, "{text}");
    assert!(detected("chi2") < 60.0, "{text}");
    assert!(median("cusum") < median("glr"), "{text}");
    assert!((0.2..=3.0).contains(&far("cusum")), "{text}");
}

/// The kernel kind through the binary: `simulate` injects a candidate fault function
/// of the state through E, `replay` alarms and isolates it by exclusion, `evaluate`
/// runs it over seeds (Li, Boem, Pin & Parisini's example at a fiftieth of its noise).
#[test]
fn kernel_candidates_simulate_replay_and_evaluate() {
    let dir = TempDir::new("kernel");
    let cfg = config("examples/kernel-paper-low-noise.toml");
    let csv = dir.file("phi2.csv");
    let jsonl = dir.file("phi2.jsonl");
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "12000",
        "--fault",
        "phi2:1",
        "--onset",
        "5000",
        "--output",
        &csv,
    ]));
    let out = glrmon(&["replay", "--config", &cfg, &csv, "--output", &jsonl]);
    let text = ok(&out) + &String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("1 alarm, 0 errors"), "{text}");
    assert!(text.contains("isolated=[phi2] excluded=[phi1]"), "{text}");
    let records = std::fs::read_to_string(&jsonl).unwrap();
    let alarm = records
        .lines()
        .find(|l| l.contains("\"type\":\"alarm\""))
        .expect("an alarm record");
    let k: u64 = alarm
        .split("\"k\":")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    assert!((5000..6500).contains(&k), "alarm at {k}");
    // No fault injected: no alarm.
    ok(&glrmon(&[
        "simulate",
        "--config",
        &cfg,
        "--samples",
        "8000",
        "--output",
        &csv,
    ]));
    let out = glrmon(&["replay", "--config", &cfg, &csv, "--output", &jsonl]);
    let text = ok(&out) + &String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("0 alarms, 0 errors"), "{text}");
    let out = ok(&glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--fault",
        "phi2:1",
        "--runs",
        "4",
        "--onset",
        "5000",
        "--samples",
        "12000",
    ]));
    assert!(
        out.contains("phi2 (1.000)                100.0%      4"),
        "{out}"
    );
    let row = out
        .lines()
        .rfind(|l| l.starts_with("phi2 "))
        .expect("the isolation row of phi2");
    let counts: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(counts[1..3], ["0", "4"], "{out}");
    assert!(!out.contains("minmax isolation"), "{out}");
    // Side by side with the GLR on the sampled model, whose dictionary is E's columns.
    let out = ok(&glrmon(&[
        "evaluate",
        "--config",
        &cfg,
        "--detector",
        "kernel,glr",
        "--fault",
        "phi2:1",
        "--runs",
        "4",
        "--onset",
        "5000",
        "--samples",
        "12000",
    ]));
    let row = |kind: &str| {
        out.lines()
            .find(|l| l.starts_with(kind) && l.contains("phi2 (1.000)"))
            .unwrap_or_else(|| panic!("no {kind} row: {out}"))
            .split_whitespace()
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let (kernel, glr) = (row("kernel "), row("glr "));
    assert_eq!(
        (kernel[3].as_str(), glr[3].as_str()),
        ("100.0%", "100.0%"),
        "{out}"
    );
    assert_eq!(kernel.last().map(String::as_str), Some("100.0%"), "{out}");
    let delay = |r: &[String]| r[4].parse::<u64>().unwrap();
    assert!(delay(&glr) < delay(&kernel), "{out}");
}
