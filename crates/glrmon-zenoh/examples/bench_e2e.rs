//! End-to-end load benchmark: N bench-A channels (LPV n = 2, p = 1, m = 2, w = 100)
//! published through Zenoh on loopback to the daemon's runtime, publisher and daemon in
//! one process on this machine's cores.
//!
//! For each rate of `--rates` (samples/s over all channels; 0: as fast as the publisher
//! can go) it runs two phases on the same payloads, each with fresh sessions:
//! - **zenoh**: Zenoh alone, a subscriber per key that only counts: the transport's own
//!   throughput and one-way latency for these payload sizes, the ceiling for glrmon;
//! - **glrmon**: the daemon's runtime (Zenoh source, workers, Zenoh sink, and a recorder
//!   with `--record DIR`): sustained samples/s, drops, alarms (detected faults, false
//!   alarms, repeats), alarm latency (publication of the sample → alarm received by a
//!   subscriber) and alarm delivery (receipt → written by every sink, the runtime's
//!   histogram).
//!
//! Every `--faulty-every`-th channel gets a sensor bias of 1.0 (5 σ of its noise) at
//! the middle sample; `--faulty-every 1 --stat-every 1 --record DIR` is the plant-wide
//! burst: every channel alarmed at once, every statistic published and recorded.
//!
//! ```text
//! cargo run --release -p glrmon-zenoh --example bench_e2e -- --channels 100 --samples 5000 --batch 1 --rates 0,500000
//! cargo run --release -p glrmon-zenoh --example bench_e2e -- --channels 1000 --samples 300 --batch 1 --rates 5000 \
//!     --faulty-every 1 --stat-every 1 --record /tmp/rec
//! ```

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_monitor::Monitor;
use glrmon_runtime::{
    LATENCY_BUCKETS, LatencyHistogram, Runtime, RuntimeEvents, RuntimeSettings, SinkError,
};
use glrmon_wire::{Record, Sample, decode_record, encode_samples};
use glrmon_zenoh::{SessionSettings, ZenohSink, ZenohSource};
use zenoh::Wait as _;
use zenoh::bytes::ZBytes;

/// The allocator of the `glrmon` binary, so that the runtime is measured as it runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

