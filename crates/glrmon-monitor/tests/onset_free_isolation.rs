//! Isolation at the alarm knows that the onset is uncertain.
//!
//! The §6.1 plant of Zhang & Basseville (2014): a jump of x0 at k = 201 and a jump of
//! x1 at 200 give the same first innovation. The minmax test run at the crossing's
//! onset estimate r̂ = 200 once isolated `x1_jump` alone in 30 of 30 runs of an x0 jump
//! (minmax ≈ 92 against 6.6), while the update two samples later was right. Since
//! onset-free isolation, the alarm reports the faults it cannot yet tell apart as
//! ambiguous, and never the wrong jump alone; the update still isolates the injected
//! one.

use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{AlarmSettings, EpisodeEnd};
use glrmon_monitor::{Monitor, MonitorSettings, Tuning};
use glrmon_sim::scenarios;
use glrmon_wire::{IsolationResult, Record, Sample};

const SEEDS: u64 = 40;

fn monitor() -> Monitor {
    let sc = scenarios::paper2014_unstable();
    // The paper's threshold: χ²(2) at 10⁻⁴ per sample over w − s = 99 onsets.
    let threshold = chi2_upper_quantile(2.0, 1e-4 / 99.0).unwrap();
    Monitor::new(
        "unstable",
        Box::new(sc.detector().unwrap()),
        MonitorSettings {
            tuning: Tuning {
                alarm: AlarmSettings::with_threshold(threshold),
                episode_end: EpisodeEnd::BelowThreshold,
                isolation_delay: 2,
                isolation_alpha: 0.01,
                isolation_onsets: 1,
                isolation_thresholds: vec![],
            },
            groups: vec![],
            max_gap: 10,
            max_reorder: 16,
            settle: None,
        },
    )
}

fn isolated(tests: &[IsolationResult]) -> Vec<&str> {
    tests
        .iter()
        .filter(|t| t.isolated)
        .map(|t| t.fault.as_str())
        .collect()
}

/// The alarm's and the update's isolation of one run with `fault` at k = 201.
fn run(fault: &str, magnitude: f64, seed: u64) -> (Vec<IsolationResult>, Vec<IsolationResult>) {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(seed, fault, 201, magnitude).unwrap();
    let mut mon = monitor();
    let mut records = Vec::new();
    for _ in 0..300 {
        let x = sim.next_sample();
        let s = Sample {
            k: Some(x.k),
            t: None,
            u: x.u,
            y: x.y,
            p: x.p,
        };
        mon.on_sample(&s, &mut records);
    }
    let alarm = records
        .iter()
        .find_map(|r| match r {
            Record::Alarm(a) if a.k >= 201 => Some(a.isolation.clone()),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{fault}, seed {seed}: no alarm"));
    let update = records
        .iter()
        .find_map(|r| match r {
            Record::Isolation(u) if u.alarm_k >= 201 => Some(u.isolation.clone()),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{fault}, seed {seed}: no update"));
    (alarm, update)
}

/// Over many seeds and both jumps: the alarm never isolates the other jump alone, an
/// undecided alarm names the two as ambiguous with each other, and the update isolates
/// the injected jump in every run, decisively (not ambiguous).
#[test]
fn paper2014_section_6_1_alarm_never_isolates_the_wrong_jump_alone() {
    for (fault, other, magnitude) in [("x0_jump", "x1_jump", 4.0), ("x1_jump", "x0_jump", 1.5)] {
        let (mut right_at_alarm, mut ambiguous_at_alarm, mut both_at_update) = (0, 0, 0);
        for seed in 0..SEEDS {
            let (alarm, update) = run(fault, magnitude, seed);
            let at_alarm = isolated(&alarm);
            assert!(
                at_alarm != [other],
                "{fault}, seed {seed}: the alarm isolates {other} alone: {alarm:#?}"
            );
            if at_alarm.contains(&fault) {
                right_at_alarm += 1;
            } else {
                ambiguous_at_alarm += 1;
                let t = alarm.iter().find(|t| t.fault == fault).unwrap();
                assert!(
                    t.ambiguous_with.iter().any(|n| n == other),
                    "{fault}, seed {seed}: undecided without naming {other}: {alarm:#?}"
                );
            }
            let at_update = isolated(&update);
            assert!(
                at_update.contains(&fault) && at_update != [other],
                "{fault}, seed {seed}: update {update:#?}"
            );
            if at_update.len() > 1 {
                // The injected jump and, besides it, the other at the test's level.
                both_at_update += 1;
            }
            let t = update.iter().find(|t| t.fault == fault).unwrap();
            assert!(
                t.ambiguous_with.is_empty(),
                "{fault}, seed {seed}: update still ambiguous: {update:#?}"
            );
        }
        eprintln!(
            "{fault}: at the alarm {right_at_alarm} of {SEEDS} isolated right, \
             {ambiguous_at_alarm} ambiguous, 0 wrong; at the update {fault} in all, \
             {other} besides it in {both_at_update}"
        );
        // The other jump isolated besides at the 1 % level of each test: a few at most.
        assert!(both_at_update <= 3, "{fault}: {both_at_update} of {SEEDS}");
    }
}
