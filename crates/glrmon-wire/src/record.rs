//! Result records: the JSON objects glrmon publishes on Zenoh (`glrmon/<channel>/<type>`),
//! writes to MCAP and prints in replay's JSONL. The public contract is documented on
//! [`Record`].

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::error::{DecodeError, DecodeErrorKind, EncodeError, EncodeErrorKind, ErrorCode, Stage};
use crate::json_schema::record_schema;
use crate::key::result_key;
use crate::sample::{is_out_of_range, write_json};

/// Per-sample detection statistics (`type: "stat"`): the windowed GLR statistic l_k, the
/// onset r̂ and magnitude θ̂ that maximise it, the innovation ε_k and, during an alarm
/// episode, the episode's own estimate; on Zenoh decimated as configured.
///
/// `onset` and `magnitude` are the window's: they describe the best change *inside the
/// last w samples*. Once a fault that persists is older than the window, its onset has
/// left it: `onset` slides with the window (its oldest admissible onset, or another
/// inside it) and no longer dates the fault, and `magnitude` fits the settled response
/// of the old fault with the transient of one starting inside the window, so it shrinks
/// while the fault does not (a 1.32 cm sensor bias read as 0.5 cm). `episode` holds the
/// estimate at the episode's own onset instead: plot `episode.magnitude` while it is
/// present, `magnitude` otherwise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon stat")]
pub struct Stat {
    /// Channel name.
    pub channel: String,
    /// Sample index k.
    pub k: u64,
    /// Sample time in seconds, if the sample carried one.
    pub t: Option<f64>,
    /// GLR statistic l_k = max over the window of d_k(r)ᵀ C_k(r)⁺ d_k(r) (Zhang &
    /// Basseville 2014, eq. (35)); `None` (`null`) while no onset is admissible.
    pub glr: Option<f64>,
    /// Maximising onset r̂ (eq. (36)) among the window's onsets, if any. It slides with
    /// the window once a persisting fault is older than the window: `episode.onset`
    /// dates an episode's fault.
    pub onset: Option<u64>,
    /// Magnitude estimate θ̂ = C_k(r̂)⁺ d_k(r̂) (eq. (34)) at the window's r̂, one value
    /// per fault in dictionary order; empty while no onset is admissible. Once a
    /// persisting fault's onset has left the window it shrinks while the fault does
    /// not: during an episode, `episode.magnitude` is the one to plot.
    pub magnitude: Vec<f64>,
    /// Numerical rank of C_k(r̂) (fewer than the number of faults when some are not
    /// separable over the window).
    pub rank: usize,
    /// Innovation ε_k of the Kalman filter, one value per output; empty for the
    /// detector kinds that run no Kalman filter (`parity`, `fdf`, `uio`, `rls`).
    pub innovation: Vec<f64>,
    /// The detector's own residual for the kinds that are not built on the Kalman
    /// innovation: the parity residual (`parity`), the observer's weighted output
    /// error (`fdf`, `uio`), θ̂ − θ_nom (`rls`). Absent for `glr`, `chi2` and `cusum`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub residual: Vec<f64>,
    /// Alarm threshold on l_k, if configured.
    pub threshold: Option<f64>,
    /// The alarm episode's estimate while an episode is on: from its alarm's sample
    /// (the crossing) to its `alarm_end`'s, both included. `None` (`null`, or absent in
    /// records of versions before it) outside episodes and for detectors that cannot
    /// follow an onset past the window (`chi2`).
    #[serde(default)]
    pub episode: Option<EpisodeEstimate>,
}

/// The estimate of an alarm episode's fault at sample k of a `stat` record: at the
/// episode's onset, over every sample since, however long ago it left the window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EpisodeEstimate {
    /// The episode's onset r̂: its alarm's, and after its `isolation` record's sample,
    /// that record's (the onset `alarm_end` reports). It stays put while the episode
    /// lasts, unlike the window's `onset`.
    pub onset: u64,
    /// θ̂ = C_k(r̂)⁺ d_k(r̂) at the episode's onset over every sample from r̂ to k (eq.
    /// (34) continued past the window), one value per fault in the order of the record's
    /// `magnitude`: what a persisting fault's magnitude is, where the window's
    /// `magnitude` shrinks once r̂ has left the window. At the crossing it equals the
    /// alarm's `magnitude`.
    pub magnitude: Vec<f64>,
}

/// Minmax / sensitivity isolation test for one fault at an alarm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct IsolationResult {
    /// Fault name from the channel's dictionary.
    pub fault: String,
    /// Minmax test statistic for this fault.
    pub minmax: f64,
    /// Sensitivity test statistic for this fault.
    pub sensitivity: f64,
    /// Threshold the statistics are compared with.
    pub threshold: f64,
    /// Whether the fault is declared present: its minmax test exceeds the threshold at
    /// r̂ and no other fault explains the data as well at an onset of its own
    /// (`ambiguous_with` is empty).
    pub isolated: bool,
    /// The faults that cannot yet be told apart from this one once the onset is free:
    /// each, alone and at its own best onset in the window, explains the data within
    /// this test's threshold of how well this fault does at its own. At the crossing few
    /// samples carry the fault (a state jump at r and one of another state at r − 1 may
    /// give the same first innovations); the `isolation` update narrows the set. Empty
    /// when the test is decisive, and in records of versions before it existed.
    #[serde(default)]
    pub ambiguous_with: Vec<String>,
    /// For the kinds that isolate by exclusion (`kernel`): whether this fault's
    /// residual (`minmax`) has exceeded its threshold at some sample since the
    /// detection, which rules it out for the rest of the episode. Absent for the
    /// kinds that test by minmax.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excluded: Option<bool>,
}

/// An alarm: l_k crossed the threshold (`type: "alarm"`), published at the crossing.
///
/// `k` is the crossing itself: the first sample of the episode with l_k > λ, so
/// `glr > threshold` always holds. Onset, magnitude and isolation are those computed at
/// that sample; when `update_k` is set, an [`IsolationUpdate`] (`type: "isolation"`)
/// with `alarm_k` = `k` refines them at sample `update_k` if the episode is still on
/// then (an `alarm_end` before `update_k` means none will come).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon alarm")]
pub struct Alarm {
    /// Channel name.
    pub channel: String,
    /// The crossing: the sample at which l_k first exceeded the threshold.
    pub k: u64,
    /// Sample time in seconds, if known.
    pub t: Option<f64>,
    /// GLR statistic l_k at the crossing (above `threshold`).
    pub glr: f64,
    /// Threshold it crossed.
    pub threshold: f64,
    /// Estimated onset r̂.
    pub onset: u64,
    /// Magnitude estimate θ̂, in the order of `faults`.
    pub magnitude: Vec<f64>,
    /// Isolation test per fault (or configured group), at the crossing.
    pub isolation: Vec<IsolationResult>,
    /// Fault names, in the order of `magnitude`.
    pub faults: Vec<String>,
    /// The sample at which an `isolation` record will refine this alarm (`k` plus
    /// `isolation_delay`) if the episode is still on then; `None` (`null` or absent)
    /// when no refinement is scheduled (`isolation_delay = 0`, or a record of a glrmon
    /// from before the field existed, whose alarms came `isolation_delay` samples
    /// after the crossing).
    pub update_k: Option<u64>,
}

