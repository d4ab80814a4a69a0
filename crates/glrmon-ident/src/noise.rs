//! Noise covariances Q, R (and optionally S = E[w vᵀ]) of a *given* LTI model from
//! fault-free recordings: the autocovariance least-squares (ALS) method.
//!
//! The model is the user's own, x_{k+1} = F x_k + G u_k + w_k, y_k = H x_k + J u_k + v_k,
//! with E[w wᵀ] = Q, E[v vᵀ] = R, E[w vᵀ] = S (same time index, as in
//! [`solve_riccati`]). Only Q, R, S are estimated; F, G, H, J are kept.
//!
//! Outline (Odelson, Rajamani & Rawlings 2006, the ALS formulation; Åkesson, Jørgensen,
//! Poulsen & Jørgensen 2008, its generalisation to a correlated S and a noise input
//! matrix G_w; section and equation numbers are not quoted here because they were not
//! checked against the papers):
//!
//! 1. run a stable, generally suboptimal, one-step predictor with gain L over every
//!    experiment separately, skip its transient, and pool the sample autocovariances
//!    C_j = E[ε_{k+j} ε_kᵀ], j = 0..lags−1, of its innovations ε (never across a join);
//! 2. with Ā = F − L H, the state error e = x − x̂ obeys e_{k+1} = Ā e_k + w_k − L v_k,
//!    so with P̄ = Ā P̄ Āᵀ + Q − S Lᵀ − L Sᵀ + L R Lᵀ (a Lyapunov equation)
//!
//!    C_0 = H P̄ Hᵀ + R,   C_j = H Ā^j P̄ Hᵀ + H Ā^{j−1} (S − L R),  j ≥ 1,
//!
//!    which is linear in (Q, R, S). The design matrix of that linear map is built one
//!    column at a time, by evaluating the map on each basis element of the free
//!    parameters (equivalent to the Kronecker/vec form of Odelson et al. 2006, but
//!    without forming (I − Ā ⊗ Ā)⁻¹);
//! 3. the stacked sample C_j are fitted by (unweighted, identity-weighted) least
//!    squares, after a rank check of the design matrix: its full column rank is the
//!    uniqueness condition of the ALS solution (Odelson et al. 2006 state the necessary
//!    and sufficient condition for S = 0; Rajamani & Rawlings 2009 discuss the structure
//!    G_w and what it makes identifiable);
//! 4. the unconstrained estimate is projected onto the positive semi-definite cone (Q and
//!    R separately, or the joint [[Q_w, S_w], [S_wᵀ, R]] when S is estimated). This is a
//!    simpler stand-in for, not the same as, the semidefinite-constrained ALS of Odelson
//!    et al. 2006 and Rajamani & Rawlings 2009: with enough data the unconstrained
//!    estimate is already semi-definite and the two agree;
//! 5. the Kalman gain of the estimate (Riccati) becomes the next iteration's L.
//!
//! Odelson et al. write the predictor as x̂⁺ = A x̂ + A L (y − C x̂); their A L is the L
//! used here.
//!
//! Ref.: B. J. Odelson, M. R. Rajamani, J. B. Rawlings (2006), *A new autocovariance
//! least-squares method for estimating noise covariances*, Automatica 42(2), 303–308;
//! B. M. Åkesson, J. B. Jørgensen, N. K. Poulsen, S. B. Jørgensen (2008), *A generalized
//! autocovariance least-squares method for Kalman filter tuning*, J. Process Control
//! 18(7–8), 769–779; M. R. Rajamani, J. B. Rawlings (2009), *Estimation of the disturbance
//! structure from data using semidefinite programming and optimal weighting*,
//! Automatica 45(1), 142–148.

use std::fmt::Write as _;

use nalgebra::{DMatrix, DVector};

use crate::data::Experiment;
use crate::error::{IdentError, Signal};
use crate::model::{InnovationModel, solve_riccati, spectral_radius};
use crate::validation::{LjungBox, ljung_box, nis_mean};

/// A user's LTI model, x_{k+1} = F x_k + G u_k + w_k, y_k = H x_k + J u_k + v_k, in the
/// coordinates of the recordings (deviation from the operating point it is linearised
/// at, if it is a linearisation).
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalModel {
    /// F (n × n).
    pub f: DMatrix<f64>,
    /// G (n × l).
    pub g: DMatrix<f64>,
    /// H (p × n).
    pub h: DMatrix<f64>,
    /// J (p × l).
    pub j: DMatrix<f64>,
}

impl PhysicalModel {
    /// A model from its four matrices.
    #[must_use]
    pub fn new(f: DMatrix<f64>, g: DMatrix<f64>, h: DMatrix<f64>, j: DMatrix<f64>) -> Self {
        Self { f, g, h, j }
    }

    /// State dimension n.
    #[must_use]
    pub fn order(&self) -> usize {
        self.f.nrows()
    }

    /// Number of inputs l.
    #[must_use]
    pub fn inputs(&self) -> usize {
        self.g.ncols()
    }

    /// Number of outputs p.
    #[must_use]
    pub fn outputs(&self) -> usize {
        self.h.nrows()
    }

