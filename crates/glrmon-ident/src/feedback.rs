//! Were the data recorded under feedback? A Granger-causality test of y → u: do past
//! outputs help predict the inputs beyond what the inputs' own past predicts?
//!
//! # Why
//! PO-MOESP is consistent only when the inputs are independent of the noise (open
//! loop); under feedback a controller computes u_k from past outputs, hence from past
//! innovations, and its projections are biased (Ljung 1999, *System Identification*,
//! 2nd ed., §13.4; van der Veen et al. 2013, IET Control Theory Appl. 7(10), §1–3).
//! The residual analysis of Ljung (1999, §16.6) shows feedback as a correlation between
//! the inputs and *past* prediction errors; the test here asks the same question of the
//! data directly, before any model, as Granger (1969, *Investigating causal relations by
//! econometric models and cross-spectral methods*, Econometrica 37(3), 424–438) and
//! Caines & Chan (1975, *Feedback between stationary stochastic processes*, IEEE TAC
//! 20(4), 498–508) define feedback: y feeds back into u when past y improves the
//! one-step prediction of u given past u.
//!
//! # Math
//! With M lags, per experiment e and k = M..N_e−1 (a window never spans two
//! experiments), the multivariate regressions
//!
//! ```text
//! reduced:  u_k = c_e + Σ_{j=1..M} A_j u_{k−j}                      + w_k
//! full:     u_k = c_e + Σ_{j=1..M} A_j u_{k−j} + Σ_{j=1..M} B_j y_{k−j} + w_k
//! ```
//!
//! are fitted by least squares from one QR of [intercepts, past u, past y, u_k]; with E
//! and E + H the residual cross-products of the full and reduced fits, Wilks'
//! Λ = det E / det(E + H). Under H₀ (all B_j = 0: open loop, u independent of past
//! noise, u an autoregression of order ≤ M or white), Bartlett's
//! −(ν − (l − q + 1)/2) ln Λ is χ²(l·q) to O(ν⁻²), with ν = rows − regressors of the full
//! fit and q = M·p (Anderson 2003, *An Introduction to Multivariate Statistical
//! Analysis*, 3rd ed., ch. 8: the likelihood-ratio criterion of a linear hypothesis and
//! Bartlett's χ² approximation). The per-input statistics are the same with l = 1.
//!
//! An input that its own past predicts exactly (a sinusoid, a ramp) carries no
//! information on feedback and is left out of the joint test; one that the past of
//! inputs *and outputs* predicts exactly (a noise-free controller with no dither) is
//! certainly fed back: its statistic is +∞.

use glrmon_core::threshold::chi2_sf;
use nalgebra::DMatrix;

use crate::data::Experiment;
use crate::error::IdentError;
use crate::pbsid::{BLOCK_ROWS, square, stack_qr};

/// Default lags M of [`feedback_test`]: the controller's memory the test looks at.
pub const DEFAULT_FEEDBACK_LAGS: usize = 10;

/// Default level of [`feedback_test`]: the probability of calling open-loop data
/// closed-loop.
pub const DEFAULT_FEEDBACK_LEVEL: f64 = 0.01;

/// Regression rows per regressor at least: M is lowered on short records so that the
/// χ² approximation holds (Bartlett's correction is O(1/ν)).
const ROWS_PER_REGRESSOR: usize = 10;

/// An input whose reduced-fit residual variance is at most this share of its variance
/// is predicted exactly by its own past: left out.
const DETERMINISTIC: f64 = 1e-10;

/// The result of [`feedback_test`].
#[derive(Debug, Clone, PartialEq)]
pub struct FeedbackTest {
    /// Bartlett's −(ν − (l′ − q + 1)/2) ln Λ over the l′ tested inputs (+∞ when past
    /// data predict an input exactly).
    pub statistic: f64,
    /// Its degrees of freedom, l′·M·p.
    pub dof: usize,
    /// P(χ²_dof > statistic): small values reject "no feedback".
    pub p_value: f64,
    /// Lags M used.
    pub lags: usize,
    /// The level the decision is taken at.
    pub level: f64,
    /// Regression rows over all experiments.
    pub rows: usize,
    /// Per input (in the columns handed in): the p-value of its own test, `None` for an
    /// input its own past predicts exactly (not tested).
    pub per_input: Vec<Option<f64>>,
}

