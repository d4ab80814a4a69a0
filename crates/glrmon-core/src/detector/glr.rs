//! The GLR detector: model evaluation → Kalman innovation → Γ signatures →
//! moving-window GLR, one sample at a time, without allocating.
//!
//! Ref.: Zhang & Basseville 2014, §3-§5 (eqs. (6)-(10), (32)-(37), (44)-(46)).

use nalgebra::{DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::filter::decoupling::RangeComplement;
use crate::filter::innovation::InnovationFilter;
use crate::isolation::FisherStatistics;
use crate::linalg::gemm;
use crate::model::fault::FaultDictionary;
use crate::model::{Dims, LpvMatrix, Signals, StateSpace, SystemMatrices};
use crate::window::{
    DEFAULT_RANK_TOLERANCE, FollowedEvidence, FollowedOnset, StepInputs, WindowBank,
};

use super::{Detector, Sample, StepOutput};

/// Default [`WindowSettings::steady_tolerance`].
pub const DEFAULT_STEADY_TOLERANCE: f64 = 1e-12;

/// Settings of the moving-window GLR.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowSettings {
    /// w: onsets r ∈ {k − w + 1, …, k − s} are candidates (eq. (37)). At least 2.
    pub window: usize,
    /// s: the youngest candidate onset is k − s (s < w), so that at least s + 1 samples
    /// carry each candidate's signature.
    pub min_lag: usize,
    /// τ: relative cut-off for the rank of C_k(r), free of the fault units:
    /// LDLᵀ pivots D_j ≤ τ·C_jj, or eigenvalues ≤ τ·λ_max of C equilibrated to a unit
    /// diagonal, are treated as zero.
    pub rank_tolerance: f64,
    /// Relative tolerance on max|P_{k+1} − P_k| / max|P_{k+1}| below which the Riccati
    /// recursion counts as converged. When the model, the fault columns and P have been
    /// constant for w samples, the detector switches to the stationary regime (the LTI
    /// fast path: Γ, S, C and C⁻ tabulated per lag, the gain held) and switches back at
    /// the first sample whose matrices or fault columns differ, or at a gap. 0 turns the
    /// fast path off.
    pub steady_tolerance: f64,
    /// Measured samples after the start (or a restart) during which no statistic is
    /// reported (`glr`, `onset` none): 0 for none, w to hold the GLR off until the
    /// window is full, as Zhang & Basseville 2014 do in §6.2 (the filter and the window
    /// run meanwhile; only the output is withheld).
    pub warm_up: u64,
}

impl Default for WindowSettings {
    fn default() -> Self {
        Self {
            window: 100,
            min_lag: 1,
            rank_tolerance: DEFAULT_RANK_TOLERANCE,
            steady_tolerance: DEFAULT_STEADY_TOLERANCE,
            warm_up: 0,
        }
    }
}

/// The moving-window GLR detector of one channel (Zhang & Basseville 2014): the
/// Kalman innovation filter, the Γ signature window bank and the GLR maximum over the
/// window's onsets. The reference implementation of [`Detector`].
///
/// # Examples
/// ```
/// use glrmon_core::detector::{GlrDetector, Sample, StepOutput, WindowSettings};
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::model::{Lpv, StateSpace};
/// use nalgebra::{DMatrix, DVector};
///
/// let model = Lpv::lti(
///     DMatrix::from_element(1, 1, 0.9), DMatrix::zeros(1, 0),
///     DMatrix::from_element(1, 1, 1.0), DMatrix::zeros(1, 0),
///     DMatrix::from_element(1, 1, 0.01), DMatrix::from_element(1, 1, 0.01),
/// ).unwrap();
/// let faults = FaultDictionary::new(model.dims(), vec![
///     Fault::output("bias", Onset::Step, Column::Constant(DVector::from_vec(vec![1.0]))),
/// ]).unwrap();
/// let mut det = GlrDetector::new(
///     Box::new(model), faults, DVector::zeros(1), DMatrix::identity(1, 1),
///     WindowSettings { window: 20, min_lag: 0, ..Default::default() },
/// ).unwrap();
/// let mut out = StepOutput::new(1, 1);
/// for k in 0..40 {
///     let y = if k >= 30 { 1.0 } else { 0.0 }; // a sensor bias from k = 30
///     det.step(&Sample { k, u: &[], y: &[y], p: &[] }, &mut out).unwrap();
/// }
/// assert_eq!(out.onset, Some(30));
/// assert!((out.magnitude[0] - 1.0).abs() < 1e-9);
/// ```
#[derive(Debug)]
pub struct GlrDetector {
    model: Box<dyn StateSpace>,
    faults: FaultDictionary,
    filter: InnovationFilter,
    bank: WindowBank,
    settings: WindowSettings,
    dims: Dims,
    system: SystemMatrices,
    /// Ψ̃_k (n×m).
    psi: DMatrix<f64>,
    /// Φ̃_k (p×m), then overwritten with L⁻¹Φ̃_k.
    phi: DMatrix<f64>,
    /// Φ̃_k of the last measured sample, unwhitened.
    phi_last: DMatrix<f64>,
    /// F_kK_kΦ̃_k (n×m).
    fk_phi: DMatrix<f64>,
    /// Signals of the last sample, repeated for predict-only steps.
    held_u: Vec<f64>,
    held_p: Vec<f64>,
    next_k: Option<u64>,
    last_measured: Option<u64>,
    /// Running mean and sum of squared deviations of each input (Welford's algorithm).
    input_moments: Vec<(f64, f64)>,
    input_count: u64,
    input_variance: Vec<f64>,
    /// The initial state and covariance, for [`GlrDetector::restart`].
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    /// The matrices and fault columns the stationary regime is built on (or is being
    /// checked against), P_k before the last time update, and how many consecutive
    /// measured samples had the same matrices and a converged P.
    reference: SystemMatrices,
    reference_psi: DMatrix<f64>,
    reference_phi: DMatrix<f64>,
    cov_before: DMatrix<f64>,
    steady_samples: u64,
    /// The model is LTI and every fault column constant ([`StateSpace::is_constant`],
    /// [`FaultDictionary::is_constant`]), and so is E if there is one.
    constant: bool,
    /// The unknown input's matrix, when the plant has one.
    unknown_input: Option<Box<UnknownInput>>,
    /// S = E(W_kV_kᵀ), when the noises are correlated.
    cross: Option<DMatrix<f64>>,
    /// The onset followed past the window ([`GlrDetector::follow`]).
    followed: FollowedOnset,
    /// The step inputs the stationary regime holds constant (A, Ψ̃, FKΦ̃, L⁻¹H, L⁻¹Φ̃),
    /// copied when it is entered, for the followed onset's steps in that regime.
    steady_inputs: [DMatrix<f64>; 5],
}

