//! Page's CUSUM on the Kalman innovation for faults of known magnitude (Basseville &
//! Nikiforov 1993, §2.2): the sequential test that the GLR of Zhang & Basseville 2014
//! generalises to an unknown magnitude and the fault's dynamic signature.
//!
//! # Letters
//! Ahmad & Mohd-Mokhtar 2021 write the plant x(k+1) = Ax + Bu + E_f f,
//! y = Cx + Du + F_f f (their eqs. (1)-(2), (14)); here A, B, C, D are Zhang & Basseville
//! 2014's F, G, H, J, a fault's state column E_f is Ψ̃ and its output column F_f is Φ̃,
//! and the survey's Kalman residual r(k) (eq. (15)) is the innovation ε_k, its
//! covariance σ²_RES (eq. (17)) Σ. The letter A below is the filter's closed-loop matrix,
//! as in [`crate::filter::innovation`].
//!
//! # The steady signature
//! The one-step predictor of [`InnovationFilter`] is
//! X̂_{k+1} = F X̂_k + G U_k + K_p ε_k with K_p = F K_k (+ S Σ_k⁻¹ with correlated noises;
//! [`InnovationFilter::predictor_gain`], the survey's gain K beside its eq. (16)), and
//! ε_k = Y_k − J U_k − H X̂_k (eq. (10)). Under a step fault j of magnitude θ_j (eq. (44):
//! Ψ̃_jθ_j in the state equation from X_{r+1} on, Φ̃_jθ_j in the output from Y_r on), the
//! prediction error X̃_k = X_k − X̂_k has the mean Γ_kθ_j with
//! Γ_{k+1} = A Γ_k + Ψ̃_j − K_pΦ̃_j, A = F − K_pH ([`InnovationFilter::closed_loop`]), and
//! the innovation the mean (HΓ_k + Φ̃_j)θ_j (eqs. (45)-(46)). For an LTI model the gain
//! settles to the solution of the Riccati equation (survey eq. (16)), A is then stable,
//! and for a fault that began long ago Γ = (I − A)⁻¹(Ψ̃_j − K_pΦ̃_j): the innovation's mean
//! is the steady signature
//!
//! ```text
//! ρ_j = θ_j (H (I − A)⁻¹ (Ψ̃_j − K_p Φ̃_j) + Φ̃_j)
//! ```
//!
//! The steady gain is found by running the Riccati recursion of a copy of the wrapped
//! detector's own filter (same Joseph-form update, same S) until the relative change of P
//! is below [`RICCATI_TOLERANCE`], so it is the gain the running filter converges to.
//!
//! # The statistic
//! Under no fault ε_k ~ N(0, Σ_k); long after the onset of fault j, N(ρ_j, Σ_k). The
//! log-likelihood ratio of one sample is
//!
//! ```text
//! s_j,k = ρ_jᵀΣ_k⁻¹ε_k − ½ ρ_jᵀΣ_k⁻¹ρ_j = (L_k⁻¹ρ_j)ᵀ(L_k⁻¹ε_k) − ½‖L_k⁻¹ρ_j‖²
//! g_j,k = max(0, g_j,k−1 + s_j,k) = max(0, max_{r ≤ k} Σ_{i=r..k} s_j,i)
//! ```
//!
//! with L_k the running filter's Cholesky factor of Σ_k: ρ_j is whitened at every sample,
//! so the test is exact through the transient of the Riccati recursion as well. The
//! decision statistic [`StepOutput::glr`] is 2·max_j g_j,k: twice the log-likelihood
//! ratio, the scale of the GLR's l_k (Zhang & Basseville 2014, eq. (35)); a threshold h
//! here is h/2 on Page's g. The onset [`StepOutput::onset`] is Page's estimate for the
//! maximising fault: the first sample of its current run of g > 0 (the sample after g
//! was last 0), k itself when g = 0.
//!
//! In the steady regime s_j,k ~ N(−δ_j²/2, δ_j²) under no fault and N(+δ_j²/2, δ_j²)
//! long after the onset, i.i.d., with δ_j² = ρ_jᵀΣ⁻¹ρ_j
//! ([`CusumDetector::information`]): Wald's mean detection delay is (h/2)/(δ_j²/2), and
//! Siegmund's mean run length to a false alarm of one fault's CUSUM (Basseville &
//! Nikiforov 1993, §5.2; for s/δ_j ~ N(−δ_j/2, 1) and the threshold h/(2δ_j)) is
//! (e^b − b − 1)/(δ_j²/2) with b = δ_j(h/(2δ_j) + 1.166) = h/2 + 1.166·δ_j.
//!
//! # Where it departs from the GLR
//! - The GLR tests the whole dynamic signature (HΓ_k(r) + Φ_k(r))θ from the onset on,
//!   with θ free; the CUSUM assumes the settled mean ρ_j from the first faulty sample on
//!   (Page's test of a change in the mean). In the first samples after the onset the
//!   innovation's mean is still moving from Φ̃_jθ_j towards ρ_j (a sensor bias shows in
//!   full at its onset, then the filter absorbs part of it): the law under no fault is
//!   unaffected, those samples are only weighed along ρ_j instead of their own mean.
//! - The magnitudes θ̂, the isolation statistics and the innovation filter are the
//!   wrapped GLR's, as for the χ² kind: θ̂ at the GLR's own r̂, isolation available for
//!   onsets inside its window.
//! - The statistic is reported from the first sample (g starts at 0, and Σ_k carries the
//!   filter's transient); the GLR's warm-up withholds only its own statistic.
//! - [`Detector::memory`] is the GLR's window w: a CUSUM has no window, and w is what the
//!   monitor asks isolation for and what calibration clusters exceedances over. Under no
//!   fault an excursion that crosses a threshold h falls back to 0 in about
//!   (h/2)/(δ²/2) = h/δ² samples (15 at h = 15, δ = 1), well inside the usual w; a design
//!   with h/δ² above w would have one excursion counted as several clusters.
//!
//! Only LTI models, step faults and constant columns (zero, constant, an actuator bias
//! G[:, i]) have a settled signature; other dictionaries, an unknown input (E, whose
//! decoupled filter this derivation does not cover) and a filter whose steady closed loop
//! is not stable are refused by name.