/// The refined isolation of an alarm (`type: "isolation"`), `isolation_delay` samples
/// after its crossing, published only while the alarm's episode is still on.
///
/// At the crossing few samples carry the fault, and faults whose signatures differ only
/// after a few steps cannot be told apart yet; this record repeats the alarm's tests
/// with the samples since. It is not a new alarm: `alarm_k` names the alarm (its `k`,
/// the crossing) it refines, and `glr` may lie between λ·(1 − h) and λ (the episode's
/// hysteresis band).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon isolation")]
pub struct IsolationUpdate {
    /// Channel name.
    pub channel: String,
    /// The sample at which the isolation was computed: `alarm_k` + `isolation_delay`
    /// (later only when the episode, with `clear_samples` > 1, lasted through samples
    /// without an admissible onset then: the first sample with one).
    pub k: u64,
    /// Sample time in seconds, if known.
    pub t: Option<f64>,
    /// The crossing: `k` of the alarm this record refines.
    pub alarm_k: u64,
    /// GLR statistic l_k at `k`.
    pub glr: f64,
    /// The alarm threshold λ in force at `k`.
    pub threshold: f64,
    /// Onset r̂ estimated at `k`.
    pub onset: u64,
    /// Magnitude estimate θ̂ at `k`, in the order of `faults`.
    pub magnitude: Vec<f64>,
    /// Isolation test per fault (or configured group), at `k`.
    pub isolation: Vec<IsolationResult>,
    /// Fault names, in the order of `magnitude`.
    pub faults: Vec<String>,
}

/// The end of an alarm episode (`type: "alarm_end"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon alarm end")]
pub struct AlarmEnd {
    /// Channel name.
    pub channel: String,
    /// Sample index at which the episode ended.
    pub k: u64,
    /// Sample time in seconds, if known.
    pub t: Option<f64>,
    /// Onset r̂ as last reported for the episode: by its `isolation` record if one
    /// came, else by its `alarm`.
    pub onset: u64,
    /// Length of the episode in samples.
    pub duration: u64,
    /// Largest l_k during the episode.
    pub peak_glr: f64,
}

/// A sparse diagnosis over a span of samples (`type: "diagnosis"`, Zhang 2021): the faults
/// the Lasso selects, their magnitudes refitted on that support, and the regularisation
/// path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon diagnosis")]
pub struct Diagnosis {
    /// Channel name.
    pub channel: String,
    /// Sample index at which the diagnosis was made.
    pub k: u64,
    /// First sample index of the span.
    pub from: u64,
    /// Last sample index of the span.
    pub to: u64,
    /// Names of the faults selected by the Lasso.
    pub support: Vec<String>,
    /// Least-squares refit of the magnitude on the support, by fault name.
    pub estimate: BTreeMap<String, f64>,
    /// The λ chosen.
    pub lambda: f64,
    /// The range of λ over which the support stays the same, `[low, high]`. Both ends
    /// must be finite: an unbounded end is clamped by the caller (e.g. to λ_max).
    pub plateau: [f64; 2],
    /// Residual used: `kalman` (the Kalman innovations of the fault-free model,
    /// [`Diagnosis::RESIDUAL_KALMAN`]) or `kitanidis` (the Kitanidis filter's residuals,
    /// decoupled from the unknown inputs, [`Diagnosis::RESIDUAL_KITANIDIS`]).
    #[schemars(extend("enum" = [Diagnosis::RESIDUAL_KALMAN, Diagnosis::RESIDUAL_KITANIDIS]))]
    pub residual: String,
    /// Support size at each λ along the regularisation path (Zhang 2021, Fig. 2).
    pub path_support_sizes: Vec<usize>,
    /// The fault dictionary, in the order of the columns of `path_coefficients`.
    pub faults: Vec<String>,
    /// The λ values of the regularisation path, decreasing (Zhang 2021, eq. (39)).
    pub path_lambda: Vec<f64>,
    /// The Lasso estimate θ̂(λ) at each λ of `path_lambda`: one row per λ, one value
    /// per fault of `faults`.
    pub path_coefficients: Vec<Vec<f64>>,
}

impl Diagnosis {
    /// `residual` value: Kalman innovations of the fault-free model.
    pub const RESIDUAL_KALMAN: &'static str = "kalman";
    /// `residual` value: Kitanidis filter residuals (unknown-input decoupled).
    pub const RESIDUAL_KITANIDIS: &'static str = "kitanidis";
}

/// A change of the filter-consistency verdict (`type: "consistency"`): the block mean of
/// the normalised innovation squared εᵀΣ⁻¹ε left, or came back into, its χ² band. A
/// warning that the model no longer fits the plant, distinct from fault alarms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon consistency")]
pub struct Consistency {
    /// Channel name.
    pub channel: String,
    /// The last sample of the block.
    pub k: u64,
    /// Its time.
    pub t: Option<f64>,
    /// `too_large` (innovations larger than the model says: Q, R or the model too
    /// optimistic), `too_small` (too pessimistic) or `consistent` (back in the band).
    #[schemars(extend("enum" = ["consistent", "too_large", "too_small"]))]
    pub state: String,
    /// Mean of εᵀΣ⁻¹ε over the block.
    pub nis_mean: f64,
    /// Its expected value under a fitting model: p, the number of outputs.
    pub expected: f64,
    /// The band `[low, high]` on the block mean at the configured level.
    pub band: [f64; 2],
    /// Samples per block.
    pub window: u64,
}

/// A counted rejection or failure (`type: "error"`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "glrmon error")]
pub struct ErrorRecord {
    /// Channel name.
    pub channel: String,
    /// Sample index, if known.
    pub k: Option<u64>,
    /// Catalogue code, serialized as its snake_case label.
    pub code: ErrorCode,
    /// What, where and why, e.g. `channel "pump3": field y has 3 values, model expects 4`.
    pub message: String,
    /// Where in the data flow it happened.
    pub stage: Stage,
}

impl ErrorRecord {
    /// The record of a decode error, with its channel, code and message.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_wire::{decode_samples, DecodeLimits, ErrorRecord, Stage};
    ///
    /// let err = decode_samples("pump3", b"{}", &DecodeLimits::default(), &mut Vec::new())
    ///     .unwrap_err();
    /// let rec = ErrorRecord::from_decode_error(&err, None, Stage::Receiving);
    /// assert_eq!(rec.code.as_str(), "missing_field");
    /// assert_eq!(rec.message, r#"channel "pump3": field y is missing"#);
    /// ```
    #[must_use]
    pub fn from_decode_error(err: &DecodeError, k: Option<u64>, stage: Stage) -> Self {
        ErrorRecord {
            channel: err.channel.clone(),
            k,
            code: err.code(),
            message: err.to_string(),
            stage,
        }
    }
}