    fn check(&self) -> Result<(), IdentError> {
        let (n, l, p) = (self.order(), self.inputs(), self.outputs());
        let bad = |why: String| Err(IdentError::InvalidSetting { name: "model", why });
        if n == 0 || self.f.ncols() != n {
            return bad(format!(
                "F is {}×{}; it must be square with at least one state",
                self.f.nrows(),
                self.f.ncols()
            ));
        }
        if p == 0 {
            return Err(IdentError::NoOutput);
        }
        if self.g.nrows() != n || self.h.ncols() != n || self.j.nrows() != p || self.j.ncols() != l
        {
            return bad(format!(
                "F is {n}×{n}, so G must be {n}×l, H p×{n}, J p×l; got G {}×{}, H {}×{}, J {}×{}",
                self.g.nrows(),
                self.g.ncols(),
                self.h.nrows(),
                self.h.ncols(),
                self.j.nrows(),
                self.j.ncols()
            ));
        }
        if [&self.f, &self.g, &self.h, &self.j]
            .iter()
            .any(|m| m.iter().any(|v| !v.is_finite()))
        {
            return bad("F, G, H, J must be finite".to_owned());
        }
        Ok(())
    }

    fn innovation_model(&self, gain: &DMatrix<f64>) -> InnovationModel {
        let (n, p) = (self.order(), self.outputs());
        InnovationModel {
            a: self.f.clone(),
            b: self.g.clone(),
            c: self.h.clone(),
            d: self.j.clone(),
            k: gain.clone(),
            re: DMatrix::identity(p, p),
            q: DMatrix::zeros(n, n),
            s: DMatrix::zeros(n, p),
            r: DMatrix::zeros(p, p),
            p: DMatrix::zeros(n, n),
        }
    }
}

/// Structure of a covariance matrix to estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Structure {
    /// Any symmetric matrix: m(m + 1)/2 free parameters.
    #[default]
    Full,
    /// Diagonal (uncorrelated components): m free parameters.
    Diagonal,
}

/// Whether the cross covariance S = E[w vᵀ] is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CrossCovariance {
    /// S = 0 (process and measurement noises uncorrelated).
    #[default]
    Zero,
    /// S = G_w S_w with S_w (g × p) free (Åkesson et al. 2008).
    Free,
}

/// Which noise covariances are free, and how.
///
/// The process noise enters as w = G_w ξ with cov(ξ) = Q_w, so Q = G_w Q_w G_wᵀ and
/// S = G_w S_w; without a noise input matrix G_w = I (Q_w = Q).
///
/// Not every structure is identifiable from output data: the output spectrum only
/// determines the n·p + p(p + 1)/2 parameters of the innovation form (K, Re), so a full
/// Q with a free S is never identifiable, and a full Q with S = 0 fails already for
/// n = 3, p = 2 (rank 8 for 9 parameters) although it works for n = 2, p = 2.
/// [`estimate_noise`] checks the rank and names the parameters in the undetermined
/// combinations ([`IdentError::NotIdentifiable`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NoiseStructure {
    /// G_w (n × g), how the g process noise sources enter the states; `None` = I_n.
    pub noise_input: Option<DMatrix<f64>>,
    /// Structure of Q_w (g × g).
    pub q: Structure,
    /// Structure of R (p × p).
    pub r: Structure,
    /// Whether S is estimated.
    pub s: CrossCovariance,
}

/// An initial guess of Q and R (S = 0) from which the first predictor gain is computed.
#[derive(Debug, Clone, PartialEq)]
pub struct InitialGuess {
    /// Q₀ (n × n), positive semi-definite.
    pub q: DMatrix<f64>,
    /// R₀ (p × p), positive definite.
    pub r: DMatrix<f64>,
}

/// Settings of [`estimate_noise`].
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseSettings {
    /// Which parameters are free.
    pub structure: NoiseStructure,
    /// Number of autocovariance lags C_0..C_{lags−1} fitted (≥ 1; Odelson et al. 2006
    /// take it large enough for Ā^lags to be negligible). Default 15.
    pub lags: usize,
    /// Number of ALS solves (≥ 1); each after the first uses the Kalman gain of the
    /// previous estimate. Default 3.
    pub iterations: usize,
    /// Samples skipped at the start of every experiment before the innovations are used
    /// (the predictor starts from x̂₀ = 0). `None`: until ρ(Ā)^k < 10⁻⁶, at most 10 000.
    pub transient: Option<usize>,
    /// Initial guess for the first gain. `None`: R₀ = the pooled sample covariance of y
    /// (each experiment centred), Q₀ = 0.1 · (tr R₀ / p) / σ_max(H)² · I.
    pub initial: Option<InitialGuess>,
    /// A singular value of the column-normalised design matrix below this fraction of
    /// the largest counts as zero (not identifiable). Default 10⁻⁸.
    pub rank_tolerance: f64,
    /// Lags of the Ljung–Box test of the final filter's innovations. Default 20.
    pub ljung_box_lags: usize,
}

impl Default for NoiseSettings {
    fn default() -> Self {
        Self {
            structure: NoiseStructure::default(),
            lags: 15,
            iterations: 3,
            transient: None,
            initial: None,
            rank_tolerance: 1e-8,
            ljung_box_lags: 20,
        }
    }
}

