//! Detectors: a residual generator and the decision statistic computed on it, one
//! sample at a time, behind the one interface every consumer uses ([`Detector`]).
//!
//! The kinds:
//! - [`GlrDetector`] (`glr.rs`): the Kalman (or, with an unknown input, Kitanidis)
//!   innovation, the Γ signature window bank and the moving-window GLR of Zhang &
//!   Basseville 2014, §3-§5, with the sufficient statistics minmax isolation needs;
//! - [`Chi2Detector`] (`chi2.rs`): the classical baseline, the χ² test of one
//!   sample's normalized innovation εᵀΣ⁻¹ε, on the same filter;
//! - [`CusumDetector`] (`cusum.rs`): Page's CUSUM of the same innovation for faults of
//!   known magnitude, on their steady signatures (Basseville & Nikiforov 1993, §2.2);
//! - [`parity::ParityDetector`] (`parity.rs`): the parity-space residual of Ahmad &
//!   Mohd-Mokhtar 2021, eqs. (4)-(8), over a window of s + 1 samples, decoupled from a
//!   disturbance or with the optimal parity vector of eq. (7);
//! - [`FdfDetector`] (`fdf.rs`): the observer-based fault-detection filter of Ahmad &
//!   Mohd-Mokhtar 2021, eq. (9), with a given gain L and residual weight V or the
//!   unified optimal ones of their eq. (18), evaluated by χ² or windowed energy;
//! - [`UioDetector`] (`uio.rs`): the unknown-input observer of Chen, Patton & Zhang
//!   1996, a fixed-gain observer of an LTI model whose residual is decoupled from an
//!   unknown input, with the χ² or windowed-energy evaluation;
//! - [`RlsDetector`] (`rls.rs`): parameter estimation, the ARX parameters of each
//!   output estimated by recursive least squares and tested against their nominal
//!   values;
//! - [`KernelDetector`] (`kernel/`): the kernel-based deadbeat estimator and fault
//!   detection and isolation of Li, Boem, Pin & Parisini for a continuous-time model
//!   with bounded noise: thresholds that guarantee no false alarm, and isolation
//!   among candidate fault functions of the estimated state.
//!
//! # Adding a kind
//! A new kind is a new module here implementing [`Detector`], allocation-free in
//! [`Detector::step`] like the others; the configuration names it in one variant of
//! `glrmon_spec::DetectorKind` (its name, its threshold law and one line of the
//! factory `Channel::detector`). The monitor, the daemon, recording, replay, the
//! report, `calibrate`, `evaluate` and `validate` then run it unchanged.

mod chi2;
mod cusum;
pub mod evaluation;
mod fdf;
mod glr;
pub mod kernel;
pub mod parity;
mod rls;
mod uio;

pub use chi2::Chi2Detector;
pub use cusum::{CusumDetector, RICCATI_TOLERANCE, siegmund_threshold};
pub use evaluation::{EnergyWindow, Evaluation};
pub use fdf::{
    FdfDetector, FdfGains, disturbance_gain, energy_threshold, error_covariance,
    residual_covariance, spectral_radius,
};
pub use glr::{DEFAULT_STEADY_TOLERANCE, GlrDetector, WindowSettings};
pub use kernel::{
    Candidate, CandidateFn, KernelDetector, KernelModel, KernelSettings, KernelVerdict,
};
pub use rls::{ArxForm, DEFAULT_EXCITATION, EquationError, RlsDetector, RlsSettings};
pub use uio::{
    RESIDUAL_RANK_TOLERANCE, UioCondition, UioDesign, UioDetector, check_uio_conditions,
};

use nalgebra::DVector;

use crate::error::{ModelError, StepError};
use crate::filter::innovation::InnovationFilter;
use crate::isolation::FisherStatistics;
use crate::model::Dims;
use crate::model::fault::FaultDictionary;
use crate::window::FollowedEvidence;

/// A channel's fault detector: the residual generator of a model-based method and the
/// decision statistic it computes on each sample.
///
/// Its contract, which the monitor relies on:
/// - samples come with consecutive indices k; [`Detector::step`] refuses any other
///   (and a malformed sample) with its state unchanged, and a missing sample is
///   bridged by [`Detector::predict_only`] or, where the kind cannot bridge one,
///   by [`Detector::restart`];
/// - [`Detector::step`] overwrites a [`StepOutput`] made once by
///   [`StepOutput::for_detector`] (its innovation, residual and magnitude lengths are
///   the kind's), and does not allocate;
/// - the decision statistic is [`StepOutput::glr`] (compared with the channel's
///   threshold), with the onset estimate [`StepOutput::onset`] and one magnitude per
///   fault of the dictionary; [`StepOutput::normalized_innovation`] is the residual's
///   χ² statistic, which the filter-consistency test reads;
/// - the same samples give the same bits.
pub trait Detector: std::fmt::Debug + Send {
    /// The kind's name as the configuration writes it (`glr`, `chi2`).
    fn kind(&self) -> &'static str;

