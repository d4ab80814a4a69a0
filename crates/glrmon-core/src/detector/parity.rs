//! The parity-space detector: residuals from the parity relations of a window of s + 1
//! samples (Ahmad & Mohd-Mokhtar 2021, eqs. (4)-(8)).
//!
//! The survey writes x(k+1) = Ax + Bu + E_d d + E_f f, y = Cx + Du + F_d d + F_f f; glrmon
//! writes A, B, C, D as F, G, H, J (Zhang & Basseville 2014), E_d as the unknown input E,
//! and its faults' columns Ψ (state) and Φ (output) are E_f and F_f. Over the window
//! k − s … k the stacked outputs obey the parity relation (4)
//!
//! ```text
//! Y_s(k) = H_{o,s} X_{k−s} + H_{u,s} U_s(k) + H_{d,s} D_s(k) + H_{w,s} W_s(k) + V_s(k)
//! ```
//!
//! with H_{o,s} the stacked H_i Φ(i, k−s), H_{u,s} (and H_{d,s}, with E_d and F_d in place
//! of G and J) the block Toeplitz matrix of the survey, and H_{w,s} the same for the
//! process noise (E = I, F = 0): built from the matrices of each sample of the window,
//! so an LTV or LPV model has its time-varying H_{o,s}. A parity matrix M with
//! M[H_{o,s} H_{d,s}] = 0 gives the residual (5)
//!
//! ```text
//! r(k) = M (Y_s(k) − H_{u,s} U_s(k)) = M (H_{w,s} W_s + V_s + H_{f,s} F_s)
//! ```
//!
//! free of the unknown initial state and, when such an M exists (perfect decoupling),
//! of the disturbance. M is an orthonormal basis of the left null space of
//! [H_{o,s} H_{d,s}] (a Householder QR with column pivoting decides its rank), so the
//! parity space has dimension (s + 1)p − rank [H_{o,s} H_{d,s}]. Where no M decouples
//! the disturbance, the optimal parity vector of (7) is used instead: among the parity
//! vectors of H_{o,s}, the v minimising ‖vH_{d,s}‖/‖vH_{f,s}‖, the generalised
//! eigenvector of the pencil (M_oH_fH_fᵀM_oᵀ, M_oH_dH_dᵀM_oᵀ) of largest eigenvalue
//! (LTI models only).
//!
//! The record's residual is the window's outputs minus their best fit by the model
//! from an unknown initial state (and disturbance): MᵀM(Y_s − H_{u,s}U_s), the
//! orthogonal projection on the parity space, (s + 1)p values in output units, which
//! does not depend on the basis chosen for M; with the optimal vector, the scalar
//! v(Y_s − H_{u,s}U_s).
//!
//! Evaluation: rᵀΣ_r⁻¹r with Σ_r = M Σ_Y Mᵀ the residual's covariance under the noise
//! model (Σ_Y = H_{w,s}Q_sH_{w,s}ᵀ + R_s + the cross terms of S = E(WVᵀ)), χ² with
//! dim M degrees of freedom under no fault; or the windowed energy of r (8), (12).
//! Consecutive residuals share s samples: they are correlated, so exceedances cluster
//! over s + 1 samples ([`Detector::memory`]).

use nalgebra::{DMatrix, DVector};

use crate::error::{ModelError, StepError};
use crate::linalg::{at, cholesky_in_place};
use crate::model::fault::{Column, FaultDictionary};
use crate::model::{Dims, Signals, StateSpace, SystemMatrices};

use super::evaluation::{EnergyWindow, Evaluation};
use super::{Detector, Sample, StepOutput, check_sample};

/// Default relative tolerance of the rank decision on [H_{o,s} H_{d,s}].
pub const DEFAULT_PARITY_RANK_TOLERANCE: f64 = 1e-9;

/// The parity detector's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParitySettings {
    /// s, the order: the window holds s + 1 samples.
    pub order: usize,
    /// How the residual becomes the decision statistic.
    pub evaluation: Evaluation,
    /// A column of [H_{o,s} H_{d,s}] whose remaining norm is below this fraction of
    /// the largest column norm adds no rank.
    pub rank_tolerance: f64,
}

/// The disturbance d of the survey's eqs. (1)-(2): E_d (n×q) on the state, F_d (p×q)
/// on the outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Disturbance {
    /// E_d, the disturbance's state columns.
    pub state: DMatrix<f64>,
    /// F_d, its output columns.
    pub output: DMatrix<f64>,
}

/// How the parity residual treats the disturbance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decoupling {
    /// No disturbance is modelled: M spans the left null space of H_{o,s}.
    NotNeeded,
    /// M[H_{o,s} H_{d,s}] = 0: the residual ignores any disturbance.
    Perfect,
    /// No parity vector decouples the disturbance: the optimal vector of eq. (7),
    /// whose ratio J_s = ‖vH_{d,s}‖/‖vH_{f,s}‖ is given.
    Optimal {
        /// J_s, the smallest ratio of the disturbance's to the faults' gain.
        ratio: f64,
    },
}

/// The parity space of an LTI model at order s, for `glrmon validate` and the
/// detector's construction.
#[derive(Debug, Clone)]
pub struct ParityDesign {
    /// s.
    pub order: usize,
    /// dim of the parity space of [H_{o,s} H_{d,s}] ((s + 1)p minus its rank).
    pub dimension: usize,
    /// dim of the parity space of H_{o,s} alone.
    pub state_free_dimension: usize,
    /// How the disturbance is treated.
    pub decoupling: Decoupling,
}

/// The parity-space detector (survey eqs. (4)-(8)).
///
/// # Examples
/// ```
/// use glrmon_core::detector::parity::{ParityDetector, ParitySettings};
/// use glrmon_core::detector::Evaluation;
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::{Detector, Lpv, Sample, StepOutput};
/// use nalgebra::{DMatrix, DVector};
/// let model = Lpv::lti(
///     DMatrix::from_row_slice(2, 2, &[0.5, 1.0, 0.0, 0.8]),
///     DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
///     DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
///     DMatrix::zeros(1, 1),
///     DMatrix::identity(2, 2) * 0.01,
///     DMatrix::from_element(1, 1, 0.01),
/// )
/// .unwrap();
/// let faults = FaultDictionary::new(
///     glrmon_core::StateSpace::dims(&model),
///     vec![Fault::output("bias", Onset::Step, Column::Constant(DVector::from_element(1, 1.0)))],
/// )
/// .unwrap();
/// let settings = ParitySettings { order: 2, evaluation: Evaluation::Chi2, rank_tolerance: 1e-9 };
/// let mut det = ParityDetector::new(Box::new(model), faults, None, None, settings).unwrap();
/// assert_eq!(det.residual_len(), 3);
/// let mut out = StepOutput::for_detector(&det);
/// for k in 0..3 {
///     det.step(&Sample { k, u: &[0.0], y: &[0.0], p: &[] }, &mut out).unwrap();
/// }
/// assert_eq!(out.glr, Some(0.0)); // x = 0 explains three zero outputs exactly
/// assert_eq!(out.onset, Some(0));
/// ```
#[derive(Debug)]
pub struct ParityDetector {
    model: Box<dyn StateSpace>,
    faults: FaultDictionary,
    dims: Dims,
    settings: ParitySettings,
    disturbance: Option<Disturbance>,
    cross: Option<DMatrix<f64>>,
    constant: bool,
    decoupling: Decoupling,
    /// The smallest order with a parity space (decoupled from the disturbance where
    /// one is, at k = 0), for reports.
    smallest: Option<usize>,
    /// (s + 1)p.
    rows: usize,
    /// Rows of M in use (the parity space's dimension, or 1 for the optimal vector).
    m_rows: usize,
    /// The window's matrices, oldest first once `filled` = s + 1 (a ring otherwise).
    systems: Vec<SystemMatrices>,
    /// Y_s and U_s, oldest sample first.
    ys: Vec<f64>,
    us: Vec<f64>,
    filled: usize,
    next_k: Option<u64>,
    /// Design of the current window: M (rows × rows, first `m_rows` rows used), H_{u,s},
    /// the Cholesky factor of Σ_r.
    m: DMatrix<f64>,
    hu: DMatrix<f64>,
    sigma_chol: DMatrix<f64>,
    scratch: Scratch,
    z: DVector<f64>,
    r: DVector<f64>,
    white: DVector<f64>,
    energy: EnergyWindow,
}

