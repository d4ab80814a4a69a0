//! Covariances as written and as used: a constant symmetric matrix whose smallest
//! eigenvalue is only a rounding error below zero is projected onto the nearest positive
//! semi-definite matrix instead of being refused.
//!
//! # Why a tolerance, and why 10⁻⁵
//!
//! Papers print covariances rounded. Zhang & Basseville 2014 §6.2 gives the gas network's
//! Q = [[100.2766, −66.1165], [−66.1165, 43.5933]] to four decimals; as printed its
//! determinant is −3.7·10⁻³, so λ_min = −2.548·10⁻⁵ with λ_max = 143.87 (ratio −1.8·10⁻⁷).
//! Rounding every entry of a symmetric matrix to d decimals adds a symmetric ΔQ with
//! |ΔQ_ij| ≤ ½·10⁻ᵈ, which moves each eigenvalue by at most ‖ΔQ‖₂ ≤ ‖ΔQ‖_F ≤ n·½·10⁻ᵈ
//! (Weyl): a positive semi-definite matrix printed to d decimals keeps
//! λ_min ≥ −n·½·10⁻ᵈ. For the paper's Q that bound is −10⁻⁴ = −7·10⁻⁷·λ_max.
//!
//! [`PSD_TOLERANCE`] = 10⁻⁵, relative to the spectral radius, covers it 14 times over and
//! covers d-decimal printing of any matrix with n·½·10⁻ᵈ ≤ 10⁻⁵·λ_max (four decimals:
//! λ_max ≥ 5n). Counted in significant digits s of the largest entry (which for a PSD
//! matrix is at most λ_max), |ΔQ_ij| ≤ ½·10¹⁻ˢ·λ_max, so it covers s = 7 up to n = 20 and
//! s = 6 for n ≤ 2. A sign error or a swapped entry gives λ_min of the order of the
//! entries and is still refused; a matrix printed with too few digits is refused with a
//! message saying so.
//!
//! # The projection
//!
//! Higham (1988): in the Frobenius norm the nearest symmetric matrix with eigenvalues ≥ δ
//! to a symmetric M = V diag(λ) Vᵀ is V diag(max(λ_i, δ)) Vᵀ; the change is
//! ‖ΔM‖_F = ‖(δ − λ_i)₊‖₂, of the order of |λ_min|.
//!
//! - **Q** (positive semi-definite): δ = 0, Higham's nearest PSD matrix.
//! - **R and P₀** (positive definite: Σ_k = H_kP_kH_kᵀ + R_k must be invertible whatever
//!   P_k does, and the filter starts from P₀): δ = 10⁻⁵·λ_max. Rounding hides the true
//!   smallest eigenvalue somewhere in (0, 10⁻⁵·λ_max]; the top of that range trusts the
//!   nearly noise-free output combination no more than the printed figures allow, and
//!   keeps the condition number at most 10⁵ so Σ_k's Cholesky factor stays accurate.
//!   Clipping at 0 would leave R singular.
//!
//! Roundoff-level negatives (λ_min ≥ −10⁻⁹·λ_max, e.g. Q = G Gᵀ computed by a program)
//! are used as written, as before: projecting would only change the last bits.
//! LPV covariances are checked at their base point as before and never projected:
//! clipping the base would not make Q(p) PSD at other scheduling points, and projecting
//! at every p would change the model with p.

use nalgebra::DMatrix;

/// The largest negative eigenvalue accepted (and projected away) in a constant
/// covariance, relative to its spectral radius: |λ_min| ≤ `PSD_TOLERANCE`·ρ(M). See the
/// [module documentation](self) for what it covers.
pub const PSD_TOLERANCE: f64 = 1e-5;

/// Negative eigenvalues down to this fraction of the spectral radius are floating-point
/// noise: accepted silently and used as written.
const ROUNDOFF: f64 = 1e-9;

/// A positive definite matrix's smallest eigenvalue must exceed this fraction of the
/// largest to be used as written.
const DEFINITE: f64 = 1e-12;

/// What to do with a symmetric covariance.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Verdict {
    /// Use it as written.
    Kept,
    /// Use `matrix` instead: the nearest matrix with eigenvalues ≥ `floor`.
    Projected {
        /// The projected matrix.
        matrix: DMatrix<f64>,
        /// Smallest eigenvalue as written.
        lambda_min: f64,
        /// Largest eigenvalue as written.
        lambda_max: f64,
        /// The eigenvalue floor δ of the projection.
        floor: f64,
        /// max |ΔM_ij|.
        change: f64,
    },
    /// Beyond the tolerance.
    Rejected {
        /// Smallest eigenvalue.
        lambda_min: f64,
        /// Largest eigenvalue.
        lambda_max: f64,
    },
}

