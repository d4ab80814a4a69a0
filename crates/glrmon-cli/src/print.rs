//! Human-readable one-line rendering of alarms, as `glrmon watch` prints them.
//!
//! Every string of a record (channel, fault names, code text, message) may come from any
//! Zenoh peer, so each passes through [`Escaped`]: a line is always one line, and never
//! drives the terminal.

use std::fmt::Write as _;
use std::sync::OnceLock;

use glrmon_report::clock::{Zone, format_time, is_wall_clock};

use glrmon_wire::text::Escaped;
use glrmon_wire::{
    Alarm, AlarmEnd, Consistency, Diagnosis, ErrorRecord, IsolationResult, IsolationUpdate, Record,
};

/// One line for an alarm, isolation update, alarm end, diagnosis, error or consistency
/// change; `None` for other records (`stat`, and types this version does not know).
pub(crate) fn line(record: &Record) -> Option<String> {
    match record {
        Record::Alarm(a) => Some(alarm_line(a)),
        Record::Isolation(u) => Some(update_line(u)),
        Record::AlarmEnd(e) => Some(end_line(e)),
        Record::Diagnosis(d) => Some(diagnosis_line(d)),
        Record::Error(e) => Some(error_line(e)),
        Record::Consistency(c) => Some(consistency_line(c)),
        _ => None,
    }
}

/// Most faults an alarm line names in `magnitude=[…]` and `minmax=[…]`; `--json`
/// gives all of them.
const MAX_LISTED: usize = 5;

/// `isolated=[…] ambiguous=[…] magnitude=[…] minmax=[…]` of an alarm or an isolation
/// update (`ambiguous` only when some faults cannot yet be told apart once the onset
/// is free). A dictionary of more than [`MAX_LISTED`] faults lists the isolated and
/// ambiguous faults first, then
/// the others with the largest minmax statistics, up to [`MAX_LISTED`] in all, and
/// says how many it left out.
fn isolation_fields(isolation: &[IsolationResult], faults: &[String], magnitude: &[f64]) -> String {
    if isolation.iter().any(|t| t.excluded.is_some()) {
        return exclusion_fields(isolation);
    }
    let isolated: Vec<String> = isolation
        .iter()
        .filter(|i| i.isolated)
        .map(|i| Escaped(&i.fault).to_string())
        .collect();
    let ambiguous: Vec<String> = isolation
        .iter()
        .filter(|i| !i.ambiguous_with.is_empty())
        .map(|i| Escaped(&i.fault).to_string())
        .collect();
    let mut listed: Vec<usize> = (0..faults.len().min(magnitude.len())).collect();
    let mut tests: Vec<&IsolationResult> = isolation.iter().collect();
    let mut left_out = 0;
    if faults.len() > MAX_LISTED {
        let test_of = |name: &str| isolation.iter().find(|t| t.fault == name);
        let rank = |name: &str| {
            test_of(name).map_or((false, f64::NEG_INFINITY), |t| {
                (t.isolated || !t.ambiguous_with.is_empty(), t.minmax)
            })
        };
        listed.sort_by(|&a, &b| {
            let (ia, ma) = rank(&faults[a]);
            let (ib, mb) = rank(&faults[b]);
            ib.cmp(&ia).then(mb.total_cmp(&ma))
        });
        left_out = listed.len().saturating_sub(MAX_LISTED);
        listed.truncate(MAX_LISTED);
        tests = listed.iter().filter_map(|&i| test_of(&faults[i])).collect();
    }
    let mut mag = String::new();
    for (n, &i) in listed.iter().enumerate() {
        let sep = if n == 0 { "" } else { ", " };
        let _ = write!(
            mag,
            "{sep}{} {}",
            Escaped(&faults[i]),
            self::magnitude(magnitude[i])
        );
    }
    let mut minmax = String::new();
    for (n, t) in tests.iter().enumerate() {
        let sep = if n == 0 { "" } else { ", " };
        let _ = write!(
            minmax,
            "{sep}{} {:.1}/{:.1}",
            Escaped(&t.fault),
            t.minmax,
            t.threshold
        );
    }
    let more = if left_out > 0 {
        format!(" (+{left_out} more faults: --json lists all)")
    } else {
        String::new()
    };
    let ambiguous = if ambiguous.is_empty() {
        String::new()
    } else {
        format!(" ambiguous=[{}]", ambiguous.join(", "))
    };
    format!(
        "isolated=[{}]{ambiguous} magnitude=[{mag}] minmax=[{minmax}]{more}",
        isolated.join(", ")
    )
}

