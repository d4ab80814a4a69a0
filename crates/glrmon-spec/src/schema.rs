//! The TOML schema, as written by users. Strict: unknown keys are errors.
//!
//! Matrix entries are written row by row (`H = [[1.0, 0.0]]` is 1×2). A matrix may be a
//! scalar (times the identity; square matrices only), a dense array of rows, or an LPV
//! table `{ base = [[..]], p0 = [[..]], p3 = [[..]] }` meaning M_0 + p0·M_p0 + p3·M_p3.
//!
//! Every type here also describes itself as a JSON Schema ([`schemars::JsonSchema`]):
//! [`crate::json_schema`] derives the schema editors validate a configuration against
//! from these very types, and their doc comments become its descriptions (and the key
//! tables of docs/CONFIG.md), so each field's comment says what it is, its unit or
//! shape, and its default.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::PathBuf;

use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::Deserialize;

/// A whole glrmon configuration file: one deployment (Zenoh session, recording,
/// daemon settings and the monitored channels).
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ConfigFile {
    /// `[zenoh]`: Zenoh session settings, used by `glrmon run` and the other commands
    /// that talk to Zenoh. Optional: every key has a default.
    #[serde(default)]
    pub zenoh: ZenohSpec,
    /// `[recording]`: MCAP recording of the daemon's inputs and results, used by
    /// `glrmon run`. Optional: recording is off by default.
    #[serde(default)]
    pub recording: RecordingSpec,
    /// `[daemon]`: worker threads, queues, limits and endpoints of `glrmon run`.
    /// Optional: every key has a default.
    #[serde(default)]
    pub daemon: DaemonSpec,
    /// `[[channels]]`: the monitored channels, one table each; at least one is required
    /// (an empty list is an error found after parsing).
    #[serde(default)]
    pub channels: Vec<ChannelSpec>,
}

/// `[zenoh]`: Zenoh session settings.
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ZenohSpec {
    /// Path of a Zenoh JSON5 configuration file, passed to Zenoh untouched (the keys
    /// below are applied on top of it). Default: none (Zenoh's defaults).
    pub config: Option<PathBuf>,
    /// Session mode: `peer`, `client` or `router`. Default `peer`.
    #[schemars(extend("enum" = ["peer", "client", "router"]))]
    pub mode: Option<String>,
    /// Endpoints to connect to, e.g. `["tcp/127.0.0.1:7447"]`. Default: none.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. `["tcp/0.0.0.0:7447"]`. Default: none.
    #[serde(default)]
    pub listen: Vec<String>,
    /// Multicast scouting for peers on the local network (boolean). Default: off.
    pub multicast_scouting: Option<bool>,
}

/// `[daemon]`: workers, queues, output decimation, shutdown, instance name, sharding
/// and metrics of `glrmon run`.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DaemonSpec {
    /// Worker threads over which the channels are spread (1 to 1024). Default: the
    /// number of available cores.
    pub workers: Option<usize>,
    /// Capacity of each worker's queue, in payloads (1 to 4194304). A full queue drops
    /// the payload (counted). Default 4096.
    #[serde(default = "default_worker_queue")]
    pub worker_queue: usize,
    /// Capacity of each worker's queue in MiB of payloads: memory is bounded in bytes as
    /// well as in payloads; a payload beyond it is dropped. At least
    /// `max_payload_bytes`. Default 64.
    #[serde(default = "default_worker_queue_mb")]
    pub worker_queue_mb: f64,
    /// Capacity of all worker queues together, in MiB. At least `max_payload_bytes`.
    /// Default 256.
    #[serde(default = "default_intake_mb")]
    pub intake_mb: f64,
    /// Capacity of the output (publication) queues, in records (1 to 4194304): half
    /// for alarms, isolation updates, alarm ends, diagnoses and errors, which the
    /// workers wait for, half for statistics (dropped when full) and inputs. Default
    /// 16384.
    #[serde(default = "default_output_queue")]
    pub output_queue: usize,
    /// Publish one `stat` record (the per-sample statistics) in this many samples per
    /// channel; 0 publishes none. Default 10.
    #[serde(default = "default_stat_every")]
    pub stat_every: u64,
    /// Largest accepted payload, in bytes (1 to 67108864); a larger one is refused as
    /// `too_large`. Default 1048576 (1 MiB).
    #[serde(default = "default_max_payload")]
    pub max_payload_bytes: usize,
    /// Longest drain of the queues at shutdown, in seconds (finite, positive).
    /// Default 5.
    #[serde(default = "default_shutdown")]
    pub shutdown_timeout: f64,
    /// Instance name used by the status queryable and the liveliness token (no `/`,
    /// `*`, `$`, `?`, `#`, `@` or whitespace). Default: `<host>-<pid>`.
    pub instance: Option<String>,
    /// `"i/N"`: this instance monitors only the channels whose name hashes to shard i
    /// of N (0 ≤ i < N; a stable FNV-1a hash), so that N instances started from one
    /// configuration split its channels between them. `"auto"`: the instances started
    /// from one configuration find each other on Zenoh and split its channels among
    /// the live ones (rendezvous hashing); when one is lost, the others take its
    /// channels over within the Zenoh lease (docs/OPERATIONS.md). Default: every
    /// channel.
    pub shard: Option<String>,
    /// Local address (`host:port`, e.g. `127.0.0.1:9464`) of the Prometheus `/metrics`,
    /// `/healthz` and `/readyz` endpoints. Default: none (no HTTP endpoint).
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

/// `[recording]`: MCAP files of the daemon's inputs and results.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RecordingSpec {
    /// Whether `glrmon run` records inputs and results. Default false.
    #[serde(default)]
    pub enabled: bool,
    /// Directory of the recordings, created if missing. Default `recordings` (relative
    /// to the working directory).
    pub directory: Option<PathBuf>,
    /// File name prefix: files are named `<prefix>-<UTC time>-<n>.mcap` (no `/` or
    /// backslash). Default `glrmon`.
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// Record every input sample (needed by `glrmon replay`). Default true.
    #[serde(default = "default_true")]
    pub inputs: bool,
    /// Record one `stat` record in this many samples per channel; 0 records none.
    /// Default 1.
    #[serde(default = "default_one")]
    pub stat_every: u64,
    /// Start a new file at this size, in MB (finite, positive). Default 1024.
    #[serde(default = "default_max_file_mb")]
    pub max_file_mb: f64,
    /// Start a new file after this many seconds (finite, positive). Default 3600.
    #[serde(default = "default_max_file_seconds")]
    pub max_file_seconds: f64,
    /// Delete the oldest recordings while their total exceeds this many MB (at least
    /// `max_file_mb`). Default: no cap.
    pub max_total_mb: Option<f64>,
    /// Close a chunk and flush at least this often, in seconds (positive, at most 60).
    /// Default 1.
    #[serde(default = "default_flush_seconds")]
    pub flush_seconds: f64,
    /// Chunk size in KiB before compression (1 to 1048576). Default 1024.
    #[serde(default = "default_chunk_kb")]
    pub chunk_kb: u64,
    /// Chunk compression: `zstd` or `none`. Default `zstd`.
    #[schemars(extend("enum" = ["zstd", "none"]))]
    #[serde(default = "default_compression")]
    pub compression: String,
    /// Messages queued for the file-writing thread (1 to 4194304). Default 65536.
    #[serde(default = "default_recording_queue")]
    pub queue: usize,
    /// `[recording.capture]`: pre/post-fault capture, inputs recorded only around
    /// alarms. Default: none (every input is recorded when `inputs` is true).
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
#[derive(Debug, Clone, Copy, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CaptureSpec {
    /// Seconds of inputs kept in memory and written before an alarm (0 to 3600).
    /// Required.
    pub before_seconds: f64,
    /// Seconds of inputs written after an alarm (0 to 3600). Required.
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

