//! glrmon's configuration: a strict TOML file describing a deployment (Zenoh and
//! recording settings, and a list of channels with their model, fault dictionary and
//! GLR settings), parsed and validated into core types.
//!
//! Every error names its path and the reason, e.g.
//! `channels[1] "pump3": model.F is 3×2 but H has 3 columns`; all errors of a file are
//! reported, not only the first.
//!
//! ```
//! let cfg = glrmon_spec::parse(r#"
//! [[channels]]
//! name = "tank"
//! model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
//! faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
//! "#).unwrap();
//! assert_eq!(cfg.channels[0].key, "plant/tank");
//! let detector = cfg.channels[0].detector().unwrap();
//! assert_eq!((detector.kind(), detector.faults().len()), ("glr", 1));
//! ```
#![warn(missing_docs)]

pub mod covariance;
mod detector;
pub mod edit;
pub mod expr;
pub mod keys;
pub mod limits;
mod locate;
mod payload;
pub mod reference;
pub mod schema;
pub mod template;
pub mod write;

use std::fmt;
use std::path::Path;

use glrmon_core::calibration::Target;
use glrmon_core::kitanidis::unknown_input_rank;
use glrmon_core::sparse::{LassoSettings, PlateauScale};
use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{
    AlarmSettings, Column, DEFAULT_RANK_TOLERANCE, Dims, Fault, FaultDictionary, Lpv, LpvMatrix,
    ModelError, Onset, SignalScaling, WindowSettings,
};
use nalgebra::{DMatrix, DVector};

pub use crate::covariance::PSD_TOLERANCE;
use crate::covariance::Verdict;
pub use crate::detector::DetectorKind;
use crate::expr::{Expr, ExprColumn, ExprContext};
pub use crate::locate::did_you_mean;
pub use crate::payload::PayloadFormat;
use crate::schema::{
    ChannelSpec, ConfigFile, DaemonSpec, DiagnosisSpec, EntrySpec, FaultSpec, MatrixSpec,
    RecordingSpec, ZenohSpec,
};

/// One problem in a configuration, with the path of the offending field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Where, e.g. `channels[1] "pump3": faults[2].psi[0]`.
    pub path: String,
    /// Why.
    pub message: String,
    /// The line and column of the offending key (or of the deepest enclosing key the
    /// file has) in the TOML text, when known.
    pub location: Option<Location>,
}

/// A position in the configuration's text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Location {
    /// Line, from 1.
    pub line: usize,
    /// Column in characters, from 1.
    pub column: usize,
}

impl Problem {
    /// The problem as a compiler prints it, `file.toml:12:5: channels[0] "a": …` (the
    /// file alone when the location is unknown).
    ///
    /// ```
    /// let text = "[[channels]]\nname = \"a\"\n[channels.model]\nF = [[0.9]]\nH = [[1.0, 0.0]]\nQ = 0.01\nR = 0.04\n";
    /// let errors = glrmon_spec::parse(text).unwrap_err();
    /// assert!(errors.errors.iter().any(|e| e
    ///     .in_file("plant.toml")
    ///     .starts_with("plant.toml:4:1: channels[0] \"a\": model.F is 1×1 but H has 2 columns")));
    /// ```
    #[must_use]
    pub fn in_file(&self, file: &str) -> String {
        match self.location {
            Some(l) => format!("{file}:{}:{}: {}", l.line, l.column, Body(self)),
            None => format!("{file}: {}", Body(self)),
        }
    }
}

/// A problem's path and message, without its location.
struct Body<'a>(&'a Problem);

impl fmt::Display for Body<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.0;
        // "model.F is 3×2 but …" reads as a sentence; other reasons follow a colon.
        let verb = ["is ", "has ", "names ", "cannot ", "evaluates ", "drives "];
        if p.path.is_empty() {
            write!(f, "{}", p.message)
        } else if verb.iter().any(|v| p.message.starts_with(v)) {
            write!(f, "{} {}", p.path, p.message)
        } else {
            write!(f, "{}: {}", p.path, p.message)
        }
    }
}

impl fmt::Display for Problem {
    /// The path and the message, `channels[0] "a": …`; [`Problem::in_file`] adds the
    /// file and the location, `file:12:5: …`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", Body(self))
    }
}

/// Every error found in a configuration.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct SpecErrors {
    /// The errors, in file order.
    pub errors: Vec<Problem>,
}

impl SpecErrors {
    /// Every problem as [`Problem::in_file`] prints it, one per line:
    /// `file.toml:12:5: channels[0] "a": …`.
    #[must_use]
    pub fn in_file(&self, file: &str) -> String {
        let lines: Vec<String> = self.errors.iter().map(|e| e.in_file(file)).collect();
        lines.join("\n")
    }
}

impl fmt::Display for SpecErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.errors.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

/// A validated configuration.
#[derive(Debug, Clone)]
pub struct Config {
    /// Zenoh settings.
    pub zenoh: ZenohSpec,
    /// Recording settings.
    pub recording: RecordingSpec,
    /// Daemon settings.
    pub daemon: DaemonSpec,
    /// The channels.
    pub channels: Vec<Channel>,
    /// Problems that do not prevent running (e.g. an unobservable model).
    pub warnings: Vec<Problem>,
    /// The TOML text the configuration was parsed from (recorded with the data).
    pub source: String,
}

/// The keys of a channel's `[channels.glr]` table that a reload (SIGHUP) applies to the
/// running monitor: the detection threshold and how it is set, the alarm episode
/// settings, and the isolation tests' delay, level and thresholds. Everything else
/// shapes the filters and needs a restart.
pub const RELOADABLE_GLR_KEYS: [&str; 8] = [
    "threshold",
    "false_alarm",
    "threshold_mode",
    "calibrated",
    "hysteresis",
    "clear_samples",
    "isolation_delay",
    "isolation_alpha",
];

/// A shard of the channels of a configuration: the channels whose name hashes to
/// `index` modulo `count` (FNV-1a, 64 bits, over the name's UTF-8 bytes: the same on
/// every machine and in every release, so a fleet started from one configuration
/// splits it the same way every time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// i, from 0.
    pub index: u32,
    /// N, at least 1.
    pub count: u32,
}

impl Shard {
    /// Whether the channel named `name` belongs to this shard.
    #[must_use]
    pub fn owns(&self, name: &str) -> bool {
        shard_hash(name) % u64::from(self.count) == u64::from(self.index)
    }
}

/// FNV-1a (64 bits) of the name: the stable hash that assigns channels to shards.
#[must_use]
pub fn shard_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `"i/N"` with 0 ≤ i < N.
    fn from_str(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("\"{s}\" is not of the form i/N (e.g. 0/2)"))?;
        let index: u32 = i
            .trim()
            .parse()
            .map_err(|_| format!("\"{s}\": shard index \"{i}\" is not a whole number"))?;
        let count: u32 = n
            .trim()
            .parse()
            .map_err(|_| format!("\"{s}\": shard count \"{n}\" is not a whole number"))?;
        if count == 0 || index >= count {
            return Err(format!(
                "\"{s}\": the index must be below the count (shards 0/{count} … {}/{count})",
                count.saturating_sub(1)
            ));
        }
        Ok(Self { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Config {
    /// The channels of `shard` only (all when `None`), the others dropped.
    #[must_use]
    pub fn into_shard(mut self, shard: Option<Shard>) -> Self {
        if let Some(s) = shard {
            self.channels.retain(|c| s.owns(&c.name));
        }
        self
    }

    /// What stands between this configuration and `new` for a reload without a
    /// restart (SIGHUP): every changed setting other than a channel's thresholds and
    /// alarm settings ([`RELOADABLE_GLR_KEYS`]), as a path with the reason, e.g.
    /// `channels "pump3".model: changed (needs a restart: the filters depend on it)`.
    /// Empty when `new` can be applied by retuning the running monitors.
    #[must_use]
    pub fn restart_needed(&self, new: &Config) -> Vec<String> {
        let parse = |text: &str| text.parse::<toml::Table>().unwrap_or_default();
        let (old, new) = (parse(&self.source), parse(&new.source));
        let mut out = Vec::new();
        let keys: std::collections::BTreeSet<&String> = old.keys().chain(new.keys()).collect();
        for key in keys.into_iter().filter(|k| *k != "channels") {
            if old.get(key) != new.get(key) {
                out.push(format!("[{key}]: changed (needs a restart)"));
            }
        }
        let channels = |t: &toml::Table| -> Vec<(String, toml::Table)> {
            t.get("channels")
                .and_then(toml::Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(toml::Value::as_table)
                        .map(|c| {
                            let name = c.get("name").and_then(toml::Value::as_str).unwrap_or("");
                            (name.to_owned(), c.clone())
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        let (before, after) = (channels(&old), channels(&new));
        for (name, _) in &before {
            if !after.iter().any(|(n, _)| n == name) {
                out.push(format!("channels \"{name}\": removed (needs a restart)"));
            }
        }
        for (name, table) in &after {
            let Some((_, was)) = before.iter().find(|(n, _)| n == name) else {
                out.push(format!("channels \"{name}\": added (needs a restart)"));
                continue;
            };
            let strip = |t: &toml::Table| {
                let mut t = t.clone();
                if let Some(toml::Value::Table(glr)) = t.get_mut("glr") {
                    for k in RELOADABLE_GLR_KEYS {
                        glr.remove(k);
                    }
                }
                t
            };
            let (a, b) = (strip(was), strip(table));
            let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            for key in keys {
                if a.get(key) != b.get(key) {
                    out.push(format!(
                        "channels \"{name}\".{key}: changed (needs a restart: only glr.{} are reloaded)",
                        RELOADABLE_GLR_KEYS.join(", glr.")
                    ));
                }
            }
        }
        out
    }

    /// The channel named `name`.
    #[must_use]
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }

    /// The channel a tool works on: the one named, or the only one when no name is
    /// given.
    ///
    /// # Errors
    /// [`ChannelChoiceError`] when the name is not a channel of the configuration,
    /// or no name is given and there are several channels (or none).
    ///
    /// # Examples
    /// ```
    /// let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
    /// assert_eq!(cfg.pick_channel(Some("unstable")).unwrap().name, "unstable");
    /// let err = cfg.pick_channel(None).unwrap_err();
    /// assert_eq!(err.to_string(), "the configuration has several channels: choose one with --channel");
    /// ```
    pub fn pick_channel(&self, name: Option<&str>) -> Result<&Channel, ChannelChoiceError> {
        match name {
            Some(n) => self.channel(n).ok_or_else(|| ChannelChoiceError::Unknown {
                name: n.to_owned(),
                channels: self.channels.iter().map(|c| c.name.clone()).collect(),
            }),
            None => match self.channels.as_slice() {
                [only] => Ok(only),
                _ => Err(ChannelChoiceError::Ambiguous),
            },
        }
    }
}

/// Why [`Config::pick_channel`] found no channel.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ChannelChoiceError {
    /// No channel has that name.
    #[error(
        "no channel \"{name}\" in the configuration (channels: {}){}",
        channels.join(", "),
        channel_suggestion(name, channels)
    )]
    Unknown {
        /// The name asked for.
        name: String,
        /// The configuration's channels.
        channels: Vec<String>,
    },
    /// No name was given and the configuration does not have exactly one channel.
    #[error("the configuration has several channels: choose one with --channel")]
    Ambiguous,
}

/// `; did you mean "x"?` when a channel's name is close to `name`.
fn channel_suggestion(name: &str, channels: &[String]) -> String {
    let names: Vec<&str> = channels.iter().map(String::as_str).collect();
    did_you_mean(name, &names).map_or_else(String::new, |s| format!("; did you mean \"{s}\"?"))
}

/// How a fault column is computed.
#[derive(Debug, Clone)]
enum ColumnPlan {
    Zero,
    Constant(DVector<f64>),
    InputBias(usize),
    GainLoss(usize),
    Exprs(Vec<Expr>),
}

#[derive(Debug, Clone)]
struct FaultPlan {
    name: String,
    onset: Onset,
    state: ColumnPlan,
    output: ColumnPlan,
}

/// How the detection threshold was set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ThresholdSource {
    /// Given explicitly.
    Explicit,
    /// χ²(m) upper quantile at α/(w − s) for a per-sample false-alarm probability α.
    Bonferroni {
        /// α.
        false_alarm: f64,
    },
    /// χ²(m) upper quantile at α: right for one onset, optimistic for the window.
    Chi2 {
        /// α.
        false_alarm: f64,
    },
    /// Found by `glrmon calibrate` on fault-free data.
    Calibrated {
        /// What it was calibrated for: a mean number of samples between false-alarm
        /// episodes, or a fraction of samples above λ.
        target: glrmon_core::calibration::Target,
        /// Samples used.
        samples: u64,
        /// Episodes at λ on them (for a per-sample target, clusters of exceedances).
        episodes: u64,
        /// Samples above λ among them, when recorded.
        exceedances: Option<u64>,
        /// 95 % confidence interval of λ.
        interval: [f64; 2],
    },
}

/// PI controller of a simulated channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Controller {
    /// Output measured.
    pub output: usize,
    /// Input driven.
    pub input: usize,
    /// Setpoint.
    pub setpoint: f64,
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
}

