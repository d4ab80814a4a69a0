//! Pre-deployment isolability report: can the faults of a dictionary be told apart over
//! one GLR window?
//!
//! The input is the Fisher information of the fault magnitudes over one window,
//! F = C_k(r) = Σ_j S_jᵀ Σ_j⁻¹ S_j (Zhang & Basseville 2014, eq. (32)), an m × m symmetric
//! positive semi-definite matrix. It is the matrix Basseville (1996) calls **F** (eq. (84);
//! her number of faults q is our m). From it [`isolability`] derives
//!
//! * the numerical rank and condition number of F,
//! * the correlation matrix ρ_ij = F_ij / √(F_ii F_jj) and a verdict for every pair,
//! * the faults that are undetectable over the window (F_jj ≈ 0),
//! * the three isolation criteria C1, C2, C3 of M. Basseville, *Information criteria for
//!   residual generation and fault detection and isolation*, INRIA RR-2890 (1996),
//!   §5-§6, in particular §6.3, eqs. (89)-(92).
//!
//! # Why a high correlation means "not isolable"
//!
//! The minmax test for fault a treats the other faults b as nuisance parameters and
//! replaces them by their least favourable value (Basseville 1996 §3.2.3, Lemma 3.7): the
//! statistic t*_a (49) is χ² with noncentrality K*(η_a) = η_aᵀ F*_a η_a (50), where F*_a
//! is the Schur complement of Lemma 3.4, eq. (32):
//!
//! ```text
//! F*_a = F_aa − F_ab F_bb⁻¹ F_ba .
//! ```
//!
//! For a pair of scalar faults this is F*_a = F_aa − F_ab²/F_bb = F_aa (1 − ρ_ab²): only
//! the fraction 1 − ρ² of fault a's information survives the rejection of fault b. At
//! |ρ| = 0.95 ([`DEFAULT_CORRELATION_LIMIT`]) less than 10 % is left, i.e. a fault must be
//! 1/√(1 − ρ²) ≈ 3.2 times larger to be isolated than to be detected; as |ρ| → 1 nothing
//! is left and the two faults cannot be told apart at any magnitude.
//!
//! # The three isolation criteria (Basseville 1996, §6.2-§6.3)
//!
//! All three are built on the Kullback distance between two zero-mean Gaussian laws with
//! covariances Σ₁, Σ₂ (eq. (87)):
//!
//! ```text
//! K(Σ₁, Σ₂) = ½ ( tr(Σ₁Σ₂⁻¹ − I_q) − ln|Σ₁Σ₂⁻¹| )                       (87)
//! ```
//!
//! and measure how far F is from a diagonal matrix, because a diagonal F means that the
//! fault "inertia" Υᵀ F Υ (eq. (86)) is a sum of per-fault contributions with no cross
//! terms (§6.1):
//!
//! ```text
//! C1(F) = K(F, I_q)            = ½ (Σ F_ii − ln|F| − q)                    (89), (92)
//! C2(F) = min_δ>0 K(F, δ I_q)  = ½ (q ln(Σ F_ii / q) − ln|F|)   [δ* = tr F / q]   (90), (92)
//! C3(F) = min_Δ>0 K(F, Δ)      = ½ (Σ ln F_ii − ln|F|)          [Δ* = diag F]     (91), (92)
//!       = C0(F) = −½ ln(|F| / Π F_ii)
//! ```
//!
//! C3 = C0 is the mutual information among the components of a Gaussian vector with
//! covariance F, i.e. the mutual information among the fault components.
//!
//! | criterion | 0 exactly when        | invariant under                           |
//! |-----------|-----------------------|-------------------------------------------|
//! | C1        | F = I                 | orthogonal F ↦ AFAᵀ                       |
//! | C2        | F = δ I (δ > 0)       | orthogonal, common scale F ↦ δF           |
//! | C3        | F diagonal            | change of fault units F ↦ DFD (D diagonal) |
//!
//! C1 is "a very strong isolation constraint, because the faults generally have different
//! units" (§6.3); C2 only asks for balanced sensitivities; C3 only asks for no coupling.
//! Since each is a minimum of the same distance over a larger set of reference matrices
//! ({I} ⊂ {δI} ⊂ {Δ}), always C1 ≥ C2 ≥ C3 ≥ 0. The paper applies them to F as it is,
//! without normalisation, and so does this module. (Applied to the unit-diagonal
//! correlation matrix all three would collapse to C3, which is already unit-free.) For
//! "can the faults be told apart", C3 and the correlations are the relevant, unit-free
//! numbers; C1 and C2 additionally penalise unbalanced sensitivities and so depend on the
//! units in which the fault magnitudes are expressed.
//!
//! The criteria are Kullback distances K(F, Δ) to a positive definite Δ, whose −ln|F| term
//! diverges when F is singular (the Gaussian law with covariance F is degenerate): for a
//! singular F — including any undetectable fault — all three are `f64::INFINITY`.
//!
//! Numerically, ln|F| is evaluated as Σ ln F_ii + ln|R| with R the correlation matrix, so
//! that C3 = −½ ln|R|, C2 = C3 + ½ Σ ln(tr F / (q F_ii)) and
//! C1 = C3 + ½ Σ (F_ii − 1 − ln F_ii); this is the same as (92) but accurate when the
//! fault units differ by many orders of magnitude.
//!
//! # Numerical decisions
//!
//! The relative tolerance τ = 10⁻⁹ is the detector's default rank tolerance
//! (`DEFAULT_RANK_TOLERANCE`). Every decision is taken on unit-free numbers, so that no
//! verdict depends on the units in which the fault magnitudes are expressed (a cut-off
//! relative to the largest F_jj called a gas-pipeline outlet leak of θ ≈ −4·10⁴
//! undetectable next to two inlet faults of θ ≈ 10⁻⁵, because its F_jj was below 10⁻⁹
//! of theirs):
//!
//! * a fault is **undetectable** when F_jj = 0 (F_jj ≤ 0): its signature vanishes over
//!   the window, and the GLR's LDLᵀ factorisation of C_k(r), which keeps pivot j when
//!   D_j > τ·C_jj, drops it; any F_jj > 0, however small in the chosen units, is
//!   information the detector uses;
//! * the **rank** counts the eigenvalues λ > τ · λ_max(R) of the correlation matrix R of
//!   the detectable faults (F equilibrated to a unit diagonal, as the isolation tests
//!   decide their ranks); F is singular when the rank is below m.
//!
//! ρ, C3, the rank and the verdicts do not depend on the fault units; the condition
//! number of F, C1 and C2 do.

