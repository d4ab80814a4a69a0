//! `glrmon replay --config X data.csv --report out.html`, end to end with the real
//! binary: the report opens with where it comes from (this glrmon, the configuration,
//! the data file, when, in UTC) and speaks of the channel's signals by name and unit.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A tank whose level sensor LI201 (cm) and outflow FI301 (m³/h) are read in scaled
/// model units, fed by FIC101 (m³/h).
const TANKS: &str = r#"
[[channels]]
name = "tanks"
[channels.model]
F = [[0.9, 0.0], [0.0, 0.5]]
G = [[0.1], [1.0]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.01
R = 0.01
[channels.scaling]
y_offset = [120.0, 4.0]
y_scale = [0.5, 0.1]
[channels.columns]
u = ["FIC101"]
y = ["LI201", "FI301"]
u_units = ["m³/h"]
y_units = ["cm", "m³/h"]
[channels.simulation]
inputs = ["normal(0, 1)"]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 40
"#;

/// A scratch directory, removed at the end.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("glrmon-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn glrmon(dir: &Path, args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "glrmon {args:?}: {stderr}");
    stderr
}

#[test]
fn the_report_says_where_it_comes_from_and_names_signals_in_their_units() {
    let scratch = Scratch::new("report-labels");
    let dir = &scratch.0;
    std::fs::write(dir.join("tanks.toml"), TANKS).unwrap();
    glrmon(
        dir,
        &[
            "simulate",
            "--config",
            "tanks.toml",
            "--samples",
            "900",
            "--seed",
            "3",
            "--fault",
            "LI201_bias:1.32",
            "--onset",
            "300",
            "--output",
            "fault.csv",
        ],
    );
    let before = jiff::Timestamp::now();
    let stderr = glrmon(
        dir,
        &[
            "replay",
            "--config",
            "tanks.toml",
            "fault.csv",
            "--report",
            "fault.html",
            "--quiet",
        ],
    );
    let after = jiff::Timestamp::now();
    assert!(stderr.contains("1 alarm"), "{stderr}");
    let html = std::fs::read_to_string(dir.join("fault.html")).unwrap();

    // Provenance: this glrmon, the configuration and data paths as given, the time the
    // report was made (UTC, ISO 8601, to the second, between the command's start and end).
    let line = html
        .split("<p class=\"provenance\">")
        .nth(1)
        .and_then(|s| s.split("</p>").next())
        .expect("a provenance line");
    let version = env!("CARGO_PKG_VERSION");
    assert!(
        line.starts_with(&format!("Made by glrmon {version} (git ")),
        "{line}"
    );
    assert!(
        line.contains(
            "from configuration <code>tanks.toml</code> and data <code>fault.csv</code>, at "
        ),
        "{line}"
    );
    let made = line
        .split(", at ")
        .nth(1)
        .and_then(|s| s.strip_suffix(" (UTC)."))
        .expect("a time");
    let made: jiff::Timestamp = made.parse().unwrap_or_else(|e| panic!("{made}: {e}"));
    assert!(
        before.as_second() <= made.as_second() && made <= after,
        "{made} not in {before} … {after}"
    );

    // Signals by name and unit, θ̂ by unit, the episode's θ̂ drawn.
    assert!(!html.contains("ε_k["), "no output indices");
    for want in [
        "Kalman innovation ε_k [cm]: LI201",
        "Kalman innovation ε_k [m³/h]: FI301",
        "Magnitude estimate θ̂ [cm]: LI201_bias",
        "Magnitude estimate θ̂ [m³/h]: FI301_bias, FIC101_bias",
        "class=\"episode-magnitude\"",
    ] {
        assert!(html.contains(want), "{want} missing");
    }
}