/// How `glrmon simulate` drives a channel: expressions of k (random functions allowed).
#[derive(Debug, Clone, Default)]
pub struct SimulationPlan {
    /// U_k, one per input (missing ones are 0).
    pub inputs: Vec<Expr>,
    /// p(k), one per signal (missing ones are 0).
    pub signals: Vec<Expr>,
    /// d_k entering through E.
    pub unknown_input: Vec<Expr>,
    /// Optional PI controller.
    pub controller: Option<Controller>,
}

/// The residual generator of sparse diagnosis (Zhang 2021, §III).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResidualKind {
    /// The Kalman filter's updated output error ỹ_{k|k} (Zhang 2021, §III-A, eqs. (4)-(7)):
    /// assumes no unknown input.
    Kalman,
    /// The Kitanidis filter's output error ỹ_k (Zhang 2021, §III-B, eqs. (24)-(27)):
    /// decoupled from the unknown input E d_k; needs E and Assumption (iv).
    Kitanidis,
}

impl ResidualKind {
    /// `"kalman"` or `"kitanidis"`, as in the configuration and the `diagnosis` record.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            ResidualKind::Kalman => "kalman",
            ResidualKind::Kitanidis => "kitanidis",
        }
    }
}

impl fmt::Display for ResidualKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Sparse diagnosis settings of a channel (`[channels.diagnosis]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiagnosisSettings {
    /// Whether the monitor runs a diagnosis at every alarm.
    pub enabled: bool,
    /// The residual generator.
    pub residual: ResidualKind,
    /// Largest number of samples in the regression (`None`: from r̂ to the alarm).
    pub span: Option<usize>,
    /// Samples of filter quantities kept for the regression (at least 2).
    pub history: usize,
    /// The Lasso path (Zhang 2021, eq. (39)).
    pub lasso: LassoSettings,
    /// Level α of the no-fault test before the λ rule, in (0, 1] (1: no test).
    pub alpha: f64,
}

/// Default level of the sparse diagnosis's no-fault test: as `glr.isolation_alpha`.
pub const DEFAULT_DIAGNOSIS_ALPHA: f64 = 0.01;

/// The CSV column names of a channel's inputs, outputs and signals.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Columns {
    /// The column read into u_i, for each input.
    pub u: Vec<String>,
    /// The column read into y_i, for each output.
    pub y: Vec<String>,
    /// The column read into p_i, for each scheduling signal.
    pub p: Vec<String>,
    /// The names were given (`[channels.columns]`): a file's other columns are skipped.
    /// Otherwise they are the numbered names and an unknown column is an error.
    pub named: bool,
}

impl Columns {
    /// `u0…u{l−1}`, `y0…`, `p0…`: the default names.
    #[must_use]
    pub fn numbered(dims: Dims) -> Self {
        let names =
            |prefix: char, count: usize| (0..count).map(|i| format!("{prefix}{i}")).collect();
        Self {
            u: names('u', dims.inputs),
            y: names('y', dims.outputs),
            p: names('p', dims.signals),
            named: false,
        }
    }
}

/// A validated channel.
#[derive(Debug, Clone)]
pub struct Channel {
    /// Unique name.
    pub name: String,
    /// Input key expression.
    pub key: String,
    /// How its payloads are encoded.
    pub payload: PayloadFormat,
    /// Sample period in seconds, if given.
    pub period: Option<f64>,
    /// Dimensions.
    pub dims: Dims,
    /// The model.
    pub model: Lpv,
    /// Unknown-input matrix E (n×q, constant or LPV), if given.
    pub unknown_input: Option<LpvMatrix>,
    /// Cross-covariance S = E(W_kV_kᵀ) (n×p) of the noises, if given.
    pub cross_covariance: Option<DMatrix<f64>>,
    /// Raw plant units → model units (`[channels.scaling]`), applied on intake.
    pub scaling: Option<SignalScaling>,
    /// The CSV column names of the signals (`[channels.columns]`).
    pub columns: Columns,
    /// X̂_0.
    pub x0: DVector<f64>,
    /// P_0.
    pub p0: DMatrix<f64>,
    /// GLR window.
    pub window: WindowSettings,
    /// Detection threshold and hysteresis.
    pub alarm: AlarmSettings,
    /// How the threshold was set.
    pub threshold_source: ThresholdSource,
    /// Samples between crossing and isolation.
    pub isolation_delay: u32,
    /// Type-I probability of each isolation test.
    pub isolation_alpha: f64,
    /// Isolation groups `(name, fault indices)`.
    pub groups: Vec<(String, Vec<usize>)>,
    /// Calibrated isolation thresholds by test name (`[channels.glr.calibrated]
    /// isolation`), replacing the χ² quantile of those tests.
    pub isolation_thresholds: Vec<(String, f64)>,
    /// The detection method ([`Channel::detector`] builds it).
    pub detector_kind: DetectorKind,
    /// Largest gap filled by predict-only steps.
    pub max_gap: u64,
    /// How many indices before the last processed one a sample is refused as late;
    /// further back is a sequence reset.
    pub max_reorder: u64,
    /// Fault names in dictionary order.
    pub fault_names: Vec<String>,
    /// Simulation settings.
    pub simulation: SimulationPlan,
    /// Sparse diagnosis settings.
    pub diagnosis: DiagnosisSettings,
    /// The filter-consistency test, when enabled.
    pub consistency: Option<glrmon_core::consistency::ConsistencySettings>,
    faults: Vec<FaultPlan>,
    /// The configuration path of each fault, in dictionary order (`channels[0] "x":
    /// faults[1]`, or `… faults[0] (y2)` for an expanded shortcut).
    fault_paths: Vec<String>,
}

impl Channel {
    /// A fresh fault dictionary (expression columns keep per-channel history, so each
    /// detector or simulator gets its own).
    ///
    /// # Errors
    /// As [`FaultDictionary::new`] (not expected after validation).
    pub fn dictionary(&self) -> Result<FaultDictionary, ModelError> {
        let d = self.dims;
        let column = |plan: &ColumnPlan| match plan {
            ColumnPlan::Zero => Column::Zero,
            ColumnPlan::Constant(v) => Column::Constant(v.clone()),
            ColumnPlan::InputBias(i) => Column::InputBias { input: *i },
            ColumnPlan::GainLoss(i) => Column::GainLoss { input: *i },
            ColumnPlan::Exprs(e) => {
                Column::Custom(Box::new(ExprColumn::new(e.clone(), d.inputs, d.signals)))
            }
        };
        let faults = self
            .faults
            .iter()
            .map(|f| Fault {
                name: f.name.clone(),
                onset: f.onset,
                state: column(&f.state),
                output: column(&f.output),
            })
            .collect();
        FaultDictionary::new(d, faults)
    }

    /// The degrees of freedom of the detector's whitened innovation: p, or p − q with
    /// q unknown inputs, which the detector decouples (Zhang 2021 §III-B).
    #[must_use]
    pub fn innovation_dof(&self) -> usize {
        self.dims.outputs - self.unknown_input.as_ref().map_or(0, |e| e.shape().1)
    }

    /// The configuration path of fault `index` (dictionary order), e.g.
    /// `channels[0] "pump3": faults[1]`, for messages that name the field at fault.
    #[must_use]
    pub fn fault_path(&self, index: usize) -> Option<&str> {
        self.fault_paths.get(index).map(String::as_str)
    }

    /// Whether the model's matrices (and E, if any) are constant (LTI).
    #[must_use]
    pub fn model_is_constant(&self) -> bool {
        use glrmon_core::StateSpace as _;
        self.model.is_constant()
            && (self.unknown_input.as_ref()).is_none_or(|e| e.terms().is_empty())
    }

    /// The onset profiles of the faults, in dictionary order.
    #[must_use]
    pub fn onsets(&self) -> Vec<Onset> {
        self.faults.iter().map(|f| f.onset).collect()
    }
}

fn validate_recording(v: &mut Validator, r: &schema::RecordingSpec) {
    let positive = |x: f64| x.is_finite() && x > 0.0;
    for (field, value) in [
        ("max_file_mb", r.max_file_mb),
        ("max_file_seconds", r.max_file_seconds),
        ("flush_seconds", r.flush_seconds),
    ] {
        if !positive(value) {
            v.error(
                format!("recording.{field}"),
                format!("{value} must be finite and positive"),
            );
        }
    }
    if let Some(cap) = r.max_total_mb {
        if !positive(cap) {
            v.error(
                "recording.max_total_mb".into(),
                format!("{cap} must be finite and positive"),
            );
        } else if cap < r.max_file_mb {
            v.error(
                "recording.max_total_mb".into(),
                format!(
                    "{cap} MB is less than one file (max_file_mb = {} MB): the cap would \
                     delete every finished recording",
                    r.max_file_mb
                ),
            );
        }
    }
    if r.flush_seconds > 60.0 {
        v.error(
            "recording.flush_seconds".into(),
            format!(
                "{} s: at most 60, so that a crash loses little",
                r.flush_seconds
            ),
        );
    }
    if !(1..=1 << 20).contains(&r.chunk_kb) {
        v.error(
            "recording.chunk_kb".into(),
            format!("{} is not in 1..=1048576", r.chunk_kb),
        );
    }
    if !matches!(r.compression.as_str(), "zstd" | "none") {
        v.error(
            "recording.compression".into(),
            locate::not_one_of(&r.compression, &["zstd", "none"]),
        );
    }
    if r.queue == 0 {
        v.error("recording.queue".into(), "must be positive".into());
    }
    if r.queue > limits::MAX_QUEUE {
        v.error(
            "recording.queue".into(),
            format!(
                "{} is more than {} (limits::MAX_QUEUE)",
                r.queue,
                limits::MAX_QUEUE
            ),
        );
    }
    if r.prefix.is_empty() || r.prefix.contains(['/', '\\']) {
        v.error(
            "recording.prefix".into(),
            format!("\"{}\" must be a non-empty file name part", r.prefix),
        );
    }
    if let Some(c) = r.capture {
        for (field, value) in [
            ("before_seconds", c.before_seconds),
            ("after_seconds", c.after_seconds),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                v.error(
                    format!("recording.capture.{field}"),
                    format!("{value} must be finite and non-negative"),
                );
            } else if value > limits::MAX_CAPTURE_SECONDS {
                v.error(
                    format!("recording.capture.{field}"),
                    format!(
                        "{value} s is more than {} s (limits::MAX_CAPTURE_SECONDS)",
                        limits::MAX_CAPTURE_SECONDS
                    ),
                );
            }
        }
    }
}

