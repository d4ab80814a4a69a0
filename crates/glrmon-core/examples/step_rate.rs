//! Samples per second of `GlrDetector::step` per scenario and vector level, and of
//! the kernel detector on the example of Li, Boem, Pin & Parisini, best of
//! several rounds (robust to a shared machine's noise; criterion's `make bench` gives
//! the confidence intervals).
//!
//! `cargo run --release -p glrmon-core --example step_rate [-- ROUNDS STEPS [FILTER]]`
//! (FILTER keeps the runs whose case name and level contain it, e.g. `bench-A` or
//! `fast path) Avx512`).

use std::time::Instant;

use glrmon_core::{Detector, KernelSettings, Sample, StepOutput, VectorLevel};
use glrmon_sim::kernel_example as example;
use glrmon_sim::{SimSample, scenarios};

/// The kernel detector's rate over `steps` samples after 2 000 (the estimator active),
/// best of `rounds`; the fault at sample 5 000 puts detection and isolation in the span.
fn kernel_rate(rounds: u64, steps: usize) {
    let warm = 2_000;
    let data = example::simulate(&example::ExampleRun {
        samples: warm + steps,
        ..example::ExampleRun::paper(0)
    });
    let mut best = f64::INFINITY;
    for _ in 0..rounds {
        // Noise-free with a floor of 10⁻³: φ₂ detected at 5.02 s, the isolation filters
        // running from there on.
        let mut det = example::detector(KernelSettings {
            floor: 1e-3,
            ..KernelSettings::paper_example(1e-3)
        })
        .expect("the example builds");
        let mut out = StepOutput::for_detector(&det);
        let mut run = |range: std::ops::Range<usize>| {
            for k in range {
                det.step(&data.sample(k), &mut out).expect("valid sample");
            }
        };
        run(0..warm);
        let t = Instant::now();
        run(warm..warm + steps);
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!(
        "{:40} {:>8}: {:>7.0} k samples/s ({:.3} µs/sample)",
        "kernel Li et al. §V n5 p4 p*3, 2 candidates",
        "scalar",
        steps as f64 / best / 1e3,
        best / steps as f64 * 1e6
    );
}

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
    if "kernel Li et al. §V scalar".contains(&filter) {
        kernel_rate(rounds, steps);
    }
}
