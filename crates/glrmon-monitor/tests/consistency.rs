//! Filter consistency: the block χ² test of εᵀΣ⁻¹ε stays silent on fault-free
//! data from the model, and warns (`consistency` records, not alarms) when the model's
//! measurement noise R is mis-set by ×4 or ×¼.

use glrmon_wire::Record;

/// The `consistency` records of 100 000 samples of bench-A (true R = 0.04) monitored
/// with the demo's `lpv` channel whose R is replaced by `r`.
fn consistency_records(r: &str, seed: u64) -> (Vec<glrmon_wire::Consistency>, usize) {
    let text = include_str!("../../../config/demo.toml");
    assert!(text.contains("R = 0.04\n"));
    let cfg = glrmon_spec::parse(&text.replacen("R = 0.04\n", &format!("R = {r}\n"), 1)).unwrap();
    let channel = cfg.channel("lpv").unwrap();
    assert_eq!(
        channel.consistency.map(|c| c.window),
        Some(500),
        "on by default"
    );
    let mut mon = glrmon_monitor::Monitor::from_channel(channel).unwrap();
    let mut sim = glrmon_sim::scenarios::bench_a().simulator(seed).unwrap();
    let mut records = Vec::new();
    let mut found = Vec::new();
    let mut alarms = 0;
    for k in 0..100_000u64 {
        let x = sim.next_sample();
        let s = glrmon_wire::Sample {
            k: Some(k),
            t: None,
            u: x.u,
            y: x.y,
            p: x.p,
        };
        mon.on_sample(&s, &mut records);
        for r in records.drain(..) {
            match r {
                Record::Consistency(c) => found.push(c),
                Record::Alarm(_) => alarms += 1,
                _ => {}
            }
        }
    }
    (found, alarms)
}

#[test]
fn silent_on_fault_free_data_from_the_model() {
    for seed in [1, 2] {
        let (found, _) = consistency_records("0.04", seed);
        assert!(found.is_empty(), "seed {seed}: {found:?}");
    }
}

#[test]
fn warns_when_r_is_four_times_too_large_or_too_small() {
    // R ×4 in the model: the innovations are smaller than Σ says.
    let (found, _) = consistency_records("0.16", 3);
    assert_eq!(
        found.len(),
        1,
        "one change of verdict, then it stays: {found:?}"
    );
    assert_eq!(found[0].state, "too_small");
    assert_eq!(found[0].k, 499, "at the end of the first block");
    assert!(found[0].nis_mean < found[0].band[0]);
    // R ×¼: larger than Σ says.
    let (found, _) = consistency_records("0.01", 3);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].state, "too_large");
    assert!(found[0].nis_mean > found[0].band[1]);
    eprintln!(
        "R x1/4: block mean of NIS {:.3} (band [{:.3}, {:.3}], expected {})",
        found[0].nis_mean, found[0].band[0], found[0].band[1], found[0].expected
    );
}
