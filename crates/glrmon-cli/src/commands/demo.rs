//! `glrmon demo`: the main job on an embedded default. One in-process peer-mode Zenoh
//! session; the channels of the embedded `config/demo.toml` are simulated and published
//! on their keys, one fault injected a few seconds in; the daemon's runtime monitors them
//! and publishes results on `glrmon/<channel>/…`; a subscriber prints the alarms and
//! their isolation updates as `glrmon watch` does; a summary at the end, with each
//! alarm's latency: samples from the crossing (the first l_k above λ in the `stat`
//! records) to the sample of the `alarm` record.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use clap::Args;
use glrmon_daemon::{Daemon, DaemonBuilder};
use glrmon_input::OutputFormat;
use glrmon_runtime::{FnSink, JsonLinesSink, Output};
use glrmon_sim::SimSample;

use crate::common::InvalidInput;
use glrmon_wire::{Record, Sample, decode_record, encode_sample};
use glrmon_zenoh::SessionSettings;
use zenoh::Wait as _;
use zenoh::sample::Sample as ZenohSample;

use crate::log::LogEvents;
use crate::print;

/// The demo's channels, embedded so the demo needs no file.
pub(crate) const DEMO_CONFIG: &str = include_str!("../../../../config/demo.toml");

/// The injected fault: channel, fault, onset, magnitude.
const FAULT: (&str, &str, u64, f64) = ("unstable", "x0_jump", 201, 4.0);

#[derive(Debug, Args)]
pub(crate) struct DemoArgs {
    /// Simulated duration in seconds.
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    /// Samples per second per channel; 0 publishes as fast as possible.
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Seed of the simulated noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also listen on this endpoint (e.g. tcp/127.0.0.1:7447) so that `glrmon watch`
    /// in another terminal sees the results.
    #[arg(long, value_name = "ENDPOINT", value_parser = crate::flags::endpoint)]
    listen: Vec<String>,
    /// Where the results go, by the name's extension: `.mcap`, the MCAP recording of
    /// every input and result (`glrmon replay` re-runs it; default
    /// glrmon-demo.mcap); any other name, every record (stat, alarm, alarm_end, error)
    /// as JSON lines. Give it twice for both.
    #[arg(long, value_name = "FILE")]
    output: Vec<PathBuf>,
    /// Write no MCAP recording.
    #[arg(long)]
    no_record: bool,
    /// Replaced by `--output FILE.mcap` (refused with a hint: `Command::old_spelling`).
    #[arg(long, hide = true)]
    pub(crate) record: Option<PathBuf>,
}

/// The demo's outputs: the MCAP recording (unless `--no-record`) and the JSON lines
/// file, from the `--output` names' extensions.
fn outputs(args: &DemoArgs) -> anyhow::Result<(Option<PathBuf>, Option<PathBuf>)> {
    let (mcap, jsonl): (Vec<&PathBuf>, Vec<&PathBuf>) = args
        .output
        .iter()
        .partition(|p| OutputFormat::of(p) == OutputFormat::Mcap);
    if mcap.len() > 1 || jsonl.len() > 1 {
        return Err(InvalidInput(
            "--output: at most one .mcap recording and one JSON lines file".into(),
        )
        .into());
    }
    let record = match (mcap.first(), args.no_record) {
        (Some(p), true) => {
            return Err(InvalidInput(format!(
                "--output {} and --no-record contradict each other",
                p.display()
            ))
            .into());
        }
        (Some(p), false) => Some((*p).clone()),
        (None, true) => None,
        (None, false) => Some(PathBuf::from("glrmon-demo.mcap")),
    };
    Ok((record, jsonl.first().map(|p| (*p).clone())))
}

pub(crate) fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(demo(args))
}

