//! End-to-end load benchmark: N bench-A channels (LPV n = 2, p = 1, m = 2, w = 100)
//! published through Zenoh on loopback to the daemon's runtime, as fast as the
//! publisher can go. Reports sustained samples/s, drops, alarm latency (publish of the
//! batch holding the alarm's sample → alarm received) and memory per channel.
//!
//! `cargo run --release -p glrmon-zenoh --example bench_e2e -- --channels 1000 --samples 300 --batch 10`

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_monitor::Monitor;
use glrmon_runtime::{Runtime, RuntimeEvents, RuntimeSettings, SinkError};
use glrmon_wire::{Record, Sample, decode_record, encode_samples};
use glrmon_zenoh::{SessionSettings, ZenohSink, ZenohSource};
use zenoh::Wait as _;

struct Quiet;
impl RuntimeEvents for Quiet {
    fn sink_error(&self, e: &SinkError) {
        eprintln!("sink error: {e}");
    }
}

fn arg(name: &str, default: u64) -> u64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        })
        .unwrap_or(0)
}

const CHANNEL: &str = r#"
[[channels]]
name = "NAME"
signals = 1
[channels.model]
F = { base = [[0.8, 0.1], [-0.2, 0.7]], p0 = [[0.05, 0.0], [0.0, -0.05]] }
G = [[1.0], [0.5]]
H = { base = [[1.0, 0.0]], p0 = [[0.0, 0.1]] }
Q = 0.01
R = 0.04
[[channels.faults]]
name = "actuator_bias"
kind = "actuator_bias"
input = 0
[[channels.faults]]
name = "sensor_bias"
kind = "sensor_bias"
output = 0
[channels.glr]
window = 100
false_alarm = 1e-4
[channels.simulation]
inputs = ["sin(0.05*k)"]
signals = ["sin(0.01*k)"]
"#;

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let channels = arg("--channels", 100) as usize;
    let samples = arg("--samples", 1000);
    let batch = arg("--batch", 10).max(1) as usize;
    let workers = arg("--workers", 2) as usize;
    let faulty_every = arg("--faulty-every", 10) as usize;
    // Target total rate in samples/s (0: as fast as the publisher can go).
    let rate = arg("--rate", 0) as f64;
    let onset = samples / 2;

    let text: String = (0..channels)
        .map(|i| CHANNEL.replace("NAME", &format!("ch{i}")))
        .collect();
    let cfg = glrmon_spec::parse(&text).expect("config");
    let rss0 = rss_kib();
    let monitors: Vec<Monitor> = cfg
        .channels
        .iter()
        .map(|c| Monitor::from_channel(c).expect("monitor"))
        .collect();
    let rss1 = rss_kib();

    // Data: bench-A simulated; every `faulty_every`-th channel gets a sensor bias of 1.0.
    let payloads = payloads(&cfg, samples, batch, faulty_every, onset);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let daemon = glrmon_zenoh::open(&SessionSettings {
        mode: Some("peer".into()),
        listen: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .expect("daemon session");
    let settings = RuntimeSettings {
        workers,
        stat_every: 0,
        ..RuntimeSettings::default()
    };
    let (sinks, recorder_stats) = sinks(&daemon, &cfg);
    let runtime = Runtime::start(monitors, sinks, &settings, Arc::new(Quiet));
    let keys: Vec<Vec<String>> = cfg
        .channels
        .iter()
        .map(glrmon_spec::Channel::input_keys)
        .collect();
    let _source = ZenohSource::declare(&daemon, &keys, &runtime.intake())
        .await
        .expect("source");

    let plant = glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .expect("plant session");
    let received: Arc<Mutex<Vec<(String, u64, Instant)>>> = Arc::default();
    let r = received.clone();
    let _alarms = plant
        .declare_subscriber("glrmon/*/alarm")
        .callback(move |s| {
            if let Ok(Record::Alarm(a)) = decode_record(&s.payload().to_bytes()) {
                r.lock().unwrap().push((a.channel, a.k, Instant::now()));
            }
        })
        .await
        .expect("alarm subscriber");
    let publishers = publishers(&plant, &keys.concat()).await;
    // Publish round-robin over channels, one batch at a time.
    let mut sent_at: HashMap<(usize, u64), Instant> = HashMap::new();
    let start = Instant::now();
    let batches = payloads[0].len();
    let round = Duration::from_secs_f64(if rate > 0.0 {
        (channels * batch) as f64 / rate
    } else {
        0.0
    });
    for b in 0..batches {
        if rate > 0.0 {
            let due = start + round * b as u32;
            while Instant::now() < due {
                std::hint::spin_loop();
                if due.saturating_duration_since(Instant::now()) > Duration::from_millis(2) {
                    tokio::time::sleep(Duration::from_millis(1)).await;
                }
            }
        }
        for (i, (p, channel)) in publishers.iter().zip(&payloads).enumerate() {
            let (last_k, bytes) = &channel[b];
            p.put(bytes.clone()).wait().expect("put");
            if i % faulty_every == 0 && *last_k >= onset {
                sent_at.insert((i, *last_k), Instant::now());
            }
        }
    }
    let published = start.elapsed();
    let stats = runtime.stats();
    let finished = settled(&stats).await;
    let elapsed = finished.duration_since(start);
    let processed: u64 = stats
        .iter()
        .map(|s| s.samples.load(Ordering::Relaxed))
        .sum();
    let dropped: u64 = stats
        .iter()
        .map(|s| s.dropped.load(Ordering::Relaxed))
        .sum();
    let alarms = received.lock().unwrap().clone();
    let lat = latencies_ms(&alarms, &sent_at, batch as u64, samples);
    let pct = |p: f64| {
        lat.get(((lat.len() as f64 - 1.0) * p).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let expected_alarms = (0..channels).filter(|i| i % faulty_every == 0).count();
    println!(
        "channels={channels} samples/channel={samples} batch={batch} workers={workers} target rate={rate} samples/s: \
         {processed} samples processed in {:.3} s = {:.0} samples/s (publishing took {:.3} s), \
         dropped payloads={dropped}, alarms {}/{expected_alarms}, alarm latency p50={:.2} ms p99={:.2} ms, \
         memory per channel ≈ {:.1} KiB (RSS {} → {} KiB for the monitors)",
        elapsed.as_secs_f64(),
        processed as f64 / elapsed.as_secs_f64(),
        published.as_secs_f64(),
        alarms.len(),
        pct(0.5),
        pct(0.99),
        (rss1.saturating_sub(rss0)) as f64 / channels as f64,
        rss0,
        rss1
    );
    let (_, sinks) = runtime.shutdown(Duration::from_secs(60));
    drop(sinks);
    if let Some(stats) = recorder_stats {
        report_recording(&stats);
    }
}

/// Each channel's samples as JSON batches of `batch`, with the last k of each batch;
/// every `faulty_every`-th channel has a sensor bias of 1.0 from `onset`.
fn payloads(
    cfg: &glrmon_spec::Config,
    samples: u64,
    batch: usize,
    faulty_every: usize,
    onset: u64,
) -> Vec<Vec<(u64, Vec<u8>)>> {
    let channels = cfg.channels.len();
    let sc = glrmon_sim::scenarios::bench_a();
    let mut payloads: Vec<Vec<(u64, Vec<u8>)>> = Vec::with_capacity(channels);
    for (i, c) in cfg.channels.iter().enumerate() {
        let mut sim = if i % faulty_every == 0 {
            sc.faulty_simulator(i as u64, "sensor_bias", onset, 1.0)
                .expect("sim")
        } else {
            sc.simulator(i as u64).expect("sim")
        };
        let all: Vec<Sample> = (0..samples)
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
        payloads.push(
            all.chunks(batch)
                .map(|b| {
                    let mut buf = Vec::new();
                    encode_samples(&c.name, b, &mut buf).expect("encode");
                    (b.last().and_then(|s| s.k).unwrap_or(0), buf)
                })
                .collect(),
        );
    }
    payloads
}

/// A publisher per key, each waiting until the daemon's subscriber matches it.
async fn publishers(
    plant: &zenoh::Session,
    keys: &[String],
) -> Vec<zenoh::pubsub::Publisher<'static>> {
    let mut publishers = Vec::new();
    for key in keys {
        let p = plant
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .await
            .expect("publisher");
        while !p
            .matching_status()
            .await
            .map(|m| m.matching())
            .unwrap_or(false)
        {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        publishers.push(p);
    }
    publishers
}

/// When the channels' counters stopped moving (every payload processed, dropped or
/// rejected), after 500 ms without change.
async fn settled(stats: &[Arc<glrmon_runtime::ChannelStats>]) -> Instant {
    let progress = || -> u64 {
        stats
            .iter()
            .map(|s| {
                s.samples.load(Ordering::Relaxed)
                    + s.dropped.load(Ordering::Relaxed)
                    + s.errors
                        .lock()
                        .map(|e| e.values().sum::<u64>())
                        .unwrap_or(0)
            })
            .sum()
    };
    let mut last = (progress(), Instant::now());
    let mut finished = Instant::now();
    while last.1.elapsed() < Duration::from_millis(500) {
        tokio::time::sleep(Duration::from_millis(1)).await;
        let now = progress();
        if now != last.0 {
            last = (now, Instant::now());
            finished = Instant::now();
        }
    }
    finished
}

/// Each alarm's latency in ms, from the publication of the batch holding its sample.
fn latencies_ms(
    alarms: &[(String, u64, Instant)],
    sent_at: &HashMap<(usize, u64), Instant>,
    batch: u64,
    samples: u64,
) -> Vec<f64> {
    let mut lat: Vec<f64> = alarms
        .iter()
        .filter_map(|(ch, k, at)| {
            let i: usize = ch.trim_start_matches("ch").parse().ok()?;
            // The batch holding sample k was published at sent_at[(i, last k of that batch)].
            let last = ((k / batch) + 1) * batch - 1;
            let sent = sent_at.get(&(i, last.min(samples - 1)))?;
            Some(at.duration_since(*sent).as_secs_f64() * 1e3)
        })
        .collect();
    lat.sort_by(f64::total_cmp);
    lat
}

/// What the recorder wrote.
fn report_recording(stats: &glrmon_record::RecorderStats) {
    let files = stats.finished.lock().unwrap().clone();
    let bytes: u64 = files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    println!(
        "recorded {} messages in {} file(s), {:.1} MB ({:.1} bytes per message)",
        stats.messages.load(Ordering::Relaxed),
        files.len(),
        bytes as f64 / 1e6,
        bytes as f64 / stats.messages.load(Ordering::Relaxed).max(1) as f64
    );
}

/// The Zenoh publisher sink and, with `--record DIR`, a recorder of every input and
/// stat to MCAP, as `glrmon run` has.
fn sinks(
    daemon: &zenoh::Session,
    cfg: &glrmon_spec::Config,
) -> (
    Vec<Box<dyn glrmon_runtime::Sink>>,
    Option<Arc<glrmon_record::RecorderStats>>,
) {
    let mut sinks: Vec<Box<dyn glrmon_runtime::Sink>> =
        vec![Box::new(ZenohSink::new(daemon.clone()))];
    // `--record DIR`: also record every input and stat to MCAP, as `glrmon run` does.
    let record_dir = {
        let args: Vec<String> = std::env::args().collect();
        args.iter()
            .position(|a| a == "--record")
            .and_then(|i| args.get(i + 1).cloned())
    };
    let mut recorder_stats = None;
    if let Some(dir) = &record_dir {
        let recorder = glrmon_record::Recorder::start(
            glrmon_record::RecorderSettings {
                directory: dir.into(),
                prefix: "bench".into(),
                ..glrmon_record::RecorderSettings::default()
            },
            glrmon_record::FileHeader {
                config: cfg.source.clone(),
                channels: cfg.channels.iter().map(|c| c.name.clone()).collect(),
                extra: std::collections::BTreeMap::new(),
            },
        )
        .expect("recorder");
        recorder_stats = Some(recorder.stats());
        sinks.push(Box::new(recorder));
    }
    (sinks, recorder_stats)
}
