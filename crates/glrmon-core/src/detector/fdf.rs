//! The observer-based fault-detection filter (FDF) of Ahmad & Mohd-Mokhtar 2021, eqs.
//! (9)-(10), its residual evaluation (eqs. (8), (12)-(13), (19)) and the unified optimal
//! gains of their eq. (18).
//!
//! # Letters
//! The survey writes the plant x(k+1) = Ax + Bu + E_d d + E_f f, y = Cx + Du + F_d d + F_f f;
//! here A, B, C, D are Zhang & Basseville 2014's F, G, H, J, and the disturbance enters as
//! the noises W_k = E_d d_k and V_k = F_d d_k, so that for a white d of unit covariance
//! Q = E_dE_dᵀ, R = F_dF_dᵀ and S = E(W_kV_kᵀ) = E_dF_dᵀ (survey Table 1). The FDF's two
//! design matrices keep the survey's names: the observer gain L (n×p) and the residual
//! weight (post-filter) V (any number of rows × p); the measurement noise always carries
//! its index, V_k.
//!
//! # The filter (survey eq. (9))
//! ```text
//! X̂_{k+1} = F_k X̂_k + G_k U_k + L (Y_k − J_k U_k − H_k X̂_k)
//! r_k     = V (Y_k − J_k U_k − H_k X̂_k)
//! ```
//! The estimation error e_k = X_k − X̂_k obeys e_{k+1} = (F_k − LH_k) e_k + W_k − L V_k
//! and r_k = V (H_k e_k + V_k) under no fault: e_k depends on V_0 … V_{k−1} only, so the
//! two terms are uncorrelated and
//! ```text
//! P_{k+1} = (F_k − LH_k) P_k (F_k − LH_k)ᵀ + Q_k + L R_k Lᵀ − S Lᵀ − L Sᵀ
//! Σ_r,k   = V (H_k P_k H_kᵀ + R_k) Vᵀ
//! ```
//! from P_0 (the covariance of X_0 around X̂_0). The detector runs this recursion on
//! every sample, so Σ_r,k is the residual's covariance at that sample, through the
//! transient too, and rᵀΣ_r⁺r is χ²(rank Σ_r,k) under no fault from the first sample on.
//! F − LH must be stable (spectral radius below 1): the survey's condition that the
//! estimation error go to zero; [`error_covariance`] and [`residual_covariance`] give the
//! steady state.
//!
//! For a gain other than the optimal one the residual is coloured: E(r_{k+1}r_kᵀ) =
//! V H ((F − LH) P Hᵀ + S − L R) Vᵀ ≠ 0. The per-sample χ² then has the right marginal
//! law (the false-alarm probability per sample is the one its threshold is set for) but
//! its exceedances are correlated: alarms come in clusters, and the number of separate
//! false alarms per unit time is lower than α per sample.
//!
//! # The unified optimal solution (survey eq. (18), Table 1)
//! [`FdfGains::optimal`]: L = (F X Hᵀ + S) Σ⁻¹ and V = Σ^{−1/2}, Σ = H X Hᵀ + R, with X
//! the stabilising solution of X = F X Fᵀ − L Σ Lᵀ + Q. This L is the steady one-step
//! Kalman predictor gain (Table 1: the two designs coincide), so the residual is white
//! with covariance V Σ Vᵀ = I, and the transfer from d to r is co-inner: ‖G_rd‖_∞ = 1,
//! which is why the survey's threshold (19) is δ_d itself.
//!
//! # Evaluation
//! [`Evaluation::Chi2`]: rᵀΣ_r⁺r on each sample, the Cholesky factor of Σ_r,k when it is
//! definite, otherwise its eigen decomposition with the eigenvalues below
//! [`DEFAULT_RANK_TOLERANCE`]·λ_max dropped (degrees of freedom = the rank kept; a
//! component of r outside range Σ_r is then not tested). [`Evaluation::Energy`]: the
//! windowed energy J_k = (Σ_{i=k−w+1..k} r_iᵀr_i)^{1/2} of eqs. (8), (12); its bound for a
//! disturbance of bounded energy, survey eqs. (13), (19), is [`energy_threshold`].

use nalgebra::{Complex, DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::isolation::DEFAULT_RANK_TOLERANCE;
use crate::linalg::{
    cholesky_in_place, gemm, gemv, jacobi_eigen, solve_lower_in_place, symmetrize,
};
use crate::model::fault::FaultDictionary;
use crate::model::{Dims, Signals, StateSpace, SystemMatrices};

use super::{Detector, EnergyWindow, Evaluation, Sample, StepOutput};

/// Doubling steps of [`FdfGains::optimal`] and [`error_covariance`] before giving up: the
/// k-th step covers 2^k samples of the underlying recursion.
const MAX_DOUBLINGS: usize = 64;

/// Relative change at which a doubling iteration has converged.
const DOUBLING_TOLERANCE: f64 = 1e-15;

/// The spectral radius of a square matrix: its largest eigenvalue modulus (0 for an
/// empty matrix, +∞ when the eigenvalues cannot be computed, so that a stability test
/// on it fails).
#[must_use]
pub fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    if m.is_empty() {
        return 0.0;
    }
    if !m.is_square() || m.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    match nalgebra::linalg::Schur::try_new(m.clone(), f64::EPSILON, 10_000) {
        Some(schur) => schur
            .complex_eigenvalues()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max),
        None => f64::INFINITY,
    }
}

/// The FDF's design: the observer gain L (n×p) and the residual weight V (rows × p) of
/// survey eq. (9).
#[derive(Debug, Clone, PartialEq)]
pub struct FdfGains {
    /// L, n×p: X̂_{k+1} = F X̂_k + G U_k + L (Y_k − J U_k − H X̂_k).
    pub l: DMatrix<f64>,
    /// V, rows×p: r_k = V (Y_k − J U_k − H X̂_k).
    pub v: DMatrix<f64>,
}

impl FdfGains {
    /// The unified optimal solution of survey eq. (18) for the noise Q = E_dE_dᵀ (n×n),
    /// R = F_dF_dᵀ (p×p), S = E_dF_dᵀ (n×p):
    /// L = (F X Hᵀ + S)(H X Hᵀ + R)⁻¹, V = (H X Hᵀ + R)^{−1/2} (the symmetric root), X the
    /// stabilising solution of X = F X Fᵀ − L (H X Hᵀ + R) Lᵀ + Q.
    ///
    /// X is found by the structure-preserving doubling algorithm (Chu, Fan & Lin 2005) on
    /// the equation with the cross term removed (F − SR⁻¹H, Q − SR⁻¹Sᵀ): each step doubles
    /// the horizon of the Riccati recursion started at X = 0, until the relative change is
    /// below 1e-15 (at most 64 steps); the gain is then checked to make F − LH stable.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for the matrices;
    /// [`ModelError::Setting`] when R is not positive definite, when [Q S; Sᵀ R] is not a
    /// covariance, or when the Riccati equation has no stabilising solution reached from 0
    /// (a mode on or outside the unit circle that the noise does not excite or the
    /// outputs do not see).
    pub fn optimal(
        f: &DMatrix<f64>,
        h: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &DMatrix<f64>,
        s: &DMatrix<f64>,
    ) -> Result<Self, ModelError> {
        let (n, p) = check_plant(f, h)?;
        check_noise(n, p, q, r, s)?;
        let Some(r_inv) = r.clone().cholesky().map(|c| c.inverse()) else {
            return Err(ModelError::Setting {
                what: "R",
                detail: "R = F_dF_dᵀ is not positive definite: the unified solution (18) \
                         needs noise on every output"
                    .into(),
            });
        };
        let sr = s * &r_inv;
        let mut q_bar = q - &sr * s.transpose();
        symmetrize(q_bar.as_mut_slice(), n);
        let smallest = q_bar.clone().symmetric_eigen().eigenvalues.min();
        if smallest < -1e-12 * q.amax().max(r.amax()).max(f64::MIN_POSITIVE) {
            return Err(ModelError::Setting {
                what: "S",
                detail: format!(
                    "[Q S; Sᵀ R] is not a covariance: Q − SR⁻¹Sᵀ has the eigenvalue \
                     {smallest:e} < 0 (S is too large for Q and R)"
                ),
            });
        }
        // Control form of the filter equation: A = (F − SR⁻¹H)ᵀ, G = HᵀR⁻¹H, H = Q̄.
        let mut a = (f - &sr * h).transpose();
        let mut g = h.transpose() * &r_inv * h;
        let mut x = q_bar;
        let identity = DMatrix::<f64>::identity(n, n);
        let mut converged = false;
        for _ in 0..MAX_DOUBLINGS {
            let w = (&identity + &g * &x).lu();
            let (Some(wa), Some(wg)) = (w.solve(&a), w.solve(&g)) else {
                return Err(ModelError::Setting {
                    what: "Riccati equation (18)",
                    detail: "the doubling iteration met a singular I + GX".into(),
                });
            };
            let x_next = &x + a.transpose() * &x * &wa;
            let g_next = &g + &a * &wg * a.transpose();
            let a_next = &a * &wa;
            let change = (&x_next - &x).amax();
            let scale = x_next.amax();
            x = x_next;
            symmetrize(x.as_mut_slice(), n);
            g = g_next;
            symmetrize(g.as_mut_slice(), n);
            a = a_next;
            if !x.iter().all(|v| v.is_finite()) {
                break;
            }
            if change <= DOUBLING_TOLERANCE * scale {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(ModelError::Setting {
                what: "Riccati equation (18)",
                detail: format!(
                    "X did not converge in {MAX_DOUBLINGS} doubling steps: F has a mode on \
                     or outside the unit circle that the outputs do not see"
                ),
            });
        }
        let sigma = {
            let mut m = h * &x * h.transpose() + r;
            symmetrize(m.as_mut_slice(), p);
            m
        };
        let eig = sigma.clone().symmetric_eigen();
        let root_inv = DMatrix::from_diagonal(&eig.eigenvalues.map(|l| 1.0 / l.sqrt()));
        let v = &eig.eigenvectors * root_inv * eig.eigenvectors.transpose();
        let Some(sigma_inv) = sigma.cholesky().map(|c| c.inverse()) else {
            return Err(ModelError::Setting {
                what: "R",
                detail: "H X Hᵀ + R is not positive definite".into(),
            });
        };
        let l = (f * &x * h.transpose() + s) * sigma_inv;
        let radius = spectral_radius(&(f - &l * h));
        if radius.is_nan() || radius >= 1.0 {
            return Err(ModelError::Setting {
                what: "Riccati equation (18)",
                detail: format!(
                    "no stabilising solution: F − LH has spectral radius {radius} ≥ 1 (a mode \
                     on or outside the unit circle is not excited by the noise Q − SR⁻¹Sᵀ)"
                ),
            });
        }
        Ok(Self { l, v })
    }

    /// Checks the design against the plant (F n×n, H p×n): L is n×p, V has p columns and
    /// at least one row, both finite, V not zero, and F − LH (the survey's A − LC) has
    /// spectral radius below 1, the condition for the estimation error to vanish and the
    /// residual to stay bounded.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] naming L or V, [`ModelError::NonFinite`],
    /// [`ModelError::Setting`] for a zero V or an unstable F − LH (with its spectral
    /// radius).
    pub fn check(&self, f: &DMatrix<f64>, h: &DMatrix<f64>) -> Result<(), ModelError> {
        let (n, p) = check_plant(f, h)?;
        if self.l.shape() != (n, p) {
            return Err(ModelError::Dimension {
                what: "L",
                detail: format!(
                    "the observer gain L is {}×{}, expected {n}×{p} (states × outputs)",
                    self.l.nrows(),
                    self.l.ncols()
                ),
            });
        }
        if self.v.ncols() != p || self.v.nrows() == 0 {
            return Err(ModelError::Dimension {
                what: "V",
                detail: format!(
                    "the residual weight V is {}×{}, expected at least one row and {p} \
                     columns (one per output)",
                    self.v.nrows(),
                    self.v.ncols()
                ),
            });
        }
        if self.l.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "L" });
        }
        if self.v.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "V" });
        }
        if self.v.iter().all(|&v| v == 0.0) {
            return Err(ModelError::Setting {
                what: "V",
                detail: "V is zero: the residual would be identically zero".into(),
            });
        }
        let radius = spectral_radius(&(f - &self.l * h));
        if radius.is_nan() || radius >= 1.0 {
            return Err(ModelError::Setting {
                what: "L",
                detail: format!(
                    "F − LH (the survey's A − LC) is not stable: spectral radius {radius:.6} ≥ 1, \
                     so the estimation error does not vanish and the residual diverges"
                ),
            });
        }
        Ok(())
    }
}

