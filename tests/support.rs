//! Helpers shared by the end-to-end tests (the real binary, scratch directories, free
//! ports, daemons whose log is watched, a client publishing samples): included with
//! `#[path]`, not a test of its own. Each test uses some of them.
#![allow(dead_code)]

use std::io::Read;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The binary under test.
pub(crate) fn glrmon() -> Command {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
}

/// `glrmon evaluate` of the 2014 gas pipeline's Table 1 faults (fault 1 −2e-5, fault 2
/// −1e-5 at sample 300 of 500), `runs` runs each: the Fig. 7-8 protocol. The caller
/// adds the outputs (`--json`, `--json-out`, `--report`).
pub(crate) fn evaluate_gas_pipeline_table1(runs: usize) -> Command {
    let mut cmd = glrmon();
    cmd.args(["evaluate", "--config"])
        .arg(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../config/examples/paper2014-gas-pipeline.toml"),
        )
        .args(["--fault", "g0_leak:-2e-5,gp_leak:-1e-5", "--runs"])
        .arg(runs.to_string())
        .args(["--onset", "300", "--samples", "500"]);
    cmd
}

/// Runs `cmd` and returns its output, failing the test with both streams when it fails.
pub(crate) fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The exit code of `child`, which must exit within `limit` (after a SIGTERM, say).
pub(crate) fn exit_code_within(child: &mut Child, limit: Duration) -> Option<i32> {
    let t = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s.code();
        }
        assert!(t.elapsed() < limit, "no exit within {limit:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A scratch directory `glrmon-<tag>-<pid>` in the temporary directory, removed at the
/// end of the test.
pub(crate) struct Scratch(pub(crate) PathBuf);

impl Scratch {
    pub(crate) fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("glrmon-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Publishes `n` samples (k = 0…n−1, u = [1], y = [0, 0]) of the `dc_motor` channel on
/// `plant/dc_motor` from a client session connected to `endpoint`, once a subscriber
/// matches (10 s at most). The session stays open for the caller (a client the daemon
/// counts, a subscriber of its results).
pub(crate) async fn publish_dc_motor(endpoint: &str, n: u64) -> zenoh::Session {
    use zenoh::Wait as _;
    let session = glrmon_zenoh::open(&glrmon_zenoh::SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint.to_owned()],
        multicast_scouting: Some(false),
        ..glrmon_zenoh::SessionSettings::default()
    })
    .await
    .unwrap();
    let publisher = session
        .declare_publisher("plant/dc_motor")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .unwrap();
    let t = Instant::now();
    while !publisher.matching_status().await.unwrap().matching() {
        assert!(t.elapsed() < Duration::from_secs(10));
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    for k in 0..n {
        let s = glrmon_wire::Sample {
            k: Some(k),
            t: None,
            u: vec![1.0],
            y: vec![0.0, 0.0],
            p: Vec::new(),
        };
        let mut b = Vec::new();
        glrmon_wire::encode_sample("dc_motor", &s, &mut b).unwrap();
        publisher.put(b).wait().unwrap();
    }
    session
}

/// A free TCP port on loopback.
pub(crate) fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

/// Spawns `cmd` (INFO log, no colours, stdout piped) with its standard error collected
/// as it comes, for tests that wait for a log line.
pub(crate) fn spawn_logged(cmd: &mut Command) -> (Child, Arc<Mutex<String>>) {
    let mut child = cmd
        .env("GLRMON_LOG", "info")
        .env("NO_COLOR", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = Arc::new(Mutex::new(String::new()));
    let sink = stderr.clone();
    let mut pipe = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = pipe.read(&mut buf) {
            if n == 0 {
                break;
            }
            sink.lock()
                .unwrap()
                .push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    });
    (child, stderr)
}

/// The Python of target/pyenv, where `make deps-python` installs the official libraries
/// (mcap, mcap-ros2-support, protobuf) that the binary-format tests encode with.
pub(crate) fn python() -> Command {
    let target = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .to_path_buf();
    let python = target.join("pyenv/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run `make deps-python` (the official encoders these tests compare with)",
        python.display()
    );
    let mut cmd = Command::new(python);
    cmd.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../../tests/python"));
    cmd
}

/// The bytes of a hexadecimal string.
pub(crate) fn unhex(hex: &str) -> Vec<u8> {
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
        .collect()
}

/// A client session to the daemon at `endpoint` (multicast scouting off).
pub(crate) async fn client(endpoint: &str) -> zenoh::Session {
    glrmon_zenoh::open(&glrmon_zenoh::SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint.to_owned()],
        multicast_scouting: Some(false),
        ..glrmon_zenoh::SessionSettings::default()
    })
    .await
    .unwrap()
}

