//! Live payloads that give a channel's signals by name, with the real binary on a real
//! Zenoh session over loopback (explicit tcp/127.0.0.1 endpoints, multicast scouting
//! off): `glrmon run` on a channel whose `[channels.columns]` name its signals reads
//! `{"t": …, "V101": …, "SI201": …, "II202": …}` and `{"u": {"V101": …}, "y": {…}}`
//! as it reads positional arrays, and publishes the same alarm; a payload missing a name
//! is an `error` record naming the channel and the signal.

#[path = "support.rs"]
mod support;

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use glrmon_wire::{Record, decode_record};
use support::{Scratch, free_port, glrmon, run_ok};
use zenoh::Wait as _;

/// The DC motor of config/examples/dc-motor.toml with its columns named as a plant
/// names them, listening on `endpoint`, one `stat` per 1000 samples.
fn config(dir: &Path, endpoint: &str) -> PathBuf {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let motor = std::fs::read_to_string(example).unwrap().replace(
        "[channels.glr]",
        "[channels.columns]\nu = [\"V101\"]\ny = [\"SI201\", \"II202\"]\n\n[channels.glr]",
    );
    let text = format!(
        "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n\
         [daemon]\nstat_every = 1000\n\n{motor}"
    );
    let path = dir.join("motor.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A running `glrmon run`, killed at the end of the test.
struct Daemon(Child);

impl Daemon {
    fn start(config: &Path, instance: &str) -> Self {
        let mut child = glrmon()
            .args(["run", "--config"])
            .arg(config)
            .args(["--instance", instance])
            .env("GLRMON_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.contains("monitoring 1 channel(s)"), "{line}");
        Self(child)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The samples of a simulated run with an actuator bias from sample 200: (k, t, u, y).
fn simulated(dir: &Path, config: &Path) -> Vec<(u64, f64, f64, [f64; 2])> {
    let csv = dir.join("sim.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(config)
            .args(["--samples", "400", "--seed", "7"])
            .args(["--fault", "actuator_bias:0.5", "--onset", "200", "--output"])
            .arg(&csv),
    );
    let text = std::fs::read_to_string(csv).unwrap();
    assert!(text.starts_with("k,t,V101,SI201,II202\n"), "{text:.80}");
    text.lines()
        .skip(1)
        .map(|line| {
            let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            (f[0] as u64, f[1], f[2], [f[3], f[4]])
        })
        .collect()
}

/// Publishes `payloads` on `plant/dc_motor` to the daemon at `endpoint` and returns the
/// records it publishes on `glrmon/dc_motor/*` (but `stat`) until `until` says enough.
fn exchange(endpoint: &str, payloads: &[String], until: impl Fn(&[Record]) -> bool) -> Vec<Record> {
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let session = glrmon_zenoh::open(&glrmon_zenoh::SessionSettings {
            mode: Some("client".into()),
            connect: vec![endpoint.to_owned()],
            multicast_scouting: Some(false),
            ..glrmon_zenoh::SessionSettings::default()
        })
        .await
        .unwrap();
        let results = session
            .declare_subscriber("glrmon/dc_motor/*")
            .await
            .unwrap();
        let publisher = session
            .declare_publisher("plant/dc_motor")
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .await
            .unwrap();
        let t = Instant::now();
        while !publisher.matching_status().await.unwrap().matching() {
            assert!(t.elapsed() < Duration::from_secs(10), "no subscriber");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        for p in payloads {
            publisher.put(p.as_bytes().to_vec()).wait().unwrap();
        }
        let mut records = Vec::new();
        let t = Instant::now();
        while !until(&records) {
            let left = Duration::from_secs(20).saturating_sub(t.elapsed());
            assert!(!left.is_zero(), "records so far: {records:#?}");
            if let Ok(Ok(sample)) = tokio::time::timeout(left, results.recv_async()).await {
                let record = decode_record(&sample.payload().to_bytes()).unwrap();
                if !matches!(record, Record::Stat(_)) {
                    records.push(record);
                }
            }
        }
        session.close().await.unwrap();
        records
    })
}

/// The alarm (as published, JSON) of `payloads` sent to a fresh daemon.
fn alarm_of(dir: &Path, tag: &str, payloads: &[String]) -> String {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = config(dir, &endpoint);
    let _daemon = Daemon::start(&config, &format!("named-{tag}-{}", std::process::id()));
    let records = exchange(&endpoint, payloads, |r| {
        r.iter().any(|r| matches!(r, Record::Alarm(_)))
    });
    let errors: Vec<_> = records
        .iter()
        .filter(|r| matches!(r, Record::Error(_)))
        .collect();
    assert!(errors.is_empty(), "{tag}: {errors:#?}");
    let alarm = records
        .iter()
        .find(|r| matches!(r, Record::Alarm(_)))
        .unwrap();
    let mut json = Vec::new();
    glrmon_wire::encode_json(alarm, &mut json).unwrap();
    String::from_utf8(json).unwrap()
}

#[test]
fn named_payloads_raise_the_alarm_of_positional_ones() {
    let scratch = Scratch::new("named-payloads");
    let samples = simulated(&scratch.0, &config(&scratch.0, "tcp/127.0.0.1:1"));
    // `{:?}` of a finite f64 is a JSON number that reads back to the same bits.
    let positional: Vec<String> = samples
        .iter()
        .map(|(k, t, u, y)| {
            format!(
                r#"{{"k":{k},"t":{t:?},"u":[{u:?}],"y":[{:?},{:?}]}}"#,
                y[0], y[1]
            )
        })
        .collect();
    let flat: Vec<String> = samples
        .iter()
        .map(|(k, t, u, y)| {
            format!(
                r#"{{"k":{k},"t":{t:?},"II202":{:?},"V101":{u:?},"SI201":{:?}}}"#,
                y[1], y[0]
            )
        })
        .collect();
    let grouped: Vec<String> = samples
        .iter()
        .map(|(k, t, u, y)| {
            format!(
                r#"{{"k":{k},"t":{t:?},"u":{{"V101":{u:?}}},"y":{{"II202":{:?},"SI201":{:?}}}}}"#,
                y[1], y[0]
            )
        })
        .collect();
    let want = alarm_of(&scratch.0, "positional", &positional);
    // The fault's alarm (a false alarm before it would not test much).
    assert!(want.contains(r#""k":20"#), "{want}");
    assert_eq!(alarm_of(&scratch.0, "flat", &flat), want);
    assert_eq!(alarm_of(&scratch.0, "grouped", &grouped), want);
}

#[test]
fn a_payload_missing_a_name_is_an_error_naming_channel_and_field() {
    let scratch = Scratch::new("named-payload-error");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = config(&scratch.0, &endpoint);
    let _daemon = Daemon::start(&config, &format!("named-error-{}", std::process::id()));
    let payloads = [
        r#"{"k":0,"t":0.0,"V101":1.0,"SI201":0.1}"#.to_owned(),
        r#"{"k":1,"t":0.01,"V101":1.0,"SI201":0.1,"II202":0.2,"SI202":3}"#.to_owned(),
    ];
    let records = exchange(&endpoint, &payloads, |r| r.len() >= 2);
    let messages: Vec<(&str, &str)> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some((e.code.as_str(), e.message.as_str())),
            _ => None,
        })
        .collect();
    assert_eq!(
        messages,
        [
            (
                "missing_field",
                r#"channel "dc_motor": field II202 is missing"#
            ),
            (
                "unknown_field",
                r#"channel "dc_motor": field SI202 is not a field of a sample (k, t, u, y, p)"#
            ),
        ]
    );
}
