//! Decoupling an unknown input E_kd_k from the GLR's innovation (Zhang 2021, §III-B and
//! Fig. 1, with the 2014 GLR of Zhang & Basseville run on the decoupled sequence).
//!
//! The plant has an arbitrary unknown input between samples k − 1 and k:
//!
//! ```text
//! X_k = F_{k−1}X_{k−1} + G_{k−1}U_{k−1} + E_{k−1}d_{k−1} + W_{k−1} + Ψ_{k−1}θ
//! ```
//!
//! The filter predicts without d: X̂_k = F_{k−1}X̂_{k−1|k−1} + G_{k−1}U_{k−1}, so the
//! innovation ε_k = Y_k − J_kU_k − H_kX̂_k carries H_kE_{k−1}d_{k−1}. With Σ_k = L_kL_kᵀ
//! (eq. (8), without d) and the Householder factorisation
//!
//! ```text
//! L_k⁻¹H_kE_{k−1} = Q_k [R_k; 0] = Q_{1,k}R_k         (p×q, full column rank q, Assumption (iv))
//! ```
//!
//! the last p − q rows of Q_kᵀL_k⁻¹ε_k, z_k = Q_{2,k}ᵀL_k⁻¹ε_k, do not depend on d, and
//! under no fault they are N(0, I_{p−q}) and white: the updated estimate with the
//! Kitanidis gain (Zhang 2021, eqs. (24c)-(24g); Gillijns & De Moor 2007 show it is the
//! minimum-variance unbiased gain)
//!
//! ```text
//! K̄_k = P_kH_kᵀL_k⁻ᵀQ_{2,k}Q_{2,k}ᵀL_k⁻¹ + E_{k−1}R_k⁻¹Q_{1,k}ᵀL_k⁻¹,   (I − K̄_kH_k)E_{k−1} = 0
//! ```
//!
//! leaves an error orthogonal to z_k (PH ᵀ − K̄Σ)L⁻ᵀQ₂ = 0, so each z_{k+1}, a function of
//! that error and of new noise, is orthogonal to every earlier z (checked empirically in
//! the tests). The GLR of the 2014 paper then runs on z_k unchanged, with the
//! signatures of the 2021 paper's Υ̃ recursion (Prop. 2, eq. (27), with the output-fault
//! term of [`crate::sparse::residual`]) in place of Γ:
//!
//! ```text
//! Γ_{k+1}(r) = F_k(I − K̄_kH_k)Γ_k(r) + Ψ_k(r) − F_kK̄_kΦ_k(r)      (eq. (46) with K̄ for K)
//! S_k(r)     = [0; Q_{2,k}ᵀ] L_k⁻¹ (H_kΓ_k(r) + Φ_k(r))           (eq. (45), decoupled)
//! ```
//!
//! Γ_k(r) is the 2021 paper's Υ_{k|k−1}: the prediction of eq. (27a). Keeping p rows
//! (the first q zero) leaves every window pass of the GLR bank as it is; the
//! innovation's χ² law has p − q degrees of freedom.
//!
//! A state fault's component in the range of E_k is invisible (an unknown input can
//! produce it at any sample): it is removed before the Γ recursion, so
//! that a fault entirely in that range has a signature of exactly zero and is reported
//! as not detectable, instead of carrying rounding errors into the statistic.

use nalgebra::DMatrix;

use crate::error::{StepError, UNKNOWN_INPUT_RANK_TOLERANCE};
use crate::linalg::{at, gemm, solve_lower_in_place};

/// A Householder QR factorisation A = Q[R; 0] of a `rows`×`cols` matrix (rows ≥ cols),
/// kept as its reflectors, allocation-free after construction.
#[derive(Debug, Clone)]
pub(crate) struct Householder {
    rows: usize,
    cols: usize,
    /// Reflector j in column j, rows j.., and R above the diagonal (column-major).
    v: Vec<f64>,
    /// 2/vⱼᵀvⱼ per reflector (0: identity).
    tau: Vec<f64>,
    /// R's diagonal.
    diag: Vec<f64>,
}