use nalgebra::{DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::filter::innovation::InnovationFilter;
use crate::isolation::FisherStatistics;
use crate::model::fault::{Column, FaultDictionary, Onset};
use crate::model::{Dims, Signals, SystemMatrices};

use super::{Detector, GlrDetector, Sample, StepOutput, spectral_radius};

/// Relative change max|P_{k+1} − P_k| / max|P_{k+1}| at which the Riccati recursion counts
/// as converged to the steady gain.
pub const RICCATI_TOLERANCE: f64 = 1e-13;

/// Steps of the Riccati recursion before the steady gain is declared not found.
const MAX_RICCATI_STEPS: usize = 100_000;

/// ‖ρ_j‖ below this fraction of the norms of its terms θ_jΦ̃_j, θ_jH(I − A)⁻¹Ψ̃_j and
/// θ_jH(I − A)⁻¹K_pΦ̃_j: the terms cancel, the settled fault does not show.
const VANISHING_SIGNATURE: f64 = 1e-9;

/// Page's CUSUM of the innovation for each fault of the dictionary at its known
/// magnitude, on the filter of a [`GlrDetector`].
///
/// The decision statistic is 2·max_j g_j,k (see the module documentation); the GLR
/// window runs beside it unchanged, for the magnitudes θ̂, isolation and sparse diagnosis.
///
/// # Examples
/// ```
/// use glrmon_core::detector::{
///     CusumDetector, Detector, GlrDetector, Sample, StepOutput, WindowSettings,
/// };
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::model::{Lpv, StateSpace};
/// use nalgebra::{DMatrix, DVector};
///
/// let one = |x| DMatrix::from_element(1, 1, x);
/// let model = Lpv::lti(one(0.9), DMatrix::zeros(1, 0), one(1.0), DMatrix::zeros(1, 0),
///     one(1e-4), one(1e-4)).unwrap();
/// let faults = FaultDictionary::new(model.dims(), vec![
///     Fault::output("bias", Onset::Step, Column::Constant(DVector::from_vec(vec![1.0]))),
/// ]).unwrap();
/// let glr = GlrDetector::new(Box::new(model), faults, DVector::zeros(1),
///     DMatrix::identity(1, 1), WindowSettings { window: 20, min_lag: 0, ..Default::default() })
///     .unwrap();
/// let mut det = CusumDetector::new(glr, vec![0.5]).unwrap();
/// let mut out = StepOutput::new(1, 1);
/// for k in 0..60 {
///     let y = if k >= 40 { 0.5 } else { 0.0 }; // a sensor bias of the design magnitude
///     det.step(&Sample { k, u: &[], y: &[y], p: &[] }, &mut out).unwrap();
/// }
/// // The filter absorbs part of the bias: the settled innovation mean ρ is 16 % of it.
/// assert!((det.signatures()[(0, 0)] / 0.5 - 0.157).abs() < 1e-3);
/// assert!(out.glr.unwrap() > 200.0);
/// assert_eq!(out.onset, Some(40));
/// ```
#[derive(Debug)]
pub struct CusumDetector {
    glr: GlrDetector,
    magnitudes: Vec<f64>,
    /// ρ_j, column j (p×m).
    signatures: DMatrix<f64>,
    /// Σ of the steady filter.
    steady_covariance: DMatrix<f64>,
    /// δ_j² = ρ_jᵀΣ⁻¹ρ_j with the steady Σ.
    information: Vec<f64>,
    /// L_k⁻¹ρ_j of the current sample.
    whitened: DMatrix<f64>,
    /// s_j,k of the current sample.
    increments: Vec<f64>,
    /// g_j,k.
    sums: Vec<f64>,
    /// The first sample of fault j's current run of g_j > 0.
    starts: Vec<Option<u64>>,
}

impl CusumDetector {
    /// The CUSUM of `glr`'s innovation for each fault of its dictionary at the known
    /// magnitude `magnitudes[j]` (θ_j, in the fault's units: the signature is
    /// θ_j·(Ψ̃_j, Φ̃_j)); the model, the dictionary and the filter (with its S) are the
    /// GLR's. Solves the Riccati equation of the filter and computes the steady signatures
    /// ρ_j; every buffer of the per-sample path is allocated here.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when there is not one magnitude per fault;
    /// [`ModelError::Setting`] naming the fault for a magnitude that is zero or not finite,
    /// an onset profile other than a step, a gain-loss or custom column, a fault that does
    /// not reach the outputs or whose settled signature vanishes; naming the model when it
    /// is not LTI, E for an unknown input, R when the innovation covariance is not positive
    /// definite, and the Riccati equation when it does not converge or its closed loop is
    /// not stable; [`ModelError::NonFinite`] for a model that evaluates to NaN/∞.
    pub fn new(mut glr: GlrDetector, magnitudes: Vec<f64>) -> Result<Self, ModelError> {
        let dims = glr.dims();
        let (n, p, m) = (dims.states, dims.outputs, glr.fault_count());
        if magnitudes.len() != m {
            return Err(ModelError::Dimension {
                what: "magnitudes",
                detail: format!(
                    "{} magnitudes for {m} faults: the CUSUM needs one known magnitude θ_j per \
                     fault of the dictionary",
                    magnitudes.len()
                ),
            });
        }
        check_faults(glr.faults(), &magnitudes)?;
        if glr.unknown_inputs() > 0 {
            return Err(ModelError::Setting {
                what: "E",
                detail: "the CUSUM's steady signatures are derived for the Kalman filter: with \
                         an unknown input the innovation is the decoupled Kitanidis filter's, \
                         whose settled fault signatures are not derived here"
                    .into(),
            });
        }
        if !glr.model_mut().is_constant() {
            return Err(ModelError::Setting {
                what: "model",
                detail: "the CUSUM needs an LTI model: a step fault's signature settles only \
                         under constant matrices, and this model's matrices change with the \
                         sample or its scheduling signals"
                    .into(),
            });
        }
        let system = evaluate(&mut glr, dims)?;
        let steady = steady_filter(glr.filter(), &system)?;
        let (a, kp) = (steady.closed_loop(), steady.predictor_gain());
        let radius = spectral_radius(a);
        if radius.is_nan() || radius >= 1.0 {
            return Err(ModelError::Setting {
                what: "Riccati equation",
                detail: format!(
                    "the steady filter's closed loop A = F − K_pH has spectral radius {radius} \
                     ≥ 1 (a mode on or outside the unit circle that the noise Q does not \
                     excite): a step fault's signature would not settle"
                ),
            });
        }
        let lu = (DMatrix::<f64>::identity(n, n) - a).lu();
        let sigma = steady.innovation_covariance().clone();
        let Some(sigma_chol) = sigma.clone().cholesky() else {
            return Err(ModelError::Setting {
                what: "R",
                detail: "the steady innovation covariance H P Hᵀ + R is not positive definite"
                    .into(),
            });
        };
        let mut signatures = DMatrix::zeros(p, m);
        let mut information = Vec::with_capacity(m);
        for (j, (fault, &theta)) in glr.faults().faults().iter().zip(&magnitudes).enumerate() {
            let psi = column(&fault.state, &system, n);
            let phi = column(&fault.output, &system, p);
            let solve = |v: DVector<f64>| lu.solve(&v).filter(|x| x.iter().all(|v| v.is_finite()));
            let (Some(state_part), Some(gain_part)) = (solve(psi), solve(kp * &phi)) else {
                return Err(ModelError::Setting {
                    what: "Riccati equation",
                    detail: "I − A is singular: the steady signatures do not exist".into(),
                });
            };
            let (state_part, gain_part) = (&system.h * state_part, &system.h * gain_part);
            let rho = (&state_part - &gain_part + &phi) * theta;
            let scale = theta.abs() * (phi.norm() + state_part.norm() + gain_part.norm());
            if scale == 0.0 {
                return Err(ModelError::Setting {
                    what: "fault dictionary",
                    detail: format!(
                        "fault \"{}\" does not reach the outputs (its columns are zero): the \
                         CUSUM has nothing to test",
                        fault.name
                    ),
                });
            }
            if rho.norm() <= VANISHING_SIGNATURE * scale {
                return Err(ModelError::Setting {
                    what: "fault dictionary",
                    detail: format!(
                        "fault \"{}\" has a vanishing steady signature (‖ρ‖ = {:e}): the \
                         filter absorbs the settled fault (e.g. a sensor bias on a plant with \
                         an integrator), so a CUSUM for its settled mean would never see it",
                        fault.name,
                        rho.norm()
                    ),
                });
            }
            information.push(rho.dot(&sigma_chol.solve(&rho)));
            signatures.set_column(j, &rho);
        }
        Ok(Self {
            glr,
            magnitudes,
            signatures,
            steady_covariance: sigma,
            information,
            whitened: DMatrix::zeros(p, m),
            increments: vec![0.0; m],
            sums: vec![0.0; m],
            starts: vec![None; m],
        })
    }

    /// The GLR detector underneath.
    #[must_use]
    pub fn glr(&self) -> &GlrDetector {
        &self.glr
    }

    /// θ_j, one per fault.
    #[must_use]
    pub fn magnitudes(&self) -> &[f64] {
        &self.magnitudes
    }

    /// The steady signatures: column j is ρ_j, the innovation's mean long after the onset
    /// of fault j at magnitude θ_j (p×m).
    #[must_use]
    pub fn signatures(&self) -> &DMatrix<f64> {
        &self.signatures
    }

    /// Σ of the steady filter, the innovation covariance the running filter converges to.
    #[must_use]
    pub fn steady_innovation_covariance(&self) -> &DMatrix<f64> {
        &self.steady_covariance
    }

    /// δ_j² = ρ_jᵀΣ⁻¹ρ_j with the steady Σ, one per fault: the information of one sample
    /// about fault j; the CUSUM's drift per sample is −δ_j²/2 under no fault and +δ_j²/2
    /// under the settled fault.
    #[must_use]
    pub fn information(&self) -> &[f64] {
        &self.information
    }

    /// Page's g_j,k after the last step, one per fault (the decision statistic is twice
    /// their maximum).
    #[must_use]
    pub fn statistics(&self) -> &[f64] {
        &self.sums
    }

    /// Page's onset estimate of each fault after the last step: the first sample of its
    /// current run of g_j > 0 (`None` where g_j = 0).
    #[must_use]
    pub fn onsets(&self) -> &[Option<u64>] {
        &self.starts
    }

    /// s_j,k = (L_k⁻¹ρ_j)ᵀ(L_k⁻¹ε_k) − ½‖L_k⁻¹ρ_j‖² for the sample the filter has just
    /// measured; false when one of them is not finite.
    fn log_likelihood_ratios(&mut self) -> bool {
        let filter = self.glr.filter();
        let (p, m) = self.whitened.shape();
        self.whitened.copy_from(&self.signatures);
        filter.whiten_in_place(self.whitened.as_mut_slice(), m);
        let eps = filter.whitened_innovation().as_slice();
        let white = self.whitened.as_slice();
        for (j, s) in self.increments.iter_mut().enumerate() {
            let rho = &white[j * p..(j + 1) * p];
            let (mut cross, mut square) = (0.0, 0.0);
            for (r, e) in rho.iter().zip(eps) {
                cross += r * e;
                square += r * r;
            }
            *s = cross - 0.5 * square;
        }
        self.increments.iter().all(|s| s.is_finite())
    }
}

/// Refuses what has no settled signature: magnitudes that are zero or not finite, onset
/// profiles other than a step, columns that vary from sample to sample.
fn check_faults(faults: &FaultDictionary, magnitudes: &[f64]) -> Result<(), ModelError> {
    for (fault, &theta) in faults.faults().iter().zip(magnitudes) {
        if !theta.is_finite() || theta == 0.0 {
            return Err(ModelError::Setting {
                what: "magnitudes",
                detail: format!(
                    "fault \"{}\" has the magnitude {theta}: the CUSUM tests a known magnitude \
                     θ_j, finite and non-zero",
                    fault.name
                ),
            });
        }
        let profile = match fault.onset {
            Onset::Step => None,
            Onset::Impulse => Some("an impulse"),
            Onset::Ramp => Some("a ramp"),
            Onset::Known => Some("a known profile without onset"),
        };
        if let Some(profile) = profile {
            return Err(ModelError::Setting {
                what: "fault dictionary",
                detail: format!(
                    "the CUSUM needs a step fault whose signature settles: fault \"{}\" is \
                     {profile}",
                    fault.name
                ),
            });
        }
        for c in [&fault.state, &fault.output] {
            let varying = match c {
                Column::Zero | Column::Constant(_) | Column::InputBias { .. } => continue,
                Column::GainLoss { .. } => {
                    "a gain-loss column −G[:, i]·u_i, which varies with \
                                            the input"
                }
                Column::Custom(_) => "a custom column, which may vary from sample to sample",
            };
            return Err(ModelError::Setting {
                what: "fault dictionary",
                detail: format!(
                    "the CUSUM needs a step fault whose signature settles: fault \"{}\" has \
                     {varying}",
                    fault.name
                ),
            });
        }
    }
    Ok(())
}

/// The model's constant matrices.
fn evaluate(glr: &mut GlrDetector, dims: Dims) -> Result<SystemMatrices, ModelError> {
    let mut system = SystemMatrices::zeros(dims);
    let (u, p) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
    glr.model_mut()
        .evaluate(0, &Signals { u: &u, p: &p }, &mut system);
    if !system.is_finite() {
        return Err(ModelError::NonFinite { what: "model" });
    }
    Ok(system)
}

/// A copy of `filter` run through its Riccati recursion (time and measurement updates on
/// zero data: P, K, A and K_p do not depend on the data) until P settles.
fn steady_filter(
    filter: &InnovationFilter,
    system: &SystemMatrices,
) -> Result<InnovationFilter, ModelError> {
    let mut filter = filter.clone();
    let (u, y) = (vec![0.0; system.g.ncols()], vec![0.0; system.h.nrows()]);
    let mut before = filter.covariance().clone();
    let mut change = f64::INFINITY;
    for _ in 0..MAX_RICCATI_STEPS {
        if filter.measure(system, &u, &y).is_err() {
            return Err(ModelError::Setting {
                what: "R",
                detail: "the innovation covariance H P Hᵀ + R of the Riccati recursion is not \
                         positive definite"
                    .into(),
            });
        }
        filter.time_update(system, &u);
        let cov = filter.covariance();
        if !cov.iter().all(|v| v.is_finite()) {
            break;
        }
        change = cov
            .iter()
            .zip(before.iter())
            .fold(0.0_f64, |a, (x, y)| a.max((x - y).abs()));
        if change <= RICCATI_TOLERANCE * cov.amax() {
            return Ok(filter);
        }
        before.copy_from(cov);
    }
    Err(ModelError::Setting {
        what: "Riccati equation",
        detail: format!(
            "the Kalman filter's Riccati recursion (survey eq. (16)) did not settle in \
             {MAX_RICCATI_STEPS} steps (last change of P {change:e}): the CUSUM needs the \
             steady gain, which exists when the outputs see every unstable mode of F"
        ),
    })
}

/// Ψ̃_j or Φ̃_j of a constant column (checked by [`check_faults`]).
fn column(c: &Column, system: &SystemMatrices, len: usize) -> DVector<f64> {
    match c {
        Column::Constant(v) => v.clone(),
        Column::InputBias { input } => system.g.column(*input).into_owned(),
        _ => DVector::zeros(len),
    }
}

impl Detector for CusumDetector {
    fn kind(&self) -> &'static str {
        "cusum"
    }

    fn describe(&self) -> String {
        format!(
            "Page's CUSUM of the innovation for {} fault(s) of known magnitude, beside the \
             GLR window w = {}",
            self.magnitudes.len(),
            self.glr.settings().window
        )
    }

    fn memory(&self) -> usize {
        self.glr.settings().window
    }

    fn dims(&self) -> Dims {
        self.glr.dims()
    }

    fn faults(&self) -> &FaultDictionary {
        self.glr.faults()
    }

    fn unknown_inputs(&self) -> usize {
        self.glr.unknown_inputs()
    }

    fn next_index(&self) -> Option<u64> {
        self.glr.next_index()
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.glr.step(sample, out)?;
        if !self.log_likelihood_ratios() {
            return Err(StepError::Numerical {
                what: "the CUSUM's log-likelihood ratio is not finite",
            });
        }
        let k = sample.k;
        let mut best = 0;
        for j in 0..self.sums.len() {
            let g = self.sums[j] + self.increments[j];
            if g > 0.0 {
                self.sums[j] = g;
                self.starts[j].get_or_insert(k);
            } else {
                self.sums[j] = 0.0;
                self.starts[j] = None;
            }
            if self.sums[j] > self.sums[best] {
                best = j;
            }
        }
        out.glr = Some(2.0 * self.sums[best]);
        out.onset = Some(self.starts[best].unwrap_or(k));
        Ok(())
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        self.glr.predict_only(k)
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        self.glr.restart()?;
        self.sums.fill(0.0);
        self.starts.fill(None);
        Ok(())
    }

    fn forget_evidence(&mut self) -> bool {
        if !self.glr.forget_evidence() {
            return false;
        }
        self.sums.fill(0.0);
        self.starts.fill(None);
        true
    }

    fn fisher_statistics(&self, onset: u64) -> Option<FisherStatistics> {
        self.glr.fisher_statistics(onset)
    }

    fn onset_statistic(&self, onset: u64) -> Option<(f64, usize)> {
        self.glr.onset_statistic(onset)
    }

    fn onset_information(&self, onset: u64, information: &mut [f64], score: &mut [f64]) -> bool {
        Detector::onset_information(&self.glr, onset, information, score)
    }

    fn innovation_filter(&self) -> Option<&InnovationFilter> {
        Some(self.glr.filter())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detector::WindowSettings;
    use crate::model::fault::Fault;
    use crate::model::{Lpv, LpvMatrix, StateSpace};
    use crate::threshold::chi2_upper_quantile;

    /// xorshift64* with Box-Muller normals: the core has no rand dependency.
    struct Rng(u64, Option<f64>);

    impl Rng {
        fn new(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1, None)
        }
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
            ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            if let Some(z) = self.1.take() {
                return z;
            }
            let (u1, u2) = (self.uniform(), self.uniform());
            let radius = (-2.0 * u1.ln()).sqrt();
            let angle = 2.0 * std::f64::consts::PI * u2;
            self.1 = Some(radius * angle.sin());
            radius * angle.cos()
        }
        fn normals(&mut self, len: usize) -> DVector<f64> {
            DVector::from_fn(len, |_, _| self.normal())
        }
    }

    /// P_0 of the detectors, and the covariance of the simulated X_0 around 0.
    const P0: f64 = 0.01;

    /// A plant of the tests (J = 0, one input) with the input law of its simulation,
    /// U_k = offset − feedback·X_k: the detector sees U_k, so the innovation does not
    /// depend on it, and the feedback keeps the state of an unstable plant bounded.
    struct Plant {
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
        feedback: DMatrix<f64>,
        offset: f64,
    }

    /// Zhang & Basseville 2014, §6.1: unstable (eigenvalue 1.2808), stabilised in the
    /// simulation by the state feedback K_fb = [0.5 1.2] (F − G K_fb has eigenvalues of
    /// modulus √0.5).
    fn paper() -> Plant {
        Plant {
            f: DMatrix::from_row_slice(2, 2, &[0.5, 1.0, 0.0, 1.2]),
            g: DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            h: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            q: DMatrix::identity(2, 2) * 0.0025,
            r: DMatrix::from_element(1, 1, 0.0025),
            feedback: DMatrix::from_row_slice(1, 2, &[0.5, 1.2]),
            offset: 0.0,
        }
    }

    /// The survey's DC motor (A, B, C = I₂, D = 0) with R = diag(0.0025, 0.0012),
    /// Q = 1e-4·I and a constant input 0.5.
    fn motor() -> Plant {
        Plant {
            f: DMatrix::from_row_slice(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
            g: DMatrix::from_row_slice(2, 1, &[0.0047, 0.4512]),
            h: DMatrix::identity(2, 2),
            q: DMatrix::identity(2, 2) * 1e-4,
            r: DMatrix::from_row_slice(2, 2, &[0.0025, 0.0, 0.0, 0.0012]),
            feedback: DMatrix::zeros(1, 2),
            offset: 0.5,
        }
    }

    /// S = E(W_kV_kᵀ) for the motor, with [Q S; Sᵀ R] a covariance.
    fn motor_cross() -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, &[2e-4, 0.0, 0.0, -1e-4])
    }

    fn model(pl: &Plant) -> Lpv {
        let p = pl.h.nrows();
        Lpv::lti(
            pl.f.clone(),
            pl.g.clone(),
            pl.h.clone(),
            DMatrix::zeros(p, 1),
            pl.q.clone(),
            pl.r.clone(),
        )
        .unwrap()
    }

    fn glr(model: Lpv, faults: Vec<Fault>) -> GlrDetector {
        let n = model.dims().states;
        let faults = FaultDictionary::new(model.dims(), faults).unwrap();
        GlrDetector::new(
            Box::new(model),
            faults,
            DVector::zeros(n),
            DMatrix::identity(n, n) * P0,
            WindowSettings {
                window: 20,
                min_lag: 0,
                ..Default::default()
            },
        )
        .unwrap()
    }

    fn detector(pl: &Plant, faults: Vec<Fault>, magnitudes: Vec<f64>) -> CusumDetector {
        CusumDetector::new(glr(model(pl), faults), magnitudes).unwrap()
    }

    fn step_fault(name: &str, state: bool, column: Column) -> Fault {
        if state {
            Fault::state(name, Onset::Step, column)
        } else {
            Fault::output(name, Onset::Step, column)
        }
    }

    fn constant(v: &[f64]) -> Column {
        Column::Constant(DVector::from_column_slice(v))
    }

    /// §6.1: a step in the first state equation and a sensor bias.
    fn paper_faults() -> Vec<Fault> {
        vec![
            step_fault("x1_step", true, constant(&[1.0, 0.0])),
            step_fault("sensor_bias", false, constant(&[1.0])),
        ]
    }

    /// The motor: an actuator bias (G's column, the survey's E_f = B) and a bias of the
    /// first sensor.
    fn motor_faults() -> Vec<Fault> {
        vec![
            step_fault("actuator_bias", true, Column::InputBias { input: 0 }),
            step_fault("current_sensor_bias", false, constant(&[1.0, 0.0])),
        ]
    }

    /// A step fault as the simulation injects it: Ψ̃θ into X_{k+1} and Φ̃θ into Y_k for
    /// k ≥ onset (Zhang & Basseville 2014, eqs. (4), (44)).
    struct Injected {
        psi: DVector<f64>,
        phi: DVector<f64>,
        theta: f64,
        onset: u64,
    }

    struct Sim<'a> {
        pl: &'a Plant,
        x: DVector<f64>,
        rng: Rng,
        noise: f64,
        chol_q: DMatrix<f64>,
        chol_r: DMatrix<f64>,
        fault: Option<Injected>,
    }

    impl<'a> Sim<'a> {
        /// `noise` scales W, V and X_0 ~ N(0, P0·I) (0: noise-free, X_0 = 0).
        fn new(pl: &'a Plant, seed: u64, noise: f64, fault: Option<Injected>) -> Self {
            let mut rng = Rng::new(seed);
            let n = pl.f.nrows();
            let x = rng.normals(n) * (P0.sqrt() * noise);
            Self {
                pl,
                x,
                rng,
                noise,
                chol_q: pl.q.clone().cholesky().unwrap().l(),
                chol_r: pl.r.clone().cholesky().unwrap().l(),
                fault,
            }
        }

        /// (U_k, Y_k), and X_{k+1}.
        fn next(&mut self, k: u64) -> ([f64; 1], Vec<f64>) {
            let (n, p) = (self.pl.f.nrows(), self.pl.h.nrows());
            let u = self.pl.offset - (&self.pl.feedback * &self.x)[0];
            let mut y = &self.pl.h * &self.x + &self.chol_r * self.rng.normals(p) * self.noise;
            let mut x = &self.pl.f * &self.x
                + &self.pl.g * u
                + &self.chol_q * self.rng.normals(n) * self.noise;
            if let Some(f) = self.fault.as_ref().filter(|f| k >= f.onset) {
                y += &f.phi * f.theta;
                x += &f.psi * f.theta;
            }
            self.x = x;
            ([u], y.as_slice().to_vec())
        }
    }

    fn step(det: &mut CusumDetector, sim: &mut Sim<'_>, k: u64, out: &mut StepOutput) {
        let (u, y) = sim.next(k);
        let sample = Sample {
            k,
            u: &u,
            y: &y,
            p: &[],
        };
        Detector::step(det, &sample, out).unwrap();
    }

    /// The magnitude of the motor's first-sensor bias whose steady information δ² is 1.
    fn unit_sensor_bias(pl: &Plant) -> f64 {
        let fault = || {
            vec![step_fault(
                "current_sensor_bias",
                false,
                constant(&[1.0, 0.0]),
            )]
        };
        let probe = detector(pl, fault(), vec![1.0]);
        1.0 / probe.information()[0].sqrt()
    }

    /// (a) Noise-free data with the step fault injected 350 samples before: the
    /// innovation the running filter measures is ρ_j, on both plants, for a state fault
    /// (a constant column; G's column) and a sensor bias, and on the motor with correlated
    /// noises too (S enters the gain, not the noise-free data). And δ_j² is ρ_jᵀΣ⁻¹ρ_j
    /// with the Σ the running filter has reached.
    #[test]
    fn the_steady_signature_is_the_innovation_long_after_the_onset() {
        // Each plant with its dictionary, the magnitudes, and the columns (Ψ̃_j, Φ̃_j) the
        // simulation injects, written out (G's column for the actuator bias).
        struct Case {
            plant: Plant,
            faults: fn() -> Vec<Fault>,
            magnitudes: [f64; 2],
            columns: [[Vec<f64>; 2]; 2],
            cross: Option<DMatrix<f64>>,
        }
        let motor_columns = || {
            [
                [vec![0.0047, 0.4512], vec![0.0, 0.0]],
                [vec![0.0, 0.0], vec![1.0, 0.0]],
            ]
        };
        let cases = [
            Case {
                plant: paper(),
                faults: paper_faults,
                magnitudes: [0.7, -0.4],
                columns: [[vec![1.0, 0.0], vec![0.0]], [vec![0.0, 0.0], vec![1.0]]],
                cross: None,
            },
            Case {
                plant: motor(),
                faults: motor_faults,
                magnitudes: [0.3, 0.05],
                columns: motor_columns(),
                cross: None,
            },
            Case {
                plant: motor(),
                faults: motor_faults,
                magnitudes: [0.3, 0.05],
                columns: motor_columns(),
                cross: Some(motor_cross()),
            },
        ];
        for Case {
            plant: pl,
            faults,
            magnitudes,
            columns,
            cross,
        } in &cases
        {
            for (j, [psi, phi]) in columns.iter().enumerate() {
                let mut inner = glr(model(pl), faults());
                if let Some(s) = cross {
                    inner = inner.with_cross_covariance(s.clone()).unwrap();
                }
                let mut det = CusumDetector::new(inner, magnitudes.to_vec()).unwrap();
                let mut out = StepOutput::for_detector(&det);
                let fault = Injected {
                    psi: DVector::from_column_slice(psi),
                    phi: DVector::from_column_slice(phi),
                    theta: magnitudes[j],
                    onset: 50,
                };
                let mut sim = Sim::new(pl, 1, 0.0, Some(fault));
                for k in 0..400 {
                    step(&mut det, &mut sim, k, &mut out);
                }
                let rho = det.signatures().column(j);
                let error = (&out.innovation - rho).amax();
                assert!(
                    error <= 1e-9,
                    "fault {j}: innovation {} vs ρ {} (error {error:e})",
                    out.innovation.transpose(),
                    rho.transpose()
                );
                // The settled mean is not the mean at the onset: the derivation matters.
                let at_onset = DVector::from_column_slice(phi) * magnitudes[j];
                assert!((&at_onset - rho).amax() > 1e-3 * rho.amax(), "fault {j}");
                let sigma = det.glr().filter().innovation_covariance();
                assert!((det.steady_innovation_covariance() - sigma).amax() <= 1e-12);
                let info = rho.dot(&(sigma.clone().try_inverse().unwrap() * rho));
                assert!((det.information()[j] - info).abs() <= 1e-9 * info);
            }
        }
        // The correlated noises change the gain K_p = FK + SΣ⁻¹, and with it ρ.
        let plain = detector(&motor(), motor_faults(), vec![0.3, 0.05]);
        let correlated = glr(model(&motor()), motor_faults())
            .with_cross_covariance(motor_cross())
            .unwrap();
        let correlated = CusumDetector::new(correlated, vec![0.3, 0.05]).unwrap();
        let change = (plain.signatures() - correlated.signatures()).amax();
        assert!(change > 1e-3 * plain.signatures().amax(), "{change:e}");
    }

    /// (b) On random data (noise, and a sensor bias from sample 300), Page's recursion
    /// equals the maximum over onsets r ≤ k of Σ_{i=r..k} s_i floored at 0, with s_i
    /// computed here from ε_k, the filter's Σ_k inverted densely and ρ_j; its onset is the
    /// maximising r, and the decision statistic is twice the largest g.
    #[test]
    fn page_recursion_is_the_maximum_over_onsets_of_the_summed_llr() {
        let pl = motor();
        let mut det = detector(&pl, motor_faults(), vec![0.3, 0.05]);
        let mut out = StepOutput::for_detector(&det);
        let fault = Injected {
            psi: DVector::zeros(2),
            phi: DVector::from_column_slice(&[1.0, 0.0]),
            theta: 0.05,
            onset: 300,
        };
        let mut sim = Sim::new(&pl, 7, 1.0, Some(fault));
        let len = 700;
        let (mut s, mut g, mut starts) = ([vec![], vec![]], [vec![], vec![]], [vec![], vec![]]);
        let mut positive = 0;
        for k in 0..len {
            step(&mut det, &mut sim, k, &mut out);
            let sigma_inv = (det.glr().filter().innovation_covariance().clone())
                .try_inverse()
                .unwrap();
            for j in 0..2 {
                let rho = det.signatures().column(j).into_owned();
                let llr =
                    rho.dot(&(&sigma_inv * &out.innovation)) - 0.5 * rho.dot(&(&sigma_inv * &rho));
                s[j].push(llr);
                g[j].push(det.statistics()[j]);
                starts[j].push(det.onsets()[j]);
            }
            let best = usize::from(g[1][k as usize] > g[0][k as usize]);
            assert_eq!(out.glr, Some(2.0 * g[best][k as usize]));
            assert_eq!(out.onset, Some(starts[best][k as usize].unwrap_or(k)));
        }
        for j in 0..2 {
            for k in 0..len as usize {
                let (mut sum, mut max, mut argmax) = (0.0, 0.0, None);
                for r in (0..=k).rev() {
                    sum += s[j][r];
                    if sum > max {
                        (max, argmax) = (sum, Some(r as u64));
                    }
                }
                let error = (g[j][k] - max).abs();
                assert!(
                    error <= 1e-12 * max.max(1.0),
                    "fault {j}, k = {k}: {} vs {max}",
                    g[j][k]
                );
                assert_eq!(starts[j][k], argmax, "fault {j}, k = {k}");
                positive += usize::from(max > 0.0);
            }
        }
        // Both faults' CUSUMs had runs (the sensor one from the bias on), and resets.
        assert!(positive > 400 && positive < 1300, "{positive}");
    }

    /// (c) No fault, the motor with a first-sensor bias of δ² = 1 as the design: the mean
    /// run length to g > h/2 (the statistic restarted from 0 after each alarm, the filter
    /// running on) against Siegmund's approximation for s_k ~ N(−δ²/2, δ²), i.e. a
    /// CUSUM of N(−δ/2, 1) increments with threshold h/(2δ):
    /// ARL₀ ≈ (e^b − b − 1)/(δ²/2), b = δ(h/(2δ) + 1.166). Beside it, the χ² law of
    /// εᵀΣ⁻¹ε (2 degrees of freedom) over the same 10⁶ samples. Measured: ARL₀ 321.6 over
    /// 3109 alarms against 338.1 (−4.9 %); mean εᵀΣ⁻¹ε 1.997, exceedance rate 0.0099.
    #[test]
    fn fault_free_run_lengths_match_siegmund_and_the_chi2_law_holds() {
        let pl = motor();
        let theta = unit_sensor_bias(&pl);
        let fault = vec![step_fault(
            "current_sensor_bias",
            false,
            constant(&[1.0, 0.0]),
        )];
        let mut det = detector(&pl, fault, vec![theta]);
        let delta2 = det.information()[0];
        assert!((delta2 - 1.0).abs() < 1e-12);
        let h = 8.0;
        let quantile = chi2_upper_quantile(2.0, 0.01).unwrap();
        let mut out = StepOutput::for_detector(&det);
        let mut sim = Sim::new(&pl, 11, 1.0, None);
        let len = 1_000_000;
        let (mut runs, mut since, mut chi2_sum, mut exceed) = (Vec::new(), 0_u64, 0.0, 0_u64);
        for k in 0..len {
            step(&mut det, &mut sim, k, &mut out);
            chi2_sum += out.normalized_innovation;
            exceed += u64::from(out.normalized_innovation > quantile);
            since += 1;
            if out.glr.unwrap() > h {
                runs.push(since);
                since = 0;
                det.sums.fill(0.0);
                det.starts.fill(None);
            }
        }
        let arl = runs.iter().sum::<u64>() as f64 / runs.len() as f64;
        let delta = delta2.sqrt();
        let b = delta * (h / (2.0 * delta) + 1.166);
        let siegmund = (b.exp() - b - 1.0) / (delta2 / 2.0);
        assert!(
            (arl / siegmund - 1.0).abs() <= 0.3,
            "ARL₀ {arl:.1} over {} alarms, Siegmund {siegmund:.1}",
            runs.len()
        );
        let mean = chi2_sum / len as f64;
        assert!((mean / 2.0 - 1.0).abs() <= 0.03, "mean εᵀΣ⁻¹ε {mean}");
        let rate = exceed as f64 / len as f64;
        assert!((rate / 0.01 - 1.0).abs() <= 0.3, "exceedance rate {rate}");
        eprintln!(
            "ARL₀ {arl:.1} ({} alarms), Siegmund {siegmund:.1}; χ² mean {mean:.4}, rate {rate:.5}",
            runs.len()
        );
    }

    /// (d) A first-sensor bias of the design magnitude (δ² = 1) from sample 200, 300
    /// seeded runs, threshold h = 20: the mean delay (samples from the onset to the
    /// alarm, both counted) against Wald's (h/2)/(δ²/2) = 20, and Page's onset estimate at
    /// the alarm against the true onset.
    /// Measured: mean delay 19.4 samples, no false alarm before the onset, onset error
    /// +0.11 on average and 2.7 in mean absolute value.
    #[test]
    fn a_sensor_bias_of_the_design_magnitude_is_detected_after_walds_delay() {
        let pl = motor();
        let theta = unit_sensor_bias(&pl);
        let fault = vec![step_fault(
            "current_sensor_bias",
            false,
            constant(&[1.0, 0.0]),
        )];
        let mut det = detector(&pl, fault, vec![theta]);
        let delta2 = det.information()[0];
        let (h, onset) = (20.0, 200);
        let mut out = StepOutput::for_detector(&det);
        let (mut delays, mut onset_errors, mut early) = (Vec::new(), Vec::new(), 0);
        for run in 0..300 {
            Detector::restart(&mut det).unwrap();
            let fault = Injected {
                psi: DVector::zeros(2),
                phi: DVector::from_column_slice(&[1.0, 0.0]),
                theta,
                onset,
            };
            let mut sim = Sim::new(&pl, 1000 + run, 1.0, Some(fault));
            for k in 0..onset + 300 {
                step(&mut det, &mut sim, k, &mut out);
                if out.glr.unwrap() > h {
                    if k < onset {
                        early += 1;
                    } else {
                        delays.push((k - onset + 1) as f64);
                        onset_errors.push(out.onset.unwrap() as f64 - onset as f64);
                    }
                    break;
                }
            }
        }
        assert!(early <= 3, "{early} false alarms before the onset");
        assert!(delays.len() + early == 300, "a run missed the fault");
        let mean_delay = delays.iter().sum::<f64>() / delays.len() as f64;
        let wald = (h / 2.0) / (delta2 / 2.0);
        assert!(
            (mean_delay / wald - 1.0).abs() <= 0.3,
            "mean delay {mean_delay:.2}, Wald {wald:.2}"
        );
        let mean_onset_error = onset_errors.iter().sum::<f64>() / onset_errors.len() as f64;
        let mean_abs =
            onset_errors.iter().map(|e| e.abs()).sum::<f64>() / onset_errors.len() as f64;
        assert!(mean_abs <= 4.0, "mean |r̂ − r| = {mean_abs:.2}");
        eprintln!(
            "mean delay {mean_delay:.2} (Wald {wald:.2}) over {} runs, {early} early; onset error mean {mean_onset_error:.2}, mean |·| {mean_abs:.2}",
            delays.len()
        );
    }

    /// (e) What has no settled signature is refused, named: a ramp, an impulse, a gain
    /// loss, an LPV model, a zero or non-finite magnitude, a magnitude count that is not
    /// the dictionary's, an unknown input, a fault that reaches no output, a sensor bias
    /// that an integrating plant's filter absorbs (ρ = 0), and a plant whose Riccati
    /// recursion does not settle (an unstable mode the outputs do not see).
    #[test]
    fn refuses_what_has_no_settled_signature_naming_it() {
        let pl = motor();
        let refuse = |model: Lpv, faults: Vec<Fault>, magnitudes: Vec<f64>| {
            CusumDetector::new(glr(model, faults), magnitudes)
                .unwrap_err()
                .to_string()
        };
        let sensor = || step_fault("current_sensor_bias", false, constant(&[1.0, 0.0]));
        let cases = [
            (
                vec![Fault::output("drift", Onset::Ramp, constant(&[1.0, 0.0]))],
                vec![1.0],
                "fault \"drift\" is a ramp",
            ),
            (
                vec![Fault::state("kick", Onset::Impulse, constant(&[1.0, 0.0]))],
                vec![1.0],
                "fault \"kick\" is an impulse",
            ),
            (
                vec![step_fault("gain", true, Column::GainLoss { input: 0 })],
                vec![0.1],
                "fault \"gain\" has a gain-loss column",
            ),
            (
                vec![
                    step_fault("actuator_bias", true, Column::InputBias { input: 0 }),
                    sensor(),
                ],
                vec![0.3, 0.0],
                "fault \"current_sensor_bias\" has the magnitude 0",
            ),
            (vec![sensor()], vec![f64::NAN], "has the magnitude NaN"),
            (vec![sensor()], vec![1.0, 2.0], "2 magnitudes for 1 faults"),
            (
                vec![step_fault("nothing", false, constant(&[0.0, 0.0]))],
                vec![1.0],
                "fault \"nothing\" does not reach the outputs",
            ),
        ];
        for (faults, magnitudes, expected) in cases {
            let e = refuse(model(&pl), faults, magnitudes);
            assert!(e.contains(expected), "{e}");
            assert!(e.contains("CUSUM"), "{e}");
        }
        let [f, g, h, j, q, r] = model(&pl).matrices().map(Clone::clone);
        let scheduled = LpvMatrix::new(f.base().clone(), vec![(0, DMatrix::identity(2, 2) * 0.01)]);
        let lpv = Lpv::new(scheduled.unwrap(), g, h, j, q, r, 1).unwrap();
        let e = refuse(lpv, vec![sensor()], vec![1.0]);
        assert!(e.starts_with("model: the CUSUM needs an LTI model"), "{e}");
        let with_e = glr(model(&pl), vec![sensor()])
            .with_unknown_input(LpvMatrix::constant(DMatrix::from_column_slice(
                2,
                1,
                &[1.0, 0.0],
            )))
            .unwrap();
        let e = CusumDetector::new(with_e, vec![1.0])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("E: the CUSUM"), "{e}");
        // x_{k+1} = x_k + w_k, y = x + v: the steady filter absorbs a constant sensor bias
        // (H(I − A)⁻¹K_p = 1).
        let one = |x| DMatrix::from_element(1, 1, x);
        let integrator = Lpv::lti(one(1.0), one(0.0), one(1.0), one(0.0), one(1e-4), one(1e-2));
        let bias = vec![step_fault("level_bias", false, constant(&[1.0]))];
        let e = refuse(integrator.unwrap(), bias, vec![1.0]);
        assert!(
            e.contains("fault \"level_bias\" has a vanishing steady signature"),
            "{e}"
        );
        // An unstable mode the output does not see: P grows without bound.
        let hidden = Lpv::lti(
            DMatrix::from_row_slice(2, 2, &[1.2, 0.0, 0.0, 0.5]),
            DMatrix::from_column_slice(2, 1, &[1.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
            one(0.0),
            DMatrix::identity(2, 2) * 0.01,
            one(0.01),
        );
        let bias = vec![step_fault("bias", false, constant(&[1.0]))];
        let e = refuse(hidden.unwrap(), bias, vec![1.0]);
        assert!(
            e.starts_with("Riccati equation: the Kalman filter's Riccati recursion"),
            "{e}"
        );
    }

    /// The Detector contract and the wrapped GLR: innovation, θ̂ and rank are the GLR's bit
    /// for bit; a refused sample or index changes nothing; a gap freezes g (no
    /// measurement, no increment); a restart forgets g and the index.
    #[test]
    fn the_contract_and_the_glr_beside_it() {
        let pl = motor();
        let mut det = detector(&pl, motor_faults(), vec![0.3, 0.05]);
        let mut reference = glr(model(&pl), motor_faults());
        let (mut out, mut expected) = (StepOutput::for_detector(&det), StepOutput::new(2, 2));
        let fault = Injected {
            psi: DVector::zeros(2),
            phi: DVector::from_column_slice(&[1.0, 0.0]),
            theta: 0.1,
            onset: 30,
        };
        let mut sim = Sim::new(&pl, 3, 1.0, Some(fault));
        for k in 0..60 {
            let (u, y) = sim.next(k);
            let sample = Sample {
                k,
                u: &u,
                y: &y,
                p: &[],
            };
            Detector::step(&mut det, &sample, &mut out).unwrap();
            reference.step(&sample, &mut expected).unwrap();
            assert_eq!(
                (
                    &out.innovation,
                    out.normalized_innovation,
                    &out.magnitude,
                    out.rank
                ),
                (
                    &expected.innovation,
                    expected.normalized_innovation,
                    &expected.magnitude,
                    expected.rank
                )
            );
            assert_eq!(
                out.glr,
                Some(2.0 * det.statistics()[0].max(det.statistics()[1]))
            );
        }
        assert!(det.statistics()[1] > 10.0, "{:?}", det.statistics());
        assert!(
            det.onsets()[1].is_some_and(|r| (25..=35).contains(&r)),
            "{:?}",
            det.onsets()
        );
        assert!(Detector::fisher_statistics(&det, 50).is_some());
        let (g, starts) = (det.statistics().to_vec(), det.onsets().to_vec());
        let late = Detector::step(
            &mut det,
            &Sample {
                k: 70,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
            &mut out,
        );
        assert!(matches!(
            late,
            Err(StepError::OutOfOrder {
                expected: 60,
                got: 70
            })
        ));
        let nan = Detector::step(
            &mut det,
            &Sample {
                k: 60,
                u: &[0.5],
                y: &[f64::NAN, 0.0],
                p: &[],
            },
            &mut out,
        );
        assert!(matches!(
            nan,
            Err(StepError::NonFinite {
                field: "y",
                index: 0
            })
        ));
        assert_eq!(
            (det.statistics(), det.onsets()),
            (g.as_slice(), starts.as_slice())
        );
        Detector::predict_only(&mut det, 60).unwrap();
        assert_eq!(
            (det.statistics(), det.onsets()),
            (g.as_slice(), starts.as_slice())
        );
        assert_eq!(det.next_index(), Some(61));
        Detector::restart(&mut det).unwrap();
        assert_eq!(
            (det.statistics(), det.next_index()),
            ([0.0, 0.0].as_slice(), None)
        );
        assert_eq!(det.onsets(), [None, None].as_slice());
        assert_eq!(
            (
                det.kind(),
                det.memory(),
                det.innovation_len(),
                det.residual_len()
            ),
            ("cusum", 20, 2, 0)
        );
        assert!(det.estimates_magnitude() && det.innovation_filter().is_some());
        assert_eq!(det.magnitudes(), [0.3, 0.05].as_slice());
    }
}

/// The threshold h on [`CusumDetector`]'s statistic 2·max_j g_j for a false-alarm
/// probability per sample `false_alarm`, from Siegmund's approximation of the mean run
/// length of a CUSUM with N(−δ²/2, δ²) increments under no fault,
/// ARL₀ ≈ (e^b − b − 1)/(δ²/2), b = h/2 + 1.166δ (Basseville & Nikiforov 1993, §5.2),
/// set to m/α for each of the m faults' CUSUMs (so that their union alarms at most α per
/// sample, Bonferroni), the largest over the faults. `information` holds δ_j² =
/// ρ_jᵀΣ⁻¹ρ_j ([`CusumDetector::information`]). `None` for an α outside (0, 1) or a
/// non-positive δ².
#[must_use]
pub fn siegmund_threshold(information: &[f64], false_alarm: f64) -> Option<f64> {
    if !(false_alarm > 0.0 && false_alarm < 1.0) || information.is_empty() {
        return None;
    }
    let m = information.len() as f64;
    let mut worst = f64::NEG_INFINITY;
    for &d2 in information {
        if !(d2.is_finite() && d2 > 0.0) {
            return None;
        }
        // Solve e^b − b − 1 = c for b > 0 by Newton from above (the left side is convex
        // and increasing there, so the iterates decrease monotonically to the root).
        let c = m * d2 / (2.0 * false_alarm);
        let mut b = (c + 1.0).ln() + 1.0;
        for _ in 0..100 {
            let f = b.exp() - b - 1.0 - c;
            let step = f / (b.exp() - 1.0);
            b -= step;
            if step.abs() <= 1e-14 * b.abs() {
                break;
            }
        }
        worst = worst.max(2.0 * (b - 1.166 * d2.sqrt()));
    }
    Some(worst.max(0.0))
}

#[cfg(test)]
mod siegmund_tests {
    use super::siegmund_threshold;

    /// The threshold inverts Siegmund's formula: at h the approximate ARL₀ of each
    /// fault's CUSUM is m/α (to 1e-9 relative), for one and for three faults; a
    /// smaller α gives a larger h.
    #[test]
    fn the_siegmund_threshold_inverts_the_run_length_approximation() {
        let arl = |h: f64, d2: f64| {
            let b = h / 2.0 + 1.166 * d2.sqrt();
            (b.exp() - b - 1.0) / (d2 / 2.0)
        };
        let h = siegmund_threshold(&[1.0], 1.0 / 338.1).unwrap();
        assert!((arl(h, 1.0) / 338.1 - 1.0).abs() < 1e-9, "h = {h}");
        assert!((h - 8.0).abs() < 0.01, "h = {h} (the ARL 338.1 of h = 8)");
        let info = [0.5, 2.0, 8.0];
        let h3 = siegmund_threshold(&info, 1e-4).unwrap();
        let arls: Vec<f64> = info.iter().map(|&d2| arl(h3, d2)).collect();
        assert!(arls.iter().all(|&a| a >= 3e4 * (1.0 - 1e-9)), "{arls:?}");
        assert!(
            arls.iter().any(|&a| (a / 3e4 - 1.0).abs() < 1e-9),
            "{arls:?}"
        );
        assert!(siegmund_threshold(&[1.0], 1e-6).unwrap() > h);
        assert_eq!(siegmund_threshold(&[1.0], 1.5), None);
        assert_eq!(siegmund_threshold(&[0.0], 0.01), None);
    }
}
