//! Parameter-estimation fault detection: the ARX parameters of each output, estimated
//! online by recursive least squares (RLS) and compared with their nominal values
//! (Ahmad & Mohd-Mokhtar 2021, "Parameter-estimation-based residual generation": the
//! residual is the difference between the estimated and the nominal parameters; a
//! component fault is a change ΔA, ΔB, ΔC, ΔD of the model's matrices, their eq. (3)).
//!
//! Letters: the survey's A, B, C, D are F, G, H, J here (X_{k+1} = F X_k + G U_k + W_k,
//! Y_k = H X_k + J U_k + V_k, W ~ N(0, Q), V ~ N(0, R)); its disturbance terms E_d d,
//! F_d d are the noises W, V. The model must be LTI ([`StateSpace::is_constant`]): an
//! LPV model has no fixed nominal parameters to compare with.
//!
//! # The ARX form of the model
//!
//! With z the forward shift and a(z) = det(zI − F) = z^n + a_1 z^{n−1} + … + a_n, the
//! adjugate is adj(zI − F) = Σ_{j=1..n} M_{j−1} z^{n−j}, where Faddeev–LeVerrier gives
//! both: M_0 = I, and for j = 1..n, a_j = −tr(F M_{j−1})/j, M_j = F M_{j−1} + a_j I
//! (M_n = 0 by Cayley–Hamilton). From Y = [H(zI − F)⁻¹G + J]U + H(zI − F)⁻¹W + V,
//! multiplied by a(z) and divided by z^n, every output i obeys for k ≥ n, whatever the
//! initial state:
//!
//! ```text
//! y_i(k) = −Σ_{j=1..n} a_j y_i(k−j) + Σ_{j=0..n} b_{i,j}ᵀ u(k−j) + e_i(k)
//! b_0 = J,   b_j = H M_{j−1} G + a_j J   (p×l, row i is b_{i,j}ᵀ)
//! e_i(k) = Σ_{j=1..n} (H M_{j−1})_i W(k−j) + Σ_{j=0..n} a_j v_i(k−j)   (a_0 = 1)
//! ```
//!
//! θ_nom,i = [a_1 … a_n, b_{i,0}ᵀ … b_{i,n}ᵀ] (b_{i,0} left out when J = 0: no
//! feed-through), d = n + (n + 1)l parameters per output (n + nl without feed-through).
//! Each output has its own estimate: the outputs share the inputs' lags but each
//! regresses on its own past. An output whose A(z) and B_i(z) share a root (a mode of F
//! the inputs do not reach or y_i does not see) has no unique ARX parameters; the
//! constructor refuses it (generalized Sylvester matrix of a, b_{i,1..l} rank deficient).
//!
//! # The equation error, and why it is whitened
//!
//! e_i is not white: it is a moving average of order n, with autocovariance
//! r_i(τ) = Σ_j (H M_{j−1})_i Q (H M_{j+τ−1})_iᵀ + R_ii Σ_j a_j a_{j+τ}, τ = 0..n.
//! Plain least squares on the raw regressors is then biased (the past outputs in the
//! regressor are correlated with e_i(k)), and the bias grows, relative to the estimate's
//! spread, with the forgetting horizon: a χ² test of θ̂ − θ_nom would alarm on fault-free
//! data (measured in the tests). The noise model is known, so the spectral factor
//! r_i(z) = σ²_{ε,i} C_i(z)C_i(z⁻¹) (C_i monic, zeros inside the unit circle) is computed
//! once (the innovations Riccati recursion) and the regression is whitened:
//! φ_f(k) = φ(k) − Σ c_j φ_f(k−j), y_f(k) = y(k) − Σ c_j y_f(k−j), so that
//! y_f(k) = φ_f(k)ᵀθ + ε(k) with ε white, of variance σ²_{ε,i}, uncorrelated with φ_f(k).
//! The parameters are unchanged (this is least squares with a known noise model,
//! Clarke's generalized least squares); it departs from plain RLS on raw data. The raw
//! regressor φ(k) = [−y_i(k−1) … −y_i(k−n), u(k)ᵀ … u(k−n)ᵀ] is filtered (not y and u
//! separately), so the filters' zero start adds a transient of the noise's size only.
//!
//! # Recursive least squares with exponential forgetting
//!
//! ```text
//! K_k = P_{k−1}φ_k / (λ_k + φ_kᵀP_{k−1}φ_k)
//! θ̂_k = θ̂_{k−1} + K_k (y_k − φ_kᵀθ̂_{k−1})
//! P_k = (P_{k−1} − K_kφ_kᵀP_{k−1}) / λ_k   (symmetrised)
//! ```
//!
//! (φ, y the whitened regressor and output), from θ̂_0 = θ_nom, P_0 = p0·I, λ_k = λ_f
//! while the data excite every parameter and 1 otherwise (see below). This minimises
//! Σ_t w_t(y_t − φ_tᵀθ)² + w_0‖θ − θ_nom‖²/p0 with w_t = Π_{s>t} λ_s, so
//! P_k⁻¹ = w_0/p0·I + Σ_t w_tφ_tφ_tᵀ.
//!
//! # The residual and its covariance
//!
//! r_k = θ̂_k − θ_nom, stacked over the outputs (residual length p·d). Under no fault,
//! θ̂_k − θ_nom = P_k Σ_t w_t φ_t ε_t, and ε_t is white and independent of φ_t, so
//!
//! ```text
//! Σ_θ = cov(θ̂_k) = σ²_ε P_k S_k P_k,   S_k = Σ_t w_t² φ_tφ_tᵀ = λ_k² S_{k−1} + φ_kφ_kᵀ
//! ```
//!
//! which the detector tracks. In stationarity (E φφᵀ = Φ, w_t = λ^{k−t}, k ≫ 1/(1−λ)):
//! Σ w_t φφᵀ ≈ Φ/(1−λ), so P ≈ (1−λ)Φ⁻¹, and S ≈ Φ/(1−λ²), so
//! Σ_θ ≈ σ²(1−λ)²/(1−λ²)·Φ⁻¹ = σ² (1−λ)/(1+λ) Φ⁻¹ = σ² P/(1+λ): half of the σ²P one
//! would read off the recursion for λ near 1 (exactly σ²P for λ = 1, where S = P⁻¹).
//! The sandwich is kept rather than the stationary P/(1+λ) because it is also right at
//! the start, across the samples where forgetting stops, and for non-stationary inputs.
//!
//! The decision statistic with [`Evaluation::Chi2`] is Σ_i r_iᵀΣ_{θ,i}⁺r_i (the survey's
//! eq. (17) on the parameter residual), χ²(p·d) approximately under no fault. The
//! approximation: (i) θ̂ is a weighted sum of about 1/(1−λ) terms, Gaussian only
//! asymptotically; (ii) the estimates of different outputs are treated as independent
//! (Σ_θ block diagonal), which leaves the statistic's mean right (tr Σ_bd⁻¹Σ = p·d) but
//! not its tail when the outputs' noises are correlated; (iii) P_k is itself random. The
//! tests measure the false-alarm rate at the χ²(α = 0.01) quantile; `calibrate` sets the
//! threshold from fault-free data when the approximation is not good enough. With
//! [`Evaluation::Energy`] it is the windowed energy (eqs. (12)-(13)) of r.
//!
//! # Persistence of excitation
//!
//! The information over the forgetting horizon is I_k = λ_f I_{k−1} + φ_kφ_kᵀ (always
//! with λ_f). It is normalised to unit diagonal, N = D^{−1/2} I_k D^{−1/2} (D = diag I_k),
//! which makes it unit-free and its eigenvalues average 1; the input excites every
//! parameter when the smallest eigenvalue of N is above [`RlsSettings::excitation`]
//! (10⁻⁶ by default), decided by a Cholesky factorisation of N − excitation·I, which
//! exists exactly then. (The smallest eigenvalue relative to the mean rather than to the
//! largest, which lies between the mean and d times it: the same measure within a
//! factor d, for a factorisation per sample instead of an eigendecomposition, which
//! took three quarters of the step's time.) Without excitation the test is suspended
//! ([`StepOutput::glr`] `None`, [`RlsDetector::excited`] false) and forgetting stops
//! (λ_k = 1), so that P cannot grow without bound in the directions the data no longer
//! visit (covariance wind-up); once the input excites again, forgetting and the test
//! resume. The survey's remark that the method "always needs an excitation signal"
//! (which its own DC-motor simulation, u = 0.5 constant, does not give) is this.
//!
//! # Onset and memory
//!
//! The weights λ^{k−t} fall below e⁻¹ after H = round(1/(1 − λ_f)) samples: the
//! statistic's evidence is the last H samples, [`Detector::memory`] is H (plus the
//! energy window's w − 1) and the onset is k − memory + 1, clamped at the first sample
//! since the start. For λ_f = 1 nothing is forgotten: the memory is unbounded
//! (`usize::MAX`) and the onset is the first sample.
//!
//! # Correlated noises
//!
//! With S = E(W_kV_kᵀ) ≠ 0 (an identified innovation model: Q = K Re Kᵀ, R = Re,
//! S = K Re), [`RlsDetector::with_cross_covariance`] adds S's terms to r_i(τ); for an
//! innovation model the equation error is then det(zI − F + KH)·e/zⁿ exactly, and the
//! whitened error its innovation.
//!
//! # Measured (the tests)
//!
//! - Batch least squares on 2·10⁵ samples of the survey's DC motor: the raw regression's
//!   largest parameter bias is 290σ (current) and 320σ (speed); whitened, 1.9σ and 1.2σ.
//! - Fault-free, DC motor, 3·10⁵ samples, χ²(8): mean 7.89, exceedance rate at the
//!   α = 0.01 quantile 0.0089 (λ_f = 0.99) and 0.0088 (λ_f = 0.98). With σ²P/(1+λ) for
//!   Σ_θ the mean is 7.81 and 7.73, with σ²P 3.9 = 8/(1+λ): the derivation above.
//! - Two outputs whose noises are correlated (0.25 at lag 0 after whitening): mean
//!   16.04 for χ²(16) but a rate of 0.018 at α = 0.01 (1.8α; 2.7α at α = 0.001): the
//!   block-diagonal Σ_θ's cost; `calibrate` such channels.
//! - DC motor (λ_f = 0.98, χ²(8) at α = 10⁻⁶): a pole 0.5488 → 0.45 is detected after
//!   5 samples, the actuator gain × 0.7 after 3, the speed sensor's gain × 0.9 after 37,
//!   a speed-sensor bias of 0.2 (4 noise deviations) after 4.
//!
//! # Missing samples
//!
//! The regressor holds the last n outputs and inputs, and a missing sample's input is
//! unknown: RLS cannot bridge it without inventing data. [`Detector::predict_only`]
//! therefore restarts the regression's lags and whitening filters (as at the first
//! sample) and keeps θ̂, P, S and the information: the next n samples only refill the
//! lags (no update, [`StepOutput::glr`] `None`). `StepError::UnknownInputGap` would
//! have the monitor blame an unknown input (model.E) and restart the estimate from
//! θ_nom, losing what the data taught.

use nalgebra::{DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::linalg::{
    at, cholesky_in_place, gemm, gemv, jacobi_eigen, solve_lower_in_place, symmetrize,
};
use crate::model::fault::FaultDictionary;
use crate::model::{Dims, Signals, StateSpace, SystemMatrices};
use crate::window::DEFAULT_RANK_TOLERANCE;

use super::evaluation::{EnergyWindow, Evaluation};
use super::{Detector, Sample, StepOutput};

/// Default [`RlsSettings::excitation`]: the smallest eigenvalue of the normalised
/// information (eigenvalues averaging 1) above 10⁻⁶.
pub const DEFAULT_EXCITATION: f64 = 1e-6;

/// Relative singular-value threshold below which A(z) and B_i(z) are taken to share a
/// root (the generalized Sylvester matrix of the normalised polynomials).
const COPRIME_TOLERANCE: f64 = 1e-9;

/// Iterations allowed to the spectral factorisation of the equation error: enough for
/// zeros of C_i(z) up to about 1 − 10⁻⁵ in modulus.
const SPECTRAL_ITERATIONS: usize = 1_000_000;

/// The RLS settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RlsSettings {
    /// λ_f ∈ (0, 1]: the forgetting factor; the horizon is round(1/(1 − λ_f)) samples
    /// (unbounded for 1).
    pub forgetting: f64,
    /// p0 > 0: P_0 = p0·I, the initial covariance around θ_nom (in the parameters'
    /// units squared); large values let the first samples move θ̂ freely.
    pub p0: f64,
    /// In (0, 1): the test runs while the smallest eigenvalue of the information over
    /// the horizon, normalised to unit diagonal (eigenvalues averaging 1), is above this.
    pub excitation: f64,
}