/// (n, p) of F (n×n, non-empty) and H (p×n), both finite.
fn check_plant(f: &DMatrix<f64>, h: &DMatrix<f64>) -> Result<(usize, usize), ModelError> {
    let n = f.nrows();
    if n == 0 || f.ncols() != n {
        return Err(ModelError::Dimension {
            what: "F",
            detail: format!("F must be square and non-empty, got {}×{}", n, f.ncols()),
        });
    }
    if h.ncols() != n || h.nrows() == 0 {
        return Err(ModelError::Dimension {
            what: "H",
            detail: format!("H is {}×{} but F is {n}×{n}", h.nrows(), h.ncols()),
        });
    }
    for (what, m) in [("F", f), ("H", h)] {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what });
        }
    }
    Ok((n, h.nrows()))
}

/// Q n×n, R p×p, S n×p, finite.
fn check_noise(
    n: usize,
    p: usize,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: &DMatrix<f64>,
) -> Result<(), ModelError> {
    for (what, m, shape) in [("Q", q, (n, n)), ("R", r, (p, p)), ("S", s, (n, p))] {
        if m.shape() != shape {
            return Err(ModelError::Dimension {
                what,
                detail: format!(
                    "{what} is {}×{}, expected {}×{}",
                    m.nrows(),
                    m.ncols(),
                    shape.0,
                    shape.1
                ),
            });
        }
        if m.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what });
        }
    }
    Ok(())
}

/// The steady covariance P of the estimation error e = X − X̂ of an FDF with gain L:
/// P = (F − LH) P (F − LH)ᵀ + Q + L R Lᵀ − S Lᵀ − L Sᵀ, a discrete Lyapunov equation
/// solved by Smith's doubling (P ← P + A P Aᵀ, A ← A²) until the added term is below
/// 1e-15 of P (at most 64 steps, 2⁶⁴ samples of the recursion).
///
/// # Errors
/// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for the matrices,
/// [`ModelError::Setting`] when F − LH is not stable (no steady state).
pub fn error_covariance(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    l: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: &DMatrix<f64>,
) -> Result<DMatrix<f64>, ModelError> {
    let (n, p) = check_plant(f, h)?;
    check_noise(n, p, q, r, s)?;
    let gains = FdfGains {
        l: l.clone(),
        v: DMatrix::identity(p, p),
    };
    gains.check(f, h)?;
    let mut a = f - l * h;
    let mut c = q + l * r * l.transpose() - s * l.transpose() - l * s.transpose();
    symmetrize(c.as_mut_slice(), n);
    for _ in 0..MAX_DOUBLINGS {
        let added = &a * &c * a.transpose();
        let change = added.amax();
        c += added;
        symmetrize(c.as_mut_slice(), n);
        a = &a * &a;
        if change <= DOUBLING_TOLERANCE * c.amax() || a.amax() == 0.0 {
            return Ok(c);
        }
    }
    Ok(c)
}

/// The steady covariance of the FDF's residual under no fault, Σ_r = V (H P Hᵀ + R) Vᵀ
/// with P from [`error_covariance`].
///
/// # Errors
/// As [`error_covariance`], and [`FdfGains::check`] for V.
pub fn residual_covariance(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    gains: &FdfGains,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: &DMatrix<f64>,
) -> Result<DMatrix<f64>, ModelError> {
    gains.check(f, h)?;
    let p = error_covariance(f, h, &gains.l, q, r, s)?;
    let mut sigma = &gains.v * (h * p * h.transpose() + r) * gains.v.transpose();
    symmetrize(sigma.as_mut_slice(), gains.v.nrows());
    Ok(sigma)
}

/// ‖G_rd‖_∞, the largest gain from the disturbance d to the residual r of survey eq.
/// (10), G_rd(z) = V [H (zI − F + LH)⁻¹ (E_d − L F_d) + F_d] (the survey writes it without
/// the weight V, which eq. (9) applies to r).
///
/// Computed as the largest singular value of G_rd(e^{jω}) over a grid of ω in [0, π]
/// (the plant is real: −ω gives the same value), at least 1024 intervals and fine enough
/// that a peak of the closest pole to the unit circle spans several points
/// (π/N ≤ (1 − ρ)/4, ρ the spectral radius of F − LH, at most 2²⁰ intervals), refined
/// by golden-section search between the neighbours of the largest grid value. A peak
/// narrower than the grid spacing could be missed; the value is then a lower bound.
///
/// # Errors
/// [`FdfGains::check`] for the design; [`ModelError::Dimension`] when E_d is not n×k or
/// F_d not p×k for the same k ≥ 1; [`ModelError::NonFinite`].
pub fn disturbance_gain(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    gains: &FdfGains,
    e_d: &DMatrix<f64>,
    f_d: &DMatrix<f64>,
) -> Result<f64, ModelError> {
    gains.check(f, h)?;
    let (n, p) = (f.nrows(), h.nrows());
    let k = e_d.ncols();
    if e_d.nrows() != n || k == 0 {
        return Err(ModelError::Dimension {
            what: "E_d",
            detail: format!(
                "E_d is {}×{}, expected {n} rows and at least one column",
                e_d.nrows(),
                k
            ),
        });
    }
    if f_d.shape() != (p, k) {
        return Err(ModelError::Dimension {
            what: "F_d",
            detail: format!(
                "F_d is {}×{}, expected {p}×{k} (outputs × the columns of E_d)",
                f_d.nrows(),
                f_d.ncols()
            ),
        });
    }
    for (what, m) in [("E_d", e_d), ("F_d", f_d)] {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what });
        }
    }
    let a = f - &gains.l * h;
    let b = e_d - &gains.l * f_d;
    let radius = spectral_radius(&a);
    let c = |m: &DMatrix<f64>| m.map(|x| Complex::new(x, 0.0));
    let (a_c, b_c, h_c, fd_c, v_c) = (c(&a), c(&b), c(h), c(f_d), c(&gains.v));
    let gain_at = |w: f64| -> f64 {
        let z = Complex::new(w.cos(), w.sin());
        let mut m = -a_c.clone();
        for i in 0..n {
            m[(i, i)] += z;
        }
        match m.lu().solve(&b_c) {
            Some(x) => {
                let g = &v_c * (&h_c * x + &fd_c);
                g.svd(false, false).singular_values.max()
            }
            None => f64::INFINITY,
        }
    };
    let spacing = (1.0 - radius) / 4.0;
    let intervals = ((std::f64::consts::PI / spacing).ceil() as usize).clamp(1024, 1 << 20);
    let step = std::f64::consts::PI / intervals as f64;
    let (mut best_i, mut best) = (0, f64::NEG_INFINITY);
    for i in 0..=intervals {
        let g = gain_at(i as f64 * step);
        if g > best {
            (best_i, best) = (i, g);
        }
    }
    let (mut lo, mut hi) = (
        (best_i.saturating_sub(1)) as f64 * step,
        ((best_i + 1).min(intervals)) as f64 * step,
    );
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut g1, mut g2) = (gain_at(x1), gain_at(x2));
    for _ in 0..80 {
        if g1 >= g2 {
            hi = x2;
            (x2, g2) = (x1, g1);
            x1 = hi - ratio * (hi - lo);
            g1 = gain_at(x1);
        } else {
            lo = x1;
            (x1, g1) = (x2, g2);
            x2 = lo + ratio * (hi - lo);
            g2 = gain_at(x2);
        }
    }
    Ok(best.max(g1).max(g2))
}

