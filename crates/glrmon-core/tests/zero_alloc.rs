//! The per-sample path allocates nothing (an invariant of docs/ARCHITECTURE.md): a
//! counting global allocator around 10⁴ steps after warm-up, for the LPV bench-A
//! channel, the §6.1 plant, and a gap (predict-only) path.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

use glrmon_core::{Sample, StateSpace, StepOutput};
use glrmon_sim::{SimSample, scenarios};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
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
        let before = ALLOCATIONS.load(Ordering::Relaxed);
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
        let after = ALLOCATIONS.load(Ordering::Relaxed);
        assert_eq!(after - before, 0, "allocations over 10⁴ steps");
        assert_eq!(det.is_stationary(), sc.model.is_constant());
        assert!(out.glr.is_some());
    }
}
