//! The unknown-input observer (UIO): a full-order observer whose state estimate, and
//! so its residual, does not depend on an unknown input d_k, for LTI plants.
//!
//! Ahmad & Mohd-Mokhtar 2021 survey the idea (§ "UIO-based fault detection": the
//! unknown input is decoupled from the state estimate, so the residual is free of it);
//! the observer is the discrete full-order UIO of Chen, Patton & Zhang 1996 ("Design of
//! unknown input observers and robust fault detection filters", Int. J. Control 63(1))
//! and Chen & Patton 1999 (*Robust model-based fault diagnosis for dynamic systems*,
//! ch. 3). Its residual is the output error of the survey's eq. (9) with V = I, turned
//! into the decision statistic by eq. (17)'s χ² test (rᵀΣ_r⁺r) or the windowed energy of
//! eqs. (12)-(13) ([`Evaluation`]).
//!
//! # Letters
//!
//! The survey's eqs. (1)-(2), x(k+1) = Ax + Bu + E_d d + E_f f, y = Cx + Du + F_d d +
//! F_f f, are written with Zhang & Basseville 2014's letters: A → F, B → G, C → H,
//! D → J, E_d → E (n×q), F_d = 0 (d enters the state only), and the noises of the
//! model, W_k ~ N(0, Q), V_k ~ N(0, R), uncorrelated (S = 0):
//!
//! ```text
//! X_{k+1} = F X_k + G U_k + E d_k + W_k
//! Y_k     = H X_k + J U_k + V_k,          Y'_k = Y_k − J U_k
//! ```
//!
//! Chen & Patton's own H, the observer's feed-through of the output, is written 𝐇
//! (bold, n×p) to keep H for the output matrix.
//!
//! # The observer
//!
//! ```text
//! z_{k+1} = N z_k + T G U_k + K Y'_k,     X̂_k = z_k + 𝐇 Y'_k,     r_k = Y'_k − H X̂_k
//! (𝐇H − I)E = 0,  T = I − 𝐇H,  N = TF − K₁H,  K₂ = N𝐇,  K = K₁ + K₂,  N stable
//! ```
//!
//! 𝐇 = E(HE)⁺ (E[(HE)ᵀHE]⁻¹(HE)ᵀ when HE has full column rank) solves (𝐇H − I)E = 0
//! exactly when rank(HE) = rank(E), the matching condition: every direction d can push
//! the state in must show in the outputs. E may have dependent columns: 𝐇 is computed as
//! Ê(HÊ)⁺ with Ê = E's columns scaled to unit norm, the same matrix when E has full
//! column rank, and one with 𝐇HE = E in every case.
//!
//! # Error dynamics
//!
//! With e_k = X_k − X̂_k, TE = 0 removes d and the choice of N and K₂ removes X_k:
//!
//! ```text
//! e_{k+1} = N e_k + T W_k − K₁ V_k − 𝐇 V_{k+1},        r_k = H e_k + V_k
//! ```
//!
//! e_k holds −𝐇V_k, which r_k's own V_k meets; the error of z, ξ_k = TX_k − z_k =
//! e_k + 𝐇V_k, depends on the noises before k only:
//!
//! ```text
//! ξ_{k+1} = N ξ_k + T W_k − K V_k,      r_k = H ξ_k + (I − Π) V_k,      Π = H𝐇 = HE(HE)⁺
//! P = N P Nᵀ + T Q Tᵀ + K R Kᵀ,        Σ_r = H P Hᵀ + (I − Π) R (I − Π)
//! ```
//!
//! Π is the orthogonal projector on range(HE). P and Σ_r, the steady-state covariances
//! under the noise model, are computed once ([`UioDesign`]; a test checks Σ_r against the
//! covariance of e_k with its V_{k+1} terms and against simulated residuals).
//!
//! # The gain K₁
//!
//! Chen & Patton leave K₁ to the designer (any K₁ with N stable: pole placement). Here
//! it is the one that makes the residual as good as the noise model allows. With
//! K₂ = N𝐇 substituted, ξ obeys
//!
//! ```text
//! ξ_{k+1} = TF ξ_k + (T W_k − TF𝐇 V_k) − K₁ (H ξ_k + (I − Π) V_k)
//! ```
//!
//! the error of a one-step predictor of TX_k from the outputs d cannot reach, U₂ᵀY'_k =
//! U₂ᵀH·TX_k + U₂ᵀV_k (U₂: an orthonormal basis of range(HE)^⊥, p × (p − rank HE)),
//! with correlated process and measurement noises
//!
//! ```text
//! Q̄ = TQTᵀ + TF𝐇R𝐇ᵀFᵀTᵀ,    R̃ = U₂ᵀRU₂,    S̃ = E[(TW − TF𝐇V)(U₂ᵀV)ᵀ] = −TF𝐇RU₂
//! ```
//!
//! K₁ = K̃U₂ᵀ with K̃ = (TF P H̃ᵀ + S̃)(H̃ P H̃ᵀ + R̃)⁻¹ the steady-state Kalman predictor gain
//! of that problem (H̃ = U₂ᵀH; P the stabilising solution of its Riccati equation, solved
//! by the structure-preserving doubling algorithm) gives the least error covariance P of
//! every K₁, and makes U₂ᵀr_k the innovation of those outputs: white, N(0, Σ̃ = H̃PH̃ᵀ + R̃).
//! Since ΠHT = 0 and K̃'s columns lie in range(T) (TFPH̃ᵀ and S̃ both begin with T),
//! Πr_k = 0: Σ_r = U₂Σ̃U₂ᵀ is singular in the directions of HE and has rank
//! p − rank(HE), the χ² degrees of freedom (rᵀΣ_r⁺r, Σ_r⁺ from Σ_r's eigenvalues above
//! [`RESIDUAL_RANK_TOLERANCE`] of the largest). Πr_k = 0 holds from the first sample on
//! (z₀ = Tx̂₀, and N, TG and K map into range(T)); the start only sets ξ's covariance,
//! that of T(X₀ − x̂₀), which then tends to P.
//!
//! # Conditions
//!
//! Checked at construction, each named in its [`ModelError::Condition`] ([`UioCondition`],
//! [`check_uio_conditions`] for the structural ones alone): the matching condition
//! rank(HE) = rank(E); a residual left, rank(HE) < p; (H, TF) detectable (PBH: rank
//! [λI − TF; H] = n for every eigenvalue |λ| ≥ 1 of TF); R̃ positive definite; the
//! Riccati equation converging; N stable (spectral radius below 1).
//!
//! # The Kitanidis filter
//!
//! glrmon's GLR decouples an unknown input with the Kitanidis filter
//! ([`crate::filter::decoupling`]). The same in both: they need the matching condition
//! (the Kitanidis filter in the stricter form rank(HE) = q, E of full column rank); their
//! estimates are unbiased whatever d is, with no model of d; they spend rank(HE) output
//! directions on d and leave p − rank(HE) degrees of freedom to the residual; neither can
//! bridge a missing sample (d moves the state unobserved over it). What differs: the
//! Kitanidis filter is the minimum-variance unbiased filter at every sample: its gain
//! K̄_k is time-varying, from a Riccati recursion started at (x̂₀, P₀), valid for LPV
//! models and a time-varying E_k; the part of K̄_k that takes up d,
//! E[(HE)ᵀΣ_k⁻¹HE]⁻¹(HE)ᵀΣ_k⁻¹, is 𝐇 with the innovation covariance as weight; and its
//! innovation is whitened at each sample into z_k = Q₂ᵀL_k⁻¹ε_k ~ N(0, I_{p−q}). The UIO
//! is a fixed-gain observer for an LTI model: its matrices are computed once, 𝐇 is the
//! unweighted pseudo-inverse (any 𝐇 with 𝐇HE = E would decouple), its poles eig(N) are
//! the designer's through K₁, a step is three matrix-vector products with no covariance
//! recursion, and its residual is the raw p-vector with the singular covariance Σ_r.
//! With K₁ from the Riccati equation above, both residuals carry the same information
//! (the innovation of the outputs d cannot reach, given everything before): in steady
//! state rᵀΣ_r⁺r equals the Kitanidis filter's ‖z_k‖² (a test finds them equal to 10⁻¹¹ relative).
//! With any other stabilising K₁ the UIO residual is still free of d, but correlated in
//! time and its error covariance P larger.

