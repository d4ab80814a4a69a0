//! Subspace identification: block Hankel matrices per experiment, one LQ factorisation,
//! oblique projections, the SVD of the PO-MOESP weighted block, then a model of any
//! order from it.
//!
//! # Math
//! With past/future horizon i, each Hankel column (a window of 2i samples starting at t)
//! stacks, in this order,
//!
//! `[U_f⁻; u_i; U_p; Y_p; y_i; Y_f⁻]`
//!
//! (U_p = u_t..u_{t+i−1}, u_i = u_{t+i}, U_f⁻ = u_{t+i+1}..u_{t+2i−1}, same for y). The
//! order is chosen so that, with H = L Qᵀ (L lower triangular, from the QR of Hᵀ), both
//! oblique projections O_i = Y_f /_{U_f} W_p and O_{i−1} = Y_f⁻ /_{U_f⁻} W_p⁺ are read
//! off L with one triangular block each (Van Overschee & De Moor 1996, ch. 4 for the
//! projections, ch. 6 for their LQ implementation). The PO-MOESP weighted block
//! O_i Π_{U_f}^⊥ is L₃₂ (Verhaegen 1994, *Identification of the deterministic part of
//! MIMO state space models given in innovations form from input-output data*,
//! Automatica 30(1), 61–74), whose SVD gives the extended observability matrix
//! Γ_i = U₁ S₁^{1/2}.
//!
//! Experiments are never joined: each contributes its own Hankel columns (a window never
//! spans two experiments), and the columns of all experiments are stacked before the
//! LQ: the usual multi-experiment extension of subspace methods (Verhaegen & Verdult
//! 2007, *Filtering and System Identification*, ch. 9).

use nalgebra::{DMatrix, DVector};

use crate::data::Experiment;
use crate::error::IdentError;
use crate::model::{InnovationModel, solve_riccati};

/// The factored data of a set of experiments for one horizon: any order up to
/// [`Subspace::max_order`] is then a cheap [`Subspace::model`].
#[derive(Debug, Clone)]
pub struct Subspace {
    horizon: usize,
    inputs: usize,
    outputs: usize,
    columns: usize,
    /// L (m × m), scaled by 1/√j so that row inner products are sample averages.
    lower: DMatrix<f64>,
    /// O_i = Y_f /_{U_f} W_p in the coordinates of L (ip × m).
    o_i: DMatrix<f64>,
    /// O_{i−1} = Y_f⁻ /_{U_f⁻} W_p⁺ ((i − 1)p × m).
    o_i_minus: DMatrix<f64>,
    /// Left singular vectors of L₃₂ (ip × min(ip, i(l + p))).
    left: DMatrix<f64>,
    singular_values: DVector<f64>,
    rank: usize,
}

/// Iteration cap of every SVD: far above what finite data need, and a guarantee of
/// termination on pathological data.
const SVD_MAX_ITERATIONS: usize = 100_000;

/// Row offsets of the blocks of a Hankel column.
#[derive(Debug, Clone, Copy)]
struct Layout {
    /// Start of u_i.
    ui: usize,
    /// Start of U_p (= end of the future inputs U_f).
    up: usize,
    /// Start of y_i (= end of W_p).
    yi: usize,
    /// Start of Y_f⁻.
    yf_minus: usize,
    /// Total rows 2i(l + p).
    rows: usize,
}

impl Layout {
    fn new(i: usize, l: usize, p: usize) -> Self {
        let ui = (i - 1) * l;
        let up = i * l;
        let yi = 2 * i * l + i * p;
        Self {
            ui,
            up,
            yi,
            yf_minus: yi + p,
            rows: 2 * i * (l + p),
        }
    }
}

/// Samples one experiment needs for horizon i: one Hankel column.
#[must_use]
pub fn min_samples(horizon: usize) -> usize {
    2 * horizon
}