impl Default for RlsSettings {
    fn default() -> Self {
        Self {
            forgetting: 0.99,
            p0: 1e3,
            excitation: DEFAULT_EXCITATION,
        }
    }
}

/// The equation error e_i of one output: a moving average of order n, its spectral
/// factor C_i(z) and the variance of the white noise ε_i it is filtered from.
#[derive(Debug, Clone, PartialEq)]
pub struct EquationError {
    autocovariance: Vec<f64>,
    polynomial: Vec<f64>,
    variance: f64,
}

impl EquationError {
    /// r_i(0), …, r_i(n): the autocovariance of e_i at lags 0..n (zero beyond).
    #[must_use]
    pub fn autocovariance(&self) -> &[f64] {
        &self.autocovariance
    }

    /// c_1, …, c_n: e_i = C_i(q⁻¹) ε_i with C_i = 1 + c_1 q⁻¹ + … + c_n q⁻ⁿ minimum phase.
    #[must_use]
    pub fn polynomial(&self) -> &[f64] {
        &self.polynomial
    }

    /// σ²_{ε,i}, the variance of the whitened equation error (0 for a noise-free output).
    #[must_use]
    pub fn variance(&self) -> f64 {
        self.variance
    }
}

/// The input-output (ARX) form of an LTI model: the characteristic polynomial of F, the
/// numerator coefficients b_j of every output and the equation errors (see the module
/// documentation for the derivation).
#[derive(Debug, Clone, PartialEq)]
pub struct ArxForm {
    dims: Dims,
    feedthrough: bool,
    a: Vec<f64>,
    b: Vec<DMatrix<f64>>,
    noise: Vec<EquationError>,
}

impl ArxForm {
    /// The ARX form of the model F, G, H, J with independent noises Q, R.
    ///
    /// # Errors
    /// [`ModelError::NonFinite`] for a non-finite matrix, [`ModelError::Setting`] when the
    /// model has no state, or an output's equation error has no minimum-phase spectral
    /// factor (it cannot be whitened).
    pub fn new(system: &SystemMatrices) -> Result<Self, ModelError> {
        Self::build(system, None)
    }

    /// The same with process and measurement noises correlated as S = E(W_kV_kᵀ) (n×p),
    /// as in an identified innovation model (Q = K Re Kᵀ, R = Re, S = K Re): S adds
    /// Σ_m a_m (H M_{m+τ−1})_i S_i + Σ_j a_{j+τ} (H M_{j−1})_i S_i to r_i(τ) (S_i the
    /// column i of S), the covariances of W(k−j) in e_i(k) with v_i(k−τ−m) and of v_i(k−m)
    /// with W(k−τ−j).
    ///
    /// # Errors
    /// As [`ArxForm::new`], and [`ModelError::Dimension`] when S is not n×p.
    pub fn with_cross_covariance(
        system: &SystemMatrices,
        s: &DMatrix<f64>,
    ) -> Result<Self, ModelError> {
        let (n, p) = (system.f.nrows(), system.h.nrows());
        if s.shape() != (n, p) {
            return Err(ModelError::Dimension {
                what: "S",
                detail: format!(
                    "S is {}×{} but the model has {n} states and {p} outputs",
                    s.nrows(),
                    s.ncols()
                ),
            });
        }
        if s.iter().any(|x| !x.is_finite()) {
            return Err(ModelError::NonFinite { what: "S" });
        }
        Self::build(system, Some(s))
    }

    fn build(system: &SystemMatrices, cross: Option<&DMatrix<f64>>) -> Result<Self, ModelError> {
        if !system.is_finite() {
            return Err(ModelError::NonFinite { what: "model" });
        }
        let n = system.f.nrows();
        let l = system.g.ncols();
        let p = system.h.nrows();
        if n == 0 {
            return Err(ModelError::Setting {
                what: "model",
                detail: "the model has no state: the ARX form has no dynamics to estimate".into(),
            });
        }
        let (a, m) = faddeev_leverrier(&system.f);
        let mut b = Vec::with_capacity(n + 1);
        b.push(system.j.clone());
        let mut hm = Vec::with_capacity(n);
        for (j, mj) in m.iter().enumerate() {
            let h_m = &system.h * mj;
            b.push(&h_m * &system.g + &system.j * a[j + 1]);
            hm.push(h_m);
        }
        let mut noise = Vec::with_capacity(p);
        for i in 0..p {
            let mut r = vec![0.0; n + 1];
            for (tau, rt) in r.iter_mut().enumerate() {
                for j in 0..n - tau {
                    let left = hm[j].row(i);
                    let right = hm[j + tau].row(i);
                    *rt += (left * &system.q * right.transpose())[(0, 0)];
                }
                let mut s = 0.0;
                for j in 0..=n - tau {
                    s += a[j] * a[j + tau];
                }
                *rt += system.r[(i, i)] * s;
                if let Some(cross) = cross {
                    // (H M_{j−1})_i S_i at j = 1..n, and 0 at j = 0.
                    let hs = |j: usize| {
                        if j == 0 {
                            0.0
                        } else {
                            hm[j - 1].row(i).dot(&cross.column(i).transpose())
                        }
                    };
                    for m in 0..=n - tau {
                        *rt += a[m] * hs(m + tau) + a[m + tau] * hs(m);
                    }
                }
            }
            let (polynomial, variance) =
                spectral_factor(&r).ok_or_else(|| ModelError::Setting {
                    what: "model",
                    detail: format!(
                        "output y{i}: its ARX equation error (autocovariance {r:?}) has no \
                         minimum-phase spectral factor (a spectral zero on or within about \
                         1e-5 of the unit circle, or Q, R, S that are not a covariance), so \
                         it cannot be whitened; give Q or R a component that reaches y{i} \
                         other than through the plant's poles on the unit circle"
                    ),
                })?;
            noise.push(EquationError {
                autocovariance: r,
                polynomial,
                variance,
            });
        }
        Ok(Self {
            dims: Dims {
                states: n,
                inputs: l,
                outputs: p,
                signals: 0,
            },
            feedthrough: system.j.iter().any(|&x| x != 0.0),
            a,
            b,
            noise,
        })
    }

    /// n, the order (the number of lags).
    #[must_use]
    pub fn order(&self) -> usize {
        self.dims.states
    }

    /// p, the number of outputs (of separate estimates).
    #[must_use]
    pub fn outputs(&self) -> usize {
        self.dims.outputs
    }

    /// l, the number of inputs.
    #[must_use]
    pub fn inputs(&self) -> usize {
        self.dims.inputs
    }

    /// 1, a_1, …, a_n: det(zI − F) = z^n + a_1 z^{n−1} + … + a_n.
    #[must_use]
    pub fn characteristic(&self) -> &[f64] {
        &self.a
    }

    /// b_j (p×l) for lag j = 0..n: b_0 = J, b_j = H M_{j−1} G + a_j J.
    ///
    /// # Panics
    /// When j > n.
    #[must_use]
    pub fn numerator(&self, lag: usize) -> &DMatrix<f64> {
        &self.b[lag]
    }

    /// Whether J ≠ 0: the parameters then include b_0 = J (the input's lag 0).
    #[must_use]
    pub fn has_feedthrough(&self) -> bool {
        self.feedthrough
    }

    /// The first input lag in the regressor: 0 with feed-through, 1 without.
    #[must_use]
    pub fn first_input_lag(&self) -> usize {
        usize::from(!self.feedthrough)
    }

    /// d, the parameters per output: n + (n + 1 − first lag)·l.
    #[must_use]
    pub fn parameters(&self) -> usize {
        let n = self.dims.states;
        n + (n + 1 - self.first_input_lag()) * self.dims.inputs
    }

    /// θ_nom of output i: [a_1 … a_n, b_{i,j}ᵀ for j = first lag..n].
    ///
    /// # Panics
    /// When i is not an output.
    #[must_use]
    pub fn nominal(&self, output: usize) -> DVector<f64> {
        let n = self.dims.states;
        let l = self.dims.inputs;
        let mut theta = DVector::zeros(self.parameters());
        theta.rows_mut(0, n).copy_from_slice(&self.a[1..]);
        for (t, lag) in (self.first_input_lag()..=n).enumerate() {
            for m in 0..l {
                theta[n + t * l + m] = self.b[lag][(output, m)];
            }
        }
        theta
    }

    /// The equation error of output i.
    ///
    /// # Panics
    /// When i is not an output.
    #[must_use]
    pub fn equation_error(&self, output: usize) -> &EquationError {
        &self.noise[output]
    }

    /// σ_min/σ_max of the generalized Sylvester matrix of a(z) and the b_{i,m}(z) of
    /// output i (each normalised): 0 when they share a root, so that the ARX
    /// parameters of y_i are not unique; `None` when no input reaches y_i.
    #[must_use]
    pub fn coprimeness(&self, output: usize) -> Option<f64> {
        let n = self.dims.states;
        let l = self.dims.inputs;
        let norm_a = self.a.iter().map(|x| x * x).sum::<f64>().sqrt();
        let norm_b = (0..l)
            .map(|m| (0..=n).map(|j| self.b[j][(output, m)].powi(2)).sum::<f64>())
            .fold(0.0, f64::max)
            .sqrt();
        if norm_b == 0.0 {
            return None;
        }
        // Columns z^s·a(z) and z^s·b_m(z), s = 0..n−1, as coefficients of z^{2n−1}..z^0.
        let mut syl = DMatrix::zeros(2 * n, n * (1 + l));
        for s in 0..n {
            for j in 0..=n {
                syl[(n - 1 - s + j, s)] = self.a[j] / norm_a;
                for m in 0..l {
                    syl[(n - 1 - s + j, n * (1 + m) + s)] = self.b[j][(output, m)] / norm_b;
                }
            }
        }
        let sv = syl.svd(false, false).singular_values;
        let max = sv.max();
        let min = sv.iter().copied().fold(f64::INFINITY, f64::min);
        Some(if max > 0.0 { min / max } else { 0.0 })
    }
}

/// det(zI − F) = Σ a_j z^{n−j} (a_0 = 1) and M_0..M_{n−1} with adj(zI − F) =
/// Σ M_{j−1} z^{n−j}, by Faddeev–LeVerrier on F scaled by a power of two (exact), so
/// that the recursion's magnitudes stay near 1.
fn faddeev_leverrier(f: &DMatrix<f64>) -> (Vec<f64>, Vec<DMatrix<f64>>) {
    let n = f.nrows();
    let amax = f.amax();
    let scale = if amax > 0.0 {
        2f64.powi(amax.log2().round() as i32)
    } else {
        1.0
    };
    let fs = f / scale;
    let mut a = vec![1.0; n + 1];
    let mut m = vec![DMatrix::identity(n, n)];
    for j in 1..=n {
        let fm = &fs * &m[j - 1];
        a[j] = -fm.trace() / j as f64;
        if j < n {
            m.push(fm + DMatrix::identity(n, n) * a[j]);
        }
    }
    let mut power = 1.0;
    for j in 0..n {
        m[j] *= power;
        power *= scale;
        a[j + 1] *= power;
    }
    (a, m)
}