use nalgebra::{Complex, DMatrix, DVector};

use crate::error::{ModelError, StepError, UNKNOWN_INPUT_RANK_TOLERANCE};
use crate::linalg::{gemv, jacobi_eigen};
use crate::model::fault::FaultDictionary;
use crate::model::{Dims, Signals, StateSpace, SystemMatrices};

use super::evaluation::{EnergyWindow, Evaluation};
use super::{Detector, Sample, StepOutput};

/// Eigenvalues of Σ_r at or below this fraction of the largest count as zero: Σ_r⁺ and
/// the χ² degrees of freedom are taken on the range of the others.
pub const RESIDUAL_RANK_TOLERANCE: f64 = 1e-9;

/// Relative threshold of the detectability test: a mode λ of TF is unobservable when
/// the smallest singular value of [λI − TF; H·s] is at most this times s =
/// max(‖TF‖_F, 1), H being scaled to that norm.
const DETECTABILITY_TOLERANCE: f64 = 1e-8;

/// Modes of TF at least this close to the unit circle count as not stable.
const UNIT_CIRCLE_MARGIN: f64 = 1e-9;

/// The conditions a UIO design must meet, each named in the [`ModelError::Condition`]
/// that reports its failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UioCondition {
    /// rank(HE) = rank(E): 𝐇 with 𝐇HE = E exists.
    Matching,
    /// rank(HE) < p: some output direction is free of d, so there is a residual.
    Residual,
    /// (H, TF) detectable: some K₁ makes N = TF − K₁H stable.
    Detectability,
    /// R̃ = U₂ᵀRU₂ positive definite: the outputs free of d are measured with noise,
    /// which the Riccati equation of K₁ needs.
    ResidualNoise,
    /// The Riccati equation of K₁ converges to a solution (doubling).
    Riccati,
    /// N = TF − K₁H has spectral radius below 1.
    Stability,
}

impl UioCondition {
    /// The condition's name, as [`ModelError::Condition`] carries it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Matching => "the matching condition rank(HE) = rank(E)",
            Self::Residual => "the residual condition rank(HE) < p",
            Self::Detectability => "the detectability of (H, TF)",
            Self::ResidualNoise => "the positive definiteness of R on the outputs free of d",
            Self::Riccati => "the convergence of the Riccati equation of K₁",
            Self::Stability => "the stability of N = TF − K₁H",
        }
    }

    /// The condition an error of [`UioDesign::new`], [`UioDetector::new`] or
    /// [`check_uio_conditions`] reports as failing (`None` for other errors).
    #[must_use]
    pub fn of(error: &ModelError) -> Option<Self> {
        let ModelError::Condition { condition, .. } = error else {
            return None;
        };
        [
            Self::Matching,
            Self::Residual,
            Self::Detectability,
            Self::ResidualNoise,
            Self::Riccati,
            Self::Stability,
        ]
        .into_iter()
        .find(|c| c.name() == *condition)
    }

    fn fails(self, detail: String) -> ModelError {
        ModelError::Condition {
            condition: self.name(),
            detail,
        }
    }
}

/// Checks the existence conditions of a UIO for F (n×n), H (p×n) and E (n×q) alone: the
/// matching condition, a residual left, and the detectability of (H, TF).
///
/// # Errors
/// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for malformed matrices;
/// [`ModelError::Condition`] naming the first condition that fails
/// ([`UioCondition::of`] tells which).
pub fn check_uio_conditions(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    e: &DMatrix<f64>,
) -> Result<(), ModelError> {
    check_shapes(f, h, e)?;
    structure(f, h, e).map(|_| ())
}

fn check_shapes(f: &DMatrix<f64>, h: &DMatrix<f64>, e: &DMatrix<f64>) -> Result<(), ModelError> {
    let n = f.nrows();
    let dim = |what, detail| Err(ModelError::Dimension { what, detail });
    if f.ncols() != n || n == 0 {
        return dim(
            "F",
            format!("F must be square and non-empty, got {n}×{}", f.ncols()),
        );
    }
    if h.ncols() != n || h.nrows() == 0 {
        return dim(
            "H",
            format!("H is {}×{} but F is {n}×{n}", h.nrows(), h.ncols()),
        );
    }
    if e.nrows() != n || e.ncols() == 0 {
        return dim(
            "E",
            format!(
                "E is {}×{}, expected {n} rows and at least one column",
                e.nrows(),
                e.ncols()
            ),
        );
    }
    for (what, m) in [("F", f), ("H", h), ("E", e)] {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what });
        }
    }
    Ok(())
}

/// The decoupling structure: 𝐇, T, U₂, ranks.
struct Structure {
    rank_he: usize,
    h_bold: DMatrix<f64>,
    t: DMatrix<f64>,
    /// Orthonormal basis of range(HE)^⊥ (p × (p − rank HE)).
    u2: DMatrix<f64>,
}

/// Ranks of E and HE, 𝐇 = Ê(HÊ)⁺, T, U₂, and the detectability of (H, TF).
///
/// Ê is E with its columns scaled to unit norm (𝐇HÊ = Ê gives 𝐇HE = E; the ranks then
/// do not depend on the units of d): rank(E) counts the singular values of Ê above
/// [`UNKNOWN_INPUT_RANK_TOLERANCE`], rank(HE) those of HÊ above it times ‖H‖_F, the
/// test the Kitanidis filter's Assumption (iv) uses.
fn structure(
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    e: &DMatrix<f64>,
) -> Result<Structure, ModelError> {
    let (n, p, q) = (f.nrows(), h.nrows(), e.ncols());
    let mut e_hat = e.clone();
    for mut c in e_hat.column_iter_mut() {
        let norm = c.norm();
        if norm > 0.0 {
            c /= norm;
        }
    }
    let tol = UNKNOWN_INPUT_RANK_TOLERANCE;
    let rank_e = e_hat
        .clone()
        .svd(false, false)
        .singular_values
        .iter()
        .filter(|&&s| s > tol)
        .count();
    let he = h * &e_hat;
    // [HÊ 0]: the same singular values as HÊ and a complete p×p U.
    let mut padded = DMatrix::zeros(p, q + p);
    padded.columns_mut(0, q).copy_from(&he);
    let svd = padded.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        unreachable!("the SVD was asked for U and Vᵀ");
    };
    let h_norm = h.norm();
    let rank_he = svd
        .singular_values
        .iter()
        .filter(|&&s| s > tol * h_norm)
        .count();
    if rank_he < rank_e {
        return Err(UioCondition::Matching.fails(format!(
            "rank(HE) = {rank_he} < rank(E) = {rank_e} (singular values of HE with E's \
             columns scaled to unit norm above {tol:.0e}·‖H‖_F): some direction the unknown \
             input moves the state in is not seen by the outputs, so no 𝐇 with 𝐇HE = E exists; \
             measure that direction or leave it out of E"
        )));
    }
    if rank_he >= p {
        return Err(UioCondition::Residual.fails(format!(
            "rank(HE) = {rank_he} = p: the unknown input reaches every output direction, so \
             none is left for a residual; more outputs than independent unknown-input \
             directions are needed"
        )));
    }
    // 𝐇 = Ê(HÊ)⁺ = Ê Σ_i v_i σ_i⁻¹ u_iᵀ over the first rank(HE) singular triplets.
    let mut pinv = DMatrix::zeros(q, p);
    for i in 0..rank_he {
        let s = svd.singular_values[i];
        for c in 0..p {
            for r in 0..q {
                pinv[(r, c)] += v_t[(i, r)] * u[(c, i)] / s;
            }
        }
    }
    let h_bold = &e_hat * pinv;
    let t = DMatrix::identity(n, n) - &h_bold * h;
    let u2 = u.columns(rank_he, p - rank_he).into_owned();
    let tf = &t * f;
    if let Some(mode) = undetectable_mode(&tf, h)? {
        return Err(UioCondition::Detectability.fails(format!(
            "the mode λ = {:.6}{:+.6}i of TF (|λ| = {:.6} ≥ 1) is not seen by H (rank \
             [λI − TF; H] < n), so no K₁ makes N = TF − K₁H stable; TF = (I − 𝐇H)F keeps of F \
             what the unknown input cannot reach, and an output must observe this mode \
             through it",
            mode.re,
            mode.im,
            mode.norm()
        )));
    }
    Ok(Structure {
        rank_he,
        h_bold,
        t,
        u2,
    })
}