/// One ALS solve: the gain it used and the estimate it gave.
#[derive(Debug, Clone, PartialEq)]
pub struct AlsIteration {
    /// The predictor gain L whose innovations were fitted (n × p).
    pub gain: DMatrix<f64>,
    /// ρ(F − L H).
    pub predictor_spectral_radius: f64,
    /// Samples skipped at the start of each experiment.
    pub transient: usize,
    /// Innovation samples used (all experiments).
    pub samples: usize,
    /// Q = G_w Q_w G_wᵀ after the projection (n × n).
    pub q: DMatrix<f64>,
    /// R after the projection (p × p).
    pub r: DMatrix<f64>,
    /// S = G_w S_w after the projection (n × p), if estimated.
    pub s: Option<DMatrix<f64>>,
    /// Rank of the design matrix (equals the parameter count: it is checked).
    pub design_rank: usize,
    /// Condition number of the column-normalised design matrix.
    pub design_condition: f64,
    /// Relative least-squares residual ‖A θ − b‖ / ‖b‖ of the stacked autocovariances.
    pub residual: f64,
    /// Whether the positive semi-definite projection changed the least-squares solution.
    pub projected: bool,
}

/// The estimated noise model of a [`PhysicalModel`] and the Kalman filter it gives.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseEstimate {
    /// Process noise covariance Q = G_w Q_w G_wᵀ (n × n).
    pub q: DMatrix<f64>,
    /// Measurement noise covariance R (p × p).
    pub r: DMatrix<f64>,
    /// Cross covariance S = E[w vᵀ] = G_w S_w (n × p), if estimated.
    pub s: Option<DMatrix<f64>>,
    /// Q_w (g × g), the covariance of the noise sources (equal to Q without G_w).
    pub q_w: DMatrix<f64>,
    /// S_w (g × p), if estimated.
    pub s_w: Option<DMatrix<f64>>,
    /// Steady Kalman gain K (predictor form, n × p) of the estimate.
    pub k: DMatrix<f64>,
    /// Innovation covariance Re = H P Hᵀ + R (p × p).
    pub re: DMatrix<f64>,
    /// Steady one-step prediction error covariance P (n × n), the Riccati solution.
    pub p: DMatrix<f64>,
    /// Autocovariance lags fitted.
    pub lags: usize,
    /// Names of the free parameters, in the order of the least-squares unknowns
    /// (`Q[i,j]` or `Q_w[i,j]`, `R[i,j]`, `S[i,j]` or `S_w[i,j]`, upper triangles).
    pub parameters: Vec<String>,
    /// Rank of the last design matrix (= `parameters.len()`).
    pub design_rank: usize,
    /// Every ALS solve, first to last (the last one's Q, R, S are the estimate).
    pub iterations: Vec<AlsIteration>,
    /// Mean NIS of the final filter's innovations on the data (after the transient): p
    /// for a consistent filter.
    pub nis_mean: Option<f64>,
    /// Ljung–Box test of each output's final innovations (experiments pooled by
    /// concatenation: the few lag products across a join are an O(lags/N) share).
    pub ljung_box: Vec<LjungBox>,
}

impl NoiseEstimate {
    /// The model with its estimated noise, as an [`InnovationModel`] (A = F, B = G,
    /// C = H, D = J, and K, Re, Q, S, R, P of the estimate), ready for the monitor.
    #[must_use]
    pub fn innovation_model(&self, model: &PhysicalModel) -> InnovationModel {
        InnovationModel {
            a: model.f.clone(),
            b: model.g.clone(),
            c: model.h.clone(),
            d: model.j.clone(),
            k: self.k.clone(),
            re: self.re.clone(),
            q: self.q.clone(),
            s: self
                .s
                .clone()
                .unwrap_or_else(|| DMatrix::zeros(model.order(), model.outputs())),
            r: self.r.clone(),
            p: self.p.clone(),
        }
    }
}

