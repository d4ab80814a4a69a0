//! Editing a configuration's text in place: what `glrmon calibrate --write` does to the
//! user's file. The edit keeps everything it does not change (comments, key order,
//! blank lines, quoting), and the result is validated before it is returned.
//!
//! ```
//! use glrmon_core::threshold::calibration::{Calibration, Target};
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

use glrmon_core::threshold::calibration::{Calibration, Target};
use nalgebra::DMatrix;

use crate::{DetectorKind, SpecErrors};

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
    /// The channel's `model` is something other than a table (inline or not).
    #[error("channels.model is not a table")]
    ModelNotTable,
    /// A matrix to write has a value that is not finite (named).
    #[error("{0} has a value that is not finite")]
    NotFinite(&'static str),
    /// An isolation threshold to write is not finite and positive: a test the data
    /// could not calibrate, to be left out rather than written.
    #[error("the isolation threshold of \"{test}\" is {value}, not finite and positive")]
    Isolation {
        /// The test.
        test: String,
        /// The threshold.
        value: f64,
    },
    /// The edited text would not be a valid configuration.
    #[error("the updated configuration would be invalid:\n{0}")]
    Invalid(SpecErrors),
}

/// Sets `[channels.glr.calibrated]` of `channel` in the configuration `text` to the
/// calibration `c` (with `source`, a description of the data it was found on, and the
/// isolation thresholds `isolation` as `(test, threshold)` pairs, left out when empty)
/// and removes the other ways of setting the detection threshold (`threshold`,
/// `false_alarm`, `threshold_mode`). The table replaces any earlier one whole: a test
/// missing from `isolation` (one that could not be calibrated) falls back to its χ²
/// threshold. Returns the edited text: everything else of `text` (comments, order,
/// layout) is kept.
///
/// # Errors
/// [`EditError::Toml`] when `text` is not TOML, [`EditError::NoChannels`] or
/// [`EditError::NoChannel`] when it has no channel named `channel`,
/// [`EditError::GlrNotTable`] when that channel's `glr` is not a table,
/// [`EditError::Isolation`] for an isolation threshold that is not finite and positive
/// (naming its test), and [`EditError::Invalid`] when the edited text does not
/// [`parse`](crate::parse).
pub fn set_calibrated(
    text: &str,
    channel: &str,
    c: &Calibration,
    isolation: &[(&str, f64)],
    source: &str,
) -> Result<String, EditError> {
    if let Some(&(test, value)) = isolation.iter().find(|(_, t)| !(t.is_finite() && *t > 0.0)) {
        return Err(EditError::Isolation {
            test: test.to_owned(),
            value,
        });
    }
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

/// Sets `glr.detector` of `channel` in the configuration `text` to `kind`, for
/// comparing kinds on the same channel (`glrmon evaluate --detector`): every kind is
/// then set to the same false-alarm probability per sample, `false_alarm` if given,
/// else the configured one (10⁻⁴ when none is given), since a threshold set for one kind's
/// statistic (`threshold`, `[channels.glr.calibrated]`) means nothing for another's;
/// `[channels.parity]`, `[channels.observer]`, `[channels.rls]` and `[channels.cusum]`
/// are removed for kinds they do not apply to; `[channels.kernel]` stays, since it
/// describes the plant for every kind (the `kernel` kind, whose threshold is the bound
/// 1, gets no `false_alarm` and drops `[[channels.faults]]`), and a residual kind's `evaluation` is
/// its χ² test (a windowed energy has no law to set a threshold from); the CUSUM's
/// magnitudes are
/// `cusum_magnitudes` where the channel has no `[channels.cusum]`. Returns the edited
/// text.
///
/// # Errors
/// As [`set_calibrated`]: [`EditError::Toml`], [`EditError::NoChannels`],
/// [`EditError::NoChannel`], [`EditError::GlrNotTable`], and [`EditError::Invalid`]
/// when the channel cannot run `kind` (e.g. a parity space that is empty).
pub fn set_detector(
    text: &str,
    channel: &str,
    kind: DetectorKind,
    false_alarm: Option<f64>,
    cusum_magnitudes: Option<&[f64]>,
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
    if kind != DetectorKind::Parity {
        table.remove("parity");
    }
    // Every kind at the same false-alarm probability: the residual kinds by their χ²
    // law (a windowed energy has none, and its threshold is removed below).
    for key in ["parity", "observer", "rls"] {
        if let Some(t) = table
            .get_mut(key)
            .and_then(toml_edit::Item::as_table_like_mut)
        {
            t.remove("evaluation");
            t.remove("energy_window");
        }
    }
    if kind != DetectorKind::Rls {
        table.remove("rls");
    }
    if kind != DetectorKind::Cusum {
        table.remove("cusum");
    } else if let Some(m) = cusum_magnitudes
        && !table.contains_key("cusum")
    {
        let mut cusum = toml_edit::Table::new();
        cusum.insert(
            "magnitudes",
            toml_edit::value(m.iter().copied().collect::<toml_edit::Array>()),
        );
        table.insert("cusum", toml_edit::Item::Table(cusum));
    }
    // `[channels.kernel]` describes the plant for every kind (its fault channels give
    // the others' dictionary); the kernel kind takes its faults from it alone.
    if kind == DetectorKind::Kernel && table.contains_key("kernel") {
        table.remove("faults");
    }
    if !matches!(kind, DetectorKind::Fdf | DetectorKind::Uio) {
        table.remove("observer");
    } else if kind == DetectorKind::Uio
        && let Some(o) = table
            .get_mut("observer")
            .and_then(toml_edit::Item::as_table_like_mut)
    {
        // The UIO designs its own gain.
        o.remove("L");
        o.remove("V");
    }
    if kind.runs_kalman_filter() {
        // Sparse diagnosis needs the Kalman filter; other kinds refuse it.
    } else if let Some(d) = table
        .get_mut("diagnosis")
        .and_then(toml_edit::Item::as_table_like_mut)
    {
        d.remove("enabled");
    }
    if table.get("glr").is_none() {
        table.insert("glr", toml_edit::table());
    }
    let glr = table
        .get_mut("glr")
        .and_then(toml_edit::Item::as_table_like_mut)
        .ok_or(EditError::GlrNotTable)?;
    let explicit = glr.contains_key("threshold") || glr.contains_key("calibrated");
    for key in ["threshold", "calibrated", "threshold_mode"] {
        glr.remove(key);
    }
    if kind == DetectorKind::Kernel {
        // Its threshold is the bound 1, not a false-alarm probability.
        glr.remove("false_alarm");
    } else if let Some(p) = false_alarm {
        glr.insert("false_alarm", toml_edit::value(p));
    } else if explicit && !glr.contains_key("false_alarm") {
        glr.insert("false_alarm", toml_edit::value(1e-4));
    }
    glr.insert("detector", toml_edit::value(kind.name()));
    let updated = doc.to_string();
    crate::parse(&updated).map_err(EditError::Invalid)?;
    Ok(updated)
}

/// The start of the comment line [`set_noise`] leaves before the noise covariances
/// (a later [`set_noise`] replaces it).
pub const NOISE_NOTE: &str = "# Noise covariances Q, R";

/// Sets `model.Q` and `model.R` of `channel` in the configuration `text` to `q` and
/// `r` (made exactly symmetric: each pair of off-diagonal entries is replaced by its
/// mean), and `model.S` to `s`, or removes `model.S` when `s` is `None`. Matrices are
/// written as arrays of row arrays with Rust's shortest round-trip (`{:?}`) float
/// formatting. A comment line starting with [`NOISE_NOTE`] and naming `source` (where
/// the values came from) is left before `Q` in a `[channels.model]` table, or before
/// `model` when it is an inline table; an earlier such line is replaced. Everything
/// else of `text` (comments, order, layout, the other matrices) is kept.
///
/// ```
/// use nalgebra::DMatrix;
///
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let text = "[[channels]]\nname = \"tank\"\n\
///             model = { F = [[0.9]], H = [[1.0]], Q = 1.0, R = 1.0 } # by hand\n\
///             faults = [{ name = \"bias\", kind = \"sensor_bias\", output = 0 }]\n";
/// let edited = glrmon_spec::edit::set_noise(
///     text, "tank", &one(0.01), &one(0.04), None, "a.csv",
/// )
/// .unwrap();
/// assert!(edited.contains("Q = [[0.01]], R = [[0.04]] } # by hand"), "{edited}");
/// let cfg = glrmon_spec::parse(&edited).unwrap();
/// assert_eq!(cfg.channels[0].model.matrices()[4].base()[(0, 0)], 0.01);
/// ```
///
/// # Errors
/// [`EditError::Toml`] when `text` is not TOML, [`EditError::NoChannels`] or
/// [`EditError::NoChannel`] when it has no channel named `channel`,
/// [`EditError::ModelNotTable`] when that channel's `model` is missing or not a table,
/// [`EditError::NotFinite`] when a matrix has a value that is not finite, and
/// [`EditError::Invalid`] when the edited text does not [`parse`](crate::parse) (e.g.
/// a matrix of the wrong size, or an R that is not positive definite).
pub fn set_noise(
    text: &str,
    channel: &str,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
    source: &str,
) -> Result<String, EditError> {
    for (name, m) in [("Q", Some(q)), ("R", Some(r)), ("S", s)] {
        if m.is_some_and(|m| m.iter().any(|v| !v.is_finite())) {
            return Err(EditError::NotFinite(name));
        }
    }
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
    let note = format!(
        "{NOISE_NOTE}{} from {}",
        if s.is_some() { ", S" } else { "" },
        source.replace(['\n', '\r'], " ")
    );
    // In an inline table, the space before `}` is the last value's suffix: it stays
    // last when S is added or removed.
    let (inline, tail) = match table.get("model") {
        Some(toml_edit::Item::Table(_)) => (false, String::new()),
        Some(toml_edit::Item::Value(toml_edit::Value::InlineTable(t))) => (
            true,
            t.iter()
                .last()
                .and_then(|(_, v)| v.decor().suffix()?.as_str().map(str::to_owned))
                .filter(|s| s.trim().is_empty())
                .unwrap_or_default(),
        ),
        _ => return Err(EditError::ModelNotTable),
    };
    {
        let model = table
            .get_mut("model")
            .and_then(toml_edit::Item::as_table_like_mut)
            .ok_or(EditError::ModelNotTable)?;
        // A continuous-time model's Qc gives way to the per-sample Q estimated from
        // the samples (a model with `A` takes either).
        model.remove("Qc");
        put(model, "Q", &symmetric(q));
        put(model, "R", &symmetric(r));
        match s {
            Some(s) => put(model, "S", s),
            None => {
                model.remove("S");
            }
        }
        if !inline && let Some(mut key) = model.key_mut("Q") {
            add_note(key.leaf_decor_mut(), &note);
        }
    }
    if inline && let Some(mut key) = table.key_mut("model") {
        add_note(key.leaf_decor_mut(), &note);
    }
    if let Some(model) = table
        .get_mut("model")
        .and_then(toml_edit::Item::as_value_mut)
        .and_then(toml_edit::Value::as_inline_table_mut)
    {
        respace(model, &tail);
    }
    let updated = doc.to_string();
    crate::parse(&updated).map_err(EditError::Invalid)?;
    Ok(updated)
}

/// Gives the last value of an inline table the suffix `tail` and the others none
/// (when theirs is only whitespace).
fn respace(table: &mut toml_edit::InlineTable, tail: &str) {
    let count = table.len();
    for (i, (_, value)) in table.iter_mut().enumerate() {
        let blank = value
            .decor()
            .suffix()
            .and_then(toml_edit::RawString::as_str)
            .is_none_or(|s| s.trim().is_empty());
        if i + 1 == count {
            value.decor_mut().set_suffix(tail.to_owned());
        } else if blank {
            value.decor_mut().set_suffix("");
        }
    }
}

/// `m` with m[j,i] = m[i,j] = (m[i,j] + m[j,i]) / 2 exactly.
fn symmetric(m: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = m.clone();
    for i in 0..m.nrows().min(m.ncols()) {
        for j in i + 1..m.ncols().min(m.nrows()) {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
    }
    out
}

/// Sets `key` of `table` to the rows of `m`, keeping the old value's surrounding
/// whitespace (but not a comment after it: it was about the old value).
fn put(table: &mut dyn toml_edit::TableLike, key: &str, m: &DMatrix<f64>) {
    let mut value = rows(m);
    if let Some(old) = table.get(key).and_then(toml_edit::Item::as_value) {
        let raw = |r: Option<&toml_edit::RawString>| {
            r.and_then(toml_edit::RawString::as_str)
                .filter(|s| s.trim().is_empty())
                .map(str::to_owned)
        };
        if let Some(prefix) = raw(old.decor().prefix()) {
            value.decor_mut().set_prefix(prefix);
        }
        value
            .decor_mut()
            .set_suffix(raw(old.decor().suffix()).unwrap_or_default());
    }
    table.insert(key, toml_edit::Item::Value(value));
}

/// `[[a, b], [c, d]]` with `{:?}` floats.
fn rows(m: &DMatrix<f64>) -> toml_edit::Value {
    let text = format!(
        "[{}]",
        m.row_iter()
            .map(|row| format!(
                "[{}]",
                row.iter()
                    .map(|v| format!("{v:?}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut value: toml_edit::Value = text
        .parse()
        .unwrap_or_else(|e| unreachable!("{text} is a TOML array: {e}"));
    value.decor_mut().set_prefix(" ");
    value
}

/// Puts the comment line `note` last in `decor`'s prefix (before the key, at its
/// indentation), dropping an earlier note.
fn add_note(decor: &mut toml_edit::Decor, note: &str) {
    let prefix = decor
        .prefix()
        .and_then(toml_edit::RawString::as_str)
        .unwrap_or("")
        .to_owned();
    let (body, indent) = match prefix.rfind('\n') {
        Some(i) => prefix.split_at(i + 1),
        None => ("", prefix.as_str()),
    };
    let kept: String = body
        .split_inclusive('\n')
        .filter(|line| !line.trim_start().starts_with(NOISE_NOTE))
        .collect();
    decor.set_prefix(format!("{kept}{indent}{note}\n{indent}"));
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

    /// An isolation threshold that is not finite and positive (a test the data could
    /// not calibrate) is refused naming its test, before anything is written; an
    /// earlier calibrated table is replaced whole, so a test left out falls back to χ².
    #[test]
    fn an_isolation_threshold_of_zero_is_refused_naming_its_test() {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = set_calibrated(TEXT, "tank", &calibration(), &[("level_bias", bad)], "a")
                .unwrap_err();
            assert!(matches!(&e, EditError::Isolation { test, .. } if test == "level_bias"));
            assert!(e.to_string().contains("\"level_bias\""), "{e}");
        }
        let once =
            set_calibrated(TEXT, "tank", &calibration(), &[("level_bias", 7.5)], "a").unwrap();
        let again = set_calibrated(&once, "tank", &calibration(), &[], "b").unwrap();
        assert!(!again.contains("isolation"), "{again}");
        let cfg = crate::parse(&again).unwrap();
        assert!(cfg.channels[0].isolation_thresholds.is_empty());
    }

    /// A per-sample target is written as `sample_far` with the exceedances,
    /// and reads back as such; a file with both targets, or neither, is refused.
    #[test]
    fn a_sample_far_target_is_recorded_and_read_back() {
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

    const TWO: &str = r#"# Two states, two outputs.
[[channels]]
name = "plant"
# the model, by hand
[channels.model]
F = [[0.9, 0.1], [0.0, 0.8]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.1 # a guess
R = [[1.0, 0.0], [0.0, 1.0]]
S = [[0.0, 0.0], [0.0, 0.0]]

[[channels.faults]]
name = "b0"
kind = "sensor_bias"
output = 0
"#;

    fn m(n: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(n, n, v)
    }

    fn noise() -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        (
            m(2, &[0.01, 0.002, 0.0020000000000000004, 0.03]),
            m(2, &[0.04, 0.0, 0.0, 0.09]),
            m(2, &[0.001, 0.0, 0.0, 0.002]),
        )
    }

    #[test]
    fn a_continuous_models_qc_gives_way_to_the_estimated_per_sample_q() {
        let text = include_str!("../../../config/examples/two-tanks.toml");
        let q = m(2, &[0.003, 0.0, 0.0, 0.003]);
        let r = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![0.04, 0.04, 4e-4]));
        let edited = set_noise(text, "two_tanks", &q, &r, None, "mon.csv (ALS)").unwrap();
        assert!(!edited.contains("\nQc ="), "{edited}");
        assert!(
            edited.contains("\nA = ") && edited.contains("\nQ = "),
            "{edited}"
        );
        let channel = &crate::parse(&edited).unwrap().channels[0];
        let d = channel
            .discretised
            .as_ref()
            .expect("still continuous in A, B");
        assert_eq!(d.period(), 20.0);
        assert!(d.qc().is_none(), "no Qc left");
        let q_written = channel.model.matrices()[4].base();
        assert!((q_written[(0, 0)] - 0.003).abs() < 1e-15, "{q_written}");
    }

    #[test]
    fn noise_in_a_model_table_is_replaced_keeping_comments_and_other_keys() {
        let (q, r, _) = noise();
        let edited = set_noise(TWO, "plant", &q, &r, None, "data.csv (ALS)").unwrap();
        assert_eq!(
            edited,
            r#"# Two states, two outputs.
[[channels]]
name = "plant"
# the model, by hand
[channels.model]
F = [[0.9, 0.1], [0.0, 0.8]]
H = [[1.0, 0.0], [0.0, 1.0]]
# Noise covariances Q, R from data.csv (ALS)
Q = [[0.01, 0.002], [0.002, 0.03]]
R = [[0.04, 0.0], [0.0, 0.09]]

[[channels.faults]]
name = "b0"
kind = "sensor_bias"
output = 0
"#
        );
        let cfg = crate::parse(&edited).unwrap();
        let c = &cfg.channels[0];
        let [_, _, _, _, q_read, r_read] = c.model.matrices();
        assert_eq!(q_read.base(), &symmetric(&q));
        assert_eq!(q_read.base()[(0, 1)], q_read.base()[(1, 0)]);
        assert_eq!(r_read.base(), &r);
        assert!(c.cross_covariance.is_none());
        // A second edit replaces the note and adds S.
        let (q2, r2, s2) = noise();
        let again = set_noise(&edited, "plant", &(q2 * 2.0), &r2, Some(&s2), "b.csv").unwrap();
        assert_eq!(again.matches(NOISE_NOTE).count(), 1, "{again}");
        assert!(again.contains("# Noise covariances Q, R, S from b.csv\nQ = [[0.02, "));
        assert!(
            again.contains("S = [[0.001, 0.0], [0.0, 0.002]]\n"),
            "{again}"
        );
        assert!(again.contains("# the model, by hand\n[channels.model]\nF = "));
        let cfg = crate::parse(&again).unwrap();
        assert_eq!(cfg.channels[0].cross_covariance.as_ref(), Some(&s2));
    }

    #[test]
    fn noise_in_an_inline_model_is_replaced_and_s_added_and_removed() {
        let text = TEXT.replace(
            "model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }",
            "model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 } # scalar",
        );
        let (q, r, s) = (m(1, &[0.002]), m(1, &[0.5]), m(1, &[0.01]));
        let edited = set_noise(&text, "tank", &q, &r, Some(&s), "x.mcap").unwrap();
        assert!(
            edited.contains(
                "name = \"tank\"   # the only one\n# Noise covariances Q, R, S from x.mcap\n\
                 model = { F = [[0.9]], H = [[1.0]], Q = [[0.002]], R = [[0.5]], S = [[0.01]] } \
                 # scalar\n"
            ),
            "{edited}"
        );
        assert!(edited.starts_with("# A tank, by hand.\n"));
        assert!(edited.contains("# set by hand until calibrated\nthreshold = 9.0\n"));
        let cfg = crate::parse(&edited).unwrap();
        assert_eq!(cfg.channels[0].cross_covariance.as_ref(), Some(&s));
        let removed = set_noise(&edited, "tank", &q, &r, None, "y.csv").unwrap();
        assert!(
            removed.contains(
                "# the only one\n# Noise covariances Q, R from y.csv\n\
                 model = { F = [[0.9]], H = [[1.0]], Q = [[0.002]], R = [[0.5]] } # scalar\n"
            ),
            "{removed}"
        );
        assert!(
            crate::parse(&removed).unwrap().channels[0]
                .cross_covariance
                .is_none()
        );
    }

    #[test]
    fn noise_edits_that_cannot_be_made_are_refused() {
        let (q, r, _) = noise();
        let one = m(1, &[1.0]);
        let e = set_noise(TEXT, "pump", &one, &one, None, "a").unwrap_err();
        assert!(matches!(e, EditError::NoChannel(_)), "{e:?}");
        // Q of the wrong size: the result would not validate.
        let e = set_noise(TEXT, "tank", &q, &one, None, "a").unwrap_err();
        assert!(matches!(e, EditError::Invalid(_)), "{e:?}");
        // R not positive definite.
        let e = set_noise(TWO, "plant", &q, &(r * -1.0), None, "a").unwrap_err();
        assert!(matches!(e, EditError::Invalid(_)), "{e:?}");
        let e = set_noise(TEXT, "tank", &m(1, &[f64::NAN]), &one, None, "a").unwrap_err();
        assert!(matches!(e, EditError::NotFinite("Q")), "{e:?}");
        let e = set_noise(
            "[[channels]]\nname = \"tank\"\nmodel = 1\n",
            "tank",
            &one,
            &one,
            None,
            "a",
        )
        .unwrap_err();
        assert!(matches!(e, EditError::ModelNotTable), "{e:?}");
    }
}
