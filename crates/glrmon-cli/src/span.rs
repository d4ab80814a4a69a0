//! Spans of data given on the command line as a number of samples or as a time
//! (`4320`, `1d`, `8h`, `90min`), and times printed in the unit that reads best.

use std::fmt;

/// A span as the user wrote it: a number of samples, or a time that the channel's
/// period turns into samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Span {
    /// A number of samples.
    Samples(f64),
    /// A time in seconds, and how it was written (`1d`).
    Time(f64),
}

/// Units of time a span may carry, with their length in seconds.
const UNITS: [(&str, f64); 12] = [
    ("s", 1.0),
    ("sec", 1.0),
    ("min", 60.0),
    ("m", 60.0),
    ("h", 3600.0),
    ("hour", 3600.0),
    ("hours", 3600.0),
    ("d", 86_400.0),
    ("day", 86_400.0),
    ("days", 86_400.0),
    ("w", 604_800.0),
    ("week", 604_800.0),
];

/// `clap` value parser: `4320` (samples), `4320samples`, or a time `1d`, `24h`, `90min`,
/// `3600s`, `1w`; finite and positive.
pub(crate) fn parse(text: &str) -> Result<Span, String> {
    let t = text.trim();
    // The longest prefix that is a number (so that `1e4` stays a number and `1d` splits).
    let (value, unit) = t
        .char_indices()
        .map(|(i, _)| i)
        .chain(std::iter::once(t.len()))
        .rev()
        .find_map(|i| Some((t[..i].trim().parse::<f64>().ok()?, &t[i..])))
        .ok_or_else(|| {
            format!("\"{text}\" is not a number of samples or a time such as 1d, 8h, 90min, 3600s")
        })?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("\"{text}\" must be finite and positive"));
    }
    match unit.trim() {
        "" | "samples" | "sample" => Ok(Span::Samples(value)),
        u => UNITS
            .iter()
            .find(|(name, _)| *name == u)
            .map(|(_, seconds)| Span::Time(value * seconds))
            .ok_or_else(|| {
                format!("\"{text}\": unknown unit \"{u}\" (s, min, h, d, w, or none for samples)")
            }),
    }
}

impl Span {
    /// The span in samples, given the channel's period in seconds (`None` when the
    /// channel has none: a time cannot be turned into samples then).
    pub(crate) fn samples(self, period: Option<f64>) -> Option<f64> {
        match self {
            Span::Samples(n) => Some(n),
            Span::Time(s) => period.filter(|p| *p > 0.0).map(|p| s / p),
        }
    }
}

impl fmt::Display for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Span::Samples(n) => write!(f, "{n} samples"),
            Span::Time(s) => f.write_str(&duration(*s)),
        }
    }
}

/// `clap` value parser of a time (`1h`, `30min`, `90s`, `2d`): seconds, finite and
/// positive.
pub(crate) fn parse_time(text: &str) -> Result<f64, String> {
    match parse(text)? {
        Span::Time(seconds) => Ok(seconds),
        Span::Samples(_) => Err(format!(
            "\"{text}\" has no unit: a time such as 1h, 30min, 90s, 2d"
        )),
    }
}

/// A duration in the unit that reads best: seconds below two minutes, minutes below
/// two hours, hours below two days, days above.
pub(crate) fn duration(seconds: f64) -> String {
    if seconds < 120.0 {
        format!("{} s", crate::print::magnitude(seconds))
    } else if seconds < 7200.0 {
        format!("{:.1} min", seconds / 60.0)
    } else if seconds < 172_800.0 {
        format!("{:.2} h", seconds / 3600.0)
    } else {
        format!("{:.2} d", seconds / 86_400.0)
    }
}

/// A number of samples, followed by its time in parentheses when the period is known:
/// `4320 samples (1.00 d)`.
pub(crate) fn samples_and_time(samples: f64, period: Option<f64>) -> String {
    match period.filter(|p| *p > 0.0) {
        Some(p) if samples.is_finite() => {
            format!("{samples:.0} samples ({})", duration(samples * p))
        }
        _ => format!("{samples:.0} samples"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_parse_as_samples_or_times() {
        assert_eq!(parse("4320"), Ok(Span::Samples(4320.0)));
        assert_eq!(parse("1e4"), Ok(Span::Samples(10_000.0)));
        assert_eq!(parse("500 samples"), Ok(Span::Samples(500.0)));
        assert_eq!(parse("1d"), Ok(Span::Time(86_400.0)));
        assert_eq!(parse("24h"), Ok(Span::Time(86_400.0)));
        assert_eq!(parse("90min"), Ok(Span::Time(5400.0)));
        assert_eq!(parse("0.5 w"), Ok(Span::Time(302_400.0)));
        assert!(
            parse("1 fortnight")
                .unwrap_err()
                .contains("unknown unit \"fortnight\"")
        );
        assert!(parse("-1d").unwrap_err().contains("positive"));
        assert!(parse("1e").unwrap_err().contains("unknown unit \"e\""));
        assert!(parse("d").unwrap_err().contains("not a number"));
        assert!(parse("inf").is_err());
        assert_eq!(Span::Time(86_400.0).samples(Some(20.0)), Some(4320.0));
        assert_eq!(Span::Time(86_400.0).samples(None), None);
        assert_eq!(Span::Samples(10.0).samples(None), Some(10.0));
    }

    #[test]
    fn durations_read_in_their_best_unit() {
        assert_eq!(duration(40.0), "40.00 s");
        assert_eq!(duration(600.0), "10.0 min");
        assert_eq!(duration(86_400.0), "24.00 h");
        assert_eq!(duration(5.0 * 86_400.0), "5.00 d");
        assert_eq!(
            samples_and_time(4320.0, Some(20.0)),
            "4320 samples (24.00 h)"
        );
        assert_eq!(samples_and_time(4320.0, None), "4320 samples");
    }
}