/// Estimates Q, R (and S) of `model` from fault-free `experiments` by autocovariance
/// least squares (see the [module documentation](self)).
///
/// Each experiment is filtered on its own from x̂₀ = 0 and its first `transient` samples
/// are dropped; lag products never straddle two experiments. The data must be in the
/// model's coordinates (for a linearised model, deviations from its operating point):
/// an unmodelled offset shows up as coloured innovations and biases the estimate.
///
/// # Errors
/// [`IdentError::NoExperiment`]; [`IdentError::InvalidSetting`] for an inconsistent
/// model, noise input matrix, initial guess, `lags`/`iterations` of 0, or an experiment
/// too short for the transient and the lags; [`IdentError::RowMismatch`],
/// [`IdentError::DimensionMismatch`], [`IdentError::NonFinite`] for bad data;
/// [`IdentError::NotIdentifiable`] when the design matrix is rank deficient (naming the
/// parameters that are not determined); the errors of [`solve_riccati`] when a gain
/// cannot be computed (e.g. (F, H) not detectable).
pub fn estimate_noise(
    model: &PhysicalModel,
    experiments: &[Experiment],
    settings: &NoiseSettings,
) -> Result<NoiseEstimate, IdentError> {
    model.check()?;
    check_experiments(model, experiments)?;
    if settings.lags == 0 {
        return Err(IdentError::InvalidSetting {
            name: "lags",
            why: "at least 1 (C_0) is needed".to_owned(),
        });
    }
    if settings.iterations == 0 {
        return Err(IdentError::InvalidSetting {
            name: "iterations",
            why: "at least one least-squares solve is needed".to_owned(),
        });
    }
    if !(settings.rank_tolerance > 0.0 && settings.rank_tolerance < 1.0) {
        return Err(IdentError::InvalidSetting {
            name: "rank_tolerance",
            why: format!("{} is not in (0, 1)", settings.rank_tolerance),
        });
    }
    let layout = Layout::new(model, &settings.structure)?;
    let (n, p) = (model.order(), model.outputs());

    let mut gain = initial_gain(model, experiments, settings.initial.as_ref())?;
    let mut iterations = Vec::with_capacity(settings.iterations);
    let mut last = None;
    for _ in 0..settings.iterations {
        let abar = &model.f - &gain * &model.h;
        let rho = spectral_radius(&abar);
        if rho.is_nan() || rho >= 1.0 {
            return Err(IdentError::InvalidSetting {
                name: "initial",
                why: format!(
                    "the predictor F − L H has spectral radius {rho:.4} ≥ 1: its innovations \
                     are not stationary; give a stabilising initial guess"
                ),
            });
        }
        let transient = settings.transient.unwrap_or_else(|| auto_transient(rho));
        let (sample, samples) =
            autocovariances(model, &gain, experiments, transient, settings.lags)?;
        let map = ClosedLoop::new(&abar, &gain, &model.h, settings.lags);
        let design = design_matrix(&layout, &map);
        let solved = solve(&layout, &design, &sample, settings.rank_tolerance)?;
        let (qw, r, sw, projected) = project(&layout, &solved.theta, &sample);
        let q = &layout.gw * &qw * layout.gw.transpose();
        let s = layout.cross.then(|| &layout.gw * &sw);
        iterations.push(AlsIteration {
            gain: gain.clone(),
            predictor_spectral_radius: rho,
            transient,
            samples,
            q: q.clone(),
            r: r.clone(),
            s: s.clone(),
            design_rank: solved.rank,
            design_condition: solved.condition,
            residual: solved.residual,
            projected,
        });
        let s_full = s.clone().unwrap_or_else(|| DMatrix::zeros(n, p));
        let riccati = solve_riccati(&model.f, &model.h, &q, &s_full, &r)?;
        gain = riccati.k.clone();
        last = Some((q, r, s, qw, sw, riccati, solved.rank));
    }
    let Some((q, r, s, qw, sw, riccati, design_rank)) = last else {
        unreachable!("iterations ≥ 1 was checked");
    };

    // The final filter on the data: NIS and whiteness.
    let abar = &model.f - &riccati.k * &model.h;
    let rho = spectral_radius(&abar);
    let transient = settings.transient.unwrap_or_else(|| auto_transient(rho));
    let filter = model.innovation_model(&riccati.k);
    let mut parts = Vec::with_capacity(experiments.len());
    for e in experiments {
        let pred = filter.predict(&e.inputs, &e.outputs, None)?;
        let m = e.samples().saturating_sub(transient);
        parts.push(pred.innovations.rows(e.samples() - m, m).into_owned());
    }
    let total: usize = parts.iter().map(DMatrix::nrows).sum();
    let mut innov = DMatrix::zeros(total, p);
    let mut row = 0;
    for part in &parts {
        innov.rows_mut(row, part.nrows()).copy_from(part);
        row += part.nrows();
    }
    Ok(NoiseEstimate {
        q,
        r,
        s,
        q_w: qw,
        s_w: layout.cross.then_some(sw),
        k: riccati.k.clone(),
        re: riccati.re.clone(),
        p: riccati.p.clone(),
        lags: settings.lags,
        parameters: layout.names(),
        design_rank,
        iterations,
        nis_mean: nis_mean(&innov, &riccati.re),
        ljung_box: ljung_box(&innov, settings.ljung_box_lags),
    })
}

/// Samples until ρ^k < 10⁻⁶ (at most 10 000): the initial-state error of the predictor
/// has then decayed below 10⁻⁶ of its size.
fn auto_transient(rho: f64) -> usize {
    if rho <= 1e-6 {
        return 1;
    }
    let k = (1e-6_f64).ln() / rho.ln();
    if k.is_finite() {
        (k.ceil() as usize).clamp(1, 10_000)
    } else {
        10_000
    }
}

fn check_experiments(model: &PhysicalModel, experiments: &[Experiment]) -> Result<(), IdentError> {
    if experiments.is_empty() {
        return Err(IdentError::NoExperiment);
    }
    for (e, exp) in experiments.iter().enumerate() {
        if exp.inputs.nrows() != exp.outputs.nrows() {
            return Err(IdentError::RowMismatch {
                experiment: e,
                input_rows: exp.inputs.nrows(),
                output_rows: exp.outputs.nrows(),
            });
        }
        for (signal, m, expected) in [
            (Signal::Input, &exp.inputs, model.inputs()),
            (Signal::Output, &exp.outputs, model.outputs()),
        ] {
            if m.ncols() != expected {
                return Err(IdentError::DimensionMismatch {
                    signal,
                    got: m.ncols(),
                    expected,
                });
            }
            for (column, col) in m.column_iter().enumerate() {
                if let Some((row, &value)) = col.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    return Err(IdentError::NonFinite {
                        experiment: e,
                        signal,
                        column,
                        row,
                        value,
                    });
                }
            }
        }
    }
    Ok(())
}

