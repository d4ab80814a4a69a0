//! Residual generators for sparse fault isolation (Zhang 2021, §III): the Kalman
//! filter's updated output error (Prop. 1) and the Kitanidis filter's output error,
//! which rejects an unknown input (Prop. 2), each with the matrix Υ_k that maps the
//! fault vector θ onto the residual.
//!
//! The monitored plant, in glrmon's (2014) letters, is
//!
//! ```text
//! X_{k+1} = F_k X_k + G_k U_k + E_k d_k + W_k + Ψ_k θ       (Zhang 2021, eq. (1a)/(23a))
//! Y_k     = H_k X_k + J_k U_k + V_k + Φ_k θ                  (eq. (1b)/(23b), + output faults)
//! ```
//!
//! where Ψ_k (n×m) is the 2021 paper's Φ_k (its state-fault matrix), E_kd_k an
//! arbitrary unknown input, and the output-fault term Φ_kθ (p×m) is an extension: the
//! 2021 paper has no output faults and no feed-through J_kU_k (its Example 2 moves
//! D_ku_k to the left-hand side, as done here). The 2021 paper's A, B, C, Q, R are
//! F, G, H, Q, R. Both filters are designed for θ = 0 and run on the possibly faulty
//! plant; their residual r_k (p) then satisfies the linear regression
//!
//! ```text
//! r_k = Υ_k^r θ + r_k⁰                                        (eqs. (6), (26))
//! ```
//!
//! with r_k⁰ the residual the same filter would produce on the fault-free plant (same
//! noises, same unknown input) and Υ_k^r = H_kΥ_k + Φ_k the *residual signature*
//! (p×m), produced by the recursion on the n×m matrix Υ_k (eqs. (7), (27)). Stacking
//! (Υ_k^r, r_k) over the samples gives the sparse regression of eq. (36), accumulated
//! by [`crate::sparse::GramAccumulator`].
//!
//! Output faults: repeating the proofs of Props. 1 and 2 with Y_k = H_kX_k + V_k +
//! Φ_kθ, the error dynamics (10)/(29) gain the term −K̄_{k+1}Φ_{k+1}θ and the residual
//! (18) gains Φ_kθ, so the same decoupling argument gives
//!
//! ```text
//! Υ_{k|k−1} = F_{k−1}Υ_{k−1} + Ψ_{k−1}
//! Υ_k       = (I − K̄_kH_k)Υ_{k|k−1} − K̄_kΦ_k        (eqs. (7b)/(27b) with −K̄_kΦ_k)
//! Υ_k^r     = H_kΥ_k + Φ_k = (I − H_kK̄_k)(H_kΥ_{k|k−1} + Φ_k)
//! ```
//!
//! (checked numerically in the tests). With Φ = 0 this is the paper's recursion.
//!
//! Timing. Every matrix of sample k (F_k, G_k, H_k, J_k, Q_k, R_k, U_k, Ψ_k, Φ_k,
//! E_k) is passed at sample k. Ψ_k, E_k, F_k, G_kU_k and Q_k act between samples k and
//! k + 1, so they are stored and used at the next step; the Kitanidis gain at sample
//! k + 1 needs H_{k+1}E_k (eqs. (24c)-(24g)). The filters start from a prior
//! X̂_{0|−1} = x̄_0, P_{0|−1} = P̄_0 *for the first sample's state* and update it with
//! the first measurement (a plain Kalman update: no unknown input precedes the first
//! sample), like [`crate::filter::innovation::InnovationFilter`]. The paper instead sets
//! x̂_{0|0} = x̄_0 without using y_0 and builds the regression from k = 1, …, N: the
//! recursions are the same, only the initialisation differs (here y_0 is used too,
//! and its residual also obeys Props. 1-2).

use nalgebra::{DMatrix, DVector};

use crate::error::SparseError;
use crate::linalg::{cholesky_in_place, gemm, gemv, solve_lower_in_place, symmetrize};
use crate::model::SystemMatrices;

pub use crate::error::UNKNOWN_INPUT_RANK_TOLERANCE;

/// Checks Assumption (iv) of Zhang 2021: C_{k+1}E_k (`c_next`·`e`, p×s) has full
/// column rank s, with a bounded pseudo-inverse: every singular value of C_{k+1}Ê_k
/// (unit-norm columns) above [`UNKNOWN_INPUT_RANK_TOLERANCE`]·‖C_{k+1}‖_F. This is what
/// lets the Kitanidis filter (eqs. (24c)-(24g), (30)) reject the unknown input
/// E_kd_k; it requires s ≤ p.
///
/// # Errors
/// [`SparseError::UnknownInputRank`] when the rank is deficient (including s > p and
/// a zero column of E_k), with the numerical rank; [`SparseError::Dimension`] when
/// the shapes do not chain; [`SparseError::NonFinite`] for NaN/Inf.
///
/// # Examples
/// ```
/// use glrmon_core::sparse::residual::unknown_input_rank;
/// use nalgebra::DMatrix;
/// // Zhang 2021, Example 1 (eq. (42)): C E = [−1; 0] has rank 1.
/// let c = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
/// let e = DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0]);
/// assert!(unknown_input_rank(&c, &e).is_ok());
/// // An unknown input on the unmeasured second state cannot be rejected.
/// let e2 = DMatrix::from_row_slice(3, 1, &[0.0, 1.0, 0.0]);
/// assert!(unknown_input_rank(&c, &e2).is_err());
/// ```
pub fn unknown_input_rank(c_next: &DMatrix<f64>, e: &DMatrix<f64>) -> Result<(), SparseError> {
    if c_next.ncols() != e.nrows() {
        return Err(SparseError::Dimension {
            what: "E",
            detail: format!(
                "C_{{k+1}} is {}×{} but E_k has {} rows",
                c_next.nrows(),
                c_next.ncols(),
                e.nrows()
            ),
        });
    }
    if c_next.iter().chain(e.iter()).any(|v| !v.is_finite()) {
        return Err(SparseError::NonFinite {
            what: "C_{k+1} or E_k",
        });
    }
    let mut ce = c_next * e;
    let mut sv = vec![0.0; e.ncols()];
    check_rank(c_next, e, ce.as_mut_slice(), &mut sv)
}

/// Rank check of C_{k+1}E_k given in `ce` (p×s, destroyed); `sv` has s entries.
fn check_rank(
    c: &DMatrix<f64>,
    e: &DMatrix<f64>,
    ce: &mut [f64],
    sv: &mut [f64],
) -> Result<(), SparseError> {
    let (p, ud) = (c.nrows(), e.ncols());
    if ud == 0 {
        return Ok(());
    }
    // Scale column j of CE by 1/‖E[:, j]‖: the singular values of CÊ (a zero column
    // of E stays zero and counts as a rank deficiency).
    for j in 0..ud {
        let norm = e.column(j).norm();
        if norm > 0.0 {
            ce[j * p..(j + 1) * p].iter_mut().for_each(|v| *v /= norm);
        }
    }
    singular_values_in_place(ce, p, ud, sv);
    let c_norm = c.norm();
    let limit = UNKNOWN_INPUT_RANK_TOLERANCE * c_norm;
    let rank = sv.iter().filter(|&&s| s > limit).count().min(p);
    if rank < ud {
        let smin = sv.iter().copied().fold(f64::INFINITY, f64::min);
        let ratio = if ud > p || c_norm == 0.0 {
            0.0
        } else {
            smin / c_norm
        };
        return Err(SparseError::UnknownInputRank {
            outputs: p,
            unknown_inputs: ud,
            rank,
            ratio,
        });
    }
    Ok(())
}