use nalgebra::{DMatrix, SymmetricEigen};

/// |ρ| above which two faults are declared not separable by the minmax test over the window.
///
/// At |ρ| = 0.95 the minmax test keeps 1 − ρ² < 10 % of a fault's information once the
/// other fault is rejected (see the [module documentation](self)).
pub const DEFAULT_CORRELATION_LIMIT: f64 = 0.95;

/// Relative tolerance of the rank (on the correlation matrix), of the positive
/// semi-definiteness checks and of 1 − ρ² for a pair (the detector's
/// `DEFAULT_RANK_TOLERANCE`).
const TOLERANCE: f64 = 1e-9;

/// Largest accepted |F_ij − F_ji| / √(F_ii F_jj).
const SYMMETRY_TOLERANCE: f64 = 1e-8;

/// Isolability of a fault dictionary over one window, computed by [`isolability`].
#[derive(Debug, Clone, PartialEq)]
pub struct IsolabilityReport {
    /// Numerical rank of F: the number of eigenvalues above 10⁻⁹ · λ_max(R) of the
    /// correlation matrix R of the detectable faults (independent of the fault units).
    pub rank: usize,
    /// λ_max(F) / λ_min(F) (in the units of the dictionary); `f64::INFINITY` when F is
    /// singular (rank < m or an undetectable fault) or λ_min(F) is not positive in
    /// floating point.
    pub condition_number: f64,
    /// Basseville (1996) eq. (89): C1 = K(F, I) = ½ (tr F − ln|F| − m), the Kullback
    /// distance between F and the identity. 0 exactly when F = I (perfectly isolable *and*
    /// unit sensitivities); not invariant to the fault units. `f64::INFINITY` when F is
    /// singular.
    pub c1: f64,
    /// Basseville (1996) eq. (90): C2 = min_δ K(F, δI) = ½ (m ln(tr F / m) − ln|F|), the
    /// Kullback distance to the nearest multiple of the identity. 0 exactly when F = δI
    /// (perfectly isolable with balanced sensitivities); invariant to a common scale of F.
    /// `f64::INFINITY` when F is singular.
    pub c2: f64,
    /// Basseville (1996) eq. (91): C3 = min_Δ K(F, Δ) = −½ ln(|F| / Π F_ii) = −½ ln det ρ, the
    /// mutual information among the fault components (C0 in the paper). 0 exactly when F
    /// is diagonal (perfectly isolable); invariant to the fault units. `f64::INFINITY` when
    /// F is singular.
    pub c3: f64,
    /// ρ_ij = F_ij / √(F_ii F_jj); the row and column of an undetectable fault (diagonal
    /// entry included) are 0.
    pub correlation: DMatrix<f64>,
    /// One verdict per pair i < j, in lexicographic order (0,1), (0,2), …, (1,2), ….
    pub pairs: Vec<PairVerdict>,
    /// Faults whose information F_jj is zero: their signature vanishes over the window,
    /// so no test can see them. Ascending.
    pub undetectable: Vec<usize>,
    /// The |ρ| limit the pair verdicts were made with.
    pub correlation_limit: f64,
}

/// Whether two faults can be told apart by the minmax test over the window.
#[derive(Debug, Clone, PartialEq)]
pub struct PairVerdict {
    /// Index of the first fault (a < b).
    pub a: usize,
    /// Index of the second fault.
    pub b: usize,
    /// ρ_ab = F_ab / √(F_aa F_bb) (0 if either fault is undetectable).
    pub correlation: f64,
    /// Both faults are detectable, |ρ_ab| ≤ the correlation limit, and the pair keeps
    /// information after rejection (1 − ρ_ab² > 10⁻⁹).
    pub separable: bool,
}

/// Why an isolability report could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IsolabilityError {
    /// The information matrix is not square.
    #[error("information matrix is {rows}×{cols}, not square")]
    NotSquare {
        /// Number of rows.
        rows: usize,
        /// Number of columns.
        cols: usize,
    },
    /// The information matrix has a NaN or infinite entry.
    #[error("information matrix has a non-finite entry")]
    NonFinite,
    /// The information matrix is 0×0 (no faults).
    #[error("information matrix is empty (no faults)")]
    Empty,
    /// The information matrix is not symmetric.
    #[error(
        "information matrix is not symmetric (max |F_ij − F_ji| / √(F_ii F_jj) = {max_asymmetry:e})"
    )]
    NotSymmetric {
        /// Largest |F_ij − F_ji| / √(|F_ii F_jj|) (infinite when F_ij ≠ F_ji and F_ii or
        /// F_jj is 0).
        max_asymmetry: f64,
    },
    /// The information matrix (or its correlation matrix) has a clearly negative
    /// eigenvalue, so it is not a Fisher information matrix.
    #[error(
        "information matrix is not positive semi-definite (relative min eigenvalue {relative_min_eigenvalue:e})"
    )]
    NotPositiveSemidefinite {
        /// λ_min / max |λ| of F, or of the correlation matrix of the detectable faults,
        /// whichever check failed (below −10⁻⁹).
        relative_min_eigenvalue: f64,
    },
    /// The correlation limit is NaN or outside [0, 1].
    #[error("correlation limit {limit} is not in [0, 1]")]
    InvalidCorrelationLimit {
        /// The rejected limit.
        limit: f64,
    },
}

