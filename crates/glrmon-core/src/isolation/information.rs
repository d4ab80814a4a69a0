//! The Fisher information of a fault dictionary over one GLR window, measured on a run
//! of the detector: the input F of the [isolability report](crate::isolation::isolability).
//!
//! For onset r and current sample k, Zhang & Basseville 2014, eq. (32):
//!
//! ```text
//! C_k(r) = Σ_{j=r}^{k} S_j(r)ᵀ Σ_j⁻¹ S_j(r)
//! ```
//!
//! with S_j(r) the fault signature (eq. (45)) and Σ_j the innovation covariance. It is
//! the Fisher information of θ carried by the innovations of the window, the matrix
//! Basseville (1996, §5-§6, eq. (84)) calls **F**. C depends on the model, the inputs,
//! the signals p(k) and the filter's P_k, not on the outputs, so noise-free or simulated
//! data give the information the detector will have on the real plant, provided P_k has
//! converged as it will have in operation: [`window_information`] therefore warms the
//! filter up before the window it reads.

use nalgebra::{DMatrix, DVector};

use crate::detector::{GlrDetector, Sample, StepOutput};
use crate::error::StepError;
use crate::model::fault::Onset;

/// Samples the detector runs before the window read by [`window_information`], for a
/// window of w samples: max(5w, 500), enough for the Riccati recursion of a detectable
/// model to settle. Known-profile faults need none: their information is summed from the
/// first sample.
#[must_use]
pub fn warmup_samples(window: usize, known_profiles: bool) -> u64 {
    if known_profiles {
        0
    } else {
        (5 * window as u64).max(500)
    }
}

/// The information of one window, computed by [`window_information`].
#[derive(Debug, Clone, PartialEq)]
pub struct WindowInformation {
    /// F = C_k(r) (m×m, eq. (32)) at the last sample k, for the oldest onset r of the
    /// window (for known-profile faults, r = 0: all samples).
    pub information: DMatrix<f64>,
    /// Σ_k, the innovation covariance at the last sample.
    pub covariance: DMatrix<f64>,
    /// Whether Σ stopped changing over the last step (max |Σ_k − Σ_{k−1}| ≤
    /// 10⁻¹²·max |Σ_k|): for an LTI model, whether `covariance` is its steady-state Σ.
    pub converged: bool,
    /// k − r + 1: the number of samples the information was summed over.
    pub samples: usize,
}

/// Why the information of a window could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum InformationError {
    /// The detector refused a sample.
    #[error(transparent)]
    Step(#[from] StepError),
    /// The detector no longer holds the window's oldest onset (its window setting is
    /// shorter than the one read).
    #[error("onset {onset} is not in the detector's window")]
    OnsetOutOfWindow {
        /// The onset asked for.
        onset: u64,
    },
    /// The samples ended before the warm-up and the window were complete.
    #[error("the information needs {needed} samples, only {given} were given")]
    TooFewSamples {
        /// Warm-up plus window.
        needed: u64,
        /// Samples given.
        given: u64,
    },
}

