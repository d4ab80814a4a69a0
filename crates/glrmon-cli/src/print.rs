//! Human-readable one-line rendering of alarms, as `glrmon watch` prints them.

use std::fmt::Write as _;

use glrmon_wire::{Alarm, AlarmEnd, Diagnosis, ErrorRecord, Record};

/// One line for an alarm or alarm end; `None` for other records.
pub(crate) fn line(record: &Record) -> Option<String> {
    match record {
        Record::Alarm(a) => Some(alarm_line(a)),
        Record::AlarmEnd(e) => Some(end_line(e)),
        Record::Diagnosis(d) => Some(diagnosis_line(d)),
        Record::Error(e) => Some(error_line(e)),
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
        "ALARM {} k={} onset={} glr={:.1} (threshold {:.1}) isolated=[{}] magnitude=[{}] minmax=[{}]",
        a.channel,
        a.k,
        a.onset,
        a.glr,
        a.threshold,
        isolated.join(", "),
        mag,
        tests
    )
}

fn end_line(e: &AlarmEnd) -> String {
    format!(
        "END   {} k={} onset={} duration={} peak_glr={:.1}",
        e.channel, e.k, e.onset, e.duration, e.peak_glr
    )
}

fn diagnosis_line(d: &Diagnosis) -> String {
    let est: Vec<String> = d
        .estimate
        .iter()
        .map(|(k, v)| format!("{k} {v:.3}"))
        .collect();
    format!(
        "DIAG  {} k={} span={}..{} residual={} support=[{}] estimate=[{}] lambda={:.3e}",
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

fn error_line(e: &ErrorRecord) -> String {
    let k = e.k.map_or_else(|| "-".to_owned(), |k| k.to_string());
    format!(
        "ERROR {} k={k} {}: {}",
        e.channel,
        e.code.as_str(),
        e.message
    )
}
