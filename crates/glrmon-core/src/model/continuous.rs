//! Continuous-time models sampled with a zero-order hold: the F, G and Q of eq. (1)
//! from a first-principles model dx/dt = A x + B u + w.
//!
//! A plant model derived from physics is written in continuous time,
//!
//! ```text
//! dx/dt = A x(t) + B u(t) + w(t),     E[w(t) w(s)ᵀ] = Q_c δ(t − s)
//! ```
//!
//! Q_c being the intensity (power spectral density, per unit time) of the process noise.
//! Sampled every T seconds, with the inputs held constant between samples (a zero-order
//! hold: a DCS writes an actuator's set value and keeps it until the next one), the
//! state moves over one period exactly as the discrete model of Zhang & Basseville 2014,
//! eq. (1), X_{k+1} = F X_k + G U_k + W_k, with
//!
//! ```text
//! F = e^{AT},     G = ∫₀ᵀ e^{As} ds · B,     Q = cov(W_k) = ∫₀ᵀ e^{As} Q_c e^{Aᵀs} ds
//! ```
//!
//! (Franklin, Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed., §6.3,
//! hold equivalents; Van Loan 1978, *Computing integrals involving the matrix
//! exponential*, IEEE Trans. Automat. Control 23(3), §1 and §4).
//!
//! **The output equation is not discretised.** Y_k = H X_k + J U_k + V_k is a point
//! sample of y(t) at t = kT, so H and J are those of y = C x + D u. Nor is R: a
//! continuous measurement-noise intensity has no meaning for point samples (sampling a
//! white noise gives an infinite variance) unless an anti-alias filter, which is part
//! of the model, sets the bandwidth; R is given directly, as the variance of each
//! sample's measurement noise.
//!
//! **How it is computed.**
//!
//! * F and G: one matrix exponential of the augmented matrix (Van Loan 1978, Theorem 1
//!   with a zero lower-right block; Franklin, Powell & Workman §6.3):
//!   `exp([[A, B], [0, 0]]·T) = [[F, G], [0, I]]`. B is scaled to unit norm inside the
//!   exponential and G scaled back (the upper-right block is linear in B), so that a B
//!   in large units does not add squarings that would cost F accuracy.
//! * Q: Van Loan 1978, Theorem 1 with A₁ = −A, B₁ = Q_c, A₂ = Aᵀ: the exponential of
//!   `[[−A, Q_c], [0, Aᵀ]]·τ` is `[[e^{−Aτ}, M], [0, e^{Aᵀτ}]]` with
//!   M = ∫₀^τ e^{−A(τ−s)} Q_c e^{Aᵀs} ds, so Q(τ) = e^{Aτ}·M (e^{Aτ} is the transpose of
//!   the lower-right block). The upper-left block e^{−Aτ} grows like e^{‖A‖τ}: over a
//!   whole period of a stiff model (an eigenvalue −1000 s⁻¹ sampled at 20 s) it
//!   overflows, and Q = F·M is then lost to cancellation. So the formula is applied over
//!   τ = T/2^j with ‖A‖₁τ ≤ 1/2, where it is well conditioned, and the period is
//!   rebuilt by j doublings Q(2τ) = Q(τ) + F(τ) Q(τ) F(τ)ᵀ, F(2τ) = F(τ)², which add
//!   positive semi-definite terms (no cancellation). The result is made exactly
//!   symmetric.
//! * The exponential is nalgebra's `Matrix::exp`, a port of SciPy's `expm`: scaling and
//!   squaring with Padé approximants of degree 3 to 13 chosen by the backward-error
//!   bounds of Al-Mohy & Higham 2009 (*A new scaling and squaring algorithm for the
//!   matrix exponential*, SIAM J. Matrix Anal. Appl. 31(3)), the revision of Higham
//!   2005 (*The scaling and squaring method for the matrix exponential revisited*). The
//!   tests check it against closed forms and the semigroup law; [`expm`] adds the checks
//!   it lacks (see there).
//!
//! **Accuracy.** About 1e-15 relative when ‖A‖T is of order 1 (the closed forms of the
//! tests: 1e-16 to 5e-15). A model with modes of very different speeds (stiff) loses
//! digits on its slow modes, which pay for the squarings the fast ones need: about
//! u·‖A‖₁T at worst (u = 1.1e-16), and 9e-13 is observed on F, G and Q at
//! ‖A‖₁T = 2·10⁴ (tests/continuous.rs, against an eigen-decomposition and a Simpson
//! integration). The method is backward stable (the result is e^{(A+ΔA)T} with
//! ‖ΔA‖ of the order of u‖A‖), which is little help to an A far from normal whose large
//! entries cancel: the exponential of the nilpotent c·[[1, −1], [1, −1]] comes out with
//! a relative error of 8e-5 at c = 10⁵ (physical models are not built that way).
//!
//! ```
//! use glrmon_core::model::continuous::Discretisation;
//! use nalgebra::DMatrix;
//!
//! // A tank level: dh/dt = −h/τ + u/A, τ = 600 s, sampled at T = 20 s.
//! let (tau, area, t) = (600.0_f64, 0.5, 20.0);
//! let a = DMatrix::from_element(1, 1, -1.0 / tau);
//! let b = DMatrix::from_element(1, 1, 1.0 / area);
//! let qc = DMatrix::from_element(1, 1, 1e-4);
//! let d = Discretisation::zero_order_hold(&a, &b, Some(&qc), t)?;
//! assert!((d.f()[(0, 0)] - (-t / tau).exp()).abs() < 1e-15);
//! let g = tau / area * (1.0 - (-t / tau).exp());
//! assert!((d.g()[(0, 0)] - g).abs() < 1e-12 * g);
//! # Ok::<(), glrmon_core::model::continuous::ContinuousError>(())
//! ```