/// Any result record: one JSON object with `"type"` (`stat`, `alarm`, `isolation`,
/// `alarm_end`, `diagnosis`, `error`, `consistency`) and `"channel"`, the rest of the fields flattened
/// beside them.
///
/// Letters are those of Zhang & Basseville (2014): l_k the GLR statistic (`glr`), r̂ the
/// onset, θ̂ the magnitude, ε_k the innovation.
///
/// # Floats
///
/// [`encode_json`] prints every float in the shortest form that parses back to the same
/// bits (`0.1 + 0.2` → `0.30000000000000004`, `1e-300` → `1e-300`), and [`decode_record`]
/// parses correctly rounded, so a round trip is bit-identical. Negative zero is printed as
/// `-0.0` and comes back as `-0.0` (a consumer that parses `-0.0` as `0` loses only the
/// sign of a zero).
///
/// JSON has no NaN or infinity. `null` has exactly one meaning per field and is written
/// only for `None`: `glr: null` means no onset is admissible yet (the window is not
/// filled), `t: null` that the sample had no time, `threshold: null` that none is
/// configured, `episode: null` that no alarm episode is on. A non-finite float anywhere, inside an `Option` or not, is an
/// [`EncodeError`] naming the field, rather than a silent `null` (serde_json's own
/// behaviour) that would read as "no onset". Callers turn "no value" into `None` first.
/// So prefer [`encode_json`] to serializing this type with serde directly.
///
/// # Compatibility
///
/// Decoding ignores unknown fields, so a consumer built against this version reads
/// records from a newer glrmon that added fields; the enum is `#[non_exhaustive]` so that
/// a new record type is not a breaking change either. Fields of type `Option` may be
/// absent or `null`; all others are required. [`record_schema`] gives each type's JSON
/// Schema.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
#[non_exhaustive]
// Each `#[schemars(description = "")]` below keeps the variant's doc comment out of its
// schema: a record type's schema is described by its struct's.
pub enum Record {
    /// `"stat"`.
    #[schemars(description = "")]
    Stat(Stat),
    /// `"alarm"`.
    #[schemars(description = "")]
    Alarm(Alarm),
    /// `"isolation"`.
    #[schemars(description = "")]
    Isolation(IsolationUpdate),
    /// `"alarm_end"`.
    #[schemars(description = "")]
    AlarmEnd(AlarmEnd),
    /// `"diagnosis"`.
    #[schemars(description = "")]
    Diagnosis(Diagnosis),
    /// `"error"`.
    #[schemars(description = "")]
    Error(ErrorRecord),
    /// `"consistency"`.
    #[schemars(description = "")]
    Consistency(Consistency),
}

/// Every record `type`, in the order of [`Record`]'s variants ([`Record::kind_index`]).
pub const RECORD_KINDS: [&str; 7] = [
    "stat",
    "alarm",
    "isolation",
    "alarm_end",
    "diagnosis",
    "error",
    "consistency",
];

impl Record {
    /// The record's channel.
    #[must_use]
    pub fn channel(&self) -> &str {
        match self {
            Record::Stat(r) => &r.channel,
            Record::Alarm(r) => &r.channel,
            Record::Isolation(r) => &r.channel,
            Record::AlarmEnd(r) => &r.channel,
            Record::Diagnosis(r) => &r.channel,
            Record::Error(r) => &r.channel,
            Record::Consistency(r) => &r.channel,
        }
    }

    /// The `type` tag: `stat`, `alarm`, `isolation`, `alarm_end`, `diagnosis`, `error`
    /// or `consistency`; [`RECORD_KINDS`]`[self.kind_index()]`.
    #[must_use]
    pub const fn kind_str(&self) -> &'static str {
        RECORD_KINDS[self.kind_index()]
    }

    /// The position of the record's kind in [`RECORD_KINDS`], for tables indexed by
    /// kind (e.g. one publisher per channel and kind).
    #[must_use]
    pub const fn kind_index(&self) -> usize {
        match self {
            Record::Stat(_) => 0,
            Record::Alarm(_) => 1,
            Record::Isolation(_) => 2,
            Record::AlarmEnd(_) => 3,
            Record::Diagnosis(_) => 4,
            Record::Error(_) => 5,
            Record::Consistency(_) => 6,
        }
    }

    /// The sample index the record refers to, if known.
    #[must_use]
    pub const fn k(&self) -> Option<u64> {
        match self {
            Record::Stat(r) => Some(r.k),
            Record::Alarm(r) => Some(r.k),
            Record::Isolation(r) => Some(r.k),
            Record::AlarmEnd(r) => Some(r.k),
            Record::Diagnosis(r) => Some(r.k),
            Record::Error(r) => r.k,
            Record::Consistency(r) => Some(r.k),
        }
    }

    /// The Zenoh key to publish it on: `glrmon/<channel>/<type>`.
    #[must_use]
    pub fn key(&self) -> String {
        result_key(self.channel(), self.kind_str())
    }

    /// Checks that every float is finite, i.e. that the record can be JSON.
    ///
    /// # Errors
    ///
    /// [`EncodeErrorKind::NonFinite`] naming the first offending field: `glr`,
    /// `magnitude[1]`, `isolation[0].minmax`, `estimate.leak`, `plateau[1]`, …
    pub fn check_finite(&self) -> Result<(), EncodeError> {
        let c = FiniteCheck {
            channel: self.channel(),
        };
        match self {
            Record::Stat(r) => {
                c.opt("t", r.t)?;
                c.opt("glr", r.glr)?;
                c.all("magnitude", &r.magnitude)?;
                c.all("innovation", &r.innovation)?;
                c.all("residual", &r.residual)?;
                c.opt("threshold", r.threshold)?;
                r.episode
                    .as_ref()
                    .map_or(Ok(()), |e| c.all("episode.magnitude", &e.magnitude))
            }
            Record::Alarm(r) => {
                c.opt("t", r.t)?;
                c.one("glr", r.glr)?;
                c.one("threshold", r.threshold)?;
                c.all("magnitude", &r.magnitude)?;
                c.isolation(&r.isolation)
            }
            Record::Isolation(r) => {
                c.opt("t", r.t)?;
                c.one("glr", r.glr)?;
                c.one("threshold", r.threshold)?;
                c.all("magnitude", &r.magnitude)?;
                c.isolation(&r.isolation)
            }
            Record::AlarmEnd(r) => {
                c.opt("t", r.t)?;
                c.one("peak_glr", r.peak_glr)
            }
            Record::Diagnosis(r) => {
                for (name, v) in &r.estimate {
                    c.one(&format!("estimate.{name}"), *v)?;
                }
                c.one("lambda", r.lambda)?;
                c.all("path_lambda", &r.path_lambda)?;
                for (i, row) in r.path_coefficients.iter().enumerate() {
                    c.all(&format!("path_coefficients[{i}]"), row)?;
                }
                c.all("plateau", &r.plateau)
            }
            Record::Error(_) => Ok(()),
            Record::Consistency(r) => {
                c.opt("t", r.t)?;
                c.one("nis_mean", r.nis_mean)?;
                c.one("expected", r.expected)?;
                c.all("band", &r.band)
            }
        }
    }
}

struct FiniteCheck<'a> {
    channel: &'a str,
}

impl FiniteCheck<'_> {
    fn one(&self, field: &str, value: f64) -> Result<(), EncodeError> {
        if value.is_finite() {
            Ok(())
        } else {
            Err(EncodeError {
                channel: self.channel.to_owned(),
                field: field.to_owned(),
                kind: EncodeErrorKind::NonFinite { value },
            })
        }
    }

    fn opt(&self, field: &str, value: Option<f64>) -> Result<(), EncodeError> {
        value.map_or(Ok(()), |v| self.one(field, v))
    }

    fn all(&self, field: &str, values: &[f64]) -> Result<(), EncodeError> {
        match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            None => Ok(()),
            Some((i, v)) => self.one(&format!("{field}[{i}]"), *v),
        }
    }

    fn isolation(&self, tests: &[IsolationResult]) -> Result<(), EncodeError> {
        for (i, iso) in tests.iter().enumerate() {
            self.one(&format!("isolation[{i}].minmax"), iso.minmax)?;
            self.one(&format!("isolation[{i}].sensitivity"), iso.sensitivity)?;
            self.one(&format!("isolation[{i}].threshold"), iso.threshold)?;
        }
        Ok(())
    }
}

macro_rules! record_from {
    ($($ty:ident => $variant:ident),*) => {$(
        impl From<$ty> for Record {
            fn from(r: $ty) -> Self {
                Record::$variant(r)
            }
        }
    )*};
}
record_from!(Stat => Stat, Alarm => Alarm, IsolationUpdate => Isolation, AlarmEnd => AlarmEnd, Diagnosis => Diagnosis, ErrorRecord => Error, Consistency => Consistency);