impl FeedbackTest {
    /// The test rejects "no feedback" at its level.
    #[must_use]
    pub fn feedback(&self) -> bool {
        self.p_value < self.level
    }

    /// The input with the smallest p-value, and that p-value.
    #[must_use]
    pub fn strongest(&self) -> Option<(usize, f64)> {
        self.per_input
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// The Granger test of y → u on `experiments` (preprocessed: detrended, finite, same
/// columns) with `lags` lags (lowered on short records, see the [module](self) docs),
/// the decision at `level`. `None` when there is no input (a time series has no
/// feedback) or every input is predicted exactly by its own past.
///
/// # Errors
/// [`IdentError::InvalidSetting`] for a level outside (0, 1) or zero lags;
/// [`IdentError::TooFewSamples`] when the experiments give fewer rows than a one-lag
/// test needs.
pub fn feedback_test(
    experiments: &[Experiment],
    lags: usize,
    level: f64,
) -> Result<Option<FeedbackTest>, IdentError> {
    if !(level > 0.0 && level < 1.0) {
        return Err(IdentError::InvalidSetting {
            name: "feedback_level",
            why: format!("the level must be in (0, 1), got {level}"),
        });
    }
    if lags == 0 {
        return Err(IdentError::InvalidSetting {
            name: "feedback_lags",
            why: "at least one lag is needed".into(),
        });
    }
    let Some(first) = experiments.first() else {
        return Err(IdentError::NoExperiment);
    };
    let (l, p) = (first.inputs.ncols(), first.outputs.ncols());
    if l == 0 {
        return Ok(None);
    }
    let e = experiments.len();
    let rows_at = |m: usize| -> usize {
        experiments
            .iter()
            .map(|x| x.samples().saturating_sub(m))
            .sum()
    };
    let width = |m: usize| e + m * (l + p);
    let mut m = lags;
    while m > 1 && rows_at(m) < ROWS_PER_REGRESSOR * width(m) {
        m -= 1;
    }
    let rows = rows_at(m);
    if rows < width(m) + l + 2 {
        return Err(IdentError::TooFewSamples {
            columns: rows,
            rows: width(m) + l + 2,
            horizon: m,
            inputs: l,
            outputs: p,
        });
    }
    let r = design_r(experiments, m, l, p);
    let reduced_cols = e + m * l;
    let q = m * p;
    // Residual cross-products: full E = R₃₃ᵀR₃₃, reduced E + H = R₂₃ᵀR₂₃ + E.
    let r23 = r.view((reduced_cols, reduced_cols + q), (q, l));
    let r33 = r.view((reduced_cols + q, reduced_cols + q), (l, l));
    let full = r33.transpose() * r33;
    let reduced = r23.transpose() * r23 + &full;
    let variance = input_variances(experiments, l);
    let nu = (rows - width(m)) as f64;

    let mut tested = Vec::new();
    let mut per_input = Vec::with_capacity(l);
    for i in 0..l {
        if reduced[(i, i)] <= DETERMINISTIC * variance[i] * rows as f64 {
            per_input.push(None);
            continue;
        }
        tested.push(i);
        let stat = bartlett(full[(i, i)].ln() - reduced[(i, i)].ln(), nu, 1, q);
        per_input.push(Some(chi2_sf(q as f64, stat)));
    }
    if tested.is_empty() {
        return Ok(None);
    }
    let pick = |m: &DMatrix<f64>| m.select_rows(&tested).select_columns(&tested);
    let statistic = match (log_det(&pick(&full)), log_det(&pick(&reduced))) {
        (Some(f), Some(r)) => bartlett(f - r, nu, tested.len(), q),
        // The reduced fit is positive definite (tested inputs are not predicted by their
        // own past): a singular full fit is an input predicted exactly by past outputs.
        _ => f64::INFINITY,
    };
    let dof = tested.len() * q;
    Ok(Some(FeedbackTest {
        statistic,
        dof,
        p_value: chi2_sf(dof as f64, statistic),
        lags: m,
        level,
        rows,
        per_input,
    }))
}

/// −(ν − (l − q + 1)/2) ln Λ, +∞ for a NaN or −∞ ln Λ (an exact fit), never negative.
fn bartlett(ln_lambda: f64, nu: f64, l: usize, q: usize) -> f64 {
    let factor = nu - (l as f64 - q as f64 + 1.0) / 2.0;
    let stat = -factor * ln_lambda;
    if stat.is_nan() || ln_lambda == f64::NEG_INFINITY {
        f64::INFINITY
    } else {
        stat.max(0.0)
    }
}

fn log_det(m: &DMatrix<f64>) -> Option<f64> {
    let chol = m.clone().cholesky()?;
    let ld = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
    ld.is_finite().then_some(ld)
}

/// Σ_k (u_k − ū_e)² per input, over every experiment (each about its own mean).
fn input_variances(experiments: &[Experiment], l: usize) -> Vec<f64> {
    (0..l)
        .map(|i| {
            let (mut s, mut n) = (0.0, 0usize);
            for exp in experiments {
                let col = exp.inputs.column(i);
                let mean = col.mean();
                s += col.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
                n += col.len();
            }
            s / n.max(1) as f64
        })
        .collect()
}

/// R of the QR of the rows [1_eᵀ, u_{k−1..k−M}ᵀ, y_{k−1..k−M}ᵀ, u_kᵀ], k = M..N_e−1 of
/// every experiment, a block of rows at a time (memory O((block + width)·width)).
fn design_r(experiments: &[Experiment], m: usize, l: usize, p: usize) -> DMatrix<f64> {
    let e = experiments.len();
    let width = e + m * (l + p) + l;
    let mut r = DMatrix::<f64>::zeros(0, width);
    for (ei, exp) in experiments.iter().enumerate() {
        let mut k = m;
        while k < exp.samples() {
            let len = BLOCK_ROWS.min(exp.samples() - k);
            let mut d = DMatrix::zeros(len, width);
            for row in 0..len {
                let t = k + row;
                d[(row, ei)] = 1.0;
                for j in 1..=m {
                    for s in 0..l {
                        d[(row, e + (j - 1) * l + s)] = exp.inputs[(t - j, s)];
                    }
                    for s in 0..p {
                        d[(row, e + m * l + (j - 1) * p + s)] = exp.outputs[(t - j, s)];
                    }
                }
                for s in 0..l {
                    d[(row, e + m * (l + p) + s)] = exp.inputs[(t, s)];
                }
            }
            r = stack_qr(&r, &d);
            k += len;
        }
    }
    square(r, width)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_computed_from_the_last_output_is_feedback_and_a_time_series_has_none() {
        let n = 2000;
        let mut state = 11u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let mut u = DMatrix::zeros(n, 1);
        let mut y = DMatrix::zeros(n, 1);
        let mut x = 0.0;
        for k in 0..n {
            let yk = x + 0.3 * rand();
            y[(k, 0)] = yk;
            if k + 1 < n {
                u[(k + 1, 0)] = -0.5 * yk + 0.2 * rand();
            }
            x = 0.7 * x + u[(k, 0)];
        }
        let t = feedback_test(&[Experiment::new(u, y.clone())], 5, 0.01)
            .unwrap()
            .unwrap();
        assert!(t.feedback(), "{t:?}");
        assert_eq!(t.dof, 5);
        assert!(t.p_value < 1e-12, "{t:?}");
        assert!(
            feedback_test(&[Experiment::time_series(y)], 5, 0.01)
                .unwrap()
                .is_none()
        );
    }
}