/// Classifies a symmetric matrix (symmetry is checked before) that must be positive
/// semi-definite, or positive definite when `definite`; projects it when it is within
/// [`PSD_TOLERANCE`] (Higham 1988; floors in the module documentation).
pub(crate) fn classify(m: &DMatrix<f64>, definite: bool) -> Verdict {
    let eig = m.clone().symmetric_eigen();
    let lambda_min = eig.eigenvalues.min();
    let lambda_max = eig.eigenvalues.max();
    let radius = eig.eigenvalues.amax();
    let kept = if definite {
        lambda_min > 0.0 && lambda_min > DEFINITE * lambda_max
    } else {
        lambda_min >= -ROUNDOFF * radius
    };
    if kept {
        return Verdict::Kept;
    }
    if !(lambda_max > 0.0 && lambda_min >= -PSD_TOLERANCE * radius) {
        return Verdict::Rejected {
            lambda_min,
            lambda_max,
        };
    }
    let floor = if definite {
        PSD_TOLERANCE * lambda_max
    } else {
        0.0
    };
    let clipped = eig.eigenvalues.map(|l| l.max(floor));
    let v = &eig.eigenvectors;
    let p = v * DMatrix::from_diagonal(&clipped) * v.transpose();
    // Exactly symmetric, so the symmetry check and the filter see the same matrix.
    let matrix = (&p + p.transpose()) * 0.5;
    let change = (&matrix - m).amax();
    Verdict::Projected {
        matrix,
        lambda_min,
        lambda_max,
        floor,
        change,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zhang & Basseville 2014 §6.2, as printed.
    fn paper_q() -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, &[100.2766, -66.1165, -66.1165, 43.5933])
    }

    fn projected(v: Verdict) -> (DMatrix<f64>, f64, f64) {
        match v {
            Verdict::Projected {
                matrix,
                lambda_min,
                change,
                ..
            } => (matrix, lambda_min, change),
            other => panic!("expected a projection, got {other:?}"),
        }
    }

    #[test]
    fn paper2014_gas_q_is_projected_within_1e_4_and_is_then_kept() {
        let q = paper_q();
        let (p, lambda_min, change) = projected(classify(&q, false));
        assert!((lambda_min + 2.548e-5).abs() < 1e-8, "{lambda_min:e}");
        assert!(change < 1e-4 && change > 1e-6, "{change:e}");
        assert_eq!(p, p.transpose());
        let eig = p.clone().symmetric_eigenvalues();
        assert!(eig.min() >= -ROUNDOFF * eig.amax(), "{eig}");
        // The projection moves only the null direction: the large eigenvalue stays.
        assert!((eig.max() - 143.869_925_5).abs() < 1e-6, "{eig}");
        assert_eq!(classify(&p, false), Verdict::Kept);
    }

    #[test]
    fn rounding_to_4_decimals_stays_within_the_bound_n_half_1e_4() {
        // A family of exactly singular PSD matrices a·[c², −cs; −cs, s²] printed to four
        // decimals: λ_min never goes below −n·½·10⁻⁴ = −10⁻⁴, and all are accepted.
        let round = |x: f64| (x * 1e4).round() / 1e4;
        let mut worst: f64 = 0.0;
        for i in 1..200 {
            let t = f64::from(i) * 0.0157;
            let (c, s) = (t.cos(), t.sin());
            let a = 10.0 + f64::from(i);
            let m = DMatrix::from_fn(2, 2, |r, k| {
                let u = [c, -s];
                round(a * u[r] * u[k])
            });
            let lo = m.clone().symmetric_eigenvalues().min();
            worst = worst.min(lo);
            assert!(lo >= -1e-4, "{m} λ_min {lo:e}");
            assert!(
                !matches!(classify(&m, false), Verdict::Rejected { .. }),
                "{m}"
            );
        }
        assert!(
            worst < -1e-6,
            "the sweep should produce negative eigenvalues: {worst:e}"
        );
    }

    #[test]
    fn one_percent_negative_is_rejected() {
        let m = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.0, -1e-2]));
        assert_eq!(
            classify(&m, false),
            Verdict::Rejected {
                lambda_min: -1e-2,
                lambda_max: 1.0
            }
        );
        assert!(matches!(classify(&m, true), Verdict::Rejected { .. }));
    }

    #[test]
    fn roundoff_negatives_are_kept_as_written() {
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0 - 1e-12]);
        assert_eq!(classify(&m, false), Verdict::Kept);
    }

    #[test]
    fn a_singular_r_is_lifted_to_the_floor_and_becomes_definite() {
        let r = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 1.0 - 1e-6]);
        let (p, lambda_min, change) = projected(classify(&r, true));
        assert!(lambda_min < 0.0);
        let eig = p.clone().symmetric_eigenvalues();
        let want = PSD_TOLERANCE * 5.0;
        assert!((eig.min() - want).abs() < 1e-9 * want.max(1.0), "{eig}");
        assert!(change <= want + 1e-6, "{change:e}");
        assert_eq!(classify(&p, true), Verdict::Kept);
    }

    #[test]
    fn zero_and_negative_definite_r_are_rejected() {
        assert!(matches!(
            classify(&DMatrix::zeros(1, 1), true),
            Verdict::Rejected { .. }
        ));
        assert!(matches!(
            classify(&DMatrix::from_element(1, 1, -1.0), false),
            Verdict::Rejected { .. }
        ));
    }
}
