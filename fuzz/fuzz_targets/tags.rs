//! A channel assembled from tags, fed hostile tag payloads and times: decoding never
//! panics; every sample formed holds a finite value per signal, its index grows, and
//! its time is an instant of the period; a refused payload forms no sample. The bytes
//! are cut into (tag, time step, payload) records.
#![no_main]

use glrmon_runtime::Arrival;
use glrmon_wire::DecodeLimits;
use libfuzzer_sys::fuzz_target;

const CONFIG: &str = r#"
[[channels]]
name = "tags"
model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
[channels.tags]
period = 0.5
hold = 2
[channels.tags.keys]
u0 = "plant/u"
y0 = { key = "plant/y", field = "a.b" }
y1 = { key = "plant/z", field = "v", time_field = "ts" }
"#;

fuzz_target!(|data: &[u8]| {
    let cfg = glrmon_spec::parse(CONFIG).expect("the fuzz configuration is valid");
    let mut decoder = glrmon_runtime::decoder(&cfg.channels[0]);
    let limits = DecodeLimits::default();
    let mut out = Vec::new();
    let mut last_k = None;
    let mut time = 0.0;
    let mut rest = data;
    while let [tag, step, len, tail @ ..] = rest {
        let len = usize::from(*len).min(tail.len());
        let (payload, next) = tail.split_at(len);
        rest = next;
        time += f64::from(*step) / 64.0 - 1.0;
        let arrival = Arrival {
            source_time: Some(time),
            received: time,
            declared: Default::default(),
        };
        let tag = usize::from(*tag) % 4;
        match decoder.decode_tag("tags", tag, arrival, payload, &limits, &mut out) {
            Ok(()) => {
                for s in &out {
                    assert!(s.check_finite("tags").is_ok(), "{s:?}");
                    assert_eq!((s.u.len(), s.y.len()), (1, 2));
                    let k = s.k.expect("a formed sample is numbered");
                    assert!(last_k.is_none_or(|l| k > l), "{k} after {last_k:?}");
                    last_k = Some(k);
                    let t = s.t.expect("a formed sample is timed");
                    assert!((t / 0.5 - (t / 0.5).round()).abs() < 1e-6, "{t}");
                }
            }
            Err(e) => {
                assert!(out.is_empty());
                assert_eq!(e.channel, "tags");
            }
        }
        let _ = decoder.take_notice();
    }
});