/// E_k of a plant with an unknown input E_kd_k ([`GlrDetector::with_unknown_input`]).
#[derive(Debug, Clone)]
struct UnknownInput {
    matrix: LpvMatrix,
    /// E_k at the sample being processed.
    at_k: DMatrix<f64>,
    /// range(E_k)'s complement, for the state-fault columns.
    complement: RangeComplement,
}

impl GlrDetector {
    /// Builds a detector; every buffer the per-sample path needs is allocated here.
    ///
    /// # Errors
    /// [`ModelError`] when the dictionary's dimensions differ from the model's, the
    /// initial state or covariance do not fit, or the window settings are out of range
    /// (w < 2, s ≥ w, τ not in (0, 1)).
    pub fn new(
        model: Box<dyn StateSpace>,
        faults: FaultDictionary,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        settings: WindowSettings,
    ) -> Result<Self, ModelError> {
        let dims = model.dims();
        if faults.dims() != dims {
            return Err(ModelError::Dimension {
                what: "fault dictionary",
                detail: format!("built for {:?} but the model is {:?}", faults.dims(), dims),
            });
        }
        if x0.len() != dims.states {
            return Err(ModelError::Dimension {
                what: "x0",
                detail: format!(
                    "x0 has {} entries but the model has {} states",
                    x0.len(),
                    dims.states
                ),
            });
        }
        if settings.window < 2 {
            return Err(ModelError::Setting {
                what: "window",
                detail: format!("w must be at least 2, got {}", settings.window),
            });
        }
        if settings.min_lag >= settings.window {
            return Err(ModelError::Setting {
                what: "min_lag",
                detail: format!(
                    "s must be below w = {}, got {}",
                    settings.window, settings.min_lag
                ),
            });
        }
        if !(settings.steady_tolerance >= 0.0 && settings.steady_tolerance < 1.0) {
            return Err(ModelError::Setting {
                what: "steady_tolerance",
                detail: format!(
                    "must be in [0, 1) (0 turns the LTI fast path off), got {}",
                    settings.steady_tolerance
                ),
            });
        }
        if !(settings.rank_tolerance > 0.0 && settings.rank_tolerance < 1.0) {
            return Err(ModelError::Setting {
                what: "rank_tolerance",
                detail: format!("τ must be in (0, 1), got {}", settings.rank_tolerance),
            });
        }
        let (n, p, m) = (dims.states, dims.outputs, faults.len());
        let (model_constant, faults_constant) = (model.is_constant(), faults.is_constant());
        let filter = InnovationFilter::new(x0.clone(), p0.clone(), p)?;
        let kinds: Vec<_> = faults.faults().iter().map(|f| f.onset).collect();
        let followed = FollowedOnset::new(
            n,
            p,
            kinds.clone(),
            settings.window,
            settings.rank_tolerance,
        );
        let bank = WindowBank::new(
            n,
            m,
            p,
            settings.window,
            settings.min_lag,
            kinds,
            settings.rank_tolerance,
        );
        Ok(Self {
            model,
            faults,
            filter,
            bank,
            settings,
            dims,
            system: SystemMatrices::zeros(dims),
            psi: DMatrix::zeros(n, m),
            phi: DMatrix::zeros(p, m),
            phi_last: DMatrix::zeros(p, m),
            fk_phi: DMatrix::zeros(n, m),
            held_u: vec![0.0; dims.inputs],
            held_p: vec![0.0; dims.signals],
            next_k: None,
            last_measured: None,
            input_moments: vec![(0.0, 0.0); dims.inputs],
            input_count: 0,
            input_variance: vec![0.0; dims.inputs],
            x0,
            p0,
            reference: SystemMatrices::zeros(dims),
            reference_psi: DMatrix::zeros(n, m),
            reference_phi: DMatrix::zeros(p, m),
            cov_before: DMatrix::zeros(n, n),
            steady_samples: 0,
            constant: model_constant && faults_constant,
            unknown_input: None,
            cross: None,
            followed,
            steady_inputs: [
                DMatrix::zeros(n, n),
                DMatrix::zeros(n, m),
                DMatrix::zeros(n, m),
                DMatrix::zeros(p, n),
                DMatrix::zeros(p, m),
            ],
        })
    }

