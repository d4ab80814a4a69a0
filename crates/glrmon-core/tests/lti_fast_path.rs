//! The stationary regime (LTI fast path): once the model, the fault columns
//! and the Riccati recursion are constant, Γ_k(r), S_k(r) and C_k(r) depend on the lag
//! k − r only (Zhang & Basseville 2014, eqs. (32), (45)-(46)) and are tabulated. Every
//! test runs a detector with the fast path next to one without it on the same samples
//! and requires l_k, r̂, rank and θ̂ to agree to 1e-9 relative at every sample, while
//! checking that the fast path was actually in force (and left when it must be).

mod common;

use common::run_pair;
use glrmon_core::{GlrDetector, StepOutput};
use glrmon_sim::{Simulator, scenarios};

/// Counts of one comparison run.
#[derive(Debug, Default)]
struct Run {
    stationary: u64,
    entries: u64,
    exits: u64,
    alarms_at: Vec<u64>,
    max_relative: f64,
}

fn close(a: f64, b: f64, what: &str, k: u64) -> f64 {
    let scale = a.abs().max(b.abs()).max(1.0);
    let rel = (a - b).abs() / scale;
    assert!(
        rel <= 1e-9,
        "{what} at k = {k}: fast {a} vs general {b} ({rel:e})"
    );
    rel
}

/// Runs `sc` through a fast-path detector and a general one; `gap(k)` marks missing
/// samples (predict-only on both).
fn compare(
    sc: &scenarios::Scenario,
    mut sim: Simulator,
    steps: u64,
    threshold: f64,
    gap: impl Fn(u64) -> bool,
) -> Run {
    let mut fast = sc.detector().unwrap();
    let mut general_sc = sc.clone();
    general_sc.window.steady_tolerance = 0.0;
    let mut general: GlrDetector = general_sc.detector().unwrap();
    let (p, m) = (sc.model_outputs(), sc.faults.len());
    let (mut a, mut b) = (StepOutput::new(p, m), StepOutput::new(p, m));
    let mut run = Run::default();
    let mut was = false;
    let mut above = false;
    let pair = [&mut fast, &mut general];
    run_pair(
        pair,
        [&mut a, &mut b],
        &mut sim,
        steps,
        gap,
        |k, measured, dets, outs| {
            let ([fast, general], [a, b]) = (dets, outs);
            if measured {
                assert!(!general.is_stationary());
                let mut worst = 0.0_f64;
                for (x, y) in a.innovation.iter().zip(b.innovation.iter()) {
                    worst = worst.max(close(*x, *y, "innovation", k));
                }
                worst = worst.max(close(
                    a.normalized_innovation,
                    b.normalized_innovation,
                    "εᵀΣ⁻¹ε",
                    k,
                ));
                match (a.glr, b.glr) {
                    (Some(x), Some(y)) => {
                        worst = worst.max(close(x, y, "l_k", k));
                        assert_eq!(a.onset, b.onset, "r̂ at k = {k} (l_k = {y})");
                        assert_eq!(a.rank, b.rank, "rank at k = {k}");
                        for (x, y) in a.magnitude.iter().zip(b.magnitude.iter()) {
                            worst = worst.max(close(*x, *y, "θ̂", k));
                        }
                        let now = y > threshold;
                        if now && !above {
                            run.alarms_at.push(k);
                        }
                        above = now;
                    }
                    (x, y) => assert_eq!(x, y, "glr presence at k = {k}"),
                }
                if fast.is_stationary() {
                    run.max_relative = run.max_relative.max(worst);
                }
            }
            let is = fast.is_stationary();
            run.stationary += u64::from(is);
            run.entries += u64::from(is && !was);
            run.exits += u64::from(!is && was);
            was = is;
        },
    );
    run
}

/// The unstable §6.1 plant under its PI controller (Zhang & Basseville 2014, §6.1): the
/// fast path takes over once P has converged and gives the paper's detection (the
/// impulse on x0 at r = 201 of the fixed-onset experiments, here at r = 20 001 so that
/// the fast path is in force) with the general path's numbers over 2·10⁵ samples.
#[test]
fn paper2014_s61_fast_path_equals_general_path_over_2e5_samples() {
    let sc = scenarios::paper2014_unstable();
    let sim = sc.faulty_simulator(7, "x0_jump", 20_001, 4.0).unwrap();
    let run = compare(&sc, sim, 200_000, 27.61, |_| false);
    assert_eq!(run.entries, 1, "{run:?}");
    assert!(run.stationary > 199_000, "{run:?}");
    assert!(
        run.alarms_at.contains(&20_001) || run.alarms_at.contains(&20_002),
        "{run:?}"
    );
    eprintln!(
        "§6.1: stationary for {} of 200000 samples, max relative difference {:e}",
        run.stationary, run.max_relative
    );
}

/// m = 3 with a ramp (sensor drift) among steps; p = 2; w = 160.
#[test]
fn lti_ramp_and_step_faults_fast_path_equals_general_path() {
    let sc = scenarios::lti_n3_p2_m3();
    let sim = sc
        .faulty_simulator(3, "sensor0_drift", 30_000, 0.01)
        .unwrap();
    let run = compare(&sc, sim, 40_000, 30.0, |_| false);
    assert_eq!(run.entries, 1, "{run:?}");
    assert!(run.stationary > 39_000, "{run:?}");
    assert!(
        run.alarms_at.iter().any(|k| (30_000..30_100).contains(k)),
        "{run:?}"
    );
    eprintln!(
        "n3 p2 m3: stationary for {} of 40000 samples, max relative difference {:e}, alarms {:?}",
        run.stationary, run.max_relative, run.alarms_at
    );
}

/// A gap (predict-only steps, K = 0) leaves the regime; it is entered again once P has
/// settled and a whole window has passed, with the numbers still equal.
#[test]
fn gap_leaves_the_stationary_regime_and_it_resumes() {
    let sc = scenarios::lti_n3_p2_m3();
    let sim = sc.simulator(11).unwrap();
    let run = compare(&sc, sim, 12_000, f64::INFINITY, |k| {
        (5_000..5_003).contains(&k)
    });
    assert_eq!(run.entries, 2, "{run:?}");
    assert_eq!(run.exits, 1, "{run:?}");
    assert!(run.stationary > 10_000, "{run:?}");
}

/// An LPV channel whose scheduling signal is piecewise constant, then varying: the fast
/// path is in force on each constant stretch, left at the first sample whose matrices
/// differ, and never used while they vary.
#[test]
fn changing_matrices_switch_the_fast_path_off_and_back_on() {
    let mut sc = scenarios::bench_a();
    sc.signals = Some(|k, p| {
        p[0] = if k < 4_000 {
            0.3
        } else if k < 8_000 {
            -0.4
        } else {
            (0.01 * k as f64).sin()
        }
    });
    let sim = sc.simulator(5).unwrap();
    let run = compare(&sc, sim, 12_000, f64::INFINITY, |_| false);
    assert_eq!(run.entries, 2, "{run:?}");
    assert_eq!(run.exits, 2, "{run:?}");
    // Two stretches of 4000 samples less the time to settle and fill the window.
    assert!(run.stationary > 7_000 && run.stationary < 8_000, "{run:?}");
}
