//! One accepted sample `{"k":300,"u":[1.0],"y":[1e308,0.0]}` used to make the later
//! statistics overflow; the records that followed could not be encoded and
//! vanished (an alarm among them). Now such a value is refused at intake (`too_large`),
//! and statistics that still overflow are caught where they arise (`numerical`, the
//! filter restarts), so that every record the monitor emits is finite.

use glrmon_wire::{ErrorCode, Record, Sample};

fn channel(q: &str, r: &str) -> glrmon_spec::Channel {
    let text = format!(
        r#"
[[channels]]
name = "plant"
[channels.model]
F = [[0.9, 0.0], [0.0, 0.8]]
G = [[1.0], [0.5]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = {q}
R = {r}
[channels.simulation]
inputs = ["normal(0, 1)"]
[[channels.faults]]
kind = "all_sensors"
[channels.glr]
window = 20
"#
    );
    glrmon_spec::parse(&text).unwrap().channels[0].clone()
}

fn samples(c: &glrmon_spec::Channel, n: u64, fault_at: Option<u64>) -> Vec<Sample> {
    let mut sim = glrmon_sim::from_channel(c, 3).unwrap();
    if let Some(onset) = fault_at {
        let magnitude = glrmon_sim::fault_magnitudes(c, &["y0_bias".into()], &[2.0]).unwrap();
        sim = glrmon_sim::inject(sim, c, glrmon_sim::Injection { magnitude, onset }).unwrap();
    }
    (0..n)
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
        .collect()
}

/// Every record of the run, after checking that each one is finite (encodable).
fn run(c: &glrmon_spec::Channel, input: &[Sample]) -> Vec<Record> {
    let mut mon = glrmon_monitor::Monitor::from_channel(c).unwrap();
    let mut all = Vec::new();
    for s in input {
        let mut records = Vec::new();
        mon.on_sample(s, &mut records);
        for r in &records {
            let mut json = Vec::new();
            glrmon_wire::encode_json(r, &mut json).unwrap_or_else(|e| panic!("{r:?}: {e}"));
        }
        all.extend(records);
    }
    all
}

#[test]
fn a_huge_finite_value_is_refused_at_intake_and_the_alarm_still_comes() {
    let c = channel("0.01", "0.04");
    let mut input = samples(&c, 600, Some(400));
    input[300].y[0] = 1e308;
    let records = run(&c, &input);
    let errors: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some((e.k, e.code)),
            _ => None,
        })
        .collect();
    // The refused sample is then a missing one, bridged by a predict-only step.
    assert_eq!(
        errors,
        [
            (Some(300), ErrorCode::TooLarge),
            (Some(301), ErrorCode::Gap)
        ]
    );
    let stats = records
        .iter()
        .filter(|r| matches!(r, Record::Stat(_)))
        .count();
    assert_eq!(stats, 599);
    let alarm = records.iter().find_map(|r| match r {
        Record::Alarm(a) if a.k >= 400 => Some(a.k),
        _ => None,
    });
    assert!(alarm.is_some_and(|k| k < 410), "{alarm:?}");
}

#[test]
fn statistics_that_overflow_restart_the_filter_with_an_error_record() {
    // Values within the intake bound, but a noise so small that εᵀΣ⁻¹ε overflows.
    let c = channel("1e-150", "1e-150");
    let mut input = samples(&c, 200, None);
    input[100].y[0] = 1e100;
    let records = run(&c, &input);
    let numerical: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) if e.code == ErrorCode::Numerical => Some(e.k),
            _ => None,
        })
        .collect();
    assert_eq!(numerical.first(), Some(&Some(100)), "{numerical:?}");
    // The channel goes on after its restart.
    let after = records
        .iter()
        .filter(|r| matches!(r, Record::Stat(s) if s.k > 100))
        .count();
    assert!(after >= 90, "{after} stat records after the overflow");
}