/// A reliable publisher on `key`, returned once a subscriber matches (10 s at most).
pub(crate) async fn matched_publisher(
    session: &zenoh::Session,
    key: &str,
) -> zenoh_ext::AdvancedPublisher<'static> {
    matched_plant_publisher(session, key, 0).await
}

/// A plant publisher on `key` keeping its last `cache` samples
/// (`glrmon_zenoh::plant_publisher`, JSON), returned once a subscriber matches (10 s at
/// most).
pub(crate) async fn matched_plant_publisher(
    session: &zenoh::Session,
    key: &str,
    cache: usize,
) -> zenoh_ext::AdvancedPublisher<'static> {
    let p = glrmon_zenoh::plant_publisher(
        session,
        key,
        zenoh::bytes::Encoding::APPLICATION_JSON,
        cache,
    )
    .await
    .unwrap();
    let t = Instant::now();
    while !p.matching_status().await.unwrap().matching() {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "no subscriber on {key}"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    p
}

/// The next `n` samples of `sim` as wire samples, numbered from `first`.
pub(crate) fn wire_samples(
    sim: &mut glrmon_sim::Simulator,
    first: u64,
    n: u64,
) -> Vec<glrmon_wire::Sample> {
    (first..first + n)
        .map(|k| {
            let x = sim.next_sample();
            glrmon_wire::Sample {
                k: Some(k),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            }
        })
        .collect()
}

/// A running `glrmon run --config <config> --instance <instance>` (WARN log), returned
/// once it says it monitors `channels` channels; killed when dropped.
pub(crate) struct RunningDaemon(pub(crate) Child);

impl RunningDaemon {
    pub(crate) fn start(config: &std::path::Path, instance: &str, channels: usize) -> Self {
        use std::io::BufRead as _;
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
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        // Owned before the check, so that a failed check kills it too (a daemon left
        // running would hold the test's output open).
        let daemon = Self(child);
        assert!(
            line.contains(&format!("monitoring {channels} channel(s)")),
            "{line}"
        );
        daemon
    }
}

impl Drop for RunningDaemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The records (but `stat`) received on `results` until `until` says enough (30 s at
/// most).
pub(crate) async fn collect_records(
    results: &zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    until: impl Fn(&[glrmon_wire::Record]) -> bool,
) -> Vec<glrmon_wire::Record> {
    let mut records = Vec::new();
    let t = Instant::now();
    while !until(&records) {
        let left = Duration::from_secs(30).saturating_sub(t.elapsed());
        assert!(!left.is_zero(), "records so far: {records:#?}");
        if let Ok(Ok(sample)) = tokio::time::timeout(left, results.recv_async()).await {
            let record = glrmon_wire::decode_record(&sample.payload().to_bytes()).unwrap();
            if !matches!(record, glrmon_wire::Record::Stat(_)) {
                records.push(record);
            }
        }
    }
    records
}

/// The router: `zenohd` (a child process) or a router-mode session of this process.
pub(crate) enum Router {
    Zenohd(Child),
    Session(zenoh::Session),
}

/// `zenohd` from $GLRMON_ZENOHD, the PATH or cargo's bin directory; none when
/// GLRMON_TEST_ROUTER=session asks for the in-process router.
pub(crate) fn zenohd_binary() -> Option<PathBuf> {
    if std::env::var("GLRMON_TEST_ROUTER").as_deref() == Ok("session") {
        return None;
    }
    if let Ok(p) = std::env::var("GLRMON_ZENOHD") {
        return Some(PathBuf::from(p));
    }
    let mut dirs: Vec<PathBuf> = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect())
        .unwrap_or_default();
    if let Some(h) = std::env::var_os("CARGO_HOME") {
        dirs.push(PathBuf::from(h).join("bin"));
    }
    if let Some(h) = std::env::var_os("HOME") {
        dirs.push(PathBuf::from(h).join(".cargo/bin"));
    }
    dirs.into_iter()
        .map(|d| d.join("zenohd"))
        .find(|p| p.is_file())
}

