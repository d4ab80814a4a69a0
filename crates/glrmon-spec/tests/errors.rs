//! One broken configuration per error kind: each fails with the expected path and reason.

mod common;
use common::{BASE, with};

fn errors(text: &str) -> Vec<String> {
    match glrmon_spec::parse(text) {
        Ok(_) => panic!("expected errors for:\n{text}"),
        Err(e) => e.errors.iter().map(ToString::to_string).collect(),
    }
}

fn assert_error(text: &str, expected: &str) {
    let errs = errors(text);
    assert!(
        errs.iter().any(|e| e.contains(expected)),
        "wanted «{expected}» in {errs:#?}"
    );
}

#[test]
fn the_base_fixture_is_valid() {
    let cfg = glrmon_spec::parse(BASE).unwrap();
    assert_eq!(cfg.channels[0].fault_names, ["bias", "custom"]);
    assert!(cfg.warnings.is_empty(), "{:?}", cfg.warnings);
}

#[test]
fn unknown_key_is_an_error() {
    assert_error(
        &with("name = \"pump3\"", "name = \"pump3\"\ncolour = 3"),
        "unknown field `colour`",
    );
    assert_error(
        &with("window = 50", "window = 50\nwindwo = 3"),
        "unknown field `windwo`",
    );
}

#[test]
fn f_not_square_names_h_columns() {
    let text = with(
        "F = [[0.5, 1.0], [0.0, 0.8]]",
        "F = [[0.5, 1.0], [0.0, 0.8], [1.0, 1.0]]",
    )
    .replace("H = [[1.0, 0.0]]", "H = [[1.0, 0.0, 0.0]]");
    assert_error(
        &text,
        r#"channels[0] "pump3": model.F is 3×2 but H has 3 columns"#,
    );
}

#[test]
fn ragged_rows_are_an_error() {
    assert_error(
        &with("F = [[0.5, 1.0], [0.0, 0.8]]", "F = [[0.5, 1.0], [0.0]]"),
        "model.F: row 1 has 1 entries but row 0 has 2",
    );
}

