//! Binary payloads as plants and robots publish them, with the real binary on a real
//! Zenoh session over loopback (explicit tcp/127.0.0.1 endpoints, multicast scouting
//! off). The payloads are written by the official libraries, not by glrmon: ROS 2 CDR
//! by mcap-ros2-support's serializer (`std_msgs/msg/Float64MultiArray` and
//! `glrmon_msgs/msg/Sample`), Sparkplug B by Google's protobuf (a DBIRTH with names,
//! aliases and data types, then DDATA by alias); raw f64 records are plain bytes.
//! Each decodes to the samples of the CSV they were made from, bit for bit, and a
//! daemon monitoring one channel per format on the same data raises the same alarm on
//! every channel as on the JSON one; hostile binary payloads are `error` records naming
//! the channel and the field.

#[path = "support.rs"]
mod support;

use std::path::{Path, PathBuf};

use glrmon_wire::{DecodeLimits, Record, Sample};
use support::{
    RunningDaemon, Scratch, client, collect_records, free_port, glrmon, matched_publisher, python,
    run_ok, unhex,
};
use zenoh::Wait as _;

/// The formats under test: (channel, key, the channel's payload settings).
const CHANNELS: [(&str, &str, &str); 6] = [
    ("dc_json", "plant/dc/json", ""),
    ("dc_cdr", "plant/dc/cdr", "payload = \"cdr\"\n"),
    (
        "dc_sample",
        "plant/dc/sample",
        "payload = \"cdr\"\ncdr = { message = \"glrmon_msgs/msg/Sample\" }\n",
    ),
    (
        "dc_spark",
        "spBv1.0/plant/*/edge1/dc_motor",
        "payload = \"sparkplug\"\n",
    ),
    (
        "dc_raw",
        "plant/dc/raw",
        "payload = \"raw\"\nraw = { layout = [\"k\", \"t\", \"V101\", \"SI201\", \"II202\"] }\n",
    ),
    // Configured for the default Float64MultiArray; its publisher sends
    // glrmon_msgs/msg/Sample and says so in the Zenoh encoding.
    ("dc_declared", DECLARED_KEY, "payload = \"cdr\"\n"),
];

/// The key whose payloads declare their CDR type in the Zenoh encoding.
const DECLARED_KEY: &str = "plant/dc/declared";

/// The encoding that declares glrmon_msgs/msg/Sample.
const SAMPLE_ENCODING: &str = "application/cdr;glrmon_msgs/msg/Sample";

/// The DC motor of config/examples/dc-motor.toml, its signals named as a plant names
/// them, once per format, listening on `endpoint`.
fn config(dir: &Path, endpoint: &str) -> PathBuf {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/dc-motor.toml");
    let motor = std::fs::read_to_string(example).unwrap().replace(
        "[channels.glr]",
        "[channels.columns]\nu = [\"V101\"]\ny = [\"SI201\", \"II202\"]\n\n[channels.glr]",
    );
    let mut text = format!(
        "[zenoh]\nmode = \"peer\"\nlisten = [\"{endpoint}\"]\nmulticast_scouting = false\n\n\
         [daemon]\nstat_every = 1000\n"
    );
    for (name, key, payload) in CHANNELS {
        let channel = motor.replace(
            "name = \"dc_motor\"\n",
            &format!("name = \"{name}\"\nkey = \"{key}\"\n{payload}"),
        );
        text.push_str(&channel[channel.find("[[channels]]").unwrap()..]);
    }
    let path = dir.join("formats.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A simulated run with an actuator bias from sample 200: the CSV and its samples.
fn simulated(dir: &Path, config: &Path) -> (PathBuf, Vec<Sample>) {
    let csv = dir.join("sim.csv");
    run_ok(
        glrmon()
            .args(["simulate", "--config"])
            .arg(config)
            .args(["--channel", "dc_json", "--samples", "400", "--seed", "7"])
            .args(["--fault", "actuator_bias:0.5", "--onset", "200", "--output"])
            .arg(&csv),
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("k,t,V101,SI201,II202\n"), "{text:.80}");
    let samples = text
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            Sample {
                k: Some(f[0] as u64),
                t: Some(f[1]),
                u: vec![f[2]],
                y: vec![f[3], f[4]],
                p: vec![],
            }
        })
        .collect();
    (csv, samples)
}

/// The payloads of each sample by the official encoders: (cdr, sample, sparkplug).
fn encoded(dir: &Path, csv: &Path) -> Vec<[Vec<u8>; 3]> {
    let out = dir.join("payloads.jsonl");
    run_ok(python().arg("payloads.py").arg(csv).arg(&out));
    std::fs::read_to_string(out)
        .unwrap()
        .lines()
        .map(|line| {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            ["cdr", "sample", "sparkplug"].map(|f| unhex(v[f].as_str().unwrap()))
        })
        .collect()
}

