//! The Kalman one-step predictor designed for the fault-free model, and its
//! innovation ε_k (Zhang & Basseville 2014, eqs. (6)-(10)).
//!
//! ```text
//! ε_k      = Y_k − J_k U_k − H_k X̂_k                        (10)
//! Σ_k      = H_k P_k H_kᵀ + R_k                               (8)
//! K_k      = P_k H_kᵀ Σ_k⁻¹                                   (7)
//! X̂_{k+1}  = F_k X̂_k + G_k U_k + F_k K_k ε_k                 (6)
//! P_{k+1}  = F_k [(I − K_kH_k) P_k (I − K_kH_k)ᵀ + K_k R_k K_kᵀ] F_kᵀ + Q_k
//! ```
//!
//! The covariance update is the Joseph form of eq. (8): algebraically equal to
//! F_k(I − K_kH_k)P_kF_kᵀ + Q_k, but a sum of symmetric positive semi-definite terms,
//! so P stays symmetric positive definite under rounding (checked over 10⁶ steps of
//! the unstable §6.1 plant in the tests).
//!
//! Besides ε_k and Σ_k the filter exposes what the Γ recursion (eq. (46)) needs: the
//! closed-loop matrix A_k = F_k(I − K_kH_k), the predictor gain F_kK_k, and the
//! Cholesky factor L_k of Σ_k (Σ_k = L_kL_kᵀ) used to whiten the innovation.
//!
//! With an unknown input E_kd_k ([`InnovationFilter::with_unknown_input`]) the gain is
//! the Kitanidis gain and the whitening also removes the directions H_kE_{k−1} that d
//! can reach ([`crate::filter::decoupling`], Zhang 2021 §III-B): the whitened quantities keep p
//! rows, the first q of them zero.