impl Subspace {
    /// Builds the block Hankel matrix of every experiment (already preprocessed: same l
    /// and p, detrended, finite), stacks their columns, factors it (LQ through the QR of
    /// the transpose) and computes the projections and the SVD.
    ///
    /// # Errors
    /// [`IdentError::InvalidSetting`] for a horizon below 2, [`IdentError::NoExperiment`],
    /// [`IdentError::ColumnMismatch`], [`IdentError::RowMismatch`],
    /// [`IdentError::ExperimentTooShort`] when an
    /// experiment has fewer than 2i samples, [`IdentError::TooFewSamples`] when the
    /// experiments give fewer Hankel columns than rows.
    pub fn new(experiments: &[Experiment], horizon: usize) -> Result<Self, IdentError> {
        if horizon < 2 {
            return Err(IdentError::InvalidSetting {
                name: "horizon",
                why: format!("must be at least 2 (shift invariance needs Γ_(i−1)), got {horizon}"),
            });
        }
        let i = horizon;
        let (l, p) = crate::data::check_shapes(experiments, i, min_samples(i))?;
        let layout = Layout::new(i, l, p);
        let columns: usize = experiments.iter().map(|e| e.samples() + 1 - 2 * i).sum();
        if columns < layout.rows {
            return Err(IdentError::TooFewSamples {
                columns,
                rows: layout.rows,
                horizon: i,
                inputs: l,
                outputs: p,
            });
        }
        let lower = lq_factor(experiments, i, layout, columns);

        let m = layout.rows;
        let o_i = oblique(&lower, layout.yi, m, layout.up, layout.yi);
        let o_i_minus = oblique(&lower, layout.yf_minus, m, layout.ui, layout.yf_minus);
        let l32 = lower
            .view((layout.yi, layout.up), (i * p, layout.yi - layout.up))
            .into_owned();
        let svd = nalgebra::SVD::try_new(l32, true, false, f64::EPSILON, SVD_MAX_ITERATIONS)
            .ok_or(IdentError::SvdNotConverged {
                what: "the PO-MOESP block L₃₂",
            })?;
        let singular_values = svd.singular_values.clone();
        let left = svd.u.unwrap_or_else(|| DMatrix::zeros(i * p, 0));
        let s0 = singular_values.iter().copied().fold(0.0, f64::max);
        // Relative 1e-10: rounding in the LQ of exact (noise-free) data stays far below it.
        let tol = s0 * 1e-10;
        let rank = singular_values.iter().filter(|&&s| s > tol).count();
        Ok(Self {
            horizon: i,
            inputs: l,
            outputs: p,
            columns,
            lower,
            o_i,
            o_i_minus,
            left,
            singular_values,
            rank,
        })
    }

    /// The past/future horizon i.
    #[must_use]
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Hankel columns j over all experiments (Σ N_e − 2i + 1).
    #[must_use]
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Singular values of the PO-MOESP block, descending: a gap after the n-th suggests
    /// order n.
    #[must_use]
    pub fn singular_values(&self) -> &DVector<f64> {
        &self.singular_values
    }

    /// The largest identifiable order: the numerical rank of the weighted block, at most
    /// (i − 1)p (Γ_{i−1} must have full column rank for shift invariance).
    #[must_use]
    pub fn max_order(&self) -> usize {
        self.rank.min((self.horizon - 1) * self.outputs)
    }

