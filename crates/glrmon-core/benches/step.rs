//! Per-sample cost of `GlrDetector::step`: bench-A, a larger LPV channel, and an LTI
//! channel with and without the stationary fast path.
//!
//! `cargo bench -p glrmon-core --bench step`; figures in docs/PERFORMANCE.md.

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use glrmon_core::{Sample, StepOutput, VectorLevel};
use glrmon_sim::{SimSample, scenarios};

const BATCH: usize = 10_000;

fn bench_scenario(c: &mut Criterion, name: &str, sc: &scenarios::Scenario) {
    bench_at(c, name, sc, VectorLevel::detect());
}

fn bench_at(c: &mut Criterion, name: &str, sc: &scenarios::Scenario, level: VectorLevel) {
    let mut sim = sc.simulator(42).unwrap();
    let data: Vec<SimSample> = (0..2 * BATCH).map(|_| sim.next_sample()).collect();
    let mut group = c.benchmark_group(name);
    group.throughput(Throughput::Elements(BATCH as u64));
    group.bench_function("step", |b| {
        b.iter_batched_ref(
            || {
                // Warm the window up outside the timing: the bank is full from here on.
                let mut det = sc.detector().unwrap();
                assert!(det.set_vector_level(level));
                let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
                for (k, x) in data[..BATCH].iter().enumerate() {
                    det.step(
                        &Sample {
                            k: k as u64,
                            u: &x.u,
                            y: &x.y,
                            p: &x.p,
                        },
                        &mut out,
                    )
                    .unwrap();
                }
                (det, out)
            },
            |(det, out)| {
                for (k, x) in data[BATCH..].iter().enumerate() {
                    let k = (k + BATCH) as u64;
                    det.step(
                        &Sample {
                            k,
                            u: &x.u,
                            y: &x.y,
                            p: &x.p,
                        },
                        out,
                    )
                    .unwrap();
                }
            },
            BatchSize::LargeInput,
        );
    });
    group.finish();
}

fn steps(c: &mut Criterion) {
    bench_scenario(c, "bench_a_lpv_n2_p1_m2_w100", &scenarios::bench_a());
    bench_scenario(c, "lpv_n3_p2_m4_w160", &scenarios::lpv_n3_p2_m4());
    let lti = scenarios::lti_n3_p2_m3();
    bench_scenario(c, "lti_n3_p2_m3_w160_fast_path", &lti);
    let mut general = lti.clone();
    general.window.steady_tolerance = 0.0;
    bench_scenario(c, "lti_n3_p2_m3_w160_general_path", &general);
    // The same loops at each vector width this processor has (same bits, other speed).
    for level in VectorLevel::supported() {
        bench_at(
            c,
            &format!("bench_a_at_{level:?}"),
            &scenarios::bench_a(),
            level,
        );
        bench_at(c, &format!("lti_fast_path_at_{level:?}"), &lti, level);
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = steps
}
criterion_main!(benches);
