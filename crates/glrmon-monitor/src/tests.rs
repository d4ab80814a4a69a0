use super::*;
use glrmon_sim::scenarios;

fn monitor() -> Monitor {
    let sc = scenarios::paper2014_unstable();
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

/// The kernel method's exclusion reaches the records: on the noise-free example of
/// Li, Boem, Pin & Parisini (fault φ₂ from 5 s) one alarm at the detection, then an
/// `isolation` update at the sample φ₁ is excluded, naming φ₂ isolated. At the
/// bound's threshold 1 and at a lower (calibrated) one, whose alarm comes earlier and
/// opens the isolation episode itself (`Detector::follow`).
#[test]
fn kernel_exclusion_is_published_as_an_isolation_update() {
    let first = kernel_alarm_and_update(1.0);
    let lower = kernel_alarm_and_update(0.5);
    assert!(lower < first, "alarm at {lower} below 1, {first} at 1");
}

/// The alarm's k at `threshold`, after the checks of the test above.
fn kernel_alarm_and_update(threshold: f64) -> u64 {
    use glrmon_core::KernelSettings;
    use glrmon_sim::kernel_example as example;

    let settings = KernelSettings {
        floor: 1e-3,
        ..KernelSettings::paper_example(1e-3)
    };
    let detector = example::detector(settings).unwrap();
    let mut monitor = Monitor::new(
        "plane",
        Box::new(detector),
        MonitorSettings {
            tuning: Tuning {
                alarm: AlarmSettings::with_threshold(threshold),
                episode_end: EpisodeEnd::BelowThreshold,
                isolation_delay: 0,
                isolation_alpha: 0.01,
                isolation_onsets: 1,
                isolation_thresholds: vec![],
            },
            groups: vec![],
            max_gap: 10,
            max_reorder: 16,
            settle: None,
        },
    );
    let data = example::simulate(&example::ExampleRun {
        samples: 7000,
        ..example::ExampleRun::paper(0)
    });
    let mut records = Vec::new();
    for k in 0..data.u.len() {
        monitor.on_sample(
            &Sample {
                k: Some(k as u64),
                t: Some(k as f64 * 1e-3),
                u: vec![data.u[k]],
                y: data.y[4 * k..4 * k + 4].to_vec(),
                p: vec![],
            },
            &mut records,
        );
    }
    let alarms = alarms(&records);
    assert_eq!(alarms.len(), 1, "{alarms:?}");
    let alarm = alarms[0];
    assert!((5000..5050).contains(&alarm.k), "alarm at {}", alarm.k);
    assert!(
        alarm
            .isolation
            .iter()
            .all(|r| r.excluded == Some(false) && !r.isolated)
    );
    let updates: Vec<&IsolationUpdate> = records
        .iter()
        .filter_map(|r| match r {
            Record::Isolation(u) => Some(u),
            _ => None,
        })
        .collect();
    assert_eq!(updates.len(), 1, "{updates:?}");
    let update = updates[0];
    assert_eq!(update.alarm_k, alarm.k);
    assert!(
        update.k > alarm.k && update.k < 5500,
        "update at {}",
        update.k
    );
    let by_name = |n: &str| update.isolation.iter().find(|r| r.fault == n).unwrap();
    assert_eq!(by_name("phi1").excluded, Some(true));
    assert!(by_name("phi1").minmax > by_name("phi1").threshold);
    assert!(by_name("phi2").isolated && by_name("phi2").excluded == Some(false));
    // The stat records carry [r_FD, σ_FD, r_FI,1, σ_FI,1, r_FI,2, σ_FI,2, x̂…].
    let last = records
        .iter()
        .rev()
        .find_map(|r| match r {
            Record::Stat(s) => Some(s),
            _ => None,
        })
        .unwrap();
    assert_eq!(last.residual.len(), 11);
    alarm.k
}

fn sample(x: &glrmon_sim::SimSample) -> Sample {
    Sample {
        k: Some(x.k),
        t: None,
        u: x.u.clone(),
        y: x.y.clone(),
        p: x.p.clone(),
    }
}

fn alarms(records: &[Record]) -> Vec<&Alarm> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .collect()
}