    /// One line naming the method and its settings, for reports.
    fn describe(&self) -> String;

    /// How many consecutive samples one value of the decision statistic depends on:
    /// 1 for a test of one sample, the window length w for the GLR. Calibration
    /// counts exceedances closer than this as one cluster.
    fn memory(&self) -> usize;

    /// The channel's dimensions.
    fn dims(&self) -> Dims;

    /// The fault dictionary: the faults the magnitudes and isolation tests refer to.
    fn faults(&self) -> &FaultDictionary;

    /// q, the number of unknown inputs the residual is decoupled from (0 without);
    /// the residual then has p − q degrees of freedom.
    fn unknown_inputs(&self) -> usize {
        0
    }

    /// The index expected next (`None` before the first sample or after a restart).
    fn next_index(&self) -> Option<u64>;

    /// Processes sample k.
    ///
    /// # Errors
    /// [`StepError`] for a malformed sample or an index other than the next one
    /// (state unchanged), or a numerical failure (the caller restarts).
    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError>;

    /// Bridges the missing sample k without a measurement.
    ///
    /// # Errors
    /// [`StepError::OutOfOrder`] when k is not the next index,
    /// [`StepError::UnknownInputGap`] or [`StepError::GapNotBridged`] where the kind
    /// cannot bridge a gap,
    /// [`StepError::Numerical`] on a numerical failure.
    fn predict_only(&mut self, k: u64) -> Result<(), StepError>;

    /// Forgets every sample: the next one may carry any index, as for a new
    /// detector. Off the per-sample path (may allocate).
    ///
    /// # Errors
    /// [`ModelError`] when the initial state cannot be rebuilt.
    fn restart(&mut self) -> Result<(), ModelError>;

    /// Forgets the evidence gathered so far but keeps the state estimate: the decision
    /// statistic then only sees samples after this call. The monitor calls it at the
    /// end of the settling that follows a restart, when the estimate has converged from
    /// (x̂₀, P₀) but the residuals it gave meanwhile still carry the initial-state
    /// transient. False when the kind cannot (the default): the monitor then holds
    /// alarms off for [`Detector::memory`] more samples, until that evidence has left
    /// the kind's memory. Off the per-sample path.
    fn forget_evidence(&mut self) -> bool {
        false
    }

