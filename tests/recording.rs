//! The black box, end to end with the real binary, real Zenoh sessions on
//! loopback (explicit tcp/127.0.0.1 endpoints, multicast scouting off) and real MCAP
//! files: a live run recorded and replayed to the same bits, a `kill -9` mid-recording
//! recovered, a corrupt chunk skipped and reported.

#[path = "support.rs"]
mod support;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use glrmon_record::{Event, McapReader, ReadEnd, TopicKind};
use glrmon_zenoh::SessionSettings;
use support::{Scratch, free_port, glrmon, run_ok};
use zenoh::query::QueryTarget;

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples")
}

/// The §6.1 channel and the 2021 example with sparse diagnosis on, recorded.
fn write_config(dir: &Path, endpoint: &str, recording: &str) -> PathBuf {
    let unstable = std::fs::read_to_string(examples().join("paper2014-unstable.toml")).unwrap();
    let ltv3 = std::fs::read_to_string(examples().join("paper2021-example1.toml"))
        .unwrap()
        .replacen(
            "false_alarm = 1e-4\n",
            "false_alarm = 1e-4\nisolation_delay = 100\n\n[channels.diagnosis]\nenabled = true\n",
            1,
        );
    assert!(ltv3.contains("[channels.diagnosis]"));
    let text = format!(
        "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n\
         [daemon]\nstat_every = 0\ninstance = \"rec\"\n\n[recording]\nenabled = true\n\
         directory = \"{}\"\n{recording}\n\n{unstable}\n{ltv3}",
        dir.join("rec").display()
    );
    let path = dir.join("daemon.toml");
    std::fs::write(&path, text).unwrap();
    path
}

struct Daemon(Child);