fn updates(records: &[Record]) -> Vec<&IsolationUpdate> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Isolation(u) => Some(u),
            _ => None,
        })
        .collect()
}

fn isolated(tests: &[IsolationResult]) -> Vec<&str> {
    tests
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.as_str())
        .collect()
}

/// The first `stat` at or after `from` whose l_k exceeds its threshold: the
/// crossing, as the per-sample statistic shows it.
fn first_crossing(records: &[Record], from: u64) -> Option<&Stat> {
    records.iter().find_map(|r| match r {
        Record::Stat(s) if s.k >= from && s.glr.zip(s.threshold).is_some_and(|(l, h)| l > h) => {
            Some(s)
        }
        _ => None,
    })
}

#[test]
fn one_alarm_per_episode_isolating_the_injected_state() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(1, "x0_jump", 201, 4.0).unwrap();
    let mut mon = monitor();
    let mut records = Vec::new();
    for _ in 0..450 {
        mon.on_sample(&sample(&sim.next_sample()), &mut records);
    }
    let alarms = alarms(&records);
    assert_eq!(alarms.len(), 1);
    let a = alarms[0];
    // At the crossing r̂ = 200, where only the x1 jump fits; but a jump of x0 at
    // 201 and of x1 at 200 give the same first innovation: the alarm reports the
    // two ambiguous, and the update, two samples later, resolves it.
    assert_eq!((a.k, a.onset, a.update_k), (201, 200, Some(203)));
    assert!(isolated(&a.isolation).is_empty(), "{:#?}", a.isolation);
    for (fault, rival) in [("x0_jump", "x1_jump"), ("x1_jump", "x0_jump")] {
        let t = a.isolation.iter().find(|t| t.fault == fault).unwrap();
        assert_eq!(t.ambiguous_with, [rival], "{:#?}", a.isolation);
    }
    let updates = updates(&records);
    assert_eq!(updates.len(), 1);
    let u = updates[0];
    assert_eq!((u.k, u.alarm_k, u.onset), (203, 201, 201));
    assert_eq!(isolated(&u.isolation), ["x0_jump"]);
    let ends = records
        .iter()
        .filter(|r| matches!(r, Record::AlarmEnd(_)))
        .count();
    assert_eq!(ends, 1);
    assert_eq!(
        (mon.counters().alarms, mon.counters().isolation_updates),
        (1, 1)
    );
}

