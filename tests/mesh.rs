//! Several glrmon instances behind a Zenoh router, as users deploy them. One
//! router on loopback (`zenohd` with deploy/zenohd.json5 when it is installed — `make
//! deps` builds it from crates.io; otherwise, or with GLRMON_TEST_ROUTER=session, a
//! router-mode Zenoh session in this process, the same routing code), two `glrmon run` instances in client mode with disjoint shards of 20
//! channels, started before the router is up. Asserts: each instance monitors its
//! shard only and a third instance claiming the same channels is refused; every
//! faulty channel gives exactly one alarm, from the instance that owns it;
//! `glrmon status` lists both instances; the router is stopped and restarted mid-run,
//! both instances report the reconnection, and the alarms of faults injected after it
//! all arrive. Real binary, real sessions, explicit tcp/127.0.0.1 endpoints,
//! multicast scouting off.

#[path = "support.rs"]
mod support;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_wire::{Record, Sample, decode_record, encode_sample};
use glrmon_zenoh::SessionSettings;
use zenoh::Wait as _;

const CHANNELS: usize = 20;

struct TempDir(PathBuf);
impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A running `glrmon run` with its output collected.
struct Instance {
    child: Child,
    stderr: Arc<Mutex<String>>,
}

impl Instance {
    fn spawn(cfg: &Path, shard: &str, name: &str, endpoint: &str, metrics: Option<&str>) -> Self {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_glrmon"));
        cmd.args(["run", "--config"])
            .arg(cfg)
            .args(["--shard", shard, "--instance", name, "--mode", "client"])
            .args(["--connect", endpoint]);
        if let Some(m) = metrics {
            cmd.args(["--metrics", m]);
        }
        let (child, stderr) = support::spawn_logged(&mut cmd);
        Self { child, stderr }
    }

