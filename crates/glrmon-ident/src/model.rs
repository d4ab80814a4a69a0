//! The innovation model, its noise model (Riccati) and its one-step predictor.

use nalgebra::{Complex, DMatrix, DVector};

use crate::error::{IdentError, Signal};

/// A discrete-time LTI model in innovation form,
///
/// x_{k+1} = A x_k + B u_k + K e_k,   y_k = C x_k + D u_k + e_k,   e_k ~ (0, Re) white,
///
/// with the forward (general, correlated) noise model it came from:
/// x_{k+1} = A x_k + B u_k + w_k, y_k = C x_k + D u_k + v_k,
/// E[w wᵀ] = Q, E[w vᵀ] = S, E[v vᵀ] = R.
///
/// Ref.: Van Overschee & De Moor (1996), *Subspace Identification for Linear Systems*,
/// ch. 4 (the combined deterministic–stochastic model and its forward innovation form);
/// Ljung (1999), *System Identification*, §4.3 (state-space models, innovations form).
#[derive(Debug, Clone, PartialEq)]
pub struct InnovationModel {
    /// A (n × n).
    pub a: DMatrix<f64>,
    /// B (n × l).
    pub b: DMatrix<f64>,
    /// C (p × n).
    pub c: DMatrix<f64>,
    /// D (p × l).
    pub d: DMatrix<f64>,
    /// Steady Kalman gain K (n × p).
    pub k: DMatrix<f64>,
    /// Innovation covariance Re = C P Cᵀ + R (p × p).
    pub re: DMatrix<f64>,
    /// Process noise covariance Q (n × n) of the forward model.
    pub q: DMatrix<f64>,
    /// Cross covariance S = E[w vᵀ] (n × p).
    pub s: DMatrix<f64>,
    /// Measurement noise covariance R (p × p).
    pub r: DMatrix<f64>,
    /// Steady one-step prediction error covariance P (n × n), the Riccati solution.
    pub p: DMatrix<f64>,
}

/// The result of running the one-step predictor over a record.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// ŷ_{k|k−1}, one row per sample (N × p).
    pub predicted: DMatrix<f64>,
    /// Innovations e_k = y_k − ŷ_{k|k−1} (N × p).
    pub innovations: DMatrix<f64>,
}

impl InnovationModel {
    /// State dimension n.
    #[must_use]
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Number of inputs l.
    #[must_use]
    pub fn inputs(&self) -> usize {
        self.b.ncols()
    }

    /// Number of outputs p.
    #[must_use]
    pub fn outputs(&self) -> usize {
        self.c.nrows()
    }

    /// Eigenvalues of A (the poles), sorted by decreasing modulus then argument.
    #[must_use]
    pub fn poles(&self) -> Vec<Complex<f64>> {
        sorted_eigenvalues(&self.a)
    }

    /// Spectral radius of the predictor's state matrix A − K C: below 1 the one-step
    /// predictor forgets its initial state and its innovations are stationary.
    #[must_use]
    pub fn predictor_spectral_radius(&self) -> f64 {
        spectral_radius(&(&self.a - &self.k * &self.c))
    }

    /// Markov parameters: D, then C A^j B for j = 0..count−1 (the impulse response).
    #[must_use]
    pub fn markov_parameters(&self, count: usize) -> Vec<DMatrix<f64>> {
        let mut out = Vec::with_capacity(count + 1);
        out.push(self.d.clone());
        let mut ab = self.b.clone();
        for _ in 0..count {
            out.push(&self.c * &ab);
            ab = &self.a * ab;
        }
        out
    }

