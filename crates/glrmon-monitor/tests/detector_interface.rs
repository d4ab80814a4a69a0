//! The detector interface: a kind the crate does not ship plugs into the monitor with
//! nothing but an implementation of `glrmon_core::Detector` (what docs/ARCHITECTURE.md
//! says a new kind adds, besides its configuration name and factory line). The test
//! double is Page's CUSUM for a known increase δ of one sensor's mean (Basseville &
//! Nikiforov 1993, §2.2): g_k = max(0, g_{k−1} + δ/σ²·(y_k − δ/2)), the onset the
//! sample after g was last 0, the magnitude the mean of y since then.

use glrmon_core::{
    AlarmSettings, Column, Detector, Dims, Fault, FaultDictionary, ModelError, Onset, Sample,
    StepError, StepOutput,
};
use glrmon_monitor::{Monitor, MonitorSettings, Tuning};
use glrmon_wire::{ErrorCode, Record};

#[derive(Debug)]
struct Cusum {
    dims: Dims,
    faults: FaultDictionary,
    delta: f64,
    g: f64,
    /// The first sample of the current run of g > 0, and the sum of y over it.
    run: Option<(u64, f64, u64)>,
    next: Option<u64>,
    restarts: u32,
}

impl Cusum {
    fn new(delta: f64) -> Self {
        let dims = Dims {
            states: 1,
            inputs: 0,
            outputs: 1,
            signals: 0,
        };
        let bias = Fault::output(
            "bias",
            Onset::Step,
            Column::Constant(nalgebra::DVector::from_element(1, 1.0)),
        );
        Self {
            dims,
            faults: FaultDictionary::new(dims, vec![bias]).unwrap(),
            delta,
            g: 0.0,
            run: None,
            next: None,
            restarts: 0,
        }
    }
}

impl Detector for Cusum {
    fn kind(&self) -> &'static str {
        "cusum"
    }
    fn describe(&self) -> String {
        format!("CUSUM for a mean increase δ = {}", self.delta)
    }
    fn memory(&self) -> usize {
        1
    }
    fn dims(&self) -> Dims {
        self.dims
    }
    fn faults(&self) -> &FaultDictionary {
        &self.faults
    }
    fn next_index(&self) -> Option<u64> {
        self.next
    }
    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        if let Some(next) = self.next.filter(|&n| n != sample.k) {
            return Err(StepError::OutOfOrder {
                expected: next,
                got: sample.k,
            });
        }
        let y = sample.y[0];
        self.g = (self.g + self.delta * (y - self.delta / 2.0)).max(0.0);
        self.run = if self.g > 0.0 {
            let (start, sum, n) = self.run.unwrap_or((sample.k, 0.0, 0));
            Some((start, sum + y, n + 1))
        } else {
            None
        };
        out.k = sample.k;
        out.innovation[0] = y;
        out.normalized_innovation = y * y;
        out.glr = Some(self.g);
        out.onset = Some(self.run.map_or(sample.k, |(start, _, _)| start));
        out.magnitude[0] = self.run.map_or(0.0, |(_, sum, n)| sum / n as f64);
        out.rank = 1;
        self.next = Some(sample.k + 1);
        Ok(())
    }
    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        self.next = Some(k + 1);
        Ok(())
    }
    fn restart(&mut self) -> Result<(), ModelError> {
        self.restarts += 1;
        (self.g, self.run, self.next) = (0.0, None, None);
        Ok(())
    }
}

fn monitor() -> Monitor {
    Monitor::new(
        "cusum",
        Box::new(Cusum::new(2.0)),
        MonitorSettings {
            tuning: Tuning {
                alarm: AlarmSettings::with_threshold(5.0),
                episode_end: glrmon_core::EpisodeEnd::FaultGone {
                    alpha: 0.01,
                    samples: 3,
                },
                isolation_delay: 2,
                isolation_alpha: 0.01,
                isolation_onsets: 1,
                isolation_thresholds: vec![],
            },
            groups: vec![],
            max_gap: 10,
            max_reorder: 16,
            settle: None,
        },
    )
}

/// y_k = 0.5 sin k, plus 2 from `onset` on.
fn sample(k: u64, onset: u64) -> glrmon_wire::Sample {
    let bias = if k >= onset { 2.0 } else { 0.0 };
    glrmon_wire::Sample {
        k: Some(k),
        t: None,
        u: vec![],
        y: vec![0.5 * (k as f64).sin() + bias],
        p: vec![],
    }
}

#[test]
fn a_detector_kind_from_outside_the_crate_raises_the_monitors_alarm_with_its_onset() {
    let mut mon = monitor();
    let mut records = Vec::new();
    for k in 0..400 {
        mon.on_sample(&sample(k, 300), &mut records);
    }
    // Before the fault every increment δ(y − δ/2) ≤ 2(0.5 − 1) < 0: g stays 0.
    let alarms: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Alarm(a) => Some(a),
            _ => None,
        })
        .collect();
    assert_eq!(alarms.len(), 1, "{alarms:#?}");
    let a = alarms[0];
    // From 300 on each increment is 2(2 + 0.5 sin k − 1) ≥ 1: g > 5 within 5 samples.
    assert!((301..=304).contains(&a.k), "alarm at {}", a.k);
    assert_eq!(a.onset, 300);
    assert_eq!(a.faults, ["bias"]);
    assert!((a.magnitude[0] - 2.0).abs() < 0.5, "{:?}", a.magnitude);
    // The kind has no Fisher statistics: no isolation tests, and no update pretends any.
    assert!(a.isolation.is_empty());
    assert_eq!(mon.counters().alarms, 1);
    assert_eq!(mon.detector().kind(), "cusum");
    let stats = records
        .iter()
        .filter(|r| matches!(r, Record::Stat(_)))
        .count();
    assert_eq!(stats, 400);
}

#[test]
fn the_monitor_bridges_gaps_and_restarts_through_the_interface() {
    let mut mon = monitor();
    let mut records = Vec::new();
    for k in (0..50).chain(53..60).chain(5..10) {
        mon.on_sample(&sample(k, 1000), &mut records);
    }
    let codes: Vec<ErrorCode> = records
        .iter()
        .filter_map(|r| match r {
            Record::Error(e) => Some(e.code),
            _ => None,
        })
        .collect();
    // 50..52 bridged by predict-only steps; k = 5 after 59 is a publisher numbering anew.
    assert_eq!(codes, [ErrorCode::Gap, ErrorCode::SequenceReset]);
    assert_eq!(mon.counters().gap_samples, 3);
    assert_eq!(mon.counters().restarts, 1);
    assert_eq!(mon.detector().next_index(), Some(10));
}