/// The minimum-phase spectral factor of a moving average of order n with
/// autocovariance r(0..n): c_1..c_n and σ² with r(τ) = σ² Σ_j c_j c_{j+τ} (c_0 = 1).
///
/// The innovations Riccati recursion of the realisation x_{k+1} = Z x_k + K ε_k,
/// e_k = x_k[0] + ε_k (Z the up-shift): Π ← ZΠZᵀ + g gᵀ/σ², g = [r(1)…r(n)]ᵀ − ZΠe_1,
/// σ² = r(0) − Π_00, K = g/σ², from Π = 0; it converges to the factor whose zeros lie
/// inside the unit circle (at the rate of their squared modulus). `None` when it does
/// not converge (a zero on the unit circle) or σ² is not positive.
fn spectral_factor(r: &[f64]) -> Option<(Vec<f64>, f64)> {
    let n = r.len() - 1;
    if r[0] == 0.0 && r.iter().all(|&x| x == 0.0) {
        return Some((vec![0.0; n], 0.0));
    }
    if n == 0 {
        return (r[0] > 0.0).then(|| (Vec::new(), r[0]));
    }
    let mut pi = DMatrix::<f64>::zeros(n, n);
    let mut next = DMatrix::<f64>::zeros(n, n);
    let mut g = vec![0.0; n];
    let mut gain = vec![0.0; n];
    let mut variance = r[0];
    for iteration in 0..SPECTRAL_ITERATIONS {
        let s2 = r[0] - pi[(0, 0)];
        if !(s2 > 0.0 && s2.is_finite()) {
            return None;
        }
        for (i, gi) in g.iter_mut().enumerate() {
            *gi = r[i + 1] - if i + 1 < n { pi[(i + 1, 0)] } else { 0.0 };
        }
        let mut change: f64 = (s2 - variance).abs() / s2;
        let mut size: f64 = 1.0;
        for (ki, gi) in gain.iter_mut().zip(&g) {
            let k = gi / s2;
            change = change.max((k - *ki).abs());
            size = size.max(k.abs());
            *ki = k;
        }
        variance = s2;
        if iteration > 0 && change <= 1e-14 * size {
            return Some((gain, variance));
        }
        for j in 0..n {
            for i in 0..n {
                let shifted = if i + 1 < n && j + 1 < n {
                    pi[(i + 1, j + 1)]
                } else {
                    0.0
                };
                next[(i, j)] = shifted + g[i] * g[j] / s2;
            }
        }
        std::mem::swap(&mut pi, &mut next);
    }
    None
}

/// One output's estimate and its buffers (d parameters, n lags).
#[derive(Debug, Clone)]
struct OutputRls {
    nominal: DVector<f64>,
    /// c_1..c_n of the whitening filter.
    c: DVector<f64>,
    /// σ²_ε.
    variance: f64,
    theta: DVector<f64>,
    p: DMatrix<f64>,
    /// S_k = Σ w_t² φφᵀ.
    s: DMatrix<f64>,
    /// I_k = Σ λ_f^{k−t} φφᵀ.
    info: DMatrix<f64>,
    theta_next: DVector<f64>,
    p_next: DMatrix<f64>,
    s_next: DMatrix<f64>,
    info_next: DMatrix<f64>,
    /// The raw regressor φ(k), then the whitened φ_f(k).
    phi: DVector<f64>,
    phi_f: DVector<f64>,
    /// φ_f(k−1−j) in column j.
    phi_history: DMatrix<f64>,
    /// y_f(k−1−j) at j.
    y_history: DVector<f64>,
    y_f: f64,
    p_phi: DVector<f64>,
    excited_next: bool,
    /// The excitation decision of the last update.
    excited: bool,
    residual: DVector<f64>,
    statistic: f64,
    rank: usize,
    // Scratch.
    sym: DMatrix<f64>,
    tmp: DMatrix<f64>,
    values: DVector<f64>,
    vectors: DMatrix<f64>,
    scale: DVector<f64>,
}

impl OutputRls {
    fn new(nominal: DVector<f64>, noise: &EquationError, p0: f64, n: usize) -> Self {
        let d = nominal.len();
        let z = |r, c| DMatrix::zeros(r, c);
        Self {
            theta: nominal.clone(),
            nominal,
            c: DVector::from_column_slice(noise.polynomial()),
            variance: noise.variance(),
            p: DMatrix::identity(d, d) * p0,
            s: z(d, d),
            info: z(d, d),
            theta_next: DVector::zeros(d),
            p_next: z(d, d),
            s_next: z(d, d),
            info_next: z(d, d),
            phi: DVector::zeros(d),
            phi_f: DVector::zeros(d),
            phi_history: z(d, n),
            y_history: DVector::zeros(n),
            y_f: 0.0,
            p_phi: DVector::zeros(d),
            excited_next: false,
            excited: false,
            residual: DVector::zeros(d),
            statistic: 0.0,
            rank: 0,
            sym: z(d, d),
            tmp: z(d, d),
            values: DVector::zeros(d),
            vectors: z(d, d),
            scale: DVector::zeros(d),
        }
    }

    fn reset(&mut self, p0: f64) {
        self.theta.copy_from(&self.nominal);
        self.p.fill(0.0);
        self.p.fill_diagonal(p0);
        self.s.fill(0.0);
        self.info.fill(0.0);
        self.excited = false;
        self.restart_filters();
    }

    fn restart_filters(&mut self) {
        self.phi_history.fill(0.0);
        self.y_history.fill(0.0);
    }

    /// The whitened φ_f(k), y_f(k) from the raw regressor in `phi` and y_i(k).
    fn whiten(&mut self, y: f64) {
        let (d, n) = self.phi_history.shape();
        self.phi_f.copy_from(&self.phi);
        gemv(
            -1.0,
            self.phi_history.as_slice(),
            d,
            n,
            self.c.as_slice(),
            1.0,
            self.phi_f.as_mut_slice(),
        );
        let mut y_f = y;
        for (cj, yj) in self.c.iter().zip(self.y_history.iter()) {
            y_f -= cj * yj;
        }
        self.y_f = y_f;
    }

    /// The RLS update of sample k into the `_next` buffers; `false` when it is not
    /// finite or P lost positive definiteness.
    fn propose(&mut self, forgetting: f64, threshold: f64) -> bool {
        let d = self.phi_f.len();
        let phi = self.phi_f.as_slice();
        for j in 0..d {
            for i in 0..d {
                self.info_next[(i, j)] = forgetting * self.info[(i, j)] + phi[i] * phi[j];
            }
        }
        self.excited_next = excites(&self.info_next, threshold, &mut self.sym);
        let lambda = if self.excited_next { forgetting } else { 1.0 };
        gemv(
            1.0,
            self.p.as_slice(),
            d,
            d,
            phi,
            0.0,
            self.p_phi.as_mut_slice(),
        );
        let denominator = lambda + self.phi_f.dot(&self.p_phi);
        let error = self.y_f - self.phi_f.dot(&self.theta);
        if !(denominator > 0.0 && denominator.is_finite() && error.is_finite()) {
            return false;
        }
        let step = error / denominator;
        for i in 0..d {
            self.theta_next[i] = self.theta[i] + self.p_phi[i] * step;
        }
        let lambda2 = lambda * lambda;
        for j in 0..d {
            let kj = self.p_phi[j] / denominator;
            for i in 0..d {
                self.p_next[(i, j)] = (self.p[(i, j)] - self.p_phi[i] * kj) / lambda;
                self.s_next[(i, j)] = lambda2 * self.s[(i, j)] + phi[i] * phi[j];
            }
        }
        symmetrize(self.p_next.as_mut_slice(), d);
        self.theta_next.iter().all(|x| x.is_finite())
            && self.p_next.iter().all(|x| x.is_finite())
            && self.s_next.iter().all(|x| x.is_finite())
            && (0..d).all(|i| self.p_next[(i, i)] > 0.0)
    }

    /// Makes the proposed update the state and shifts the whitening filters.
    fn commit(&mut self) {
        std::mem::swap(&mut self.theta, &mut self.theta_next);
        std::mem::swap(&mut self.p, &mut self.p_next);
        std::mem::swap(&mut self.s, &mut self.s_next);
        std::mem::swap(&mut self.info, &mut self.info_next);
        self.excited = self.excited_next;
        let (d, n) = self.phi_history.shape();
        let h = self.phi_history.as_mut_slice();
        h.copy_within(0..d * (n - 1), d);
        h[..d].copy_from_slice(self.phi_f.as_slice());
        let y = self.y_history.as_mut_slice();
        y.copy_within(0..n - 1, 1);
        y[0] = self.y_f;
    }

    /// r = θ̂ − θ_nom and rᵀΣ_θ⁺r with Σ_θ = σ² P S P, and the rank of Σ_θ.
    fn evaluate(&mut self) {
        let d = self.theta.len();
        self.residual.copy_from(&self.theta);
        self.residual -= &self.nominal;
        // Σ_θ = σ² P (S P), into `sym`.
        gemm(
            1.0,
            self.s.as_slice(),
            (d, d),
            false,
            self.p.as_slice(),
            (d, d),
            false,
            0.0,
            self.tmp.as_mut_slice(),
        );
        gemm(
            self.variance,
            self.p.as_slice(),
            (d, d),
            false,
            self.tmp.as_slice(),
            (d, d),
            false,
            0.0,
            self.sym.as_mut_slice(),
        );
        symmetrize(self.sym.as_mut_slice(), d);
        // The statistic does not depend on the parameters' units: scale to unit diagonal.
        for i in 0..d {
            let v = self.sym[(i, i)];
            self.scale[i] = if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 };
        }
        for j in 0..d {
            for i in 0..d {
                self.sym[(i, j)] *= self.scale[i] * self.scale[j];
            }
        }
        for i in 0..d {
            self.values[i] = self.scale[i] * self.residual[i];
        }
        // While the data excite every parameter Σ_θ is positive definite: its Cholesky
        // factor L gives rᵀΣ⁻¹r = ‖L⁻¹r‖². Otherwise the pseudo-inverse by eigenvalues.
        if self.excited {
            self.tmp.copy_from(&self.sym);
            if cholesky_in_place(self.tmp.as_mut_slice(), d) {
                solve_lower_in_place(self.tmp.as_slice(), d, self.values.as_mut_slice(), 1);
                self.statistic = self.values.norm_squared();
                self.rank = d;
                return;
            }
        }
        jacobi_eigen(
            self.sym.as_mut_slice(),
            d,
            self.values.as_mut_slice(),
            self.vectors.as_mut_slice(),
        );
        let max = self.values.iter().copied().fold(0.0, f64::max);
        let (mut statistic, mut rank) = (0.0, 0);
        for e in 0..d {
            let v = self.values[e];
            if max > 0.0 && v > DEFAULT_RANK_TOLERANCE * max {
                let mut z = 0.0;
                for i in 0..d {
                    z += self.vectors[at(d, i, e)] * self.scale[i] * self.residual[i];
                }
                statistic += z * z / v;
                rank += 1;
            }
        }
        self.statistic = statistic;
        self.rank = rank;
    }
}

/// D^{−1/2} M D^{−1/2} (D = diag M) into `out`, the information normalised to unit
/// diagonal; `false` when a diagonal entry is not positive (a regressor that never
/// moved).
fn normalise(m: &DMatrix<f64>, out: &mut DMatrix<f64>) -> bool {
    let d = m.nrows();
    if !(0..d).all(|i| m[(i, i)] > 0.0) {
        return false;
    }
    for j in 0..d {
        for i in 0..d {
            out[(i, j)] = m[(i, j)] / (m[(i, i)] * m[(j, j)]).sqrt();
        }
    }
    true
}

/// Whether the smallest eigenvalue of the normalised information N exceeds
/// `threshold`: N − threshold·I has a Cholesky factor exactly then.
fn excites(info: &DMatrix<f64>, threshold: f64, scratch: &mut DMatrix<f64>) -> bool {
    if !normalise(info, scratch) {
        return false;
    }
    let d = info.nrows();
    for i in 0..d {
        scratch[(i, i)] -= threshold;
    }
    cholesky_in_place(scratch.as_mut_slice(), d)
}

