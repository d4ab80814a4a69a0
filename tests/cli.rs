//! End-to-end tests of the real `glrmon` binary.

use std::process::Command;

fn glrmon() -> Command {
    Command::new(env!("CARGO_BIN_EXE_glrmon"))
}

/// `glrmon demo` (what `make demo` runs): the faulty channel raises exactly one alarm,
/// isolating the injected fault, the clean channels none; the JSONL output holds one
/// stat per sample per channel.
#[test]
fn demo_prints_one_alarm_for_the_faulty_channel_with_the_right_isolation() {
    let dir = std::env::temp_dir().join(format!("glrmon-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let jsonl = dir.join("demo.jsonl");
    let out = glrmon()
        .args(["demo", "--seconds", "6", "--rate", "0", "--output"])
        .arg(&jsonl)
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
    assert!(
        alarms[0].starts_with("ALARM unstable k=203 onset=201"),
        "{stdout}"
    );
    assert!(alarms[0].contains("isolated=[x0_jump]"), "{stdout}");
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
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn usage_error_exits_2() {
    let out = glrmon().arg("no-such-command").output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}
