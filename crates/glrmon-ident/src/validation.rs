//! Validation statistics of a predictor's innovations: fit (NRMSE), whiteness
//! (Ljung–Box) and consistency with Re (NIS).

use glrmon_core::threshold::chi2_sf;
use nalgebra::{DMatrix, DVector};

/// Normalised root-mean-square error per output column,
/// ‖y − ŷ‖ / ‖y − ȳ‖ (0 is a perfect fit, 1 is no better than the mean).
///
/// It is 1 − the "fit" of Ljung's `compare`; a column with no spread gives +∞ unless the
/// error is zero too (then 0). Columns beyond the shorter matrix's are ignored.
#[must_use]
pub fn nrmse(outputs: &DMatrix<f64>, predicted: &DMatrix<f64>) -> DVector<f64> {
    let p = outputs.ncols().min(predicted.ncols());
    let n = outputs.nrows().min(predicted.nrows());
    DVector::from_fn(p, |j, _| {
        if n == 0 {
            return f64::NAN;
        }
        let y = outputs.column(j);
        let mean = y.rows(0, n).sum() / n as f64;
        let (mut err, mut spread) = (0.0, 0.0);
        for k in 0..n {
            err += (y[k] - predicted[(k, j)]).powi(2);
            spread += (y[k] - mean).powi(2);
        }
        match (err == 0.0, spread == 0.0) {
            (true, _) => 0.0,
            (false, true) => f64::INFINITY,
            (false, false) => (err / spread).sqrt(),
        }
    })
}

/// The Ljung–Box portmanteau test of one innovation column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LjungBox {
    /// Q = N(N + 2) Σ_{k=1}^{h} r_k² / (N − k), r_k the sample autocorrelation at lag k.
    pub q: f64,
    /// Lags h = degrees of freedom of the χ² reference.
    pub lags: usize,
    /// P(χ²_h > Q): small values reject whiteness.
    pub p_value: f64,
}

/// Ljung–Box Q statistic of each column of `innovations` over lags 1..=`lags`, with its
/// χ²_h p-value.
///
/// Ref.: Ljung & Box (1978), *On a measure of lack of fit in time series models*,
/// Biometrika 65(2), 297–303; Ljung (1999), ch. 16 (residual analysis).
/// `lags` is clipped to N − 1; with N < 2 the statistic is 0 and the p-value 1.
#[must_use]
pub fn ljung_box(innovations: &DMatrix<f64>, lags: usize) -> Vec<LjungBox> {
    let n = innovations.nrows();
    let h = lags.min(n.saturating_sub(1));
    innovations
        .column_iter()
        .map(|col| {
            if h == 0 {
                return LjungBox {
                    q: 0.0,
                    lags: h,
                    p_value: 1.0,
                };
            }
            let mean = col.sum() / n as f64;
            let c0: f64 = col.iter().map(|v| (v - mean).powi(2)).sum();
            let mut q = 0.0;
            if c0 > 0.0 {
                for k in 1..=h {
                    let ck: f64 = (k..n).map(|t| (col[t] - mean) * (col[t - k] - mean)).sum();
                    let rk = ck / c0;
                    q += rk * rk / (n - k) as f64;
                }
            }
            let q = n as f64 * (n as f64 + 2.0) * q;
            LjungBox {
                q,
                lags: h,
                p_value: chi2_sf(h as f64, q),
            }
        })
        .collect()
}

/// Mean normalised innovation squared, (1/N) Σ e_kᵀ Re⁻¹ e_k. For a consistent model it
/// is close to p (χ²_p mean). `None` if Re is not positive definite or there is no
/// sample.
///
/// Ref.: Bar-Shalom, Li & Kirubarajan (2001), *Estimation with Applications to Tracking
/// and Navigation*, §5.4 (NIS test).
#[must_use]
pub fn nis_mean(innovations: &DMatrix<f64>, re: &DMatrix<f64>) -> Option<f64> {
    let n = innovations.nrows();
    if n == 0 || re.nrows() != innovations.ncols() {
        return None;
    }
    let chol = re.clone().cholesky()?;
    // ‖L⁻¹ e‖² for all rows at once: solve L Z = Eᵀ.
    let z = chol.l().solve_lower_triangular(&innovations.transpose())?;
    Some(z.norm_squared() / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ljung_box_rejects_an_ar1_and_accepts_an_uncorrelated_sequence() {
        // A ±1 sequence from a linear congruential generator's top bit is uncorrelated;
        // x_k = 0.5 x_{k−1} + that sequence has r_1 ≈ 0.5.
        let n = 4000;
        let mut state = 7u64;
        let white = DMatrix::from_fn(n, 1, |_, _| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            if state >> 63 == 1 { 1.0 } else { -1.0 }
        });
        let mut ar = white.clone();
        for k in 1..n {
            ar[(k, 0)] += 0.5 * ar[(k - 1, 0)];
        }
        let lb_ar = ljung_box(&ar, 20)[0];
        assert!(lb_ar.p_value < 1e-10, "{lb_ar:?}");
        assert_eq!(lb_ar.lags, 20);
        let lb_white = ljung_box(&white, 20)[0];
        assert!(lb_white.p_value > 0.01, "{lb_white:?}");
    }

    #[test]
    fn nrmse_of_the_mean_is_one_and_of_the_truth_zero() {
        let y = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 2.0, 0.0, 3.0, 0.0, 4.0, 0.0]);
        let mean = DMatrix::from_row_slice(4, 2, &[2.5, 0.0, 2.5, 0.0, 2.5, 0.0, 2.5, 0.0]);
        let fit = nrmse(&y, &mean);
        assert!((fit[0] - 1.0).abs() < 1e-15);
        assert_eq!(fit[1], 0.0);
        assert_eq!(nrmse(&y, &y)[0], 0.0);
    }

    #[test]
    fn nis_of_unit_innovations_is_their_mean_square() {
        let e = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 2.0]);
        let re = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 4.0]));
        assert!((nis_mean(&e, &re).unwrap() - 1.0).abs() < 1e-15);
    }
}
