//! The daemon as a library, embedded as a user's program would: a real Zenoh session
//! on loopback (explicit TCP endpoints, no multicast scouting), a publisher in a
//! second session, a sink of the program's own; reload and shutdown through the API.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glrmon_daemon::{DaemonBuilder, NoEvents};
use glrmon_runtime::MemorySink;
use glrmon_wire::{ErrorCode, Record, Sample, encode_sample};
use glrmon_zenoh::{Endpoints, SessionSettings};

const CONFIG: &str = r#"
[[channels]]
name = "tank"
key = "plant/tank"
[channels.model]
F = [[0.9]]
H = [[1.0]]
Q = 0.01
R = 0.04
[[channels.faults]]
name = "bias"
kind = "sensor_bias"
output = 0
[channels.glr]
window = 20
threshold = 30.0
"#;

fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_embedded_daemon_alarms_reloads_and_drains() {
    let endpoint = free_endpoint();
    let settings = SessionSettings {
        mode: Some("peer".into()),
        listen: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    };
    let session = glrmon_zenoh::open(&settings).await.unwrap();
    let memory = MemorySink::default();
    let records = memory.records();
    let cfg = glrmon_spec::parse(CONFIG).unwrap();
    let mut daemon = DaemonBuilder::new(cfg, "embedded")
        .sink(Box::new(memory))
        .events(Arc::new(NoEvents))
        .start(&session, &Endpoints::of(&settings).unwrap())
        .await
        .unwrap();
    assert_eq!(daemon.instance(), "embedded");
    assert_eq!(daemon.runtime().channel_names(), ["tank"]);

    let plant = glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .unwrap();
    // The subscriber is declared: wait until the plant's session can reach it.
    let publisher = plant.declare_publisher("plant/tank").await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut buf = Vec::new();
    for k in 0..300_u64 {
        let bias = if k >= 200 { 3.0 } else { 0.0 };
        let sample = Sample {
            k: Some(k),
            y: vec![0.05 * ((k as f64) * 0.7).sin() + bias],
            ..Sample::default()
        };
        buf.clear();
        encode_sample("tank", &sample, &mut buf).unwrap();
        publisher.put(buf.clone()).await.unwrap();
    }
    publisher
        .put(b"{\"k\": 300, \"y\": [\"x\"]}".to_vec())
        .await
        .unwrap();
    let stats = daemon.runtime().stats();
    let started = Instant::now();
    while stats[0].samples.load(std::sync::atomic::Ordering::Relaxed) < 300 {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "samples not processed"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }

    // A threshold is retuned in place; a model change needs a restart.
    let retuned = CONFIG.replace("threshold = 30.0", "threshold = 40.0");
    assert_eq!(
        daemon
            .reload(glrmon_spec::parse(&retuned).unwrap())
            .unwrap(),
        1
    );
    let remodelled = retuned.replace("F = [[0.9]]", "F = [[0.8]]");
    let refused = daemon
        .reload(glrmon_spec::parse(&remodelled).unwrap())
        .unwrap_err();
    assert!(refused.to_string().contains("model"), "{refused}");
    assert!(daemon.config().source.contains("threshold = 40.0"));

    let stopped = daemon.shutdown(Duration::from_secs(10)).await;
    assert!(stopped.in_time);
    assert!(stopped.recorder.is_none());
    let got: Vec<Record> = records
        .lock()
        .unwrap()
        .iter()
        .map(|o| o.record.clone())
        .collect();
    let alarm = got
        .iter()
        .find_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .expect("an alarm");
    assert!((199..=201).contains(&alarm.onset), "{alarm:#?}");
    assert!(alarm.k >= 200 && alarm.k <= 203, "{alarm:#?}");
    let refused: Vec<_> = got
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some(e.code),
            _ => None,
        })
        .collect();
    assert_eq!(refused, [ErrorCode::WrongType]);
    plant.close().await.unwrap();
    session.close().await.unwrap();
}