/// The `alarm` record (it once arrived `isolation_delay` samples late) is
/// appended by the very sample whose l_k first exceeds λ, right after that
/// sample's `stat`, with its l_k, r̂ and θ̂; the `isolation` record follows exactly
/// `isolation_delay` samples later, names the alarm and isolates the injected state.
#[test]
fn the_alarm_is_published_at_the_crossing_and_the_isolation_delay_later() {
    for (fault, magnitude, delay) in [
        ("x0_jump", 4.0, 2u32),
        ("x1_jump", 1.5, 7),
        ("x0_jump", 4.0, 30),
    ] {
        let sc = scenarios::paper2014_unstable();
        let mut sim = sc.faulty_simulator(4, fault, 201, magnitude).unwrap();
        let mut mon = monitor();
        mon.retune(&Tuning {
            alarm: mon.settings.tuning.alarm,
            episode_end: mon.settings.tuning.episode_end,
            isolation_delay: delay,
            isolation_alpha: 0.01,
            isolation_onsets: 1,
            isolation_thresholds: vec![],
        });
        let mut records = Vec::new();
        // The records each sample appended, by the sample's k.
        let mut by_sample: Vec<Vec<Record>> = Vec::new();
        for _ in 0..450 {
            let mut step = Vec::new();
            mon.on_sample(&sample(&sim.next_sample()), &mut step);
            records.extend(step.iter().cloned());
            by_sample.push(step);
        }
        let crossing = first_crossing(&records, 0).expect("a crossing").clone();
        assert!(
            crossing.k >= 201,
            "{fault}: crossing {} before the fault",
            crossing.k
        );
        let alarms = alarms(&records);
        assert_eq!(alarms.len(), 1, "{fault}: {alarms:#?}");
        let a = alarms[0];
        assert_eq!(a.k, crossing.k, "{fault}: alarm k is the crossing");
        assert_eq!(Some(a.glr), crossing.glr);
        assert_eq!(Some(a.onset), crossing.onset);
        assert_eq!(a.magnitude, crossing.magnitude);
        assert!(a.glr > a.threshold, "{fault}: {} ≤ {}", a.glr, a.threshold);
        assert_eq!(a.update_k, Some(crossing.k + u64::from(delay)));
        let step = &by_sample[crossing.k as usize];
        assert!(
            matches!(step.as_slice(), [Record::Stat(s), Record::Alarm(_)] if s.k == crossing.k),
            "{fault}: {step:#?}"
        );
        let updates = updates(&records);
        assert_eq!(updates.len(), 1, "{fault}: {updates:#?}");
        let u = updates[0];
        assert_eq!(u.k, crossing.k + u64::from(delay), "{fault}");
        assert_eq!(u.alarm_k, a.k);
        assert!(matches!(
            by_sample[u.k as usize].as_slice(),
            [Record::Stat(s), Record::Isolation(_)] if s.k == u.k
        ));
        assert!(
            u.glr >= u.threshold * 0.9,
            "{fault}: episode on at the update"
        );
        assert!(
            isolated(&u.isolation).contains(&fault),
            "{fault}: {:#?}",
            u.isolation
        );
    }
}

/// An episode shorter than the isolation delay: the alarm at the crossing (l_k > λ)
/// is its only isolation; no record comes after its end claiming an alarm, or any
/// isolation, with l_k below the threshold.
#[test]
fn an_episode_shorter_than_the_delay_has_its_alarm_at_the_crossing_and_no_update() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(1, "x0_jump", 201, 4.0).unwrap();
    let mut mon = monitor();
    mon.retune(&Tuning {
        alarm: mon.settings.tuning.alarm,
        episode_end: mon.settings.tuning.episode_end,
        isolation_delay: 1000,
        isolation_alpha: 0.01,
        isolation_onsets: 1,
        isolation_thresholds: vec![],
    });
    let mut records = Vec::new();
    for _ in 0..1500 {
        mon.on_sample(&sample(&sim.next_sample()), &mut records);
    }
    let crossing = first_crossing(&records, 0).expect("a crossing").k;
    let alarms = alarms(&records);
    assert_eq!(alarms.len(), 1, "{alarms:#?}");
    let a = alarms[0];
    assert_eq!((a.k, a.update_k), (crossing, Some(crossing + 1000)));
    assert!(a.glr > a.threshold);
    let end = records
        .iter()
        .find_map(|r| match r {
            Record::AlarmEnd(e) => Some(e),
            _ => None,
        })
        .expect("the episode ends");
    assert!(end.k < crossing + 1000, "end at {}", end.k);
    assert_eq!((end.k - end.duration, end.onset), (a.k, a.onset));
    assert!(updates(&records).is_empty(), "{:#?}", updates(&records));
    assert_eq!(mon.counters().isolation_updates, 0);
}