    /// The Fisher information C_k(r) and score d_k(r) of onset r after the last step,
    /// on which minmax and sensitivity isolation run (Zhang & Basseville 2014, eqs.
    /// (38)-(41)). `None` when the kind has none or r is not available. Allocates:
    /// for alarms, not for every sample.
    fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        let _ = onset;
        None
    }

    /// The GLR statistic d_k(r)ᵀC_k(r)⁺d_k(r) of onset r after the last step and the
    /// rank of C_k(r), as the window computed them (eq. (36)); `None` when the kind has
    /// no window of onsets or r is not in it. Allocation-free: the onset-free isolation
    /// check bounds each onset's single-group statistics by it, to build the Fisher
    /// statistics of few onsets only.
    fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        let _ = onset;
        None
    }

    /// Writes C_k(r) (m×m, column-major) and d_k(r) (m) of onset r after the last step,
    /// as [`Detector::fisher_statistics`] wraps them, without allocating; false when
    /// the kind has none or r is not available.
    fn onset_information(&self, onset: u64, information: &mut [f64], score: &mut [f64]) -> bool {
        let _ = (onset, information, score);
        false
    }

    /// The Kalman innovation filter, for the kinds that run one: sparse diagnosis
    /// restarts its residual filter from this filter's prediction.
    fn innovation_filter(&self) -> Option<&InnovationFilter> {
        None
    }

    /// Follows the fault of onset r (an alarm's r̂) past the window from the next
    /// sample on, so that [`Detector::followed`] says whether it is still in the data
    /// (`Some(r)`), or stops following (`None`). False when the kind cannot follow an
    /// onset or r is no longer available; the monitor then ends episodes on the
    /// decision statistic. Off the per-sample path (may allocate).
    fn follow(&mut self, onset: Option<u64>) -> bool {
        let _ = onset;
        false
    }

    /// The followed fault's evidence in the last [`Detector::memory`] samples: z_k,
    /// the score test along the fault's magnitude estimated before them, N(0, 1) when
    /// they carry no fault and N(√δ, 1) while it goes on (δ the information of those
    /// samples about it); [`FollowedEvidence::continues`] decides. `None` when nothing
    /// is followed or no sample has been measured since.
    fn followed(&self) -> Option<FollowedEvidence> {
        None
    }

    /// The followed fault's magnitude θ̂ = C_k(r)⁺d_k(r) at the followed onset r over
    /// every sample from r to the last one (eq. (34) continued past the window), one
    /// value per fault of [`Detector::faults`]: the episode's estimate, which stays
    /// that of a fault that persists, where [`StepOutput::magnitude`] slides with the
    /// window once r has left it. `None` when nothing is followed or no sample has been
    /// measured since. Allocation-free.
    fn followed_magnitude(&self) -> Option<&[f64]> {
        None
    }

    /// The length of [`StepOutput::innovation`]: p for the kinds built on the Kalman
    /// (or Kitanidis) filter, 0 for residual generators that run no such filter
    /// (parity space, observers, parameter estimation), whose residual is
    /// [`StepOutput::residual`] instead.
    fn innovation_len(&self) -> usize {
        self.dims().outputs
    }

    /// The length of [`StepOutput::residual`]: the kind's own residual besides the
    /// innovation (the parity residual, an observer's output error, θ̂ − θ_nom); 0 for
    /// the kinds whose residual is the innovation.
    fn residual_len(&self) -> usize {
        0
    }

    /// Isolation by the kind's own residual tests, for kinds that isolate without
    /// Fisher statistics (the kernel method's exclusion of candidate fault functions,
    /// Li, Boem, Pin & Parisini, Prop. 4.2): one test per fault of
    /// [`Detector::faults`], in its order. `None` when the kind has none or no
    /// isolation episode is open. Allocates: for alarms and their updates.
    fn residual_isolation(&self) -> Option<Vec<ResidualIsolation>> {
        None
    }

    /// A counter that changes whenever [`Detector::residual_isolation`]'s verdict
    /// changes (a candidate excluded, an episode opened): the monitor publishes an
    /// isolation update at that sample. Constant for the kinds without.
    fn isolation_revision(&self) -> u64 {
        0
    }

    /// Whether [`StepOutput::magnitude`] carries a magnitude estimate θ̂ per fault.
    /// Kinds that only detect leave it zero and say so here, so that no one reads
    /// zeros as an estimate.
    fn estimates_magnitude(&self) -> bool {
        true
    }
}

/// The checks every kind makes before touching its state: the index is the next one
/// and below 2⁶⁴ − 1, and u, y, p have the model's lengths and finite values.
pub(crate) fn check_sample(
    dims: Dims,
    next_k: Option<u64>,
    s: &Sample<'_>,
) -> Result<(), StepError> {
    if s.k == u64::MAX {
        return Err(StepError::IndexTooLarge { k: s.k });
    }
    if let Some(next) = next_k
        && s.k != next
    {
        return Err(StepError::OutOfOrder {
            expected: next,
            got: s.k,
        });
    }
    for (field, v, expected) in [
        ("u", s.u, dims.inputs),
        ("y", s.y, dims.outputs),
        ("p", s.p, dims.signals),
    ] {
        if v.len() != expected {
            return Err(StepError::WrongDimension {
                field,
                expected,
                got: v.len(),
            });
        }
        if let Some(index) = v.iter().position(|x| !x.is_finite()) {
            return Err(StepError::NonFinite { field, index });
        }
    }
    Ok(())
}