use std::fmt;

use nalgebra::{Complex, DMatrix};

/// A continuous-time model that cannot be discretised. Each names the matrix concerned
/// as the caller gave it (`"A"`, `"B"`, `"Qc"`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ContinuousError {
    /// A matrix has the wrong shape.
    #[error("{what}: {detail}")]
    Dimension {
        /// The matrix concerned.
        what: &'static str,
        /// What disagrees with what.
        detail: String,
    },
    /// A matrix holds NaN or ±∞.
    #[error("{what} holds a non-finite value (NaN or infinity)")]
    NonFinite {
        /// The matrix concerned.
        what: &'static str,
    },
    /// The sample period is not finite and positive.
    #[error("the sample period T = {period} s must be finite and positive")]
    Period {
        /// The period given, in seconds.
        period: f64,
    },
    /// The noise intensity is not symmetric.
    #[error("{what} is not symmetric (max |M − Mᵀ| = {asymmetry:.3e})")]
    NotSymmetric {
        /// The matrix concerned.
        what: &'static str,
        /// Its largest |M − Mᵀ| entry.
        asymmetry: f64,
    },
    /// The result does not fit in a double: e^{AT} overflows (an unstable mode grows by
    /// more than 1e308 over one period).
    #[error(
        "{what} overflows: the model grows beyond the range of a double over one period \
         (an eigenvalue of A with a real part above about 709/T, or an A so far from \
         normal, large entries cancelling, that e^{{AT}} cannot be computed in double \
         precision)"
    )]
    Overflow {
        /// The result concerned (`"e^{AT}"`, `"Q"`).
        what: &'static str,
    },
}

/// The largest ‖M‖₁ handed to nalgebra's exponential; a larger M is scaled by a power
/// of two first and the result squared back (see [`expm`]).
const EXPM_NORM_CAP: f64 = 65536.0;

/// The largest ‖A‖₁τ over which Van Loan's block formula is applied before doubling
/// (see the module's documentation): e^{−Aτ} stays within e^{1/2} ≈ 1.65 in norm.
const VAN_LOAN_NORM: f64 = 0.5;

