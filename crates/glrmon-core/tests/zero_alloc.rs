//! The per-sample path allocates nothing (an invariant of docs/ARCHITECTURE.md): a
//! counting global allocator around 10⁴ steps after warm-up, for the LPV bench-A
//! channel, the §6.1 plant, and a gap (predict-only) path.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use glrmon_core::{Sample, StateSpace, StepOutput};
use glrmon_sim::{SimSample, scenarios};

struct Counting;

thread_local! {
    /// Allocations made by this thread: the tests run in parallel, each counts its own.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn samples(sc: &scenarios::Scenario, n: usize) -> Vec<SimSample> {
    let mut sim = sc.simulator(1).unwrap();
    (0..n).map(|_| sim.next_sample()).collect()
}

#[test]
fn step_performs_zero_heap_allocations_after_warmup() {
    for sc in [
        scenarios::bench_a(),
        scenarios::paper2014_unstable(),
        scenarios::lpv_n3_p2_m4(),
        scenarios::lti_n3_p2_m3(),
    ] {
        let data = samples(&sc, 12_000);
        let mut det = sc.detector().unwrap();
        let mut out = StepOutput::new(sc.model_outputs(), sc.faults.len());
        let warmup = 2_000;
        for (k, x) in data.iter().enumerate().take(warmup) {
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
        let before = allocations();
        for (k, x) in data.iter().enumerate().skip(warmup) {
            let k = k as u64;
            // Gaps, then none: an LTI channel leaves the fast path at each gap and
            // enters it again (tables built) in the measured span.
            if k.is_multiple_of(97) && k < 7_000 {
                det.predict_only(k).unwrap();
            } else {
                det.step(
                    &Sample {
                        k,
                        u: &x.u,
                        y: &x.y,
                        p: &x.p,
                    },
                    &mut out,
                )
                .unwrap();
            }
        }
        let after = allocations();
        assert_eq!(after - before, 0, "allocations over 10⁴ steps");
        assert_eq!(det.is_stationary(), sc.model.is_constant());
        assert!(out.glr.is_some());
    }
}

/// The kernel deadbeat detector on the example of Li, Boem, Pin & Parisini, through
/// the detection at 5 s and the isolation episode that follows (candidates evaluated,
/// φ₁ excluded) inside the measured span.
#[test]
fn kernel_step_performs_zero_heap_allocations_through_detection_and_isolation() {
    use glrmon_core::{Detector, KernelSettings};
    use glrmon_sim::kernel_example as example;

    let settings = KernelSettings {
        floor: 1e-3,
        ..KernelSettings::paper_example(1e-3)
    };
    let mut det = example::detector(settings).unwrap();
    let data = example::simulate(&example::ExampleRun {
        samples: 12_000,
        ..example::ExampleRun::paper(0)
    });
    let mut out = StepOutput::for_detector(&det);
    let warmup = 2_000;
    let mut before = 0;
    for k in 0..data.len() {
        if k == warmup {
            before = allocations();
        }
        det.step(&data.sample(k), &mut out).unwrap();
    }
    let after = allocations();
    assert_eq!(after - before, 0, "allocations over 10⁴ steps");
    assert_eq!(det.verdict().isolated(), Some(1), "φ₂ isolated in the span");
    // The counter sees this thread's allocations.
    let tests = det.residual_isolation();
    assert!(tests.is_some() && allocations() > after);
}
