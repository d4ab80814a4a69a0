use super::*;
use glrmon_wire::{Record, encode_sample};

struct NoEvents;
impl RuntimeEvents for NoEvents {
    fn sink_error(&self, _: &SinkError) {}
}

fn demo_monitors() -> (glrmon_spec::Config, Vec<Monitor>) {
    // A long max_gap: every dropped run is filled, none rejected.
    let text = include_str!("../../../config/demo.toml")
        .replace("false_alarm = 1e-4", "false_alarm = 1e-4\nmax_gap = 100000");
    let cfg = glrmon_spec::parse(&text).unwrap();
    let monitors = cfg
        .channels
        .iter()
        .map(|c| Monitor::from_channel(c).unwrap())
        .collect();
    (cfg, monitors)
}

fn payloads(cfg: &glrmon_spec::Config, n: u64) -> Vec<Vec<Vec<u8>>> {
    cfg.channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut sim =
                glrmon_sim::Simulator::new(Box::new(c.model.clone()), c.x0.clone(), i as u64)
                    .unwrap();
            (0..n)
                .map(|_| {
                    let x = sim.next_sample();
                    let s = Sample {
                        k: Some(x.k),
                        t: None,
                        u: x.u,
                        y: x.y,
                        p: x.p,
                    };
                    let mut b = Vec::new();
                    encode_sample(c.name.as_str(), &s, &mut b).unwrap();
                    b
                })
                .collect()
        })
        .collect()
}

