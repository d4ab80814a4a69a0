//! Recordings glrmon did not write: a ROS 2 bag in MCAP written by the official
//! library (mcap-ros2-support, ROS 2 profile, CDR messages with their ros2msg schema,
//! zstd chunks), the same messages as Foxglove JSON, and as protobuf messages written by
//! the official library of MCAP's protobuf profile (mcap-protobuf-support, a
//! FileDescriptorSet schema with a dependency), replayed with
//! config/examples/ros2-bag.toml by the real binary, give the records (alarm, its
//! isolation update) of the CSV the bag was made from, bit for bit but for the times;
//! a mapping that names a topic the bag does not have is refused with the bag's topics;
//! a bag cut short replays up to its last whole chunk and says so; a protobuf schema that
//! is not a FileDescriptorSet makes each of its topic's messages an error naming the
//! topic.

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
    let protobuf_bag = scratch.0.join("motor-protobuf.mcap");
    run_ok(python().arg("protobuf_bag.py").arg(&csv).arg(&protobuf_bag));
    let config = example();
    let (want, _) = records(&["--config".as_ref(), config.as_os_str(), csv.as_os_str()]);
    assert!(
        want.iter()
            .any(|r| r["type"] == "alarm" && r["onset"] == 200),
        "{want:?}"
    );
    for file in [&bag, &json_bag, &protobuf_bag] {
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
    let info = run_ok(glrmon().arg("info").arg(&protobuf_bag));
    let info = String::from_utf8(info.stdout).unwrap();
    assert!(
        info.contains("written:   not by glrmon (mcap-python/1.6.0 mcap-protobuf-support/")
            && info.contains("/dc_motor/y  glrmon_test.Float64Array (schema protobuf, messages protobuf)  400 messages"),
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

/// A protobuf bag whose schema data is garbage (not a FileDescriptorSet): its messages
/// are read by nothing, and each becomes an error record (`wrong_type`) naming its
/// topic and why; the summary counts them by topic.
#[test]
fn a_protobuf_bag_with_a_garbage_schema_gives_an_error_for_each_message() {
    let scratch = Scratch::new("foreign-garbage-schema");
    let csv = scratch.0.join("motor.csv");
    std::fs::write(
        &csv,
        "k,t,u0,y0,y1\n0,0.0,1.0,0.1,0.2\n1,0.01,1.0,0.1,0.2\n2,0.02,1.0,0.1,0.2\n",
    )
    .unwrap();
    let bag = scratch.0.join("garbage.mcap");
    run_ok(
        python()
            .arg("protobuf_bag.py")
            .arg(&csv)
            .arg(&bag)
            .arg("--garbage-schema"),
    );
    let config = example();
    let (got, said) = records(&["--config".as_ref(), config.as_os_str(), bag.as_os_str()]);
    let why = "its protobuf schema glrmon_test.Float64Array: not a FileDescriptorSet: ";
    assert_eq!(got.len(), 6, "{got:?}");
    for (i, r) in got.iter().enumerate() {
        let topic = ["/dc_motor/u", "/dc_motor/y"][i % 2];
        let text = r["message"].as_str().unwrap();
        assert!(
            r["type"] == "error"
                && r["code"] == "wrong_type"
                && text.starts_with(&format!(
                    "channel \"dc_motor\": topic {topic}: message {} cannot be read: {why}",
                    i + 1
                )),
            "{r}"
        );
    }
    for topic in ["/dc_motor/u", "/dc_motor/y"] {
        assert!(
            said.contains(&format!("  topic {topic}: 3 messages not read: {why}")),
            "{said}"
        );
    }
    assert!(
        said.contains("channel \"dc_motor\": 0 samples, 0 alarms, 6 errors (wrong_type 6)"),
        "{said}"
    );
}

/// The batch tools read a bag through the channel's `[channels.topics]` as they read
/// the CSV it was made from: `identify --topics` writes the same model (the period,
/// estimated from times that went through the bag's nanosecond epoch stamps, to 10⁻⁵),
/// `identify --model` the same noise covariances, `calibrate` the same thresholds.
#[test]
fn identify_and_calibrate_read_a_bag_as_its_csv() {
    let scratch = Scratch::new("foreign-batch");
    // The example's motor with a full-rank Q and an input rich enough to identify.
    let config = scratch.0.join("motor.toml");
    let text = std::fs::read_to_string(example())
        .unwrap()
        .replace("Q = [[0.002896780428, 0.0], [0.0, 0.0]]", "Q = 0.003")
        .replace(
            "inputs = [\"1.0 + 0.5*sin(0.02*k)\"]",
            "inputs = [\"1.0 + 0.5*sin(0.02*k) + 0.4*sin(1.3*k) + 0.3*sin(2.9*k)\"]",
        );
    assert!(text.contains("Q = 0.003") && text.contains("sin(2.9*k)"));
    std::fs::write(&config, text).unwrap();
    let csv = scratch.0.join("motor.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(&config)
            .args(["--samples", "3000", "--seed", "11", "--output"])
            .arg(&csv),
    );
    let bag = scratch.0.join("motor.mcap");
    run_ok(python().arg("ros2_bag.py").arg(&csv).arg(&bag));
    // The written configuration without its comments (they name the files).
    let written = |args: &[&std::ffi::OsStr], name: &str| -> Vec<String> {
        let out = scratch.0.join(name);
        run_ok(
            glrmon()
                .arg("identify")
                .args(args)
                .arg("--output")
                .arg(&out),
        );
        std::fs::read_to_string(out)
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(str::to_owned)
            .collect()
    };
    let channel = ["--channel".as_ref(), "dc_motor".as_ref()];
    let from_csv = written(&[&channel[..], &[csv.as_os_str()]].concat(), "csv.toml");
    let from_bag = written(
        &[
            &channel[..],
            &["--topics".as_ref(), config.as_os_str(), bag.as_os_str()],
        ]
        .concat(),
        "bag.toml",
    );
    assert_eq!(from_csv.len(), from_bag.len());
    let mut compared = 0;
    for (a, b) in from_csv.iter().zip(&from_bag) {
        if let (Some(a), Some(b)) = (a.strip_prefix("period = "), b.strip_prefix("period = ")) {
            let (a, b): (f64, f64) = (a.parse().unwrap(), b.parse().unwrap());
            assert!(
                (a - b).abs() < 1e-5 * a,
                "period {a} from the CSV, {b} from the bag"
            );
        } else {
            assert_eq!(a, b);
            compared += 1;
        }
    }
    assert!(
        from_bag.iter().any(|l| l.starts_with("F = ")),
        "{from_bag:?}"
    );
    assert!(compared > 20, "{compared} lines compared");
    let model = ["--model".as_ref(), config.as_os_str()];
    assert_eq!(
        written(&[&model[..], &[csv.as_os_str()]].concat(), "noise-csv.toml"),
        written(&[&model[..], &[bag.as_os_str()]].concat(), "noise-bag.toml"),
    );
    let calibrated = |file: &Path| -> String {
        let out = run_ok(
            glrmon()
                .args(["calibrate", "--config"])
                .arg(&config)
                .args(["--mtbfa", "1000"])
                .arg(file),
        );
        let text = String::from_utf8(out.stdout).unwrap();
        text.replace(&file.display().to_string(), "FILE")
    };
    let (a, b) = (calibrated(&csv), calibrated(&bag));
    assert!(a.contains("threshold"), "{a}");
    assert_eq!(a, b);
}