impl Householder {
    pub(crate) fn new(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            v: vec![0.0; rows * cols],
            tau: vec![0.0; cols],
            diag: vec![0.0; cols],
        }
    }

    /// Factorises `a` (`rows`×`cols`, column-major). Returns false when a column is
    /// (numerically) in the span of the previous ones: |R_jj| ≤ tol·‖a_j‖, a test that
    /// does not depend on the columns' scales (a zero column fails).
    pub(crate) fn factor(&mut self, a: &[f64]) -> bool {
        let (p, q) = (self.rows, self.cols);
        self.v.copy_from_slice(&a[..p * q]);
        let mut full_rank = true;
        for j in 0..q {
            let column_norm = (0..p)
                .map(|i| a[at(p, i, j)] * a[at(p, i, j)])
                .sum::<f64>()
                .sqrt();
            let norm = (j..p)
                .map(|i| self.v[at(p, i, j)] * self.v[at(p, i, j)])
                .sum::<f64>()
                .sqrt();
            if norm.is_nan() || norm <= UNKNOWN_INPUT_RANK_TOLERANCE * column_norm {
                full_rank = false;
            }
            let x0 = self.v[at(p, j, j)];
            let alpha = if x0 > 0.0 { -norm } else { norm };
            self.v[at(p, j, j)] = x0 - alpha;
            let vtv = 2.0 * (norm * norm - alpha * x0);
            self.tau[j] = if vtv > 0.0 { 2.0 / vtv } else { 0.0 };
            self.diag[j] = alpha;
            for c in (j + 1)..q {
                let dot: f64 = (j..p)
                    .map(|i| self.v[at(p, i, j)] * self.v[at(p, i, c)])
                    .sum();
                let f = self.tau[j] * dot;
                for i in j..p {
                    let vij = self.v[at(p, i, j)];
                    self.v[at(p, i, c)] -= f * vij;
                }
            }
        }
        full_rank
    }

    /// x ← Qᵀx for x of `rows` entries at `stride`.
    pub(crate) fn apply_qt(&self, x: &mut [f64], stride: usize) {
        for j in 0..self.cols {
            self.reflect(j, x, stride);
        }
    }

    /// x ← Qx for x of `rows` entries at `stride`.
    pub(crate) fn apply_q(&self, x: &mut [f64], stride: usize) {
        for j in (0..self.cols).rev() {
            self.reflect(j, x, stride);
        }
    }

    #[inline(always)]
    fn reflect(&self, j: usize, x: &mut [f64], stride: usize) {
        let p = self.rows;
        let dot: f64 = (j..p).map(|i| self.v[at(p, i, j)] * x[i * stride]).sum();
        let f = self.tau[j] * dot;
        for i in j..p {
            x[i * stride] -= f * self.v[at(p, i, j)];
        }
    }

    /// x ← [0; Q₂ᵀx] (the component outside range(A) in Q's basis), or exactly zero when
    /// that component is below [`UNKNOWN_INPUT_RANK_TOLERANCE`] of ‖x‖ (x in range(A)
    /// up to rounding); `back` returns the kept component to the original basis,
    /// (I − Q₁Q₁ᵀ)x.
    fn cut_range(&self, x: &mut [f64], back: bool) {
        let before = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if before == 0.0 {
            return;
        }
        self.apply_qt(x, 1);
        x[..self.cols].fill(0.0);
        let after = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if after <= UNKNOWN_INPUT_RANK_TOLERANCE * before {
            x.fill(0.0);
        } else if back {
            self.apply_q(x, 1);
        }
    }

    /// y ← yR⁻¹ for a row y of `cols` entries at `stride` (R upper triangular).
    fn solve_right_r(&self, y: &mut [f64], stride: usize) {
        let p = self.rows;
        for j in 0..self.cols {
            let mut s = y[j * stride];
            for i in 0..j {
                s -= y[i * stride] * self.v[at(p, i, j)];
            }
            y[j * stride] = s / self.diag[j];
        }
    }
}

/// The unknown-input part of [`crate::InnovationFilter`]: E_{k−1} for the next
/// measurement, the factorisation of L_k⁻¹H_kE_{k−1}, and the projection and gain that
/// decouple d (module documentation).
#[derive(Debug, Clone)]
pub(crate) struct Decoupling {
    n: usize,
    p: usize,
    q: usize,
    /// E_{k−1}, set by the last time update (none before the first sample: no unknown
    /// input precedes it, and its update is the plain Kalman one).
    e_prev: DMatrix<f64>,
    pending: bool,
    /// The factorisation in use, and the one being built (swapped on success).
    qr: Householder,
    qr_next: Householder,
    /// Whether the last measurement was decoupled.
    applied: bool,
    /// L⁻¹HE (p×q).
    m: Vec<f64>,
}

impl Decoupling {
    pub(crate) fn new(n: usize, p: usize, q: usize) -> Self {
        Self {
            n,
            p,
            q,
            e_prev: DMatrix::zeros(n, q),
            pending: false,
            qr: Householder::new(p, q),
            qr_next: Householder::new(p, q),
            applied: false,
            m: vec![0.0; p * q],
        }
    }

    /// q, the number of unknown inputs.
    pub(crate) fn unknown_inputs(&self) -> usize {
        self.q
    }

    /// E_k, acting between this sample and the next.
    pub(crate) fn set_next(&mut self, e: &DMatrix<f64>) {
        self.e_prev.copy_from(e);
        self.pending = true;
    }