async fn demo(args: &DemoArgs) -> anyhow::Result<()> {
    let (record, jsonl) = outputs(args)?;
    let cfg = glrmon_spec::parse(DEMO_CONFIG)
        .map_err(|e| anyhow::anyhow!("embedded demo config: {e}"))?;
    let rate_hz = if args.rate > 0.0 { args.rate } else { 100.0 };
    let samples = (args.seconds as f64 * rate_hz).round() as u64;
    let session_settings = SessionSettings {
        mode: Some("peer".into()),
        listen: args.listen.clone(),
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    };
    let session = glrmon_zenoh::open(&session_settings).await?;
    let (watchers, alarms_seen) = watch_alarms(&session).await?;
    let latency = Arc::new(Mutex::new(Latency::default()));
    let daemon = start_daemon(
        &cfg,
        &session,
        &session_settings,
        record.as_ref(),
        jsonl.as_ref(),
        &latency,
    )
    .await?;
    let keys: Vec<Vec<String>> = cfg
        .channels
        .iter()
        .map(glrmon_spec::Channel::input_keys)
        .collect();
    let mut plants = plants(&cfg, &session, args.seed).await?;
    println!(
        "glrmon demo: in-process Zenoh peer session {}, {} channels ({}), {samples} samples each at {}",
        session.zid(),
        plants.len(),
        keys.concat().join(", "),
        if args.rate > 0.0 {
            format!("{rate_hz} Hz")
        } else {
            "full speed".into()
        }
    );
    println!(
        "  injected: fault {} of magnitude {} on channel {} at k = {} ({:.2} s)",
        FAULT.1,
        FAULT.3,
        FAULT.0,
        FAULT.2,
        FAULT.2 as f64 / rate_hz
    );
    let started = Instant::now();
    publish(&mut plants, samples, args.rate, rate_hz).await?;
    // Wait until every published sample has been processed (a condition, bounded).
    let stats = daemon.runtime().stats();
    let names = daemon.runtime().channel_names().to_vec();
    let deadline = Instant::now() + Duration::from_secs(30);
    while glrmon_runtime::channel_statuses(&names, &stats)
        .iter()
        .any(|c| c.samples + c.dropped < samples)
        && Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let stopped = daemon.shutdown(Duration::from_secs(10)).await;
    let raised: u64 = glrmon_runtime::channel_statuses(&names, &stats)
        .iter()
        .map(|c| c.alarms)
        .sum();
    let deadline = Instant::now() + Duration::from_secs(5);
    while alarms_seen.load(Ordering::Relaxed) < raised && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    drop(watchers);
    print_summary(started, &names, &stats, &latency);
    if let Some(p) = &jsonl {
        println!("records written to {}", p.display());
    }
    if let (Some(stats), Some(record)) = (stopped.recorder, &record) {
        let finished = stats.finished.lock().map(|f| f.clone()).unwrap_or_default();
        if let Some(file) = finished.last() {
            std::fs::rename(file, record)
                .with_context(|| format!("renaming {} to {}", file.display(), record.display()))?;
            println!(
                "recording: {} ({} messages); replay it with: {} replay {} --report report.html",
                record.display(),
                stats.messages.load(Ordering::Relaxed),
                crate::common::invoked_as(),
                record.display()
            );
        }
    }
    let _ = session.close().await;
    anyhow::ensure!(stopped.in_time, "the runtime did not drain in time");
    Ok(())
}

