//! End-to-end tests of `glrmon run` (the real binary) on real Zenoh sessions over
//! loopback: explicit tcp/127.0.0.1 endpoints, multicast scouting off, no mocks.

#[path = "support.rs"]
mod support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_wire::{Record, Sample, decode_record, encode_sample};
use glrmon_zenoh::SessionSettings;
use support::free_port;
use zenoh::Wait as _;
use zenoh::query::QueryTarget;

/// A running `glrmon run`, killed if the test ends early.
struct Daemon {
    child: Child,
    endpoint: String,
    _dir: tempdir::Dir,
}

mod tempdir {
    pub(crate) struct Dir(pub(crate) std::path::PathBuf);
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl Daemon {
    /// Starts the daemon on the paper's §6.1 channel and the DC motor, listening on a
    /// fresh loopback port; returns once it reports that intake is open.
    fn start(tag: &str) -> Self {
        let port = free_port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let dir = std::env::temp_dir().join(format!("glrmon-daemon-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples");
        let unstable = std::fs::read_to_string(root.join("paper2014-unstable.toml")).unwrap();
        let motor = std::fs::read_to_string(root.join("dc-motor.toml")).unwrap();
        let text = format!(
            "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n[daemon]\nstat_every = 0\ninstance = \"test-{tag}\"\n\n{unstable}\n{motor}"
        );
        let cfg = dir.join("daemon.toml");
        std::fs::write(&cfg, text).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_glrmon"))
            .args(["run", "--config"])
            .arg(&cfg)
            .env("GLRMON_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.contains("monitoring 2 channel(s)"), "{line}");
        Self {
            child,
            endpoint,
            _dir: tempdir::Dir(dir),
        }
    }

    fn settings(&self) -> SessionSettings {
        SessionSettings {
            mode: Some("peer".into()),
            connect: vec![self.endpoint.clone()],
            multicast_scouting: Some(false),
            ..SessionSettings::default()
        }
    }

    /// SIGTERM, then the exit status within `limit`.
    fn terminate(mut self, limit: Duration) -> (Option<i32>, Duration) {
        let t = Instant::now();
        Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        while t.elapsed() < limit {
            if let Some(s) = self.child.try_wait().unwrap() {
                return (s.code(), t.elapsed());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        (None, t.elapsed())
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Everything the daemon publishes under glrmon/**.
async fn collect(
    session: &zenoh::Session,
) -> (zenoh::pubsub::Subscriber<()>, Arc<Mutex<Vec<Record>>>) {
    let got = Arc::new(Mutex::new(Vec::new()));
    let g = got.clone();
    let sub = session
        .declare_subscriber("glrmon/**")
        .callback(move |s| {
            if let Ok(r) = decode_record(&s.payload().to_bytes()) {
                g.lock().unwrap().push(r);
            }
        })
        .await
        .unwrap();
    (sub, got)
}

async fn publisher(session: &zenoh::Session, key: &str) -> zenoh::pubsub::Publisher<'static> {
    let p = session
        .declare_publisher(key.to_owned())
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .unwrap();
    let t = Instant::now();
    while !p.matching_status().await.unwrap().matching() {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "no subscriber on {key}"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    p
}

/// Samples of a channel of the daemon's config, simulated as `glrmon simulate` does.
fn simulated(channel: &str, fault: Option<(&str, u64, f64)>, n: u64) -> Vec<Vec<u8>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples");
    let file = if channel == "unstable" {
        "paper2014-unstable.toml"
    } else {
        "dc-motor.toml"
    };
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let unique = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!(
        "glrmon-sim-{channel}-{}-{unique}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("s.csv");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_glrmon"));
    cmd.args(["simulate", "--config"]).arg(root.join(file));
    cmd.args(["--samples", &n.to_string(), "--seed", "7", "--output"])
        .arg(&csv);
    if let Some((f, onset, mag)) = fault {
        cmd.args([
            "--fault",
            &format!("{f}:{mag}"),
            "--onset",
            &onset.to_string(),
        ]);
    }
    assert!(cmd.status().unwrap().success());
    let text = std::fs::read_to_string(&csv).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            let col = |name: &str| header.iter().position(|h| *h == name);
            let pick = |prefix: char| -> Vec<f64> {
                header
                    .iter()
                    .enumerate()
                    .filter(|(_, h)| h.starts_with(prefix) && h[1..].parse::<usize>().is_ok())
                    .map(|(i, _)| v[i])
                    .collect()
            };
            let s = Sample {
                k: col("k").map(|i| v[i] as u64),
                t: None,
                u: pick('u'),
                y: pick('y'),
                p: pick('p'),
            };
            let mut b = Vec::new();
            encode_sample(channel, &s, &mut b).unwrap();
            b
        })
        .collect()
}

/// Polls the status queryable until `channel` has processed `samples` samples.
async fn wait_processed(session: &zenoh::Session, channel: &str, samples: u64) -> String {
    let t = Instant::now();
    loop {
        let replies = session
            .get("glrmon/@status/*")
            .target(QueryTarget::All)
            .timeout(Duration::from_secs(2))
            .await
            .unwrap();
        let mut last = String::new();
        while let Ok(r) = replies.recv_async().await {
            if let Ok(s) = r.result() {
                last = s.payload().try_to_string().unwrap().into_owned();
            }
        }
        let want = format!("\"channel\":\"{channel}\",\"samples\":{samples},");
        if last.contains(&want) {
            return last;
        }
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "status never reached {want}: {last}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn alarms<'a>(records: &'a [Record], channel: &str) -> Vec<&'a glrmon_wire::Alarm> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Alarm(a) if a.channel == channel => Some(a),
            _ => None,
        })
        .collect()
}

/// A faulty channel published to a running daemon gives exactly one alarm with
/// the right isolation; a clean channel none; status and liveliness answer; SIGTERM
/// exits 0 within the bounded time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn faulty_channel_gives_one_alarm_clean_channel_none_then_sigterm_exits_0() {
    let daemon = Daemon::start("alarm");
    let session = glrmon_zenoh::open(&daemon.settings()).await.unwrap();
    let (_sub, got) = collect(&session).await;
    let faulty = simulated("unstable", Some(("x0_jump", 201, 4.0)), 400);
    let clean = simulated("dc_motor", None, 400);
    let (pu, pm) = (
        publisher(&session, "plant/unstable").await,
        publisher(&session, "plant/dc_motor").await,
    );
    for (a, b) in faulty.iter().zip(&clean) {
        pu.put(a.clone()).wait().unwrap();
        pm.put(b.clone()).wait().unwrap();
    }
    wait_processed(&session, "unstable", 400).await;
    let status = wait_processed(&session, "dc_motor", 400).await;
    assert!(status.contains("\"instance\":\"test-alarm\""), "{status}");
    // Liveliness: the instance's token is visible.
    let replies = session
        .liveliness()
        .get("glrmon/@instances/*")
        .timeout(Duration::from_secs(2))
        .await
        .unwrap();
    let mut alive = Vec::new();
    while let Ok(r) = replies.recv_async().await {
        if let Ok(s) = r.result() {
            alive.push(s.key_expr().to_string());
        }
    }
    assert_eq!(alive, ["glrmon/@instances/test-alarm"]);
    let (code, took) = daemon.terminate(Duration::from_secs(10));
    assert_eq!(code, Some(0), "exit after {took:?}");
    let records = got.lock().unwrap().clone();
    let a = alarms(&records, "unstable");
    assert_eq!(a.len(), 1, "{a:#?}");
    // The alarm at the crossing, its isolation refined 2 samples later.
    assert_eq!((a[0].k, a[0].onset, a[0].update_k), (201, 200, Some(203)));
    let updates: Vec<&glrmon_wire::IsolationUpdate> = records
        .iter()
        .filter_map(|r| match r {
            Record::Isolation(u) if u.channel == "unstable" => Some(u),
            _ => None,
        })
        .collect();
    assert_eq!(updates.len(), 1, "{updates:#?}");
    assert_eq!(
        (updates[0].k, updates[0].alarm_k, updates[0].onset),
        (203, 201, 201)
    );
    let isolated: Vec<&str> = updates[0]
        .isolation
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.as_str())
        .collect();
    assert_eq!(isolated, ["x0_jump"]);
    assert!(alarms(&records, "dc_motor").is_empty());
    let _ = session.close().await;
}

/// Each kind of bad payload, interleaved with good samples, yields its `error`
/// record; the good stream's alarm arrives at the same k as without them; a gap (missing
/// samples) is filled, not corrupting the filter.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_payloads_and_gaps_are_reported_and_the_alarm_is_unchanged() {
    let daemon = Daemon::start("bad");
    let session = glrmon_zenoh::open(&daemon.settings()).await.unwrap();
    let (_sub, got) = collect(&session).await;
    let faulty = simulated("unstable", Some(("x0_jump", 201, 4.0)), 400);
    let pu = publisher(&session, "plant/unstable").await;
    let big = format!("{{\"y\":[{}1]}}", "0,".repeat(600_000));
    // (before the good sample of this k, payload, expected code)
    let bad: Vec<(u64, Vec<u8>, &str)> = vec![
        (50, b"{not json".to_vec(), "invalid_json"),
        (60, br#"{"k":"x","y":[1.0]}"#.to_vec(), "wrong_type"),
        (
            70,
            br#"{"k":70,"u":[0.0],"y":[1.0,2.0]}"#.to_vec(),
            "wrong_dimension",
        ),
        (
            80,
            br#"{"k":80,"u":[0.0],"y":[1e999]}"#.to_vec(),
            "non_finite",
        ),
        (
            // Late by 4 (within max_reorder = 16): refused alone. A sample much
            // older is a sequence reset (tests/recording.rs, monitor tests/sequence.rs).
            90,
            br#"{"k":85,"u":[0.0],"y":[1.0]}"#.to_vec(),
            "out_of_order",
        ),
        (100, big.into_bytes(), "too_large"),
        (
            111,
            br#"{"k":110,"u":[0.0],"y":[1.0]}"#.to_vec(),
            "duplicate",
        ),
        (
            120,
            br#"{"k":120,"u":[0.0],"y":[1.0],"colour":3}"#.to_vec(),
            "unknown_field",
        ),
        (
            130,
            br#"[{"k":130,"u":[0.0],"y":[1.0]},{"k":131,"u":[0.0]}]"#.to_vec(),
            "missing_field",
        ),
    ];
    for (k, payload) in faulty.iter().enumerate() {
        let k = k as u64;
        if (300..305).contains(&k) {
            continue; // a gap
        }
        for (at, b, _) in &bad {
            if *at == k {
                pu.put(b.clone()).wait().unwrap();
            }
        }
        pu.put(payload.clone()).wait().unwrap();
    }
    wait_processed(&session, "unstable", 395).await;
    let (code, _) = daemon.terminate(Duration::from_secs(10));
    assert_eq!(code, Some(0));
    let records = got.lock().unwrap().clone();
    let errors: Vec<(&str, String)> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some((e.code.as_str(), e.message.clone())),
            _ => None,
        })
        .collect();
    let codes: Vec<&str> = errors.iter().map(|e| e.0).filter(|c| *c != "gap").collect();
    let want: Vec<&str> = bad.iter().map(|b| b.2).collect();
    assert_eq!(codes, want, "{errors:#?}");
    assert!(
        errors
            .iter()
            .any(|e| e.0 == "gap" && e.1.contains("samples 300..304 missing")),
        "{errors:#?}"
    );
    assert!(
        errors
            .iter()
            .any(|e| e.0 == "wrong_dimension"
                && e.1.contains("field y has 2 values, model expects 1")),
        "{errors:#?}"
    );
    let a = alarms(&records, "unstable");
    assert_eq!(a.len(), 1, "{a:#?}");
    assert_eq!((a[0].k, a[0].onset), (201, 200));
    let _ = session.close().await;
}