fn raw(s: &Sample) -> Vec<u8> {
    [s.k.unwrap() as f64, s.t.unwrap(), s.u[0], s.y[0], s.y[1]]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

fn json(s: &Sample) -> Vec<u8> {
    format!(
        r#"{{"k":{},"t":{:?},"u":[{:?}],"y":[{:?},{:?}]}}"#,
        s.k.unwrap(),
        s.t.unwrap(),
        s.u[0],
        s.y[0],
        s.y[1]
    )
    .into_bytes()
}

#[test]
fn official_encoders_payloads_decode_to_the_csvs_samples() {
    let scratch = Scratch::new("binary-decode");
    let config_path = config(&scratch.0, "tcp/127.0.0.1:1");
    let (csv, samples) = simulated(&scratch.0, &config_path);
    let payloads = encoded(&scratch.0, &csv);
    assert_eq!(payloads.len(), samples.len());
    let cfg = glrmon_spec::load(&config_path).unwrap();
    let mut decoders: Vec<_> = cfg.channels.iter().map(glrmon_runtime::decoder).collect();
    let limits = DecodeLimits::default();
    let mut out = Vec::new();
    for (i, (want, [cdr, msg, spark])) in samples.iter().zip(&payloads).enumerate() {
        for (c, payload) in [(1, cdr), (2, msg), (3, spark)] {
            decoders[c]
                .decode(CHANNELS[c].0, payload, &limits, &mut out)
                .unwrap();
            let got = &out[0];
            let (k, t) = match c {
                // The index and time travel in the glrmon message only; Sparkplug
                // carries milliseconds since the epoch.
                2 => (want.k, want.t),
                3 => (
                    None,
                    Some((1_700_000_000_000 + 10 * i as u64) as f64 / 1000.0),
                ),
                _ => (None, None),
            };
            assert_eq!((got.k, got.t), (k, t), "{} at {i}", CHANNELS[c].0);
            // Bit for bit: the same f64s.
            assert_eq!(
                (&got.u, &got.y),
                (&want.u, &want.y),
                "{} at {i}",
                CHANNELS[c].0
            );
        }
        decoders[4]
            .decode("dc_raw", &raw(want), &limits, &mut out)
            .unwrap();
        assert_eq!(&out[0], want);
    }
}

/// Publishes each `(key, payload, Zenoh encoding)` in order to the daemon at
/// `endpoint` (a publisher per key, as separate devices would) and returns the records
/// published on `glrmon/**` (but `stat`) until `until` says enough.
fn exchange(
    endpoint: &str,
    payloads: &[(&str, Vec<u8>, Option<&str>)],
    until: impl Fn(&[Record]) -> bool,
) -> Vec<Record> {
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let session = client(endpoint).await;
        let results = session.declare_subscriber("glrmon/*/*").await.unwrap();
        let mut publishers = std::collections::BTreeMap::new();
        for (key, _, _) in payloads {
            if !publishers.contains_key(key) {
                publishers.insert(*key, matched_publisher(&session, key).await);
            }
        }
        for (key, p, encoding) in payloads {
            let put = publishers[key].put(p.clone());
            match encoding {
                Some(e) => put.encoding(*e).wait().unwrap(),
                None => put.wait().unwrap(),
            }
        }
        let records = collect_records(&results, until).await;
        session.close().await.unwrap();
        records
    })
}

#[test]
fn every_format_raises_the_alarm_of_the_json_channel() {
    let scratch = Scratch::new("binary-alarms");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = config(&scratch.0, &endpoint);
    let (csv, samples) = simulated(&scratch.0, &config);
    let payloads = encoded(&scratch.0, &csv);
    let _daemon = RunningDaemon::start(
        &config,
        &format!("binary-{}", std::process::id()),
        CHANNELS.len(),
    );
    let spark_key = |i: usize| {
        if i == 0 {
            "spBv1.0/plant/DBIRTH/edge1/dc_motor"
        } else {
            "spBv1.0/plant/DDATA/edge1/dc_motor"
        }
    };
    let mut sent: Vec<(&str, Vec<u8>, Option<&str>)> = Vec::new();
    for (i, (s, [cdr, msg, spark])) in samples.iter().zip(payloads).enumerate() {
        sent.push(("plant/dc/json", json(s), None));
        sent.push(("plant/dc/cdr", cdr, None));
        sent.push(("plant/dc/sample", msg.clone(), None));
        sent.push((DECLARED_KEY, msg, Some(SAMPLE_ENCODING)));
        sent.push((spark_key(i), spark, None));
        sent.push(("plant/dc/raw", raw(s), None));
    }
    let alarms = |r: &[Record]| r.iter().filter(|r| matches!(r, Record::Alarm(_))).count();
    let records = exchange(&endpoint, &sent, |r| alarms(r) >= CHANNELS.len());
    let errors: Vec<_> = records
        .iter()
        .filter(|r| matches!(r, Record::Error(_)))
        .collect();
    assert!(errors.is_empty(), "{errors:#?}");
    let mut by_channel = std::collections::BTreeMap::new();
    for r in &records {
        if let Record::Alarm(a) = r {
            let mut a = a.clone();
            // Times differ by format (the sample's, Sparkplug's milliseconds, the
            // transport's); the channel is the one compared.
            a.t = None;
            let name = std::mem::take(&mut a.channel);
            assert!(
                by_channel.insert(name.clone(), a).is_none(),
                "two alarms on {name}"
            );
        }
    }
    let json = &by_channel["dc_json"];
    // The fault's alarm (a false alarm before it would not test much).
    assert!(json.k >= 200 && json.k < 260, "{json:?}");
    for (name, _, _) in CHANNELS {
        assert_eq!(&by_channel[name], json, "{name}");
    }
}

