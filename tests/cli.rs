//! End-to-end tests of the real `glrmon` binary.

#[path = "support.rs"]
mod support;

use support::{Scratch, glrmon};

/// `glrmon demo` (what `make demo` runs): the faulty channel raises exactly one alarm,
/// isolating the injected fault, the clean channels none; the JSONL output holds one
/// stat per sample per channel; the MCAP recording replays to the same JSON lines, in
/// the same order.
#[test]
fn demo_prints_one_alarm_for_the_faulty_channel_with_the_right_isolation() {
    let dir = std::env::temp_dir().join(format!("glrmon-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let jsonl = dir.join("demo.jsonl");
    let mcap = dir.join("demo.mcap");
    let out = glrmon()
        .args(["demo", "--seconds", "6", "--rate", "0", "--output"])
        .arg(&jsonl)
        .arg("--output")
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    let alarms: Vec<&str> = stdout.lines().filter(|l| l.starts_with("ALARM")).collect();
    assert_eq!(alarms.len(), 1, "{stdout}");
    // The alarm at the crossing (l_k first above λ at 201, the injected
    // onset), its isolation refined isolation_delay = n = 2 samples later.
    assert!(
        alarms[0].starts_with("ALARM unstable k=201 onset=200"),
        "{stdout}"
    );
    assert!(alarms[0].contains(" update_k=203 "), "{stdout}");
    let updates: Vec<&str> = stdout.lines().filter(|l| l.starts_with("ISOL")).collect();
    assert_eq!(updates.len(), 1, "{stdout}");
    assert!(
        updates[0].starts_with("ISOL  unstable k=203 alarm_k=201 onset=201"),
        "{stdout}"
    );
    assert!(updates[0].contains("isolated=[x0_jump]"), "{stdout}");
    assert!(
        stdout.contains(
            "  alarm unstable: l_k first above the threshold at k=201, alarm record at k=201 \
             (latency 0 samples), isolation update at k=203"
        ),
        "{stdout}"
    );
    for clean in ["dc_motor", "lpv"] {
        assert!(
            stdout.contains(&format!("  {clean:<10} samples=600 alarms=0 errors=0")),
            "{stdout}"
        );
    }
    let text = std::fs::read_to_string(&jsonl).unwrap();
    let stats = text
        .lines()
        .filter(|l| l.contains(r#""type":"stat""#))
        .count();
    assert_eq!(stats, 3 * 600);
    // The same from the published records: the alarm's k is the first stat of the
    // channel whose l_k exceeds its threshold.
    let records: Vec<glrmon_wire::Record> = text
        .lines()
        .map(|l| glrmon_wire::decode_record(l.as_bytes()).unwrap())
        .filter(|r| r.channel() == "unstable")
        .collect();
    let crossing = records.iter().find_map(|r| match r {
        glrmon_wire::Record::Stat(s) if s.glr.zip(s.threshold).is_some_and(|(l, h)| l > h) => {
            Some(s.k)
        }
        _ => None,
    });
    let alarm_k = records.iter().find_map(|r| match r {
        glrmon_wire::Record::Alarm(a) => Some(a.k),
        _ => None,
    });
    assert_eq!((crossing, alarm_k), (Some(201), Some(201)));
    assert!(stdout.contains("recording: "), "{stdout}");
    let replayed = dir.join("replay.jsonl");
    let out = glrmon()
        .arg("replay")
        .arg(&mcap)
        .arg("--output")
        .arg(&replayed)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Channels interleave differently (live: as the workers finished; replay: in
    // recording order), and live alarms overtake the statistics queued before them;
    // each channel's sequence of lines of each type is identical.
    let by_channel = |text: &str| {
        let mut m: std::collections::BTreeMap<(String, String), Vec<String>> = Default::default();
        let field = |l: &str, name: &str| {
            l.split(&format!("\"{name}\":\""))
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap()
                .to_owned()
        };
        for l in text.lines() {
            m.entry((field(l, "channel"), field(l, "type")))
                .or_default()
                .push(l.to_owned());
        }
        m
    };
    let live = by_channel(&text);
    let channels: std::collections::BTreeSet<&String> = live.keys().map(|(c, _)| c).collect();
    assert_eq!(channels.len(), 3);
    assert!(
        by_channel(&std::fs::read_to_string(&replayed).unwrap()) == live,
        "the replay of the demo's recording differs from its live output"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn usage_error_exits_2() {
    let out = glrmon().arg("no-such-command").output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

/// `glrmon replay … | head -1`: when the reader of standard output goes away, an
/// offline command ends by SIGPIPE, quietly, as `cat` does; it used to panic in
/// `println!` (exit 101, "failed printing to stdout: Broken pipe").
#[test]
fn a_closed_pipe_ends_an_offline_command_quietly() {
    use std::io::Read as _;
    use std::os::unix::process::ExitStatusExt as _;
    let dir = std::env::temp_dir().join(format!("glrmon-pipe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("data.csv");
    let config = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/examples/paper2014-unstable.toml"
    );
    let simulated = glrmon()
        .args([
            "simulate",
            "--config",
            config,
            "--samples",
            "20000",
            "--output",
        ])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(
        simulated.status.success(),
        "{}",
        String::from_utf8_lossy(&simulated.stderr)
    );
    let mut child = glrmon()
        .args(["replay", "--config", config])
        .arg(&csv)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 16];
    child.stdout.take().unwrap().read_exact(&mut first).unwrap();
    // The pipe's read end is dropped here: the next write gets EPIPE.
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.signal(), Some(13), "{:?}: {stderr}", out.status);
}

const EXAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../config/examples/paper2014-unstable.toml"
);

/// Every spelling of an earlier version is a usage error (exit 2) whose message gives
/// the new one: one flag vocabulary across the commands.
#[test]
fn old_spellings_are_usage_errors_naming_the_new_one() {
    let cases: &[(&[&str], &str)] = &[
        (&["validate", EXAMPLE], "--config FILE"),
        (
            &[
                "simulate",
                "--config",
                EXAMPLE,
                "--samples",
                "10",
                "--fault",
                "x0_jump",
                "--magnitude",
                "4",
                "--output",
                "x.csv",
            ],
            "NAME:MAGNITUDE",
        ),
        (
            &[
                "simulate",
                "--config",
                EXAMPLE,
                "--samples",
                "10",
                "--fault",
                "x0_jump:4",
                "--magnitude",
                "4",
                "--output",
                "x.csv",
            ],
            "--fault NAME:MAGNITUDE",
        ),
        (
            &["evaluate", "--config", EXAMPLE, "--json", "runs.json"],
            "--json-out runs.json",
        ),
        (&["demo", "--record", "x.mcap"], "--output x.mcap"),
        (&["watch", "--mode", "routr"], "router"),
        (&["watch", "--listen", "127.0.0.1:1"], "tcp/127.0.0.1:1"),
        (
            &["run", "--config", EXAMPLE, "--connect", "tcp/host"],
            "HOST:PORT",
        ),
    ];
    for (args, hint) in cases {
        let out = glrmon().args(*args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains(hint),
            "{args:?}: wanted «{hint}» in {stderr}"
        );
    }
}

/// Every command's `--help` ends with examples, and the top line says what glrmon is.
#[test]
fn every_help_has_examples() {
    let top = glrmon().arg("--help").output().unwrap();
    let top = String::from_utf8_lossy(&top.stdout).into_owned();
    assert!(
        top.starts_with("Detect, date, isolate and size faults"),
        "{top}"
    );
    let commands: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 14, "{commands:?}");
    for c in &commands {
        let out = glrmon().args([c.as_str(), "--help"]).output().unwrap();
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{c}");
        assert!(help.contains("Examples:\n  glrmon "), "{c} --help:\n{help}");
    }
}

/// `glrmon --version` names the commit it was built from.
#[test]
fn version_names_the_commit() {
    let out = glrmon().arg("--version").output().unwrap();
    let v = String::from_utf8_lossy(&out.stdout);
    assert!(
        v.starts_with(&format!("glrmon {} (git ", env!("CARGO_PKG_VERSION"))),
        "{v}"
    );
}

/// Completion scripts for every shell clap knows and the manual pages, one per
/// command, generated from the parser.
#[test]
fn completions_and_manual_pages_are_generated() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let out = glrmon().args(["completions", shell]).output().unwrap();
        assert!(out.status.success(), "{shell}");
        let script = String::from_utf8_lossy(&out.stdout);
        assert!(
            script.contains("identify"),
            "{shell}: no subcommand in the script"
        );
        assert!(script.contains("log-format"), "{shell}: no global flag");
    }
    let scratch = Scratch::new("man");
    let out = glrmon()
        .args(["man", "--out-dir"])
        .arg(&scratch.0)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let main = std::fs::read_to_string(scratch.0.join("glrmon.1")).unwrap();
    assert!(
        main.starts_with(".ie") || main.contains(".TH glrmon 1"),
        "{main}"
    );
    assert!(
        main.contains("glrmon\\-run(1)") || main.contains("glrmon-run"),
        "{main}"
    );
    let run = std::fs::read_to_string(scratch.0.join("glrmon-run.1")).unwrap();
    assert!(run.contains("\\-\\-config"), "{run}");
}

/// Runs the daemon on a free loopback port for a second with `flags` before the
/// command, stops it with SIGTERM and returns its standard error.
fn daemon_log(flags: &[&str]) -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let child = glrmon()
        .args(flags)
        .args(["run", "--config", EXAMPLE, "--listen"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .env("GLRMON_LOG", "info")
        .env_remove("NO_COLOR")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    // SAFETY: kill(2) on the child's pid with SIGTERM.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// `--log-format json`: every line on standard error is a JSON object with an
/// ISO-8601 UTC timestamp, a level and a message; `--color always` colours text logs,
/// `auto` leaves a pipe plain.
#[test]
fn json_logs_parse_and_colour_follows_the_flag() {
    let stderr = daemon_log(&["--log-format", "json"]);
    let mut messages = Vec::new();
    for line in stderr.lines() {
        let v: serde_json::Value =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        let ts = v["timestamp"].as_str().unwrap();
        assert!(
            ts.len() == 24 && ts.ends_with('Z') && ts.as_bytes()[10] == b'T',
            "{ts}"
        );
        assert!(v["level"].is_string(), "{line}");
        messages.push(v["message"].as_str().unwrap().to_owned());
    }
    assert!(
        messages.iter().any(|m| m == "Monitoring started."),
        "{stderr}"
    );
    assert!(messages.iter().any(|m| m == "Stopped."), "{stderr}");

    assert!(daemon_log(&["--color", "always"]).contains("\u{1b}["));
    assert!(!daemon_log(&["--color", "auto"]).contains('\u{1b}'));
    assert!(!daemon_log(&["--color", "never"]).contains('\u{1b}'));
}

/// `glrmon replay X --report r.html`, the demo's hint: the report, and no JSON lines
/// on the terminal; `--output -` still asks for them.
#[test]
fn a_report_alone_writes_no_json_lines() {
    let scratch = Scratch::new("report");
    let csv = scratch.0.join("data.csv");
    let sim = glrmon()
        .args(["simulate", "--config", EXAMPLE, "--samples", "400"])
        .args(["--fault", "x0_jump:4", "--onset", "201", "--output"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(sim.status.success());
    let report = scratch.0.join("r.html");
    let out = glrmon()
        .args(["replay", "--config", EXAMPLE, "--quiet", "--report"])
        .arg(&report)
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(
        out.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(std::fs::metadata(&report).unwrap().len() > 10_000);
    let out = glrmon()
        .args([
            "replay", "--config", EXAMPLE, "--quiet", "--output", "-", "--report",
        ])
        .arg(&report)
        .arg(&csv)
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).lines().count(),
        400 + 3
    );
}

/// `glrmon config init` writes a template that `glrmon validate` accepts, refuses to
/// overwrite without --force, and refuses a channel name validation would refuse;
/// `glrmon config schema` prints JSON.
#[test]
fn config_init_writes_a_valid_template_and_schema_prints_json() {
    let dir = std::env::temp_dir().join(format!("glrmon-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("glrmon.toml");
    let _ = std::fs::remove_file(&file);
    let init = |extra: &[&str]| {
        glrmon()
            .args(["config", "init", "--channel", "tank", "--output"])
            .arg(&file)
            .args(extra)
            .output()
            .unwrap()
    };
    let out = init(&[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.contains("name = \"tank\""), "{text}");
    let out = glrmon()
        .args(["validate", "--config"])
        .arg(&file)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(stdout.contains("valid, 1 channel(s)"), "{stdout}");
    assert!(!stdout.contains("warning"), "{stdout}");

    let out = init(&[]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--force"));
    assert!(init(&["--force"]).status.success());

    let out = glrmon()
        .args(["config", "init", "--channel", "a b"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));

    let out = glrmon().args(["config", "schema"]).output().unwrap();
    assert!(out.status.success());
    let schema: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(schema["definitions"]["ChannelSpec"].is_object());

    let help = glrmon().args(["config", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("Examples:"), "{help}");
    std::fs::remove_dir_all(&dir).unwrap();
}
