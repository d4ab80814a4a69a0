//! Sparse fault diagnosis (Zhang 2021) end to end: `glrmon simulate` and
//! `glrmon diagnose` on the paper's Example 1 (config/examples/paper2021-example1.toml),
//! and its Table I rates for every q through the library (the code of the `table1` example).

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

/// On fault-free Example 1 data `glrmon diagnose` says "no fault": an
/// empty support and estimate in the record, and the text names the χ² test. (The
/// paper's rule alone always selected some of the 50 faults.)
#[test]
fn diagnose_on_fault_free_data_reports_no_fault() {
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

/// glrmon's own exact-support rates (%) on Example 1 with the shipped configuration
/// (plateau in λ), q = 5…25, 1000 trials per q with the seeds
/// [`table_1_exact_support_rate_every_q`] draws its first trials from:
/// `cargo run -p glrmon-cli --example table1 -- --trials 1000` (seed 2021).
const GLRMON_1000: [f64; 21] = [
    99.8, 99.3, 97.9, 94.7, 92.2, 83.0, 79.5, 71.1, 63.7, 54.6, 48.5, 42.1, 36.4, 29.8, 27.8, 21.8,
    20.3, 12.3, 14.0, 10.0, 10.1,
];

/// Zhang 2021, Table I for every q = 5…25 (1000 trials each in the paper), 300 seeded
/// trials per q through the library (the code of the `table1` example; ~40 s in a
/// test build). s.e. is the standard error of the difference between our rate and the
/// paper's if both had the paper's rate p: √(p(1 − p)(1/300 + 1/1000))
/// ([`table1::difference_se`]).
///
/// - q = 5, 6, 7: the measured rate is within ±3 s.e. of the paper's.
/// - q ≥ 8: glrmon is above the paper, increasingly with q (1000 trials: 94.7 vs 90.0 %
///   at q = 8, 92.2 vs 81.7 % at q = 9, 48.5 vs 29.5 % at q = 15, 10.1 vs 2.2 % at
///   q = 25; 3.5 s.e. and more of the 1000-trial difference), so we assert at least
///   the paper's rate − 3 s.e., and, so that a change of glrmon's could still fail,
///   within ±3 standard errors of glrmon's own 1000-trial rate ([`GLRMON_1000`];
///   s.e. with 1/300 + 1/1000 as above, conservative since our 300 trials are the
///   first 300 of those 1000).
///
/// Why glrmon is above the paper was looked for, not found. Not the λ rule: measuring
/// the plateau in ln λ instead of λ changes the 1000-trial rates by at most 6 points
/// (q = 9: 90.8 against 92.2 %; q = 15: 48.3 against 48.5 %), and the path holds the
/// exact support at some λ in only a few more trials (q = 9: 95.6 %; q = 15: 60.8 %):
/// no reading of "the middle of the range" can come down to 81.7 % or 29.5 % from
/// above while staying a plateau rule. Not the least-squares
/// refit: it runs on the support the Lasso chose and changes only the magnitudes. What
/// the paper does not state and may differ: its Lasso solver and λ grid ("numerically
/// exploring different values of λ"; e.g. MATLAB's `lasso` standardises the columns
/// and fits an intercept by default), and how Φ_k's entries are drawn beyond "uniform
/// within [−17.3, 17.3]" (we draw them afresh at every k).
#[test]
fn table_1_exact_support_rate_every_q() {
    let channel = table1::example1_channel(
        &table1::example1_path(),
        glrmon_spec::ResidualKind::Kitanidis,
    )
    .unwrap();
    let trials = 300u64;
    let start = std::time::Instant::now();
    let mut failures = Vec::new();
    for (i, &(q, paper)) in table1::PAPER.iter().enumerate() {
        let mut ok = 0;
        for t in 0..trials {
            let trial = table1::trial(&channel, q, table1::trial_seed(2021, q, t), false).unwrap();
            ok += u64::from(trial.exact());
        }
        let rate = ok as f64 / trials as f64;
        let p = paper / 100.0;
        let se = table1::difference_se(p, trials);
        let own = GLRMON_1000[i] / 100.0;
        let own_se = (own * (1.0 - own) * (1.0 / trials as f64 + 1.0 / 1000.0)).sqrt();
        let (lo, hi) = table1::wilson(ok, trials);
        let verdict = if q <= 7 {
            (rate - p).abs() <= 3.0 * se
        } else {
            rate >= p - 3.0 * se && (rate - own).abs() <= 3.0 * own_se
        };
        println!(
            "Table I, q = {q:2}: {ok:3}/{trials} = {:5.1} % (95 % CI [{:5.1}, {:5.1}]), paper \
             {paper:4.1} % ± 3 s.e. = ±{:.1}, (rate − paper)/s.e. = {:+.1}{}",
            100.0 * rate,
            100.0 * lo,
            100.0 * hi,
            300.0 * se,
            (rate - p) / se,
            if verdict { "" } else { "  <- FAILS" }
        );
        if !verdict {
            failures.push(q);
        }
    }
    println!("Table I: {:.1} s", start.elapsed().as_secs_f64());
    assert!(
        failures.is_empty(),
        "Table I out of band at q = {failures:?}"
    );
}

/// Zhang 2021, Table II: q = 5 faults, sensor noise R = r·I₂ (in the simulation and in
/// the filter), N = 100, 300 seeded trials per r through the library (the code of the
/// `table1` example with `--noise`; the paper: 1000 trials per r).
///
/// - The simulation is the paper's: the average per-sensor SNR (sample variances of
///   H X_k and of v_k) is within 1 dB of the paper's column at every r.
/// - With the plateau measured in λ (`plateau_scale = "linear"`, which the shipped
///   configuration sets) the rate is at least the paper's − 3 s.e. (s.e. as in
///   [`table_1_exact_support_rate_every_q`]). 1000 trials per r = 0.5, 10, …, 200 with
///   `table1 --trials 1000 --noise …`: within ±2.2 s.e. of the paper at every r but
///   r = 190 (58.8 % vs 63.9 %; docs/REPRODUCTION.md).
/// - With glrmon's default, the plateau measured in ln λ, the rate at r = 100 is far
///   below the paper's (1000 trials: 50.8 % vs 78.6 %): the log scale prefers the
///   small-λ runs, and under strong noise those carry spurious faults. This is the
///   gap first measured with `simulate` + `diagnose` (53.3 % at r = 100).
#[test]
fn table_2_exact_support_rate_with_sensor_noise() {
    let path = table1::example1_path();
    let trials = 300u64;
    let q = 5;
    let mut failures = Vec::new();
    for r in [10.0, 50.0, 100.0, 200.0] {
        let &(_, snr1, snr2, paper) = table1::PAPER_TABLE2.iter().find(|row| row.0 == r).unwrap();
        let channel =
            table1::example1_channel_with_noise(&path, glrmon_spec::ResidualKind::Kitanidis, r)
                .unwrap();
        assert_eq!(
            channel.diagnosis.lasso.plateau_scale,
            glrmon_core::sparse::PlateauScale::Linear,
            "the shipped Example 1 configuration measures the plateau in λ"
        );
        let mut log_channel = channel.clone();
        log_channel.diagnosis.lasso.plateau_scale = glrmon_core::sparse::PlateauScale::Log;
        let (mut ok, mut ok_log, mut snr) = (0u64, 0u64, [0.0; 2]);
        for t in 0..trials {
            let seed = table1::trial_seed(2021 ^ r.to_bits(), q, t);
            let trial = table1::trial(&channel, q, seed, false).unwrap();
            ok += u64::from(trial.exact());
            snr[0] += trial.snr_db[0] / trials as f64;
            snr[1] += trial.snr_db[1] / trials as f64;
            if r == 100.0 {
                ok_log += u64::from(table1::trial(&log_channel, q, seed, false).unwrap().exact());
            }
        }
        let p = paper / 100.0;
        let se = table1::difference_se(p, trials);
        let rate = ok as f64 / trials as f64;
        println!(
            "Table II, r = {r:3}: SNR {:5.2} / {:5.2} dB (paper {snr1:5.2} / {snr2:5.2}), \
             {ok}/{trials} = {:5.1} % (paper {paper:4.1} %, (rate − paper)/s.e. = {:+.1})",
            snr[0],
            snr[1],
            100.0 * rate,
            (rate - p) / se
        );
        if (snr[0] - snr1).abs() > 1.0 || (snr[1] - snr2).abs() > 1.0 {
            failures.push(format!("r = {r}: SNR {snr:?} vs ({snr1}, {snr2})"));
        }
        if rate < p - 3.0 * se {
            failures.push(format!(
                "r = {r}: {:.1} % below the paper's {paper} % − 3 s.e.",
                100.0 * rate
            ));
        }
        if r == 100.0 {
            let log_rate = ok_log as f64 / trials as f64;
            println!(
                "  log-λ plateau at r = 100: {ok_log}/{trials} = {:5.1} %",
                100.0 * log_rate
            );
            if log_rate >= p - 3.0 * se {
                failures.push(format!(
                    "r = 100: the log-λ plateau reaches {:.1} %, expected well below the paper",
                    100.0 * log_rate
                ));
            }
        }
    }
    assert!(failures.is_empty(), "Table II: {failures:#?}");
}

#[allow(dead_code)]
#[path = "../crates/glrmon-cli/examples/example2.rs"]
mod example2;

/// Zhang 2021, Example 2 (Figs 6-7) on the stand-in pipe of
/// config/examples/paper2021-example2.toml: leaks 10 and 15 of magnitude 1e-4 among 30
/// delayed-input candidates, N = 500, Kalman innovations.
///
/// - One run through the real binary (`simulate`, then `diagnose --json`, seed 1): the
///   support is exactly the two leaks, on a plateau of 2 faults, and their least-squares
///   magnitudes are within 5 % of 1e-4 (seen: 1.017e-4, 0.977e-4).
/// - 60 seeded runs through the library: the two leaks exactly in at least 75 % of runs
///   at 1e-4 (200 runs: 89.0 %), and in at most 25 % at 2e-5, 13.6 dB below the sensor
///   noise (200 runs: 6.5 %): isolation is lost as the leaks sink into the noise.
#[test]
fn example_2_isolates_two_leaks_among_thirty_delayed_inputs() {
    let dir = std::env::temp_dir().join(format!("glrmon-example2-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("example2.csv");
    let config = example2::example2_path();
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--samples", "500", "--seed", "1"])
            .args(["--fault", "leak10:1e-4,leak15:1e-4", "--output"])
            .arg(&csv),
    );
    let json = run_ok(
        glrmon()
            .args(["diagnose", "--json", "--config"])
            .arg(&config)
            .arg(&csv),
    );
    let glrmon_wire::Record::Diagnosis(d) =
        glrmon_wire::decode_record(json.trim().as_bytes()).unwrap()
    else {
        panic!("not a diagnosis: {json}");
    };
    assert_eq!(d.support, ["leak10", "leak15"], "{json}");
    for leak in ["leak10", "leak15"] {
        let v = d.estimate[leak];
        assert!((v / 1e-4 - 1.0).abs() < 0.05, "{leak}: θ̂ = {v:e}");
    }
    let chosen = d.path_lambda.iter().position(|&l| l == d.lambda).unwrap();
    assert_eq!(d.path_support_sizes[chosen], 2);
    std::fs::remove_dir_all(&dir).unwrap();

    let cfg = glrmon_spec::load(&config).unwrap();
    let channel = &cfg.channels[0];
    let want: Vec<usize> = example2::LEAKS.iter().map(|l| l - 1).collect();
    let rate = |theta: f64| {
        let runs = 60u64;
        let exact = (1..=runs)
            .filter(|&seed| {
                let (d, _) = example2::run(channel, theta, seed).unwrap();
                d.detail.support == want
            })
            .count();
        exact as f64 / runs as f64
    };
    let (strong, weak) = (rate(1e-4), rate(2e-5));
    println!("Example 2: exact isolation {strong:.3} at 1e-4, {weak:.3} at 2e-5 (60 runs each)");
    assert!(strong >= 0.75, "{strong}");
    assert!(weak <= 0.25, "{weak}");
}
