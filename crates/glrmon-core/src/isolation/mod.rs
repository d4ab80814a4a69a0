//! Fault isolation after a GLR alarm: global, sensitivity and minmax (nuisance-rejection)
//! χ² tests on the sufficient statistics of the alarm.
//!
//! # What
//! When the moving-window GLR has fired at time k with estimated onset r̂, the innovations
//! since r̂ stacked into Z (Zhang & Basseville 2014, eq. (38)) are Gaussian,
//! Z ~ N(Mθ, R) (eq. (39)). Everything the data say about the fault vector θ (length m,
//! one entry per fault of the dictionary) is carried by two small objects, the Fisher
//! information and the normalised residual (score)
//!
//! ```text
//! F = MᵀR⁻¹M = C_k(r̂)      (m×m, symmetric positive semi-definite)
//! ζ = MᵀR⁻¹Z = d_k(r̂)      (m-vector, ζ ~ N(Fθ, F))
//! ```
//!
//! For a partition θ = (θ_a, θ_b) into the faults under test (a) and the others (b),
//! [`FisherStatistics`] computes
//!
//! * the **global** test ζᵀF⁻¹ζ (θ = 0 against θ ≠ 0), χ² with rank F degrees of
//!   freedom under θ = 0 ([`FisherStatistics::global`]);
//! * the **sensitivity** test ζ_aᵀF_aa⁻¹ζ_a, the GLR of θ = 0 against θ = (θ_a, 0): it
//!   assumes the other faults absent (Basseville 1996, §3.2, Lemma 3.5, eqs. (34)-(38))
//!   ([`FisherStatistics::sensitivity`]);
//! * the **minmax** test (Zhang & Basseville 2014, eq. (41); Basseville 1996, §3.2,
//!   Lemma 3.7, eqs. (45)-(51)), the GLR of θ_a = 0 against θ_a ≠ 0 with θ_b an unknown
//!   nuisance replaced by its least favourable value (equivalently its maximum-likelihood
//!   estimate):
//!
//!   ```text
//!   ζ*_a = ζ_a − F_ab F_bb⁻¹ ζ_b          (residual of the regression of ζ_a on ζ_b)
//!   F*_a = F_aa − F_ab F_bb⁻¹ F_ba        (Schur complement of F_bb in F)
//!   l_a  = ζ*_aᵀ F*_a⁻¹ ζ*_a              (41)
//!   ```
//!
//!   Under θ_a = 0 it is χ² with rank F*_a degrees of freedom *whatever θ_b is*
//!   ([`FisherStatistics::minmax`]). Running it for each fault (or group of faults) and
//!   comparing with thresholds is the isolation rule (43) of Zhang & Basseville (2014).
//!
//! The three are tied by the additive decomposition of the global test (Basseville 1996,
//! §3.2.4, Lemma 3.10, eq. (68)): for every partition,
//!
//! ```text
//! ζᵀF⁻¹ζ = l_a (minmax for a) + ζ_bᵀF_bb⁻¹ζ_b (sensitivity for b),
//! rank F = rank F*_a + rank F_bb.
//! ```
//!
//! # Why minmax
//! Fault signatures are usually correlated (F_ab ≠ 0), so a fault b that is present leaks
//! into the sensitivity test of a fault a that is not: sensitivity tests over-isolate.
//! The minmax test removes everything in ζ_a that θ_b can explain, at the price of some
//! power (Basseville 1996, Lemma 3.9).
//!
//! # Singular information
//! Before the signatures are persistently exciting, or when two faults have the same
//! signature, F (or a block of it, or a Schur complement) is singular. Every inverse above
//! is then a pseudo-inverse computed from a symmetric eigendecomposition in which
//! eigenvalues ≤ τ·λ_max are treated as zero ([`DEFAULT_RANK_TOLERANCE`],
//! [`FisherStatistics::with_rank_tolerance`]); the number of kept eigenvalues is reported
//! as the degrees of freedom. Because ζ = MᵀR⁻¹Z lies in range(F) (and ζ_b in
//! range(F_bb), ζ*_a in range(F*_a)), ζᵀF⁺ζ is still exactly 2 ln of the likelihood
//! ratio, χ² with the rank as degrees of freedom.
//!
//! The eigenvalues are those of the **equilibrated** problem: with U = diag(F)^{-1/2}
//! (U_jj = 0 when F_jj = 0: a fault without signature is dropped), F̂ = UFU has a unit
//! diagonal and ζ̂ = Uζ; θ̂ = U F̂⁺ζ̂ maps back. Every test is invariant under a change of
//! fault units (F ↦ SFS, ζ ↦ Sζ for a positive diagonal S) in exact arithmetic, and so
//! are its rank decisions only when they are taken on F̂: relative to λ_max(F) they
//! would drop a fault whose units make its F_jj small next to another's (they once
//! dropped a gas-pipeline leak of θ ≈ −4·10⁴ beside faults of θ ≈ 10⁻⁵ with columns
//! ≈ 4·10⁵).
//! The GLR bank's LDLᵀ decides its rank by the same scale-free measure.
//!
//! The rank of F is decided once: F̂ is replaced by its truncation F̃ = GᵀG, where
//! G = Λ_r^{1/2}V_rᵀ (r×m) keeps the r eigenpairs above the cut-off, and ζ̂ by the
//! equivalent r-vector Z̃ = Λ_r^{-1/2}V_rᵀζ̂ (F̃ = GᵀG, ζ̂ = GᵀZ̃: a compressed stacked
//! problem Z̃ ~ N(Gθ, I_r) with the same information). The blocks of every test are
//! taken from G, and the Schur complement is evaluated in Gram form,
//! F*_a = HᵀH and ζ*_a = HᵀZ̃ with H = (I − P_b)G_a, P_b the orthogonal projector on
//! range(G_b) (Basseville 1996, eq. (45), the projection form of (41)). Subtracting
//! F_ab F_bb⁺ F_ba directly would leave a rounding residue of order ε·κ(F_bb)·‖F‖ where
//! F*_a is exactly zero (fault a spanned by the nuisance faults), often above the
//! cut-off; with one rank decision and the Gram form the decomposition above holds to
//! rounding, degrees of freedom included, in rank-deficient cases too.
//!
//! # Cost
//! Each test costs O(m³) (a few eigendecompositions of m×m or smaller matrices),
//! independently of the window length: F and ζ are the accumulated C_k(r̂), d_k(r̂) of the
//! GLR bank. The stacked form of §4.3 would build Z (pw entries for p outputs and a window
//! of w samples), M (pw×m) and R (pw×pw) and cost O((pw)³). The functions allocate; they
//! are meant to run at alarms, not per sample.
//!
//! # References
//! * Q. Zhang, M. Basseville (2014), *Statistical detection and isolation of additive
//!   faults in linear time-varying systems*, Automatica 50(10), §4.3, eqs. (38)-(43).
//! * M. Basseville (1996), *Information criteria for residual generation and fault
//!   detection and isolation*, §3.2 (sensitivity tests, statistical rejection/minmax,
//!   mixed approach).

pub mod ambiguity;
pub mod information;
pub mod isolability;

use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// Default relative eigenvalue cut-off τ: eigenvalues ≤ τ·λ_max of an equilibrated
/// information matrix (unit diagonal, see the [module documentation](self)) are treated
/// as zero. Same value as the GLR bank's default.
pub const DEFAULT_RANK_TOLERANCE: f64 = 1e-9;

/// Cap on the implicit-QR iterations of nalgebra's symmetric eigensolver, per unit of
/// dimension. nalgebra's own default is unbounded, and it is known to stall on some
/// matrices with zero diagonal entries (dimforge/nalgebra#1025); past the cap the cyclic
/// Jacobi fallback takes over.
const QR_ITERATIONS_PER_DIM: usize = 64;

