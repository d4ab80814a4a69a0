//! SIGHUP reloads a running daemon's thresholds and alarm settings without
//! restarting its filters, and refuses (logging why, changing nothing) an invalid file
//! or a change that needs a restart. Real binary, a real Zenoh session on loopback.

#[path = "support.rs"]
mod support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_wire::{Sample, encode_sample};
use glrmon_zenoh::SessionSettings;
use zenoh::Wait as _;

struct Daemon {
    child: Child,
    stderr: Arc<Mutex<String>>,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Daemon {
    fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(ok.success());
    }

    /// Waits (bounded) until the log contains `text` `times` times.
    fn wait_log(&self, text: &str, times: usize) -> String {
        let t = Instant::now();
        loop {
            let log = self.stderr.lock().unwrap().clone();
            if log.matches(text).count() >= times {
                return log;
            }
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "no {text:?} in\n{log}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// (samples, alarms, alarm active) of the channel from the status queryable.
async fn counters(session: &zenoh::Session) -> (u64, u64, bool) {
    let replies = glrmon_zenoh::query_status(session, "*", Duration::from_secs(2))
        .await
        .unwrap();
    let v: serde_json::Value = serde_json::from_str(&replies[0].1).unwrap();
    let c = &v["channels"][0];
    (
        c["samples"].as_u64().unwrap(),
        c["alarms"].as_u64().unwrap(),
        c["alarm_active"].as_bool().unwrap(),
    )
}

async fn wait_samples(session: &zenoh::Session, n: u64) -> (u64, u64, bool) {
    let t = Instant::now();
    loop {
        let c = counters(session).await;
        if c.0 == n {
            return c;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "stuck at {c:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sighup_applies_thresholds_and_refuses_what_needs_a_restart() {
    let dir = std::env::temp_dir().join(format!("glrmon-reload-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let motor = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"),
    )
    .unwrap();
    assert!(motor.contains("false_alarm = 1e-4") && motor.contains("R = 0.0025"));
    let head = format!(
        "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\n\n[daemon]\nstat_every = 0\ninstance = \"reload\"\n\n"
    );
    let cfg = dir.join("plant.toml");
    std::fs::write(&cfg, format!("{head}{motor}")).unwrap();
    let (mut child, stderr) = support::spawn_logged(
        Command::new(env!("CARGO_BIN_EXE_glrmon"))
            .args(["run", "--config"])
            .arg(&cfg),
    );
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.contains("monitoring 1 channel(s)"), "{line}");
    let daemon = Daemon { child, stderr };

    // Clean samples of the DC motor.
    let csv = dir.join("clean.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_glrmon"))
        .args(["simulate", "--config"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"))
        .args(["--samples", "600", "--seed", "5", "--output"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    // Columns: k, t, u0, y0, y1 (as `glrmon simulate` writes them).
    assert!(text.starts_with("k,t,u0,y0,y1"), "{}", &text[..40]);
    let session = glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .unwrap();
    let publisher = session
        .declare_publisher("plant/dc_motor")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .unwrap();
    // Rows `range` of the clean data, their indices shifted by `shift` (to publish the
    // same data again later on).
    let publish_shifted = |range: std::ops::Range<usize>, shift: u64| {
        for r in &rows[range] {
            let s = Sample {
                k: Some(r[0] as u64 + shift),
                t: None,
                u: vec![r[2]],
                y: vec![r[3], r[4]],
                p: Vec::new(),
            };
            let mut b = Vec::new();
            encode_sample("dc_motor", &s, &mut b).unwrap();
            publisher.put(b).wait().unwrap();
        }
    };
    let publish = |range: std::ops::Range<usize>| publish_shifted(range, 0);
    let t = Instant::now();
    while !publisher.matching_status().await.unwrap().matching() {
        assert!(t.elapsed() < Duration::from_secs(10));
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    publish(0..300);
    assert_eq!(
        wait_samples(&session, 300).await,
        (300, 0, false),
        "clean data, no alarm"
    );

    // A far lower threshold, applied by SIGHUP: clean data now alarms, and the filter
    // goes on (the sample count continues from 300).
    let low = motor.replace("false_alarm = 1e-4", "threshold = 0.5");
    std::fs::write(&cfg, format!("{head}{low}")).unwrap();
    daemon.signal("-HUP");
    daemon.wait_log("Configuration reloaded", 1);
    publish(300..450);
    let (samples, alarms, active) = wait_samples(&session, 450).await;
    assert_eq!(samples, 450);
    assert!(
        alarms >= 1 && active,
        "the reloaded threshold 0.5 raised no alarm"
    );

    // A model change needs a restart: refused, and the threshold stays 0.5.
    let model = low.replace("R = 0.0025", "R = 0.003");
    std::fs::write(&cfg, format!("{head}{model}")).unwrap();
    daemon.signal("-HUP");
    let log = daemon.wait_log("Reload refused", 1);
    assert!(
        log.contains("channels \"dc_motor\".model: changed (needs a restart"),
        "{log}"
    );
    // An invalid file is refused too, naming the problem.
    std::fs::write(&cfg, format!("{head}{low}\n[[channels]]\nname = 3\n")).unwrap();
    daemon.signal("-HUP");
    daemon.wait_log("Reload refused", 2);
    publish(450..600);
    // Under the original threshold (27.6) clean data would have ended the episode.
    let (samples, _, active) = wait_samples(&session, 600).await;
    assert_eq!(samples, 600);
    assert!(
        active,
        "threshold 0.5 no longer in force after the refusals"
    );

    // A storm of SIGHUPs (the same file, then a changed one) while samples flow: reloads
    // run off the intake path and are coalesced; every sample is processed, the last
    // file is in force (its threshold raised back: the episode ends on clean data).
    let before = daemon
        .stderr
        .lock()
        .unwrap()
        .matches("Configuration reloaded")
        .count();
    std::fs::write(&cfg, format!("{head}{low}")).unwrap();
    for _ in 0..10 {
        daemon.signal("-HUP");
    }
    let high = motor.replace("false_alarm = 1e-4", "threshold = 1000.0");
    std::fs::write(&cfg, format!("{head}{high}")).unwrap();
    for _ in 0..10 {
        daemon.signal("-HUP");
    }
    daemon.wait_log("Configuration reloaded", before + 1);
    // Wait for the coalesced reloads to settle: the last SIGHUP's reread is applied.
    std::thread::sleep(Duration::from_millis(1000));
    let reloads = daemon
        .stderr
        .lock()
        .unwrap()
        .matches("Configuration reloaded")
        .count()
        - before;
    assert!(
        (1..=20).contains(&reloads),
        "{reloads} reloads for 20 SIGHUPs"
    );
    publish_shifted(0..600, 600);
    let (samples, _, active) = wait_samples(&session, 1200).await;
    assert_eq!(samples, 1200, "no sample lost to the reloads");
    assert!(
        !active,
        "the last file's threshold 1000 is in force: the episode ended"
    );

    daemon.signal("-TERM");
    let mut daemon = daemon;
    let code = support::exit_code_within(&mut daemon.child, Duration::from_secs(10));
    assert_eq!(code, Some(0));
    let _ = session.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// A SIGHUP with each hostile configuration (an empty H, the
/// oversized windows and history, a key in glrmon's own space, bad instance names) is
/// refused by the same validation as `glrmon validate`, naming the field, and the daemon
/// goes on: no panic (H = [] killed it with exit 101), samples still processed, a clean
/// exit 0 at SIGTERM.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sighup_with_hostile_configs_is_refused_and_the_daemon_goes_on() {
    let dir = std::env::temp_dir().join(format!("glrmon-reload21-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let motor = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"),
    )
    .unwrap();
    let head = |instance: &str| {
        format!(
            "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\n\n[daemon]\nstat_every = 0\ninstance = \"{instance}\"\n\n"
        )
    };
    let cfg = dir.join("plant.toml");
    std::fs::write(&cfg, format!("{}{motor}", head("reload21"))).unwrap();
    let (mut child, stderr) = support::spawn_logged(
        Command::new(env!("CARGO_BIN_EXE_glrmon"))
            .args(["run", "--config"])
            .arg(&cfg),
    );
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.contains("monitoring 1 channel(s)"), "{line}");
    let mut daemon = Daemon { child, stderr };
    let h = "H = [[1.0, 0.0], [0.0, 1.0]]";
    let window = "window = 100";
    let name = "name = \"dc_motor\"";
    assert!(motor.contains(h) && motor.contains(window) && motor.contains(name));
    let hostile: Vec<(String, &str)> = vec![
        (motor.replace(h, "H = []"), "model.H has no rows"),
        (
            motor.replace(h, "H = [[1.0, 0.0], [0.0]]"),
            "model.H: row 1 has 1 entries",
        ),
        (
            motor.replace("P0 = 0.01", "P0 = []"),
            "model.P0 has no rows",
        ),
        (
            motor.replace(window, "window = 9223372036854775807"),
            "glr.window: w = 9223372036854775807 is more than 100000",
        ),
        (
            motor.replace(window, "window = 1000000000"),
            "glr.window: w = 1000000000 is more than 100000",
        ),
        (
            format!("{motor}\n[channels.diagnosis]\nenabled = true\nhistory = 1000000000000\n"),
            "diagnosis.history: 1000000000000 samples is more than 1000000",
        ),
        (
            motor.replace(name, "name = \"dc_motor\"\nkey = \"glrmon/**\""),
            "intersects glrmon's own key space glrmon/**",
        ),
    ];
    let mut refusals = 0;
    for (text, expected) in &hostile {
        std::fs::write(&cfg, format!("{}{text}", head("reload21"))).unwrap();
        daemon.signal("-HUP");
        refusals += 1;
        let log = daemon.wait_log("Reload refused", refusals);
        assert!(log.contains(expected), "wanted «{expected}» in\n{log}");
    }
    for (instance, expected) in [
        ("", "daemon.instance is empty"),
        ("a/b/**", "daemon.instance"),
    ] {
        std::fs::write(&cfg, format!("{}{motor}", head(instance))).unwrap();
        daemon.signal("-HUP");
        refusals += 1;
        let log = daemon.wait_log("Reload refused", refusals);
        assert!(log.contains(expected), "wanted «{expected}» in\n{log}");
    }
    assert!(
        daemon.child.try_wait().unwrap().is_none(),
        "the daemon exited: {}",
        daemon.stderr.lock().unwrap()
    );
    // Still monitoring: samples go through.
    let session = support::publish_dc_motor(&endpoint, 50).await;
    assert_eq!(wait_samples(&session, 50).await.0, 50);
    daemon.signal("-TERM");
    let code = support::exit_code_within(&mut daemon.child, Duration::from_secs(10));
    assert_eq!(code, Some(0));
    let _ = session.close().await;
    let _ = std::fs::remove_dir_all(&dir);
}