/// The eigenvalues of a real square matrix (Schur), or the detectability condition as
/// failing when the decomposition does not converge.
fn eigenvalues(a: &DMatrix<f64>, condition: UioCondition) -> Result<Vec<Complex<f64>>, ModelError> {
    let schur =
        nalgebra::linalg::Schur::try_new(a.clone(), f64::EPSILON, 10_000).ok_or_else(|| {
            condition.fails("the eigenvalues could not be computed (no Schur convergence)".into())
        })?;
    Ok(schur.complex_eigenvalues().iter().copied().collect())
}

/// A mode λ of A with |λ| ≥ 1 that H does not see (PBH test), if any.
fn undetectable_mode(
    a: &DMatrix<f64>,
    h: &DMatrix<f64>,
) -> Result<Option<Complex<f64>>, ModelError> {
    let (n, p) = (a.nrows(), h.nrows());
    let scale = a.norm().max(1.0);
    let h_scale = if h.norm() > 0.0 {
        scale / h.norm()
    } else {
        1.0
    };
    for lambda in eigenvalues(a, UioCondition::Detectability)? {
        if lambda.norm() < 1.0 - UNIT_CIRCLE_MARGIN {
            continue;
        }
        let pbh = DMatrix::<Complex<f64>>::from_fn(n + p, n, |i, j| {
            if i < n {
                let d = if i == j {
                    lambda
                } else {
                    Complex::new(0.0, 0.0)
                };
                d - Complex::new(a[(i, j)], 0.0)
            } else {
                Complex::new(h[(i - n, j)] * h_scale, 0.0)
            }
        });
        let smallest = pbh
            .svd(false, false)
            .singular_values
            .iter()
            .fold(f64::INFINITY, |m, &s| m.min(s));
        if smallest <= DETECTABILITY_TOLERANCE * scale {
            return Ok(Some(lambda));
        }
    }
    Ok(None)
}

fn symmetrize(m: &mut DMatrix<f64>) {
    let t = m.transpose();
    *m += t;
    *m *= 0.5;
}