/// The first predictor gain: from the user's guess, or from R₀ = pooled cov(y) and
/// Q₀ = 0.1 (tr R₀ / p) / σ_max(H)² I (both scale like the data, so the gain is
/// invariant to a rescaling of the outputs).
fn initial_gain(
    model: &PhysicalModel,
    experiments: &[Experiment],
    initial: Option<&InitialGuess>,
) -> Result<DMatrix<f64>, IdentError> {
    let (n, p) = (model.order(), model.outputs());
    let (q0, r0) = if let Some(guess) = initial {
        if guess.q.shape() != (n, n) || guess.r.shape() != (p, p) {
            return Err(IdentError::InvalidSetting {
                name: "initial",
                why: format!(
                    "Q₀ must be {n}×{n} and R₀ {p}×{p}; got {}×{} and {}×{}",
                    guess.q.nrows(),
                    guess.q.ncols(),
                    guess.r.nrows(),
                    guess.r.ncols()
                ),
            });
        }
        (guess.q.clone(), guess.r.clone())
    } else {
        let mut r0 = DMatrix::zeros(p, p);
        let mut count = 0usize;
        for e in experiments {
            let y = &e.outputs;
            if y.nrows() == 0 {
                continue;
            }
            let mean = y.row_mean();
            let centred = DMatrix::from_fn(y.nrows(), p, |i, j| y[(i, j)] - mean[j]);
            r0 += centred.tr_mul(&centred);
            count += y.nrows();
        }
        r0 /= count.max(1) as f64;
        let scale = r0.trace() / p as f64;
        if scale.is_nan() || scale <= 0.0 {
            return Err(IdentError::InvalidSetting {
                name: "initial",
                why: "the outputs are constant: give an initial guess".to_owned(),
            });
        }
        // Nearly collinear outputs: keep R₀ positive definite.
        r0 += DMatrix::identity(p, p) * (1e-6 * scale);
        let h_norm = model.h.clone().svd(false, false).singular_values.max();
        let h2 = if h_norm > 0.0 { h_norm * h_norm } else { 1.0 };
        (DMatrix::identity(n, n) * (0.1 * scale / h2), r0)
    };
    Ok(solve_riccati(&model.f, &model.h, &q0, &DMatrix::zeros(n, p), &r0)?.k)
}

/// Pooled sample autocovariances C_j = Σ_e Σ_k ε_{k+j} ε_kᵀ / Σ_e (N_e − t − j) of the
/// predictor's innovations, each experiment after its transient t, stacked as
/// [vec C_0; …; vec C_{lags−1}] (column-major vec). Also returns the samples used.
fn autocovariances(
    model: &PhysicalModel,
    gain: &DMatrix<f64>,
    experiments: &[Experiment],
    transient: usize,
    lags: usize,
) -> Result<(DVector<f64>, usize), IdentError> {
    let p = model.outputs();
    let filter = model.innovation_model(gain);
    let mut sums = vec![DMatrix::<f64>::zeros(p, p); lags];
    let mut counts = vec![0usize; lags];
    let mut samples = 0;
    for (e, exp) in experiments.iter().enumerate() {
        let n = exp.samples();
        if n <= transient + lags {
            return Err(IdentError::InvalidSetting {
                name: "lags",
                why: format!(
                    "experiment {e} has {n} samples; skipping the transient ({transient}) and \
                     using {lags} lags needs more than {}",
                    transient + lags
                ),
            });
        }
        let pred = filter.predict(&exp.inputs, &exp.outputs, None)?;
        let m = n - transient;
        let eps = pred.innovations.rows(transient, m);
        samples += m;
        for (j, (sum, count)) in sums.iter_mut().zip(&mut counts).enumerate() {
            // Σ_k ε_{k+j} ε_kᵀ within this experiment only.
            *sum += eps.rows(j, m - j).tr_mul(&eps.rows(0, m - j));
            *count += m - j;
        }
    }
    let mut stacked = DVector::zeros(lags * p * p);
    for (j, (sum, count)) in sums.iter().zip(&counts).enumerate() {
        let c = sum / *count as f64;
        stacked
            .rows_mut(j * p * p, p * p)
            .copy_from_slice(c.as_slice());
    }
    Ok((stacked, samples))
}

/// One free parameter: its matrix and position (upper triangle for symmetric ones).
#[derive(Debug, Clone, Copy)]
enum Param {
    Q(usize, usize),
    R(usize, usize),
    S(usize, usize),
}

/// The free parameters of a [`NoiseStructure`] and how they fill Q_w, R, S_w.
struct Layout {
    gw: DMatrix<f64>,
    has_gw: bool,
    g: usize,
    p: usize,
    cross: bool,
    q_diag: bool,
    r_diag: bool,
    params: Vec<Param>,
}