/// Buffers of the window's design (sized once).
#[derive(Debug)]
struct Scratch {
    /// [H_{o,s} H_{d,s}] (rows × cols), destroyed by the QR.
    a: DMatrix<f64>,
    /// Householder vectors and their β.
    v: DMatrix<f64>,
    beta: Vec<f64>,
    norms: Vec<f64>,
    /// H_{w,s} (rows × s·n) and H_{w,s}·blockdiag(Q).
    hw: DMatrix<f64>,
    hwq: DMatrix<f64>,
    /// Σ_Y (rows × rows).
    sigma_y: DMatrix<f64>,
    /// M Σ_Y (m_rows × rows).
    m_sigma: DMatrix<f64>,
    /// Transition products (n × max(n, l, q)).
    t: DMatrix<f64>,
    t2: DMatrix<f64>,
    e: DVector<f64>,
}

impl ParityDetector {
    /// A parity detector of order `settings.order` for `model`, decoupled from
    /// `disturbance` where it can be, with process/measurement cross-covariance
    /// `cross` (S, n×p) if the noises are correlated.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] for matrices of the wrong shape;
    /// [`ModelError::Setting`] for an order whose parity space is empty (naming the
    /// smallest order that has one, for LTI models), a disturbance no parity vector of
    /// an LTV model can be optimised against, or a residual covariance that is not
    /// positive definite (R singular in the parity directions).
    pub fn new(
        mut model: Box<dyn StateSpace>,
        faults: FaultDictionary,
        disturbance: Option<Disturbance>,
        cross: Option<DMatrix<f64>>,
        settings: ParitySettings,
    ) -> Result<Self, ModelError> {
        let dims = model.dims();
        let (n, l, p) = (dims.states, dims.inputs, dims.outputs);
        if let Some(d) = &disturbance {
            let q = d.state.ncols();
            if d.state.nrows() != n || d.output.shape() != (p, q) || q == 0 {
                return Err(ModelError::Dimension {
                    what: "disturbance",
                    detail: format!(
                        "E_d is {}×{} and F_d {}×{}: expected {n}×q and {p}×q with q ≥ 1",
                        d.state.nrows(),
                        d.state.ncols(),
                        d.output.nrows(),
                        d.output.ncols()
                    ),
                });
            }
            if d.state
                .iter()
                .chain(d.output.iter())
                .any(|x| !x.is_finite())
            {
                return Err(ModelError::NonFinite { what: "E_d, F_d" });
            }
        }
        if let Some(s) = &cross
            && s.shape() != (n, p)
        {
            return Err(ModelError::Dimension {
                what: "S",
                detail: format!("S is {}×{}, expected {n}×{p}", s.nrows(), s.ncols()),
            });
        }
        if faults.dims() != dims {
            return Err(ModelError::Dimension {
                what: "fault dictionary",
                detail: "built for other dimensions than the model's".into(),
            });
        }
        if matches!(settings.evaluation, Evaluation::Energy { window: 0 }) {
            return Err(ModelError::Setting {
                what: "energy_window",
                detail: "must be at least 1 sample".into(),
            });
        }
        if !(settings.rank_tolerance > 0.0 && settings.rank_tolerance < 1.0) {
            return Err(ModelError::Setting {
                what: "rank_tolerance",
                detail: format!("{} is not in (0, 1)", settings.rank_tolerance),
            });
        }
        let s = settings.order;
        let rows = (s + 1) * p;
        let q = disturbance.as_ref().map_or(0, |d| d.state.ncols());
        let cols = n + (s + 1) * q;
        let width = n.max(l).max(q).max(1);
        let constant = model.is_constant();
        // The design at k = 0 with zero signals: the LTI design, or an LTV model's
        // nominal one (its parity space's dimension and how d is decoupled).
        let mut systems: Vec<SystemMatrices> =
            (0..=s).map(|_| SystemMatrices::zeros(dims)).collect();
        let zero_u = vec![0.0; l];
        let zero_p = vec![0.0; dims.signals];
        let signals = Signals {
            u: &zero_u,
            p: &zero_p,
        };
        for sys in &mut systems {
            model.evaluate(0, &signals, sys);
        }
        if !systems[0].is_finite() {
            return Err(ModelError::NonFinite { what: "model" });
        }
        let mut this = Self {
            model,
            faults,
            dims,
            settings,
            disturbance,
            cross,
            constant,
            decoupling: Decoupling::NotNeeded,
            smallest: None,
            rows,
            m_rows: 0,
            systems,
            ys: vec![0.0; rows],
            us: vec![0.0; (s + 1) * l],
            filled: 0,
            next_k: None,
            m: DMatrix::zeros(rows, rows),
            hu: DMatrix::zeros(rows, (s + 1) * l),
            sigma_chol: DMatrix::zeros(rows, rows),
            scratch: Scratch {
                a: DMatrix::zeros(rows, cols),
                v: DMatrix::zeros(rows, cols.min(rows)),
                beta: vec![0.0; cols.min(rows)],
                norms: vec![0.0; cols],
                hw: DMatrix::zeros(rows, s * n),
                hwq: DMatrix::zeros(rows, s * n),
                sigma_y: DMatrix::zeros(rows, rows),
                m_sigma: DMatrix::zeros(rows, rows),
                t: DMatrix::zeros(n, width),
                t2: DMatrix::zeros(n, width),
                e: DVector::zeros(rows),
            },
            z: DVector::zeros(rows),
            r: DVector::zeros(rows),
            white: DVector::zeros(rows),
            energy: EnergyWindow::new(settings.evaluation.memory()),
        };
        this.design()?;
        Ok(this)
    }

    /// The smallest order whose parity space is not empty: decoupled from the
    /// disturbance when some order up to max(s, 4n + 4) decouples it, else of H_o,s
    /// alone (the model at k = 0).
    #[must_use]
    pub fn smallest_order(&self) -> Option<usize> {
        self.smallest
    }