    /// Factorises L_k⁻¹H_kE_{k−1} with the new Cholesky factor `chol` (p×p) into the
    /// spare factorisation; nothing in use changes.
    ///
    /// # Errors
    /// [`StepError::Numerical`] when H_kE_{k−1} has lost full column rank (Assumption
    /// (iv) of Zhang 2021 at this sample).
    pub(crate) fn prepare(&mut self, chol: &[f64], h: &[f64]) -> Result<(), StepError> {
        if !self.pending {
            return Ok(());
        }
        let (n, p, q) = (self.n, self.p, self.q);
        gemm(
            1.0,
            h,
            (p, n),
            false,
            self.e_prev.as_slice(),
            (n, q),
            false,
            0.0,
            &mut self.m,
        );
        solve_lower_in_place(chol, p, &mut self.m, q);
        if !self.qr_next.factor(&self.m) {
            return Err(StepError::Numerical {
                what: "H_k·E_{k−1} does not have full column rank at this sample: the unknown \
                       input cannot be decoupled (Assumption (iv) of Zhang 2021)",
            });
        }
        Ok(())
    }

    /// Makes the factorisation of [`Decoupling::prepare`] the one in use.
    pub(crate) fn commit(&mut self) {
        self.applied = self.pending;
        if self.applied {
            std::mem::swap(&mut self.qr, &mut self.qr_next);
        }
    }

    /// Whether the last measurement was decoupled (p − q degrees of freedom).
    pub(crate) fn applied(&self) -> bool {
        self.applied
    }

    /// Each of the `cols` columns x (p entries, already multiplied by L⁻¹) becomes
    /// [0; Q₂ᵀx].
    pub(crate) fn project(&self, x: &mut [f64], cols: usize) {
        if !self.applied {
            return;
        }
        let p = self.p;
        for c in 0..cols {
            let col = &mut x[c * p..(c + 1) * p];
            self.qr.apply_qt(col, 1);
            col[..self.q].fill(0.0);
        }
    }

    /// [`Decoupling::project`] for model columns (Φ_k): a column whose projection is below
    /// [`UNKNOWN_INPUT_RANK_TOLERANCE`] of its norm becomes exactly zero. Not for ε_k,
    /// which a large d can make mostly removable without its remainder being rounding.
    pub(crate) fn project_columns(&self, x: &mut [f64], cols: usize) {
        if !self.applied {
            return;
        }
        for col in x.chunks_exact_mut(self.p).take(cols) {
            self.qr.cut_range(col, false);
        }
    }

    /// Turns X = P_kH_kᵀL_k⁻ᵀ (n×p) into X Q₂Q₂ᵀ + E_{k−1}R⁻¹Q₁ᵀ, row by row, so that a
    /// right division by L gives the Kitanidis gain K̄_k.
    pub(crate) fn correct_gain(&self, x: &mut [f64]) {
        if !self.applied {
            return;
        }
        let (n, q) = (self.n, self.q);
        for r in 0..n {
            let row = &mut x[r..];
            self.qr.apply_qt(row, n);
            for j in 0..q {
                row[j * n] = self.e_prev[(r, j)];
            }
            self.qr.solve_right_r(row, n);
            self.qr.apply_q(row, n);
        }
    }
}

/// The projection of state-fault columns onto the orthogonal complement of range(E_k)
/// (module documentation): a column whose remainder is below
/// [`UNKNOWN_INPUT_RANK_TOLERANCE`] of its norm becomes exactly zero.
#[derive(Debug, Clone)]
pub(crate) struct RangeComplement {
    n: usize,
    qr: Householder,
}

impl RangeComplement {
    pub(crate) fn new(n: usize, q: usize) -> Self {
        Self {
            n,
            qr: Householder::new(n, q),
        }
    }

    /// Factorises E_k (n×q). Returns false when E_k does not have full column rank.
    pub(crate) fn factor(&mut self, e: &DMatrix<f64>) -> bool {
        self.qr.factor(e.as_slice())
    }