    /// The innovation model of order `order`, in the coordinates of the data handed to
    /// [`Subspace::new`].
    ///
    /// # Math
    /// 1. Γ_i = U₁ S₁^{1/2}; C = first block row of Γ_i; A = Γ_{i−1}^† Γ̄_i (Γ_{i−1}: Γ_i
    ///    without its last block row, Γ̄_i: without its first), the shift invariance of
    ///    Verhaegen (1994), Van Overschee & De Moor (1996) ch. 4.
    /// 2. States X_i = Γ_i^† O_i, X_{i+1} = Γ_{i−1}^† O_{i−1} (VODM 1996 ch. 4: the
    ///    states of a bank of non-steady Kalman filters, close to the steady ones for a
    ///    long enough horizon).
    /// 3. B, D by least squares: [X_{i+1} − A X_i; Y_{i|i} − C X_i] = [B; D] U_{i|i} + ρ.
    /// 4. [Q S; Sᵀ R] = ρ ρᵀ / j (VODM 1996 ch. 4, the residuals of the state-sequence
    ///    least squares); K, Re from the Riccati
    ///    equation ([`solve_riccati`]).
    ///
    /// # Errors
    /// [`IdentError::OrderAboveRank`] for order 0 or above [`Subspace::max_order`];
    /// the errors of [`solve_riccati`].
    pub fn model(&self, order: usize) -> Result<InnovationModel, IdentError> {
        let (i, l, p) = (self.horizon, self.inputs, self.outputs);
        let max = self.max_order();
        if order == 0 || order > max {
            return Err(IdentError::OrderAboveRank {
                order,
                rank: self.rank,
                horizon_limit: (i - 1) * p,
                max,
            });
        }
        let n = order;
        let layout = Layout::new(i, l, p);
        let sqrt_s = DVector::from_fn(n, |k, _| self.singular_values[k].sqrt());
        let u1 = self.left.columns(0, n);
        let gamma = DMatrix::from_fn(i * p, n, |r, c| u1[(r, c)] * sqrt_s[c]);
        // Γ_i^† = S₁^{−1/2} U₁ᵀ (U₁ has orthonormal columns).
        let gamma_pinv = DMatrix::from_fn(n, i * p, |r, c| u1[(c, r)] / sqrt_s[r]);
        let gamma_up = gamma.rows(0, (i - 1) * p).into_owned();
        let gamma_up_pinv = pinv(&gamma_up);
        let a = &gamma_up_pinv * gamma.rows(p, (i - 1) * p);
        let c = gamma.rows(0, p).into_owned();

        let x_i = &gamma_pinv * &self.o_i;
        let x_next = &gamma_up_pinv * &self.o_i_minus;
        let y_ii = self.lower.rows(layout.yi, p);
        let u_ii = self.lower.rows(layout.ui, l);
        let mut z = DMatrix::zeros(n + p, layout.rows);
        z.rows_mut(0, n).copy_from(&(&x_next - &a * &x_i));
        z.rows_mut(n, p).copy_from(&(y_ii - &c * &x_i));
        let (b, d, rho) = if l == 0 {
            (DMatrix::zeros(n, 0), DMatrix::zeros(p, 0), z)
        } else {
            let uut = u_ii * u_ii.transpose();
            let bd = &z * u_ii.transpose() * pinv(&uut);
            let rho = &z - &bd * u_ii;
            (bd.rows(0, n).into_owned(), bd.rows(n, p).into_owned(), rho)
        };
        let cov = &rho * rho.transpose();
        let cov = (&cov + cov.transpose()) * 0.5;
        let q = cov.view((0, 0), (n, n)).into_owned();
        let s = cov.view((0, n), (n, p)).into_owned();
        let r = cov.view((n, n), (p, p)).into_owned();
        let riccati = solve_riccati(&a, &c, &q, &s, &r)?;
        Ok(InnovationModel {
            a,
            b,
            c,
            d,
            k: riccati.k,
            re: riccati.re,
            q,
            s,
            r,
            p: riccati.p,
        })
    }
}

/// Hankel columns (window starts) per block of Hᵀ in [`lq_factor`]: memory stays
/// O((block + m)·m) however long the recordings are.
const BLOCK_WINDOWS: usize = 1024;

/// Parts of the windows factored separately in [`lq_factor`] (a tall-skinny QR):
/// fixed, whatever the machine, so that the result's bits do not depend on its cores.
const PARTS: usize = 4;

/// L of H = L Qᵀ (m × m, lower triangular), through the QR of Hᵀ (Hᵀ = Q R, L = Rᵀ; Q is
/// never formed). Hᵀ is factored a block of windows at a time: the R of [R_prev; block]
/// is the R of all rows so far (up to row signs, which flip columns of L and leave
/// every row inner product, hence every projection, unchanged).
///
/// The windows are cut into [`PARTS`] contiguous parts of about equal size, each
/// factored on a thread of its own, and the R of the stacked parts' R factors is the R
/// of all (tall-skinny QR, Demmel et al. 2012, "Communication-optimal parallel and
/// sequential QR and LU factorizations", §3): the same numbers on any machine, about
/// twice as fast on two cores.
fn lq_factor(experiments: &[Experiment], i: usize, layout: Layout, columns: usize) -> DMatrix<f64> {
    let scale = 1.0 / (columns as f64).sqrt();
    // Every block of windows, in order: (experiment, first window, windows).
    let mut blocks = Vec::new();
    for (e, exp) in experiments.iter().enumerate() {
        let windows = exp.samples() + 1 - 2 * i;
        let mut start = 0;
        while start < windows {
            let len = BLOCK_WINDOWS.min(windows - start);
            blocks.push((e, start, len));
            start += len;
        }
    }
    let total: usize = blocks.iter().map(|b| b.2).sum();
    let mut parts: Vec<Vec<(usize, usize, usize)>> = vec![Vec::new(); PARTS];
    let mut done = 0;
    for block in blocks {
        let part = (done * PARTS / total.max(1)).min(PARTS - 1);
        parts[part].push(block);
        done += block.2;
    }
    let factor = |part: &[(usize, usize, usize)]| {
        let mut r = DMatrix::<f64>::zeros(0, layout.rows);
        for &(e, start, len) in part {
            let block = hankel_rows(&experiments[e], i, layout, start, len, scale);
            let mut stacked = DMatrix::zeros(r.nrows() + len, layout.rows);
            stacked.rows_mut(0, r.nrows()).copy_from(&r);
            stacked.rows_mut(r.nrows(), len).copy_from(&block);
            r = stacked.qr().r();
        }
        r
    };
    let factors: Vec<DMatrix<f64>> = std::thread::scope(|scope| {
        let handles: Vec<_> = parts
            .iter()
            .map(|part| scope.spawn(|| factor(part)))
            .collect();
        handles
            .into_iter()
            .zip(&parts)
            // A part whose thread could not finish is factored here instead.
            .map(|(h, part)| h.join().unwrap_or_else(|_| factor(part)))
            .collect()
    });
    let rows: usize = factors.iter().map(DMatrix::nrows).sum();
    let mut stacked = DMatrix::zeros(rows, layout.rows);
    let mut at = 0;
    for f in &factors {
        stacked.rows_mut(at, f.nrows()).copy_from(f);
        at += f.nrows();
    }
    let r = if factors.iter().filter(|f| f.nrows() > 0).count() > 1 {
        stacked.qr().r()
    } else {
        // One part (short recordings): its R is already the factor, bit for bit the
        // sequential one.
        factors
            .into_iter()
            .find(|f| f.nrows() > 0)
            .unwrap_or(stacked)
    };
    r.transpose()
}