/// The parameter-estimation detector: per output, RLS with forgetting on the whitened
/// ARX regression of an LTI model, and the χ² (or energy) test of θ̂ − θ_nom (see the
/// module documentation).
///
/// # Examples
/// ```
/// use glrmon_core::detector::{Evaluation, RlsDetector, RlsSettings, Sample, StepOutput};
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::model::{Lpv, StateSpace};
/// use glrmon_core::Detector;
/// use nalgebra::{DMatrix, DVector};
///
/// let one = |x| DMatrix::from_element(1, 1, x);
/// let model = Lpv::lti(one(0.8), one(1.0), one(1.0), one(0.0), one(0.01), one(0.01)).unwrap();
/// let faults = FaultDictionary::new(model.dims(), vec![
///     Fault::output("bias", Onset::Step, Column::Constant(DVector::from_vec(vec![1.0]))),
/// ]).unwrap();
/// let det = RlsDetector::new(Box::new(model), faults, RlsSettings::default(), Evaluation::Chi2)
///     .unwrap();
/// // y(k) = 0.8 y(k−1) + u(k−1) + e(k): θ_nom = [a_1, b_1] = [−0.8, 1].
/// assert_eq!(det.arx().nominal(0).as_slice(), &[-0.8, 1.0]);
/// assert_eq!((det.kind(), det.memory(), det.residual_len()), ("rls", 100, 2));
/// ```
#[derive(Debug)]
pub struct RlsDetector {
    faults: FaultDictionary,
    arx: ArxForm,
    settings: RlsSettings,
    evaluation: Evaluation,
    energy: EnergyWindow,
    dims: Dims,
    /// n, the lags.
    order: usize,
    first_lag: usize,
    /// H = round(1/(1 − λ_f)); `None` for λ_f = 1.
    horizon: Option<u64>,
    /// Updates before the test reports: H, or 10·d for λ_f = 1.
    warm_up: u64,
    outputs: Vec<OutputRls>,
    /// y(k−1−j) in column j (p×n).
    y_lags: DMatrix<f64>,
    /// u(k−1−j) in column j (l×n).
    u_lags: DMatrix<f64>,
    /// Consecutive samples in the lags (at most n).
    filled: usize,
    next_k: Option<u64>,
    first_k: Option<u64>,
    updates: u64,
    /// F, G, H, J, Q, R, evaluated once.
    system: SystemMatrices,
}

/// The conditions on an ARX form for estimation: every output reached by an input, with
/// A(z) and B_i(z) coprime, and with noise under the χ² evaluation.
fn check_arx(arx: &ArxForm, evaluation: Evaluation) -> Result<(), ModelError> {
    let setting = |detail: String| {
        Err(ModelError::Setting {
            what: "model",
            detail,
        })
    };
    for i in 0..arx.outputs() {
        match arx.coprimeness(i) {
            None => {
                return setting(format!(
                    "no input reaches output y{i} (B_{i}(z) = 0): its parameters cannot be \
                     estimated"
                ));
            }
            Some(ratio) if ratio <= COPRIME_TOLERANCE => {
                return setting(format!(
                    "output y{i}: A(z) (the characteristic polynomial of F) and B_{i}(z) share \
                     a root (smallest singular value of their Sylvester matrix {ratio:.1e} of \
                     the largest): a mode of F is not reached by the inputs or not seen by \
                     y{i}, so the ARX parameters of y{i} are not unique; give y{i} a minimal \
                     realisation of its own"
                ));
            }
            Some(_) => {}
        }
        if evaluation == Evaluation::Chi2 && arx.equation_error(i).variance() == 0.0 {
            return setting(format!(
                "output y{i} has no noise (R_{i}{i} = 0 and Q does not reach it): the χ² \
                 evaluation needs the estimate's covariance, which is then 0; give the model \
                 noise or use the energy evaluation"
            ));
        }
    }
    Ok(())
}

impl RlsDetector {
    /// The detector for the LTI `model` (its F, G, H, J, Q, R), reporting against the
    /// fault dictionary `faults` (carried for the monitor: this kind detects, it does not
    /// estimate per-fault magnitudes), with RLS `settings` and the residual
    /// `evaluation` (χ² or windowed energy).
    ///
    /// # Errors
    /// [`ModelError::Setting`] naming the failing condition: a model whose matrices change
    /// (not LTI), without state or known input, a λ_f outside (0, 1], a horizon shorter
    /// than the d parameters of an output, p0 or the excitation threshold out of range,
    /// an energy window of 0, an output whose A(z) and B_i(z) share a root or that no
    /// input reaches, an output without noise under [`Evaluation::Chi2`] (its covariance
    /// would be 0), an equation error that cannot be whitened;
    /// [`ModelError::Dimension`] when the fault dictionary's dimensions are not the
    /// model's; [`ModelError::NonFinite`] for a non-finite matrix.
    pub fn new(
        mut model: Box<dyn StateSpace>,
        faults: FaultDictionary,
        settings: RlsSettings,
        evaluation: Evaluation,
    ) -> Result<Self, ModelError> {
        let dims = model.dims();
        if !model.is_constant() {
            return Err(ModelError::Setting {
                what: "model",
                detail: "the rls detector compares estimated ARX parameters with one \
                         nominal set, which needs an LTI model: this model's matrices \
                         change with the sample or the scheduling signals"
                    .into(),
            });
        }
        if faults.dims() != dims {
            return Err(ModelError::Dimension {
                what: "fault dictionary",
                detail: format!("built for {:?} but the model has {:?}", faults.dims(), dims),
            });
        }
        if dims.inputs == 0 {
            return Err(ModelError::Setting {
                what: "model",
                detail: "the model has no known input: parameter estimation needs an input \
                         that excites the plant (an autoregression on the noise alone has \
                         no nominal parameters to compare with)"
                    .into(),
            });
        }
        let setting = |what, detail: String| Err(ModelError::Setting { what, detail });
        let lambda = settings.forgetting;
        if !(lambda > 0.0 && lambda <= 1.0) {
            return setting(
                "forgetting",
                format!("λ_f = {lambda} must be in (0, 1] (1: no forgetting)"),
            );
        }
        if !(settings.p0 > 0.0 && settings.p0.is_finite()) {
            return setting(
                "p0",
                format!(
                    "p0 = {} must be positive and finite (P_0 = p0·I)",
                    settings.p0
                ),
            );
        }
        if !(settings.excitation > 0.0 && settings.excitation < 1.0) {
            return setting(
                "excitation",
                format!(
                    "{} must be in (0, 1): the smallest eigenvalue of the information \
                     normalised to unit diagonal (eigenvalues averaging 1)",
                    settings.excitation
                ),
            );
        }
        if let Evaluation::Energy { window: 0 } = evaluation {
            return setting(
                "window",
                "the energy window must hold at least 1 sample".into(),
            );
        }
        let mut system = SystemMatrices::zeros(dims);
        let (u0, p0) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
        model.evaluate(0, &Signals { u: &u0, p: &p0 }, &mut system);
        let arx = ArxForm::new(&system)?;
        let d = arx.parameters();
        let horizon = (lambda < 1.0).then(|| (1.0 / (1.0 - lambda)).round() as u64);
        if let Some(h) = horizon
            && h < d as u64
        {
            return setting(
                "forgetting",
                format!(
                    "λ_f = {lambda} gives a horizon of {h} samples, fewer than the {d} \
                     parameters of each output: they cannot be estimated from so few \
                     samples; raise λ_f to at least {:.4}",
                    1.0 - 1.0 / d as f64
                ),
            );
        }
        check_arx(&arx, evaluation)?;
        let n = arx.order();
        let outputs = (0..dims.outputs)
            .map(|i| OutputRls::new(arx.nominal(i), arx.equation_error(i), settings.p0, n))
            .collect();
        Ok(Self {
            faults,
            settings,
            evaluation,
            energy: EnergyWindow::new(evaluation.memory()),
            dims,
            order: n,
            first_lag: arx.first_input_lag(),
            horizon,
            warm_up: horizon.unwrap_or(10 * d as u64),
            outputs,
            y_lags: DMatrix::zeros(dims.outputs, n),
            u_lags: DMatrix::zeros(dims.inputs, n),
            filled: 0,
            next_k: None,
            first_k: None,
            updates: 0,
            arx,
            system,
        })
    }

    /// The same detector for process and measurement noises correlated as
    /// S = E(W_kV_kᵀ) (n×p, constant), e.g. an identified innovation model (Q = K Re Kᵀ,
    /// R = Re, S = K Re), whose equation error S changes
    /// ([`ArxForm::with_cross_covariance`]): without it the whitening filter is wrong and
    /// the estimate biased. Starts afresh.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for S, and the noise
    /// conditions of [`RlsDetector::new`].
    pub fn with_cross_covariance(mut self, s: DMatrix<f64>) -> Result<Self, ModelError> {
        let arx = ArxForm::with_cross_covariance(&self.system, &s)?;
        check_arx(&arx, self.evaluation)?;
        let n = arx.order();
        self.outputs = (0..self.dims.outputs)
            .map(|i| OutputRls::new(arx.nominal(i), arx.equation_error(i), self.settings.p0, n))
            .collect();
        self.arx = arx;
        self.restart();
        Ok(self)
    }

