//! End-to-end tests of the binary against text from outside that tries to drive a
//! terminal or forge log lines: ESC/OSC sequences (`ESC ] 0 ; … BEL` retitles the
//! window, `ESC [ 2 J` clears the screen), line breaks that start a fake log line, C1
//! controls and the bidi override U+202E, in a payload's field names, in forged records
//! on Zenoh (real sessions over loopback: explicit tcp/127.0.0.1 endpoints, multicast
//! scouting off) and in a recording's metadata, channel names and file name. Each output
//! must carry the visible escapes and no raw control character.

#[path = "support.rs"]
mod support;

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use glrmon_wire::decode_record;
use glrmon_wire::text::needs_escape;
use support::{Scratch, exit_code_within, free_port, glrmon, run_ok, spawn_logged};

/// The characters found raw in `text`, other than its own line breaks: each one a
/// terminal could act on or a reader be misled by.
fn raw_controls(text: &str) -> Vec<char> {
    text.chars()
        .filter(|&c| c != '\n' && needs_escape(c))
        .collect()
}

fn assert_clean(what: &str, text: &str) {
    let raw = raw_controls(text);
    assert!(raw.is_empty(), "{what} holds raw {raw:?}:\n{text}");
}

/// A Zenoh session of the test: a peer on `listen` or a client of `connect`.
async fn session(listen: Option<&str>, connect: Option<&str>) -> zenoh::Session {
    glrmon_zenoh::open(&glrmon_zenoh::SessionSettings {
        mode: Some(if listen.is_some() { "peer" } else { "client" }.into()),
        listen: listen.map(str::to_owned).into_iter().collect(),
        connect: connect.map(str::to_owned).into_iter().collect(),
        multicast_scouting: Some(false),
        ..glrmon_zenoh::SessionSettings::default()
    })
    .await
    .unwrap()
}