    /// The same detector for process and measurement noises correlated as
    /// S = E(W_kV_kᵀ) (n×p, constant; [`InnovationFilter::with_cross_covariance`]): an
    /// identified innovation model (Q = K Re Kᵀ, R = Re, S = K Re) then runs at its own
    /// order with the exact steady predictor, Σ_k → Re.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for S, and
    /// [`ModelError::Setting`] with an unknown input (the decoupled filter is derived
    /// for uncorrelated noises).
    pub fn with_cross_covariance(mut self, s: DMatrix<f64>) -> Result<Self, ModelError> {
        if self.unknown_input.is_some() {
            return Err(ModelError::Setting {
                what: "S",
                detail: "correlated noises (S) cannot be combined with an unknown input (E)".into(),
            });
        }
        self.filter = self.filter.with_cross_covariance(s.clone())?;
        self.cross = Some(s);
        Ok(self)
    }

    /// The same detector for a plant with an unknown input E_kd_k (E n×q, constant or
    /// LPV over the scheduling signals): the GLR runs on the innovation decoupled from
    /// d, with the signatures of the Kitanidis filter's Υ̃ recursion (Zhang 2021,
    /// §III-B, Prop. 2, eq. (27); [`crate::filter::decoupling`]), so that no d_k can raise an
    /// alarm. A state fault's component in range(E_k) cannot be told from d and is
    /// removed; a fault entirely in it has no signature (not detectable). A missing
    /// sample cannot be bridged ([`GlrDetector::predict_only`] refuses it): d moves the
    /// state unobserved over it.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when E does not have n rows, [`ModelError::NonFinite`],
    /// [`ModelError::Setting`] when q = 0, q ≥ p, or E at its base point does not have
    /// full column rank.
    pub fn with_unknown_input(mut self, e: LpvMatrix) -> Result<Self, ModelError> {
        if self.cross.is_some() {
            return Err(ModelError::Setting {
                what: "E",
                detail: "an unknown input (E) cannot be combined with correlated noises (S)".into(),
            });
        }
        let (n, q) = e.shape();
        if n != self.dims.states {
            return Err(ModelError::Dimension {
                what: "E",
                detail: format!(
                    "E has {n} rows but the model has {} states",
                    self.dims.states
                ),
            });
        }
        if e.base()
            .iter()
            .chain(e.terms().iter().flat_map(|(_, m)| m.iter()))
            .any(|v| !v.is_finite())
        {
            return Err(ModelError::NonFinite { what: "E" });
        }
        self.filter = self.filter.with_unknown_input(q)?;
        let mut complement = RangeComplement::new(n, q);
        if !complement.factor(e.base()) {
            return Err(ModelError::Setting {
                what: "E",
                detail: "the columns of E are linearly dependent: give one column per \
                         independent unknown-input direction"
                    .into(),
            });
        }
        self.constant &= e.terms().is_empty();
        self.unknown_input = Some(Box::new(UnknownInput {
            at_k: e.base().clone(),
            matrix: e,
            complement,
        }));
        Ok(self)
    }

    /// q, the number of unknown inputs (0 without).
    #[must_use]
    pub fn unknown_inputs(&self) -> usize {
        self.filter.unknown_inputs()
    }