    /// The model's ARX form: θ_nom, the polynomials and the equation errors.
    #[must_use]
    pub fn arx(&self) -> &ArxForm {
        &self.arx
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> RlsSettings {
        self.settings
    }

    /// The residual evaluation.
    #[must_use]
    pub fn evaluation(&self) -> Evaluation {
        self.evaluation
    }

    /// H = round(1/(1 − λ_f)), the forgetting horizon; `None` for λ_f = 1.
    #[must_use]
    pub fn horizon(&self) -> Option<u64> {
        self.horizon
    }

    /// Whether the last update found every output's regressor exciting (false before
    /// the first): while false the test is suspended and [`StepOutput::glr`] is `None`.
    #[must_use]
    pub fn excited(&self) -> bool {
        self.outputs.iter().all(|o| o.excited)
    }

    /// The smallest, over the outputs, eigenvalue of the normalised information after
    /// the last update (compared with [`RlsSettings::excitation`]; its eigenvalues
    /// average 1). Off the per-sample path: allocates.
    #[must_use]
    pub fn excitation(&self) -> f64 {
        self.outputs
            .iter()
            .map(|o| {
                let mut n = o.info.clone();
                if normalise(&o.info, &mut n) {
                    n.symmetric_eigenvalues().min().max(0.0)
                } else {
                    0.0
                }
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// θ̂ of output i.
    ///
    /// # Panics
    /// When i is not an output.
    #[must_use]
    pub fn estimate(&self, output: usize) -> &[f64] {
        self.outputs[output].theta.as_slice()
    }

    /// Σ_θ = σ²_ε P S P of output i, the covariance of θ̂ under no fault. Allocates.
    ///
    /// # Panics
    /// When i is not an output.
    #[must_use]
    pub fn covariance(&self, output: usize) -> DMatrix<f64> {
        let o = &self.outputs[output];
        &o.p * &o.s * &o.p * o.variance
    }

    /// Processes sample k: the regressor from the lags, the whitened RLS update of every
    /// output, and the statistic.
    ///
    /// # Errors
    /// [`StepError::WrongDimension`] / [`StepError::NonFinite`] for a malformed sample,
    /// [`StepError::OutOfOrder`] when k is not the next index,
    /// [`StepError::IndexTooLarge`], [`StepError::Numerical`] when the update is not
    /// finite or P loses positive definiteness. On error the state is unchanged.
    pub fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.check(sample)?;
        let (n, l) = (self.order, self.dims.inputs);
        let complete = self.filled >= n;
        if complete {
            for (i, o) in self.outputs.iter_mut().enumerate() {
                for j in 0..n {
                    o.phi[j] = -self.y_lags[(i, j)];
                }
                for (t, lag) in (self.first_lag..=n).enumerate() {
                    for m in 0..l {
                        o.phi[n + t * l + m] = if lag == 0 {
                            sample.u[m]
                        } else {
                            self.u_lags[(m, lag - 1)]
                        };
                    }
                }
                o.whiten(sample.y[i]);
                if !o.propose(self.settings.forgetting, self.settings.excitation) {
                    return Err(StepError::Numerical {
                        what: "the RLS update is not finite or its covariance P lost \
                               positive definiteness",
                    });
                }
            }
            for o in &mut self.outputs {
                o.commit();
            }
            self.updates += 1;
        }
        let p = self.dims.outputs;
        let y = self.y_lags.as_mut_slice();
        y.copy_within(0..p * (n - 1), p);
        y[..p].copy_from_slice(sample.y);
        let u = self.u_lags.as_mut_slice();
        u.copy_within(0..l * (n - 1), l);
        u[..l].copy_from_slice(sample.u);
        self.filled = (self.filled + 1).min(n);
        self.next_k = Some(sample.k + 1);
        let first = *self.first_k.get_or_insert(sample.k);
        self.emit(sample.k, first, complete, out);
        Ok(())
    }

    /// Fills `out` from the current estimates.
    fn emit(&mut self, k: u64, first: u64, updated: bool, out: &mut StepOutput) {
        let (mut statistic, mut rank, mut energy) = (0.0, 0, 0.0);
        let len = self.residual_len();
        if out.residual.len() != len {
            // A buffer not made by `StepOutput::for_detector`: sized once.
            out.residual = DVector::zeros(len);
        }
        let mut offset = 0;
        for o in &mut self.outputs {
            o.evaluate();
            statistic += o.statistic;
            rank += o.rank;
            energy += o.residual.norm_squared();
            let d = o.residual.len();
            out.residual.as_mut_slice()[offset..offset + d].copy_from_slice(o.residual.as_slice());
            offset += d;
        }
        let active = updated && self.updates >= self.warm_up && self.excited();
        out.k = k;
        out.innovation.fill(0.0);
        out.magnitude.fill(0.0);
        out.normalized_innovation = if statistic.is_finite() {
            statistic
        } else {
            0.0
        };
        out.rank = rank;
        out.glr = match self.evaluation {
            Evaluation::Chi2 => (active && statistic.is_finite()).then_some(statistic),
            Evaluation::Energy { .. } => {
                if active {
                    self.energy.push(energy)
                } else {
                    self.energy.clear();
                    None
                }
            }
        };
        let span = self.memory().saturating_sub(1) as u64;
        out.onset = out.glr.map(|_| k.saturating_sub(span).max(first));
    }

    /// A missing sample k: the lags and whitening filters restart (the next n samples
    /// refill them without an update); θ̂, P, S and the information are kept.
    ///
    /// # Errors
    /// [`StepError::OutOfOrder`] when k is not the next index or no sample has been
    /// seen yet.
    pub fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        match self.next_k {
            Some(next) if next == k && k < u64::MAX => {}
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
        self.filled = 0;
        for o in &mut self.outputs {
            o.restart_filters();
        }
        self.energy.clear();
        self.next_k = Some(k + 1);
        Ok(())
    }

    /// Forgets every sample: θ̂ = θ_nom, P = p0·I, no lags, no information.
    pub fn restart(&mut self) {
        for o in &mut self.outputs {
            o.reset(self.settings.p0);
        }
        self.y_lags.fill(0.0);
        self.u_lags.fill(0.0);
        self.energy.clear();
        self.filled = 0;
        self.next_k = None;
        self.first_k = None;
        self.updates = 0;
    }

    fn check(&self, s: &Sample<'_>) -> Result<(), StepError> {
        super::check_sample(self.dims, self.next_k, s)
    }
}

impl Detector for RlsDetector {
    fn kind(&self) -> &'static str {
        "rls"
    }

    fn describe(&self) -> String {
        let horizon = self
            .horizon
            .map_or_else(|| "unbounded".to_owned(), |h| format!("{h} samples"));
        let evaluation = match self.evaluation {
            Evaluation::Chi2 => "χ² of θ̂ − θ_nom".to_owned(),
            Evaluation::Energy { window } => format!("energy of θ̂ − θ_nom over {window} samples"),
        };
        format!(
            "RLS parameter estimation of the ARX form (order {}, {} parameters per output), \
             λ_f = {}, horizon {horizon}, {evaluation}",
            self.order,
            self.arx.parameters(),
            self.settings.forgetting
        )
    }

    fn memory(&self) -> usize {
        match self.horizon {
            Some(h) => usize::try_from(h)
                .unwrap_or(usize::MAX)
                .saturating_add(self.evaluation.memory() - 1),
            None => usize::MAX,
        }
    }

    fn dims(&self) -> Dims {
        self.dims
    }

    fn faults(&self) -> &FaultDictionary {
        &self.faults
    }

    fn next_index(&self) -> Option<u64> {
        self.next_k
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        RlsDetector::step(self, sample, out)
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        RlsDetector::predict_only(self, k)
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        RlsDetector::restart(self);
        Ok(())
    }

    fn innovation_len(&self) -> usize {
        0
    }

    fn residual_len(&self) -> usize {
        self.dims.outputs * self.arx.parameters()
    }

    fn estimates_magnitude(&self) -> bool {
        false
    }
}

#[cfg(test)]
// The tests walk parallel per-sample vectors (inputs, outputs, regressors) by index.
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use crate::model::Lpv;
    use crate::model::fault::{Column, Fault, Onset};
    use crate::threshold::chi2_upper_quantile;

    /// xorshift64* with Box–Muller normals.
    struct Rng(u64);

    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        /// Uniform in (0, 1].
        fn uniform(&mut self) -> f64 {
            ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
        }

        fn normal(&mut self) -> f64 {
            let (u1, u2) = (self.uniform(), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        }

        /// A PRBS-like ±1.
        fn sign(&mut self) -> f64 {
            if self.next_u64() >> 63 == 0 {
                -1.0
            } else {
                1.0
            }
        }
    }

    /// A plant simulated from its state space: W = w_factor·ξ, V = diag(v_std)·ξ.
    struct Plant {
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        j: DMatrix<f64>,
        w_factor: DMatrix<f64>,
        v_std: Vec<f64>,
        x: DVector<f64>,
    }

    impl Plant {
        fn new(system: &SystemMatrices, w_factor: DMatrix<f64>, v_std: Vec<f64>) -> Self {
            Self {
                f: system.f.clone(),
                g: system.g.clone(),
                h: system.h.clone(),
                j: system.j.clone(),
                x: DVector::zeros(system.f.nrows()),
                w_factor,
                v_std,
            }
        }

        fn output(&mut self, u: &[f64], rng: &mut Rng) -> Vec<f64> {
            let u = DVector::from_column_slice(u);
            let mut y = &self.h * &self.x + &self.j * &u;
            for (yi, s) in y.iter_mut().zip(&self.v_std) {
                *yi += s * rng.normal();
            }
            let xi = DVector::from_fn(self.w_factor.ncols(), |_, _| rng.normal());
            self.x = &self.f * &self.x + &self.g * &u + &self.w_factor * xi;
            y.as_slice().to_vec()
        }
    }

    fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, v)
    }

    fn system(
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        j: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
    ) -> SystemMatrices {
        SystemMatrices { f, g, h, j, q, r }
    }

    fn model(s: &SystemMatrices) -> Lpv {
        Lpv::lti(
            s.f.clone(),
            s.g.clone(),
            s.h.clone(),
            s.j.clone(),
            s.q.clone(),
            s.r.clone(),
        )
        .unwrap()
    }

    fn dictionary(dims: Dims) -> FaultDictionary {
        let column = Column::Constant(DVector::from_element(dims.outputs, 1.0));
        FaultDictionary::new(dims, vec![Fault::output("bias", Onset::Step, column)]).unwrap()
    }

    fn detector(s: &SystemMatrices, settings: RlsSettings, evaluation: Evaluation) -> RlsDetector {
        let model = model(s);
        let faults = dictionary(model.dims());
        RlsDetector::new(Box::new(model), faults, settings, evaluation).unwrap()
    }

    fn settings(forgetting: f64) -> RlsSettings {
        RlsSettings {
            forgetting,
            ..RlsSettings::default()
        }
    }

    /// The survey's DC motor (their A, B, C, D, E_ω and noise variances σ²_ω = 0.0012,
    /// σ²_v = 0.0025): Q = σ²_ω E_ωE_ωᵀ, R = σ²_v I.
    fn dc_motor() -> SystemMatrices {
        let e = m(2, 1, &[-1.5537, 0.0]);
        system(
            m(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
            m(2, 1, &[0.0047, 0.4512]),
            DMatrix::identity(2, 2),
            DMatrix::zeros(2, 1),
            &e * e.transpose() * 0.0012,
            DMatrix::identity(2, 2) * 0.0025,
        )
    }

    fn dc_motor_plant(s: &SystemMatrices) -> Plant {
        Plant::new(
            s,
            m(2, 1, &[-1.5537 * 0.0012f64.sqrt(), 0.0]),
            vec![0.05, 0.05],
        )
    }

    /// A 2-state plant with two inputs, two outputs and feed-through.
    fn mimo(noise: f64) -> SystemMatrices {
        system(
            m(2, 2, &[0.6, 0.3, -0.2, 0.7]),
            m(2, 2, &[1.0, 0.5, 0.0, 1.0]),
            m(2, 2, &[1.0, 0.0, 0.5, 1.0]),
            m(2, 2, &[0.1, 0.0, 0.0, 0.2]),
            DMatrix::identity(2, 2) * noise,
            DMatrix::identity(2, 2) * noise,
        )
    }

    fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
        let mut c = vec![0.0; a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                c[i + j] += x * y;
            }
        }
        c
    }

    fn sample<'a>(k: u64, u: &'a [f64], y: &'a [f64]) -> Sample<'a> {
        Sample { k, u, y, p: &[] }
    }

    #[test]
    fn characteristic_polynomial_is_recovered() {
        // T diag(0.9, −0.5, 0.3, 0.1) T⁻¹: det(zI − F) = (z − 0.9)(z + 0.5)(z − 0.3)(z − 0.1).
        let t = m(
            4,
            4,
            &[
                1.0, 2.0, 0.0, -1.0, 0.5, 1.0, 3.0, 0.0, 0.0, -1.0, 1.0, 2.0, 1.0, 0.0, 0.5, 1.0,
            ],
        );
        let diag = DMatrix::from_diagonal(&DVector::from_vec(vec![0.9, -0.5, 0.3, 0.1]));
        let f = &t * diag * t.clone().try_inverse().unwrap();
        let mut want = vec![1.0];
        for root in [0.9, -0.5, 0.3, 0.1] {
            want = poly_mul(&want, &[1.0, -root]);
        }
        let (a, _) = faddeev_leverrier(&f);
        for (x, y) in a.iter().zip(&want) {
            assert!((x - y).abs() < 1e-12, "{a:?} vs {want:?}");
        }
        // A companion matrix with large coefficients: det(zI − F) = z³ − 30z² + 200z − 7.
        let f = m(3, 3, &[30.0, -200.0, 7.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let (a, _) = faddeev_leverrier(&f);
        let want = [1.0, -30.0, 200.0, -7.0];
        for (x, y) in a.iter().zip(&want) {
            assert!((x - y).abs() < 1e-11 * y.abs().max(1.0), "{a:?}");
        }
        // The DC motor: z² − (0.2231 + 0.5488) z + 0.2231·0.5488 + 0.0109·0.0022.
        let arx = ArxForm::new(&dc_motor()).unwrap();
        let want = [1.0, -0.7719, 0.2231 * 0.5488 + 0.0109 * 0.0022];
        for (x, y) in arx.characteristic().iter().zip(&want) {
            assert!((x - y).abs() < 1e-15, "{:?}", arx.characteristic());
        }
    }

    /// The transfer function H(zI − F)⁻¹G + J at a point, against Σ b_j z^{n−j} / a(z).
    #[test]
    fn arx_form_is_the_transfer_function() {
        let s = mimo(0.0);
        let arx = ArxForm::new(&s).unwrap();
        for z in [1.7, -0.4, 3.0] {
            let resolvent = (DMatrix::identity(2, 2) * z - &s.f).try_inverse().unwrap();
            let want = &s.h * resolvent * &s.g + &s.j;
            let den: f64 = (0..=2)
                .map(|j| arx.characteristic()[j] * z.powi(2 - j as i32))
                .sum();
            let num = (0..=2).fold(DMatrix::zeros(2, 2), |acc, j| {
                acc + arx.numerator(j) * z.powi(2 - j as i32)
            });
            assert!((num / den - want).amax() < 1e-13);
        }
    }

    /// Test (a): the ARX recursion of a 2-state MIMO model reproduces its noise-free
    /// output from the same inputs, whatever the initial state.
    #[test]
    fn arx_form_reproduces_the_noise_free_output_exactly() {
        let s = mimo(0.0);
        let arx = ArxForm::new(&s).unwrap();
        let mut plant = Plant::new(&s, DMatrix::zeros(2, 1), vec![0.0, 0.0]);
        plant.x = DVector::from_vec(vec![1.0, -2.0]);
        let mut rng = Rng(7);
        let u: Vec<Vec<f64>> = (0..500).map(|_| vec![rng.normal(), rng.sign()]).collect();
        let y: Vec<Vec<f64>> = u.iter().map(|u| plant.output(u, &mut rng)).collect();
        let a = arx.characteristic();
        let mut worst: f64 = 0.0;
        for k in 2..500 {
            for i in 0..2 {
                let mut pred = 0.0;
                for j in 1..=2 {
                    pred -= a[j] * y[k - j][i];
                }
                for j in 0..=2 {
                    for mm in 0..2 {
                        pred += arx.numerator(j)[(i, mm)] * u[k - j][mm];
                    }
                }
                worst = worst.max((pred - y[k][i]).abs());
            }
        }
        assert!(worst <= 1e-10, "{worst:e}");
        assert!(arx.has_feedthrough());
        assert_eq!(arx.parameters(), 2 + 3 * 2);
        // θ_nom lays out [a_1, a_2, b_0ᵀ, b_1ᵀ, b_2ᵀ] of the output's row.
        let theta = arx.nominal(1);
        assert_eq!(theta[0], a[1]);
        assert_eq!(theta[3], arx.numerator(0)[(1, 1)]);
        assert_eq!(theta[6], arx.numerator(2)[(1, 0)]);
    }

    #[test]
    fn spectral_factor_is_the_minimum_phase_one() {
        // e = ε + 0.5ε(k−1) − 0.3ε(k−2), σ² = 2.
        let r = [2.0 * (1.0 + 0.25 + 0.09), 2.0 * (0.5 - 0.15), 2.0 * -0.3];
        let (c, s2) = spectral_factor(&r).unwrap();
        assert!(
            (c[0] - 0.5).abs() < 1e-12 && (c[1] + 0.3).abs() < 1e-12,
            "{c:?}"
        );
        assert!((s2 - 2.0).abs() < 1e-12);
        // 1 + 2.5q⁻¹ + q⁻² has a zero at −2: the factor reflects it to −0.5.
        let (c, s2) = spectral_factor(&[8.25, 5.0, 1.0]).unwrap();
        assert!(
            (c[0] - 1.0).abs() < 1e-10 && (c[1] - 0.25).abs() < 1e-10,
            "{c:?}"
        );
        assert!((s2 - 4.0).abs() < 1e-9);
        // (1 − q⁻¹)ε has its zero on the unit circle: no whitening filter.
        assert!(spectral_factor(&[2.0, -1.0]).is_none());
    }

    /// The equation error's autocovariance r_i(τ) against the sample autocovariance of
    /// A(q)y_i − B_i(q)u on a simulated DC motor.
    #[test]
    fn equation_error_autocovariance_matches_simulation() {
        let s = dc_motor();
        let arx = ArxForm::new(&s).unwrap();
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(11);
        let n = 200_000;
        let u: Vec<f64> = (0..n).map(|_| rng.sign()).collect();
        let y: Vec<Vec<f64>> = u.iter().map(|&u| plant.output(&[u], &mut rng)).collect();
        let a = arx.characteristic();
        for i in 0..2 {
            let e: Vec<f64> = (2..n)
                .map(|k| {
                    let mut e = y[k][i];
                    for j in 1..=2 {
                        e += a[j] * y[k - j][i] - arx.numerator(j)[(i, 0)] * u[k - j];
                    }
                    e
                })
                .collect();
            let r = arx.equation_error(i).autocovariance();
            for tau in 0..=3 {
                let sample: f64 =
                    (tau..e.len()).map(|k| e[k] * e[k - tau]).sum::<f64>() / (e.len() - tau) as f64;
                let want = r.get(tau).copied().unwrap_or(0.0);
                assert!(
                    (sample - want).abs() < 0.02 * r[0],
                    "y{i} τ = {tau}: {sample} vs {want}"
                );
            }
        }
    }

    /// Steps `det` through `n` samples of `plant` driven by `input`, returning l_k
    /// (`NaN` where `None`).
    fn run(
        det: &mut RlsDetector,
        plant: &mut Plant,
        rng: &mut Rng,
        n: usize,
        mut input: impl FnMut(u64, &mut Rng) -> Vec<f64>,
    ) -> Vec<f64> {
        let mut out = StepOutput::for_detector(det);
        let start = det.next_index().unwrap_or(0);
        (start..start + n as u64)
            .map(|k| {
                let u = input(k, rng);
                let y = plant.output(&u, rng);
                det.step(&sample(k, &u, &y), &mut out).unwrap();
                out.glr.unwrap_or(f64::NAN)
            })
            .collect()
    }

    fn signs(l: usize) -> impl FnMut(u64, &mut Rng) -> Vec<f64> {
        move |_, r| (0..l).map(|_| r.sign()).collect()
    }

    fn max_error(a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    /// Test (b): on exciting input RLS reaches the parameters of a plant that differs
    /// from the model; noise-free with λ_f = 1 exactly, and against batch least squares
    /// (dense normal equations of the same data).
    #[test]
    fn rls_converges_to_the_true_parameters() {
        let nominal = mimo(0.0);
        let mut truth = mimo(0.0);
        truth.f[(0, 0)] = 0.5;
        truth.f[(1, 1)] = 0.75;
        truth.g *= 1.2;
        let want = ArxForm::new(&truth).unwrap();
        let rls = RlsSettings {
            forgetting: 1.0,
            p0: 1e6,
            ..RlsSettings::default()
        };
        let mut det = detector(&nominal, rls, Evaluation::Energy { window: 10 });
        let mut plant = Plant::new(&truth, DMatrix::zeros(2, 1), vec![0.0, 0.0]);
        plant.x = DVector::from_vec(vec![0.3, -1.0]);
        let mut rng = Rng(21);
        let n = 400;
        let u: Vec<Vec<f64>> = (0..n).map(|_| vec![rng.normal(), rng.normal()]).collect();
        let y: Vec<Vec<f64>> = u.iter().map(|u| plant.output(u, &mut rng)).collect();
        let mut out = StepOutput::for_detector(&det);
        for k in 0..n {
            det.step(&sample(k as u64, &u[k], &y[k]), &mut out).unwrap();
        }
        for i in 0..2 {
            let truth_i = want.nominal(i);
            let error = max_error(det.estimate(i), truth_i.as_slice());
            assert!(error < 1e-8, "y{i}: {error:e}");
            // Batch least squares: rows [−y_i(k−1), −y_i(k−2), u(k)ᵀ, u(k−1)ᵀ, u(k−2)ᵀ].
            let rows: Vec<Vec<f64>> = (2..n)
                .map(|k| {
                    let mut r = vec![-y[k - 1][i], -y[k - 2][i]];
                    for j in 0..=2 {
                        r.extend_from_slice(&u[k - j]);
                    }
                    r
                })
                .collect();
            let phi = DMatrix::from_fn(rows.len(), 8, |r, c| rows[r][c]);
            let target = DVector::from_fn(rows.len(), |r, _| y[r + 2][i]);
            let batch = (phi.transpose() * &phi)
                .cholesky()
                .unwrap()
                .solve(&(phi.transpose() * target));
            assert!(max_error(batch.as_slice(), truth_i.as_slice()) < 1e-10);
            assert!(max_error(det.estimate(i), batch.as_slice()) < 1e-8);
        }
        // With noise (Q = R = 10⁻⁴ I) and λ_f = 1 over 2·10⁴ samples: within a few
        // standard deviations of the estimate's covariance σ²PSP (measured: about 1).
        let noisy = mimo(1e-4);
        let mut truth = noisy.clone();
        truth.f[(0, 0)] = 0.5;
        truth.f[(1, 1)] = 0.75;
        truth.g *= 1.2;
        let mut det = detector(&noisy, rls, Evaluation::Chi2);
        let mut plant = Plant::new(&truth, DMatrix::identity(2, 2) * 0.01, vec![0.01, 0.01]);
        run(&mut det, &mut plant, &mut rng, 20_000, |_, r| {
            vec![r.normal(), r.normal()]
        });
        for i in 0..2 {
            let error = DVector::from_column_slice(det.estimate(i)) - want.nominal(i);
            let spread = det.covariance(i).trace().sqrt();
            eprintln!(
                "y{i}: |θ̂ − θ_true| = {:.2e}, √tr Σ_θ = {spread:.2e}",
                error.norm()
            );
            assert!(error.norm() < 4.0 * spread && error.norm() < 2e-3, "y{i}");
        }
    }

    /// Plain least squares on the raw ARX regressors is biased by the coloured equation
    /// error; on the whitened regressors it is not (batch estimates over 2·10⁵ samples of
    /// the DC motor, bias in units of the estimate's standard deviation).
    #[test]
    fn whitening_removes_the_least_squares_bias() {
        let s = dc_motor();
        let arx = ArxForm::new(&s).unwrap();
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(31);
        let n = 200_000;
        let u: Vec<f64> = (0..n).map(|_| rng.sign()).collect();
        let y: Vec<Vec<f64>> = u.iter().map(|&u| plant.output(&[u], &mut rng)).collect();
        for i in 0..2 {
            let noise = arx.equation_error(i);
            let c = noise.polynomial();
            let rows: Vec<[f64; 5]> = (2..n)
                .map(|k| [-y[k - 1][i], -y[k - 2][i], u[k - 1], u[k - 2], y[k][i]])
                .collect();
            let mut filtered = rows.clone();
            for t in 0..rows.len() {
                for j in 1..=2.min(t) {
                    for col in 0..5 {
                        filtered[t][col] -= c[j - 1] * filtered[t - j][col];
                    }
                }
            }
            let nominal = arx.nominal(i);
            let mut worst = [0.0f64; 2];
            for (w, data) in [&rows, &filtered].into_iter().enumerate() {
                let phi = DMatrix::from_fn(data.len(), 4, |r, col| data[r][col]);
                let target = DVector::from_fn(data.len(), |r, _| data[r][4]);
                let gram = phi.transpose() * &phi;
                let inverse = gram.clone().try_inverse().unwrap();
                let theta = &inverse * (phi.transpose() * &target);
                let residual = &target - &phi * &theta;
                let s2 = residual.norm_squared() / data.len() as f64;
                for p in 0..4 {
                    let z = (theta[p] - nominal[p]).abs() / (s2 * inverse[(p, p)]).sqrt();
                    worst[w] = worst[w].max(z);
                }
            }
            eprintln!(
                "y{i}: largest |bias|/σ raw {:.1}, whitened {:.1}",
                worst[0], worst[1]
            );
            assert!(
                worst[0] > 10.0,
                "y{i}: raw least squares looks unbiased: {}",
                worst[0]
            );
            assert!(
                worst[1] < 4.0,
                "y{i}: whitened least squares is biased: {}",
                worst[1]
            );
        }
    }

    /// l_k of the DC motor (survey noise, λ_f = 0.98, PRBS input): 3000 fault-free
    /// samples from `plant`, then 3000 from `faulty` (same state, same random stream).
    fn dc_motor_change(faulty: Option<&SystemMatrices>, bias: f64) -> (Vec<f64>, Vec<f64>) {
        let s = dc_motor();
        let mut det = detector(&s, settings(0.98), Evaluation::Chi2);
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(5);
        let before = run(&mut det, &mut plant, &mut rng, 3000, signs(1));
        if let Some(f) = faulty {
            let x = plant.x.clone();
            plant = dc_motor_plant(f);
            plant.x = x;
        }
        let mut out = StepOutput::for_detector(&det);
        let after = (3000..6000)
            .map(|k| {
                let u = [rng.sign()];
                let mut y = plant.output(&u, &mut rng);
                y[1] += bias;
                det.step(&sample(k, &u, &y), &mut out).unwrap();
                out.glr.unwrap_or(f64::NAN)
            })
            .collect();
        (before, after)
    }

    /// Test (c): parameter changes of the DC motor (survey eq. (3): ΔA, ΔB, ΔC) and an
    /// additive speed-sensor bias are detected at the χ²(8) quantile of α = 10⁻⁶, which
    /// the 3000 fault-free samples before never reach (largest l_k 22.3 measured).
    /// Measured delays: pole 5, actuator gain 3, sensor gain 37, sensor bias 4 samples.
    #[test]
    fn parameter_changes_are_detected() {
        let threshold = chi2_upper_quantile(8.0, 1e-6).unwrap();
        let mut pole = dc_motor();
        pole.f[(1, 1)] = 0.45;
        let mut gain = dc_motor();
        gain.g *= 0.7;
        let mut sensor = dc_motor();
        sensor.h[(1, 1)] = 0.9;
        for (name, faulty, bias, within) in [
            ("pole 0.5488 → 0.45", Some(&pole), 0.0, 20),
            ("actuator gain × 0.7", Some(&gain), 0.0, 20),
            ("speed sensor gain × 0.9", Some(&sensor), 0.0, 100),
            ("speed sensor bias 0.2", None, 0.2, 20),
        ] {
            let (before, after) = dc_motor_change(faulty, bias);
            assert!(
                before[100..].iter().all(|x| !x.is_nan()),
                "{name}: test not running"
            );
            let largest = before
                .iter()
                .copied()
                .filter(|x| !x.is_nan())
                .fold(0.0, f64::max);
            assert!(largest < threshold, "{name}: false alarm {largest}");
            let delay = after.iter().position(|&x| x > threshold);
            assert!(delay.is_some_and(|d| d < within), "{name}: delay {delay:?}");
            assert!(
                after[2000..].iter().all(|&x| x > threshold),
                "{name}: alarm lost"
            );
        }
    }

    /// On a well-conditioned plant the estimate follows an actuator gain change to the
    /// changed plant's ARX parameters (within 4 standard deviations of σ²PSP).
    #[test]
    fn estimate_follows_a_gain_change() {
        let s = mimo(1e-3);
        let mut faulty = s.clone();
        faulty.g.column_mut(1).scale_mut(0.5);
        let want = ArxForm::new(&faulty).unwrap();
        let mut det = detector(&s, settings(0.995), Evaluation::Chi2);
        let w = DMatrix::identity(2, 2) * 1e-3f64.sqrt();
        let mut plant = Plant::new(&s, w.clone(), vec![1e-3f64.sqrt(); 2]);
        let mut rng = Rng(41);
        run(&mut det, &mut plant, &mut rng, 2000, signs(2));
        let mut plant = Plant::new(&faulty, w, vec![1e-3f64.sqrt(); 2]);
        let glr = run(&mut det, &mut plant, &mut rng, 3000, signs(2));
        assert!(glr[2999] > chi2_upper_quantile(16.0, 1e-6).unwrap());
        for i in 0..2 {
            let error = DVector::from_column_slice(det.estimate(i)) - want.nominal(i);
            let spread = det.covariance(i).trace().sqrt();
            assert!(
                error.norm() < 4.0 * spread,
                "y{i}: {} vs {spread}",
                error.norm()
            );
        }
    }

    /// Test (d): a constant input stops the excitation: the test is suspended (`glr`
    /// `None`, `excited()` false) and P stops growing; PRBS again resumes it.
    /// Measured (λ_f = 0.95): the smallest normalised eigenvalue falls below 10⁻⁶ within
    /// 400 samples of the input's stop and P's largest entry freezes at about 2·10⁴.
    #[test]
    fn constant_input_suspends_the_test_until_excitation_returns() {
        let s = mimo(0.01);
        let mut det = detector(&s, settings(0.95), Evaluation::Chi2);
        let mut plant = Plant::new(&s, DMatrix::identity(2, 2) * 0.1, vec![0.1, 0.1]);
        let mut rng = Rng(9);
        let glr = run(&mut det, &mut plant, &mut rng, 1500, signs(2));
        assert!(det.excited() && glr[100..].iter().all(|x| !x.is_nan()));
        let largest_p =
            |det: &RlsDetector| det.outputs.iter().map(|o| o.p.amax()).fold(0.0, f64::max);
        let glr = run(&mut det, &mut plant, &mut rng, 500, |_, _| vec![0.5, -0.2]);
        assert!(!det.excited() && det.excitation() < DEFAULT_EXCITATION);
        let frozen = largest_p(&det);
        let suspended = run(&mut det, &mut plant, &mut rng, 1000, |_, _| vec![0.5, -0.2]);
        assert!(glr[400..].iter().chain(&suspended).all(|x| x.is_nan()));
        assert!(largest_p(&det) <= frozen && frozen < 1e5, "{frozen}");
        let resumed = run(&mut det, &mut plant, &mut rng, 1000, signs(2));
        let back = resumed.iter().position(|x| !x.is_nan()).unwrap();
        assert!(back < 200, "{back}");
        assert!(det.excited() && resumed[back..].iter().all(|x| !x.is_nan()));
    }

    /// Test (e): on fault-free data the χ² statistic's mean is its degrees of freedom
    /// and the exceedance rate at the χ²(α = 0.01) quantile is α, for the DC motor
    /// (outputs with nearly independent noises). Measured over 3·10⁵ samples:
    /// λ_f = 0.99: mean 7.89, rate 0.0089; λ_f = 0.98: mean 7.89, rate 0.0088.
    /// It also checks the stationary scaling cov θ̂ ≈ σ²P/(1 + λ): the statistic with
    /// σ²P/(1 + λ) in place of σ²PSP has mean 7.81 (0.99), 7.73 (0.98), and with σ²P
    /// about 8/(1 + λ), 3.9.
    #[test]
    fn fault_free_chi2_rate_is_alpha_on_the_dc_motor() {
        for lambda in [0.99, 0.98] {
            let s = dc_motor();
            let mut det = detector(&s, settings(lambda), Evaluation::Chi2);
            let mut plant = dc_motor_plant(&s);
            let mut rng = Rng(3);
            let mut out = StepOutput::for_detector(&det);
            let (mut values, mut stationary, mut naive) = (Vec::new(), Vec::new(), Vec::new());
            for k in 0..300_000u64 {
                let u = [rng.sign()];
                let y = plant.output(&u, &mut rng);
                det.step(&sample(k, &u, &y), &mut out).unwrap();
                let Some(l) = out.glr else { continue };
                values.push(l);
                if k % 20 == 0 {
                    let (mut with, mut without) = (0.0, 0.0);
                    for o in &det.outputs {
                        let cov = (&o.p * o.variance).cholesky().unwrap();
                        let z = cov.solve(&o.residual).dot(&o.residual);
                        with += z * (1.0 + lambda);
                        without += z;
                    }
                    stationary.push(with);
                    naive.push(without);
                }
            }
            assert!(values.len() > 299_000);
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let q = chi2_upper_quantile(8.0, 0.01).unwrap();
            let rate = values.iter().filter(|&&x| x > q).count() as f64 / values.len() as f64;
            let mean_stationary = stationary.iter().sum::<f64>() / stationary.len() as f64;
            let mean_naive = naive.iter().sum::<f64>() / naive.len() as f64;
            eprintln!(
                "λ_f = {lambda}: mean {mean:.3}, rate {rate:.4}, with σ²P/(1 + λ) \
                 {mean_stationary:.3}, with σ²P {mean_naive:.3}"
            );
            assert!((mean - 8.0).abs() < 0.03 * 8.0, "{mean}");
            assert!((rate - 0.01).abs() < 0.3 * 0.01, "{rate}");
            assert!(
                (mean_stationary - 8.0).abs() < 0.05 * 8.0,
                "{mean_stationary}"
            );
            let halved = 8.0 / (1.0 + lambda);
            assert!((mean_naive - halved).abs() < 0.05 * halved, "{mean_naive}");
        }
    }

    /// Test (e), outputs with correlated noises: the MIMO plant's Q = 10⁻² I drives both
    /// outputs through H = [1 0; 0.5 1], so the whitened errors of the two outputs are
    /// correlated (0.25 at lag 0, 0.21 at lag 1, … measured) and the block-diagonal Σ_θ
    /// misses it: the mean is still the degrees of freedom but the tail is heavier.
    /// Measured over 1.5·10⁵ samples at λ_f = 0.98: mean ≈ 16, rate at α = 0.01 about
    /// 1.7 α; the test asserts that band, not α.
    #[test]
    fn correlated_outputs_have_a_heavier_tail() {
        let s = mimo(0.01);
        let mut det = detector(&s, settings(0.98), Evaluation::Chi2);
        let mut plant = Plant::new(&s, DMatrix::identity(2, 2) * 0.1, vec![0.1, 0.1]);
        let mut rng = Rng(3);
        let glr = run(&mut det, &mut plant, &mut rng, 150_000, signs(2));
        let values: Vec<f64> = glr.into_iter().filter(|x| !x.is_nan()).collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let q = chi2_upper_quantile(16.0, 0.01).unwrap();
        let rate = values.iter().filter(|&&x| x > q).count() as f64 / values.len() as f64;
        eprintln!("correlated outputs: mean {mean:.3}, rate {rate:.4}");
        assert!((mean - 16.0).abs() < 0.03 * 16.0, "{mean}");
        assert!(rate > 0.013 && rate < 0.022, "{rate}");
    }

    /// Test (f): the survey's DC motor. Its ARX form by hand: a(z) = z² − 0.7719z +
    /// 0.2231·0.5488 + 0.0109·0.0022; speed y_2: b_1 = G_2 = 0.4512, b_2 = H_2(F +
    /// a_1I)G = −0.0022·0.0047 + (0.5488 − 0.7719)·0.4512; current y_1: b_1 = 0.0047,
    /// b_2 = (0.2231 − 0.7719)·0.0047 + 0.0109·0.4512. Under the survey's own input
    /// (u = 0.5, constant) nothing is excited and the test never runs.
    #[test]
    fn survey_dc_motor() {
        let s = dc_motor();
        let det = detector(&s, settings(0.98), Evaluation::Chi2);
        let arx = det.arx();
        let a2 = 0.2231 * 0.5488 + 0.0109 * 0.0022;
        let want_speed = [
            -0.7719,
            a2,
            0.4512,
            -0.0022 * 0.0047 + (0.5488 - 0.7719) * 0.4512,
        ];
        let want_current = [
            -0.7719,
            a2,
            0.0047,
            (0.2231 - 0.7719) * 0.0047 + 0.0109 * 0.4512,
        ];
        assert!(max_error(arx.nominal(1).as_slice(), &want_speed) < 1e-15);
        assert!(max_error(arx.nominal(0).as_slice(), &want_current) < 1e-15);
        assert!(!arx.has_feedthrough());
        assert_eq!(
            (det.residual_len(), det.memory(), det.horizon()),
            (8, 50, Some(50))
        );
        // Speed: e_2 = A(q)v_2 − 0.0022·w(k−2): r(0) ≈ σ²_v(1 + a_1² + a_2²).
        let r = arx.equation_error(1).autocovariance();
        let e1 = -0.0022 * -1.5537;
        let want = 0.0025 * (1.0 + 0.7719f64.powi(2) + a2 * a2) + e1 * e1 * 0.0012;
        assert!((r[0] - want).abs() < 1e-15, "{} vs {want}", r[0]);
        let mut det = detector(&s, settings(0.98), Evaluation::Chi2);
        let mut plant = dc_motor_plant(&s);
        let glr = run(&mut det, &mut plant, &mut Rng(1), 3000, |_, _| vec![0.5]);
        assert!(glr.iter().all(|x| x.is_nan()) && !det.excited());
    }

    fn constructor_error(
        s: &SystemMatrices,
        settings: RlsSettings,
        evaluation: Evaluation,
    ) -> String {
        let model = model(s);
        let faults = dictionary(model.dims());
        RlsDetector::new(Box::new(model), faults, settings, evaluation)
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn constructor_names_the_failing_condition() {
        let ok = RlsSettings::default();
        let s = dc_motor();
        // Not LTI.
        let f =
            crate::model::LpvMatrix::new(s.f.clone(), vec![(0, DMatrix::identity(2, 2))]).unwrap();
        let c = crate::model::LpvMatrix::constant;
        let lpv = Lpv::new(
            f,
            c(s.g.clone()),
            c(s.h.clone()),
            c(s.j.clone()),
            c(s.q.clone()),
            c(s.r.clone()),
            1,
        )
        .unwrap();
        let faults = dictionary(lpv.dims());
        let err = RlsDetector::new(Box::new(lpv), faults, ok, Evaluation::Chi2).unwrap_err();
        assert!(err.to_string().contains("needs an LTI model"), "{err}");
        // No input.
        let mut none = s.clone();
        none.g = DMatrix::zeros(2, 0);
        none.j = DMatrix::zeros(2, 0);
        assert!(constructor_error(&none, ok, Evaluation::Chi2).contains("no known input"));
        // A mode y_0 does not see: F diagonal, H = I.
        let mut split = s.clone();
        split.f = m(2, 2, &[0.5, 0.0, 0.0, 0.8]);
        split.g = m(2, 1, &[1.0, 1.0]);
        let err = constructor_error(&split, ok, Evaluation::Chi2);
        assert!(
            err.contains("output y0") && err.contains("share a root"),
            "{err}"
        );
        // An output no input reaches.
        let mut deaf = s.clone();
        deaf.f = m(2, 2, &[0.5, 0.0, 0.0, 0.8]);
        deaf.g = m(2, 1, &[1.0, 0.0]);
        deaf.h = m(2, 2, &[1.0, 0.0, 0.0, 1.0]);
        assert!(constructor_error(&deaf, ok, Evaluation::Chi2).contains("share a root"));
        let mut mute = s.clone();
        mute.h = m(2, 2, &[1.0, 0.0, 0.0, 0.0]);
        let err = constructor_error(&mute, ok, Evaluation::Chi2);
        assert!(err.contains("no input reaches output y1"), "{err}");
        // No noise: no χ², but the energy evaluation runs.
        let quiet = mimo(0.0);
        let err = constructor_error(&quiet, ok, Evaluation::Chi2);
        assert!(err.contains("y0 has no noise"), "{err}");
        let _ = detector(&quiet, ok, Evaluation::Energy { window: 5 });
        // Settings.
        for (bad, word) in [
            (
                RlsSettings {
                    forgetting: 0.0,
                    ..ok
                },
                "λ_f = 0",
            ),
            (
                RlsSettings {
                    forgetting: 1.5,
                    ..ok
                },
                "(0, 1]",
            ),
            (
                RlsSettings {
                    forgetting: f64::NAN,
                    ..ok
                },
                "λ_f",
            ),
            (
                RlsSettings {
                    forgetting: 0.7,
                    ..ok
                },
                "fewer than the 4 parameters",
            ),
            (RlsSettings { p0: 0.0, ..ok }, "p0"),
            (
                RlsSettings {
                    p0: f64::INFINITY,
                    ..ok
                },
                "p0",
            ),
            (
                RlsSettings {
                    excitation: 0.0,
                    ..ok
                },
                "(0, 1)",
            ),
            (
                RlsSettings {
                    excitation: 1.0,
                    ..ok
                },
                "(0, 1)",
            ),
        ] {
            let err = constructor_error(&s, bad, Evaluation::Chi2);
            assert!(err.contains(word), "{word}: {err}");
        }
        let err = constructor_error(&s, ok, Evaluation::Energy { window: 0 });
        assert!(err.contains("window"), "{err}");
        // A dictionary for another model.
        let other = dictionary(Dims {
            states: 3,
            inputs: 1,
            outputs: 2,
            signals: 0,
        });
        let err = RlsDetector::new(Box::new(model(&s)), other, ok, Evaluation::Chi2).unwrap_err();
        assert!(matches!(err, ModelError::Dimension { .. }), "{err}");
    }

    /// A refused sample changes nothing: a twin fed only the good samples gives the same
    /// bits; restart is a new detector; the interface's lengths and names.
    #[test]
    fn step_contract() {
        let s = dc_motor();
        let mut det = detector(&s, settings(0.95), Evaluation::Chi2);
        let mut twin = detector(&s, settings(0.95), Evaluation::Chi2);
        assert_eq!(
            (
                det.kind(),
                det.innovation_len(),
                det.residual_len(),
                det.estimates_magnitude()
            ),
            ("rls", 0, 8, false)
        );
        assert!(det.describe().contains("λ_f = 0.95"), "{}", det.describe());
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(2);
        let data: Vec<([f64; 1], Vec<f64>)> = (0..300)
            .map(|_| {
                let u = [rng.sign()];
                let y = plant.output(&u, &mut rng);
                (u, y)
            })
            .collect();
        let mut out = StepOutput::for_detector(&det);
        let mut twin_out = StepOutput::for_detector(&twin);
        for (k, (u, y)) in data.iter().enumerate() {
            let k = k as u64;
            if k % 37 == 5 {
                let bad = [f64::NAN, y[1]];
                assert_eq!(
                    det.step(&sample(k, u, &bad), &mut out),
                    Err(StepError::NonFinite {
                        field: "y",
                        index: 0
                    })
                );
                assert!(matches!(
                    det.step(&sample(k, u, &y[..1]), &mut out),
                    Err(StepError::WrongDimension { field: "y", .. })
                ));
                assert!(matches!(
                    det.step(&sample(k + 1, u, y), &mut out),
                    Err(StepError::OutOfOrder { .. })
                ));
                assert!(matches!(
                    det.step(&sample(k, &[], y), &mut out),
                    Err(StepError::WrongDimension { field: "u", .. })
                ));
            }
            det.step(&sample(k, u, y), &mut out).unwrap();
            twin.step(&sample(k, u, y), &mut twin_out).unwrap();
            assert_eq!(out, twin_out, "k = {k}");
        }
        assert!(out.glr.is_some() && out.rank == 8);
        assert_eq!(out.onset, Some(299 - 19));
        assert_eq!(det.next_index(), Some(300));
        det.restart();
        assert_eq!(det.next_index(), None);
        let mut fresh = detector(&s, settings(0.95), Evaluation::Chi2);
        let mut fresh_out = StepOutput::for_detector(&fresh);
        for (k, (u, y)) in data.iter().enumerate() {
            let k = 1000 + k as u64;
            det.step(&sample(k, u, y), &mut out).unwrap();
            fresh.step(&sample(k, u, y), &mut fresh_out).unwrap();
            assert_eq!(out, fresh_out);
        }
        assert_eq!(
            det.step(&sample(u64::MAX, &[0.0], &[0.0, 0.0]), &mut out),
            Err(StepError::IndexTooLarge { k: u64::MAX })
        );
    }

    /// A missing sample restarts the lags: the n = 2 samples after it report nothing and
    /// leave θ̂ as it was, then the test goes on from the kept estimate.
    #[test]
    fn a_gap_refills_the_lags_and_keeps_the_estimate() {
        let s = dc_motor();
        let mut det = detector(&s, settings(0.95), Evaluation::Chi2);
        assert!(matches!(
            det.predict_only(0),
            Err(StepError::OutOfOrder { .. })
        ));
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(4);
        run(&mut det, &mut plant, &mut rng, 200, signs(1));
        assert!(matches!(
            det.predict_only(201),
            Err(StepError::OutOfOrder { .. })
        ));
        det.predict_only(200).unwrap();
        let _ = plant.output(&[0.0], &mut rng);
        let kept: Vec<f64> = det.estimate(1).to_vec();
        let mut out = StepOutput::for_detector(&det);
        for k in 201..203 {
            let u = [rng.sign()];
            let y = plant.output(&u, &mut rng);
            det.step(&sample(k, &u, &y), &mut out).unwrap();
            assert_eq!(out.glr, None);
            assert_eq!(det.estimate(1), &kept[..]);
        }
        let glr = run(&mut det, &mut plant, &mut rng, 100, signs(1));
        assert!(glr.iter().all(|x| !x.is_nan()));
        assert_ne!(det.estimate(1), &kept[..]);
    }

    /// The energy evaluation is (Σ_{last w} rᵀr)^{1/2} of the residual the step reports;
    /// its onset spans the horizon and the window.
    #[test]
    fn energy_evaluation_is_the_windowed_residual_energy() {
        let s = dc_motor();
        let w = 7;
        let mut det = detector(&s, settings(0.95), Evaluation::Energy { window: w });
        assert_eq!(det.memory(), 20 + w - 1);
        let mut plant = dc_motor_plant(&s);
        let mut rng = Rng(8);
        let mut out = StepOutput::for_detector(&det);
        let mut squares = Vec::new();
        for k in 0..300u64 {
            let u = [rng.sign()];
            let y = plant.output(&u, &mut rng);
            det.step(&sample(k, &u, &y), &mut out).unwrap();
            squares.push(out.residual.norm_squared());
            if let Some(j) = out.glr {
                let direct: f64 = squares[squares.len() - w..].iter().sum();
                assert!((j - direct.sqrt()).abs() < 1e-12 * j.max(1.0));
                assert_eq!(out.onset, Some(k.saturating_sub(25)));
            }
        }
        assert!(out.glr.is_some());
        // Without forgetting the memory is unbounded and the onset is the first sample.
        let rls = RlsSettings {
            forgetting: 1.0,
            ..RlsSettings::default()
        };
        let mut det = detector(&s, rls, Evaluation::Chi2);
        assert_eq!((det.memory(), det.horizon()), (usize::MAX, None));
        run(&mut det, &mut plant, &mut rng, 5, signs(1));
        let mut out = StepOutput::for_detector(&det);
        for k in 5..200u64 {
            let u = [rng.sign()];
            let y = plant.output(&u, &mut rng);
            det.step(&sample(k, &u, &y), &mut out).unwrap();
        }
        assert_eq!((out.glr.is_some(), out.onset), (true, Some(0)));
    }

    /// An innovation model x⁺ = Fx + Gu + Ke, y = Hx + e (Q = K Re Kᵀ, R = Re,
    /// S = K Re): its ARX equation error is det(zI − F + KH)/zⁿ · e, so the spectral
    /// factor must be the characteristic polynomial of F − KH and σ² = Re. With S the
    /// fault-free χ² statistic has mean d; without it (S ignored) it does not (measured
    /// over 10⁵ samples, λ_f = 0.99: 3.99 with S, 8.7 without, for d = 4).
    #[test]
    fn innovation_model_whitens_to_its_own_innovation() {
        let f = m(2, 2, &[0.6, 0.3, -0.2, 0.7]);
        let g = m(2, 1, &[1.0, 0.5]);
        let h = m(1, 2, &[1.0, 0.0]);
        let k = m(2, 1, &[0.5, 0.2]);
        let re = 0.01;
        let sys = system(
            f.clone(),
            g.clone(),
            h.clone(),
            DMatrix::zeros(1, 1),
            &k * k.transpose() * re,
            DMatrix::from_element(1, 1, re),
        );
        let cross = &k * re;
        let arx = ArxForm::with_cross_covariance(&sys, &cross).unwrap();
        let closed = &f - &k * &h;
        let want = [-closed.trace(), closed.determinant()];
        let noise = arx.equation_error(0);
        assert!(
            max_error(noise.polynomial(), &want) < 1e-12,
            "{:?}",
            noise.polynomial()
        );
        assert!((noise.variance() - re).abs() < 1e-14);
        let mut means = Vec::new();
        for with in [true, false] {
            let mut det = detector(&sys, settings(0.99), Evaluation::Chi2);
            if with {
                det = det.with_cross_covariance(cross.clone()).unwrap();
            }
            let mut rng = Rng(17);
            let mut x = DVector::zeros(2);
            let mut out = StepOutput::for_detector(&det);
            let (mut sum, mut count) = (0.0, 0.0);
            for step in 0..100_000u64 {
                let u = [rng.sign()];
                let e = re.sqrt() * rng.normal();
                let y = [(&h * &x)[0] + e];
                x = &f * &x + &g * u[0] + &k * e;
                det.step(&sample(step, &u, &y), &mut out).unwrap();
                if let Some(l) = out.glr {
                    sum += l;
                    count += 1.0;
                }
            }
            means.push(sum / count);
        }
        eprintln!(
            "innovation model: mean {:.3} with S, {:.3} without",
            means[0], means[1]
        );
        assert!((means[0] - 4.0).abs() < 0.03 * 4.0, "{}", means[0]);
        assert!(means[1] > 5.0, "{}", means[1]);
    }
}
