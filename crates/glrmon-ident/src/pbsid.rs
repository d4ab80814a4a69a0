//! Predictor-based subspace identification (PBSID-opt): a VARX predictor estimated by
//! least squares, the extended observability × controllability product built from its
//! coefficients, an SVD for the state sequence, then the model by two least squares.
//! Consistent in closed loop, where PO-MOESP ([`Subspace`](crate::Subspace)) is biased.
//!
//! # Math
//! With z_k = [u_k; y_k], the innovation model written in predictor form is
//!
//! x_{k+1} = Ã x_k + B̃ z_k,   y_k = C x_k + D u_k + e_k,   Ã = A − KC,  B̃ = [B − KD, K],
//!
//! so that, for a past window p, x_k = Σ_{j=1..p} Ã^{j−1} B̃ z_{k−j} + Ã^p x_{k−p} and
//!
//! y_k = Σ_{j=1..p} Ξ_j z_{k−j} + D u_k + e_k + C Ã^p x_{k−p},   Ξ_j = C Ã^{j−1} B̃.
//!
//! 1. **VARX.** Ξ_1..Ξ_p and D by least squares of y_k on [z_{k−p}; …; z_{k−1}; u_k]. e_k
//!    is white and uncorrelated with the past z (whatever feedback produced the inputs),
//!    so the estimate is consistent in closed loop as long as u_k itself does not depend
//!    on e_k (a controller acting on y_{k−1}: D is estimated for every input here) and
//!    Ã^p is negligible (Chiuso 2007, *The role of vector autoregressive modeling in
//!    predictor-based subspace identification*, Automatica 43, 1034–1048, §3–4; Chiuso &
//!    Picci 2005, *Consistency analysis of some closed-loop subspace identification
//!    methods*, Automatica 41, 377–391).
//! 2. **Γ K.** The extended observability × controllability product Γ_f 𝒦_p, block row i
//!    (0 ≤ i < f), block column of lag j: C Ã^{i+j−1} B̃ = Ξ_{i+j} when i + j ≤ p, else 0
//!    (Ã^p ≈ 0). Its product with the past data, Γ_f 𝒦_p Z_p = Γ_f X, is factored by an
//!    SVD: the "optimised" PBSID of Chiuso (2007, §5), using one VARX for all block rows
//!    (van der Veen, van Wingerden, Bergamasco, Lovera & Verhaegen 2013, *Closed-loop
//!    subspace identification methods: an overview*, IET Control Theory Appl. 7(10),
//!    §4.3). With Z_p = R_pᵀ Q_pᵀ from the QR of the data, the SVD is that of
//!    Γ_f 𝒦_p R_pᵀ; for order n, x_k = Σ_n^{−1/2} U_nᵀ Γ_f 𝒦_p z̄_k (z̄_k the past window),
//!    a state basis in which the sample covariance of x is Σ_n.
//! 3. **C, D** by least squares of y_k on [x_k; u_k]; its residual is the innovation e_k.
//! 4. **A, B, K** by least squares of x_{k+1} on [x_k; u_k; e_k].
//!
//! The innovation covariance is Re = (1/N) Σ e_k e_kᵀ; the forward noise model is the
//! innovation form itself: Q = K Re Kᵀ, S = K Re, R = Re, whose Riccati solution is
//! P = 0 with gain K (the steady Kalman filter of an innovation model has no prediction
//! error in its state).
//!
//! Experiments are never joined: each contributes the rows k = p..N−1 of its own
//! regressions (a past window never spans two experiments), and the rows of all
//! experiments are stacked before every least squares.

use nalgebra::{DMatrix, DVector};

use crate::data::Experiment;
use crate::error::IdentError;
use crate::model::InnovationModel;
use crate::subspace::pinv;

/// Iteration cap of every SVD (as in [`Subspace`](crate::Subspace)).
const SVD_MAX_ITERATIONS: usize = 100_000;

/// Regression rows per block of the data QR: memory stays O((block + d)·d).
pub(crate) const BLOCK_ROWS: usize = 4096;