/// `[[channels]]`: one monitored channel of the plant: a state-space model, its fault
/// dictionary and the GLR settings.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// Unique channel name (no `/`, `*`, `$`, `?`, `#`, `@` or whitespace); results are
    /// published under `glrmon/<name>/…`. Required.
    pub name: String,
    /// Zenoh key expression the channel's samples arrive on (outside `glrmon/**`).
    /// Default `plant/<name>`.
    pub key: Option<String>,
    /// How the payloads on `key` are encoded: `json` (a sample object
    /// `{"k": …, "t": …, "u": […], "y": […], "p": […]}` or an array of them; the
    /// format docs/WIRE.md describes), `cdr` (a ROS 2 message, `[channels.cdr]`),
    /// `sparkplug` (a Sparkplug B payload whose metrics are named as the channel's
    /// columns) or `raw` (little-endian f64 records, `[channels.raw]`). Default `json`.
    #[schemars(extend("enum" = ["json", "cdr", "sparkplug", "raw"]))]
    pub payload: Option<String>,
    /// `[channels.cdr]`: the ROS 2 message type of a `payload = "cdr"` channel.
    /// Default: `std_msgs/msg/Float64MultiArray`.
    pub cdr: Option<CdrSpec>,
    /// `[channels.raw]`: the record layout of a `payload = "raw"` channel. Required
    /// with it.
    pub raw: Option<RawSpec>,
    /// `[channels.tags]`: the channel assembled from one key per signal (a tag per key,
    /// as MQTT and OPC UA gateways publish), instead of whole samples on `key`.
    /// Default: none.
    pub tags: Option<TagsSpec>,
    /// `[channels.topics]`: how `glrmon replay` reads the channel from a recording glrmon
    /// did not write (a ROS 2 bag or Foxglove MCAP: JSON, ROS 2 CDR by the file's
    /// `ros2msg` schemas): as `[channels.tags]`, with topic names as keys (`y0 = { key =
    /// "/dc_motor/y", field = "data.0" }`); `time = "zenoh"` is a message's publish
    /// time, `"arrival"` its log time. Default: none.
    pub topics: Option<TagsSpec>,
    /// Sample period in seconds (finite, positive): turns sample counts into times in
    /// reports, and discretises a continuous-time model (`model.A`), for which it is
    /// required. Default: none.
    pub period: Option<f64>,
    /// Number q of exogenous (scheduling) signals p0…p{q−1} per sample (at most 1024).
    /// Default: the highest index used in the model and expressions + 1.
    pub signals: Option<usize>,
    /// `[channels.model]`: the state-space model (Zhang & Basseville 2014, eq. (1)).
    /// Required.
    pub model: ModelSpec,
    /// `[channels.scaling]`: natural units, the operating point and scale that turn
    /// the plant's raw U, Y into the model's. Default: none (the model is in raw
    /// units).
    pub scaling: Option<ScalingSpec>,
    /// `[channels.columns]`: the CSV column names of the inputs, outputs and signals.
    /// Default: the numbered names `u0`, `y0`, `p0`, …
    pub columns: Option<ColumnsSpec>,
    /// `[[channels.faults]]`: the fault dictionary, one table per fault (at most 128
    /// after the `all_sensors`/`all_actuators` shortcuts). Default: none (a channel
    /// without faults is refused after parsing, except a `kernel` one, whose faults are
    /// its candidates and which takes none here).
    #[serde(default)]
    pub faults: Vec<FaultSpec>,
    /// `[channels.glr]`: GLR window, threshold, alarm and isolation settings.
    /// Optional: every key has a default.
    #[serde(default)]
    pub glr: GlrSpec,
    /// `[channels.simulation]`: how `glrmon simulate` (and `glrmon validate`'s
    /// isolability report) drives this channel. Default: all inputs and signals 0.
    #[serde(default)]
    pub simulation: SimulationSpec,
    /// `[channels.diagnosis]`: sparse fault diagnosis (Zhang 2021) at alarms and in
    /// `glrmon diagnose`. Default: off at alarms.
    #[serde(default)]
    pub diagnosis: DiagnosisSpec,
    /// `[channels.consistency]`: the filter-consistency monitor. Default: on, blocks
    /// of 500 samples (off for detectors that run no Kalman filter, `parity`).
    #[serde(default)]
    pub consistency: ConsistencySpec,
    /// `[channels.parity]`: the parity-space detector (`glr.detector = "parity"`).
    /// Default: the smallest order with a parity space, χ² evaluation.
    pub parity: Option<ParitySpec>,
    /// `[channels.observer]`: the observer detectors (`glr.detector = "fdf"` or
    /// `"uio"`). Default: the optimal gains, χ² evaluation.
    pub observer: Option<ObserverSpec>,
    /// `[channels.rls]`: the parameter-estimation detector (`glr.detector = "rls"`).
    /// Default: forgetting 0.99, χ² evaluation.
    pub rls: Option<RlsSpec>,
    /// `[channels.cusum]`: the CUSUM detector (`glr.detector = "cusum"`). Required
    /// with it.
    pub cusum: Option<CusumSpec>,
    /// `[channels.kernel]`: the kernel deadbeat detector (`glr.detector = "kernel"`):
    /// its fault channels E, noise bounds, kernels and candidate fault functions.
    /// Required with it. With another detector it describes the same plant, so that
    /// the kinds compare on it (`glrmon evaluate --detector kernel,glr`): without
    /// `[[channels.faults]]` the dictionary is one step fault per column of E (`E0`,
    /// `E1`, …, sampled by zero-order hold), and `simulate` and `evaluate` inject the
    /// candidates by name.
    pub kernel: Option<KernelSpec>,
}