    /// The "monitoring N channel(s)" line, once the session is open.
    fn started_line(&mut self) -> String {
        let mut line = String::new();
        BufReader::new(self.child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        line
    }

    fn log(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// GET `path` from the metrics endpoint: (status code, body).
fn http_get(addr: &str, path: &str) -> (u16, String) {
    use std::io::Write as _;
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: glrmon\r\n\r\n").unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    let code = reply.split_whitespace().nth(1).unwrap().parse().unwrap();
    let body = reply
        .split_once("\r\n\r\n")
        .map(|x| x.1.to_owned())
        .unwrap_or_default();
    (code, body)
}

fn glrmon(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(args)
        .output()
        .unwrap()
}

/// (u, y) of each sample of a run.
type Rows = Vec<(Vec<f64>, Vec<f64>)>;

/// Rows of a simulated DC motor run from `glrmon simulate`.
fn simulate(dir: &Path, fault: Option<u64>, n: u64) -> Rows {
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let csv = dir.join(format!("sim-{fault:?}.csv"));
    let mut args = vec![
        "simulate".to_owned(),
        "--config".into(),
        cfg.display().to_string(),
        "--samples".into(),
        n.to_string(),
        "--seed".into(),
        "3".into(),
        "--output".into(),
        csv.display().to_string(),
    ];
    if let Some(onset) = fault {
        for a in [
            "--fault",
            "actuator_bias:0.5",
            "--onset",
            &onset.to_string(),
        ] {
            args.push(a.to_owned());
        }
    }
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = glrmon(&refs);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols = |p: char| -> Vec<usize> {
        (0..header.len())
            .filter(|i| header[*i].starts_with(p) && header[*i][1..].parse::<usize>().is_ok())
            .collect()
    };
    let (uc, yc) = (cols('u'), cols('y'));
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (
                uc.iter().map(|i| v[*i]).collect(),
                yc.iter().map(|i| v[*i]).collect(),
            )
        })
        .collect()
}

/// Publishes rows k ∈ range of each channel's data on plant/<channel>, round-robin.
async fn publish(
    session: &zenoh::Session,
    data: &BTreeMap<String, Rows>,
    range: std::ops::Range<usize>,
) {
    let mut pubs = Vec::new();
    for ch in data.keys() {
        let p = session
            .declare_publisher(format!("plant/{ch}"))
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .await
            .unwrap();
        let t = Instant::now();
        while !p.matching_status().await.unwrap().matching() {
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "no subscriber on plant/{ch}"
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        pubs.push((ch.clone(), p));
    }
    for k in range {
        for (ch, p) in &pubs {
            let (u, y) = &data[ch][k];
            let s = Sample {
                k: Some(k as u64),
                t: None,
                u: u.clone(),
                y: y.clone(),
                p: Vec::new(),
            };
            let mut b = Vec::new();
            encode_sample(ch, &s, &mut b).unwrap();
            p.put(b).wait().unwrap();
        }
    }
}

/// Every instance's status JSON by instance name.
async fn statuses(session: &zenoh::Session) -> BTreeMap<String, serde_json::Value> {
    glrmon_zenoh::query_status(session, "*", Duration::from_secs(2))
        .await
        .unwrap()
        .into_iter()
        .map(|(n, j)| (n, serde_json::from_str(&j).unwrap()))
        .collect()
}

/// Polls the statuses until `done` holds (bounded).
async fn wait_status(
    session: &zenoh::Session,
    what: &str,
    limit: Duration,
    done: impl Fn(&BTreeMap<String, serde_json::Value>) -> bool,
) -> BTreeMap<String, serde_json::Value> {
    let t = Instant::now();
    loop {
        let s = statuses(session).await;
        if done(&s) {
            return s;
        }
        assert!(
            t.elapsed() < limit,
            "{what}: never reached; last status {s:#?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Channel → (instance, samples, alarms) from the statuses.
fn channel_table(
    s: &BTreeMap<String, serde_json::Value>,
) -> BTreeMap<String, Vec<(String, u64, u64)>> {
    let mut t: BTreeMap<String, Vec<(String, u64, u64)>> = BTreeMap::new();
    for (inst, v) in s {
        for c in v["channels"].as_array().unwrap() {
            t.entry(c["channel"].as_str().unwrap().to_owned())
                .or_default()
                .push((
                    inst.clone(),
                    c["samples"].as_u64().unwrap(),
                    c["alarms"].as_u64().unwrap(),
                ));
        }
    }
    t
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_sharded_instances_behind_a_router_survive_its_restart() {
    let dir = std::env::temp_dir().join(format!("glrmon-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let _cleanup = TempDir(dir.clone());
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());

    // 20 copies of the DC motor, ch00 … ch19.
    let motor = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"),
    )
    .unwrap();
    let mut text = "[daemon]\nstat_every = 0\nworkers = 1\n\n".to_owned();
    for i in 0..CHANNELS {
        text.push_str(&motor.replace("name = \"dc_motor\"", &format!("name = \"ch{i:02}\"")));
        text.push('\n');
    }
    let cfg = dir.join("fleet.toml");
    std::fs::write(&cfg, text).unwrap();

    // Both instances start before the router exists.
    let metrics = format!("127.0.0.1:{}", support::free_port());
    let mut a = Instance::spawn(&cfg, "0/2", "mesh-a", &endpoint, Some(&metrics));
    let mut b = Instance::spawn(&cfg, "1/2", "mesh-b", &endpoint, None);
    let t = Instant::now();
    while !(a.log().contains("No Zenoh router reachable yet")
        && b.log().contains("No Zenoh router reachable yet"))
    {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "{}\n{}",
            a.log(),
            b.log()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let router = support::Router::start(&endpoint).await;
    eprintln!("router: {}", router.kind());
    let (la, lb) = (a.started_line(), b.started_line());
    let count = |l: &str| -> usize {
        l.split("monitoring ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!(
        la.contains("instance mesh-a") && la.contains("(shard 0/2 of 20)"),
        "{la}"
    );
    assert!(
        lb.contains("instance mesh-b") && lb.contains("(shard 1/2 of 20)"),
        "{lb}"
    );
    let (na, nb) = (count(&la), count(&lb));
    assert_eq!(na + nb, CHANNELS, "{la}{lb}");
    assert!(na > 0 && nb > 0, "{la}{lb}");

    // A third instance claiming every channel is refused, naming a channel and owner.
    let third = glrmon(&[
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--instance",
        "mesh-c",
        "--mode",
        "client",
        "--connect",
        &endpoint,
    ]);
    let msg = String::from_utf8_lossy(&third.stderr);
    assert_eq!(third.status.code(), Some(1), "{msg}");
    assert!(
        msg.contains("20 channel(s) of this instance are already monitored elsewhere"),
        "{msg}"
    );
    assert!(
        msg.contains("(instance \"mesh-a\")") && msg.contains("(instance \"mesh-b\")"),
        "{msg}"
    );
    // Selected by key expression (ch10 … ch19), then refused for those ten only.
    let fourth = glrmon(&[
        "run",
        "--config",
        cfg.to_str().unwrap(),
        "--instance",
        "mesh-d",
        "--mode",
        "client",
        "--connect",
        &endpoint,
        "--channels",
        "plant/ch1$*",
    ]);
    let msg = String::from_utf8_lossy(&fourth.stderr);
    assert_eq!(fourth.status.code(), Some(1), "{msg}");
    assert!(
        msg.contains("10 channel(s) of this instance are already monitored elsewhere"),
        "{msg}"
    );
    assert!(
        msg.contains("\"ch19\"") && !msg.contains("\"ch09\""),
        "{msg}"
    );

    let publisher = glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .unwrap();
    let alarms = Arc::new(Mutex::new(Vec::new()));
    let got = alarms.clone();
    let _sub = publisher
        .declare_subscriber("glrmon/*/alarm")
        .callback(move |s| {
            if let Ok(Record::Alarm(a)) = decode_record(&s.payload().to_bytes()) {
                got.lock().unwrap().push((a.channel.clone(), a.k, a.onset));
            }
        })
        .await
        .unwrap();

    // Phase 1: faults on ch03, ch07, ch12 at k = 201; 400 samples on every channel.
    let clean = simulate(&dir, None, 800);
    let faulty_early = simulate(&dir, Some(201), 400);
    let faulty_late = simulate(&dir, Some(601), 800);
    let early = ["ch03", "ch07", "ch12"];
    let late = ["ch01", "ch15"];
    let mut data = BTreeMap::new();
    for i in 0..CHANNELS {
        let ch = format!("ch{i:02}");
        let d = if early.contains(&ch.as_str()) {
            faulty_early.clone()
        } else if late.contains(&ch.as_str()) {
            faulty_late.clone()
        } else {
            clean.clone()
        };
        data.insert(ch, d);
    }
    publish(&publisher, &data, 0..400).await;
    let s = wait_status(
        &publisher,
        "400 samples everywhere",
        Duration::from_secs(60),
        |s| {
            let t = channel_table(s);
            t.len() == CHANNELS && t.values().all(|v| v.len() == 1 && v[0].1 == 400)
        },
    )
    .await;
    let owners = channel_table(&s);
    for (ch, v) in &owners {
        let expected = u64::from(early.contains(&ch.as_str()));
        assert_eq!(
            v[0].2, expected,
            "{ch}: alarms counted by its owner {}",
            v[0].0
        );
    }

    // mesh-a's Prometheus endpoint agrees with its status; it is healthy and ready.
    let (code, body) = http_get(&metrics, "/metrics");
    assert_eq!(code, 200, "{body}");
    for (ch, v) in owners.iter().filter(|(_, v)| v[0].0 == "mesh-a") {
        let line = format!(
            "glrmon_alarms_total{{glrmon_instance=\"mesh-a\",channel=\"{ch}\"}} {}",
            v[0].2
        );
        assert!(body.contains(&line), "{line} not in\n{body}");
        let line =
            format!("glrmon_samples_total{{glrmon_instance=\"mesh-a\",channel=\"{ch}\"}} 400");
        assert!(body.contains(&line), "{line} not in\n{body}");
    }
    assert!(
        body.contains("glrmon_processing_seconds_count{glrmon_instance=\"mesh-a\"}"),
        "{body}"
    );
    assert!(
        body.contains("glrmon_zenoh_connected{glrmon_instance=\"mesh-a\"} 1"),
        "{body}"
    );
    assert_eq!(http_get(&metrics, "/healthz").0, 200);
    assert_eq!(http_get(&metrics, "/readyz").0, 200);

    // `glrmon status` lists both instances.
    let out = glrmon(&["status", "--connect", &endpoint]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        table.contains("mesh-a") && table.contains("mesh-b"),
        "{table}"
    );
    assert!(table.contains("0/2") && table.contains("1/2"), "{table}");
    assert!(table.contains("2 instance(s), 20 channel(s)"), "{table}");
    eprintln!("{table}");

    // Restart the router; both instances reconnect and say so.
    router.stop().await;
    let down = Instant::now();
    // Not ready without a router (still healthy); checked while the router is down.
    let t = Instant::now();
    while http_get(&metrics, "/readyz").0 != 503 {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "still ready without a router"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(http_get(&metrics, "/healthz").0, 200);
    let router = support::Router::start(&endpoint).await;
    let up = Instant::now();
    let s = wait_status(
        &publisher,
        "both reconnected",
        Duration::from_secs(30),
        |s| s.len() == 2 && s.values().all(|v| v["reconnections"].as_u64() == Some(1)),
    )
    .await;
    let back = up.elapsed();
    eprintln!(
        "router {} stopped for {:?}; both instances reconnected {:?} after it listened again",
        router.kind(),
        up - down,
        back
    );
    for v in s.values() {
        assert_eq!(v["connected"].as_bool(), Some(true));
    }
    assert_eq!(http_get(&metrics, "/readyz").0, 200);
    for inst in [&a, &b] {
        let log = inst.log();
        assert!(log.contains("Lost every Zenoh connection"), "{log}");
        assert!(log.contains("Reconnected to the Zenoh network"), "{log}");
    }

    // Phase 2: samples 400..800 on the channels that were clean; faults at 601 on
    // ch01 and ch15. No channel lost its state: k continues at 400.
    data.retain(|ch, _| !early.contains(&ch.as_str()));
    publish(&publisher, &data, 400..800).await;
    let s = wait_status(&publisher, "800 samples", Duration::from_secs(60), |s| {
        let t = channel_table(s);
        data.keys()
            .all(|ch| t.get(ch).is_some_and(|v| v[0].1 == 800))
    })
    .await;
    let after = channel_table(&s);
    for (ch, v) in &after {
        assert_eq!(v.len(), 1, "{ch} monitored by {v:?}");
        let expected = u64::from(early.contains(&ch.as_str()) || late.contains(&ch.as_str()));
        assert_eq!(
            v[0].2, expected,
            "{ch}: alarms counted by its owner {}",
            v[0].0
        );
        assert_eq!(v[0].0, owners[ch][0].0, "{ch} changed owner");
    }
    // Every alarm reached the subscriber, once per faulty channel.
    let t = Instant::now();
    loop {
        let mut got: Vec<String> = alarms.lock().unwrap().iter().map(|a| a.0.clone()).collect();
        got.sort();
        let mut want: Vec<String> = early.iter().chain(&late).map(|s| (*s).to_owned()).collect();
        want.sort();
        if got == want {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "alarms {got:?}, expected {want:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    for (ch, k, onset) in alarms.lock().unwrap().iter() {
        let fault_at = if late.contains(&ch.as_str()) {
            601
        } else {
            201
        };
        assert!(*k >= fault_at && *k < fault_at + 50, "{ch}: alarm at {k}");
        assert!(onset.abs_diff(fault_at) <= 10, "{ch}: onset {onset}");
    }
    drop(a);
    drop(b);
    let _ = publisher.close().await;
    router.stop().await;
}