/// e^M, the exponential of a square matrix.
///
/// nalgebra's `Matrix::exp` (Al-Mohy & Higham 2009 scaling and squaring, Padé degree
/// 3 to 13) with the checks it lacks: M must be square and finite (a NaN gives an
/// endless loop there), M with ‖M‖₁ above 2¹⁶ is scaled by 2^−s first and the result
/// squared s times (its choice of the degree takes ‖|M|²⁷‖₁, which overflows from
/// ‖M‖₁ ≈ 1e11 and then asks for 2⁶⁴ squarings), and a result that is not finite is an
/// error instead of a value.
///
/// # Errors
/// [`ContinuousError::Dimension`] when M is not square, [`ContinuousError::NonFinite`]
/// when it holds NaN or ±∞, [`ContinuousError::Overflow`] when e^M does not fit in a
/// double.
pub fn expm(m: &DMatrix<f64>) -> Result<DMatrix<f64>, ContinuousError> {
    if !m.is_square() {
        return Err(ContinuousError::Dimension {
            what: "matrix exponential",
            detail: format!("the matrix is {}×{}, not square", m.nrows(), m.ncols()),
        });
    }
    finite("matrix exponential", m)?;
    if m.is_empty() {
        return Ok(m.clone());
    }
    let norm = m.one_norm();
    // s halvings bring ‖M‖₁ to at most the cap: s ≤ 1024 − 16 for any finite M.
    let mut s = 0_i32;
    while norm * 2f64.powi(-s) > EXPM_NORM_CAP {
        s += 1;
    }
    let mut e = if s == 0 {
        m.exp()
    } else {
        (m * 2f64.powi(-s)).exp()
    };
    for _ in 0..s {
        e = &e * &e;
    }
    if e.iter().all(|v| v.is_finite()) {
        Ok(e)
    } else {
        Err(ContinuousError::Overflow { what: "e^{AT}" })
    }
}

/// The zero-order-hold discretisation of (A, B) with period T: F = e^{AT} and
/// G = ∫₀ᵀ e^{As} ds · B, from one exponential of `[[A, B], [0, 0]]·T` (Franklin,
/// Powell & Workman §6.3; Van Loan 1978, Theorem 1).
///
/// A is n×n (n ≥ 1); B is n×l, l = 0 allowed (no input).
///
/// # Errors
/// [`ContinuousError::Period`] unless T is finite and positive,
/// [`ContinuousError::Dimension`] for shapes, [`ContinuousError::NonFinite`] for NaN or
/// ±∞ in A or B, [`ContinuousError::Overflow`] when e^{AT} does not fit in a double.
pub fn zero_order_hold(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    period: f64,
) -> Result<(DMatrix<f64>, DMatrix<f64>), ContinuousError> {
    check_period(period)?;
    let n = check_a(a)?;
    if b.nrows() != n {
        return Err(ContinuousError::Dimension {
            what: "B",
            detail: format!("B has {} rows but A is {n}×{n}", b.nrows()),
        });
    }
    finite("B", b)?;
    let l = b.ncols();
    // G = c · (upper-right block) with B scaled to unit 1-norm inside (the block is
    // linear in B): the squarings are then set by A alone.
    let c = b.one_norm() * period;
    let c = if c > 0.0 && c.is_finite() { c } else { 1.0 };
    let mut aug = DMatrix::zeros(n + l, n + l);
    aug.view_mut((0, 0), (n, n)).copy_from(&(a * period));
    aug.view_mut((0, n), (n, l)).copy_from(&(b * (period / c)));
    let e = expm(&aug)?;
    let f = e.view((0, 0), (n, n)).into_owned();
    let g = e.view((0, n), (n, l)) * c;
    if !g.iter().all(|v| v.is_finite()) {
        return Err(ContinuousError::Overflow { what: "G" });
    }
    Ok((f, g))
}

