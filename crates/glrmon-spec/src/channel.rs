//! A validated channel: its model, fault dictionary, GLR, diagnosis and simulation
//! settings, as the monitor, the simulator and the tools use them.

use std::fmt;

use glrmon_core::sparse::LassoSettings;
use glrmon_core::{
    AlarmSettings, Column, Dims, Fault, FaultDictionary, Lpv, LpvMatrix, ModelError, Onset,
    SignalScaling, WindowSettings,
};
use nalgebra::{DMatrix, DVector};

use crate::expr::{Expr, ExprColumn};
use crate::{DetectorKind, PayloadFormat, Tags};

/// How a fault column is computed.
#[derive(Debug, Clone)]
pub(crate) enum ColumnPlan {
    Zero,
    Constant(DVector<f64>),
    InputBias(usize),
    GainLoss(usize),
    Exprs(Vec<Expr>),
}

#[derive(Debug, Clone)]
pub(crate) struct FaultPlan {
    pub(crate) name: String,
    pub(crate) onset: Onset,
    pub(crate) state: ColumnPlan,
    pub(crate) output: ColumnPlan,
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
    /// χ²(m) upper quantile at α for faults of known profile (no onset to search:
    /// one test per sample, exact).
    KnownOnset {
        /// α.
        false_alarm: f64,
    },
    /// The CUSUM's threshold for a per-sample false-alarm probability α from
    /// Siegmund's approximation of its mean run length, α/m per fault's CUSUM.
    Siegmund {
        /// α.
        false_alarm: f64,
    },
    /// 1, the bound of a statistic that no noise within its declared bounds can cross
    /// (the `kernel` detector's r_FD/σ_FD): no false alarm under the noise bounds, and
    /// no probability law to set it from.
    Bounded,
    /// Found by `glrmon calibrate` on fault-free data.
    Calibrated {
        /// What it was calibrated for: a mean number of samples between false-alarm
        /// episodes, or a fraction of samples above λ.
        target: glrmon_core::threshold::calibration::Target,
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

/// The RLS detector's settings of a channel (`[channels.rls]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RlsChannelSettings {
    /// Forgetting, P_0, excitation level.
    pub rls: glrmon_core::RlsSettings,
    /// How the residual becomes the decision statistic.
    pub evaluation: glrmon_core::detector::Evaluation,
}

/// A candidate fault function of the `kernel` detector, compiled
/// (`[[channels.kernel.candidates]]`).
#[derive(Debug, Clone)]
pub struct KernelCandidate {
    /// Its name, the fault's.
    pub name: String,
    /// Its Lipschitz constant in x.
    pub lipschitz: f64,
    /// φ, one expression per fault channel.
    pub f: Vec<Expr>,
}

/// The `kernel` detector's settings of a channel (`[channels.kernel]` with the
/// continuous-time model).
#[derive(Debug, Clone)]
pub struct KernelChannelSettings {
    /// A, B, C (the model's `H`) and E.
    pub model: glrmon_core::KernelModel,
    /// The method's settings, defaults filled in.
    pub settings: glrmon_core::KernelSettings,
    /// The candidate fault functions, in file order.
    pub candidates: Vec<KernelCandidate>,
}

impl KernelChannelSettings {
    /// The candidates as the detector takes them, each with its own evaluator.
    #[must_use]
    pub fn candidates(&self, inputs: usize) -> Vec<glrmon_core::Candidate> {
        self.candidates
            .iter()
            .map(|c| glrmon_core::Candidate {
                name: c.name.clone(),
                lipschitz: c.lipschitz,
                function: Box::new(crate::expr::ExprCandidate::new(c.f.clone(), inputs)),
            })
            .collect()
    }
}

/// The observer detectors' settings of a channel (`[channels.observer]`).
#[derive(Debug, Clone, PartialEq)]
pub struct ObserverSettings {
    /// The FDF's (L, V), or `None` for the optimal gains of the survey's eq. (18).
    pub gains: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// How the residual becomes the decision statistic.
    pub evaluation: glrmon_core::detector::Evaluation,
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
    /// The raw unit of each input (`columns.u_units`), empty strings when not given.
    pub u_units: Vec<String>,
    /// The raw unit of each output (`columns.y_units`), empty strings when not given.
    pub y_units: Vec<String>,
    /// The raw unit of each scheduling signal (`columns.p_units`), empty strings when
    /// not given.
    pub p_units: Vec<String>,
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
            u_units: vec![String::new(); dims.inputs],
            y_units: vec![String::new(); dims.outputs],
            p_units: vec![String::new(); dims.signals],
        }
    }

    /// The name of input i followed by its unit in brackets when known: `FIC101 [m³/h]`.
    #[must_use]
    pub fn input_label(&self, i: usize) -> String {
        label(&self.u, &self.u_units, i, 'u')
    }

    /// The name of output i followed by its unit in brackets when known: `LI201 [cm]`.
    #[must_use]
    pub fn output_label(&self, i: usize) -> String {
        label(&self.y, &self.y_units, i, 'y')
    }

    /// The raw unit of output i, if given.
    #[must_use]
    pub fn output_unit(&self, i: usize) -> Option<&str> {
        self.y_units
            .get(i)
            .map(String::as_str)
            .filter(|u| !u.is_empty())
    }

    /// The raw unit of input i, if given.
    #[must_use]
    pub fn input_unit(&self, i: usize) -> Option<&str> {
        self.u_units
            .get(i)
            .map(String::as_str)
            .filter(|u| !u.is_empty())
    }
}