/// The VARX predictor and the SVD of Γ_f 𝒦_p Z_p of a set of experiments, for one past
/// window p and future window f: any order up to [`Pbsid::max_order`] is then a
/// [`Pbsid::model`] (Chiuso 2007, §5; van der Veen et al. 2013, §4.3; see the
/// [module documentation](self)).
#[derive(Debug, Clone)]
pub struct Pbsid {
    past: usize,
    future: usize,
    inputs: usize,
    outputs: usize,
    /// Regression rows over all experiments, Σ (N_e − p).
    rows: usize,
    singular_values: DVector<f64>,
    rank: usize,
    /// Per experiment: the states of the largest order, one row per k = p..N−1.
    states: Vec<DMatrix<f64>>,
    /// Per experiment: u_k and y_k for k = p..N−1.
    data: Vec<Experiment>,
}

/// Samples one experiment needs for past window p: 2p (one regression row needs p + 1,
/// the state equation two; 2p keeps the requirement of PO-MOESP with i = p).
#[must_use]
pub fn min_samples(past: usize) -> usize {
    2 * past
}

impl Pbsid {
    /// Estimates the VARX predictor with past window `past` (p) on every experiment
    /// (already preprocessed: same l and p, detrended, finite), builds Γ_f 𝒦_p for
    /// future window `future` (f ≤ p), computes its SVD weighted by the past data and
    /// the state sequence of the largest order (Chiuso 2007, §5).
    ///
    /// # Errors
    /// [`IdentError::InvalidSetting`] for a past window below 1 or a future window not in
    /// 1..=past, [`IdentError::NoExperiment`], [`IdentError::NoOutput`],
    /// [`IdentError::ColumnMismatch`], [`IdentError::RowMismatch`],
    /// [`IdentError::ExperimentTooShort`] when an experiment has fewer than 2p samples,
    /// [`IdentError::TooFewSamples`] when the experiments give fewer regression rows than
    /// the data matrix has columns (one per experiment, p(l + p), l, p),
    /// [`IdentError::NotPositiveDefinite`] when the past window is collinear (an input
    /// that is a linear function of past data, e.g. a controller's output without dither
    /// or setpoint changes: the data do not determine that input's path),
    /// [`IdentError::SvdNotConverged`].
    pub fn new(experiments: &[Experiment], past: usize, future: usize) -> Result<Self, IdentError> {
        if past < 1 {
            return Err(IdentError::InvalidSetting {
                name: "horizon",
                why: format!("the PBSID past window must be at least 1, got {past}"),
            });
        }
        if future < 1 || future > past {
            return Err(IdentError::InvalidSetting {
                name: "horizon",
                why: format!("the PBSID future window must be in 1..={past}, got {future}"),
            });
        }
        let (l, p) = crate::data::check_shapes(experiments, past, min_samples(past))?;
        let rows: usize = experiments.iter().map(|e| e.samples() - past).sum();
        let q = past * (l + p);
        // The collinearity check regresses on a constant per experiment too.
        let width = experiments.len() + q + l + p;
        if rows < width {
            return Err(IdentError::TooFewSamples {
                columns: rows,
                rows: width,
                horizon: past,
                inputs: l,
                outputs: p,
            });
        }

        // The past window must not be collinear (after a constant per experiment).
        check_past_window(
            &data_r(experiments, past, l, p, rows, true),
            experiments.len(),
            q,
        )?;
        // 1. VARX by least squares, from R of the data [Z_p; u; y] (rows scaled 1/√N):
        // the least squares of columns of Q R on others are those of the columns of R.
        let r = data_r(experiments, past, l, p, rows, false);
        let theta = least_squares(&r, q + l);
        // Ξ_j multiplies z_{k−j}, stored at column block p − j of the past window.
        let xi = |j: usize| theta.columns((past - j) * (l + p), l + p).into_owned();

        // 2. Γ_f 𝒦_p: block (i, lag j) = Ξ_{i+j} for i + j ≤ p, column block p − j.
        let mut gamma_k = DMatrix::zeros(future * p, q);
        for i in 0..future {
            for j in 1..=past - i {
                gamma_k
                    .view_mut((i * p, (past - j) * (l + p)), (p, l + p))
                    .copy_from(&xi(i + j));
            }
        }
        let r_past = r.view((0, 0), (q, q));
        let weighted = &gamma_k * r_past.transpose();
        let svd = nalgebra::SVD::try_new(weighted, true, false, f64::EPSILON, SVD_MAX_ITERATIONS)
            .ok_or(IdentError::SvdNotConverged {
            what: "the PBSID block Γ_f 𝒦_p Z_p",
        })?;
        let singular_values = svd.singular_values.clone();
        let left = svd.u.unwrap_or_else(|| DMatrix::zeros(future * p, 0));
        let s0 = singular_values.iter().copied().fold(0.0, f64::max);
        let tol = s0 * 1e-10;
        let rank = singular_values.iter().filter(|&&s| s > tol).count();

        // The state map of the largest order: x_k = Σ^{−1/2} Uᵀ Γ_f 𝒦_p z̄_k.
        let map = DMatrix::from_fn(rank, future * p, |r, c| {
            left[(c, r)] / singular_values[r].sqrt()
        }) * &gamma_k;
        let mut states = Vec::with_capacity(experiments.len());
        let mut data = Vec::with_capacity(experiments.len());
        for exp in experiments {
            let n = exp.samples() - past;
            let mut x = DMatrix::zeros(n, rank);
            let mut start = 0;
            while start < n {
                let len = BLOCK_ROWS.min(n - start);
                let block = past_rows(exp, past, l, p, start, len);
                x.rows_mut(start, len).copy_from(&(block * map.transpose()));
                start += len;
            }
            states.push(x);
            data.push(exp.rows(past, n));
        }
        Ok(Self {
            past,
            future,
            inputs: l,
            outputs: p,
            rows,
            singular_values,
            rank,
            states,
            data,
        })
    }