/// Singular values of the column-major `rows`×`cols` matrix `a` (destroyed) by
/// one-sided Jacobi rotations (Hestenes), allocation-free and accurate for small
/// singular values; unsorted, into `out` (`cols` entries).
fn singular_values_in_place(a: &mut [f64], rows: usize, cols: usize, out: &mut [f64]) {
    for _sweep in 0..64 {
        let mut rotated = false;
        for i in 0..cols {
            for j in (i + 1)..cols {
                let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                for r in 0..rows {
                    let (x, y) = (a[r + rows * i], a[r + rows * j]);
                    alpha += x * x;
                    beta += y * y;
                    gamma += x * y;
                }
                if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + 1.0_f64.hypot(zeta));
                let c = 1.0 / 1.0_f64.hypot(t);
                let s = c * t;
                for r in 0..rows {
                    let (x, y) = (a[r + rows * i], a[r + rows * j]);
                    a[r + rows * i] = c * x - s * y;
                    a[r + rows * j] = s * x + c * y;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    for (j, o) in out.iter_mut().enumerate().take(cols) {
        *o = a[j * rows..(j + 1) * rows]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
    }
}

/// The known quantities of one sample for [`KalmanResidual::step`] and
/// [`KitanidisResidual::step`].
#[derive(Debug, Clone, Copy)]
pub struct ResidualSample<'a> {
    /// F_k, G_k, H_k, J_k, Q_k, R_k at this sample (the 2021 paper's A_k, B_k, C_k,
    /// –, Q_k, R_k).
    pub sys: &'a SystemMatrices,
    /// U_k (l).
    pub u: &'a [f64],
    /// Y_k (p).
    pub y: &'a [f64],
    /// Ψ_k (n×m), the state-fault matrix entering X_{k+1} — the 2021 paper's Φ_k in
    /// eqs. (1a), (7b), (27b). It is the whole matrix, onset profile included (for
    /// glrmon's dictionary: Ψ̃_k scaled column-wise by the onset factors).
    pub psi: &'a DMatrix<f64>,
    /// Φ_k (p×m), the output-fault matrix in Y_k; `None` for state faults only (the
    /// paper's model).
    pub phi: Option<&'a DMatrix<f64>>,
}

/// One sample's contribution to the regression of Zhang 2021, eq. (36): the residual
/// r_k and its residual signature Υ_k^r (r_k = Υ_k^rθ + r_k⁰).
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualRow {
    /// r_k (p): ỹ_{k|k} of eq. (5) (Kalman) or ỹ_k of eq. (25) (Kitanidis).
    pub residual: DVector<f64>,
    /// Υ_k^r = H_kΥ_k + Φ_k (p×m), the residual signature: C_kΥ_k of eq. (6) or
    /// C_kΥ̃_k of eq. (26) when there are no output faults. Rows of X in eq. (36).
    pub upsilon: DMatrix<f64>,
}

impl ResidualRow {
    /// Zero outputs for p outputs and m faults.
    #[must_use]
    pub fn zeros(outputs: usize, faults: usize) -> Self {
        Self {
            residual: DVector::zeros(outputs),
            upsilon: DMatrix::zeros(outputs, faults),
        }
    }
}

/// The filter shared by both generators: the Kitanidis filter of eqs. (24a)-(24h),
/// which is the Kalman filter of eqs. (4a)-(4g) when no unknown input is active
/// (s = 0, or at the first sample).
#[derive(Debug, Clone)]
struct UpdatedFilter {
    n: usize,
    p: usize,
    m: usize,
    ud: usize,
    // Prior of the current sample's state (before its measurement).
    /// F_{k−1}X̂_{k−1} + G_{k−1}U_{k−1} (the first sample: x̄_0).
    x_prior: DVector<f64>,
    /// P̄_{k|k−1} = F_{k−1}P̄_{k−1|k−1}F_{k−1}ᵀ + Q_{k−1}, eq. (24a)/(4a).
    p_prior: DMatrix<f64>,
    /// Υ_{k|k−1} = F_{k−1}Υ_{k−1} + Ψ_{k−1}.
    ups_prior: DMatrix<f64>,
    /// E_{k−1} (n×s).
    e_prev: DMatrix<f64>,
    /// Whether an unknown input acts before the current sample.
    e_active: bool,
    // Posterior at the last sample.
    x_post: DVector<f64>,
    p_post: DMatrix<f64>,
    ups_post: DMatrix<f64>,
    gain: DMatrix<f64>,
    sigma: DMatrix<f64>,
    residual_cov: DMatrix<f64>,
    /// Rank of the residual covariance: p, or p − s after an unknown input.
    residual_rank: usize,
    // Scratch.
    pht: DMatrix<f64>,
    sigma_new: DMatrix<f64>,
    chol: DMatrix<f64>,
    linv: DMatrix<f64>,
    tmp_np: DMatrix<f64>,
    kbar: DMatrix<f64>,
    ce: DMatrix<f64>,
    ce_svd: DMatrix<f64>,
    sv: Vec<f64>,
    w: DMatrix<f64>,
    qtl: DMatrix<f64>,
    mq: DMatrix<f64>,
    /// Γ_k of eq. (24c) (n×s): the unknown-input gain term, not the 2014 Γ.
    unknown_input_gain: DMatrix<f64>,
    nu: DVector<f64>,
    ihk: DMatrix<f64>,
    ikh: DMatrix<f64>,
    tmp_nn: DMatrix<f64>,
    tmp_pp: DMatrix<f64>,
    s_pm: DMatrix<f64>,
}

impl UpdatedFilter {
    fn new(
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        outputs: usize,
        faults: usize,
        unknown_inputs: usize,
    ) -> Result<Self, SparseError> {
        let n = x0.len();
        if n == 0 || outputs == 0 {
            return Err(SparseError::Dimension {
                what: "x0",
                detail: format!(
                    "need at least one state and one output, got n = {n}, p = {outputs}"
                ),
            });
        }
        if p0.shape() != (n, n) {
            return Err(SparseError::Dimension {
                what: "P0",
                detail: format!("P0 is {}×{} but x0 has {n} entries", p0.nrows(), p0.ncols()),
            });
        }
        if x0.iter().chain(p0.iter()).any(|v| !v.is_finite()) {
            return Err(SparseError::NonFinite { what: "x0/P0" });
        }
        let asym = (&p0 - p0.transpose()).amax();
        if asym > 1e-9 * p0.amax().max(1.0) {
            return Err(SparseError::Setting {
                what: "P0",
                detail: format!("P0 is not symmetric (max |P0 − P0ᵀ| = {asym:e})"),
            });
        }
        if unknown_inputs > outputs {
            return Err(SparseError::UnknownInputRank {
                outputs,
                unknown_inputs,
                rank: outputs,
                ratio: 0.0,
            });
        }
        let (p, m, ud) = (outputs, faults, unknown_inputs);
        let z = |r, c| DMatrix::zeros(r, c);
        Ok(Self {
            n,
            p,
            m,
            ud,
            x_post: x0.clone(),
            x_prior: x0,
            p_post: p0.clone(),
            p_prior: p0,
            ups_prior: z(n, m),
            e_prev: z(n, ud),
            e_active: false,
            ups_post: z(n, m),
            gain: z(n, p),
            sigma: z(p, p),
            residual_cov: z(p, p),
            residual_rank: p,
            pht: z(n, p),
            sigma_new: z(p, p),
            chol: z(p, p),
            linv: z(p, p),
            tmp_np: z(n, p),
            kbar: z(n, p),
            ce: z(p, ud),
            ce_svd: z(p, ud),
            sv: vec![0.0; ud],
            w: z(p, ud),
            qtl: z(p, p),
            mq: z(ud, p),
            unknown_input_gain: z(n, ud),
            nu: DVector::zeros(p),
            ihk: z(p, p),
            ikh: z(n, n),
            tmp_nn: z(n, n),
            tmp_pp: z(p, p),
            s_pm: z(p, m),
        })
    }

    /// Shape and finiteness checks of one sample (and of E_k when given).
    fn check(&self, s: &ResidualSample<'_>, e: Option<&DMatrix<f64>>) -> Result<(), SparseError> {
        let (n, p, m) = (self.n, self.p, self.m);
        let sys = s.sys;
        let l = sys.g.ncols();
        let shapes = [
            ("F", sys.f.shape(), (n, n)),
            ("G", sys.g.shape(), (n, l)),
            ("H", sys.h.shape(), (p, n)),
            ("J", sys.j.shape(), (p, l)),
            ("Q", sys.q.shape(), (n, n)),
            ("R", sys.r.shape(), (p, p)),
            ("psi", s.psi.shape(), (n, m)),
        ];
        for (what, got, want) in shapes {
            if got != want {
                return Err(SparseError::Dimension {
                    what,
                    detail: format!(
                        "{what} is {}×{}, expected {}×{}",
                        got.0, got.1, want.0, want.1
                    ),
                });
            }
        }
        if let Some(phi) = s.phi
            && phi.shape() != (p, m)
        {
            return Err(SparseError::Dimension {
                what: "phi",
                detail: format!("phi is {}×{}, expected {p}×{m}", phi.nrows(), phi.ncols()),
            });
        }
        if let Some(e) = e {
            if e.shape() != (n, self.ud) {
                return Err(SparseError::Dimension {
                    what: "E",
                    detail: format!(
                        "E is {}×{}, expected {n}×{} (n × unknown inputs)",
                        e.nrows(),
                        e.ncols(),
                        self.ud
                    ),
                });
            }
            if e.iter().any(|v| !v.is_finite()) {
                return Err(SparseError::NonFinite { what: "E" });
            }
        }
        if s.u.len() != l {
            return Err(SparseError::Dimension {
                what: "u",
                detail: format!("u has {} values, G has {l} columns", s.u.len()),
            });
        }
        if s.y.len() != p {
            return Err(SparseError::Dimension {
                what: "y",
                detail: format!("y has {} values, the model has {p} outputs", s.y.len()),
            });
        }
        if !sys.is_finite() {
            return Err(SparseError::NonFinite {
                what: "system matrices",
            });
        }
        if s.u.iter().any(|v| !v.is_finite()) {
            return Err(SparseError::NonFinite { what: "u" });
        }
        if s.y.iter().any(|v| !v.is_finite()) {
            return Err(SparseError::NonFinite { what: "y" });
        }
        if s.psi.iter().any(|v| !v.is_finite()) {
            return Err(SparseError::NonFinite { what: "psi" });
        }
        if s.phi.is_some_and(|phi| phi.iter().any(|v| !v.is_finite())) {
            return Err(SparseError::NonFinite { what: "phi" });
        }
        Ok(())
    }

    /// Measurement update of the current sample (eqs. (24b)-(24h), (25), (27b)), then
    /// propagation to the next sample with this sample's F, G, Q, Ψ and E.
    fn step(
        &mut self,
        s: &ResidualSample<'_>,
        e: Option<&DMatrix<f64>>,
        out: &mut ResidualRow,
    ) -> Result<(), SparseError> {
        self.check(s, e)?;
        if out.residual.len() != self.p || out.upsilon.shape() != (self.p, self.m) {
            return Err(SparseError::Dimension {
                what: "output row",
                detail: format!(
                    "the output row is {}, {}×{}; expected {}, {}×{} (ResidualRow::zeros)",
                    out.residual.len(),
                    out.upsilon.nrows(),
                    out.upsilon.ncols(),
                    self.p,
                    self.p,
                    self.m
                ),
            });
        }
        self.measure(s, out)?;
        self.propagate(s, e);
        Ok(())
    }

    /// Computes the gain K̄_k into `self.kbar` and Σ̄_k into `self.sigma_new`; fails
    /// without touching any observable state.
    fn gain(&mut self, sys: &SystemMatrices) -> Result<(), SparseError> {
        let (n, p, ud) = (self.n, self.p, self.ud);
        // P̄ Hᵀ and Σ̄ = H P̄ Hᵀ + R, eq. (24b)/(4b).
        mul(1.0, &self.p_prior, false, &sys.h, true, 0.0, &mut self.pht);
        self.sigma_new.copy_from(&sys.r);
        mul(
            1.0,
            &sys.h,
            false,
            &self.pht,
            false,
            1.0,
            &mut self.sigma_new,
        );
        symmetrize(self.sigma_new.as_mut_slice(), p);
        self.chol.copy_from(&self.sigma_new);
        if !cholesky_in_place(self.chol.as_mut_slice(), p) {
            return Err(SparseError::Numerical {
                what: "Σ̄_k = H_kP̄_{k|k−1}H_kᵀ + R_k is not positive definite",
            });
        }
        // L⁻¹ (Σ̄ = LLᵀ) and the Kalman gain K = P̄HᵀΣ̄⁻¹ = (P̄Hᵀ L⁻ᵀ) L⁻¹, eq. (4c).
        self.linv.fill_with_identity();
        solve_lower_in_place(self.chol.as_slice(), p, self.linv.as_mut_slice(), p);
        mul(
            1.0,
            &self.pht,
            false,
            &self.linv,
            true,
            0.0,
            &mut self.tmp_np,
        );
        mul(
            1.0,
            &self.tmp_np,
            false,
            &self.linv,
            false,
            0.0,
            &mut self.kbar,
        );
        if ud == 0 || !self.e_active {
            return Ok(());
        }
        // Unknown input: CE (p×s), Assumption (iv).
        mul(1.0, &sys.h, false, &self.e_prev, false, 0.0, &mut self.ce);
        self.ce_svd.copy_from(&self.ce);
        check_rank(
            &sys.h,
            &self.e_prev,
            self.ce_svd.as_mut_slice(),
            &mut self.sv,
        )?;
        // With W = L⁻¹CE = QR (Householder), Ξ = EᵀCᵀΣ̄⁻¹CE = WᵀW = RᵀR (eq. (24d)) and
        // Ξ⁻¹EᵀCᵀΣ̄⁻¹ = R⁻¹QᵀL⁻¹ =: M (s×p), computed without forming Ξ.
        mul(1.0, &self.linv, false, &self.ce, false, 0.0, &mut self.w);
        self.qtl.copy_from(&self.linv);
        householder_qr_apply(&mut self.w, &mut self.qtl);
        let rmax = (0..ud)
            .map(|j| self.w[(j, j)].abs())
            .fold(0.0_f64, f64::max);
        for j in 0..ud {
            let r = self.w[(j, j)].abs();
            if r.is_nan() || r <= 1e-13 * rmax {
                return Err(SparseError::Numerical {
                    what: "Ξ_k = E_kᵀC_{k+1}ᵀΣ̄⁻¹C_{k+1}E_k is singular",
                });
            }
        }
        // M = R⁻¹ (QᵀL⁻¹)[0..s, :], back substitution column by column.
        for c in 0..p {
            for i in (0..ud).rev() {
                let mut v = self.qtl[(i, c)];
                for k in (i + 1)..ud {
                    v -= self.w[(i, k)] * self.mq[(k, c)];
                }
                self.mq[(i, c)] = v / self.w[(i, i)];
            }
        }
        // The unknown-input gain Γ = E − P̄CᵀΣ̄⁻¹CE = E − K CE, eq. (24c) (the 2021
        // paper's Γ, not the 2014 fault signature); K̄ = K + ΓΞ⁻¹EᵀCᵀΣ̄⁻¹ = K + ΓM,
        // eq. (24g) (Λ = ΓΞ⁻¹, eq. (24e), is not formed).
        self.unknown_input_gain.copy_from(&self.e_prev);
        mul(
            -1.0,
            &self.kbar,
            false,
            &self.ce,
            false,
            1.0,
            &mut self.unknown_input_gain,
        );
        debug_assert_eq!(self.unknown_input_gain.shape(), (n, ud));
        mul(
            1.0,
            &self.unknown_input_gain,
            false,
            &self.mq,
            false,
            1.0,
            &mut self.kbar,
        );
        Ok(())
    }

    fn measure(
        &mut self,
        s: &ResidualSample<'_>,
        out: &mut ResidualRow,
    ) -> Result<(), SparseError> {
        let (n, p, l) = (self.n, self.p, s.sys.g.ncols());
        let sys = s.sys;
        self.gain(sys)?;
        // From here on nothing fails.
        self.residual_rank = if self.ud > 0 && self.e_active {
            p - self.ud
        } else {
            p
        };
        std::mem::swap(&mut self.gain, &mut self.kbar);
        std::mem::swap(&mut self.sigma, &mut self.sigma_new);
        // ν = Y − JU − H X̂⁻ and X̂_k = X̂⁻ + K̄ν, eq. (24h)/(4g).
        self.nu.as_mut_slice().copy_from_slice(s.y);
        gemv(
            -1.0,
            sys.j.as_slice(),
            p,
            l,
            s.u,
            1.0,
            self.nu.as_mut_slice(),
        );
        gemv(
            -1.0,
            sys.h.as_slice(),
            p,
            n,
            self.x_prior.as_slice(),
            1.0,
            self.nu.as_mut_slice(),
        );
        self.x_post.copy_from(&self.x_prior);
        gemv(
            1.0,
            self.gain.as_slice(),
            n,
            p,
            self.nu.as_slice(),
            1.0,
            self.x_post.as_mut_slice(),
        );
        // I − HK̄ (p×p); residual Y − JU − HX̂_k = (I − HK̄)ν, eq. (25)/(5).
        mul(-1.0, &sys.h, false, &self.gain, false, 0.0, &mut self.ihk);
        for i in 0..p {
            self.ihk[(i, i)] += 1.0;
        }
        gemv(
            1.0,
            self.ihk.as_slice(),
            p,
            p,
            self.nu.as_slice(),
            0.0,
            out.residual.as_mut_slice(),
        );
        // S = HΥ⁻ + Φ; Υ_k = Υ⁻ − K̄S = (I − K̄H)Υ⁻ − K̄Φ, eq. (27b)/(7b);
        // Υ_k^r = (I − HK̄)S = HΥ_k + Φ.
        mul(
            1.0,
            &sys.h,
            false,
            &self.ups_prior,
            false,
            0.0,
            &mut self.s_pm,
        );
        if let Some(phi) = s.phi {
            self.s_pm += phi;
        }
        self.ups_post.copy_from(&self.ups_prior);
        mul(
            -1.0,
            &self.gain,
            false,
            &self.s_pm,
            false,
            1.0,
            &mut self.ups_post,
        );
        mul(
            1.0,
            &self.ihk,
            false,
            &self.s_pm,
            false,
            0.0,
            &mut out.upsilon,
        );
        // P̄_{k|k} in Joseph form (I − K̄H)P̄⁻(I − K̄H)ᵀ + K̄RK̄ᵀ: algebraically equal to
        // eq. (24f) for the Kitanidis gain (and to (4d) for the Kalman gain).
        mul(-1.0, &self.gain, false, &sys.h, false, 0.0, &mut self.ikh);
        for i in 0..n {
            self.ikh[(i, i)] += 1.0;
        }
        mul(
            1.0,
            &self.ikh,
            false,
            &self.p_prior,
            false,
            0.0,
            &mut self.tmp_nn,
        );
        mul(
            1.0,
            &self.tmp_nn,
            false,
            &self.ikh,
            true,
            0.0,
            &mut self.p_post,
        );
        mul(1.0, &self.gain, false, &sys.r, false, 0.0, &mut self.tmp_np);
        mul(
            1.0,
            &self.tmp_np,
            false,
            &self.gain,
            true,
            1.0,
            &mut self.p_post,
        );
        symmetrize(self.p_post.as_mut_slice(), n);
        // Covariance of the fault-free residual: (I − HK̄)Σ̄(I − HK̄)ᵀ.
        mul(
            1.0,
            &self.ihk,
            false,
            &self.sigma,
            false,
            0.0,
            &mut self.tmp_pp,
        );
        mul(
            1.0,
            &self.tmp_pp,
            false,
            &self.ihk,
            true,
            0.0,
            &mut self.residual_cov,
        );
        symmetrize(self.residual_cov.as_mut_slice(), p);
        Ok(())
    }

    /// X̂⁻ = F X̂ + G U, P̄⁻ = F P̄ Fᵀ + Q (eq. (24a)), Υ⁻ = F Υ + Ψ, E_prev = E.
    fn propagate(&mut self, s: &ResidualSample<'_>, e: Option<&DMatrix<f64>>) {
        let (n, l) = (self.n, s.sys.g.ncols());
        let sys = s.sys;
        gemv(
            1.0,
            sys.f.as_slice(),
            n,
            n,
            self.x_post.as_slice(),
            0.0,
            self.x_prior.as_mut_slice(),
        );
        gemv(
            1.0,
            sys.g.as_slice(),
            n,
            l,
            s.u,
            1.0,
            self.x_prior.as_mut_slice(),
        );
        mul(
            1.0,
            &sys.f,
            false,
            &self.p_post,
            false,
            0.0,
            &mut self.tmp_nn,
        );
        self.p_prior.copy_from(&sys.q);
        mul(
            1.0,
            &self.tmp_nn,
            false,
            &sys.f,
            true,
            1.0,
            &mut self.p_prior,
        );
        symmetrize(self.p_prior.as_mut_slice(), n);
        self.ups_prior.copy_from(s.psi);
        mul(
            1.0,
            &sys.f,
            false,
            &self.ups_post,
            false,
            1.0,
            &mut self.ups_prior,
        );
        if let Some(e) = e {
            self.e_prev.copy_from(e);
            self.e_active = self.ud > 0;
        }
    }
}

/// C = α·op(A)·op(B) + β·C on nalgebra matrices, allocation-free (shapes are checked
/// by the callers).
#[allow(clippy::too_many_arguments)]
fn mul(
    alpha: f64,
    a: &DMatrix<f64>,
    ta: bool,
    b: &DMatrix<f64>,
    tb: bool,
    beta: f64,
    c: &mut DMatrix<f64>,
) {
    gemm(
        alpha,
        a.as_slice(),
        a.shape(),
        ta,
        b.as_slice(),
        b.shape(),
        tb,
        beta,
        c.as_mut_slice(),
    );
}

/// Householder QR of `w` (p×q, p ≥ q) in place: on exit its upper triangle holds R
/// (below the diagonal is garbage) and `b` (p×c) is replaced by QᵀB.
fn householder_qr_apply(w: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
    let (p, ud) = w.shape();
    for j in 0..ud.min(p) {
        let norm = (j..p).map(|i| w[(i, j)] * w[(i, j)]).sum::<f64>().sqrt();
        if norm == 0.0 {
            continue;
        }
        let alpha = if w[(j, j)] > 0.0 { -norm } else { norm };
        // v = x − αe_1 stored in column j from row j on; vᵀv = 2(norm² − αx_0).
        let x0 = w[(j, j)];
        w[(j, j)] = x0 - alpha;
        let vtv = 2.0 * (norm * norm - alpha * x0);
        if vtv == 0.0 {
            w[(j, j)] = alpha;
            continue;
        }
        for c in (j + 1)..ud {
            let dot: f64 = (j..p).map(|i| w[(i, j)] * w[(i, c)]).sum();
            let f = 2.0 * dot / vtv;
            for i in j..p {
                let vij = w[(i, j)];
                w[(i, c)] -= f * vij;
            }
        }
        for c in 0..b.ncols() {
            let dot: f64 = (j..p).map(|i| w[(i, j)] * b[(i, c)]).sum();
            let f = 2.0 * dot / vtv;
            for i in j..p {
                let vij = w[(i, j)];
                b[(i, c)] -= f * vij;
            }
        }
        w[(j, j)] = alpha;
    }
}

/// Residual generator of Zhang 2021, §III-A: the Kalman filter (eqs. (4a)-(4g))
/// designed for θ = 0, its updated output error r_k = ỹ_{k|k} = Y_k − J_kU_k −
/// H_kX̂_{k|k} (eq. (5)) and the residual signature Υ_k^r = H_kΥ_k (+ Φ_k) with
/// Υ_k from eq. (7) (Prop. 1: ỹ_{k|k} = C_kΥ_kθ + ỹ⁰_{k|k}, eq. (6)).
///
/// State faults Ψ_kθ (the paper's Φ_kθ) follow the paper; output faults Φ_kθ are an
/// extension derived in the [module documentation](self). There is no unknown input:
/// use [`KitanidisResidual`] for E_kd_k.
///
/// Covariance of the fault-free residual (not in the paper, derived here): ỹ_{k|k} =
/// (I − H_kK_k)ε_k with ε_k the innovation, so it is white with covariance
/// R_kΣ_k⁻¹R_k = (I − H_kK_k)Σ_k(I − H_kK_k)ᵀ ([`KalmanResidual::residual_covariance`]).
#[derive(Debug, Clone)]
pub struct KalmanResidual {
    filter: UpdatedFilter,
}

impl KalmanResidual {
    /// A filter for `outputs` outputs and `faults` faults, started from the prior
    /// X̂_{0|−1} = `x0`, P_{0|−1} = `p0` of the first sample's state (the paper's
    /// x̄_0, P̄_0, Assumption (ii)), with Υ_{0|−1} = 0 (eq. (7a)).
    ///
    /// # Errors
    /// [`SparseError::Dimension`] when P_0 is not n×n or n or p is 0,
    /// [`SparseError::NonFinite`] for NaN/Inf, [`SparseError::Setting`] when P_0 is not
    /// symmetric.
    pub fn new(
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        outputs: usize,
        faults: usize,
    ) -> Result<Self, SparseError> {
        Ok(Self {
            filter: UpdatedFilter::new(x0, p0, outputs, faults, 0)?,
        })
    }

    /// Processes sample k: measurement update (eqs. (4b)-(4d), (4g)), residual
    /// ỹ_{k|k} (eq. (5)) and Υ_k (eq. (7b)) written into `out`, then the time update
    /// with this sample's F_k, G_kU_k, Q_k and Ψ_k (eqs. (4a), (4e)). Allocation-free.
    ///
    /// # Errors
    /// [`SparseError::Dimension`] / [`SparseError::NonFinite`] for a malformed sample
    /// or output row, [`SparseError::Numerical`] when Σ_k is not positive definite.
    /// The filter and `out` are unchanged then.
    pub fn step(
        &mut self,
        s: &ResidualSample<'_>,
        out: &mut ResidualRow,
    ) -> Result<(), SparseError> {
        self.filter.step(s, None, out)
    }

    /// X̂_{k|k}, the updated state estimate of the last sample.
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.filter.x_post
    }

    /// P_{k|k}, its error covariance (eq. (4d), Joseph form).
    #[must_use]
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.filter.p_post
    }

    /// K_k (n×p), eq. (4c).
    #[must_use]
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.filter.gain
    }

    /// Σ_k = H_kP_{k|k−1}H_kᵀ + R_k, eq. (4b).
    #[must_use]
    pub fn innovation_covariance(&self) -> &DMatrix<f64> {
        &self.filter.sigma
    }

    /// Υ_k (n×m), eq. (7): the sensitivity of the state-estimation error X_k −
    /// X̂_{k|k} to θ.
    #[must_use]
    pub fn upsilon_state(&self) -> &DMatrix<f64> {
        &self.filter.ups_post
    }

    /// Covariance of the fault-free residual ỹ⁰_{k|k}: R_kΣ_k⁻¹R_k, computed as
    /// (I − H_kK_k)Σ_k(I − H_kK_k)ᵀ (derived here; not in the paper). The residual
    /// sequence is white, so its pseudo-inverse is the weight that whitens the
    /// regression ([`crate::sparse::GramAccumulator::push_weighted`]).
    #[must_use]
    pub fn residual_covariance(&self) -> &DMatrix<f64> {
        &self.filter.residual_cov
    }

    /// Rank of [`KalmanResidual::residual_covariance`]: p (for [`residual_weight`]).
    #[must_use]
    pub fn residual_rank(&self) -> usize {
        self.filter.residual_rank
    }
}

