//! The warm-up of Zhang & Basseville 2014, §6.2: the GLR is held off until the window of
//! w samples is full. Only the output is withheld: the filter and the window run, so
//! from the w-th sample on every output equals that of a detector without warm-up, and
//! a restart holds the GLR off again.

use glrmon_core::{Sample, StepOutput};
use glrmon_sim::scenarios;

#[test]
fn the_glr_is_withheld_until_the_window_is_full_and_then_unchanged() {
    let sc = scenarios::paper2014_unstable();
    let w = sc.window.window as u64;
    let mut plain = sc.detector().unwrap();
    let mut held_sc = sc.clone();
    held_sc.window.warm_up = w;
    let mut held = held_sc.detector().unwrap();
    let mut sim = sc.faulty_simulator(3, &sc.faults[0].0, 2 * w, 1.0).unwrap();
    let (mut a, mut b) = (
        StepOutput::new(sc.model_outputs(), sc.faults.len()),
        StepOutput::new(sc.model_outputs(), sc.faults.len()),
    );
    let samples: Vec<_> = (0..3 * w).map(|_| sim.next_sample()).collect();
    for s in &samples {
        let sample = Sample {
            k: s.k,
            u: &s.u,
            y: &s.y,
            p: &s.p,
        };
        plain.step(&sample, &mut a).unwrap();
        held.step(&sample, &mut b).unwrap();
        if s.k + 1 < w {
            assert_eq!((b.glr, b.onset, b.rank), (None, None, 0), "k = {}", s.k);
        } else {
            assert_eq!(
                (a.glr.map(f64::to_bits), a.onset, a.rank),
                (b.glr.map(f64::to_bits), b.onset, b.rank),
                "k = {}",
                s.k
            );
            assert_eq!(a.magnitude, b.magnitude);
        }
        assert_eq!(a.innovation, b.innovation);
    }
    assert!(a.glr.is_some_and(|g| g > 0.0));
    held.restart().unwrap();
    let s = &samples[0];
    held.step(
        &Sample {
            k: 0,
            u: &s.u,
            y: &s.y,
            p: &s.p,
        },
        &mut b,
    )
    .unwrap();
    assert_eq!(b.glr, None);
}