use nalgebra::{DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::filter::decoupling::Decoupling;
use crate::linalg::{
    Shape, cholesky_in_place, copy_n, gemm, gemv, solve_lower_in_place,
    solve_right_lower_transpose_in_place, symmetrize, with_shape,
};
use crate::model::SystemMatrices;

/// Kalman one-step predictor with its last measurement update.
#[derive(Debug, Clone)]
pub struct InnovationFilter {
    n: usize,
    p: usize,
    /// X̂_k, the prediction of the next sample's state.
    state: DVector<f64>,
    /// P_k, its error covariance.
    cov: DMatrix<f64>,
    /// ε_k of the last measured sample.
    innovation: DVector<f64>,
    /// Σ_k of the last measured sample.
    innovation_cov: DMatrix<f64>,
    /// L_k with Σ_k = L_kL_kᵀ.
    chol: DMatrix<f64>,
    /// L_k⁻¹ε_k.
    innovation_white: DVector<f64>,
    /// L_k⁻¹H_k (with an unknown input, [0; Q₂ᵀL_k⁻¹H_k]).
    h_white: DMatrix<f64>,
    /// K_k (n×p).
    gain: DMatrix<f64>,
    /// A_k = F_k(I − K_kH_k), or F_k after a predict-only step.
    closed_loop: DMatrix<f64>,
    /// F_kK_k, or 0 after a predict-only step.
    predictor_gain: DMatrix<f64>,
    // Scratch, sized once.
    pht: DMatrix<f64>,
    ikh: DMatrix<f64>,
    tmp_nn: DMatrix<f64>,
    tmp_nn2: DMatrix<f64>,
    tmp_np: DMatrix<f64>,
    tmp_n: DVector<f64>,
    tmp_pp: DMatrix<f64>,
    chol_scratch: DMatrix<f64>,
    /// Predict-only steps since the last measured sample (the length j of the gap
    /// so far).
    gap_len: u64,
    /// W_j = Σ_i A_i V A_iᵀ: the held inputs' error over the gap so far, as if its
    /// samples were uncorrelated (see [`InnovationFilter::predict_only`]).
    gap_cov: DMatrix<f64>,
    /// The unknown input's decoupling, when the model has one.
    unknown_input: Option<Box<Decoupling>>,
    /// S = E(W_kV_kᵀ) and S Σ_k⁻¹ (n×p each), when process and measurement noise are
    /// correlated ([`InnovationFilter::with_cross_covariance`]).
    cross: Option<Box<(DMatrix<f64>, DMatrix<f64>)>>,
}

impl InnovationFilter {
    /// A filter started at X̂_0 = `x0` with covariance P_0 = `p0`, for `outputs` outputs.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when P_0 is not n×n, [`ModelError::NonFinite`] for
    /// NaN/Inf, [`ModelError::Setting`] when P_0 is not symmetric positive semi-definite.
    pub fn new(x0: DVector<f64>, p0: DMatrix<f64>, outputs: usize) -> Result<Self, ModelError> {
        let n = x0.len();
        if p0.shape() != (n, n) {
            return Err(ModelError::Dimension {
                what: "P0",
                detail: format!("P0 is {}×{} but x0 has {n} entries", p0.nrows(), p0.ncols()),
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
        let p = outputs;
        let z = |r, c| DMatrix::zeros(r, c);
        Ok(Self {
            n,
            p,
            state: x0,
            cov: p0,
            innovation: DVector::zeros(p),
            innovation_cov: z(p, p),
            chol: z(p, p),
            innovation_white: DVector::zeros(p),
            h_white: z(p, n),
            gain: z(n, p),
            closed_loop: z(n, n),
            predictor_gain: z(n, p),
            pht: z(n, p),
            ikh: z(n, n),
            tmp_nn: z(n, n),
            tmp_nn2: z(n, n),
            tmp_np: z(n, p),
            tmp_n: DVector::zeros(n),
            tmp_pp: z(p, p),
            chol_scratch: z(p, p),
            gap_len: 0,
            gap_cov: z(n, n),
            unknown_input: None,
            cross: None,
        })
    }

    /// The same filter for process and measurement noises correlated as S = E(W_kV_kᵀ)
    /// (n×p, constant): the one-step predictor of Anderson & Moore (Optimal Filtering,
    /// 1979, §5.5), K_p = F_kK_k + SΣ_k⁻¹, A_k = F_k − K_pH_k,
    /// P_{k+1} = F_kP_kF_kᵀ + Q_k − K_pΣ_kK_pᵀ, with K_p in place of F_kK_k in the Γ
    /// recursion (Zhang & Basseville 2014, eq. (46)). An identified innovation model
    /// x⁺ = Ax + Bu + Ke, y = Cx + Du + e is Q = K Re Kᵀ, R = Re, S = K Re: its predictor
    /// is exact at order n and Σ_k tends to Re.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when S is not n×p, [`ModelError::NonFinite`].
    pub fn with_cross_covariance(mut self, s: DMatrix<f64>) -> Result<Self, ModelError> {
        if s.shape() != (self.n, self.p) {
            return Err(ModelError::Dimension {
                what: "S",
                detail: format!(
                    "S is {}×{} but the model has {} states and {} outputs",
                    s.nrows(),
                    s.ncols(),
                    self.n,
                    self.p
                ),
            });
        }
        if s.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "S" });
        }
        let gain = DMatrix::zeros(self.n, self.p);
        self.cross = Some(Box::new((s, gain)));
        Ok(self)
    }

    /// The same filter for a plant with an unknown input E_kd_k of `unknown_inputs`
    /// (q) columns: from the second sample on, the gain is Kitanidis' (Zhang 2021, eqs.
    /// (24c)-(24g)) and the whitened innovation has p − q degrees of freedom
    /// ([`crate::filter::decoupling`]). E_k is given after each time update with
    /// [`InnovationFilter::set_unknown_input`].
    ///
    /// # Errors
    /// [`ModelError::Setting`] when q = 0 or q ≥ p (nothing would be left to test).
    pub fn with_unknown_input(mut self, unknown_inputs: usize) -> Result<Self, ModelError> {
        if unknown_inputs == 0 || unknown_inputs >= self.p {
            return Err(ModelError::Setting {
                what: "E",
                detail: format!(
                    "E has {unknown_inputs} columns and there are {} outputs: decoupling \
                     needs at least one column and fewer columns than outputs",
                    self.p
                ),
            });
        }
        self.unknown_input = Some(Box::new(Decoupling::new(self.n, self.p, unknown_inputs)));
        Ok(self)
    }

    /// E_k (n×q), the unknown input's matrix between this sample and the next; the next
    /// [`InnovationFilter::measure`] decouples H_{k+1}E_k. Ignored without an unknown
    /// input.
    pub fn set_unknown_input(&mut self, e: &DMatrix<f64>) {
        if let Some(d) = &mut self.unknown_input {
            d.set_next(e);
        }
    }

    /// q, the number of unknown inputs (0 without).
    #[must_use]
    pub fn unknown_inputs(&self) -> usize {
        self.unknown_input
            .as_ref()
            .map_or(0, |d| d.unknown_inputs())
    }

    /// The degrees of freedom of the last whitened innovation: p, or p − q when it was
    /// decoupled from an unknown input.
    #[must_use]
    pub fn innovation_dof(&self) -> usize {
        match &self.unknown_input {
            Some(d) if d.applied() => self.p - d.unknown_inputs(),
            _ => self.p,
        }
    }

    /// x ← W_k x for the `cols` output-fault columns of x (p×cols, Φ_k): L_k⁻¹x, and
    /// with an unknown input the projection that zeroes the directions H_kE_{k−1}
    /// ([`crate::filter::decoupling`]), as ε_k and H_k are whitened. A column the projection
    /// leaves below [`crate::error::UNKNOWN_INPUT_RANK_TOLERANCE`] of its norm lies in
    /// those directions and becomes exactly zero (not rounding noise, which the
    /// scale-free rank decisions would count).
    pub fn whiten_in_place(&self, x: &mut [f64], cols: usize) {
        solve_lower_in_place(self.chol.as_slice(), self.p, x, cols);
        if let Some(d) = &self.unknown_input {
            d.project_columns(x, cols);
        }
    }

    /// Measurement update for sample k: computes ε_k, Σ_k, L_k, K_k and the whitened
    /// quantities. The predicted state and covariance are not changed until
    /// [`InnovationFilter::time_update`].
    ///
    /// # Errors
    /// [`StepError::Numerical`] when Σ_k is not positive definite; nothing observable
    /// is changed then.
    pub fn measure(&mut self, sys: &SystemMatrices, u: &[f64], y: &[f64]) -> Result<(), StepError> {
        self.gap_len = 0;
        with_shape!(self.n, self.p, |s| self.measure_in(s, sys, u, y))
    }

    /// [`InnovationFilter::measure`] for one [`Shape`] (n, p fixed at compile time for
    /// the small channels, so the products unroll; the same operations either way).
    #[inline(always)]
    fn measure_in(
        &mut self,
        s: impl Shape,
        sys: &SystemMatrices,
        u: &[f64],
        y: &[f64],
    ) -> Result<(), StepError> {
        let (n, p) = (s.n(), s.p());
        // P Hᵀ (n×p) and Σ = H P Hᵀ + R (p×p), factorised in scratch first so that a
        // failure leaves the last step's outputs intact.
        gemm(
            1.0,
            self.cov.as_slice(),
            (n, n),
            false,
            sys.h.as_slice(),
            (p, n),
            true,
            0.0,
            self.pht.as_mut_slice(),
        );
        copy_n(self.tmp_pp.as_mut_slice(), sys.r.as_slice(), p * p);
        gemm(
            1.0,
            sys.h.as_slice(),
            (p, n),
            false,
            self.pht.as_slice(),
            (n, p),
            false,
            1.0,
            self.tmp_pp.as_mut_slice(),
        );
        symmetrize(self.tmp_pp.as_mut_slice(), p);
        copy_n(
            self.chol_scratch.as_mut_slice(),
            self.tmp_pp.as_slice(),
            p * p,
        );
        if !cholesky_in_place(self.chol_scratch.as_mut_slice(), p) {
            return Err(StepError::Numerical {
                what: "innovation covariance Σ_k is not positive definite",
            });
        }
        if let Some(d) = &mut self.unknown_input {
            d.prepare(self.chol_scratch.as_slice(), sys.h.as_slice())?;
            d.commit();
        }
        std::mem::swap(&mut self.chol, &mut self.chol_scratch);
        copy_n(
            self.innovation_cov.as_mut_slice(),
            self.tmp_pp.as_slice(),
            p * p,
        );
        self.innovation_from(s, sys, u, y);
        copy_n(self.h_white.as_mut_slice(), sys.h.as_slice(), p * n);
        solve_lower_in_place(self.chol.as_slice(), p, self.h_white.as_mut_slice(), n);
        // K = P Hᵀ Σ⁻¹ = (P Hᵀ L⁻ᵀ) L⁻¹: solve X Lᵀ = P Hᵀ, then K L = X. With an
        // unknown input, X becomes XQ₂Q₂ᵀ + E R⁻¹Q₁ᵀ in between (the Kitanidis gain).
        copy_n(self.gain.as_mut_slice(), self.pht.as_slice(), n * p);
        solve_right_lower_transpose_in_place(self.chol.as_slice(), p, self.gain.as_mut_slice(), n);
        if let Some(d) = &self.unknown_input {
            d.project(self.h_white.as_mut_slice(), n);
            d.correct_gain(self.gain.as_mut_slice());
        }
        solve_right_lower_in_place(self.chol.as_slice(), p, self.gain.as_mut_slice(), n);
        if let Some(c) = &mut self.cross {
            let (s, s_sigma) = &mut **c;
            copy_n(s_sigma.as_mut_slice(), s.as_slice(), n * p);
            solve_right_lower_transpose_in_place(
                self.chol.as_slice(),
                p,
                s_sigma.as_mut_slice(),
                n,
            );
            solve_right_lower_in_place(self.chol.as_slice(), p, s_sigma.as_mut_slice(), n);
        }
        Ok(())
    }

    /// Time update after [`InnovationFilter::measure`] of the same sample: X̂_{k+1},
    /// P_{k+1} (Joseph form), A_k and F_kK_k.
    pub fn time_update(&mut self, sys: &SystemMatrices, u: &[f64]) {
        with_shape!(self.n, self.p, |s| self.time_update_in(s, sys, u));
    }

    /// [`InnovationFilter::time_update`] for one [`Shape`].
    #[inline(always)]
    fn time_update_in(&mut self, s: impl Shape, sys: &SystemMatrices, u: &[f64]) {
        let (n, p) = (s.n(), s.p());
        // I − K H
        gemm(
            -1.0,
            self.gain.as_slice(),
            (n, p),
            false,
            sys.h.as_slice(),
            (p, n),
            false,
            0.0,
            self.ikh.as_mut_slice(),
        );
        for i in 0..n {
            self.ikh[(i, i)] += 1.0;
        }
        // Updated covariance (I − KH) P (I − KH)ᵀ + K R Kᵀ, into tmp_nn.
        gemm(
            1.0,
            self.ikh.as_slice(),
            (n, n),
            false,
            self.cov.as_slice(),
            (n, n),
            false,
            0.0,
            self.tmp_nn2.as_mut_slice(),
        );
        gemm(
            1.0,
            self.tmp_nn2.as_slice(),
            (n, n),
            false,
            self.ikh.as_slice(),
            (n, n),
            true,
            0.0,
            self.tmp_nn.as_mut_slice(),
        );
        gemm(
            1.0,
            self.gain.as_slice(),
            (n, p),
            false,
            sys.r.as_slice(),
            (p, p),
            false,
            0.0,
            self.tmp_np.as_mut_slice(),
        );
        gemm(
            1.0,
            self.tmp_np.as_slice(),
            (n, p),
            false,
            self.gain.as_slice(),
            (n, p),
            true,
            1.0,
            self.tmp_nn.as_mut_slice(),
        );
        self.updated_state(s);
        // A = F (I − K H), F K.
        gemm(
            1.0,
            sys.f.as_slice(),
            (n, n),
            false,
            self.ikh.as_slice(),
            (n, n),
            false,
            0.0,
            self.closed_loop.as_mut_slice(),
        );
        gemm(
            1.0,
            sys.f.as_slice(),
            (n, n),
            false,
            self.gain.as_slice(),
            (n, p),
            false,
            0.0,
            self.predictor_gain.as_mut_slice(),
        );
        self.propagate(s, sys, u);
        self.correlated_noise(s, sys);
    }

    /// With correlated noises (S): K_p = FK + SΣ⁻¹ into the predictor gain, A = F − K_pH,
    /// X̂_{k+1} += SΣ⁻¹ε and P_{k+1} −= FKSᵀ + S(FK)ᵀ + SΣ⁻¹Sᵀ, which turns
    /// FP_{k|k}Fᵀ + Q into FPFᵀ + Q − K_pΣK_pᵀ (P_{k|k} = P − KΣKᵀ).
    #[inline(always)]
    fn correlated_noise(&mut self, s: impl Shape, sys: &SystemMatrices) {
        let Some(c) = &self.cross else {
            return;
        };
        let (n, p) = (s.n(), s.p());
        let (cross, s_sigma) = &**c;
        gemv(
            1.0,
            s_sigma.as_slice(),
            n,
            p,
            self.innovation.as_slice(),
            1.0,
            self.state.as_mut_slice(),
        );
        gemm(
            -1.0,
            self.predictor_gain.as_slice(),
            (n, p),
            false,
            cross.as_slice(),
            (n, p),
            true,
            1.0,
            self.cov.as_mut_slice(),
        );
        gemm(
            -1.0,
            cross.as_slice(),
            (n, p),
            false,
            self.predictor_gain.as_slice(),
            (n, p),
            true,
            1.0,
            self.cov.as_mut_slice(),
        );
        gemm(
            -1.0,
            s_sigma.as_slice(),
            (n, p),
            false,
            cross.as_slice(),
            (n, p),
            true,
            1.0,
            self.cov.as_mut_slice(),
        );
        symmetrize(self.cov.as_mut_slice(), n);
        for (k, m) in self.predictor_gain.iter_mut().zip(s_sigma.iter()) {
            *k += m;
        }
        gemm(
            -1.0,
            s_sigma.as_slice(),
            (n, p),
            false,
            sys.h.as_slice(),
            (p, n),
            false,
            1.0,
            self.closed_loop.as_mut_slice(),
        );
    }

    /// Measurement step of the stationary filter: ε_k and L⁻¹ε_k with the gain, Σ and
    /// L of the last full [`InnovationFilter::measure`] held (the Riccati recursion has
    /// converged: eqs. (7)-(8) would give them again). Cannot fail.
    pub fn measure_steady(&mut self, sys: &SystemMatrices, u: &[f64], y: &[f64]) {
        self.gap_len = 0;
        with_shape!(self.n, self.p, |s| self.innovation_from(s, sys, u, y));
    }

    /// ε = y − Ju − HX̂ (eq. (10)) and L⁻¹ε with the current L.
    #[inline(always)]
    fn innovation_from(&mut self, s: impl Shape, sys: &SystemMatrices, u: &[f64], y: &[f64]) {
        let (n, p, l) = (s.n(), s.p(), sys.g.ncols());
        self.innovation.as_mut_slice().copy_from_slice(y);
        gemv(
            -1.0,
            sys.j.as_slice(),
            p,
            l,
            u,
            1.0,
            self.innovation.as_mut_slice(),
        );
        gemv(
            -1.0,
            sys.h.as_slice(),
            p,
            n,
            self.state.as_slice(),
            1.0,
            self.innovation.as_mut_slice(),
        );
        copy_n(
            self.innovation_white.as_mut_slice(),
            self.innovation.as_slice(),
            p,
        );
        solve_lower_in_place(
            self.chol.as_slice(),
            p,
            self.innovation_white.as_mut_slice(),
            1,
        );
        if let Some(d) = &self.unknown_input {
            d.project(self.innovation_white.as_mut_slice(), 1);
        }
    }

    /// Time update of the stationary filter: X̂_{k+1} = F_k(X̂_k + Kε_k) + G_kU_k
    /// (eq. (6)) with the held gain; P, A and FK are unchanged.
    pub fn time_update_steady(&mut self, sys: &SystemMatrices, u: &[f64]) {
        with_shape!(self.n, self.p, |s| {
            self.updated_state(s);
            self.propagate_state(s, sys, u);
            if let Some(c) = &self.cross {
                gemv(
                    1.0,
                    c.1.as_slice(),
                    s.n(),
                    s.p(),
                    self.innovation.as_slice(),
                    1.0,
                    self.state.as_mut_slice(),
                );
            }
        });
    }

    /// The updated state X̂_{k|k} = X̂_k + Kε_k, into tmp_n.
    #[inline(always)]
    fn updated_state(&mut self, s: impl Shape) {
        let (n, p) = (s.n(), s.p());
        copy_n(self.tmp_n.as_mut_slice(), self.state.as_slice(), n);
        gemv(
            1.0,
            self.gain.as_slice(),
            n,
            p,
            self.innovation.as_slice(),
            1.0,
            self.tmp_n.as_mut_slice(),
        );
    }

    /// Predict-only step for a missing sample: X̂_{k+1} = F_kX̂_k + G_kU_k,
    /// P_{k+1} = F_kP_kF_kᵀ + Q_k + Δ_j, A_k = F_k, F_kK_k = 0 (no measurement, no
    /// gain). The input of a missing sample is unknown: `u` is a guess (the last one
    /// seen) and `input_variance` (V = diag(v), the mean square error of that guess per
    /// input, or empty for none) its uncertainty, so that the prediction error it
    /// causes is covered by P instead of showing up as a fault after the gap.
    ///
    /// The guesses' errors d_i over one gap are correlated in any way (a slow input
    /// keeps one error for the whole gap), so P covers their worst case: after j
    /// missing samples the error Σ_i A_i d_i (A_i = F⋯F G) has, by Cauchy–Schwarz,
    /// Var(cᵀΣ_i A_i d_i) ≤ j·Σ_i cᵀA_iVA_iᵀc for every c. P therefore carries
    /// j·W_j with W_j = F W_{j−1} Fᵀ + G V Gᵀ, the white-error sum, which is the
    /// increment Δ_j = j·W_j − (j−1)·F W_{j−1} Fᵀ = F W_{j−1} Fᵀ + j·G V Gᵀ.
    pub fn predict_only(&mut self, sys: &SystemMatrices, u: &[f64], input_variance: &[f64]) {
        self.tmp_n.copy_from(&self.state);
        self.tmp_nn.copy_from(&self.cov);
        self.closed_loop.copy_from(&sys.f);
        self.predictor_gain.fill(0.0);
        self.propagate(
            crate::linalg::Dynamic {
                n: self.n,
                p: self.p,
            },
            sys,
            u,
        );
        let n = self.n;
        self.gap_len += 1;
        if self.gap_len == 1 {
            self.gap_cov.fill(0.0);
        } else {
            // F W_{j−1} Fᵀ, entering P once and W_j once.
            gemm(
                1.0,
                sys.f.as_slice(),
                (n, n),
                false,
                self.gap_cov.as_slice(),
                (n, n),
                false,
                0.0,
                self.tmp_nn2.as_mut_slice(),
            );
            gemm(
                1.0,
                self.tmp_nn2.as_slice(),
                (n, n),
                false,
                sys.f.as_slice(),
                (n, n),
                true,
                0.0,
                self.tmp_nn.as_mut_slice(),
            );
            self.cov += &self.tmp_nn;
            self.gap_cov.copy_from(&self.tmp_nn);
        }
        let j = self.gap_len as f64;
        for (i, var) in input_variance.iter().enumerate().take(sys.g.ncols()) {
            if *var > 0.0 && var.is_finite() {
                for c in 0..n {
                    for r in 0..n {
                        let gvg = sys.g[(r, i)] * var * sys.g[(c, i)];
                        self.cov[(r, c)] += j * gvg;
                        self.gap_cov[(r, c)] += gvg;
                    }
                }
            }
        }
    }

    /// X̂_{k+1} = F tmp_n + G u, P_{k+1} = F tmp_nn Fᵀ + Q.
    #[inline(always)]
    fn propagate(&mut self, s: impl Shape, sys: &SystemMatrices, u: &[f64]) {
        self.propagate_state(s, sys, u);
        let n = s.n();
        gemm(
            1.0,
            sys.f.as_slice(),
            (n, n),
            false,
            self.tmp_nn.as_slice(),
            (n, n),
            false,
            0.0,
            self.tmp_nn2.as_mut_slice(),
        );
        copy_n(self.cov.as_mut_slice(), sys.q.as_slice(), n * n);
        gemm(
            1.0,
            self.tmp_nn2.as_slice(),
            (n, n),
            false,
            sys.f.as_slice(),
            (n, n),
            true,
            1.0,
            self.cov.as_mut_slice(),
        );
        symmetrize(self.cov.as_mut_slice(), n);
    }

    /// X̂_{k+1} = F tmp_n + G u.
    #[inline(always)]
    fn propagate_state(&mut self, s: impl Shape, sys: &SystemMatrices, u: &[f64]) {
        let (n, l) = (s.n(), sys.g.ncols());
        gemv(
            1.0,
            sys.f.as_slice(),
            n,
            n,
            self.tmp_n.as_slice(),
            0.0,
            self.state.as_mut_slice(),
        );
        gemv(
            1.0,
            sys.g.as_slice(),
            n,
            l,
            u,
            1.0,
            self.state.as_mut_slice(),
        );
    }

    /// X̂_k: the predicted state for the next sample.
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.state
    }

    /// P_k: covariance of the predicted state.
    #[must_use]
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.cov
    }

    /// ε_k of the last measured sample (eq. (10)).
    #[must_use]
    pub fn innovation(&self) -> &DVector<f64> {
        &self.innovation
    }

    /// Σ_k of the last measured sample (eq. (8)).
    #[must_use]
    pub fn innovation_covariance(&self) -> &DMatrix<f64> {
        &self.innovation_cov
    }

    /// L_k, the lower Cholesky factor of Σ_k.
    #[must_use]
    pub fn innovation_cholesky(&self) -> &DMatrix<f64> {
        &self.chol
    }

    /// L_k⁻¹ε_k, the whitened innovation (N(0, I) under no fault); with an unknown
    /// input [0; Q₂ᵀL_k⁻¹ε_k], N(0, I) on its last p − q entries.
    #[must_use]
    pub fn whitened_innovation(&self) -> &DVector<f64> {
        &self.innovation_white
    }

    /// L_k⁻¹H_k.
    #[must_use]
    pub fn whitened_output_matrix(&self) -> &DMatrix<f64> {
        &self.h_white
    }

    /// K_k (eq. (7)); with an unknown input, the Kitanidis gain K̄_k (Zhang 2021, eq.
    /// (24g)).
    #[must_use]
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.gain
    }

    /// A_k = F_k(I − K_kH_k), the matrix that propagates Γ in eq. (46).
    #[must_use]
    pub fn closed_loop(&self) -> &DMatrix<f64> {
        &self.closed_loop
    }

    /// F_kK_k, which maps the output fault Φ_k into Γ_{k+1} in eq. (46).
    #[must_use]
    pub fn predictor_gain(&self) -> &DMatrix<f64> {
        &self.predictor_gain
    }

    /// εᵀΣ⁻¹ε of the last measured sample: χ²(p) under no fault (with an unknown input,
    /// the decoupled part's: χ²(p − q), [`InnovationFilter::innovation_dof`]).
    #[must_use]
    pub fn normalized_innovation_squared(&self) -> f64 {
        self.innovation_white.norm_squared()
    }
}