/// Runs `detector` (fresh: its first sample is numbered 0) on `samples`, given as
/// (U_k, Y_k, p(k)), for [`warmup_samples`] plus one window, and returns the Fisher
/// information C_k(r) of eq. (32) for the oldest onset of the window, with the innovation
/// covariance at the last sample. The outputs Y_k do not change the information; any
/// data with the plant's inputs and signals do.
///
/// Only as many samples are taken as needed: warm-up plus w for onset-searching faults,
/// w for known-profile faults (the window setting w of the detector).
///
/// # Errors
/// [`InformationError::Step`] when the detector refuses a sample (wrong lengths,
/// non-finite values, a detector that has already run, …),
/// [`InformationError::TooFewSamples`] when `samples` ends early,
/// [`InformationError::OnsetOutOfWindow`] should the detector not hold the onset read.
pub fn window_information<I>(
    detector: &mut GlrDetector,
    samples: I,
) -> Result<WindowInformation, InformationError>
where
    I: IntoIterator<Item = (Vec<f64>, Vec<f64>, Vec<f64>)>,
{
    let known = detector
        .faults()
        .faults()
        .iter()
        .all(|f| f.onset == Onset::Known);
    let w = detector.settings().window as u64;
    let needed = warmup_samples(detector.settings().window, known) + w;
    let mut out = StepOutput::new(detector.dims().outputs, detector.fault_count());
    let mut previous: Option<DMatrix<f64>> = None;
    let mut converged = false;
    let mut given = 0;
    for (u, y, p) in samples.into_iter().take(needed as usize) {
        detector.step(
            &Sample {
                k: given,
                u: &u,
                y: &y,
                p: &p,
            },
            &mut out,
        )?;
        let sigma = detector.filter().innovation_covariance();
        if let Some(prev) = &previous {
            converged = (sigma - prev).amax() <= 1e-12 * sigma.amax();
        }
        previous = Some(sigma.clone());
        given += 1;
    }
    if given < needed {
        return Err(InformationError::TooFewSamples { needed, given });
    }
    let onset = if known { 0 } else { needed - w };
    let m = detector.fault_count();
    let (mut information, mut score) = (DMatrix::zeros(m, m), DVector::zeros(m));
    if !detector.information(onset, &mut information, &mut score) {
        return Err(InformationError::OnsetOutOfWindow { onset });
    }
    Ok(WindowInformation {
        information,
        covariance: detector.filter().innovation_covariance().clone(),
        converged,
        samples: (needed - onset) as usize,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detector::WindowSettings;
    use crate::model::fault::{Column, Fault, FaultDictionary};
    use crate::model::{Lpv, StateSpace};

    const A: f64 = 0.9;
    const Q: f64 = 0.1;
    const R: f64 = 0.5;
    const P0: f64 = 1.0;

    /// x_{k+1} = 0.9 x_k + w_k, y_k = x_k + v_k, with a step on the state ("drift") and
    /// a step on the sensor ("bias").
    fn detector(window: usize, onset: Onset) -> GlrDetector {
        let scalar = |v| DMatrix::from_element(1, 1, v);
        let model = Lpv::lti(
            scalar(A),
            DMatrix::zeros(1, 0),
            scalar(1.0),
            DMatrix::zeros(1, 0),
            scalar(Q),
            scalar(R),
        )
        .unwrap();
        let one = || Column::Constant(DVector::from_vec(vec![1.0]));
        let faults = FaultDictionary::new(
            model.dims(),
            vec![
                Fault::state("drift", onset, one()),
                Fault::output("bias", onset, one()),
            ],
        )
        .unwrap();
        GlrDetector::new(
            Box::new(model),
            faults,
            DVector::zeros(1),
            scalar(P0),
            WindowSettings {
                window,
                min_lag: 1,
                ..Default::default()
            },
        )
        .unwrap()
    }

    fn zeros() -> impl Iterator<Item = (Vec<f64>, Vec<f64>, Vec<f64>)> {
        std::iter::repeat_with(|| (vec![], vec![0.0], vec![]))
    }

    /// Eq. (32) summed by hand for step faults of onset r over samples r…k: the scalar
    /// Riccati recursion for P_j and Σ_j = P_j + R, the signature recursion (eq. (46))
    /// Γ_{j+1} = A(1 − K_j)Γ_j − A K_j Φ̃ + Ψ̃ with Γ_r = 0, K_j = P_j / Σ_j, and
    /// S_j = (Γ_j^drift, Γ_j^bias + 1).
    fn direct(r: u64, k: u64) -> DMatrix<f64> {
        let mut p = P0;
        let (mut g_drift, mut g_bias) = (0.0, 0.0);
        let mut c = DMatrix::zeros(2, 2);
        for j in 0..=k {
            let sigma = p + R;
            let gain = p / sigma;
            if j >= r {
                let s = DMatrix::from_row_slice(1, 2, &[g_drift, g_bias + 1.0]);
                c += s.transpose() * &s / sigma;
                g_drift = A * (1.0 - gain) * g_drift + 1.0;
                g_bias = A * (1.0 - gain) * g_bias - A * gain;
            }
            p = A * A * (1.0 - gain) * p + Q;
        }
        c
    }

    fn assert_close(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) {
        let err = (a - b).amax();
        assert!(err <= tol * b.amax(), "{a} vs {b}: error {err:e}");
    }

    #[test]
    fn information_equals_eq_32_summed_by_hand() {
        let w = 12;
        let mut det = detector(w, Onset::Step);
        let info = window_information(&mut det, zeros()).unwrap();
        let needed = warmup_samples(w, false) + w as u64;
        assert_eq!(info.samples, w);
        assert_close(
            &info.information,
            &direct(needed - w as u64, needed - 1),
            1e-12,
        );
        assert!(info.converged);
        // Steady state: Σ = P + R with P the fixed point of the Riccati recursion.
        let mut p = P0;
        for _ in 0..needed {
            p = A * A * R * p / (p + R) + Q;
        }
        assert!((info.covariance[(0, 0)] - (p + R)).abs() <= 1e-12);
    }

    #[test]
    fn known_profiles_sum_over_every_sample_from_the_first() {
        let w = 30;
        let mut det = detector(w, Onset::Known);
        let info = window_information(&mut det, zeros()).unwrap();
        assert_eq!(info.samples, w);
        assert_close(&info.information, &direct(0, w as u64 - 1), 1e-12);
    }

    #[test]
    fn the_outputs_do_not_change_the_information() {
        let mut a = detector(8, Onset::Step);
        let mut b = detector(8, Onset::Step);
        let mut k = 0.0_f64;
        let wiggly = std::iter::repeat_with(move || {
            k += 1.0;
            (vec![], vec![(0.7 * k).sin()], vec![])
        });
        let ia = window_information(&mut a, zeros()).unwrap();
        let ib = window_information(&mut b, wiggly).unwrap();
        assert_close(&ia.information, &ib.information, 1e-12);
    }

    #[test]
    fn too_few_samples_is_an_error() {
        let mut det = detector(10, Onset::Step);
        let err = window_information(&mut det, zeros().take(100)).unwrap_err();
        assert_eq!(
            err,
            InformationError::TooFewSamples {
                needed: 510,
                given: 100
            }
        );
    }
}