    /// How the residual treats the disturbance.
    #[must_use]
    pub fn decoupling(&self) -> Decoupling {
        self.decoupling
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> ParitySettings {
        self.settings
    }

    /// The χ² degrees of freedom of rᵀΣ_r⁻¹r: the parity space's dimension (1 with
    /// the optimal vector).
    #[must_use]
    pub fn dof(&self) -> usize {
        self.m_rows
    }

    /// Builds M, H_{u,s} and chol Σ_r from `systems` (all equal: the design at
    /// k = 0), deciding the parity space's dimension and the decoupling.
    fn design(&mut self) -> Result<ParityDesign, ModelError> {
        let n = self.dims.states;
        let s = self.settings.order;
        let tol = self.settings.rank_tolerance;
        let q = self.disturbance.as_ref().map_or(0, |d| d.state.ncols());
        let state_free_dimension = parity_dimension(&self.systems[0], None, s, tol);
        if state_free_dimension == 0 {
            let max = (s + 4 * n + 4).min(64);
            return Err(ModelError::Setting {
                what: "parity order",
                detail: match smallest_order(&self.systems[0], None, max, tol) {
                    Some(o) => format!(
                        "s = {s} gives no parity space ((s + 1)p = {} rows, all reached by \
                         the initial state): the smallest order that gives one is {o}",
                        self.rows
                    ),
                    None => format!("no order up to {max} gives a parity space"),
                },
            });
        }
        // Only up to the configured order: the search costs a QR per order, and an
        // order above s that decoupled d would not change this detector.
        let max = s;
        self.smallest = self
            .disturbance
            .as_ref()
            .and_then(|d| smallest_order(&self.systems[0], Some(d), max, tol))
            .or_else(|| smallest_order(&self.systems[0], None, max, tol));
        self.build_blocks();
        let rank = self.null_space();
        let dimension = self.rows - rank;
        if dimension > 0 {
            self.m_rows = dimension;
            if q > 0 {
                self.decoupling = Decoupling::Perfect;
            }
        } else if self.disturbance.is_none() {
            return Err(ModelError::Setting {
                what: "parity order",
                detail: format!(
                    "s = {s}: the parity space is empty at the rank tolerance {tol:e} (a rank \
                     decision at the tolerance's edge): raise the order"
                ),
            });
        } else if self.constant {
            let ratio = self.optimal_vector()?;
            self.decoupling = Decoupling::Optimal { ratio };
            self.m_rows = 1;
        } else {
            return Err(ModelError::Setting {
                what: "parity decoupling",
                detail: format!(
                    "no parity vector of order {s} decouples the disturbance, and the \
                     optimal vector of eq. (7) is offered for LTI models only: raise the \
                     order (the smallest with perfect decoupling at k = 0: {})",
                    smallest_order(
                        &self.systems[0],
                        self.disturbance.as_ref(),
                        (s + 4 * n + 4).min(64),
                        tol
                    )
                    .map_or_else(|| "none up to 64".to_owned(), |o| o.to_string())
                ),
            });
        }
        self.covariance()?;
        Ok(ParityDesign {
            order: s,
            dimension,
            state_free_dimension,
            decoupling: self.decoupling,
        })
    }

    fn probe_rank(a: &DMatrix<f64>, tol: f64) -> usize {
        let mut a = a.clone();
        let (rows, cols) = a.shape();
        let mut v = DMatrix::zeros(rows, cols.min(rows));
        let mut beta = vec![0.0; cols.min(rows)];
        let mut norms = vec![0.0; cols];
        householder_pivoted(&mut a, &mut v, &mut beta, &mut norms, tol)
    }

    /// Fills scratch.a = [H_{o,s} H_{d,s}], hu = H_{u,s} and scratch.hw = H_{w,s} from
    /// the window's matrices (`systems` oldest first). Allocation-free.
    #[allow(clippy::needless_range_loop)] // block indices name the window's samples
    fn build_blocks(&mut self) {
        let (n, l, p) = (self.dims.states, self.dims.inputs, self.dims.outputs);
        let s = self.settings.order;
        let rows = self.rows;
        let sc = &mut self.scratch;
        let sys = &self.systems;
        // H_{o,s}: block i = H_i Φ(i, 0), Φ(i, 0) = F_{i−1}⋯F_0.
        set_identity(&mut sc.t, n);
        for i in 0..=s {
            mul_into(&sys[i].h, &sc.t, n, &mut sc.a, i * p, 0);
            mul_square_in_place(&sys[i].f, &mut sc.t, &mut sc.t2, n);
        }
        toeplitz_into(sys, None, l, p, &mut self.hu, 0, &mut sc.t, &mut sc.t2);
        if let Some(d) = &self.disturbance {
            let q = d.state.ncols();
            toeplitz_into(
                sys,
                Some((&d.state, &d.output)),
                q,
                p,
                &mut sc.a,
                n,
                &mut sc.t,
                &mut sc.t2,
            );
        }
        // H_{w,s}: the noise W_{k−s+j} for j < s reaches row blocks i > j.
        for r in 0..rows {
            for c in 0..s * n {
                sc.hw[(r, c)] = 0.0;
            }
        }
        for j in 0..s {
            set_identity(&mut sc.t, n);
            for i in (j + 1)..=s {
                mul_into(&sys[i].h, &sc.t, n, &mut sc.hw, i * p, j * n);
                mul_square_in_place(&sys[i].f, &mut sc.t, &mut sc.t2, n);
            }
        }
    }

    /// M ← an orthonormal basis of the left null space of scratch.a (its first
    /// rows − rank rows); returns the rank. Allocation-free.
    fn null_space(&mut self) -> usize {
        let sc = &mut self.scratch;
        let rank = householder_pivoted(
            &mut sc.a,
            &mut sc.v,
            &mut sc.beta,
            &mut sc.norms,
            self.settings.rank_tolerance,
        );
        null_rows(&sc.v, &sc.beta, rank, &mut sc.e, &mut self.m);
        rank
    }

    /// The optimal parity vector of eq. (7) into M's first row; returns J_s.
    fn optimal_vector(&mut self) -> Result<f64, ModelError> {
        let s = self.settings.order;
        let rows = self.rows;
        let tol = self.settings.rank_tolerance;
        let sys = self.systems[0].clone();
        let Some(d) = self.disturbance.clone() else {
            return Err(ModelError::Setting {
                what: "parity decoupling",
                detail: "the optimal parity vector needs a disturbance".into(),
            });
        };
        let (ho, _, hd) = stacked(&sys, Some(&d), s);
        let hf = fault_toeplitz(&sys, &self.faults, s).ok_or_else(|| ModelError::Setting {
            what: "parity decoupling",
            detail: "no parity vector decouples the disturbance, and the optimal vector of \
                     eq. (7) needs constant fault columns (sensor, actuator bias or constant \
                     Ψ/Φ), which this dictionary does not have"
                .into(),
        })?;
        let mo = left_null_basis(&ho, tol);
        let a = &mo * &hd * hd.transpose() * mo.transpose();
        let b = &mo * &hf * hf.transpose() * mo.transpose();
        let chol = a.clone().cholesky().ok_or_else(|| ModelError::Setting {
            what: "parity decoupling",
            detail: "the disturbance's Gram matrix on the parity space is singular although \
                     no parity vector decouples it"
                .into(),
        })?;
        let l = chol.l();
        let linv = l
            .clone()
            .try_inverse()
            .expect("Cholesky factor is invertible");
        let c = &linv * &b * linv.transpose();
        let eig = c.symmetric_eigen();
        let (imax, lmax) = eig
            .eigenvalues
            .iter()
            .copied()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .expect("non-empty");
        if lmax <= 0.0 {
            return Err(ModelError::Setting {
                what: "parity decoupling",
                detail: "the faults do not reach the parity space at this order: no parity \
                         vector is sensitive to them"
                    .into(),
            });
        }
        let w = linv.transpose() * eig.eigenvectors.column(imax);
        let mut v = mo.transpose() * w;
        let norm = v.norm();
        v /= norm;
        for i in 0..rows {
            self.m[(0, i)] = v[i];
        }
        Ok(1.0 / lmax.sqrt())
    }

    /// Σ_Y of the window and chol(M Σ_Y Mᵀ) into sigma_chol. Allocation-free.
    #[allow(clippy::needless_range_loop)] // block indices name the window's samples
    fn covariance(&mut self) -> Result<(), ModelError> {
        let (n, p) = (self.dims.states, self.dims.outputs);
        let s = self.settings.order;
        let rows = self.rows;
        let mr = self.m_rows;
        let sc = &mut self.scratch;
        let sys = &self.systems;
        // Σ_Y = R_s + H_w Q_s H_wᵀ + C + Cᵀ, C[i, j] = H_w[i, j] S for i > j.
        sc.sigma_y.fill(0.0);
        for i in 0..=s {
            for a in 0..p {
                for b in 0..p {
                    sc.sigma_y[(i * p + a, i * p + b)] = sys[i].r[(a, b)];
                }
            }
        }
        for j in 0..s {
            for r in 0..rows {
                for c in 0..n {
                    let mut acc = 0.0;
                    for t in 0..n {
                        acc += sc.hw[(r, j * n + t)] * sys[j].q[(t, c)];
                    }
                    sc.hwq[(r, j * n + c)] = acc;
                }
            }
        }
        for a in 0..rows {
            for b in 0..rows {
                let mut acc = 0.0;
                for c in 0..s * n {
                    acc += sc.hwq[(a, c)] * sc.hw[(b, c)];
                }
                sc.sigma_y[(a, b)] += acc;
            }
        }
        if let Some(cross) = &self.cross {
            for i in 0..=s {
                for j in 0..i {
                    for a in 0..p {
                        for b in 0..p {
                            let mut acc = 0.0;
                            for t in 0..n {
                                acc += sc.hw[(i * p + a, j * n + t)] * cross[(t, b)];
                            }
                            sc.sigma_y[(i * p + a, j * p + b)] += acc;
                            sc.sigma_y[(j * p + b, i * p + a)] += acc;
                        }
                    }
                }
            }
        }
        for a in 0..mr {
            for b in 0..rows {
                let mut acc = 0.0;
                for c in 0..rows {
                    acc += self.m[(a, c)] * sc.sigma_y[(c, b)];
                }
                sc.m_sigma[(a, b)] = acc;
            }
        }
        let chol = self.sigma_chol.as_mut_slice();
        for a in 0..mr {
            for b in 0..mr {
                let mut acc = 0.0;
                for c in 0..rows {
                    acc += sc.m_sigma[(a, c)] * self.m[(b, c)];
                }
                chol[at(mr, a, b)] = acc;
            }
        }
        if cholesky_in_place(&mut chol[..mr * mr], mr) {
            Ok(())
        } else {
            Err(ModelError::Setting {
                what: "parity residual covariance",
                detail: "M Σ_Y Mᵀ is not positive definite: the noise model leaves a parity \
                         direction without noise (R singular?)"
                    .into(),
            })
        }
    }

    /// Shifts the window by one sample and stores sample k's data and matrices.
    fn push_sample(&mut self, sample: &Sample<'_>) {
        let (l, p) = (self.dims.inputs, self.dims.outputs);
        let s = self.settings.order;
        if self.filled == s + 1 {
            self.ys.copy_within(p.., 0);
            self.us.copy_within(l.., 0);
            if !self.constant {
                self.systems.rotate_left(1);
            }
        } else {
            self.filled += 1;
        }
        let slot = self.filled - 1;
        self.ys[slot * p..(slot + 1) * p].copy_from_slice(sample.y);
        self.us[slot * l..(slot + 1) * l].copy_from_slice(sample.u);
        if !self.constant {
            let signals = Signals {
                u: sample.u,
                p: sample.p,
            };
            self.model
                .evaluate(sample.k, &signals, &mut self.systems[slot]);
        }
    }
}

/// The left null space's dimension of [H_{o,s} H_{d,s}] for an LTI model's matrices
/// at order s: what `glrmon validate` reports, and 0 when the order is too small.
#[must_use]
pub fn parity_dimension(
    sys: &SystemMatrices,
    disturbance: Option<&Disturbance>,
    order: usize,
    tolerance: f64,
) -> usize {
    let (ho, _, hd) = stacked(sys, disturbance, order);
    let a = if hd.ncols() > 0 {
        let mut a = DMatrix::zeros(ho.nrows(), ho.ncols() + hd.ncols());
        a.columns_mut(0, ho.ncols()).copy_from(&ho);
        a.columns_mut(ho.ncols(), hd.ncols()).copy_from(&hd);
        a
    } else {
        ho
    };
    a.nrows() - ParityDetector::probe_rank(&a, tolerance)
}

/// The smallest order s ≤ `max_order` whose parity space is not empty (decoupled from
/// the disturbance if one is given).
#[must_use]
pub fn smallest_order(
    sys: &SystemMatrices,
    disturbance: Option<&Disturbance>,
    max_order: usize,
    tolerance: f64,
) -> Option<usize> {
    (0..=max_order).find(|&s| parity_dimension(sys, disturbance, s, tolerance) > 0)
}

/// H_{o,s}, H_{u,s} and H_{d,s} of LTI matrices, straight from their definitions
/// (allocating: construction, validation and tests).
#[must_use]
#[allow(clippy::needless_range_loop)] // block indices name the window's samples
pub fn stacked(
    sys: &SystemMatrices,
    disturbance: Option<&Disturbance>,
    s: usize,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let p = sys.h.nrows();
    let mut powers = vec![DMatrix::identity(sys.f.nrows(), sys.f.nrows())];
    for i in 1..=s {
        let next = &sys.f * &powers[i - 1];
        powers.push(next);
    }
    let mut ho = DMatrix::zeros((s + 1) * p, sys.f.nrows());
    for i in 0..=s {
        ho.rows_mut(i * p, p).copy_from(&(&sys.h * &powers[i]));
    }
    let toeplitz = |b: &DMatrix<f64>, d: &DMatrix<f64>| {
        let w = b.ncols();
        let mut t = DMatrix::zeros((s + 1) * p, (s + 1) * w);
        for i in 0..=s {
            for j in 0..=i {
                let block = if i == j {
                    d.clone()
                } else {
                    &sys.h * &powers[i - j - 1] * b
                };
                t.view_mut((i * p, j * w), (p, w)).copy_from(&block);
            }
        }
        t
    };
    let hu = toeplitz(&sys.g, &sys.j);
    let hd = disturbance.map_or_else(
        || DMatrix::zeros((s + 1) * p, 0),
        |d| toeplitz(&d.state, &d.output),
    );
    (ho, hu, hd)
}

/// H_{f,s} of the dictionary's constant columns (Ψ as E_f, Φ as F_f), `None` when a
/// column changes with the sample.
fn fault_toeplitz(
    sys: &SystemMatrices,
    faults: &FaultDictionary,
    s: usize,
) -> Option<DMatrix<f64>> {
    let (n, p) = (sys.f.nrows(), sys.h.nrows());
    let m = faults.len();
    let mut ef = DMatrix::zeros(n, m);
    let mut ff = DMatrix::zeros(p, m);
    for (j, fault) in faults.faults().iter().enumerate() {
        match &fault.state {
            Column::Zero => {}
            Column::Constant(v) => ef.column_mut(j).copy_from(v),
            Column::InputBias { input } => ef.column_mut(j).copy_from(&sys.g.column(*input)),
            _ => return None,
        }
        match &fault.output {
            Column::Zero => {}
            Column::Constant(v) => ff.column_mut(j).copy_from(v),
            _ => return None,
        }
    }
    let d = Disturbance {
        state: ef,
        output: ff,
    };
    Some(stacked(sys, Some(&d), s).2)
}

/// Householder QR with column pivoting of `a` (rows × cols) in place: the Householder
/// vectors go to `v`'s columns (v_j[j] = 1), their β to `beta`; stops when the largest
/// remaining column norm falls below `tol` times the largest initial one. Returns the
/// rank. Allocation-free.
fn householder_pivoted(
    a: &mut DMatrix<f64>,
    v: &mut DMatrix<f64>,
    beta: &mut [f64],
    norms: &mut [f64],
    tol: f64,
) -> usize {
    let (rows, cols) = a.shape();
    let steps = rows.min(cols);
    let mut largest = 0.0f64;
    for c in 0..cols {
        let mut acc = 0.0;
        for r in 0..rows {
            acc += a[(r, c)] * a[(r, c)];
        }
        norms[c] = acc.sqrt();
        largest = largest.max(norms[c]);
    }
    if largest == 0.0 {
        return 0;
    }
    let floor = tol * largest;
    for j in 0..steps {
        // Pivot: the column of largest remaining norm (recomputed: exact, and cheap
        // at these sizes).
        let mut best = j;
        let mut best_norm = -1.0;
        for c in j..cols {
            let mut acc = 0.0;
            for r in j..rows {
                acc += a[(r, c)] * a[(r, c)];
            }
            norms[c] = acc.sqrt();
            if norms[c] > best_norm {
                best_norm = norms[c];
                best = c;
            }
        }
        if best_norm <= floor {
            return j;
        }
        if best != j {
            a.swap_columns(j, best);
        }
        let alpha = a[(j, j)];
        let sigma = if alpha >= 0.0 { -best_norm } else { best_norm };
        // v = x − σe₁, scaled so v[j] = 1; β = 2/(vᵀv).
        let v0 = alpha - sigma;
        let mut vtv = 1.0;
        v[(j, j)] = 1.0;
        for r in (j + 1)..rows {
            let x = a[(r, j)] / v0;
            v[(r, j)] = x;
            vtv += x * x;
        }
        for r in 0..j {
            v[(r, j)] = 0.0;
        }
        beta[j] = 2.0 / vtv;
        a[(j, j)] = sigma;
        for r in (j + 1)..rows {
            a[(r, j)] = 0.0;
        }
        for c in (j + 1)..cols {
            let mut dot = 0.0;
            for r in j..rows {
                dot += v[(r, j)] * a[(r, c)];
            }
            let f = beta[j] * dot;
            for r in j..rows {
                a[(r, c)] -= f * v[(r, j)];
            }
        }
    }
    steps
}

/// Rows of `m` ← the left null space's orthonormal basis of a matrix whose pivoted QR
/// left Householder vectors `v`, `beta` and `rank`: row t is (Q e_{rank+t})ᵀ with
/// Q = H_0 H_1 ⋯ H_{rank−1}. Allocation-free (`e` is scratch of the rows' length).
fn null_rows(
    v: &DMatrix<f64>,
    beta: &[f64],
    rank: usize,
    e: &mut DVector<f64>,
    m: &mut DMatrix<f64>,
) {
    let rows = v.nrows();
    for t in 0..rows - rank {
        e.fill(0.0);
        e[rank + t] = 1.0;
        for j in (0..rank).rev() {
            let mut dot = 0.0;
            for i in j..rows {
                dot += v[(i, j)] * e[i];
            }
            let f = beta[j] * dot;
            for i in j..rows {
                e[i] -= f * v[(i, j)];
            }
        }
        for i in 0..rows {
            m[(t, i)] = e[i];
        }
    }
}

/// An orthonormal basis (as rows) of the left null space of `a` (allocating).
#[must_use]
pub fn left_null_basis(a: &DMatrix<f64>, tolerance: f64) -> DMatrix<f64> {
    let mut work = a.clone();
    let (rows, cols) = a.shape();
    let mut v = DMatrix::zeros(rows, cols.min(rows));
    let mut beta = vec![0.0; cols.min(rows)];
    let mut norms = vec![0.0; cols];
    let rank = householder_pivoted(&mut work, &mut v, &mut beta, &mut norms, tolerance);
    let mut m = DMatrix::zeros(rows, rows);
    let mut e = DVector::zeros(rows);
    null_rows(&v, &beta, rank, &mut e, &mut m);
    m.rows(0, rows - rank).into_owned()
}

/// The block Toeplitz matrix of the survey's H_{u,s} into `out`'s columns from
/// `col0`: column block j holds, in row block j, the direct term (J_j, or F_d) and, in
/// row blocks i > j, H_i Φ(i, j + 1) B_j with B_j = G_j (or E_d). Allocation-free.
#[allow(clippy::too_many_arguments)]
fn toeplitz_into(
    sys: &[SystemMatrices],
    fixed: Option<(&DMatrix<f64>, &DMatrix<f64>)>,
    width: usize,
    p: usize,
    out: &mut DMatrix<f64>,
    col0: usize,
    t: &mut DMatrix<f64>,
    t2: &mut DMatrix<f64>,
) {
    let blocks = sys.len();
    let rows = out.nrows();
    for r in 0..rows {
        for c in 0..blocks * width {
            out[(r, col0 + c)] = 0.0;
        }
    }
    if width == 0 {
        return;
    }
    for j in 0..blocks {
        let (b, direct) = fixed.unwrap_or((&sys[j].g, &sys[j].j));
        let n = b.nrows();
        for r in 0..p {
            for c in 0..width {
                out[(j * p + r, col0 + j * width + c)] = direct[(r, c)];
            }
        }
        for r in 0..n {
            for c in 0..width {
                t[(r, c)] = b[(r, c)];
            }
        }
        for (i, sys_i) in sys.iter().enumerate().skip(j + 1) {
            mul_into(&sys_i.h, t, width, out, i * p, col0 + j * width);
            mul_square_in_place(&sys_i.f, t, t2, width);
        }
    }
}

fn set_identity(t: &mut DMatrix<f64>, n: usize) {
    for c in 0..t.ncols() {
        for r in 0..n {
            t[(r, c)] = if r == c && c < n { 1.0 } else { 0.0 };
        }
    }
}

/// out[row0.., col0..] = H (p×n) · T[:, ..width] (n × width).
fn mul_into(
    h: &DMatrix<f64>,
    t: &DMatrix<f64>,
    width: usize,
    out: &mut DMatrix<f64>,
    row0: usize,
    col0: usize,
) {
    let (p, n) = h.shape();
    for c in 0..width {
        for r in 0..p {
            let mut acc = 0.0;
            for i in 0..n {
                acc += h[(r, i)] * t[(i, c)];
            }
            out[(row0 + r, col0 + c)] = acc;
        }
    }
}

/// T[:, ..width] ← F · T[:, ..width], through `t2`.
fn mul_square_in_place(
    f: &DMatrix<f64>,
    t: &mut DMatrix<f64>,
    t2: &mut DMatrix<f64>,
    width: usize,
) {
    let n = f.nrows();
    for c in 0..width {
        for r in 0..n {
            let mut acc = 0.0;
            for i in 0..n {
                acc += f[(r, i)] * t[(i, c)];
            }
            t2[(r, c)] = acc;
        }
    }
    for c in 0..width {
        for r in 0..n {
            t[(r, c)] = t2[(r, c)];
        }
    }
}

impl Detector for ParityDetector {
    fn kind(&self) -> &'static str {
        "parity"
    }

