//! Editing a configuration's text in place: what `glrmon calibrate --write` does to the
//! user's file. The edit keeps everything it does not change (comments, key order,
//! blank lines, quoting), and the result is validated before it is returned.
//!
//! ```
//! use glrmon_core::calibration::{Calibration, Target};
//!
//! let text = r#"# the tank
//! [[channels]]
//! name = "tank"
//! model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
//! faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
//!
//! [channels.glr]
//! threshold = 9.0 # by hand
//! "#;
//! let c = Calibration {
//!     threshold: 12.5,
//!     target: Target::Mtbfa(10_000.0),
//!     samples: 100_000,
//!     episodes: 10,
//!     exceedances: 25,
//!     expected: 10.0,
//!     rate_interval: (5_000.0, 20_000.0),
//!     threshold_interval: (12.0, 13.0),
//! };
//! let edited =
//!     glrmon_spec::edit::set_calibrated(text, "tank", &c, &[("level_bias", 7.5)], "a.csv")
//!         .unwrap();
//! assert!(edited.starts_with("# the tank\n"));
//! assert!(!edited.contains("by hand"));
//! let cfg = glrmon_spec::parse(&edited).unwrap();
//! assert_eq!(cfg.channels[0].alarm.threshold, 12.5);
//! ```

use glrmon_core::calibration::{Calibration, Target};

use crate::SpecErrors;

/// Why a configuration's text could not be edited. None of these is the machine's
/// fault: the text, or the channel asked for, is.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EditError {
    /// The text is not TOML (the parser's message).
    #[error("{0}")]
    Toml(String),
    /// The text has no `[[channels]]` array of tables.
    #[error("no [[channels]]")]
    NoChannels,
    /// No channel of the text has this name.
    #[error("no channel \"{0}\"")]
    NoChannel(String),
    /// The channel's `glr` is something other than a table.
    #[error("channels.glr is not a table")]
    GlrNotTable,
    /// The edited text would not be a valid configuration.
    #[error("the updated configuration would be invalid:\n{0}")]
    Invalid(SpecErrors),
}

/// Sets `[channels.glr.calibrated]` of `channel` in the configuration `text` to the
/// calibration `c` (with `source`, a description of the data it was found on, and the
/// isolation thresholds `isolation` as `(test, threshold)` pairs, left out when empty)
/// and removes the other ways of setting the detection threshold (`threshold`,
/// `false_alarm`, `threshold_mode`). Returns the edited text: everything else of
/// `text` (comments, order, layout) is kept.
///
/// # Errors
/// [`EditError::Toml`] when `text` is not TOML, [`EditError::NoChannels`] or
/// [`EditError::NoChannel`] when it has no channel named `channel`,
/// [`EditError::GlrNotTable`] when that channel's `glr` is not a table, and
/// [`EditError::Invalid`] when the edited text does not [`parse`](crate::parse).
pub fn set_calibrated(
    text: &str,
    channel: &str,
    c: &Calibration,
    isolation: &[(&str, f64)],
    source: &str,
) -> Result<String, EditError> {
    let mut doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| EditError::Toml(e.to_string()))?;
    let channels = doc
        .get_mut("channels")
        .and_then(toml_edit::Item::as_array_of_tables_mut)
        .ok_or(EditError::NoChannels)?;
    let table = channels
        .iter_mut()
        .find(|t| t.get("name").and_then(|v| v.as_str()) == Some(channel))
        .ok_or_else(|| EditError::NoChannel(channel.to_owned()))?;
    if table.get("glr").is_none() {
        table.insert("glr", toml_edit::table());
    }
    let glr = table
        .get_mut("glr")
        .and_then(toml_edit::Item::as_table_mut)
        .ok_or(EditError::GlrNotTable)?;
    for key in ["threshold", "false_alarm", "threshold_mode"] {
        glr.remove(key);
    }
    let mut cal = toml_edit::Table::new();
    let count = |n: u64| toml_edit::value(i64::try_from(n).unwrap_or(i64::MAX));
    cal.insert("threshold", toml_edit::value(c.threshold));
    match c.target {
        Target::Mtbfa(m) => {
            cal.insert("mtbfa", toml_edit::value(m));
        }
        Target::SampleFar(f) => {
            cal.insert("sample_far", toml_edit::value(f));
        }
    }
    cal.insert("samples", count(c.samples));
    cal.insert("episodes", count(c.episodes));
    if matches!(c.target, Target::SampleFar(_)) {
        cal.insert("exceedances", count(c.exceedances));
    }
    let mut interval = toml_edit::Array::new();
    interval.push(c.threshold_interval.0);
    interval.push(c.threshold_interval.1);
    cal.insert("interval", toml_edit::value(interval));
    cal.insert("source", toml_edit::value(source));
    let mut iso = toml_edit::InlineTable::new();
    for &(test, threshold) in isolation {
        iso.insert(test, threshold.into());
    }
    if !iso.is_empty() {
        cal.insert("isolation", toml_edit::value(iso));
    }
    glr.insert("calibrated", toml_edit::Item::Table(cal));
    let updated = doc.to_string();
    crate::parse(&updated).map_err(EditError::Invalid)?;
    Ok(updated)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"# A tank, by hand.