#[test]
fn unknown_signal_in_a_fault_column_names_the_entry() {
    assert_error(
        &with(r#"psi = ["0.5*u0", 1.0]"#, r#"psi = ["0.5*u7", 1.0]"#),
        r#"faults[1].psi[0]: unknown signal "u7""#,
    );
}

#[test]
fn fault_column_of_the_wrong_length() {
    assert_error(
        &with(r#"psi = ["0.5*u0", 1.0]"#, "psi = [1.0, 2.0, 3.0]"),
        "faults[1].psi has 3 entries, expected 2",
    );
}

#[test]
fn non_symmetric_q() {
    assert_error(
        &with("Q = 0.01", "Q = [[0.01, 0.002], [0.0, 0.01]]"),
        "model.Q is not symmetric",
    );
}

#[test]
fn non_psd_q() {
    assert_error(
        &with("Q = 0.01", "Q = [[0.01, 0.0], [0.0, -0.01]]"),
        "model.Q is not positive semi-definite",
    );
}

#[test]
fn non_pd_r() {
    assert_error(
        &with("R = 0.04", "R = 0.0"),
        "model.R is not positive definite",
    );
}

#[test]
fn non_pd_p0() {
    assert_error(
        &with("R = 0.04", "R = 0.04\nP0 = [[1.0, 2.0], [2.0, 1.0]]"),
        "model.P0 is not positive definite",
    );
}

#[test]
fn min_lag_not_below_window() {
    assert_error(
        &with("min_lag = 1", "min_lag = 50"),
        "glr.min_lag: s = 50 must be below w = 50",
    );
}

#[test]
fn window_below_two() {
    assert_error(
        &with("window = 50\nmin_lag = 1", "window = 1\nmin_lag = 0"),
        "glr.window: w = 1 must be at least 2",
    );
}

#[test]
fn duplicate_channel_names() {
    let text = format!(
        "{BASE}\n{}",
        BASE.replace("[channels.glr]\nwindow = 50\nmin_lag = 1", "")
    );
    assert_error(
        &text,
        r#"channels[1] "pump3": duplicate channel name "pump3""#,
    );
}

#[test]
fn duplicate_fault_names() {
    assert_error(
        &with(r#"name = "custom""#, r#"name = "bias""#),
        r#"faults[1]: duplicate fault name "bias""#,
    );
}

#[test]
fn nan_and_inf_anywhere() {
    assert_error(
        &with(
            "F = [[0.5, 1.0], [0.0, 0.8]]",
            "F = [[0.5, nan], [0.0, 0.8]]",
        ),
        "model.F: entry [0][1] is not finite",
    );
    assert_error(&with("R = 0.04", "R = inf"), "model.R is not finite");
    assert_error(
        &with(r#"psi = ["0.5*u0", 1.0]"#, r#"psi = ["0.5*u0", -inf]"#),
        "faults[1].psi[1] is not finite",
    );
}

#[test]
fn actuator_fault_on_a_missing_input() {
    assert_error(
        &with("input = 0", "input = 3"),
        "faults[0].input: input u3 does not exist (the channel has 1 inputs)",
    );
}

#[test]
fn unknown_onset_and_kind() {
    assert_error(
        &with(
            r#"kind = "actuator_bias""#,
            r#"kind = "actuator_bias"
onset = "sudden""#,
        ),
        r#"faults[0].onset: "sudden" is not one of step, impulse, ramp, known"#,
    );
    assert_error(
        &with(r#"kind = "actuator_bias""#, r#"kind = "leak""#),
        r#"faults[0].kind: "leak" is not one of"#,
    );
}

#[test]
fn threshold_and_false_alarm_together() {
    assert_error(
        &with(
            "window = 50",
            "window = 50\nthreshold = 20.0\nfalse_alarm = 1e-3",
        ),
        "give one of `threshold`, `false_alarm` and `[channels.glr.calibrated]`",
    );
}

#[test]
fn unknown_threshold_mode_and_calibrated_interval_not_containing_the_threshold() {
    assert_error(
        &with("window = 50", "window = 50\nthreshold_mode = \"magic\""),
        "\"magic\" is not one of bonferroni, chi2",
    );
    assert_error(
        &with(
            "window = 50\nmin_lag = 1",
            "window = 50\nmin_lag = 1\n[channels.glr.calibrated]\nthreshold = 20.0\nmtbfa = 1e4\nsamples = 1000000\nepisodes = 98\ninterval = [21.0, 22.0]",
        ),
        "does not contain the threshold 20",
    );
}

#[test]
fn every_error_is_listed_not_only_the_first() {
    let text = with("R = 0.04", "R = 0.0")
        .replace("min_lag = 1", "min_lag = 80")
        .replace(r#"psi = ["0.5*u0", 1.0]"#, r#"psi = ["0.5*u9", 1.0]"#);
    let errs = errors(&text);
    assert!(errs.len() >= 3, "{errs:#?}");
    for want in ["model.R", "glr.min_lag", "faults[1].psi[0]"] {
        assert!(
            errs.iter().any(|e| e.contains(want)),
            "{want} missing from {errs:#?}"
        );
    }
}

#[test]
fn unobservable_model_is_a_warning_not_an_error() {
    let cfg = glrmon_spec::parse(&with(
        "F = [[0.5, 1.0], [0.0, 0.8]]",
        "F = [[0.5, 0.0], [0.0, 0.8]]",
    ))
    .unwrap();
    assert!(
        cfg.warnings
            .iter()
            .any(|w| w.to_string().contains("not observable")),
        "{:?}",
        cfg.warnings
    );
}

#[test]
fn false_alarm_gives_the_bonferroni_chi2_threshold() {
    let cfg =
        glrmon_spec::parse(&with("window = 50", "window = 50\nfalse_alarm = 0.0049")).unwrap();
    // χ²(2) upper quantile at α/(w − s) = 0.0049/49 = 1e-4 is −2 ln 1e-4.
    let t = cfg.channels[0].alarm.threshold;
    assert!((t - 18.420680743952367).abs() < 1e-9, "{t}");
}

#[test]
fn every_shipped_config_is_valid() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let mut files = vec![root.join("demo.toml")];
    for e in std::fs::read_dir(root.join("examples")).unwrap() {
        files.push(e.unwrap().path());
    }
    assert!(files.len() >= 4);
    for f in files {
        if let Err(e) = glrmon_spec::load(&f) {
            panic!("{}:\n{e}", f.display());
        }
    }
}

/// Zhang 2021, Assumption (iv): the Kitanidis residual needs H·E of full column rank; an
/// unknown input on the unmeasured second state cannot be decoupled.
#[test]
fn unknown_input_invisible_to_the_outputs_fails_assumption_iv() {
    let text = with("R = 0.04", "R = 0.04\nE = [[0.0], [1.0]]");
    assert_error(
        &text,
        r#"channels[0] "pump3": model.E: Assumption (iv) of Zhang 2021 fails: C_{k+1}E_k (1×1) has numerical rank 0, not full column rank 1"#,
    );
    // More unknown-input directions than outputs.
    let text = with("R = 0.04", "R = 0.04\nE = [[1.0, 0.0], [0.0, 1.0]]");
    assert_error(&text, r#"channels[0] "pump3": model.E: Assumption (iv)"#);
    // The same E is fine when the outputs see it and leave a direction free of it…
    let ok = with("H = [[1.0, 0.0]]", "H = [[1.0, 0.0], [0.0, 1.0]]")
        .replace("R = 0.04", "R = 0.04\nE = [[1.0], [0.0]]");
    let cfg = glrmon_spec::parse(&ok).unwrap();
    let d = cfg.channels[0].diagnosis;
    assert_eq!(d.residual, glrmon_spec::ResidualKind::Kitanidis);
    assert!(!d.enabled);
    assert_eq!(d.history, 100);
    assert_eq!(cfg.channels[0].innovation_dof(), 1);
    // …and a rank-deficient E is an error whatever the residual: the detector itself
    // decouples the unknown input (Zhang 2021 §III-B).
    let kalman = with("H = [[1.0, 0.0]]", "H = [[1.0, 0.0], [1.0, 0.0]]")
        .replace("R = 0.04", "R = 0.04\nE = [[0.0], [1.0]]")
        + "\n[channels.diagnosis]\nresidual = \"kalman\"\n";
    assert_error(&kalman, "model.E: Assumption (iv)");
}

#[test]
fn diagnosis_table_is_strict_and_checked() {
    let diag = |body: &str| format!("{BASE}\n[channels.diagnosis]\n{body}\n");
    assert_error(&diag("enabeld = true"), "unknown field `enabeld`");
    assert_error(
        &diag("residual = \"kitanidis\""),
        r#"channels[0] "pump3": diagnosis.residual is "kitanidis" but the model has no unknown-input matrix E"#,
    );
    assert_error(
        &diag("residual = \"luenberger\""),
        r#"channels[0] "pump3": diagnosis.residual: "luenberger" is not one of kalman, kitanidis"#,
    );
    assert_error(&diag("history = 1"), "diagnosis.history");
    assert_error(&diag("span = 0"), "diagnosis.span");
    assert_error(
        &diag("lasso = { ratio = 1.5 }"),
        r#"channels[0] "pump3": diagnosis.lasso.ratio"#,
    );
    assert_error(
        &diag("lasso = { path_points = 1 }"),
        "diagnosis.lasso.path_points",
    );
    assert_error(&diag("lasso = { points = 10 }"), "unknown field `points`");
    assert_error(
        &diag("alpha = 0.0"),
        r#"channels[0] "pump3": diagnosis.alpha: 0 is not in (0, 1]"#,
    );
    assert_error(
        &diag("alpha = 1.5"),
        "diagnosis.alpha: 1.5 is not in (0, 1]",
    );
    assert_eq!(
        glrmon_spec::parse(&diag("alpha = 1.0")).unwrap().channels[0]
            .diagnosis
            .alpha,
        1.0
    );
    assert_eq!(
        glrmon_spec::parse(BASE).unwrap().channels[0]
            .diagnosis
            .alpha,
        glrmon_spec::DEFAULT_DIAGNOSIS_ALPHA
    );
    let cfg = glrmon_spec::parse(&diag(
        "enabled = true\nspan = 30\nhistory = 60\nlasso = { path_points = 50, ratio = 1e-3 }",
    ))
    .unwrap();
    let d = cfg.channels[0].diagnosis;
    assert!(d.enabled);
    assert_eq!(d.residual, glrmon_spec::ResidualKind::Kalman);
    assert_eq!((d.span, d.history), (Some(30), 60));
    assert_eq!((d.lasso.path_points, d.lasso.ratio), (50, 1e-3));
    assert_eq!(
        d.lasso.plateau_scale,
        glrmon_core::sparse::PlateauScale::Log
    );
    let cfg = glrmon_spec::parse(&diag("lasso = { plateau_scale = \"linear\" }")).unwrap();
    assert_eq!(
        cfg.channels[0].diagnosis.lasso.plateau_scale,
        glrmon_core::sparse::PlateauScale::Linear
    );
    assert_error(
        &diag("lasso = { plateau_scale = \"lin\" }"),
        "diagnosis.lasso.plateau_scale",
    );
}

#[test]
fn bad_shard_and_metrics_address_name_the_daemon_keys() {
    let text = format!("[daemon]\nshard = \"2/2\"\nmetrics = \"localhost\"\n{BASE}");
    assert_error(
        &text,
        "daemon.shard: \"2/2\": the index must be below the count",
    );
    assert_error(
        &text,
        "daemon.metrics: \"localhost\" is not a local address",
    );
}

#[test]
fn warm_up_is_the_window_a_count_or_an_error() {
    let warm = |v: &str| {
        let cfg = glrmon_spec::parse(&with("min_lag = 1", &format!("min_lag = 1\nwarm_up = {v}")))
            .unwrap();
        cfg.channels[0].window.warm_up
    };
    assert_eq!(warm("\"window\""), 50);
    assert_eq!(warm("30"), 30);
    assert_eq!(
        glrmon_spec::parse(BASE).unwrap().channels[0].window.warm_up,
        0
    );
    assert_error(
        &with("min_lag = 1", "min_lag = 1\nwarm_up = \"full\""),
        "glr.warm_up: \"full\" is not \"window\" or a number of samples",
    );
}

#[test]
fn an_unknown_input_must_leave_an_output_direction() {
    assert_error(
        &with("R = 0.04", "R = 0.04\nE = [[1.0], [0.0]]"),
        "model.E has 1 columns and H has 1 rows",
    );
}

/// Zhang & Basseville 2014 §6.2's Q, printed to four decimals, has
/// λ_min = −2.5·10⁻⁵ (1.8·10⁻⁷ of λ_max). It is accepted with a warning naming the field,
/// and the model uses the nearest PSD matrix, within 10⁻⁴ of the printed one.
#[test]
fn paper2014_gas_q_is_projected_with_a_warning() {
    let text = with(
        "Q = 0.01",
        "Q = [[100.2766, -66.1165], [-66.1165, 43.5933]]",
    );
    let cfg = glrmon_spec::parse(&text).unwrap();
    let warning = cfg
        .warnings
        .iter()
        .map(ToString::to_string)
        .find(|w| w.contains("model.Q"))
        .unwrap_or_else(|| panic!("no model.Q warning in {:?}", cfg.warnings));
    assert!(
        warning.starts_with(r#"channels[0] "pump3": model.Q is not positive semi-definite as written (smallest eigenvalue -2.548e-5"#),
        "{warning}"
    );
    assert!(warning.contains("max |ΔQ| = "), "{warning}");
    let given = nalgebra::DMatrix::from_row_slice(2, 2, &[100.2766, -66.1165, -66.1165, 43.5933]);
    let used = cfg.channels[0].model.matrices()[4].base().clone();
    let change = (&used - &given).amax();
    assert!(change > 0.0 && change < 1e-4, "max |ΔQ| = {change:e}");
    assert_eq!(used, used.transpose());
    let eig = used.symmetric_eigenvalues();
    assert!(eig.min() >= -1e-12 * eig.max(), "{eig}");
    // The channel builds: the projected Q reaches the filter.
    assert!(cfg.channels[0].detector().is_ok());
}

/// The tolerance is for rounding, not for wrong matrices: λ_min = −10⁻²·λ_max
/// is refused, and the message names the field, λ_min and the tolerance.
#[test]
fn q_one_percent_indefinite_is_rejected_naming_the_field() {
    let errs = errors(&with("Q = 0.01", "Q = [[1.0, 0.0], [0.0, -0.01]]"));
    let e = errs
        .iter()
        .find(|e| e.contains("model.Q"))
        .unwrap_or_else(|| panic!("{errs:#?}"));
    assert!(
        e.starts_with(r#"channels[0] "pump3": model.Q is not positive semi-definite (smallest eigenvalue -1.000e-2"#),
        "{e}"
    );
    assert!(e.contains("1e-5"), "{e}");
}

/// A rounded R that is singular as written is raised to eigenvalues ≥
/// 10⁻⁵·λ_max (R must stay positive definite), with a warning.
#[test]
fn rounded_singular_r_is_made_definite_with_a_warning() {
    let text = BASE
        .replace("H = [[1.0, 0.0]]", "H = [[1.0, 0.0], [0.0, 1.0]]")
        .replace("R = 0.04", "R = [[4.0, 2.0], [2.0, 0.99999]]");
    let cfg = glrmon_spec::parse(&text).unwrap();
    let w: Vec<String> = cfg.warnings.iter().map(ToString::to_string).collect();
    assert!(
        w.iter()
            .any(|w| w.contains("model.R is not positive definite as written")),
        "{w:#?}"
    );
    let used = cfg.channels[0].model.matrices()[5].base().clone();
    let eig = used.symmetric_eigenvalues();
    assert!((eig.min() / eig.max() - 1e-5).abs() < 1e-9, "{eig}");
}

/// An LPV covariance keeps the check at its base point and is never projected.
#[test]
fn lpv_q_is_checked_at_its_base_point_without_projection() {
    assert_error(
        &with(
            "Q = 0.01",
            "Q = { base = [[1.0, 0.0], [0.0, -1e-7]], p0 = [[0.1, 0.0], [0.0, 0.1]] }",
        ),
        "model.Q is not positive semi-definite at its base point",
    );
}

/// An identified innovation model (Q = K·Re·Kᵀ, R = Re, S = K·Re) is accepted and its
/// detector runs with the cross-covariance; S with the wrong shape, with E, or too large
/// for Q and R is an error naming model.S.
#[test]
fn cross_covariance_s_is_checked_and_reaches_the_detector() {
    // K = [0.5, 0.2]ᵀ, Re = 0.04: Q = K Re Kᵀ, S = K Re.
    let innovation = with(
        "Q = 0.01\nR = 0.04",
        "Q = [[0.01, 0.004], [0.004, 0.0016]]\nR = 0.04\nS = [[0.02], [0.008]]",
    );
    let cfg = glrmon_spec::parse(&innovation).unwrap();
    let ch = &cfg.channels[0];
    assert_eq!(
        ch.cross_covariance.as_ref().map(|s| s.shape()),
        Some((2, 1))
    );
    assert!(ch.detector().is_ok());
    assert_error(
        &with("R = 0.04", "R = 0.04\nS = [[0.02, 0.0]]"),
        "model.S is 1×2 but F is 2×2 and H has 1 rows (expected 2×1)",
    );
    assert_error(
        &with("R = 0.04", "R = 0.04\nS = [[0.5], [0.0]]"),
        "model.S: makes the joint noise covariance [[Q, S], [Sᵀ, R]] indefinite",
    );
}

/// `kind = "all_sensors"` / `"all_actuators"` make one sensor bias per output and one
/// actuator bias per input, named y0_bias, u0_bias (or after a given prefix), next to
/// hand-written faults; misuse names the entry.
#[test]
fn all_sensors_and_all_actuators_expand_to_one_fault_per_signal() {
    let text = with(
        "[[channels.faults]]\nname = \"bias\"",
        "[[channels.faults]]\nkind = \"all_sensors\"\n\n[[channels.faults]]\nname = \"act\"\nkind = \"all_actuators\"\nonset = \"ramp\"\n\n[[channels.faults]]\nname = \"bias\"",
    );
    let cfg = glrmon_spec::parse(&text).unwrap();
    let ch = &cfg.channels[0];
    assert_eq!(ch.fault_names, ["y0_bias", "act0", "bias", "custom"]);
    assert_eq!(
        ch.onsets()[..2],
        [glrmon_core::Onset::Step, glrmon_core::Onset::Ramp]
    );
    assert!(ch.detector().is_ok());
    assert_error(
        &with(
            "[[channels.faults]]\nname = \"bias\"",
            "[[channels.faults]]\nkind = \"all_sensors\"\noutput = 0\n\n[[channels.faults]]\nname = \"bias\"",
        ),
        "faults[0]: kind \"all_sensors\" makes one fault per signal: remove input/output/psi/phi",
    );
    assert_error(
        &with(
            "name = \"bias\"\nkind = \"actuator_bias\"",
            "kind = \"actuator_bias\"",
        ),
        "faults[0].name is missing: every fault needs a name",
    );
    assert_error(
        &with(
            "[[channels.faults]]\nname = \"bias\"",
            "[[channels.faults]]\nkind = \"all_sensors\"\n\n[[channels.faults]]\nname = \"y0_bias\"",
        ),
        "duplicate fault name \"y0_bias\"",
    );
}

/// `[zenoh]` endpoints are checked with the file, as `--listen`/`--connect` are on the
/// command line: `validate` refuses `127.0.0.1:7447` (no protocol) with the fix, instead
/// of `run` failing on Zenoh's JSON5 error.
#[test]
fn malformed_zenoh_endpoints_name_their_field_and_the_fix() {
    let text = format!(
        "[zenoh]\nlisten = [\"tcp/127.0.0.1:7447\", \"127.0.0.1:7448\"]\nconnect = [\"tcp/router\"]\n{BASE}"
    );
    let e = errors(&text);
    assert_eq!(e.len(), 2, "{e:?}");
    assert!(
        e[0].starts_with("zenoh.connect[0]: \"tcp/router\": \"router\" is not HOST:PORT"),
        "{e:?}"
    );
    assert!(
        e[1].starts_with("zenoh.listen[1]: \"127.0.0.1:7448\": no protocol")
            && e[1].ends_with("e.g. tcp/127.0.0.1:7448"),
        "{e:?}"
    );
}

#[test]
fn scales_and_offsets_beyond_the_limits_name_the_scaling_field_not_a_fault() {
    let scaled = |scaling: &str| {
        with(
            "[channels.glr]",
            &format!(
                "[[channels.faults]]\nname = \"s\"\nkind = \"sensor_bias\"\noutput = 0\n\n\
                 [channels.scaling]\n{scaling}\n\n[channels.glr]"
            ),
        )
    };
    // A tiny scale once overflowed the raw-unit fault's signature and was reported on the
    // fault; a huge one underflowed two faults' correlation into ±∞.
    for (scaling, path) in [
        (
            "y_scale = [1e-300]",
            "scaling.y_scale[0]: 1e-300 is outside [1e-60, 1e60]",
        ),
        ("y_scale = [1e160]", "scaling.y_scale[0]: 1e160 is outside"),
        ("u_scale = [1e-61]", "scaling.u_scale[0]: 1e-61 is outside"),
        (
            "y_offset = [1e308]",
            "scaling.y_offset[0]: 1e308 is beyond ±1e40",
        ),
        ("u_offset = [-1e41]", "scaling.u_offset[0]: -1e41 is beyond"),
    ] {
        let errs = errors(&scaled(scaling));
        assert!(
            errs.iter().any(|e| e.contains(path)),
            "{scaling}: {errs:#?}"
        );
        assert!(
            !errs.iter().any(|e| e.contains("faults[")),
            "{scaling}: an error named a fault: {errs:#?}"
        );
    }
    // At the limits, the channel is valid.
    glrmon_spec::parse(&scaled(
        "y_scale = [1e-60]\ny_offset = [1e40]\nu_scale = [1e60]",
    ))
    .unwrap();
}

#[test]
fn units_label_the_signals_and_are_checked() {
    let cfg = glrmon_spec::parse(&with(
        "[channels.glr]",
        "[channels.columns]\ny_units = [\"cm\"]\n\n[channels.glr]",
    ))
    .unwrap();
    let columns = &cfg.channels[0].columns;
    assert_eq!(columns.output_label(0), "y0 [cm]");
    assert_eq!(columns.input_label(0), "u0");
    assert!(!columns.named, "units alone do not name the columns");
    assert_error(
        &with(
            "[channels.glr]",
            "[channels.columns]\ny_units = [\"cm\", \"m\"]\n\n[channels.glr]",
        ),
        "columns.y_units has 2 units but the channel has 1 outputs",
    );
    assert_error(
        &with(
            "[channels.glr]",
            "[channels.columns]\nu_units = [\"m\\u0007\"]\n\n[channels.glr]",
        ),
        "columns.u_units[0] is not a unit label",
    );
}