/// `[channels.kernel]`: the kernel-based deadbeat fault detection and isolation of Li,
/// Boem, Pin & Parisini (fast-convergent FDI), for `glr.detector = "kernel"`: the
/// continuous-time plant dx/dt = A x + B u + E f(t, x, u) + d_x, y = H x + d_y (the
/// model's `A`, `B`, `H`, with the channel's `period`; `Q`/`Qc` and `R` are required
/// by `[channels.model]` but unused) with noises bounded in Euclidean norm,
/// ‖d_x‖ ≤ `state_noise`, ‖d_y‖ ≤ `output_noise`. A deadbeat estimate of the state,
/// exact after a finite time and insensitive to the fault, feeds the fault's image
/// through a bilateral kernel, r_FD, compared with the worst-case image σ_FD of the
/// noise within its bounds: the statistic is r_FD/(σ_FD + `floor`) and its threshold
/// 1 (no false alarm while the noises stay within their bounds, up to the sampling
/// error `floor` covers). After a detection, each candidate fault function φᵢ is
/// excluded once its isolation residual exceeds its threshold; the one left is
/// isolated. Detection and isolation only: no magnitude, no onset search. The
/// channel's faults are the candidates (`[[channels.faults]]` is not given); without
/// candidates, one fault named `f`.
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct KernelSpec {
    /// E: the fault channels, n×p⋆ (rows; p⋆ < n fault functions enter the state as
    /// E f); H E must have full column rank (the method's Assumption 1). Required.
    #[serde(rename = "E")]
    pub e: Option<Vec<Vec<f64>>>,
    /// d̄_y ≥ 0: the bound on the output noise's Euclidean norm, in output units.
    /// Default 0. At least one of `output_noise`, `state_noise` and `floor` must be
    /// positive.
    pub output_noise: Option<f64>,
    /// d̄_x ≥ 0: the bound on the state noise's Euclidean norm, in state units per
    /// second. Default 0.
    pub state_noise: Option<f64>,
    /// An absolute floor (≥ 0) added to the detection and isolation thresholds, for the
    /// sampling error the continuous-time bounds do not cover (and noise-free models,
    /// whose bounds are 0). Default 0.
    pub floor: Option<f64>,
    /// ω_h, h = 1…n⋆: the deadbeat estimator's kernel rates, one per state of the
    /// fault-free part (n⋆ = n − p⋆), distinct and positive, in 1/s. Default
    /// 1, 2, …, n⋆ (the paper's choice for n⋆ = 2).
    pub rates: Option<Vec<f64>>,
    /// ω̄ > 0 of the estimator's kernels, in 1/s. Default 2.5 (the paper's).
    pub omega_bar: Option<f64>,
    /// N ≥ n⋆: the order of the estimator's kernels. Default n⋆.
    pub order: Option<usize>,
    /// ω > 0: the rate of the detection and isolation kernel, in 1/s; the statistic
    /// forgets like e^{−ωt}. Default 1 (the paper's).
    pub detection_rate: Option<f64>,
    /// θ_a > 0: the estimate is used once |det Γ(t)| ≥ θ_a; |det Γ(t)| tends to a
    /// limit set by the rates, which θ_a must stay below. Default 0.7 × the limit (the
    /// paper's 0.7 for the rates 1, 2, whose limit is 1).
    pub activation: Option<f64>,
    /// Seconds (> 0) the statistic must stay at or below 1 before a new detection may
    /// open a new isolation episode. Default 5 (the paper's).
    pub rearm: Option<f64>,
    /// `[[channels.kernel.candidates]]`: the candidate fault functions of the
    /// isolation, one table each. Default: none (detection only, one fault `f`).
    #[serde(default)]
    pub candidates: Vec<KernelCandidateSpec>,
}

/// `[[channels.kernel.candidates]]`: a candidate fault function φ(t, x, u) ∈ ℝ^{p⋆},
/// with its Lipschitz constant in x.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct KernelCandidateSpec {
    /// Unique name, the fault's name in alarms and isolation results (the rules of
    /// fault names). Required.
    pub name: String,
    /// L ≥ 0: the Lipschitz constant of φ in x, ‖φ(t, x, u) − φ(t, x', u)‖ ≤
    /// L‖x − x'‖, which scales the candidate's isolation threshold. Required.
    pub lipschitz: f64,
    /// φ: one expression per fault channel (p⋆, the columns of `E`) of the estimated
    /// state `x0` … `x{n−1}` (0-based), the inputs `u<i>` and the time `t` in seconds
    /// (k·`period`), with the functions and constants of fault columns (no lags, no
    /// `k`, no `p<i>`), e.g. `["x1 + x2", "cos(x3)", "cos(0.5*x4)"]`. Required.
    pub f: Vec<String>,
}

/// `[channels.cusum]`: Page's CUSUM on the Kalman innovation, the optimal sequential
/// test for a fault of known magnitude (the test the GLR generalises to unknown ones):
/// one CUSUM per fault along the innovation's steady response to it, the statistic
/// 2·max_j g_j (on the GLR's scale), Page's onset estimate, the GLR's magnitudes and
/// isolation. Step faults with constant columns (sensor and actuator biases, constant
/// Ψ/Φ), LTI models without `E`. With `glr.false_alarm` the threshold comes from
/// Siegmund's approximation of the mean time to a false alarm.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CusumSpec {
    /// The magnitude θ_j each fault's CUSUM is tuned for, one per fault in dictionary
    /// order (finite, non-zero, in the fault's units): a fault near this size is
    /// detected fastest. Required.
    pub magnitudes: Vec<f64>,
}

/// `[channels.rls]`: parameter estimation (the survey's parameter-estimation methods):
/// the ARX parameters of each output, derived from the model (its characteristic
/// polynomial and numerators), estimated by recursive least squares with forgetting
/// on regressors whitened by the model's equation error, and tested against their
/// nominal values. LTI models with at least one known input; the test is suspended
/// (and says so) while the input does not excite the parameters.
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RlsSpec {
    /// λ_f in (0, 1]: the forgetting factor; the estimate remembers about 1/(1 − λ_f)
    /// samples. Default 0.99.
    pub forgetting: Option<f64>,
    /// p0 > 0: the initial covariance P_0 = p0·I around the nominal parameters.
    /// Default 1000.
    pub p0: Option<f64>,
    /// The excitation level in (0, 1) below which the test is suspended: the smallest
    /// eigenvalue of the regressors' normalised information. Default 1e-6.
    pub excitation: Option<f64>,
    /// `chi2` (default; (θ̂ − θ_nom)ᵀΣ_θ⁺(θ̂ − θ_nom), approximately χ² with the
    /// parameters' number) or `energy` (windowed energy over `energy_window` samples:
    /// give `glr.threshold` or calibrate).
    #[schemars(extend("enum" = ["chi2", "energy"]))]
    pub evaluation: Option<String>,
    /// Samples of the windowed energy (`evaluation = "energy"`), 1 to 100000. Default 10.
    pub energy_window: Option<usize>,
}