/// The JSON Schema (draft 7) of a configuration file, pretty-printed: derived from the
/// very types the TOML is deserialised into ([`schema::ConfigFile`]), with their doc
/// comments as descriptions and their defaults. Editors that validate TOML against a
/// JSON Schema (taplo, VS Code's Even Better TOML) complete and check keys with it;
/// `glrmon config schema` prints it.
///
/// It checks what the types check (keys, types, the keyword lists); the rest (shapes
/// against n, p and l, expressions, limits) is [`parse`]'s.
///
/// ```
/// let schema: serde_json::Value = serde_json::from_str(&glrmon_spec::json_schema()).unwrap();
/// assert_eq!(schema["title"], "glrmon configuration");
/// ```
#[must_use]
pub fn json_schema() -> String {
    let generator = schemars::generate::SchemaSettings::draft07().into_generator();
    let mut schema = generator.into_root_schema_for::<ConfigFile>();
    schema.insert("title".into(), "glrmon configuration".into());
    let mut value = schema.to_value();
    unwrap_descriptions(&mut value);
    // Serialising a `serde_json::Value` cannot fail.
    serde_json::to_string_pretty(&value).unwrap_or_default()
}

/// Doc comments are wrapped at 88 columns: their line breaks become spaces in the
/// schema's descriptions (an editor wraps them itself); blank lines stay paragraphs.
fn unwrap_descriptions(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map.iter_mut() {
                if key == "description"
                    && let serde_json::Value::String(text) = v
                {
                    *text = text
                        .split("\n\n")
                        .map(|p| p.split('\n').collect::<Vec<_>>().join(" "))
                        .collect::<Vec<_>>()
                        .join("\n\n");
                } else {
                    unwrap_descriptions(v);
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(unwrap_descriptions),
        _ => {}
    }
}

/// Reads and validates a configuration file.
///
/// # Errors
/// [`SpecErrors`] with every problem found (an unreadable file is one problem).
pub fn load(path: &Path) -> Result<Config, SpecErrors> {
    let text = std::fs::read_to_string(path).map_err(|e| SpecErrors {
        errors: vec![Problem {
            path: path.display().to_string(),
            message: format!("cannot read: {e}"),
            location: None,
        }],
    })?;
    parse(&text)
}

/// Parses and validates a configuration from TOML text.
///
/// # Errors
/// [`SpecErrors`] with every problem found.
pub fn parse(text: &str) -> Result<Config, SpecErrors> {
    let file: ConfigFile = toml::from_str(text).map_err(|e| {
        let spans = locate::Spans::new(text);
        // A syntax error keeps toml's rendering (its line, and the line quoted with a
        // caret); an error of the schema (an unknown key, a wrong type) is located
        // and, for an unknown key, gets the closest known one.
        let problem = match e.span() {
            Some(span) if spans.parsed() => Problem {
                path: String::new(),
                message: locate::with_field_suggestion(e.message().trim_end()),
                location: Some(spans.location(span.start)),
            },
            _ => Problem {
                path: String::new(),
                message: e.to_string().trim_end().to_owned(),
                location: None,
            },
        };
        SpecErrors {
            errors: vec![problem],
        }
    })?;
    let mut v = Validator::default();
    if file.channels.is_empty() {
        v.error(
            String::new(),
            "no channels: add at least one [[channels]] table".into(),
        );
    }
    if let Some(mode) = &file.zenoh.mode
        && !matches!(mode.as_str(), "peer" | "client" | "router")
    {
        v.error(
            "zenoh.mode".into(),
            locate::not_one_of(mode, &["peer", "client", "router"]),
        );
    }
    for (field, endpoints) in [
        ("zenoh.connect", &file.zenoh.connect),
        ("zenoh.listen", &file.zenoh.listen),
    ] {
        for (i, e) in endpoints.iter().enumerate() {
            if let Err(why) = check_endpoint(e) {
                v.error(format!("{field}[{i}]"), why);
            }
        }
    }
    let d = &file.daemon;
    if d.workers == Some(0)
        || d.worker_queue == 0
        || d.output_queue == 0
        || d.max_payload_bytes == 0
    {
        v.error(
            "daemon".into(),
            "workers, worker_queue, output_queue and max_payload_bytes must be positive".into(),
        );
    }
    for (field, mb) in [
        ("worker_queue_mb", d.worker_queue_mb),
        ("intake_mb", d.intake_mb),
    ] {
        // At least one payload of the largest accepted size must fit.
        let least = d.max_payload_bytes as f64 / (1024.0 * 1024.0);
        if !(mb.is_finite() && mb >= least && mb <= 1024.0 * 1024.0) {
            v.error(
                format!("daemon.{field}"),
                format!("{mb} must be between max_payload_bytes ({least} MiB) and 1048576 MiB"),
            );
        }
    }
    for (field, value, max) in [
        ("workers", d.workers.unwrap_or(1), limits::MAX_WORKERS),
        ("worker_queue", d.worker_queue, limits::MAX_QUEUE),
        ("output_queue", d.output_queue, limits::MAX_QUEUE),
        (
            "max_payload_bytes",
            d.max_payload_bytes,
            limits::MAX_PAYLOAD_BYTES,
        ),
    ] {
        if value > max {
            v.error(
                format!("daemon.{field}"),
                format!("{value} is more than {max} (glrmon_spec::limits)"),
            );
        }
    }
    if let Some(instance) = &d.instance
        && let Err(e) = validate_instance(instance)
    {
        v.error("daemon.instance".into(), e);
    }
    if !(d.shutdown_timeout.is_finite() && d.shutdown_timeout > 0.0) {
        v.error(
            "daemon.shutdown_timeout".into(),
            format!("{} must be finite and positive", d.shutdown_timeout),
        );
    }
    if let Some(text) = &d.shard
        && let Err(e) = text.parse::<Shard>()
    {
        v.error("daemon.shard".into(), e);
    }
    if let Some(addr) = &d.metrics
        && addr.parse::<std::net::SocketAddr>().is_err()
    {
        v.error(
            "daemon.metrics".into(),
            format!("\"{addr}\" is not a local address of the form 127.0.0.1:9464"),
        );
    }
    validate_recording(&mut v, &file.recording);
    let mut channels = Vec::new();
    for (i, spec) in file.channels.iter().enumerate() {
        let prefix = format!("channels[{i}] \"{}\"", spec.name);
        if file.channels[..i].iter().any(|c| c.name == spec.name) {
            v.error(
                prefix.clone(),
                format!("duplicate channel name \"{}\"", spec.name),
            );
        }
        if let Some(key) = &spec.key
            && let Err(e) = keys::check_input_key(key)
        {
            v.error(join(&prefix, "key"), e);
        }
        if let Some(c) = v.channel(&prefix, spec) {
            channels.push(c);
        }
    }
    if !(v.errors.is_empty() && v.warnings.is_empty()) {
        let spans = locate::Spans::new(text);
        let names: Vec<&str> = file.channels.iter().map(|c| c.name.as_str()).collect();
        for p in v.errors.iter_mut().chain(v.warnings.iter_mut()) {
            p.location = spans.locate(&p.path, &names);
        }
    }
    if v.errors.is_empty() {
        Ok(Config {
            zenoh: file.zenoh,
            recording: file.recording,
            daemon: file.daemon,
            channels,
            warnings: v.warnings,
            source: text.to_owned(),
        })
    } else {
        Err(SpecErrors { errors: v.errors })
    }
}

/// `message`, with `; did you mean "x"?` when a candidate is close to `word`.
fn suggest(mut message: String, word: &str, candidates: &[&str]) -> String {
    if let Some(s) = did_you_mean(word, candidates) {
        message.push_str(&format!("; did you mean \"{s}\"?"));
    }
    message
}

#[derive(Default)]
struct Validator {
    errors: Vec<Problem>,
    warnings: Vec<Problem>,
}

fn join(prefix: &str, field: &str) -> String {
    format!("{prefix}: {field}")
}

impl Validator {
    fn error(&mut self, path: String, message: String) {
        self.errors.push(Problem {
            path,
            message,
            location: None,
        });
    }

    fn warn(&mut self, path: String, message: String) {
        self.warnings.push(Problem {
            path,
            message,
            location: None,
        });
    }

    /// A matrix as an [`LpvMatrix`]; `square` gives n for a scalar.
    fn matrix(
        &mut self,
        prefix: &str,
        name: &str,
        spec: &MatrixSpec,
        square: Option<usize>,
    ) -> Option<LpvMatrix> {
        let path = join(prefix, &format!("model.{name}"));
        match spec {
            MatrixSpec::Scalar(s) => {
                let Some(n) = square else {
                    self.error(
                        path,
                        "a scalar is only allowed for square matrices whose size is known".into(),
                    );
                    return None;
                };
                if !s.is_finite() {
                    self.error(path, "is not finite".into());
                    return None;
                }
                Some(LpvMatrix::constant(DMatrix::identity(n, n) * *s))
            }
            MatrixSpec::Dense(rows) => self.dense(&path, rows).map(LpvMatrix::constant),
            MatrixSpec::Lpv(table) => {
                let Some(base_rows) = table.get("base") else {
                    self.error(path, "an LPV matrix needs a `base` entry".into());
                    return None;
                };
                let base = self.dense(&format!("{path}.base"), base_rows)?;
                let mut terms = Vec::new();
                for (key, rows) in table {
                    if key == "base" {
                        continue;
                    }
                    let index = key.strip_prefix('p').and_then(|d| d.parse::<usize>().ok());
                    let Some(index) = index else {
                        self.error(
                            format!("{path}.{key}"),
                            "LPV entries are `base` and `p<i>` (scheduling signal i)".into(),
                        );
                        continue;
                    };
                    if index >= limits::MAX_SIGNALS {
                        self.error(
                            format!("{path}.{key}"),
                            format!(
                                "names signal p{index}: at most {} signals (limits::MAX_SIGNALS)",
                                limits::MAX_SIGNALS
                            ),
                        );
                        continue;
                    }
                    let m = self.dense(&format!("{path}.{key}"), rows)?;
                    if m.shape() != base.shape() {
                        self.error(
                            format!("{path}.{key}"),
                            format!(
                                "is {}×{} but base is {}×{}",
                                m.nrows(),
                                m.ncols(),
                                base.nrows(),
                                base.ncols()
                            ),
                        );
                        continue;
                    }
                    terms.push((index, m));
                }
                match LpvMatrix::new(base, terms) {
                    Ok(m) => Some(m),
                    Err(e) => {
                        self.error(path, e.to_string());
                        None
                    }
                }
            }
        }
    }

    fn dense(&mut self, path: &str, rows: &[Vec<f64>]) -> Option<DMatrix<f64>> {
        // An empty matrix (`[]`, `[[]]`) is never meant: every matrix of the model has
        // at least one row and one column (issue 21: `H = []` reached nalgebra).
        if rows.is_empty() {
            self.error(
                path.to_owned(),
                "has no rows: write it row by row, e.g. [[1.0, 0.0]]".into(),
            );
            return None;
        }
        let cols = rows.first().map_or(0, Vec::len);
        if cols == 0 {
            self.error(
                path.to_owned(),
                "has an empty row 0: every row needs at least one entry".into(),
            );
            return None;
        }
        if rows.len() > limits::MAX_MATRIX_SIDE || cols > limits::MAX_MATRIX_SIDE {
            self.error(
                path.to_owned(),
                format!(
                    "is {}×{}: at most {} rows and columns (limits::MAX_MATRIX_SIDE)",
                    rows.len(),
                    cols,
                    limits::MAX_MATRIX_SIDE
                ),
            );
            return None;
        }
        for (i, r) in rows.iter().enumerate() {
            if r.len() != cols {
                self.error(
                    path.to_owned(),
                    format!("row {i} has {} entries but row 0 has {cols}", r.len()),
                );
                return None;
            }
            if let Some(j) = r.iter().position(|x| !x.is_finite()) {
                self.error(path.to_owned(), format!("entry [{i}][{j}] is not finite"));
                return None;
            }
        }
        Some(DMatrix::from_fn(rows.len(), cols, |i, j| rows[i][j]))
    }

    fn shape(
        &mut self,
        prefix: &str,
        name: &str,
        m: &LpvMatrix,
        want: (usize, usize),
        why: &str,
    ) -> bool {
        let got = m.shape();
        if got != want {
            self.error(
                join(prefix, &format!("model.{name}")),
                format!(
                    "is {}×{} but {why} (expected {}×{})",
                    got.0, got.1, want.0, want.1
                ),
            );
            return false;
        }
        true
    }

    /// Symmetric, and positive (semi-)definite. A constant matrix within
    /// [`PSD_TOLERANCE`] of that (a paper's rounded figures) comes back projected, with a
    /// warning, and the caller uses it instead; an LPV matrix is checked at its base
    /// point and used as written (see [`covariance`](mod@covariance)).
    /// `model.S`: constant, n×p, not with E, and the joint noise covariance
    /// `[[Q, S], [Sᵀ, R]]` positive semi-definite (checked at the base point of Q and R,
    /// with the relative tolerance of the near-PSD rule).
    fn cross_covariance(
        &mut self,
        prefix: &str,
        model: &schema::ModelSpec,
        (n, p): (usize, usize),
        with_e: bool,
        (q, r): (&LpvMatrix, &LpvMatrix),
    ) -> Option<DMatrix<f64>> {
        let s = model
            .s
            .as_ref()
            .and_then(|s| self.matrix(prefix, "S", s, None))?;
        let path = join(prefix, "model.S");
        if !s.terms().is_empty() {
            self.error(path, "cannot depend on scheduling signals".into());
            return None;
        }
        if !self.shape(
            prefix,
            "S",
            &s,
            (n, p),
            &format!("F is {n}×{n} and H has {p} rows"),
        ) {
            return None;
        }
        if with_e {
            self.error(
                path,
                "cannot be combined with an unknown input (model.E): the decoupled filter \
                 assumes uncorrelated noises"
                    .into(),
            );
            return None;
        }
        let s = s.base().clone();
        if q.base().shape() == (n, n) && r.base().shape() == (p, p) {
            let mut joint = DMatrix::zeros(n + p, n + p);
            joint.view_mut((0, 0), (n, n)).copy_from(q.base());
            joint.view_mut((n, n), (p, p)).copy_from(r.base());
            joint.view_mut((0, n), (n, p)).copy_from(&s);
            joint.view_mut((n, 0), (p, n)).copy_from(&s.transpose());
            let eig = joint.symmetric_eigenvalues();
            let top = eig.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            let low = eig.iter().copied().fold(f64::INFINITY, f64::min);
            if low < -covariance::PSD_TOLERANCE * top {
                self.error(
                    path,
                    format!(
                        "makes the joint noise covariance [[Q, S], [Sᵀ, R]] indefinite \
                         (smallest eigenvalue {low:.3e}, largest {top:.3e}): |S| is too large \
                         for Q and R (for an innovation model, Q = K·Re·Kᵀ, R = Re, S = K·Re)"
                    ),
                );
                return None;
            }
        }
        Some(s)
    }

    fn covariance(
        &mut self,
        prefix: &str,
        name: &str,
        m: &LpvMatrix,
        definite: bool,
    ) -> Option<LpvMatrix> {
        let path = join(prefix, &format!("model.{name}"));
        for (label, mat) in
            std::iter::once(("", m.base())).chain(m.terms().iter().map(|(_, t)| (" term", t)))
        {
            let asym = (mat - mat.transpose()).amax();
            if asym > 1e-9 * mat.amax().max(1e-300) {
                self.error(
                    path.clone(),
                    format!("is not symmetric{label} (max |M − Mᵀ| = {asym:.3e})"),
                );
                return None;
            }
        }
        let kind = if definite {
            "positive definite"
        } else {
            "positive semi-definite"
        };
        if !m.terms().is_empty() {
            // Today's check at the base point: no projection for an LPV matrix.
            let eig = m.base().clone().symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            let bad = if definite {
                !(lo > 1e-12 * hi.abs().max(1e-300) && lo > 0.0)
            } else {
                lo < -1e-9 * hi.abs().max(1e-300)
            };
            if bad {
                self.error(
                    path,
                    format!(
                        "is not {kind} at its base point (smallest eigenvalue {lo:.3e}; an LPV \
                         covariance is used as written, never projected)"
                    ),
                );
            }
            return None;
        }
        match covariance::classify(m.base(), definite) {
            Verdict::Kept => None,
            Verdict::Rejected {
                lambda_min,
                lambda_max,
            } => {
                self.error(
                    path,
                    format!(
                        "is not {kind} (smallest eigenvalue {lambda_min:.3e}, largest \
                         {lambda_max:.3e}; a rounded matrix is accepted down to \
                         −{PSD_TOLERANCE:e} × the spectral radius: give more digits if it was \
                         rounded)"
                    ),
                );
                None
            }
            Verdict::Projected {
                matrix,
                lambda_min,
                lambda_max,
                floor,
                change,
            } => {
                let clip = if definite {
                    format!(
                        "eigenvalues below {PSD_TOLERANCE:e} × λ_max = {floor:.3e} raised to it"
                    )
                } else {
                    "negative eigenvalues set to 0".to_owned()
                };
                self.warn(
                    path,
                    format!(
                        "is not {kind} as written (smallest eigenvalue {lambda_min:.3e}, \
                         largest {lambda_max:.3e}, within the tolerance {PSD_TOLERANCE:e} for \
                         rounded figures): using the nearest {kind} matrix ({clip}; \
                         max |Δ{name}| = {change:.3e})"
                    ),
                );
                Some(LpvMatrix::constant(matrix))
            }
        }
    }

    fn channel(&mut self, prefix: &str, spec: &ChannelSpec) -> Option<Channel> {
        let before = self.errors.len();
        if let Err(e) = validate_name(&spec.name) {
            self.error(join(prefix, "name"), e);
        }
        self.glr_ranges(prefix, &spec.glr);
        let model = &spec.model;
        // Dimensions: n from F (or H), p from H, l from G (or J).
        let h = self.matrix(prefix, "H", &model.h, None);
        let n_hint = h.as_ref().map(|h| h.shape().1);
        let f = self.matrix(prefix, "F", &model.f, n_hint);
        let (Some(f), Some(h)) = (f, h) else {
            return None;
        };
        let (n, n2) = f.shape();
        if n != n2 || n == 0 {
            let hc = h.shape().1;
            let why = if hc != n2 {
                format!("is {n}×{n2} but H has {hc} columns")
            } else {
                format!("is {n}×{n2}: it must be square and non-empty")
            };
            self.error(join(prefix, "model.F"), why);
            return None;
        }
        let p = h.shape().0;
        if h.shape().1 != n {
            self.error(
                join(prefix, "model.F"),
                format!("is {n}×{n} but H has {} columns", h.shape().1),
            );
            return None;
        }
        if p == 0 {
            self.error(
                join(prefix, "model.H"),
                "has no rows: the channel needs at least one output".into(),
            );
            return None;
        }
        if !self.dimension_limits(prefix, n, p) {
            return None;
        }
        let g = model
            .g
            .as_ref()
            .and_then(|g| self.matrix(prefix, "G", g, None));
        let j = model
            .j
            .as_ref()
            .and_then(|j| self.matrix(prefix, "J", j, None));
        let l = g
            .as_ref()
            .map(|g| g.shape().1)
            .or(j.as_ref().map(|j| j.shape().1))
            .unwrap_or(0);
        if (model.g.is_some() && g.is_none()) || (model.j.is_some() && j.is_none()) {
            // The error is recorded; l is unknown, so nothing below can be checked.
            return None;
        }
        let g = g.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(n, l)));
        let j = j.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(p, l)));
        // Every product below (faults, E, S, diagnosis) assumes these shapes: a
        // mismatch ends the channel's checks here instead of panicking in nalgebra.
        let g_ok = self.shape(
            prefix,
            "G",
            &g,
            (n, l),
            &format!("F is {n}×{n} and there are {l} inputs"),
        );
        let j_ok = self.shape(
            prefix,
            "J",
            &j,
            (p, l),
            &format!("H has {p} rows and there are {l} inputs"),
        );
        if !(g_ok && j_ok) {
            return None;
        }
        if l > limits::MAX_INPUTS {
            self.error(
                join(prefix, "model.G"),
                format!(
                    "has {l} columns (inputs): at most {} (limits::MAX_INPUTS)",
                    limits::MAX_INPUTS
                ),
            );
            return None;
        }
        let mut q = self.matrix(prefix, "Q", &model.q, Some(n))?;
        let mut r = self.matrix(prefix, "R", &model.r, Some(p))?;
        if self.shape(prefix, "Q", &q, (n, n), &format!("F is {n}×{n}"))
            && let Some(projected) = self.covariance(prefix, "Q", &q, false)
        {
            q = projected;
        }
        if self.shape(prefix, "R", &r, (p, p), &format!("H has {p} rows"))
            && let Some(projected) = self.covariance(prefix, "R", &r, true)
        {
            r = projected;
        }
        let p0 = match &model.p0 {
            Some(s) => self.matrix(prefix, "P0", s, Some(n)),
            None => Some(LpvMatrix::constant(DMatrix::identity(n, n))),
        };
        let p0 = p0.filter(|m| {
            m.terms().is_empty() || {
                self.error(
                    join(prefix, "model.P0"),
                    "cannot depend on scheduling signals".into(),
                );
                false
            }
        });
        let p0 = match p0 {
            Some(m) if self.shape(prefix, "P0", &m, (n, n), &format!("F is {n}×{n}")) => {
                Some(self.covariance(prefix, "P0", &m, true).unwrap_or(m))
            }
            other => other,
        };
        let x0 = match &model.x0 {
            Some(x) if x.len() != n => {
                self.error(
                    join(prefix, "model.x0"),
                    format!("has {} entries but F is {n}×{n}", x.len()),
                );
                DVector::zeros(n)
            }
            Some(x) if x.iter().any(|v| !v.is_finite()) => {
                self.error(join(prefix, "model.x0"), "is not finite".into());
                DVector::zeros(n)
            }
            Some(x) => DVector::from_column_slice(x),
            None => DVector::zeros(n),
        };
        let e = model
            .e
            .as_ref()
            .and_then(|e| self.matrix(prefix, "E", e, None));
        let e =
            e.filter(|e| self.shape(prefix, "E", e, (n, e.shape().1), &format!("F is {n}×{n}")));
        let cross = self.cross_covariance(prefix, model, (n, p), e.is_some(), (&q, &r));
        let diagnosis = self.diagnosis(prefix, spec, &h, e.as_ref().map(LpvMatrix::base));
        // Signals: explicit, or the highest LPV index + 1.
        let lpv_max = [&f, &g, &h, &j, &q, &r]
            .into_iter()
            .chain(e.as_ref())
            .flat_map(|m| m.terms().iter().map(|(i, _)| *i + 1))
            .max()
            .unwrap_or(0);
        let signals = spec.signals.unwrap_or(lpv_max);
        if signals > limits::MAX_SIGNALS {
            self.error(
                join(prefix, "signals"),
                format!(
                    "is {signals}: at most {} (limits::MAX_SIGNALS)",
                    limits::MAX_SIGNALS
                ),
            );
            return None;
        }
        if signals < lpv_max {
            self.error(
                join(prefix, "signals"),
                format!(
                    "is {signals} but the model uses scheduling signal p{}",
                    lpv_max - 1
                ),
            );
        }
        let dims = Dims {
            states: n,
            inputs: l,
            outputs: p,
            signals,
        };
        let scaling = spec
            .scaling
            .as_ref()
            .and_then(|sc| self.scaling(prefix, sc, dims));
        let columns = self.columns(prefix, spec.columns.as_ref(), dims);
        let (faults, fault_paths) =
            self.faults(prefix, spec, dims, (&g, &j), scaling.as_ref(), &columns);
        if faults.len() > limits::MAX_FAULTS {
            self.error(
                join(prefix, "faults"),
                format!(
                    "holds {} faults (shortcuts expanded): at most {} (limits::MAX_FAULTS)",
                    faults.len(),
                    limits::MAX_FAULTS
                ),
            );
        }
        if self.errors.len() > before {
            return None;
        }
        let footprint = limits::ChannelFootprint {
            states: n,
            outputs: p,
            inputs: l,
            faults: faults.len(),
            window: spec.glr.window,
            history: diagnosis.history,
        };
        let bytes = footprint.bytes();
        if bytes > limits::CHANNEL_MEMORY_BUDGET {
            let (field, what) = if footprint.history_bytes() > footprint.window_bytes() {
                ("diagnosis.history", "lower diagnosis.history")
            } else {
                ("glr.window", "lower glr.window (or use fewer faults)")
            };
            self.error(
                join(prefix, field),
                format!(
                    "makes the channel need about {} ({}), more than the budget of {} per \
                     channel: {what}",
                    limits::human_bytes(bytes),
                    footprint.breakdown(),
                    limits::human_bytes(limits::CHANNEL_MEMORY_BUDGET),
                ),
            );
            return None;
        }
        let lpv = match Lpv::new(f, g, h, j, q, r, signals) {
            Ok(m) => m,
            Err(e) => {
                self.error(join(prefix, "model"), e.to_string());
                return None;
            }
        };
        self.observability(prefix, &lpv);
        let glr = &spec.glr;
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let tolerance = glr.rank_tolerance.unwrap_or(DEFAULT_RANK_TOLERANCE);
        if !(tolerance > 0.0 && tolerance < 1.0) {
            self.error(
                gpath("rank_tolerance"),
                format!("{tolerance} is not in (0, 1)"),
            );
        }
        let detector_kind = match glr.detector.as_deref() {
            None => DetectorKind::default(),
            Some(name) => DetectorKind::from_name(name).unwrap_or_else(|| {
                self.error(
                    gpath("detector"),
                    locate::not_one_of(name, &DetectorKind::NAMES),
                );
                DetectorKind::default()
            }),
        };
        let innovation_dof = dims.outputs - e.as_ref().map_or(0, |e| e.shape().1).min(dims.outputs);
        let m = detector_kind.statistic_dof(faults.len(), innovation_dof);
        let known = faults.iter().all(|f| f.onset == Onset::Known);
        let given = [
            glr.threshold.is_some(),
            glr.false_alarm.is_some(),
            glr.calibrated.is_some(),
        ];
        if given.iter().filter(|&&g| g).count() > 1 {
            self.error(
                gpath("threshold"),
                "give one of `threshold`, `false_alarm` and `[channels.glr.calibrated]`".into(),
            );
        }
        if glr.threshold_mode.is_some() && glr.threshold.is_some() {
            self.error(
                gpath("threshold_mode"),
                "applies to `false_alarm`, not to an explicit `threshold`".into(),
            );
        }
        let positive = |t: f64| t.is_finite() && t > 0.0;
        let (threshold, threshold_source) = if let Some(t) = glr.threshold {
            if !positive(t) {
                self.error(
                    gpath("threshold"),
                    format!("{t} must be finite and positive"),
                );
            }
            (t, ThresholdSource::Explicit)
        } else if let Some(c) = &glr.calibrated {
            if !positive(c.threshold) {
                self.error(
                    gpath("calibrated.threshold"),
                    format!("{} must be finite and positive", c.threshold),
                );
            }
            if !(c.interval[0] <= c.threshold && c.threshold <= c.interval[1]) {
                self.error(
                    gpath("calibrated.interval"),
                    format!(
                        "[{}, {}] does not contain the threshold {}",
                        c.interval[0], c.interval[1], c.threshold
                    ),
                );
            }
            let target = match (c.mtbfa, c.sample_far) {
                (Some(m), None) => {
                    if !(m.is_finite() && m > 1.0) {
                        self.error(
                            gpath("calibrated.mtbfa"),
                            format!("{m} must be more than 1 sample"),
                        );
                    }
                    Target::Mtbfa(m)
                }
                (None, Some(f)) => {
                    if !(f > 0.0 && f < 1.0) {
                        self.error(
                            gpath("calibrated.sample_far"),
                            format!("{f} must be in (0, 1)"),
                        );
                    }
                    Target::SampleFar(f)
                }
                (m, f) => {
                    self.error(
                        gpath("calibrated"),
                        format!(
                            "give exactly one target, mtbfa or sample_far (got {})",
                            if m.is_some() && f.is_some() {
                                "both"
                            } else {
                                "neither"
                            }
                        ),
                    );
                    Target::Mtbfa(f64::NAN)
                }
            };
            (
                c.threshold,
                ThresholdSource::Calibrated {
                    target,
                    samples: c.samples,
                    episodes: c.episodes,
                    exceedances: c.exceedances,
                    interval: c.interval,
                },
            )
        } else {
            let a = glr.false_alarm.unwrap_or(1e-4);
            let chi2 = match glr.threshold_mode.as_deref() {
                None | Some("bonferroni") => false,
                Some("chi2") => true,
                Some(other) => {
                    self.error(
                        gpath("threshold_mode"),
                        locate::not_one_of(other, &["bonferroni", "chi2"]),
                    );
                    false
                }
            };
            let per_onset = !detector_kind.maximises_over_onsets();
            let onsets = if known || chi2 || per_onset {
                1
            } else {
                glr.window.saturating_sub(glr.min_lag).max(1)
            };
            match chi2_upper_quantile(m as f64, a / onsets as f64) {
                Ok(t) if chi2 || per_onset => (t, ThresholdSource::Chi2 { false_alarm: a }),
                Ok(t) => (t, ThresholdSource::Bonferroni { false_alarm: a }),
                Err(e) => {
                    self.error(gpath("false_alarm"), e.to_string());
                    (0.0, ThresholdSource::Explicit)
                }
            }
        };
        let mut groups = Vec::new();
        for (gi, g) in glr.groups.iter().enumerate() {
            let mut idx = Vec::new();
            for name in &g.faults {
                match faults.iter().position(|f| &f.name == name) {
                    Some(i) => idx.push(i),
                    None => {
                        let names: Vec<&str> = faults.iter().map(|f| f.name.as_str()).collect();
                        self.error(
                            gpath(&format!("groups[{gi}].faults")),
                            suggest(format!("unknown fault \"{name}\""), name, &names),
                        );
                    }
                }
            }
            if idx.is_empty() {
                self.error(gpath(&format!("groups[{gi}]")), "names no fault".into());
            }
            groups.push((g.name.clone(), idx));
        }
        if let Some(cal) = &glr.calibrated {
            let tests: Vec<&str> = if glr.groups.is_empty() {
                faults.iter().map(|f| f.name.as_str()).collect()
            } else {
                glr.groups.iter().map(|g| g.name.as_str()).collect()
            };
            for (name, t) in &cal.isolation {
                if !tests.contains(&name.as_str()) {
                    self.error(
                        gpath(&format!("calibrated.isolation.{name}")),
                        suggest(
                            format!("no isolation test \"{name}\" (tests: {})", tests.join(", ")),
                            name,
                            &tests,
                        ),
                    );
                } else if !(t.is_finite() && *t > 0.0) {
                    self.error(
                        gpath(&format!("calibrated.isolation.{name}")),
                        format!("{t} must be finite and positive"),
                    );
                }
            }
        }
        let simulation = self.simulation(prefix, spec, dims, e.as_ref().map(LpvMatrix::base));
        let c = spec.consistency;
        if c.window > limits::MAX_CONSISTENCY_WINDOW {
            self.error(
                join(prefix, "consistency.window"),
                format!(
                    "{} samples is more than {} (limits::MAX_CONSISTENCY_WINDOW)",
                    c.window,
                    limits::MAX_CONSISTENCY_WINDOW
                ),
            );
        }
        let consistency = if c.enabled {
            let settings = glrmon_core::consistency::ConsistencySettings {
                window: c.window,
                alpha: c.alpha,
            };
            let dof = dims.outputs - e.as_ref().map_or(0, |e| e.shape().1).min(dims.outputs);
            match glrmon_core::consistency::Consistency::new(dof.max(1), settings) {
                Ok(_) => Some(settings),
                Err(e) => {
                    let field = if c.window == 0 { "window" } else { "alpha" };
                    self.error(join(prefix, &format!("consistency.{field}")), e.to_string());
                    None
                }
            }
        } else {
            None
        };
        let warm_up = match &glr.warm_up {
            None => 0,
            Some(schema::WarmUpSpec::Samples(n)) => *n,
            Some(schema::WarmUpSpec::Keyword(w)) if w == "window" => glr.window as u64,
            Some(schema::WarmUpSpec::Keyword(other)) => {
                self.error(
                    join(prefix, "glr.warm_up"),
                    format!("\"{other}\" is not \"window\" or a number of samples"),
                );
                0
            }
        };
        let payload = match spec.payload.as_deref() {
            None => PayloadFormat::default(),
            Some(name) => PayloadFormat::from_name(name).unwrap_or_else(|| {
                self.error(
                    join(prefix, "payload"),
                    locate::not_one_of(name, &PayloadFormat::NAMES),
                );
                PayloadFormat::default()
            }),
        };
        if self.errors.len() > before {
            return None;
        }
        Some(Channel {
            name: spec.name.clone(),
            payload,
            key: spec
                .key
                .clone()
                .unwrap_or_else(|| format!("plant/{}", spec.name)),
            period: spec.period,
            dims,
            model: lpv,
            unknown_input: e,
            cross_covariance: cross,
            scaling,
            columns,
            x0,
            p0: p0
                .map(|m| m.base().clone())
                .unwrap_or_else(|| DMatrix::identity(n, n)),
            window: WindowSettings {
                window: glr.window,
                min_lag: glr.min_lag,
                rank_tolerance: tolerance,
                warm_up,
                ..WindowSettings::default()
            },
            alarm: AlarmSettings {
                threshold,
                hysteresis: glr.hysteresis,
                clear_samples: glr.clear_samples.max(1),
            },
            threshold_source,
            isolation_delay: glr.isolation_delay.unwrap_or(n as u32),
            isolation_alpha: glr.isolation_alpha,
            detector_kind,
            isolation_thresholds: glr
                .calibrated
                .as_ref()
                .map(|c| c.isolation.iter().map(|(k, v)| (k.clone(), *v)).collect())
                .unwrap_or_default(),
            groups,
            max_gap: glr.max_gap,
            max_reorder: glr.max_reorder,
            fault_names: faults.iter().map(|f| f.name.clone()).collect(),
            fault_paths,
            simulation,
            diagnosis,
            consistency,
            faults,
        })
    }

    /// Checks of the GLR settings that need no model, done first so that they are
    /// reported together with model errors.
    fn glr_ranges(&mut self, prefix: &str, glr: &schema::GlrSpec) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        if glr.window > limits::MAX_WINDOW {
            self.error(
                gpath("window"),
                format!(
                    "w = {} is more than {} (limits::MAX_WINDOW)",
                    glr.window,
                    limits::MAX_WINDOW
                ),
            );
        }
        for (field, value, max) in [
            ("max_gap", glr.max_gap, limits::MAX_GAP),
            ("max_reorder", glr.max_reorder, limits::MAX_REORDER),
        ] {
            if value > max {
                self.error(
                    gpath(field),
                    format!(
                        "{value} is more than {max} (limits::{})",
                        field.to_uppercase()
                    ),
                );
            }
        }
        if let Some(schema::WarmUpSpec::Samples(n)) = glr.warm_up
            && n > limits::MAX_WARM_UP
        {
            self.error(
                gpath("warm_up"),
                format!(
                    "{n} is more than {} (limits::MAX_WARM_UP)",
                    limits::MAX_WARM_UP
                ),
            );
        }
        if glr.window < 2 {
            self.error(
                gpath("window"),
                format!("w = {} must be at least 2", glr.window),
            );
        }
        if glr.min_lag >= glr.window {
            self.error(
                gpath("min_lag"),
                format!("s = {} must be below w = {}", glr.min_lag, glr.window),
            );
        }
        if !(0.0..1.0).contains(&glr.hysteresis) {
            self.error(
                gpath("hysteresis"),
                format!("{} is not in [0, 1)", glr.hysteresis),
            );
        }
        if !(glr.isolation_alpha > 0.0 && glr.isolation_alpha < 1.0) {
            self.error(
                gpath("isolation_alpha"),
                format!("{} is not in (0, 1)", glr.isolation_alpha),
            );
        }
    }

    /// `[channels.diagnosis]`: ranges, the residual kind, and Assumption (iv) of Zhang
    /// 2021 for the Kitanidis residual (H·E of full column rank, checked at the base
    /// point of H).
    fn diagnosis(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        h: &LpvMatrix,
        e: Option<&DMatrix<f64>>,
    ) -> DiagnosisSettings {
        let d: &DiagnosisSpec = &spec.diagnosis;
        let dpath = |f: &str| join(prefix, &format!("diagnosis.{f}"));
        let residual = match d.residual.as_deref() {
            None if spec.model.e.is_some() => ResidualKind::Kitanidis,
            None => ResidualKind::Kalman,
            Some("kalman") => ResidualKind::Kalman,
            Some("kitanidis") => {
                if spec.model.e.is_none() {
                    self.error(
                        dpath("residual"),
                        "is \"kitanidis\" but the model has no unknown-input matrix E: \
                         add model.E or use residual = \"kalman\""
                            .into(),
                    );
                }
                ResidualKind::Kitanidis
            }
            Some(other) => {
                self.error(
                    dpath("residual"),
                    locate::not_one_of(other, &["kalman", "kitanidis"]),
                );
                ResidualKind::Kalman
            }
        };
        if let Some(e) = e {
            if let Err(err) = unknown_input_rank(h.base(), e) {
                let text = format!(
                    "{err} (H·E must have full column rank: the detector and the Kitanidis \
                     residual decouple the unknown input{})",
                    if h.terms().is_empty() {
                        ""
                    } else {
                        "; checked at the base point of H"
                    }
                );
                self.error(join(prefix, "model.E"), text);
            } else if e.ncols() >= h.shape().0 {
                self.error(
                    join(prefix, "model.E"),
                    format!(
                        "has {} columns and H has {} rows: once the unknown input is \
                         decoupled no output direction is left to detect faults with \
                         (E needs fewer columns than there are outputs)",
                        e.ncols(),
                        h.shape().0
                    ),
                );
            }
        }
        let window = spec.glr.window;
        let history = d.history.unwrap_or(window.saturating_mul(2));
        // The default 2w is bounded by the window's own limit: only explicit values are
        // checked here, so that an oversized window is blamed on glr.window alone.
        for (field, value) in [("history", d.history), ("span", d.span)] {
            if let Some(value) = value
                && value > limits::MAX_HISTORY
            {
                self.error(
                    dpath(field),
                    format!(
                        "{value} samples is more than {} (limits::MAX_HISTORY)",
                        limits::MAX_HISTORY
                    ),
                );
            }
        }
        if history < 2 {
            self.error(
                dpath("history"),
                format!("{history} must be at least 2 samples"),
            );
        }
        if d.span == Some(0) {
            self.error(dpath("span"), "0 must be at least 1 sample".into());
        }
        if let Some(span) = d.span
            && span > history
        {
            self.warn(
                dpath("span"),
                format!(
                    "{span} exceeds diagnosis.history = {history}: the regression holds at \
                         most {history} samples"
                ),
            );
        }
        let defaults = LassoSettings::default();
        let plateau_scale = match d.lasso.plateau_scale.as_deref() {
            None => defaults.plateau_scale,
            Some("log") => PlateauScale::Log,
            Some("linear") => PlateauScale::Linear,
            Some(other) => {
                self.error(
                    dpath("lasso.plateau_scale"),
                    locate::not_one_of(other, &["log", "linear"]),
                );
                defaults.plateau_scale
            }
        };
        let lasso = LassoSettings {
            path_points: d.lasso.path_points.unwrap_or(defaults.path_points),
            ratio: d.lasso.ratio.unwrap_or(defaults.ratio),
            plateau_scale,
            ..defaults
        };
        if lasso.path_points < 2 {
            self.error(
                dpath("lasso.path_points"),
                format!("{} must be at least 2", lasso.path_points),
            );
        }
        if lasso.path_points > limits::MAX_PATH_POINTS {
            self.error(
                dpath("lasso.path_points"),
                format!(
                    "{} is more than {} (limits::MAX_PATH_POINTS)",
                    lasso.path_points,
                    limits::MAX_PATH_POINTS
                ),
            );
        }
        if !(lasso.ratio > 0.0 && lasso.ratio < 1.0) {
            self.error(
                dpath("lasso.ratio"),
                format!("{} is not in (0, 1) (λ_min/λ_max)", lasso.ratio),
            );
        }
        let alpha = d.alpha.unwrap_or(DEFAULT_DIAGNOSIS_ALPHA);
        if !(alpha > 0.0 && alpha <= 1.0) {
            self.error(
                dpath("alpha"),
                format!("{alpha} is not in (0, 1] (1 turns the no-fault test off)"),
            );
        }
        DiagnosisSettings {
            enabled: d.enabled,
            residual,
            span: d.span,
            history,
            lasso,
            alpha,
        }
    }

    /// n and p within [`limits::MAX_STATES`] and [`limits::MAX_OUTPUTS`].
    fn dimension_limits(&mut self, prefix: &str, n: usize, p: usize) -> bool {
        let mut ok = true;
        if n > limits::MAX_STATES {
            self.error(
                join(prefix, "model.F"),
                format!(
                    "is {n}×{n}: at most {} states (limits::MAX_STATES)",
                    limits::MAX_STATES
                ),
            );
            ok = false;
        }
        if p > limits::MAX_OUTPUTS {
            self.error(
                join(prefix, "model.H"),
                format!(
                    "has {p} rows: at most {} outputs (limits::MAX_OUTPUTS)",
                    limits::MAX_OUTPUTS
                ),
            );
            ok = false;
        }
        ok
    }

    fn observability(&mut self, prefix: &str, model: &Lpv) {
        let [f, _, h, ..] = model.matrices();
        let (f, h) = (f.base(), h.base());
        let n = f.nrows();
        let p = h.nrows();
        let mut o = DMatrix::zeros(p * n, n);
        let mut block = h.clone();
        for i in 0..n {
            o.view_mut((i * p, 0), (p, n)).copy_from(&block);
            block = &block * f;
        }
        let sv = o.singular_values();
        let smax = sv.max();
        let rank = sv.iter().filter(|s| **s > 1e-9 * smax).count();
        if rank < n {
            self.warn(
                join(prefix, "model"),
                format!(
                    "(F, H) is not observable at the base point: the observability matrix has rank {rank} < n = {n}"
                ),
            );
        }
    }

    /// `[channels.columns]` into [`Columns`]: one unique, non-empty name per signal,
    /// none of them `k` or `t` and none with a comma.
    fn columns(&mut self, prefix: &str, spec: Option<&schema::ColumnsSpec>, dims: Dims) -> Columns {
        let mut columns = Columns::numbered(dims);
        let Some(spec) = spec else {
            return columns;
        };
        columns.named = true;
        let mut all: Vec<(String, String)> = Vec::new();
        for (field, given, target, count, what) in [
            ("u", &spec.u, &mut columns.u, dims.inputs, "inputs"),
            ("y", &spec.y, &mut columns.y, dims.outputs, "outputs"),
            ("p", &spec.p, &mut columns.p, dims.signals, "signals"),
        ] {
            let path = join(prefix, &format!("columns.{field}"));
            if let Some(names) = given {
                if names.len() != count {
                    self.error(
                        path.clone(),
                        format!(
                            "has {} names but the channel has {count} {what}",
                            names.len()
                        ),
                    );
                }
                target.clone_from(names);
            }
            for (i, name) in target.iter().enumerate() {
                let at = format!("{path}[{i}]");
                if name.trim().is_empty() || name.trim() != name || name.contains(',') {
                    self.error(
                        at,
                        format!("\"{name}\" is not a column name (empty, padded or with a comma)"),
                    );
                } else if name == "k" || name == "t" {
                    self.error(at, format!("\"{name}\" is the sample index or time column"));
                } else if let Some((other, _)) = all.iter().find(|(_, n)| n == name) {
                    self.error(at, format!("\"{name}\" is also {other}"));
                } else {
                    all.push((format!("{field}{i}"), name.clone()));
                }
            }
        }
        columns
    }

    /// `[channels.scaling]` into a [`SignalScaling`]: absent lists are offset 0 and
    /// scale 1, present ones have one entry per input (u_*) or output (y_*).
    fn scaling(
        &mut self,
        prefix: &str,
        spec: &schema::ScalingSpec,
        dims: Dims,
    ) -> Option<SignalScaling> {
        let before = self.errors.len();
        let list =
            |v: &mut Self, field: &str, given: &Option<Vec<f64>>, len: usize, default: f64| {
                let path = join(prefix, &format!("scaling.{field}"));
                let what = if field.starts_with('u') {
                    "inputs"
                } else {
                    "outputs"
                };
                match given {
                    Some(x) if x.len() != len => {
                        v.error(
                            path,
                            format!("has {} entries but the channel has {len} {what}", x.len()),
                        );
                        Vec::new()
                    }
                    Some(x) => {
                        let scale = field.ends_with("scale");
                        for (i, value) in x.iter().enumerate() {
                            if !value.is_finite() || (scale && *value <= 0.0) {
                                v.error(
                                    format!("{path}[{i}]"),
                                    format!(
                                        "{value} must be {}",
                                        if scale {
                                            "finite and positive"
                                        } else {
                                            "finite"
                                        }
                                    ),
                                );
                            }
                        }
                        x.clone()
                    }
                    None => vec![default; len],
                }
            };
        let u_offset = list(self, "u_offset", &spec.u_offset, dims.inputs, 0.0);
        let u_scale = list(self, "u_scale", &spec.u_scale, dims.inputs, 1.0);
        let y_offset = list(self, "y_offset", &spec.y_offset, dims.outputs, 0.0);
        let y_scale = list(self, "y_scale", &spec.y_scale, dims.outputs, 1.0);
        if self.errors.len() > before {
            return None;
        }
        match SignalScaling::new(u_offset, u_scale, y_offset, y_scale) {
            Ok(s) => Some(s),
            Err(e) => {
                self.error(join(prefix, "scaling"), e.to_string());
                None
            }
        }
    }

    fn faults(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        dims: Dims,
        (g, j): (&LpvMatrix, &LpvMatrix),
        scaling: Option<&SignalScaling>,
        columns: &Columns,
    ) -> (Vec<FaultPlan>, Vec<String>) {
        if spec.faults.is_empty() {
            self.error(
                join(prefix, "faults"),
                "the fault dictionary is empty".into(),
            );
        }
        let expanded = self.expand_shortcuts(prefix, &spec.faults, dims, columns);
        let mut out = Vec::new();
        let mut paths = Vec::new();
        for (i, (path, f)) in expanded.iter().enumerate() {
            if expanded[..i].iter().any(|(_, g)| g.name == f.name) {
                self.error(path.clone(), format!("duplicate fault name \"{}\"", f.name));
            }
            if f.name.is_empty() {
                self.error(
                    format!("{path}.name"),
                    "is missing: every fault needs a name".into(),
                );
                continue;
            }
            if let Some(plan) = self.fault(path, f, dims, j)
                && let Some(plan) = self.in_raw_units(path, f, plan, g, scaling)
            {
                out.push(plan);
                paths.push(path.clone());
            }
        }
        let known = out.iter().filter(|f| f.onset == Onset::Known).count();
        if known != 0 && known != out.len() {
            self.error(
                join(prefix, "faults"),
                "known-profile faults cannot be mixed with step/impulse/ramp faults in one channel"
                    .into(),
            );
        }
        (out, paths)
    }

    /// The dictionary with the `all_sensors` / `all_actuators` shortcuts expanded into
    /// one `sensor_bias` per output / `actuator_bias` per input, each with its path
    /// (`faults[i]`, or `faults[i] (y2)` for an expanded entry). A fault without a name
    /// is named after its signal: `y2_bias`, or `<column>_bias` when
    /// `[channels.columns]` names the columns.
    fn expand_shortcuts(
        &mut self,
        prefix: &str,
        faults: &[FaultSpec],
        dims: Dims,
        columns: &Columns,
    ) -> Vec<(String, FaultSpec)> {
        let mut out = Vec::with_capacity(faults.len());
        for (i, f) in faults.iter().enumerate() {
            let path = join(prefix, &format!("faults[{i}]"));
            let (kind, letter, count) = match f.kind.as_deref() {
                Some("all_sensors") => ("sensor_bias", 'y', dims.outputs),
                Some("all_actuators") => ("actuator_bias", 'u', dims.inputs),
                _ => {
                    out.push((path, f.clone()));
                    continue;
                }
            };
            if f.input.is_some() || f.output.is_some() || f.psi.is_some() || f.phi.is_some() {
                self.error(
                    path,
                    format!(
                        "kind \"{}\" makes one fault per signal: remove input/output/psi/phi",
                        f.kind.as_deref().unwrap_or_default()
                    ),
                );
                continue;
            }
            if count == 0 {
                self.error(
                    format!("{path}.kind"),
                    "\"all_actuators\": the channel has no inputs".into(),
                );
                continue;
            }
            for s in 0..count {
                let name = if f.name.is_empty() {
                    let list = if letter == 'u' {
                        &columns.u
                    } else {
                        &columns.y
                    };
                    match list.get(s) {
                        Some(column) if columns.named => format!("{column}_bias"),
                        _ => format!("{letter}{s}_bias"),
                    }
                } else {
                    format!("{}{s}", f.name)
                };
                out.push((
                    format!("{path} ({letter}{s})"),
                    FaultSpec {
                        name,
                        kind: Some(kind.to_owned()),
                        onset: f.onset.clone(),
                        input: (letter == 'u').then_some(s),
                        output: (letter == 'y').then_some(s),
                        psi: None,
                        phi: None,
                    },
                ));
            }
        }
        out
    }

    /// A `sensor_*` / `actuator_*` fault of a scaled channel, with its magnitude in the
    /// signal's raw units: a raw bias b of y_j is b / y_scale_j in model units, so the
    /// column is e_j / y_scale_j (G·e_i / u_scale_i, J·e_i / u_scale_i for an input).
    /// An actuator gain loss θ is unit-free, but with an input offset the model input is
    /// no longer proportional to the raw one, so that case is refused.
    fn in_raw_units(
        &mut self,
        path: &str,
        f: &FaultSpec,
        plan: FaultPlan,
        g: &LpvMatrix,
        scaling: Option<&SignalScaling>,
    ) -> Option<FaultPlan> {
        let Some(scaling) = scaling else {
            return Some(plan);
        };
        let divide = |c: ColumnPlan, s: f64| match c {
            ColumnPlan::Constant(v) => ColumnPlan::Constant(v / s),
            other => other,
        };
        match (f.kind.as_deref(), f.input, f.output) {
            (Some("sensor_bias" | "sensor_drift"), _, Some(j)) => {
                let s = scaling.y_scale().get(j).copied().unwrap_or(1.0);
                Some(FaultPlan {
                    output: divide(plan.output, s),
                    ..plan
                })
            }
            (Some("actuator_bias"), Some(i), _) => {
                let s = scaling.u_scale().get(i).copied().unwrap_or(1.0);
                if s == 1.0 {
                    return Some(plan);
                }
                if !g.terms().is_empty() {
                    self.error(
                        path.to_owned(),
                        format!(
                            "kind \"actuator_bias\" on a scaled input (scaling.u_scale[{i}] = {s}) \
                             needs a constant G: write psi/phi for an LPV G"
                        ),
                    );
                    return None;
                }
                Some(FaultPlan {
                    state: ColumnPlan::Constant(g.base().column(i) / s),
                    output: divide(plan.output, s),
                    ..plan
                })
            }
            (Some("actuator_gain"), Some(i), _) => {
                if scaling.u_offset().get(i).is_some_and(|o| *o != 0.0) {
                    self.error(
                        path.to_owned(),
                        format!(
                            "kind \"actuator_gain\" on an input with an operating point \
                             (scaling.u_offset[{i}] ≠ 0) is not supported: write psi/phi"
                        ),
                    );
                    return None;
                }
                Some(plan)
            }
            _ => Some(plan),
        }
    }

    fn fault(
        &mut self,
        path: &str,
        f: &FaultSpec,
        dims: Dims,
        j_matrix: &LpvMatrix,
    ) -> Option<FaultPlan> {
        let kind = f.kind.as_deref().unwrap_or("custom");
        let default_onset = if kind == "sensor_drift" {
            "ramp"
        } else {
            "step"
        };
        let onset_name = f.onset.as_deref().unwrap_or(default_onset);
        let onset = match onset_name {
            "step" => Onset::Step,
            "impulse" => Onset::Impulse,
            "ramp" => Onset::Ramp,
            "known" => Onset::Known,
            other => {
                self.error(
                    format!("{path}.onset"),
                    locate::not_one_of(other, &["step", "impulse", "ramp", "known"]),
                );
                return None;
            }
        };
        let shortcut = kind != "custom";
        if shortcut && (f.psi.is_some() || f.phi.is_some()) {
            self.error(
                path.to_owned(),
                format!("kind \"{kind}\" defines its own columns: remove psi/phi"),
            );
            return None;
        }
        let need_input = |v: &mut Self| -> Option<usize> {
            match f.input {
                Some(i) if i < dims.inputs => Some(i),
                Some(i) => {
                    v.error(
                        format!("{path}.input"),
                        format!(
                            "input u{i} does not exist (the channel has {} inputs)",
                            dims.inputs
                        ),
                    );
                    None
                }
                None => {
                    v.error(
                        format!("{path}.input"),
                        format!("kind \"{kind}\" needs `input`"),
                    );
                    None
                }
            }
        };
        let need_output = |v: &mut Self| -> Option<usize> {
            match f.output {
                Some(j) if j < dims.outputs => Some(j),
                Some(j) => {
                    v.error(
                        format!("{path}.output"),
                        format!(
                            "output y{j} does not exist (the channel has {} outputs)",
                            dims.outputs
                        ),
                    );
                    None
                }
                None => {
                    v.error(
                        format!("{path}.output"),
                        format!("kind \"{kind}\" needs `output`"),
                    );
                    None
                }
            }
        };
        let unit =
            |len: usize, at: usize| DVector::from_fn(len, |r, _| if r == at { 1.0 } else { 0.0 });
        let (state, output) = match kind {
            "actuator_bias" | "actuator_gain" => {
                let i = need_input(self)?;
                let jcol = j_matrix.base().column(i).into_owned();
                let j_used = jcol.iter().any(|x| *x != 0.0) || !j_matrix.terms().is_empty();
                if j_used {
                    if kind == "actuator_gain" || !j_matrix.terms().is_empty() {
                        self.error(
                            path.to_owned(),
                            format!("kind \"{kind}\" with a non-zero J column for u{i} is not supported: write psi/phi expressions"),
                        );
                        return None;
                    }
                    (ColumnPlan::InputBias(i), ColumnPlan::Constant(jcol))
                } else if kind == "actuator_bias" {
                    (ColumnPlan::InputBias(i), ColumnPlan::Zero)
                } else {
                    (ColumnPlan::GainLoss(i), ColumnPlan::Zero)
                }
            }
            "sensor_bias" | "sensor_drift" => {
                let j = need_output(self)?;
                if kind == "sensor_drift" && onset != Onset::Ramp {
                    self.error(
                        format!("{path}.onset"),
                        "a sensor drift is a ramp: remove `onset`".into(),
                    );
                }
                (
                    ColumnPlan::Zero,
                    ColumnPlan::Constant(unit(dims.outputs, j)),
                )
            }
            "custom" => {
                if f.psi.is_none() && f.phi.is_none() {
                    self.error(
                        path.to_owned(),
                        "a custom fault needs `psi` (state column) and/or `phi` (output column)"
                            .into(),
                    );
                    return None;
                }
                let state =
                    self.column(&format!("{path}.psi"), f.psi.as_deref(), dims.states, dims)?;
                let output =
                    self.column(&format!("{path}.phi"), f.phi.as_deref(), dims.outputs, dims)?;
                (state, output)
            }
            other => {
                self.error(
                    format!("{path}.kind"),
                    locate::not_one_of(
                        other,
                        &[
                            "custom",
                            "actuator_bias",
                            "actuator_gain",
                            "sensor_bias",
                            "sensor_drift",
                            "all_sensors",
                            "all_actuators",
                        ],
                    ),
                );
                return None;
            }
        };
        Some(FaultPlan {
            name: f.name.clone(),
            onset,
            state,
            output,
        })
    }

    fn column(
        &mut self,
        path: &str,
        entries: Option<&[EntrySpec]>,
        len: usize,
        dims: Dims,
    ) -> Option<ColumnPlan> {
        let Some(entries) = entries else {
            return Some(ColumnPlan::Zero);
        };
        if entries.len() != len {
            self.error(
                path.to_owned(),
                format!("has {} entries, expected {len}", entries.len()),
            );
            return None;
        }
        let ctx = ExprContext {
            inputs: dims.inputs,
            signals: dims.signals,
            allow_k: true,
            allow_lags: true,
            allow_random: false,
        };
        let mut exprs = Vec::new();
        let mut all_constant = true;
        let mut ok = true;
        for (i, e) in entries.iter().enumerate() {
            let parsed = match e {
                EntrySpec::Number(x) if !x.is_finite() => {
                    self.error(format!("{path}[{i}]"), "is not finite".into());
                    ok = false;
                    continue;
                }
                EntrySpec::Number(x) => Expr::parse(&format!("{x:?}"), &ctx),
                EntrySpec::Expr(s) => Expr::parse(s, &ctx),
            };
            match parsed {
                Ok(x) => {
                    all_constant &= x.constant_value().is_some();
                    exprs.push(x);
                }
                Err(err) => {
                    self.error(format!("{path}[{i}]"), err.to_string());
                    ok = false;
                }
            }
        }
        if !ok {
            return None;
        }
        if all_constant {
            let v = DVector::from_iterator(
                len,
                exprs.iter().map(|e| e.constant_value().unwrap_or(0.0)),
            );
            if v.iter().any(|x| !x.is_finite()) {
                self.error(path.to_owned(), "evaluates to a non-finite value".into());
                return None;
            }
            return Some(if v.iter().all(|x| *x == 0.0) {
                ColumnPlan::Zero
            } else {
                ColumnPlan::Constant(v)
            });
        }
        Some(ColumnPlan::Exprs(exprs))
    }

    fn simulation(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        dims: Dims,
        e: Option<&DMatrix<f64>>,
    ) -> SimulationPlan {
        let sim = &spec.simulation;
        let ctx = ExprContext {
            inputs: 0,
            signals: 0,
            allow_k: true,
            allow_lags: false,
            allow_random: true,
        };
        let list =
            |v: &mut Self, field: &str, src: &[String], max: usize, what: &str| -> Vec<Expr> {
                let path = join(prefix, &format!("simulation.{field}"));
                if src.len() > max {
                    v.error(
                        path.clone(),
                        format!(
                            "has {} expressions but the channel has {max} {what}",
                            src.len()
                        ),
                    );
                }
                src.iter()
                    .enumerate()
                    .filter_map(|(i, s)| match Expr::parse(s, &ctx) {
                        Ok(x) => Some(x),
                        Err(err) => {
                            v.error(format!("{path}[{i}]"), err.to_string());
                            None
                        }
                    })
                    .collect()
            };
        let inputs = list(self, "inputs", &sim.inputs, dims.inputs, "inputs");
        let signals = list(self, "signals", &sim.signals, dims.signals, "signals");
        let d = e.map_or(0, |e| e.ncols());
        let unknown_input = list(self, "unknown_input", &sim.unknown_input, d, "columns in E");
        let controller = sim.controller.as_ref().map(|c| Controller {
            output: c.output,
            input: c.input,
            setpoint: c.setpoint,
            kp: c.kp,
            ki: c.ki,
        });
        if let Some(c) = controller
            && (c.input >= dims.inputs || c.output >= dims.outputs)
        {
            self.error(
                join(prefix, "simulation.controller"),
                format!(
                    "drives u{} from y{} but the channel has {} inputs and {} outputs",
                    c.input, c.output, dims.inputs, dims.outputs
                ),
            );
        }
        SimulationPlan {
            inputs,
            signals,
            unknown_input,
            controller,
        }
    }
}