    /// Replaces each of the `cols` columns of `psi` (n×cols) by its component outside
    /// range(E_k).
    pub(crate) fn project(&self, psi: &mut [f64], cols: usize) {
        for col in psi.chunks_exact_mut(self.n).take(cols) {
            self.qr.cut_range(col, true);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn householder_reproduces_the_matrix_and_solves_with_r() {
        let a = DMatrix::from_row_slice(4, 2, &[1.0, 2.0, -3.0, 0.5, 0.25, 4.0, 2.0, -1.0]);
        let mut qr = Householder::new(4, 2);
        assert!(qr.factor(a.as_slice()));
        // Qᵀa_j = [R_{:,j}; 0].
        for j in 0..2 {
            let mut col: Vec<f64> = a.column(j).iter().copied().collect();
            qr.apply_qt(&mut col, 1);
            for (i, v) in col.iter().enumerate() {
                if i > j {
                    assert!(v.abs() < 1e-14, "entry {i} of column {j}: {v}");
                }
            }
            assert!((col[j] - qr.diag[j]).abs() < 1e-14);
            let mut back = col.clone();
            qr.apply_q(&mut back, 1);
            for (x, y) in back.iter().zip(a.column(j).iter()) {
                assert!((x - y).abs() < 1e-14);
            }
        }
        // A second column collinear with the first fails the rank test, whatever its
        // scale.
        let b = DMatrix::from_row_slice(3, 2, &[1.0, 1e8, 2.0, 2e8, 3.0, 3e8]);
        assert!(!qr_factor(&b));
        let zero = DMatrix::from_row_slice(2, 1, &[0.0, 0.0]);
        assert!(!qr_factor(&zero));
    }

    use crate::StepError;
    use crate::detector::{GlrDetector, Sample, StepOutput, WindowSettings};
    use crate::filter::innovation::InnovationFilter;
    use crate::model::fault::{Column, Fault, FaultDictionary, Onset};
    use crate::model::{Lpv, LpvMatrix, StateSpace, SystemMatrices};
    use crate::sparse::residual::{KitanidisResidual, ResidualRow, ResidualSample};
    use crate::sparse::test_rng::Rng;
    use nalgebra::DVector;

    /// Zhang 2021, §V, Example 1 (eqs. (40)-(42)): A_k over p = (e^{−k}, cos k, sin k),
    /// C = [1 0 0; 0 0 1], E = [−1 0 0]ᵀ, Q = I, R = 0.5 I.
    fn example1() -> Lpv {
        let term = |i, j| {
            let mut m = DMatrix::zeros(3, 3);
            m[(i, j)] = 0.1;
            m
        };
        let f = LpvMatrix::new(
            DMatrix::from_row_slice(3, 3, &[-0.8, 0.7, 0.0, -0.6, 0.0, 0.0, 0.0, -0.5, -0.4]),
            vec![(0, term(0, 2)), (1, term(1, 2)), (2, term(2, 0))],
        )
        .unwrap();
        let c = |m: DMatrix<f64>| LpvMatrix::constant(m);
        Lpv::new(
            f,
            c(DMatrix::zeros(3, 0)),
            c(DMatrix::from_row_slice(
                2,
                3,
                &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            )),
            c(DMatrix::zeros(2, 0)),
            c(DMatrix::identity(3, 3)),
            c(DMatrix::identity(2, 2) * 0.5),
            3,
        )
        .unwrap()
    }

    fn e1() -> DMatrix<f64> {
        DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0])
    }

    fn signals(k: u64) -> [f64; 3] {
        let kf = k as f64;
        [(-kf).exp(), kf.cos(), kf.sin()]
    }

    /// The Example 1 plant, with the unknown input scaled by `d_scale` (1: the paper's
    /// d_k = 10 sin(0.1k) + N(0, 1) + 100) and an optional step fault (Ψ̃, Φ̃, θ, onset)
    /// of its own: samples (y, p) for `len` samples; the noises depend on `seed` only.
    fn simulate(
        seed: u64,
        len: u64,
        d_scale: f64,
        fault: Option<(DVector<f64>, DVector<f64>, f64, u64)>,
    ) -> Vec<([f64; 2], [f64; 3])> {
        simulate_with(seed, len, d_scale, fault, |_| e1())
    }

    fn simulate_with(
        seed: u64,
        len: u64,
        d_scale: f64,
        fault: Option<(DVector<f64>, DVector<f64>, f64, u64)>,
        e_of: impl Fn(&[f64; 3]) -> DMatrix<f64>,
    ) -> Vec<([f64; 2], [f64; 3])> {
        let mut model = example1();
        let mut sys = SystemMatrices::zeros(model.dims());
        let mut rng = Rng::new(seed);
        let mut x = DVector::<f64>::zeros(3);
        let mut out = Vec::with_capacity(len as usize);
        for k in 0..len {
            let p = signals(k);
            model.evaluate(k, &crate::model::Signals { u: &[], p: &p }, &mut sys);
            let mut y = &sys.h * &x + DVector::from_fn(2, |_, _| 0.5f64.sqrt() * rng.normal());
            let d = d_scale * (10.0 * (0.1 * k as f64).sin() + rng.normal() + 100.0);
            let w = DVector::from_fn(3, |_, _| rng.normal());
            x = &sys.f * &x + e_of(&p) * d + w;
            if let Some((psi, phi, theta, onset)) = &fault {
                if k >= *onset {
                    y += phi * *theta;
                }
                if k >= *onset {
                    // A step's Ψ_kθ enters X_{k+1} from k = r on (eq. (4)).
                    x += psi * *theta;
                }
            }
            out.push(([y[0], y[1]], p));
        }
        out
    }