/// Maximal number of sweeps of the Jacobi fallback (it typically needs fewer than 10).
const JACOBI_MAX_SWEEPS: usize = 100;

/// A χ² test statistic and its degrees of freedom (the rank of the information matrix
/// it was computed from).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestStatistic {
    /// Value of the quadratic form (2 ln of the likelihood ratio); ≥ 0, or NaN if the
    /// inputs of [`pinv_quadratic_form`] were not finite.
    pub value: f64,
    /// Degrees of freedom of its χ² distribution under the null hypothesis: the numerical
    /// rank of the information matrix involved.
    pub dof: usize,
}

impl TestStatistic {
    /// The result for non-finite input.
    const NAN: Self = Self {
        value: f64::NAN,
        dof: 0,
    };
}

/// Invalid input to [`FisherStatistics`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IsolationError {
    /// The information matrix is not square, or the score's length differs from its size.
    #[error(
        "dimension mismatch: information matrix is {rows}×{cols} and score has {score} \
         entries (expected m×m and m)"
    )]
    DimensionMismatch {
        /// Rows of the information matrix.
        rows: usize,
        /// Columns of the information matrix.
        cols: usize,
        /// Length of the score vector.
        score: usize,
    },
    /// The subset of faults under test is empty.
    #[error("empty subset of faults")]
    EmptySubset,
    /// A fault index is not smaller than the number of faults m.
    #[error("fault index {index} out of range for m = {dim} faults")]
    IndexOutOfRange {
        /// The offending index.
        index: usize,
        /// The number of faults m.
        dim: usize,
    },
    /// A fault index appears twice in the subset.
    #[error("fault index {index} appears more than once in the subset")]
    DuplicateIndex {
        /// The repeated index.
        index: usize,
    },
    /// An entry of the information matrix or of the score is NaN or infinite.
    #[error("non-finite entry in the {input}")]
    NonFinite {
        /// Which input: `"information matrix"` or `"score"`.
        input: &'static str,
    },
}

/// The sufficient statistics (F, ζ) of an alarm and the isolation tests computed from
/// them.
///
/// F = MᵀR⁻¹M (the GLR bank's C_k(r̂)) and ζ = MᵀR⁻¹Z (its d_k(r̂)) are those of
/// Zhang & Basseville 2014, eq. (41); the tests are those of Basseville 1996, §3.2. See
/// the [module documentation](self) for the formulas and the treatment of singular F.
///
/// # Examples
/// Two faults with correlated signatures; the data were produced by fault 0 alone.
/// ```
/// use glrmon_core::isolation::{FisherStatistics, IsolationError, TestStatistic};
/// use nalgebra::{DMatrix, DVector};
///
/// let f = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
/// let zeta = DVector::from_vec(vec![6.0, 3.0]);
/// let stats = FisherStatistics::new(f, zeta)?;
///
/// let close = |t: TestStatistic, v: f64, dof: usize| (t.value - v).abs() < 1e-12 && t.dof == dof;
/// // Global test ζᵀF⁻¹ζ, 2 degrees of freedom.
/// assert!(close(stats.global(), 9.0, 2));
/// // The sensitivity test of fault 1 responds to fault 0 through the correlation...
/// assert!(close(stats.sensitivity(&[1])?, 3.0, 1));
/// // ...the minmax test of fault 1 rejects it (eq. (41)): ζ*₁ = 3 − (2/4)·6 = 0.
/// assert!(close(stats.minmax(&[1])?, 0.0, 1));
/// // Minmax test of fault 0: ζ*₀ = 6 − (2/3)·3 = 4, F*₀ = 4 − 4/3 = 8/3, l₀ = 16/(8/3).
/// assert!(close(stats.minmax(&[0])?, 6.0, 1));
/// // Basseville 1996, §3.2: global = minmax for {0} + sensitivity for {1}.
/// let sum = stats.minmax(&[0])?.value + stats.sensitivity(&[1])?.value;
/// assert!((stats.global().value - sum).abs() < 1e-12);
/// // Magnitude θ̂ = F⁻¹ζ.
/// let theta = stats.magnitude();
/// assert!((theta[0] - 1.5).abs() < 1e-12 && theta[1].abs() < 1e-12);
/// # Ok::<(), IsolationError>(())
/// ```
#[derive(Debug, Clone)]
pub struct FisherStatistics {
    /// F, symmetrised.
    information: DMatrix<f64>,
    /// ζ.
    score: DVector<f64>,
    /// The diagonal of U = diag(F)^{-1/2} (0 where F_jj ≤ 0).
    unit: DVector<f64>,
    /// ζ̂ = Uζ.
    unit_score: DVector<f64>,
    /// Relative eigenvalue cut-off τ.
    tol: f64,
    /// Eigendecomposition of F̂ = UFU (independent of τ).
    eigen: Eigen,
    /// The compressed problem for the current τ.
    reduced: Reduced,
}

/// The rank-r compressed problem of the equilibrated F̂, ζ̂: G = Λ_r^{1/2}V_rᵀ (r×m) and
/// Z̃ = Λ_r^{-1/2}V_rᵀζ̂, with GᵀG = F̃ (F̂ truncated to its r eigenvalues > τ·λ_max) and
/// GᵀZ̃ = ζ̂'s projection on range F̂.
#[derive(Debug, Clone)]
struct Reduced {
    g: DMatrix<f64>,
    z: DVector<f64>,
}

impl FisherStatistics {
    /// Wraps the Fisher information F (m×m) and the score ζ (m), with the rank tolerance
    /// [`DEFAULT_RANK_TOLERANCE`].
    ///
    /// F is replaced by (F + Fᵀ)/2 to remove rounding asymmetry. It should be positive
    /// semi-definite and ζ should lie in its range, as they do when they come from data
    /// (F = MᵀR⁻¹M, ζ = MᵀR⁻¹Z); negative eigenvalues are treated as zero, a fault with
    /// F_jj ≤ 0 is dropped, and any part of ζ outside the range of F is ignored. m = 0 is
    /// accepted (every test is then 0 with 0 degrees of freedom). Costs one m×m
    /// eigendecomposition, of the equilibrated F̂ (see the [module documentation](self)).
    ///
    /// # Errors
    /// [`IsolationError::DimensionMismatch`] if F is not square or ζ's length differs
    /// from its size; [`IsolationError::NonFinite`] if an entry is NaN or infinite.
    pub fn new(information: DMatrix<f64>, score: DVector<f64>) -> Result<Self, IsolationError> {
        let (rows, cols) = information.shape();
        if rows != cols || score.len() != rows {
            return Err(IsolationError::DimensionMismatch {
                rows,
                cols,
                score: score.len(),
            });
        }
        if !score.iter().all(|x| x.is_finite()) {
            return Err(IsolationError::NonFinite { input: "score" });
        }
        if !information.iter().all(|x| x.is_finite()) {
            return Err(IsolationError::NonFinite {
                input: "information matrix",
            });
        }
        let information = symmetrized(&information);
        let (unit, equilibrated) = equilibrated(&information);
        let unit_score = score.component_mul(&unit);
        // `None` exactly when an entry is not finite, excluded above.
        let Some(eigen) = Eigen::new(&equilibrated) else {
            return Err(IsolationError::NonFinite {
                input: "information matrix",
            });
        };
        let reduced = eigen.reduce(&unit_score, DEFAULT_RANK_TOLERANCE);
        Ok(Self {
            information,
            score,
            unit,
            unit_score,
            tol: DEFAULT_RANK_TOLERANCE,
            eigen,
            reduced,
        })
    }

