//! The kernel-based deadbeat fault detection and isolation of Li, Boem, Pin &
//! Parisini (fast-convergent FDI): a continuous-time LTI plant
//! ẋ = Ax + Bu + Ef(t, x, u) + d_x, y = Cx + d_y with bounded noise ‖d_x‖ ≤ d̄_x,
//! ‖d_y‖ ≤ d̄_y; a state estimate exact after a finite time and insensitive to the
//! fault ([`estimator`]); the fault's image through a bilateral kernel against a
//! threshold that no noise within the bounds can cross (guaranteed: no false alarm);
//! isolation among candidate fault functions φᵢ(t, x, u) by exclusion.
//!
//! Sampled data: every image is integrated exactly over a sample period under a
//! first-order hold on the signals ([`volterra`]), so the only departure from the
//! paper's continuous-time claims is the hold's error, O(Δ²) for smooth signals.
//!
//! The files: `decomposition.rs` (the offline design (3), (5) and the assumptions),
//! `volterra.rs` (the sampled images (9), (18)), `estimator.rs` (§III-A),
//! `residual.rs` (§III-B, §IV).

pub mod decomposition;
pub mod estimator;
pub mod residual;
pub mod volterra;

use nalgebra::DMatrix;

use crate::error::{ModelError, StepError};
use crate::model::Dims;
use crate::model::fault::{Column, Fault, FaultDictionary, Onset};

use super::{Detector, ResidualIsolation, Sample, StepOutput, check_sample};
use decomposition::Decomposition;
use estimator::DeadbeatEstimator;
use residual::{FaultImage, FaultImageBounds};
use volterra::MAX_RATE_STEP;

/// A candidate fault function φᵢ(t, x, u) ∈ ℝ^{p⋆} of the isolation (§IV).
///
/// Must be deterministic and allocation-free: it runs on every sample of an episode.
pub trait CandidateFn: Send + std::fmt::Debug {
    /// Writes φ(t, x, u) into `out` (length p⋆), every entry.
    fn evaluate(&mut self, t: f64, x: &[f64], u: &[f64], out: &mut [f64]);
}

/// A named candidate fault function with its Lipschitz constant Lᵢ in x (‖φᵢ(t, x, u)
/// − φᵢ(t, x', u)‖ ≤ Lᵢ‖x − x'‖), which scales its isolation threshold (37).
#[derive(Debug)]
pub struct Candidate {
    /// Unique name, used as the fault name in isolation results.
    pub name: String,
    /// Lᵢ ≥ 0.
    pub lipschitz: f64,
    /// φᵢ.
    pub function: Box<dyn CandidateFn>,
}

/// The continuous-time model ẋ = Ax + Bu + Ef, y = Cx.
#[derive(Debug, Clone)]
pub struct KernelModel {
    /// A (n × n).
    pub a: DMatrix<f64>,
    /// B (n × l).
    pub b: DMatrix<f64>,
    /// C (p × n).
    pub c: DMatrix<f64>,
    /// E (n × p⋆): the fault channels.
    pub e: DMatrix<f64>,
}

/// The method's settings, with the paper's letters.
#[derive(Debug, Clone, PartialEq)]
pub struct KernelSettings {
    /// Δ, the sample period in seconds (the model is continuous).
    pub period: f64,
    /// ω_h, h = 1…n⋆: the estimator kernels' rates (6), distinct and positive.
    pub estimator_rates: Vec<f64>,
    /// ω̄ > 0 of the kernels (6).
    pub omega_bar: f64,
    /// N ≥ n⋆: the kernels' order (6).
    pub kernel_order: usize,
    /// ω > 0 of the detection kernel (13).
    pub detection_rate: f64,
    /// θ_a > 0: the estimate is used once |det Γ| ≥ θ_a (Remark 4.1).
    pub activation: f64,
    /// d̄_x ≥ 0: the bound on the state noise's Euclidean norm.
    pub state_noise: f64,
    /// d̄_y ≥ 0: the bound on the output noise's Euclidean norm.
    pub output_noise: f64,
    /// An absolute floor added to the thresholds, for the sampling error the
    /// continuous-time bounds do not cover (and noise-free models, where the bounds
    /// are 0).
    pub floor: f64,
    /// Seconds the statistic must stay at or below 1 before a new detection may
    /// start a new isolation episode (when no monitor holds the episode through
    /// [`Detector::follow`]: under a monitor, it ends with the alarm episode).
    pub rearm: f64,
}

