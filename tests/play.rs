//! `glrmon play` and `glrmon info` end to end, with the real binary, a real daemon on
//! loopback (explicit tcp/127.0.0.1 endpoints, multicast scouting off) and real MCAP
//! files: a recording with a fault played into `glrmon run` gives the alarms that
//! `glrmon replay` of the same file gives.

#[path = "support.rs"]
mod support;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use glrmon_record::{Event, McapReader, TopicKind};
use glrmon_zenoh::SessionSettings;
use support::{Scratch, free_port, glrmon, run_ok};
use zenoh::query::QueryTarget;

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2014-unstable.toml")
}

/// A recording of `samples` simulated samples of the §6.1 channel with a jump at 701.
fn simulated_recording(dir: &Path, samples: u64) -> PathBuf {
    let path = dir.join("sim.mcap");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(example())
            .args(["--samples", &samples.to_string(), "--seed", "3"])
            .args(["--fault", "x0_jump:4", "--onset", "701"])
            .arg("--output")
            .arg(&path),
    );
    path
}

struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Polls the daemon's status queryable until it contains `want`.
fn wait_status(endpoint: &str, want: &str) {
    use zenoh::Wait as _;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let session = rt
        .block_on(glrmon_zenoh::open(&SessionSettings {
            mode: Some("client".into()),
            connect: vec![endpoint.to_owned()],
            multicast_scouting: Some(false),
            ..SessionSettings::default()
        }))
        .unwrap();
    let t = Instant::now();
    loop {
        let replies = session
            .get("glrmon/@status/*")
            .target(QueryTarget::All)
            .timeout(Duration::from_secs(2))
            .wait()
            .unwrap();
        let mut last = String::new();
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                last = s.payload().try_to_string().unwrap().into_owned();
            }
        }
        if last.contains(want) {
            return;
        }
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "status never reached {want}: {last}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The records of `kinds` in a recording, as JSON text, in order.
fn records_in(path: &Path, kinds: &[TopicKind]) -> Vec<String> {
    let mut r = McapReader::new(BufReader::new(std::fs::File::open(path).unwrap())).unwrap();
    let mut out = Vec::new();
    while let Some(e) = r.next_event().unwrap() {
        if let Event::Message(m) = e
            && m.topic.kind.is_some_and(|k| kinds.contains(&k))
        {
            out.push(String::from_utf8(m.data).unwrap());
        }
    }
    out
}

/// (channel, onset, isolated faults, k) of each alarm.
fn alarm_summary(records: &[String]) -> Vec<(String, u64, Vec<String>, u64)> {
    records
        .iter()
        .map(|r| serde_json::from_str::<serde_json::Value>(r).unwrap())
        .filter(|v| v["type"] == "alarm")
        .map(|v| {
            let isolated = v["isolation"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|i| i["isolated"] == true)
                .map(|i| i["fault"].as_str().unwrap().to_owned())
                .collect();
            (
                v["channel"].as_str().unwrap().to_owned(),
                v["onset"].as_u64().unwrap(),
                isolated,
                v["k"].as_u64().unwrap(),
            )
        })
        .collect()
}