/// Results through the runtime equal the monitor run directly, record for record.
#[test]
fn runtime_gives_the_same_records_as_direct_monitoring() {
    let (cfg, monitors) = demo_monitors();
    let data = payloads(&cfg, 400);
    let sink = MemorySink::default();
    let got = sink.records();
    let settings = RuntimeSettings {
        workers: 2,
        worker_queue: 100_000,
        stat_every: 1,
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(
        monitors,
        vec![Box::new(sink)],
        &settings,
        Arc::new(NoEvents),
    );
    let intake = rt.intake();
    for k in 0..400 {
        for (ch, d) in data.iter().enumerate() {
            let offer = intake.offer(
                ch,
                Payload {
                    bytes: d[k].clone(),
                    received: Instant::now(),
                    source_time: None,
                    tag: 0,
                    declared: Declared::Nothing,
                },
            );
            assert_eq!(offer, Offer::Accepted);
        }
    }
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    let (_, mut direct) = demo_monitors();
    for (ch, d) in data.iter().enumerate() {
        let mut want = Vec::new();
        for p in d {
            for s in decode_one(&cfg.channels[ch].name, p).unwrap() {
                direct[ch].on_sample(&s, &mut want);
            }
        }
        let got: Vec<Record> = got
            .lock()
            .unwrap()
            .iter()
            .filter(|o| o.record.channel() == cfg.channels[ch].name)
            .map(|o| o.record.clone())
            .collect();
        assert_eq!(got, want, "channel {ch}");
    }
}

/// A full worker queue drops payloads at intake, counts them per channel, and the
/// channel fills the hole with predict-only steps when samples carry no k.
#[test]
fn full_queue_drops_are_counted_and_become_gaps() {
    let (cfg, monitors) = demo_monitors();
    let data = payloads(&cfg, 2000);
    let settings = RuntimeSettings {
        workers: 1,
        worker_queue: 4,
        stat_every: 0,
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(monitors, vec![], &settings, Arc::new(NoEvents));
    let intake = rt.intake();
    let stats = rt.stats();
    let mut dropped = 0;
    let mut accepted = 0;
    // The DC motor (channel 1): stable in open loop, like the payloads fed here. Bursts
    // of 10 into a queue of 4 drop some of each burst; the producer then waits (on the
    // condition, not on time) until the worker has caught up, so drops and accepted
    // payloads interleave.
    for burst in data[1].chunks(10) {
        for p in burst {
            // Strip k so that the runtime's drop accounting is what reveals the gaps.
            let s = String::from_utf8(p.clone()).unwrap();
            let without_k = s.replacen(r#""k":"#, r#""ignored":"#, 1);
            let json = without_k
                .split_once(',')
                .map(|(_, rest)| format!("{{{rest}"))
                .unwrap();
            match intake.offer(
                1,
                Payload {
                    bytes: json.into_bytes(),
                    received: Instant::now(),
                    source_time: None,
                    tag: 0,
                    declared: Declared::Nothing,
                },
            ) {
                Offer::Dropped => dropped += 1,
                Offer::Accepted => accepted += 1,
                other => panic!("{other:?}"),
            }
        }
        while stats[1].samples.load(Ordering::Relaxed) < accepted {
            std::thread::yield_now();
        }
    }
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    assert!(dropped > 0, "the flood must overflow a queue of 4");
    let st = &stats[1];
    assert_eq!(st.dropped.load(Ordering::Relaxed), dropped);
    let processed = st.samples.load(Ordering::Relaxed);
    let errors = st.errors.lock().unwrap().clone();
    assert_eq!(
        processed + dropped,
        2000,
        "every payload is either processed or counted as dropped: {errors:?}"
    );
    // Every drop followed by an accepted payload becomes a filled gap at its place.
    let gaps = errors.get("gap").copied().unwrap_or(0);
    assert!(
        gaps > 0 || processed < 2,
        "{errors:?} dropped {dropped} processed {processed}"
    );
    assert_eq!(
        errors.keys().filter(|k| **k != "gap").count(),
        0,
        "{errors:?}"
    );
}

#[test]
fn oversized_payloads_and_unknown_channels_are_refused() {
    let (_, monitors) = demo_monitors();
    let settings = RuntimeSettings {
        limits: DecodeLimits {
            max_payload_bytes: 100,
            ..DecodeLimits::default()
        },
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(monitors, vec![], &settings, Arc::new(NoEvents));
    let intake = rt.intake();
    let big = Payload {
        bytes: vec![b' '; 101],
        received: Instant::now(),
        source_time: None,
        tag: 0,
        declared: Declared::Nothing,
    };
    assert_eq!(intake.offer(0, big), Offer::TooLarge);
    let p = Payload {
        bytes: b"{}".to_vec(),
        received: Instant::now(),
        source_time: None,
        tag: 0,
        declared: Declared::Nothing,
    };
    assert_eq!(intake.offer(99, p), Offer::UnknownChannel);
    let stats = rt.stats();
    let (_, _) = rt.shutdown(Duration::from_secs(5));
    assert_eq!(stats[0].errors.lock().unwrap().get("too_large"), Some(&1));
    let p = Payload {
        bytes: b"{}".to_vec(),
        received: Instant::now(),
        source_time: None,
        tag: 0,
        declared: Declared::Nothing,
    };
    assert_eq!(intake.offer(0, p), Offer::Closed);
}

/// A sink that blocks on its first record until the sender sends (or is dropped), and
/// the kinds of the records it wrote, in order.
#[allow(clippy::type_complexity)]
fn stalled_sink() -> (
    Box<dyn Sink>,
    std::sync::mpsc::Sender<()>,
    Arc<Mutex<Vec<&'static str>>>,
) {
    let (release_tx, release_rx) = std::sync::mpsc::channel::<()>();
    let release_rx = Mutex::new(release_rx);
    let written: Arc<Mutex<Vec<&'static str>>> = Arc::default();
    let w = written.clone();
    let sink = crate::FnSink::new("stall", move |o: &crate::Output| {
        let mut w = w.lock().unwrap();
        if w.is_empty() {
            let _ = release_rx.lock().unwrap().recv();
        }
        w.push(o.record.kind_str());
    });
    (Box::new(sink), release_tx, written)
}

/// Intake memory is bounded in bytes. One publisher of 1 MiB payloads
/// used to grow the daemon from 140 MB to 2.9 GB (4096 payloads per worker); with the
/// worker's queue limited to 3 MiB, a stalled worker holds at most 3 MiB of payloads,
/// the rest are dropped and counted, and the bytes are given back as they are taken.
#[test]
fn intake_memory_is_bounded_in_bytes() {
    let (_, monitors) = demo_monitors();
    // The output queue fills behind the stalled sink, then the worker stalls, then its
    // intake queue fills.
    let (sink, release_tx, _) = stalled_sink();
    let settings = RuntimeSettings {
        workers: 1,
        worker_queue: 4096,
        worker_queue_bytes: 3 << 20,
        intake_bytes: 256 << 20,
        output_queue: 16,
        limits: DecodeLimits {
            max_payload_bytes: 2 << 20,
            ..DecodeLimits::default()
        },
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(monitors, vec![sink], &settings, Arc::new(NoEvents));
    let intake = rt.intake();
    let metrics = rt.metrics();
    let (mut accepted, mut dropped, mut most) = (0u64, 0u64, 0i64);
    // Not JSON: each payload becomes one error record, so 8 + 1 of them (the urgent
    // half of output_queue, and the one in hand) stall the worker behind the blocked
    // sink; then the queue holds what 3 MiB allow.
    for _ in 0..200 {
        let offer = intake.offer(
            0,
            Payload {
                bytes: vec![b'x'; 1 << 20],
                received: Instant::now(),
                source_time: None,
                tag: 0,
                declared: Declared::Nothing,
            },
        );
        match offer {
            Offer::Accepted => accepted += 1,
            Offer::Dropped => dropped += 1,
            other => panic!("{other:?}"),
        }
        most = most.max(metrics.queued_bytes.load(Ordering::Relaxed));
    }
    assert!(most <= 3 << 20, "{most} bytes queued");
    assert!(dropped >= 150, "accepted {accepted}, dropped {dropped}");
    let stats = rt.stats();
    assert_eq!(stats[0].dropped.load(Ordering::Relaxed), dropped);
    release_tx.send(()).unwrap();
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    assert_eq!(metrics.queued_bytes.load(Ordering::Relaxed), 0);
}

/// Records that must arrive overtake the statistics queued before them: with the sink
/// stalled on the first `stat`, 300 more `stat` records and then an `error` record
/// queue up; once released, the `error` is written right after the record in hand,
/// before the 300 `stat` records queued ahead of it, and nothing is lost.
#[test]
fn urgent_records_overtake_queued_statistics() {
    let (cfg, monitors) = demo_monitors();
    let data = payloads(&cfg, 301);
    let (sink, release_tx, written) = stalled_sink();
    let settings = RuntimeSettings {
        workers: 1,
        output_queue: 4096,
        stat_every: 1,
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(monitors, vec![sink], &settings, Arc::new(NoEvents));
    let intake = rt.intake();
    let payload = |bytes: Vec<u8>| Payload {
        bytes,
        received: Instant::now(),
        source_time: None,
        tag: 0,
        declared: Declared::Nothing,
    };
    for bytes in &data[0] {
        assert_eq!(intake.offer(0, payload(bytes.clone())), Offer::Accepted);
    }
    assert_eq!(
        intake.offer(0, payload(b"not json".to_vec())),
        Offer::Accepted
    );
    let stats = rt.stats();
    let deadline = Instant::now() + Duration::from_secs(30);
    while stats[0].errors.lock().unwrap().values().sum::<u64>() == 0 {
        assert!(Instant::now() < deadline, "the worker did not finish");
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(stats[0].samples.load(Ordering::Relaxed), 301);
    release_tx.send(()).unwrap();
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    let written = written.lock().unwrap();
    assert_eq!(written.len(), 302, "every record written");
    assert_eq!(written.iter().filter(|k| **k == "stat").count(), 301);
    let error_at = written.iter().position(|k| *k == "error").unwrap();
    // The stalled `stat`, at most one more taken before the error arrived, then it.
    assert!(error_at <= 2, "error written at position {error_at}");
}

/// A released channel's payloads are not taken (`Offer::Idle`, not counted as drops)
/// and it leaves the status; taken again, its monitor resumes before the next payload:
/// its records then equal those of a monitor resumed by hand and fed the same samples.
#[test]
fn a_released_channel_is_idle_and_resumes_when_taken() {
    let (cfg, monitors) = demo_monitors();
    let data = payloads(&cfg, 600);
    let sink = MemorySink::default();
    let got = sink.records();
    let settings = RuntimeSettings {
        workers: 1,
        worker_queue: 100_000,
        stat_every: 1,
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(
        monitors,
        vec![Box::new(sink)],
        &settings,
        Arc::new(NoEvents),
    );
    let (intake, switch) = (rt.intake(), rt.switch());
    let offer = |k: usize| {
        intake.offer(
            0,
            Payload {
                bytes: data[0][k].clone(),
                received: Instant::now(),
                source_time: None,
                tag: 0,
                declared: Declared::Nothing,
            },
        )
    };
    for k in 0..200 {
        assert_eq!(offer(k), Offer::Accepted);
    }
    assert!(switch.release(0));
    assert!(!switch.release(0), "released once");
    assert!(!switch.is_monitored(0));
    for k in 200..400 {
        assert_eq!(offer(k), Offer::Idle);
    }
    assert_eq!(rt.stats()[0].dropped.load(Ordering::Relaxed), 0);
    assert!(
        rt.channel_statuses()
            .iter()
            .all(|c| c.channel != cfg.channels[0].name)
    );
    let instance: Arc<str> = Arc::from("b");
    assert!(switch.take(0, &instance, 2));
    assert!(!switch.take(0, &instance, 2), "taken once");
    for k in 400..600 {
        assert_eq!(offer(k), Offer::Accepted);
    }
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);

    let (_, mut direct) = demo_monitors();
    let mut want = Vec::new();
    let feed = |m: &mut Monitor, range: std::ops::Range<usize>, out: &mut Vec<Record>| {
        for k in range {
            for s in decode_one(&cfg.channels[0].name, &data[0][k]).unwrap() {
                m.on_sample(&s, out);
            }
        }
    };
    feed(&mut direct[0], 0..200, &mut want);
    direct[0].resume().unwrap();
    feed(&mut direct[0], 400..600, &mut want);
    let got: Vec<Record> = got
        .lock()
        .unwrap()
        .iter()
        .filter(|o| o.record.channel() == cfg.channels[0].name)
        .map(|o| o.record.clone())
        .collect();
    assert_eq!(got.len(), want.len());
    assert_eq!(got, want);
    // The resumption restarted the filter: no gap was reported for the 200 samples
    // another instance saw.
    assert!(!got.iter().any(|r| matches!(r, Record::Error(_))));
}