/// A channel name must be usable in a Zenoh key expression chunk.
/// Longest instance name (`daemon.instance`, `glrmon run --instance`).
pub const MAX_INSTANCE_LEN: usize = 64;

/// Checks an instance name: 1 to [`MAX_INSTANCE_LEN`] characters among `A-Z a-z 0-9 _ . -`,
/// so that it is one plain chunk of the status and liveliness keys
/// (`glrmon/@status/<instance>`, `glrmon/@instances/<instance>`): no `/`, no wildcard, no
/// `@`, nothing a shell or a log would mangle.
///
/// # Errors
/// Why the name is refused, as a sentence that follows the field's path.
///
/// # Examples
///
/// ```
/// assert!(glrmon_spec::validate_instance("plant-a.01").is_ok());
/// assert!(glrmon_spec::validate_instance("a/b/**").is_err());
/// assert!(glrmon_spec::validate_instance("").is_err());
/// ```
pub fn validate_instance(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty: an instance name is 1 to 64 characters of A-Z a-z 0-9 _ . -".into());
    }
    if name.len() > MAX_INSTANCE_LEN {
        return Err(format!(
            "has {} characters: at most {MAX_INSTANCE_LEN}",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-')))
    {
        return Err(format!(
            "\"{}\" contains {c:?}: an instance name is one key chunk of A-Z a-z 0-9 _ . - \
             (it ends the status and liveliness keys glrmon/@status/<instance>)",
            name.escape_debug()
        ));
    }
    Ok(())
}

fn validate_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty".into());
    }
    if let Some(c) = name.chars().find(|c| {
        matches!(c, '/' | '*' | '$' | '?' | '#' | '@') || c.is_whitespace() || c.is_control()
    }) {
        return Err(format!(
            "\"{name}\" contains '{c}', which cannot appear in a key expression chunk"
        ));
    }
    Ok(())
}