/// `[channels.observer]`: the observer-based residual generators, for
/// `glr.detector = "fdf"` (the fault-detection filter of Ahmad & Mohd-Mokhtar 2021, eqs.
/// (9)-(10): X̂_{k+1} = F X̂_k + G U_k + L(Y_k − J U_k − H X̂_k), residual
/// r_k = V(Y_k − J U_k − H X̂_k)) or `"uio"` (the unknown-input observer of Chen, Patton
/// & Zhang 1996, decoupled from `model.E`, which it needs).
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ObserverSpec {
    /// L: the FDF's observer gain, n×p, rows; F − LH must be stable. Default: the
    /// unified optimal solution of the survey's eq. (18), the steady-state Kalman
    /// predictor gain of Q, R, S (with V = Σ^{−1/2}). Not for `uio`, whose gain is
    /// designed from the model.
    #[serde(rename = "L")]
    pub l: Option<Vec<Vec<f64>>>,
    /// V: the FDF's residual weight, rows of p numbers. Default: Σ^{−1/2} with the
    /// optimal L, the identity with a given L. Not for `uio`.
    #[serde(rename = "V")]
    pub v: Option<Vec<Vec<f64>>>,
    /// `chi2` (default; rᵀΣ_r⁺r with the residual's covariance under Q, R) or `energy`
    /// (the windowed energy of eq. (12) over `energy_window` samples: give
    /// `glr.threshold`, e.g. J_th of eq. (13) or (19), or calibrate).
    #[schemars(extend("enum" = ["chi2", "energy"]))]
    pub evaluation: Option<String>,
    /// Samples of the windowed energy (`evaluation = "energy"`), 1 to 100000. Default 10.
    pub energy_window: Option<usize>,
}

/// `[channels.parity]`: the parity-space residual of Ahmad & Mohd-Mokhtar 2021, eqs.
/// (4)-(8), for `glr.detector = "parity"`: the outputs of a window of s + 1 samples
/// minus their best fit by the model from an unknown initial state (and the unknown
/// input `model.E`, decoupled where the parity space allows it, else the optimal
/// parity vector of eq. (7)).
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ParitySpec {
    /// Order s: the window holds s + 1 samples (at most 64). Default: the smallest order
    /// whose parity space is not empty (decoupled from `model.E` if given).
    pub order: Option<usize>,
    /// How the residual becomes the statistic compared with the threshold: `chi2`
    /// (default; rᵀΣ_r⁻¹r with the residual's covariance under Q, R, χ² with the
    /// parity space's dimension, so `glr.false_alarm` sets the threshold) or `energy`
    /// (the windowed energy (Σ rᵀr)^{1/2} over `energy_window` samples, survey eq.
    /// (12): give `glr.threshold`, e.g. the bound J_th = δ_d of eq. (8), or calibrate).
    #[schemars(extend("enum" = ["chi2", "energy"]))]
    pub evaluation: Option<String>,
    /// Samples of the windowed energy (`evaluation = "energy"`), 1 to 100000. Default 10.
    pub energy_window: Option<usize>,
    /// Relative rank cut-off of [H_o,s H_d,s], in (0, 1). Default 1e-9.
    pub rank_tolerance: Option<f64>,
}