/// Residual generator of Zhang 2021, §III-B: the Kitanidis filter (eqs. (24a)-(24h))
/// designed for θ = 0, which rejects the unknown input E_kd_k, its output error
/// r_k = ỹ_k = Y_k − J_kU_k − H_kX̂_k (eq. (25)) and the residual signature Υ_k^r =
/// H_kΥ̃_k (+ Φ_k) with Υ̃_k from eq. (27) (Prop. 2: ỹ_k = C_kΥ̃_kθ + ỹ⁰_k, eq. (26)).
/// The residual does not depend on d_k at all: the gain satisfies
/// (I − K̄_{k+1}C_{k+1})E_k = 0 (eq. (30)).
///
/// The 2021 paper's Γ_{k+1} of eq. (24c) (an n×s gain term, not the 2014 fault
/// signature) is called the *unknown-input gain* here; it is not exposed.
///
/// Requires Assumption (iv) at every step: H_{k+1}E_k of full column rank (checked,
/// see [`unknown_input_rank`]). With s = 0 unknown inputs the filter is the Kalman
/// filter of [`KalmanResidual`].
///
/// Covariance of the fault-free residual (not in the paper, derived here): ỹ_k =
/// (I − H_kK̄_k)(H_kε̄_k + V_k) with ε̄_k the state prediction error without the
/// unknown input, so it is (I − H_kK̄_k)Σ̄_k(I − H_kK̄_k)ᵀ, *singular* of rank p − s
/// (the s directions H_kE_{k−1} are spent on estimating d). The residual sequence is
/// white (Cov(X̃_k, ỹ_k) = 0 because (I − H_kK̄_k)H_kE_{k−1} = 0), and the residual
/// signature lies in the same range, so the pseudo-inverse of this covariance is the
/// whitening weight ([`crate::sparse::GramAccumulator::push_weighted`]). The paper
/// itself uses the unweighted regression.
///
/// # Examples
/// ```
/// use glrmon_core::sparse::residual::{KitanidisResidual, ResidualRow, ResidualSample};
/// use glrmon_core::model::{Dims, SystemMatrices};
/// use glrmon_core::sparse::GramAccumulator;
/// use nalgebra::{DMatrix, DVector};
/// let dims = Dims { states: 3, inputs: 0, outputs: 2, signals: 0 };
/// let mut sys = SystemMatrices::zeros(dims);
/// sys.f = DMatrix::from_row_slice(3, 3, &[-0.8, 0.7, 0.0, -0.6, 0.0, 0.1, 0.0, -0.5, -0.4]);
/// sys.h = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
/// sys.q = DMatrix::identity(3, 3);
/// sys.r = DMatrix::identity(2, 2) * 0.5;
/// let e = DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0]);
/// let psi = DMatrix::from_element(3, 4, 1.0); // Ψ_k: 4 candidate state faults
/// let mut filter =
///     KitanidisResidual::new(DVector::zeros(3), DMatrix::identity(3, 3), 2, 4, 1).unwrap();
/// let mut row = ResidualRow::zeros(2, 4);
/// let mut gram = GramAccumulator::new(4);
/// for _ in 0..10 {
///     let s = ResidualSample { sys: &sys, u: &[], y: &[0.1, -0.2], psi: &psi, phi: None };
///     filter.step(&s, &e, &mut row).unwrap();
///     gram.push(&row.upsilon, &row.residual).unwrap();
/// }
/// assert_eq!(gram.samples(), 10);
/// ```
#[derive(Debug, Clone)]
pub struct KitanidisResidual {
    filter: UpdatedFilter,
}

