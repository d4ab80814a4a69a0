//! The TOML schema, as written by users. Strict: unknown keys are errors.
//!
//! Matrix entries are written row by row (`H = [[1.0, 0.0]]` is 1×2). A matrix may be a
//! scalar (times the identity; square matrices only), a dense array of rows, or an LPV
//! table `{ base = [[..]], p0 = [[..]], p3 = [[..]] }` meaning M_0 + p0·M_p0 + p3·M_p3.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Deserialize;

/// A whole configuration file: one deployment.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConfigFile {
    /// Zenoh session settings (used by `glrmon run`).
    #[serde(default)]
    pub zenoh: ZenohSpec,
    /// Recording settings (used by `glrmon run`).
    #[serde(default)]
    pub recording: RecordingSpec,
    /// Daemon settings (used by `glrmon run`).
    #[serde(default)]
    pub daemon: DaemonSpec,
    /// The monitored channels.
    #[serde(default)]
    pub channels: Vec<ChannelSpec>,
}

/// Zenoh session settings.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohSpec {
    /// A Zenoh JSON5 configuration file, passed through untouched.
    pub config: Option<PathBuf>,
    /// `peer` (default) or `client`.
    pub mode: Option<String>,
    /// Endpoints to connect to, e.g. `tcp/127.0.0.1:7447`.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    #[serde(default)]
    pub listen: Vec<String>,
    /// Multicast scouting (default off).
    pub multicast_scouting: Option<bool>,
}

/// Daemon settings: workers, queues, output decimation, shutdown.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonSpec {
    /// Worker threads over which channels are sharded (default: available cores).
    pub workers: Option<usize>,
    /// Capacity of each worker's queue in payloads (default 4096); a full queue drops.
    #[serde(default = "default_worker_queue")]
    pub worker_queue: usize,
    /// Capacity of each worker's queue in MiB of payloads (default 64): memory is
    /// bounded in bytes as well as in payloads; a payload beyond it is dropped.
    #[serde(default = "default_worker_queue_mb")]
    pub worker_queue_mb: f64,
    /// Capacity of all worker queues together in MiB (default 256).
    #[serde(default = "default_intake_mb")]
    pub intake_mb: f64,
    /// Capacity of the output queue in records (default 16384).
    #[serde(default = "default_output_queue")]
    pub output_queue: usize,
    /// Publish one `stat` record in this many per channel (default 10; 0: none).
    #[serde(default = "default_stat_every")]
    pub stat_every: u64,
    /// Largest accepted payload in bytes (default 1 MiB).
    #[serde(default = "default_max_payload")]
    pub max_payload_bytes: usize,
    /// Bound on the shutdown drain in seconds (default 5).
    #[serde(default = "default_shutdown")]
    pub shutdown_timeout: f64,
    /// Instance name for the status queryable and liveliness token (default: host-pid).
    pub instance: Option<String>,
    /// `"i/N"`: this instance monitors only the channels whose name hashes to shard i
    /// of N (0 ≤ i < N; a stable FNV-1a hash), so that N instances started from one
    /// configuration split its channels between them (docs/OPERATIONS.md).
    pub shard: Option<String>,
    /// Local address (`host:port`) of the Prometheus `/metrics`, `/healthz` and
    /// `/readyz` endpoints; none by default.
    pub metrics: Option<String>,
}

impl Default for DaemonSpec {
    fn default() -> Self {
        Self {
            workers: None,
            worker_queue: default_worker_queue(),
            worker_queue_mb: default_worker_queue_mb(),
            intake_mb: default_intake_mb(),
            output_queue: default_output_queue(),
            stat_every: default_stat_every(),
            max_payload_bytes: default_max_payload(),
            shutdown_timeout: default_shutdown(),
            instance: None,
            shard: None,
            metrics: None,
        }
    }
}

fn default_worker_queue() -> usize {
    4096
}
fn default_worker_queue_mb() -> f64 {
    64.0
}
fn default_intake_mb() -> f64 {
    256.0
}
fn default_output_queue() -> usize {
    16384
}
fn default_stat_every() -> u64 {
    10
}
fn default_max_payload() -> usize {
    1 << 20
}
fn default_shutdown() -> f64 {
    5.0
}