/// Rows `start..start + len` of Hᵀ·`scale` for one experiment: one row per window
/// (Hankel column), one column per Hankel row in the [`Layout`] order. A window lies
/// inside its experiment: experiments are never joined.
fn hankel_rows(
    exp: &Experiment,
    i: usize,
    layout: Layout,
    start: usize,
    len: usize,
    scale: f64,
) -> DMatrix<f64> {
    let l = layout.up / i;
    let p = (layout.rows - 2 * i * l) / (2 * i);
    let (u, y) = (&exp.inputs, &exp.outputs);
    let mut h = DMatrix::zeros(len, layout.rows);
    for (row, t) in (start..start + len).enumerate() {
        // Future inputs u_{t+i+1}..u_{t+2i−1}, then u_{t+i}, then U_p.
        let mut col = 0;
        for k in (i + 1..2 * i).chain(std::iter::once(i)).chain(0..i) {
            for s in 0..l {
                h[(row, col)] = u[(t + k, s)] * scale;
                col += 1;
            }
        }
        // Y_p, then y_{t+i}, then Y_f⁻: y in natural time order.
        for k in 0..2 * i {
            for s in 0..p {
                h[(row, col)] = y[(t + k, s)] * scale;
                col += 1;
            }
        }
    }
    h
}

/// The oblique projection of the rows `[target, end)` of L along the rows before `past`
/// (future inputs) onto the rows `[past, target)` (past data): T[:, past..target] ·
/// L[past..target, past..target]^† · L[past..target, :].
fn oblique(
    lower: &DMatrix<f64>,
    target: usize,
    end: usize,
    past: usize,
    past_end: usize,
) -> DMatrix<f64> {
    let w = past_end - past;
    let t = lower.view((target, past), (end - target, w));
    let lpp = lower.view((past, past), (w, w)).into_owned();
    let coef = t * pinv(&lpp);
    coef * lower.rows(past, w)
}