/// Appends `record` as one JSON object (no trailing newline) to `out`.
///
/// Floats are printed shortest-roundtrip, so [`decode_record`] gives back bit-identical
/// values; `None` is written as `null`.
///
/// # Errors
///
/// [`EncodeErrorKind::NonFinite`] if any float is NaN or infinite (see the module docs
/// for why this is not mapped to `null`); `out` is then unchanged.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{encode_json, AlarmEnd, Record};
///
/// let rec = Record::from(AlarmEnd {
///     channel: "pump3".into(), k: 140, t: None, onset: 101, duration: 39, peak_glr: 87.5,
/// });
/// let mut out = Vec::new();
/// encode_json(&rec, &mut out)?;
/// assert_eq!(out, br#"{"type":"alarm_end","channel":"pump3","k":140,"t":null,"onset":101,"duration":39,"peak_glr":87.5}"#);
/// # Ok::<(), glrmon_wire::EncodeError>(())
/// ```
pub fn encode_json(record: &Record, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    record.check_finite()?;
    write_json(record.channel(), record, out)
}

/// Decodes one record from a JSON object.
///
/// Unknown fields are ignored (see the module docs on compatibility); the payload must be
/// an object, not an array.
///
/// # Errors
///
/// A [`DecodeError`] whose `channel` is the record's if it could be read (empty
/// otherwise) and whose `field` names the fault: `InvalidJson`, `NonFinite` (a number
/// such as `1e999`), `MissingField`, `WrongType` (including an unknown `type`, `code` or
/// `stage`), `WrongDimension` (`plateau` not of length 2), `DuplicateField`.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{decode_record, ErrorCode, Record};
///
/// let rec = decode_record(br#"{"type":"error","channel":"pump3","k":null,"code":"gap",
///                             "message":"2 samples missing","stage":"processing"}"#)?;
/// assert_eq!(rec.kind_str(), "error");
///
/// let err = decode_record(br#"{"type":"alarm_end","channel":"pump3","k":1}"#).unwrap_err();
/// assert_eq!(err.code(), ErrorCode::MissingField);
/// assert_eq!(err.to_string(), r#"channel "pump3": field onset is missing"#);
/// # Ok::<(), glrmon_wire::DecodeError>(())
/// ```
pub fn decode_record(payload: &[u8]) -> Result<Record, DecodeError> {
    // serde's internally tagged enums also accept `["stat", …]` arrays; the wire format
    // is objects only.
    let first = payload.iter().copied().find(|b| !b.is_ascii_whitespace());
    if first != Some(b'{') {
        return Err(
            match serde_json::from_slice::<serde::de::IgnoredAny>(payload) {
                Err(err) => syntax_error(&err),
                Ok(_) => DecodeError::new("", None, wrong_type(EXPECT_RECORD)),
            },
        );
    }
    serde_json::from_slice(payload).map_err(|err| record_error(payload, &err))
}

const EXPECT_RECORD: &str = "a record object";

fn wrong_type(expected: &str) -> DecodeErrorKind {
    DecodeErrorKind::WrongType {
        expected: expected.to_owned(),
    }
}

fn syntax_error(err: &serde_json::Error) -> DecodeError {
    let kind = if is_out_of_range(err) {
        DecodeErrorKind::NonFinite
    } else {
        DecodeErrorKind::InvalidJson(err.to_string())
    };
    DecodeError::new("", None, kind)
}

/// Turns serde's error into a located one. serde's derive reports "invalid type: string,
/// expected f64" without saying which field, so on this (rare) path the payload is parsed
/// again as a `Value` and checked against the record's JSON Schema ([`record_schema`]),
/// which names the field.
fn record_error(payload: &[u8], err: &serde_json::Error) -> DecodeError {
    if err.classify() != serde_json::error::Category::Data {
        return syntax_error(err);
    }
    let Ok(Value::Object(obj)) = serde_json::from_slice::<Value>(payload) else {
        return DecodeError::new("", None, wrong_type(EXPECT_RECORD));
    };
    let channel = obj
        .get("channel")
        .and_then(Value::as_str)
        .unwrap_or_default();
    let msg = err.to_string();
    if let Some(name) = msg
        .strip_prefix("duplicate field `")
        .and_then(|m| m.split('`').next())
    {
        return DecodeError::new(
            channel,
            Some(name.to_owned()),
            DecodeErrorKind::DuplicateField,
        );
    }
    match locate(&obj) {
        Some((field, kind)) => DecodeError::new(channel, Some(field), kind),
        // Only reachable if the schema accepts what serde refused; the test
        // `schema_matches_serialized_fields` guards against that.
        None => DecodeError::new(
            channel,
            None,
            wrong_type(&format!("a valid record ({msg})")),
        ),
    }
}

type Located = (String, DecodeErrorKind);

/// The first field of `obj` that its record's schema refuses, and why.
fn locate(obj: &Map<String, Value>) -> Option<Located> {
    let schema = match obj.get("type") {
        None => return Some(("type".to_owned(), DecodeErrorKind::MissingField)),
        Some(Value::String(kind)) => record_schema(kind),
        Some(_) => None,
    };
    match schema {
        Some(schema) => locate_in(obj, "", schema),
        None => {
            let expected = format!("one of {}", RECORD_KINDS.join(", "));
            Some(("type".to_owned(), wrong_type(&expected)))
        }
    }
}

/// The first property of `obj` that the object schema `schema` refuses, else the first it
/// requires that is missing (in declaration order, as serde reports it), each named
/// `prefix` + its name.
fn locate_in(obj: &Map<String, Value>, prefix: &str, schema: &Value) -> Option<Located> {
    let properties = schema["properties"].as_object()?;
    let refused = properties.iter().find_map(|(name, property)| {
        let value = obj.get(name)?;
        locate_value(value, format!("{prefix}{name}"), property)
    });
    refused.or_else(|| {
        let required = schema["required"].as_array()?;
        let missing = required
            .iter()
            .filter_map(Value::as_str)
            .find(|name| !obj.contains_key(*name))?;
        Some((format!("{prefix}{missing}"), DecodeErrorKind::MissingField))
    })
}

/// Where in `value` (at `path`) the schema `schema` refuses it: `path` itself, or an item
/// or property of it.
fn locate_value(value: &Value, path: String, schema: &Value) -> Option<Located> {
    if value.is_null() && allows(schema, "null") {
        return None;
    }
    let refused = || Some((path.clone(), wrong_type(&expected(schema))));
    match value {
        Value::Array(items) if allows(schema, "array") => {
            let len = |key: &str| schema[key].as_u64().and_then(|n| usize::try_from(n).ok());
            if let (Some(min), Some(max)) = (len("minItems"), len("maxItems"))
                && min == max
                && items.len() != min
            {
                return Some((
                    path,
                    DecodeErrorKind::WrongDimension {
                        expected: min,
                        got: items.len(),
                    },
                ));
            }
            items
                .iter()
                .enumerate()
                .find_map(|(i, item)| locate_value(item, format!("{path}[{i}]"), &schema["items"]))
        }
        Value::Object(map) if allows(schema, "object") => match &schema["additionalProperties"] {
            entry @ Value::Object(_) => map
                .iter()
                .find_map(|(name, v)| locate_value(v, format!("{path}.{name}"), entry)),
            _ => locate_in(map, &format!("{path}."), schema),
        },
        Value::Number(n) if allows(schema, "integer") => {
            let fits = match schema["format"].as_str() {
                Some("uint") => n.as_u64().is_some_and(|v| usize::try_from(v).is_ok()),
                _ if schema["minimum"] == 0 => n.is_u64(),
                _ => n.is_u64() || n.is_i64(),
            };
            if fits { None } else { refused() }
        }
        Value::Number(_) if allows(schema, "number") => None,
        Value::Bool(_) if allows(schema, "boolean") => None,
        Value::String(_) if allows(schema, "string") => match schema["enum"].as_array() {
            Some(values) if !values.contains(value) => refused(),
            _ => None,
        },
        _ => refused(),
    }
}

