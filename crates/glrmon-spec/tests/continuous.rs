//! `[channels.model]` written in continuous time: `A`, `B`, `Qc` with the channel's
//! `period`, discretised when the file is read (F = e^{AT}, G = ∫₀ᵀ e^{As}ds·B,
//! Q = ∫₀ᵀ e^{As}Qc e^{Aᵀs}ds), so that the channel holds an ordinary F, G, Q; each
//! conflict with the discrete keys an error naming both; the period required and
//! positive; an LPV A refused, an LPV B or Qc discretised term by term.

use glrmon_core::model::continuous::{process_noise, zero_order_hold};
use nalgebra::DMatrix;

/// A tank level, dh/dt = −h/600 + u/0.5 (cm, m³/h… per second), sampled every 20 s.
const TANK: &str = r#"
[[channels]]
name = "tank"
period = 20.0

[channels.model]
A = [[-0.0016666666666666668]]
B = [[2.0]]
Qc = 1e-4
H = [[1.0]]
R = 0.04

[[channels.faults]]
kind = "all_actuators"
"#;

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

fn with(replace: &str, by: &str) -> String {
    assert!(TANK.contains(replace), "fixture lacks {replace}");
    TANK.replacen(replace, by, 1)
}

#[test]
fn a_continuous_model_is_discretised_when_read() {
    let cfg = glrmon_spec::parse(TANK).unwrap();
    let c = &cfg.channels[0];
    let [f, g, h, j, q, r] = c.model.matrices();
    let (a, t) = (-1.0f64 / 600.0, 20.0);
    assert!((f.base()[(0, 0)] - (a * t).exp()).abs() < 1e-15);
    let want_g = (a * t).exp_m1() / a * 2.0;
    assert!((g.base()[(0, 0)] - want_g).abs() < 1e-13 * want_g);
    let want_q = 1e-4 * (2.0 * a * t).exp_m1() / (2.0 * a);
    assert!((q.base()[(0, 0)] - want_q).abs() < 1e-13 * want_q);
    // The output equation is not discretised.
    assert_eq!(h.base()[(0, 0)], 1.0);
    assert_eq!(j.base()[(0, 0)], 0.0);
    assert_eq!(r.base()[(0, 0)], 0.04);
    let d = c.discretised.as_ref().expect("discretised");
    assert_eq!(d.period(), 20.0);
    assert_eq!(d.f(), f.base());
    assert!(d.to_string().contains("time constants 600 s"), "{d}");
    assert_eq!(c.fault_names, ["u0_bias"]);
    // A discrete model has no discretisation.
    let discrete = TANK
        .replace("A = [[-0.0016666666666666668]]", "F = [[0.967]]")
        .replace("B = [[2.0]]", "G = [[39.3]]")
        .replace("Qc = 1e-4", "Q = 0.002");
    let cfg = glrmon_spec::parse(&discrete).unwrap();
    assert!(cfg.channels[0].discretised.is_none());
}

#[test]
fn a_per_sample_q_may_be_given_with_a() {
    let cfg = glrmon_spec::parse(&with("Qc = 1e-4", "Q = 0.002")).unwrap();
    let c = &cfg.channels[0];
    assert_eq!(c.model.matrices()[4].base()[(0, 0)], 0.002);
    let d = c.discretised.as_ref().unwrap();
    assert!(d.q().is_none());
    assert!(!d.to_string().contains("Van Loan"), "{d}");
}

#[test]
fn each_conflict_names_both_keys() {
    assert_error(
        &with("A = ", "F = [[0.9]]\nA = "),
        r#"channels[0] "tank": model.A is given with model.F: write the state equation either in discrete time (F, G, Q) or in continuous time (A, B, Qc"#,
    );
    assert_error(
        &with("B = [[2.0]]", "B = [[2.0]]\nG = [[1.0]]"),
        "model.G is given with model.B",
    );
    assert_error(
        &with("B = [[2.0]]", "G = [[1.0]]"),
        "model.G is the discrete-time input matrix but the model is written in continuous time (model.A): give B instead",
    );
    assert_error(
        &with("Qc = 1e-4", "Qc = 1e-4\nQ = 0.002"),
        "model.Qc is given with model.Q",
    );
    assert_error(&with("Qc = 1e-4", ""), "model.Qc is required with model.A");
    // The continuous keys without A.
    let discrete = with("A = [[-0.0016666666666666668]]", "F = [[0.967]]");
    assert_error(
        &discrete,
        "model.B is the continuous-time input matrix (dx/dt = A x + B u) and needs model.A",
    );
    assert_error(
        &discrete,
        "model.Qc is a continuous-time noise intensity and needs model.A",
    );
    assert_error(
        &discrete.replace("B = [[2.0]]", "B = [[2.0]]\nG = [[1.0]]"),
        "model.B is given with model.G",
    );
    assert_error(
        &with("A = [[-0.0016666666666666668]]", ""),
        r#"channels[0] "tank": model.F is required"#,
    );
    assert_error(
        &discrete.replace("Qc = 1e-4", "").replace("B = ", "G = "),
        "model.Q is required",
    );
}