/// The covariance Q = ∫₀ᵀ e^{As} Q_c e^{Aᵀs} ds of the noise W_k that a continuous white
/// noise of intensity Q_c adds to the state over one period T (Van Loan 1978,
/// Theorem 1: the exponential of `[[−A, Q_c], [0, Aᵀ]]·τ`), over τ = T/2^j with
/// ‖A‖₁τ ≤ 1/2 and j doublings Q(2τ) = Q(τ) + F(τ)Q(τ)F(τ)ᵀ (see the module's
/// documentation for why). Exactly symmetric; positive semi-definite when Q_c is, up to
/// rounding.
///
/// # Errors
/// [`ContinuousError::Period`] unless T is finite and positive,
/// [`ContinuousError::Dimension`] unless A and Q_c are n×n,
/// [`ContinuousError::NonFinite`] for NaN or ±∞, [`ContinuousError::NotSymmetric`] when
/// Q_c is not symmetric (to 1e-9 of its largest entry), [`ContinuousError::Overflow`]
/// when Q does not fit in a double.
pub fn process_noise(
    a: &DMatrix<f64>,
    qc: &DMatrix<f64>,
    period: f64,
) -> Result<DMatrix<f64>, ContinuousError> {
    check_period(period)?;
    let n = check_a(a)?;
    if qc.shape() != (n, n) {
        return Err(ContinuousError::Dimension {
            what: "Qc",
            detail: format!("Qc is {}×{} but A is {n}×{n}", qc.nrows(), qc.ncols()),
        });
    }
    finite("Qc", qc)?;
    let asymmetry = (qc - qc.transpose()).amax();
    if asymmetry > 1e-9 * qc.amax() {
        return Err(ContinuousError::NotSymmetric {
            what: "Qc",
            asymmetry,
        });
    }
    let scale = qc.one_norm();
    if scale == 0.0 {
        return Ok(DMatrix::zeros(n, n));
    }
    // τ = T/2^j with ‖A‖₁τ ≤ 1/2 (j ≤ 1100 for any finite A and T).
    let norm = a.one_norm() * period;
    let mut halvings = 0_i32;
    while norm * 2f64.powi(-halvings) > VAN_LOAN_NORM {
        halvings += 1;
    }
    let tau = period * 2f64.powi(-halvings);
    // The upper-right block is linear in Q_c: Q_c is scaled to unit 1-norm over τ inside
    // the exponential and the result scaled back, so that its units do not drive the
    // squarings.
    let c = scale * tau;
    let mut block = DMatrix::zeros(2 * n, 2 * n);
    block.view_mut((0, 0), (n, n)).copy_from(&(a * -tau));
    block.view_mut((0, n), (n, n)).copy_from(&(qc * (tau / c)));
    block
        .view_mut((n, n), (n, n))
        .copy_from(&(a.transpose() * tau));
    let e = expm(&block)?;
    let mut f = e.view((n, n), (n, n)).transpose();
    let mut q = &f * e.view((0, n), (n, n)) * c;
    symmetrise(&mut q);
    for _ in 0..halvings {
        q += &f * &q * f.transpose();
        symmetrise(&mut q);
        f = &f * &f;
    }
    if q.iter().all(|v| v.is_finite()) {
        Ok(q)
    } else {
        Err(ContinuousError::Overflow { what: "Q" })
    }
}

/// A continuous-time model (A, B, and optionally Q_c) and its zero-order-hold
/// discretisation with period T: F, G and, with Q_c, Q.
#[derive(Debug, Clone, PartialEq)]
pub struct Discretisation {
    period: f64,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    qc: Option<DMatrix<f64>>,
    f: DMatrix<f64>,
    g: DMatrix<f64>,
    q: Option<DMatrix<f64>>,
}

