//! `glrmon run` as a service, with the real binary on loopback (explicit tcp/127.0.0.1
//! endpoints, multicast scouting off): readiness and the Zenoh sessions by kind with a
//! client-only publisher, the readiness of a daemon that only connects, the Prometheus
//! exposition (label, build and process metrics, parsed as a scraper would), and the
//! systemd notification protocol (READY, RELOADING, STOPPING) on a real datagram socket.

#[path = "support.rs"]
mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_zenoh::SessionSettings;

/// A running `glrmon run`, killed if the test ends early; its directory removed.
struct Daemon {
    child: Child,
    stderr: Arc<Mutex<String>>,
    dir: PathBuf,
    /// The readiness line on standard output.
    line: String,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn motor() -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"),
    )
    .unwrap()
}

impl Daemon {
    /// Writes `zenoh` (the `[zenoh]` table's lines) and the DC motor channel into a
    /// configuration, starts the daemon with `env`, and (unless `wait_line` is false)
    /// waits for its readiness line.
    fn start(tag: &str, zenoh: &str, metrics: Option<u16>, env: &[(&str, &Path)]) -> Self {
        let dir = std::env::temp_dir().join(format!("glrmon-svc-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let metrics = metrics.map_or(String::new(), |p| format!("metrics = \"127.0.0.1:{p}\"\n"));
        let text = format!(
            "[zenoh]\n{zenoh}multicast_scouting = false\n\n[daemon]\nstat_every = 0\ninstance = \"svc-{tag}\"\n{metrics}\n{}",
            motor()
        );
        let cfg = dir.join("plant.toml");
        std::fs::write(&cfg, text).unwrap();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_glrmon"));
        cmd.args(["run", "--config"]).arg(&cfg);
        for (k, v) in env {
            cmd.env(k, v);
        }
        let (mut child, stderr) = support::spawn_logged(&mut cmd);
        let stdout = child.stdout.take().unwrap();
        let mut daemon = Self {
            child,
            stderr,
            dir,
            line: String::new(),
        };
        BufReader::new(stdout).read_line(&mut daemon.line).unwrap();
        assert!(
            daemon.line.contains("monitoring 1 channel(s)"),
            "{}\n{}",
            daemon.line,
            daemon.stderr.lock().unwrap()
        );
        daemon
    }

    fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(ok.success());
    }

    /// SIGTERM, then the exit code (bounded).
    fn terminate(&mut self) -> Option<i32> {
        self.signal("-TERM");
        let t = Instant::now();
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s.code();
            }
            assert!(
                t.elapsed() < Duration::from_secs(15),
                "no exit after SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// (status code, body) of `GET path` on 127.0.0.1:port.
fn get(port: u16, path: &str) -> (u16, String) {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    let code = reply
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = reply
        .split_once("\r\n\r\n")
        .map_or(String::new(), |(_, b)| b.to_owned());
    (code, body)
}

/// Polls `GET path` until `ok` holds for (code, body) (bounded); returns the last answer.
fn wait_get(port: u16, path: &str, ok: impl Fn(u16, &str) -> bool) -> (u16, String) {
    let t = Instant::now();
    loop {
        let (code, body) = get(port, path);
        if ok(code, &body) {
            return (code, body);
        }
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "{path}: still {code}\n{body}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// One sample of the Prometheus text format: name, labels, value.
type Series = (String, BTreeMap<String, String>, f64);

/// Parses a text exposition (format 0.0.4) strictly, as a scraper would: every sample
/// line is `name{label="value",…} number` with a metric name and label names of
/// Prometheus's alphabet, escapes `\\ \" \n` only, a `# TYPE` before the family's
/// samples, each family declared once, no series twice.
fn parse_exposition(text: &str) -> Result<Vec<Series>, String> {
    let ident = |s: &str, colon: bool| {
        !s.is_empty()
            && !s.starts_with(|c: char| c.is_ascii_digit())
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || (colon && c == ':'))
    };
    let mut typed: BTreeMap<String, String> = BTreeMap::new();
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let err = |why: &str| Err(format!("line {}: {why}: {line}", n + 1));
        if line.is_empty() {
            continue;
        }
        if let Some(rest) = line.strip_prefix("# ") {
            let mut w = rest.splitn(3, ' ');
            match (w.next(), w.next(), w.next()) {
                (Some("HELP"), Some(name), Some(_)) if ident(name, true) => {}
                (Some("TYPE"), Some(name), Some(kind)) if ident(name, true) => {
                    if !["counter", "gauge", "histogram", "summary", "untyped"].contains(&kind) {
                        return err("unknown type");
                    }
                    if typed.insert(name.to_owned(), kind.to_owned()).is_some() {
                        return err("family declared twice");
                    }
                }
                _ => return err("bad comment"),
            }
            continue;
        }
        let (name, rest) = match line.find(['{', ' ']) {
            Some(i) => line.split_at(i),
            None => return err("no value"),
        };
        if !ident(name, true) {
            return err("bad metric name");
        }
        let mut labels = BTreeMap::new();
        let mut rest = rest;
        if let Some(r) = rest.strip_prefix('{') {
            let mut chars = r.char_indices().peekable();
            let end = loop {
                let Some((i, c)) = chars.next() else {
                    return err("unterminated labels");
                };
                if c == '}' {
                    break i;
                }
                if c == ',' {
                    continue;
                }
                let start = i;
                let mut eq = None;
                for (j, c) in chars.by_ref() {
                    if c == '=' {
                        eq = Some(j);
                        break;
                    }
                }
                let Some(eq) = eq else {
                    return err("label without =");
                };
                let lname = &r[start..eq];
                if !ident(lname, false) {
                    return err("bad label name");
                }
                if chars.next().map(|x| x.1) != Some('"') {
                    return err("label value not quoted");
                }
                let mut value = String::new();
                loop {
                    match chars.next() {
                        Some((_, '"')) => break,
                        Some((_, '\\')) => match chars.next().map(|x| x.1) {
                            Some('\\') => value.push('\\'),
                            Some('"') => value.push('"'),
                            Some('n') => value.push('\n'),
                            _ => return err("bad escape"),
                        },
                        Some((_, c)) => value.push(c),
                        None => return err("unterminated label value"),
                    }
                }
                if labels.insert(lname.to_owned(), value).is_some() {
                    return err("label twice");
                }
            };
            rest = &r[end + 1..];
        }
        let Some(value) = rest.strip_prefix(' ') else {
            return err("no space before the value");
        };
        let value: f64 = match value {
            "+Inf" => f64::INFINITY,
            "-Inf" => f64::NEG_INFINITY,
            "NaN" => f64::NAN,
            v => match v.parse() {
                Ok(v) => v,
                Err(_) => return err("value not a number"),
            },
        };
        let family = ["_bucket", "_sum", "_count", "_total"]
            .iter()
            .find_map(|s| {
                name.strip_suffix(s)
                    .filter(|f| typed.contains_key(*f))
                    .map(str::to_owned)
            })
            .unwrap_or_else(|| name.to_owned());
        if !typed.contains_key(&family) {
            return err("sample before its # TYPE");
        }
        if !seen.insert(format!("{name}{labels:?}")) {
            return err("series twice");
        }
        out.push((name.to_owned(), labels, value));
    }
    Ok(out)
}

fn value(series: &[Series], name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    series
        .iter()
        .find(|(n, l, _)| {
            n == name
                && labels
                    .iter()
                    .all(|(k, v)| l.get(*k).map(String::as_str) == Some(v))
        })
        .map(|s| s.2)
}

/// The brief's scenario: the daemon is a peer that listens; a publisher connects as a
/// client only. The daemon is ready as soon as its listener is up and intake is open;
/// the client shows in the sessions (metrics and `glrmon status`), and
/// `glrmon_zenoh_connected` goes to 1. The exposition parses, with the label
/// `glrmon_instance` (never `instance`), the build information and the process metrics.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_listening_daemon_is_ready_and_counts_client_publishers() {
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let mport = support::free_port();
    let mut daemon = Daemon::start(
        "client",
        &format!("mode = \"peer\"\nlisten = [\"{endpoint}\"]\n"),
        Some(mport),
        &[],
    );
    // The start line names the mode, the Zenoh id and the endpoints in use.
    assert!(
        daemon.line.contains("; zenoh peer ")
            && daemon
                .line
                .contains(&format!(", listen {endpoint}, connect none")),
        "{}",
        daemon.line
    );
    // The log line before it says the same (read from the pipe by a thread: waited for).
    let t = Instant::now();
    loop {
        let log = daemon.stderr.lock().unwrap().clone();
        if log.contains("Monitoring started.") {
            assert!(log.contains(&format!("listen={endpoint}")), "{log}");
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(10), "{log}");
        std::thread::sleep(Duration::from_millis(10));
    }
    // Listening, intake open, no remote yet: ready, and not connected.
    let (code, body) = get(mport, "/readyz");
    assert_eq!((code, body.as_str()), (200, "ready\n"));
    let (_, text) = get(mport, "/metrics");
    let series = parse_exposition(&text).unwrap();
    let inst = [("glrmon_instance", "svc-client")];
    assert_eq!(value(&series, "glrmon_zenoh_connected", &inst), Some(0.0));
    assert_eq!(value(&series, "glrmon_ready", &inst), Some(1.0));

    let session = support::publish_dc_motor(&endpoint, 100).await;
    let (_, text) = tokio::task::spawn_blocking(move || {
        wait_get(mport, "/metrics", |_, body| {
            body.contains(
                r#"glrmon_samples_total{glrmon_instance="svc-client",channel="dc_motor"} 100"#,
            ) && body
                .contains(r#"glrmon_zenoh_sessions{glrmon_instance="svc-client",kind="client"} 1"#)
        })
    })
    .await
    .unwrap();
    let series = parse_exposition(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert_eq!(value(&series, "glrmon_zenoh_connected", &inst), Some(1.0));
    assert_eq!(value(&series, "glrmon_ready", &inst), Some(1.0));
    for (kind, n) in [("router", 0.0), ("peer", 0.0), ("client", 1.0)] {
        assert_eq!(
            value(
                &series,
                "glrmon_zenoh_sessions",
                &[("glrmon_instance", "svc-client"), ("kind", kind)]
            ),
            Some(n),
            "{kind}"
        );
    }
    assert!(
        series.iter().all(|(_, l, _)| !l.contains_key("instance")),
        "Prometheus would rename `instance` to exported_instance:\n{text}"
    );
    assert!(
        series
            .iter()
            .filter(|(n, _, _)| n.starts_with("glrmon_") && n != "glrmon_build_info")
            .all(|(_, l, _)| l.get("glrmon_instance").map(String::as_str) == Some("svc-client")),
        "{text}"
    );
    let build = series
        .iter()
        .find(|(n, _, _)| n == "glrmon_build_info")
        .expect("glrmon_build_info");
    assert_eq!(build.2, 1.0);
    assert_eq!(
        build.1.get("version").map(String::as_str),
        Some(env!("CARGO_PKG_VERSION"))
    );
    let git = build.1.get("git").expect("git label");
    assert!(!git.is_empty(), "{text}");
    #[cfg(target_os = "linux")]
    {
        for name in [
            "process_cpu_seconds_total",
            "process_open_fds",
            "process_max_fds",
            "process_virtual_memory_bytes",
            "process_resident_memory_bytes",
            "process_start_time_seconds",
        ] {
            let v = value(&series, name, &[]).unwrap_or_else(|| panic!("no {name}\n{text}"));
            // CPU time is counted in clock ticks (10 ms): a daemon that has done little
            // may not have used one yet.
            let least_ok = if name == "process_cpu_seconds_total" {
                v >= 0.0
            } else {
                v > 0.0
            };
            assert!(v.is_finite() && least_ok, "{name} = {v}");
        }
        let typed = |name: &str, kind: &str| text.contains(&format!("# TYPE {name} {kind}\n"));
        assert!(typed("process_cpu_seconds_total", "counter"));
        assert!(typed("process_resident_memory_bytes", "gauge"));
        let start = value(&series, "process_start_time_seconds", &[]).unwrap();
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64();
        assert!(
            start <= now + 1.0 && start > now - 600.0,
            "started at {start}, now {now}"
        );
        let rss = value(&series, "process_resident_memory_bytes", &[]).unwrap();
        assert!(rss > 1e6, "{rss}");
    }

    // `glrmon status` sees the publisher (and itself, another client, once the daemon's
    // 100 ms poll has seen its session).
    let status = |json: bool| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_glrmon"));
        cmd.arg("status");
        if json {
            cmd.arg("--json");
        }
        let out = cmd
            .args(["--connect", &endpoint, "--timeout", "2"])
            .stderr(Stdio::inherit())
            .output()
            .unwrap();
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let table = status(false);
    let row = table
        .lines()
        .find(|l| l.starts_with("svc-client"))
        .unwrap_or_else(|| panic!("{table}"));
    assert!(
        row.contains(" 1 client ") || row.contains(" 2 clients "),
        "{table}"
    );
    assert!(!row.contains("(down)"), "{table}");
    eprintln!("{table}");
    let json = status(true);
    let st = glrmon_wire::status::decode(json.trim().as_bytes()).unwrap();
    assert!(st.connected, "{json}");
    let sessions = st.sessions.unwrap();
    assert_eq!((sessions.routers, sessions.peers), (0, 0), "{json}");
    assert!((1..=2).contains(&sessions.clients), "{json}");
    let _ = session.close().await;
    // A client leaving is not a lost network: no reconnection is counted.
    let (_, text) = tokio::task::spawn_blocking(move || {
        wait_get(mport, "/metrics", |_, body| {
            body.contains(r#"glrmon_zenoh_connected{glrmon_instance="svc-client"} 0"#)
        })
    })
    .await
    .unwrap();
    assert!(
        text.contains(r#"glrmon_zenoh_reconnections_total{glrmon_instance="svc-client"} 0"#),
        "{text}"
    );
    assert_eq!(get(mport, "/readyz").0, 200, "still listening: still ready");
    assert_eq!(daemon.terminate(), Some(0));
}

/// A daemon that listens on nothing and only connects is not ready while nobody is
/// there to connect to (503 naming why), and ready once its peer is up.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_daemon_that_only_connects_is_ready_once_connected() {
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let mport = support::free_port();
    let mut daemon = Daemon::start(
        "connect",
        &format!("mode = \"peer\"\nconnect = [\"{endpoint}\"]\n"),
        Some(mport),
        &[],
    );
    assert!(
        daemon
            .line
            .contains(&format!("listen none, connect {endpoint}")),
        "{}",
        daemon.line
    );
    let (code, body) = get(mport, "/readyz");
    assert_eq!(
        (code, body.as_str()),
        (
            503,
            "not listening, and not connected to any Zenoh router, peer or client\n"
        )
    );
    let peer = glrmon_zenoh::open(&SessionSettings {
        mode: Some("peer".into()),
        listen: vec![endpoint.clone()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    })
    .await
    .unwrap();
    let (_, text) = tokio::task::spawn_blocking(move || {
        wait_get(mport, "/readyz", |code, _| code == 200);
        get(mport, "/metrics")
    })
    .await
    .unwrap();
    let series = parse_exposition(&text).unwrap();
    assert_eq!(
        value(
            &series,
            "glrmon_zenoh_sessions",
            &[("glrmon_instance", "svc-connect"), ("kind", "peer")]
        ),
        Some(1.0),
        "{text}"
    );
    let _ = peer.close().await;
    assert_eq!(daemon.terminate(), Some(0));
}

/// Datagrams received on a notify socket, as text.
#[cfg(unix)]
fn recv_until(
    sock: &std::os::unix::net::UnixDatagram,
    got: &mut Vec<String>,
    line: &str,
) -> String {
    let t = Instant::now();
    let mut buf = [0u8; 4096];
    loop {
        let remaining = Duration::from_secs(20).saturating_sub(t.elapsed());
        assert!(!remaining.is_zero(), "no {line:?} among {got:?}");
        sock.set_read_timeout(Some(remaining)).unwrap();
        let n = sock
            .recv(&mut buf)
            .unwrap_or_else(|e| panic!("{e}: no {line:?} among {got:?}"));
        let msg = String::from_utf8_lossy(&buf[..n]).into_owned();
        got.push(msg.clone());
        if msg.lines().any(|l| l == line) {
            return msg;
        }
    }
}

/// systemd's Type=notify protocol, on a real datagram socket as systemd makes one:
/// READY=1 once the readiness line is out, WATCHDOG=1 pings when WATCHDOG_USEC is set,
/// RELOADING=1 (with MONOTONIC_USEC) and READY=1 again around a SIGHUP reload,
/// STOPPING=1 at SIGTERM, then exit 0.
#[cfg(unix)]
#[test]
fn notify_socket_gets_ready_reloading_and_stopping() {
    use std::os::unix::net::UnixDatagram;
    let dir = std::env::temp_dir().join(format!("glrmon-notify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("notify.sock");
    let _ = std::fs::remove_file(&path);
    let sock = UnixDatagram::bind(&path).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let cfg_dir = std::env::temp_dir().join(format!("glrmon-notify-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&cfg_dir).unwrap();
    let cfg = cfg_dir.join("plant.toml");
    std::fs::write(
        &cfg,
        format!(
            "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n[daemon]\nstat_every = 0\ninstance = \"svc-notify\"\n\n{}",
            motor()
        ),
    )
    .unwrap();
    let (mut child, stderr) = support::spawn_logged(
        Command::new(env!("CARGO_BIN_EXE_glrmon"))
            .args(["run", "--config"])
            .arg(&cfg)
            .env("NOTIFY_SOCKET", &path)
            // WatchdogSec=0.4: WATCHDOG=1 every 0.2 s while every worker runs.
            .env("WATCHDOG_USEC", "400000"),
    );
    let stdout = child.stdout.take().unwrap();
    let mut daemon = Daemon {
        child,
        stderr,
        dir: cfg_dir,
        line: String::new(),
    };
    let mut got = Vec::new();
    let ready = recv_until(&sock, &mut got, "READY=1");
    assert!(
        ready.contains("STATUS=instance svc-notify monitoring 1 channel(s)"),
        "{ready}"
    );
    // READY=1 came after the readiness line: by now the line is in the pipe, readable
    // without waiting for the daemon.
    {
        use std::os::fd::AsRawFd;
        // SAFETY: F_SETFL on a pipe this process owns.
        let rc = unsafe { libc::fcntl(stdout.as_raw_fd(), libc::F_SETFL, libc::O_NONBLOCK) };
        assert_eq!(rc, 0);
        let mut reader = BufReader::new(stdout);
        reader
            .read_line(&mut daemon.line)
            .expect("READY=1 before the readiness line");
        assert!(
            daemon.line.contains("monitoring 1 channel(s)"),
            "{}",
            daemon.line
        );
    }
    recv_until(&sock, &mut got, "WATCHDOG=1");
    daemon.signal("-HUP");
    let reloading = recv_until(&sock, &mut got, "RELOADING=1");
    assert!(
        reloading.lines().any(|l| l
            .strip_prefix("MONOTONIC_USEC=")
            .is_some_and(|v| v.parse::<u64>().is_ok_and(|v| v > 0))),
        "{reloading}"
    );
    recv_until(&sock, &mut got, "READY=1");
    // The log line is read from the daemon's stderr by a thread of this test: it may
    // arrive after the notification (the CI run saw it so).
    let t = Instant::now();
    while !daemon
        .stderr
        .lock()
        .unwrap()
        .contains("Configuration reloaded")
    {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "{}",
            daemon.stderr.lock().unwrap()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    daemon.signal("-TERM");
    recv_until(&sock, &mut got, "STOPPING=1");
    let code = support::exit_code_within(&mut daemon.child, Duration::from_secs(15));
    assert_eq!(code, Some(0));
    // Nothing after STOPPING=1 (the watchdog stops with it) but what was already sent.
    sock.set_nonblocking(true).unwrap();
    let mut buf = [0u8; 4096];
    while let Ok(n) = sock.recv(&mut buf) {
        got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    let firsts: Vec<&str> = got
        .iter()
        .filter_map(|m| m.lines().next())
        .filter(|l| *l != "WATCHDOG=1")
        .collect();
    assert_eq!(
        firsts,
        ["READY=1", "RELOADING=1", "READY=1", "STOPPING=1"],
        "{got:?}"
    );
    let stopping = got
        .iter()
        .position(|m| m.starts_with("STOPPING=1"))
        .unwrap();
    assert!(
        got[stopping + 1..]
            .iter()
            .all(|m| m.starts_with("WATCHDOG=1")),
        "{got:?}"
    );
    eprintln!("notify messages: {got:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
