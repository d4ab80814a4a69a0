//! `glrmon identify --model CONFIG` end to end with the real binary: the noise
//! covariances of a user's own LTI model (2 states, 1 input, 2 outputs, full Q and R)
//! from 20 000 fault-free samples simulated with the true Q, R, starting from a
//! configuration whose Q is 10× and R 0.1× the truth.
//!
//! Tolerances: the ALS tests of glrmon-ident (crates/glrmon-ident/tests/noise.rs,
//! `full_q_and_r_of_a_two_state_system_with_an_input`, same plant) assert relative
//! Frobenius errors below 0.08 (Q) and 0.10 (R) at 40 000 samples; with half the data
//! the errors grow by about √2, so 0.12 and 0.15 here.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::DMatrix;

fn glrmon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = glrmon(args);
    assert!(
        out.status.success(),
        "{args:?}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("glrmon-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const Q_TRUE: [f64; 4] = [0.5, 0.15, 0.15, 0.3];
const R_TRUE: [f64; 4] = [0.4, 0.1, 0.1, 0.3];

/// The plant with noise `q`, `r` (TOML rows) and an optional `[channels.scaling]`.
fn plant(q: &str, r: &str, scaling: &str) -> String {
    format!(
        r#"# Two states, one input, two outputs.
[[channels]]
name = "plant"

[channels.model]
F = [[0.8, 0.2], [-0.1, 0.7]]
G = [[1.0], [0.5]]
H = [[1.0, 0.0], [0.3, 1.0]]
J = [[0.1], [0.0]]
Q = {q} # a guess
R = {r}

[[channels.faults]]
name = "y0_bias"
kind = "sensor_bias"
output = 0

[channels.simulation]
inputs = ["sin(0.05*k)"]
{scaling}"#
    )
}

fn true_plant(scaling: &str) -> String {
    plant(
        "[[0.5, 0.15], [0.15, 0.3]]",
        "[[0.4, 0.1], [0.1, 0.3]]",
        scaling,
    )
}

/// Q ×10, R ×0.1.
fn wrong_plant(scaling: &str) -> String {
    plant(
        "[[5.0, 1.5], [1.5, 3.0]]",
        "[[0.04, 0.01], [0.01, 0.03]]",
        scaling,
    )
}

fn rel(estimate: &DMatrix<f64>, truth: &[f64; 4]) -> f64 {
    let truth = DMatrix::from_row_slice(2, 2, truth);
    (estimate - &truth).norm() / truth.norm()
}

/// Simulates the true plant, runs `identify --model` on the wrong one, and checks the
/// written Q, R and the printed NIS; returns the printed report.
fn recovers(name: &str, scaling: &str) -> String {
    let dir = dir(name);
    let truth = dir.join("true.toml");
    let wrong = dir.join("wrong.toml");
    let fixed = dir.join("fixed.toml");
    let data = dir.join("data.csv");
    std::fs::write(&truth, true_plant(scaling)).unwrap();
    std::fs::write(&wrong, wrong_plant(scaling)).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    ok(&[
        "simulate",
        "--config",
        &s(&truth),
        "--channel",
        "plant",
        "--samples",
        "20000",
        "--seed",
        "3",
        "--output",
        &s(&data),
    ]);
    let said = ok(&[
        "identify",
        "--model",
        &s(&wrong),
        &s(&data),
        "--output",
        &s(&fixed),
        "--force",
    ]);
    eprintln!("{said}");
    let written = std::fs::read_to_string(&fixed).unwrap();
    // The rest of the user's file is kept; the old Q's comment goes with it.
    assert!(written.starts_with("# Two states, one input, two outputs.\n"));
    assert!(written.contains("# Noise covariances Q, R from `glrmon identify --model"));
    assert!(!written.contains("a guess"), "{written}");
    let cfg = glrmon_spec::parse(&written).unwrap();
    let [f, .., q, r] = cfg.channels[0].model.matrices();
    assert_eq!(f.base()[(0, 1)], 0.2);
    let (eq, er) = (rel(q.base(), &Q_TRUE), rel(r.base(), &R_TRUE));
    eprintln!("relative errors: Q {eq:.4}, R {er:.4}");
    assert!(eq < 0.12, "Q error {eq}: {}", q.base());
    assert!(er < 0.15, "R error {er}: {}", r.base());
    assert_eq!(q.base()[(0, 1)], q.base()[(1, 0)]);
    assert!(cfg.channels[0].cross_covariance.is_none());
    // NIS within 4σ of p = 2, σ = sqrt(2p / N).
    let line = said
        .lines()
        .find(|l| l.starts_with("mean NIS on the data "))
        .unwrap_or_else(|| panic!("{said}"));
    let nis: f64 = line["mean NIS on the data ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let sigma = (4.0_f64 / 20_000.0).sqrt();
    assert!((nis - 2.0).abs() < 4.0 * sigma, "NIS {nis}");
    assert!(
        said.contains("design matrix: rank 6 for 6 parameters"),
        "{said}"
    );
    assert!(
        said.contains(&format!(
            "glrmon calibrate --config {} --channel plant OTHER-DAYS.csv --mtbfa 10000 --write",
            s(&fixed),
        )),
        "{said}"
    );
    std::fs::remove_dir_all(&dir).ok();
    said
}

#[test]
fn the_noise_of_a_users_model_is_recovered_from_fault_free_data() {
    let said = recovers("identify-model", "");
    assert!(said.contains("no scaling"), "{said}");
}

/// The same plant in raw units: outputs recorded as 100 + 10·y, the input as 2 + u.
/// The simulator writes raw units, and the estimation must go back to model units.
#[test]
fn the_channels_scaling_is_applied_before_the_estimation() {
    let said = recovers(
        "identify-model-scaled",
        "\n[channels.scaling]\nu_offset = [2.0]\ny_offset = [100.0, -50.0]\ny_scale = [10.0, 10.0]\n",
    );
    assert!(said.contains("the channel's scaling applied"), "{said}");
}

#[test]
fn an_unidentifiable_structure_and_an_lpv_model_exit_1_naming_why() {
    let dir = dir("identify-model-refused");
    let truth = dir.join("true.toml");
    let data = dir.join("data.csv");
    std::fs::write(&truth, true_plant("")).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    ok(&[
        "simulate",
        "--config",
        &s(&truth),
        "--samples",
        "3000",
        "--seed",
        "4",
        "--output",
        &s(&data),
    ]);
    let out_file = s(&dir.join("out.toml"));

    // A free S with a full Q: never identifiable.
    let out = glrmon(&[
        "identify",
        "--model",
        &s(&truth),
        &s(&data),
        "--output",
        &out_file,
        "--cross-covariance",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    eprintln!("{err}");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("not identifiable"), "{err}");
    assert!(err.contains("for 10 free parameters"), "{err}");
    assert!(err.contains("\"S[0,0]\""), "{err}");
    assert!(err.contains("hint: leave out --cross-covariance"), "{err}");
    assert!(!Path::new(&out_file).exists());

    // An LPV model.
    let lpv = dir.join("lpv.toml");
    std::fs::write(
        &lpv,
        true_plant("")
            .replace(
                "F = [[0.8, 0.2], [-0.1, 0.7]]",
                "F = { base = [[0.8, 0.2], [-0.1, 0.7]], p0 = [[0.05, 0.0], [0.0, -0.05]] }",
            )
            .replace("name = \"plant\"\n", "name = \"plant\"\nsignals = 1\n")
            + "signals = [\"sin(0.01*k)\"]\n",
    )
    .unwrap();
    let out = glrmon(&[
        "identify",
        "--model",
        &s(&lpv),
        &s(&data),
        "--output",
        &out_file,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    eprintln!("{err}");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("model.F has scheduling terms (p0)"), "{err}");
    assert!(err.contains("LPV"), "{err}");

    // Usage: the subspace flags do not go with --model; --channel is needed without it.
    let out = glrmon(&[
        "identify",
        "--model",
        &s(&truth),
        "--order",
        "2",
        &s(&data),
        "--output",
        &out_file,
    ]);
    assert_eq!(out.status.code(), Some(2));
    let out = glrmon(&["identify", &s(&data), "--output", &out_file]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--channel"));
    std::fs::remove_dir_all(&dir).ok();
}