#[test]
fn hostile_binary_payloads_are_errors_naming_channel_and_field() {
    let scratch = Scratch::new("binary-hostile");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let config = config(&scratch.0, &endpoint);
    let _daemon = RunningDaemon::start(
        &config,
        &format!("binary-{}", std::process::id()),
        CHANNELS.len(),
    );
    // Header; no dimension, data_offset 0, two values (after 4 bytes of padding to the
    // f64's alignment) for the channel's three.
    let mut short_array = vec![0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0];
    short_array.extend([1.0f64, 2.0].iter().flat_map(|v| v.to_le_bytes()));
    let mut nan = 0.0f64.to_le_bytes().repeat(2);
    nan.extend(f64::NAN.to_le_bytes());
    nan.extend(0.0f64.to_le_bytes().repeat(2));
    let sent: Vec<(&str, Vec<u8>, Option<&str>)> = vec![
        ("plant/dc/cdr", b"{\"u\":[1]}".to_vec(), None),
        ("plant/dc/cdr", short_array.clone(), None),
        // A CDR type the channel does not read, as the encoding declares it.
        (
            DECLARED_KEY,
            short_array,
            Some("application/cdr;sensor_msgs/msg/Imu"),
        ),
        ("plant/dc/raw", vec![0; 20], None),
        ("plant/dc/raw", nan, None),
        (
            "spBv1.0/plant/DDATA/edge1/dc_motor",
            vec![0x12, 0x40, 0x0a],
            None,
        ),
        // A Sparkplug metric named V101 (datatype Double) alone: the others never seen.
        (
            "spBv1.0/plant/DDATA/edge1/dc_motor",
            vec![
                0x12, 0x11, 0x0a, 0x04, b'V', b'1', b'0', b'1', 0x20, 0x0a, 0x69, 0, 0, 0, 0, 0, 0,
                0xf0, 0x3f,
            ],
            None,
        ),
    ];
    let n = sent.len();
    let records = exchange(&endpoint, &sent, |r| r.len() >= n);
    let mut messages: Vec<(String, String)> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some((e.code.as_str().to_owned(), e.message.clone())),
            _ => None,
        })
        .collect();
    messages.sort();
    let want = [
        (
            "missing_field",
            "channel \"dc_spark\": field SI201 is missing",
        ),
        (
            "non_finite",
            "channel \"dc_raw\": field V101 is not a finite number",
        ),
        (
            "wrong_dimension",
            "channel \"dc_cdr\": field data has 2 values, model expects 3",
        ),
        (
            "wrong_type",
            "channel \"dc_cdr\": field encapsulation has the wrong type: expected the CDR \
             header 00 01 (little-endian) or 00 00 (big-endian): plain CDR",
        ),
        (
            "wrong_type",
            "channel \"dc_raw\": payload has the wrong type: expected whole records of 40 \
             bytes (5 little-endian f64), not 20 bytes",
        ),
        (
            "wrong_type",
            "channel \"dc_declared\": field encoding has the wrong type: expected a CDR \
             message type glrmon reads (std_msgs/msg/Float64MultiArray, \
             glrmon_msgs/msg/Sample), as the Zenoh encoding application/cdr;<type> names it",
        ),
    ];
    for (code, message) in want {
        assert!(
            messages.iter().any(|(c, m)| c == code && m == message),
            "no {code} {message:?} in {messages:#?}"
        );
    }
    assert!(
        messages
            .iter()
            .any(|(c, m)| c == "wrong_type" && m.starts_with("channel \"dc_spark\": payload has the wrong type: expected a Sparkplug B payload (protobuf): metric")),
        "{messages:#?}"
    );
    assert_eq!(messages.len(), n, "{messages:#?}");
}