/// Isolability report for the Fisher information `information` = F = C_k(r) of the
/// fault dictionary over one window.
///
/// Pairs with |ρ| > `correlation_limit` (usually [`DEFAULT_CORRELATION_LIMIT`]) are
/// declared not separable. See the [module documentation](self) for the definitions.
///
/// # Errors
/// [`IsolabilityError`] when F is not square, empty, has a non-finite entry, is not
/// symmetric (relative tolerance 10⁻⁸) or not positive semi-definite (relative tolerance
/// 10⁻⁹), or when `correlation_limit` is not in [0, 1].
///
/// # Examples
///
/// ```
/// use glrmon_core::isolation::isolability::{isolability, DEFAULT_CORRELATION_LIMIT};
/// use nalgebra::DMatrix;
///
/// // Three faults; "b" and "c" have nearly proportional signatures (ρ = 0.998),
/// // "a" is decoupled from both.
/// let f = DMatrix::from_row_slice(3, 3, &[
///     4.0, 0.0,   0.0,
///     0.0, 1.0,   2.994,
///     0.0, 2.994, 9.0,
/// ]);
/// let report = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
/// assert_eq!(report.rank, 3);
/// assert!(report.pairs[0].separable && report.pairs[1].separable); // (a,b), (a,c)
/// assert!(!report.pairs[2].separable);                            // (b,c)
/// // C3 is the mutual information among the faults: −½ ln(1 − ρ²) here.
/// assert!((report.c3 + 0.5 * (1.0 - 0.998_f64.powi(2)).ln()).abs() < 1e-9);
/// assert!(report.c1 >= report.c2 && report.c2 >= report.c3);
/// assert_eq!(
///     report.verdicts(&["a", "b", "c"], 100),
///     vec!["fault \"b\" and fault \"c\" cannot be told apart by the minmax test over \
///           100 samples (correlation 0.998 > 0.95)"],
/// );
/// ```
pub fn isolability(
    information: &DMatrix<f64>,
    correlation_limit: f64,
) -> Result<IsolabilityReport, IsolabilityError> {
    let (rows, cols) = information.shape();
    if rows != cols {
        return Err(IsolabilityError::NotSquare { rows, cols });
    }
    let m = rows;
    if m == 0 {
        return Err(IsolabilityError::Empty);
    }
    if information.iter().any(|x| !x.is_finite()) {
        return Err(IsolabilityError::NonFinite);
    }
    if !(0.0..=1.0).contains(&correlation_limit) {
        return Err(IsolabilityError::InvalidCorrelationLimit {
            limit: correlation_limit,
        });
    }

    // Symmetry, relative to the geometric mean of the two diagonal entries (unit-free:
    // no floor taken from the other faults' entries).
    let mut max_asymmetry = 0.0_f64;
    for i in 0..m {
        for j in (i + 1)..m {
            let diff = (information[(i, j)] - information[(j, i)]).abs();
            if diff == 0.0 {
                continue;
            }
            let scale = information[(i, i)].abs().sqrt() * information[(j, j)].abs().sqrt();
            let rel = if scale > 0.0 {
                diff / scale
            } else {
                f64::INFINITY
            };
            max_asymmetry = max_asymmetry.max(rel);
        }
    }
    if max_asymmetry > SYMMETRY_TOLERANCE {
        return Err(IsolabilityError::NotSymmetric { max_asymmetry });
    }
    let f = (information + information.transpose()) * 0.5;

    // Spectrum of F: positive semi-definiteness, condition number.
    let eig = f.clone().symmetric_eigenvalues();
    let lambda_max = eig.max();
    let lambda_min = eig.min();
    let spectral_norm = lambda_max.abs().max(lambda_min.abs());
    if lambda_min < -TOLERANCE * spectral_norm {
        return Err(IsolabilityError::NotPositiveSemidefinite {
            relative_min_eigenvalue: lambda_min / spectral_norm,
        });
    }

    // Undetectable faults: F_jj = 0, a pivot the GLR's LDLᵀ drops whatever the units
    // (it keeps D_j > τ·C_jj).
    let d: Vec<f64> = (0..m).map(|i| f[(i, i)]).collect();
    let undetectable: Vec<usize> = (0..m).filter(|&i| d[i] <= 0.0).collect();
    let detectable: Vec<usize> = (0..m).filter(|i| !undetectable.contains(i)).collect();

    // Correlation matrix.
    let mut correlation = DMatrix::zeros(m, m);
    for &i in &detectable {
        for &j in &detectable {
            // √F_ii·√F_jj, not √(F_ii·F_jj): the product of two informations of size
            // 1e-200 underflows to 0 and made the correlation ±∞.
            correlation[(i, j)] = if i == j {
                1.0
            } else {
                f[(i, j)] / (d[i].sqrt() * d[j].sqrt())
            };
        }
    }

    // ln|R| over the detectable faults (also a scale-free PSD check).
    // (nalgebra's eigensolver panics on an empty matrix.)
    let r_eig: Vec<f64> = if detectable.is_empty() {
        Vec::new()
    } else {
        let r_det = correlation
            .select_rows(&detectable)
            .select_columns(&detectable);
        r_det.symmetric_eigenvalues().iter().copied().collect()
    };
    let r_min = r_eig.iter().copied().fold(1.0, f64::min);
    let r_max = r_eig.iter().copied().fold(1.0, f64::max);
    if r_min < -TOLERANCE * r_max {
        return Err(IsolabilityError::NotPositiveSemidefinite {
            relative_min_eigenvalue: r_min / r_max,
        });
    }
    // The rank on the correlation matrix: unit-free, as the isolation tests decide it.
    let rank = r_eig.iter().filter(|&&l| l > TOLERANCE * r_max).count();

    let singular = rank < m || r_min <= 0.0;
    let condition_number = if singular || lambda_min <= 0.0 {
        f64::INFINITY
    } else {
        lambda_max / lambda_min
    };
    let (c1, c2, c3) = if singular {
        (f64::INFINITY, f64::INFINITY, f64::INFINITY)
    } else {
        // (92) with ln|F| = Σ ln F_ii + ln|R|.
        let c3 = -0.5 * r_eig.iter().map(|l| l.ln()).sum::<f64>();
        let mean = d.iter().sum::<f64>() / m as f64;
        let c2_extra = 0.5 * d.iter().map(|&x| (mean / x).ln()).sum::<f64>();
        let c1_extra = 0.5
            * d.iter()
                .map(|&x| {
                    let e = x - 1.0;
                    e - e.ln_1p()
                })
                .sum::<f64>();
        let c3 = c3.max(0.0);
        let c2 = (c3 + c2_extra).max(c3);
        let c1 = (c3 + c1_extra).max(c2);
        (c1, c2, c3)
    };

    let mut pairs = Vec::with_capacity(m * m.saturating_sub(1) / 2);
    for a in 0..m {
        for b in (a + 1)..m {
            let rho = correlation[(a, b)];
            let separable = !undetectable.contains(&a)
                && !undetectable.contains(&b)
                && rho.abs() <= correlation_limit
                && 1.0 - rho * rho > TOLERANCE;
            pairs.push(PairVerdict {
                a,
                b,
                correlation: rho,
                separable,
            });
        }
    }

    Ok(IsolabilityReport {
        rank,
        condition_number,
        c1,
        c2,
        c3,
        correlation,
        pairs,
        undetectable,
        correlation_limit,
    })
}