impl KitanidisResidual {
    /// A filter for `outputs` outputs, `faults` faults and `unknown_inputs` (s)
    /// unknown-input directions, started from the prior X̂_{0|−1} = `x0`, P̄_{0|−1} =
    /// `p0` of the first sample's state, with Υ̃ = 0 (eq. (27a)).
    ///
    /// # Errors
    /// As [`KalmanResidual::new`], and [`SparseError::UnknownInputRank`] when s > p
    /// (Assumption (iv) cannot hold).
    pub fn new(
        x0: DVector<f64>,
        p0: DMatrix<f64>,
        outputs: usize,
        faults: usize,
        unknown_inputs: usize,
    ) -> Result<Self, SparseError> {
        Ok(Self {
            filter: UpdatedFilter::new(x0, p0, outputs, faults, unknown_inputs)?,
        })
    }

    /// Processes sample k with the unknown-input matrix E_k (n×s; it enters X_{k+1},
    /// so it shapes the gain of the *next* sample). Measurement update with
    /// Σ̄_k, Γ, Ξ, K̄_k from H_k and the stored E_{k−1} (eqs. (24b)-(24g)), X̂_k
    /// (eq. (24h)), residual ỹ_k (eq. (25)) and residual signature from Υ̃_k (eq.
    /// (27b)) into `out`; then propagation with F_k, G_kU_k, Q_k, Ψ_k, E_k (eq. (24a)).
    /// The first sample has no preceding unknown input and gets a Kalman update.
    /// Allocation-free.
    ///
    /// # Errors
    /// [`SparseError::UnknownInputRank`] when H_kE_{k−1} is not of full column rank
    /// (Assumption (iv)), [`SparseError::Numerical`] when Σ̄_k is not positive
    /// definite, [`SparseError::Dimension`] / [`SparseError::NonFinite`] for a
    /// malformed sample, E_k or output row. The filter and `out` are unchanged then.
    /// A rank failure is reported one call after the offending E_{k−1} was passed
    /// (the check needs H_k) and repeats if the same sample is retried: the filter
    /// cannot pass it. For a constant E and H, call [`unknown_input_rank`] once
    /// before running.
    pub fn step(
        &mut self,
        s: &ResidualSample<'_>,
        e: &DMatrix<f64>,
        out: &mut ResidualRow,
    ) -> Result<(), SparseError> {
        self.filter.step(s, Some(e), out)
    }