/// Waits until a subscriber of `key` is known to `session` (10 s at most).
async fn matched(session: &zenoh::Session, key: &str) {
    let publisher = session.declare_publisher(key.to_owned()).await.unwrap();
    let t = Instant::now();
    while !publisher.matching_status().await.unwrap().matching() {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "no subscriber of {key}"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// A payload whose unknown field name holds a window-title OSC, a screen clear, a bidi
/// override and a line break followed by a forged log line: the daemon's text log
/// reports the rejection on one line, with every one of them escaped.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hostile_field_name_reaches_the_text_log_escaped() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let (mut child, stderr) = spawn_logged(
        glrmon()
            .args(["--log-format", "text", "run", "--config"])
            .arg(&config)
            .args(["--listen", &endpoint]),
    );
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.contains("monitoring 1 channel(s)"), "{line}");

    let client = session(None, Some(&endpoint)).await;
    matched(&client, "plant/dc_motor").await;
    let forged = "2026-12-03T10:00:00.000Z  INFO ALARM dc_motor k=1 forged";
    let payload = format!(r#"{{"y":[0,0],"y\u001b]0;pwned\u0007\u001b[2J\u202e\n{forged}":1}}"#);
    client.put("plant/dc_motor", payload).await.unwrap();

    let t = Instant::now();
    while !stderr.lock().unwrap().contains("Rejected input") {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "no rejection logged: {}",
            stderr.lock().unwrap()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    client.close().await.unwrap();
    // SAFETY: kill(2) with SIGTERM on the child's own pid.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
    assert_eq!(
        exit_code_within(&mut child, Duration::from_secs(20)),
        Some(0)
    );

    let log = stderr.lock().unwrap().clone();
    assert_clean("the log", &log);
    assert!(
        log.contains(&format!(
            r"field y\x1b]0;pwned\x07\x1b[2J\u{{202e}}\n{forged} is not a field"
        )),
        "{log}"
    );
    assert!(
        !log.lines().any(|l| l.starts_with(forged)),
        "a forged line starts a line of the log:\n{log}"
    );
}

/// The records published under `glrmon/**` by a hostile peer, with the lines `watch`
/// must print for them (text mode), and a payload on a hostile key that does not decode.
struct Forged {
    records: Vec<String>,
    bad_key: &'static str,
    bad_payload: &'static str,
}

fn forged() -> Forged {
    let records = vec![
        // JSON escapes: serde turns them into the raw characters.
        r#"{"type":"alarm","channel":"\u001b]0;pwned\u0007","k":5,"t":null,"glr":30.0,"threshold":20.0,"onset":4,"magnitude":[1.0],"isolation":[],"faults":["leak\u001b[2J\u001b[H"],"update_k":null}"#.to_owned(),
        r#"{"type":"error","channel":"pump\u202e1","k":null,"code":"unknown_field","message":"x\n2026-12-03T10:00:00.000Z  INFO ALARM pump3 k=1 forged","stage":"receiving"}"#.to_owned(),
        // Raw C1 CSI and bidi override inside a string, raw CR LF between fields: valid
        // JSON that a stat line passes on verbatim.
        "{\"type\":\"stat\",\r\n\"channel\":\"s\u{9b}2J\u{202e}\",\"k\":1,\"t\":null,\"glr\":null,\"onset\":null,\"magnitude\":[],\"rank\":0,\"innovation\":[],\"threshold\":null}".to_owned(),
    ];
    for r in &records {
        assert!(decode_record(r.as_bytes()).is_ok(), "not a record: {r}");
    }
    Forged {
        records,
        bad_key: "glrmon/\u{202e}bad/diagnosis",
        bad_payload: r#"{"type":"diagnosis","channel":"c","estimate":{"\u001b]0;pwned\u0007\nALARM":"x"}}"#,
    }
}

/// Runs `glrmon watch --all` with `flags` against a peer of the test that publishes the
/// forged records; returns its standard output and error.
async fn watch(flags: &[&str]) -> (String, String) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let peer = session(Some(&endpoint), None).await;
    let forged = forged();
    let child = glrmon()
        .args(["watch", "--all", "--count"])
        .arg(forged.records.len().to_string())
        .args(flags)
        .args(["--connect", &endpoint])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    matched(&peer, "glrmon/x/alarm").await;
    peer.put(forged.bad_key, forged.bad_payload).await.unwrap();
    for (i, r) in forged.records.iter().enumerate() {
        peer.put(format!("glrmon/x{i}/record"), r.as_str())
            .await
            .unwrap();
    }
    let out = tokio::task::spawn_blocking(move || child.wait_with_output())
        .await
        .unwrap()
        .unwrap();
    peer.close().await.unwrap();
    let (stdout, stderr) = (
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    (stdout, stderr)
}

/// `watch` shows forged records of a hostile peer as one escaped line each: no window
/// title, no cleared screen, no fake line; the undecodable payload's key and the field
/// its error names are escaped too.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_escapes_forged_records_keys_and_decode_errors() {
    let (stdout, stderr) = watch(&[]).await;
    assert_clean("watch's output", &stdout);
    assert_clean("watch's errors", &stderr);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(
        lines[0].starts_with(r"ALARM \x1b]0;pwned\x07 k=5 onset=4 ")
            && lines[0].contains(r"leak\x1b[2J\x1b[H"),
        "{stdout}"
    );
    assert_eq!(
        lines[1],
        r"ERROR pump\u{202e}1 k=- unknown_field: x\n2026-12-03T10:00:00.000Z  INFO ALARM pump3 k=1 forged  [! no source: not published by a glrmon instance]"
    );
    // Every forged record's line is flagged as published by no glrmon instance (the
    // one printed as JSON has its flag on stderr).
    assert!(
        lines[..2]
            .iter()
            .all(|l| l.ends_with("[! no source: not published by a glrmon instance]")),
        "{stdout}"
    );
    assert!(
        lines[2].starts_with(r#"{"type":"stat",  "channel":"s\u009b2J\u202e","#),
        "{stdout}"
    );
    assert!(
        stderr.starts_with(r"glrmon watch: glrmon/\u{202e}bad/diagnosis: ")
            && stderr.contains(r"field estimate.\x1b]0;pwned\x07\nALARM has the wrong type"),
        "{stderr}"
    );
}

/// `watch --json` passes the records on as JSON lines of the same value, with their
/// raw line breaks, C1 and bidi characters turned into whitespace and JSON escapes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_json_keeps_each_record_one_safe_line_of_the_same_value() {
    let (stdout, stderr) = watch(&["--json"]).await;
    assert_clean("watch --json's output", &stdout);
    assert_clean("watch --json's errors", &stderr);
    let lines: Vec<&str> = stdout.lines().collect();
    let records = forged().records;
    assert_eq!(lines.len(), records.len(), "{stdout}");
    for (line, sent) in lines.iter().zip(&records) {
        let got: serde_json::Value = serde_json::from_str(line).unwrap();
        let sent: serde_json::Value = serde_json::from_str(sent).unwrap();
        assert_eq!(got, sent);
    }
    assert!(
        lines[0].contains(r#""channel":"\u001b]0;pwned\u0007""#),
        "{stdout}"
    );
}

/// `glrmon info` on a recording whose file name, metadata, channel and topic names hold
/// control sequences and bidi overrides: the table and the JSON show them escaped (the
/// JSON as the same values), and an unreadable hostile file name is escaped in the
/// error.
#[test]
fn info_escapes_a_recordings_names_and_metadata() {
    let scratch = Scratch::new("hostile-info");
    let path = scratch.0.join("rec\u{1b}[2J\u{202e}lmx.mcap");
    let channel = "\u{1b}]0;pwned\u{7}";
    let header = glrmon_record::FileHeader {
        config: String::new(),
        channels: vec![channel.to_owned(), "ok\nALARM forged".to_owned()],
        extra: BTreeMap::from([
            ("instance".to_owned(), "\u{1b}[2J\u{202e}inst".to_owned()),
            ("source".to_owned(), "src\r\u{9b}31mred".to_owned()),
            ("glrmon_version".to_owned(), "1.0\u{7}".to_owned()),
        ]),
    };
    let mut file =
        glrmon_record::McapFile::create(&path, glrmon_record::FileOptions::default(), &header)
            .unwrap();
    file.write(
        channel,
        glrmon_record::TopicKind::Inputs,
        1_000,
        1_000,
        br#"{"k":0,"y":[1.0]}"#,
    )
    .unwrap();
    let path = file.finish().unwrap();

    let out = run_ok(glrmon().arg("info").arg(&path));
    let table = String::from_utf8(out.stdout).unwrap();
    assert_clean("info's table", &table);
    for expected in [
        r"rec\x1b[2J\u{202e}lmx.mcap",
        r"version:   glrmon 1.0\x07",
        r"instance:  \x1b[2J\u{202e}inst",
        r"source:    src\r\u{9b}31mred",
        r"channels:  \x1b]0;pwned\x07, ok\nALARM forged",
        r"glrmon/\x1b]0;pwned\x07/inputs",
    ] {
        assert!(table.contains(expected), "no {expected} in\n{table}");
    }

    let out = run_ok(glrmon().args(["info", "--json"]).arg(&path));
    let json = String::from_utf8(out.stdout).unwrap();
    assert_clean("info --json", &json);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["metadata"]["instance"], "\u{1b}[2J\u{202e}inst");
    assert_eq!(v["channels"][0], channel);
    assert!(json.contains(r"\u202einst"), "{json}");

    let missing = scratch.0.join("gone\u{1b}]0;pwned\u{7}\u{202e}.mcap");
    let out = glrmon().arg("info").arg(&missing).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_clean("info's error", &stderr);
    assert!(
        stderr.contains(r"gone\x1b]0;pwned\x07\u{202e}.mcap"),
        "{stderr}"
    );
}

