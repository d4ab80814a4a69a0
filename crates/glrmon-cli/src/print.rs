//! Human-readable one-line rendering of alarms, as `glrmon watch` prints them.

use std::fmt::Write as _;

use glrmon_wire::{Alarm, AlarmEnd, Consistency, Diagnosis, ErrorRecord, Record};

/// One line for an alarm or alarm end; `None` for other records.
pub(crate) fn line(record: &Record) -> Option<String> {
    match record {
        Record::Alarm(a) => Some(alarm_line(a)),
        Record::AlarmEnd(e) => Some(end_line(e)),
        Record::Diagnosis(d) => Some(diagnosis_line(d)),
        Record::Error(e) => Some(error_line(e)),
        Record::Consistency(c) => Some(consistency_line(c)),
        _ => None,
    }
}

fn alarm_line(a: &Alarm) -> String {
    let isolated: Vec<&str> = a
        .isolation
        .iter()
        .filter(|i| i.isolated)
        .map(|i| i.fault.as_str())
        .collect();
    let mut mag = String::new();
    for (i, (name, v)) in a.faults.iter().zip(&a.magnitude).enumerate() {
        let sep = if i == 0 { "" } else { ", " };
        let _ = write!(mag, "{sep}{name} {v:.3}");
    }
    let mut tests = String::new();
    for (i, t) in a.isolation.iter().enumerate() {
        let sep = if i == 0 { "" } else { ", " };
        let _ = write!(tests, "{sep}{} {:.1}/{:.1}", t.fault, t.minmax, t.threshold);
    }
    format!(
        "ALARM {} k={} onset={} glr={:.1} (threshold {:.1}) isolated=[{}] magnitude=[{}] minmax=[{}]{}",
        a.channel,
        a.k,
        a.onset,
        a.glr,
        a.threshold,
        isolated.join(", "),
        mag,
        tests,
        time(a.t)
    )
}

fn end_line(e: &AlarmEnd) -> String {
    format!(
        "END   {} k={} onset={} duration={} peak_glr={:.1}{}",
        e.channel,
        e.k,
        e.onset,
        e.duration,
        e.peak_glr,
        time(e.t)
    )
}

fn diagnosis_line(d: &Diagnosis) -> String {
    let est: Vec<String> = d
        .estimate
        .iter()
        .map(|(k, v)| format!("{k} {v:.3}"))
        .collect();
    // An empty support is the diagnosis's "no fault" (the χ² test of θ = 0).
    let none = if d.support.is_empty() {
        " (no fault)"
    } else {
        ""
    };
    format!(
        "DIAG  {} k={} span={}..{} residual={} support=[{}]{none} estimate=[{}] lambda={:.3e}",
        d.channel,
        d.k,
        d.from,
        d.to,
        d.residual,
        d.support.join(", "),
        est.join(", "),
        d.lambda
    )
}

fn consistency_line(c: &Consistency) -> String {
    format!(
        "MODEL {} k={} consistency={} nis_mean={:.3} band=[{:.3}, {:.3}] expected={} window={}{}",
        c.channel,
        c.k,
        c.state,
        c.nis_mean,
        c.band[0],
        c.band[1],
        c.expected,
        c.window,
        time(c.t)
    )
}

fn error_line(e: &ErrorRecord) -> String {
    let k = e.k.map_or_else(|| "-".to_owned(), |k| k.to_string());
    format!(
        "ERROR {} k={k} {}: {}",
        e.channel,
        e.code.as_str(),
        e.message
    )
}

/// ` t=…` (the sample's time in seconds) when the record carries one.
fn time(t: Option<f64>) -> String {
    t.map_or_else(String::new, |t| format!(" t={t:.3}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::IsolationResult;

    #[test]
    fn alarm_line_names_channel_time_onset_isolated_fault_and_magnitude() {
        let a = Alarm {
            channel: "pump3".into(),
            k: 203,
            t: Some(2.03),
            glr: 1805.1,
            threshold: 27.6,
            onset: 201,
            magnitude: vec![3.981, 0.005],
            isolation: vec![IsolationResult {
                fault: "x0_jump".into(),
                minmax: 1213.1,
                sensitivity: 1300.0,
                threshold: 6.6,
                isolated: true,
            }],
            faults: vec!["x0_jump".into(), "x1_jump".into()],
        };
        let line = line(&Record::Alarm(a)).unwrap();
        assert_eq!(
            line,
            "ALARM pump3 k=203 onset=201 glr=1805.1 (threshold 27.6) isolated=[x0_jump] magnitude=[x0_jump 3.981, x1_jump 0.005] minmax=[x0_jump 1213.1/6.6] t=2.030"
        );
    }
}