    /// Sets the relative eigenvalue cut-off τ: in every pseudo-inverse, eigenvalues
    /// ≤ τ·λ_max are treated as zero (λ_max of F̂ for the rank of F, of F̂_aa for a
    /// sensitivity test and for the Schur complement F*_a, of F̂_bb for F_bb⁺; F̂ the
    /// equilibrated F of the [module documentation](self), so that no decision depends on
    /// the fault units). A NaN or negative τ is replaced by [`DEFAULT_RANK_TOLERANCE`].
    #[must_use]
    pub fn with_rank_tolerance(mut self, tol: f64) -> Self {
        self.tol = sanitized_tolerance(tol);
        self.reduced = self.eigen.reduce(&self.unit_score, self.tol);
        self
    }

    /// Number of faults m.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.score.len()
    }

    /// The Fisher information F = MᵀR⁻¹M (symmetrised).
    #[must_use]
    pub fn information(&self) -> &DMatrix<f64> {
        &self.information
    }

    /// The score ζ = MᵀR⁻¹Z.
    #[must_use]
    pub fn score(&self) -> &DVector<f64> {
        &self.score
    }

    /// The rank tolerance τ in use.
    #[must_use]
    pub fn rank_tolerance(&self) -> f64 {
        self.tol
    }

    /// Global test ζᵀF⁺ζ of θ = 0 against θ ≠ 0; χ² with rank F degrees of freedom under
    /// θ = 0 (eigenvalues ≤ τ·λ_max(F̂) of the equilibrated F dropped). It is the GLR statistic of the alarm
    /// (Zhang & Basseville 2014, eq. (35)) up to the rank decision.
    #[must_use]
    pub fn global(&self) -> TestStatistic {
        TestStatistic {
            value: self.reduced.z.norm_squared(),
            dof: self.reduced.z.len(),
        }
    }

    /// Sensitivity test ζ_aᵀF_aa⁺ζ_a for the faults in `subset` (Basseville 1996, §3.2,
    /// Lemma 3.5): the GLR of θ = 0 against θ = (θ_a, 0), i.e. assuming the other faults
    /// absent. χ² with rank F_aa degrees of freedom under θ = 0 (eigenvalues
    /// ≤ τ·λ_max(F̂_aa) dropped; F_aa and ζ_a are those of the rank-truncated F̂, see the
    /// [module documentation](self)). The order of `subset` does not matter; if it holds
    /// every fault this is [`global`](Self::global).
    ///
    /// # Errors
    /// [`IsolationError::EmptySubset`], [`IsolationError::IndexOutOfRange`] or
    /// [`IsolationError::DuplicateIndex`] for an invalid `subset`.
    pub fn sensitivity(&self, subset: &[usize]) -> Result<TestStatistic, IsolationError> {
        let (a, b) = self.partition(subset)?;
        if b.is_empty() {
            return Ok(self.global());
        }
        let ga = self.reduced.g.select_columns(&a);
        let faa = ga.tr_mul(&ga);
        let za = ga.tr_mul(&self.reduced.z);
        Ok(quadratic_form(&faa, &za, self.tol, None))
    }

    /// Minmax (statistical nuisance rejection) test for the faults in `subset`
    /// (Zhang & Basseville 2014, eq. (41); Basseville 1996, §3.2, Lemma 3.7): with b the
    /// complement of the subset, ζ*_a = ζ_a − F_ab F_bb⁺ ζ_b, F*_a = F_aa − F_ab F_bb⁺ F_ba
    /// and the statistic is ζ*_aᵀ F*_a⁺ ζ*_a, the GLR of θ_a = 0 against θ_a ≠ 0 with θ_b
    /// an unknown nuisance. χ² with rank F*_a degrees of freedom under θ_a = 0, whatever
    /// θ_b.
    ///
    /// F_bb⁺ drops eigenvalues ≤ τ·λ_max(F̂_bb), F*_a⁺ those ≤ τ·λ_max(F̂_aa): a direction
    /// of θ_a whose information is (up to τ) entirely explained by the nuisance faults
    /// cannot be isolated and adds no degree of freedom. F*_a and ζ*_a are evaluated in
    /// the Gram form HᵀH, HᵀZ̃ on the rank-truncated F̂ (see the
    /// [module documentation](self)). The order of `subset` does not matter; if it holds
    /// every fault (b empty) this is [`global`](Self::global) (and
    /// [`sensitivity`](Self::sensitivity)).
    ///
    /// # Errors
    /// [`IsolationError::EmptySubset`], [`IsolationError::IndexOutOfRange`] or
    /// [`IsolationError::DuplicateIndex`] for an invalid `subset`.
    pub fn minmax(&self, subset: &[usize]) -> Result<TestStatistic, IsolationError> {
        let (a, b) = self.partition(subset)?;
        if b.is_empty() {
            return Ok(self.global());
        }
        let Reduced { g, z } = &self.reduced;
        let ga = g.select_columns(&a);
        let gb = g.select_columns(&b);
        let (Some(faa), Some(fbb)) = (Eigen::new(&ga.tr_mul(&ga)), Eigen::new(&gb.tr_mul(&gb)))
        else {
            return Ok(TestStatistic::NAN); // unreachable: G is finite
        };
        // F_bb⁺ = WWᵀ; U = G_b W is an orthonormal basis of range(G_b), P_b = UUᵀ.
        let u = &gb * fbb.root_pinv(self.tol, None);
        // H = (I − P_b) G_a: F*_a = HᵀH = F_aa − F_ab F_bb⁺ F_ba and
        // ζ*_a = HᵀZ̃ = ζ_a − F_ab F_bb⁺ ζ_b.
        let h = &ga - &u * u.tr_mul(&ga);
        let f_star = h.tr_mul(&h);
        let z_star = h.tr_mul(z);
        Ok(quadratic_form(
            &f_star,
            &z_star,
            self.tol,
            Some(faa.lambda_max()),
        ))
    }

    /// Estimated fault magnitude θ̂ = U F̂⁺ ζ̂ (eigenvalues ≤ τ·λ_max(F̂) dropped): a
    /// least-squares solution of Fθ = ζ, the maximum-likelihood estimate of θ
    /// (Zhang & Basseville 2014, eq. (34)) when F is regular; when it is not, the one of
    /// minimum norm in the fault units of F̂ (so that a change of units S gives S⁻¹θ̂),
    /// 0 for a fault with F_jj = 0.
    #[must_use]
    pub fn magnitude(&self) -> DVector<f64> {
        let w = self.eigen.root_pinv(self.tol, None);
        (&w * w.tr_mul(&self.unit_score)).component_mul(&self.unit)
    }

    /// Validates `subset` and returns (a, b): the subset sorted, and its complement.
    fn partition(&self, subset: &[usize]) -> Result<(Vec<usize>, Vec<usize>), IsolationError> {
        if subset.is_empty() {
            return Err(IsolationError::EmptySubset);
        }
        let m = self.dim();
        let mut in_a = vec![false; m];
        for &index in subset {
            match in_a.get_mut(index) {
                None => return Err(IsolationError::IndexOutOfRange { index, dim: m }),
                Some(true) => return Err(IsolationError::DuplicateIndex { index }),
                Some(flag) => *flag = true,
            }
        }
        let a = (0..m).filter(|&i| in_a[i]).collect();
        let b = (0..m).filter(|&i| !in_a[i]).collect();
        Ok((a, b))
    }
}