    fn describe(&self) -> String {
        let decoupling = match self.decoupling {
            Decoupling::NotNeeded => String::new(),
            Decoupling::Perfect => ", disturbance decoupled".to_owned(),
            Decoupling::Optimal { ratio } => {
                format!(", optimal parity vector (J_s = {ratio:.3e})")
            }
        };
        let evaluation = match self.settings.evaluation {
            Evaluation::Chi2 => format!("χ²({}) of rᵀΣ_r⁻¹r", self.m_rows),
            Evaluation::Energy { window } => format!("energy over {window} samples"),
        };
        let smallest = self.smallest.map_or_else(String::new, |o| {
            format!("; the smallest order with one is {o}")
        });
        format!(
            "parity space of order {} (dimension {}{decoupling}{smallest}), {evaluation}",
            self.settings.order, self.m_rows
        )
    }

    fn memory(&self) -> usize {
        self.settings.order + self.settings.evaluation.memory()
    }

    fn dims(&self) -> Dims {
        self.dims
    }

    fn faults(&self) -> &FaultDictionary {
        &self.faults
    }

    fn unknown_inputs(&self) -> usize {
        self.disturbance.as_ref().map_or(0, |d| d.state.ncols())
    }

    fn next_index(&self) -> Option<u64> {
        self.next_k
    }

