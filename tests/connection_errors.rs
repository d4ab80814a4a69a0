//! A Zenoh endpoint that cannot be reached or listened on, with the real binary on
//! loopback (explicit tcp/127.0.0.1 endpoints, multicast scouting off): one line on
//! standard error naming the endpoint, the reason and the flag or configuration key to
//! change, exit code 3, and none of Zenoh's own WARN lines (source paths under
//! `.cargo/registry`, Rust's `Single(tcp/…)`) unless the log filter asks for them.

#[path = "support.rs"]
mod support;

use std::io::{BufRead as _, BufReader, Read as _};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use support::{Scratch, free_port, glrmon, run_ok};

fn demo_config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/demo.toml")
}

/// `cmd` under the default log filter (neither `GLRMON_LOG` nor `RUST_LOG` set), with
/// a bound on its time.
fn output(cmd: &mut Command) -> Output {
    let child = cmd
        .env_remove("GLRMON_LOG")
        .env_remove("RUST_LOG")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let id = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(Duration::from_secs(60)) {
        Ok(out) => out.unwrap(),
        Err(_) => {
            // SAFETY: kill(2) on the pid of a child this test started and did not reap.
            unsafe { libc::kill(id as libc::pid_t, libc::SIGKILL) };
            panic!("{cmd:?} did not exit within 60 s");
        }
    }
}

/// The non-empty lines of standard error.
fn stderr_lines(out: &Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_owned)
        .collect()
}

/// Exactly one line, `glrmon: …` with each of `wanted`, none of Zenoh's internals, and
/// exit code 3.
fn assert_one_clear_line(out: &Output, wanted: &[&str]) -> String {
    let lines = stderr_lines(out);
    assert_eq!(lines.len(), 1, "one line expected: {lines:#?}");
    let line = &lines[0];
    assert!(line.starts_with("glrmon: "), "{line}");
    for w in wanted {
        assert!(line.contains(w), "{w:?} missing from: {line}");
    }
    for bad in [".cargo/registry", "Single(", " at /", ".rs:", "WARN"] {
        assert!(!line.contains(bad), "{bad:?} in: {line}");
    }
    assert_eq!(out.status.code(), Some(3), "{line}");
    line.clone()
}

#[test]
fn watch_and_status_name_a_dead_endpoint_once_with_the_flag() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    for command in ["watch", "status"] {
        let out = output(glrmon().args([command, "--connect", &endpoint]));
        assert_one_clear_line(
            &out,
            &[
                &format!("cannot connect to {endpoint} (connection refused)"),
                "is `glrmon run` or a Zenoh router listening there?",
                "--connect",
            ],
        );
    }
}

#[test]
fn play_names_a_dead_endpoint_once_with_the_flag() {
    let scratch = Scratch::new("connection-play");
    let recording = scratch.0.join("sim.mcap");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(demo_config())
            .args(["--channel", "dc_motor", "--samples", "20", "--output"])
            .arg(&recording),
    );
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out =
        output(
            glrmon()
                .arg("play")
                .arg(&recording)
                .args(["--rate", "0", "--connect", &endpoint]),
        );
    assert_one_clear_line(&out, &[&endpoint, "connection refused", "--connect"]);
}

#[test]
fn simulate_publish_names_a_dead_endpoint_once_with_the_flag() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = output(
        glrmon()
            .args(["simulate", "--config"])
            .arg(demo_config())
            .args(["--channel", "dc_motor", "--samples", "20", "--publish"])
            .args(["--connect", &endpoint]),
    );
    assert_one_clear_line(&out, &[&endpoint, "connection refused", "--connect"]);
}

#[test]
fn run_names_a_busy_listen_port_once_with_the_flag_or_the_key() {
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let endpoint = format!("tcp/{}", busy.local_addr().unwrap());
    let out = output(
        glrmon()
            .args(["run", "--config"])
            .arg(demo_config())
            .args(["--listen", &endpoint]),
    );
    let line = assert_one_clear_line(
        &out,
        &[
            &format!("cannot listen on {endpoint} (address already in use)"),
            "choose another endpoint with --listen",
        ],
    );
    assert_eq!(
        line.to_ascii_lowercase()
            .matches("address already in use")
            .count(),
        1,
        "{line}"
    );

    // The same endpoint from the configuration: the key is named, with the file.
    let scratch = Scratch::new("connection-run");
    let config = scratch.0.join("plant.toml");
    let text = std::fs::read_to_string(demo_config()).unwrap().replace(
        "[zenoh]\n",
        &format!("[zenoh]\nlisten = [\"{endpoint}\"]\n"),
    );
    std::fs::write(&config, text).unwrap();
    let out = output(glrmon().args(["run", "--config"]).arg(&config));
    assert_one_clear_line(
        &out,
        &[
            &endpoint,
            &format!("--listen or [zenoh] listen in {}", config.display()),
        ],
    );
    drop(busy);
}

/// A peer whose connect endpoint is dead starts (Zenoh keeps trying), saying so once in
/// glrmon's words, not Zenoh's.
#[test]
fn a_peer_run_says_once_that_its_connect_endpoint_is_dead() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut child = glrmon()
        .args(["run", "--config"])
        .arg(demo_config())
        .args(["--listen", &format!("tcp/127.0.0.1:{}", free_port())])
        .args(["--connect", &endpoint])
        .env_remove("GLRMON_LOG")
        .env_remove("RUST_LOG")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    let t = Instant::now();
    while !line.starts_with("glrmon run: ") {
        line.clear();
        assert!(
            stdout.read_line(&mut line).unwrap() > 0,
            "no readiness line"
        );
        assert!(t.elapsed() < Duration::from_secs(30));
    }
    let _ = child.kill();
    let _ = child.wait();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains(" WARN ")).collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    let w = warnings[0];
    for wanted in [
        &format!("Not connected to {endpoint} (connection refused)"),
        "Check --connect.",
    ] {
        assert!(w.contains(wanted), "{wanted:?} missing from: {w}");
    }
    for bad in [".cargo/registry", "Single(", "Scouting delay"] {
        assert!(!stderr.contains(bad), "{bad:?} in: {stderr}");
    }
}

/// A log filter the user sets shows Zenoh's own lines again.
#[test]
fn a_user_log_filter_shows_zenohs_lines() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = glrmon()
        .args(["watch", "--connect", &endpoint])
        .env("GLRMON_LOG", "info,zenoh=debug")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!("Unable to connect to {endpoint}")),
        "{stderr}"
    );
    assert_eq!(out.status.code(), Some(3), "{stderr}");
}
