//! The payload decoder interface: a format the crate does not ship plugs into a
//! channel's pipeline, and into the daemon's runtime, with nothing but an
//! implementation of `PayloadDecoder` (what docs/ARCHITECTURE.md says a new format
//! adds, besides its configuration name and factory arm). The test double reads y as
//! raw little-endian f64 values, one sample per payload, numbered by arrival.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glrmon_monitor::Monitor;
use glrmon_runtime::{
    ChannelPipeline, ChannelSetup, Fanout, MemorySink, Payload, PayloadDecoder, Runtime,
    RuntimeEvents, RuntimeSettings, Sink, SinkError,
};
use glrmon_wire::{DecodeError, DecodeErrorKind, DecodeLimits, ErrorCode, Record, Sample};

const CONFIG: &str = r#"
[[channels]]
name = "tank"
[channels.model]
F = [[0.9]]
H = [[1.0]]
Q = 0.01
R = 0.04
[[channels.faults]]
name = "bias"
kind = "sensor_bias"
output = 0
[channels.glr]
window = 20
threshold = 30.0
"#;

#[derive(Debug)]
struct RawF64 {
    outputs: usize,
}

impl PayloadDecoder for RawF64 {
    fn format(&self) -> &'static str {
        "raw-f64"
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        _limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        out.clear();
        if payload.len() != 8 * self.outputs {
            return Err(DecodeError::new(
                channel,
                Some("y".into()),
                DecodeErrorKind::WrongDimension {
                    expected: self.outputs,
                    got: payload.len() / 8,
                },
            ));
        }
        let y = payload
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect();
        out.push(Sample {
            y,
            ..Sample::default()
        });
        Ok(())
    }
}

fn monitor() -> Monitor {
    let cfg = glrmon_spec::parse(CONFIG).unwrap();
    Monitor::from_channel(&cfg.channels[0]).unwrap()
}

/// 60 payloads of y = 0.1, a bias of 3 from the 40th on, and one of 5 bytes at 20.
fn payloads() -> Vec<Vec<u8>> {
    (0..60)
        .map(|i| match i {
            20 => vec![1, 2, 3, 4, 5],
            i if i >= 40 => 3.1_f64.to_le_bytes().to_vec(),
            _ => 0.1_f64.to_le_bytes().to_vec(),
        })
        .collect()
}

fn check(records: &[Record]) {
    let errors: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some(e),
            _ => None,
        })
        .collect();
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert_eq!(errors[0].code, ErrorCode::WrongDimension);
    assert!(
        errors[0].message.contains("\"tank\"") && errors[0].message.contains("field y"),
        "{}",
        errors[0].message
    );
    let stats = records
        .iter()
        .filter(|r| matches!(r, Record::Stat(_)))
        .count();
    assert_eq!(stats, 59);
    let alarm = records
        .iter()
        .find_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .expect("an alarm");
    // The refused payload left no hole in the arrival count: the bias enters at k = 39.
    assert!(alarm.onset >= 38 && alarm.onset <= 40, "{alarm:#?}");
}

#[test]
fn a_decoder_from_outside_the_crate_feeds_a_pipeline() {
    let memory = MemorySink::default();
    let records = memory.records();
    let mut fanout = Fanout::new(vec![Box::new(memory) as Box<dyn Sink>], 1);
    let mut pipeline = ChannelPipeline::new(0, monitor(), fanout.plan())
        .with_decoder(Box::new(RawF64 { outputs: 1 }));
    assert_eq!(pipeline.decoder().format(), "raw-f64");
    for p in payloads() {
        pipeline
            .payload(
                &p,
                Default::default(),
                &DecodeLimits::default(),
                0,
                &mut fanout,
            )
            .unwrap();
    }
    fanout.close(&mut |e| panic!("{e}"));
    let got: Vec<Record> = records
        .lock()
        .unwrap()
        .iter()
        .map(|o| o.record.clone())
        .collect();
    check(&got);
    assert_eq!(
        pipeline.stats().errors.lock().unwrap()["wrong_dimension"],
        1
    );
}

struct NoEvents;
impl RuntimeEvents for NoEvents {
    fn sink_error(&self, e: &SinkError) {
        panic!("{e}");
    }
}

#[test]
fn the_daemons_workers_decode_with_the_channels_decoder() {
    let memory = MemorySink::default();
    let records = memory.records();
    let settings = RuntimeSettings {
        workers: 1,
        worker_queue: 1000,
        stat_every: 1,
        ..RuntimeSettings::default()
    };
    let setup = ChannelSetup {
        monitor: monitor(),
        decoder: Box::new(RawF64 { outputs: 1 }),
    };
    let rt = Runtime::start(
        vec![setup],
        vec![Box::new(memory)],
        &settings,
        Arc::new(NoEvents),
    );
    let intake = rt.intake();
    for p in payloads() {
        intake.offer(
            0,
            Payload {
                bytes: p,
                received: Instant::now(),
                source_time: Some(1.5e9),
                tag: 0,
                declared: glrmon_runtime::Declared::Nothing,
            },
        );
    }
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    let got: Vec<Record> = records
        .lock()
        .unwrap()
        .iter()
        .map(|o| o.record.clone())
        .collect();
    check(&got);
    // The transport's time reaches the samples the decoder left without one.
    assert!(got.iter().all(|r| match r {
        Record::Stat(s) => s.t == Some(1.5e9),
        _ => true,
    }));
}