/// Recording settings (`[recording]`): MCAP files of inputs and results.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingSpec {
    /// Whether `glrmon run` records inputs and results.
    #[serde(default)]
    pub enabled: bool,
    /// Directory of the recordings (default `recordings`).
    pub directory: Option<PathBuf>,
    /// File name prefix (default `glrmon`): `<prefix>-<UTC time>-<n>.mcap`.
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// Record every input sample (default true; needed by `glrmon replay`).
    #[serde(default = "default_true")]
    pub inputs: bool,
    /// Record one `stat` record in this many per channel (default 1; 0: none).
    #[serde(default = "default_one")]
    pub stat_every: u64,
    /// Start a new file at this size in MB (default 1024).
    #[serde(default = "default_max_file_mb")]
    pub max_file_mb: f64,
    /// Start a new file after this many seconds (default 3600).
    #[serde(default = "default_max_file_seconds")]
    pub max_file_seconds: f64,
    /// Delete the oldest recordings while the total exceeds this many MB (default: no cap).
    pub max_total_mb: Option<f64>,
    /// Close a chunk and flush at least this often, in seconds (default 1).
    #[serde(default = "default_flush_seconds")]
    pub flush_seconds: f64,
    /// Chunk size in KiB before compression (default 1024).
    #[serde(default = "default_chunk_kb")]
    pub chunk_kb: u64,
    /// `zstd` (default) or `none`.
    #[serde(default = "default_compression")]
    pub compression: String,
    /// Messages queued for the file thread (default 65536).
    #[serde(default = "default_recording_queue")]
    pub queue: usize,
    /// Pre/post-fault capture: inputs kept only around alarms.
    pub capture: Option<CaptureSpec>,
}

impl Default for RecordingSpec {
    fn default() -> Self {
        Self {
            enabled: false,
            directory: None,
            prefix: default_prefix(),
            inputs: true,
            stat_every: 1,
            max_file_mb: default_max_file_mb(),
            max_file_seconds: default_max_file_seconds(),
            max_total_mb: None,
            flush_seconds: default_flush_seconds(),
            chunk_kb: default_chunk_kb(),
            compression: default_compression(),
            queue: default_recording_queue(),
            capture: None,
        }
    }
}

/// `[recording.capture]`: keep the last `before_seconds` of inputs in memory and write
/// them, and `after_seconds` more, when an alarm fires.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureSpec {
    /// Seconds of inputs kept before an alarm.
    pub before_seconds: f64,
    /// Seconds of inputs written after an alarm.
    pub after_seconds: f64,
}

fn default_prefix() -> String {
    "glrmon".into()
}
fn default_true() -> bool {
    true
}
fn default_one() -> u64 {
    1
}
fn default_max_file_mb() -> f64 {
    1024.0
}
fn default_max_file_seconds() -> f64 {
    3600.0
}
fn default_flush_seconds() -> f64 {
    1.0
}
fn default_chunk_kb() -> u64 {
    1024
}
fn default_compression() -> String {
    "zstd".into()
}
fn default_recording_queue() -> usize {
    65536
}

/// One channel of the plant.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// Unique name; results are published under `glrmon/<name>/…`.
    pub name: String,
    /// Input key expression (default `plant/<name>`).
    pub key: Option<String>,
    /// Sample period in seconds, informative.
    pub period: Option<f64>,
    /// Number of exogenous signals p0…p{q−1} per sample (default: the highest index
    /// used + 1).
    pub signals: Option<usize>,
    /// The state-space model.
    pub model: ModelSpec,
    /// Natural units: the operating point and scale that turn the plant's raw U, Y
    /// into the model's (`[channels.scaling]`).
    pub scaling: Option<ScalingSpec>,
    /// The CSV column names of the inputs, outputs and signals (`[channels.columns]`).
    pub columns: Option<ColumnsSpec>,
    /// The fault dictionary.
    #[serde(default)]
    pub faults: Vec<FaultSpec>,
    /// GLR and alarm settings.
    #[serde(default)]
    pub glr: GlrSpec,
    /// How `glrmon simulate` drives this channel.
    #[serde(default)]
    pub simulation: SimulationSpec,
    /// Sparse fault diagnosis (Zhang 2021) at alarms and in `glrmon diagnose`.
    #[serde(default)]
    pub diagnosis: DiagnosisSpec,
    /// Filter-consistency monitor (`[channels.consistency]`).
    #[serde(default)]
    pub consistency: ConsistencySpec,
}

