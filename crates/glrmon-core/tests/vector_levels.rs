//! Same inputs, same bits at every vector width (docs/ARCHITECTURE.md invariant): the
//! window loops compiled for SSE2, AVX2 and AVX-512F do the same operations per onset,
//! so every output of every sample is bit-identical, through the general path, gaps
//! and the LTI fast path. Levels this processor lacks are reported, not faked. A
//! processor without FMA rounds the recursions' a·b + c twice instead of once: its
//! statistics stay within rounding of the others' and its onsets are the same.

mod common;

use common::{bits, run_steps};
use glrmon_core::{StepOutput, VectorLevel, fused_multiply_add};
use glrmon_sim::scenarios;

fn run(sc: &scenarios::Scenario, fault: &str, level: VectorLevel) -> Vec<Vec<u64>> {
    let mut det = sc.detector().unwrap();
    assert!(det.set_vector_level(level));
    let mut sim = sc.faulty_simulator(9, fault, 3_000, 2.0).unwrap();
    let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
    let gap = |k| (1_500..1_503).contains(&k);
    run_steps(&mut det, &mut sim, &mut out, 5_000, gap, |_, out| bits(out))
}

#[test]
fn every_vector_level_gives_the_same_bits() {
    let levels = VectorLevel::supported();
    eprintln!("vector levels of this processor: {levels:?}");
    for (sc, fault) in [
        (scenarios::bench_a(), "sensor_bias"),
        (scenarios::paper2014_unstable(), "x0_jump"),
        (scenarios::lpv_n3_p2_m4(), "actuator1_bias"),
        (scenarios::lti_n3_p2_m3(), "sensor0_drift"),
    ] {
        let reference = run(&sc, fault, VectorLevel::Baseline);
        for level in &levels[1..] {
            let other = run(&sc, fault, *level);
            for (k, (a, b)) in reference.iter().zip(&other).enumerate() {
                assert_eq!(
                    a, b,
                    "{fault}: {level:?} differs from the baseline at output {k}"
                );
            }
        }
    }
}

/// The statistic and onset of every sample, default rounding or a·b + c rounded twice.
fn run_rounding(sc: &scenarios::Scenario, fault: &str, separate: bool) -> Vec<(f64, u64)> {
    let mut det = sc.detector().unwrap();
    if separate {
        det.set_separate_rounding();
    }
    let mut sim = sc.faulty_simulator(9, fault, 3_000, 2.0).unwrap();
    let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
    let gap = |k| (1_500..1_503).contains(&k);
    run_steps(&mut det, &mut sim, &mut out, 5_000, gap, |_, out| {
        (out.glr.unwrap_or(0.0), out.onset.unwrap_or(u64::MAX))
    })
}

#[test]
fn rounding_twice_without_fma_stays_within_rounding_of_the_fused_recursions() {
    for (sc, fault) in [
        (scenarios::bench_a(), "sensor_bias"),
        (scenarios::paper2014_unstable(), "x0_jump"),
        (scenarios::lpv_n3_p2_m4(), "actuator1_bias"),
        (scenarios::lti_n3_p2_m3(), "sensor0_drift"),
    ] {
        let fused = run_rounding(&sc, fault, false);
        assert!(!fused.is_empty());
        let separate = run_rounding(&sc, fault, true);
        let mut worst = 0.0_f64;
        let mut onsets_differ = 0;
        for ((a, ra), (b, rb)) in fused.iter().zip(&separate) {
            worst = worst.max((a - b).abs() / (1.0 + a.abs()));
            onsets_differ += usize::from(ra != rb);
        }
        eprintln!(
            "{fault}: largest relative difference of l_k {worst:.1e}, {onsets_differ} onsets differ of {}",
            fused.len()
        );
        assert!(worst < 1e-11, "{fault}: l_k differs by {worst:e}");
        // The switch took effect: the roundings differ somewhere (none would mean both
        // runs rounded alike, as they do on a processor without FMA).
        if fused_multiply_add() {
            assert!(worst > 0.0, "{fault}: the two roundings gave the same bits");
        } else {
            eprintln!("no FMA on this processor: both runs rounded twice");
        }
        // A near-tie between two onsets may fall either way; no more than a few.
        assert!(
            onsets_differ * 1000 <= fused.len(),
            "{fault}: {onsets_differ} onsets differ"
        );
    }
}