/// Quadratic form xᵀA⁺x and numerical rank of the symmetric positive semi-definite
/// matrix A, through a symmetric eigendecomposition Â = VΛVᵀ of the equilibrated
/// Â = UAU, U = diag(A)^{-1/2} (U_ii = 0 where A_ii ≤ 0), in which eigenvalues
/// ≤ tol·λ_max (and all non-positive ones) are treated as zero:
/// xᵀA⁺x = Σ_{λ_i > tol·λ_max} (v_iᵀUx)²/λ_i, and `dof` is the number of kept eigenvalues.
/// Equilibrating first makes the rank independent of the units of x's components
/// (A ↦ SAS, x ↦ Sx for a positive diagonal S change neither).
///
/// Only the symmetric part (A + Aᵀ)/2 is used. When x ∈ range(A) — as ζ ∈ range(F) for
/// F = MᵀR⁻¹M, ζ = MᵀR⁻¹Z — the result does not depend on the choice of generalised
/// inverse and is the χ² statistic of Zhang & Basseville 2014, eq. (41) and
/// Basseville 1996, §3.2. A NaN or negative `tol` is replaced by
/// [`DEFAULT_RANK_TOLERANCE`]. For a 0×0 matrix the result is 0 with 0 degrees of
/// freedom; if A or x has a NaN or infinite entry it is NaN with 0 degrees of freedom.
///
/// # Panics
/// If A is not square or x's length differs from A's size.
///
/// # Examples
/// ```
/// use glrmon_core::isolation::{pinv_quadratic_form, DEFAULT_RANK_TOLERANCE};
/// use nalgebra::{DMatrix, DVector};
///
/// // A singular matrix (two identical fault signatures) and x in its range.
/// let a = DMatrix::from_row_slice(2, 2, &[2.0, 2.0, 2.0, 2.0]);
/// let x = DVector::from_vec(vec![4.0, 4.0]);
/// let t = pinv_quadratic_form(&a, &x, DEFAULT_RANK_TOLERANCE);
/// assert_eq!(t.dof, 1);
/// assert!((t.value - 8.0).abs() < 1e-12); // xᵀA⁺x = 32/4
/// ```
#[must_use]
pub fn pinv_quadratic_form(a: &DMatrix<f64>, x: &DVector<f64>, tol: f64) -> TestStatistic {
    assert!(
        a.is_square() && x.len() == a.nrows(),
        "pinv_quadratic_form: A is {}×{} and x has {} entries",
        a.nrows(),
        a.ncols(),
        x.len()
    );
    if !a.iter().all(|v| v.is_finite()) {
        return TestStatistic::NAN;
    }
    let (unit, equilibrated) = equilibrated(&symmetrized(a));
    quadratic_form(
        &equilibrated,
        &x.component_mul(&unit),
        sanitized_tolerance(tol),
        None,
    )
}

/// U = diag(A)^{-1/2} as a vector (0 where A_ii ≤ 0) and the equilibrated UAU, whose
/// diagonal is 1 (or 0 for a dropped row and column). A finite PSD A gives a finite
/// UAU: |A_ij| ≤ √(A_ii A_jj) keeps every entry within [−1, 1].
fn equilibrated(a: &DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let unit = DVector::from_fn(a.nrows(), |i, _| {
        let d = a[(i, i)];
        if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 }
    });
    let scaled = DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] * unit[i] * unit[j]);
    (unit, scaled)
}

/// xᵀA⁺x with eigenvalues ≤ tol·reference dropped (reference = λ_max(A) when `None`);
/// NaN if A or x has a non-finite entry. Sizes must agree (checked by the callers).
fn quadratic_form(
    a: &DMatrix<f64>,
    x: &DVector<f64>,
    tol: f64,
    reference: Option<f64>,
) -> TestStatistic {
    if !x.iter().all(|v| v.is_finite()) {
        return TestStatistic::NAN;
    }
    match Eigen::new(a) {
        Some(eigen) => {
            let w = eigen.root_pinv(tol, reference);
            TestStatistic {
                value: w.tr_mul(x).norm_squared(),
                dof: w.ncols(),
            }
        }
        None => TestStatistic::NAN,
    }
}

/// Eigendecomposition A = V diag(λ) Vᵀ of the symmetric part of a finite matrix.
#[derive(Debug, Clone)]
struct Eigen {
    values: DVector<f64>,
    /// Eigenvectors as columns.
    vectors: DMatrix<f64>,
}

impl Eigen {
    /// `None` if A has a non-finite entry. Never panics and always terminates.
    ///
    /// A is scaled by its largest entry first, then decomposed with nalgebra's
    /// [`SymmetricEigen`] under an iteration cap, falling back to cyclic Jacobi rotations
    /// if the cap is hit.
    fn new(a: &DMatrix<f64>) -> Option<Self> {
        let n = a.nrows();
        if !a.iter().all(|v| v.is_finite()) {
            return None;
        }
        let scale = a.amax();
        if scale == 0.0 {
            return Some(Self {
                values: DVector::zeros(n),
                vectors: DMatrix::identity(n, n),
            });
        }
        let s = symmetrized(a) / scale;
        let (values, vectors) =
            match SymmetricEigen::try_new(s.clone(), f64::EPSILON, QR_ITERATIONS_PER_DIM * n) {
                Some(eig) => (eig.eigenvalues, eig.eigenvectors),
                None => jacobi_eigen(s),
            };
        Some(Self {
            values: values * scale,
            vectors,
        })
    }

    /// Largest eigenvalue, or 0 if none is positive.
    fn lambda_max(&self) -> f64 {
        self.values.iter().copied().fold(0.0, f64::max)
    }

    /// Indices and 1/√λ of the kept eigenpairs: λ > tol·reference and λ > 0
    /// (reference = λ_max when `None`).
    fn kept(&self, tol: f64, reference: Option<f64>) -> Vec<(usize, f64)> {
        let cut = tol * reference.unwrap_or_else(|| self.lambda_max());
        self.values
            .iter()
            .enumerate()
            .filter(|&(_, &l)| l > cut && l > 0.0)
            .map(|(i, &l)| (i, 1.0 / l.sqrt()))
            .filter(|&(_, s)| s.is_finite())
            .collect()
    }

    /// W = V_r Λ_r^{-1/2} over the kept eigenpairs, so that A⁺ = WWᵀ and xᵀA⁺x = ‖Wᵀx‖².
    fn root_pinv(&self, tol: f64, reference: Option<f64>) -> DMatrix<f64> {
        let kept = self.kept(tol, reference);
        let mut w = DMatrix::zeros(self.vectors.nrows(), kept.len());
        for (col, &(i, inv_sqrt)) in kept.iter().enumerate() {
            w.set_column(col, &(self.vectors.column(i) * inv_sqrt));
        }
        w
    }

    /// The compressed problem (G, Z̃) of `score` for the cut-off `tol`.
    fn reduce(&self, score: &DVector<f64>, tol: f64) -> Reduced {
        let kept = self.kept(tol, None);
        let n = self.vectors.nrows();
        let mut g = DMatrix::zeros(kept.len(), n);
        let mut z = DVector::zeros(kept.len());
        for (row, &(i, inv_sqrt)) in kept.iter().enumerate() {
            let v = self.vectors.column(i);
            g.set_row(row, &(v.transpose() / inv_sqrt));
            z[row] = v.dot(score) * inv_sqrt;
        }
        Reduced { g, z }
    }
}