impl Router {
    /// The shipped deploy/zenohd.json5 on `endpoint`.
    pub(crate) async fn start(endpoint: &str) -> Self {
        Self::start_with(None, endpoint).await
    }

    /// A router from the configuration file `config` (which listens on `endpoint`), or
    /// the shipped deploy/zenohd.json5 on `endpoint`.
    pub(crate) async fn start_with(config: Option<&std::path::Path>, endpoint: &str) -> Self {
        let t = Instant::now();
        loop {
            let r = match zenohd_binary() {
                Some(bin) => {
                    let mut cmd = Command::new(bin);
                    match config {
                        Some(file) => cmd.arg("--config").arg(file),
                        // The shipped router configuration, on this test's port.
                        None => cmd
                            .arg("--config")
                            .arg(
                                std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                                    .join("../../deploy/zenohd.json5"),
                            )
                            .args(["--listen", endpoint, "--no-multicast-scouting"]),
                    };
                    let child = cmd
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .spawn()
                        .unwrap();
                    let addr = endpoint.split_once('/').map_or(endpoint, |(_, a)| a);
                    let up = Instant::now();
                    while std::net::TcpStream::connect(addr).is_err() {
                        assert!(
                            up.elapsed() < Duration::from_secs(20),
                            "zenohd not listening"
                        );
                        tokio::time::sleep(Duration::from_millis(20)).await;
                    }
                    Some(Router::Zenohd(child))
                }
                None => {
                    assert!(
                        std::env::var_os("GLRMON_REQUIRE_ZENOHD").is_none(),
                        "GLRMON_REQUIRE_ZENOHD is set but no zenohd was found (make deps-zenohd)"
                    );
                    let c = match config {
                        Some(file) => zenoh::Config::from_file(file).unwrap(),
                        None => {
                            let mut c = zenoh::Config::default();
                            c.insert_json5("mode", "\"router\"").unwrap();
                            c.insert_json5("listen/endpoints", &format!("[\"{endpoint}\"]"))
                                .unwrap();
                            c.insert_json5("scouting/multicast/enabled", "false")
                                .unwrap();
                            c
                        }
                    };
                    zenoh::open(c).await.ok().map(Router::Session)
                }
            };
            if let Some(r) = r {
                return r;
            }
            // The port of a router just stopped can take a moment to be free again.
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "router did not start"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    pub(crate) fn kind(&self) -> &'static str {
        match self {
            Router::Zenohd(_) => "zenohd",
            Router::Session(_) => "router-mode session",
        }
    }

    pub(crate) async fn stop(self) {
        match self {
            Router::Zenohd(mut c) => {
                let _ = c.kill();
                let _ = c.wait();
            }
            Router::Session(s) => s.close().await.unwrap(),
        }
    }
}

/// Kills the process `pid` (SIGKILL) when dropped: the test ends or fails.
pub(crate) struct KillOnDrop(pub(crate) u32);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-9", &self.0.to_string()])
            .status();
    }
}