impl<D: Detector + ?Sized> Detector for Box<D> {
    fn kind(&self) -> &'static str {
        (**self).kind()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
    fn memory(&self) -> usize {
        (**self).memory()
    }
    fn dims(&self) -> Dims {
        (**self).dims()
    }
    fn faults(&self) -> &FaultDictionary {
        (**self).faults()
    }
    fn unknown_inputs(&self) -> usize {
        (**self).unknown_inputs()
    }
    fn next_index(&self) -> Option<u64> {
        (**self).next_index()
    }
    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        (**self).step(sample, out)
    }
    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        (**self).predict_only(k)
    }
    fn restart(&mut self) -> Result<(), ModelError> {
        (**self).restart()
    }
    fn forget_evidence(&mut self) -> bool {
        (**self).forget_evidence()
    }
    fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        (**self).fisher_statistics(onset)
    }
    fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        (**self).onset_statistic(onset)
    }
    fn onset_information(&self, onset: u64, information: &mut [f64], score: &mut [f64]) -> bool {
        (**self).onset_information(onset, information, score)
    }
    fn innovation_filter(&self) -> Option<&InnovationFilter> {
        (**self).innovation_filter()
    }
    fn follow(&mut self, onset: Option<u64>) -> bool {
        (**self).follow(onset)
    }
    fn followed(&self) -> Option<FollowedEvidence> {
        (**self).followed()
    }
    fn followed_magnitude(&self) -> Option<&[f64]> {
        (**self).followed_magnitude()
    }
    fn innovation_len(&self) -> usize {
        (**self).innovation_len()
    }
    fn residual_len(&self) -> usize {
        (**self).residual_len()
    }
    fn estimates_magnitude(&self) -> bool {
        (**self).estimates_magnitude()
    }
    fn residual_isolation(&self) -> Option<Vec<ResidualIsolation>> {
        (**self).residual_isolation()
    }
    fn isolation_revision(&self) -> u64 {
        (**self).isolation_revision()
    }
}

/// One fault's isolation test in [`Detector::residual_isolation`]: its residual
/// against its threshold, and the verdict so far in the episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualIsolation {
    /// The isolation residual (r_FI,i of the kernel method) at the last sample.
    pub statistic: f64,
    /// Its threshold (σ_FI,i) at the last sample.
    pub threshold: f64,
    /// Whether the residual has exceeded its threshold at some sample of the
    /// episode: the fault is not the one acting.
    pub excluded: bool,
    /// Whether the fault is isolated: every other one is excluded.
    pub isolated: bool,
}

/// One sample of a channel: index k, known inputs U_k, outputs Y_k, signals p(k).
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// Sample index k; consecutive samples have consecutive indices.
    pub k: u64,
    /// U_k (length l).
    pub u: &'a [f64],
    /// Y_k (length p).
    pub y: &'a [f64],
    /// p(k) (length q).
    pub p: &'a [f64],
}

/// What one step produced. Allocated once with [`StepOutput::for_detector`], overwritten by
/// every [`Detector::step`].
#[derive(Debug, Clone, PartialEq)]
pub struct StepOutput {
    /// The sample index k.
    pub k: u64,
    /// The residual: the innovation ε_k (Zhang & Basseville 2014, eq. (10)) for the
    /// kinds built on the Kalman filter.
    pub innovation: DVector<f64>,
    /// εᵀΣ⁻¹ε: χ²(p) under no fault (χ²(p − q) decoupled from q unknown inputs); for
    /// kinds without an innovation ([`Detector::innovation_len`] 0), their residual's
    /// normalized square, which the filter-consistency test does not read.
    pub normalized_innovation: f64,
    /// The kind's own residual ([`Detector::residual_len`] values; empty for the kinds
    /// whose residual is the innovation).
    pub residual: DVector<f64>,
    /// The decision statistic: l_k (eq. (35)) for the GLR; `None` while the kind has
    /// no value to report (no admissible onset yet, warm-up).
    pub glr: Option<f64>,
    /// The onset estimate r̂_k (eq. (36)); k itself for a test of one sample.
    pub onset: Option<u64>,
    /// θ̂, one value per fault (eq. (34): C_k(r̂)⁺d_k(r̂)); zeros when `glr` is `None`.
    pub magnitude: DVector<f64>,
    /// rank C_k(r̂): the χ² degrees of freedom of l_k.
    pub rank: usize,
}

impl StepOutput {
    /// Buffers for a detector with `outputs` outputs and `faults` faults whose
    /// residual is the innovation.
    #[must_use]
    pub fn new(outputs: usize, faults: usize) -> Self {
        Self {
            k: 0,
            innovation: DVector::zeros(outputs),
            normalized_innovation: 0.0,
            residual: DVector::zeros(0),
            glr: None,
            onset: None,
            magnitude: DVector::zeros(faults),
            rank: 0,
        }
    }

    /// Buffers sized for `detector`: its innovation, residual and faults.
    #[must_use]
    pub fn for_detector(detector: &dyn Detector) -> Self {
        let mut out = Self::new(detector.innovation_len(), detector.faults().len());
        out.residual = DVector::zeros(detector.residual_len());
        out
    }
}
