//! The binary formats and tag assembly decode without allocating once a channel's first
//! payloads have sized its buffers (a counting global allocator): CDR, Sparkplug B
//! (names compared where they lie in the payload), raw records, and a channel
//! assembled from tags, whose formed samples reuse the buffers of earlier ones.

#[path = "../../../tests/counting_alloc.rs"]
mod counting_alloc;

use std::sync::atomic::Ordering;

use glrmon_runtime::{Arrival, Publication, publications};
use glrmon_wire::{DecodeLimits, Sample};

use counting_alloc::{ALLOCATIONS, COUNTED, Counting};

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const MODEL: &str = r#"model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]"#;

/// The payloads of `n` samples of a channel, each with the time it is published at.
fn payloads(channel: &glrmon_spec::Channel, n: usize) -> Vec<(f64, Publication)> {
    let mut out = Vec::new();
    for k in 0..n {
        let t = 1000.0 + k as f64 * 0.01;
        let sample = Sample {
            k: Some(k as u64),
            t: Some(t),
            u: vec![1.0 + k as f64 * 1e-3],
            y: vec![0.5, -2.0 + k as f64],
            p: vec![],
        };
        let mut publications_of = Vec::new();
        publications(channel, &sample, &mut publications_of).unwrap();
        // The tags of one period, 1 ms apart, 5 ms into it.
        for (i, p) in publications_of.into_iter().enumerate() {
            out.push((t + 0.005 + i as f64 * 0.001, p));
        }
    }
    out
}

#[test]
fn binary_formats_and_tags_decode_without_allocating() {
    for (settings, formed_per_payload) in [
        ("payload = \"cdr\"", 1.0),
        (
            "payload = \"cdr\"\ncdr = { message = \"glrmon_msgs/msg/Sample\" }",
            1.0,
        ),
        ("payload = \"sparkplug\"", 1.0),
        (
            "payload = \"raw\"\nraw = { layout = [\"k\", \"t\", \"u0\", \"y0\", \"y1\"] }",
            1.0,
        ),
        (
            "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nu0 = \"plant/u\"\n\
             y0 = { key = \"plant/y\", field = \"data.value\" }\ny1 = \"plant/z\"",
            1.0 / 3.0,
        ),
    ] {
        let text = format!("[[channels]]\nname = \"m\"\n{MODEL}\n{settings}\n");
        let cfg = glrmon_spec::parse(&text).unwrap();
        let mut decoder = glrmon_runtime::decoder(&cfg.channels[0]);
        let all = payloads(&cfg.channels[0], 1100);
        let (warm, measured) = all.split_at(all.len() / 11);
        let limits = DecodeLimits::default();
        let mut out = Vec::new();
        let mut decode = |(t, p): &(f64, Publication), out: &mut Vec<Sample>| {
            let arrival = Arrival {
                source_time: Some(*t),
                received: *t,
                declared: Default::default(),
            };
            decoder
                .decode_tag("m", p.key, arrival, &p.bytes, &limits, out)
                .unwrap();
        };
        for p in warm {
            decode(p, &mut out);
        }
        let mut formed = 0usize;
        ALLOCATIONS.store(0, Ordering::Relaxed);
        for p in measured {
            COUNTED.with(|c| c.set(true));
            decode(p, &mut out);
            COUNTED.with(|c| c.set(false));
            formed += out.len();
        }
        let allocations = ALLOCATIONS.load(Ordering::Relaxed);
        assert_eq!(allocations, 0, "{settings}: {allocations} allocations");
        let want = measured.len() as f64 * formed_per_payload;
        assert!(
            (formed as f64 - want).abs() <= 1.0,
            "{settings}: {formed} samples"
        );
    }
    // The count works: an error's message allocates.
    let cfg = glrmon_spec::parse(&format!(
        "[[channels]]\nname = \"m\"\npayload = \"cdr\"\n{MODEL}\n"
    ))
    .unwrap();
    let mut decoder = glrmon_runtime::decoder(&cfg.channels[0]);
    let mut out = Vec::new();
    COUNTED.with(|c| c.set(true));
    let refused = decoder.decode("m", b"nope", &DecodeLimits::default(), &mut out);
    COUNTED.with(|c| c.set(false));
    assert!(refused.is_err() && ALLOCATIONS.load(Ordering::Relaxed) > 0);
}