/// `isolation_delay = 0`: the alarm's isolation is final; nothing is announced.
#[test]
fn without_delay_the_alarm_announces_no_update() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(1, "x0_jump", 201, 4.0).unwrap();
    let mut mon = monitor();
    mon.retune(&Tuning {
        alarm: mon.settings.tuning.alarm,
        episode_end: mon.settings.tuning.episode_end,
        isolation_delay: 0,
        isolation_alpha: 0.01,
        isolation_onsets: 1,
        isolation_thresholds: vec![],
    });
    let mut records = Vec::new();
    for _ in 0..450 {
        mon.on_sample(&sample(&sim.next_sample()), &mut records);
    }
    let alarms = alarms(&records);
    assert_eq!(alarms.len(), 1);
    assert_eq!(alarms[0].k, first_crossing(&records, 0).unwrap().k);
    assert_eq!(alarms[0].update_k, None);
    assert!(updates(&records).is_empty());
}

/// Without `stat` records the monitor emits exactly the other records of a run
/// with them (same alarms, isolation and numbers), and no `stat`.
#[test]
fn turning_stat_records_off_changes_nothing_else() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(1, "x0_jump", 201, 4.0).unwrap();
    let (mut with, mut without) = (monitor(), monitor());
    without.set_stat_records(false);
    let (mut rw, mut ro) = (Vec::new(), Vec::new());
    for _ in 0..450 {
        let s = sample(&sim.next_sample());
        with.on_sample(&s, &mut rw);
        without.on_sample(&s, &mut ro);
    }
    let stats = rw.iter().filter(|r| matches!(r, Record::Stat(_))).count();
    assert_eq!(stats, 450);
    rw.retain(|r| !matches!(r, Record::Stat(_)));
    assert!(rw.iter().any(|r| matches!(r, Record::Alarm(_))));
    assert_eq!(rw, ro);
    assert_eq!(with.counters(), without.counters());
}

#[test]
fn bad_samples_are_rejected_and_leave_the_channel_untouched() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.simulator(3).unwrap();
    let (mut clean, mut dirty) = (monitor(), monitor());
    let (mut rc, mut rd) = (Vec::new(), Vec::new());
    for i in 0..60u64 {
        let x = sim.next_sample();
        let s = sample(&x);
        clean.on_sample(&s, &mut rc);
        if i == 20 {
            let mut bad = s.clone();
            bad.y = vec![1.0, 2.0];
            dirty.on_sample(&bad, &mut rd);
            // `{"y":[..]}` on a channel with an input: u is missing.
            let mut no_u = s.clone();
            no_u.u = Vec::new();
            dirty.on_sample(&no_u, &mut rd);
            let mut nan = s.clone();
            nan.u = vec![f64::NAN];
            dirty.on_sample(&nan, &mut rd);
        }
        dirty.on_sample(&s, &mut rd);
        if i == 30 {
            dirty.on_sample(&s, &mut rd); // duplicate
        }
    }
    let stats = |r: &[Record]| -> Vec<Stat> {
        r.iter()
            .filter_map(|r| {
                if let Record::Stat(s) = r {
                    Some(s.clone())
                } else {
                    None
                }
            })
            .collect()
    };
    assert_eq!(stats(&rc), stats(&rd));
    let codes: Vec<&str> = rd
        .iter()
        .filter_map(|r| {
            if let Record::Error(e) = r {
                Some(e.code.as_str())
            } else {
                None
            }
        })
        .collect();
    assert_eq!(
        codes,
        [
            "wrong_dimension",
            "missing_field",
            "non_finite",
            "duplicate"
        ]
    );
    assert!(rd.iter().any(|r| matches!(r, Record::Error(e) if e.message.contains("field y has 2 values, model expects 1"))));
    assert!(rd.iter().any(|r| matches!(r, Record::Error(e) if e.message.contains("field u is missing or empty (the model has 1 input)"))));
}