/// Model matrices (letters of Zhang & Basseville 2014, eq. (1)).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// F (n×n).
    #[serde(rename = "F")]
    pub f: MatrixSpec,
    /// G (n×l); absent means no known inputs enter the state.
    #[serde(rename = "G")]
    pub g: Option<MatrixSpec>,
    /// H (p×n).
    #[serde(rename = "H")]
    pub h: MatrixSpec,
    /// J (p×l); absent means zero.
    #[serde(rename = "J")]
    pub j: Option<MatrixSpec>,
    /// Q (n×n), symmetric positive semi-definite. A constant Q whose smallest eigenvalue
    /// is negative by at most [`PSD_TOLERANCE`](crate::PSD_TOLERANCE) × its spectral
    /// radius (a rounded printout) is replaced by the nearest PSD matrix, with a warning.
    #[serde(rename = "Q")]
    pub q: MatrixSpec,
    /// R (p×p), symmetric positive definite. A constant R within
    /// [`PSD_TOLERANCE`](crate::PSD_TOLERANCE) of that has its small eigenvalues raised
    /// to `PSD_TOLERANCE` × λ_max, with a warning.
    #[serde(rename = "R")]
    pub r: MatrixSpec,
    /// Unknown-input matrix E (n×q, q < p): the detector runs on the innovation
    /// decoupled from E·d_k, and sparse diagnosis on the Kitanidis residual.
    #[serde(rename = "E")]
    pub e: Option<MatrixSpec>,
    /// Cross-covariance S = E(W_kV_kᵀ) (n×p, constant) of correlated process and
    /// measurement noises: an identified innovation model x⁺ = Ax + Bu + Ke,
    /// y = Cx + Du + e is written Q = K·Re·Kᵀ, R = Re, S = K·Re, and runs at its own
    /// order with the exact predictor.
    #[serde(rename = "S")]
    pub s: Option<MatrixSpec>,
    /// X̂_0 (default 0).
    pub x0: Option<Vec<f64>>,
    /// P_0 (default I), symmetric positive definite (rounded matrices as for R).
    #[serde(rename = "P0")]
    pub p0: Option<MatrixSpec>,
}

/// `[channels.scaling]`: model value = (raw value − offset) / scale, per input and
/// output, applied to every sample on intake (and inverted for simulated samples). An
/// absent list means offset 0 or scale 1 for each signal of that kind.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScalingSpec {
    /// Operating point of each input u0…u{l−1}.
    pub u_offset: Option<Vec<f64>>,
    /// Scale of each input (finite, positive).
    pub u_scale: Option<Vec<f64>>,
    /// Operating point of each output y0…y{p−1}.
    pub y_offset: Option<Vec<f64>>,
    /// Scale of each output (finite, positive).
    pub y_scale: Option<Vec<f64>>,
}

/// `[channels.columns]`: the CSV header names read into u0…, y0…, p0… (in that
/// order); other columns of such a file are skipped. An absent list keeps the numbered
/// names (`u0`, `u1`, …).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnsSpec {
    /// Names of the inputs' columns.
    pub u: Option<Vec<String>>,
    /// Names of the outputs' columns.
    pub y: Option<Vec<String>>,
    /// Names of the scheduling signals' columns.
    pub p: Option<Vec<String>>,
}

/// A matrix: scalar × identity, dense rows, or LPV table.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum MatrixSpec {
    /// s·I (square matrices only).
    Scalar(f64),
    /// Rows.
    Dense(Vec<Vec<f64>>),
    /// `{ base = rows, p<i> = rows, … }`.
    Lpv(BTreeMap<String, Vec<Vec<f64>>>),
}

/// A fault column entry: a number or an expression over the sample's signals.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum EntrySpec {
    /// A constant.
    Number(f64),
    /// An expression such as `"-0.5*u0"` or `"p3"`.
    Expr(String),
}

/// A fault of the dictionary.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    /// Unique name within the channel (required, except for the `all_sensors` and
    /// `all_actuators` shortcuts, where it is an optional prefix).
    #[serde(default)]
    pub name: String,
    /// `custom` (default when `psi`/`phi` are given), `actuator_bias`, `actuator_gain`,
    /// `sensor_bias` or `sensor_drift`; or a shortcut for one fault per signal:
    /// `all_sensors` (a `sensor_bias` per output, named `y0_bias`, …) and
    /// `all_actuators` (an `actuator_bias` per input, `u0_bias`, …).
    pub kind: Option<String>,
    /// Onset profile: `step` (default), `impulse`, `ramp` (default of `sensor_drift`) or
    /// `known`.
    pub onset: Option<String>,
    /// Input index of actuator faults.
    pub input: Option<usize>,
    /// Output index of sensor faults.
    pub output: Option<usize>,
    /// Ψ̃: state column (n entries).
    pub psi: Option<Vec<EntrySpec>>,
    /// Φ̃: output column (p entries).
    pub phi: Option<Vec<EntrySpec>>,
}