/// Checks the syntax of a Zenoh endpoint, `PROTOCOL/ADDRESS[?metadata][#config]`: a
/// protocol name, and for the IP transports (tcp, udp, tls, quic, ws) an address with a
/// host and a port. The error says why and shows the likely fix (`127.0.0.1:7447` →
/// `tcp/127.0.0.1:7447`). Zenoh itself checks the rest when the session opens.
///
/// # Errors
/// A message for the user when the endpoint is malformed.
///
/// # Examples
///
/// ```
/// assert!(glrmon_spec::check_endpoint("tcp/127.0.0.1:7447").is_ok());
/// let e = glrmon_spec::check_endpoint("127.0.0.1:7447").unwrap_err();
/// assert!(e.contains("tcp/127.0.0.1:7447"));
/// ```
pub fn check_endpoint(s: &str) -> Result<(), String> {
    let hint = |why: &str| {
        let example = if s.contains('/') {
            "tcp/127.0.0.1:7447".to_owned()
        } else {
            format!("tcp/{s}")
        };
        format!("\"{s}\": {why}: an endpoint is PROTOCOL/ADDRESS, e.g. {example}")
    };
    let Some((protocol, rest)) = s.split_once('/') else {
        return Err(hint("no protocol"));
    };
    if protocol.is_empty()
        || !protocol
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-')
    {
        return Err(hint(&format!("\"{protocol}\" is not a protocol")));
    }
    let address = rest.split(['?', '#']).next().unwrap_or_default();
    if address.is_empty() {
        return Err(hint("no address"));
    }
    if matches!(protocol, "tcp" | "udp" | "tls" | "quic" | "ws") {
        let port_ok = address
            .rsplit_once(':')
            .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok());
        if !port_ok {
            return Err(hint(&format!("\"{address}\" is not HOST:PORT")));
        }
    }
    Ok(())
}