/// Whether `schema`'s `type` (one name or a list) includes `ty`.
fn allows(schema: &Value, ty: &str) -> bool {
    match &schema["type"] {
        Value::String(t) => t == ty,
        Value::Array(types) => types.iter().any(|t| t == ty),
        _ => false,
    }
}

/// What `schema` accepts, in words: "a number or null", "an array of 2 numbers", …
fn expected(schema: &Value) -> String {
    let text = noun(schema, false);
    if allows(schema, "null") {
        format!("{text} or null")
    } else {
        text
    }
}

/// The kind of value `schema` accepts besides `null`, as one (`a number`) or many
/// (`numbers`).
fn noun(schema: &Value, plural: bool) -> String {
    let pick = |one: &str, many: &str| if plural { many } else { one }.to_owned();
    if let Some(values) = schema["enum"].as_array() {
        let names: Vec<&str> = values.iter().filter_map(Value::as_str).collect();
        return format!("one of {}", names.join(", "));
    }
    let ty = ["integer", "number", "string", "boolean", "array", "object"]
        .into_iter()
        .find(|ty| allows(schema, ty));
    match ty {
        Some("integer") if schema["minimum"] == 0 => {
            pick("a non-negative integer", "non-negative integers")
        }
        Some("integer") => pick("an integer", "integers"),
        Some("number") => pick("a number", "numbers"),
        Some("string") => pick("a string", "strings"),
        Some("boolean") => pick("a boolean", "booleans"),
        Some("array") => {
            let items = noun(&schema["items"], true);
            match (schema["minItems"].as_u64(), schema["maxItems"].as_u64()) {
                (Some(min), Some(max)) if min == max => {
                    format!("{} {min} {items}", pick("an array of", "arrays of"))
                }
                _ => format!("{} {items}", pick("an array of", "arrays of")),
            }
        }
        Some(_) if schema["additionalProperties"].is_object() => format!(
            "{} {}",
            pick("an object of", "objects of"),
            noun(&schema["additionalProperties"], true)
        ),
        Some(_) => pick("an object", "objects"),
        None => pick("a valid value", "valid values"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn stat() -> Stat {
        Stat {
            channel: "pump3".into(),
            k: 12,
            t: Some(1_732_200_000.25),
            glr: Some(0.1 + 0.2),
            onset: Some(7),
            magnitude: vec![1e-300, -0.0, 2.5],
            rank: 3,
            innovation: vec![0.1, -1.7976931348623157e308],
            residual: Vec::new(),
            threshold: Some(13.8),
            episode: Some(EpisodeEstimate {
                onset: 3,
                magnitude: vec![1.25, -5e-324, 0.0],
            }),
        }
    }

    fn stat_before_onset() -> Stat {
        Stat {
            glr: None,
            onset: None,
            magnitude: vec![],
            rank: 0,
            t: None,
            threshold: None,
            episode: None,
            ..stat()
        }
    }

    fn alarm() -> Alarm {
        Alarm {
            channel: "pump3".into(),
            k: 140,
            t: None,
            glr: 87.5,
            threshold: 13.8,
            onset: 101,
            magnitude: vec![0.3, 5e-324],
            isolation: vec![
                IsolationResult {
                    excluded: None,
                    fault: "leak".into(),
                    minmax: 40.25,
                    sensitivity: 39.0,
                    threshold: 6.63,
                    isolated: true,
                    ambiguous_with: Vec::new(),
                },
                IsolationResult {
                    excluded: None,
                    fault: "bias".into(),
                    minmax: 0.125,
                    sensitivity: 1.0 / 3.0,
                    threshold: 6.63,
                    isolated: false,
                    ambiguous_with: Vec::new(),
                },
            ],
            faults: vec!["leak".into(), "bias".into()],
            update_k: Some(150),
        }
    }

    fn isolation_update() -> IsolationUpdate {
        IsolationUpdate {
            channel: "pump3".into(),
            k: 150,
            t: Some(15.0),
            alarm_k: 140,
            glr: 80.25,
            threshold: 13.8,
            onset: 100,
            magnitude: vec![0.5, -1e-300],
            isolation: vec![IsolationResult {
                excluded: None,
                fault: "leak".into(),
                minmax: 60.5,
                sensitivity: 61.0,
                threshold: 6.63,
                isolated: true,
                ambiguous_with: Vec::new(),
            }],
            faults: vec!["leak".into(), "bias".into()],
        }
    }

    fn alarm_end() -> AlarmEnd {
        AlarmEnd {
            channel: "pump3".into(),
            k: 180,
            t: Some(-0.0),
            onset: 101,
            duration: 40,
            peak_glr: 91.0,
        }
    }

    fn diagnosis() -> Diagnosis {
        Diagnosis {
            channel: "pump3".into(),
            k: 200,
            from: 90,
            to: 200,
            support: vec!["leak".into()],
            estimate: BTreeMap::from([("leak".into(), 0.1 + 0.7), ("bias".into(), -1e-300)]),
            lambda: 0.05,
            plateau: [0.01, 0.2],
            residual: Diagnosis::RESIDUAL_KITANIDIS.into(),
            path_support_sizes: vec![0, 1, 1, 2],
            faults: vec!["leak".into(), "bias".into()],
            path_lambda: vec![0.4, 0.2, 0.1, 0.05],
            path_coefficients: vec![
                vec![0.0, 0.0],
                vec![0.3, 0.0],
                vec![0.5, 0.0],
                vec![0.7, -0.01],
            ],
        }
    }

    fn error() -> ErrorRecord {
        ErrorRecord {
            channel: "pump3".into(),
            k: Some(3),
            code: ErrorCode::WrongDimension,
            message: r#"channel "pump3": field y has 3 values, model expects 4"#.into(),
            stage: Stage::Processing,
        }
    }

    fn all_records() -> Vec<Record> {
        vec![
            stat().into(),
            stat_before_onset().into(),
            Stat {
                innovation: Vec::new(),
                residual: vec![0.25, -1.5, 3.0],
                ..stat()
            }
            .into(),
            alarm().into(),
            Alarm {
                update_k: None,
                ..alarm()
            }
            .into(),
            isolation_update().into(),
            alarm_end().into(),
            diagnosis().into(),
            error().into(),
            ErrorRecord { k: None, ..error() }.into(),
            Consistency {
                channel: "pump3".into(),
                k: 999,
                t: Some(12.5),
                state: "too_large".into(),
                nis_mean: 4.25,
                expected: 1.0,
                band: [0.7, 1.3],
                window: 500,
            }
            .into(),
        ]
    }

    /// Every float of a record as bits, in field order, to compare bit-identically
    /// (`PartialEq` on f64 says 0.0 == -0.0).
    fn float_bits(record: &Record) -> Vec<u64> {
        let mut out = Vec::new();
        let mut push = |v: f64| out.push(v.to_bits());
        match record {
            Record::Stat(r) => {
                r.t.into_iter()
                    .chain(r.glr)
                    .chain(r.threshold)
                    .for_each(&mut push);
                r.magnitude
                    .iter()
                    .chain(&r.innovation)
                    .chain(r.episode.iter().flat_map(|e| &e.magnitude))
                    .copied()
                    .for_each(&mut push);
            }
            Record::Alarm(r) => {
                r.t.into_iter()
                    .chain([r.glr, r.threshold])
                    .for_each(&mut push);
                r.magnitude.iter().copied().for_each(&mut push);
                r.isolation.iter().for_each(|i| {
                    [i.minmax, i.sensitivity, i.threshold]
                        .into_iter()
                        .for_each(&mut push)
                });
            }
            Record::Isolation(r) => {
                r.t.into_iter()
                    .chain([r.glr, r.threshold])
                    .for_each(&mut push);
                r.magnitude.iter().copied().for_each(&mut push);
                r.isolation.iter().for_each(|i| {
                    [i.minmax, i.sensitivity, i.threshold]
                        .into_iter()
                        .for_each(&mut push)
                });
            }
            Record::AlarmEnd(r) => r.t.into_iter().chain([r.peak_glr]).for_each(&mut push),
            Record::Diagnosis(r) => {
                r.estimate
                    .values()
                    .copied()
                    .chain([r.lambda])
                    .chain(r.plateau)
                    .for_each(&mut push);
            }
            Record::Error(_) => {}
            Record::Consistency(r) => {
                r.t.into_iter()
                    .chain([r.nis_mean, r.expected])
                    .chain(r.band)
                    .for_each(&mut push)
            }
        }
        out
    }

    fn json(record: &Record) -> String {
        let mut out = Vec::new();
        encode_json(record, &mut out).unwrap();
        String::from_utf8(out).unwrap()
    }

    fn round_trip(record: &Record) -> Record {
        let mut out = Vec::new();
        encode_json(record, &mut out).unwrap();
        decode_record(&out).unwrap()
    }

    #[test]
    fn every_record_round_trips_bit_identically() {
        for record in all_records() {
            let back = round_trip(&record);
            assert_eq!(back, record);
            assert_eq!(float_bits(&back), float_bits(&record), "{record:?}");
        }
    }

    #[test]
    fn stat_json_shape() {
        let mut out = Vec::new();
        encode_json(&stat().into(), &mut out).unwrap();
        assert_eq!(
            std::str::from_utf8(&out).unwrap(),
            r#"{"type":"stat","channel":"pump3","k":12,"t":1732200000.25,"glr":0.30000000000000004,"onset":7,"magnitude":[1e-300,-0.0,2.5],"rank":3,"innovation":[0.1,-1.7976931348623157e+308],"threshold":13.8,"episode":{"onset":3,"magnitude":[1.25,-5e-324,0.0]}}"#
        );
        out.clear();
        encode_json(&stat_before_onset().into(), &mut out).unwrap();
        let text = std::str::from_utf8(&out).unwrap();
        assert!(
            text.contains(r#""glr":null,"onset":null,"magnitude":[]"#),
            "{text}"
        );
    }

    #[test]
    fn alarm_diagnosis_and_error_json_shape() {
        let mut out = Vec::new();
        encode_json(&alarm().into(), &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.starts_with(r#"{"type":"alarm","channel":"pump3","k":140,"t":null,"glr":87.5"#),
            "{text}"
        );
        assert!(text.contains(r#""isolation":[{"fault":"leak","minmax":40.25,"sensitivity":39.0,"threshold":6.63,"isolated":true,"ambiguous_with":[]},"#), "{text}");
        assert!(
            text.ends_with(r#""faults":["leak","bias"],"update_k":150}"#),
            "{text}"
        );
        let text = json(
            &Alarm {
                update_k: None,
                ..alarm()
            }
            .into(),
        );
        assert!(text.ends_with(r#","update_k":null}"#), "{text}");

        assert_eq!(
            json(&isolation_update().into()),
            r#"{"type":"isolation","channel":"pump3","k":150,"t":15.0,"alarm_k":140,"glr":80.25,"threshold":13.8,"onset":100,"magnitude":[0.5,-1e-300],"isolation":[{"fault":"leak","minmax":60.5,"sensitivity":61.0,"threshold":6.63,"isolated":true,"ambiguous_with":[]}],"faults":["leak","bias"]}"#
        );

        let text = json(&diagnosis().into());
        assert!(
            text.contains(r#""estimate":{"bias":-1e-300,"leak":0.7999999999999999}"#),
            "{text}"
        );
        assert!(
            text.contains(
                r#""plateau":[0.01,0.2],"residual":"kitanidis","path_support_sizes":[0,1,1,2]"#
            ),
            "{text}"
        );

        let text = json(&ErrorRecord { k: None, ..error() }.into());
        assert!(
            text.starts_with(
                r#"{"type":"error","channel":"pump3","k":null,"code":"wrong_dimension""#
            ),
            "{text}"
        );
        assert!(text.ends_with(r#""stage":"processing"}"#), "{text}");
    }

    #[test]
    fn channel_kind_and_key() {
        let kinds: Vec<_> = all_records().iter().map(Record::kind_str).collect();
        assert_eq!(
            kinds,
            [
                "stat",
                "stat",
                "stat",
                "alarm",
                "alarm",
                "isolation",
                "alarm_end",
                "diagnosis",
                "error",
                "error",
                "consistency"
            ]
        );
        for record in all_records() {
            assert_eq!(record.channel(), "pump3");
            assert!(RECORD_KINDS.contains(&record.kind_str()));
            assert_eq!(record.key(), format!("glrmon/pump3/{}", record.kind_str()));
            let json: Value = serde_json::from_str(&json(&record)).unwrap();
            assert_eq!(json["type"], record.kind_str());
            assert_eq!(json["channel"], "pump3");
        }
        assert_eq!(Record::from(alarm()).k(), Some(140));
        assert_eq!(Record::from(isolation_update()).k(), Some(150));
        assert_eq!(Record::from(ErrorRecord { k: None, ..error() }).k(), None);
    }

    #[test]
    fn non_finite_floats_are_encode_errors_even_in_options() {
        let cases: Vec<(Record, &str)> = vec![
            (
                Stat {
                    glr: Some(f64::NAN),
                    ..stat()
                }
                .into(),
                "glr",
            ),
            (
                Stat {
                    t: Some(f64::INFINITY),
                    ..stat()
                }
                .into(),
                "t",
            ),
            (
                Stat {
                    threshold: Some(f64::NEG_INFINITY),
                    ..stat()
                }
                .into(),
                "threshold",
            ),
            (
                Stat {
                    innovation: vec![0.0, f64::NAN],
                    ..stat()
                }
                .into(),
                "innovation[1]",
            ),
            (
                Stat {
                    innovation: Vec::new(),
                    residual: vec![0.5, 1.0, f64::INFINITY],
                    ..stat()
                }
                .into(),
                "residual[2]",
            ),
            (
                Stat {
                    episode: Some(EpisodeEstimate {
                        onset: 3,
                        magnitude: vec![1.0, 2.0, f64::INFINITY],
                    }),
                    ..stat()
                }
                .into(),
                "episode.magnitude[2]",
            ),
            (
                Alarm {
                    magnitude: vec![f64::NAN],
                    ..alarm()
                }
                .into(),
                "magnitude[0]",
            ),
            (
                Alarm {
                    isolation: vec![IsolationResult {
                        excluded: None,
                        sensitivity: f64::INFINITY,
                        ..alarm().isolation[0].clone()
                    }],
                    ..alarm()
                }
                .into(),
                "isolation[0].sensitivity",
            ),
            (
                IsolationUpdate {
                    isolation: vec![IsolationResult {
                        excluded: None,
                        minmax: f64::NAN,
                        ..isolation_update().isolation[0].clone()
                    }],
                    ..isolation_update()
                }
                .into(),
                "isolation[0].minmax",
            ),
            (
                IsolationUpdate {
                    glr: f64::INFINITY,
                    ..isolation_update()
                }
                .into(),
                "glr",
            ),
            (
                AlarmEnd {
                    peak_glr: f64::NAN,
                    ..alarm_end()
                }
                .into(),
                "peak_glr",
            ),
            (
                Diagnosis {
                    estimate: BTreeMap::from([("leak".into(), f64::NAN)]),
                    ..diagnosis()
                }
                .into(),
                "estimate.leak",
            ),
            (
                Diagnosis {
                    plateau: [0.0, f64::INFINITY],
                    ..diagnosis()
                }
                .into(),
                "plateau[1]",
            ),
            (
                Diagnosis {
                    lambda: f64::NAN,
                    ..diagnosis()
                }
                .into(),
                "lambda",
            ),
        ];
        for (record, field) in cases {
            let mut out = b"keep".to_vec();
            let err = encode_json(&record, &mut out).unwrap_err();
            assert_eq!(err.field, field);
            assert_eq!(err.code(), ErrorCode::NonFinite);
            assert!(
                err.to_string()
                    .starts_with(&format!(r#"channel "pump3": field {field} is "#)),
                "{err}"
            );
            assert_eq!(out, b"keep", "out unchanged on error");
        }
    }

    #[test]
    fn decode_ignores_unknown_fields_and_accepts_absent_options() {
        let rec = decode_record(
            br#"{"type":"alarm_end","channel":"c","k":1,"onset":0,"duration":2,"peak_glr":3,"future":{"x":[1]}}"#,
        )
        .unwrap();
        assert_eq!(
            rec,
            Record::AlarmEnd(AlarmEnd {
                channel: "c".into(),
                k: 1,
                t: None,
                onset: 0,
                duration: 2,
                peak_glr: 3.0
            })
        );
    }

    /// A `stat` of a glrmon from before `episode` existed decodes with none; one with
    /// an episode round-trips it, and a wrongly typed value in it is located.
    #[test]
    fn a_stat_without_episode_decodes_with_none_and_one_with_it_is_checked() {
        let rec = decode_record(
            br#"{"type":"stat","channel":"c","k":9,"t":null,"glr":2.5,"onset":7,"magnitude":[0.5],"rank":1,"innovation":[0.1],"threshold":13.8}"#,
        )
        .unwrap();
        let Record::Stat(s) = rec else {
            panic!("{rec:?}")
        };
        assert_eq!((s.k, s.onset, s.episode), (9, Some(7), None));

        let text = json(&stat().into());
        assert!(
            text.ends_with(
                r#""threshold":13.8,"episode":{"onset":3,"magnitude":[1.25,-5e-324,0.0]}}"#
            ),
            "{text}"
        );
        let none = json(&stat_before_onset().into());
        assert!(
            none.ends_with(r#""threshold":null,"episode":null}"#),
            "{none}"
        );

        let mut value: Value = serde_json::from_str(&text).unwrap();
        value["episode"]["magnitude"][1] = Value::from("big");
        assert_record_error(
            &value.to_string(),
            ErrorCode::WrongType,
            Some("episode.magnitude[1]"),
        );
        value["episode"] = serde_json::json!({"magnitude": [1.0]});
        assert_record_error(
            &value.to_string(),
            ErrorCode::MissingField,
            Some("episode.onset"),
        );
        value["episode"] = Value::from(3);
        let err = assert_record_error(&value.to_string(), ErrorCode::WrongType, Some("episode"));
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field episode has the wrong type: expected an object or null"#
        );
    }

    /// An `alarm` of a glrmon from before `update_k` existed (published after the
    /// isolation delay) still decodes, with no update scheduled.
    #[test]
    fn an_alarm_without_update_k_decodes_with_none() {
        let rec = decode_record(
            br#"{"type":"alarm","channel":"c","k":9,"t":null,"glr":20.5,"threshold":13.8,"onset":7,"magnitude":[1.5],"isolation":[],"faults":["leak"]}"#,
        )
        .unwrap();
        let Record::Alarm(a) = rec else {
            panic!("{rec:?}")
        };
        assert_eq!((a.k, a.onset, a.update_k), (9, 7, None));
    }

    fn assert_record_error(json: &str, code: ErrorCode, field: Option<&str>) -> DecodeError {
        let err = decode_record(json.as_bytes()).unwrap_err();
        assert_eq!(err.code(), code, "{json}: {err}");
        assert_eq!(err.field.as_deref(), field, "{json}: {err}");
        if let Some(field) = field {
            assert!(
                err.to_string().contains(&format!("field {field} ")),
                "{err}"
            );
        }
        err
    }

    #[test]
    fn decode_errors_name_channel_and_field() {
        let err = assert_record_error(
            r#"{"type":"alarm","channel":"pump3","k":1,"t":null,"glr":"high","threshold":1,"onset":0,"magnitude":[],"isolation":[],"faults":[]}"#,
            ErrorCode::WrongType,
            Some("glr"),
        );
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field glr has the wrong type: expected a number"#
        );
        assert_record_error(
            r#"{"channel":"pump3"}"#,
            ErrorCode::MissingField,
            Some("type"),
        );
        assert_record_error(
            r#"{"type":"status","channel":"pump3"}"#,
            ErrorCode::WrongType,
            Some("type"),
        );
        assert_record_error(
            r#"{"type":"error","k":1}"#,
            ErrorCode::MissingField,
            Some("channel"),
        );
        let err = assert_record_error(
            r#"{"type":"error","channel":"pump3","k":-1,"code":"gap","message":"","stage":"sending"}"#,
            ErrorCode::WrongType,
            Some("k"),
        );
        assert_eq!(err.channel, "pump3");
        assert_record_error(
            r#"{"type":"error","channel":"pump3","code":"bogus","message":"","stage":"sending"}"#,
            ErrorCode::WrongType,
            Some("code"),
        );
        assert_record_error(
            r#"{"type":"error","channel":"pump3","code":"gap","message":"","stage":"later"}"#,
            ErrorCode::WrongType,
            Some("stage"),
        );
        let mut alarm_json: Value = serde_json::from_str(&json(&alarm().into())).unwrap();
        alarm_json["isolation"][1]["isolated"] = Value::from("yes");
        assert_record_error(
            &alarm_json.to_string(),
            ErrorCode::WrongType,
            Some("isolation[1].isolated"),
        );
        alarm_json["isolation"][1] = Value::from(3);
        assert_record_error(
            &alarm_json.to_string(),
            ErrorCode::WrongType,
            Some("isolation[1]"),
        );

        let mut diag: Value = serde_json::from_str(&json(&diagnosis().into())).unwrap();
        diag["plateau"] = serde_json::json!([1.0, 2.0, 3.0]);
        let err = assert_record_error(
            &diag.to_string(),
            ErrorCode::WrongDimension,
            Some("plateau"),
        );
        assert_eq!(
            err.kind,
            DecodeErrorKind::WrongDimension {
                expected: 2,
                got: 3
            }
        );
        diag["plateau"] = serde_json::json!([1.0, 2.0]);
        diag["estimate"]["leak"] = Value::Null;
        assert_record_error(
            &diag.to_string(),
            ErrorCode::WrongType,
            Some("estimate.leak"),
        );
    }

    #[test]
    fn decode_syntax_and_shape_errors() {
        assert_record_error("", ErrorCode::InvalidJson, None);
        assert_record_error(r#"{"type":"stat""#, ErrorCode::InvalidJson, None);
        assert_record_error(r#"{"type":"stat","glr":1e999}"#, ErrorCode::NonFinite, None);
        assert_record_error("[1,2]", ErrorCode::WrongType, None);
        assert_record_error(
            r#"["error","c",null,"gap","m","sending"]"#,
            ErrorCode::WrongType,
            None,
        );
        assert_record_error("null", ErrorCode::WrongType, None);
        assert_record_error(
            r#"{"type":"alarm_end","channel":"c","k":1,"k":2,"onset":0,"duration":2,"peak_glr":3}"#,
            ErrorCode::Duplicate,
            Some("k"),
        );
    }

    /// Each record's JSON Schema lists exactly the fields it serializes (a record may
    /// leave out only the fields the schema does not require: a stat's empty
    /// `residual`), requires those that are not `Option`s (which may be absent or
    /// `null`) or defaulted, and locates a wrongly typed or missing value in any of them.
    #[test]
    fn schema_matches_serialized_fields() {
        for record in all_records() {
            let kind = record.kind_str();
            let Value::Object(obj) = serde_json::from_str::<Value>(&json(&record)).unwrap() else {
                panic!("record is not an object");
            };
            let schema = record_schema(kind).unwrap();
            assert_eq!(schema["properties"]["type"]["const"], kind);
            let properties = schema["properties"].as_object().unwrap();
            let is_required = |name: &str| {
                schema["required"]
                    .as_array()
                    .unwrap()
                    .contains(&Value::from(name))
            };
            let mut want: Vec<&String> = properties
                .keys()
                .filter(|name| obj.contains_key(*name) || is_required(name))
                .collect();
            let mut got: Vec<&String> = obj.keys().collect();
            want.sort_unstable();
            got.sort_unstable();
            assert_eq!(got, want, "{kind}");

            for (name, property) in properties
                .iter()
                .filter(|(name, _)| *name != "type" && obj.contains_key(*name))
            {
                let required = is_required(name);
                let defaulted = kind == "stat" && name == "residual";
                assert_eq!(
                    required,
                    !allows(property, "null") && !defaulted,
                    "{kind}.{name}"
                );

                let mut bad = obj.clone();
                let wrong = if allows(property, "string") {
                    Value::from(7)
                } else {
                    Value::from("x")
                };
                bad.insert(name.clone(), wrong);
                let text = Value::Object(bad).to_string();
                let err = decode_record(text.as_bytes()).unwrap_err();
                assert_eq!(err.field.as_deref(), Some(name.as_str()), "{text}: {err}");
                assert_eq!(err.code(), ErrorCode::WrongType);

                let mut missing = obj.clone();
                missing.remove(name);
                let text = Value::Object(missing).to_string();
                match decode_record(text.as_bytes()) {
                    Err(err) => {
                        assert!(required, "{text}: {err}");
                        assert_eq!(err.field.as_deref(), Some(name.as_str()), "{text}: {err}");
                        assert_eq!(err.code(), ErrorCode::MissingField);
                    }
                    Ok(_) => assert!(!required, "{text}"),
                }
            }
        }
    }

    /// A wrongly typed value is reported with what its field accepts, in words.
    #[test]
    fn decode_errors_say_what_the_field_expects() {
        for (record, field, expected) in [
            (Record::from(diagnosis()), "k", "a non-negative integer"),
            (diagnosis().into(), "plateau", "an array of 2 numbers"),
            (
                diagnosis().into(),
                "path_coefficients",
                "an array of arrays of numbers",
            ),
            (diagnosis().into(), "estimate", "an object of numbers"),
            (diagnosis().into(), "residual", "one of kalman, kitanidis"),
            (alarm().into(), "t", "a number or null"),
            (alarm().into(), "isolation", "an array of objects"),
            (alarm().into(), "faults", "an array of strings"),
            (
                error().into(),
                "stage",
                "one of receiving, processing, sending",
            ),
        ] {
            let mut value: Value = serde_json::from_str(&json(&record)).unwrap();
            value[field] = Value::from(true);
            let err = decode_record(value.to_string().as_bytes()).unwrap_err();
            assert_eq!(
                err.to_string(),
                format!(
                    r#"channel "pump3": field {field} has the wrong type: expected {expected}"#
                )
            );
        }
    }

    #[test]
    fn error_record_from_decode_error() {
        let err = DecodeError::new("pump3", Some("y[2]".into()), DecodeErrorKind::NonFinite);
        let rec = ErrorRecord::from_decode_error(&err, Some(9), Stage::Receiving);
        assert_eq!(rec.code, ErrorCode::NonFinite);
        assert_eq!(
            rec.message,
            r#"channel "pump3": field y[2] is not a finite number"#
        );
        assert_eq!(round_trip(&rec.clone().into()), Record::Error(rec));
    }

    fn finite_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<u64>()
                .prop_map(f64::from_bits)
                .prop_filter("finite", |v| v.is_finite()),
            any::<f64>().prop_filter("finite", |v| v.is_finite()),
            Just(-0.0),
        ]
    }

    fn floats() -> impl Strategy<Value = Vec<f64>> {
        proptest::collection::vec(finite_f64(), 0..5)
    }

    fn arb_record() -> impl Strategy<Value = Record> {
        let name = "[a-z_]{1,8}";
        prop_oneof![
            (
                any::<u64>(),
                proptest::option::of(finite_f64()),
                proptest::option::of(finite_f64()),
                floats(),
                floats(),
                proptest::option::of(floats())
            )
                .prop_map(|(k, t, glr, magnitude, innovation, episode)| {
                    Record::from(Stat {
                        k,
                        t,
                        glr,
                        onset: glr.map(|_| k / 2),
                        rank: magnitude.len(),
                        magnitude,
                        innovation,
                        episode: episode.map(|magnitude| EpisodeEstimate {
                            onset: k / 3,
                            magnitude,
                        }),
                        ..stat()
                    })
                }),
            (
                finite_f64(),
                finite_f64(),
                finite_f64(),
                floats(),
                proptest::bool::ANY,
                name
            )
                .prop_map(|(glr, minmax, sensitivity, magnitude, isolated, fault)| {
                    Record::from(Alarm {
                        glr,
                        magnitude,
                        isolation: vec![IsolationResult {
                            excluded: None,
                            fault: fault.clone(),
                            minmax,
                            sensitivity,
                            threshold: glr,
                            isolated,
                            ambiguous_with: vec![fault.clone()],
                        }],
                        ..alarm()
                    })
                }),
            (
                finite_f64(),
                floats(),
                proptest::option::of(finite_f64()),
                any::<u64>()
            )
                .prop_map(|(glr, magnitude, t, alarm_k)| {
                    Record::from(IsolationUpdate {
                        glr,
                        magnitude,
                        t,
                        alarm_k,
                        ..isolation_update()
                    })
                }),
            (proptest::option::of(finite_f64()), finite_f64()).prop_map(|(t, peak_glr)| {
                Record::from(AlarmEnd {
                    t,
                    peak_glr,
                    ..alarm_end()
                })
            }),
            (
                proptest::collection::btree_map(name, finite_f64(), 0..4),
                finite_f64(),
                finite_f64(),
                finite_f64()
            )
                .prop_map(|(estimate, lambda, lo, hi)| Record::from(Diagnosis {
                    estimate,
                    lambda,
                    plateau: [lo, hi],
                    ..diagnosis()
                })),
            (
                proptest::option::of(any::<u64>()),
                ".{0,20}",
                proptest::sample::select(ErrorCode::ALL.to_vec())
            )
                .prop_map(|(k, message, code)| Record::from(ErrorRecord {
                    k,
                    message,
                    code,
                    ..error()
                })),
        ]
    }

    proptest! {
        /// encode_json → decode_record is the identity, every float bit for bit,
        /// over arbitrary finite bit patterns (subnormals, -0.0, extremes).
        #[test]
        fn record_round_trip_is_bit_identical(record in arb_record()) {
            let back = round_trip(&record);
            prop_assert_eq!(float_bits(&back), float_bits(&record));
            prop_assert_eq!(back, record);
        }
    }
}
