//! Binary payloads as a plant or robot publishes them (ROS 2 CDR, Sparkplug B, raw f64
//! records): decoding never panics; a decoded sample holds finite values of the
//! channel's dimensions (the positional formats) or a value for every signal
//! (Sparkplug); a refused payload leaves no sample behind. The first byte picks the
//! decoder (and the message type the transport declares, which a CDR decoder follows),
//! the rest is the payload; the Sparkplug decoder keeps what earlier inputs taught it,
//! as it does on a live key.
#![no_main]

use std::sync::{Mutex, OnceLock};

use glrmon_runtime::{Arrival, Declared, PayloadDecoder};
use glrmon_spec::CdrMessage;
use glrmon_wire::DecodeLimits;
use libfuzzer_sys::fuzz_target;

const CONFIG: &str = r#"
[[channels]]
name = "cdr"
payload = "cdr"
model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]

[[channels]]
name = "sample"
payload = "cdr"
cdr = { message = "glrmon_msgs/msg/Sample" }
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]

[[channels]]
name = "spark"
payload = "sparkplug"
model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
[channels.columns]
u = ["A"]
y = ["B", "C"]

[[channels]]
name = "raw"
payload = "raw"
raw = { layout = ["k", "t", "_", "y1", "u0", "y0"] }
model = { F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
"#;

fn decoders() -> &'static Mutex<Vec<Box<dyn PayloadDecoder>>> {
    static DECODERS: OnceLock<Mutex<Vec<Box<dyn PayloadDecoder>>>> = OnceLock::new();
    DECODERS.get_or_init(|| {
        let cfg = glrmon_spec::parse(CONFIG).expect("the fuzz configuration is valid");
        Mutex::new(cfg.channels.iter().map(glrmon_runtime::decoder).collect())
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, payload)) = data.split_first() else {
        return;
    };
    let mut decoders = decoders().lock().unwrap_or_else(|e| e.into_inner());
    let which = usize::from(pick) % decoders.len();
    let limits = DecodeLimits {
        max_payload_bytes: 1 << 16,
        max_batch: 64,
        max_vector_len: 16,
    };
    let declared = match usize::from(pick) / decoders.len() % 4 {
        0 => Declared::Nothing,
        1 => Declared::Cdr(CdrMessage::Float64MultiArray),
        2 => Declared::Cdr(CdrMessage::Sample),
        _ => Declared::OtherCdr,
    };
    let arrival = Arrival {
        declared,
        ..Arrival::default()
    };
    let mut out = Vec::new();
    match decoders[which].decode_tag("fuzz", 0, arrival, payload, &limits, &mut out) {
        Ok(()) => {
            // The positional formats give the channel's lengths; a glrmon_msgs/Sample
            // (configured or declared) carries its own, which the monitor checks.
            let lengths = match (which, declared) {
                (_, Declared::Cdr(CdrMessage::Sample)) | (1, Declared::Nothing) => None,
                (1, _) => Some((0, 1, 0)),
                _ => Some((1, 2, 0)),
            };
            for s in &out {
                assert!(s.check_finite("fuzz").is_ok(), "{s:?}");
                if let Some(lengths) = lengths {
                    assert_eq!((s.u.len(), s.y.len(), s.p.len()), lengths, "{s:?}");
                }
                assert!(s.u.len() <= 16 && s.y.len() <= 16 && s.p.len() <= 16);
            }
            assert!(out.len() <= 64);
        }
        Err(e) => {
            assert!(out.is_empty());
            assert_eq!(e.channel, "fuzz");
        }
    }
});