impl IsolabilityReport {
    /// Number of faults m.
    pub fn faults(&self) -> usize {
        self.correlation.nrows()
    }

    /// `true` when every fault is detectable and every pair separable.
    pub fn isolable(&self) -> bool {
        self.undetectable.is_empty() && self.pairs.iter().all(|p| p.separable)
    }

    /// max |ρ_ab| over the pairs of faults: how close the least separable pair is to
    /// indistinguishable, the one number to read when there are too many pairs to list
    /// (0 with a single fault).
    #[must_use]
    pub fn max_pair_correlation(&self) -> f64 {
        self.pairs
            .iter()
            .map(|p| p.correlation.abs())
            .fold(0.0_f64, f64::max)
    }

    /// Plain-language verdicts, one line per non-separable pair or undetectable fault, given the fault names, e.g.
    /// `fault "a" and fault "b" cannot be told apart by the minmax test over 100 samples (correlation 0.998 > 0.95)`.
    ///
    /// `window` is the number of samples F was accumulated over (only used in the text).
    /// Faults without a name in `names` are called `#j`. Undetectable faults come first
    /// (one line each), then the non-separable pairs of detectable faults (a pair with an
    /// undetectable member is covered by that member's line). If F is singular although
    /// no line explains it (a linear dependence among three or more signatures that no
    /// single pair shows), one more line names the faults involved. An empty vector means
    /// the faults are isolable over the window.
    pub fn verdicts(&self, names: &[&str], window: usize) -> Vec<String> {
        let name = |j: usize| match names.get(j) {
            Some(n) => format!("fault \"{n}\""),
            None => format!("fault #{j}"),
        };
        let samples = if window == 1 {
            "1 sample".to_owned()
        } else {
            format!("{window} samples")
        };
        let mut lines = Vec::new();
        for &j in &self.undetectable {
            lines.push(format!(
                "{} is undetectable over {samples}: its signature is (numerically) zero, \
                 so it carries no information",
                name(j)
            ));
        }
        for p in &self.pairs {
            if p.separable || self.undetectable.contains(&p.a) || self.undetectable.contains(&p.b) {
                continue;
            }
            let why = if p.correlation.abs() > self.correlation_limit {
                if p.correlation >= 0.0 {
                    format!(
                        "correlation {:.3} > {}",
                        p.correlation, self.correlation_limit
                    )
                } else {
                    format!(
                        "correlation {:.3}, |correlation| > {}",
                        p.correlation, self.correlation_limit
                    )
                }
            } else {
                format!(
                    "correlation {:.3}: no information left after rejecting the other",
                    p.correlation
                )
            };
            lines.push(format!(
                "{} and {} cannot be told apart by the minmax test over {samples} ({why})",
                name(p.a),
                name(p.b)
            ));
        }
        if lines.is_empty() && self.c3.is_infinite() {
            lines.push(self.dependence_line(&name, &samples));
        }
        lines
    }