    fn step(&mut self, sample: &Sample<'_>, out: &mut StepOutput) -> Result<(), StepError> {
        check_sample(self.dims, self.next_k, sample)?;
        self.push_sample(sample);
        self.next_k = Some(sample.k + 1);
        out.k = sample.k;
        out.rank = self.m_rows;
        out.magnitude.fill(0.0);
        let s = self.settings.order;
        if self.filled < s + 1 {
            out.glr = None;
            out.onset = None;
            out.normalized_innovation = 0.0;
            out.residual.fill(0.0);
            return Ok(());
        }
        if !self.constant {
            if !self.systems.iter().all(SystemMatrices::is_finite) {
                return Err(StepError::Numerical {
                    what: "the model's matrices over the parity window are not finite",
                });
            }
            self.build_blocks();
            let rank = self.null_space();
            if self.rows - rank != self.m_rows {
                self.filled = 0;
                return Err(StepError::Numerical {
                    what: "the parity space's dimension changed with the model's matrices",
                });
            }
            if self.covariance().is_err() {
                self.filled = 0;
                return Err(StepError::Numerical {
                    what: "the parity residual's covariance is not positive definite",
                });
            }
        }
        let (l, rows, mr) = (self.dims.inputs, self.rows, self.m_rows);
        let cols_u = (s + 1) * l;
        for i in 0..rows {
            let mut acc = self.ys[i];
            for c in 0..cols_u {
                acc -= self.hu[(i, c)] * self.us[c];
            }
            self.z[i] = acc;
        }
        let mut energy = 0.0;
        for a in 0..mr {
            let mut acc = 0.0;
            for c in 0..rows {
                acc += self.m[(a, c)] * self.z[c];
            }
            self.r[a] = acc;
            self.white[a] = acc;
            energy += acc * acc;
        }
        let chol = self.sigma_chol.as_slice();
        for i in 0..mr {
            let mut acc = self.white[i];
            for t in 0..i {
                acc -= chol[at(mr, i, t)] * self.white[t];
            }
            self.white[i] = acc / chol[at(mr, i, i)];
        }
        let chi2: f64 = (0..mr).map(|i| self.white[i] * self.white[i]).sum();
        out.normalized_innovation = chi2;
        match self.decoupling {
            Decoupling::Optimal { .. } => out.residual[0] = self.r[0],
            _ => {
                for c in 0..rows {
                    let mut acc = 0.0;
                    for a in 0..mr {
                        acc += self.m[(a, c)] * self.r[a];
                    }
                    out.residual[c] = acc;
                }
            }
        }
        let first = sample.k - s as u64;
        match self.settings.evaluation {
            Evaluation::Chi2 => {
                out.glr = Some(chi2);
                out.onset = Some(first);
            }
            Evaluation::Energy { window } => {
                out.glr = self.energy.push(energy);
                out.onset = out.glr.map(|_| first.saturating_sub(window as u64 - 1));
            }
        }
        Ok(())
    }