/// The threshold J_th of the windowed energy J_k = (Σ r_iᵀr_i)^{1/2} for a disturbance
/// of bounded energy ‖d‖₂ ≤ δ_d, survey eqs. (13), (19): J_th = sup ‖r‖₂ = ‖G_rd‖_∞·δ_d
/// ([`disturbance_gain`]). δ_d bounds ‖d‖₂ = (Σ dᵀd)^{1/2}, as in the survey's
/// evaluation section and like J_k a root of an energy (the survey's parity section
/// calls δ_d a bound on ‖d‖₂² itself: pass its square root then). For the unified solution (18) G_rd is co-inner, ‖G_rd‖_∞ = 1,
/// and this is the survey's J_th = δ_d. The bound holds for every window once the
/// initial estimation error has decayed (a window's energy is at most the total one).
/// Offered for validation: the detector compares J_k with the channel's threshold.
///
/// # Errors
/// As [`disturbance_gain`], and [`ModelError::Setting`] when δ_d is negative or not
/// finite.
pub fn energy_threshold(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    gains: &FdfGains,
    e_d: &DMatrix<f64>,
    f_d: &DMatrix<f64>,
    delta_d: f64,
) -> Result<f64, ModelError> {
    if !(delta_d.is_finite() && delta_d >= 0.0) {
        return Err(ModelError::Setting {
            what: "δ_d",
            detail: format!("the disturbance energy bound must be finite and ≥ 0, got {delta_d}"),
        });
    }
    Ok(disturbance_gain(f, h, gains, e_d, f_d)? * delta_d)
}

/// The observer-based fault-detection filter of survey eq. (9) with the gains L and V
/// of [`FdfGains`], and its residual's exact covariance Σ_r,k under the model's noise
/// (module documentation).
///
/// The decision statistic ([`StepOutput::glr`]) is rᵀΣ_r⁺r ([`Evaluation::Chi2`], onset
/// k) or the windowed energy ([`Evaluation::Energy`], onset k − w + 1 counted in samples
/// measured, `None` until w have been); [`StepOutput::normalized_innovation`] is rᵀΣ_r⁺r
/// and [`StepOutput::rank`] its degrees of freedom either way. No magnitude is
/// estimated. A missing sample is bridged by prediction with the last input (see
/// [`FdfDetector::predict_only`]).
#[derive(Debug)]
pub struct FdfDetector {
    model: Box<dyn StateSpace>,
    faults: FaultDictionary,
    dims: Dims,
    constant: bool,
    system: SystemMatrices,
    l: DMatrix<f64>,
    v: DMatrix<f64>,
    /// S = E(W_kV_kᵀ) (n×p), zero unless [`FdfDetector::with_cross_covariance`].
    s: DMatrix<f64>,
    evaluation: Evaluation,
    energy: EnergyWindow,
    /// The indices of the samples in the energy window, a ring in step with `energy`.
    window_index: Vec<u64>,
    window_next: usize,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    /// X̂_k and P_k for the next sample.
    state: DVector<f64>,
    cov: DMatrix<f64>,
    /// Σ_r,k of the last measured sample and its factor (Cholesky or eigenvectors).
    sigma_r: DMatrix<f64>,
    factor: DMatrix<f64>,
    eigenvalues: Vec<f64>,
    eigenvectors: DMatrix<f64>,
    /// Y_k − J_kU_k − H_kX̂_k and r_k of the last measured sample.
    output_error: DVector<f64>,
    residual: DVector<f64>,
    // Scratch, sized once.
    state_next: DVector<f64>,
    cov_next: DMatrix<f64>,
    closed_loop: DMatrix<f64>,
    tmp_nn: DMatrix<f64>,
    tmp_np: DMatrix<f64>,
    tmp_pn: DMatrix<f64>,
    tmp_pp: DMatrix<f64>,
    tmp_mp: DMatrix<f64>,
    tmp_m: DVector<f64>,
    held_u: Vec<f64>,
    held_p: Vec<f64>,
    /// Running mean and sum of squared deviations of each input (Welford's algorithm).
    input_moments: Vec<(f64, f64)>,
    input_count: u64,
    input_variance: Vec<f64>,
    next_k: Option<u64>,
}