    /// Forgets every sample: the filter starts again from (x̂₀, P₀), the window is
    /// empty and the next sample may carry any index, as for a new detector. For a run
    /// that cannot be continued: a gap longer than the channel tolerates (predict-only
    /// steps over it would only blow P up on an unstable plant), or a numerical failure.
    /// Allocates (it is off the per-sample path).
    ///
    /// # Errors
    /// [`ModelError`] only if (x̂₀, P₀) were invalid, which [`GlrDetector::new`] excludes.
    pub fn restart(&mut self) -> Result<(), ModelError> {
        let (n, p, m) = (self.dims.states, self.dims.outputs, self.faults.len());
        let filter = InnovationFilter::new(self.x0.clone(), self.p0.clone(), p)?;
        self.filter = match (&self.unknown_input, &self.cross) {
            (Some(ui), _) => filter.with_unknown_input(ui.matrix.shape().1)?,
            (None, Some(s)) => filter.with_cross_covariance(s.clone())?,
            (None, None) => filter,
        };
        let kinds = self.faults.faults().iter().map(|f| f.onset).collect();
        let (level, fused) = (self.bank.level(), self.bank.fused());
        self.bank = WindowBank::new(
            n,
            m,
            p,
            self.settings.window,
            self.settings.min_lag,
            kinds,
            self.settings.rank_tolerance,
        );
        self.bank.set_level(level);
        self.bank.set_fused(fused);
        self.held_u.fill(0.0);
        self.held_p.fill(0.0);
        self.next_k = None;
        self.last_measured = None;
        self.input_moments.fill((0.0, 0.0));
        self.input_count = 0;
        self.input_variance.fill(0.0);
        self.steady_samples = 0;
        self.followed.stop();
        Ok(())
    }

    /// Forgets the window's evidence but keeps the filter: the onsets up to the last
    /// measured sample leave the window, the next sample is the oldest onset, and a
    /// followed onset is dropped. For the end of the settling after a restart: the
    /// filter has converged from (x̂₀, P₀), but the innovations it gave meanwhile carry
    /// the initial-state error as a decaying transient that the signatures of the early
    /// onsets would fit as a fault. Each onset's statistic depends only on the samples
    /// from it on (eqs. (32)-(36)), so the later onsets' statistics are those of the
    /// window that did not forget. False (nothing forgotten) for a dictionary of known
    /// onsets, whose one onset is the run's start, and before the first sample.
    pub fn forget_evidence(&mut self) -> bool {
        if self.next_k.is_none() || !self.bank.forget() {
            return false;
        }
        self.steady_samples = 0;
        self.followed.stop();
        true
    }