/// `isolated=[…] excluded=[…] r_FI=[…]` of a kind that isolates by exclusion (the
/// kernel method): each candidate's isolation residual over its threshold.
fn exclusion_fields(isolation: &[IsolationResult]) -> String {
    let names = |keep: fn(&IsolationResult) -> bool| {
        isolation
            .iter()
            .filter(|t| keep(t))
            .map(|t| Escaped(&t.fault).to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let isolated = names(|t| t.isolated);
    let excluded = names(|t| t.excluded == Some(true));
    let mut tests = String::new();
    for (n, t) in isolation.iter().take(MAX_LISTED).enumerate() {
        let sep = if n == 0 { "" } else { ", " };
        let _ = write!(
            tests,
            "{sep}{} {}/{}",
            Escaped(&t.fault),
            self::magnitude(t.minmax),
            self::magnitude(t.threshold)
        );
    }
    let more = if isolation.len() > MAX_LISTED {
        format!(
            " (+{} more: --json lists all)",
            isolation.len() - MAX_LISTED
        )
    } else {
        String::new()
    };
    format!("isolated=[{isolated}] excluded=[{excluded}] r_FI=[{tests}]{more}")
}

fn alarm_line(a: &Alarm) -> String {
    let update = a
        .update_k
        .map_or_else(String::new, |u| format!(" update_k={u}"));
    format!(
        "ALARM {} k={} onset={} glr={:.1} (threshold {:.1}) {}{update}{}",
        Escaped(&a.channel),
        a.k,
        a.onset,
        a.glr,
        a.threshold,
        isolation_fields(&a.isolation, &a.faults, &a.magnitude),
        time(a.t)
    )
}

fn update_line(u: &IsolationUpdate) -> String {
    format!(
        "ISOL  {} k={} alarm_k={} onset={} glr={:.1} (threshold {:.1}) {}{}",
        Escaped(&u.channel),
        u.k,
        u.alarm_k,
        u.onset,
        u.glr,
        u.threshold,
        isolation_fields(&u.isolation, &u.faults, &u.magnitude),
        time(u.t)
    )
}

fn end_line(e: &AlarmEnd) -> String {
    format!(
        "END   {} k={} onset={} duration={} peak_glr={:.1}{}",
        Escaped(&e.channel),
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
        .map(|(k, v)| format!("{} {v:.3}", Escaped(k)))
        .collect();
    let support: Vec<String> = d.support.iter().map(|f| Escaped(f).to_string()).collect();
    // An empty support is the diagnosis's "no fault" (the χ² test of θ = 0).
    let none = if d.support.is_empty() {
        " (no fault)"
    } else {
        ""
    };
    format!(
        "DIAG  {} k={} span={}..{} residual={} support=[{}]{none} estimate=[{}] lambda={:.3e}",
        Escaped(&d.channel),
        d.k,
        d.from,
        d.to,
        Escaped(&d.residual),
        support.join(", "),
        est.join(", "),
        d.lambda
    )
}

fn consistency_line(c: &Consistency) -> String {
    format!(
        "MODEL {} k={} consistency={} nis_mean={:.3} band=[{:.3}, {:.3}] expected={} window={}{}",
        Escaped(&c.channel),
        c.k,
        Escaped(&c.state),
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
        Escaped(&e.channel),
        e.code.as_str(),
        Escaped(&e.message)
    )
}

/// The zone of the wall-clock times in the lines (`--local-time`), set once by `main`.
static ZONE: OnceLock<Zone> = OnceLock::new();

/// Shows wall-clock times in `zone` from now on (UTC until called).
pub(crate) fn set_zone(zone: Zone) {
    let _ = ZONE.set(zone);
}

/// ` t=…` when the record carries the sample's time: ISO-8601 for a wall-clock time,
/// seconds otherwise ([`glrmon_report::clock`]).
fn time(t: Option<f64>) -> String {
    let zone = ZONE.get().copied().unwrap_or_default();
    match t {
        Some(t) if is_wall_clock(t) => format!(" t={}", format_time(t, zone)),
        Some(t) => format!(" t={t:.3}"),
        None => String::new(),
    }
}

/// A fault magnitude with 4 significant digits: fixed-point from 10⁻³ to 10⁵, else in
/// scientific notation (a leak of 1e-4 per unit of flow must not print as 0.0001 or
/// 0.0000).
pub(crate) fn magnitude(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if (1e-3..1e5).contains(&a) {
        // Digits after the point for 4 significant ones: 3 − ⌊log₁₀|v|⌋, in 0…6.
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn exclusion_tests_print_residuals_over_thresholds() {
        use glrmon_wire::IsolationResult;
        let test = |fault: &str, r: f64, s: f64, excluded: bool, isolated: bool| IsolationResult {
            excluded: Some(excluded),
            fault: fault.into(),
            minmax: r,
            sensitivity: r,
            threshold: s,
            isolated,
            ambiguous_with: Vec::new(),
        };
        let tests = [
            test("phi1", 0.7697, 0.7689, true, false),
            test("phi2", 1.223e-4, 2.981, false, true),
        ];
        assert_eq!(
            super::isolation_fields(&tests, &["phi1".into(), "phi2".into()], &[0.0, 0.0]),
            "isolated=[phi2] excluded=[phi1] r_FI=[phi1 0.7697/0.7689, phi2 1.223e-4/2.981]"
        );
    }

    #[test]
    fn magnitudes_keep_four_significant_digits() {
        assert_eq!(super::magnitude(1.0), "1.000");
        assert_eq!(super::magnitude(-0.98765), "-0.9877");
        assert_eq!(super::magnitude(0.0012345), "0.001234");
        assert_eq!(super::magnitude(1.0234e-4), "1.023e-4");
        assert_eq!(super::magnitude(-43980.0), "-43980");
        assert_eq!(super::magnitude(2.5e7), "2.500e7");
        assert_eq!(super::magnitude(0.0), "0");
    }

    use super::*;

    /// Faults that cannot yet be told apart once the onset is free are printed as
    /// ambiguous, none as isolated.
    #[test]
    fn alarm_line_prints_the_ambiguous_faults() {
        let test = |fault: &str, rival: &str, minmax| IsolationResult {
            excluded: None,
            fault: fault.into(),
            minmax,
            sensitivity: minmax,
            threshold: 6.6,
            isolated: false,
            ambiguous_with: vec![rival.into()],
        };
        let a = Alarm {
            channel: "unstable".into(),
            k: 201,
            t: None,
            glr: 95.0,
            threshold: 15.4,
            onset: 200,
            magnitude: vec![0.1, 1.2],
            isolation: vec![
                test("x0_jump", "x1_jump", 0.4),
                test("x1_jump", "x0_jump", 92.0),
            ],
            faults: vec!["x0_jump".into(), "x1_jump".into()],
            update_k: Some(203),
        };
        assert_eq!(
            line(&Record::Alarm(a)).unwrap(),
            "ALARM unstable k=201 onset=200 glr=95.0 (threshold 15.4) isolated=[] ambiguous=[x0_jump, x1_jump] magnitude=[x0_jump 0.1000, x1_jump 1.200] minmax=[x0_jump 0.4/6.6, x1_jump 92.0/6.6] update_k=203"
        );
    }

    #[test]
    fn alarm_line_names_channel_time_onset_isolated_fault_and_magnitude() {
        let a = Alarm {
            channel: "pump3".into(),
            k: 201,
            t: Some(2.01),
            glr: 1805.1,
            threshold: 27.6,
            onset: 201,
            magnitude: vec![3.981, 0.005],
            isolation: vec![IsolationResult {
                excluded: None,
                fault: "x0_jump".into(),
                minmax: 1213.1,
                sensitivity: 1300.0,
                threshold: 6.6,
                isolated: true,
                ambiguous_with: Vec::new(),
            }],
            faults: vec!["x0_jump".into(), "x1_jump".into()],
            update_k: Some(203),
        };
        let text = line(&Record::Alarm(a.clone())).unwrap();
        assert_eq!(
            text,
            "ALARM pump3 k=201 onset=201 glr=1805.1 (threshold 27.6) isolated=[x0_jump] magnitude=[x0_jump 3.981, x1_jump 0.005000] minmax=[x0_jump 1213.1/6.6] update_k=203 t=2.010"
        );
        let text = line(&Record::Alarm(Alarm {
            update_k: None,
            ..a
        }))
        .unwrap();
        assert!(
            text.ends_with("minmax=[x0_jump 1213.1/6.6] t=2.010"),
            "{text}"
        );
    }

    #[test]
    fn isolation_line_names_its_alarm_and_sample() {
        let u = IsolationUpdate {
            channel: "pump3".into(),
            k: 203,
            t: None,
            alarm_k: 201,
            glr: 25.0,
            threshold: 27.6,
            onset: 200,
            magnitude: vec![3.5],
            isolation: vec![IsolationResult {
                excluded: None,
                fault: "x0_jump".into(),
                minmax: 0.5,
                sensitivity: 1.5,
                threshold: 6.6,
                isolated: false,
                ambiguous_with: Vec::new(),
            }],
            faults: vec!["x0_jump".into()],
        };
        assert_eq!(
            line(&Record::Isolation(u)).unwrap(),
            "ISOL  pump3 k=203 alarm_k=201 onset=200 glr=25.0 (threshold 27.6) isolated=[] magnitude=[x0_jump 3.500] minmax=[x0_jump 0.5/6.6]"
        );
    }

    #[test]
    fn large_dictionaries_list_isolated_then_strongest_faults_only() {
        let faults: Vec<String> = (0..31).map(|i| format!("y{i}_bias")).collect();
        let isolation: Vec<IsolationResult> = (0..31)
            .map(|i| IsolationResult {
                excluded: None,
                fault: format!("y{i}_bias"),
                minmax: f64::from(i),
                sensitivity: 100.0,
                threshold: 6.6,
                isolated: i == 3,
                ambiguous_with: Vec::new(),
            })
            .collect();
        let a = Alarm {
            channel: "plant".into(),
            k: 900,
            t: Some(1_796_191_746.296),
            glr: 300.0,
            threshold: 40.0,
            onset: 880,
            magnitude: (0..31).map(f64::from).collect(),
            isolation,
            faults,
            update_k: None,
        };
        let text = line(&Record::Alarm(a)).unwrap();
        assert_eq!(
            text,
            "ALARM plant k=900 onset=880 glr=300.0 (threshold 40.0) isolated=[y3_bias] \
             magnitude=[y3_bias 3.000, y30_bias 30.00, y29_bias 29.00, y28_bias 28.00, y27_bias 27.00] \
             minmax=[y3_bias 3.0/6.6, y30_bias 30.0/6.6, y29_bias 29.0/6.6, y28_bias 28.0/6.6, y27_bias 27.0/6.6] \
             (+26 more faults: --json lists all) t=2026-12-02T06:09:06.296Z"
        );
        assert!(text.len() < 400, "{} characters", text.len());
    }

    /// A forged record from any peer: its channel, fault names and message reach the
    /// line only as visible escapes, so the line stays one line and sends nothing to the
    /// terminal.
    #[test]
    fn hostile_strings_of_a_record_are_escaped() {
        let a = Alarm {
            channel: "p\u{1b}]0;pwned\u{7}".into(),
            k: 1,
            t: None,
            glr: 30.0,
            threshold: 20.0,
            onset: 1,
            magnitude: vec![1.0],
            isolation: Vec::new(),
            faults: vec!["leak\n2026-12-03T10:00:00Z  INFO ALARM pump3".into()],
            update_k: None,
        };
        let text = line(&Record::Alarm(a)).unwrap();
        assert_eq!(
            text,
            r"ALARM p\x1b]0;pwned\x07 k=1 onset=1 glr=30.0 (threshold 20.0) isolated=[] magnitude=[leak\n2026-12-03T10:00:00Z  INFO ALARM pump3 1.000] minmax=[]"
        );
        let e = ErrorRecord {
            channel: "\u{202e}pmup".into(),
            k: None,
            code: glrmon_wire::ErrorCode::UnknownField,
            message: "field \u{1b}[2J\r is not a field".into(),
            stage: glrmon_wire::Stage::Receiving,
        };
        assert_eq!(
            line(&Record::Error(e)).unwrap(),
            r"ERROR \u{202e}pmup k=- unknown_field: field \x1b[2J\r is not a field"
        );
    }
}