/// GLR window, threshold and alarm settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlrSpec {
    /// w (default 100).
    #[serde(default = "default_window")]
    pub window: usize,
    /// s (default 1).
    #[serde(default = "default_min_lag")]
    pub min_lag: usize,
    /// Explicit threshold λ on l_k.
    pub threshold: Option<f64>,
    /// Target false-alarm probability per sample (default 10⁻⁴ when no threshold is
    /// given): λ is the χ²(m) upper quantile at α/(w − s) (Bonferroni over the window),
    /// or at α with `threshold_mode = "chi2"`.
    pub false_alarm: Option<f64>,
    /// How `false_alarm` becomes λ: `bonferroni` (default; a conservative bound) or
    /// `chi2` (the per-onset quantile; optimistic: the maximum over the window exceeds
    /// it far more often than α).
    pub threshold_mode: Option<String>,
    /// A threshold found by `glrmon calibrate` for a mean time between false alarms.
    pub calibrated: Option<CalibratedSpec>,
    /// The detection statistic: `glr` (default; the windowed GLR of Zhang & Basseville
    /// 2014) or `chi2` (the plain χ²(p) test of εᵀΣ⁻¹ε on each sample: the classical
    /// baseline, for comparing with the GLR on your data; alarms then carry r̂ = k).
    pub detector: Option<String>,
    /// Hysteresis h: an episode ends below λ(1 − h) (default 0.1).
    #[serde(default = "default_hysteresis")]
    pub hysteresis: f64,
    /// Consecutive samples below λ(1 − h) that end an episode (default 1).
    #[serde(default = "default_clear")]
    pub clear_samples: u32,
    /// Samples between the alarm (raised at the crossing) and its isolation update
    /// (default n; 0: none).
    pub isolation_delay: Option<u32>,
    /// Type-I probability of each isolation test (default 0.01).
    #[serde(default = "default_isolation_alpha")]
    pub isolation_alpha: f64,
    /// Isolation groups (default: each fault against all others).
    #[serde(default)]
    pub groups: Vec<GroupSpec>,
    /// Relative rank cut-off τ for C_k(r) (default 10⁻⁹).
    pub rank_tolerance: Option<f64>,
    /// Largest run of missing samples filled by predict-only steps (default 100); after
    /// a longer one the filter restarts from its initial state.
    #[serde(default = "default_max_gap")]
    pub max_gap: u64,
    /// A sample repeating the last processed index, or up to this many indices before
    /// it, is refused alone as duplicate or late (default 16); one further back means
    /// the publisher started numbering again, and the filter restarts at it.
    #[serde(default = "default_max_reorder")]
    pub max_reorder: u64,
    /// Samples after the start (and after each restart) during which the GLR is held
    /// off: `"window"` (w, until the window is full, as Zhang & Basseville 2014 §6.2
    /// do), a sample count, or none (default).
    pub warm_up: Option<WarmUpSpec>,
}

/// `glr.warm_up`: a keyword or a number of samples.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum WarmUpSpec {
    /// A number of samples.
    Samples(u64),
    /// `"window"`.
    Keyword(String),
}

impl Default for GlrSpec {
    fn default() -> Self {
        Self {
            window: default_window(),
            min_lag: default_min_lag(),
            threshold: None,
            false_alarm: None,
            threshold_mode: None,
            calibrated: None,
            detector: None,
            hysteresis: default_hysteresis(),
            clear_samples: default_clear(),
            isolation_delay: None,
            isolation_alpha: default_isolation_alpha(),
            groups: Vec::new(),
            rank_tolerance: None,
            max_gap: default_max_gap(),
            max_reorder: default_max_reorder(),
            warm_up: None,
        }
    }
}

fn default_window() -> usize {
    100
}
fn default_min_lag() -> usize {
    1
}
fn default_hysteresis() -> f64 {
    0.1
}
fn default_clear() -> u32 {
    1
}
fn default_isolation_alpha() -> f64 {
    0.01
}
fn default_max_gap() -> u64 {
    100
}
fn default_max_reorder() -> u64 {
    16
}

/// A named group of faults tested together against the others.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupSpec {
    /// Name reported in alarms.
    pub name: String,
    /// Fault names.
    pub faults: Vec<String>,
}