impl Daemon {
    fn start(config: &Path) -> Self {
        let mut child = glrmon()
            .args(["run", "--config"])
            .arg(config)
            .env("GLRMON_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.contains("monitoring 2 channel(s)"), "{line}");
        Self(child)
    }

    fn signal(&mut self, sig: &str) -> Option<i32> {
        Command::new("kill")
            .args([sig, &self.0.id().to_string()])
            .status()
            .unwrap();
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(20) {
            if let Some(s) = self.0.try_wait().unwrap() {
                return s.code();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `glrmon simulate --publish` (the real binary, a client of the daemon's endpoint).
fn publish(config: &Path, channel: &str, samples: u64, seed: u64, extra: &[&str], endpoint: &str) {
    let mut cmd = glrmon();
    cmd.args(["simulate", "--config"]).arg(config).args([
        "--channel",
        channel,
        "--samples",
        &samples.to_string(),
        "--seed",
        &seed.to_string(),
        "--publish",
        "--connect",
        endpoint,
    ]);
    cmd.args(extra);
    run_ok(&mut cmd);
}

fn session(endpoint: &str) -> zenoh::Session {
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(glrmon_zenoh::open(&SessionSettings {
        mode: Some("client".into()),
        connect: vec![endpoint.to_owned()],
        multicast_scouting: Some(false),
        ..SessionSettings::default()
    }))
    .unwrap()
}

/// Polls the status queryable until it contains every `want` text.
fn wait_status(session: &zenoh::Session, want: &[&str]) {
    use zenoh::Wait as _;
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
        if want.iter().all(|w| last.contains(w)) {
            return;
        }
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "status never reached {want:?}: {last}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every message of a recording by (channel, kind), in order.
type Messages = BTreeMap<(String, &'static str), Vec<Vec<u8>>>;

/// Reads a recording; every message is checked against the JSON Schema recorded for
/// its topic, as Foxglove would read it.
fn read_all(path: &Path) -> (Messages, ReadEnd, usize) {
    let file = std::fs::File::open(path).unwrap();
    let mut r = McapReader::new(BufReader::new(file)).unwrap();
    let mut out = Messages::new();
    let mut schemas: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    while let Some(e) = r.next_event().unwrap() {
        if let Event::Message(m) = e {
            // The foxglove.Log topic is every channel's: filed under "*".
            let channel = m
                .topic
                .channel
                .clone()
                .or_else(|| (m.topic.kind == Some(TopicKind::Log)).then(|| "*".to_owned()));
            let (Some(c), Some(k)) = (&channel, m.topic.kind) else {
                panic!("a message without glrmon metadata: {:?}", m.topic);
            };
            assert_eq!(
                (
                    m.topic.schema_encoding.as_str(),
                    m.topic.message_encoding.as_str()
                ),
                ("jsonschema", "json")
            );
            let schema = schemas
                .entry(m.topic.schema.clone())
                .or_insert_with(|| serde_json::from_slice(&m.topic.schema_data).unwrap());
            let value: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            if let Err(e) = validate(schema, &value, "") {
                panic!(
                    "{}: message does not match schema {}: {e}\n{value}",
                    m.topic.topic, m.topic.schema
                );
            }
            out.entry((c.clone(), k.as_str())).or_default().push(m.data);
        }
    }
    (out, r.end().clone(), r.damage().len())
}

/// A JSON Schema validator for the keywords glrmon's schemas use; any other keyword
/// fails, so the schemas cannot drift outside what is checked here.
fn validate(schema: &serde_json::Value, v: &serde_json::Value, at: &str) -> Result<(), String> {
    use serde_json::Value;
    let obj = schema
        .as_object()
        .ok_or(format!("{at}: schema is not an object"))?;
    for key in obj.keys() {
        if !matches!(
            key.as_str(),
            "type"
                | "properties"
                | "required"
                | "additionalProperties"
                | "items"
                | "minItems"
                | "maxItems"
                | "enum"
                | "const"
                | "minimum"
                | "oneOf"
                | "description"
                | "title"
                | "format"
                | "default"
                | "$schema"
        ) {
            return Err(format!("{at}: unsupported schema keyword {key}"));
        }
    }
    if let Some(alternatives) = obj.get("oneOf").and_then(Value::as_array) {
        let matching = alternatives
            .iter()
            .filter(|s| validate(s, v, at).is_ok())
            .count();
        if matching != 1 {
            return Err(format!(
                "{at}: {v} matches {matching} alternatives of oneOf"
            ));
        }
    }
    if let Some(c) = obj.get("const")
        && c != v
    {
        return Err(format!("{at}: {v} is not {c}"));
    }
    if let (Some(min), Some(x)) = (obj.get("minimum").and_then(Value::as_f64), v.as_f64())
        && x < min
    {
        return Err(format!("{at}: {v} is below {min}"));
    }
    if let Some(arr) = v.as_array() {
        let len = arr.len() as u64;
        if obj
            .get("minItems")
            .and_then(Value::as_u64)
            .is_some_and(|n| len < n)
            || obj
                .get("maxItems")
                .and_then(Value::as_u64)
                .is_some_and(|n| len > n)
        {
            return Err(format!("{at}: {len} items is out of bounds"));
        }
    }
    if let Some(t) = obj.get("type") {
        let types: Vec<&str> = match t {
            Value::String(s) => vec![s.as_str()],
            Value::Array(a) => a.iter().filter_map(Value::as_str).collect(),
            _ => return Err(format!("{at}: bad type")),
        };
        let ok = types.iter().any(|t| match *t {
            "object" => v.is_object(),
            "array" => v.is_array(),
            "string" => v.is_string(),
            "number" => v.is_number(),
            "integer" => v.is_u64() || v.is_i64(),
            "boolean" => v.is_boolean(),
            "null" => v.is_null(),
            _ => false,
        });
        if !ok {
            return Err(format!("{at}: {v} is not of type {types:?}"));
        }
    }
    if let Some(e) = obj.get("enum").and_then(Value::as_array)
        && !e.contains(v)
    {
        return Err(format!("{at}: {v} is not one of {e:?}"));
    }
    if let (Some(items), Some(arr)) = (obj.get("items"), v.as_array()) {
        for (i, x) in arr.iter().enumerate() {
            validate(items, x, &format!("{at}[{i}]"))?;
        }
    }
    if let Some(o) = v.as_object() {
        let props = obj.get("properties").and_then(Value::as_object);
        for r in obj
            .get("required")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            let r = r.as_str().unwrap_or_default();
            if !o.contains_key(r) {
                return Err(format!("{at}: required field {r} is missing"));
            }
        }
        for (k, x) in o {
            match (
                props.and_then(|p| p.get(k)),
                obj.get("additionalProperties"),
            ) {
                (Some(s), _) => validate(s, x, &format!("{at}.{k}"))?,
                (None, Some(Value::Bool(false))) => {
                    return Err(format!("{at}: field {k} is not in the schema"));
                }
                (None, Some(s @ Value::Object(_))) => validate(s, x, &format!("{at}.{k}"))?,
                (None, _) => {}
            }
        }
    }
    Ok(())
}

#[test]
fn the_schema_validator_rejects_what_it_should() {
    let schema: serde_json::Value = serde_json::from_str(
        r#"{"type":"object","properties":{"k":{"type":"integer"},"y":{"type":"array","items":{"type":"number"}}},"required":["y"],"additionalProperties":false}"#,
    )
    .unwrap();
    let ok = |s: &str| validate(&schema, &serde_json::from_str(s).unwrap(), "");
    assert!(ok(r#"{"k":1,"y":[0.5]}"#).is_ok());
    assert!(ok(r#"{"k":1}"#).is_err(), "missing required");
    assert!(ok(r#"{"k":1.5,"y":[]}"#).is_err(), "float for integer");
    assert!(ok(r#"{"y":["a"]}"#).is_err(), "string item");
    assert!(ok(r#"{"y":[],"z":1}"#).is_err(), "extra field");
    let pair: serde_json::Value = serde_json::from_str(
        r#"{"type":"array","items":{"type":"integer","minimum":0},"minItems":2,"maxItems":2}"#,
    )
    .unwrap();
    assert!(validate(&pair, &serde_json::json!([0, 1]), "").is_ok());
    assert!(
        validate(&pair, &serde_json::json!([0]), "").is_err(),
        "too short"
    );
    assert!(
        validate(&pair, &serde_json::json!([0, -1]), "").is_err(),
        "below minimum"
    );
    let tagged: serde_json::Value = serde_json::from_str(
        r#"{"oneOf":[{"properties":{"type":{"const":"a"}},"required":["type"]},{"properties":{"type":{"const":"b"}},"required":["type"]}]}"#,
    )
    .unwrap();
    assert!(validate(&tagged, &serde_json::json!({"type": "b"}), "").is_ok());
    assert!(
        validate(&tagged, &serde_json::json!({"type": "c"}), "").is_err(),
        "no alternative"
    );
    let odd: serde_json::Value = serde_json::from_str(r#"{"uniqueItems":true}"#).unwrap();
    assert!(
        validate(&odd, &serde_json::json!(1), "").is_err(),
        "unknown keyword"
    );
}

fn jsonl_by_kind(text: &str) -> Messages {
    let mut out = Messages::new();
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let kind = TopicKind::parse(v["type"].as_str().unwrap()).unwrap();
        let channel = v["channel"].as_str().unwrap().to_owned();
        out.entry((channel, kind.as_str()))
            .or_default()
            .push(line.as_bytes().to_vec());
    }
    out
}

fn files(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut f: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().ends_with(suffix))
        .collect();
    f.sort();
    f
}

/// A live run through Zenoh, recorded; `glrmon replay FILE.mcap` (no
/// --config) gives every `stat`, `alarm`, `isolation`, `alarm_end`, `diagnosis` and
/// `error` record
/// byte for byte (hence bit for bit: shortest round-trip floats) — as JSON lines and as
/// an MCAP output.
#[test]
fn live_run_recorded_then_replayed_gives_identical_records() {
    let scratch = Scratch::new("live");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = write_config(&scratch.0, &endpoint, "");
    let mut daemon = Daemon::start(&config);
    let fault = ["--fault", "x0_jump:4", "--onset", "201"];
    publish(&config, "unstable", 600, 3, &fault, &endpoint);
    // Known-profile faults of the 2021 example act from the first sample.
    let faults = ["--fault", "f05:1,f16:1,f28:1,f39:1,f42:1"];
    publish(&config, "ltv3", 200, 11, &faults, &endpoint);
    {
        use zenoh::Wait as _;
        let s = session(&endpoint);
        // Bad payloads between the good ones: recorded as intake events, replayed as
        // the same error records.
        for bad in [&b"{\"y\": [1,"[..], b"{\"y\": [1, 2, 3]}", b"[]"] {
            s.put("plant/unstable", bad.to_vec()).wait().unwrap();
        }
        // Samples numbered from 0 again (a restarted publisher): one `sequence_reset`,
        // the filter restarts and all 50 are processed.
        publish(&config, "unstable", 50, 4, &[], &endpoint);
        wait_status(
            &s,
            &[
                "\"channel\":\"unstable\",\"samples\":650,",
                "\"sequence_reset\":1",
                // `{"y": [1, 2, 3]}` has no `u` for a model with an input.
                "\"missing_field\":1",
                "\"channel\":\"ltv3\",\"samples\":200,",
            ],
        );
    }
    assert_eq!(daemon.signal("-TERM"), Some(0), "SIGTERM: clean exit");
    let rec = scratch.0.join("rec");
    assert!(
        files(&rec, ".mcap.tmp").is_empty(),
        "a file left unfinished"
    );
    let finished = files(&rec, ".mcap");
    assert_eq!(finished.len(), 1, "{finished:?}");
    let (live, end, damage) = read_all(&finished[0]);
    assert_eq!((end, damage), (ReadEnd::Finished, 0));
    let count = |m: &Messages, c: &str, k: &str| m.get(&(c.to_owned(), k)).map_or(0, Vec::len);
    // 600 + 50 samples and `{"y": [1, 2, 3]}`, which decodes (the monitor rejects it:
    // no `u`).
    assert_eq!(count(&live, "unstable", "inputs"), 651);
    assert_eq!(count(&live, "ltv3", "inputs"), 200);
    // `{"y": [1,` is refused at intake; `[]` is an empty batch.
    assert_eq!(count(&live, "unstable", "intake"), 1);
    // invalid_json, missing_field and the sequence_reset of the renumbered samples.
    assert_eq!(count(&live, "unstable", "error"), 3);
    assert!(count(&live, "unstable", "alarm") >= 1);
    assert!(count(&live, "unstable", "isolation") >= 1);
    assert!(count(&live, "ltv3", "diagnosis") >= 1);

    let jsonl = scratch.0.join("replay.jsonl");
    let out = run_ok(
        glrmon()
            .arg("replay")
            .arg(&finished[0])
            .arg("--output")
            .arg(&jsonl),
    );
    let replayed = jsonl_by_kind(&std::fs::read_to_string(&jsonl).unwrap());
    let mcap_out = scratch.0.join("replay.mcap");
    run_ok(
        glrmon()
            .arg("replay")
            .arg(&finished[0])
            .arg("--output")
            .arg(&mcap_out),
    );
    let (replayed_mcap, _, _) = read_all(&mcap_out);
    let mut compared = BTreeMap::new();
    for kind in glrmon_wire::RECORD_KINDS {
        for channel in ["unstable", "ltv3"] {
            let key = (channel.to_owned(), kind);
            let a = live.get(&key).cloned().unwrap_or_default();
            let b = replayed.get(&key).cloned().unwrap_or_default();
            let c = replayed_mcap.get(&key).cloned().unwrap_or_default();
            assert_eq!(
                a.len(),
                b.len(),
                "{key:?}: live {} vs replay {}",
                a.len(),
                b.len()
            );
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert_eq!(
                    x,
                    y,
                    "{key:?} #{i}:\n live   {}\n replay {}",
                    String::from_utf8_lossy(x),
                    String::from_utf8_lossy(y)
                );
            }
            assert_eq!(a, c, "{key:?}: the MCAP output differs");
            *compared.entry(kind).or_insert(0) += a.len();
        }
    }
    // Every alarm and error is also a foxglove.Log message, and the replay writes the
    // same ones, byte for byte.
    let logs = live
        .get(&("*".to_owned(), "log"))
        .cloned()
        .unwrap_or_default();
    assert_eq!(
        logs.len(),
        count(&live, "unstable", "alarm")
            + count(&live, "unstable", "error")
            + count(&live, "ltv3", "alarm")
            + count(&live, "ltv3", "error")
    );
    assert_eq!(
        Some(&logs),
        replayed_mcap.get(&("*".to_owned(), "log")),
        "the replay's foxglove.Log messages differ"
    );
    // `glrmon diagnose` reads a recording too (its configuration included).
    let diag =
        run_ok(
            glrmon()
                .arg("diagnose")
                .arg(&finished[0])
                .args(["--channel", "ltv3", "--json"]),
        );
    let d: serde_json::Value = serde_json::from_slice(&diag.stdout).unwrap();
    assert_eq!(
        d["support"],
        serde_json::json!(["f05", "f16", "f28", "f39", "f42"]),
        "{d}"
    );
    // The inputs of the MCAP output are the recorded ones.
    assert_eq!(
        live.get(&("unstable".into(), "inputs")),
        replayed_mcap.get(&("unstable".into(), "inputs"))
    );
    eprintln!(
        "live vs replay, identical records: {compared:?}; replay said: {}",
        String::from_utf8_lossy(&out.stderr)
            .lines()
            .find(|l| l.contains("replayed"))
            .unwrap_or("")
    );
}

/// Inputs of `channel` in a (possibly unfinished) recording.
fn inputs_in(path: &Path, channel: &str) -> usize {
    let Ok(file) = std::fs::File::open(path) else {
        return 0;
    };
    let Ok(mut r) = McapReader::new(BufReader::new(file)) else {
        return 0;
    };
    let mut n = 0;
    while let Ok(Some(e)) = r.next_event() {
        if let Event::Message(m) = e
            && m.topic.kind == Some(TopicKind::Inputs)
            && m.topic.channel.as_deref() == Some(channel)
        {
            n += 1;
        }
    }
    n
}

/// Crash safety: `kill -9` while recording leaves a `.mcap.tmp` file that
/// reads back up to its last flushed chunk; `glrmon replay` replays it (reporting it
/// unfinished) and `glrmon recover` rewrites it as a finished, replayable file.
#[test]
fn kill_9_mid_recording_reads_back_to_the_last_flushed_chunk() {
    let scratch = Scratch::new("kill9");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = write_config(&scratch.0, &endpoint, "flush_seconds = 0.2");
    let mut daemon = Daemon::start(&config);
    publish(&config, "unstable", 2000, 5, &[], &endpoint);
    let rec = scratch.0.join("rec");
    let partial = files(&rec, ".mcap.tmp");
    assert_eq!(partial.len(), 1, "{partial:?}");
    // Flushed within flush_seconds: wait (bounded) until the file holds them all.
    let t = Instant::now();
    while inputs_in(&partial[0], "unstable") < 2000 {
        assert!(t.elapsed() < Duration::from_secs(30), "never flushed");
        std::thread::sleep(Duration::from_millis(50));
    }
    // More samples on the other channel, then the crash: some of them are in no
    // flushed chunk yet.
    publish(&config, "ltv3", 1000, 6, &[], &endpoint);
    assert_eq!(
        daemon.signal("-KILL"),
        None,
        "killed by a signal, no exit code"
    );
    assert!(files(&rec, ".mcap").is_empty(), "nothing was finished");

    let out = glrmon()
        .arg("replay")
        .arg(&partial[0])
        .arg("--output")
        .arg(scratch.0.join("crashed.jsonl"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("unfinished"), "{stderr}");
    let replayed = std::fs::read_to_string(scratch.0.join("crashed.jsonl")).unwrap();
    let stats = replayed
        .lines()
        .filter(|l| l.contains("\"type\":\"stat\""))
        .count();

    let recovered = scratch.0.join("recovered.mcap");
    let out = run_ok(
        glrmon()
            .arg("recover")
            .arg(&partial[0])
            .arg("--output")
            .arg(&recovered),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("unfinished"), "{said}");
    let (messages, end, damage) = read_all(&recovered);
    assert_eq!((end, damage), (ReadEnd::Finished, 0));
    let count = |c: &str| messages.get(&(c.to_owned(), "inputs")).map_or(0, Vec::len);
    assert_eq!(count("unstable"), 2000, "every flushed input is recovered");
    assert!(count("ltv3") <= 1000);
    assert_eq!(
        stats,
        count("unstable") + count("ltv3"),
        "replay saw every recovered input"
    );
    // The recovered file keeps the configuration: it replays without --config.
    run_ok(
        glrmon()
            .arg("replay")
            .arg(&recovered)
            .arg("--output")
            .arg(scratch.0.join("r.jsonl")),
    );
    eprintln!(
        "kill -9: recovered 2000 of 2000 flushed inputs and {} of the 1000 published in the \
         last burst; recover said: {}",
        count("ltv3"),
        said.trim()
    );
}

/// Byte offsets and lengths of the chunk records of an MCAP file.
fn chunks(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if bytes[at] == 0x06 {
            out.push((at, 9 + len));
        }
        if bytes[at] == 0x02 {
            break;
        }
        at += 9 + len;
    }
    out
}

/// A recording with a corrupt chunk: the readable part is replayed, the damage
/// reported with its byte range, and the exit code is 1.
#[test]
fn corrupt_chunk_is_skipped_reported_and_exit_code_is_1() {
    let scratch = Scratch::new("corrupt");
    // The §6.1 unstable plant with its default max_gap (100): after the samples of the
    // lost chunk the filter restarts, and the rest of the file is monitored.
    let config = examples().join("paper2014-unstable.toml");
    let csv = scratch.0.join("s.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--samples", "20000", "--seed", "9", "--output"])
            .arg(&csv),
    );
    let full = scratch.0.join("full.mcap");
    run_ok(
        glrmon()
            .args(["replay", "--config"])
            .arg(&config)
            .arg(&csv)
            .arg("--output")
            .arg(&full),
    );
    let mut bytes = std::fs::read(&full).unwrap();
    let found = chunks(&bytes);
    assert!(found.len() >= 4, "{} chunks", found.len());
    // A chunk of messages (not one of the small chunks that declare a topic).
    let data: Vec<(usize, usize)> = found.iter().copied().filter(|c| c.1 > 4096).collect();
    assert!(data.len() >= 3, "{} chunks of messages", data.len());
    let (at, len) = data[1];
    for b in &mut bytes[at + len / 2..at + len / 2 + 64] {
        *b ^= 0x5a;
    }
    let corrupt = scratch.0.join("corrupt.mcap");
    std::fs::write(&corrupt, &bytes).unwrap();

    let out = glrmon()
        .arg("replay")
        .arg(&corrupt)
        .arg("--output")
        .arg(scratch.0.join("out.jsonl"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("damaged: bytes {at}..{}: chunk skipped", at + len)),
        "{stderr}"
    );
    let text = std::fs::read_to_string(scratch.0.join("out.jsonl")).unwrap();
    let ks: Vec<u64> = text
        .lines()
        .filter(|l| l.contains("\"type\":\"stat\""))
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["k"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert!(ks.len() > 10_000 && ks.len() < 20_000, "{} stats", ks.len());
    assert_eq!(
        ks.last(),
        Some(&19_999),
        "the chunks after the damage were replayed"
    );
    eprintln!(
        "corrupt chunk {} of {} (bytes {at}..{}): {} of 20000 samples replayed",
        found.iter().position(|c| c.0 == at).unwrap_or(0) + 1,
        found.len(),
        at + len,
        ks.len()
    );
}
