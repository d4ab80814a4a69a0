//! Recordings glrmon did not write: a ROS 2 bag in MCAP written by the official
//! library (mcap-ros2-support, ROS 2 profile, CDR messages with their ros2msg schema,
//! zstd chunks), and the same messages as Foxglove JSON, replayed with
//! config/examples/ros2-bag.toml by the real binary, give the records (alarm, its
//! isolation update) of the CSV the bag was made from, bit for bit but for the times;
//! a mapping that names a topic the bag does not have is refused with the bag's topics;
//! a bag cut short replays up to its last whole chunk and says so.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};

use support::{Scratch, glrmon, python, run_ok};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/ros2-bag.toml")
}

/// The records of a replay but `stat`, each with its time removed.
fn records(args: &[&std::ffi::OsStr]) -> (Vec<serde_json::Value>, String) {
    let out = run_ok(glrmon().arg("replay").args(args));
    let records = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|r| r["type"] != "stat")
        .map(|mut r| {
            r.as_object_mut().unwrap().remove("t");
            r
        })
        .collect();
    (records, String::from_utf8(out.stderr).unwrap())
}

#[test]
fn a_ros2_bag_replays_to_the_records_of_its_csv() {
    let scratch = Scratch::new("foreign-bag");
    let csv = scratch.0.join("motor.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(example())
            .args([
                "--samples",
                "400",
                "--seed",
                "7",
                "--fault",
                "actuator_bias:0.5",
            ])
            .args(["--onset", "200", "--output"])
            .arg(&csv),
    );
    let bag = scratch.0.join("motor.mcap");
    let json_bag = scratch.0.join("motor-json.mcap");
    run_ok(python().arg("ros2_bag.py").arg(&csv).arg(&bag));
    run_ok(
        python()
            .arg("ros2_bag.py")
            .arg(&csv)
            .arg(&json_bag)
            .arg("--json"),
    );
    let config = example();
    let (want, _) = records(&["--config".as_ref(), config.as_os_str(), csv.as_os_str()]);
    assert!(
        want.iter()
            .any(|r| r["type"] == "alarm" && r["onset"] == 200),
        "{want:?}"
    );
    for file in [&bag, &json_bag] {
        let (got, said) = records(&["--config".as_ref(), config.as_os_str(), file.as_os_str()]);
        assert_eq!(got, want, "{}", file.display());
        assert!(
            said.contains("800 messages (/dc_motor/u 400, /dc_motor/y 400)")
                && said.contains("channel \"dc_motor\": 400 samples, 1 alarm, 0 errors"),
            "{said}"
        );
    }
    // A bag cut short (its writer killed) is streamed up to its last whole chunk: the
    // samples before are replayed, and the replay says what it lost and exits 1.
    let cut = scratch.0.join("cut.mcap");
    let bytes = std::fs::read(&bag).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).unwrap();
    let out = glrmon()
        .args(["replay", "--config"])
        .arg(&config)
        .arg(&cut)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("the file is unfinished (no footer): read up to byte")
            && said.contains("the file is damaged; the readable part was replayed"),
        "{said}"
    );
    let replayed = String::from_utf8_lossy(&out.stdout).lines().count();
    assert!(replayed > 0, "{said}");
    // `glrmon info` lists what a mapping needs.
    let info = run_ok(glrmon().arg("info").arg(&bag));
    let info = String::from_utf8(info.stdout).unwrap();
    assert!(
        info.contains("written:   not by glrmon (mcap-python/")
            && info.contains("/dc_motor/y  std_msgs/msg/Float64MultiArray (schema ros2msg, messages cdr)  400 messages"),
        "{info}"
    );
    // A mapping naming a topic the bag does not have.
    let wrong = scratch.0.join("wrong.toml");
    std::fs::write(
        &wrong,
        std::fs::read_to_string(&config)
            .unwrap()
            .replace("key = \"/dc_motor/u\"", "key = \"/motor/voltage\""),
    )
    .unwrap();
    let out = glrmon()
        .args(["replay", "--config"])
        .arg(&wrong)
        .arg(&bag)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("topic \"/motor/voltage\" is not in the recording (its topics: /dc_motor/u, /dc_motor/y)"),
        "{said}"
    );
}
