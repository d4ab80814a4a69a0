//! A plant export whose time column is ISO 8601 text (`timestamp`, `time`, `Time`,
//! `datetime`) replays with `t` in seconds since the Unix epoch, with the real binary:
//! the records' `t` are the file's times, the alarm is the one of the same file with
//! numeric times, and a malformed time is a bad row naming its row and column, counted
//! like a bad number.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};

use support::{Scratch, glrmon, run_ok};

/// 2026-11-27T08:00:00Z in seconds since the Unix epoch.
const T0: f64 = 1_795_766_400.0;

/// The DC motor of config/examples/dc-motor.toml (period 0.01 s) with its columns
/// named as a plant names them.
fn config(dir: &Path) -> PathBuf {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let text = std::fs::read_to_string(example).unwrap().replace(
        "[channels.glr]",
        "[channels.columns]\nu = [\"V101\"]\ny = [\"SI201\", \"II202\"]\n\n[channels.glr]",
    );
    let path = dir.join("motor.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `t` (k·0.01 s) as an ISO 8601 time after [`T0`], in the form `form` picks.
fn iso(k: u64, form: usize) -> String {
    let cs = k; // centiseconds
    let (m, s, c) = (cs / 6000, cs / 100 % 60, cs % 100);
    match form {
        0 => format!("2026-11-27T08:{m:02}:{s:02}.{c:02}Z"),
        // The same instant one hour east, and naive (taken as UTC).
        1 => format!("2026-11-27T09:{m:02}:{s:02}.{c:02}+01:00"),
        _ => format!("2026-11-27 08:{m:02}:{s:02}.{c:02}"),
    }
}

/// The lines of a JSON Lines output of `type`.
fn records<'a>(out: &'a str, kind: &str) -> Vec<&'a str> {
    let tag = format!("\"type\":\"{kind}\"");
    out.lines().filter(|l| l.contains(&tag)).collect()
}

/// A number field of a record line.
fn number(line: &str, field: &str) -> Option<f64> {
    let at = line.find(&format!("\"{field}\":"))? + field.len() + 3;
    let rest = &line[at..];
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// Replays `csv`; (stderr, records).
fn replay(config: &Path, csv: &Path) -> (String, String) {
    let out = csv.with_extension("jsonl");
    let done = run_ok(
        glrmon()
            .arg("replay")
            .arg("--config")
            .arg(config)
            .arg(csv)
            .arg("--output")
            .arg(&out),
    );
    (
        String::from_utf8_lossy(&done.stderr).into_owned(),
        std::fs::read_to_string(out).unwrap(),
    )
}

#[test]
fn an_iso_time_column_replays_with_t_in_epoch_seconds() {
    let scratch = Scratch::new("csv-times");
    let config = config(&scratch.0);
    let numeric = scratch.0.join("numeric.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--samples", "400", "--seed", "7"])
            .args(["--fault", "actuator_bias:0.5", "--onset", "200", "--output"])
            .arg(&numeric),
    );
    let text = std::fs::read_to_string(&numeric).unwrap();
    assert!(text.starts_with("k,t,V101,SI201,II202\n"), "{text:.80}");
    let (_, want) = replay(&config, &numeric);
    let want_alarms = records(&want, "alarm");
    assert_eq!(want_alarms.len(), 1, "{want_alarms:#?}");

    for (form, name) in ["timestamp", "Time", "datetime"].into_iter().enumerate() {
        // The export: its own time column, no k, columns in another order.
        let mut export = format!("{name},II202,SI201,V101\n");
        for (k, line) in text.lines().skip(1).enumerate() {
            let f: Vec<&str> = line.split(',').collect();
            export.push_str(&format!(
                "{},{},{},{}\n",
                iso(k as u64, form),
                f[4],
                f[3],
                f[2]
            ));
        }
        let csv = scratch.0.join(format!("{name}.csv"));
        std::fs::write(&csv, export).unwrap();
        let (stderr, got) = replay(&config, &csv);
        assert!(
            stderr.contains("400 samples, 1 alarm, 0 errors"),
            "{stderr}"
        );
        let stats = records(&got, "stat");
        assert_eq!(stats.len(), 400);
        for (k, stat) in stats.iter().enumerate() {
            let t = number(stat, "t").unwrap_or_else(|| panic!("no t: {stat}"));
            assert!((t - (T0 + k as f64 * 0.01)).abs() < 1e-5, "{name}: {stat}");
        }
        let alarms = records(&got, "alarm");
        assert_eq!(alarms.len(), 1, "{name}: {alarms:#?}");
        let k = number(alarms[0], "k").unwrap();
        assert_eq!(Some(k), number(want_alarms[0], "k"), "the same alarm");
        let t = number(alarms[0], "t").unwrap();
        assert!((t - (T0 + k * 0.01)).abs() < 1e-5, "{}", alarms[0]);
    }
}

#[test]
fn a_malformed_time_is_a_bad_row_naming_row_and_column() {
    let scratch = Scratch::new("csv-bad-time");
    let config = config(&scratch.0);
    let mut csv_text = String::from("timestamp,V101,SI201,II202\n");
    for k in 0..50 {
        let time = match k {
            20 => "2026-11-27T08:00:00.20Zjunk".to_owned(),
            30 => "27/11/2026 08:00:00.30".to_owned(),
            _ => iso(k, 0),
        };
        csv_text.push_str(&format!("{time},1.0,0.0,0.0\n"));
    }
    let csv = scratch.0.join("bad.csv");
    std::fs::write(&csv, csv_text).unwrap();
    let (stderr, got) = replay(&config, &csv);
    assert!(
        stderr.contains("50 rows, 48 samples") && stderr.contains("2 errors"),
        "{stderr}"
    );
    let errors = records(&got, "error");
    assert_eq!(errors.len(), 2, "{errors:#?}");
    assert!(
        errors[0].contains(
            r#"row 22: column timestamp: \"2026-11-27T08:00:00.20Zjunk\" is neither seconds nor an ISO 8601 time"#
        ) && errors[0].contains(r#""code":"wrong_type""#),
        "{}",
        errors[0]
    );
    assert!(
        errors[1].contains(r#"row 32: column timestamp: \"27/11/2026 08:00:00.30\""#),
        "{}",
        errors[1]
    );
}