/// The steady-state Kalman predictor gain K of x_{k+1} = A x_k + w_k, y_k = C x_k + v_k with
/// cov[w; v] = [Q S; Sᵀ R]: P solving P = APAᵀ + Q − KΣKᵀ, Σ = CPCᵀ + R, K = (APCᵀ +
/// S)Σ⁻¹.
///
/// S is removed first (Ā = A − SR⁻¹C, Q̂ = Q − SR⁻¹Sᵀ), and the Riccati equation of
/// (Ā, C, Q̂, R) is solved by the structure-preserving doubling algorithm (Chu, Fan &
/// Lin 2005), whose iterates converge quadratically to the stabilising solution:
/// A₀ = Āᵀ, G₀ = CᵀR⁻¹C, H₀ = Q̂, W = (I + G_jH_j)⁻¹, A_{j+1} = A_jWA_j,
/// G_{j+1} = G_j + A_jWG_jA_jᵀ, H_{j+1} = H_j + A_jᵀH_jWA_j → P.
fn steady_predictor(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: &DMatrix<f64>,
) -> Result<DMatrix<f64>, ModelError> {
    let n = a.nrows();
    let riccati = |detail: String| UioCondition::Riccati.fails(detail);
    let r_inv = r
        .clone()
        .cholesky()
        .ok_or_else(|| {
            UioCondition::ResidualNoise.fails(
                "U₂ᵀRU₂ is not positive definite: every output direction free of the \
                 unknown input needs measurement noise (R > 0 on range(HE)^⊥)"
                    .into(),
            )
        })?
        .inverse();
    let a_bar = a - s * &r_inv * c;
    let mut q_hat = q - s * &r_inv * s.transpose();
    symmetrize(&mut q_hat);
    let mut aj = a_bar.transpose();
    let mut gj = c.transpose() * &r_inv * c;
    symmetrize(&mut gj);
    let mut hj = q_hat;
    let identity = DMatrix::<f64>::identity(n, n);
    let mut converged = false;
    for _ in 0..100 {
        let w = (&identity + &gj * &hj)
            .lu()
            .try_inverse()
            .ok_or_else(|| riccati("I + G_jH_j became singular in the doubling".into()))?;
        let aw = &aj * &w;
        let mut g_next = &gj + &aw * &gj * aj.transpose();
        let mut h_next = &hj + aj.transpose() * &hj * &w * &aj;
        let a_next = &aw * &aj;
        symmetrize(&mut g_next);
        symmetrize(&mut h_next);
        if !(h_next.iter().chain(g_next.iter()).chain(a_next.iter())).all(|v| v.is_finite()) {
            return Err(riccati("the doubling iterates overflowed".into()));
        }
        let change = (&h_next - &hj).norm();
        let size = h_next.norm();
        aj = a_next;
        gj = g_next;
        hj = h_next;
        if change <= 1e-13 * size {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(riccati(
            "the doubling did not converge in 100 iterations".into(),
        ));
    }
    let p = hj;
    let mut sigma = c * &p * c.transpose() + r;
    symmetrize(&mut sigma);
    let chol = sigma
        .clone()
        .cholesky()
        .ok_or_else(|| riccati("CPCᵀ + R is not positive definite".into()))?;
    let gain = (a * &p * c.transpose() + s) * chol.inverse();
    let mut next = a * &p * a.transpose() + q - &gain * &sigma * gain.transpose();
    symmetrize(&mut next);
    let residual = (&next - &p).norm();
    if residual > 1e-8 * (p.norm() + q.norm()) {
        return Err(riccati(format!(
            "the doubling's solution leaves a residual {residual:.3e} in the Riccati equation"
        )));
    }
    Ok(gain)
}

/// The UIO of an LTI model: 𝐇, T, N, K₁, K₂, the error covariance P and the residual
/// covariance Σ_r with its pseudo-inverse (module documentation).
#[derive(Debug, Clone)]
pub struct UioDesign {
    h_bold: DMatrix<f64>,
    t: DMatrix<f64>,
    n: DMatrix<f64>,
    k1: DMatrix<f64>,
    k2: DMatrix<f64>,
    k: DMatrix<f64>,
    tg: DMatrix<f64>,
    error_covariance: DMatrix<f64>,
    residual_covariance: DMatrix<f64>,
    residual_covariance_pinv: DMatrix<f64>,
    /// Λ^{−1/2}Vᵀ over Σ_r's kept eigenpairs (rank × p): rᵀΣ_r⁺r = ‖W r‖².
    whitening: DMatrix<f64>,
    rank: usize,
    unknown_input_rank: usize,
    spectral_radius: f64,
}

impl UioDesign {
    /// Designs the UIO for the constant matrices `system` (F, G, H, J, Q, R) and the
    /// unknown input's matrix `e` (n×q).
    ///
    /// # Errors
    /// [`ModelError::Dimension`] / [`ModelError::NonFinite`] for malformed matrices;
    /// [`ModelError::Condition`] naming the [`UioCondition`] that fails.
    pub fn new(system: &SystemMatrices, e: &DMatrix<f64>) -> Result<Self, ModelError> {
        let (f, h) = (&system.f, &system.h);
        check_shapes(f, h, e)?;
        if !system.is_finite() {
            return Err(ModelError::NonFinite {
                what: "the model's matrices",
            });
        }
        let p = h.nrows();
        let st = structure(f, h, e)?;
        let (t, h_bold, u2) = (&st.t, &st.h_bold, &st.u2);
        let (q, r) = (&system.q, &system.r);
        let tf = t * f;
        let tfh = &tf * h_bold;
        let h_tilde = u2.transpose() * h;
        let mut q_bar = t * q * t.transpose() + &tfh * r * tfh.transpose();
        symmetrize(&mut q_bar);
        let mut r_tilde = u2.transpose() * r * u2;
        symmetrize(&mut r_tilde);
        let s_tilde = -(&tfh * r * u2);
        let k_tilde = steady_predictor(&tf, &h_tilde, &q_bar, &r_tilde, &s_tilde)?;
        let k1 = &k_tilde * u2.transpose();
        let n_matrix = &tf - &k1 * h;
        let spectral_radius = eigenvalues(&n_matrix, UioCondition::Stability)?
            .iter()
            .fold(0.0_f64, |m, z| m.max(z.norm()));
        if spectral_radius.is_nan() || spectral_radius >= 1.0 {
            return Err(UioCondition::Stability.fails(format!(
                "N has spectral radius {spectral_radius:.6} ≥ 1: the Riccati equation has no \
                 stabilising solution, as when a mode of TF on the unit circle gets no process \
                 noise (Q = 0 on it)"
            )));
        }
        let k2 = &n_matrix * h_bold;
        let k = &k1 + &k2;
        let mut drive = t * q * t.transpose() + &k * r * k.transpose();
        symmetrize(&mut drive);
        let error_covariance = lyapunov(&n_matrix, &drive)?;
        let projector = DMatrix::<f64>::identity(p, p) - h * h_bold;
        let mut residual_covariance =
            h * &error_covariance * h.transpose() + &projector * r * projector.transpose();
        symmetrize(&mut residual_covariance);
        let mut work = residual_covariance.clone();
        let mut values = vec![0.0; p];
        let mut vectors = DMatrix::zeros(p, p);
        jacobi_eigen(work.as_mut_slice(), p, &mut values, vectors.as_mut_slice());
        let largest = values.iter().fold(0.0_f64, |m, &v| m.max(v));
        let kept: Vec<usize> = (0..p)
            .filter(|&i| values[i] > RESIDUAL_RANK_TOLERANCE * largest)
            .collect();
        if kept.is_empty() {
            return Err(UioCondition::ResidualNoise.fails(
                "the residual's covariance Σ_r is zero: the noise model gives the residual no \
                 variance to test it against"
                    .into(),
            ));
        }
        let mut whitening = DMatrix::zeros(kept.len(), p);
        for (row, &i) in kept.iter().enumerate() {
            let scale = values[i].sqrt().recip();
            for c in 0..p {
                whitening[(row, c)] = vectors[(c, i)] * scale;
            }
        }
        let residual_covariance_pinv = whitening.transpose() * &whitening;
        Ok(Self {
            tg: t * &system.g,
            h_bold: st.h_bold,
            t: st.t,
            n: n_matrix,
            k1,
            k2,
            k,
            error_covariance,
            residual_covariance,
            residual_covariance_pinv,
            rank: kept.len(),
            whitening,
            unknown_input_rank: st.rank_he,
            spectral_radius,
        })
    }

    /// 𝐇 = E(HE)⁺ (n×p): X̂_k = z_k + 𝐇Y'_k, with 𝐇HE = E.
    #[must_use]
    pub fn h_bold(&self) -> &DMatrix<f64> {
        &self.h_bold
    }

    /// T = I − 𝐇H (n×n), with TE = 0.
    #[must_use]
    pub fn t(&self) -> &DMatrix<f64> {
        &self.t
    }

    /// N = TF − K₁H (n×n), the observer's dynamics; stable.
    #[must_use]
    pub fn n(&self) -> &DMatrix<f64> {
        &self.n
    }

    /// K₁ (n×p), from the Riccati equation of the outputs free of d.
    #[must_use]
    pub fn k1(&self) -> &DMatrix<f64> {
        &self.k1
    }

    /// K₂ = N𝐇 (n×p).
    #[must_use]
    pub fn k2(&self) -> &DMatrix<f64> {
        &self.k2
    }

    /// K = K₁ + K₂ (n×p), the gain of Y'_k in z_{k+1}.
    #[must_use]
    pub fn k(&self) -> &DMatrix<f64> {
        &self.k
    }

    /// The spectral radius of N (below 1): the error of z decays as its powers.
    #[must_use]
    pub fn spectral_radius(&self) -> f64 {
        self.spectral_radius
    }

    /// P (n×n), the steady-state covariance of z's error ξ_k = TX_k − z_k.
    #[must_use]
    pub fn error_covariance(&self) -> &DMatrix<f64> {
        &self.error_covariance
    }

    /// Σ_r = HPHᵀ + (I − Π)R(I − Π) (p×p), the residual's steady-state covariance under
    /// the noise model; zero on range(HE).
    #[must_use]
    pub fn residual_covariance(&self) -> &DMatrix<f64> {
        &self.residual_covariance
    }

    /// Σ_r⁺ (p×p), on the range of Σ_r's eigenvalues above [`RESIDUAL_RANK_TOLERANCE`] of
    /// the largest.
    #[must_use]
    pub fn residual_covariance_pinv(&self) -> &DMatrix<f64> {
        &self.residual_covariance_pinv
    }

    /// rank Σ_r: the degrees of freedom of rᵀΣ_r⁺r, χ² under no fault; p − rank(HE) when
    /// R is positive definite.
    #[must_use]
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// rank(HE) = rank(E): the unknown-input directions the residual is decoupled from.
    #[must_use]
    pub fn unknown_input_rank(&self) -> usize {
        self.unknown_input_rank
    }
}

/// X solving X = AXAᵀ + M for a stable A, by doubling (X = Σ_i A^iMA^{iᵀ}, the terms
/// summed 2^j at a time).
fn lyapunov(a: &DMatrix<f64>, m: &DMatrix<f64>) -> Result<DMatrix<f64>, ModelError> {
    let mut x = m.clone();
    let mut aj = a.clone();
    for _ in 0..64 {
        let mut add = &aj * &x * aj.transpose();
        symmetrize(&mut add);
        x += &add;
        if add.norm() <= 1e-17 * x.norm() {
            return Ok(x);
        }
        aj = &aj * &aj;
    }
    Err(UioCondition::Stability.fails(
        "the Lyapunov equation of the error of z did not converge: N is too close to \
         instability"
            .into(),
    ))
}

/// The unknown-input observer as a detector ([`Detector`], kind `uio`): the residual
/// r_k = Y'_k − HX̂_k, free of d, and its decision statistic by [`Evaluation`].
///
/// # Examples
/// ```
/// use glrmon_core::detector::{Evaluation, Sample, StepOutput, UioDetector};
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::model::{Lpv, StateSpace};
/// use glrmon_core::Detector;
/// use nalgebra::{DMatrix, DVector};
///
/// // The survey's DC motor, with d entering the current equation.
/// let model = Lpv::lti(
///     DMatrix::from_row_slice(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
///     DMatrix::from_row_slice(2, 1, &[0.0047, 0.4512]),
///     DMatrix::identity(2, 2),
///     DMatrix::zeros(2, 1),
///     DMatrix::identity(2, 2) * 1e-4,
///     DMatrix::from_diagonal(&DVector::from_vec(vec![0.0025, 0.0012])),
/// ).unwrap();
/// let faults = FaultDictionary::new(model.dims(), vec![
///     Fault::output("speed_bias", Onset::Step, Column::Constant(DVector::from_vec(vec![0.0, 1.0]))),
/// ]).unwrap();
/// let e = DMatrix::from_row_slice(2, 1, &[-1.5537, 0.0]);
/// let mut det = UioDetector::new(Box::new(model), e, faults, DVector::zeros(2), Evaluation::Chi2).unwrap();
/// assert_eq!(det.design().rank(), 1);
/// let mut out = StepOutput::for_detector(&det);
/// det.step(&Sample { k: 0, u: &[0.5], y: &[0.0, 0.0], p: &[] }, &mut out).unwrap();
/// assert_eq!(out.onset, Some(0));
/// ```
#[derive(Debug)]
pub struct UioDetector {
    design: UioDesign,
    faults: FaultDictionary,
    dims: Dims,
    evaluation: Evaluation,
    energy: EnergyWindow,
    h: DMatrix<f64>,
    j: DMatrix<f64>,
    x0: DVector<f64>,
    /// z_k, the observer's state before sample k.
    z: DVector<f64>,
    z_next: DVector<f64>,
    y_prime: DVector<f64>,
    x_hat: DVector<f64>,
    residual: DVector<f64>,
    white: DVector<f64>,
    next_k: Option<u64>,
}

impl UioDetector {
    /// The UIO of the LTI `model` (evaluated once, at k = 0 with zero signals) for the
    /// unknown input E d_k with `e` (n×q); `faults` is the channel's dictionary (the
    /// detector reports no magnitudes), `x0` the initial state estimate X̂₀ (z₀ = Tx₀),
    /// `evaluation` the decision statistic. Every buffer the per-sample path needs is
    /// allocated here.
    ///
    /// # Errors
    /// [`ModelError::Setting`] for a model that is not constant
    /// ([`StateSpace::is_constant`]) or an energy window of 0 samples;
    /// [`ModelError::Dimension`] when `e`, `x0` or the dictionary do not fit the model;
    /// [`ModelError::NonFinite`]; [`ModelError::Condition`] naming the [`UioCondition`]
    /// that fails ([`UioDesign::new`]).
    pub fn new(
        mut model: Box<dyn StateSpace>,
        e: DMatrix<f64>,
        faults: FaultDictionary,
        x0: DVector<f64>,
        evaluation: Evaluation,
    ) -> Result<Self, ModelError> {
        let dims = model.dims();
        if !model.is_constant() {
            return Err(ModelError::Setting {
                what: "model",
                detail: "the unknown-input observer needs an LTI model (F, G, H, J, Q, R \
                         constant); this one varies with the scheduling signals"
                    .into(),
            });
        }
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
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "x0" });
        }
        if let Evaluation::Energy { window: 0 } = evaluation {
            return Err(ModelError::Setting {
                what: "window",
                detail: "the energy window must hold at least 1 sample, got 0".into(),
            });
        }
        let mut system = SystemMatrices::zeros(dims);
        let (u, p) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
        model.evaluate(0, &Signals { u: &u, p: &p }, &mut system);
        let design = UioDesign::new(&system, &e)?;
        let (n, p, rank) = (dims.states, dims.outputs, design.rank);
        let z = &design.t * &x0;
        Ok(Self {
            energy: EnergyWindow::new(evaluation.memory()),
            evaluation,
            faults,
            dims,
            h: system.h,
            j: system.j,
            x0,
            z_next: DVector::zeros(n),
            z,
            y_prime: DVector::zeros(p),
            x_hat: DVector::zeros(n),
            residual: DVector::zeros(p),
            white: DVector::zeros(rank),
            next_k: None,
            design,
        })
    }

    /// The design: 𝐇, T, N, K, Σ_r and its rank.
    #[must_use]
    pub fn design(&self) -> &UioDesign {
        &self.design
    }

    /// The decision statistic's evaluation.
    #[must_use]
    pub fn evaluation(&self) -> Evaluation {
        self.evaluation
    }

    /// X̂_k = z_k + 𝐇Y'_k of the last measured sample (zero before the first).
    #[must_use]
    pub fn state_estimate(&self) -> &DVector<f64> {
        &self.x_hat
    }

    fn check(&self, s: &Sample<'_>) -> Result<(), StepError> {
        super::check_sample(self.dims, self.next_k, s)
    }
}