    /// The past window p.
    #[must_use]
    pub fn past(&self) -> usize {
        self.past
    }

    /// The future window f.
    #[must_use]
    pub fn future(&self) -> usize {
        self.future
    }

    /// Regression rows over all experiments, Σ (N_e − p).
    #[must_use]
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Singular values of Γ_f 𝒦_p Z_p (scaled by 1/√N), descending: a gap after the
    /// n-th suggests order n (Chiuso 2007, §5).
    #[must_use]
    pub fn singular_values(&self) -> &DVector<f64> {
        &self.singular_values
    }

    /// The largest identifiable order: the numerical rank of Γ_f 𝒦_p Z_p (at most f·p).
    #[must_use]
    pub fn max_order(&self) -> usize {
        self.rank
    }

    /// The innovation model of order `order`, in the coordinates of the data handed to
    /// [`Pbsid::new`]: steps 3 and 4 of the [module documentation](self) (Chiuso 2007,
    /// §5; van der Veen et al. 2013, §4.3), with Re the sample covariance of the
    /// residuals of step 3 and Q = K Re Kᵀ, S = K Re, R = Re, P = 0.
    ///
    /// # Errors
    /// [`IdentError::OrderAboveRank`] for order 0 or above [`Pbsid::max_order`]
    /// (`horizon_limit` is then f·p).
    pub fn model(&self, order: usize) -> Result<InnovationModel, IdentError> {
        let (l, p) = (self.inputs, self.outputs);
        let max = self.max_order();
        if order == 0 || order > max {
            return Err(IdentError::OrderAboveRank {
                order,
                rank: self.rank,
                horizon_limit: self.future * p,
                max,
            });
        }
        let n = order;
        // 3. y_k = C x_k + D u_k + e_k.
        let mut design = DMatrix::zeros(self.rows, n + l + p);
        let mut at = 0;
        for (x, exp) in self.states.iter().zip(&self.data) {
            let len = x.nrows();
            design
                .view_mut((at, 0), (len, n))
                .copy_from(&x.columns(0, n));
            design.view_mut((at, n), (len, l)).copy_from(&exp.inputs);
            design
                .view_mut((at, n + l), (len, p))
                .copy_from(&exp.outputs);
            at += len;
        }
        let cd = least_squares(&design, n + l);
        let regressors = design.columns(0, n + l);
        let e = design.columns(n + l, p) - regressors * cd.transpose();
        let c = cd.columns(0, n).into_owned();
        let d = cd.columns(n, l).into_owned();
        let re = e.transpose() * &e / self.rows as f64;
        let re = (&re + re.transpose()) * 0.5;

        // 4. x_{k+1} = A x_k + B u_k + K e_k, within each experiment.
        let pairs = self.rows - self.states.len();
        let mut design = DMatrix::zeros(pairs, 2 * n + l + p);
        let (mut at, mut from) = (0, 0);
        for (x, exp) in self.states.iter().zip(&self.data) {
            let len = x.nrows() - 1;
            design
                .view_mut((at, 0), (len, n))
                .copy_from(&x.view((0, 0), (len, n)));
            design
                .view_mut((at, n), (len, l))
                .copy_from(&exp.inputs.rows(0, len));
            design
                .view_mut((at, n + l), (len, p))
                .copy_from(&e.rows(from, len));
            design
                .view_mut((at, n + l + p), (len, n))
                .copy_from(&x.view((1, 0), (len, n)));
            at += len;
            from += len + 1;
        }
        let abk = least_squares(&design, n + l + p);
        let a = abk.columns(0, n).into_owned();
        let b = abk.columns(n, l).into_owned();
        let k = abk.columns(n + l, p).into_owned();
        let s = &k * &re;
        let q = &s * k.transpose();
        let q = (&q + q.transpose()) * 0.5;
        Ok(InnovationModel {
            a,
            b,
            c,
            d,
            k,
            q,
            s,
            r: re.clone(),
            re,
            p: DMatrix::zeros(n, n),
        })
    }
}