impl FdfDetector {
    /// An FDF on `model` (constant or time-varying: evaluated on every sample) with the
    /// design `gains`, started at X̂_0 = `x0` with error covariance P_0 = `p0` (the
    /// covariance of X_0 − x0; the χ² is exact from the first sample when it is), its
    /// residual evaluated by `evaluation`. `faults` is the channel's dictionary, which the
    /// monitor's isolation and reports refer to; the FDF itself does not use it.
    ///
    /// The stability of F − LH is checked on the model at sample 0 with zero signals: for
    /// a time-varying model that is a frozen-time check, not a guarantee.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when the dictionary, x0, P0, L or V do not fit the model;
    /// [`ModelError::NonFinite`]; [`ModelError::Setting`] when P0 is not symmetric
    /// positive semi-definite, V is zero, F − LH is not stable, or the energy window is 0.
    pub fn new(
        mut model: Box<dyn StateSpace>,
        faults: FaultDictionary,
        gains: FdfGains,
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        evaluation: Evaluation,
    ) -> Result<Self, ModelError> {
        let dims = model.dims();
        if faults.dims() != dims {
            return Err(ModelError::Dimension {
                what: "fault dictionary",
                detail: format!("built for {:?} but the model is {:?}", faults.dims(), dims),
            });
        }
        let (n, p, l) = (dims.states, dims.outputs, dims.inputs);
        if x0.len() != n {
            return Err(ModelError::Dimension {
                what: "x0",
                detail: format!("x0 has {} entries but the model has {n} states", x0.len()),
            });
        }
        if p0.shape() != (n, n) {
            return Err(ModelError::Dimension {
                what: "P0",
                detail: format!(
                    "P0 is {}×{} but the model has {n} states",
                    p0.nrows(),
                    p0.ncols()
                ),
            });
        }
        if x0.iter().chain(p0.iter()).any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "x0/P0" });
        }
        let asym = (&p0 - p0.transpose()).amax();
        if asym > 1e-9 * p0.amax().max(1.0) {
            return Err(ModelError::Setting {
                what: "P0",
                detail: format!("P0 is not symmetric (max |P0 − P0ᵀ| = {asym:e})"),
            });
        }
        let smallest = p0.clone().symmetric_eigen().eigenvalues.min();
        if smallest < -1e-9 * p0.amax().max(1.0) {
            return Err(ModelError::Setting {
                what: "P0",
                detail: format!(
                    "P0 is not positive semi-definite (smallest eigenvalue {smallest:e})"
                ),
            });
        }
        if let Evaluation::Energy { window: 0 } = evaluation {
            return Err(ModelError::Setting {
                what: "window",
                detail: "the energy window needs at least 1 sample, got 0".into(),
            });
        }
        let mut system = SystemMatrices::zeros(dims);
        let (zero_u, zero_p) = (vec![0.0; l], vec![0.0; dims.signals]);
        model.evaluate(
            0,
            &Signals {
                u: &zero_u,
                p: &zero_p,
            },
            &mut system,
        );
        if !system.is_finite() {
            return Err(ModelError::NonFinite {
                what: "the model at sample 0",
            });
        }
        gains.check(&system.f, &system.h)?;
        let m = gains.v.nrows();
        let window = evaluation.memory();
        let z = |r, c| DMatrix::zeros(r, c);
        Ok(Self {
            constant: model.is_constant(),
            model,
            faults,
            dims,
            system,
            l: gains.l,
            v: gains.v,
            s: z(n, p),
            evaluation,
            energy: EnergyWindow::new(window),
            window_index: vec![0; window],
            window_next: 0,
            state: x0.clone(),
            cov: p0.clone(),
            x0,
            p0,
            sigma_r: z(m, m),
            factor: z(m, m),
            eigenvalues: vec![0.0; m],
            eigenvectors: z(m, m),
            output_error: DVector::zeros(p),
            residual: DVector::zeros(m),
            state_next: DVector::zeros(n),
            cov_next: z(n, n),
            closed_loop: z(n, n),
            tmp_nn: z(n, n),
            tmp_np: z(n, p),
            tmp_pn: z(p, n),
            tmp_pp: z(p, p),
            tmp_mp: z(m, p),
            tmp_m: DVector::zeros(m),
            held_u: vec![0.0; l],
            held_p: vec![0.0; dims.signals],
            input_moments: vec![(0.0, 0.0); l],
            input_count: 0,
            input_variance: vec![0.0; l],
            next_k: None,
        })
    }

    /// The same detector for process and measurement noises correlated as
    /// S = E(W_kV_kᵀ) (n×p, constant; the survey's E_dF_dᵀ), which enters the error
    /// covariance recursion as −SLᵀ − LSᵀ.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when S is not n×p, [`ModelError::NonFinite`].
    pub fn with_cross_covariance(mut self, s: DMatrix<f64>) -> Result<Self, ModelError> {
        let (n, p) = (self.dims.states, self.dims.outputs);
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
        if s.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "S" });
        }
        self.s = s;
        Ok(self)
    }

    /// X̂_k, the state estimate for the next sample.
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.state
    }

    /// P_k, the covariance of the estimation error X_k − X̂_k for the next sample.
    #[must_use]
    pub fn error_covariance(&self) -> &DMatrix<f64> {
        &self.cov
    }

    /// Σ_r,k, the residual's covariance at the last measured sample.
    #[must_use]
    pub fn residual_covariance(&self) -> &DMatrix<f64> {
        &self.sigma_r
    }

    /// The residual evaluation.
    #[must_use]
    pub fn evaluation(&self) -> Evaluation {
        self.evaluation
    }

    fn check(&self, s: &Sample<'_>) -> Result<(), StepError> {
        super::check_sample(self.dims, self.next_k, s)
    }

    /// The model at sample k (held for a constant model).
    fn evaluate(&mut self, k: u64, u: &[f64], p: &[f64]) -> Result<(), StepError> {
        if self.constant {
            return Ok(());
        }
        self.model.evaluate(k, &Signals { u, p }, &mut self.system);
        if self.system.is_finite() {
            Ok(())
        } else {
            Err(StepError::Numerical {
                what: "the model evaluated at this sample's signals is not finite",
            })
        }
    }

    /// Σ_r,k = V (H P Hᵀ + R) Vᵀ from the current P.
    fn residual_covariance_now(&mut self) {
        let (n, p, m) = (self.dims.states, self.dims.outputs, self.v.nrows());
        let sys = &self.system;
        gemm(
            1.0,
            sys.h.as_slice(),
            (p, n),
            false,
            self.cov.as_slice(),
            (n, n),
            false,
            0.0,
            self.tmp_pn.as_mut_slice(),
        );
        self.tmp_pp.copy_from(&sys.r);
        gemm(
            1.0,
            self.tmp_pn.as_slice(),
            (p, n),
            false,
            sys.h.as_slice(),
            (p, n),
            true,
            1.0,
            self.tmp_pp.as_mut_slice(),
        );
        gemm(
            1.0,
            self.v.as_slice(),
            (m, p),
            false,
            self.tmp_pp.as_slice(),
            (p, p),
            false,
            0.0,
            self.tmp_mp.as_mut_slice(),
        );
        gemm(
            1.0,
            self.tmp_mp.as_slice(),
            (m, p),
            false,
            self.v.as_slice(),
            (m, p),
            true,
            0.0,
            self.sigma_r.as_mut_slice(),
        );
        symmetrize(self.sigma_r.as_mut_slice(), m);
    }

    /// rᵀΣ_r⁺r and rank Σ_r: by Cholesky when every pivot exceeds
    /// [`DEFAULT_RANK_TOLERANCE`] times the largest variance, otherwise by the eigen
    /// decomposition with the eigenvalues below that fraction of the largest dropped.
    fn normalized_square(&mut self) -> (f64, usize) {
        let m = self.v.nrows();
        let tol = DEFAULT_RANK_TOLERANCE;
        let largest = (0..m).map(|i| self.sigma_r[(i, i)]).fold(0.0, f64::max);
        if largest <= 0.0 {
            return (0.0, 0);
        }
        self.factor.copy_from(&self.sigma_r);
        if cholesky_in_place(self.factor.as_mut_slice(), m)
            && (0..m).all(|i| self.factor[(i, i)] * self.factor[(i, i)] > tol * largest)
        {
            self.tmp_m.copy_from(&self.residual);
            solve_lower_in_place(self.factor.as_slice(), m, self.tmp_m.as_mut_slice(), 1);
            return (self.tmp_m.norm_squared(), m);
        }
        self.factor.copy_from(&self.sigma_r);
        jacobi_eigen(
            self.factor.as_mut_slice(),
            m,
            &mut self.eigenvalues,
            self.eigenvectors.as_mut_slice(),
        );
        let top = self.eigenvalues.iter().copied().fold(0.0, f64::max);
        let (mut sum, mut rank) = (0.0, 0);
        for (i, &lambda) in self.eigenvalues.iter().enumerate() {
            if lambda > tol * top {
                let c = self.eigenvectors.column(i).dot(&self.residual);
                sum += c * c / lambda;
                rank += 1;
            }
        }
        (sum, rank)
    }

    /// Processes sample k: the residual r_k and its covariance Σ_r,k, the decision
    /// statistic, then X̂_{k+1} and P_{k+1}.
    ///
    /// # Errors
    /// [`StepError::WrongDimension`] / [`StepError::NonFinite`] for a malformed sample,
    /// [`StepError::OutOfOrder`] when k is not the next index, [`StepError::Numerical`]
    /// when the model at this sample or the recursion is not finite. On error the
    /// detector's state is unchanged.
    pub fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.check(sample)?;
        self.evaluate(sample.k, sample.u, sample.p)?;
        let (n, p, l, m) = (
            self.dims.states,
            self.dims.outputs,
            self.dims.inputs,
            self.v.nrows(),
        );
        let sys = &self.system;
        self.output_error.as_mut_slice().copy_from_slice(sample.y);
        gemv(
            -1.0,
            sys.j.as_slice(),
            p,
            l,
            sample.u,
            1.0,
            self.output_error.as_mut_slice(),
        );
        gemv(
            -1.0,
            sys.h.as_slice(),
            p,
            n,
            self.state.as_slice(),
            1.0,
            self.output_error.as_mut_slice(),
        );
        gemv(
            1.0,
            self.v.as_slice(),
            m,
            p,
            self.output_error.as_slice(),
            0.0,
            self.residual.as_mut_slice(),
        );
        self.residual_covariance_now();
        if !self.sigma_r.iter().all(|v| v.is_finite()) {
            return Err(StepError::Numerical {
                what: "the residual covariance Σ_r is not finite",
            });
        }
        let (statistic, rank) = self.normalized_square();
        // X̂_{k+1} = F X̂ + G U + L (Y − JU − HX̂).
        let sys = &self.system;
        gemv(
            1.0,
            sys.f.as_slice(),
            n,
            n,
            self.state.as_slice(),
            0.0,
            self.state_next.as_mut_slice(),
        );
        gemv(
            1.0,
            sys.g.as_slice(),
            n,
            l,
            sample.u,
            1.0,
            self.state_next.as_mut_slice(),
        );
        gemv(
            1.0,
            self.l.as_slice(),
            n,
            p,
            self.output_error.as_slice(),
            1.0,
            self.state_next.as_mut_slice(),
        );
        // P_{k+1} = A P Aᵀ + Q + (LR − S) Lᵀ − L Sᵀ, A = F − LH.
        self.closed_loop.copy_from(&sys.f);
        gemm(
            -1.0,
            self.l.as_slice(),
            (n, p),
            false,
            sys.h.as_slice(),
            (p, n),
            false,
            1.0,
            self.closed_loop.as_mut_slice(),
        );
        gemm(
            1.0,
            self.closed_loop.as_slice(),
            (n, n),
            false,
            self.cov.as_slice(),
            (n, n),
            false,
            0.0,
            self.tmp_nn.as_mut_slice(),
        );
        self.cov_next.copy_from(&sys.q);
        gemm(
            1.0,
            self.tmp_nn.as_slice(),
            (n, n),
            false,
            self.closed_loop.as_slice(),
            (n, n),
            true,
            1.0,
            self.cov_next.as_mut_slice(),
        );
        gemm(
            1.0,
            self.l.as_slice(),
            (n, p),
            false,
            sys.r.as_slice(),
            (p, p),
            false,
            0.0,
            self.tmp_np.as_mut_slice(),
        );
        self.tmp_np -= &self.s;
        gemm(
            1.0,
            self.tmp_np.as_slice(),
            (n, p),
            false,
            self.l.as_slice(),
            (n, p),
            true,
            1.0,
            self.cov_next.as_mut_slice(),
        );
        gemm(
            -1.0,
            self.l.as_slice(),
            (n, p),
            false,
            self.s.as_slice(),
            (n, p),
            true,
            1.0,
            self.cov_next.as_mut_slice(),
        );
        symmetrize(self.cov_next.as_mut_slice(), n);
        if !(statistic.is_finite()
            && self.state_next.iter().all(|v| v.is_finite())
            && self.cov_next.iter().all(|v| v.is_finite()))
        {
            return Err(StepError::Numerical {
                what: "the FDF's state estimate or error covariance is not finite",
            });
        }
        std::mem::swap(&mut self.state, &mut self.state_next);
        std::mem::swap(&mut self.cov, &mut self.cov_next);
        let k = sample.k;
        out.k = k;
        out.normalized_innovation = statistic;
        out.rank = rank;
        out.residual.copy_from(&self.residual);
        out.magnitude.fill(0.0);
        match self.evaluation {
            Evaluation::Chi2 => {
                out.glr = Some(statistic);
                out.onset = Some(k);
            }
            Evaluation::Energy { .. } => {
                let w = self.window_index.len();
                self.window_index[self.window_next] = k;
                self.window_next = (self.window_next + 1) % w;
                out.glr = self.energy.push(self.residual.norm_squared());
                out.onset = out.glr.map(|_| self.window_index[self.window_next]);
            }
        }
        self.finish_measured(sample);
        Ok(())
    }

    /// Held signals, input moments and the next index after a measured sample.
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
    }

    /// Bridges the missing sample k as [`crate::GlrDetector::predict_only`] does:
    /// X̂_{k+1} = F X̂_k + G U with U the last sample's input (the missing one is
    /// unknown) and no correction, P_{k+1} = F P_k Fᵀ + Q + G diag(σ²_u) Gᵀ with σ²_u the
    /// inputs' running variance, so that the input guessed wrong does not look like a
    /// fault after the gap. The energy window keeps its samples (none is added).
    ///
    /// # Errors
    /// [`StepError::OutOfOrder`] when k is not the next index or no sample has been seen
    /// yet; [`StepError::Numerical`] when the model or the prediction is not finite.
    pub fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
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
        if !self.constant {
            self.model.evaluate(
                k,
                &Signals {
                    u: &self.held_u,
                    p: &self.held_p,
                },
                &mut self.system,
            );
            if !self.system.is_finite() {
                return Err(StepError::Numerical {
                    what: "the model evaluated at the held signals is not finite",
                });
            }
        }
        let (n, l) = (self.dims.states, self.dims.inputs);
        let count = self.input_count as f64;
        for (v, (_, m2)) in self.input_variance.iter_mut().zip(&self.input_moments) {
            *v = if count > 1.0 { m2 / (count - 1.0) } else { 0.0 };
        }
        let sys = &self.system;
        gemv(
            1.0,
            sys.f.as_slice(),
            n,
            n,
            self.state.as_slice(),
            0.0,
            self.state_next.as_mut_slice(),
        );
        gemv(
            1.0,
            sys.g.as_slice(),
            n,
            l,
            &self.held_u,
            1.0,
            self.state_next.as_mut_slice(),
        );
        gemm(
            1.0,
            sys.f.as_slice(),
            (n, n),
            false,
            self.cov.as_slice(),
            (n, n),
            false,
            0.0,
            self.tmp_nn.as_mut_slice(),
        );
        self.cov_next.copy_from(&sys.q);
        gemm(
            1.0,
            self.tmp_nn.as_slice(),
            (n, n),
            false,
            sys.f.as_slice(),
            (n, n),
            true,
            1.0,
            self.cov_next.as_mut_slice(),
        );
        for (i, &var) in self.input_variance.iter().enumerate() {
            if var > 0.0 && var.is_finite() {
                for c in 0..n {
                    for r in 0..n {
                        self.cov_next[(r, c)] += sys.g[(r, i)] * var * sys.g[(c, i)];
                    }
                }
            }
        }
        symmetrize(self.cov_next.as_mut_slice(), n);
        if !(self.state_next.iter().all(|v| v.is_finite())
            && self.cov_next.iter().all(|v| v.is_finite()))
        {
            return Err(StepError::Numerical {
                what: "the FDF's prediction over the gap is not finite",
            });
        }
        std::mem::swap(&mut self.state, &mut self.state_next);
        std::mem::swap(&mut self.cov, &mut self.cov_next);
        self.next_k = Some(k + 1);
        Ok(())
    }

    /// Forgets every sample: X̂ = x0, P = P0, an empty energy window, any next index.
    pub fn restart(&mut self) {
        self.state.copy_from(&self.x0);
        self.cov.copy_from(&self.p0);
        self.energy.clear();
        self.window_next = 0;
        self.held_u.fill(0.0);
        self.held_p.fill(0.0);
        self.input_moments.fill((0.0, 0.0));
        self.input_count = 0;
        self.input_variance.fill(0.0);
        self.next_k = None;
    }
}