    fn predict_only(&mut self, k: u64) -> Result<(), StepError> {
        if let Some(next) = self.next_k
            && k != next
        {
            return Err(StepError::OutOfOrder {
                expected: next,
                got: k,
            });
        }
        // The missing sample would sit in the next s windows: they start afresh
        // after it.
        self.filled = 0;
        self.energy.clear();
        self.next_k = Some(k + 1);
        Ok(())
    }

    fn restart(&mut self) -> Result<(), ModelError> {
        self.filled = 0;
        self.energy.clear();
        self.next_k = None;
        Ok(())
    }

    fn innovation_len(&self) -> usize {
        0
    }

    fn residual_len(&self) -> usize {
        match self.decoupling {
            Decoupling::Optimal { .. } => 1,
            _ => self.rows,
        }
    }

    fn estimates_magnitude(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::fault::{Fault, Onset};
    use crate::model::{Lpv, LpvMatrix};
    use crate::sparse::test_rng::Rng;
    use crate::threshold::chi2_upper_quantile;

    fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(rows, cols, v)
    }

    /// The unstable plant of Zhang & Basseville 2014, §6.1 (n = 2, p = 1).
    fn plant() -> Lpv {
        Lpv::lti(
            m(2, 2, &[0.5, 1.0, 0.0, 1.2]),
            m(2, 1, &[0.0, 1.0]),
            m(1, 2, &[1.0, 0.0]),
            DMatrix::zeros(1, 1),
            DMatrix::identity(2, 2) * 0.0025,
            DMatrix::from_element(1, 1, 0.0025),
        )
        .unwrap()
    }

    /// The survey's DC motor (Ahmad & Mohd-Mokhtar 2021, §DC motor), with its
    /// measurement noise σ_v² = 0.0025, σ_ω² = 0.0012 and a small process noise.
    fn dc_motor() -> Lpv {
        Lpv::lti(
            m(2, 2, &[0.2231, 0.0109, -0.0022, 0.5488]),
            m(2, 1, &[0.0047, 0.4512]),
            DMatrix::identity(2, 2),
            DMatrix::zeros(2, 1),
            DMatrix::identity(2, 2) * 1e-4,
            DMatrix::from_diagonal(&DVector::from_vec(vec![0.0025, 0.0012])),
        )
        .unwrap()
    }

    fn bias(dims: Dims, output: usize) -> FaultDictionary {
        let mut phi = DVector::zeros(dims.outputs);
        phi[output] = 1.0;
        FaultDictionary::new(
            dims,
            vec![Fault::output("bias", Onset::Step, Column::Constant(phi))],
        )
        .unwrap()
    }

    fn settings(order: usize) -> ParitySettings {
        ParitySettings {
            order,
            evaluation: Evaluation::Chi2,
            rank_tolerance: DEFAULT_PARITY_RANK_TOLERANCE,
        }
    }

    fn detector(model: Lpv, order: usize) -> ParityDetector {
        let faults = bias(model.dims(), 0);
        ParityDetector::new(Box::new(model), faults, None, None, settings(order)).unwrap()
    }

    fn lti_matrices(model: &mut Lpv) -> SystemMatrices {
        let dims = model.dims();
        let mut sys = SystemMatrices::zeros(dims);
        let (u, p) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
        model.evaluate(0, &Signals { u: &u, p: &p }, &mut sys);
        sys
    }

    /// The parity matrix against its definition (survey, eq. (5) and P_s): M H_{o,s} = 0
    /// with H_{o,s} built directly as [C; CA; …; CA^s], MMᵀ = I, and the parity space's
    /// dimension (s + 1)p − n for an observable pair; an order too small is refused
    /// naming the smallest that works.
    #[test]
    fn the_parity_matrix_annihilates_the_observability_matrix() {
        let mut model = dc_motor();
        let sys = lti_matrices(&mut model);
        assert_eq!(detector(dc_motor(), 3).smallest_order(), Some(1));
        assert_eq!(detector(plant(), 4).smallest_order(), Some(2));
        for s in 1..4 {
            let det = detector(dc_motor(), s);
            let (ho, _, _) = stacked(&sys, None, s);
            let rows = det.dof();
            assert_eq!(rows, (s + 1) * 2 - 2, "s = {s}");
            let mm = det.m.rows(0, rows).into_owned();
            assert!((&mm * &ho).amax() < 1e-12, "s = {s}");
            let gram = &mm * mm.transpose();
            assert!((gram - DMatrix::identity(rows, rows)).amax() < 1e-12);
        }
        assert!(
            ParityDetector::new(
                Box::new(dc_motor()),
                bias(dc_motor().dims(), 0),
                None,
                None,
                settings(0)
            )
            .is_err()
        );
        let err = ParityDetector::new(
            Box::new(plant()),
            bias(plant().dims(), 0),
            None,
            None,
            settings(1),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("s = 1 gives no parity space")
                && err.contains("smallest order that gives one is 2"),
            "{err}"
        );
        let mut p = plant();
        let sys = lti_matrices(&mut p);
        assert_eq!(smallest_order(&sys, None, 10, 1e-9), Some(2));
        assert_eq!(parity_dimension(&sys, None, 4, 1e-9), 3);
    }

