//! Same inputs, same bits at every vector width (docs/ARCHITECTURE.md invariant): the
//! window loops compiled for SSE2, AVX2 and AVX-512F do the same operations per onset,
//! so every output of every sample is bit-identical, through the general path, gaps
//! and the LTI fast path. Levels this processor lacks are reported, not faked.

mod common;

use common::{bits, run_steps};
use glrmon_core::{StepOutput, VectorLevel};
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
