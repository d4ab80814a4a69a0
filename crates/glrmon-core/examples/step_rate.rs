//! Samples per second of `GlrDetector::step` per scenario and vector level, best of
//! several rounds (robust to a shared machine's noise; criterion's `make bench` gives
//! the confidence intervals).
//!
//! `cargo run --release -p glrmon-core --example step_rate [-- ROUNDS STEPS [FILTER]]`
//! (FILTER keeps the runs whose case name and level contain it, e.g. `bench-A` or
//! `fast path) Avx512`).

use std::time::Instant;

use glrmon_core::{Sample, StepOutput, VectorLevel};
use glrmon_sim::{SimSample, scenarios};

fn main() {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let filter = std::env::args()
        .skip(1)
        .find(|a| a.parse::<u64>().is_err())
        .unwrap_or_default();
    let rounds = args.first().copied().unwrap_or(5);
    let steps = args.get(1).copied().unwrap_or(100_000) as usize;
    let lti = scenarios::lti_n3_p2_m3();
    let mut lti_general = lti.clone();
    lti_general.window.steady_tolerance = 0.0;
    let cases = [
        ("bench-A LPV n2 p1 m2 w100 (general)", scenarios::bench_a()),
        ("LPV n3 p2 m4 w160 (general)", scenarios::lpv_n3_p2_m4()),
        ("LTI n3 p2 m3 w160 (fast path)", lti),
        ("LTI n3 p2 m3 w160 (general)", lti_general),
    ];
    let selected = |name: &str, level: VectorLevel| format!("{name} {level:?}").contains(&filter);
    for (name, sc) in &cases {
        if !VectorLevel::supported()
            .into_iter()
            .any(|l| selected(name, l))
        {
            continue;
        }
        let mut sim = sc.simulator(42).expect("scenario simulates");
        let warm = 2_000;
        let data: Vec<SimSample> = (0..warm + steps).map(|_| sim.next_sample()).collect();
        for level in VectorLevel::supported() {
            if !selected(name, level) {
                continue;
            }
            let mut best = f64::INFINITY;
            for _ in 0..rounds {
                let mut det = sc.detector().expect("scenario builds");
                det.set_vector_level(level);
                let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
                let mut run = |range: std::ops::Range<usize>| {
                    for k in range {
                        let x = &data[k];
                        let s = Sample {
                            k: k as u64,
                            u: &x.u,
                            y: &x.y,
                            p: &x.p,
                        };
                        det.step(&s, &mut out).expect("valid sample");
                    }
                };
                run(0..warm);
                let t = Instant::now();
                run(warm..warm + steps);
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!(
                "{name:40} {:>8}: {:>7.0} k samples/s ({:.3} µs/sample)",
                format!("{level:?}"),
                steps as f64 / best / 1e3,
                best / steps as f64 * 1e6
            );
        }
    }
}