/// The watcher: alarms, isolation updates and ends printed as `glrmon watch` prints
/// them, and the number of alarms seen.
async fn watch_alarms(
    session: &zenoh::Session,
) -> anyhow::Result<(Vec<zenoh::pubsub::Subscriber<()>>, Arc<AtomicU64>)> {
    let alarms_seen = Arc::new(AtomicU64::new(0));
    let seen = alarms_seen.clone();
    let print_record = Arc::new(move |s: ZenohSample| {
        if let Ok(r) = decode_record(&s.payload().to_bytes()) {
            if let Some(line) = print::line(&r) {
                println!("{line}");
            }
            if matches!(r, Record::Alarm(_)) {
                seen.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    let mut watchers = Vec::new();
    for key in ["glrmon/*/alarm$*", "glrmon/*/isolation"] {
        let print_record = print_record.clone();
        watchers.push(
            session
                .declare_subscriber(key)
                .callback(move |s| print_record(s))
                .await
                .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?,
        );
    }
    Ok((watchers, alarms_seen))
}

/// The daemon: runtime, Zenoh sink (and optionally a JSONL file and the recording),
/// Zenoh source, on the demo's own session, with nothing to announce; every `stat`
/// record goes to `latency`.
async fn start_daemon(
    cfg: &glrmon_spec::Config,
    session: &zenoh::Session,
    session_settings: &SessionSettings,
    record: Option<&PathBuf>,
    jsonl: Option<&PathBuf>,
    latency: &Arc<Mutex<Latency>>,
) -> anyhow::Result<Daemon> {
    let measured = latency.clone();
    let mut builder = DaemonBuilder::new(cfg.clone(), "demo")
        .announce(false)
        .metrics(None)
        .events(Arc::new(LogEvents))
        .sink(Box::new(FnSink::new("latency", move |o: &Output| {
            if let Ok(mut l) = measured.lock() {
                l.see(&o.record);
            }
        })));
    if let Some(p) = jsonl {
        let file = std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
        builder = builder.sink(Box::new(JsonLinesSink::new(
            std::io::BufWriter::new(file),
            1,
        )));
    }
    let recorder = record.map(|record| {
        let directory = match record.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        glrmon_record::RecorderSettings {
            directory,
            prefix: ".glrmon-demo".into(),
            max_file_bytes: None,
            max_file_duration: None,
            ..glrmon_record::RecorderSettings::default()
        }
    });
    let mut settings = glrmon_runtime::RuntimeSettings::from_spec(&cfg.daemon);
    settings.stat_every = 1;
    let endpoints = glrmon_zenoh::Endpoints::of(session_settings)?;
    Ok(builder
        .recorder(recorder)
        .runtime_settings(settings)
        .start(session, &endpoints)
        .await?)
}

/// One simulated channel and the publisher of its samples.
type Plant = (
    String,
    glrmon_sim::Simulator,
    zenoh::pubsub::Publisher<'static>,
);

/// The plant: each channel simulated (the demo's fault injected on its channel) and
/// published on its key.
async fn plants(
    cfg: &glrmon_spec::Config,
    session: &zenoh::Session,
    seed: u64,
) -> anyhow::Result<Vec<Plant>> {
    let mut plants = Vec::new();
    for (i, c) in cfg.channels.iter().enumerate() {
        let seed = seed.wrapping_add(i as u64);
        let sim = if c.name == FAULT.0 {
            crate::common::simulator(
                c,
                seed,
                &[crate::flags::FaultArg {
                    name: FAULT.1.to_owned(),
                    magnitude: FAULT.3,
                }],
                FAULT.2,
            )?
        } else {
            crate::common::simulator(c, seed, &[], 0)?
        };
        let publisher = session
            .declare_publisher(c.key.clone())
            .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .await
            .map_err(|e| anyhow::anyhow!("declaring a publisher on {}: {e}", c.key))?;
        plants.push((c.name.clone(), sim, publisher));
    }
    Ok(plants)
}

/// Publishes `samples` samples of every plant, at `rate` Hz (0: full speed), with
/// sample times at `rate_hz`.
async fn publish(
    plants: &mut [Plant],
    samples: u64,
    rate: f64,
    rate_hz: f64,
) -> anyhow::Result<()> {
    let mut interval =
        (rate > 0.0).then(|| tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz)));
    let mut x = SimSample {
        k: 0,
        u: vec![],
        y: vec![],
        p: vec![],
    };
    let mut sample = Sample::default();
    let mut buf = Vec::new();
    for k in 0..samples {
        if let Some(i) = &mut interval {
            i.tick().await;
        }
        for (name, sim, publisher) in plants.iter_mut() {
            sim.next_into(&mut x);
            sample.k = Some(x.k);
            sample.t = Some(k as f64 / rate_hz);
            sample.u.clone_from(&x.u);
            sample.y.clone_from(&x.y);
            sample.p.clone_from(&x.p);
            buf.clear();
            encode_sample(name, &sample, &mut buf)?;
            publisher
                .put(buf.clone())
                .wait()
                .map_err(|e| anyhow::anyhow!("publishing on {name}: {e}"))?;
        }
    }
    Ok(())
}

/// Each channel's counters and each alarm's measured latency.
fn print_summary(
    started: Instant,
    names: &[String],
    stats: &[Arc<glrmon_runtime::ChannelStats>],
    latency: &Mutex<Latency>,
) {
    println!("summary ({:.1} s):", started.elapsed().as_secs_f64());
    for c in glrmon_runtime::channel_statuses(names, stats) {
        println!(
            "  {:<10} samples={} alarms={} errors={} dropped={} active={}",
            c.channel,
            c.samples,
            c.alarms,
            c.error_total(),
            c.dropped,
            c.alarm_active
        );
    }
    if let Ok(l) = latency.lock() {
        for a in &l.alarms {
            let crossed = l.crossing(a);
            let crossing = crossed.map_or_else(|| "unseen".to_owned(), |c| format!("k={c}"));
            let latency =
                crossed.map_or_else(|| "?".to_owned(), |c| a.k.saturating_sub(c).to_string());
            let update = match a.update {
                Some(u) => format!("isolation update at k={u}"),
                None => "no isolation update (episode over first)".to_owned(),
            };
            println!(
                "  alarm {}: l_k first above the threshold at {crossing}, alarm record at k={} \
                 (latency {latency} samples), {update}",
                a.channel, a.k
            );
        }
    }
}

/// One alarm as the demo measured it.
#[derive(Debug)]
struct MeasuredAlarm {
    channel: String,
    /// The alarm record's sample.
    k: u64,
    /// The sample of its `isolation` record.
    update: Option<u64>,
}

/// Detection latency in samples, measured from the records as a consumer sees them:
/// the `stat` records say where l_k went above the threshold, the `alarm` record where
/// the alarm was raised (alarms overtake statistics, so an alarm may arrive before the
/// `stat` of its crossing).
#[derive(Debug, Default)]
struct Latency {
    /// Per channel: every sample whose l_k went from at most λ (or none) to above it,
    /// and whether the last `stat` was above λ.
    rising: std::collections::HashMap<String, (Vec<u64>, bool)>,
    alarms: Vec<MeasuredAlarm>,
}

impl Latency {
    fn see(&mut self, record: &Record) {
        match record {
            Record::Stat(s) => {
                let above = s.glr.zip(s.threshold).is_some_and(|(l, h)| l > h);
                let entry = self.rising.entry(s.channel.clone()).or_default();
                if above && !entry.1 {
                    entry.0.push(s.k);
                }
                entry.1 = above;
            }
            Record::Alarm(a) => self.alarms.push(MeasuredAlarm {
                channel: a.channel.clone(),
                k: a.k,
                update: None,
            }),
            Record::Isolation(u) => {
                if let Some(a) = self
                    .alarms
                    .iter_mut()
                    .rev()
                    .find(|a| a.channel == u.channel && a.k == u.alarm_k)
                {
                    a.update = Some(u.k);
                }
            }
            _ => {}
        }
    }

    /// The sample at which l_k last went above the threshold at or before alarm `a`.
    fn crossing(&self, a: &MeasuredAlarm) -> Option<u64> {
        self.rising
            .get(&a.channel)
            .and_then(|(r, _)| r.iter().rev().find(|k| **k <= a.k).copied())
    }
}