    fn dictionary() -> FaultDictionary {
        let model = example1();
        let col = |v: &[f64]| Column::Constant(DVector::from_column_slice(v));
        FaultDictionary::new(
            model.dims(),
            vec![
                Fault::state("x2", Onset::Step, col(&[0.0, 1.0, 0.0])),
                Fault::state("x1_in_range_of_E", Onset::Step, col(&[3.0, 0.0, 0.0])),
                Fault::output("y1_bias", Onset::Step, col(&[0.0, 1.0])),
            ],
        )
        .unwrap()
    }

    fn detector(window: usize, unknown_input: bool) -> GlrDetector {
        let det = GlrDetector::new(
            Box::new(example1()),
            dictionary(),
            DVector::zeros(3),
            DMatrix::identity(3, 3),
            WindowSettings {
                window,
                min_lag: 0,
                ..WindowSettings::default()
            },
        )
        .unwrap();
        if unknown_input {
            det.with_unknown_input(LpvMatrix::constant(e1())).unwrap()
        } else {
            det
        }
    }

    /// The Kitanidis gain of the decoupled innovation filter equals Zhang 2021's eq.
    /// (24g) as [`KitanidisResidual`] computes it (a different factorisation: R⁻¹QᵀL⁻¹
    /// after Ξ = WᵀW), and the filters' state estimates agree, over 200 samples of
    /// Example 1 with its unknown input.
    #[test]
    fn gain_equals_the_kitanidis_gain_of_zhang_2021_eq_24g() {
        let mut model = example1();
        let data = simulate(7, 200, 1.0, None);
        let mut filter = InnovationFilter::new(DVector::zeros(3), DMatrix::identity(3, 3), 2)
            .unwrap()
            .with_unknown_input(1)
            .unwrap();
        let mut kit =
            KitanidisResidual::new(DVector::zeros(3), DMatrix::identity(3, 3), 2, 1, 1).unwrap();
        let mut sys = SystemMatrices::zeros(model.dims());
        let mut row = ResidualRow::zeros(2, 1);
        let psi = DMatrix::zeros(3, 1);
        let mut worst = (0.0_f64, 0.0_f64);
        for (k, (y, p)) in data.iter().enumerate() {
            model.evaluate(k as u64, &crate::model::Signals { u: &[], p }, &mut sys);
            filter.measure(&sys, &[], y).unwrap();
            let s = ResidualSample {
                sys: &sys,
                u: &[],
                y,
                psi: &psi,
                phi: None,
            };
            kit.step(&s, &e1(), &mut row).unwrap();
            let gain = (filter.gain() - kit.gain()).amax() / kit.gain().amax();
            assert_eq!(filter.innovation_dof(), if k == 0 { 2 } else { 1 });
            filter.time_update(&sys, &[]);
            filter.set_unknown_input(&e1());
            // X̂_{k+1} = F_kX̂_{k|k} (no known input).
            let predicted = &sys.f * kit.state();
            let state = (filter.state() - &predicted).amax() / predicted.amax().max(1.0);
            worst = (worst.0.max(gain), worst.1.max(state));
        }
        assert!(worst.0 < 1e-12 && worst.1 < 1e-12, "{worst:?}");
    }

    /// Zhang 2021, Prop. 2 and Fig. 1: the decoupled GLR does not see the unknown input.
    /// Two plants with the same noises, one with the paper's d_k ≈ 100 and one with
    /// d ≡ 0, give the same l_k, r̂ and θ̂ at every sample (to rounding: the states
    /// differ by ~10³), while the 2014 GLR on the Kalman innovation of the same model
    /// explodes. The fault entirely in range(E) has a Fisher information of exactly 0.
    #[test]
    fn decoupled_glr_is_blind_to_the_unknown_input() {
        let with_d = simulate(11, 400, 1.0, None);
        let without = simulate(11, 400, 0.0, None);
        let (mut a, mut b) = (detector(20, true), detector(20, true));
        let mut kalman = detector(20, false);
        let (mut oa, mut ob, mut ok) = (
            StepOutput::new(2, 3),
            StepOutput::new(2, 3),
            StepOutput::new(2, 3),
        );
        let mut worst = 0.0_f64;
        let mut kalman_max = 0.0_f64;
        for k in 0..400u64 {
            let (ya, p) = &with_d[k as usize];
            let (yb, _) = &without[k as usize];
            a.step(
                &Sample {
                    k,
                    u: &[],
                    y: ya,
                    p,
                },
                &mut oa,
            )
            .unwrap();
            b.step(
                &Sample {
                    k,
                    u: &[],
                    y: yb,
                    p,
                },
                &mut ob,
            )
            .unwrap();
            kalman
                .step(
                    &Sample {
                        k,
                        u: &[],
                        y: ya,
                        p,
                    },
                    &mut ok,
                )
                .unwrap();
            kalman_max = kalman_max.max(ok.glr.unwrap_or(0.0));
            assert_eq!(oa.onset, ob.onset, "k = {k}");
            assert_eq!(oa.rank, ob.rank, "k = {k}");
            if let (Some(ga), Some(gb)) = (oa.glr, ob.glr) {
                worst = worst.max((ga - gb).abs() / gb.max(1.0));
            }
            for (ta, tb) in oa.magnitude.iter().zip(ob.magnitude.iter()) {
                worst = worst.max((ta - tb).abs() / tb.abs().max(1.0));
            }
        }
        assert!(worst < 1e-9, "largest relative difference {worst:e}");
        assert!(kalman_max > 1e3, "the Kalman GLR reached only {kalman_max}");
        let onset = oa.onset.unwrap();
        let mut info = DMatrix::zeros(3, 3);
        let mut score = DVector::zeros(3);
        assert!(a.information(onset, &mut info, &mut score));
        assert_eq!(
            info.column(1).iter().copied().collect::<Vec<_>>(),
            vec![0.0; 3]
        );
        assert!(info[(0, 0)] > 0.0 && info[(2, 2)] > 0.0);
    }