#[test]
fn gaps_are_filled_by_predict_only_steps() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.simulator(3).unwrap();
    let mut mon = monitor();
    let mut records = Vec::new();
    for i in 0..100u64 {
        let x = sim.next_sample();
        if (40..43).contains(&i) {
            continue;
        }
        mon.on_sample(&sample(&x), &mut records);
    }
    assert_eq!(mon.counters().gap_samples, 3);
    assert_eq!(mon.counters().samples, 97);
    assert!(
        records
            .iter()
            .any(|r| matches!(r, Record::Error(e) if e.code == ErrorCode::Gap))
    );
    assert_eq!(mon.counters().alarms, 0);
}
/// A gap longer than max_gap (10) in the middle of an alarm episode: the episode
/// ends there (`alarm_end`), the filter restarts at the next sample, and the
/// channel goes on detecting: the same fault later raises a new alarm. Before, the
/// sample after such a gap, and every later one, was dropped.
#[test]
fn a_gap_longer_than_max_gap_restarts_the_filter_and_monitoring_goes_on() {
    let sc = scenarios::paper2014_unstable();
    let mut sim = sc.simulator(3).unwrap();
    let mut mon = monitor();
    let mut records = Vec::new();
    for i in 0..2000u64 {
        let mut x = sim.next_sample();
        if (210..1210).contains(&i) {
            continue;
        }
        if i == 201 || i == 1601 {
            x.y[0] += 4.0;
        }
        mon.on_sample(&sample(&x), &mut records);
    }
    let c = mon.counters();
    assert_eq!(c.restarts, 1);
    assert_eq!(c.samples, 1000);
    let ends: Vec<&AlarmEnd> = records
        .iter()
        .filter_map(|r| match r {
            Record::AlarmEnd(e) => Some(e),
            _ => None,
        })
        .collect();
    let alarms: Vec<&Alarm> = records
        .iter()
        .filter_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .collect();
    assert_eq!(ends.first().map(|e| e.k), Some(1210), "{ends:?}");
    assert!(alarms.iter().any(|a| a.k == 1601), "{alarms:?}");
    assert!(
        records
            .iter()
            .any(|r| matches!(r, Record::Isolation(u) if u.alarm_k == 1601 && u.onset == 1601)),
        "{records:?}"
    );
    assert!(records.iter().any(|r| matches!(r, Record::Error(e)
        if e.code == ErrorCode::Gap && e.k == Some(1210) && e.message.contains("restarts"))));
}

/// A small plant with four step faults; the alarm's diagnosis isolates the
/// injected sensor bias and sizes it. With only m = 4 faults the plateau rule of
/// Zhang 2021 §IV competes with the path's lower end (a run of noise-level supports
/// can be as wide as the true one), hence λ_min/λ_max = 10⁻² and a fault well above
/// the noise (θ = 1, σ = 0.01): 100 of 100 seeds isolate the injected fault then.
const SMALL: &str = r#"
[[channels]]
name = "small"
[channels.model]
F = [[0.5, 0.1], [0.0, 0.6]]
G = [[1.0], [0.0]]
H = [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]
Q = 0.0001
R = 0.0001
[[channels.faults]]
name = "act"
kind = "actuator_bias"
input = 0
[[channels.faults]]
name = "s0"
kind = "sensor_bias"
output = 0
[[channels.faults]]
name = "s1"
kind = "sensor_bias"
output = 1
[[channels.faults]]
name = "s2"
kind = "sensor_bias"
output = 2
[channels.glr]
window = 30
isolation_delay = 15
[channels.diagnosis]
enabled = true
lasso = { ratio = 1e-2 }
"#;

/// The `SMALL` channel simulated with fault `fault` (dictionary index) of magnitude
/// `magnitude` from sample `onset`, input u0 = sin(0.2k).
fn small_sim(
    ch: &glrmon_spec::Channel,
    seed: u64,
    fault: usize,
    magnitude: f64,
    onset: u64,
) -> glrmon_sim::Simulator {
    let theta = (0..ch.fault_names.len())
        .map(|j| if j == fault { magnitude } else { 0.0 })
        .collect::<Vec<f64>>();
    glrmon_sim::Simulator::new(Box::new(ch.model.clone()), ch.x0.clone(), seed)
        .unwrap()
        .with_inputs(Box::new(|k, u: &mut [f64]| u[0] = (0.2 * k as f64).sin()))
        .with_fault(
            ch.dictionary().unwrap(),
            glrmon_sim::Injection {
                magnitude: theta.into(),
                onset,
            },
        )
        .unwrap()
}

