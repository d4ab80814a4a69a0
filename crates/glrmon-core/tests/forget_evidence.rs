//! `forget_evidence` (the end of the settling after a restart): the filter goes on
//! untouched, the onsets up to the call leave the window, and every later onset keeps
//! the statistic it has in a window that forgot nothing, since the statistic of onset r
//! sums the samples from r on only (Zhang & Basseville 2014, eqs. (32)-(36)). Once the
//! window has slid past the call, the two detectors agree in every output.

use glrmon_core::{Detector, Sample, StepOutput};
use glrmon_sim::scenarios::{self, Scenario};

fn check(sc: &Scenario, forget_at: u64) {
    let w = sc.window.window as u64;
    let mut plain = sc.detector().unwrap();
    let mut forgetful = sc.detector().unwrap();
    let mut sim = sc
        .faulty_simulator(7, &sc.faults[0].0, forget_at + w / 2, 3.0)
        .unwrap();
    let (mut a, mut b) = (
        StepOutput::new(sc.model_outputs(), sc.faults.len()),
        StepOutput::new(sc.model_outputs(), sc.faults.len()),
    );
    let (mut compared, mut peak) = (0, 0.0_f64);
    for _ in 0..forget_at + 2 * w {
        let s = sim.next_sample();
        let sample = Sample {
            k: s.k,
            u: &s.u,
            y: &s.y,
            p: &s.p,
        };
        plain.step(&sample, &mut a).unwrap();
        forgetful.step(&sample, &mut b).unwrap();
        // The filter is untouched; in the stationary regime the forgetful one is back
        // on the general recursion, whose P equals the frozen one to rounding.
        for (x, y) in a.innovation.iter().zip(b.innovation.iter()) {
            assert!(
                (x - y).abs() <= 1e-12 * (1.0 + x.abs()),
                "k = {}: {x} vs {y}",
                s.k
            );
        }
        if s.k == forget_at {
            assert!(Detector::forget_evidence(&mut forgetful));
        }
        if s.k <= forget_at {
            continue;
        }
        // As at a start, an onset needs min_lag samples before it is tested.
        if s.k > forget_at + sc.window.min_lag as u64 {
            assert!(b.glr.is_some(), "k = {}", s.k);
        }
        peak = peak.max(b.glr.unwrap_or(0.0));
        if let Some(onset) = b.onset {
            assert!(onset > forget_at, "k = {}: onset {onset} forgotten", s.k);
        }
        for r in (forget_at + 1)..=s.k {
            let (Some((x, rx)), Some((y, ry))) =
                (plain.onset_statistic(r), forgetful.onset_statistic(r))
            else {
                continue;
            };
            assert_eq!(rx, ry, "k = {}, r = {r}", s.k);
            assert!(
                (x - y).abs() <= 1e-9 * (1.0 + x.abs()),
                "k = {}, r = {r}: {x} vs {y}",
                s.k
            );
            compared += 1;
        }
        for r in 0..=forget_at {
            assert_eq!(forgetful.onset_statistic(r), None, "k = {}, r = {r}", s.k);
        }
        if s.k >= forget_at + w {
            assert_eq!((a.onset, a.rank), (b.onset, b.rank), "k = {}", s.k);
            let (x, y) = (a.glr.unwrap(), b.glr.unwrap());
            assert!(
                (x - y).abs() <= 1e-9 * (1.0 + x.abs()),
                "k = {}: {x} vs {y}",
                s.k
            );
        }
    }
    assert!(compared > 1000, "{compared} statistics compared");
    assert!(
        peak > 50.0,
        "the fault after the forgetting is seen: peak l_k {peak}"
    );
}

/// An LPV channel, whose window never enters the stationary regime.
#[test]
fn forgetting_keeps_the_later_onsets_statistics_lpv() {
    check(&scenarios::bench_a(), 150);
}

/// An LTI channel forgets while its window runs on the stationary tables (after
/// 2w samples), which it leaves.
#[test]
fn forgetting_keeps_the_later_onsets_statistics_in_the_stationary_regime() {
    let sc = scenarios::paper2014_unstable();
    let w = sc.window.window as u64;
    check(&sc, 3 * w);
}