    /// Processes sample k: the measurement update, the signatures and sufficient
    /// statistics of every onset in the window, the GLR maximum, and the time update.
    ///
    /// # Errors
    /// [`StepError::WrongDimension`] / [`StepError::NonFinite`] for a malformed sample,
    /// [`StepError::OutOfOrder`] when k is not the next index (call
    /// [`GlrDetector::predict_only`] for missing samples), [`StepError::Numerical`] when
    /// the model at this sample gives a non-finite matrix or a singular Σ_k. On error
    /// the detector's state is unchanged.
    ///
    /// # Examples
    ///
    /// A wrong index is refused and changes nothing (the [`GlrDetector`] example runs a
    /// whole fault):
    ///
    /// ```
    /// use glrmon_core::detector::{GlrDetector, Sample, StepOutput, WindowSettings};
    /// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
    /// use glrmon_core::model::{Lpv, StateSpace};
    /// use glrmon_core::StepError;
    /// use nalgebra::{DMatrix, DVector};
    ///
    /// let one = |x| DMatrix::from_element(1, 1, x);
    /// let model = Lpv::lti(one(0.9), DMatrix::zeros(1, 0), one(1.0), DMatrix::zeros(1, 0), one(0.01), one(0.01)).unwrap();
    /// let faults = FaultDictionary::new(model.dims(), vec![
    ///     Fault::output("bias", Onset::Step, Column::Constant(DVector::from_vec(vec![1.0]))),
    /// ]).unwrap();
    /// let mut det = GlrDetector::new(Box::new(model), faults, DVector::zeros(1), DMatrix::identity(1, 1),
    ///     WindowSettings { window: 10, min_lag: 0, ..Default::default() }).unwrap();
    /// let mut out = StepOutput::new(1, 1);
    /// det.step(&Sample { k: 0, u: &[], y: &[0.1], p: &[] }, &mut out).unwrap();
    /// assert_eq!(out.k, 0);
    /// let late = det.step(&Sample { k: 5, u: &[], y: &[0.1], p: &[] }, &mut out);
    /// assert!(matches!(late, Err(StepError::OutOfOrder { .. })));
    /// assert_eq!(det.next_index(), Some(1));
    /// ```
    pub fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.check(sample)?;
        let signals = Signals {
            u: sample.u,
            p: sample.p,
        };
        let k = sample.k;
        if self.bank.is_steady() && self.constant {
            // An LTI model with constant fault columns: nothing to evaluate or compare.
            self.step_steady(sample, out);
            return Ok(());
        }
        self.model.evaluate(k, &signals, &mut self.system);
        if !self.system.is_finite() {
            return Err(StepError::Numerical {
                what: "the model evaluated at this sample's signals is not finite",
            });
        }
        self.faults.evaluate(
            k,
            &signals,
            &self.system,
            self.psi.as_mut_slice(),
            self.phi.as_mut_slice(),
        );
        if let Some(ui) = &mut self.unknown_input {
            if !ui.matrix.terms().is_empty() {
                ui.matrix.evaluate_into(sample.p, &mut ui.at_k);
                if !ui.at_k.iter().all(|v| v.is_finite()) || !ui.complement.factor(&ui.at_k) {
                    return Err(StepError::Numerical {
                        what: "E_k evaluated at this sample's signals is not finite or does \
                               not have full column rank",
                    });
                }
            }
            ui.complement
                .project(self.psi.as_mut_slice(), self.faults.len());
        }
        if self.bank.is_steady() {
            if self.matches_reference() {
                self.step_steady(sample, out);
                return Ok(());
            }
            self.leave_steady();
        }
        self.filter.measure(&self.system, sample.u, sample.y)?;
        match self.next_k {
            None => self.bank.start(k),
            Some(_) => self.bank.begin(k),
        }
        let (n, p, m) = (self.dims.states, self.dims.outputs, self.faults.len());
        (self.phi_last.as_mut_slice()).copy_from_slice(self.phi.as_slice());
        // Whiten Φ̃_k in place; F_kK_kΦ̃_k uses the unwhitened copy after the time update.
        self.filter.whiten_in_place(self.phi.as_mut_slice(), m);
        // The filter's time update (A_k, F_kK_k) goes first so that one pass over the
        // window does the signatures, the statistics and Γ's time update (eq. (46)).
        (self.cov_before.as_mut_slice()).copy_from_slice(self.filter.covariance().as_slice());
        self.filter.time_update(&self.system, sample.u);
        if let Some(ui) = &self.unknown_input {
            self.filter.set_unknown_input(&ui.at_k);
        }
        gemm(
            1.0,
            self.filter.predictor_gain().as_slice(),
            (n, p),
            false,
            self.phi_last.as_slice(),
            (p, m),
            false,
            0.0,
            self.fk_phi.as_mut_slice(),
        );
        let inputs = StepInputs {
            h_white: self.filter.whitened_output_matrix().as_slice(),
            phi_white: self.phi.as_slice(),
            eps_white: self.filter.whitened_innovation().as_slice(),
            closed_loop: self.filter.closed_loop().as_slice(),
            psi: self.psi.as_slice(),
            fk_phi: self.fk_phi.as_slice(),
        };
        let best = self.bank.step(k, &inputs);
        if self.followed.onset().is_some() {
            self.followed.measure(
                k,
                inputs.h_white,
                inputs.phi_white,
                inputs.eps_white,
                inputs.closed_loop,
                inputs.psi,
                inputs.fk_phi,
            );
        }
        self.write_output(k, best, out);
        self.track_stationarity(k);
        self.finish_measured(sample);
        Ok(())
    }

    /// A measured sample in the stationary regime (model and fault columns checked equal
    /// to the tables' by the caller): the held-gain filter, d and the statistic per
    /// onset from the tables, no Riccati or Γ recursion.
    fn step_steady(&mut self, sample: &Sample<'_>, out: &mut StepOutput) {
        let k = sample.k;
        self.filter.measure_steady(&self.system, sample.u, sample.y);
        self.bank.begin(k);
        self.bank
            .accumulate_steady(k, self.filter.whitened_innovation().as_slice());
        let best = self.bank.maximize_steady(k);
        self.write_output(k, best, out);
        if self.followed.onset().is_some() {
            let [a, psi, fk_phi, h_white, phi_white] = &self.steady_inputs;
            self.followed.measure(
                k,
                h_white.as_slice(),
                phi_white.as_slice(),
                self.filter.whitened_innovation().as_slice(),
                a.as_slice(),
                psi.as_slice(),
                fk_phi.as_slice(),
            );
        }
        self.filter.time_update_steady(&self.system, sample.u);
        self.bank.advance_steady(k);
        self.finish_measured(sample);
    }

    fn write_output(
        &mut self,
        k: u64,
        best: Option<crate::window::WindowMax>,
        out: &mut StepOutput,
    ) {
        out.k = k;
        // Withheld during the warm-up (this sample is measured sample input_count + 1).
        let best = best.filter(|_| self.input_count + 1 >= self.settings.warm_up);
        (out.innovation.as_mut_slice()).copy_from_slice(self.filter.innovation().as_slice());
        out.normalized_innovation = self.filter.normalized_innovation_squared();
        match best {
            Some(b) => {
                out.glr = Some(b.glr);
                out.onset = Some(b.onset);
                out.rank = b.rank;
                self.bank.magnitude(b.onset, out.magnitude.as_mut_slice());
            }
            None => {
                out.glr = None;
                out.onset = None;
                out.rank = 0;
                out.magnitude.fill(0.0);
            }
        }
    }

    /// Held signals, input moments and indices after a measured sample.
    fn finish_measured(&mut self, sample: &Sample<'_>) {
        self.held_u.copy_from_slice(sample.u);
        self.held_p.copy_from_slice(sample.p);
        self.input_count += 1;
        let count = self.input_count as f64;
        for ((mean, m2), u) in self.input_moments.iter_mut().zip(sample.u) {
            let delta = u - *mean;
            *mean += delta / count;
            *m2 += delta * (u - *mean);
        }
        self.next_k = Some(sample.k + 1);
        self.last_measured = Some(sample.k);
    }

    /// Whether this sample's matrices and fault columns equal those the stationary
    /// regime was built on (bit for bit).
    fn matches_reference(&self) -> bool {
        self.system == self.reference
            && self.psi == self.reference_psi
            && self.phi == self.reference_phi
    }

    /// After a general measured step at k: counts the samples over which the model, the
    /// fault columns and P stayed constant, and enters the stationary regime once the
    /// whole window has been built under them.
    fn track_stationarity(&mut self, k: u64) {
        let tol = self.settings.steady_tolerance;
        let e_varies =
            (self.unknown_input.as_ref()).is_some_and(|ui| !ui.matrix.terms().is_empty());
        if tol == 0.0 || e_varies {
            return;
        }
        let same = self.system == self.reference
            && self.psi == self.reference_psi
            && self.phi_last == self.reference_phi;
        if !same {
            // This sample's matrices become the reference by exchanging the buffers, not
            // by copying them (eight copies per sample of an LPV model, whose matrices
            // change at every sample: 8-10 % of a bench-A step). The next sample
            // overwrites the other buffers whole before reading them: the model's
            // `evaluate` (its contract), the dictionary's, and `phi_last` from `phi`.
            std::mem::swap(&mut self.reference, &mut self.system);
            std::mem::swap(&mut self.reference_psi, &mut self.psi);
            std::mem::swap(&mut self.reference_phi, &mut self.phi_last);
            self.steady_samples = 0;
            return;
        }
        let cov = self.filter.covariance();
        let scale = cov.amax();
        let change = cov
            .iter()
            .zip(self.cov_before.iter())
            .fold(0.0_f64, |a, (x, y)| a.max((x - y).abs()));
        if change > tol * scale {
            self.steady_samples = 0;
            return;
        }
        self.steady_samples += 1;
        if self.steady_samples >= self.settings.window as u64 {
            let held = [
                self.filter.closed_loop(),
                &self.psi,
                &self.fk_phi,
                self.filter.whitened_output_matrix(),
                &self.phi,
            ];
            for (copy, m) in self.steady_inputs.iter_mut().zip(held) {
                copy.copy_from(m);
            }
            self.bank.enter_steady(
                k,
                self.filter.closed_loop().as_slice(),
                self.psi.as_slice(),
                self.fk_phi.as_slice(),
                self.filter.whitened_output_matrix().as_slice(),
                self.phi.as_slice(),
            );
        }
    }

    /// Back to the general recursion (between steps).
    fn leave_steady(&mut self) {
        self.bank.leave_steady();
        self.steady_samples = 0;
    }

    /// The vector width the window loops run at (the widest the processor has, unless
    /// set).
    #[must_use]
    pub fn vector_level(&self) -> crate::VectorLevel {
        self.bank.level()
    }

    /// Runs the window loops at `level`; false, changing nothing, when this processor
    /// does not support it. Every level gives the same bits (a test compares them), so
    /// this only serves to measure and to check that claim.
    pub fn set_vector_level(&mut self, level: crate::VectorLevel) -> bool {
        if !crate::VectorLevel::supported().contains(&level) {
            return false;
        }
        self.bank.set_level(level);
        true
    }

    /// Runs the measured steps of the window as one fused pass over the onsets (the
    /// default, where the dimensions have one) or as separate passes. Both give the same
    /// bits (tests/fused_general.rs compares them); this exists for that test and for
    /// measurements.
    #[doc(hidden)]
    pub fn set_fused_window(&mut self, enabled: bool) {
        self.bank.set_fused(enabled);
    }

    /// Runs the window at the baseline level with a·b + c rounded twice, as on an x86-64
    /// processor without FMA (see [`crate::VectorLevel`]); for the test that compares
    /// that case with the fused rounding.
    #[doc(hidden)]
    pub fn set_separate_rounding(&mut self) {
        self.bank.set_separate_rounding();
    }

    /// Whether the stationary regime (the LTI fast path) is in force.
    #[must_use]
    pub fn is_stationary(&self) -> bool {
        self.bank.is_steady()
    }

    /// Predict-only step for a missing sample k: no measurement, so C and d do not
    /// change; X̂, P and every Γ advance with K_k = 0, using the last sample's inputs and
    /// signals (held), and P grows by G diag(σ²_u) Gᵀ with σ²_u the inputs' running
    /// variance, since the missing input is unknown. A missing sample is thereby neither
    /// skipped nor invented.
    ///
    /// # Errors
    /// [`StepError::OutOfOrder`] when k is not the next index or no sample has been
    /// seen yet; [`StepError::Numerical`] when the model is not finite;
    /// [`StepError::UnknownInputGap`] for a plant with an unknown input
    /// ([`GlrDetector::with_unknown_input`]), whose state d moves unobserved over a gap.
    pub fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        if self.unknown_input.is_some() {
            return Err(StepError::UnknownInputGap { k });
        }
        match self.next_k {
            Some(next) if next == k => {}
            Some(next) => {
                return Err(StepError::OutOfOrder {
                    expected: next,
                    got: k,
                });
            }
            None => {
                return Err(StepError::OutOfOrder {
                    expected: k,
                    got: k,
                });
            }
        }
        // A gap breaks the stationary regime (no measurement: K = 0 at this step).
        self.leave_steady();
        let signals = Signals {
            u: &self.held_u,
            p: &self.held_p,
        };
        self.model.evaluate(k, &signals, &mut self.system);
        if !self.system.is_finite() {
            return Err(StepError::Numerical {
                what: "the model evaluated at the held signals is not finite",
            });
        }
        self.faults.evaluate(
            k,
            &signals,
            &self.system,
            self.psi.as_mut_slice(),
            self.phi.as_mut_slice(),
        );
        self.bank.begin(k);
        // The missing sample's input is unknown: the held value, whose mean square
        // error about the input's running moments, σ² + (u_held − μ)², enters P through
        // G, so a gap does not look like a fault.
        let n = self.input_count as f64;
        for ((v, (mean, m2)), held) in self
            .input_variance
            .iter_mut()
            .zip(&self.input_moments)
            .zip(&self.held_u)
        {
            *v = if n > 1.0 {
                m2 / (n - 1.0) + (held - mean).powi(2)
            } else {
                0.0
            };
        }
        self.filter
            .predict_only(&self.system, &self.held_u, &self.input_variance);
        self.fk_phi.fill(0.0);
        self.bank.time_update(
            k,
            self.filter.closed_loop().as_slice(),
            self.psi.as_slice(),
            self.fk_phi.as_slice(),
            true,
        );
        self.followed.predict(
            k,
            self.filter.closed_loop().as_slice(),
            self.psi.as_slice(),
            self.fk_phi.as_slice(),
        );
        self.next_k = Some(k + 1);
        Ok(())
    }

    fn check(&self, s: &Sample<'_>) -> Result<(), StepError> {
        super::check_sample(self.dims, self.next_k, s)
    }

    /// The index the detector expects next (`None` before the first sample).
    #[must_use]
    pub fn next_index(&self) -> Option<u64> {
        self.next_k
    }

    /// The channel's dimensions.
    #[must_use]
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// m, the number of faults.
    #[must_use]
    pub fn fault_count(&self) -> usize {
        self.faults.len()
    }

    /// The fault dictionary.
    #[must_use]
    pub fn faults(&self) -> &FaultDictionary {
        &self.faults
    }

    /// The window settings.
    #[must_use]
    pub fn settings(&self) -> WindowSettings {
        self.settings
    }

    /// The plant model, for the kinds built on this detector that derive their design
    /// from its matrices (the CUSUM's steady fault signatures). Mutable because
    /// [`StateSpace::evaluate`] takes `&mut self`; evaluating it changes nothing the
    /// detector holds (it keeps its own copy of each sample's matrices).
    pub fn model_mut(&mut self) -> &mut dyn StateSpace {
        self.model.as_mut()
    }

    /// The Kalman innovation filter (X̂, P, ε, Σ, K).
    #[must_use]
    pub fn filter(&self) -> &InnovationFilter {
        &self.filter
    }

    /// The sufficient statistics F = C_k(r), ζ = d_k(r) of onset r after the last step,
    /// for isolation (they equal MᵀR⁻¹M and MᵀR⁻¹Z of eqs. (38)-(41)). `None` when r is
    /// no longer in the window. Allocates: call it at alarms, not per sample.
    #[must_use]
    pub fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        let m = self.faults.len();
        let mut info = DMatrix::zeros(m, m);
        let mut score = DVector::zeros(m);
        if !self
            .bank
            .information(onset, info.as_mut_slice(), score.as_mut_slice())
        {
            return None;
        }
        FisherStatistics::new(info, score)
            .ok()
            .map(|f| f.with_rank_tolerance(self.settings.rank_tolerance))
    }

    /// Writes C_k(r) (m×m) and d_k(r) (m) of onset r after the last step; false when r
    /// is not in the window.
    pub fn information(
        &self,
        onset: u64,
        info: &mut DMatrix<f64>,
        score: &mut DVector<f64>,
    ) -> bool {
        self.bank
            .information(onset, info.as_mut_slice(), score.as_mut_slice())
    }

    /// Keeps (`true`) or stops keeping the fault signature of every onset after each
    /// measured step, for [`GlrDetector::signature`], from the next measured step on.
    ///
    /// Off by default: the statistic needs only C_k(r) and d_k(r) (eqs. (32)-(33)),
    /// which the fused window pass computes from signatures it holds in registers.
    /// Keeping them costs p·m stores per onset and step and p·m·w·8 bytes more of the
    /// window's cache footprint (10 KiB at p = 2, m = 4, w = 160, where the rest is
    /// 37.5 KiB and a 48 KiB L1 data cache then no longer holds it).
    ///
    /// ```
    /// # use glrmon_core::GlrDetector;
    /// # fn f(det: &mut GlrDetector) {
    /// det.keep_signatures(true);
    /// # }
    /// ```
    pub fn keep_signatures(&mut self, keep: bool) {
        self.bank.set_keep_signatures(keep);
    }

    /// Writes the fault signature S_k(r) = H_kΓ_k(r) + Φ_k(r) (p×m, eq. (45)) of onset r
    /// at the last measured sample k; false when r is not in the window, or when the
    /// signatures are not kept ([`GlrDetector::keep_signatures`]) or were switched on after
    /// that sample. With an unknown input it is the part the decoupled innovation sees,
    /// L_k[0; Q₂ᵀ]L_k⁻¹S_k(r) ([`GlrDetector::with_unknown_input`]).
    pub fn signature(&self, onset: u64, out: &mut DMatrix<f64>) -> bool {
        if self.last_measured != self.next_k.map(|n| n - 1) {
            // The last step was predict-only: no signature at that sample.
            return false;
        }
        if !self.bank.whitened_signature(onset, out.as_mut_slice()) {
            return false;
        }
        let chol = self.filter.innovation_cholesky();
        let p = self.dims.outputs;
        for j in 0..self.faults.len() {
            for i in (0..p).rev() {
                let mut v = 0.0;
                for l in 0..=i {
                    v += chol[(i, l)] * out[(l, j)];
                }
                out[(i, j)] = v;
            }
        }
        true
    }

    /// Writes Γ_{k+1}(r) (n×m) of onset r after the step at k (eq. (46)); false when r
    /// is not in the window.
    pub fn gamma(&self, onset: u64, out: &mut DMatrix<f64>) -> bool {
        self.bank.gamma(onset, out.as_mut_slice())
    }

    /// Follows the fault of onset r past the window from the next sample on
    /// (`Some(r)`, r in the window after the last step), or stops (`None`); see
    /// [`Detector::follow`]. False when r is not in the window.
    pub fn follow(&mut self, onset: Option<u64>) -> bool {
        let Some(r) = onset else {
            self.followed.stop();
            return true;
        };
        let (n, m) = (self.dims.states, self.faults.len());
        // Off the per-sample path (at an alarm): small allocations are fine.
        let (mut gamma, mut info, mut score) = (vec![0.0; n * m], vec![0.0; m * m], vec![0.0; m]);
        if !self.bank.gamma(r, &mut gamma) || !self.bank.information(r, &mut info, &mut score) {
            return false;
        }
        self.followed.start(r, &gamma, &info, &score);
        true
    }

    /// The followed fault's evidence in the last w samples (see
    /// [`Detector::followed`]).
    #[must_use]
    pub fn followed(&self) -> Option<FollowedEvidence> {
        self.followed.statistic()
    }

    /// The followed fault's magnitude over every sample from its onset on (see
    /// [`Detector::followed_magnitude`]).
    #[must_use]
    pub fn followed_magnitude(&self) -> Option<&[f64]> {
        self.followed.magnitude()
    }

    /// Rank of C_k(r) and the statistic d_k(r)ᵀC_k(r)⁺d_k(r) at the last step.
    #[must_use]
    pub fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        Some((self.bank.statistic_of(onset)?, self.bank.rank_of(onset)?))
    }
}