    /// Survey, eq. (5): on noise-free, fault-free data the residual is zero, here for
    /// an LPV model whose F and H change with a scheduling signal at every sample
    /// (time-varying H_{o,s}), driven by a random input.
    #[test]
    fn the_residual_of_an_ltv_model_is_zero_on_noise_free_fault_free_data() {
        let lpv = Lpv::new(
            LpvMatrix::new(
                m(2, 2, &[0.6, 0.3, -0.2, 0.7]),
                vec![(0, m(2, 2, &[0.2, 0.0, 0.1, -0.1]))],
            )
            .unwrap(),
            LpvMatrix::constant(m(2, 1, &[0.5, 1.0])),
            LpvMatrix::new(
                m(2, 2, &[1.0, 0.0, 0.3, 1.0]),
                vec![(0, m(2, 2, &[0.0, 0.5, 0.0, 0.0]))],
            )
            .unwrap(),
            LpvMatrix::constant(m(2, 1, &[0.1, 0.0])),
            LpvMatrix::constant(DMatrix::identity(2, 2) * 0.01),
            LpvMatrix::constant(DMatrix::identity(2, 2) * 0.01),
            1,
        )
        .unwrap();
        let mut truth = lpv.clone();
        let dims = lpv.dims();
        let mut det =
            ParityDetector::new(Box::new(lpv), bias(dims, 1), None, None, settings(2)).unwrap();
        assert_eq!(det.dof(), 4);
        let mut out = StepOutput::for_detector(&det);
        let mut rng = Rng::new(7);
        let mut x = DVector::from_vec(vec![3.0, -2.0]);
        let mut sys = SystemMatrices::zeros(dims);
        let mut worst: f64 = 0.0;
        let mut largest_y: f64 = 0.0;
        for k in 0..2000u64 {
            let u = [rng.normal() * 2.0];
            let p = [(k as f64 * 0.07).sin()];
            truth.evaluate(k, &Signals { u: &u, p: &p }, &mut sys);
            let y = &sys.h * &x + &sys.j * DVector::from_row_slice(&u);
            largest_y = largest_y.max(y.amax());
            det.step(
                &Sample {
                    k,
                    u: &u,
                    y: y.as_slice(),
                    p: &p,
                },
                &mut out,
            )
            .unwrap();
            if k >= 2 {
                worst = worst.max(out.residual.amax());
                assert!(out.glr.unwrap() < 1e-16, "k = {k}: {:?}", out.glr);
            }
            x = &sys.f * &x + &sys.g * DVector::from_row_slice(&u);
        }
        assert!(
            worst < 1e-12 * largest_y.max(1.0),
            "worst residual {worst:e}"
        );
    }

    fn noisy_run(
        det: &mut ParityDetector,
        model: &mut Lpv,
        samples: u64,
        seed: u64,
        fault: impl Fn(u64) -> f64,
    ) -> (Vec<f64>, Vec<DVector<f64>>) {
        let dims = model.dims();
        let sys = lti_matrices(model);
        let qc = sys.q.clone().cholesky().unwrap().l();
        let rc = sys.r.clone().cholesky().unwrap().l();
        let mut rng = Rng::new(seed);
        let mut x = DVector::zeros(dims.states);
        let mut out = StepOutput::for_detector(&*det);
        let (mut stats, mut residuals) = (Vec::new(), Vec::new());
        for k in 0..samples {
            let u = [(k as f64 * 0.05).sin()];
            let v = &rc * DVector::from_fn(dims.outputs, |_, _| rng.normal());
            let mut y = &sys.h * &x + &sys.j * DVector::from_row_slice(&u) + v;
            y[0] += fault(k);
            det.step(
                &Sample {
                    k,
                    u: &u,
                    y: y.as_slice(),
                    p: &[],
                },
                &mut out,
            )
            .unwrap();
            if let Some(g) = out.glr {
                stats.push(g);
                residuals.push(out.residual.clone());
            }
            let w = &qc * DVector::from_fn(dims.states, |_, _| rng.normal());
            x = &sys.f * &x + &sys.g * DVector::from_row_slice(&u) + w;
        }
        (stats, residuals)
    }

    /// Under no fault rᵀΣ_r⁻¹r is χ²(dim M): its mean is the dimension and it exceeds
    /// the α = 0.01 quantile 1 % of the time (±30 %), over 40 000 samples of the survey's
    /// DC motor; and Σ_r (through the recorded projection MᵀM(Y − H_uU), whose
    /// covariance is MᵀΣ_rM) matches the empirical covariance.
    #[test]
    fn the_chi2_statistic_follows_its_law_under_no_fault() {
        let mut model = dc_motor();
        let mut det = detector(dc_motor(), 2);
        let dof = det.dof();
        assert_eq!(dof, 4);
        let n = 40_000;
        let (stats, residuals) = noisy_run(&mut det, &mut model, n, 11, |_| 0.0);
        let mean = stats.iter().sum::<f64>() / stats.len() as f64;
        assert!((mean / dof as f64 - 1.0).abs() < 0.03, "mean {mean}");
        let h = chi2_upper_quantile(dof as f64, 0.01).unwrap();
        let rate = stats.iter().filter(|&&s| s > h).count() as f64 / stats.len() as f64;
        assert!((rate / 0.01 - 1.0).abs() < 0.3, "exceedance rate {rate}");
        // Σ of the projection: MᵀΣ_rM, Σ_r = LLᵀ.
        let mr = det.dof();
        let l = DMatrix::from_fn(mr, mr, |i, j| {
            if j <= i {
                det.sigma_chol.as_slice()[at(mr, i, j)]
            } else {
                0.0
            }
        });
        let mm = det.m.rows(0, mr).into_owned();
        let expected = mm.transpose() * (&l * l.transpose()) * &mm;
        let rows = residuals[0].len();
        let mut empirical = DMatrix::zeros(rows, rows);
        for r in &residuals {
            empirical += r * r.transpose();
        }
        empirical /= residuals.len() as f64;
        let scale = expected.amax();
        assert!(
            (&empirical - &expected).amax() < 0.05 * scale,
            "empirical {empirical:.5} expected {expected:.5}"
        );
    }

    /// A sensor bias of 4σ on the speed sensor drives the statistic past the 10⁻⁴
    /// quantile within the window, and the onset is the window's first sample.
    #[test]
    fn a_sensor_bias_is_detected() {
        let mut model = dc_motor();
        let mut det = detector(dc_motor(), 2);
        let h = chi2_upper_quantile(det.dof() as f64, 1e-4).unwrap();
        let (stats, _) = noisy_run(&mut det, &mut model, 600, 3, |k| {
            if k >= 500 { 0.2 } else { 0.0 }
        });
        // stats[i] is the statistic at k = i + 2.
        assert!(stats[..496].iter().filter(|&&s| s > h).count() <= 1);
        let first = stats.iter().skip(498).position(|&s| s > h).map(|i| i + 500);
        assert!(first.is_some_and(|k| k <= 503), "first alarm at {first:?}");
    }