impl Discretisation {
    /// Discretises dx/dt = A x + B u + w, cov intensity Q_c (when given), with a
    /// zero-order hold of period T: [`zero_order_hold`] and [`process_noise`].
    ///
    /// # Errors
    /// As [`zero_order_hold`] and [`process_noise`].
    pub fn zero_order_hold(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        qc: Option<&DMatrix<f64>>,
        period: f64,
    ) -> Result<Self, ContinuousError> {
        let (f, g) = zero_order_hold(a, b, period)?;
        let q = qc.map(|qc| process_noise(a, qc, period)).transpose()?;
        Ok(Self {
            period,
            a: a.clone(),
            b: b.clone(),
            qc: qc.cloned(),
            f,
            g,
            q,
        })
    }

    /// The sample period T, in seconds (the unit of A's 1/time).
    #[must_use]
    pub fn period(&self) -> f64 {
        self.period
    }

    /// A (n×n), as given.
    #[must_use]
    pub fn a(&self) -> &DMatrix<f64> {
        &self.a
    }

    /// B (n×l), as given.
    #[must_use]
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }

    /// Q_c (n×n), if given.
    #[must_use]
    pub fn qc(&self) -> Option<&DMatrix<f64>> {
        self.qc.as_ref()
    }

    /// F = e^{AT}.
    #[must_use]
    pub fn f(&self) -> &DMatrix<f64> {
        &self.f
    }

    /// G = ∫₀ᵀ e^{As} ds · B.
    #[must_use]
    pub fn g(&self) -> &DMatrix<f64> {
        &self.g
    }

    /// Q = ∫₀ᵀ e^{As} Q_c e^{Aᵀs} ds, when Q_c was given.
    #[must_use]
    pub fn q(&self) -> Option<&DMatrix<f64>> {
        self.q.as_ref()
    }

    /// The eigenvalues of F, largest modulus first (each of a complex pair listed); `None`
    /// when the real Schur decomposition does not converge in 10⁴ iterations. They are
    /// e^{λT} for the eigenvalues λ of A: modulus below 1 for a stable mode.
    #[must_use]
    pub fn eigenvalues(&self) -> Option<Vec<Complex<f64>>> {
        let schur = nalgebra::linalg::Schur::try_new(self.f.clone(), f64::EPSILON, 10_000)?;
        let mut eig: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();
        eig.sort_by(|x, y| y.norm().total_cmp(&x.norm()).then(y.im.total_cmp(&x.im)));
        Some(eig)
    }

    /// The spectral radius of F (the largest |eigenvalue|): below 1 when every mode of
    /// the model is stable.
    #[must_use]
    pub fn spectral_radius(&self) -> Option<f64> {
        self.eigenvalues()
            .map(|e| e.iter().map(|z| z.norm()).fold(0.0, f64::max))
    }
}

/// One line: the period, the method, the eigenvalues of F, stability and the time
/// constants −T/ln|μ| of the stable modes (four significant digits), e.g. `sampled every
/// T = 20 s: F = e^{AT}, G = ∫₀ᵀe^{As}ds·B (zero-order hold), Q = ∫₀ᵀe^{As}·Qc·e^{Aᵀs}ds
/// (Van Loan 1978); eigenvalues of F 0.9817, 0.9794 (stable, spectral radius 0.9817;
/// time constants 1080 s, 960 s)`.
impl fmt::Display for Discretisation {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            out,
            "sampled every T = {} s: F = e^{{AT}}, G = ∫₀ᵀe^{{As}}ds·B (zero-order hold)",
            self.period
        )?;
        if self.q.is_some() {
            out.write_str(", Q = ∫₀ᵀe^{As}·Qc·e^{Aᵀs}ds (Van Loan 1978)")?;
        }
        let Some(eig) = self.eigenvalues() else {
            return out.write_str("; eigenvalues of F not computed (no convergence)");
        };
        // A conjugate pair once, as a ± b·i.
        let shown: Vec<String> = eig
            .iter()
            .filter(|z| z.im >= 0.0)
            .map(|z| {
                if z.im == 0.0 {
                    format!("{:.4}", z.re)
                } else {
                    format!("{:.4} ± {:.4}i", z.re, z.im)
                }
            })
            .collect();
        let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
        // e^{λT} of λ = 0 (an integrator) or λ = ±iω is 1 in modulus up to rounding.
        let verdict = if (radius - 1.0).abs() <= 1e-12 {
            "marginally stable: a mode on the unit circle (an integrator or an undamped oscillation)"
        } else if radius < 1.0 {
            "stable"
        } else {
            "unstable"
        };
        write!(
            out,
            "; eigenvalues of F {} ({verdict}, spectral radius {radius:.4}",
            shown.join(", ")
        )?;
        let constants: Vec<String> = eig
            .iter()
            .filter(|z| z.im >= 0.0 && z.norm() > 0.0 && z.norm() < 1.0)
            .map(|z| format!("{} s", significant(-self.period / z.norm().ln())))
            .collect();
        if !constants.is_empty() {
            write!(out, "; time constants {}", constants.join(", "))?;
        }
        out.write_str(")")
    }
}

