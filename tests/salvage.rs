//! MCAP salvage end to end with the real binary: a recording whose
//! middle chunk header is zeroed is recovered past the damage, `glrmon recover` writes
//! every readable message, names the lost time range and exits 1; `glrmon replay`
//! replays the chunks after the damage and exits 1.

#[path = "support.rs"]
mod support;

use std::collections::HashMap;
use std::path::Path;

use glrmon_record::{Event, McapReader};
use support::{Scratch, glrmon, run_ok};

/// Byte offsets and lengths of the chunk records of an MCAP file's data section.
fn chunks(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if bytes[at] == 0x06 {
            out.push((at, 9 + len));
        }
        if bytes[at] == 0x0f || bytes[at] == 0x02 {
            break;
        }
        at += 9 + len;
    }
    out
}

/// Every message of a recording as (log time, topic, data).
fn messages(path: &Path) -> Vec<(u64, String, Vec<u8>)> {
    let mut r = McapReader::new(std::fs::File::open(path).unwrap()).unwrap();
    let mut out = Vec::new();
    while let Some(e) = r.next_event().unwrap() {
        if let Event::Message(m) = e {
            out.push((m.log_time, m.topic.topic.clone(), m.data));
        }
    }
    out
}

#[test]
fn recover_of_a_zeroed_chunk_header_salvages_the_rest_and_exits_1() {
    let scratch = Scratch::new("zeroed");
    let config =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2014-unstable.toml");
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
    let victim = found.len() / 2;
    let (at, len) = found[victim];
    bytes[at..at + 9].fill(0);
    let damaged = scratch.0.join("damaged.mcap");
    std::fs::write(&damaged, &bytes).unwrap();

    let recovered = scratch.0.join("recovered.mcap");
    let out = glrmon()
        .arg("recover")
        .arg(&damaged)
        .arg("--output")
        .arg(&recovered)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains(&format!("damaged, skipped: bytes {at}..")),
        "{stderr}"
    );
    assert!(stderr.contains("1 damaged region(s)"), "{stderr}");
    // The lost time range, from the index: "messages logged A..=B ns".
    let range = stderr
        .split("messages logged ")
        .nth(1)
        .and_then(|s| s.split(" ns").next())
        .unwrap_or_else(|| panic!("no lost time range in: {stderr}"));
    let (a, b) = range.split_once("..=").unwrap();
    let (a, b): (u64, u64) = (a.parse().unwrap(), b.parse().unwrap());
    assert!(a <= b);

    let original = messages(&full);
    let got = messages(&recovered);
    assert!(got.len() < original.len() && !got.is_empty());
    // Every recovered message is one of the original's; every original message logged
    // outside the lost range is recovered, none strictly inside it.
    let mut pool: HashMap<&(u64, String, Vec<u8>), usize> = HashMap::new();
    for m in &original {
        *pool.entry(m).or_default() += 1;
    }
    for m in &got {
        let n = pool
            .get_mut(m)
            .expect("a recovered message not in the original");
        assert!(*n > 0, "a message recovered twice");
        *n -= 1;
        assert!(
            m.0 <= a || m.0 >= b,
            "a message of the lost range recovered"
        );
    }
    let outside = original.iter().filter(|m| m.0 < a || m.0 > b).count();
    assert!(got.len() >= outside, "{} < {outside}", got.len());
    let known = stderr
        .split("recovered of ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse::<usize>().ok());
    assert_eq!(known, Some(original.len()), "{stderr}");

    // A replay of the damaged file goes on after the damage, and exits 1 too.
    let out = glrmon()
        .arg("replay")
        .arg(&damaged)
        .arg("--output")
        .arg(scratch.0.join("out.jsonl"))
        .output()
        .unwrap();
    let replay_err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{replay_err}");
    assert!(replay_err.contains("damaged: bytes"), "{replay_err}");
    let text = std::fs::read_to_string(scratch.0.join("out.jsonl")).unwrap();
    let last_k = text
        .lines()
        .filter(|l| l.contains("\"type\":\"stat\""))
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?["k"].as_u64())
        .max();
    assert_eq!(
        last_k,
        Some(19_999),
        "the chunks after the damage were replayed"
    );
    eprintln!(
        "zeroed header of chunk {} of {} (bytes {at}..{}): recover wrote {} of {} messages, \
         lost range {a}..={b} ns; exit 1\n{stderr}",
        victim + 1,
        found.len(),
        at + len,
        got.len(),
        original.len()
    );
}
