//! The fused window pass gives the same bits as the separate passes (a faster layout
//! of the window loop). For small n, m, p one pass over the onsets does the
//! signatures, C and d, the dropped-pivot LDLᵀ statistic and Γ's time update in
//! registers; every onset gets the same operations in the same order as in the passes
//! (`accumulate`, `maximize`, `time_update`), so every output of every sample must be
//! equal bit for bit, at every vector level, through a fault and predict-only gaps, and
//! the magnitude (from an LDLᵀ recomputed at r̂ alone after the fused pass) too. The
//! fused pass runs at the AVX2 and AVX-512F levels (the baseline runs the passes), so
//! on a processor without them this compares the passes with themselves.

mod common;

use common::{bits, run_steps};
use glrmon_core::{StepOutput, VectorLevel};
use glrmon_sim::scenarios;

/// The outputs of 4000 samples (fault at 2500, gaps at 1200-1202 and 2600) through
/// the general path, fused or not.
fn run(sc: &scenarios::Scenario, fault: &str, level: VectorLevel, fused: bool) -> Vec<Vec<u64>> {
    let mut sc = sc.clone();
    sc.window.steady_tolerance = 0.0;
    let mut det = sc.detector().unwrap();
    assert!(det.set_vector_level(level));
    det.set_fused_window(fused);
    let mut sim = sc.faulty_simulator(17, fault, 2_500, 2.0).unwrap();
    let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
    let gap = |k| (1_200..1_203).contains(&k) || k == 2_600;
    let all = run_steps(&mut det, &mut sim, &mut out, 4_000, gap, |_, out| bits(out));
    assert!(!det.is_stationary());
    all
}

#[test]
fn fused_window_pass_equals_the_separate_passes_bit_for_bit() {
    // The scenarios' own windows, then windows that are not a multiple of the register
    // width (the last slots go through a half-width register and one at a time).
    let with_window = |mut sc: scenarios::Scenario, w: usize| {
        sc.window.window = w;
        sc
    };
    for (sc, fault) in [
        (scenarios::bench_a(), "sensor_bias"),
        (scenarios::paper2014_unstable(), "x0_jump"),
        (scenarios::lpv_n3_p2_m4(), "actuator1_bias"),
        (scenarios::lti_n3_p2_m3(), "sensor0_drift"),
        (with_window(scenarios::bench_a(), 37), "actuator_bias"),
        (with_window(scenarios::paper2014_unstable(), 99), "x1_jump"),
        (with_window(scenarios::lpv_n3_p2_m4(), 45), "sensor0_bias"),
        (with_window(scenarios::lti_n3_p2_m3(), 11), "sensor0_drift"),
    ] {
        let reference = run(&sc, fault, VectorLevel::Baseline, false);
        for level in VectorLevel::supported() {
            let fused = run(&sc, fault, level, true);
            assert_eq!(reference.len(), fused.len());
            for (k, (a, b)) in reference.iter().zip(&fused).enumerate() {
                assert_eq!(a, b, "{fault}: fused at {level:?} differs at output {k}");
            }
        }
    }
}

/// Signatures are kept only on request (`GlrDetector::keep_signatures`), and the fused
/// pass keeps the same bits as the passes: every onset of the window at every 50th
/// sample, n = 3, p = 2, m = 4, w = 45. Without the request, and after switching it
/// on until the next measured step, `signature` says there is none.
#[test]
fn kept_signatures_of_the_fused_pass_equal_the_passes_and_are_off_by_default() {
    use nalgebra::DMatrix;
    let mut sc = scenarios::lpv_n3_p2_m4();
    sc.window.window = 45;
    sc.window.steady_tolerance = 0.0;
    let (p, m) = (sc.model_outputs(), sc.faults.len());
    let signatures = |level: VectorLevel, fused: bool| {
        let mut det = sc.detector().unwrap();
        assert!(det.set_vector_level(level));
        det.set_fused_window(fused);
        let mut sim = sc.faulty_simulator(5, "actuator1_bias", 300, 2.0).unwrap();
        let mut out = StepOutput::new(p, m);
        let mut s = DMatrix::zeros(p, m);
        let mut kept = Vec::new();
        run_steps(&mut det, &mut sim, &mut out, 100, |_| false, |_, _| ());
        assert!(!det.signature(99, &mut s), "signatures are off by default");
        det.keep_signatures(true);
        assert!(!det.signature(99, &mut s), "switched on after sample 99");
        let mut count = 0;
        for k in 100..600_u64 {
            step_one(&mut det, &mut sim, &mut out, k);
            if k % 50 == 0 {
                for onset in k - 44..=k {
                    assert!(det.signature(onset, &mut s), "onset {onset} at {k}");
                    kept.extend(s.iter().map(|x| x.to_bits()));
                    count += 1;
                }
            }
        }
        assert_eq!(count, 10 * 45);
        kept
    };
    let reference = signatures(VectorLevel::Baseline, false);
    for level in VectorLevel::supported() {
        assert!(
            signatures(level, true) == reference,
            "fused signatures at {level:?} differ from the passes'"
        );
    }
}

/// Sample k of `sim` through `det`, measured.
fn step_one(
    det: &mut glrmon_core::GlrDetector,
    sim: &mut glrmon_sim::Simulator,
    out: &mut StepOutput,
    k: u64,
) {
    let x = sim.next_sample();
    let s = glrmon_core::Sample {
        k,
        u: &x.u,
        y: &x.y,
        p: &x.p,
    };
    det.step(&s, out).unwrap();
}