impl KernelSettings {
    /// The paper's example settings (Section V) at period Δ: ω_h = 1, 2, ω̄ = 2.5,
    /// N = 2, ω = 1, θ_a = 0.7, rearm 5 s, no noise and floor 0 (set them).
    #[must_use]
    pub fn paper_example(period: f64) -> Self {
        Self {
            period,
            estimator_rates: vec![1.0, 2.0],
            omega_bar: 2.5,
            kernel_order: 2,
            detection_rate: 1.0,
            activation: 0.7,
            state_noise: 0.0,
            output_noise: 0.0,
            floor: 0.0,
            rearm: 5.0,
        }
    }
}

/// Where an isolation episode stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelVerdict {
    /// k of the detection that started the episode (T_D), if one is open.
    pub detected_at: Option<u64>,
    /// Per candidate, the sample at which it was excluded (r_FI,i > σ_FI,i).
    pub excluded_at: Vec<Option<u64>>,
}

impl KernelVerdict {
    /// The isolated candidate: the only one not excluded (Prop. 4.2), once all
    /// others are.
    #[must_use]
    pub fn isolated(&self) -> Option<usize> {
        if self.detected_at.is_none() || self.excluded_at.len() < 2 {
            return None;
        }
        let mut left = self
            .excluded_at
            .iter()
            .enumerate()
            .filter(|(_, e)| e.is_none());
        match (left.next(), left.next()) {
            (Some((i, _)), None) => Some(i),
            _ => None,
        }
    }

    /// True when every candidate is excluded: the fault is none of them.
    #[must_use]
    pub fn unknown(&self) -> bool {
        self.detected_at.is_some()
            && !self.excluded_at.is_empty()
            && self.excluded_at.iter().all(Option::is_some)
    }
}

/// The kernel deadbeat detector behind the [`Detector`] interface.
///
/// Its decision statistic ([`StepOutput::glr`]) is r_FD/(σ_FD + floor), to be
/// compared with 1; `None` until the estimator is active. Its residual
/// ([`StepOutput::residual`]) is [r_FD, σ_FD, r_FI,1, σ_FI,1, …, x̂₀ … x̂_{n−1}] (the
/// isolation pairs 0 outside an episode). It cannot bridge a missing sample (the
/// images need every sample of the hold): a gap restarts it.
#[derive(Debug)]
pub struct KernelDetector {
    dims: Dims,
    settings: KernelSettings,
    design: Decomposition,
    faults: FaultDictionary,
    candidates: Vec<Candidate>,
    estimator: DeadbeatEstimator,
    detection: FaultImage,
    isolation: FaultImage,
    bounds: FaultImageBounds,
    eps_x_factors: (f64, f64),
    state: Vec<f64>,
    candidate_values: Vec<f64>,
    verdict: KernelVerdict,
    quiet: u64,
    rearm_samples: u64,
    /// The isolation episode is held open by the monitor's alarm episode.
    followed: bool,
    revision: u64,
    isolation_tests: Vec<(f64, f64)>,
    next: Option<u64>,
    active_from: Option<u64>,
}

fn spectral_norm(m: &DMatrix<f64>) -> f64 {
    m.singular_values().iter().copied().fold(0.0, f64::max)
}