/// Moore–Penrose pseudo-inverse by SVD, singular values below
/// max(rows, cols)·ε·σ_max treated as zero.
pub(crate) fn pinv(m: &DMatrix<f64>) -> DMatrix<f64> {
    let (r, c) = m.shape();
    if r == 0 || c == 0 {
        return DMatrix::zeros(c, r);
    }
    let Some(svd) = nalgebra::SVD::try_new(m.clone(), true, true, f64::EPSILON, SVD_MAX_ITERATIONS)
    else {
        // Only on non-finite entries; a zero pseudo-inverse then makes the caller's
        // covariances fail their positive-definiteness check rather than loop.
        return DMatrix::zeros(c, r);
    };
    let smax = svd.singular_values.iter().copied().fold(0.0, f64::max);
    let tol = smax * f64::EPSILON * r.max(c) as f64;
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let mut out = DMatrix::zeros(c, r);
            for (k, &s) in svd.singular_values.iter().enumerate() {
                if s > tol {
                    out += v_t.row(k).transpose() * u.column(k).transpose() / s;
                }
            }
            out
        }
        _ => DMatrix::zeros(c, r),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// All of Hᵀ/√j, experiment after experiment.
    fn hankel_transpose(
        experiments: &[Experiment],
        i: usize,
        layout: Layout,
        columns: usize,
    ) -> DMatrix<f64> {
        let scale = 1.0 / (columns as f64).sqrt();
        let mut h = DMatrix::zeros(0, layout.rows);
        for exp in experiments {
            let windows = exp.samples() + 1 - 2 * i;
            let block = hankel_rows(exp, i, layout, 0, windows, scale);
            let mut next = DMatrix::zeros(h.nrows() + windows, layout.rows);
            next.rows_mut(0, h.nrows()).copy_from(&h);
            next.rows_mut(h.nrows(), windows).copy_from(&block);
            h = next;
        }
        h
    }

    #[test]
    fn blockwise_lq_gives_the_gram_matrix_of_the_whole_hankel_matrix() {
        // L Lᵀ = H Hᵀ / j whatever the blocks: 3 experiments, one longer than a block.
        let i = 2;
        let layout = Layout::new(i, 1, 2);
        let exps: Vec<Experiment> = [BLOCK_WINDOWS + 500, 40, 7]
            .iter()
            .enumerate()
            .map(|(e, &n)| {
                Experiment::new(
                    DMatrix::from_fn(n, 1, |k, _| ((k * 7 + e) as f64 * 0.91).sin()),
                    DMatrix::from_fn(n, 2, |k, j| ((k * (j + 3) + e) as f64 * 0.53).cos()),
                )
            })
            .collect();
        let columns: usize = exps.iter().map(|e| e.samples() + 1 - 2 * i).sum();
        let h = hankel_transpose(&exps, i, layout, columns);
        let lower = lq_factor(&exps, i, layout, columns);
        let gram = h.transpose() * &h;
        let err = (&lower * lower.transpose() - &gram).amax();
        assert!(err < 1e-12 * gram.amax(), "{err}");
        let strictly_upper = lower.upper_triangle() - DMatrix::from_diagonal(&lower.diagonal());
        assert_eq!(strictly_upper.amax(), 0.0, "L is not lower triangular");
    }

    #[test]
    fn no_hankel_window_spans_two_experiments() {
        // Experiment e is constant e + 1: a window mixing two experiments would hold two
        // different values.
        let i = 3;
        let exps: Vec<Experiment> = (0..2)
            .map(|e| {
                Experiment::new(
                    DMatrix::from_element(10, 1, (e + 1) as f64),
                    DMatrix::from_element(10, 2, (e + 1) as f64),
                )
            })
            .collect();
        let layout = Layout::new(i, 1, 2);
        let columns = 2 * (10 + 1 - 2 * i);
        let h = hankel_transpose(&exps, i, layout, columns);
        assert_eq!(h.shape(), (10, 18));
        for (r, row) in h.row_iter().enumerate() {
            let expected = if r < 5 { 1.0_f64 } else { 2.0 } / (columns as f64).sqrt();
            assert!(
                row.iter().all(|&v| v == expected),
                "window {r} mixes experiments"
            );
        }
    }

    #[test]
    fn hankel_layout_puts_each_sample_where_the_projections_expect_it() {
        let i = 2;
        let n = 6;
        let u = DMatrix::from_fn(n, 1, |k, _| 100.0 + k as f64);
        let y = DMatrix::from_fn(n, 1, |k, _| k as f64);
        let layout = Layout::new(i, 1, 1);
        let h = hankel_transpose(&[Experiment::new(u, y)], i, layout, 3);
        let s = 3_f64.sqrt();
        // Window t = 1: [u_4; u_3; u_1 u_2; y_1 y_2; y_3; y_4].
        let row: Vec<f64> = h.row(1).iter().map(|v| (v * s).round()).collect();
        assert_eq!(row, vec![104.0, 103.0, 101.0, 102.0, 1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn too_few_samples_and_order_above_rank_are_errors() {
        let y = DMatrix::from_fn(12, 2, |k, j| ((k * (j + 2)) as f64).sin());
        let err = Subspace::new(&[Experiment::time_series(y.clone())], 4).unwrap_err();
        assert!(
            matches!(
                err,
                IdentError::TooFewSamples {
                    columns: 5,
                    rows: 16,
                    ..
                }
            ),
            "{err}"
        );
        let err =
            Subspace::new(&[Experiment::time_series(y.rows(0, 5).into_owned())], 3).unwrap_err();
        assert!(
            matches!(err, IdentError::ExperimentTooShort { needed: 6, .. }),
            "{err}"
        );
        let long = DMatrix::from_fn(400, 1, |k, _| (k as f64 * 0.9).sin());
        let sub = Subspace::new(&[Experiment::time_series(long)], 5).unwrap();
        // A pure sinusoid is order 2.
        assert_eq!(sub.max_order(), 2);
        let err = sub.model(3).unwrap_err();
        assert!(
            matches!(
                err,
                IdentError::OrderAboveRank {
                    order: 3,
                    max: 2,
                    ..
                }
            ),
            "{err}"
        );
    }
}