    /// Runs the steady one-step-ahead predictor
    /// x̂_{k+1} = A x̂_k + B u_k + K (y_k − C x̂_k − D u_k) from x̂_0 = `x0` (zero if `None`)
    /// over `inputs` (N × l) and `outputs` (N × p), in the model's (deviation) coordinates.
    ///
    /// Ref.: Ljung (1999), §4.3 (the predictor of the innovations form).
    ///
    /// # Errors
    /// [`IdentError::DimensionMismatch`] when the columns do not match l and p or `x0`
    /// does not match n; [`IdentError::RowMismatch`] (experiment 0) when the row counts
    /// differ.
    pub fn predict(
        &self,
        inputs: &DMatrix<f64>,
        outputs: &DMatrix<f64>,
        x0: Option<&DVector<f64>>,
    ) -> Result<Prediction, IdentError> {
        let (n, l, p) = (self.order(), self.inputs(), self.outputs());
        if inputs.ncols() != l {
            return Err(IdentError::DimensionMismatch {
                signal: Signal::Input,
                got: inputs.ncols(),
                expected: l,
            });
        }
        if outputs.ncols() != p {
            return Err(IdentError::DimensionMismatch {
                signal: Signal::Output,
                got: outputs.ncols(),
                expected: p,
            });
        }
        if inputs.nrows() != outputs.nrows() {
            return Err(IdentError::RowMismatch {
                experiment: 0,
                input_rows: inputs.nrows(),
                output_rows: outputs.nrows(),
            });
        }
        let mut x = match x0 {
            Some(x0) if x0.len() != n => {
                return Err(IdentError::DimensionMismatch {
                    signal: Signal::Input,
                    got: x0.len(),
                    expected: n,
                });
            }
            Some(x0) => x0.clone(),
            None => DVector::zeros(n),
        };
        let samples = outputs.nrows();
        let mut predicted = DMatrix::zeros(samples, p);
        let mut innovations = DMatrix::zeros(samples, p);
        // Workspaces allocated once: the loop itself allocates nothing.
        let mut u = DVector::zeros(l);
        let mut yhat = DVector::zeros(p);
        let mut e = DVector::zeros(p);
        let mut x_next = DVector::zeros(n);
        for k in 0..samples {
            u.iter_mut()
                .zip(inputs.row(k).iter())
                .for_each(|(d, s)| *d = *s);
            yhat.gemv(1.0, &self.c, &x, 0.0);
            yhat.gemv(1.0, &self.d, &u, 1.0);
            for j in 0..p {
                e[j] = outputs[(k, j)] - yhat[j];
                predicted[(k, j)] = yhat[j];
                innovations[(k, j)] = e[j];
            }
            x_next.gemv(1.0, &self.a, &x, 0.0);
            x_next.gemv(1.0, &self.b, &u, 1.0);
            x_next.gemv(1.0, &self.k, &e, 1.0);
            std::mem::swap(&mut x, &mut x_next);
        }
        Ok(Prediction {
            predicted,
            innovations,
        })
    }
}

/// Eigenvalues of a square matrix, sorted by decreasing modulus, then decreasing
/// imaginary part (so conjugate pairs come + then −).
#[must_use]
pub fn sorted_eigenvalues(m: &DMatrix<f64>) -> Vec<Complex<f64>> {
    if m.nrows() == 0 || m.nrows() != m.ncols() {
        return Vec::new();
    }
    let mut eig: Vec<Complex<f64>> = m.complex_eigenvalues().iter().copied().collect();
    eig.sort_by(|a, b| {
        b.norm()
            .total_cmp(&a.norm())
            .then(b.re.total_cmp(&a.re))
            .then(b.im.total_cmp(&a.im))
    });
    eig
}

/// Largest eigenvalue modulus (0 for an empty matrix).
#[must_use]
pub fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    sorted_eigenvalues(m).first().map_or(0.0, |z| z.norm())
}

/// Maximum iterations of the Riccati difference equation.
const RICCATI_MAX_ITERATIONS: usize = 100_000;
/// Relative change at which the Riccati iteration has converged.
const RICCATI_TOLERANCE: f64 = 1e-12;

/// The stabilising solution of the filter Riccati equation and what follows from it.
#[derive(Debug, Clone, PartialEq)]
pub struct RiccatiSolution {
    /// Steady one-step prediction error covariance P.
    pub p: DMatrix<f64>,
    /// Kalman gain K = (A P Cᵀ + S) Re⁻¹ (predictor form).
    pub k: DMatrix<f64>,
    /// Innovation covariance Re = C P Cᵀ + R.
    pub re: DMatrix<f64>,
    /// Iterations of the difference equation until convergence.
    pub iterations: usize,
}