    /// Survey, eq. (6) and the rank condition M[H_{o,s} H_{d,s}] = 0: the DC motor's
    /// disturbance E_d = [−1.5537; 0] (F_d = 0) is perfectly decoupled at s = 1, so an
    /// arbitrary disturbance of any size leaves the residual unchanged to rounding.
    #[test]
    fn a_decoupled_disturbance_leaves_the_residual_unchanged() {
        let d = Disturbance {
            state: m(2, 1, &[-1.5537, 0.0]),
            output: DMatrix::zeros(2, 1),
        };
        let make = || {
            ParityDetector::new(
                Box::new(dc_motor()),
                bias(dc_motor().dims(), 1),
                Some(d.clone()),
                None,
                settings(1),
            )
            .unwrap()
        };
        let mut with = make();
        let mut without = make();
        assert_eq!(with.decoupling(), Decoupling::Perfect);
        let mut sys_model = dc_motor();
        let sys = lti_matrices(&mut sys_model);
        let (ho, _, hd) = stacked(&sys, Some(&d), 1);
        let mm = with.m.rows(0, with.dof()).into_owned();
        assert!((&mm * &ho).amax() < 1e-12 && (&mm * &hd).amax() < 1e-12);
        let mut rng = Rng::new(5);
        let (mut xa, mut xb) = (DVector::zeros(2), DVector::zeros(2));
        let (mut oa, mut ob) = (
            StepOutput::for_detector(&with),
            StepOutput::for_detector(&without),
        );
        for k in 0..500u64 {
            let u = [0.5];
            let noise = DVector::from_vec(vec![rng.normal() * 0.05, rng.normal() * 0.035]);
            let dk = 50.0 * (0.3 * k as f64).sin() + if k > 200 { 80.0 } else { 0.0 };
            let ya = &sys.h * &xa + &noise;
            let yb = &sys.h * &xb + &noise;
            with.step(
                &Sample {
                    k,
                    u: &u,
                    y: ya.as_slice(),
                    p: &[],
                },
                &mut oa,
            )
            .unwrap();
            without
                .step(
                    &Sample {
                        k,
                        u: &u,
                        y: yb.as_slice(),
                        p: &[],
                    },
                    &mut ob,
                )
                .unwrap();
            if k >= 1 {
                assert!(
                    (oa.glr.unwrap() - ob.glr.unwrap()).abs() < 1e-9 * (1.0 + ob.glr.unwrap()),
                    "k = {k}"
                );
                assert!((&oa.residual - &ob.residual).amax() < 1e-9);
            }
            let w = DVector::from_vec(vec![rng.normal() * 0.01, rng.normal() * 0.01]);
            xa = &sys.f * &xa + &sys.g * 0.5 + &d.state * dk + &w;
            xb = &sys.f * &xb + &sys.g * 0.5 + &w;
        }
    }

    /// Survey, eq. (7): where no parity vector decouples the disturbance, the optimal
    /// one minimises ‖vH_{d,s}‖/‖vH_{f,s}‖ over the parity space; checked against a
    /// brute-force search over the (two-dimensional) parity space of the §6.1 plant at
    /// s = 3.
    #[test]
    fn the_optimal_parity_vector_minimises_the_disturbance_to_fault_ratio() {
        let d = Disturbance {
            state: m(2, 1, &[1.0, 0.0]),
            output: m(1, 1, &[0.5]),
        };
        let det = ParityDetector::new(
            Box::new(plant()),
            bias(plant().dims(), 0),
            Some(d.clone()),
            None,
            settings(3),
        )
        .unwrap();
        let Decoupling::Optimal { ratio } = det.decoupling() else {
            panic!("expected the optimal vector, got {:?}", det.decoupling());
        };
        assert_eq!(det.residual_len(), 1);
        let mut p = plant();
        let sys = lti_matrices(&mut p);
        let (ho, _, hd) = stacked(&sys, Some(&d), 3);
        let hf = fault_toeplitz(&sys, &bias(plant().dims(), 0), 3).unwrap();
        let basis = left_null_basis(&ho, 1e-9);
        assert_eq!(basis.nrows(), 2);
        let v = det.m.row(0).into_owned();
        assert!((&v * &ho).amax() < 1e-10);
        let j = |v: &nalgebra::RowDVector<f64>| (v * &hd).norm() / (v * &hf).norm();
        assert!((j(&v) - ratio).abs() < 1e-9 * ratio);
        let brute = (0..20_000)
            .map(|i| {
                let a = std::f64::consts::PI * f64::from(i) / 20_000.0;
                let w = nalgebra::RowDVector::from_vec(vec![a.cos(), a.sin()]);
                j(&(w * &basis))
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            ratio <= brute * (1.0 + 1e-9) && ratio > brute * (1.0 - 1e-6),
            "{ratio} vs {brute}"
        );
    }

    /// The windowed energy (survey eq. (12)) equals the root of the last w squared
    /// residual norms, and its onset is the first sample of the oldest window.
    #[test]
    fn the_energy_evaluation_sums_the_windows_residuals() {
        let mut model = dc_motor();
        let faults = bias(dc_motor().dims(), 0);
        let mut energy = ParityDetector::new(
            Box::new(dc_motor()),
            faults,
            None,
            None,
            ParitySettings {
                evaluation: Evaluation::Energy { window: 10 },
                ..settings(2)
            },
        )
        .unwrap();
        assert_eq!(energy.memory(), 12);
        let mut chi2 = detector(dc_motor(), 2);
        let (e_stats, e_res) = noisy_run(&mut energy, &mut model, 200, 9, |_| 0.0);
        let (_, c_res) = noisy_run(&mut chi2, &mut model, 200, 9, |_| 0.0);
        assert_eq!(e_stats.len(), 200 - 2 - 9);
        for (i, j) in e_stats.iter().enumerate() {
            let direct: f64 = c_res[i..i + 10].iter().map(|r| r.norm_squared()).sum();
            assert!((j - direct.sqrt()).abs() < 1e-12 * (1.0 + j), "{i}");
            assert!((&e_res[i] - &c_res[i + 9]).amax() < 1e-15);
        }
    }

    /// Bad samples are refused with the state unchanged; a missing sample restarts
    /// the window.
    #[test]
    fn bad_samples_are_refused_and_gaps_restart_the_window() {
        let mut det = detector(dc_motor(), 1);
        let mut out = StepOutput::for_detector(&det);
        det.step(
            &Sample {
                k: 0,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
            &mut out,
        )
        .unwrap();
        assert!(
            det.step(
                &Sample {
                    k: 1,
                    u: &[0.5],
                    y: &[f64::NAN, 0.0],
                    p: &[]
                },
                &mut out
            )
            .is_err()
        );
        assert!(
            det.step(
                &Sample {
                    k: 2,
                    u: &[0.5],
                    y: &[0.0, 0.0],
                    p: &[]
                },
                &mut out
            )
            .is_err()
        );
        assert!(
            det.step(
                &Sample {
                    k: 1,
                    u: &[0.5],
                    y: &[0.0],
                    p: &[]
                },
                &mut out
            )
            .is_err()
        );
        det.step(
            &Sample {
                k: 1,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
            &mut out,
        )
        .unwrap();
        assert!(out.glr.is_some());
        det.predict_only(2).unwrap();
        det.step(
            &Sample {
                k: 3,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
            &mut out,
        )
        .unwrap();
        assert_eq!(out.glr, None);
        det.step(
            &Sample {
                k: 4,
                u: &[0.5],
                y: &[0.0, 0.0],
                p: &[],
            },
            &mut out,
        )
        .unwrap();
        assert_eq!(out.onset, Some(3));
    }
}