/// `glrmon replay` of a recording whose inputs name a hostile channel and carry a
/// payload with a hostile field name: the skipped channel, the bad input's field and
/// the damage summary on standard error are escaped.
#[test]
fn replay_escapes_a_recordings_channels_and_bad_inputs() {
    let scratch = Scratch::new("hostile-replay");
    let config = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml"),
    )
    .unwrap();
    let header = glrmon_record::FileHeader {
        config,
        channels: vec!["dc_motor".to_owned()],
        extra: BTreeMap::new(),
    };
    let path = scratch.0.join("hostile.mcap");
    let mut file =
        glrmon_record::McapFile::create(&path, glrmon_record::FileOptions::default(), &header)
            .unwrap();
    let inputs = glrmon_record::TopicKind::Inputs;
    let ghost = "\u{1b}[2J\u{202e}ghost";
    for (i, (channel, payload)) in [
        ("dc_motor", r#"{"k":0,"u":[1],"y":[0,0]}"#),
        (
            "dc_motor",
            r#"{"k":1,"u":[1],"y":[0,0],"y\u001b]0;pwned\u0007\nglrmon replay: forged":1}"#,
        ),
        (ghost, r#"{"k":0,"y":[0]}"#),
    ]
    .into_iter()
    .enumerate()
    {
        let t = 1_000 + i as u64;
        file.write(channel, inputs, t, t, payload.as_bytes())
            .unwrap();
    }
    let path = file.finish().unwrap();

    let out = glrmon()
        .args(["replay", "--quiet", "--output"])
        .arg(scratch.0.join("out.jsonl"))
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_clean("replay's report", &stderr);
    assert_clean("replay's output", &String::from_utf8(out.stdout).unwrap());
    for expected in [
        r#"channel "\x1b[2J\u{202e}ghost": 1 inputs skipped"#,
        r"field y\x1b]0;pwned\x07\nglrmon replay: forged is not a field",
    ] {
        assert!(stderr.contains(expected), "no {expected} in\n{stderr}");
    }
    assert!(
        !stderr
            .lines()
            .any(|l| l.starts_with("glrmon replay: forged")),
        "a forged line in\n{stderr}"
    );
}

/// `glrmon status` asks every instance; a hostile peer answers under a name with a
/// window-title OSC, a line break and a bidi override, and a shard that clears the
/// screen: the table and `--json` show them escaped.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn status_escapes_a_hostile_instances_name_and_status() {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let peer = session(Some(&endpoint), None).await;
    let key = "glrmon/@status/\u{1b}]0;pwned\u{7}\nALARM\u{202e}x";
    let status = "{\"instance\":\"x\",\"uptime\":1,\"shard\":\"\\u001b[2J\u{9b}\",\"connected\":true,\
                  \"reconnections\":0,\"overlaps\":0,\"samples_per_second\":0.0,\"channels\":[]}";
    let _queryable = peer
        .declare_queryable(key)
        .callback(move |query| {
            use zenoh::Wait as _;
            query.reply(key, status).wait().unwrap();
        })
        .await
        .unwrap();
    for json in [false, true] {
        let mut cmd = glrmon();
        cmd.args(["status", "--timeout", "2", "--connect", &endpoint]);
        if json {
            cmd.arg("--json");
        }
        let out = tokio::task::spawn_blocking(move || cmd.output())
            .await
            .unwrap()
            .unwrap();
        let (stdout, stderr) = (
            String::from_utf8(out.stdout).unwrap(),
            String::from_utf8(out.stderr).unwrap(),
        );
        assert!(out.status.success(), "{stdout}\n{stderr}");
        assert_clean("status", &stdout);
        assert_clean("status's errors", &stderr);
        if json {
            let v: serde_json::Value = serde_json::from_str(stdout.trim_end()).unwrap();
            assert_eq!(v["shard"], "\u{1b}[2J\u{9b}");
            assert!(stdout.contains(r#""shard":"\u001b[2J\u009b""#), "{stdout}");
        } else {
            let lines: Vec<&str> = stdout.lines().collect();
            assert_eq!(lines.len(), 3, "{stdout}");
            assert!(
                lines[1].starts_with(r"\x1b]0;pwned\x07\nALARM\u{202e}x  \x1b[2J\u{9b} "),
                "{stdout}"
            );
        }
    }
    peer.close().await.unwrap();
}