    /// Line for a singular F with no undetectable fault and no non-separable pair: the
    /// faults with weight in the null vector of the correlation matrix.
    fn dependence_line(&self, name: &dyn Fn(usize) -> String, samples: &str) -> String {
        let m = self.faults();
        let eig = SymmetricEigen::new(self.correlation.clone());
        let k = eig.eigenvalues.imin();
        let v = eig.eigenvectors.column(k);
        let vmax = v.amax();
        let involved: Vec<String> = (0..m)
            .filter(|&i| v[i].abs() > 1e-3 * vmax)
            .map(name)
            .collect();
        format!(
            "{} cannot be told apart by the minmax test over {samples}: their signatures are \
             linearly dependent (information matrix rank {} < {m})",
            involved.join(", "),
            self.rank.min(m - 1)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
    }

    /// (92) evaluated directly with determinants.
    fn criteria_92(f: &DMatrix<f64>) -> (f64, f64, f64) {
        let q = f.nrows() as f64;
        let ln_det = f.determinant().ln();
        let tr = f.trace();
        let sum_ln = f.diagonal().iter().map(|x| x.ln()).sum::<f64>();
        (
            0.5 * (tr - ln_det - q),
            0.5 * (q * tr.ln() - ln_det - q * q.ln()),
            0.5 * (sum_ln - ln_det),
        )
    }

    /// F = SᵀS from a signature matrix given column by column.
    fn gram(p: usize, columns: &[&[f64]]) -> DMatrix<f64> {
        let s = DMatrix::from_fn(p, columns.len(), |i, j| columns[j][i]);
        s.transpose() * s
    }

    #[test]
    fn max_pair_correlation_is_the_largest_absolute_correlation() {
        // ρ(0,1) = −0.9 (negative: the absolute value counts), ρ(0,2) = 0.3, ρ(1,2) = 0.
        let f = DMatrix::from_row_slice(3, 3, &[1.0, -0.9, 0.3, -0.9, 1.0, 0.0, 0.3, 0.0, 1.0]);
        let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
        assert!(close(r.max_pair_correlation(), 0.9, 1e-12));
        let single = isolability(&DMatrix::from_element(1, 1, 2.0), 0.95).unwrap();
        assert_eq!(single.max_pair_correlation(), 0.0);
    }

    #[test]
    fn diagonal_information_is_perfectly_isolable() {
        let f = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.0, 4.0, 9.0, 0.25]));
        let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
        assert_eq!(r.rank, 4);
        assert!(close(r.condition_number, 36.0, 1e-12));
        assert_eq!(r.c3, 0.0); // no coupling: mutual information 0
        let (c1, c2, _) = criteria_92(&f);
        assert!(close(r.c1, c1, 1e-12) && close(r.c2, c2, 1e-12));
        assert!(r.c1 > 0.0 && r.c2 > 0.0); // unbalanced sensitivities
        assert_eq!(r.correlation, DMatrix::identity(4, 4));
        assert_eq!(r.pairs.len(), 6);
        assert!(r.pairs.iter().all(|p| p.separable && p.correlation == 0.0));
        assert!(r.undetectable.is_empty());
        assert!(r.isolable());
        assert!(r.verdicts(&["a", "b", "c", "d"], 50).is_empty());
    }

    #[test]
    fn ideal_values_of_c1_and_c2() {
        let r = isolability(&DMatrix::identity(3, 3), 0.95).unwrap();
        assert_eq!((r.c1, r.c2, r.c3), (0.0, 0.0, 0.0));
        assert_eq!(r.condition_number, 1.0);
        let r = isolability(&(DMatrix::identity(3, 3) * 5.0), 0.95).unwrap();
        assert_eq!((r.c2, r.c3), (0.0, 0.0));
        // C1 = K(5I, I) = ½ q (5 − 1 − ln 5).
        assert!(close(r.c1, 1.5 * (4.0 - 5.0_f64.ln()), 1e-14));
    }

    /// Informations of size 1e-200 (signatures of size 1e-100) have a finite
    /// correlation; their product underflows, and once gave "correlation inf".
    #[test]
    fn tiny_informations_have_a_finite_correlation() {
        let f = DMatrix::from_row_slice(2, 2, &[1e-200, 0.5e-200, 0.5e-200, 1e-200]);
        let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
        assert!(
            close(r.correlation[(0, 1)], 0.5, 1e-12),
            "{}",
            r.correlation
        );
        assert!(r.isolable(), "{:?}", r.verdicts(&["a", "b"], 10));
    }

    #[test]
    fn pair_order_and_indices() {
        let r = isolability(&DMatrix::identity(4, 4), 0.95).unwrap();
        let idx: Vec<(usize, usize)> = r.pairs.iter().map(|p| (p.a, p.b)).collect();
        assert_eq!(idx, vec![(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]);
    }

    #[test]
    fn identical_signatures_are_not_separable() {
        let s0: &[f64] = &[1.0, -2.0, 0.5, 3.0];
        let s1: &[f64] = &[0.3, 1.0, 1.0, -1.0];
        let f = gram(4, &[s0, s1, s0]);
        let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
        assert_eq!(r.rank, 2);
        assert_eq!(r.condition_number, f64::INFINITY);
        assert_eq!(
            (r.c1, r.c2, r.c3),
            (f64::INFINITY, f64::INFINITY, f64::INFINITY)
        );
        assert!(r.undetectable.is_empty());
        let p02 = r.pairs.iter().find(|p| (p.a, p.b) == (0, 2)).unwrap();
        assert!(close(p02.correlation, 1.0, 1e-14));
        assert!(!p02.separable);
        assert!(
            r.pairs
                .iter()
                .filter(|p| (p.a, p.b) != (0, 2))
                .all(|p| p.separable)
        );
        assert!(!r.isolable());
        assert_eq!(
            r.verdicts(&["x", "y", "x_again"], 100),
            vec![
                "fault \"x\" and fault \"x_again\" cannot be told apart by the minmax test over \
                 100 samples (correlation 1.000 > 0.95)"
            ]
        );
        // Opposite signatures: ρ = −1, still not separable.
        let minus: Vec<f64> = s0.iter().map(|x| -2.0 * x).collect();
        let r = isolability(&gram(4, &[s0, &minus]), 0.95).unwrap();
        assert!(close(r.pairs[0].correlation, -1.0, 1e-14));
        assert!(!r.pairs[0].separable);
        assert_eq!(r.rank, 1);
        assert_eq!(
            r.verdicts(&["a", "b"], 1),
            vec![
                "fault \"a\" and fault \"b\" cannot be told apart by the minmax test over \
                 1 sample (correlation -1.000, |correlation| > 0.95)"
            ]
        );
        // Even with the limit at 1, a collinear pair keeps no information.
        let r = isolability(&gram(4, &[s0, s0]), 1.0).unwrap();
        assert!(!r.pairs[0].separable);
        assert!(r.verdicts(&["a", "b"], 10)[0].contains("no information left"));
    }

    #[test]
    fn zero_signature_is_undetectable() {
        let s0: &[f64] = &[1.0, 0.0, 2.0];
        let s1: &[f64] = &[0.0, 0.0, 0.0];
        let s2: &[f64] = &[0.0, 1.0, -1.0];
        let f = gram(3, &[s0, s1, s2]);
        let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
        assert_eq!(r.undetectable, vec![1]);
        assert_eq!(r.rank, 2);
        assert_eq!(r.condition_number, f64::INFINITY);
        assert_eq!(
            (r.c1, r.c2, r.c3),
            (f64::INFINITY, f64::INFINITY, f64::INFINITY)
        );
        assert_eq!(
            r.correlation.row(1).iter().copied().collect::<Vec<_>>(),
            vec![0.0; 3]
        );
        assert_eq!(
            r.correlation.column(1).iter().copied().collect::<Vec<_>>(),
            vec![0.0; 3]
        );
        assert_eq!(r.correlation[(0, 0)], 1.0);
        // Pairs with the undetectable fault are not separable, the other pair is.
        let sep: Vec<bool> = r.pairs.iter().map(|p| p.separable).collect();
        assert_eq!(sep, vec![false, true, false]);
        assert_eq!(
            r.verdicts(&["a", "dead"], 20),
            vec![
                "fault \"dead\" is undetectable over 20 samples: its signature is (numerically) \
                 zero, so it carries no information"
            ]
        );
        // Everything zero: everything undetectable, rank 0.
        let r = isolability(&DMatrix::zeros(2, 2), 0.95).unwrap();
        assert_eq!(r.undetectable, vec![0, 1]);
        assert_eq!(r.rank, 0);
        assert_eq!(r.c3, f64::INFINITY);
        assert_eq!(r.verdicts(&[], 5).len(), 2);
    }

    #[test]
    fn three_way_dependence_is_reported() {
        // s2 = s0 + s1 with pairwise |ρ| ≤ 0.82: every pair passes, F is singular.
        let s0: &[f64] = &[1.0, 0.0, 0.0];
        let s1: &[f64] = &[0.0, 1.0, 0.0];
        let s2: &[f64] = &[1.0, 1.0, 0.0];
        let s3: &[f64] = &[0.0, 0.0, 1.0];
        let r = isolability(&gram(3, &[s0, s1, s2, s3]), 0.95).unwrap();
        assert!(r.pairs.iter().all(|p| p.separable));
        assert_eq!(r.rank, 3);
        assert_eq!(r.c3, f64::INFINITY);
        assert_eq!(
            r.verdicts(&["a", "b", "c", "d"], 30),
            vec![
                "fault \"a\", fault \"b\", fault \"c\" cannot be told apart by the minmax test \
                 over 30 samples: their signatures are linearly dependent (information matrix \
                 rank 3 < 4)"
            ]
        );
    }

    #[test]
    fn names_fall_back_to_indices() {
        let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.99, 0.99, 1.0]);
        let r = isolability(&f, 0.95).unwrap();
        assert_eq!(
            r.verdicts(&["only"], 7),
            vec![
                "fault \"only\" and fault #1 cannot be told apart by the minmax test over \
                 7 samples (correlation 0.990 > 0.95)"
            ]
        );
    }

    #[test]
    fn schur_complement_identity_for_a_pair() {
        for (faa, fbb, rho) in [(2.0_f64, 0.5, 0.3), (1e3, 1e-3, -0.9), (7.0, 7.0, 0.999)] {
            let fab = rho * (faa * fbb).sqrt();
            let f = DMatrix::from_row_slice(2, 2, &[faa, fab, fab, fbb]);
            let r = isolability(&f, 0.95).unwrap();
            let rho_hat = r.correlation[(0, 1)];
            assert!(close(rho_hat, rho, 1e-14));
            // F*_a = F_aa − F_ab F_bb⁻¹ F_ba (Basseville 1996 eq. (32)) = F_aa (1 − ρ²).
            let schur_a = faa - fab * fab / fbb;
            let schur_b = fbb - fab * fab / faa;
            assert!(close(schur_a, faa * (1.0 - rho_hat * rho_hat), 1e-12));
            assert!(close(schur_b, fbb * (1.0 - rho_hat * rho_hat), 1e-12));
            // ... and it is the inverse of the diagonal of F⁻¹ (Lemma 3.4).
            let inv = f.clone().try_inverse().unwrap();
            assert!(close(schur_a, 1.0 / inv[(0, 0)], 1e-10));
            // For m = 2, C3 = −½ ln(1 − ρ²) = −½ ln(F*_a / F_aa).
            assert!(close(r.c3, -0.5 * (schur_a / faa).ln(), 1e-10));
        }
    }

    #[test]
    fn errors() {
        let e = |f: DMatrix<f64>| isolability(&f, 0.95).unwrap_err();
        assert_eq!(
            e(DMatrix::zeros(2, 3)),
            IsolabilityError::NotSquare { rows: 2, cols: 3 }
        );
        assert_eq!(e(DMatrix::zeros(0, 0)), IsolabilityError::Empty);
        assert_eq!(
            e(DMatrix::zeros(0, 1)),
            IsolabilityError::NotSquare { rows: 0, cols: 1 }
        );
        let mut f = DMatrix::identity(2, 2);
        f[(0, 1)] = f64::NAN;
        assert_eq!(e(f.clone()), IsolabilityError::NonFinite);
        f[(0, 1)] = f64::INFINITY;
        assert_eq!(e(f), IsolabilityError::NonFinite);
        let f = DMatrix::from_row_slice(2, 2, &[4.0, 0.5, 0.1, 1.0]);
        match e(f) {
            IsolabilityError::NotSymmetric { max_asymmetry } => {
                assert!(close(max_asymmetry, 0.2, 1e-12));
            }
            other => panic!("{other:?}"),
        }
        // Rounding-level asymmetry is accepted (and symmetrised).
        let f = DMatrix::from_row_slice(2, 2, &[4.0, 0.5, 0.5 + 1e-15, 1.0]);
        assert!(isolability(&f, 0.95).is_ok());
        // |ρ| > 1: not an information matrix.
        let f = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(
            e(f),
            IsolabilityError::NotPositiveSemidefinite { .. }
        ));
        // Caught on the correlation matrix even when F's spectrum is dominated by a large
        // fault (λ_min(F) = −750 is within τ·λ_max(F) = 1000 of zero).
        let f = DMatrix::from_row_slice(
            3,
            3,
            &[1e12, 0.0, 0.0, 0.0, 1500.0, 2250.0, 0.0, 2250.0, 1500.0],
        );
        match e(f) {
            IsolabilityError::NotPositiveSemidefinite {
                relative_min_eigenvalue,
            } => {
                assert!(close(relative_min_eigenvalue, -0.2, 1e-12));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            e(-DMatrix::identity(2, 2)),
            IsolabilityError::NotPositiveSemidefinite { .. }
        ));
        for limit in [f64::NAN, -0.1, 1.5] {
            assert!(matches!(
                isolability(&DMatrix::identity(2, 2), limit),
                Err(IsolabilityError::InvalidCorrelationLimit { .. })
            ));
        }
        assert_eq!(
            IsolabilityError::NotSquare { rows: 2, cols: 3 }.to_string(),
            "information matrix is 2×3, not square"
        );
    }

    #[test]
    fn disparate_units() {
        // Fault magnitudes in units 10⁴ apart (F_ii ratio 10⁸ < 1/τ): still detectable, and
        // ρ and C3 are exactly those of the unit-free problem.
        let rho = 0.5;
        let f = DMatrix::from_row_slice(2, 2, &[1e4, rho, rho, 1e-4]);
        let r = isolability(&f, 0.95).unwrap();
        assert_eq!(r.rank, 2);
        assert!(r.undetectable.is_empty());
        assert!(close(r.correlation[(0, 1)], rho, 1e-15));
        assert!(close(r.c3, -0.5 * (1.0 - rho * rho).ln(), 1e-14));
        assert!(r.c1 > r.c2 && r.c2 > r.c3);
        // F_ii ratio 10¹⁸ > 1/τ: a change of units only, so the small fault is as
        // detectable and as isolable as the large one, as it is for the GLR, whose LDLᵀ
        // keeps a pivot when D_j > τ·C_jj. (This asserted "undetectable, rank 1" while
        // the cut-off was τ·max_i F_ii, which made `glrmon
        // validate` call a gas-pipeline leak undetectable for its units alone.)
        let f = DMatrix::from_row_slice(2, 2, &[1e12, 0.0, 0.0, 1e-6]);
        let r = isolability(&f, 0.95).unwrap();
        assert!(r.undetectable.is_empty());
        assert_eq!(r.rank, 2);
        assert!(r.isolable());
        assert_eq!(r.c3, 0.0);
        assert!(r.verdicts(&["big", "small"], 10).is_empty());
        // A zero signature is still undetectable, whatever the other's scale.
        let f = DMatrix::from_row_slice(2, 2, &[1e-300, 0.0, 0.0, 0.0]);
        let r = isolability(&f, 0.95).unwrap();
        assert_eq!(r.undetectable, vec![1]);
        assert_eq!(r.rank, 1);
    }

    #[test]
    fn single_fault() {
        let r = isolability(&DMatrix::from_element(1, 1, 3.0), 0.95).unwrap();
        assert_eq!((r.rank, r.c2, r.c3), (1, 0.0, 0.0));
        assert!(r.pairs.is_empty() && r.isolable());
        let r = isolability(&DMatrix::from_element(1, 1, 0.0), 0.95).unwrap();
        assert_eq!(r.undetectable, vec![0]);
    }

    /// Random SPD F = AᵀA + 0.1 I (m = 2..6) and a diagonal change of units D.
    fn spd_and_scaling() -> impl Strategy<Value = (DMatrix<f64>, Vec<f64>, f64)> {
        (2usize..=6).prop_flat_map(|m| {
            (
                prop::collection::vec(-1.0f64..1.0, m * m),
                prop::collection::vec((0.2f64..5.0, any::<bool>()), m),
                0.01f64..100.0,
            )
                .prop_map(move |(a, d, delta)| {
                    let a = DMatrix::from_vec(m, m, a);
                    let f = a.transpose() * &a + DMatrix::identity(m, m) * 0.1;
                    let d = d
                        .into_iter()
                        .map(|(x, neg)| if neg { -x } else { x })
                        .collect();
                    (f, d, delta)
                })
        })
    }

    proptest! {
        #[test]
        fn unit_change_leaves_correlation_and_c3_unchanged((f, d, delta) in spd_and_scaling()) {
            let m = f.nrows();
            let dm = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(d.clone()));
            let scaled = &dm * &f * &dm;
            let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
            let s = isolability(&scaled, DEFAULT_CORRELATION_LIMIT).unwrap();
            prop_assert_eq!(r.rank, m);
            prop_assert_eq!(s.rank, m);
            // ρ(DFD)_ij = sign(d_i d_j) ρ(F)_ij: |ρ|, verdicts and C3 are unit-free.
            for i in 0..m {
                for j in 0..m {
                    let sign = (d[i] * d[j]).signum();
                    prop_assert!(close(s.correlation[(i, j)], sign * r.correlation[(i, j)], 1e-12));
                }
            }
            for (p, q) in r.pairs.iter().zip(&s.pairs) {
                prop_assert!(close(p.correlation.abs(), q.correlation.abs(), 1e-12));
            }
            prop_assert!(close(s.c3, r.c3, 1e-9));
            // C2 is invariant to a common scale, C1 is not (it is 0 only at F = I).
            let t = isolability(&(&f * delta), DEFAULT_CORRELATION_LIMIT).unwrap();
            prop_assert!(close(t.c2, r.c2, 1e-9));
            prop_assert!(close(t.c3, r.c3, 1e-9));
            // C1 − C2 = ½ q (x − 1 − ln x), x = tr F / q: the only scale-dependent part.
            let x = t.correlation.nrows() as f64;
            let xt = (&f * delta).trace() / x;
            prop_assert!(close(t.c1 - t.c2, 0.5 * x * (xt - 1.0 - xt.ln()), 1e-8));
        }

        #[test]
        fn criteria_match_92_and_are_ordered((f, _d, _delta) in spd_and_scaling()) {
            let r = isolability(&f, DEFAULT_CORRELATION_LIMIT).unwrap();
            let (c1, c2, c3) = criteria_92(&f);
            prop_assert!(close(r.c1, c1, 1e-9), "{} vs {}", r.c1, c1);
            prop_assert!(close(r.c2, c2, 1e-9), "{} vs {}", r.c2, c2);
            prop_assert!(close(r.c3, c3, 1e-9), "{} vs {}", r.c3, c3);
            // Nested minimisations: C1 ≥ C2 ≥ C3 ≥ 0.
            prop_assert!(r.c1 >= r.c2 && r.c2 >= r.c3 && r.c3 >= 0.0);
            // C3 = −½ ln|R|: the mutual information among the fault components.
            let ln_det_r = r.correlation.determinant().ln();
            prop_assert!(close(r.c3, -0.5 * ln_det_r, 1e-9));
            // Condition number from the spectrum.
            let e = f.symmetric_eigenvalues();
            prop_assert!(close(r.condition_number, e.max() / e.min(), 1e-9));
        }

        #[test]
        fn orthogonal_invariance_of_c1_c2((f, _d, _delta) in spd_and_scaling(), theta in 0.0f64..6.3) {
            // Givens rotation in the (0, 1) plane.
            let m = f.nrows();
            let mut a = DMatrix::identity(m, m);
            let (s, c) = theta.sin_cos();
            a[(0, 0)] = c; a[(0, 1)] = -s; a[(1, 0)] = s; a[(1, 1)] = c;
            let g = &a * &f * a.transpose();
            let g = (&g + g.transpose()) * 0.5;
            let r = isolability(&f, 0.95).unwrap();
            let t = isolability(&g, 0.95).unwrap();
            prop_assert!(close(t.c1, r.c1, 1e-9));
            prop_assert!(close(t.c2, r.c2, 1e-9));
            // C2 = max over orthogonal A of C0(AFAᵀ) = C3(AFAᵀ) (§6.3).
            prop_assert!(t.c3 <= r.c2 * (1.0 + 1e-9) + 1e-12);
        }

        #[test]
        fn schur_identity_random_pairs(faa in 1e-3f64..1e3, fbb in 1e-3f64..1e3, rho in -0.999f64..0.999) {
            let fab = rho * (faa * fbb).sqrt();
            let f = DMatrix::from_row_slice(2, 2, &[faa, fab, fab, fbb]);
            let r = isolability(&f, 0.95).unwrap();
            let rh = r.correlation[(0, 1)];
            prop_assert!(close(faa - fab * fab / fbb, faa * (1.0 - rh * rh), 1e-10));
            prop_assert_eq!(r.pairs[0].separable, rho.abs() <= 0.95);
        }
    }
}