impl Layout {
    fn new(model: &PhysicalModel, structure: &NoiseStructure) -> Result<Self, IdentError> {
        let (n, p) = (model.order(), model.outputs());
        let gw = match &structure.noise_input {
            Some(gw) if gw.nrows() != n || gw.ncols() == 0 => {
                return Err(IdentError::InvalidSetting {
                    name: "noise_input",
                    why: format!(
                        "G_w is {}×{}; it must have n = {n} rows and at least one column",
                        gw.nrows(),
                        gw.ncols()
                    ),
                });
            }
            Some(gw) if gw.iter().any(|v| !v.is_finite()) => {
                return Err(IdentError::InvalidSetting {
                    name: "noise_input",
                    why: "G_w must be finite".to_owned(),
                });
            }
            Some(gw) => gw.clone(),
            None => DMatrix::identity(n, n),
        };
        let g = gw.ncols();
        let mut params = Vec::new();
        for i in 0..g {
            for j in i..g {
                if i == j || structure.q == Structure::Full {
                    params.push(Param::Q(i, j));
                }
            }
        }
        for i in 0..p {
            for j in i..p {
                if i == j || structure.r == Structure::Full {
                    params.push(Param::R(i, j));
                }
            }
        }
        let cross = structure.s == CrossCovariance::Free;
        if cross {
            for i in 0..g {
                for j in 0..p {
                    params.push(Param::S(i, j));
                }
            }
        }
        Ok(Self {
            gw,
            has_gw: structure.noise_input.is_some(),
            g,
            p,
            cross,
            q_diag: structure.q == Structure::Diagonal,
            r_diag: structure.r == Structure::Diagonal,
            params,
        })
    }

    fn names(&self) -> Vec<String> {
        let w = if self.has_gw { "_w" } else { "" };
        self.params
            .iter()
            .map(|param| match *param {
                Param::Q(i, j) => format!("Q{w}[{i},{j}]"),
                Param::R(i, j) => format!("R[{i},{j}]"),
                Param::S(i, j) => format!("S{w}[{i},{j}]"),
            })
            .collect()
    }

    /// Q_w (g × g), R (p × p), S_w (g × p) of a parameter vector.
    fn unpack(&self, theta: &[f64]) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let mut qw = DMatrix::zeros(self.g, self.g);
        let mut r = DMatrix::zeros(self.p, self.p);
        let mut sw = DMatrix::zeros(self.g, self.p);
        for (param, &v) in self.params.iter().zip(theta) {
            match *param {
                Param::Q(i, j) => {
                    qw[(i, j)] = v;
                    qw[(j, i)] = v;
                }
                Param::R(i, j) => {
                    r[(i, j)] = v;
                    r[(j, i)] = v;
                }
                Param::S(i, j) => sw[(i, j)] = v,
            }
        }
        (qw, r, sw)
    }
}

/// What the autocovariance map needs of the closed loop Ā = F − L H.
struct ClosedLoop {
    gain: DMatrix<f64>,
    h: DMatrix<f64>,
    /// H Ā^j, j = 0..lags−1.
    h_abar: Vec<DMatrix<f64>>,
    /// Ā^(2^i) while not negligible (Smith's doubling for the Lyapunov equation).
    doubling: Vec<DMatrix<f64>>,
}

impl ClosedLoop {
    fn new(abar: &DMatrix<f64>, gain: &DMatrix<f64>, h: &DMatrix<f64>, lags: usize) -> Self {
        let mut h_abar = Vec::with_capacity(lags);
        let mut m = h.clone();
        for _ in 0..lags {
            let next = &m * abar;
            h_abar.push(m);
            m = next;
        }
        let mut doubling = Vec::new();
        let mut a = abar.clone();
        // ρ(Ā) < 1 was checked; 64 squarings sum 2⁶⁴ terms of the series.
        for _ in 0..64 {
            let norm = a.norm();
            if norm < 1e-300 {
                break;
            }
            let next = &a * &a;
            doubling.push(a);
            if norm * norm < 1e-20 {
                break;
            }
            a = next;
        }
        Self {
            gain: gain.clone(),
            h: h.clone(),
            h_abar,
            doubling,
        }
    }

    /// P̄ = Σ_k Ā^k W Ā^kᵀ, the solution of P̄ = Ā P̄ Āᵀ + W, by doubling:
    /// P ← P + Ā^(2^i) P Ā^(2^i)ᵀ.
    fn lyapunov(&self, w: &DMatrix<f64>) -> DMatrix<f64> {
        let mut p = w.clone();
        for a in &self.doubling {
            p += a * &p * a.transpose();
        }
        (&p + p.transpose()) * 0.5
    }

    /// The stacked [vec C_0; …; vec C_{lags−1}] that (Q, R, S) would give (see the
    /// module documentation).
    fn map(&self, q: &DMatrix<f64>, r: &DMatrix<f64>, s: &DMatrix<f64>) -> DVector<f64> {
        let l = &self.gain;
        let sl = s * l.transpose();
        let w = q - &sl - sl.transpose() + l * r * l.transpose();
        let pbar = self.lyapunov(&w);
        let p = self.h.nrows();
        let lags = self.h_abar.len();
        let pht = &pbar * self.h.transpose();
        let cross = s - l * r;
        let mut out = DVector::zeros(lags * p * p);
        for (j, h_abar) in self.h_abar.iter().enumerate() {
            let mut c = h_abar * &pht;
            if j == 0 {
                c += r;
            } else {
                c += &self.h_abar[j - 1] * &cross;
            }
            out.rows_mut(j * p * p, p * p).copy_from_slice(c.as_slice());
        }
        out
    }
}