impl Detector for GlrDetector {
    fn kind(&self) -> &'static str {
        "glr"
    }

    fn describe(&self) -> String {
        format!(
            "GLR, window w = {}, s = {}",
            self.settings.window, self.settings.min_lag
        )
    }

    fn memory(&self) -> usize {
        self.settings.window
    }

    fn dims(&self) -> Dims {
        self.dims
    }

    fn faults(&self) -> &FaultDictionary {
        &self.faults
    }

    fn unknown_inputs(&self) -> usize {
        GlrDetector::unknown_inputs(self)
    }

    fn next_index(&self) -> Option<u64> {
        self.next_k
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        GlrDetector::step(self, sample, out)
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        GlrDetector::predict_only(self, k)
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        GlrDetector::restart(self)
    }

    fn forget_evidence(&mut self) -> bool {
        GlrDetector::forget_evidence(self)
    }

    fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        GlrDetector::onset_statistic(self, onset)
    }

    fn onset_information(&self, onset: u64, information: &mut [f64], score: &mut [f64]) -> bool {
        let m = self.faults.len();
        information.len() == m * m
            && score.len() == m
            && self.bank.information(onset, information, score)
    }

    fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        GlrDetector::fisher_statistics(self, onset)
    }

    fn innovation_filter(&self) -> Option<&InnovationFilter> {
        Some(&self.filter)
    }

    fn follow(&mut self, onset: Option<u64>) -> bool {
        GlrDetector::follow(self, onset)
    }

    fn followed(&self) -> Option<FollowedEvidence> {
        GlrDetector::followed(self)
    }

    fn followed_magnitude(&self) -> Option<&[f64]> {
        GlrDetector::followed_magnitude(self)
    }
}