struct Quiet;
impl RuntimeEvents for Quiet {
    fn sink_error(&self, e: &SinkError) {
        eprintln!("sink error: {e}");
    }
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn arg_u64(name: &str, default: u64) -> u64 {
    arg(name).and_then(|v| v.parse().ok()).unwrap_or(default)
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
false_alarm = ALPHA
[channels.simulation]
inputs = ["sin(0.05*k)"]
signals = ["sin(0.01*k)"]
"#;

/// What the run is asked for.
struct Plan {
    channels: usize,
    samples: u64,
    batch: usize,
    workers: usize,
    faulty_every: usize,
    onset: u64,
    stat_every: u64,
    alpha: f64,
    record: Option<String>,
}

/// Each channel's payloads: (first k, last k, bytes) per batch.
type Payloads = Vec<Vec<(u64, u64, ZBytes)>>;

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let samples = arg_u64("--samples", 1000);
    let plan = Plan {
        channels: arg_u64("--channels", 100) as usize,
        samples,
        batch: arg_u64("--batch", 10).max(1) as usize,
        workers: arg_u64("--workers", 2) as usize,
        faulty_every: arg_u64("--faulty-every", 10).max(1) as usize,
        onset: samples / 2,
        stat_every: arg_u64("--stat-every", 0),
        alpha: arg("--false-alarm")
            .and_then(|v| v.parse().ok())
            .unwrap_or(1e-7),
        record: arg("--record"),
    };
    let rates: Vec<f64> = arg("--rates")
        .or_else(|| arg("--rate"))
        .unwrap_or_else(|| "0".into())
        .split(',')
        .filter_map(|r| r.trim().parse().ok())
        .collect();
    let text: String = (0..plan.channels)
        .map(|i| {
            CHANNEL
                .replace("NAME", &format!("ch{i}"))
                .replace("ALPHA", &format!("{:e}", plan.alpha))
        })
        .collect();
    let cfg = glrmon_spec::parse(&text).expect("config");
    let payloads = payloads(&cfg, &plan);
    let bytes: usize = payloads.iter().flatten().map(|(_, _, b)| b.len()).sum();
    let messages: usize = payloads.iter().map(Vec::len).sum();
    println!(
        "{} channels × {} samples in batches of {} ({} messages, {:.0} bytes each on average), \
         faults on every {}th channel from k = {}, false_alarm = {:e}, stat_every = {}, recording {}",
        plan.channels,
        plan.samples,
        plan.batch,
        messages,
        bytes as f64 / messages as f64,
        plan.faulty_every,
        plan.onset,
        plan.alpha,
        plan.stat_every,
        plan.record.as_deref().unwrap_or("off"),
    );
    for rate in rates {
        if !std::env::args().any(|a| a == "--no-zenoh") {
            zenoh_alone(&cfg, &payloads, &plan, rate).await;
        }
        glrmon(&cfg, &payloads, &plan, rate).await;
    }
}

/// A free loopback endpoint.
fn endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

/// The daemon's side (a peer listening on loopback) and the plant's (a client).
async fn sessions() -> (zenoh::Session, zenoh::Session) {
    let endpoint = endpoint();
    let daemon = glrmon_zenoh::open(&SessionSettings {
        mode: Some("peer".into()),
        listen: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .expect("daemon session");
    let plant = glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .expect("plant session");
    (daemon, plant)
}

/// Publishes every payload round-robin over the channels, one batch of each channel per
/// round, `rate` samples/s over all channels (0: as fast as the publisher can go); the
/// publisher sleeps when it is ahead, as a plant's would. Returns each message's
/// publication time since `start`, by channel and batch, and how long it took.
fn publish(
    publishers: &[zenoh::pubsub::Publisher<'static>],
    payloads: &Payloads,
    plan: &Plan,
    rate: f64,
    start: Instant,
) -> (Vec<Vec<u64>>, Duration) {
    let batches = payloads[0].len();
    let mut sent = vec![vec![0u64; batches]; payloads.len()];
    let round = if rate > 0.0 {
        (payloads.len() * plan.batch) as f64 / rate
    } else {
        0.0
    };
    for b in 0..batches {
        if rate > 0.0 {
            let due = start + Duration::from_secs_f64(round * b as f64);
            let ahead = due.saturating_duration_since(Instant::now());
            if ahead > Duration::from_micros(200) {
                std::thread::sleep(ahead);
            }
        }
        for (i, (p, channel)) in publishers.iter().zip(payloads).enumerate() {
            p.put(channel[b].2.clone()).wait().expect("put");
            sent[i][b] = ns_since(start);
        }
    }
    (sent, start.elapsed())
}

fn ns_since(start: Instant) -> u64 {
    u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// Percentile `p` of sorted values.
fn pct(sorted: &[f64], p: f64) -> f64 {
    sorted
        .get(((sorted.len() as f64 - 1.0) * p).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// Zenoh alone: the same publishers and payloads, a subscriber per key that records the
/// receipt time of each message.
async fn zenoh_alone(cfg: &glrmon_spec::Config, payloads: &Payloads, plan: &Plan, rate: f64) {
    let (daemon, plant) = sessions().await;
    let keys = keys(cfg);
    let batches = payloads[0].len();
    let received: Arc<Vec<Vec<AtomicU64>>> = Arc::new(
        (0..payloads.len())
            .map(|_| (0..batches).map(|_| AtomicU64::new(0)).collect())
            .collect(),
    );
    let start = Instant::now() + Duration::from_secs(3600);
    let start = Arc::new(Mutex::new(start));
    let mut subscribers = Vec::new();
    for (i, key) in keys.iter().flatten().enumerate() {
        let received = received.clone();
        let start = start.clone();
        let next = AtomicU64::new(0);
        subscribers.push(
            daemon
                .declare_subscriber(key.as_str())
                .callback(move |s| {
                    let _bytes = s.payload().to_bytes();
                    let b = next.fetch_add(1, Ordering::Relaxed) as usize;
                    let t0 = *start.lock().unwrap();
                    if let Some(slot) = received[i].get(b) {
                        slot.store(
                            u64::try_from(Instant::now().saturating_duration_since(t0).as_nanos())
                                .unwrap_or(0),
                            Ordering::Relaxed,
                        );
                    }
                })
                .await
                .expect("subscriber"),
        );
    }
    let publishers = publishers(&plant, &keys.concat()).await;
    let t0 = Instant::now();
    *start.lock().unwrap() = t0;
    let (sent, published) = publish(&publishers, payloads, plan, rate, t0);
    let total: u64 = received.iter().map(|c| c.len() as u64).sum();
    let arrived = || {
        received
            .iter()
            .flatten()
            .filter(|r| r.load(Ordering::Relaxed) > 0)
            .count() as u64
    };
    let wait = Instant::now();
    while arrived() < total && wait.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    let last = received
        .iter()
        .flatten()
        .map(|r| r.load(Ordering::Relaxed))
        .max()
        .unwrap_or(0);
    let mut lat: Vec<f64> = received
        .iter()
        .zip(&sent)
        .flat_map(|(r, s)| r.iter().zip(s))
        .filter(|(r, _)| r.load(Ordering::Relaxed) > 0)
        .map(|(r, s)| r.load(Ordering::Relaxed).saturating_sub(*s) as f64 / 1e6)
        .collect();
    lat.sort_by(f64::total_cmp);
    let secs = last as f64 / 1e9;
    println!(
        "zenoh  rate={rate}: {} of {total} messages in {secs:.3} s = {:.0} messages/s = {:.0} samples/s \
         (publishing took {:.3} s), latency p50={:.3} ms p99={:.3} ms",
        arrived(),
        arrived() as f64 / secs,
        (arrived() as usize * plan.batch) as f64 / secs,
        published.as_secs_f64(),
        pct(&lat, 0.5),
        pct(&lat, 0.99),
    );
    drop(subscribers);
    let _ = plant.close().await;
    let _ = daemon.close().await;
}

/// Each channel's input keys.
fn keys(cfg: &glrmon_spec::Config) -> Vec<Vec<String>> {
    cfg.channels
        .iter()
        .map(glrmon_spec::Channel::input_keys)
        .collect()
}

/// glrmon: the daemon's runtime between the Zenoh source and sinks.
async fn glrmon(cfg: &glrmon_spec::Config, payloads: &Payloads, plan: &Plan, rate: f64) {
    let rss0 = rss_kib();
    let monitors: Vec<Monitor> = cfg
        .channels
        .iter()
        .map(|c| Monitor::from_channel(c).expect("monitor"))
        .collect();
    let rss1 = rss_kib();
    let (daemon, plant) = sessions().await;
    let settings = RuntimeSettings {
        workers: plan.workers,
        stat_every: plan.stat_every,
        ..RuntimeSettings::default()
    };
    let (sinks, recorder_stats) = sinks(&daemon, cfg, plan);
    let runtime = Runtime::start(monitors, sinks, &settings, Arc::new(Quiet));
    let keys = keys(cfg);
    let source = ZenohSource::declare(&daemon, &keys, &runtime.intake())
        .await
        .expect("source");
    let received: Arc<Mutex<Vec<(String, u64, u64)>>> = Arc::default();
    let start = Arc::new(Mutex::new(Instant::now() + Duration::from_secs(3600)));
    let (r, t0) = (received.clone(), start.clone());
    let alarms_sub = plant
        .declare_subscriber("glrmon/*/alarm")
        .callback(move |s| {
            if let Ok(Record::Alarm(a)) = decode_record(&s.payload().to_bytes()) {
                let at = Instant::now().saturating_duration_since(*t0.lock().unwrap());
                r.lock()
                    .unwrap()
                    .push((a.channel, a.k, u64::try_from(at.as_nanos()).unwrap_or(0)));
            }
        })
        .await
        .expect("alarm subscriber");
    // Error records by code (gaps, restarts, refusals), and their first messages.
    let errors: Arc<Mutex<std::collections::BTreeMap<String, u64>>> = Arc::default();
    let e = errors.clone();
    let errors_sub = plant
        .declare_subscriber("glrmon/*/error")
        .callback(move |s| {
            if let Ok(Record::Error(r)) = decode_record(&s.payload().to_bytes()) {
                *e.lock()
                    .unwrap()
                    .entry(r.code.as_str().to_owned())
                    .or_default() += 1;
            }
        })
        .await
        .expect("error subscriber");
    let publishers = publishers(&plant, &keys.concat()).await;
    let begin = Instant::now();
    *start.lock().unwrap() = begin;
    let (sent, published) = publish(&publishers, payloads, plan, rate, begin);
    let stats = runtime.stats();
    let finished = settled(&stats).await;
    let elapsed = finished.duration_since(begin);
    let processed: u64 = stats
        .iter()
        .map(|s| s.samples.load(Ordering::Relaxed))
        .sum();
    let dropped: u64 = stats
        .iter()
        .map(|s| s.dropped.load(Ordering::Relaxed))
        .sum();
    let alarms = received.lock().unwrap().clone();
    let verdict = judge(&alarms, payloads, &sent, plan);
    let metrics = runtime.metrics();
    let stat_drops = runtime.stat_drops();
    let (_, sinks) = runtime.shutdown(Duration::from_secs(60));
    drop(sinks);
    println!(
        "glrmon rate={rate}: {processed} samples processed in {:.3} s = {:.0} samples/s (publishing took {:.3} s), \
         dropped payloads={dropped}, stat records shed={stat_drops}, faults alarmed {}/{} (false alarms {}, \
         repeated {}; at most {:.2} false alarms expected), alarm latency p50={:.2} ms p99={:.2} ms max={:.2} ms, \
         processing (receipt → records queued) p50 ≤ {} ms p99 ≤ {} ms, \
         delivery of alarms/isolations/ends: {} records, p99 ≤ {} ms, {:.1} % within 50 ms; \
         memory per channel ≈ {:.1} KiB",
        elapsed.as_secs_f64(),
        processed as f64 / elapsed.as_secs_f64(),
        published.as_secs_f64(),
        verdict.detected,
        verdict.faulty,
        verdict.false_alarms,
        verdict.repeated,
        verdict.false_bound,
        pct(&verdict.latency_ms, 0.5),
        pct(&verdict.latency_ms, 0.99),
        verdict.latency_ms.last().copied().unwrap_or(f64::NAN),
        histogram_quantile_ms(&metrics.processing, 0.5),
        histogram_quantile_ms(&metrics.processing, 0.99),
        histogram_count(&metrics.delivery),
        histogram_quantile_ms(&metrics.delivery, 0.99),
        100.0 * histogram_fraction_within(&metrics.delivery, 0.05),
        (rss1.saturating_sub(rss0)) as f64 / plan.channels as f64,
    );
    let errors = errors.lock().unwrap().clone();
    if !errors.is_empty() || verdict.false_alarms > 0 {
        println!(
            "       error records by code: {errors:?}; false alarms (channel, k): {:?}",
            &verdict.false_list[..verdict.false_list.len().min(10)]
        );
    }
    if let Some(stats) = recorder_stats {
        report_recording(&stats);
    }
    drop(source);
    drop(alarms_sub);
    drop(errors_sub);
    let _ = plant.close().await;
    let _ = daemon.close().await;
}

/// The alarms judged against the injected faults.
struct Verdict {
    faulty: usize,
    detected: usize,
    false_alarms: usize,
    repeated: usize,
    /// The false-alarm probability times the samples that could raise one: the
    /// expected count's upper bound (the Bonferroni threshold is conservative).
    false_bound: f64,
    /// Latency of each detected fault's first alarm, sorted.
    latency_ms: Vec<f64>,
    /// The false alarms: (channel, k).
    false_list: Vec<(usize, u64)>,
}

fn judge(
    alarms: &[(String, u64, u64)],
    payloads: &Payloads,
    sent: &[Vec<u64>],
    plan: &Plan,
) -> Verdict {
    let faulty = |i: usize| i.is_multiple_of(plan.faulty_every);
    let mut first = vec![false; plan.channels];
    let mut v = Verdict {
        faulty: (0..plan.channels).filter(|i| faulty(*i)).count(),
        detected: 0,
        false_alarms: 0,
        repeated: 0,
        false_bound: 0.0,
        latency_ms: Vec::new(),
        false_list: Vec::new(),
    };
    let healthy_samples: u64 = (0..plan.channels)
        .map(|i| if faulty(i) { plan.onset } else { plan.samples })
        .sum();
    v.false_bound = plan.alpha * healthy_samples as f64;
    for (ch, k, at) in alarms {
        let Some(i) = ch
            .trim_start_matches("ch")
            .parse::<usize>()
            .ok()
            .filter(|i| *i < plan.channels)
        else {
            continue;
        };
        if !faulty(i) || *k < plan.onset {
            v.false_alarms += 1;
            v.false_list.push((i, *k));
        } else if first[i] {
            v.repeated += 1;
        } else {
            first[i] = true;
            v.detected += 1;
            // The message holding sample k.
            if let Some(b) = payloads[i]
                .iter()
                .position(|(a, z, _)| *a <= *k && *k <= *z)
            {
                v.latency_ms
                    .push(at.saturating_sub(sent[i][b]) as f64 / 1e6);
            }
        }
    }
    v.latency_ms.sort_by(f64::total_cmp);
    v
}

fn histogram_count(h: &LatencyHistogram) -> u64 {
    h.counts.iter().map(|c| c.load(Ordering::Relaxed)).sum()
}

/// The upper bound of the bucket holding quantile `q`, in ms.
fn histogram_quantile_ms(h: &LatencyHistogram, q: f64) -> String {
    let n = histogram_count(h);
    let mut seen = 0;
    for (i, c) in h.counts.iter().enumerate() {
        seen += c.load(Ordering::Relaxed);
        if n > 0 && seen as f64 >= q * n as f64 {
            return LATENCY_BUCKETS
                .get(i)
                .map_or_else(|| "∞".into(), |b| format!("{}", b * 1e3));
        }
    }
    "-".into()
}

fn histogram_fraction_within(h: &LatencyHistogram, bound_s: f64) -> f64 {
    let n = histogram_count(h);
    let within: u64 = h
        .counts
        .iter()
        .zip(LATENCY_BUCKETS)
        .filter(|(_, b)| *b <= bound_s)
        .map(|(c, _)| c.load(Ordering::Relaxed))
        .sum();
    within as f64 / n.max(1) as f64
}

/// Each channel's samples as JSON batches of `batch`; every `faulty_every`-th channel
/// has a sensor bias of 1.0 from `onset`.
fn payloads(cfg: &glrmon_spec::Config, plan: &Plan) -> Payloads {
    let sc = glrmon_sim::scenarios::bench_a();
    let mut payloads = Vec::with_capacity(cfg.channels.len());
    for (i, c) in cfg.channels.iter().enumerate() {
        let mut sim = if i.is_multiple_of(plan.faulty_every) {
            sc.faulty_simulator(i as u64, "sensor_bias", plan.onset, 1.0)
                .expect("sim")
        } else {
            sc.simulator(i as u64).expect("sim")
        };
        let all: Vec<Sample> = (0..plan.samples)
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
            all.chunks(plan.batch)
                .map(|b| {
                    let mut buf = Vec::new();
                    encode_samples(&c.name, b, &mut buf).expect("encode");
                    let k = |s: Option<&Sample>| s.and_then(|s| s.k).unwrap_or(0);
                    (k(b.first()), k(b.last()), ZBytes::from(buf))
                })
                .collect(),
        );
    }
    payloads
}

/// A publisher per key, each waiting until a subscriber matches it.
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
/// record to MCAP, as `glrmon run` has.
fn sinks(
    daemon: &zenoh::Session,
    cfg: &glrmon_spec::Config,
    plan: &Plan,
) -> (
    Vec<Box<dyn glrmon_runtime::Sink>>,
    Option<Arc<glrmon_record::RecorderStats>>,
) {
    let names: Vec<String> = cfg.channels.iter().map(|c| c.name.clone()).collect();
    let mut sinks: Vec<Box<dyn glrmon_runtime::Sink>> = vec![Box::new(
        ZenohSink::declaring(daemon.clone(), &names).expect("publishers"),
    )];
    let mut recorder_stats = None;
    if let Some(dir) = &plan.record {
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