[[channels]]
name = "tank"   # the only one
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]

[channels.glr]
window = 20
# set by hand until calibrated
threshold = 9.0
"#;

    fn calibration() -> Calibration {
        Calibration {
            threshold: 12.5,
            target: Target::Mtbfa(10_000.0),
            samples: 100_000,
            episodes: 10,
            exceedances: 25,
            expected: 10.0,
            rate_interval: (5_000.0, 20_000.0),
            threshold_interval: (12.0, 13.0),
        }
    }

    #[test]
    fn the_threshold_is_replaced_and_comments_and_layout_are_kept() {
        let edited = set_calibrated(
            TEXT,
            "tank",
            &calibration(),
            &[("level_bias", 7.5)],
            "a.csv",
        )
        .unwrap();
        assert_eq!(
            edited,
            r#"# A tank, by hand.
[[channels]]
name = "tank"   # the only one
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]

[channels.glr]
window = 20

[channels.glr.calibrated]
threshold = 12.5
mtbfa = 10000.0
samples = 100000
episodes = 10
interval = [12.0, 13.0]
source = "a.csv"
isolation = { level_bias = 7.5 }
"#
        );
        let cfg = crate::parse(&edited).unwrap();
        assert_eq!(cfg.channels[0].alarm.threshold, 12.5);
        assert_eq!(
            cfg.channels[0].isolation_thresholds,
            [("level_bias".to_owned(), 7.5)]
        );
    }

    /// Issue 20: a per-sample target is written as `sample_far` with the exceedances,
    /// and reads back as such; a file with both targets, or neither, is refused.
    #[test]
    fn issue_20_a_sample_far_target_is_recorded_and_read_back() {
        let c = Calibration {
            target: Target::SampleFar(0.01),
            exceedances: 40,
            ..calibration()
        };
        let edited = set_calibrated(TEXT, "tank", &c, &[], "a.csv, b.csv").unwrap();
        assert!(
            edited.contains(
                "threshold = 12.5\nsample_far = 0.01\nsamples = 100000\nepisodes = 10\n\
                 exceedances = 40\n"
            ),
            "{edited}"
        );
        assert!(!edited.contains("mtbfa"), "{edited}");
        let cfg = crate::parse(&edited).unwrap();
        assert!(matches!(
            cfg.channels[0].threshold_source,
            crate::ThresholdSource::Calibrated {
                target: Target::SampleFar(f),
                exceedances: Some(40),
                ..
            } if f == 0.01
        ));
        let both = edited.replace("sample_far = 0.01", "sample_far = 0.01\nmtbfa = 100.0");
        let e = crate::parse(&both).unwrap_err().to_string();
        assert!(
            e.contains("glr.calibrated") && e.contains("exactly one target") && e.contains("both"),
            "{e}"
        );
        let neither = edited.replace("sample_far = 0.01\n", "");
        let e = crate::parse(&neither).unwrap_err().to_string();
        assert!(e.contains("neither"), "{e}");
    }

    #[test]
    fn an_unknown_channel_and_text_that_is_not_toml_are_refused() {
        let c = calibration();
        let e = set_calibrated(TEXT, "pump", &c, &[], "a.csv").unwrap_err();
        assert!(
            matches!(&e, EditError::NoChannel(n) if n == "pump"),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "no channel \"pump\"");
        let e = set_calibrated("[[channels]\n", "tank", &c, &[], "a.csv").unwrap_err();
        assert!(matches!(e, EditError::Toml(_)), "{e:?}");
        let e = set_calibrated("x = 1\n", "tank", &c, &[], "a.csv").unwrap_err();
        assert!(matches!(e, EditError::NoChannels), "{e:?}");
    }

    #[test]
    fn an_edit_that_would_make_the_configuration_invalid_is_refused() {
        let c = Calibration {
            threshold: -1.0,
            ..calibration()
        };
        let e = set_calibrated(TEXT, "tank", &c, &[], "a.csv").unwrap_err();
        assert!(matches!(e, EditError::Invalid(_)), "{e:?}");
    }
}
