//! Payload decoding rate of each format: 10⁵ samples of the DC motor (1 input, 2
//! outputs) as its plant publishes them (`glrmon_runtime::publications`), decoded by
//! the channel's decoder, best of `ROUNDS` rounds; a tag channel's three payloads per
//! sample are counted as one sample.
//!
//! `cargo run --release -q -p glrmon-runtime --example decode_rate [ROUNDS]`

use std::time::Instant;

use glrmon_runtime::{Arrival, publications};
use glrmon_wire::{DecodeLimits, Sample};

const MODEL: &str = r#"model = { F = [[0.2231, 0.0109], [-0.0022, 0.5488]], G = [[0.0047], [0.4512]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.0029, R = 0.0025 }
faults = [{ name = "bias", kind = "actuator_bias", input = 0 }]"#;

const SAMPLES: usize = 100_000;

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5);
    println!("format                          samples/s   ns/payload  bytes/payload");
    for (name, settings) in [
        ("json", ""),
        (
            "json, named",
            "[channels.columns]\nu = [\"V101\"]\ny = [\"I201\", \"S202\"]",
        ),
        ("cdr Float64MultiArray", "payload = \"cdr\""),
        (
            "cdr glrmon_msgs/Sample",
            "payload = \"cdr\"\ncdr = { message = \"glrmon_msgs/msg/Sample\" }",
        ),
        ("sparkplug", "payload = \"sparkplug\""),
        (
            "raw",
            "payload = \"raw\"\nraw = { layout = [\"k\", \"t\", \"u0\", \"y0\", \"y1\"] }",
        ),
        (
            "tags (3 keys, period)",
            "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nu0 = \"plant/u\"\ny0 = \"plant/i\"\ny1 = \"plant/s\"",
        ),
    ] {
        let text = format!("[[channels]]\nname = \"m\"\n{MODEL}\n{settings}\n");
        let cfg = glrmon_spec::parse(&text).expect("valid");
        let channel = &cfg.channels[0];
        let mut payloads = Vec::new();
        for k in 0..SAMPLES {
            let t = 1.8e9 + k as f64 * 0.01;
            let sample = Sample {
                k: Some(k as u64),
                t: Some(t),
                u: vec![1.0 + 0.5 * (0.02 * k as f64).sin()],
                y: vec![0.1 * k as f64, -3.25 + 1e-3 * k as f64],
                p: vec![],
            };
            let mut out = Vec::new();
            publications(channel, &sample, &mut out).expect("encodable");
            for (i, p) in out.into_iter().enumerate() {
                payloads.push((t + 0.002 + i as f64 * 1e-3, p));
            }
        }
        let bytes: usize = payloads.iter().map(|(_, p)| p.bytes.len()).sum();
        let limits = DecodeLimits::default();
        let mut best = f64::INFINITY;
        let mut formed = 0;
        for _ in 0..rounds {
            let mut decoder = glrmon_runtime::decoder(channel);
            let mut out = Vec::new();
            formed = 0;
            let start = Instant::now();
            for (t, p) in &payloads {
                let arrival = Arrival {
                    source_time: Some(*t),
                    received: *t,
                    declared: Default::default(),
                };
                decoder
                    .decode_tag("m", p.key, arrival, &p.bytes, &limits, &mut out)
                    .expect("decodes");
                formed += out.len();
            }
            best = best.min(start.elapsed().as_secs_f64());
        }
        println!(
            "{name:<30} {:>10.0} {:>12.0} {:>14.1}",
            formed as f64 / best,
            best * 1e9 / payloads.len() as f64,
            bytes as f64 / payloads.len() as f64
        );
    }
}