/// Solves X·L = B in place for X (B is `rows`×`n`, L lower triangular).
#[inline(always)]
fn solve_right_lower_in_place(l: &[f64], n: usize, b: &mut [f64], rows: usize) {
    for r in 0..rows {
        for j in (0..n).rev() {
            let mut s = b[r + rows * j];
            for k in (j + 1)..n {
                s -= b[r + rows * k] * l[k + n * j];
            }
            b[r + rows * j] = s / l[j + n * j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Dims, SystemMatrices};

    fn sys() -> SystemMatrices {
        let mut s = SystemMatrices::zeros(Dims {
            states: 2,
            inputs: 1,
            outputs: 1,
            signals: 0,
        });
        s.f = DMatrix::from_row_slice(2, 2, &[0.5, 1.0, 0.0, 1.2]);
        s.g = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        s.h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        s.q = DMatrix::identity(2, 2) * 0.0025;
        s.r = DMatrix::from_element(1, 1, 0.0025);
        s
    }

    /// Eqs. (6)-(8) written with nalgebra's operators, as a reference.
    #[test]
    fn one_step_matches_textbook_equations_6_to_8() {
        let s = sys();
        let x0 = DVector::from_vec(vec![1.0, 0.5]);
        let p0 = DMatrix::from_row_slice(2, 2, &[0.3, 0.1, 0.1, 0.2]);
        let mut f = InnovationFilter::new(x0.clone(), p0.clone(), 1).unwrap();
        let (u, y) = ([0.3], [1.7]);
        f.measure(&s, &u, &y).unwrap();
        f.time_update(&s, &u);
        let sigma = &s.h * &p0 * s.h.transpose() + &s.r;
        let k = &p0 * s.h.transpose() * sigma.clone().try_inverse().unwrap();
        let eps = DVector::from_vec(y.to_vec()) - &s.h * &x0;
        let x1 = &s.f * &x0 + &s.g * DVector::from_vec(u.to_vec()) + &s.f * &k * &eps;
        let p1 = &s.f * (DMatrix::identity(2, 2) - &k * &s.h) * &p0 * s.f.transpose() + &s.q;
        assert!((f.innovation() - &eps).amax() < 1e-15);
        assert!((f.innovation_covariance() - &sigma).amax() < 1e-15);
        assert!((f.gain() - &k).amax() < 1e-15);
        assert!((f.state() - x1).amax() < 1e-14);
        assert!((f.covariance() - p1).amax() < 1e-14);
        let a = &s.f * (DMatrix::identity(2, 2) - &k * &s.h);
        assert!((f.closed_loop() - a).amax() < 1e-15);
    }

    /// The fixed-shape code (n, p known at compile time, loops unrolled) and the
    /// run-time-shape code are the same operations: same bits over a long run of a
    /// 3-state, 2-output plant, in the full and the held-gain steps.
    #[test]
    fn fixed_and_dynamic_shapes_give_the_same_bits() {
        use crate::linalg::{Dynamic, Fixed};
        let mut s = SystemMatrices::zeros(Dims {
            states: 3,
            inputs: 1,
            outputs: 2,
            signals: 0,
        });
        s.f = DMatrix::from_row_slice(3, 3, &[0.9, 0.2, 0.0, -0.1, 0.8, 0.3, 0.05, 0.0, 1.01]);
        s.g = DMatrix::from_row_slice(3, 1, &[0.1, 0.0, 1.0]);
        s.h = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.5, 0.0, 1.0, -0.2]);
        s.j = DMatrix::from_row_slice(2, 1, &[0.0, 0.3]);
        s.q = DMatrix::from_row_slice(3, 3, &[0.02, 0.001, 0.0, 0.001, 0.01, 0.0, 0.0, 0.0, 0.03]);
        s.r = DMatrix::from_row_slice(2, 2, &[0.04, 0.01, 0.01, 0.05]);
        let x0 = DVector::from_vec(vec![0.1, -0.2, 0.3]);
        let p0 = DMatrix::identity(3, 3);
        let mut fixed = InnovationFilter::new(x0.clone(), p0.clone(), 2).unwrap();
        let mut dynamic = InnovationFilter::new(x0, p0, 2).unwrap();
        let bits = |f: &InnovationFilter| -> Vec<u64> {
            [f.state(), f.innovation(), f.whitened_innovation()]
                .into_iter()
                .flat_map(|v| v.iter().copied())
                .chain(f.covariance().iter().copied())
                .chain(f.gain().iter().copied())
                .chain(f.closed_loop().iter().copied())
                .map(f64::to_bits)
                .collect()
        };
        let dynamic_shape = Dynamic { n: 3, p: 2 };
        for k in 0..2000_u32 {
            let t = f64::from(k);
            let u = [(0.37 * t).sin()];
            let y = [(0.11 * t).cos(), 0.5 * (0.23 * t).sin() + 0.01 * t.sqrt()];
            if k < 1500 {
                fixed.measure_in(Fixed::<3, 2>, &s, &u, &y).unwrap();
                fixed.time_update_in(Fixed::<3, 2>, &s, &u);
                dynamic.measure_in(dynamic_shape, &s, &u, &y).unwrap();
                dynamic.time_update_in(dynamic_shape, &s, &u);
            } else {
                fixed.innovation_from(Fixed::<3, 2>, &s, &u, &y);
                fixed.updated_state(Fixed::<3, 2>);
                fixed.propagate_state(Fixed::<3, 2>, &s, &u);
                dynamic.innovation_from(dynamic_shape, &s, &u, &y);
                dynamic.updated_state(dynamic_shape);
                dynamic.propagate_state(dynamic_shape, &s, &u);
            }
            assert_eq!(bits(&fixed), bits(&dynamic), "step {k}");
        }
        assert!(fixed.state().iter().all(|x| x.is_finite()));
    }

    /// Over a gap of j missing samples P is F^jP_0F^jᵀ + Σ F^iQF^iᵀ + j·Σ_i A_iVA_iᵀ
    /// (A_i = F^iG), written out as sums, and it covers the error of a guess that is
    /// wrong by the same d at every missing sample (the worst correlation): for the
    /// direction c of that error, cᵀPc ≥ (cᵀΣ_i A_i d)². A measured sample ends the gap:
    /// the next gap starts from j = 1.
    #[test]
    fn a_gap_covers_the_held_inputs_error_whatever_its_correlation() {
        let mut s = sys();
        s.f = DMatrix::from_row_slice(2, 2, &[0.9, 0.3, -0.2, 0.95]);
        let (p0, v) = (DMatrix::identity(2, 2) * 0.1, 0.7);
        let mut f = InnovationFilter::new(DVector::zeros(2), p0.clone(), 1).unwrap();
        for round in 0..2 {
            let start = f.covariance().clone();
            let mut reference_noise = start.clone();
            let mut white = DMatrix::zeros(2, 2);
            let mut constant = DVector::zeros(2);
            for j in 1..=40_u32 {
                f.predict_only(&s, &[0.0], &[v]);
                reference_noise = &s.f * &reference_noise * s.f.transpose() + &s.q;
                white = &s.f * &white * s.f.transpose() + &s.g * v * s.g.transpose();
                constant = &s.f * &constant + &s.g * v.sqrt();
                let expected = &reference_noise + &white * f64::from(j);
                let scale = expected.amax();
                assert!(
                    (f.covariance() - &expected).amax() < 1e-12 * scale,
                    "round {round}, j = {j}"
                );
                let c = constant.normalize();
                let covered = (c.transpose() * f.covariance() * &c)[(0, 0)];
                let error = c.dot(&constant).powi(2);
                assert!(covered >= error, "j = {j}: {covered} < {error}");
            }
            f.measure(&s, &[0.0], &[0.0]).unwrap();
            f.time_update(&s, &[0.0]);
        }
    }

    #[test]
    fn non_positive_sigma_is_an_error_and_keeps_previous_outputs() {
        let mut s = sys();
        let mut f = InnovationFilter::new(DVector::zeros(2), DMatrix::zeros(2, 2), 1).unwrap();
        f.measure(&s, &[0.0], &[1.0]).unwrap();
        let before = f.innovation().clone();
        s.r[(0, 0)] = -1.0;
        assert!(matches!(
            f.measure(&s, &[0.0], &[5.0]),
            Err(StepError::Numerical { .. })
        ));
        assert_eq!(f.innovation(), &before);
    }
}