#[cfg(test)]
mod shard_tests {
    use super::*;

    #[test]
    fn shards_partition_the_channels_and_parse_strictly() {
        let names: Vec<String> = (0..1000).map(|i| format!("pump{i:03}")).collect();
        for count in [1_u32, 2, 3, 7] {
            let shards: Vec<Shard> = (0..count).map(|index| Shard { index, count }).collect();
            let mut sizes = vec![0usize; count as usize];
            for n in &names {
                let owners: Vec<&Shard> = shards.iter().filter(|s| s.owns(n)).collect();
                assert_eq!(owners.len(), 1, "{n} in {count} shards");
                sizes[owners[0].index as usize] += 1;
            }
            // A fair split: every shard within 25 % of 1000/N.
            let fair = 1000.0 / f64::from(count);
            assert!(
                sizes
                    .iter()
                    .all(|s| (*s as f64 - fair).abs() <= 0.25 * fair),
                "{sizes:?}"
            );
        }
        // Fixed values: the assignment must never change between releases.
        assert_eq!(shard_hash(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(shard_hash("a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!("1/2".parse::<Shard>(), Ok(Shard { index: 1, count: 2 }));
        for bad in ["2/2", "1", "x/2", "0/0", "-1/2"] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains(bad), "{e}");
        }
    }
}