/// `[channels.model]`: the model matrices, letters of Zhang & Basseville 2014,
/// eq. (1): X_{k+1} = F X_k + G U_k + W_k + Ψ_k(r)·θ,
/// Y_k = H X_k + J U_k + V_k + Φ_k(r)·θ, with cov(W) = Q, cov(V) = R. Each matrix is a
/// scalar (times I, square matrices only), rows, or an LPV table. The state equation
/// may instead be written in continuous time, dx/dt = A x + B u + w with
/// E[w(t)w(s)ᵀ] = Qc·δ(t − s): `A`, `B`, `Qc` in place of `F`, `G`, `Q`, discretised
/// when the file is read with the channel's `period` T and a zero-order hold
/// (F = e^{AT}, G = ∫₀ᵀ e^{As} ds·B, Q = ∫₀ᵀ e^{As}·Qc·e^{Aᵀs} ds), so that every tool
/// sees an ordinary F, G, Q. H, J, R, E, S, x0 and P0 keep their meaning in both forms:
/// the output equation is a point sample at t = kT and is not discretised.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// F: state transition, n×n (n states, at most 128). Default: none (required, unless
    /// the continuous-time `A` is given instead).
    #[serde(rename = "F")]
    pub f: Option<MatrixSpec>,
    /// G: known-input matrix, n×l (l inputs, at most 64). Default: absent, no known
    /// input enters the state. Not with `A` (give `B`).
    #[serde(rename = "G")]
    pub g: Option<MatrixSpec>,
    /// H: output matrix, p×n (p outputs, at most 64). Required.
    #[serde(rename = "H")]
    pub h: MatrixSpec,
    /// J: feed-through of the known inputs to the outputs, p×l. Default: zero.
    #[serde(rename = "J")]
    pub j: Option<MatrixSpec>,
    /// Q: process-noise covariance cov(W_k), n×n, symmetric positive semi-definite; a
    /// scalar q means q·I. A constant Q whose smallest eigenvalue is negative by at most
    /// `PSD_TOLERANCE` (1e-9) × its spectral radius (a rounded printout) is replaced by
    /// the nearest PSD matrix, with a warning. With `A`, a Q given instead of `Qc` is
    /// the covariance per sample (as `glrmon identify --model` estimates it). Default:
    /// none (required, unless `A` and `Qc` are given).
    #[serde(rename = "Q")]
    pub q: Option<MatrixSpec>,
    /// R: measurement-noise covariance cov(V_k), p×p, symmetric positive definite; a
    /// scalar r means r·I. Required. A constant R within `PSD_TOLERANCE` of that has its
    /// small eigenvalues raised to `PSD_TOLERANCE` × λ_max, with a warning.
    #[serde(rename = "R")]
    pub r: MatrixSpec,
    /// E: unknown-input matrix, n×q with q < p (X_{k+1} gets + E d_k, d_k unknown): the
    /// detector runs on the innovation decoupled from E d_k (p − q directions), and
    /// sparse diagnosis on the Kitanidis residual (Zhang 2021 §III-B); H E must have
    /// full column rank. Constant. Default: none.
    #[serde(rename = "E")]
    pub e: Option<MatrixSpec>,
    /// Fd: the unknown input's effect on the outputs, p×q (Y_k gets + Fd d_k with the d_k
    /// of `E`: the survey's F_d), constant; needs `E` (zeros if d reaches only the
    /// outputs). Only the `parity` detector decouples it (M[H_o,s H_d,s] = 0 with F_d
    /// in H_d,s); the Kalman-based kinds (`glr`, `chi2`) and `uio` decouple state unknown
    /// inputs only and refuse it; `fdf` and `rls` do not decouple. `glrmon simulate`
    /// adds it to the outputs. Default: none (zero).
    #[serde(rename = "Fd")]
    pub fd: Option<MatrixSpec>,
    /// S: cross-covariance E(W_k V_kᵀ), n×p, constant, of correlated process and
    /// measurement noises: an identified innovation model x⁺ = Ax + Bu + Ke,
    /// y = Cx + Du + e is written Q = K·Re·Kᵀ, R = Re, S = K·Re, and runs at its own
    /// order with the exact predictor. Not with E. Default: none (uncorrelated).
    #[serde(rename = "S")]
    pub s: Option<MatrixSpec>,
    /// X̂_0: initial state estimate, n numbers. Default: zeros.
    pub x0: Option<Vec<f64>>,
    /// P_0: initial state covariance, n×n, symmetric positive definite (rounded
    /// matrices as for R). Default: the identity I.
    #[serde(rename = "P0")]
    pub p0: Option<MatrixSpec>,
    /// A: continuous-time state matrix of dx/dt = A x + B u + w, n×n, in 1/s (the
    /// model's time unit is the second, as `period`'s), instead of F: F = e^{AT} with the
    /// channel's `period` T, which is then required. Constant: an LPV table is refused
    /// (e^{A(p)T} is not affine in p). Default: none (a discrete-time model).
    #[serde(rename = "A")]
    pub a: Option<MatrixSpec>,
    /// B: continuous-time input matrix, n×l, in state units per second per input unit,
    /// with `A`, instead of G: G = ∫₀ᵀ e^{As} ds·B (the inputs held over each period, a
    /// zero-order hold). May be an LPV table (G is then too, exactly). Default: absent,
    /// no known input enters the state.
    #[serde(rename = "B")]
    pub b: Option<MatrixSpec>,
    /// Qc: continuous process-noise intensity (power spectral density) of w,
    /// E[w(t)w(s)ᵀ] = Qc·δ(t − s), n×n, symmetric positive semi-definite, in state
    /// units² per second; a scalar q means q·I. With `A`, instead of Q:
    /// Q = ∫₀ᵀ e^{As}·Qc·e^{Aᵀs} ds (Van Loan 1978), about Qc·T for a period short
    /// next to the time constants. May be an LPV table. Default: none (then Q is
    /// required).
    #[serde(rename = "Qc")]
    pub qc: Option<MatrixSpec>,
}

/// `[channels.scaling]`: model value = (raw value − offset) / scale, per input and
/// output, applied to every sample on intake (and inverted for simulated samples). An
/// absent list means offset 0 or scale 1 for each signal of that kind.
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScalingSpec {
    /// Operating point of each input u0…u{l−1}, in raw units (l numbers). Default: 0.
    pub u_offset: Option<Vec<f64>>,
    /// Scale of each input, in raw units per model unit (l finite, positive numbers).
    /// Default: 1.
    pub u_scale: Option<Vec<f64>>,
    /// Operating point of each output y0…y{p−1}, in raw units (p numbers). Default: 0.
    pub y_offset: Option<Vec<f64>>,
    /// Scale of each output, in raw units per model unit (p finite, positive numbers).
    /// Default: 1.
    pub y_scale: Option<Vec<f64>>,
}

/// `[channels.columns]`: the CSV header names read into u0…, y0…, p0… (in that
/// order), which also name the signals in reports and alarm lines, and their units;
/// with names given, other columns of such a file are skipped. An absent list keeps
/// the numbered names (`u0`, `u1`, …).
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ColumnsSpec {
    /// CSV column names of the inputs u0…u{l−1} (l names). Default `u0`, `u1`, …
    pub u: Option<Vec<String>>,
    /// CSV column names of the outputs y0…y{p−1} (p names). Default `y0`, `y1`, …
    pub y: Option<Vec<String>>,
    /// CSV column names of the scheduling signals p0…p{q−1} (q names). Default `p0`,
    /// `p1`, …
    pub p: Option<Vec<String>>,
    /// Units of the inputs as the plant gives them (raw units, before
    /// `[channels.scaling]`), e.g. `["m³/h", "m³/h"]`: l labels, shown by reports,
    /// `validate` and the alarm lines beside raw-unit magnitudes. Default: none.
    pub u_units: Option<Vec<String>>,
    /// Units of the outputs in raw units (p labels), e.g. `["cm", "cm", "m³/h"]`.
    /// Default: none.
    pub y_units: Option<Vec<String>>,
    /// Units of the scheduling signals (q labels). Default: none.
    pub p_units: Option<Vec<String>>,
}

/// `[channels.cdr]`: which ROS 2 message a `cdr` channel receives (docs/WIRE.md).
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CdrSpec {
    /// The message type: `std_msgs/msg/Float64MultiArray` (`data` holds the inputs,
    /// then the outputs, then the scheduling signals, from `layout.data_offset` on; the
    /// time is the transport's) or `glrmon_msgs/msg/Sample` (`int64 k`, −1 for none;
    /// `float64 t`, NaN for none; `float64[] u`, `y`, `p`). Default
    /// `std_msgs/msg/Float64MultiArray`. A payload whose Zenoh encoding declares its
    /// type (`application/cdr;glrmon_msgs/msg/Sample`) is decoded as that type.
    #[schemars(extend("enum" = ["std_msgs/msg/Float64MultiArray", "glrmon_msgs/msg/Sample"]))]
    pub message: Option<String>,
}

/// `[channels.raw]`: the record of a `raw` channel, each field an 8-byte little-endian
/// f64; a payload holds one or more whole records, one sample each.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RawSpec {
    /// The fields in byte order: `k` (the sample index, an integer value), `t` (the
    /// time in seconds), the channel's column names (`[channels.columns]`, else `u0`,
    /// `y0`, `p0`, …: every signal exactly once) and `_` for 8 bytes not read, e.g.
    /// `["t", "u0", "y0", "y1"]`. Required.
    pub layout: Vec<String>,
}