    /// An LPV unknown-input matrix, E_k = [−1, 0.5·cos k, 0]ᵀ (p1 = cos k), is decoupled
    /// sample by sample: with d ≈ 100 and d ≡ 0 the outputs are the same to 1e-9.
    #[test]
    fn an_lpv_unknown_input_is_decoupled_at_every_sample() {
        let e_of = |p: &[f64; 3]| DMatrix::from_column_slice(3, 1, &[-1.0, 0.5 * p[1], 0.0]);
        let with_d = simulate_with(13, 300, 1.0, None, e_of);
        let without = simulate_with(13, 300, 0.0, None, e_of);
        let lpv = || {
            let mut term = DMatrix::zeros(3, 1);
            term[(1, 0)] = 0.5;
            LpvMatrix::new(e1(), vec![(1, term)]).unwrap()
        };
        let make = || detector(20, false).with_unknown_input(lpv()).unwrap();
        let (mut a, mut b) = (make(), make());
        let (mut oa, mut ob) = (StepOutput::new(2, 3), StepOutput::new(2, 3));
        let mut worst = 0.0_f64;
        let mut largest = 0.0_f64;
        for k in 0..300u64 {
            let (ya, p) = &with_d[k as usize];
            let (yb, _) = &without[k as usize];
            a.step(
                &Sample {
                    k,
                    u: &[],
                    y: ya,
                    p,
                },
                &mut oa,
            )
            .unwrap();
            b.step(
                &Sample {
                    k,
                    u: &[],
                    y: yb,
                    p,
                },
                &mut ob,
            )
            .unwrap();
            assert_eq!((oa.onset, oa.rank), (ob.onset, ob.rank), "k = {k}");
            if let (Some(ga), Some(gb)) = (oa.glr, ob.glr) {
                worst = worst.max((ga - gb).abs() / gb.max(1.0));
                largest = largest.max(ga);
            }
        }
        assert!(worst < 1e-9, "largest relative difference {worst:e}");
        // The constant E of the other tests does not decouple this d.
        let mut c = detector(20, true);
        let mut oc = StepOutput::new(2, 3);
        let mut constant_max = 0.0_f64;
        for k in 0..300u64 {
            let (y, p) = &with_d[k as usize];
            c.step(&Sample { k, u: &[], y, p }, &mut oc).unwrap();
            constant_max = constant_max.max(oc.glr.unwrap_or(0.0));
        }
        assert!(
            constant_max > 10.0 * largest.max(1.0),
            "{constant_max} vs {largest}"
        );
    }