/// Solves the filter-form discrete algebraic Riccati equation
///
/// P = A P Aᵀ + Q − (A P Cᵀ + S)(C P Cᵀ + R)⁻¹(A P Cᵀ + S)ᵀ
///
/// by iterating the Riccati difference equation from P = 0 (monotone convergence to
/// the stabilising solution when (A, C) is detectable and the noise model is positive
/// semi-definite), and returns P, K and Re with K = (A P Cᵀ + S) Re⁻¹, Re = C P Cᵀ + R.
///
/// Ref.: Van Overschee & De Moor (1996), ch. 4 (from Q, S, R to the forward innovation
/// model through the Riccati equation); Anderson & Moore (1979), *Optimal Filtering*,
/// ch. 4 (the time-invariant filter and the convergence of the Riccati difference
/// equation).
///
/// # Errors
/// [`IdentError::NotPositiveDefinite`] when C P Cᵀ + R is not positive definite,
/// [`IdentError::RiccatiNotConverged`] when the iteration does not settle.
pub fn solve_riccati(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    q: &DMatrix<f64>,
    s: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<RiccatiSolution, IdentError> {
    let n = a.nrows();
    let mut p = DMatrix::<f64>::zeros(n, n);
    let mut change = f64::INFINITY;
    for iteration in 1..=RICCATI_MAX_ITERATIONS {
        let re = c * &p * c.transpose() + r;
        let chol = re
            .clone()
            .cholesky()
            .ok_or(IdentError::NotPositiveDefinite {
                what: "the innovation covariance C P Cᵀ + R",
            })?;
        let g = a * &p * c.transpose() + s;
        // g Re⁻¹ gᵀ through the Cholesky factor: stable and symmetric.
        let k = chol.solve(&g.transpose()).transpose();
        let mut next = a * &p * a.transpose() + q - &k * g.transpose();
        next = (&next + next.transpose()) * 0.5;
        change = (&next - &p).norm() / (1.0 + next.norm());
        p = next;
        if !change.is_finite() {
            // Diverged (an unstable, undetectable mode): P overflows.
            return Err(IdentError::RiccatiNotConverged {
                iterations: iteration,
                change,
            });
        }
        if change < RICCATI_TOLERANCE {
            let re = c * &p * c.transpose() + r;
            let re = (&re + re.transpose()) * 0.5;
            let chol = re
                .clone()
                .cholesky()
                .ok_or(IdentError::NotPositiveDefinite {
                    what: "the innovation covariance C P Cᵀ + R",
                })?;
            let g = a * &p * c.transpose() + s;
            let k = chol.solve(&g.transpose()).transpose();
            return Ok(RiccatiSolution {
                p,
                k,
                re,
                iterations: iteration,
            });
        }
    }
    Err(IdentError::RiccatiNotConverged {
        iterations: RICCATI_MAX_ITERATIONS,
        change,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn riccati_scalar_matches_closed_form() {
        // x⁺ = a x + w, y = x + v, Q = q, R = r, S = 0:
        // P = a²P + q − a²P²/(P + r)  ⇒  P² + P (r(1 − a²) − q) − q r = 0.
        let (a, q, r) = (0.9_f64, 0.5, 2.0);
        let b = r * (1.0 - a * a) - q;
        let p_exact = (-b + (b * b + 4.0 * q * r).sqrt()) / 2.0;
        let m = |v: f64| DMatrix::from_element(1, 1, v);
        let RiccatiSolution { p, k, re, .. } =
            solve_riccati(&m(a), &m(1.0), &m(q), &m(0.0), &m(r)).unwrap();
        assert!((p[(0, 0)] - p_exact).abs() < 1e-10);
        assert!((re[(0, 0)] - (p_exact + r)).abs() < 1e-10);
        assert!((k[(0, 0)] - a * p_exact / (p_exact + r)).abs() < 1e-10);
    }

    #[test]
    fn undetectable_unstable_mode_is_an_error_not_a_nan() {
        // x⁺ = 2x + w never seen (C = 0): P doubles forever.
        let m = |v: f64| DMatrix::from_element(1, 1, v);
        let err = solve_riccati(&m(2.0), &m(0.0), &m(1.0), &m(0.0), &m(1.0)).unwrap_err();
        assert!(
            matches!(err, IdentError::RiccatiNotConverged { iterations, .. } if iterations < 2000),
            "{err}"
        );
        assert!(err.to_string().contains("detectable"));
    }

    #[test]
    fn innovation_form_noise_gives_back_k_and_re() {
        // Q = K Re Kᵀ, S = K Re, R = Re  ⇒  P = 0, gain K, covariance Re.
        let a = DMatrix::from_row_slice(2, 2, &[0.8, 0.1, 0.0, 0.5]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 1.0]);
        let k = DMatrix::from_row_slice(2, 1, &[0.4, 0.2]);
        let re = DMatrix::from_element(1, 1, 0.3);
        let RiccatiSolution {
            p,
            k: k_hat,
            re: re_hat,
            ..
        } = solve_riccati(&a, &c, &(&k * &re * k.transpose()), &(&k * &re), &re).unwrap();
        assert!(p.norm() < 1e-12);
        assert!((k_hat - k).norm() < 1e-12);
        assert!((re_hat - re).norm() < 1e-12);
    }

    #[test]
    fn predictor_of_a_static_gain_returns_the_output_residual() {
        let model = InnovationModel {
            a: DMatrix::zeros(1, 1),
            b: DMatrix::zeros(1, 1),
            c: DMatrix::zeros(1, 1),
            d: DMatrix::from_element(1, 1, 2.0),
            k: DMatrix::zeros(1, 1),
            re: DMatrix::identity(1, 1),
            q: DMatrix::zeros(1, 1),
            s: DMatrix::zeros(1, 1),
            r: DMatrix::identity(1, 1),
            p: DMatrix::zeros(1, 1),
        };
        let u = DMatrix::from_row_slice(3, 1, &[1.0, 2.0, 3.0]);
        let y = DMatrix::from_row_slice(3, 1, &[2.5, 4.0, 5.0]);
        let pred = model.predict(&u, &y, None).unwrap();
        assert_eq!(pred.innovations.as_slice(), &[0.5, 0.0, -1.0]);
        let err = model.predict(&u, &DMatrix::zeros(3, 2), None).unwrap_err();
        assert!(matches!(
            err,
            IdentError::DimensionMismatch {
                signal: Signal::Output,
                ..
            }
        ));
    }
}
