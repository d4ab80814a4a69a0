//! Sample indices can neither wrap nor poison a channel.
//! Before: k = 2⁶⁴ − 1 wrapped the counter (then k = 0 was accepted, l_k stayed null and
//! a faulty stream raised no alarm); after one sample with k = 10¹⁵ every later sample
//! was refused as out of order; a publisher that restarted and numbered from 0 again
//! lost all its samples up to the old index (200 of 500 here).

use glrmon_wire::{ErrorCode, Record, Sample};

const CONFIG: &str = r#"
[[channels]]
name = "tank"
[channels.model]
F = [[0.9]]
G = [[1.0]]
H = [[1.0]]
Q = 0.01
R = 0.04
[channels.simulation]
inputs = ["normal(0, 1)"]
[[channels.faults]]
name = "bias"
kind = "sensor_bias"
output = 0
[channels.glr]
window = 20
"#;

fn channel() -> glrmon_spec::Channel {
    glrmon_spec::parse(CONFIG).unwrap().channels[0].clone()
}

/// `n` samples, numbered from `first`, with a sensor bias of 2 from sample `onset` on.
fn stream(first: u64, n: u64, onset: Option<u64>, seed: u64) -> Vec<Sample> {
    let c = channel();
    let mut sim = glrmon_sim::from_channel(&c, seed).unwrap();
    if let Some(onset) = onset {
        let magnitude = glrmon_sim::fault_magnitudes(&c, &["bias".into()], &[2.0]).unwrap();
        sim = glrmon_sim::inject(sim, &c, glrmon_sim::Injection { magnitude, onset }).unwrap();
    }
    (0..n)
        .map(|i| {
            let x = sim.next_sample();
            Sample {
                k: Some(first + i),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            }
        })
        .collect()
}

struct Seen {
    alarms: Vec<u64>,
    errors: Vec<(Option<u64>, ErrorCode)>,
    glr_values: usize,
}

fn run(samples: &[Sample]) -> (Seen, u64) {
    let mut mon = glrmon_monitor::Monitor::from_channel(&channel()).unwrap();
    let mut records = Vec::new();
    let mut seen = Seen {
        alarms: vec![],
        errors: vec![],
        glr_values: 0,
    };
    for s in samples {
        mon.on_sample(s, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Alarm(a) => seen.alarms.push(a.k),
                Record::Error(e) => seen.errors.push((e.k, e.code)),
                Record::Stat(s) => seen.glr_values += usize::from(s.glr.is_some()),
                _ => {}
            }
        }
    }
    (seen, mon.counters().samples)
}

#[test]
fn the_largest_index_is_refused_and_the_stream_goes_on() {
    let mut samples = stream(0, 100, None, 1);
    samples.push(Sample {
        k: Some(u64::MAX),
        ..samples[0].clone()
    });
    // The stream goes on where it was, with a fault from k = 150.
    let rest = stream(0, 300, Some(150), 2);
    samples.extend(rest.into_iter().skip(100));
    let (seen, processed) = run(&samples);
    assert_eq!(seen.errors, [(Some(u64::MAX), ErrorCode::TooLarge)]);
    assert_eq!(processed, 300);
    assert!(
        seen.alarms.iter().any(|&k| (150..170).contains(&k)),
        "{:?}",
        seen.alarms
    );
    // And the core refuses it too, for library users.
    let mut det = channel().glr_detector().unwrap();
    let mut out = glrmon_core::StepOutput::new(1, 1);
    let e = det
        .step(
            &glrmon_core::Sample {
                k: u64::MAX,
                u: &[0.0],
                y: &[0.0],
                p: &[],
            },
            &mut out,
        )
        .unwrap_err();
    assert!(
        matches!(e, glrmon_core::StepError::IndexTooLarge { .. }),
        "{e}"
    );
}

#[test]
fn one_huge_index_does_not_poison_the_channel() {
    let mut samples = stream(0, 300, None, 3);
    samples.push(Sample {
        k: Some(1_000_000_000_000_000),
        ..samples[0].clone()
    });
    samples.extend(stream(300, 300, Some(100), 4));
    let (seen, processed) = run(&samples);
    // The jump forward restarts (gap), the return backward restarts (sequence reset);
    // nothing else is refused and the fault at k = 400 raises its alarm.
    let codes: Vec<ErrorCode> = seen.errors.iter().map(|e| e.1).collect();
    assert_eq!(
        codes,
        [ErrorCode::Gap, ErrorCode::SequenceReset],
        "{:?}",
        seen.errors
    );
    assert_eq!(processed, 601);
    assert!(
        seen.alarms.iter().any(|&k| (400..420).contains(&k)),
        "{:?}",
        seen.alarms
    );
}

#[test]
fn a_publisher_that_numbers_from_zero_again_loses_nothing() {
    let mut samples = stream(0, 200, None, 5);
    samples.extend(stream(0, 300, None, 6));
    let (seen, processed) = run(&samples);
    assert_eq!(seen.errors, [(Some(0), ErrorCode::SequenceReset)]);
    assert_eq!(processed, 500);
    // The first run has l_k from its second sample on (onsets need k > r); the
    // restarted run settles for w = 20 samples first, then likewise.
    assert_eq!(seen.glr_values, 199 + (300 - 20 - 1), "{}", seen.glr_values);
}

/// A publisher that restarts its numbering in the middle of an episode: the episode's
/// `alarm_end` is at the last sample it processed, with the episode's duration (it
/// once said k = 0, duration 0 for an episode that ran from its alarm to k = 399).
#[test]
fn an_episode_cut_by_a_publisher_restart_ends_at_its_last_sample() {
    let mut samples = stream(0, 400, Some(200), 8);
    for (i, s) in samples.iter_mut().enumerate() {
        s.t = Some(0.5 * i as f64);
    }
    samples.extend(stream(0, 100, None, 9));
    let mut mon = glrmon_monitor::Monitor::from_channel(&channel()).unwrap();
    let mut records = Vec::new();
    for s in &samples {
        mon.on_sample(s, &mut records);
    }
    let alarm = records
        .iter()
        .find_map(|r| match r {
            Record::Alarm(a) => Some(a.clone()),
            _ => None,
        })
        .expect("an alarm");
    let ends: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::AlarmEnd(e) => Some(e.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(ends.len(), 1, "{ends:?}");
    assert_eq!((ends[0].k, ends[0].t), (399, Some(199.5)), "{ends:?}");
    assert_eq!(ends[0].duration, 399 - alarm.k, "{ends:?}");
}

#[test]
fn small_reorderings_are_refused_one_by_one() {
    let mut samples = stream(0, 100, None, 7);
    // A late sample 5 before the last, a duplicate of the last, then the stream goes on.
    samples.push(samples[94].clone());
    samples.push(samples[99].clone());
    samples.extend(stream(100, 50, None, 8));
    let (seen, processed) = run(&samples);
    assert_eq!(
        seen.errors,
        [
            (Some(94), ErrorCode::OutOfOrder),
            (Some(99), ErrorCode::Duplicate)
        ]
    );
    assert_eq!(processed, 150);
}