impl Detector for FdfDetector {
    fn kind(&self) -> &'static str {
        "fdf"
    }

    fn describe(&self) -> String {
        let evaluation = match self.evaluation {
            Evaluation::Chi2 => "χ² test of rᵀΣ_r⁺r per sample".to_owned(),
            Evaluation::Energy { window } => {
                format!("windowed residual energy over {window} samples (survey eq. (12))")
            }
        };
        format!(
            "observer fault-detection filter (survey eq. (9)), {} residual rows, {evaluation}",
            self.v.nrows()
        )
    }

    fn memory(&self) -> usize {
        self.evaluation.memory()
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
        FdfDetector::step(self, sample, out)
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        FdfDetector::predict_only(self, k)
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        FdfDetector::restart(self);
        Ok(())
    }

    fn innovation_len(&self) -> usize {
        0
    }

    fn residual_len(&self) -> usize {
        self.v.nrows()
    }

    fn estimates_magnitude(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::innovation::InnovationFilter;
    use crate::model::Lpv;
    use crate::model::fault::{Column, Fault, Onset};
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

    /// The survey's DC motor (§ "Comparison of fault detection techniques"): F, G, H = I₂,
    /// J = 0, with the disturbance d ∈ ℝ³ white of unit covariance entering as
    /// W = E_d d, V_k = F_d d:
    /// - E_d = [−1.5537·σ_ω 0 0; 0 0 0]: the survey's E_ω with its σ_ω² = 0.0012;
    /// - F_d = [c σ_v 0; 0 0 σ_v]: the survey's sensor noise σ_v² = 0.0025 on each output,
    ///   and the first sensor also picking up the load disturbance (c = 0.03), so that
    ///   S = E_dF_dᵀ ≠ 0 and the cross-covariance terms are exercised.
    ///
    /// Q = E_dE_dᵀ, R = F_dF_dᵀ, S = E_dF_dᵀ.
    struct Motor {
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        e_d: DMatrix<f64>,
        f_d: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
        s: DMatrix<f64>,
    }

    fn motor() -> Motor {
        let (sigma_w, sigma_v, c) = (0.0012_f64.sqrt(), 0.0025_f64.sqrt(), 0.03);
        let e_d = DMatrix::from_row_slice(2, 3, &[-1.5537 * sigma_w, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let f_d = DMatrix::from_row_slice(2, 3, &[c, sigma_v, 0.0, 0.0, 0.0, sigma_v]);
        Motor {
            f: DMatrix::from_row_slice(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
            g: DMatrix::from_row_slice(2, 1, &[0.0047, 0.4512]),
            h: DMatrix::identity(2, 2),
            q: &e_d * e_d.transpose(),
            r: &f_d * f_d.transpose(),
            s: &e_d * f_d.transpose(),
            e_d,
            f_d,
        }
    }

    /// A gain that is not the optimal one, with F − LH stable.
    fn plain_gain() -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, &[0.1, 0.0, 0.0, 0.3])
    }

    fn detector(m: &Motor, gains: FdfGains, p0: DMatrix<f64>, ev: Evaluation) -> FdfDetector {
        let model = Lpv::lti(
            m.f.clone(),
            m.g.clone(),
            m.h.clone(),
            DMatrix::zeros(2, 1),
            m.q.clone(),
            m.r.clone(),
        )
        .unwrap();
        let faults = FaultDictionary::new(
            model.dims(),
            vec![Fault::output(
                "speed_sensor_bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
            )],
        )
        .unwrap();
        FdfDetector::new(Box::new(model), faults, gains, DVector::zeros(2), p0, ev)
            .unwrap()
            .with_cross_covariance(m.s.clone())
            .unwrap()
    }

    /// Samples (u, y) of the motor with u = 0.5, started at X_0 = `x0`, the disturbance
    /// scaled by `noise` (0 for noise-free data) and `bias(k)` added to the outputs.
    fn simulate(
        m: &Motor,
        len: usize,
        seed: u64,
        x0: DVector<f64>,
        noise: f64,
        bias: impl Fn(usize) -> [f64; 2],
    ) -> Vec<(f64, [f64; 2], DVector<f64>)> {
        let mut rng = Rng::new(seed);
        let mut x = x0;
        let mut data = Vec::with_capacity(len);
        for k in 0..len {
            let d = rng.normals(3) * noise;
            let y = &m.h * &x + &m.f_d * &d;
            let b = bias(k);
            data.push((0.5, [y[0] + b[0], y[1] + b[1]], x.clone()));
            x = &m.f * &x + &m.g * 0.5 + &m.e_d * &d;
        }
        data
    }

    /// Runs `det` over `data`, returning each step's output.
    fn run(det: &mut FdfDetector, data: &[(f64, [f64; 2], DVector<f64>)]) -> Vec<StepOutput> {
        let mut out = StepOutput::for_detector(det);
        data.iter()
            .enumerate()
            .map(|(k, (u, y, _))| {
                let sample = Sample {
                    k: k as u64,
                    u: &[*u],
                    y,
                    p: &[],
                };
                det.step(&sample, &mut out).unwrap();
                out.clone()
            })
            .collect()
    }

    fn optimal(m: &Motor) -> FdfGains {
        FdfGains::optimal(&m.f, &m.h, &m.q, &m.r, &m.s).unwrap()
    }

    /// Survey Table 1: the unified solution's L is the steady one-step predictor gain of
    /// glrmon's own Kalman filter run with the same Q, R, S (F K_k + SΣ_k⁻¹ of
    /// [`InnovationFilter::with_cross_covariance`]), and V = Σ^{−1/2} whitens that
    /// filter's innovation covariance: V Σ Vᵀ = I.
    #[test]
    fn table_1_the_optimal_gain_is_the_steady_kalman_predictor_gain() {
        let m = motor();
        let gains = optimal(&m);
        let mut sys = SystemMatrices::zeros(Dims {
            states: 2,
            inputs: 1,
            outputs: 2,
            signals: 0,
        });
        sys.f.copy_from(&m.f);
        sys.g.copy_from(&m.g);
        sys.h.copy_from(&m.h);
        sys.q.copy_from(&m.q);
        sys.r.copy_from(&m.r);
        let mut kf = InnovationFilter::new(DVector::zeros(2), DMatrix::identity(2, 2), 2)
            .unwrap()
            .with_cross_covariance(m.s.clone())
            .unwrap();
        let mut last = DMatrix::zeros(2, 2);
        for _ in 0..500 {
            last.copy_from(kf.predictor_gain());
            kf.measure(&sys, &[0.5], &[0.0, 0.0]).unwrap();
            kf.time_update(&sys, &[0.5]);
        }
        assert!(
            (kf.predictor_gain() - &last).amax() < 1e-15,
            "filter converged"
        );
        let gap = (kf.predictor_gain() - &gains.l).amax();
        assert!(
            gap <= 1e-9,
            "L {} vs Kalman {}",
            gains.l,
            kf.predictor_gain()
        );
        let whitened = &gains.v * kf.innovation_covariance() * gains.v.transpose();
        assert!((whitened - DMatrix::identity(2, 2)).amax() <= 1e-9);
        assert!(
            (&gains.v - gains.v.transpose()).amax() < 1e-12,
            "the symmetric root"
        );
        // The correlated noise matters: without S the gain differs.
        let no_s = FdfGains::optimal(&m.f, &m.h, &m.q, &m.r, &DMatrix::zeros(2, 2)).unwrap();
        assert!((no_s.l - &gains.l).amax() > 1e-3);
    }

    /// The recursion of the module documentation written with nalgebra's operators:
    /// r_k, Σ_r,k, X̂_{k+1} and P_{k+1} over the first steps from a P_0 far from steady.
    #[test]
    fn steps_match_the_dense_equations() {
        let m = motor();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::from_row_slice(3, 2, &[1.0, 0.5, 0.0, 2.0, -1.0, 1.0]),
        };
        let p0 = DMatrix::from_row_slice(2, 2, &[0.4, 0.1, 0.1, 0.3]);
        let mut det = detector(&m, gains.clone(), p0.clone(), Evaluation::Chi2);
        let data = simulate(&m, 5, 7, DVector::from_vec(vec![0.3, -0.2]), 1.0, |_| {
            [0.0; 2]
        });
        let (mut x, mut p) = (DVector::zeros(2), p0);
        let mut out = StepOutput::for_detector(&det);
        for (k, (u, y, _)) in data.iter().enumerate() {
            let sample = Sample {
                k: k as u64,
                u: &[*u],
                y,
                p: &[],
            };
            det.step(&sample, &mut out).unwrap();
            let e = DVector::from_column_slice(y) - &m.h * &x;
            let r = &gains.v * &e;
            let sigma = &gains.v * (&m.h * &p * m.h.transpose() + &m.r) * gains.v.transpose();
            let a = &m.f - &gains.l * &m.h;
            x = &m.f * &x + &m.g * *u + &gains.l * &e;
            p = &a * &p * a.transpose() + &m.q + &gains.l * &m.r * gains.l.transpose()
                - &m.s * gains.l.transpose()
                - &gains.l * m.s.transpose();
            assert!((&out.residual - &r).amax() < 1e-14);
            assert!((det.residual_covariance() - &sigma).amax() < 1e-14);
            assert!((det.state() - &x).amax() < 1e-14);
            assert!((det.error_covariance() - &p).amax() < 1e-14);
            // V has 3 rows and rank 2: Σ_r is singular, the χ² has 2 degrees of freedom
            // and is r's squared norm in the metric of Σ_r's range.
            let svd = sigma.clone().svd(true, true);
            let eps = 1e-9 * svd.singular_values.max();
            let pinv = svd.pseudo_inverse(eps).unwrap();
            let want = (r.transpose() * pinv * &r)[(0, 0)];
            assert_eq!(out.rank, 2);
            assert!((out.normalized_innovation - want).abs() < 1e-9 * want.max(1.0));
            assert_eq!(out.glr, Some(out.normalized_innovation));
            assert_eq!(out.onset, Some(k as u64));
        }
    }

    /// Noise-free, fault-free data from a state the filter does not know: X̂ → X and
    /// r → 0 to rounding, at the rate of the stable F − LH.
    #[test]
    fn noise_free_data_the_estimate_converges_and_the_residual_vanishes() {
        let m = motor();
        for gains in [
            optimal(&m),
            FdfGains {
                l: plain_gain(),
                v: DMatrix::identity(2, 2),
            },
        ] {
            let mut det = detector(&m, gains, DMatrix::identity(2, 2), Evaluation::Chi2);
            let x0 = DVector::from_vec(vec![1.0, -2.0]);
            let data = simulate(&m, 120, 1, x0.clone(), 0.0, |_| [0.0; 2]);
            let outs = run(&mut det, &data);
            assert!(outs[0].residual.amax() > 0.5, "the initial error shows");
            let last = outs.last().unwrap();
            assert!(last.residual.amax() < 1e-13, "{}", last.residual);
            let x_next = &m.f * &data.last().unwrap().2 + &m.g * 0.5;
            assert!((det.state() - x_next).amax() < 1e-13);
        }
    }

    /// Smith's doubling against the Lyapunov equation solved through Kronecker products,
    /// (I − A⊗A) vec P = vec C.
    #[test]
    fn error_covariance_solves_the_lyapunov_equation() {
        let m = motor();
        let l = plain_gain();
        let p = error_covariance(&m.f, &m.h, &l, &m.q, &m.r, &m.s).unwrap();
        let a = &m.f - &l * &m.h;
        let c = &m.q + &l * &m.r * l.transpose() - &m.s * l.transpose() - &l * m.s.transpose();
        let kron = a.kronecker(&a);
        let lhs = DMatrix::identity(4, 4) - kron;
        let vec_c = DVector::from_column_slice(c.as_slice());
        let vec_p = lhs.lu().solve(&vec_c).unwrap();
        let want = DMatrix::from_column_slice(2, 2, vec_p.as_slice());
        assert!(
            (&p - &want).amax() < 1e-15 * want.amax().max(1.0) * 10.0,
            "{p} {want}"
        );
    }

    /// Σ_r (steady state, [`residual_covariance`]) against the empirical covariance of r
    /// over 100 000 noisy fault-free samples, for a non-optimal L and a non-diagonal V:
    /// every entry within 3 % of √(Σ_ii Σ_jj). The detector's own Σ_r,k has reached the
    /// same matrix.
    #[test]
    fn residual_covariance_matches_the_empirical_one() {
        let m = motor();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 2.0]),
        };
        let sigma = residual_covariance(&m.f, &m.h, &gains, &m.q, &m.r, &m.s).unwrap();
        let mut det = detector(&m, gains, DMatrix::zeros(2, 2), Evaluation::Chi2);
        let len = 100_000;
        let data = simulate(&m, len, 11, DVector::zeros(2), 1.0, |_| [0.0; 2]);
        let outs = run(&mut det, &data);
        let mut empirical = DMatrix::zeros(2, 2);
        for o in &outs {
            empirical += &o.residual * o.residual.transpose();
        }
        empirical /= len as f64;
        let mut worst: f64 = 0.0;
        for i in 0..2 {
            for j in 0..2 {
                let scale = (sigma[(i, i)] * sigma[(j, j)]).sqrt();
                worst = worst.max((empirical[(i, j)] - sigma[(i, j)]).abs() / scale);
            }
        }
        assert!(
            worst < 0.03,
            "worst relative deviation {worst}: {empirical} vs {sigma}"
        );
        assert!((det.residual_covariance() - &sigma).amax() < 1e-12 * sigma.amax());
    }

    /// The χ² statistic under no fault: mean within 3 % of its degrees of freedom and
    /// exceedance rate of the α = 0.01 quantile within ±30 % of 0.01, over 50 000
    /// samples, for the optimal gains, a non-optimal L (coloured residual, same marginal
    /// law) and a 3-row V of rank 2 (pseudo-inverse, 2 degrees of freedom).
    #[test]
    fn chi2_statistic_has_its_law_under_no_fault() {
        let m = motor();
        let cases = [
            ("optimal", optimal(&m)),
            (
                "non-optimal L",
                FdfGains {
                    l: plain_gain(),
                    v: DMatrix::identity(2, 2),
                },
            ),
            (
                "rank-deficient V",
                FdfGains {
                    l: plain_gain(),
                    v: DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]),
                },
            ),
        ];
        let threshold = chi2_upper_quantile(2.0, 0.01).unwrap();
        for (seed, (name, gains)) in cases.into_iter().enumerate() {
            let mut det = detector(&m, gains, DMatrix::zeros(2, 2), Evaluation::Chi2);
            let len = 50_000;
            let data = simulate(&m, len, 100 + seed as u64, DVector::zeros(2), 1.0, |_| {
                [0.0; 2]
            });
            let outs = run(&mut det, &data);
            assert!(outs.iter().all(|o| o.rank == 2), "{name}");
            let mean = outs.iter().map(|o| o.glr.unwrap()).sum::<f64>() / len as f64;
            let rate =
                outs.iter().filter(|o| o.glr.unwrap() > threshold).count() as f64 / len as f64;
            assert!((mean - 2.0).abs() < 0.06, "{name}: mean {mean}");
            assert!((rate - 0.01).abs() < 0.003, "{name}: rate {rate}");
        }
    }

    /// The χ² is right from the first sample: X_0 drawn from N(0, P_0) with a P_0 much
    /// larger than the steady error covariance, 8 000 independent runs, the mean of
    /// rᵀΣ_r,k⁻¹r at each of the first 5 samples within 5 % of 2 (its standard error is
    /// 1.1 %). Normalised by the steady Σ_r instead, the first sample's mean would be
    /// tr(Σ_r⁻¹(P_0 + R)), over 100.
    #[test]
    fn chi2_is_exact_through_the_transient() {
        let m = motor();
        let p0 = DMatrix::from_row_slice(2, 2, &[0.5, 0.1, 0.1, 0.2]);
        let root = p0.clone().cholesky().unwrap().l();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 2),
        };
        let steady = residual_covariance(&m.f, &m.h, &gains, &m.q, &m.r, &m.s).unwrap();
        let with_steady = (steady.try_inverse().unwrap() * (&p0 + &m.r)).trace();
        assert!(with_steady > 100.0, "{with_steady}");
        let mut det = detector(&m, gains, p0, Evaluation::Chi2);
        let mut rng = Rng::new(5);
        let (runs, horizon) = (8_000, 5);
        let mut sums = [0.0; 5];
        for run_index in 0..runs {
            det.restart();
            let x0 = &root * rng.normals(2);
            let data = simulate(&m, horizon, 1_000 + run_index, x0, 1.0, |_| [0.0; 2]);
            for (k, o) in run(&mut det, &data).iter().enumerate() {
                sums[k] += o.normalized_innovation;
            }
        }
        for (k, s) in sums.iter().enumerate() {
            let mean = s / runs as f64;
            assert!((mean - 2.0).abs() < 0.1, "sample {k}: mean {mean}");
        }
    }

    /// An unstable F − LH, and L and V of the wrong shapes, are refused naming the
    /// condition.
    #[test]
    fn unstable_or_misshapen_designs_are_refused() {
        let m = motor();
        let build = |gains: FdfGains| {
            let model = Lpv::lti(
                m.f.clone(),
                m.g.clone(),
                m.h.clone(),
                DMatrix::zeros(2, 1),
                m.q.clone(),
                m.r.clone(),
            )
            .unwrap();
            let faults = FaultDictionary::new(
                model.dims(),
                vec![Fault::output(
                    "bias",
                    Onset::Step,
                    Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
                )],
            )
            .unwrap();
            let p0 = DMatrix::identity(2, 2);
            FdfDetector::new(
                Box::new(model),
                faults,
                gains,
                DVector::zeros(2),
                p0,
                Evaluation::Chi2,
            )
            .unwrap_err()
            .to_string()
        };
        let unstable = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 0.0]);
        let want = spectral_radius(&(&m.f - &unstable * &m.h));
        assert!(want > 1.2);
        let err = build(FdfGains {
            l: unstable,
            v: DMatrix::identity(2, 2),
        });
        assert!(
            err.contains("F − LH (the survey's A − LC) is not stable: spectral radius 1.22"),
            "{err}"
        );
        let err = build(FdfGains {
            l: DMatrix::zeros(2, 1),
            v: DMatrix::identity(2, 2),
        });
        assert!(
            err.starts_with("L: the observer gain L is 2×1, expected 2×2"),
            "{err}"
        );
        let err = build(FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 3),
        });
        assert!(err.starts_with("V: the residual weight V is 2×3"), "{err}");
        let err = build(FdfGains {
            l: plain_gain(),
            v: DMatrix::zeros(1, 2),
        });
        assert!(err.contains("V is zero"), "{err}");
        let model = Lpv::lti(
            m.f.clone(),
            m.g.clone(),
            m.h.clone(),
            DMatrix::zeros(2, 1),
            m.q.clone(),
            m.r.clone(),
        )
        .unwrap();
        let faults = FaultDictionary::new(
            model.dims(),
            vec![Fault::output(
                "bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
            )],
        )
        .unwrap();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 2),
        };
        let p0 = DMatrix::identity(2, 2);
        let ev = Evaluation::Energy { window: 0 };
        let err = FdfDetector::new(Box::new(model), faults, gains, DVector::zeros(2), p0, ev)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("the energy window needs at least 1 sample"),
            "{err}"
        );
        let err = FdfGains::optimal(
            &m.f,
            &m.h,
            &m.q,
            &DMatrix::zeros(2, 2),
            &DMatrix::zeros(2, 2),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("R = F_dF_dᵀ is not positive definite"),
            "{err}"
        );
        let err = FdfGains::optimal(&m.f, &m.h, &m.q, &m.r, &(&m.s * 100.0))
            .unwrap_err()
            .to_string();
        assert!(err.contains("[Q S; Sᵀ R] is not a covariance"), "{err}");
    }

    /// The spectral radius of a scaled rotation is its scale; of a triangular matrix,
    /// its largest diagonal modulus.
    #[test]
    fn spectral_radius_of_known_matrices() {
        let rotation = DMatrix::from_row_slice(2, 2, &[0.6, -0.8, 0.8, 0.6]) * 0.9;
        assert!((spectral_radius(&rotation) - 0.9).abs() < 1e-14);
        let triangular =
            DMatrix::from_row_slice(3, 3, &[0.5, 3.0, 1.0, 0.0, -1.5, 2.0, 0.0, 0.0, 0.2]);
        assert!((spectral_radius(&triangular) - 1.5).abs() < 1e-14);
        assert_eq!(spectral_radius(&DMatrix::zeros(0, 0)), 0.0);
    }

    /// A bias of 5σ_v on the speed sensor from sample 300: the optimal FDF's χ² at a
    /// false-alarm probability of 10⁻⁴ per sample raises no alarm before it and one
    /// within 3 samples of it, and so does the non-optimal one.
    #[test]
    fn a_sensor_bias_is_detected_within_a_few_samples() {
        let m = motor();
        let threshold = chi2_upper_quantile(2.0, 1e-4).unwrap();
        for gains in [
            optimal(&m),
            FdfGains {
                l: plain_gain(),
                v: DMatrix::identity(2, 2),
            },
        ] {
            let mut det = detector(&m, gains, DMatrix::zeros(2, 2), Evaluation::Chi2);
            let onset = 300;
            let data = simulate(&m, 340, 21, DVector::zeros(2), 1.0, |k| {
                [0.0, if k >= onset { 0.25 } else { 0.0 }]
            });
            let outs = run(&mut det, &data);
            let first = outs
                .iter()
                .position(|o| o.glr.unwrap() > threshold)
                .unwrap();
            assert!(first >= onset && first < onset + 3, "alarm at {first}");
        }
    }

    /// Lag-1 autocorrelation of the residual's components over 100 000 fault-free
    /// samples: with the optimal gains every entry of the normalised lag-1 covariance is
    /// within ±3/√N of 0 (white residual, Table 1); with the non-optimal L it is the
    /// theoretical V H ((F − LH) P Hᵀ + S − L R) Vᵀ (normalised) within ±4/√N, and that
    /// is far from 0.
    #[test]
    fn the_optimal_residual_is_white_and_the_other_is_not() {
        let m = motor();
        let len = 100_000;
        let bound = 3.0 / (len as f64).sqrt();
        let lag1 = |gains: FdfGains, seed| {
            let mut det = detector(&m, gains, DMatrix::zeros(2, 2), Evaluation::Chi2);
            let data = simulate(&m, len, seed, DVector::zeros(2), 1.0, |_| [0.0; 2]);
            let outs = run(&mut det, &data);
            let (mut c0, mut c1) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 2));
            for w in outs.windows(2) {
                c0 += &w[0].residual * w[0].residual.transpose();
                c1 += &w[1].residual * w[0].residual.transpose();
            }
            DMatrix::from_fn(2, 2, |i, j| c1[(i, j)] / (c0[(i, i)] * c0[(j, j)]).sqrt())
        };
        let white = lag1(optimal(&m), 31);
        assert!(white.amax() < bound, "{white} vs ±{bound}");
        let l = plain_gain();
        let gains = FdfGains {
            l: l.clone(),
            v: DMatrix::identity(2, 2),
        };
        let coloured = lag1(gains, 32);
        let p = error_covariance(&m.f, &m.h, &l, &m.q, &m.r, &m.s).unwrap();
        let a = &m.f - &l * &m.h;
        let cov1 = &m.h * (&a * &p * m.h.transpose() + &m.s - &l * &m.r);
        let cov0 = &m.h * &p * m.h.transpose() + &m.r;
        let theory = DMatrix::from_fn(2, 2, |i, j| {
            cov1[(i, j)] / (cov0[(i, i)] * cov0[(j, j)]).sqrt()
        });
        assert!(
            (&coloured - &theory).amax() < 4.0 / (len as f64).sqrt(),
            "{coloured} vs {theory}"
        );
        assert!(theory.amax() > 10.0 * bound, "{theory}");
    }

    /// The unified solution's G_rd is co-inner: ‖G_rd‖_∞ = 1, so J_th = δ_d (survey eq.
    /// (19)); every singular value of G_rd(e^{jω}) is 1, checked densely at a few ω.
    #[test]
    fn the_optimal_disturbance_gain_is_one() {
        let m = motor();
        let gains = optimal(&m);
        let gain = disturbance_gain(&m.f, &m.h, &gains, &m.e_d, &m.f_d).unwrap();
        assert!((gain - 1.0).abs() < 1e-9, "{gain}");
        let jth = energy_threshold(&m.f, &m.h, &gains, &m.e_d, &m.f_d, 0.7).unwrap();
        assert!((jth - 0.7).abs() < 1e-9);
        let c = |x: &DMatrix<f64>| x.map(|v| Complex::new(v, 0.0));
        for w in [0.0, 0.4, 1.3, 3.0] {
            let z = Complex::new(f64::cos(w), f64::sin(w));
            let a = &m.f - &gains.l * &m.h;
            let resolvent = (DMatrix::identity(2, 2).map(|v| Complex::new(v, 0.0)) * z - c(&a))
                .try_inverse()
                .unwrap();
            let g = c(&gains.v) * (resolvent * c(&(&m.e_d - &gains.l * &m.f_d)) + c(&m.f_d));
            let gg = &g * g.adjoint();
            let off = gg - DMatrix::identity(2, 2).map(|v| Complex::new(v, 0.0));
            assert!(off.iter().all(|z| z.norm() < 1e-9), "{off}");
        }
        assert!(energy_threshold(&m.f, &m.h, &gains, &m.e_d, &m.f_d, -1.0).is_err());
    }

    /// A first-order plant, G_rd(z) = b/(z − a) + f_d with a = F − L, b = e_d − L f_d:
    /// |G_rd(e^{jω})| is monotone in cos ω, so ‖G_rd‖_∞ is its value at ω = 0 or π. A
    /// constant disturbance of energy δ² over a long window through the detector
    /// reaches J_k ≈ ‖G_rd‖_∞·δ and never exceeds it.
    #[test]
    fn disturbance_gain_of_a_first_order_plant() {
        let (f, l, e_d, f_d) = (0.9, 0.5, 1.0, 0.3);
        let one = |x| DMatrix::from_element(1, 1, x);
        let gains = FdfGains {
            l: one(l),
            v: one(1.0),
        };
        let (a, b) = (f - l, e_d - l * f_d);
        let want = f64::max((b / (1.0 - a) + f_d).abs(), (b / (-1.0 - a) + f_d).abs());
        let gain = disturbance_gain(&one(f), &one(1.0), &gains, &one(e_d), &one(f_d)).unwrap();
        assert!((gain - want).abs() < 1e-12, "{gain} vs {want}");
        let window = 4_000;
        let delta = 2.0;
        let model = Lpv::lti(
            one(f),
            DMatrix::zeros(1, 0),
            one(1.0),
            DMatrix::zeros(1, 0),
            one(0.0),
            one(0.0),
        )
        .unwrap();
        let faults = FaultDictionary::new(
            model.dims(),
            vec![Fault::output(
                "bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![1.0])),
            )],
        )
        .unwrap();
        let mut det = FdfDetector::new(
            Box::new(model),
            faults,
            gains,
            DVector::zeros(1),
            DMatrix::zeros(1, 1),
            Evaluation::Energy { window },
        )
        .unwrap();
        let d = delta / (window as f64).sqrt();
        let (mut x, mut last) = (0.0, None);
        let mut out = StepOutput::for_detector(&det);
        for k in 0..window {
            let y = x + f_d * d;
            det.step(
                &Sample {
                    k: k as u64,
                    u: &[],
                    y: &[y],
                    p: &[],
                },
                &mut out,
            )
            .unwrap();
            x = f * x + e_d * d;
            last = out.glr;
        }
        let j = last.unwrap();
        assert!(
            j <= gain * delta && j > 0.99 * gain * delta,
            "{j} vs {}",
            gain * delta
        );
    }

    /// The energy evaluation: J_k is the root of the last w residual squares, `None`
    /// before w samples, with onset the oldest sample in the window, a missing sample
    /// bridged by prediction counted out of it.
    #[test]
    fn energy_evaluation_over_a_window_with_a_gap() {
        let m = motor();
        let w = 5;
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 2),
        };
        let mut det = detector(
            &m,
            gains,
            DMatrix::zeros(2, 2),
            Evaluation::Energy { window: w },
        );
        assert_eq!(det.memory(), w);
        let data = simulate(&m, 30, 3, DVector::zeros(2), 1.0, |_| [0.0; 2]);
        let mut out = StepOutput::for_detector(&det);
        let mut seen: Vec<(u64, f64)> = Vec::new();
        for (k, (u, y, _)) in data.iter().enumerate() {
            let k = k as u64;
            if k == 12 {
                det.predict_only(k).unwrap();
                continue;
            }
            det.step(
                &Sample {
                    k,
                    u: &[*u],
                    y,
                    p: &[],
                },
                &mut out,
            )
            .unwrap();
            seen.push((k, out.residual.norm_squared()));
            if seen.len() < w {
                assert_eq!(out.glr, None);
                assert_eq!(out.onset, None);
            } else {
                let tail = &seen[seen.len() - w..];
                let want = tail.iter().map(|(_, s)| s).sum::<f64>().sqrt();
                assert!((out.glr.unwrap() - want).abs() < 1e-12 * want);
                assert_eq!(out.onset, Some(tail[0].0));
            }
        }
        assert_eq!(out.onset, Some(25));
    }

    /// A time-varying model (F_k = F_0 + p(k)·F_1) is evaluated on every sample: the
    /// detector follows the dense recursion with each sample's F_k, including across a
    /// missing sample predicted with the held signal.
    #[test]
    fn a_time_varying_model_is_evaluated_on_every_sample() {
        use crate::model::LpvMatrix;
        let m = motor();
        let f1 = DMatrix::from_row_slice(2, 2, &[0.1, 0.0, 0.05, -0.2]);
        let constant = |x: &DMatrix<f64>| LpvMatrix::constant(x.clone());
        let model = Lpv::new(
            LpvMatrix::new(m.f.clone(), vec![(0, f1.clone())]).unwrap(),
            constant(&m.g),
            constant(&m.h),
            constant(&DMatrix::zeros(2, 1)),
            constant(&m.q),
            constant(&m.r),
            1,
        )
        .unwrap();
        assert!(!model.is_constant());
        let faults = FaultDictionary::new(
            model.dims(),
            vec![Fault::output(
                "bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
            )],
        )
        .unwrap();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 2),
        };
        let p0 = DMatrix::identity(2, 2) * 0.2;
        let mut det = FdfDetector::new(
            Box::new(model),
            faults,
            gains.clone(),
            DVector::zeros(2),
            p0.clone(),
            Evaluation::Chi2,
        )
        .unwrap();
        let (mut x, mut p) = (DVector::zeros(2), p0);
        let mut out = StepOutput::for_detector(&det);
        let mut held = 0.0;
        for k in 0..20_u64 {
            let signal = (0.7 * k as f64).sin();
            let f_k = |s: f64| &m.f + &f1 * s;
            if k == 9 {
                det.predict_only(k).unwrap();
                let f = f_k(held);
                x = &f * &x + &m.g * 0.5;
                p = &f * &p * f.transpose() + &m.q;
            } else {
                let y = [0.1 * signal, 0.05];
                let sample = Sample {
                    k,
                    u: &[0.5],
                    y: &y,
                    p: &[signal],
                };
                det.step(&sample, &mut out).unwrap();
                let f = f_k(signal);
                let e = DVector::from_column_slice(&y) - &m.h * &x;
                let a = &f - &gains.l * &m.h;
                assert!((&out.residual - &e).amax() < 1e-14);
                x = &f * &x + &m.g * 0.5 + &gains.l * &e;
                p = &a * &p * a.transpose() + &m.q + &gains.l * &m.r * gains.l.transpose();
                held = signal;
            }
            assert!((det.state() - &x).amax() < 1e-14, "sample {k}");
            assert!((det.error_covariance() - &p).amax() < 1e-14, "sample {k}");
        }
    }

    /// A missing sample is predicted with the last input and no correction, P growing by
    /// F P Fᵀ + Q + G σ²_u Gᵀ (σ²_u the inputs' running variance); malformed and
    /// out-of-order samples are refused with the state unchanged; restart forgets all.
    #[test]
    fn predict_only_refusals_and_restart() {
        let m = motor();
        let gains = FdfGains {
            l: plain_gain(),
            v: DMatrix::identity(2, 2),
        };
        let mut det = detector(&m, gains, DMatrix::identity(2, 2) * 0.1, Evaluation::Chi2);
        assert_eq!(det.kind(), "fdf");
        assert_eq!((det.innovation_len(), det.residual_len()), (0, 2));
        assert!(!det.estimates_magnitude());
        assert!(matches!(
            det.predict_only(0),
            Err(StepError::OutOfOrder { .. })
        ));
        let mut out = StepOutput::for_detector(&det);
        let inputs = [0.2, 0.6, 0.4];
        for (k, u) in inputs.iter().enumerate() {
            let sample = Sample {
                k: k as u64,
                u: &[*u],
                y: &[0.01, -0.02],
                p: &[],
            };
            det.step(&sample, &mut out).unwrap();
        }
        let (x, p) = (det.state().clone(), det.error_covariance().clone());
        let bad = [
            Sample {
                k: 3,
                u: &[0.5],
                y: &[0.0],
                p: &[],
            },
            Sample {
                k: 3,
                u: &[f64::NAN],
                y: &[0.0, 0.0],
                p: &[],
            },
            Sample {
                k: 4,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
        ];
        for sample in &bad {
            assert!(det.step(sample, &mut out).is_err());
            assert_eq!(det.state(), &x);
            assert_eq!(det.next_index(), Some(3));
        }
        assert!(matches!(
            det.predict_only(4),
            Err(StepError::OutOfOrder { .. })
        ));
        det.predict_only(3).unwrap();
        let variance = 0.04; // sample variance of 0.2, 0.6, 0.4
        let want_x = &m.f * &x + &m.g * 0.4;
        let want_p = &m.f * &p * m.f.transpose() + &m.q + &m.g * variance * m.g.transpose();
        assert!((det.state() - want_x).amax() < 1e-15);
        assert!((det.error_covariance() - want_p).amax() < 1e-15);
        assert_eq!(det.next_index(), Some(4));
        Detector::restart(&mut det).unwrap();
        assert_eq!(det.next_index(), None);
        assert_eq!(det.state(), &DVector::zeros(2));
        assert_eq!(det.error_covariance(), &(DMatrix::identity(2, 2) * 0.1));
        let sample = Sample {
            k: 77,
            u: &[0.5],
            y: &[0.0, 0.0],
            p: &[],
        };
        det.step(&sample, &mut out).unwrap();
        assert_eq!(det.next_index(), Some(78));
    }
}
