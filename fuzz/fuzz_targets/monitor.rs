//! Sample payloads through a channel's monitor, as the daemon's workers run them: any
//! sequence of payloads (indices anywhere in u64, huge or tiny values, wrong lengths)
//! never panics, and every record the monitor emits can be encoded (no record may be
//! lost to a non-finite number).
#![no_main]

use std::sync::OnceLock;

use glrmon_wire::{DecodeLimits, decode_samples, encode_json};
use libfuzzer_sys::fuzz_target;

const CONFIG: &str = r#"
[[channels]]
name = "fuzz"
[channels.model]
F = [[0.9, 0.1], [0.0, 0.7]]
G = [[1.0], [0.5]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.01
R = 0.04
[channels.scaling]
u_offset = [3.0]
u_scale = [0.5]
y_offset = [12.0, -4.0]
y_scale = [0.1, 20.0]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
kind = "all_actuators"
[channels.glr]
window = 8
isolation_delay = 2
[channels.diagnosis]
enabled = true
"#;

fn channel() -> &'static glrmon_spec::Channel {
    static CHANNEL: OnceLock<glrmon_spec::Channel> = OnceLock::new();
    CHANNEL.get_or_init(|| glrmon_spec::parse(CONFIG).expect("valid").channels[0].clone())
}

fuzz_target!(|data: &[u8]| {
    let Ok(mut monitor) = glrmon_monitor::Monitor::from_channel(channel()) else {
        return;
    };
    let (mut samples, mut records, mut json) = (Vec::new(), Vec::new(), Vec::new());
    // Newline-separated payloads: a fuzzed stream of publishes.
    for payload in data.split(|b| *b == b'\n') {
        if decode_samples("fuzz", payload, &DecodeLimits::default(), &mut samples).is_err() {
            continue;
        }
        for s in &samples {
            monitor.on_sample(s, &mut records);
        }
        for r in records.drain(..) {
            json.clear();
            encode_json(&r, &mut json).expect("every record the monitor emits is finite");
        }
    }
});