fn small_run(text: &str) -> (Monitor, Vec<Record>) {
    let cfg = glrmon_spec::parse(text).unwrap();
    let ch = &cfg.channels[0];
    let mut sim = small_sim(ch, 11, 2, 1.0, 100); // s1
    let mut mon = Monitor::from_channel(ch).unwrap();
    let mut records = Vec::new();
    for _ in 0..200 {
        mon.on_sample(&sample(&sim.next_sample()), &mut records);
    }
    (mon, records)
}

/// A diagnosis follows the alarm at the crossing (over r̂..crossing) and the
/// isolation update 15 samples later (over its r̂..k); the latter isolates the
/// injected fault and sizes it.
#[test]
fn a_diagnosis_follows_the_alarm_and_its_update_and_isolates_the_injected_fault() {
    let (mon, records) = small_run(SMALL);
    let alarm = records
        .iter()
        .position(|r| matches!(r, Record::Alarm(_)))
        .expect("an alarm");
    let Record::Alarm(a) = &records[alarm] else {
        unreachable!()
    };
    let Some(Record::Diagnosis(d)) = records.get(alarm + 1) else {
        panic!(
            "no diagnosis right after the alarm: {:?}",
            records.get(alarm + 1)
        );
    };
    assert_eq!((d.k, d.to, d.from), (a.k, a.k, a.onset));
    let update = records
        .iter()
        .position(|r| matches!(r, Record::Isolation(_)))
        .expect("an isolation update");
    let Record::Isolation(u) = &records[update] else {
        unreachable!()
    };
    assert_eq!((u.alarm_k, u.k), (a.k, a.k + 15));
    let Some(Record::Diagnosis(d)) = records.get(update + 1) else {
        panic!(
            "no diagnosis right after the update: {:?}",
            records.get(update + 1)
        );
    };
    assert_eq!((d.k, d.to, d.from), (u.k, u.k, u.onset));
    assert_eq!(d.channel, "small");
    assert_eq!(d.residual, "kalman");
    assert_eq!(d.support, ["s1"]);
    let est = d.estimate["s1"];
    assert!((est - 1.0).abs() < 0.1, "θ̂ = {est}");
    assert!(d.plateau[0] <= d.lambda && d.lambda <= d.plateau[1]);
    assert!(d.plateau.iter().all(|v| v.is_finite()));
    assert_eq!(d.path_support_sizes.len(), 100);
    assert_eq!(d.path_support_sizes[0], 0);
    let diagnoses = records
        .iter()
        .filter(|r| matches!(r, Record::Diagnosis(_)))
        .count();
    let c = mon.counters();
    assert_eq!(diagnoses as u64, c.alarms + c.isolation_updates);
    assert_eq!(c.diagnoses, c.alarms + c.isolation_updates);
    let errors: Vec<_> = records
        .iter()
        .filter(|r| matches!(r, Record::Error(_)))
        .collect();
    assert!(errors.is_empty(), "{errors:?}");
}

#[test]
fn no_diagnosis_when_disabled() {
    let (mon, records) = small_run(&SMALL.replace("enabled = true", "enabled = false"));
    assert!(mon.diagnosis().is_none());
    assert!(mon.counters().alarms >= 1);
    assert!(!records.iter().any(|r| matches!(r, Record::Diagnosis(_))));
    assert_eq!(mon.counters().diagnoses, 0);
    // The same run without the table at all.
    let text = SMALL.replace(
        "[channels.diagnosis]\nenabled = true\nlasso = { ratio = 1e-2 }\n",
        "",
    );
    assert_ne!(text, SMALL);
    let (_, plain) = small_run(&text);
    assert_eq!(plain, records);
}