fn label(names: &[String], units: &[String], i: usize, prefix: char) -> String {
    let name = names
        .get(i)
        .cloned()
        .unwrap_or_else(|| format!("{prefix}{i}"));
    match units.get(i).filter(|u| !u.is_empty()) {
        Some(unit) => format!("{name} [{unit}]"),
        None => name,
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
    /// The keys of its signals when it is assembled from tags (`[channels.tags]`);
    /// then `key` is not subscribed to.
    pub tags: Option<Tags>,
    /// How a foreign recording's topics give its signals (`[channels.topics]`): keys
    /// are topic names.
    pub topics: Option<Tags>,
    /// Sample period in seconds, if given.
    pub period: Option<f64>,
    /// Dimensions.
    pub dims: Dims,
    /// The model.
    pub model: Lpv,
    /// How the model's F, G (and Q) were computed from a state equation written in
    /// continuous time (`model.A`, `B`, `Qc` with `period`: a zero-order hold, Q by Van
    /// Loan's method): the period, A, B, Qc, the results, and F's eigenvalues; its
    /// `Display` is a one-line summary for reports (period, method, eigenvalues of F,
    /// stability, time constants). `None` for a model written in discrete time.
    pub discretised: Option<glrmon_core::Discretisation>,
    /// Unknown-input matrix E (n×q, constant or LPV), if given.
    pub unknown_input: Option<LpvMatrix>,
    /// F_d (p×q): the unknown input's effect on the outputs (`model.Fd`), if given.
    pub unknown_input_outputs: Option<DMatrix<f64>>,
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
    /// How an alarm episode ends (`glr.episode_end`, `gone_alpha`, `gone_samples`).
    pub episode_end: glrmon_core::EpisodeEnd,
    /// How the threshold was set.
    pub threshold_source: ThresholdSource,
    /// Samples between crossing and isolation.
    pub isolation_delay: u32,
    /// Type-I probability of each isolation test.
    pub isolation_alpha: f64,
    /// The number of onsets the isolation level is divided among for a test without
    /// a calibrated threshold: w − s under `isolation_law = "bonferroni"` (the GLR's
    /// default), 1 under `chi2` or for a detector that tests one onset.
    pub isolation_onsets: u64,
    /// Isolation groups `(name, fault indices)`.
    pub groups: Vec<(String, Vec<usize>)>,
    /// Calibrated isolation thresholds by test name (`[channels.glr.calibrated]
    /// isolation`), replacing the χ² quantile of those tests.
    pub isolation_thresholds: Vec<(String, f64)>,
    /// The detection method ([`Channel::detector`] builds it).
    pub detector_kind: DetectorKind,
    /// The degrees of freedom of the decision statistic's χ² law under no fault, for
    /// one tested onset ([`DetectorKind::statistic_dof`]; the parity space's dimension
    /// for `parity`).
    pub statistic_dof: usize,
    /// The parity detector's settings (`[channels.parity]`), for `detector = "parity"`.
    pub parity: Option<glrmon_core::detector::parity::ParitySettings>,
    /// The observer detectors' settings (`[channels.observer]`), for `detector =
    /// "fdf"` or `"uio"`.
    pub observer: Option<ObserverSettings>,
    /// The RLS detector's settings (`[channels.rls]`), for `detector = "rls"`.
    pub rls: Option<RlsChannelSettings>,
    /// The magnitudes the CUSUM is tuned for (`[channels.cusum]`), one per fault, for
    /// `detector = "cusum"`.
    pub cusum_magnitudes: Option<Vec<f64>>,
    /// The kernel detector's model, settings and candidates (`[channels.kernel]`), for
    /// `detector = "kernel"`.
    pub kernel: Option<KernelChannelSettings>,
    /// Largest gap filled by predict-only steps.
    pub max_gap: u64,
    /// Samples of settling after a restart, alarms held off (`None`: the detector's
    /// memory).
    pub settle: Option<u64>,
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
    pub consistency: Option<glrmon_core::filter::consistency::ConsistencySettings>,
    pub(crate) faults: Vec<FaultPlan>,
    /// The configuration path of each fault, in dictionary order (`channels[0] "x":
    /// faults[1]`, or `… faults[0] (y2)` for an expanded shortcut).
    pub(crate) fault_paths: Vec<String>,
}

impl Channel {
    /// The key expressions the channel's input arrives on: its `key`, or its tags'
    /// distinct keys ([`Tags::keys`]; a payload's tag number is its key's index here).
    #[must_use]
    pub fn input_keys(&self) -> Vec<String> {
        match &self.tags {
            Some(tags) => tags.keys().into_iter().map(|(k, _)| k.to_owned()).collect(),
            None => vec![self.key.clone()],
        }
    }

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