impl KernelDetector {
    /// Designs the detector for `model` (with `signals` exogenous signals per
    /// sample, carried and unused) and checks every setting.
    ///
    /// # Errors
    /// [`ModelError`] naming the matrix, setting or assumption that fails.
    pub fn new(
        model: &KernelModel,
        signals: usize,
        settings: KernelSettings,
        candidates: Vec<Candidate>,
    ) -> Result<Self, ModelError> {
        let design = Decomposition::new(&model.a, &model.b, &model.c, &model.e)?;
        let set = |what: &'static str, detail: String| ModelError::Setting { what, detail };
        let dt = settings.period;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(set(
                "period",
                format!("must be positive and finite, got {dt}"),
            ));
        }
        let order = design.order;
        if settings.estimator_rates.len() != order {
            return Err(set(
                "rates",
                format!(
                    "needs n⋆ = {order} kernel rates ω_h (one per state of the fault-free \
                     part), got {}",
                    settings.estimator_rates.len()
                ),
            ));
        }
        for (i, &w) in settings.estimator_rates.iter().enumerate() {
            if !(w.is_finite() && w > 0.0) {
                return Err(set(
                    "rates",
                    format!("ω_{} = {w} must be positive and finite", i + 1),
                ));
            }
            if settings.estimator_rates[..i].contains(&w) {
                return Err(set(
                    "rates",
                    format!("ω_h = {w} appears twice: Γ would be singular"),
                ));
            }
        }
        for (what, v) in [
            ("omega_bar", settings.omega_bar),
            ("detection_rate", settings.detection_rate),
            ("activation", settings.activation),
            ("rearm", settings.rearm),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(set(what, format!("must be positive and finite, got {v}")));
            }
        }
        for (what, v) in [
            ("state_noise", settings.state_noise),
            ("output_noise", settings.output_noise),
            ("floor", settings.floor),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(set(
                    what,
                    format!("must be non-negative and finite, got {v}"),
                ));
            }
        }
        if settings.state_noise == 0.0 && settings.output_noise == 0.0 && settings.floor == 0.0 {
            return Err(set(
                "floor",
                "with zero noise bounds the threshold is 0 and the sampling error alone would \
                 alarm: set state_noise, output_noise or a positive floor"
                    .into(),
            ));
        }
        if settings.kernel_order < order {
            return Err(set(
                "order",
                format!(
                    "N = {} must be at least n⋆ = {order}: the boundary terms of the kernel \
                     at τ = 0 vanish only for derivatives below N",
                    settings.kernel_order
                ),
            ));
        }
        let fastest = settings
            .estimator_rates
            .iter()
            .copied()
            .fold(2.0 * settings.detection_rate, f64::max);
        if fastest * dt > MAX_RATE_STEP {
            return Err(set(
                "period",
                format!(
                    "Δ = {dt} s is too long for the fastest kernel rate {fastest} s⁻¹ \
                     (rate·Δ above {MAX_RATE_STEP})"
                ),
            ));
        }
        // |det Γ(t)| tends to |det V|, V[h][j] = (−1)^{n⋆−j} ω_h^{n⋆−j}.
        let limit = DMatrix::from_fn(order, order, |h, j| {
            let e = order - 1 - j;
            let s = if e % 2 == 0 { 1.0 } else { -1.0 };
            s * settings.estimator_rates[h].powi(e as i32)
        })
        .determinant()
        .abs();
        if settings.activation >= limit {
            return Err(set(
                "activation",
                format!(
                    "θ_a = {} is not below the limit |det Γ(∞)| = {limit:.6} of these rates: \
                     the estimator would never start",
                    settings.activation
                ),
            ));
        }
        for (i, c) in candidates.iter().enumerate() {
            if !(c.lipschitz.is_finite() && c.lipschitz >= 0.0) {
                return Err(set(
                    "lipschitz",
                    format!(
                        "candidate \"{}\": must be non-negative and finite, got {}",
                        c.name, c.lipschitz
                    ),
                ));
            }
            if candidates[..i].iter().any(|o| o.name == c.name) {
                return Err(set(
                    "candidates",
                    format!("duplicate candidate name \"{}\"", c.name),
                ));
            }
        }
        let n = model.a.nrows();
        let dims = Dims {
            states: n,
            inputs: model.b.ncols(),
            outputs: model.c.nrows(),
            signals,
        };
        let names: Vec<Fault> = if candidates.is_empty() {
            vec![Fault::state("f", Onset::Step, Column::Zero)]
        } else {
            candidates
                .iter()
                .map(|c| Fault::state(&c.name, Onset::Step, Column::Zero))
                .collect()
        };
        let faults = FaultDictionary::new(dims, names)?;
        let p = design.faults;
        let t_inv_1 = design.t_inv.rows(0, p).into_owned();
        let t_inv_2 = design.t_inv.rows(p, order).into_owned();
        let eps_zeta1 = spectral_norm(&design.s1) * settings.output_noise;
        let eps_eta = spectral_norm(&design.s2) * settings.output_noise;
        let dx1 = spectral_norm(&t_inv_1) * settings.state_noise;
        let dx2 = spectral_norm(&t_inv_2) * settings.state_noise;
        let bounds = FaultImageBounds {
            e1_inv: spectral_norm(&design.e1_inv),
            e1_inv_a11: spectral_norm(&(&design.e1_inv * &design.a11)),
            e1_inv_a12: spectral_norm(&(&design.e1_inv * &design.a12)),
            eps_zeta1,
            dx1,
        };
        let eps_x_factors = (
            spectral_norm(&design.t.columns(0, p).into_owned()),
            spectral_norm(&design.t.columns(p, order).into_owned()),
        );
        let estimator = DeadbeatEstimator::new(
            &design,
            dims.inputs,
            &settings.estimator_rates,
            settings.omega_bar,
            settings.kernel_order,
            settings.activation,
            dt,
            [eps_zeta1, eps_eta, dx2],
        );
        let omega = settings.detection_rate;
        let detection = FaultImage::new(omega, dt, p, order, dims.inputs, 0);
        let isolation = FaultImage::new(omega, dt, p, order, dims.inputs, candidates.len());
        let rearm_samples = ((settings.rearm / dt).ceil() as u64).max(1);
        let candidate_count = candidates.len();
        Ok(Self {
            dims,
            design,
            faults,
            estimator,
            detection,
            isolation,
            bounds,
            eps_x_factors,
            state: vec![0.0; n],
            candidate_values: vec![0.0; candidates.len() * p],
            verdict: KernelVerdict {
                detected_at: None,
                excluded_at: vec![None; candidates.len()],
            },
            candidates,
            quiet: 0,
            rearm_samples,
            followed: false,
            revision: 0,
            isolation_tests: vec![(0.0, 0.0); candidate_count],
            next: None,
            active_from: None,
            settings,
        })
    }

    /// The offline design: T, S, the blocks of (3) and the canonical form (5).
    #[must_use]
    pub fn design(&self) -> &Decomposition {
        &self.design
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> &KernelSettings {
        &self.settings
    }

    /// The candidates.
    #[must_use]
    pub fn candidates(&self) -> &[Candidate] {
        &self.candidates
    }

    /// x̂ (11) at the last sample (zeros before activation).
    #[must_use]
    pub fn state_estimate(&self) -> &[f64] {
        &self.state
    }

    /// The sample at which the estimator became active (|det Γ| ≥ θ_a).
    #[must_use]
    pub fn active_from(&self) -> Option<u64> {
        self.active_from
    }

    /// The current isolation episode.
    #[must_use]
    pub fn verdict(&self) -> &KernelVerdict {
        &self.verdict
    }

    /// The deadbeat estimator.
    #[must_use]
    pub fn estimator(&self) -> &DeadbeatEstimator {
        &self.estimator
    }
}