/// The design matrix: column i is the map evaluated on the i-th basis parameter.
fn design_matrix(layout: &Layout, map: &ClosedLoop) -> DMatrix<f64> {
    let cols = layout.params.len();
    let rows = map.h_abar.len() * layout.p * layout.p;
    let mut a = DMatrix::zeros(rows, cols);
    let mut theta = vec![0.0; cols];
    for i in 0..cols {
        theta.iter_mut().for_each(|t| *t = 0.0);
        theta[i] = 1.0;
        let (qw, r, sw) = layout.unpack(&theta);
        let q = &layout.gw * &qw * layout.gw.transpose();
        let s = &layout.gw * &sw;
        a.set_column(i, &map.map(&q, &r, &s));
    }
    a
}

struct Solved {
    theta: Vec<f64>,
    rank: usize,
    condition: f64,
    residual: f64,
}

/// Least squares on the column-normalised design matrix by SVD, after the rank check.
fn solve(
    layout: &Layout,
    design: &DMatrix<f64>,
    b: &DVector<f64>,
    tolerance: f64,
) -> Result<Solved, IdentError> {
    let cols = design.ncols();
    let scale: Vec<f64> = design
        .column_iter()
        .map(|c| {
            let n = c.norm();
            if n > 0.0 { n } else { 1.0 }
        })
        .collect();
    // Zero rows pad a short design so that the SVD gives the full right singular basis.
    let rows = design.nrows().max(cols);
    let mut a = DMatrix::zeros(rows, cols);
    for (i, s) in scale.iter().enumerate() {
        a.view_mut((0, i), (design.nrows(), 1))
            .copy_from(&(design.column(i) / *s));
    }
    let svd = a.svd(true, true);
    let (u, v_t) = match (&svd.u, &svd.v_t) {
        (Some(u), Some(v_t)) => (u, v_t),
        _ => {
            return Err(IdentError::SvdNotConverged {
                what: "the ALS design matrix",
            });
        }
    };
    let sigma = &svd.singular_values;
    let s_max = sigma.max();
    let s_min = sigma.min();
    let small: Vec<usize> = (0..sigma.len())
        .filter(|&i| sigma[i].is_nan() || sigma[i] <= tolerance * s_max)
        .collect();
    let rank = sigma.len() - small.len();
    if rank < cols {
        // A parameter is undetermined when it has a sizeable share in the null space.
        let names = layout.names();
        let mut undetermined = Vec::new();
        for (k, name) in names.iter().enumerate() {
            let share: f64 = small.iter().map(|&i| v_t[(i, k)].powi(2)).sum();
            if share > 0.01 {
                undetermined.push(name.clone());
            }
        }
        let mut hint = String::new();
        if layout.cross {
            hint.push_str("estimate S only with a noise input matrix G_w of few columns, ");
        }
        let _ = write!(
            hint,
            "restrict Q (Diagonal, or a noise input matrix G_w), restrict R (Diagonal), or \
             use more lags"
        );
        return Err(IdentError::NotIdentifiable {
            rank,
            parameters: cols,
            undetermined,
            hint,
        });
    }
    let mut b_pad = DVector::zeros(rows);
    b_pad.rows_mut(0, b.len()).copy_from(b);
    let utb = u.tr_mul(&b_pad);
    let mut theta_s = DVector::zeros(cols);
    for i in 0..sigma.len() {
        theta_s += v_t.row(i).transpose() * (utb[i] / sigma[i]);
    }
    let theta: Vec<f64> = theta_s.iter().zip(&scale).map(|(t, s)| t / s).collect();
    let fit = design * DVector::from_column_slice(&theta);
    let bn = b.norm();
    Ok(Solved {
        theta,
        rank,
        condition: s_max / s_min,
        residual: if bn > 0.0 { (fit - b).norm() / bn } else { 0.0 },
    })
}

/// Eigenvalues of a symmetric matrix clipped below at `floor`.
fn clip_psd(m: &DMatrix<f64>, floor: f64) -> DMatrix<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let d = eig.eigenvalues.map(|v| v.max(floor));
    let out = &eig.eigenvectors * DMatrix::from_diagonal(&d) * eig.eigenvectors.transpose();
    (&out + out.transpose()) * 0.5
}

fn min_eigenvalue(m: &DMatrix<f64>) -> f64 {
    ((m + m.transpose()) * 0.5).symmetric_eigenvalues().min()
}

fn zero_off_diagonal(m: &mut DMatrix<f64>) {
    let d = m.diagonal();
    *m = DMatrix::from_diagonal(&d);
}