/// How `glrmon simulate` drives the channel.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    /// U_k, one expression of `k` per input (random functions allowed); default 0.
    #[serde(default)]
    pub inputs: Vec<String>,
    /// p(k), one expression of `k` per signal; default 0.
    #[serde(default)]
    pub signals: Vec<String>,
    /// Unknown input d_k entering through E, one expression per column of E.
    #[serde(default)]
    pub unknown_input: Vec<String>,
    /// A PI controller closing the loop (for unstable plants).
    pub controller: Option<ControllerSpec>,
}

/// PI controller `u_k[input] = kp·e_k + I_k`, `I_{k+1} = I_k + ki·e_k`, `e_k = setpoint − y_k[output]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
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

/// `[channels.diagnosis]`: sparse fault diagnosis (Zhang 2021, *Dynamic system fault
/// diagnosis under sparseness assumption*): when an alarm fires, the residuals of a
/// Kalman or Kitanidis filter from the onset r̂ to the alarm are regressed on the fault
/// signatures and the few active faults selected by the Lasso (eq. (39)).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnosisSpec {
    /// Run a diagnosis at every alarm of the channel (default false). `glrmon diagnose`
    /// works whatever this says.
    #[serde(default)]
    pub enabled: bool,
    /// Residual generator: `kitanidis` (rejects the unknown input E d_k, Zhang 2021
    /// §III-B; the default when the model has E) or `kalman` (§III-A; the default
    /// otherwise).
    pub residual: Option<String>,
    /// Largest number of samples in the regression (default: every sample from r̂ to
    /// the alarm that the history holds).
    pub span: Option<usize>,
    /// Samples of filter quantities kept to rebuild the regression at an alarm (default
    /// 2 × `glr.window`).
    pub history: Option<usize>,
    /// Level α of the no-fault test that precedes the λ rule: the probability that a
    /// fault-free span gets a non-empty support (default 0.01; 1 turns the test off and
    /// keeps Zhang 2021's rule, which always selects some faults). See
    /// `glrmon_core::sparse::no_fault_test`.
    pub alpha: Option<f64>,
    /// Settings of the Lasso path.
    #[serde(default)]
    pub lasso: LassoSpec,
}

/// `[channels.diagnosis.lasso]`: the λ path of Zhang 2021, eq. (39).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LassoSpec {
    /// Number of log-spaced λ values from λ_max down (default 100, at least 2).
    pub path_points: Option<usize>,
    /// λ_min/λ_max, in (0, 1) (default 1e-4).
    pub ratio: Option<f64>,
}

/// `[channels.consistency]`: the block χ² test of εᵀΣ⁻¹ε that warns when the model no
/// longer fits the plant (a `consistency` record, distinct from fault alarms).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConsistencySpec {
    /// On by default.
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// Samples per block (default 500).
    #[serde(default = "default_consistency_window")]
    pub window: usize,
    /// Probability that a block of a fitting model falls outside the band (default 10⁻⁶).
    #[serde(default = "default_consistency_alpha")]
    pub alpha: f64,
}

impl Default for ConsistencySpec {
    fn default() -> Self {
        Self {
            enabled: true,
            window: default_consistency_window(),
            alpha: default_consistency_alpha(),
        }
    }
}

fn default_consistency_window() -> usize {
    500
}
fn default_consistency_alpha() -> f64 {
    1e-6
}

/// `[channels.glr.calibrated]`: a threshold from `glrmon calibrate`, with what it was
/// calibrated for and on.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibratedSpec {
    /// λ.
    pub threshold: f64,
    /// Target mean number of samples between false-alarm episodes (this or
    /// `sample_far`).
    #[serde(default)]
    pub mtbfa: Option<f64>,
    /// Target fraction of fault-free samples whose l_k exceeds λ (this or `mtbfa`).
    #[serde(default)]
    pub sample_far: Option<f64>,
    /// Fault-free samples it was calibrated on.
    pub samples: u64,
    /// Episodes at λ on those samples (for `sample_far`, the clusters of exceedances
    /// within the window).
    pub episodes: u64,
    /// Samples above λ among them (written for `sample_far`).
    #[serde(default)]
    pub exceedances: Option<u64>,
    /// 95 % confidence interval of λ.
    pub interval: [f64; 2],
    /// Where the data came from (free text).
    #[serde(default)]
    pub source: String,
    /// Calibrated isolation thresholds by test name (a fault, or a `[[channels.glr.groups]]`
    /// name): the minmax statistic at r̂ exceeds them on fault-free data with the
    /// channel's `isolation_alpha`.
    #[serde(default)]
    pub isolation: BTreeMap<String, f64>,
}