/// `[channels.tags]`: a channel whose signals arrive each on a key of its own, as a
/// bare JSON number (`12.5`, `true`) or a field of a JSON object; samples are formed on
/// a fixed `period` or at each value of a `trigger` signal (docs/WIRE.md).
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TagsSpec {
    /// Sample period in seconds (finite, positive): a sample at every multiple of it,
    /// each signal at its last value at or before that time. One of `period` and
    /// `trigger` is required.
    pub period: Option<f64>,
    /// The signal (a column name) whose every value forms a sample, with the other
    /// signals at their latest values. One of `period` and `trigger` is required.
    pub trigger: Option<String>,
    /// How long a signal that sent nothing keeps its last value: `hold` periods (or
    /// triggers); beyond, samples are gaps until it sends again (1 to 1000000).
    /// Default 3.
    pub hold: Option<u32>,
    /// The time of a tag's value: `zenoh` (the Zenoh timestamp of the publication,
    /// else its arrival) or `arrival` (when glrmon received it: for publishers whose
    /// clocks disagree). A tag with `time_field` reads its time from the payload.
    /// Default `zenoh`.
    #[schemars(extend("enum" = ["zenoh", "arrival"]))]
    pub time: Option<String>,
    /// Each signal's key: `y0 = "plant/dc/current"`, or `y1 = { key = "plant/dc/speed",
    /// field = "value", time_field = "ts" }` to read a field of a JSON object (a path
    /// `data.speed`) and the time in seconds since the Unix epoch from another. Every
    /// signal of the channel (by its column name) has one. Required.
    pub keys: std::collections::BTreeMap<String, TagKeySpec>,
}

/// Where one signal of a tag channel arrives.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum TagKeySpec {
    /// The key expression; the payload is a bare JSON number or boolean.
    Key(String),
    /// A key expression and the fields of its JSON payload.
    Fields(TagFieldsSpec),
}

/// A signal's key expression and the fields of its JSON payload.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TagFieldsSpec {
    /// The Zenoh key expression the signal arrives on (outside `glrmon/**`). Required.
    pub key: String,
    /// The path of the value in a JSON object, fields joined by `.` (`value`,
    /// `data.speed`; a number indexes an array, `data.0`). Default: the payload is the
    /// bare number.
    pub field: Option<String>,
    /// The path of the value's time (seconds since the Unix epoch, a number) in the
    /// JSON object. Default: the time `time` says.
    pub time_field: Option<String>,
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

/// The rows of a dense matrix, as a schema: an array of arrays of numbers.
fn rows_schema(description: &str) -> Schema {
    json_schema!({
        "description": description,
        "type": "array",
        "minItems": 1,
        "items": { "type": "array", "minItems": 1, "items": { "type": "number" } }
    })
}

/// By hand: the derive would call the LPV table a map of any keys, where only `base`
/// and `p<i>` are accepted, and `base` is required.
impl JsonSchema for MatrixSpec {
    fn schema_name() -> Cow<'static, str> {
        "Matrix".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        let rows = rows_schema("Dense rows: `[[a, b], [c, d]]` is 2×2, written row by row.");
        let lpv_rows = rows_schema("Rows of one term, the same shape as `base`.");
        json_schema!({
            "description": "A matrix: a scalar s (s·I, square matrices only), dense rows \
                (`[[1.0, 0.0], [0.0, 1.0]]`, row by row), or an LPV table \
                `{ base = rows, p0 = rows, … }` meaning M_0 + p0(k)·M_p0 + … \
                (Zhang & Basseville 2014, eq. (53)).",
            "anyOf": [
                { "type": "number", "description": "s·I (square matrices only)." },
                rows,
                {
                    "type": "object",
                    "description": "LPV table: `base` plus one term per scheduling signal p<i>.",
                    "required": ["base"],
                    "propertyNames": { "pattern": "^(base|p[0-9]+)$" },
                    "additionalProperties": lpv_rows
                }
            ]
        })
    }
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

/// By hand: the derive would say "a number or any string", where the string is an
/// expression of the grammar of [`crate::expr`].
impl JsonSchema for EntrySpec {
    fn schema_name() -> Cow<'static, str> {
        "Entry".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "description": "A column entry: a number, or an expression (a string) of the known \
                inputs `u<i>`, the scheduling signals `p<i>`, their past values `u0[-1]`, \
                numbers, `+ - * / ^`, the functions sin cos tan exp log sqrt abs min max \
                pow and the constants pi, e; evaluated at every sample.",
            "anyOf": [
                { "type": "number" },
                { "type": "string", "minLength": 1, "examples": ["-0.5*u0", "p3", "0.2*u0[-1] - p0"] }
            ]
        })
    }
}

/// `[[channels.faults]]`: one fault of the dictionary, an additive change θ·(Ψ, Φ)
/// from an unknown onset r (Zhang & Basseville 2014, eq. (1)). Either a `kind`
/// shortcut with `input`/`output`, or explicit `psi`/`phi` columns.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    /// Unique name within the channel, reported in alarms. Required, except for the
    /// `all_sensors` and `all_actuators` shortcuts, where it is an optional prefix
    /// (faults `<name>0`, `<name>1`, …).
    #[serde(default)]
    pub name: String,
    /// Fault kind: `custom` (the default; give `psi` and/or `phi`), `actuator_bias`
    /// (Ψ = G e_i, Φ = J e_i; needs `input`), `actuator_gain` (loss of effectiveness,
    /// Ψ = −G e_i u_i; needs `input`), `sensor_bias` (Φ = e_j; needs `output`) or
    /// `sensor_drift` (a sensor bias with a ramp onset); or a shortcut for one fault
    /// per signal: `all_sensors` (a `sensor_bias` per output, named `y0_bias`, …) and
    /// `all_actuators` (an `actuator_bias` per input, `u0_bias`, …).
    #[schemars(extend("enum" = ["custom", "actuator_bias", "actuator_gain", "sensor_bias", "sensor_drift", "all_sensors", "all_actuators"]))]
    pub kind: Option<String>,
    /// Onset profile of the fault from its onset r (Zhang & Basseville 2014, eqs. (4),
    /// (51)): `step` (default; Ψ̃·1{k ≥ r}), `impulse` (a jump entering X_r), `ramp`
    /// ((k − r + 1)·Ψ̃; the default and only choice of `sensor_drift`) or `known` (the
    /// columns are the whole profile: no onset search).
    #[schemars(extend("enum" = ["step", "impulse", "ramp", "known"]))]
    pub onset: Option<String>,
    /// Index i of the input u_i of an actuator fault (0-based, below l).
    pub input: Option<usize>,
    /// Index j of the output y_j of a sensor fault (0-based, below p).
    pub output: Option<usize>,
    /// Ψ̃: the state fault signature column (Zhang & Basseville 2014), n entries, each
    /// a number or an expression of `u<i>`, `p<i>`, lags such as `"u0[-1]"`. Default:
    /// zero. In model units.
    pub psi: Option<Vec<EntrySpec>>,
    /// Φ̃: the output fault signature column (Zhang & Basseville 2014), p entries, each
    /// a number or an expression. Default: zero. In model units.
    pub phi: Option<Vec<EntrySpec>>,
}

