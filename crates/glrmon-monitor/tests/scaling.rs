//! Signals in natural units (`[channels.scaling]`): a channel whose model is written in
//! centred, scaled units and told its operating point and scales must behave exactly as
//! the same plant written in raw units — same samples simulated, same l_k, same alarms,
//! and magnitudes θ̂ of its sensor and actuator biases in the signals' raw units.
//!
//! Model in scaled units: F, G, H, J, Q, R below; scaling u = 3 + 0.5·u_s,
//! y = (12, 1400) + diag(0.1, 20)·y_s. The same plant in raw units (offsets only):
//! G_raw = G/0.5, H_raw = diag(0.1, 20)·H, J_raw = diag(0.1, 20)·J/0.5,
//! R_raw = diag(0.1, 20)·R·diag(0.1, 20).

use glrmon_wire::Record;

const SCALED: &str = r#"
[[channels]]
name = "scaled"
[channels.model]
F = [[0.8, 0.1], [0.0, 0.7]]
G = [[1.0], [0.5]]
H = [[1.0, 0.0], [0.5, 1.0]]
J = [[0.0], [0.2]]
Q = [[0.01, 0.0], [0.0, 0.02]]
R = [[0.04, 0.0], [0.0, 0.09]]
[channels.scaling]
u_offset = [3.0]
u_scale = [0.5]
y_offset = [12.0, 1400.0]
y_scale = [0.1, 20.0]
[channels.simulation]
inputs = ["3 + 0.5 * normal(0, 1)"]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 30
"#;

const RAW: &str = r#"
[[channels]]
name = "raw"
[channels.model]
F = [[0.8, 0.1], [0.0, 0.7]]
G = [[2.0], [1.0]]
H = [[0.1, 0.0], [10.0, 20.0]]
J = [[0.0], [8.0]]
Q = [[0.01, 0.0], [0.0, 0.02]]
R = [[0.0004, 0.0], [0.0, 36.0]]
[channels.scaling]
u_offset = [3.0]
y_offset = [12.0, 1400.0]
[channels.simulation]
inputs = ["3 + 0.5 * normal(0, 1)"]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 30
"#;

fn channel(text: &str) -> glrmon_spec::Channel {
    glrmon_spec::parse(text).expect("valid").channels[0].clone()
}

/// `n` samples of `channel`'s simulator (seed 11) with fault `fault` of raw magnitude
/// `theta` from sample 300.
fn simulate(
    channel: &glrmon_spec::Channel,
    fault: &str,
    theta: f64,
    n: usize,
) -> Vec<glrmon_wire::Sample> {
    let magnitude = glrmon_sim::fault_magnitudes(channel, &[fault.into()], &[theta]).unwrap();
    let injection = glrmon_sim::Injection {
        magnitude,
        onset: 300,
    };
    let sim = glrmon_sim::from_channel(channel, 11).unwrap();
    let mut sim = glrmon_sim::inject(sim, channel, injection).unwrap();
    (0..n)
        .map(|_| {
            let x = sim.next_sample();
            glrmon_wire::Sample {
                k: Some(x.k),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            }
        })
        .collect()
}