impl KernelDetector {
    /// Opens an isolation episode detected at k: the isolation filters restart at the
    /// next sample integrated (the paper's reset at T_D, (20)).
    fn open_episode(&mut self, k: u64) {
        self.verdict.detected_at = Some(k);
        self.verdict.excluded_at.fill(None);
        self.isolation_tests.fill((0.0, 0.0));
        self.isolation.reset();
        self.quiet = 0;
        self.revision += 1;
    }

    fn close_episode(&mut self) {
        self.verdict.detected_at = None;
        self.verdict.excluded_at.fill(None);
        self.isolation_tests.fill((0.0, 0.0));
        self.quiet = 0;
        self.followed = false;
        self.revision += 1;
    }
}

impl Detector for KernelDetector {
    fn kind(&self) -> &'static str {
        "kernel"
    }

    fn describe(&self) -> String {
        let s = &self.settings;
        format!(
            "kernel deadbeat FDI (Li, Boem, Pin & Parisini): ω_h = {:?}, ω̄ = {}, N = {}, \
             ω = {}, θ_a = {}, d̄_x = {}, d̄_y = {}, {} candidates",
            s.estimator_rates,
            s.omega_bar,
            s.kernel_order,
            s.detection_rate,
            s.activation,
            s.state_noise,
            s.output_noise,
            self.candidates.len()
        )
    }

    fn memory(&self) -> usize {
        // The detection kernel forgets like e^{−ω(t−τ)}: 5/ω seconds.
        ((5.0 / self.settings.detection_rate / self.settings.period).ceil() as usize).max(1)
    }

    fn dims(&self) -> Dims {
        self.dims
    }

    fn faults(&self) -> &FaultDictionary {
        &self.faults
    }

    fn next_index(&self) -> Option<u64> {
        self.next
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        check_sample(self.dims, self.next, sample)?;
        let k = sample.k;
        out.k = k;
        out.magnitude.fill(0.0);
        out.residual.fill(0.0);
        out.rank = self.design.faults;
        let active = self.estimator.push(&self.design, sample.y, sample.u);
        self.next = Some(k + 1);
        if !active {
            out.glr = None;
            out.onset = None;
            out.normalized_innovation = 0.0;
            return Ok(());
        }
        if self.active_from.is_none() {
            self.active_from = Some(k);
        }
        self.estimator.state(&self.design, &mut self.state);
        let eps_zeta2 = self.estimator.eps_zeta2();
        let eps_x =
            self.eps_x_factors.0 * self.estimator.eps_zeta1() + self.eps_x_factors.1 * eps_zeta2;
        self.detection.push(
            &self.design,
            self.estimator.zeta1(),
            self.estimator.zeta2(),
            sample.u,
            &[],
            eps_zeta2,
            eps_x,
        );
        let floor = self.settings.floor;
        let r_fd = self.detection.residual();
        let sigma_fd = self.detection.threshold(&self.bounds);
        // At the bank's origin every image is 0: r_FD = σ_FD = 0, no evidence.
        let statistic = if r_fd == 0.0 {
            0.0
        } else {
            r_fd / (sigma_fd + floor)
        };
        if !statistic.is_finite() {
            return Err(StepError::Numerical {
                what: "the kernel detection statistic r_FD/σ_FD is not finite",
            });
        }
        out.glr = Some(statistic);
        out.onset = Some(k);
        out.normalized_innovation = statistic * statistic;
        out.residual[0] = r_fd;
        out.residual[1] = sigma_fd;

        // Episodes: a detection resets the isolation filters (20); the episode ends
        // after `rearm` seconds at or below the threshold, or, when the monitor holds
        // it (`follow`), at the end of the monitor's alarm episode.
        if statistic > 1.0 {
            self.quiet = 0;
            if self.verdict.detected_at.is_none() {
                self.open_episode(k);
            }
        } else if self.verdict.detected_at.is_some() && !self.followed {
            self.quiet += 1;
            if self.quiet >= self.rearm_samples {
                self.close_episode();
            }
        }
        let m = self.candidates.len();
        if self.verdict.detected_at.is_some() && m > 0 {
            let p = self.design.faults;
            let t = k as f64 * self.settings.period;
            for (i, c) in self.candidates.iter_mut().enumerate() {
                c.function.evaluate(
                    t,
                    &self.state,
                    sample.u,
                    &mut self.candidate_values[i * p..(i + 1) * p],
                );
            }
            // A candidate that is not finite at the estimated state (a logarithm of a
            // negative value, an overflow) cannot be the acting fault: it is excluded,
            // and its image integrates zeros so that the others go on.
            for i in 0..m {
                let values = &mut self.candidate_values[i * p..(i + 1) * p];
                if values.iter().any(|v| !v.is_finite()) {
                    values.fill(0.0);
                    if self.verdict.excluded_at[i].is_none() {
                        self.verdict.excluded_at[i] = Some(k);
                        self.revision += 1;
                    }
                }
            }
            self.isolation.push(
                &self.design,
                self.estimator.zeta1(),
                self.estimator.zeta2(),
                sample.u,
                &self.candidate_values,
                eps_zeta2,
                eps_x,
            );
            let sigma = self.isolation.threshold(&self.bounds);
            let state_image = self.isolation.state_error_image();
            for i in 0..m {
                let r = self.isolation.isolation_residual(i);
                let s = self.candidates[i].lipschitz * state_image + sigma;
                out.residual[2 + 2 * i] = r;
                out.residual[3 + 2 * i] = s;
                self.isolation_tests[i] = (r, s);
                if self.verdict.excluded_at[i].is_none() && r > s + floor {
                    self.verdict.excluded_at[i] = Some(k);
                    self.revision += 1;
                }
            }
        }
        out.residual.as_mut_slice()[2 + 2 * m..].copy_from_slice(&self.state);
        Ok(())
    }

    /// The monitor's alarm episode drives the isolation episode: an alarm (at any
    /// threshold, e.g. a calibrated one below 1) opens one if none is open, and the
    /// alarm's end closes it. Returns false: the kind follows no onset's evidence,
    /// and the monitor ends its episodes on the statistic.
    fn follow(&mut self, onset: Option<u64>) -> bool {
        match onset {
            Some(_) => {
                if self.verdict.detected_at.is_none()
                    && let Some(k) = self.next.and_then(|n| n.checked_sub(1))
                {
                    self.open_episode(k);
                }
                self.followed = self.verdict.detected_at.is_some();
            }
            None => {
                if self.followed {
                    self.close_episode();
                }
            }
        }
        false
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        Err(StepError::GapNotBridged {
            k,
            reason: "the kernel images integrate every sample",
        })
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        self.estimator.reset();
        self.detection.reset();
        self.isolation.reset();
        self.close_episode();
        self.next = None;
        self.active_from = None;
        self.state.fill(0.0);
        Ok(())
    }

    fn innovation_len(&self) -> usize {
        0
    }

    fn residual_len(&self) -> usize {
        2 + 2 * self.candidates.len() + self.dims.states
    }

    fn residual_isolation(&self) -> Option<Vec<ResidualIsolation>> {
        self.verdict.detected_at?;
        if self.candidates.is_empty() {
            return None;
        }
        let isolated = self.verdict.isolated();
        Some(
            self.isolation_tests
                .iter()
                .zip(&self.verdict.excluded_at)
                .enumerate()
                .map(
                    |(i, (&(statistic, threshold), excluded))| ResidualIsolation {
                        statistic,
                        threshold,
                        excluded: excluded.is_some(),
                        isolated: isolated == Some(i),
                    },
                )
                .collect(),
        )
    }

    fn isolation_revision(&self) -> u64 {
        self.revision
    }

    fn estimates_magnitude(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests;