    /// X̂_k, the state estimate of the last sample (eq. (24h)).
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.filter.x_post
    }

    /// P̄_{k|k}, its error covariance (eq. (24f), computed in Joseph form).
    #[must_use]
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.filter.p_post
    }

    /// K̄_k (n×p), eq. (24g).
    #[must_use]
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.filter.gain
    }

    /// Σ̄_k = H_kP̄_{k|k−1}H_kᵀ + R_k, eq. (24b).
    #[must_use]
    pub fn innovation_covariance(&self) -> &DMatrix<f64> {
        &self.filter.sigma
    }

    /// Υ̃_k (n×m), eq. (27): the sensitivity of the state-estimation error X_k − X̂_k
    /// to θ.
    #[must_use]
    pub fn upsilon_state(&self) -> &DMatrix<f64> {
        &self.filter.ups_post
    }

    /// Covariance of the fault-free residual ỹ⁰_k, (I − H_kK̄_k)Σ̄_k(I − H_kK̄_k)ᵀ,
    /// of rank p − s after the first sample (derived here; not in the paper).
    #[must_use]
    pub fn residual_covariance(&self) -> &DMatrix<f64> {
        &self.filter.residual_cov
    }

    /// Rank of [`KitanidisResidual::residual_covariance`]: p − s when an unknown input
    /// preceded the last sample, p at the first sample (for [`residual_weight`]).
    #[must_use]
    pub fn residual_rank(&self) -> usize {
        self.filter.residual_rank
    }
}