/// A recording with a fault, played into `glrmon run` as fast as possible: the daemon
/// sees every sample (no drop) and raises the alarms `glrmon replay` of the same file
/// gives — same channel, onset, isolated fault and k, and the same records byte for
/// byte (alarm, isolation, alarm_end).
#[test]
fn play_into_a_daemon_gives_the_alarms_of_replay() {
    let scratch = Scratch::new("daemon");
    let samples = 1500;
    let sim = simulated_recording(&scratch.0, samples);

    // The replay of the file.
    let jsonl = scratch.0.join("replay.jsonl");
    run_ok(glrmon().arg("replay").arg(&sim).arg("--output").arg(&jsonl));
    let kinds = ["alarm", "isolation", "alarm_end"];
    let replayed: Vec<String> = std::fs::read_to_string(&jsonl)
        .unwrap()
        .lines()
        .filter(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            kinds.contains(&v["type"].as_str().unwrap())
        })
        .map(str::to_owned)
        .collect();
    let replay_alarms = alarm_summary(&replayed);
    assert!(!replay_alarms.is_empty(), "the fault raises an alarm");

    // The daemon, recording.
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let rec = scratch.0.join("rec");
    let unstable = std::fs::read_to_string(example()).unwrap();
    let config = scratch.0.join("daemon.toml");
    std::fs::write(
        &config,
        format!(
            "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n\
             [daemon]\nstat_every = 0\ninstance = \"play\"\n\n[recording]\nenabled = true\n\
             directory = \"{}\"\n\n{unstable}",
            rec.display()
        ),
    )
    .unwrap();
    let mut child = glrmon()
        .args(["run", "--config"])
        .arg(&config)
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
    let mut daemon = Daemon(child);

    let t = Instant::now();
    let out = run_ok(
        glrmon()
            .arg("play")
            .arg(&sim)
            .args(["--rate", "0", "--connect", &endpoint]),
    );
    let played = t.elapsed();
    let said = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        said.contains(&format!(
            "{samples} samples of 1 channel(s) (unstable on plant/unstable)"
        )),
        "{said}"
    );
    wait_status(
        &endpoint,
        &format!("\"channel\":\"unstable\",\"samples\":{samples},"),
    );
    Command::new("kill")
        .args(["-TERM", &daemon.0.id().to_string()])
        .status()
        .unwrap();
    let t = Instant::now();
    while daemon.0.try_wait().unwrap().is_none() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "the daemon did not stop"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut finished: Vec<PathBuf> = std::fs::read_dir(&rec)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    finished.sort();
    assert_eq!(finished.len(), 1, "{finished:?}");
    let live = records_in(
        &finished[0],
        &[TopicKind::Alarm, TopicKind::Isolation, TopicKind::AlarmEnd],
    );
    assert_eq!(
        records_in(&finished[0], &[TopicKind::Inputs]).len(),
        samples as usize,
        "every sample reached the monitor"
    );
    assert!(
        records_in(&finished[0], &[TopicKind::Intake]).is_empty(),
        "no drop"
    );
    let live_alarms = alarm_summary(&live);
    assert_eq!(live_alarms, replay_alarms);
    assert_eq!(live, replayed, "the records differ");
    eprintln!(
        "play ({samples} samples in {:.3} s) vs replay: {} alarm(s) (channel, onset, isolated, k) {:?}; {} identical records",
        played.as_secs_f64(),
        live_alarms.len(),
        live_alarms,
        live.len()
    );

    // `glrmon info` of the daemon's recording counts what was read here.
    let out = run_ok(glrmon().arg("info").arg("--json").arg(&finished[0]));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let count = |topic: &str| {
        v["topics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["topic"] == topic)
            .map_or(0, |t| t["messages"].as_u64().unwrap())
    };
    assert_eq!(count("glrmon/unstable/inputs"), samples);
    assert_eq!(count("glrmon/unstable/alarm"), live_alarms.len() as u64);
    assert_eq!(count("glrmon/log"), live_alarms.len() as u64);
    assert_eq!(v["finished"], true);
    assert_eq!(v["metadata"]["instance"], "play");
}

/// `glrmon info` of a known recording: its counts, its one topic (topics are declared
/// with their first message), its time range; `--json` parses; a file that is not a
/// recording is an error naming it (exit 1); `play` of an unknown channel too.
#[test]
fn info_prints_the_counts_of_a_known_recording() {
    let scratch = Scratch::new("info");
    let sim = simulated_recording(&scratch.0, 300);
    let out = run_ok(glrmon().arg("info").arg(&sim));
    let text = String::from_utf8(out.stdout).unwrap();
    eprintln!("{text}");
    assert!(text.contains("status:    finished"), "{text}");
    assert!(text.contains("messages:  300"), "{text}");
    assert!(text.contains("channels:  unstable"), "{text}");
    assert!(text.contains("topics:    1"), "{text}");
    assert!(text.contains("glrmon/unstable/inputs"), "{text}");
    // `simulate` logs sample k at its time t = k s (the example's period is 1 s):
    // simulation seconds, shown as seconds (a wall-clock log time would be ISO-8601).
    assert!(text.contains("start:     0.000 s"), "{text}");
    assert!(text.contains("end:       299.000 s"), "{text}");

    let out = run_ok(glrmon().arg("info").arg("--json").arg(&sim));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["messages"], 300);
    assert_eq!(v["finished"], true);
    assert_eq!(v["channels"], serde_json::json!(["unstable"]));
    assert_eq!(v["topics"].as_array().unwrap().len(), 1);
    assert_eq!(v["topics"][0]["schema"], "glrmon.Sample");
    assert_eq!(v["topics"][0]["messages"], 300);
    assert_eq!(v["topics"][0]["last_ns"], 299_000_000_000_u64);
    assert!(v["glrmon_version"].is_string(), "{v}");

    let bad = scratch.0.join("bad.mcap");
    std::fs::write(&bad, b"not a recording").unwrap();
    for args in [vec!["info"], vec!["play"]] {
        let out = glrmon().args(&args).arg(&bad).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(&*bad.display().to_string()), "{err}");
        assert!(err.contains("not an MCAP file"), "{err}");
    }
    let out = glrmon()
        .arg("play")
        .arg(&sim)
        .args(["--channel", "nope"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("channel \"nope\" is not in the recorded configuration (channels: unstable)"),
        "{err}"
    );
}