/// `[channels.glr]`: GLR window, threshold, alarm and isolation settings (Zhang &
/// Basseville 2014, §4-5).
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GlrSpec {
    /// Window w of candidate onsets r ∈ {k − w + 1, …, k − s} (eq. (37)), in samples
    /// (at most 100000, lowered by the channel's memory budget). Default 100.
    #[serde(default = "default_window")]
    pub window: usize,
    /// Minimum lag s of the window (eq. (37)), in samples, below w. Default 1.
    #[serde(default = "default_min_lag")]
    pub min_lag: usize,
    /// Explicit threshold λ on the GLR statistic l_k (eq. (35)). Default: none (set
    /// from `false_alarm`; 1 for the `kernel` detector, whose statistic r_FD/σ_FD
    /// has no probability law).
    pub threshold: Option<f64>,
    /// Target false-alarm probability per sample (default 10⁻⁴ when no threshold is
    /// given): λ is the χ²(m) upper quantile at α/(w − s) (Bonferroni over the window),
    /// or at α with `threshold_mode = "chi2"`. Not for the `kernel` detector (no
    /// probability law: its threshold 1 is a bound).
    pub false_alarm: Option<f64>,
    /// How `false_alarm` becomes λ: `bonferroni` (default; a conservative bound) or
    /// `chi2` (the per-onset quantile; optimistic: the maximum over the window exceeds
    /// it far more often than α).
    #[schemars(extend("enum" = ["bonferroni", "chi2"]))]
    pub threshold_mode: Option<String>,
    /// `[channels.glr.calibrated]`: a threshold found by `glrmon calibrate` for a mean
    /// time between false alarms (written by `glrmon calibrate --write`). Default:
    /// none.
    pub calibrated: Option<CalibratedSpec>,
    /// The detection statistic: `glr` (default; the windowed GLR of Zhang & Basseville
    /// 2014), `chi2` (the plain χ²(p) test of εᵀΣ⁻¹ε on each sample: the classical
    /// baseline, for comparing with the GLR on your data; alarms then carry r̂ = k) or
    /// `parity` (the parity-space residual, `[channels.parity]`), `fdf` (the observer
    /// fault-detection filter) or `uio` (the unknown-input observer,
    /// `[channels.observer]`) or `rls` (parameter estimation, `[channels.rls]`): these
    /// four detect only (no magnitude, no isolation); `cusum` (Page's CUSUM for faults
    /// of known magnitude, `[channels.cusum]`) keeps the GLR's magnitudes and isolation;
    /// `kernel` (the kernel deadbeat detector of a continuous-time model,
    /// `[channels.kernel]`: threshold 1, isolation among candidate fault functions, no
    /// magnitude); alarms carry the first sample of the statistic's evidence as r̂.
    #[schemars(extend("enum" = ["glr", "chi2", "cusum", "parity", "fdf", "uio", "rls", "kernel"]))]
    pub detector: Option<String>,
    /// Hysteresis h in [0, 1): an alarm episode ends below λ(1 − h). Default 0.1.
    #[serde(default = "default_hysteresis")]
    pub hysteresis: f64,
    /// Consecutive samples below λ(1 − h) that end an episode. Default 1.
    #[serde(default = "default_clear")]
    pub clear_samples: u32,
    /// How an alarm episode ends: `fault_gone` (default; when the fault followed from
    /// the alarm's onset past the window has had no evidence in the last w samples for
    /// `gone_samples` samples in a row, and l_k is below λ(1 − h): one episode per
    /// fault however long it lasts; the evidence is the magnitude of the last w
    /// samples along the fault's earlier estimate, over its standard deviation, tested
    /// at level `gone_alpha`) or `below_threshold` (when l_k stays below λ(1 − h) for
    /// `clear_samples` samples: a fault that outlasts the window can end its episode
    /// and raise another later). Kinds that cannot follow an onset (`chi2`) always end
    /// below the threshold.
    #[schemars(extend("enum" = ["fault_gone", "below_threshold"]))]
    pub episode_end: Option<String>,
    /// Level of the no-evidence test of `episode_end = "fault_gone"`, in (0, 0.5): the
    /// evidence of a fault still there falls below its normal quantile this often.
    /// Default 0.01.
    pub gone_alpha: Option<f64>,
    /// Consecutive samples without evidence of the followed fault that end an episode
    /// (`episode_end = "fault_gone"`), at least 1. Default 2w: the evidence is judged
    /// on the last w samples, and a fault still there must look gone on two windows'
    /// worth of them (a dip of one window's length happens in a long episode).
    pub gone_samples: Option<u32>,
    /// Samples between the alarm (raised at the crossing) and its isolation update; 0
    /// sends none. Default: n (the number of states); 0 for `detector = "kernel"`,
    /// which sends an update at each exclusion of a candidate instead.
    pub isolation_delay: Option<u32>,
    /// Type-I probability of each isolation (minmax) test, in (0, 1). Default 0.01.
    #[serde(default = "default_isolation_alpha")]
    pub isolation_alpha: f64,
    /// The law of an isolation test without a calibrated threshold: `bonferroni`
    /// (default for the GLR: the χ²(dof) upper quantile at `isolation_alpha`/(w − s),
    /// since the test runs at the onset r̂ the data chose, where the plain χ² level is
    /// exceeded far more often than α) or `chi2` (the quantile at `isolation_alpha`,
    /// the nominal law of a test at a known onset, as in Zhang & Basseville 2014).
    #[schemars(extend("enum" = ["bonferroni", "chi2"]))]
    pub isolation_law: Option<String>,
    /// `[[channels.glr.groups]]`: isolation groups tested together. Default: each fault
    /// against all others.
    #[serde(default)]
    pub groups: Vec<GroupSpec>,
    /// Relative rank cut-off τ of the information matrix C_k(r), in (0, 1).
    /// Default 1e-9.
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
    /// Samples after each restart of the filter (a gap longer than `max_gap`, a
    /// publisher numbering anew, a numerical failure) during which alarms are held off
    /// while the estimate converges from (x̂₀, P₀); the evidence gathered meanwhile is
    /// then forgotten, so the initial-state transient is never read as a fault.
    /// Default: the detector's memory (the window w for the GLR kinds).
    pub settle: Option<u64>,
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

/// By hand: the only keyword is `"window"`.
impl JsonSchema for WarmUpSpec {
    fn schema_name() -> Cow<'static, str> {
        "WarmUp".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "description": "A number of samples (at most 1000000000), or \"window\" (w samples).",
            "anyOf": [
                { "type": "integer", "minimum": 0 },
                { "enum": ["window"] }
            ]
        })
    }
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
            episode_end: None,
            gone_alpha: None,
            gone_samples: None,
            isolation_delay: None,
            isolation_alpha: default_isolation_alpha(),
            isolation_law: None,
            groups: Vec::new(),
            rank_tolerance: None,
            max_gap: default_max_gap(),
            max_reorder: default_max_reorder(),
            settle: None,
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
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GroupSpec {
    /// Group name, reported in alarms. Required.
    pub name: String,
    /// Names of the channel's faults in the group. Required.
    pub faults: Vec<String>,
}