/// The weight W_k that whitens a regression row for
/// [`crate::sparse::GramAccumulator::push_weighted`]: the Moore-Penrose pseudo-inverse
/// of a residual covariance (symmetric positive semi-definite, p×p) of known `rank`,
/// keeping its `rank` largest eigenvalues. The rank is structural — p for the Kalman
/// residual, p − s for the Kitanidis residual (`residual_rank()` of either filter) —
/// so no tolerance decides which eigenvalues are rounding noise. Not in Zhang 2021,
/// whose regression is unweighted. Allocates (p×p).
///
/// # Errors
/// [`SparseError::Dimension`] when `cov` is not square or `rank` exceeds p,
/// [`SparseError::NonFinite`] for NaN/Inf, [`SparseError::Numerical`] when one of the
/// `rank` largest eigenvalues is not positive (below 100·p·ε·λ_max: rounding noise, the
/// rank is wrong).
pub fn residual_weight(cov: &DMatrix<f64>, rank: usize) -> Result<DMatrix<f64>, SparseError> {
    let p = cov.nrows();
    if cov.ncols() != p || rank > p {
        return Err(SparseError::Dimension {
            what: "residual covariance",
            detail: format!(
                "it is {}×{} with rank {rank}: expected square with rank ≤ its size",
                p,
                cov.ncols()
            ),
        });
    }
    if cov.iter().any(|v| !v.is_finite()) {
        return Err(SparseError::NonFinite {
            what: "residual covariance",
        });
    }
    let sym = (cov + cov.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let top = order.first().map_or(0.0, |&i| eig.eigenvalues[i]);
    let floor = 100.0 * p as f64 * f64::EPSILON * top;
    let mut w = DMatrix::zeros(p, p);
    for &i in order.iter().take(rank) {
        let ev = eig.eigenvalues[i];
        if ev.is_nan() || ev <= floor || ev <= 0.0 {
            return Err(SparseError::Numerical {
                what: "the residual covariance has fewer positive eigenvalues than its rank",
            });
        }
        let v = eig.eigenvectors.column(i);
        w.ger(1.0 / ev, &v, &v, 1.0);
    }
    Ok(w)
}

#[cfg(test)]
// The tests walk parallel per-sample vectors (systems, noises, outputs) by index.
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;
    use crate::model::Dims;
    use crate::sparse::test_rng::Rng;
    use crate::sparse::{GramAccumulator, LassoSettings, diagnose};

    /// A random time-varying system with its unknown-input matrices and fault matrices.
    struct Scenario {
        sys: Vec<SystemMatrices>,
        e: Vec<DMatrix<f64>>,
        psi: Vec<DMatrix<f64>>,
        phi: Vec<DMatrix<f64>>,
        u: Vec<DVector<f64>>,
        x0_mean: DVector<f64>,
        p0: DMatrix<f64>,
    }

    fn spd(rng: &mut Rng, n: usize, floor: f64) -> DMatrix<f64> {
        let a = rng.matrix(n, n) * 0.5;
        &a * a.transpose() + DMatrix::identity(n, n) * floor
    }

    fn scenario(rng: &mut Rng, dims: Dims, ud: usize, m: usize, steps: usize) -> Scenario {
        let (n, l, p) = (dims.states, dims.inputs, dims.outputs);
        let mut sc = Scenario {
            sys: Vec::new(),
            e: Vec::new(),
            psi: Vec::new(),
            phi: Vec::new(),
            u: Vec::new(),
            x0_mean: DVector::from_fn(n, |_, _| rng.normal()),
            p0: spd(rng, n, 0.2),
        };
        let e_const = rng.matrix(n, ud);
        for k in 0..steps {
            let mut s = SystemMatrices::zeros(dims);
            s.f = rng.matrix(n, n) * (0.8 / (n as f64).sqrt());
            s.g = rng.matrix(n, l);
            s.h = rng.matrix(p, n);
            s.j = rng.matrix(p, l);
            s.q = spd(rng, n, 0.1);
            s.r = spd(rng, p, 0.1);
            sc.sys.push(s);
            // E alternates between a constant matrix and fresh random ones.
            sc.e.push(if k % 2 == 0 {
                e_const.clone()
            } else {
                rng.matrix(n, ud)
            });
            sc.psi.push(rng.matrix(n, m));
            sc.phi.push(rng.matrix(p, m));
            sc.u.push(DVector::from_fn(l, |_, _| rng.normal()));
        }
        sc
    }

    /// Noise realisation: x0 − x̄0, w_k, v_k.
    struct Noise {
        x0: DVector<f64>,
        w: Vec<DVector<f64>>,
        v: Vec<DVector<f64>>,
    }

    fn noise(rng: &mut Rng, sc: &Scenario) -> Noise {
        let draw = |rng: &mut Rng, cov: &DMatrix<f64>| {
            let l = cov.clone().cholesky().unwrap().l();
            &l * DVector::from_fn(cov.nrows(), |_, _| rng.normal())
        };
        Noise {
            x0: draw(rng, &sc.p0),
            w: sc.sys.iter().map(|s| draw(rng, &s.q)).collect(),
            v: sc.sys.iter().map(|s| draw(rng, &s.r)).collect(),
        }
    }

    /// Simulates eq. (1) (+ output faults): returns Y_k.
    fn simulate(
        sc: &Scenario,
        nz: &Noise,
        d: &[DVector<f64>],
        theta: &DVector<f64>,
        output_faults: bool,
    ) -> Vec<DVector<f64>> {
        let mut x = &sc.x0_mean + &nz.x0;
        let mut ys = Vec::new();
        for k in 0..sc.sys.len() {
            let s = &sc.sys[k];
            let mut y = &s.h * &x + &s.j * &sc.u[k] + &nz.v[k];
            if output_faults {
                y += &sc.phi[k] * theta;
            }
            ys.push(y);
            x = &s.f * &x + &s.g * &sc.u[k] + &sc.e[k] * &d[k] + &nz.w[k] + &sc.psi[k] * theta;
        }
        ys
    }

    /// Runs a filter over the outputs; returns the rows (residual, signature).
    fn run(
        sc: &Scenario,
        ys: &[DVector<f64>],
        kitanidis: Option<usize>,
        output_faults: bool,
    ) -> Vec<ResidualRow> {
        let (p, m) = (sc.phi[0].nrows(), sc.phi[0].ncols());
        let mut kal = KalmanResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m).unwrap();
        let mut kit = kitanidis
            .map(|ud| KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m, ud).unwrap());
        let mut rows = Vec::new();
        for k in 0..ys.len() {
            let s = ResidualSample {
                sys: &sc.sys[k],
                u: sc.u[k].as_slice(),
                y: ys[k].as_slice(),
                psi: &sc.psi[k],
                phi: output_faults.then_some(&sc.phi[k]),
            };
            let mut row = ResidualRow::zeros(p, m);
            match kit.as_mut() {
                Some(f) => f.step(&s, &sc.e[k], &mut row).unwrap(),
                None => kal.step(&s, &mut row).unwrap(),
            }
            rows.push(row);
        }
        rows
    }

    fn dims(n: usize, l: usize, p: usize) -> Dims {
        Dims {
            states: n,
            inputs: l,
            outputs: p,
            signals: 0,
        }
    }

    #[test]
    fn unknown_input_rank_accepts_full_and_rejects_deficient() {
        let mut rng = Rng::new(1);
        let c = rng.matrix(3, 4);
        let e = rng.matrix(4, 2);
        assert_eq!(unknown_input_rank(&c, &e), Ok(()));
        // Two collinear unknown-input directions.
        let mut e2 = e.clone();
        let c0 = e2.column(0) * 2.0;
        e2.set_column(1, &c0);
        let err = unknown_input_rank(&c, &e2).unwrap_err();
        match &err {
            SparseError::UnknownInputRank {
                outputs: 3,
                unknown_inputs: 2,
                rank: 1,
                ratio,
            } => assert!(*ratio < 1e-9),
            other => panic!("{other:?}"),
        }
        let msg = err.to_string();
        assert!(msg.contains("Assumption (iv)"), "{msg}");
        assert!(msg.contains("rank 1, not full column rank 2"), "{msg}");
        // More unknown inputs than outputs.
        let err = unknown_input_rank(&c, &rng.matrix(4, 4)).unwrap_err();
        assert!(
            matches!(err, SparseError::UnknownInputRank { rank: 3, .. }),
            "{err:?}"
        );
        // E in the kernel of C.
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        assert!(matches!(
            unknown_input_rank(&c, &e),
            Err(SparseError::UnknownInputRank { rank: 0, .. })
        ));
        // Ill-conditioned but within the limit, and beyond it.
        let c = DMatrix::identity(2, 2);
        let e = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1e-8]);
        assert_eq!(unknown_input_rank(&c, &e), Ok(()));
        let e = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1e-11]);
        assert!(unknown_input_rank(&c, &e).is_err());
        assert!(matches!(
            unknown_input_rank(&c, &DMatrix::zeros(3, 1)),
            Err(SparseError::Dimension { .. })
        ));
        // Singular values match nalgebra's SVD.
        let a = rng.matrix(5, 3);
        let mut work = a.clone();
        let mut sv = [0.0; 3];
        singular_values_in_place(work.as_mut_slice(), 5, 3, &mut sv);
        sv.sort_by(|x, y| y.total_cmp(x));
        let want = a.singular_values();
        for (x, y) in sv.iter().zip(want.iter()) {
            assert!((x - y).abs() < 1e-13 * want[0]);
        }
    }

    /// Eq. (30): (I − K̄_{k+1}C_{k+1})E_k = 0 at every step of random time-varying
    /// systems (s = 1, 2, 3 unknown inputs).
    #[test]
    fn kitanidis_gain_annihilates_the_unknown_input() {
        let mut rng = Rng::new(30);
        for (n, p, ud) in [(4, 3, 1), (5, 3, 2), (6, 4, 3), (3, 2, 2)] {
            let sc = scenario(&mut rng, dims(n, 1, p), ud, 3, 40);
            let nz = noise(&mut rng, &sc);
            let d: Vec<_> = (0..40)
                .map(|_| DVector::from_fn(ud, |_, _| 50.0 * rng.normal()))
                .collect();
            let ys = simulate(&sc, &nz, &d, &DVector::zeros(3), false);
            let mut f =
                KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, 3, ud).unwrap();
            let mut row = ResidualRow::zeros(p, 3);
            for k in 0..40 {
                let s = ResidualSample {
                    sys: &sc.sys[k],
                    u: sc.u[k].as_slice(),
                    y: ys[k].as_slice(),
                    psi: &sc.psi[k],
                    phi: None,
                };
                f.step(&s, &sc.e[k], &mut row).unwrap();
                if k > 0 {
                    let ikc = DMatrix::identity(n, n) - f.gain() * &sc.sys[k].h;
                    let res = (&ikc * &sc.e[k - 1]).amax();
                    assert!(
                        res < 1e-12 * sc.e[k - 1].amax(),
                        "(n,p,ud)=({n},{p},{ud}) k={k}: {res:e}"
                    );
                    // And the residual covariance has rank p − s: its s smallest
                    // eigenvalues are rounding noise.
                    assert_eq!(f.residual_rank(), p - ud);
                    let mut ev: Vec<f64> = f
                        .residual_covariance()
                        .clone()
                        .symmetric_eigen()
                        .eigenvalues
                        .iter()
                        .copied()
                        .collect();
                    ev.sort_by(f64::total_cmp);
                    let big = f.innovation_covariance().amax();
                    assert!(ev[..ud].iter().all(|v| v.abs() < 1e-12 * big), "{ev:?}");
                    assert!(ev[ud..].iter().all(|&v| v > 1e-6 * big), "{ev:?}");
                }
            }
        }
    }

    /// One step against eqs. (24a)-(24h) written with nalgebra's operators and explicit
    /// inverses, including (24f) for the covariance (computed in Joseph form).
    #[test]
    fn one_step_matches_equations_24a_to_24h() {
        let mut rng = Rng::new(24);
        let (n, p, ud, m) = (4, 3, 2, 2);
        let sc = scenario(&mut rng, dims(n, 1, p), ud, m, 3);
        let y0 = DVector::from_fn(p, |_, _| rng.normal());
        let y1 = DVector::from_fn(p, |_, _| rng.normal());
        let mut f = KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m, ud).unwrap();
        let mut row = ResidualRow::zeros(p, m);
        let sample = |k: usize, y: &DVector<f64>| {
            (
                sc.sys[k].clone(),
                sc.u[k].clone(),
                y.clone(),
                sc.psi[k].clone(),
            )
        };
        let (s0, u0, yy0, psi0) = sample(0, &y0);
        f.step(
            &ResidualSample {
                sys: &s0,
                u: u0.as_slice(),
                y: yy0.as_slice(),
                psi: &psi0,
                phi: None,
            },
            &sc.e[0],
            &mut row,
        )
        .unwrap();
        let x_k = f.state().clone();
        let p_k = f.covariance().clone();
        let ups_k = f.upsilon_state().clone();
        let (s1, u1, yy1, psi1) = sample(1, &y1);
        f.step(
            &ResidualSample {
                sys: &s1,
                u: u1.as_slice(),
                y: yy1.as_slice(),
                psi: &psi1,
                phi: None,
            },
            &sc.e[1],
            &mut row,
        )
        .unwrap();
        // Reference, k → k + 1 with A = F_0, B = G_0, E = E_0, C = H_1.
        let (a, b, e, c) = (&s0.f, &s0.g, &sc.e[0], &s1.h);
        let pp = a * &p_k * a.transpose() + &s0.q; // (24a)
        let sig = c * &pp * c.transpose() + &s1.r; // (24b)
        let si = sig.clone().try_inverse().unwrap();
        let gam = e - &pp * c.transpose() * &si * c * e; // (24c)
        let xi = e.transpose() * c.transpose() * &si * c * e; // (24d)
        let xii = xi.clone().try_inverse().unwrap();
        let lam = &gam * &xii; // (24e)
        let pk1 = &pp - &pp * c.transpose() * &si * c * &pp + &lam * &xi * lam.transpose(); // (24f)
        let kb = &pp * c.transpose() * &si + &gam * &xii * e.transpose() * c.transpose() * &si; // (24g)
        let xpred = a * &x_k + b * &u0;
        let innov = &y1 - &s1.j * &u1 - c * &xpred;
        let x1 = &xpred + &kb * &innov; // (24h)
        let resid = &y1 - &s1.j * &u1 - c * &x1; // (25)
        let ikc = DMatrix::identity(n, n) - &kb * c;
        let ups1 = &ikc * a * &ups_k + &ikc * &psi0; // (27b)
        let scale = pk1.amax();
        assert!((f.gain() - &kb).amax() < 1e-12 * kb.amax(), "K̄");
        assert!((f.covariance() - &pk1).amax() < 1e-12 * scale, "P̄ (24f)");
        assert!((f.innovation_covariance() - &sig).amax() < 1e-12 * sig.amax());
        assert!((f.state() - &x1).amax() < 1e-12 * x1.amax().max(1.0));
        assert!((&row.residual - &resid).amax() < 1e-12 * resid.amax().max(1.0));
        assert!((f.upsilon_state() - &ups1).amax() < 1e-12 * ups1.amax());
        assert!((&row.upsilon - c * &ups1).amax() < 1e-12 * ups1.amax());
        let ihk = DMatrix::identity(p, p) - c * &kb;
        let rc = &ihk * &sig * ihk.transpose();
        assert!((f.residual_covariance() - &rc).amax() < 1e-12 * sig.amax());
    }

    /// Prop. 2 (eq. (26)): residual(θ) − residual(0) = Υ_k^rθ for the same noise and
    /// unknown input, with state faults (the paper) and with output faults too (the
    /// extension); and changing d_k leaves the residual unchanged.
    #[test]
    fn kitanidis_prop2_fault_effect_is_upsilon_theta_and_d_has_no_effect() {
        let mut rng = Rng::new(26);
        for (n, p, ud, output_faults) in [(4, 3, 1, false), (5, 3, 2, true), (3, 2, 1, true)] {
            let (m, steps) = (6, 60);
            let sc = scenario(&mut rng, dims(n, 2, p), ud, m, steps);
            let nz = noise(&mut rng, &sc);
            let d: Vec<_> = (0..steps)
                .map(|k| {
                    DVector::from_fn(ud, |_, _| {
                        100.0 + 10.0 * (0.1 * k as f64).sin() + rng.normal()
                    })
                })
                .collect();
            let d2: Vec<_> = (0..steps)
                .map(|_| DVector::from_fn(ud, |_, _| 1e3 * rng.normal()))
                .collect();
            let theta = DVector::from_fn(m, |j, _| if j % 3 == 0 { 1.0 + j as f64 } else { 0.0 });
            let zero = DVector::zeros(m);
            let free = run(
                &sc,
                &simulate(&sc, &nz, &d, &zero, output_faults),
                Some(ud),
                output_faults,
            );
            let faulty = run(
                &sc,
                &simulate(&sc, &nz, &d, &theta, output_faults),
                Some(ud),
                output_faults,
            );
            let other_d = run(
                &sc,
                &simulate(&sc, &nz, &d2, &theta, output_faults),
                Some(ud),
                output_faults,
            );
            for k in 0..steps {
                let effect = &faulty[k].residual - &free[k].residual;
                let predicted = &faulty[k].upsilon * &theta;
                let scale = predicted.amax().max(1.0);
                assert!(
                    (&effect - &predicted).amax() < 1e-10 * scale,
                    "k={k}: {effect} vs {predicted}"
                );
                // Υ does not depend on the data.
                assert_eq!(faulty[k].upsilon, free[k].upsilon);
                let diff = (&other_d[k].residual - &faulty[k].residual).amax();
                let size = faulty[k].residual.amax().max(1.0);
                // The first sample precedes any unknown input.
                assert!(
                    diff < 1e-9 * size,
                    "k={k}: d changed the residual by {diff:e}"
                );
            }
        }
    }

    /// Prop. 1 (eq. (6)) for the Kalman residual, state and output faults.
    #[test]
    fn kalman_prop1_fault_effect_is_upsilon_theta() {
        let mut rng = Rng::new(6);
        for (n, p, output_faults) in [(3, 1, false), (4, 2, true), (2, 3, true)] {
            let (m, steps) = (5, 60);
            let sc = scenario(&mut rng, dims(n, 1, p), 1, m, steps);
            let nz = noise(&mut rng, &sc);
            let d: Vec<_> = (0..steps).map(|_| DVector::zeros(1)).collect();
            let theta = DVector::from_fn(m, |j, _| (j as f64) - 2.0);
            let free = run(
                &sc,
                &simulate(&sc, &nz, &d, &DVector::zeros(m), output_faults),
                None,
                output_faults,
            );
            let faulty = run(
                &sc,
                &simulate(&sc, &nz, &d, &theta, output_faults),
                None,
                output_faults,
            );
            for k in 0..steps {
                let effect = &faulty[k].residual - &free[k].residual;
                let predicted = &faulty[k].upsilon * &theta;
                assert!(
                    (&effect - &predicted).amax() < 1e-10 * predicted.amax().max(1.0),
                    "k={k}"
                );
            }
        }
    }

    /// ỹ_{k|k} = R_kΣ_k⁻¹ε_k with ε_k the innovation of the existing
    /// [`InnovationFilter`](crate::filter::innovation::InnovationFilter); and with s = 0 the
    /// Kitanidis filter is this Kalman filter.
    #[test]
    fn kalman_residual_is_r_sigma_inverse_innovation_and_kitanidis_q0_is_kalman() {
        let mut rng = Rng::new(4);
        let (n, p, m, steps) = (3, 2, 2, 30);
        let sc = scenario(&mut rng, dims(n, 1, p), 0, m, steps);
        let nz = noise(&mut rng, &sc);
        let d: Vec<_> = (0..steps).map(|_| DVector::zeros(0)).collect();
        let ys = simulate(&sc, &nz, &d, &DVector::zeros(m), false);
        let mut kal = KalmanResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m).unwrap();
        let mut kit = KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m, 0).unwrap();
        let mut inn =
            crate::filter::innovation::InnovationFilter::new(sc.x0_mean.clone(), sc.p0.clone(), p)
                .unwrap();
        let (mut r1, mut r2) = (ResidualRow::zeros(p, m), ResidualRow::zeros(p, m));
        for k in 0..steps {
            let s = ResidualSample {
                sys: &sc.sys[k],
                u: sc.u[k].as_slice(),
                y: ys[k].as_slice(),
                psi: &sc.psi[k],
                phi: None,
            };
            kal.step(&s, &mut r1).unwrap();
            kit.step(&s, &sc.e[k], &mut r2).unwrap();
            inn.measure(&sc.sys[k], sc.u[k].as_slice(), ys[k].as_slice())
                .unwrap();
            let sig = inn.innovation_covariance();
            let want = &sc.sys[k].r * sig.clone().try_inverse().unwrap() * inn.innovation();
            assert!(
                (&r1.residual - &want).amax() < 1e-11 * want.amax().max(1.0),
                "k={k}"
            );
            let rsr = &sc.sys[k].r * sig.clone().try_inverse().unwrap() * &sc.sys[k].r;
            assert!((kal.residual_covariance() - &rsr).amax() < 1e-12 * rsr.amax());
            inn.time_update(&sc.sys[k], sc.u[k].as_slice());
            assert_eq!(r1, r2);
        }
    }

    /// Monte Carlo: the fault-free residual has the stated covariance and is white
    /// (lag-1 cross-covariance 0), for both filters.
    #[test]
    fn residual_covariance_and_whiteness_match_monte_carlo() {
        let mut rng = Rng::new(77);
        let (n, p, ud, m, steps) = (4, 3, 1, 1, 6);
        let sc = scenario(&mut rng, dims(n, 1, p), ud, m, steps);
        let trials = 20_000;
        for kitanidis in [None, Some(ud)] {
            let (mut s_kk, mut s_lag) = (DMatrix::zeros(p, p), DMatrix::zeros(p, p));
            let mut cov = DMatrix::zeros(p, p);
            for _ in 0..trials {
                let nz = noise(&mut rng, &sc);
                let d: Vec<_> = (0..steps)
                    .map(|_| {
                        if kitanidis.is_some() {
                            DVector::from_fn(ud, |_, _| 30.0 * rng.normal() + 5.0)
                        } else {
                            DVector::zeros(ud)
                        }
                    })
                    .collect();
                let ys = simulate(&sc, &nz, &d, &DVector::zeros(m), false);
                let (pm, mm) = (p, m);
                let mut kal =
                    KalmanResidual::new(sc.x0_mean.clone(), sc.p0.clone(), pm, mm).unwrap();
                let mut kit =
                    KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), pm, mm, ud).unwrap();
                let mut row = ResidualRow::zeros(p, m);
                let mut prev = DVector::zeros(p);
                for k in 0..steps {
                    let s = ResidualSample {
                        sys: &sc.sys[k],
                        u: sc.u[k].as_slice(),
                        y: ys[k].as_slice(),
                        psi: &sc.psi[k],
                        phi: None,
                    };
                    match kitanidis {
                        Some(_) => kit.step(&s, &sc.e[k], &mut row).unwrap(),
                        None => kal.step(&s, &mut row).unwrap(),
                    }
                    if k == steps - 2 {
                        prev = row.residual.clone();
                    }
                }
                s_kk += &row.residual * row.residual.transpose();
                s_lag += &row.residual * prev.transpose();
                cov = if kitanidis.is_some() {
                    kit.residual_covariance().clone()
                } else {
                    kal.residual_covariance().clone()
                };
            }
            let emp = s_kk / trials as f64;
            let lag = s_lag / trials as f64;
            let scale = cov.amax();
            assert!(
                (&emp - &cov).amax() < 0.05 * scale,
                "{kitanidis:?}: empirical {emp} vs {cov}"
            );
            assert!(lag.amax() < 0.05 * scale, "{kitanidis:?}: lag-1 {lag}");
        }
    }

    #[test]
    fn errors_leave_the_filter_unchanged() {
        let mut rng = Rng::new(9);
        let (n, p, ud, m) = (3, 2, 1, 2);
        let sc = scenario(&mut rng, dims(n, 1, p), ud, m, 3);
        let mut f = KitanidisResidual::new(sc.x0_mean.clone(), sc.p0.clone(), p, m, ud).unwrap();
        let mut row = ResidualRow::zeros(p, m);
        let y = [0.3, -0.1];
        let s = ResidualSample {
            sys: &sc.sys[0],
            u: sc.u[0].as_slice(),
            y: &y,
            psi: &sc.psi[0],
            phi: None,
        };
        // E in the kernel of the next H: Assumption (iv) fails at the next step.
        let mut e_bad = DMatrix::zeros(n, ud);
        let h1 = &sc.sys[1].h;
        // A null vector of the 2×3 H_1: the cross product of its rows.
        let (a, b) = (h1.row(0), h1.row(1));
        e_bad[(0, 0)] = a[1] * b[2] - a[2] * b[1];
        e_bad[(1, 0)] = a[2] * b[0] - a[0] * b[2];
        e_bad[(2, 0)] = a[0] * b[1] - a[1] * b[0];
        f.step(&s, &e_bad, &mut row).unwrap();
        let snapshot = (f.state().clone(), f.covariance().clone(), row.clone());
        let s1 = ResidualSample {
            sys: &sc.sys[1],
            ..s
        };
        let err = f.step(&s1, &sc.e[1], &mut row).unwrap_err();
        assert!(
            matches!(err, SparseError::UnknownInputRank { rank: 0, .. }),
            "{err}"
        );
        assert_eq!(
            (f.state().clone(), f.covariance().clone(), row.clone()),
            snapshot
        );
        // Malformed inputs.
        let bad_y = [1.0];
        assert!(matches!(
            f.step(&ResidualSample { y: &bad_y, ..s1 }, &sc.e[1], &mut row),
            Err(SparseError::Dimension { what: "y", .. })
        ));
        let nan_y = [f64::NAN, 0.0];
        assert!(matches!(
            f.step(&ResidualSample { y: &nan_y, ..s1 }, &sc.e[1], &mut row),
            Err(SparseError::NonFinite { what: "y" })
        ));
        assert!(matches!(
            f.step(&s1, &DMatrix::zeros(n, 2), &mut row),
            Err(SparseError::Dimension { what: "E", .. })
        ));
        let mut bad_row = ResidualRow::zeros(p, m + 1);
        assert!(f.step(&s1, &sc.e[1], &mut bad_row).is_err());
        let mut sys_bad = sc.sys[1].clone();
        sys_bad.r = -DMatrix::identity(p, p) * 100.0;
        assert!(matches!(
            f.step(
                &ResidualSample {
                    sys: &sys_bad,
                    ..s1
                },
                &sc.e[1],
                &mut row
            ),
            Err(SparseError::Numerical { .. })
        ));
        assert_eq!(
            (f.state().clone(), f.covariance().clone(), row.clone()),
            snapshot
        );
        assert!(
            KitanidisResidual::new(DVector::zeros(3), DMatrix::identity(3, 3), 2, 1, 3).is_err()
        );
    }

    /// Zhang 2021, §V, Example 1 (eqs. (40)-(42)): 50 candidate state faults with random
    /// Ψ_k (the paper's Φ_k), 5 active, unknown input d_k = 10 sin(0.1k) + ε_k + 100,
    /// N = 100; Kitanidis residuals, unweighted regression (36), Lasso + plateau λ.
    /// The paper reports 99.5 % exact isolation over 1000 trials; here 100 trials.
    #[test]
    fn paper_example_1_isolates_5_of_50_faults() {
        let mut rng = Rng::new(2021);
        let (n, p, m, q_faults, big_n) = (3, 2, 50, 5, 100);
        let c = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let e = DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0]);
        let trials = 100;
        let mut success = 0;
        let mut weighted_success = 0;
        for trial in 0..trials {
            let mut theta = DVector::zeros(m);
            let mut set = 0;
            while set < q_faults {
                let j = rng.below(m);
                if theta[j] == 0.0 {
                    theta[j] = 1.0;
                    set += 1;
                }
            }
            let mut f = KitanidisResidual::new(DVector::zeros(n), DMatrix::identity(n, n), p, m, 1)
                .unwrap();
            let mut gram = GramAccumulator::new(m);
            let mut gram_w = GramAccumulator::new(m);
            let mut row = ResidualRow::zeros(p, m);
            let mut x = DVector::from_fn(n, |_, _| rng.normal());
            let mut sys = SystemMatrices::zeros(dims(n, 0, p));
            sys.h = c.clone();
            sys.q = DMatrix::identity(n, n);
            sys.r = DMatrix::identity(p, p) * 0.5;
            for k in 0..=big_n {
                let kf = k as f64;
                sys.f = DMatrix::from_row_slice(
                    3,
                    3,
                    &[
                        -0.8,
                        0.7,
                        0.1 * (-kf).exp(),
                        -0.6,
                        0.0,
                        0.1 * kf.cos(),
                        0.1 * kf.sin(),
                        -0.5,
                        -0.4,
                    ],
                );
                let psi = DMatrix::from_fn(n, m, |_, _| 17.3 * (2.0 * rng.uniform() - 1.0));
                let y = &c * &x + DVector::from_fn(p, |_, _| 0.5f64.sqrt() * rng.normal());
                let s = ResidualSample {
                    sys: &sys,
                    u: &[],
                    y: y.as_slice(),
                    psi: &psi,
                    phi: None,
                };
                f.step(&s, &e, &mut row).unwrap();
                if k >= 1 {
                    gram.push(&row.upsilon, &row.residual).unwrap();
                    let w = residual_weight(f.residual_covariance(), f.residual_rank()).unwrap();
                    gram_w
                        .push_weighted(&row.upsilon, &row.residual, &w)
                        .unwrap();
                }
                let d = 10.0 * (0.1 * kf).sin() + rng.normal() + 100.0;
                let w = DVector::from_fn(n, |_, _| rng.normal());
                x = &sys.f * &x + &e * d + w + &psi * &theta;
            }
            let truth: Vec<usize> = (0..m).filter(|&j| theta[j] != 0.0).collect();
            let diag = diagnose(&gram, &LassoSettings::default()).unwrap();
            assert!(diag.converged, "trial {trial}");
            if diag.support == truth {
                success += 1;
                for &(j, v) in &diag.estimate {
                    assert!((v - theta[j]).abs() < 0.2, "trial {trial}: θ_{j} = {v}");
                }
            }
            let diag_w = diagnose(&gram_w, &LassoSettings::default()).unwrap();
            if diag_w.support == truth {
                weighted_success += 1;
            }
        }
        println!(
            "Example 1: exact isolation {success}/{trials} (unweighted), {weighted_success}/{trials} (whitened)"
        );
        assert!(success >= 95, "{success}/{trials}");
        assert!(weighted_success >= 95, "{weighted_success}/{trials}");
    }

    #[test]
    fn residual_weight_is_the_pseudo_inverse() {
        let mut rng = Rng::new(12);
        let a = rng.matrix(4, 2);
        let cov = &a * a.transpose();
        let w = residual_weight(&cov, 2).unwrap();
        let pinv = cov.clone().pseudo_inverse(1e-9).unwrap();
        assert!((&w - &pinv).amax() < 1e-10 * pinv.amax());
        assert!((&cov * &w * &cov - &cov).amax() < 1e-12 * cov.amax());
        assert_eq!(residual_weight(&cov, 0).unwrap(), DMatrix::zeros(4, 4));
        assert!(matches!(
            residual_weight(&cov, 3),
            Err(SparseError::Numerical { .. })
        ));
        assert!(residual_weight(&DMatrix::zeros(2, 3), 1).is_err());
        assert!(residual_weight(&cov, 5).is_err());
    }
}