/// Per processed sample: (l_k, θ̂); and the alarms' samples.
fn monitor(
    channel: &glrmon_spec::Channel,
    samples: &[glrmon_wire::Sample],
) -> (Vec<(f64, Vec<f64>)>, Vec<u64>) {
    let mut mon = glrmon_monitor::Monitor::from_channel(channel).unwrap();
    let (mut records, mut stats, mut alarms) = (Vec::new(), Vec::new(), Vec::new());
    for s in samples {
        mon.on_sample(s, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Stat(s) => stats.push((s.glr.unwrap_or(f64::NAN), s.magnitude)),
                Record::Alarm(a) => alarms.push(a.k),
                _ => {}
            }
        }
    }
    (stats, alarms)
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a.is_nan() && b.is_nan()) || (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

#[test]
fn scaled_and_raw_unit_models_simulate_the_same_raw_samples() {
    let (scaled, raw) = (channel(SCALED), channel(RAW));
    for (fault, theta) in [("y1_bias", 30.0), ("u0_bias", 0.2)] {
        let a = simulate(&scaled, fault, theta, 600);
        let b = simulate(&raw, fault, theta, 600);
        for (x, y) in a.iter().zip(&b) {
            for (p, q) in x.u.iter().chain(&x.y).zip(y.u.iter().chain(&y.y)) {
                assert!(close(*p, *q, 1e-12), "{fault} at k = {:?}: {p} vs {q}", x.k);
            }
        }
        // The raw samples really are around the operating point.
        let mean_y1 = a.iter().map(|s| s.y[1]).sum::<f64>() / a.len() as f64;
        assert!((mean_y1 - 1400.0).abs() < 100.0, "mean y1 = {mean_y1}");
    }
}

#[test]
fn glr_alarms_and_raw_unit_magnitudes_do_not_depend_on_the_model_units() {
    let (scaled, raw) = (channel(SCALED), channel(RAW));
    assert!((scaled.alarm.threshold - raw.alarm.threshold).abs() < 1e-12);
    for (fault, theta, index) in [
        ("y0_bias", 0.8, 0),
        ("y1_bias", 30.0, 1),
        ("u0_bias", 0.6, 2),
    ] {
        let samples = simulate(&raw, fault, theta, 700);
        let (a, alarms_a) = monitor(&scaled, &samples);
        let (b, alarms_b) = monitor(&raw, &samples);
        assert_eq!(a.len(), 700);
        assert_eq!(alarms_a, alarms_b, "{fault}");
        assert!(
            !alarms_a.is_empty() && alarms_a[0] >= 300,
            "{fault}: {alarms_a:?}"
        );
        for (k, ((la, ta), (lb, tb))) in a.iter().zip(&b).enumerate() {
            assert!(close(*la, *lb, 1e-8), "{fault} k = {k}: l {la} vs {lb}");
            for (x, y) in ta.iter().zip(tb) {
                assert!(close(*x, *y, 1e-7), "{fault} k = {k}: θ̂ {x} vs {y}");
            }
        }
        // θ̂ of the injected fault in raw units near the injected value, averaged over
        // samples 310..330, while the true onset is inside the window (later, the onsets
        // of the window all come after it and the filter has partly absorbed the bias).
        // The band is wide (five noisy samples per σ of θ̂), but a unit error would be off
        // by a factor of 2 (u_scale) to 20 (y_scale).
        let estimate = a[310..330].iter().map(|(_, t)| t[index]).sum::<f64>() / 20.0;
        eprintln!("{fault}: mean θ̂ = {estimate}, injected {theta}");
        assert!(
            (0.6 * theta..1.6 * theta).contains(&estimate),
            "{fault}: θ̂ = {estimate}, injected {theta}"
        );
    }
}

#[test]
fn scaling_errors_name_the_entry() {
    let bad = SCALED.replace("y_scale = [0.1, 20.0]", "y_scale = [0.1, 0.0]");
    let e = glrmon_spec::parse(&bad).unwrap_err().to_string();
    assert!(e.contains("scaling.y_scale[1]"), "{e}");
    assert!(e.contains("finite and positive"), "{e}");
    let bad = SCALED.replace("u_offset = [3.0]", "u_offset = [3.0, 1.0]");
    let e = glrmon_spec::parse(&bad).unwrap_err().to_string();
    assert!(
        e.contains("scaling.u_offset") && e.contains("has 2 entries but the channel has 1 inputs"),
        "{e}"
    );
    let gain = SCALED.replace("J = [[0.0], [0.2]]\n", "").replace(
        "kind = \"all_actuators\"",
        "name = \"g\"\nkind = \"actuator_gain\"\ninput = 0",
    );
    let e = glrmon_spec::parse(&gain).unwrap_err().to_string();
    assert!(
        e.contains("actuator_gain") && e.contains("u_offset[0]"),
        "{e}"
    );
}

#[test]
fn column_names_are_checked() {
    let named = SCALED.replace(
        "[channels.simulation]",
        "[channels.columns]\nu = [\"FIC101\"]\ny = [\"TI1\", \"TI2\"]\n[channels.simulation]",
    );
    let c = channel(&named);
    assert!(c.columns.named);
    assert_eq!(c.columns.y, ["TI1", "TI2"]);
    for (bad, expected) in [
        (
            "y = [\"TI1\", \"TI2\"]",
            "y = [\"TI1\"]",
            "columns.y has 1 names but the channel has 2 outputs",
        ),
        (
            "y = [\"TI1\", \"TI2\"]",
            "y = [\"TI1\", \"FIC101\"]",
            "columns.y[1]: \"FIC101\" is also u0",
        ),
        (
            "u = [\"FIC101\"]",
            "u = [\"t\"]",
            "columns.u[0]: \"t\" is the sample index or time column",
        ),
        (
            "u = [\"FIC101\"]",
            "u = [\"a,b\"]",
            "columns.u[0]: \"a,b\" is not a column name",
        ),
    ]
    .map(|(from, to, e)| (named.replace(from, to), e))
    {
        let e = glrmon_spec::parse(&bad).unwrap_err().to_string();
        assert!(e.contains(expected), "{e}");
    }
}