/// A gap restarts the residual filter from the detector's prediction; later alarms
/// are still diagnosed.
#[test]
fn diagnosis_survives_a_gap() {
    let cfg = glrmon_spec::parse(SMALL).unwrap();
    let ch = &cfg.channels[0];
    let mut sim = small_sim(ch, 5, 1, -1.0, 120); // s0
    let mut mon = Monitor::from_channel(ch).unwrap();
    let mut records = Vec::new();
    for i in 0..200 {
        let x = sim.next_sample();
        if (50..53).contains(&i) {
            continue;
        }
        mon.on_sample(&sample(&x), &mut records);
    }
    assert_eq!(
        mon.diagnosis().and_then(DiagnosisEngine::held),
        Some((140, 199))
    );
    let d: Vec<&glrmon_wire::Diagnosis> = records
        .iter()
        .filter_map(|r| match r {
            Record::Diagnosis(d) => Some(d),
            _ => None,
        })
        .collect();
    // Every diagnosis spans samples after the gap only; the fault's alarm isolates it.
    assert!(d.iter().all(|d| d.from >= 53), "{d:?}");
    let last = d.last().expect("a diagnosis");
    assert_eq!(
        (last.from, last.support.as_slice()),
        (120, ["s0".to_owned()].as_slice())
    );
    assert!((last.estimate["s0"] + 1.0).abs() < 0.05);
}

/// Assumption (iv) is checked at the base point of H only: when an LPV H loses it
/// (H_kE = 0 while p0 = 1), the detector cannot decouple the unknown input at that
/// sample (Zhang 2021 §III-B): one `error` record says so, the sample is dropped and
/// the filter restarts at the next one (which needs no decoupling: nothing precedes
/// it), and the samples keep flowing. Over k = 30..35 that is every other sample.
#[test]
fn a_decoupling_failure_is_reported_and_the_filter_restarts() {
    let text = r#"
[[channels]]
name = "lpv"
signals = 1
[channels.model]
F = [[0.5, 0.1, 0.0], [0.0, 0.6, 0.1], [0.0, 0.0, 0.7]]
H = { base = [[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]], p0 = [[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }
E = [[1.0], [0.0], [0.0]]
Q = 0.01
R = 0.01
[[channels.faults]]
name = "s0"
kind = "sensor_bias"
output = 0
[channels.diagnosis]
enabled = true
"#;
    let cfg = glrmon_spec::parse(text).unwrap();
    let ch = &cfg.channels[0];
    let mut sim = glrmon_sim::Simulator::new(Box::new(ch.model.clone()), ch.x0.clone(), 3)
        .unwrap()
        .with_signals(Box::new(|k, p: &mut [f64]| {
            p[0] = if (30..36).contains(&k) { 1.0 } else { 0.0 };
        }));
    let mut mon = Monitor::from_channel(ch).unwrap();
    let mut records = Vec::new();
    for _ in 0..80 {
        mon.on_sample(&sample(&sim.next_sample()), &mut records);
    }
    let errors: Vec<&ErrorRecord> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some(e),
            _ => None,
        })
        .collect();
    let ks: Vec<Option<u64>> = errors.iter().map(|e| e.k).collect();
    assert_eq!(ks, [Some(30), Some(32), Some(34)], "{errors:#?}");
    for e in &errors {
        assert!(
            e.message.contains("Assumption (iv)") && e.message.contains("restarts"),
            "{}",
            e.message
        );
    }
    assert_eq!(mon.counters().samples, 77);
    assert_eq!(mon.counters().restarts, 3);
    let held = mon.diagnosis().and_then(DiagnosisEngine::held);
    assert_eq!(held.map(|(_, newest)| newest), Some(79));
    assert!(held.is_some_and(|(oldest, _)| oldest >= 31));
}