/// Θ (targets × regressors) minimising ‖T − X Θᵀ‖ for `design` = [X T] with X its first
/// `regressors` columns, through the R of its QR (pseudo-inverse of R_XX, so rank
/// deficiency gives the minimum-norm solution rather than a panic).
fn least_squares(design: &DMatrix<f64>, regressors: usize) -> DMatrix<f64> {
    let targets = design.ncols() - regressors;
    let r = qr_r(design);
    let r_xx = r.view((0, 0), (regressors, regressors)).into_owned();
    (pinv(&r_xx) * r.view((0, regressors), (regressors, targets))).transpose()
}

/// R (columns × columns, upper triangular) of the QR of a tall matrix, a block of rows
/// at a time (the R of [R_prev; block] is the R of all rows so far).
fn qr_r(m: &DMatrix<f64>) -> DMatrix<f64> {
    let cols = m.ncols();
    let mut r = DMatrix::<f64>::zeros(0, cols);
    let mut start = 0;
    while start < m.nrows() {
        let len = BLOCK_ROWS.min(m.nrows() - start);
        r = stack_qr(&r, &m.rows(start, len).into_owned());
        start += len;
    }
    square(r, cols)
}

/// The R of [r; block].
pub(crate) fn stack_qr(r: &DMatrix<f64>, block: &DMatrix<f64>) -> DMatrix<f64> {
    let mut stacked = DMatrix::zeros(r.nrows() + block.nrows(), block.ncols());
    stacked.rows_mut(0, r.nrows()).copy_from(r);
    stacked.rows_mut(r.nrows(), block.nrows()).copy_from(block);
    stacked.qr().r()
}

/// `r` padded with zero rows to cols × cols (when fewer rows than columns were seen).
pub(crate) fn square(r: DMatrix<f64>, cols: usize) -> DMatrix<f64> {
    if r.nrows() >= cols {
        return r.rows(0, cols).into_owned();
    }
    let mut out = DMatrix::zeros(cols, cols);
    out.rows_mut(0, r.nrows()).copy_from(&r);
    out
}

/// Smallest singular value of the past window's R (after the per-experiment constants),
/// relative to the largest, below which the past data are collinear.
const COLLINEAR_TOLERANCE: f64 = 1e-7;

/// Refuses a collinear past window: some combination of z̄_k is (to rounding) a
/// constant per experiment, typically an input computed by a linear controller from
/// past data with no external excitation (no dither, no setpoint change). The VARX is
/// then not unique, the data are not informative about that input's path (Ljung 1999,
/// *System Identification*, §13.4), and any model would be arbitrary.
fn check_past_window(r: &DMatrix<f64>, e: usize, q: usize) -> Result<(), IdentError> {
    let block = r.view((e, e), (q, q)).into_owned();
    let s = nalgebra::SVD::try_new(block, false, false, f64::EPSILON, SVD_MAX_ITERATIONS)
        .ok_or(IdentError::SvdNotConverged {
            what: "the PBSID past window",
        })?
        .singular_values;
    let max = s.iter().copied().fold(0.0, f64::max);
    let min = s.iter().copied().fold(f64::INFINITY, f64::min);
    // NaN (non-finite data) counts as collinear.
    let separated = min > COLLINEAR_TOLERANCE * max;
    if !separated {
        return Err(IdentError::NotPositiveDefinite {
            what: "the covariance of the PBSID past window z̄_k (its data are collinear: an \
                   input is a linear function of past data, e.g. a controller's output with no \
                   dither or setpoint change, and the data say nothing about its path)",
        });
    }
    Ok(())
}