    /// With a constant E on an LTI model the Kitanidis gain converges and the detector
    /// enters its stationary regime (the LTI fast path, tables per lag, held gain and
    /// projection): l_k, r̂, rank and θ̂ agree with the general recursion to 1e-9
    /// relative at every sample, through a fault on x2 from k = 600.
    #[test]
    fn the_lti_fast_path_with_an_unknown_input_equals_the_general_recursion() {
        let c = |m: DMatrix<f64>| LpvMatrix::constant(m);
        let lti = || {
            Lpv::new(
                c(DMatrix::from_row_slice(
                    3,
                    3,
                    &[-0.8, 0.7, 0.0, -0.6, 0.0, 0.0, 0.0, -0.5, -0.4],
                )),
                c(DMatrix::zeros(3, 0)),
                c(DMatrix::from_row_slice(
                    2,
                    3,
                    &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
                )),
                c(DMatrix::zeros(2, 0)),
                c(DMatrix::identity(3, 3)),
                c(DMatrix::identity(2, 2) * 0.5),
                3,
            )
            .unwrap()
        };
        let make = |steady_tolerance| {
            GlrDetector::new(
                Box::new(lti()),
                dictionary(),
                DVector::zeros(3),
                DMatrix::identity(3, 3),
                WindowSettings {
                    window: 30,
                    min_lag: 0,
                    steady_tolerance,
                    ..WindowSettings::default()
                },
            )
            .unwrap()
            .with_unknown_input(c(e1()))
            .unwrap()
        };
        let (mut fast, mut general) = (make(crate::DEFAULT_STEADY_TOLERANCE), make(0.0));
        // Example 1's signals only enter its LPV F, which this LTI model ignores: the
        // samples come from the LTV plant, a model mismatch both detectors share.
        let psi = DVector::from_column_slice(&[0.0, 1.0, 0.0]);
        let data = simulate(17, 1_000, 1.0, Some((psi, DVector::zeros(2), 5.0, 600)));
        let (mut a, mut b) = (StepOutput::new(2, 3), StepOutput::new(2, 3));
        let (mut stationary, mut worst) = (0, 0.0_f64);
        let close = |x: f64, y: f64| (x - y).abs() / x.abs().max(y.abs()).max(1.0);
        for k in 0..1_000u64 {
            let (y, p) = &data[k as usize];
            fast.step(&Sample { k, u: &[], y, p }, &mut a).unwrap();
            general.step(&Sample { k, u: &[], y, p }, &mut b).unwrap();
            stationary += u64::from(fast.is_stationary());
            assert_eq!((a.onset, a.rank), (b.onset, b.rank), "k = {k}");
            worst = worst.max(close(a.glr.unwrap_or(0.0), b.glr.unwrap_or(0.0)));
            for (x, y) in a.magnitude.iter().zip(b.magnitude.iter()) {
                worst = worst.max(close(*x, *y));
            }
        }
        assert!(worst <= 1e-9, "largest relative difference {worst:e}");
        assert!(stationary > 800, "stationary for {stationary} samples only");
    }

    /// Under no fault the decoupled whitened innovation is N(0, 1) (p − q = 1) and white,
    /// whatever d: 10⁵ samples of Example 1 with the paper's d_k. Its mean square is
    /// within 4σ of 1 (σ = √(2/N)), its lag-1 and lag-2 autocorrelations within 4/√N of
    /// 0, and the rate of exceeding χ²₁'s 99 % quantile within 4σ of 1 %.
    #[test]
    fn decoupled_innovation_is_white_with_p_minus_q_degrees_of_freedom() {
        let n = 100_000u64;
        let data = simulate(2021, n, 1.0, None);
        let mut det = detector(2, true);
        let mut out = StepOutput::new(2, 3);
        let q99 = crate::threshold::chi2_upper_quantile(1.0, 0.01).unwrap();
        let (mut sum, mut exceed) = (0.0, 0u64);
        let mut z = Vec::with_capacity(n as usize);
        for k in 0..n {
            let (y, p) = &data[k as usize];
            det.step(&Sample { k, u: &[], y, p }, &mut out).unwrap();
            if k == 0 {
                continue;
            }
            let white = det.filter().whitened_innovation();
            assert_eq!(white[0], 0.0);
            z.push(white[1]);
            sum += out.normalized_innovation;
            exceed += u64::from(out.normalized_innovation > q99);
        }
        let count = z.len() as f64;
        let mean_square = sum / count;
        assert!(
            (mean_square - 1.0).abs() < 4.0 * (2.0 / count).sqrt(),
            "{mean_square}"
        );
        for lag in [1, 2] {
            let rho =
                z.iter().zip(&z[lag..]).map(|(a, b)| a * b).sum::<f64>() / (count * mean_square);
            assert!(rho.abs() < 4.0 / count.sqrt(), "lag {lag}: ρ = {rho}");
        }
        let rate = exceed as f64 / count;
        assert!(
            (rate - 0.01).abs() < 4.0 * (0.01 * 0.99 / count).sqrt(),
            "{rate}"
        );
    }

    /// Faults outside range(E) are still detected, dated and sized on the decoupled
    /// innovation (Zhang 2021, §IV: the faults of Example 1 are isolated despite d): a
    /// step of θ = 5 on the unmeasured state x2 from k = 300, with the paper's d.
    #[test]
    fn a_fault_outside_the_range_of_e_is_detected_dated_and_sized() {
        let psi = DVector::from_column_slice(&[0.0, 1.0, 0.0]);
        let data = simulate(5, 400, 1.0, Some((psi, DVector::zeros(2), 5.0, 300)));
        let mut det = detector(150, true);
        let mut out = StepOutput::new(2, 3);
        let threshold = crate::threshold::chi2_upper_quantile(3.0, 1e-6).unwrap();
        let mut first = None;
        for k in 0..400u64 {
            let (y, p) = &data[k as usize];
            det.step(&Sample { k, u: &[], y, p }, &mut out).unwrap();
            if first.is_none() && out.glr.unwrap_or(0.0) > threshold {
                first = Some(k);
            }
        }
        let first = first.expect("no alarm");
        assert!((300..330).contains(&first), "first crossing at {first}");
        let onset = out.onset.unwrap();
        assert!(onset.abs_diff(300) <= 3, "onset {onset}");
        // The x2 fault alone: its joint estimate with the y1 bias, which the decoupled
        // innovation sees through nearly the same direction, is ill-conditioned.
        let fisher = det.fisher_statistics(onset).unwrap();
        let info = fisher.information()[(0, 0)];
        let (theta, se) = (fisher.score()[0] / info, info.sqrt().recip());
        assert!((theta - 5.0).abs() < 4.0 * se, "θ̂ = {theta}, se {se}");
    }

