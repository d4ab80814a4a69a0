//! `glrmon validate` of the real binary on the regression corpus of hostile
//! configurations, `tests/data/hostile-configs/`. Every invalid configuration exits 1
//! (never 3, never a panic's 101) with the channel and the field in the message; the
//! largest window validates within seconds.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/hostile-configs")
        .join(name)
}

/// (file, text the error must contain).
const INVALID: [(&str, &str); 12] = [
    (
        "h-empty.toml",
        r#"channels[0] "plant": model.H has no rows"#,
    ),
    (
        "f-empty-row.toml",
        r#"channels[0] "plant": model.F has an empty row 0"#,
    ),
    (
        "h-ragged.toml",
        r#"channels[0] "plant": model.H: row 1 has 1 entries"#,
    ),
    (
        "p0-empty.toml",
        r#"channels[0] "plant": model.P0 has no rows"#,
    ),
    (
        "window-2p63.toml",
        r#"channels[0] "plant": glr.window: w = 9223372036854775807 is more than 100000"#,
    ),
    (
        "window-1e9.toml",
        r#"channels[0] "plant": glr.window: w = 1000000000 is more than 100000"#,
    ),
    (
        "history-1e12.toml",
        r#"channels[0] "plant": diagnosis.history: 1000000000000 samples is more than 1000000"#,
    ),
    (
        "key-glrmon.toml",
        r#"channels[0] "plant": key: "glrmon/**" intersects glrmon's own key space"#,
    ),
    ("instance-empty.toml", "daemon.instance is empty"),
    (
        "instance-wildcard.toml",
        r#"daemon.instance: "a/b/**" contains '/'"#,
    ),
    (
        "unstable-f.toml",
        r#"channels[0] "plant": model.F: unstable (spectral radius 3.0000 ≥ 1) and the Kalman filter diverges on it: innovation covariance Σ_k is not positive definite at k = "#,
    ),
    (
        "expression-div0.toml",
        r#"channels[0] "plant": faults[1]: the fault signature is not finite"#,
    ),
];

#[test]
fn invalid_configurations_exit_1_naming_channel_and_field() {
    for (file, expected) in INVALID {
        let out = Command::new(env!("CARGO_BIN_EXE_glrmon"))
            .args(["validate", "--config"])
            .arg(corpus(file))
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{file}: {stdout}\n{stderr}");
        assert!(
            stdout.contains(expected),
            "{file}: wanted «{expected}» in\n{stdout}"
        );
        assert!(!stderr.contains("panicked"), "{file}: {stderr}");
    }
}

/// `window = 1e5` took 2 minutes to validate: the isolability report is bounded by a
/// work budget, beyond which it is skipped (the filter is still checked).
#[test]
fn the_largest_window_validates_within_seconds() {
    let t = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(["validate", "--config"])
        .arg(corpus("window-1e5-valid.toml"))
        .output()
        .unwrap();
    let elapsed = t.elapsed();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(stdout.contains("isolability: not computed"), "{stdout}");
    assert!(elapsed < Duration::from_secs(10), "{elapsed:?}");
}