/// The least-squares estimate made a valid noise model: Q_w, R (and the joint
/// [[Q_w, S_w], [S_wᵀ, R]]) projected to the nearest positive semi-definite matrices in
/// the Frobenius norm (eigenvalues clipped at 0), diagonal structures kept, S_w shrunk
/// if restoring a diagonal structure broke the joint's semi-definiteness, and R kept
/// above 10⁻⁹ · tr(C_0)/p so that the Riccati equation is defined.
fn project(
    layout: &Layout,
    theta: &[f64],
    sample: &DVector<f64>,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, bool) {
    let (g, p) = (layout.g, layout.p);
    let (qw0, r0, sw0) = layout.unpack(theta);
    let c0_trace: f64 = (0..p).map(|i| sample[i * p + i]).sum();
    let r_floor = 1e-9 * (c0_trace / p as f64).max(f64::MIN_POSITIVE);
    let (mut qw, mut r, mut sw);
    if layout.cross {
        let mut joint = DMatrix::zeros(g + p, g + p);
        joint.view_mut((0, 0), (g, g)).copy_from(&qw0);
        joint.view_mut((g, g), (p, p)).copy_from(&r0);
        joint.view_mut((0, g), (g, p)).copy_from(&sw0);
        joint.view_mut((g, 0), (p, g)).copy_from(&sw0.transpose());
        let joint = clip_psd(&joint, 0.0);
        qw = joint.view((0, 0), (g, g)).into_owned();
        r = joint.view((g, g), (p, p)).into_owned();
        sw = joint.view((0, g), (g, p)).into_owned();
        if layout.q_diag {
            zero_off_diagonal(&mut qw);
        }
        if layout.r_diag {
            zero_off_diagonal(&mut r);
        }
        if layout.q_diag || layout.r_diag {
            // Block-diagonal with PSD diagonals is PSD: bisect the largest α ≤ 1 with
            // [[Q_w, α S_w], [α S_wᵀ, R]] ⪰ 0.
            let joint_of = |alpha: f64| {
                let mut m = DMatrix::zeros(g + p, g + p);
                m.view_mut((0, 0), (g, g)).copy_from(&qw);
                m.view_mut((g, g), (p, p)).copy_from(&r);
                m.view_mut((0, g), (g, p)).copy_from(&(&sw * alpha));
                m.view_mut((g, 0), (p, g))
                    .copy_from(&(sw.transpose() * alpha));
                m
            };
            let tol = -1e-12 * joint_of(0.0).amax().max(f64::MIN_POSITIVE);
            if min_eigenvalue(&joint_of(1.0)) < tol {
                let (mut lo, mut hi) = (0.0, 1.0);
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if min_eigenvalue(&joint_of(mid)) >= tol {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                sw *= lo;
            }
        }
    } else {
        qw = if layout.q_diag {
            DMatrix::from_diagonal(&qw0.diagonal().map(|v| v.max(0.0)))
        } else {
            clip_psd(&qw0, 0.0)
        };
        r = if layout.r_diag {
            DMatrix::from_diagonal(&r0.diagonal().map(|v| v.max(0.0)))
        } else {
            clip_psd(&r0, 0.0)
        };
        sw = sw0.clone();
    }
    let r_min = min_eigenvalue(&r);
    if r_min < r_floor {
        r += DMatrix::identity(p, p) * (r_floor - r_min);
    }
    let change = (&qw - &qw0).norm() + (&r - &r0).norm() + (&sw - &sw0).norm();
    let size = qw0.norm() + r0.norm() + sw0.norm();
    let projected = change > 1e-12 * size.max(f64::MIN_POSITIVE);
    (qw, r, sw, projected)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_autocovariance_map_matches_closed_form() {
        // x⁺ = a x + w, y = x + v, gain l: ā = a − l,
        // P̄ = (q − 2 s l + l² r) / (1 − ā²), C_0 = P̄ + r, C_j = ā^j P̄ + ā^{j−1} (s − l r).
        let (a, l, q, r, s) = (0.9_f64, 0.4, 0.5, 2.0, 0.3);
        let m = |v: f64| DMatrix::from_element(1, 1, v);
        let abar = a - l;
        let cl = ClosedLoop::new(&m(abar), &m(l), &m(1.0), 4);
        let out = cl.map(&m(q), &m(r), &m(s));
        let pbar = (q - 2.0 * s * l + l * l * r) / (1.0 - abar * abar);
        assert!((out[0] - (pbar + r)).abs() < 1e-12);
        for j in 1..4 {
            let expected = abar.powi(j as i32) * pbar + abar.powi(j as i32 - 1) * (s - l * r);
            assert!((out[j] - expected).abs() < 1e-12, "lag {j}");
        }
    }

    #[test]
    fn projection_keeps_a_psd_estimate_and_clips_a_negative_one() {
        let model = PhysicalModel::new(
            DMatrix::identity(2, 2) * 0.5,
            DMatrix::zeros(2, 0),
            DMatrix::identity(2, 2),
            DMatrix::zeros(2, 0),
        );
        let layout = Layout::new(&model, &NoiseStructure::default()).unwrap();
        let sample = DVector::from_vec(vec![1.0, 0.0, 0.0, 1.0]);
        // Q = [[1, 0], [0, 2]], R = I: unchanged.
        let (qw, r, _, projected) = project(&layout, &[1.0, 0.0, 2.0, 1.0, 0.0, 1.0], &sample);
        assert!(!projected);
        assert_eq!(qw, DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 2.0]));
        assert_eq!(r, DMatrix::identity(2, 2));
        // Q = [[1, 0], [0, −1]]: the negative eigenvalue is clipped.
        let (qw, _, _, projected) = project(&layout, &[1.0, 0.0, -1.0, 1.0, 0.0, 1.0], &sample);
        assert!(projected);
        assert!((qw - DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 0.0])).norm() < 1e-12);
    }
}
