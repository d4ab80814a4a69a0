//! The episode's estimate costs no allocation on the per-sample path but the vector of
//! the `stat` record that carries it: a counting global allocator around the samples of
//! a long episode (the detector follows its onset, the monitor copies θ̂ out).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use glrmon_wire::{Record, Sample};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator unchanged; the counter is a const-initialised
// thread-local `Cell` without destructor, whose access does not allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// A stable tank's level sensor (model units: the filter absorbs most of a bias), the
/// consistency test off so that no record but `stat` comes in the measured span.
const TANK: &str = r#"
[[channels]]
name = "tank"
[channels.model]
F = [[0.9]]
G = [[0.1]]
H = [[1.0]]
Q = 0.01
R = 0.01
[channels.simulation]
inputs = ["normal(0, 1)"]
[[channels.faults]]
name = "level_bias"
kind = "sensor_bias"
output = 0
[channels.glr]
window = 40
[channels.consistency]
enabled = false
"#;

/// Allocations per sample of `on_sample` over samples 100..280 (no episode) and
/// 400..1400 (a bias of 3 from 300 on: one episode, its onset followed), with `stat`
/// records on or off.
fn per_sample(stat_records: bool) -> (f64, f64) {
    let ch = glrmon_spec::parse(TANK).unwrap().channels[0].clone();
    let magnitude = glrmon_sim::fault_magnitudes(&ch, &["level_bias".into()], &[3.0]).unwrap();
    let sim = glrmon_sim::from_channel(&ch, 5).unwrap();
    let mut sim = glrmon_sim::inject(
        sim,
        &ch,
        glrmon_sim::Injection {
            magnitude,
            onset: 300,
        },
    )
    .unwrap();
    let samples: Vec<Sample> = (0..1400)
        .map(|_| {
            let x = sim.next_sample();
            Sample {
                k: Some(x.k),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            }
        })
        .collect();
    let mut monitor = glrmon_monitor::Monitor::from_channel(&ch).unwrap();
    monitor.set_stat_records(stat_records);
    let mut records = Vec::with_capacity(16);
    let mut count = |range: std::ops::Range<usize>, monitor: &mut glrmon_monitor::Monitor| {
        let n = range.len() as f64;
        let before = allocations();
        for s in &samples[range] {
            records.clear();
            monitor.on_sample(s, &mut records);
            assert!(
                records.iter().all(|r| matches!(r, Record::Stat(_))),
                "{records:?}"
            );
        }
        (allocations() - before) as f64 / n
    };
    for s in &samples[..100] {
        monitor.on_sample(s, &mut Vec::new());
    }
    let quiet = count(100..280, &mut monitor);
    for s in &samples[280..400] {
        monitor.on_sample(s, &mut Vec::new());
    }
    assert!(monitor.alarm_active());
    let episode = count(400..1400, &mut monitor);
    assert!(monitor.alarm_active(), "the bias persists");
    (quiet, episode)
}

/// Without `stat` records, a sample of the episode allocates nothing; with them, one
/// vector more than outside it (the record's `episode.magnitude`), besides the record's
/// channel name, `magnitude` and `innovation`.
#[test]
fn following_the_episode_allocates_only_its_record_vector() {
    assert_eq!(per_sample(false), (0.0, 0.0));
    assert_eq!(per_sample(true), (3.0, 4.0));
}
