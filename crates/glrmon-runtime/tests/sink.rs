//! The sink interface: an output the crate does not ship plugs into the daemon's
//! runtime with nothing but an implementation of `Sink` (what docs/ARCHITECTURE.md
//! says a new output adds, besides the line that adds it to the assembly). The test
//! double keeps, per channel, what it was handed in order: `i` for an input, the
//! record kind otherwise, and checks the contract a recorder relies on.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_monitor::Monitor;
use glrmon_runtime::{
    InputOutput, Interest, Output, Payload, Runtime, RuntimeEvents, RuntimeSettings, Sink,
    SinkError,
};
use glrmon_wire::{Sample, encode_sample};

type Log = Arc<Mutex<Vec<String>>>;

struct Trace {
    log: Log,
    closed: Arc<Mutex<bool>>,
}

impl Sink for Trace {
    fn name(&self) -> &str {
        "trace"
    }
    fn interest(&self) -> Interest {
        Interest {
            inputs: true,
            stat_every: Some(0),
        }
    }
    fn write_input(&mut self, input: &InputOutput) -> Result<(), SinkError> {
        self.log.lock().unwrap().push(format!("i{}", input.name));
        Ok(())
    }
    fn write(&mut self, output: &Output) -> Result<(), SinkError> {
        self.log
            .lock()
            .unwrap()
            .push(output.record.kind_str().to_owned());
        Ok(())
    }
    fn close(&mut self) -> Result<(), SinkError> {
        *self.closed.lock().unwrap() = true;
        Ok(())
    }
}

struct Panics;
impl RuntimeEvents for Panics {
    fn sink_error(&self, e: &SinkError) {
        panic!("{e}");
    }
}

#[test]
fn a_sink_from_outside_the_crate_gets_inputs_before_their_records_and_is_closed() {
    let cfg = glrmon_spec::parse(
        r#"
[[channels]]
name = "tank"
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
glr = { window = 20, threshold = 30.0 }
"#,
    )
    .unwrap();
    let monitor = Monitor::from_channel(&cfg.channels[0]).unwrap();
    let (log, closed) = (Log::default(), Arc::new(Mutex::new(false)));
    let sink = Trace {
        log: log.clone(),
        closed: closed.clone(),
    };
    let settings = RuntimeSettings {
        workers: 1,
        stat_every: 1,
        ..RuntimeSettings::default()
    };
    let rt = Runtime::start(
        vec![monitor],
        vec![Box::new(sink)],
        &settings,
        Arc::new(Panics),
    );
    let intake = rt.intake();
    for k in 0..100_u64 {
        let y = if k >= 60 {
            3.0
        } else {
            0.05 * (k as f64).sin()
        };
        let mut bytes = Vec::new();
        let sample = Sample {
            k: Some(k),
            y: vec![y],
            ..Sample::default()
        };
        encode_sample("tank", &sample, &mut bytes).unwrap();
        intake.offer(
            0,
            Payload {
                bytes,
                received: Instant::now(),
                source_time: None,
                tag: 0,
                declared: glrmon_runtime::Declared::Nothing,
            },
        );
    }
    let (in_time, _) = rt.shutdown(Duration::from_secs(30));
    assert!(in_time);
    assert!(*closed.lock().unwrap(), "the sink was not closed");
    let log = log.lock().unwrap();
    // Every input arrived, each before the records it produced; `stat_every = 0`
    // keeps this sink's `stat` records away whatever the runtime's default.
    assert_eq!(log.iter().filter(|e| *e == "itank").count(), 100);
    assert!(!log.iter().any(|e| e == "stat"), "{log:?}");
    let alarm = log.iter().position(|e| e == "alarm").expect("an alarm");
    assert_eq!(log[alarm - 1], "itank", "{log:?}");
    assert_eq!(log.first().map(String::as_str), Some("itank"));
}