impl Detector for UioDetector {
    fn kind(&self) -> &'static str {
        "uio"
    }

    fn describe(&self) -> String {
        let statistic = match self.evaluation {
            Evaluation::Chi2 => format!("χ² of rᵀΣ_r⁺r ({} degrees of freedom)", self.design.rank),
            Evaluation::Energy { window } => format!("energy of r over {window} samples"),
        };
        format!(
            "unknown-input observer (Chen, Patton & Zhang 1996), decoupled from {} unknown \
             input direction(s), spectral radius of N {:.4}; {statistic}",
            self.design.unknown_input_rank, self.design.spectral_radius
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

    fn unknown_inputs(&self) -> usize {
        self.design.unknown_input_rank
    }

    fn next_index(&self) -> Option<u64> {
        self.next_k
    }

    /// Sample k: X̂_k = z_k + 𝐇Y'_k, r_k = Y'_k − HX̂_k, the statistic, and z_{k+1}.
    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        self.check(sample)?;
        let (n, l, p) = (self.dims.states, self.dims.inputs, self.dims.outputs);
        let d = &self.design;
        let y_prime = self.y_prime.as_mut_slice();
        y_prime.copy_from_slice(sample.y);
        gemv(-1.0, self.j.as_slice(), p, l, sample.u, 1.0, y_prime);
        let x_hat = self.x_hat.as_mut_slice();
        x_hat.copy_from_slice(self.z.as_slice());
        gemv(1.0, d.h_bold.as_slice(), n, p, y_prime, 1.0, x_hat);
        let residual = self.residual.as_mut_slice();
        residual.copy_from_slice(y_prime);
        gemv(-1.0, self.h.as_slice(), p, n, x_hat, 1.0, residual);
        gemv(
            1.0,
            d.whitening.as_slice(),
            d.rank,
            p,
            residual,
            0.0,
            self.white.as_mut_slice(),
        );
        let normalized: f64 = self.white.iter().map(|w| w * w).sum();
        let square: f64 = residual.iter().map(|r| r * r).sum();
        let z_next = self.z_next.as_mut_slice();
        gemv(1.0, d.n.as_slice(), n, n, self.z.as_slice(), 0.0, z_next);
        gemv(1.0, d.tg.as_slice(), n, l, sample.u, 1.0, z_next);
        gemv(1.0, d.k.as_slice(), n, p, y_prime, 1.0, z_next);
        if !(normalized.is_finite() && square.is_finite() && z_next.iter().all(|v| v.is_finite())) {
            return Err(StepError::Numerical {
                what: "the observer's state or residual is not finite",
            });
        }
        std::mem::swap(&mut self.z, &mut self.z_next);
        let k = sample.k;
        let (glr, onset) = match self.evaluation {
            Evaluation::Chi2 => (Some(normalized), Some(k)),
            Evaluation::Energy { window } => match self.energy.push(square) {
                Some(j) => (Some(j), Some(k + 1 - window as u64)),
                None => (None, None),
            },
        };
        out.k = k;
        out.normalized_innovation = normalized;
        out.residual.as_mut_slice().copy_from_slice(residual);
        out.glr = glr;
        out.onset = onset;
        out.rank = if glr.is_some() { d.rank } else { 0 };
        out.magnitude.fill(0.0);
        self.next_k = Some(k + 1);
        Ok(())
    }

    /// Refuses: the observer needs Y_k to cancel d_{k−1}, which moves the state
    /// unobserved over a missing sample; the caller restarts.
    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        Err(StepError::UnknownInputGap { k })
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        self.z.copy_from(&(&self.design.t * &self.x0));
        self.x_hat.fill(0.0);
        self.energy.clear();
        self.next_k = None;
        Ok(())
    }

    fn innovation_len(&self) -> usize {
        0
    }

    fn residual_len(&self) -> usize {
        self.dims.outputs
    }

    fn estimates_magnitude(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detector::{GlrDetector, WindowSettings};
    use crate::model::fault::{Column, Fault, Onset};
    use crate::model::{Lpv, LpvMatrix};
    use crate::threshold::chi2_upper_quantile;

    /// xorshift64* with Box-Muller normals.
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
        fn vector(&mut self, chol: &DMatrix<f64>) -> DVector<f64> {
            let z = DVector::from_fn(chol.nrows(), |_, _| self.normal());
            chol * z
        }
    }

    fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, v)
    }

    /// The matrices of a test plant and its unknown input.
    struct Plant {
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        j: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
        e: DMatrix<f64>,
    }

    impl Plant {
        /// The survey's DC motor (its §"Comparison of fault detection techniques"), d on
        /// the current: p = 2, rank(HE) = 1, one degree of freedom.
        fn dc_motor() -> Self {
            Self {
                f: m(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
                g: m(2, 1, &[0.0047, 0.4512]),
                h: DMatrix::identity(2, 2),
                j: DMatrix::zeros(2, 1),
                q: DMatrix::identity(2, 2) * 1e-4,
                r: m(2, 2, &[0.0025, 0.0, 0.0, 0.0012]),
                e: m(2, 1, &[-1.5537, 0.0]),
            }
        }

        /// n = 3, p = 3, HE oblique to the output axes, R and Q correlated: two degrees of
        /// freedom, and the cross term S̃ of the Riccati equation non-zero.
        fn oblique() -> Self {
            Self {
                f: m(3, 3, &[0.9, 0.1, 0.0, 0.0, 0.8, 0.2, 0.1, 0.0, 0.7]),
                g: m(3, 1, &[1.0, 0.0, 0.5]),
                h: m(3, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0]),
                j: m(3, 1, &[0.0, 0.1, 0.0]),
                q: m(
                    3,
                    3,
                    &[0.01, 0.002, 0.0, 0.002, 0.02, 0.001, 0.0, 0.001, 0.005],
                ),
                r: m(
                    3,
                    3,
                    &[0.02, 0.005, 0.0, 0.005, 0.03, 0.004, 0.0, 0.004, 0.01],
                ),
                e: m(3, 1, &[0.5, 1.0, -0.3]),
            }
        }

        fn model(&self) -> Lpv {
            Lpv::lti(
                self.f.clone(),
                self.g.clone(),
                self.h.clone(),
                self.j.clone(),
                self.q.clone(),
                self.r.clone(),
            )
            .unwrap()
        }

        fn system(&self) -> SystemMatrices {
            SystemMatrices {
                f: self.f.clone(),
                g: self.g.clone(),
                h: self.h.clone(),
                j: self.j.clone(),
                q: self.q.clone(),
                r: self.r.clone(),
            }
        }

        fn faults(&self) -> FaultDictionary {
            let p = self.h.nrows();
            let mut bias = DVector::zeros(p);
            bias[p - 1] = 1.0;
            FaultDictionary::new(
                self.model().dims(),
                vec![Fault::output("bias", Onset::Step, Column::Constant(bias))],
            )
            .unwrap()
        }

        fn detector(&self, evaluation: Evaluation) -> UioDetector {
            let n = self.f.nrows();
            UioDetector::new(
                Box::new(self.model()),
                self.e.clone(),
                self.faults(),
                DVector::zeros(n),
                evaluation,
            )
            .unwrap()
        }
    }

    /// Simulates X_{k+1} = FX + GU + Ed + W, Y = HX + JU + V (+ an output bias).
    struct Simulation<'a> {
        plant: &'a Plant,
        x: DVector<f64>,
        q_chol: DMatrix<f64>,
        r_chol: DMatrix<f64>,
        noise: bool,
        rng: Rng,
    }

    impl<'a> Simulation<'a> {
        fn new(plant: &'a Plant, x0: DVector<f64>, noise: bool, seed: u64) -> Self {
            Self {
                plant,
                x: x0,
                q_chol: plant.q.clone().cholesky().unwrap().l(),
                r_chol: plant.r.clone().cholesky().unwrap().l(),
                noise,
                rng: Rng::new(seed),
            }
        }

        /// Y_k, then the state moves to X_{k+1}.
        fn sample(
            &mut self,
            u: &DVector<f64>,
            d: &DVector<f64>,
            bias: &DVector<f64>,
        ) -> DVector<f64> {
            let p = self.plant;
            let mut y = &p.h * &self.x + &p.j * u + bias;
            let mut x = &p.f * &self.x + &p.g * u + &p.e * d;
            if self.noise {
                y += self.rng.vector(&self.r_chol);
                x += self.rng.vector(&self.q_chol);
            }
            self.x = x;
            y
        }
    }

    fn disturbance(k: u64, q: usize) -> DVector<f64> {
        let kf = k as f64;
        let step = if k >= 100 { 30.0 } else { 0.0 } - if k >= 250 { 80.0 } else { 0.0 };
        DVector::from_fn(q, |i, _| 50.0 * (0.3 * kf + i as f64).sin() + step)
    }

    fn input(k: u64) -> DVector<f64> {
        DVector::from_vec(vec![0.5 + 0.3 * (0.05 * k as f64).sin()])
    }

    fn step(
        det: &mut UioDetector,
        k: u64,
        u: &DVector<f64>,
        y: &DVector<f64>,
        out: &mut StepOutput,
    ) {
        let sample = Sample {
            k,
            u: u.as_slice(),
            y: y.as_slice(),
            p: &[],
        };
        det.step(&sample, out).unwrap();
    }

    /// The steady-state Kalman predictor gain F·PHᵀ(HPHᵀ + R)⁻¹ of (F, H, Q, R), by
    /// iterating the Riccati recursion: the observer without decoupling.
    fn kalman_gain(p: &Plant) -> DMatrix<f64> {
        let mut cov = p.q.clone();
        let mut gain = DMatrix::zeros(p.f.nrows(), p.h.nrows());
        for _ in 0..5000 {
            let s = &p.h * &cov * p.h.transpose() + &p.r;
            gain = &p.f * &cov * p.h.transpose() * s.clone().try_inverse().unwrap();
            cov = &p.f * &cov * p.f.transpose() + &p.q - &gain * &s * gain.transpose();
        }
        gain
    }

    /// (a) Without noise and with an arbitrary large d, X̂ converges to X and the residual
    /// to zero; the same data through the Kalman predictor without decoupling leave a
    /// residual of the size of d's effect.
    #[test]
    fn decouples_a_large_unknown_input_where_a_kalman_observer_does_not() {
        for plant in [Plant::dc_motor(), Plant::oblique()] {
            let (n, p, q) = (plant.f.nrows(), plant.h.nrows(), plant.e.ncols());
            let mut det = plant.detector(Evaluation::Chi2);
            let mut out = StepOutput::for_detector(&det);
            let x0 = DVector::from_fn(n, |i, _| 1.0 - i as f64);
            let mut sim = Simulation::new(&plant, x0.clone(), false, 1);
            let gain = kalman_gain(&plant);
            let mut kalman = DVector::zeros(n);
            let (mut worst_uio, mut worst_x, mut worst_kalman) = (0.0_f64, 0.0_f64, 0.0_f64);
            let zero = DVector::zeros(p);
            for k in 0..400 {
                let (u, d) = (input(k), disturbance(k, q));
                let x = sim.x.clone();
                let y = sim.sample(&u, &d, &zero);
                step(&mut det, k, &u, &y, &mut out);
                let eps = &y - &plant.h * &kalman - &plant.j * &u;
                kalman = &plant.f * &kalman + &plant.g * &u + &gain * &eps;
                if k >= 200 {
                    worst_uio = worst_uio.max(out.residual.amax());
                    worst_x = worst_x.max((det.state_estimate() - &x).amax() / (1.0 + x.amax()));
                    worst_kalman = worst_kalman.max(eps.amax());
                }
            }
            assert!(worst_uio <= 1e-9, "UIO residual {worst_uio:e}");
            assert!(worst_x <= 1e-9, "UIO state error {worst_x:e}");
            assert!(worst_kalman > 1.0, "Kalman residual {worst_kalman}");
        }
    }

    fn spectral_radius_by_powers(a: &DMatrix<f64>) -> f64 {
        let mut power = a.clone();
        for _ in 0..7 {
            power = &power * &power;
        }
        power.norm().powf(1.0 / 128.0)
    }

    /// (b) The design satisfies the observer's equations, N is stable, and K₁ from the
    /// Riccati equation is the gain of least error covariance.
    #[test]
    fn design_satisfies_the_observer_equations_and_minimises_the_error() {
        let mut dependent = Plant::oblique();
        // Two columns along one direction: rank(E) = rank(HE) = 1, which the Kitanidis
        // filter refuses and the pseudo-inverse accepts.
        dependent.e = m(3, 2, &[0.5, 1.0, 1.0, 2.0, -0.3, -0.6]);
        for plant in [Plant::dc_motor(), Plant::oblique(), dependent] {
            let design = UioDesign::new(&plant.system(), &plant.e).unwrap();
            let (n, p) = (plant.f.nrows(), plant.h.nrows());
            let hb = design.h_bold();
            assert!((hb * &plant.h * &plant.e - &plant.e).amax() < 1e-12);
            let t = DMatrix::identity(n, n) - hb * &plant.h;
            assert!((design.t() - &t).amax() < 1e-14);
            assert!((&t * &plant.e).amax() < 1e-12);
            let nn = &t * &plant.f - design.k1() * &plant.h;
            assert!((design.n() - &nn).amax() < 1e-14);
            assert!((design.k2() - &nn * hb).amax() < 1e-14);
            assert!((design.k() - design.k1() - design.k2()).amax() < 1e-15);
            let rho = spectral_radius_by_powers(&nn);
            assert!(rho < 1.0, "ρ(N) = {rho}");
            assert!(
                (rho - design.spectral_radius()).abs() < 0.05,
                "{rho} vs {}",
                design.spectral_radius()
            );
            assert_eq!(design.unknown_input_rank(), 1);
            assert_eq!(design.rank(), p - 1);
            // P(K₁) = N P Nᵀ + TQTᵀ + KRKᵀ by plain iteration; any other K₁, changed in
            // the outputs free of d or in range(HE), gives a larger trace.
            let error_trace = |k1: &DMatrix<f64>| {
                let nn = &t * &plant.f - k1 * &plant.h;
                let k = k1 + &nn * hb;
                let mut cov = DMatrix::zeros(n, n);
                for _ in 0..3000 {
                    cov = &nn * &cov * nn.transpose()
                        + &t * &plant.q * t.transpose()
                        + &k * &plant.r * k.transpose();
                }
                cov
            };
            let best = error_trace(design.k1());
            assert!((&best - design.error_covariance()).amax() < 1e-12 * best.amax());
            let free = DMatrix::identity(p, p) - &plant.h * hb;
            let single = |i: usize, j: usize| {
                let mut delta = DMatrix::zeros(n, p);
                delta[(i, j)] = 0.02;
                delta
            };
            let changes = [
                single(0, p - 1) * &free,
                single(n - 1, p - 1) * &free,
                DMatrix::from_element(n, p, 0.01) * &free,
                DMatrix::from_element(n, p, 0.01),
            ];
            for delta in changes {
                assert!(delta.amax() > 1e-3);
                for sign in [1.0, -1.0] {
                    let other = error_trace(&(design.k1() + &delta * sign));
                    assert!(
                        other.trace() > best.trace(),
                        "{} ≤ {}",
                        other.trace(),
                        best.trace()
                    );
                }
            }
        }
    }

    /// (c) Each failing condition is refused by name.
    #[test]
    fn refuses_each_failing_condition_by_name() {
        let condition = |plant: &Plant| {
            let err = UioDesign::new(&plant.system(), &plant.e).unwrap_err();
            let structural = check_uio_conditions(&plant.f, &plant.h, &plant.e);
            (
                UioCondition::of(&err),
                err.to_string(),
                structural.err().and_then(|e| UioCondition::of(&e)),
            )
        };
        // HE = 0: d moves state 3, which no output sees.
        let mut plant = Plant::oblique();
        plant.h = m(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        plant.j = DMatrix::zeros(2, 1);
        plant.r = DMatrix::identity(2, 2) * 0.01;
        plant.e = m(3, 1, &[0.0, 0.0, 1.0]);
        let (c, text, structural) = condition(&plant);
        assert_eq!(c, Some(UioCondition::Matching), "{text}");
        assert_eq!(structural, Some(UioCondition::Matching));
        assert!(
            text.starts_with("the matching condition rank(HE) = rank(E) fails"),
            "{text}"
        );
        assert!(text.contains("rank(HE) = 0 < rank(E) = 1"), "{text}");
        // (H, F) observable, but TF = (I − 𝐇H)F cuts the only path from the unstable
        // state 1 to the outputs (through state 2, which d also drives).
        let mut plant = Plant::oblique();
        plant.f = m(3, 3, &[1.2, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.5]);
        plant.h = m(2, 3, &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        plant.j = DMatrix::zeros(2, 1);
        plant.r = DMatrix::identity(2, 2) * 0.01;
        plant.e = m(3, 1, &[0.0, 1.0, 0.0]);
        let observability = {
            let (f, h) = (&plant.f, &plant.h);
            let mut o = DMatrix::zeros(6, 3);
            o.rows_mut(0, 2).copy_from(h);
            o.rows_mut(2, 2).copy_from(&(h * f));
            o.rows_mut(4, 2).copy_from(&(h * f * f));
            o.rank(1e-10)
        };
        assert_eq!(observability, 3);
        let (c, text, structural) = condition(&plant);
        assert_eq!(c, Some(UioCondition::Detectability), "{text}");
        assert_eq!(structural, Some(UioCondition::Detectability));
        assert!(
            text.starts_with("the detectability of (H, TF) fails"),
            "{text}"
        );
        assert!(text.contains("λ = 1.200000+0.000000i"), "{text}");
        // Two independent unknown inputs and two outputs: nothing left for a residual.
        let mut plant = Plant::dc_motor();
        plant.e = DMatrix::identity(2, 2);
        assert_eq!(condition(&plant).0, Some(UioCondition::Residual));
        // An LPV model is refused, not evaluated at one point.
        let p = Plant::dc_motor();
        let c = LpvMatrix::constant;
        let f = LpvMatrix::new(p.f.clone(), vec![(0, DMatrix::identity(2, 2) * 0.01)]).unwrap();
        let lpv = Lpv::new(
            f,
            c(p.g.clone()),
            c(p.h.clone()),
            c(p.j.clone()),
            c(p.q.clone()),
            c(p.r.clone()),
            1,
        )
        .unwrap();
        let faults = FaultDictionary::new(
            lpv.dims(),
            vec![Fault::output(
                "bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
            )],
        )
        .unwrap();
        let err = UioDetector::new(
            Box::new(lpv),
            p.e.clone(),
            faults,
            DVector::zeros(2),
            Evaluation::Chi2,
        )
        .unwrap_err();
        assert!(
            matches!(err, ModelError::Setting { what: "model", .. }),
            "{err}"
        );
        assert!(check_uio_conditions(&p.f, &p.h, &p.e).is_ok());
    }

    /// Monte-Carlo residuals of a fault-free run with a large d: (mean, covariance,
    /// statistics).
    fn fault_free_run(plant: &Plant, samples: u64, seed: u64) -> (DMatrix<f64>, Vec<f64>) {
        let (n, p, q) = (plant.f.nrows(), plant.h.nrows(), plant.e.ncols());
        let mut det = plant.detector(Evaluation::Chi2);
        let mut out = StepOutput::for_detector(&det);
        let mut sim = Simulation::new(plant, DVector::zeros(n), true, seed);
        let zero = DVector::zeros(p);
        let mut second = DMatrix::zeros(p, p);
        let mut statistics = Vec::new();
        let burn_in = 200;
        for k in 0..samples + burn_in {
            let (u, d) = (input(k), disturbance(k, q));
            let y = sim.sample(&u, &d, &zero);
            step(&mut det, k, &u, &y, &mut out);
            if k >= burn_in {
                second += &out.residual * out.residual.transpose();
                statistics.push(out.glr.unwrap());
            }
        }
        (second / samples as f64, statistics)
    }

    /// (d) Σ_r equals the covariance derived from e_k's own recursion (with its V_{k+1}
    /// term), is zero on range(HE), and matches the residuals' empirical covariance.
    #[test]
    fn residual_covariance_matches_its_derivations_and_simulation() {
        for (plant, seed) in [(Plant::oblique(), 7), (Plant::dc_motor(), 8)] {
            let design = UioDesign::new(&plant.system(), &plant.e).unwrap();
            let sigma = design.residual_covariance();
            let (n, p) = (plant.f.nrows(), plant.h.nrows());
            let (nn, k1, hb, t) = (design.n(), design.k1(), design.h_bold(), design.t());
            // e_{k+1} = N e_k + T W_k − K₁V_k − 𝐇V_{k+1}, E(e_kV_kᵀ) = −𝐇R.
            let mut pe = DMatrix::zeros(n, n);
            for _ in 0..3000 {
                pe = nn * &pe * nn.transpose()
                    + t * &plant.q * t.transpose()
                    + k1 * &plant.r * k1.transpose()
                    + hb * &plant.r * hb.transpose()
                    + nn * hb * &plant.r * k1.transpose()
                    + k1 * &plant.r * hb.transpose() * nn.transpose();
            }
            let h = &plant.h;
            let from_e = h * &pe * h.transpose() + &plant.r
                - h * hb * &plant.r
                - &plant.r * hb.transpose() * h.transpose();
            assert!(
                (&from_e - sigma).amax() < 1e-12 * sigma.amax(),
                "{from_e} vs {sigma}"
            );
            let he = h * &plant.e;
            assert!((sigma * &he).amax() < 1e-12 * sigma.amax() * he.amax());
            assert_eq!(design.rank(), p - 1);
            let pinv = design.residual_covariance_pinv();
            assert!((sigma * pinv * sigma - sigma).amax() < 1e-10 * sigma.amax());
            let (empirical, _) = fault_free_run(&plant, 200_000, seed);
            let mut worst = 0.0_f64;
            for i in 0..p {
                for j in 0..p {
                    let scale = (sigma[(i, i)] * sigma[(j, j)]).sqrt();
                    worst = worst.max((empirical[(i, j)] - sigma[(i, j)]).abs() / scale);
                }
            }
            assert!(worst < 0.02, "largest deviation {worst:.4} of √(Σ_iiΣ_jj)");
        }
    }

    /// (e) rᵀΣ_r⁺r is χ²(p − rank HE) without fault: its mean and its exceedance rate at
    /// the α = 0.01 quantile.
    #[test]
    fn chi2_statistic_has_its_law_without_fault() {
        for (plant, seed) in [(Plant::oblique(), 11), (Plant::dc_motor(), 12)] {
            let (_, stats) = fault_free_run(&plant, 100_000, seed);
            let dof = (plant.h.nrows() - 1) as f64;
            let mean = stats.iter().sum::<f64>() / stats.len() as f64;
            assert!((mean / dof - 1.0).abs() < 0.02, "mean {mean} for {dof} dof");
            let threshold = chi2_upper_quantile(dof, 0.01).unwrap();
            let rate = stats.iter().filter(|&&s| s > threshold).count() as f64 / stats.len() as f64;
            assert!((rate / 0.01 - 1.0).abs() < 0.3, "exceedance rate {rate}");
        }
    }

    /// (f) A bias on the speed sensor of the DC motor crosses the χ²(1) threshold at
    /// α = 0.01 within a few samples of its onset, with d large meanwhile.
    #[test]
    fn sensor_bias_crosses_the_threshold_within_a_few_samples() {
        let plant = Plant::dc_motor();
        let threshold = chi2_upper_quantile(1.0, 0.01).unwrap();
        let mut delays = Vec::new();
        for trial in 0..20 {
            let mut det = plant.detector(Evaluation::Chi2);
            let mut out = StepOutput::for_detector(&det);
            let mut sim = Simulation::new(&plant, DVector::zeros(2), true, 100 + trial);
            let onset = 300 + 7 * trial;
            let mut delay = None;
            for k in 0..onset + 20 {
                let bias = DVector::from_vec(vec![0.0, if k >= onset { 0.15 } else { 0.0 }]);
                let (u, d) = (input(k), disturbance(k, 1));
                let y = sim.sample(&u, &d, &bias);
                step(&mut det, k, &u, &y, &mut out);
                if k >= onset && delay.is_none() && out.glr.unwrap() > threshold {
                    delay = Some(k - onset);
                }
            }
            delays.push(delay.expect("the bias was not detected"));
        }
        assert!(delays.iter().all(|&d| d <= 3), "{delays:?}");
    }

    /// The steady-state UIO with K₁ from the Riccati equation and the Kitanidis filter
    /// of the GLR detector carry the same information: rᵀΣ_r⁺r = ‖z_k‖² once the
    /// Kitanidis filter's gain has converged.
    #[test]
    fn chi2_statistic_equals_the_kitanidis_filters_in_steady_state() {
        for plant in [Plant::oblique(), Plant::dc_motor()] {
            let (n, p, q) = (plant.f.nrows(), plant.h.nrows(), plant.e.ncols());
            let mut uio = plant.detector(Evaluation::Chi2);
            let mut kitanidis = GlrDetector::new(
                Box::new(plant.model()),
                plant.faults(),
                DVector::zeros(n),
                DMatrix::identity(n, n),
                WindowSettings {
                    window: 4,
                    min_lag: 0,
                    ..Default::default()
                },
            )
            .unwrap()
            .with_unknown_input(LpvMatrix::constant(plant.e.clone()))
            .unwrap();
            let mut out = StepOutput::for_detector(&uio);
            let mut glr_out = StepOutput::for_detector(&kitanidis);
            let mut sim = Simulation::new(&plant, DVector::zeros(n), true, 21);
            let zero = DVector::zeros(p);
            let mut worst = 0.0_f64;
            for k in 0..2000 {
                let (u, d) = (input(k), disturbance(k, q));
                let y = sim.sample(&u, &d, &zero);
                step(&mut uio, k, &u, &y, &mut out);
                let sample = Sample {
                    k,
                    u: u.as_slice(),
                    y: y.as_slice(),
                    p: &[],
                };
                kitanidis.step(&sample, &mut glr_out).unwrap();
                if k >= 500 {
                    let (a, b) = (out.normalized_innovation, glr_out.normalized_innovation);
                    worst = worst.max((a - b).abs() / (1.0 + b));
                }
            }
            assert!(worst < 1e-8, "largest relative difference {worst:e}");
        }
    }

    /// Evaluation::Energy reports J_k = (Σ r_iᵀr_i)^{1/2} over the last w residuals, from
    /// the w-th sample on, with onset k − w + 1.
    #[test]
    fn energy_evaluation_sums_the_last_w_residuals() {
        let plant = Plant::oblique();
        let mut det = plant.detector(Evaluation::Energy { window: 5 });
        assert_eq!(det.memory(), 5);
        let mut out = StepOutput::for_detector(&det);
        let mut sim = Simulation::new(&plant, DVector::zeros(3), true, 3);
        let zero = DVector::zeros(3);
        let mut squares = Vec::new();
        for k in 10..60 {
            let (u, d) = (input(k), disturbance(k, 1));
            let y = sim.sample(&u, &d, &zero);
            step(&mut det, k, &u, &y, &mut out);
            squares.push(out.residual.norm_squared());
            let seen = squares.len();
            if seen < 5 {
                assert_eq!((out.glr, out.onset, out.rank), (None, None, 0));
            } else {
                let direct: f64 = squares[seen - 5..].iter().sum();
                assert!((out.glr.unwrap() - direct.sqrt()).abs() < 1e-12 * direct.sqrt());
                assert_eq!(out.onset, Some(k - 4));
                assert_eq!(out.rank, 2);
            }
            let direct = out
                .residual
                .dot(&(det.design().residual_covariance_pinv() * &out.residual));
            assert!((out.normalized_innovation - direct).abs() < 1e-10 * (1.0 + direct));
        }
        let err = UioDetector::new(
            Box::new(plant.model()),
            plant.e.clone(),
            plant.faults(),
            DVector::zeros(3),
            Evaluation::Energy { window: 0 },
        )
        .unwrap_err();
        assert!(matches!(err, ModelError::Setting { what: "window", .. }));
    }

    /// The Detector contract: malformed or out-of-order samples change nothing, a gap is
    /// refused as an unknown-input gap, a restart forgets everything; the kind's lengths.
    #[test]
    fn follows_the_detector_contract() {
        let plant = Plant::oblique();
        let mut det = plant.detector(Evaluation::Chi2);
        let mut twin = plant.detector(Evaluation::Chi2);
        assert_eq!(det.kind(), "uio");
        assert_eq!((det.innovation_len(), det.residual_len()), (0, 3));
        assert!(!det.estimates_magnitude() && det.fisher_statistics(0).is_none());
        assert_eq!(det.unknown_inputs(), 1);
        let mut out = StepOutput::for_detector(&det);
        let mut twin_out = StepOutput::for_detector(&twin);
        assert_eq!((out.innovation.len(), out.residual.len()), (0, 3));
        let mut sim = Simulation::new(&plant, DVector::zeros(3), true, 5);
        let zero = DVector::zeros(3);
        let mut first = Vec::new();
        for k in 0..30 {
            let (u, d) = (input(k), disturbance(k, 1));
            let y = sim.sample(&u, &d, &zero);
            let bad_y = [y[0], f64::NAN, y[2]];
            let refused = [
                Sample {
                    k,
                    u: u.as_slice(),
                    y: &y.as_slice()[..2],
                    p: &[],
                },
                Sample {
                    k,
                    u: u.as_slice(),
                    y: &bad_y,
                    p: &[],
                },
                Sample {
                    k: k + 1,
                    u: u.as_slice(),
                    y: y.as_slice(),
                    p: &[],
                },
                Sample {
                    k,
                    u: &[],
                    y: y.as_slice(),
                    p: &[],
                },
            ];
            if k > 0 {
                for s in &refused {
                    assert!(det.step(s, &mut out).is_err());
                }
                assert_eq!(det.predict_only(k), Err(StepError::UnknownInputGap { k }));
            }
            step(&mut det, k, &u, &y, &mut out);
            step(&mut twin, k, &u, &y, &mut twin_out);
            assert_eq!(out, twin_out);
            assert_eq!(out.magnitude.len(), 1);
            first.push((u, y, out.clone()));
        }
        assert_eq!(det.next_index(), Some(30));
        det.restart().unwrap();
        assert_eq!(det.next_index(), None);
        for (k, (u, y, expected)) in first.iter().enumerate() {
            step(&mut det, k as u64 + 1000, u, y, &mut out);
            assert_eq!(out.residual, expected.residual);
            assert_eq!(out.glr, expected.glr);
        }
        assert!(det.describe().contains("unknown-input observer"));
    }
}