/// R of the data matrix whose rows are [1_eᵀ, z̄_kᵀ, u_kᵀ, y_kᵀ]/√N, k = p..N−1 of every
/// experiment, 1_e the indicator of the experiment when `intercepts` (else absent).
fn data_r(
    experiments: &[Experiment],
    past: usize,
    l: usize,
    p: usize,
    rows: usize,
    intercepts: bool,
) -> DMatrix<f64> {
    let q = past * (l + p);
    let c0 = if intercepts { experiments.len() } else { 0 };
    let width = c0 + q + l + p;
    let scale = 1.0 / (rows as f64).sqrt();
    let mut r = DMatrix::<f64>::zeros(0, width);
    for (ei, exp) in experiments.iter().enumerate() {
        let n = exp.samples() - past;
        let mut start = 0;
        while start < n {
            let len = BLOCK_ROWS.min(n - start);
            let mut block = DMatrix::zeros(len, width);
            if intercepts {
                block.column_mut(ei).fill(1.0);
            }
            let mut block_data = block.columns_mut(c0, q + l + p);
            block_data
                .columns_mut(0, q)
                .copy_from(&past_rows(exp, past, l, p, start, len));
            block_data
                .columns_mut(q, l)
                .copy_from(&exp.inputs.rows(past + start, len));
            block_data
                .columns_mut(q + l, p)
                .copy_from(&exp.outputs.rows(past + start, len));
            block *= scale;
            r = stack_qr(&r, &block);
            start += len;
        }
    }
    square(r, width)
}

/// Past windows z̄_k = [z_{k−p}; …; z_{k−1}] (z = [u; y]) as rows, for k = p + start ..
/// p + start + len − 1 of one experiment: a window lies inside its experiment.
fn past_rows(
    exp: &Experiment,
    past: usize,
    l: usize,
    p: usize,
    start: usize,
    len: usize,
) -> DMatrix<f64> {
    let mut h = DMatrix::zeros(len, past * (l + p));
    for row in 0..len {
        let k = past + start + row;
        for lag in 0..past {
            let t = k - past + lag;
            let col = lag * (l + p);
            for s in 0..l {
                h[(row, col + s)] = exp.inputs[(t, s)];
            }
            for s in 0..p {
                h[(row, col + l + s)] = exp.outputs[(t, s)];
            }
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn past_windows_hold_the_samples_in_time_order() {
        let n = 6;
        let u = DMatrix::from_fn(n, 1, |k, _| 100.0 + k as f64);
        let y = DMatrix::from_fn(n, 1, |k, _| k as f64);
        let exp = Experiment::new(u, y);
        // k = 3 with p = 2: [u_1 y_1 u_2 y_2].
        let h = past_rows(&exp, 2, 1, 1, 1, 1);
        assert_eq!(
            h.row(0).iter().copied().collect::<Vec<_>>(),
            vec![101.0, 1.0, 102.0, 2.0]
        );
    }

    #[test]
    fn exact_first_order_system_is_recovered() {
        // y_k = x_k + e_k, x_{k+1} = 0.8 x_k + u_k + 0.5 e_k; deterministic pseudo-noise.
        let n = 3000;
        let mut state = 7u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let u = DMatrix::from_fn(n, 1, |_, _| rand());
        let mut y = DMatrix::zeros(n, 1);
        let mut x = 0.0;
        for k in 0..n {
            let e = 0.1 * rand();
            y[(k, 0)] = x + e;
            x = 0.8 * x + u[(k, 0)] + 0.5 * e;
        }
        let id = Pbsid::new(&[Experiment::new(u, y)], 15, 5).unwrap();
        let m = id.model(1).unwrap();
        assert!((m.a[(0, 0)] - 0.8).abs() < 0.01, "{}", m.a);
        let cb = (&m.c * &m.b)[(0, 0)];
        assert!((cb - 1.0).abs() < 0.02, "{cb}");
        let ck = (&m.c * &m.k)[(0, 0)];
        assert!((ck - 0.5).abs() < 0.05, "{ck}");
        assert!(id.model(0).is_err());
    }
}