    #[test]
    fn unknown_input_settings_and_gaps_are_refused_clearly() {
        let base = || detector(5, false);
        let err = base()
            .with_unknown_input(LpvMatrix::constant(DMatrix::zeros(2, 1)))
            .unwrap_err();
        assert!(err.to_string().contains("3 states"), "{err}");
        let err = base()
            .with_unknown_input(LpvMatrix::constant(DMatrix::zeros(3, 2)))
            .unwrap_err();
        assert!(
            err.to_string().contains("fewer columns than outputs"),
            "{err}"
        );
        let err = base()
            .with_unknown_input(LpvMatrix::constant(DMatrix::zeros(3, 1)))
            .unwrap_err();
        assert!(err.to_string().contains("linearly dependent"), "{err}");
        let mut det = detector(5, true);
        let mut out = StepOutput::new(2, 3);
        det.step(
            &Sample {
                k: 0,
                u: &[],
                y: &[0.0, 0.0],
                p: &signals(0),
            },
            &mut out,
        )
        .unwrap();
        assert_eq!(
            det.predict_only(1),
            Err(StepError::UnknownInputGap { k: 1 })
        );
        assert_eq!(det.next_index(), Some(1));
        det.restart().unwrap();
        assert_eq!(det.unknown_inputs(), 1);
        det.step(
            &Sample {
                k: 9,
                u: &[],
                y: &[0.0, 0.0],
                p: &signals(9),
            },
            &mut out,
        )
        .unwrap();
    }

    /// An output-fault column in the direction H_kE_{k−1} that d reaches is whitened to
    /// exactly zero at any scale, one outside it keeps its norm's share.
    #[test]
    fn output_fault_columns_along_he_whiten_to_exact_zero() {
        let mut model = example1();
        let mut sys = SystemMatrices::zeros(model.dims());
        let mut filter = InnovationFilter::new(DVector::zeros(3), DMatrix::identity(3, 3), 2)
            .unwrap()
            .with_unknown_input(1)
            .unwrap();
        for k in 0..3u64 {
            model.evaluate(
                k,
                &crate::model::Signals {
                    u: &[],
                    p: &signals(k),
                },
                &mut sys,
            );
            filter.measure(&sys, &[], &[0.1, -0.2]).unwrap();
            filter.time_update(&sys, &[]);
            filter.set_unknown_input(&e1());
        }
        model.evaluate(
            3,
            &crate::model::Signals {
                u: &[],
                p: &signals(3),
            },
            &mut sys,
        );
        filter.measure(&sys, &[], &[0.1, -0.2]).unwrap();
        let he = &sys.h * e1();
        let mut phi = DMatrix::from_columns(&[
            he.column(0) * 3e7,
            he.column(0) * 1e-7,
            DVector::from_column_slice(&[0.0, 1.0]),
        ]);
        filter.whiten_in_place(phi.as_mut_slice(), 3);
        assert_eq!(
            phi.column(0)
                .iter()
                .chain(phi.column(1).iter())
                .copied()
                .collect::<Vec<_>>(),
            vec![0.0; 4]
        );
        assert_eq!(phi[(0, 2)], 0.0);
        assert!(phi[(1, 2)].abs() > 0.1);
    }

    fn qr_factor(a: &DMatrix<f64>) -> bool {
        Householder::new(a.nrows(), a.ncols()).factor(a.as_slice())
    }

    #[test]
    fn range_complement_zeroes_columns_in_range_and_keeps_the_rest() {
        let e = DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0]);
        let mut rc = RangeComplement::new(3, 1);
        assert!(rc.factor(&e));
        // Column 0 in range(E) at 1e6 scale, column 1 partly, column 2 orthogonal.
        let mut psi =
            DMatrix::from_row_slice(3, 3, &[3e6, 1.0, 0.0, 0.0, 2.0, 1e-6, 0.0, 3.0, 0.0]);
        rc.project(psi.as_mut_slice(), 3);
        assert_eq!(
            psi.column(0).iter().copied().collect::<Vec<_>>(),
            vec![0.0; 3]
        );
        assert!(psi[(0, 1)].abs() < 1e-15);
        assert!((psi[(1, 1)] - 2.0).abs() < 1e-15 && (psi[(2, 1)] - 3.0).abs() < 1e-15);
        assert!((psi[(1, 2)] - 1e-6).abs() < 1e-21);
    }
}