/// A positive number to four significant digits, without trailing zeros: a time
/// constant from a rounded A (1079.995 s) reads 1080, 12.5 reads 12.5.
fn significant(x: f64) -> String {
    let decimals = (3 - x.log10().floor() as i32).max(0) as usize;
    let text = format!("{x:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

fn check_period(period: f64) -> Result<(), ContinuousError> {
    if period.is_finite() && period > 0.0 {
        Ok(())
    } else {
        Err(ContinuousError::Period { period })
    }
}

/// n, for an n×n, non-empty, finite A.
fn check_a(a: &DMatrix<f64>) -> Result<usize, ContinuousError> {
    let (n, n2) = a.shape();
    if n != n2 || n == 0 {
        return Err(ContinuousError::Dimension {
            what: "A",
            detail: format!("A must be square and non-empty, got {n}×{n2}"),
        });
    }
    finite("A", a)?;
    Ok(n)
}

fn finite(what: &'static str, m: &DMatrix<f64>) -> Result<(), ContinuousError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ContinuousError::NonFinite { what })
    }
}

/// M ← (M + Mᵀ)/2, exactly symmetric.
fn symmetrise(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    for i in 0..n {
        for j in i + 1..n {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, v)
    }

    #[test]
    fn expm_of_a_rotation_generator_is_the_rotation() {
        let w = 0.7;
        let e = expm(&m(2, 2, &[0.0, w, -w, 0.0])).unwrap();
        let want = m(2, 2, &[w.cos(), w.sin(), -w.sin(), w.cos()]);
        assert!((e - want).amax() < 1e-15);
    }

    #[test]
    fn expm_of_a_large_norm_matrix_is_finite_and_scaled_down_first() {
        // ‖M‖₁ = 2e12: the prescaling path (nalgebra alone would take ‖|M|²⁷‖₁ = ∞).
        // The slow mode pays for the ~41 squarings the fast one needs: each doubles a
        // relative error, so the bound is about u·‖M‖₁ (4e-4; 7e-9 is observed).
        let e = expm(&m(2, 2, &[-2e12, 0.0, 0.0, -1.0])).unwrap();
        assert_eq!(e[(0, 0)], 0.0);
        let slow = (-1.0f64).exp();
        assert!((e[(1, 1)] - slow).abs() < f64::EPSILON * 2e12 * slow);
        assert!((e[(1, 1)] - slow).abs() < 1e-8 * slow);
    }

    #[test]
    fn errors_name_the_matrix_and_the_period() {
        let a = m(1, 1, &[-1.0]);
        let e = zero_order_hold(&a, &m(1, 1, &[1.0]), 0.0).unwrap_err();
        assert_eq!(e, ContinuousError::Period { period: 0.0 });
        let e = zero_order_hold(&a, &m(1, 1, &[1.0]), f64::NAN).unwrap_err();
        assert!(matches!(e, ContinuousError::Period { .. }), "{e}");
        let e = zero_order_hold(&m(1, 2, &[1.0, 2.0]), &m(1, 1, &[1.0]), 1.0).unwrap_err();
        assert!(e.to_string().contains("A must be square"), "{e}");
        let e = zero_order_hold(&a, &m(2, 1, &[1.0, 2.0]), 1.0).unwrap_err();
        assert!(e.to_string().contains("B has 2 rows but A is 1×1"), "{e}");
        let e = zero_order_hold(&a, &m(1, 1, &[f64::INFINITY]), 1.0).unwrap_err();
        assert_eq!(e, ContinuousError::NonFinite { what: "B" });
        let e = process_noise(&a, &m(2, 2, &[1.0, 0.0, 0.0, 1.0]), 1.0).unwrap_err();
        assert!(e.to_string().contains("Qc is 2×2 but A is 1×1"), "{e}");
        let e =
            process_noise(&m(2, 2, &[0.0; 4]), &m(2, 2, &[1.0, 0.5, 0.0, 1.0]), 1.0).unwrap_err();
        assert!(
            matches!(e, ContinuousError::NotSymmetric { what: "Qc", .. }),
            "{e}"
        );
        let e = expm(&m(1, 1, &[f64::NAN])).unwrap_err();
        assert!(matches!(e, ContinuousError::NonFinite { .. }), "{e}");
    }

    #[test]
    fn an_exploding_mode_is_an_overflow_error() {
        let e = zero_order_hold(&m(1, 1, &[100.0]), &m(1, 1, &[1.0]), 10.0).unwrap_err();
        assert!(matches!(e, ContinuousError::Overflow { .. }), "{e}");
    }

    #[test]
    fn no_input_and_zero_noise_are_allowed() {
        let a = m(2, 2, &[-1.0, 0.0, 0.0, -2.0]);
        let (f, g) = zero_order_hold(&a, &DMatrix::zeros(2, 0), 0.5).unwrap();
        assert_eq!(g.shape(), (2, 0));
        assert!((f[(1, 1)] - (-1.0f64).exp()).abs() < 1e-15);
        let q = process_noise(&a, &DMatrix::zeros(2, 2), 0.5).unwrap();
        assert_eq!(q, DMatrix::zeros(2, 2));
    }

    #[test]
    fn the_summary_names_period_method_and_stability() {
        let a = m(2, 2, &[-1.0 / 600.0, 0.0, 1.0 / 600.0, -1.0 / 300.0]);
        let d = Discretisation::zero_order_hold(
            &a,
            &m(2, 1, &[1.0, 0.0]),
            Some(&DMatrix::identity(2, 2)),
            20.0,
        )
        .unwrap();
        let text = d.to_string();
        assert!(text.starts_with("sampled every T = 20 s"), "{text}");
        assert!(text.contains("Van Loan 1978"), "{text}");
        assert!(text.contains("stable, spectral radius 0.9672"), "{text}");
        assert!(text.contains("time constants 600 s, 300 s"), "{text}");
        assert_eq!(significant(1079.995), "1080");
        assert_eq!(significant(12.5), "12.5");
        assert_eq!(significant(0.012345), "0.01235");
        let radius = d.spectral_radius().unwrap();
        assert!((radius - (-20.0f64 / 600.0).exp()).abs() < 1e-14);
        // An integrator (a = 0) and an oscillator (a complex pair).
        let d = Discretisation::zero_order_hold(
            &m(2, 2, &[0.0, 1.0, -1.0, 0.0]),
            &m(2, 1, &[0.0, 1.0]),
            None,
            0.1,
        )
        .unwrap();
        let text = d.to_string();
        assert!(
            text.contains("0.9950 ± 0.0998i (marginally stable"),
            "{text}"
        );
        assert!(!text.contains("Van Loan"), "{text}");
    }
}