#[test]
fn the_period_is_required_and_positive() {
    assert_error(
        &with("period = 20.0\n", ""),
        r#"channels[0] "tank": period is required with a continuous-time model (model.A)"#,
    );
    for bad in ["0.0", "-20.0", "nan", "inf"] {
        assert_error(
            &with("period = 20.0", &format!("period = {bad}")),
            "period is",
        );
    }
    // Also on a discrete model, whose reports turn sample counts into times with it.
    let discrete = TANK
        .replace("A = [[-0.0016666666666666668]]", "F = [[0.967]]")
        .replace("B = [[2.0]]", "G = [[39.3]]")
        .replace("Qc = 1e-4", "Q = 0.002")
        .replace("period = 20.0", "period = 0.0");
    assert_error(
        &discrete,
        "period is 0: the sample period must be a finite, positive number of seconds",
    );
}

#[test]
fn shapes_are_checked_under_the_continuous_letters() {
    assert_error(
        &with("B = [[2.0]]", "B = [[2.0], [1.0]]"),
        "model.B is 2×1 but A is 1×1 and there are 1 inputs",
    );
    assert_error(
        &with("Qc = 1e-4", "Qc = [[1e-4, 0.0], [0.0, 1e-4]]"),
        "model.Qc is 2×2 but A is 1×1",
    );
    assert_error(
        &with("H = [[1.0]]", "H = [[1.0, 0.0]]"),
        "model.A is 1×1 but H has 2 columns",
    );
    assert_error(
        &with("A = [[-0.0016666666666666668]]", "A = [[-0.001, 0.0]]"),
        "model.A is 1×2",
    );
}

#[test]
fn qc_must_be_a_symmetric_psd_intensity() {
    let two = |qc: &str| {
        TANK.replace(
            "A = [[-0.0016666666666666668]]",
            "A = [[-0.01, 0.0], [0.01, -0.02]]",
        )
        .replace("B = [[2.0]]", "B = [[2.0], [0.0]]")
        .replace("H = [[1.0]]", "H = [[1.0, 0.0], [0.0, 1.0]]")
        .replace("Qc = 1e-4", qc)
    };
    assert!(glrmon_spec::parse(&two("Qc = [[1e-4, 0.0], [0.0, 2e-4]]")).is_ok());
    assert_error(
        &two("Qc = [[1e-4, 5e-5], [0.0, 2e-4]]"),
        "model.Qc is not symmetric",
    );
    assert_error(
        &two("Qc = [[1e-4, 0.0], [0.0, -2e-4]]"),
        "model.Qc is not positive semi-definite",
    );
    assert_error(&with("Qc = 1e-4", "Qc = nan"), "model.Qc is not finite");
}

#[test]
fn an_exploding_model_is_refused_with_the_period() {
    assert_error(
        &with("A = [[-0.0016666666666666668]]", "A = [[40.0]]"),
        "model.A: e^{AT} overflows",
    );
    assert_error(
        &with("A = [[-0.0016666666666666668]]", "A = [[40.0]]"),
        "(T = 20 s)",
    );
}

#[test]
fn an_lpv_a_is_refused_and_an_lpv_b_or_qc_discretised_term_by_term() {
    assert_error(
        &with(
            "A = [[-0.0016666666666666668]]",
            "A = { base = [[-0.001]], p0 = [[0.0005]] }",
        ),
        "model.A cannot depend on scheduling signals: F = e^{A(p)T} is not affine in p",
    );
    let text = with("B = [[2.0]]", "B = { base = [[2.0]], p0 = [[0.5]] }")
        .replace("Qc = 1e-4", "Qc = { base = [[1e-4]], p1 = [[2e-5]] }");
    let cfg = glrmon_spec::parse(&text).unwrap();
    let c = &cfg.channels[0];
    assert_eq!(c.dims.signals, 2);
    let a = DMatrix::from_element(1, 1, -1.0 / 600.0);
    let [_, g, _, _, q, _] = c.model.matrices();
    let (_, g1) = zero_order_hold(&a, &DMatrix::from_element(1, 1, 0.5), 20.0).unwrap();
    assert_eq!(g.terms().len(), 1);
    assert_eq!(g.terms()[0].0, 0);
    assert!((&g.terms()[0].1 - &g1).amax() < 1e-15 * g1.amax());
    let q1 = process_noise(&a, &DMatrix::from_element(1, 1, 2e-5), 20.0).unwrap();
    assert_eq!(q.terms()[0].0, 1);
    assert!((&q.terms()[0].1 - &q1).amax() < 1e-15 * q1.amax());
}

#[test]
fn errors_are_located_at_the_key() {
    let text = with("A = ", "F = [[0.9]]\nA = ");
    let err = glrmon_spec::parse(&text).unwrap_err();
    let located = err
        .errors
        .iter()
        .find(|e| e.path.ends_with("model.A"))
        .and_then(|e| e.location)
        .expect("located");
    // Line 1 is the empty line of the opening quote, F is on line 7: A on line 8.
    assert_eq!((located.line, located.column), (8, 1), "{err}");
}

/// A Qc of the wrong shape, or not PSD, is reported once and not discretised.
#[test]
fn a_refused_qc_is_reported_once() {
    for qc in ["Qc = [[1e-4, 0.0], [0.0, 1e-4]]", "Qc = -1e-4"] {
        let errs = errors(&with("Qc = 1e-4", qc));
        assert_eq!(errs.len(), 1, "{errs:#?}");
        assert!(errs[0].contains("model.Qc is"), "{errs:#?}");
    }
}