/// Cyclic Jacobi eigenvalue algorithm for a symmetric matrix (entries of order 1):
/// eigenvalues and eigenvectors as columns. Terminates after at most
/// [`JACOBI_MAX_SWEEPS`] sweeps.
fn jacobi_eigen(mut a: DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let n = a.nrows();
    let mut v = DMatrix::identity(n, n);
    for _ in 0..JACOBI_MAX_SWEEPS {
        let total = a.norm_squared();
        let mut off = 0.0;
        for q in 1..n {
            for p in 0..q {
                off += 2.0 * a[(p, q)] * a[(p, q)];
            }
        }
        if off <= f64::EPSILON * f64::EPSILON * total {
            break;
        }
        for p in 0..n {
            for q in (p + 1)..n {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                // Rotation zeroing a_pq (Rutishauser's formulas): t = tan φ.
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = if theta.abs() > 1e150 {
                    0.5 / theta
                } else {
                    theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                rotate_columns(&mut a, p, q, c, s);
                rotate_rows(&mut a, p, q, c, s);
                rotate_columns(&mut v, p, q, c, s);
            }
        }
    }
    (a.diagonal(), v)
}

/// Columns (p, q) ← (c·col_p − s·col_q, s·col_p + c·col_q).
fn rotate_columns(m: &mut DMatrix<f64>, p: usize, q: usize, c: f64, s: f64) {
    for k in 0..m.nrows() {
        let (x, y) = (m[(k, p)], m[(k, q)]);
        m[(k, p)] = c * x - s * y;
        m[(k, q)] = s * x + c * y;
    }
}

/// Rows (p, q) ← (c·row_p − s·row_q, s·row_p + c·row_q).
fn rotate_rows(m: &mut DMatrix<f64>, p: usize, q: usize, c: f64, s: f64) {
    for k in 0..m.ncols() {
        let (x, y) = (m[(p, k)], m[(q, k)]);
        m[(p, k)] = c * x - s * y;
        m[(q, k)] = s * x + c * y;
    }
}

/// (A + Aᵀ)/2, computed without overflow.
fn symmetrized(a: &DMatrix<f64>) -> DMatrix<f64> {
    (a * 0.5) + (a.transpose() * 0.5)
}

/// NaN or negative tolerances fall back to the default.
fn sanitized_tolerance(tol: f64) -> f64 {
    if tol >= 0.0 {
        tol
    } else {
        DEFAULT_RANK_TOLERANCE
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    // ---------------------------------------------------------------- helpers

    /// splitmix64 with Box–Muller normals: a tiny deterministic generator for tests.
    struct SplitMix64(u64);

    impl SplitMix64 {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        /// Uniform in (0, 1].
        fn uniform(&mut self) -> f64 {
            ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
        }

        /// Standard normal (Box–Muller, one of the pair).
        fn normal(&mut self) -> f64 {
            let (u1, u2) = (self.uniform(), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        }

        fn normal_matrix(&mut self, rows: usize, cols: usize) -> DMatrix<f64> {
            DMatrix::from_fn(rows, cols, |_, _| self.normal())
        }
    }

    /// A stacked problem Z ~ N(Mθ, R) whitened by R = CCᵀ: M̃ = C⁻¹M, Z̃ = C⁻¹Z, so that
    /// ‖v‖²_{R⁻¹} = ‖C⁻¹v‖², F = M̃ᵀM̃, ζ = M̃ᵀZ̃.
    struct Stacked {
        m_white: DMatrix<f64>,
        z_white: DVector<f64>,
    }

    impl Stacked {
        /// R = LLᵀ + I (a full, not block-diagonal, SPD covariance).
        fn new(m: DMatrix<f64>, l: DMatrix<f64>, z: DVector<f64>) -> Self {
            let n = m.nrows();
            let r = &l * l.transpose() + DMatrix::identity(n, n);
            let c = r.cholesky().expect("LLᵀ + I is SPD").l();
            let m_white = c.solve_lower_triangular(&m).expect("C is regular");
            let z_white = c.solve_lower_triangular(&z).expect("C is regular");
            Self { m_white, z_white }
        }

        fn fisher(&self) -> FisherStatistics {
            let f = self.m_white.tr_mul(&self.m_white);
            let zeta = self.m_white.tr_mul(&self.z_white);
            FisherStatistics::new(f, zeta).expect("finite, square")
        }

        /// ‖Z‖²_{R⁻¹}.
        fn norm2(&self) -> f64 {
            self.z_white.norm_squared()
        }

        /// min over θ_cols of ‖Z − M_cols θ_cols‖²_{R⁻¹}, by nalgebra's SVD least squares
        /// on the columns of M̃ scaled to unit norm; singular values ≤ √τ·σ_max count as
        /// zero (the cut-off τ·λ_max on the equilibrated F̂ = UM̃ᵀM̃U).
        fn min_residual(&self, cols: &[usize]) -> f64 {
            if cols.is_empty() {
                return self.norm2();
            }
            let mut mc = self.m_white.select_columns(cols);
            for mut c in mc.column_iter_mut() {
                let norm = c.norm();
                if norm > 0.0 {
                    c /= norm;
                }
            }
            let svd = mc.clone().svd(true, true);
            let eps = DEFAULT_RANK_TOLERANCE.sqrt() * svd.singular_values.max();
            let theta = svd.solve(&self.z_white, eps).expect("U and Vᵀ computed");
            (&self.z_white - &mc * theta).norm_squared()
        }
    }

    /// Whether the spectra of the equilibrated F̂ (on which the rank is decided) and of all
    /// its principal blocks are clear of the rank cut-off: every eigenvalue of a block is
    /// either ≥ 1e-6 of the block's λ_max (well
    /// conditioned: a backward-stable evaluation of a quadratic form then has a forward
    /// error of order ε·λ_max/λ ≈ 2e-10 relative, under the 1e-9 and 1e-8 tolerances) or
    /// ≤ 1e-13 of it (a rounding-level zero, as when N < m). Draws with an eigenvalue in
    /// between (some κ(M_S) > 10³: a fraction of a percent) are discarded: near the
    /// cut-off, rank decisions taken relative to different scales (F, F_bb, F*_a, or the
    /// singular values of the stacked M) may legitimately differ.
    fn spectra_clear_of_cutoff(f: &DMatrix<f64>) -> bool {
        let f = &equilibrated(f).1;
        let m = f.nrows();
        (1..1usize << m).all(|mask| {
            let idx: Vec<usize> = (0..m).filter(|&i| mask & (1 << i) != 0).collect();
            let values = f
                .select_rows(&idx)
                .select_columns(&idx)
                .symmetric_eigen()
                .eigenvalues;
            let max = values.max();
            values.iter().all(|&l| l <= 1e-13 * max || l >= 1e-6 * max)
        })
    }

    fn complement(a: &[usize], m: usize) -> Vec<usize> {
        (0..m).filter(|i| !a.contains(i)).collect()
    }

    /// Every non-empty proper subset of 0..m, as index lists.
    fn proper_subsets(m: usize) -> Vec<Vec<usize>> {
        (1..(1usize << m) - 1)
            .map(|mask| (0..m).filter(|&i| mask & (1 << i) != 0).collect())
            .collect()
    }

    /// |x − y| ≤ rel·scale (+ a tiny absolute floor for scale = 0).
    fn close(x: f64, y: f64, rel: f64, scale: f64) -> bool {
        (x - y).abs() <= rel * scale.abs() + 1e-300
    }

    /// Checks global = minmax_a + sensitivity_b (value and rank) for the partition (a, b).
    fn check_decomposition(
        stats: &FisherStatistics,
        a: &[usize],
        rel: f64,
    ) -> Result<(), TestCaseError> {
        let m = stats.dim();
        let b = complement(a, m);
        let global = stats.global();
        let minmax = stats.minmax(a).expect("valid subset");
        if b.is_empty() {
            prop_assert_eq!(minmax, global);
            prop_assert_eq!(stats.sensitivity(a).expect("valid subset"), global);
            return Ok(());
        }
        let sens_b = stats.sensitivity(&b).expect("valid subset");
        prop_assert!(
            close(global.value, minmax.value + sens_b.value, rel, global.value),
            "a = {:?}: global {} ≠ minmax_a {} + sensitivity_b {}",
            a,
            global.value,
            minmax.value,
            sens_b.value
        );
        prop_assert_eq!(
            global.dof,
            minmax.dof + sens_b.dof,
            "rank additivity, a = {:?}",
            a
        );
        Ok(())
    }

    /// (N, m, M, L, Z, subset mask): N in 3..30, m in 1..6, entries of M, L uniform in
    /// [−1, 1], Z uniform in [−3, 3].
    fn problem() -> impl Strategy<Value = (usize, usize, Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>)> {
        (3usize..30, 1usize..6).prop_flat_map(|(n, m)| {
            (
                Just(n),
                Just(m),
                prop::collection::vec(-1.0..1.0f64, n * m),
                prop::collection::vec(-1.0..1.0f64, n * n),
                prop::collection::vec(-3.0..3.0f64, n),
                prop::collection::vec(any::<bool>(), m),
            )
        })
    }

    fn stacked(n: usize, m: usize, mv: &[f64], lv: &[f64], zv: &[f64]) -> Stacked {
        Stacked::new(
            DMatrix::from_column_slice(n, m, mv),
            DMatrix::from_column_slice(n, n, lv),
            DVector::from_column_slice(zv),
        )
    }

    fn subset_from_mask(mask: &[bool]) -> Vec<usize> {
        let a: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
        if a.is_empty() { vec![0] } else { a }
    }

    // ------------------------------------------------------------- properties

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Basseville 1996, §3.2.4, Lemma 3.10, eq. (68): ζᵀF⁻¹ζ = l_a + t̃_b, and
        /// rank F = rank F*_a + rank F_bb, for every single fault a and a random subset.
        /// Relative tolerance 1e-9 of the global statistic.
        #[test]
        fn global_is_minmax_plus_sensitivity_basseville96_lemma(
            (n, m, mv, lv, zv, mask) in problem()
        ) {
            let stats = stacked(n, m, &mv, &lv, &zv).fisher();
            prop_assume!(spectra_clear_of_cutoff(stats.information()));
            for i in 0..m {
                check_decomposition(&stats, &[i], 1e-9)?;
            }
            check_decomposition(&stats, &subset_from_mask(&mask), 1e-9)?;
        }

        /// Zhang & Basseville 2014, eq. (41) / Basseville 1996, eq. (51): the minmax
        /// statistic from (F, ζ) is the stacked nuisance GLR
        /// min_θb ‖Z − M_bθ_b‖²_{R⁻¹} − min_θ ‖Z − Mθ‖²_{R⁻¹}. Tolerance 1e-8 relative to
        /// ‖Z‖²_{R⁻¹}, the size of the two residuals whose difference is the statistic.
        #[test]
        fn minmax_equals_stacked_nuisance_glr_eq41((n, m, mv, lv, zv, mask) in problem()) {
            let st = stacked(n, m, &mv, &lv, &zv);
            let stats = st.fisher();
            prop_assume!(spectra_clear_of_cutoff(stats.information()));
            let all: Vec<usize> = (0..m).collect();
            let full = st.min_residual(&all);
            let mut subsets: Vec<Vec<usize>> = (0..m).map(|i| vec![i]).collect();
            subsets.push(subset_from_mask(&mask));
            for a in subsets {
                let b = complement(&a, m);
                let expected = st.min_residual(&b) - full;
                let got = stats.minmax(&a).expect("valid subset").value;
                prop_assert!(
                    close(got, expected, 1e-8, st.norm2()),
                    "a = {:?}: minmax {} vs stacked {}", a, got, expected
                );
            }
        }

        /// Basseville 1996, eq. (34): sensitivity_a = ‖Z‖²_{R⁻¹} − min_θa ‖Z − M_aθ_a‖²_{R⁻¹}.
        /// Tolerance 1e-8 relative to ‖Z‖²_{R⁻¹}.
        #[test]
        fn sensitivity_equals_stacked_glr_basseville96_eq34(
            (n, m, mv, lv, zv, mask) in problem()
        ) {
            let st = stacked(n, m, &mv, &lv, &zv);
            let stats = st.fisher();
            prop_assume!(spectra_clear_of_cutoff(stats.information()));
            let mut subsets: Vec<Vec<usize>> = (0..m).map(|i| vec![i]).collect();
            subsets.push(subset_from_mask(&mask));
            for a in subsets {
                let expected = st.norm2() - st.min_residual(&a);
                let got = stats.sensitivity(&a).expect("valid subset").value;
                prop_assert!(
                    close(got, expected, 1e-8, st.norm2()),
                    "a = {:?}: sensitivity {} vs stacked {}", a, got, expected
                );
            }
        }

        /// Zhang & Basseville 2014, eq. (35): the global statistic is the stacked GLR
        /// ‖Z‖²_{R⁻¹} − min_θ ‖Z − Mθ‖²_{R⁻¹}; F θ̂ = ζ for θ̂ = F⁺ζ. Tolerance 1e-8
        /// relative to ‖Z‖²_{R⁻¹} (statistic) and to ‖ζ‖ (normal equations).
        #[test]
        fn global_equals_stacked_glr_eq35((n, m, mv, lv, zv, _mask) in problem()) {
            let st = stacked(n, m, &mv, &lv, &zv);
            let stats = st.fisher();
            prop_assume!(spectra_clear_of_cutoff(stats.information()));
            let all: Vec<usize> = (0..m).collect();
            let expected = st.norm2() - st.min_residual(&all);
            let global = stats.global();
            prop_assert!(close(global.value, expected, 1e-8, st.norm2()),
                "global {} vs stacked {}", global.value, expected);
            prop_assert_eq!(global.dof, m.min(n));
            let theta = stats.magnitude();
            let normal = stats.information() * &theta - stats.score();
            prop_assert!(normal.norm() <= 1e-8 * stats.score().norm().max(1.0),
                "‖Fθ̂ − ζ‖ = {}", normal.norm());
        }

        /// Zhang & Basseville 2014, §4.3: l_a does not depend on θ_b. Adding a nuisance
        /// M_bθ_b to Z (ζ → ζ + F_{·b}θ_b) leaves the minmax statistic unchanged, to 1e-9
        /// of the global statistic of the shifted data.
        #[test]
        fn minmax_ignores_nuisance_eq41(
            (n, m, mv, lv, zv, mask) in problem(),
            nuisance in prop::collection::vec(-10.0..10.0f64, 5)
        ) {
            let stats = stacked(n, m, &mv, &lv, &zv).fisher();
            prop_assume!(spectra_clear_of_cutoff(stats.information()));
            let a = subset_from_mask(&mask);
            let b = complement(&a, m);
            let mut theta = DVector::zeros(m);
            for (k, &j) in b.iter().enumerate() {
                theta[j] = nuisance[k];
            }
            let shifted_score = stats.score() + stats.information() * theta;
            let shifted = FisherStatistics::new(stats.information().clone(), shifted_score)
                .expect("finite");
            let before = stats.minmax(&a).expect("valid subset");
            let after = shifted.minmax(&a).expect("valid subset");
            prop_assert_eq!(before.dof, after.dof);
            prop_assert!(close(before.value, after.value, 1e-9, shifted.global().value),
                "a = {:?}: {} vs {}", a, before.value, after.value);
        }
    }

    // ------------------------------------------------------------ fixed cases

    #[test]
    fn known_two_fault_values() {
        let f = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
        let stats = FisherStatistics::new(f, DVector::from_vec(vec![6.0, 3.0])).unwrap();
        let check = |t: TestStatistic, v: f64, dof: usize| {
            assert!((t.value - v).abs() < 1e-12, "{t:?} vs {v}");
            assert_eq!(t.dof, dof);
        };
        check(stats.global(), 9.0, 2);
        check(stats.sensitivity(&[0]).unwrap(), 9.0, 1);
        check(stats.sensitivity(&[1]).unwrap(), 3.0, 1);
        check(stats.minmax(&[0]).unwrap(), 6.0, 1);
        check(stats.minmax(&[1]).unwrap(), 0.0, 1);
        check(stats.minmax(&[1, 0]).unwrap(), 9.0, 2);
        assert_eq!(stats.minmax(&[1, 0]).unwrap(), stats.global());
        assert_eq!(stats.sensitivity(&[0, 1]).unwrap(), stats.global());
        let theta = stats.magnitude();
        assert!((theta[0] - 1.5).abs() < 1e-12 && theta[1].abs() < 1e-12);
    }

    /// Two faults with the same signature (identical columns of M) and one fault with no
    /// signature at all: F is singular, every value is finite, the degrees of freedom are
    /// the ranks, and the decomposition still holds.
    #[test]
    fn rank_deficient_information_identical_columns() {
        let mut rng = SplitMix64(0xDEC0_0041);
        let (n, m) = (12, 4);
        let mut mm = rng.normal_matrix(n, m);
        let col0 = mm.column(0).clone_owned();
        mm.set_column(2, &col0); // fault 2 ≡ fault 0
        mm.set_column(3, &DVector::zeros(n)); // fault 3 invisible
        let theta = DVector::from_vec(vec![1.0, -0.5, 0.0, 0.0]);
        let z = &mm * theta + rng.normal_matrix(n, 1).column(0);
        let st = Stacked::new(mm, rng.normal_matrix(n, n), z);
        let stats = st.fisher();

        let global = stats.global();
        assert!(global.value.is_finite());
        assert_eq!(global.dof, 2);
        for a in proper_subsets(m) {
            let sens = stats.sensitivity(&a).unwrap();
            let minmax = stats.minmax(&a).unwrap();
            assert!(sens.value.is_finite() && minmax.value.is_finite(), "{a:?}");
            check_decomposition(&stats, &a, 1e-9).unwrap();
            // The stacked form agrees too (SVD least squares, matching rank cut-off).
            let expected = st.min_residual(&complement(&a, m)) - st.min_residual(&[0, 1, 2, 3]);
            assert!(close(minmax.value, expected, 1e-8, st.norm2()), "{a:?}");
        }
        // Fault 0 cannot be told from fault 2: once 2 is a nuisance, nothing is left.
        let t0 = stats.minmax(&[0]).unwrap();
        assert_eq!(t0.dof, 0);
        assert!(t0.value <= 1e-9 * global.value);
        // Together they carry one degree of freedom.
        assert_eq!(stats.minmax(&[0, 2]).unwrap().dof, 1);
        assert_eq!(stats.sensitivity(&[0, 2]).unwrap().dof, 1);
        // The invisible fault: no information, no statistic.
        assert_eq!(
            stats.sensitivity(&[3]).unwrap(),
            TestStatistic { value: 0.0, dof: 0 }
        );
        assert_eq!(stats.minmax(&[3]).unwrap().dof, 0);
        assert_eq!(stats.minmax(&[1]).unwrap().dof, 1);
        // Minimum-norm magnitude: the shared effect is split evenly, nothing on fault 3.
        let theta = stats.magnitude();
        assert!(theta.iter().all(|x| x.is_finite()));
        assert!((theta[0] - theta[2]).abs() <= 1e-9 * theta.norm());
        assert!(theta[3].abs() <= 1e-12 * theta.norm());
        let normal = stats.information() * &theta - stats.score();
        assert!(normal.norm() <= 1e-9 * stats.score().norm());
    }

    #[test]
    fn zero_and_empty_information() {
        let zero = FisherStatistics::new(DMatrix::zeros(3, 3), DVector::zeros(3)).unwrap();
        let nothing = TestStatistic { value: 0.0, dof: 0 };
        assert_eq!(zero.global(), nothing);
        assert_eq!(zero.minmax(&[1]).unwrap(), nothing);
        assert_eq!(zero.sensitivity(&[0, 2]).unwrap(), nothing);
        assert_eq!(zero.magnitude(), DVector::zeros(3));

        let empty = FisherStatistics::new(DMatrix::zeros(0, 0), DVector::zeros(0)).unwrap();
        assert_eq!(empty.dim(), 0);
        assert_eq!(empty.global(), nothing);
        assert_eq!(empty.magnitude().len(), 0);
        assert_eq!(
            empty.minmax(&[0]),
            Err(IsolationError::IndexOutOfRange { index: 0, dim: 0 })
        );
    }

    /// A change of fault units F ↦ SFS, ζ ↦ Sζ (S = diag(10⁻⁸, 1, 10⁸), F_ii
    /// spanning 32 decades) changes no degree of freedom, no test value beyond 1e-9 of
    /// the global statistic, and gives θ̂ ↦ S⁻¹θ̂; the fault of tiny F_ii keeps its
    /// information (it was dropped by the cut-off τ·λ_max(F) of before).
    #[test]
    fn fault_units_do_not_decide_the_rank() {
        let mut rng = SplitMix64(0x19);
        let (n, m) = (20, 3);
        let mm = rng.normal_matrix(n, m);
        let theta = DVector::from_vec(vec![2.0, -1.0, 3.0]);
        let z = &mm * &theta + rng.normal_matrix(n, 1).column(0);
        let base = Stacked::new(mm.clone(), rng.normal_matrix(n, n) * 0.3, z).fisher();
        let units = DVector::from_vec(vec![1e-8, 1.0, 1e8]);
        let s = DMatrix::from_diagonal(&units);
        let scaled = FisherStatistics::new(
            &s * base.information() * &s,
            base.score().component_mul(&units),
        )
        .unwrap();
        let g = base.global();
        assert_eq!(g.dof, 3);
        assert_eq!(scaled.global().dof, 3);
        assert!(close(scaled.global().value, g.value, 1e-9, g.value));
        for a in [vec![0], vec![1], vec![2], vec![0, 2]] {
            for (x, y) in [
                (base.minmax(&a).unwrap(), scaled.minmax(&a).unwrap()),
                (
                    base.sensitivity(&a).unwrap(),
                    scaled.sensitivity(&a).unwrap(),
                ),
            ] {
                assert_eq!(x.dof, y.dof, "{a:?}");
                assert!(
                    close(x.value, y.value, 1e-9, g.value),
                    "{a:?}: {x:?} vs {y:?}"
                );
            }
        }
        let (t, u) = (base.magnitude(), scaled.magnitude());
        for j in 0..m {
            assert!(close(u[j] * units[j], t[j], 1e-9, t.amax()), "θ̂_{j}");
        }
    }

    #[test]
    fn rank_tolerance_decides_near_collinear_faults() {
        // Correlation 1 − 1e-12 between the two signatures.
        let rho = 1.0 - 1e-12;
        let f = DMatrix::from_row_slice(2, 2, &[1.0, rho, rho, 1.0]);
        let zeta = DVector::from_vec(vec![1.0, 1.0]);
        let coarse = FisherStatistics::new(f.clone(), zeta.clone()).unwrap();
        assert_eq!(coarse.global().dof, 1);
        assert_eq!(coarse.minmax(&[0]).unwrap().dof, 0);
        let fine = FisherStatistics::new(f, zeta)
            .unwrap()
            .with_rank_tolerance(1e-14);
        assert_eq!(fine.rank_tolerance(), 1e-14);
        assert_eq!(fine.global().dof, 2);
        assert_eq!(fine.minmax(&[0]).unwrap().dof, 1);
        let default = FisherStatistics::new(DMatrix::identity(1, 1), DVector::zeros(1))
            .unwrap()
            .with_rank_tolerance(f64::NAN);
        assert_eq!(default.rank_tolerance(), DEFAULT_RANK_TOLERANCE);
    }

    #[test]
    fn errors() {
        let f = DMatrix::<f64>::identity(3, 3);
        let z = DVector::from_vec(vec![1.0, 2.0, 3.0]);
        let stats = FisherStatistics::new(f.clone(), z.clone()).unwrap();

        let e = stats.minmax(&[3]).unwrap_err();
        assert_eq!(e, IsolationError::IndexOutOfRange { index: 3, dim: 3 });
        assert!(e.to_string().contains('3'));
        assert_eq!(
            stats.sensitivity(&[0, 7]),
            Err(IsolationError::IndexOutOfRange { index: 7, dim: 3 })
        );
        assert_eq!(
            stats.minmax(&[1, 0, 1]),
            Err(IsolationError::DuplicateIndex { index: 1 })
        );
        assert_eq!(
            stats.sensitivity(&[2, 2]),
            Err(IsolationError::DuplicateIndex { index: 2 })
        );
        assert_eq!(stats.minmax(&[]), Err(IsolationError::EmptySubset));
        assert_eq!(stats.sensitivity(&[]), Err(IsolationError::EmptySubset));

        let mut bad = f.clone();
        bad[(1, 2)] = f64::NAN;
        assert_eq!(
            FisherStatistics::new(bad, z.clone()).unwrap_err(),
            IsolationError::NonFinite {
                input: "information matrix"
            }
        );
        let mut bad_z = z.clone();
        bad_z[0] = f64::INFINITY;
        assert_eq!(
            FisherStatistics::new(f.clone(), bad_z).unwrap_err(),
            IsolationError::NonFinite { input: "score" }
        );

        let e = FisherStatistics::new(DMatrix::zeros(3, 2), DVector::zeros(3)).unwrap_err();
        assert_eq!(
            e,
            IsolationError::DimensionMismatch {
                rows: 3,
                cols: 2,
                score: 3
            }
        );
        assert!(e.to_string().contains("3×2"));
        assert_eq!(
            FisherStatistics::new(f, DVector::zeros(2)).unwrap_err(),
            IsolationError::DimensionMismatch {
                rows: 3,
                cols: 3,
                score: 2
            }
        );
    }

    /// Zhang & Basseville 2014, §4.3 after (41): under θ_a = 0, l_a ~ χ²(dim θ_a). Fixed
    /// M (N = 40, m = 3, correlated signatures), R = LLᵀ + I, θ = 0, 20 000 draws of Z
    /// from a fixed seed: the empirical 50/95/99 % quantiles of the single-fault minmax
    /// statistic are within 3 % of the χ²(1) quantiles. (Sampling standard deviation of
    /// the empirical quantile: ≈ 1.7 %, 1.4 %, 1.9 % of the value respectively.)
    #[test]
    fn minmax_is_chi2_1_under_h0_eq41() {
        let mut rng = SplitMix64(0x2014_0041);
        let (n, m) = (40, 3);
        let mut mm = rng.normal_matrix(n, m);
        // Correlate the signatures: column 1 shares half of column 0, column 2 of column 1.
        let c0 = mm.column(0).clone_owned();
        let c1 = mm.column(1).clone_owned();
        mm.set_column(1, &(&c1 + &c0 * 0.8));
        let c1 = mm.column(1).clone_owned();
        let c2 = mm.column(2).clone_owned();
        mm.set_column(2, &(c2 + c1 * 0.6));
        let st = Stacked::new(mm, rng.normal_matrix(n, n) * 0.5, DVector::zeros(n));
        let f = st.m_white.tr_mul(&st.m_white);

        // Z = Ce with R = CCᵀ gives C⁻¹Z = e, so ζ = M̃ᵀe.
        let draws = 20_000;
        let mut values: Vec<f64> = (0..draws)
            .map(|_| {
                let e = DVector::from_fn(n, |_, _| rng.normal());
                let stats = FisherStatistics::new(f.clone(), st.m_white.tr_mul(&e)).unwrap();
                let t = stats.minmax(&[1]).unwrap();
                assert_eq!(t.dof, 1);
                t.value
            })
            .collect();
        values.sort_by(f64::total_cmp);
        for (p, chi2) in [
            (0.50, 0.4549364231195724),
            (0.95, 3.841458820694124),
            (0.99, 6.634896601021214),
        ] {
            let q = values[(p * draws as f64) as usize];
            assert!(
                (q - chi2).abs() <= 0.03 * chi2,
                "{p}-quantile {q} vs χ²(1) {chi2}"
            );
        }
    }

    #[test]
    fn pinv_quadratic_form_matches_inverse_and_handles_edge_cases() {
        let mut rng = SplitMix64(7);
        let g = rng.normal_matrix(5, 5);
        let a = g.tr_mul(&g) + DMatrix::identity(5, 5);
        let x = DVector::from_fn(5, |_, _| rng.normal());
        let inv = a.clone().try_inverse().unwrap();
        let t = pinv_quadratic_form(&a, &x, DEFAULT_RANK_TOLERANCE);
        assert_eq!(t.dof, 5);
        let expected = x.dot(&(inv * &x));
        assert!(close(t.value, expected, 1e-12, expected));

        // Asymmetric input: only the symmetric part counts.
        let skew = DMatrix::from_fn(5, 5, |i, j| (i as f64) - (j as f64));
        let t2 = pinv_quadratic_form(&(&a + skew), &x, DEFAULT_RANK_TOLERANCE);
        assert!(close(t2.value, expected, 1e-12, expected));

        // Indefinite: negative eigenvalues are dropped.
        let d = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, -1.0]));
        let t3 = pinv_quadratic_form(&d, &DVector::from_vec(vec![2.0, 5.0]), 1e-9);
        assert_eq!(t3, TestStatistic { value: 1.0, dof: 1 });

        let empty = pinv_quadratic_form(&DMatrix::zeros(0, 0), &DVector::zeros(0), 1e-9);
        assert_eq!(empty, TestStatistic { value: 0.0, dof: 0 });
        let nan = pinv_quadratic_form(
            &DMatrix::from_element(1, 1, f64::INFINITY),
            &DVector::from_element(1, 1.0),
            1e-9,
        );
        assert!(nan.value.is_nan() && nan.dof == 0);
        let nan_x = pinv_quadratic_form(
            &DMatrix::identity(1, 1),
            &DVector::from_element(1, f64::NAN),
            1e-9,
        );
        assert!(nan_x.value.is_nan());
        // Extreme but finite scales do not overflow. Both directions count: the rank is
        // decided on the equilibrated matrix. (This asserted dof 1 when the
        // cut-off was τ·λ_max(A), which dropped the 1e-300 direction for its units
        // alone.)
        let huge = pinv_quadratic_form(
            &DMatrix::from_diagonal(&DVector::from_vec(vec![1e300, 1e-300])),
            &DVector::from_vec(vec![1e300, 1e-300]),
            1e-9,
        );
        assert_eq!(huge.dof, 2);
        assert!(close(huge.value, 1e300 + 1e-300, 1e-12, 1e300));
    }

    #[test]
    #[should_panic(expected = "pinv_quadratic_form")]
    fn pinv_quadratic_form_rejects_mismatched_sizes() {
        let _ = pinv_quadratic_form(&DMatrix::identity(2, 2), &DVector::zeros(3), 1e-9);
    }

    /// The Jacobi fallback (used when nalgebra's QR iteration hits its cap) gives a valid
    /// eigendecomposition: V orthogonal and VΛVᵀ = A to 1e-13 (entries of order 1).
    #[test]
    fn jacobi_fallback_diagonalises() {
        let mut rng = SplitMix64(11);
        for n in 1..8 {
            let g = rng.normal_matrix(n, n);
            let mut a = symmetrized(&g);
            if n > 2 {
                // Also a rank-deficient PSD case with a zero row/column.
                let h = rng.normal_matrix(n, n - 2);
                a = &h * h.transpose();
                a.row_mut(0).fill(0.0);
                a.column_mut(0).fill(0.0);
            }
            let a = &a / a.amax();
            let (values, v) = jacobi_eigen(a.clone());
            let recomposed = &v * DMatrix::from_diagonal(&values) * v.transpose();
            let err = (recomposed - &a).amax();
            assert!(err < 1e-13, "n = {n}: {err}");
            assert!(
                (v.tr_mul(&v) - DMatrix::identity(n, n)).amax() < 1e-13,
                "n = {n}"
            );
        }
    }
}
