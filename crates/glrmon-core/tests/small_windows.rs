//! Windows smaller than, and not a multiple of, a vector register (w = 2 … 18): the
//! fused pass reads and writes its lanes unchecked after one size check per step, and
//! the slots after its last whole register go through a half-width register and one at
//! a time, so these windows
//! exercise every edge of that bookkeeping. They must give the bits of the passes at
//! every vector level (through a fault and a predict-only gap), and the stationary
//! regime (tables per lag, ranks read from the tables) must answer every per-onset
//! query as the general path does.

mod common;

use common::{bits, run_pair, run_steps};
use glrmon_core::{StepOutput, VectorLevel};
use glrmon_sim::scenarios;

/// `steps` samples of the general path (fault at half-time, a gap at a third).
fn run(
    sc: &scenarios::Scenario,
    fault: &str,
    level: VectorLevel,
    fused: bool,
    steps: u64,
) -> Vec<Vec<u64>> {
    let mut sc = sc.clone();
    sc.window.steady_tolerance = 0.0;
    let mut det = sc.detector().unwrap();
    assert!(det.set_vector_level(level));
    det.set_fused_window(fused);
    let mut sim = sc.faulty_simulator(17, fault, steps / 2, 2.0).unwrap();
    let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
    // Every output, then the statistic and rank of onset r̂ as reported afterwards.
    run_steps(
        &mut det,
        &mut sim,
        &mut out,
        steps,
        |k| k == steps / 3,
        |det, out| {
            let mut b = bits(out);
            if let Some(r) = out.onset {
                let (stat, rank) = det.onset_statistic(r).unwrap();
                b.push(stat.to_bits());
                b.push(rank as u64);
            }
            b
        },
    )
}

/// The window of `sc` set to w (and the minimum lag kept below it).
fn with_window(sc: &scenarios::Scenario, w: usize) -> scenarios::Scenario {
    let mut sc = sc.clone();
    sc.window.window = w;
    if sc.window.min_lag >= w {
        sc.window.min_lag = 0;
    }
    sc
}

#[test]
fn small_windows_fused_equal_the_passes_bit_for_bit() {
    let cases = [
        (scenarios::bench_a(), "sensor_bias"),
        (scenarios::lpv_n3_p2_m4(), "actuator1_bias"),
        (scenarios::lti_n3_p2_m3(), "sensor0_drift"),
    ];
    for w in 2..=18 {
        for (sc, fault) in &cases {
            let sc = with_window(sc, w);
            let passes = run(&sc, fault, VectorLevel::Baseline, false, 300);
            for level in VectorLevel::supported() {
                let fused = run(&sc, fault, level, true, 300);
                assert_eq!(passes, fused, "w = {w}, {fault}, {level:?}");
            }
        }
    }
}

/// In the stationary regime every onset's statistic (to 10⁻⁹ relative, as in
/// lti_fast_path.rs) and rank (read from the lag tables) agree with the general path's,
/// before and after a gap that leaves it.
#[test]
fn small_windows_stationary_queries_equal_the_general_path() {
    let lti = scenarios::lti_n3_p2_m3();
    for w in 2..=18 {
        let sc = with_window(&lti, w);
        let mut general_sc = sc.clone();
        general_sc.window.steady_tolerance = 0.0;
        for level in VectorLevel::supported() {
            let mut fast = sc.detector().unwrap();
            let mut general = general_sc.detector().unwrap();
            assert!(fast.set_vector_level(level));
            assert!(general.set_vector_level(level));
            let mut sim = sc
                .faulty_simulator(3, "sensor0_drift", 100_000, 2.0)
                .unwrap();
            let (p, m) = (sc.model_outputs(), sc.faults.len());
            let (mut a, mut b) = (StepOutput::new(p, m), StepOutput::new(p, m));
            let mut stationary = 0;
            let pair = [&mut fast, &mut general];
            let outs = [&mut a, &mut b];
            run_pair(
                pair,
                outs,
                &mut sim,
                6000,
                |k| k == 4000,
                |k, _, dets, _| {
                    let [fast, general] = dets;
                    stationary += u64::from(fast.is_stationary());
                    for r in k.saturating_sub(w as u64 + 1)..=k + 1 {
                        let (f, g) = (fast.onset_statistic(r), general.onset_statistic(r));
                        assert_eq!(f.is_some(), g.is_some(), "w = {w}, k = {k}, r = {r}");
                        if let (Some((x, rx)), Some((y, ry))) = (f, g) {
                            assert_eq!(rx, ry, "rank: w = {w}, k = {k}, r = {r}");
                            assert!(
                                (x - y).abs() <= 1e-9 * (1.0 + y.abs()),
                                "statistic: w = {w}, k = {k}, r = {r}: {x} vs {y}"
                            );
                        }
                    }
                },
            );
            assert!(stationary > 1000, "w = {w}: {stationary} stationary steps");
        }
    }
}