/// `[channels.simulation]`: how `glrmon simulate` drives the channel.
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    /// U_k: one expression of `k` per input (random functions `uniform`, `normal`
    /// allowed), e.g. `["sin(0.1*k)"]`. Default: 0 for each input.
    #[serde(default)]
    pub inputs: Vec<String>,
    /// p(k): one expression of `k` per scheduling signal. Default: 0 for each signal.
    #[serde(default)]
    pub signals: Vec<String>,
    /// Unknown input d_k entering through E: one expression of `k` per column of E.
    /// Default: 0.
    #[serde(default)]
    pub unknown_input: Vec<String>,
    /// `[channels.simulation.controller]`: a PI controller closing the loop (for
    /// unstable plants). Default: none (open loop).
    pub controller: Option<ControllerSpec>,
}

/// PI controller `u_k[input] = kp·e_k + I_k`, `I_{k+1} = I_k + ki·e_k`, `e_k = setpoint − y_k[output]`.
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
    /// Index of the output measured (0-based). Required.
    pub output: usize,
    /// Index of the input driven (0-based). Required.
    pub input: usize,
    /// Setpoint of the measured output, in model units. Required.
    pub setpoint: f64,
    /// Proportional gain kp. Required.
    pub kp: f64,
    /// Integral gain ki. Required.
    pub ki: f64,
}

/// `[channels.diagnosis]`: sparse fault diagnosis (Zhang 2021, *Dynamic system fault
/// diagnosis under sparseness assumption*): when an alarm fires, the residuals of a
/// Kalman or Kitanidis filter from the onset r̂ to the alarm are regressed on the fault
/// signatures and the few active faults selected by the Lasso (eq. (39)).
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DiagnosisSpec {
    /// Run a diagnosis at every alarm of the channel. `glrmon diagnose` works whatever
    /// this says. Default false.
    #[serde(default)]
    pub enabled: bool,
    /// Residual generator: `kitanidis` (rejects the unknown input E d_k, Zhang 2021
    /// §III-B; the default when the model has E) or `kalman` (§III-A; the default
    /// otherwise).
    #[schemars(extend("enum" = ["kalman", "kitanidis"]))]
    pub residual: Option<String>,
    /// Largest number of samples in the regression (at most 1000000). Default: every
    /// sample from r̂ to the alarm that the history holds.
    pub span: Option<usize>,
    /// Samples of filter quantities kept to rebuild the regression at an alarm (at most
    /// 1000000). Default: 2 × `glr.window`.
    pub history: Option<usize>,
    /// Level α of the no-fault test that precedes the λ rule: the probability that a
    /// fault-free span gets a non-empty support (default 0.01; 1 turns the test off and
    /// keeps Zhang 2021's rule, which always selects some faults). See
    /// `glrmon_core::sparse::no_fault_test`.
    pub alpha: Option<f64>,
    /// `[channels.diagnosis.lasso]`: settings of the Lasso path. Optional.
    #[serde(default)]
    pub lasso: LassoSpec,
}

/// `[channels.diagnosis.lasso]`: the λ path of Zhang 2021, eq. (39).
#[derive(Debug, Clone, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LassoSpec {
    /// Number of log-spaced λ values from λ_max down (2 to 10000). Default 100.
    pub path_points: Option<usize>,
    /// λ_min/λ_max, in (0, 1). Default 1e-4.
    pub ratio: Option<f64>,
    /// How "the widest range of λ with the same number of faults" and its middle are
    /// measured (Zhang 2021, §IV): `log` (in ln λ, the default: a fault several times
    /// smaller than another is not missed) or `linear` (in λ: the paper's Table II,
    /// fewer spurious faults under strong noise but a smaller fault beside a larger one
    /// is often left out). See `glrmon_core::sparse::PlateauScale`.
    #[schemars(extend("enum" = ["log", "linear"]))]
    pub plateau_scale: Option<String>,
}

/// `[channels.consistency]`: the block χ² test of εᵀΣ⁻¹ε that warns when the model no
/// longer fits the plant (a `consistency` record, distinct from fault alarms).
#[derive(Debug, Clone, Copy, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ConsistencySpec {
    /// Whether the consistency test runs. Default true.
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// Samples per block (1 to 100000000). Default 500.
    #[serde(default = "default_consistency_window")]
    pub window: usize,
    /// Probability that a block of a fitting model falls outside the band, in (0, 1).
    /// Default 1e-6.
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
#[derive(Debug, Clone, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CalibratedSpec {
    /// The calibrated threshold λ on l_k. Required.
    pub threshold: f64,
    /// Target mean number of samples between false-alarm episodes (this or
    /// `sample_far`).
    #[serde(default)]
    pub mtbfa: Option<f64>,
    /// Target fraction of fault-free samples whose l_k exceeds λ (this or `mtbfa`).
    #[serde(default)]
    pub sample_far: Option<f64>,
    /// Fault-free samples it was calibrated on. Required.
    pub samples: u64,
    /// Episodes at λ on those samples (for `sample_far`, the clusters of exceedances
    /// within the window).
    pub episodes: u64,
    /// Samples above λ among them (written for `sample_far`).
    #[serde(default)]
    pub exceedances: Option<u64>,
    /// 95 % confidence interval of λ, `[low, high]`. Required.
    pub interval: [f64; 2],
    /// Where the data came from (free text). Default empty.
    #[serde(default)]
    pub source: String,
    /// Calibrated isolation thresholds by test name (a fault, or a `[[channels.glr.groups]]`
    /// name): the minmax statistic at r̂ exceeds them on fault-free data with the
    /// channel's `isolation_alpha`.
    #[serde(default)]
    pub isolation: BTreeMap<String, f64>,
}
