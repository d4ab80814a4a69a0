//! Linear time-varying state-space models, evaluated once per sample.
//!
//! The monitored plant is (Zhang & Basseville 2014, eq. (1)):
//!
//! ```text
//! X_{k+1} = F_k X_k + G_k U_k + W_k,   W_k ~ N(0, Q_k)
//! Y_k     = H_k X_k + J_k U_k + V_k,   V_k ~ N(0, R_k)
//! ```
//!
//! Every matrix may change at every step. [`Lpv`] covers the common cases
//! (constant, or affine in scheduling signals: M_k = M_0 + Σ_i p_i(k) M_i, as in
//! the paper's eq. (53)); any other law is a [`StateSpace`] implementation.

pub mod continuous;
pub mod fault;
pub mod scaling;

use nalgebra::DMatrix;

use crate::error::ModelError;

/// Dimensions of a channel: states, known inputs, outputs, scheduling signals.
///
/// Letters follow Zhang & Basseville 2014: n states, l inputs, p outputs; q is the
/// length of the sample's exogenous vector `p` (scheduling parameters and other known
/// signals: the `p0…` columns of docs/CLI.md, the `p` field of docs/WIRE.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// n: state dimension.
    pub states: usize,
    /// l: known-input dimension (may be 0).
    pub inputs: usize,
    /// p: output dimension.
    pub outputs: usize,
    /// q: number of exogenous signals carried by each sample (may be 0).
    pub signals: usize,
}

/// The known signals of one sample: inputs U_k and exogenous signals p(k).
#[derive(Debug, Clone, Copy)]
pub struct Signals<'a> {
    /// U_k, length l.
    pub u: &'a [f64],
    /// p(k), length q.
    pub p: &'a [f64],
}

/// The system matrices at one step, F_k, G_k, H_k, J_k, Q_k, R_k.
///
/// Allocated once with the channel's [`Dims`] and overwritten in place every step.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemMatrices {
    /// F_k (n×n), state transition.
    pub f: DMatrix<f64>,
    /// G_k (n×l), input to state.
    pub g: DMatrix<f64>,
    /// H_k (p×n), state to output.
    pub h: DMatrix<f64>,
    /// J_k (p×l), direct feed-through.
    pub j: DMatrix<f64>,
    /// Q_k (n×n), process-noise covariance.
    pub q: DMatrix<f64>,
    /// R_k (p×p), measurement-noise covariance.
    pub r: DMatrix<f64>,
}

impl SystemMatrices {
    /// All-zero matrices of the given dimensions.
    #[must_use]
    pub fn zeros(dims: Dims) -> Self {
        let (n, l, p) = (dims.states, dims.inputs, dims.outputs);
        Self {
            f: DMatrix::zeros(n, n),
            g: DMatrix::zeros(n, l),
            h: DMatrix::zeros(p, n),
            j: DMatrix::zeros(p, l),
            q: DMatrix::zeros(n, n),
            r: DMatrix::zeros(p, p),
        }
    }

    /// Whether every entry of every matrix is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        // A value is not finite when its exponent bits are all ones: OR-ing that test
        // over the entries is branch-free and vectorisable (checked at every sample),
        // unlike a test and a branch per entry.
        const EXP: u64 = 0x7ff0_0000_0000_0000;
        let any_nonfinite = |m: &DMatrix<f64>| {
            m.as_slice()
                .iter()
                .fold(false, |a, x| a | (x.to_bits() & EXP == EXP))
        };
        ![&self.f, &self.g, &self.h, &self.j, &self.q, &self.r]
            .iter()
            .fold(false, |a, m| a | any_nonfinite(m))
    }
}

/// A linear time-varying model: fills the system matrices for step k.
///
/// Implementations must be deterministic (same calls, same results) and must not
/// allocate in [`StateSpace::evaluate`]: it is on the per-sample path.
pub trait StateSpace: Send + std::fmt::Debug {
    /// The model's dimensions.
    fn dims(&self) -> Dims;

    /// Writes F_k, G_k, H_k, J_k, Q_k, R_k for sample `k` with known signals `signals`
    /// into `out` (already sized by [`SystemMatrices::zeros`]), every entry: on entry
    /// `out` may hold the matrices of any earlier sample, not necessarily the last (the
    /// detector exchanges buffers instead of copying them).
    fn evaluate(&mut self, k: u64, signals: &Signals<'_>, out: &mut SystemMatrices);

    /// True when the matrices never change (an LTI model). Lets callers take
    /// shortcuts that are exact only for constant matrices.
    fn is_constant(&self) -> bool {
        false
    }
}

/// A matrix affine in scheduling signals: M_k = M_0 + Σ_i p_{s_i}(k) M_i.
///
/// Ref.: Zhang & Basseville 2014, eq. (53) (LPV model of a gas network).
#[derive(Debug, Clone, PartialEq)]
pub struct LpvMatrix {
    base: DMatrix<f64>,
    terms: Vec<(usize, DMatrix<f64>)>,
}

impl LpvMatrix {
    /// A constant matrix.
    #[must_use]
    pub fn constant(base: DMatrix<f64>) -> Self {
        Self {
            base,
            terms: Vec::new(),
        }
    }

    /// A matrix with scheduling terms `(signal index, M_i)`.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when a term's shape differs from the base's.
    pub fn new(base: DMatrix<f64>, terms: Vec<(usize, DMatrix<f64>)>) -> Result<Self, ModelError> {
        for (i, (_, m)) in terms.iter().enumerate() {
            if m.shape() != base.shape() {
                return Err(ModelError::Dimension {
                    what: "LPV term",
                    detail: format!(
                        "term {i} is {}×{} but the base matrix is {}×{}",
                        m.nrows(),
                        m.ncols(),
                        base.nrows(),
                        base.ncols()
                    ),
                });
            }
        }
        Ok(Self { base, terms })
    }

    /// M_0.
    #[must_use]
    pub fn base(&self) -> &DMatrix<f64> {
        &self.base
    }

    /// The scheduling terms `(signal index, M_i)`.
    #[must_use]
    pub fn terms(&self) -> &[(usize, DMatrix<f64>)] {
        &self.terms
    }

    /// Shape (rows, columns).
    #[must_use]
    pub fn shape(&self) -> (usize, usize) {
        self.base.shape()
    }

    /// Writes M_0 + Σ_i p_{s_i} M_i into `out` (same shape), without allocating.
    /// A scheduling index beyond `p` reads as 0 (the builder rejects such models).
    #[inline]
    pub fn evaluate_into(&self, p: &[f64], out: &mut DMatrix<f64>) {
        let out = out.as_mut_slice();
        out.copy_from_slice(self.base.as_slice());
        for (signal, m) in &self.terms {
            let weight = p.get(*signal).copied().unwrap_or(0.0);
            for (o, x) in out.iter_mut().zip(m.as_slice()) {
                *o += weight * x;
            }
        }
    }

    fn max_signal(&self) -> Option<usize> {
        self.terms.iter().map(|(s, _)| *s).max()
    }
}

/// An LPV (or LTI) model: each of F, G, H, J, Q, R is an [`LpvMatrix`].
///
/// # Examples
/// ```
/// use glrmon_core::model::{Lpv, LpvMatrix, StateSpace};
/// use nalgebra::DMatrix;
/// // The unstable plant of Zhang & Basseville 2014, §6.1 (eqs. 51-52).
/// let model = Lpv::lti(
///     DMatrix::from_row_slice(2, 2, &[0.5, 1.0, 0.0, 1.2]),
///     DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
///     DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
///     DMatrix::zeros(1, 1),
///     DMatrix::identity(2, 2) * 0.0025,
///     DMatrix::from_element(1, 1, 0.0025),
/// )
/// .unwrap();
/// assert_eq!(model.dims().states, 2);
/// assert!(model.is_constant());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Lpv {
    dims: Dims,
    f: LpvMatrix,
    g: LpvMatrix,
    h: LpvMatrix,
    j: LpvMatrix,
    q: LpvMatrix,
    r: LpvMatrix,
}

impl Lpv {
    /// Builds and checks an LPV model with `signals` exogenous signals per sample.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] naming the matrix whose shape disagrees with F and H,
    /// or a scheduling index not below `signals`; [`ModelError::NonFinite`] for NaN/Inf.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        f: LpvMatrix,
        g: LpvMatrix,
        h: LpvMatrix,
        j: LpvMatrix,
        q: LpvMatrix,
        r: LpvMatrix,
        signals: usize,
    ) -> Result<Self, ModelError> {
        let (n, n2) = f.shape();
        if n != n2 || n == 0 {
            return Err(dim_err(
                "F",
                format!("F must be square and non-empty, got {n}×{n2}"),
            ));
        }
        let (p, hn) = h.shape();
        if hn != n || p == 0 {
            return Err(dim_err("H", format!("H is {p}×{hn} but F is {n}×{n}")));
        }
        let (gn, l) = g.shape();
        if gn != n {
            return Err(dim_err("G", format!("G has {gn} rows but F is {n}×{n}")));
        }
        if j.shape() != (p, l) {
            let (a, b) = j.shape();
            return Err(dim_err("J", format!("J is {a}×{b}, expected {p}×{l}")));
        }
        if q.shape() != (n, n) {
            let (a, b) = q.shape();
            return Err(dim_err("Q", format!("Q is {a}×{b}, expected {n}×{n}")));
        }
        if r.shape() != (p, p) {
            let (a, b) = r.shape();
            return Err(dim_err("R", format!("R is {a}×{b}, expected {p}×{p}")));
        }
        for (name, m) in [
            ("F", &f),
            ("G", &g),
            ("H", &h),
            ("J", &j),
            ("Q", &q),
            ("R", &r),
        ] {
            if let Some(s) = m.max_signal()
                && s >= signals
            {
                return Err(dim_err(
                    name,
                    format!("scheduling signal p{s} used but samples carry {signals} signals"),
                ));
            }
            let finite = m.base.iter().all(|x| x.is_finite())
                && m.terms.iter().all(|(_, t)| t.iter().all(|x| x.is_finite()));
            if !finite {
                return Err(ModelError::NonFinite { what: name });
            }
        }
        Ok(Self {
            dims: Dims {
                states: n,
                inputs: l,
                outputs: p,
                signals,
            },
            f,
            g,
            h,
            j,
            q,
            r,
        })
    }

    /// A linear time-invariant model (no scheduling signals).
    ///
    /// # Errors
    /// As [`Lpv::new`].
    pub fn lti(
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        j: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DMatrix<f64>,
    ) -> Result<Self, ModelError> {
        Self::new(
            LpvMatrix::constant(f),
            LpvMatrix::constant(g),
            LpvMatrix::constant(h),
            LpvMatrix::constant(j),
            LpvMatrix::constant(q),
            LpvMatrix::constant(r),
            0,
        )
    }

    /// Sets the number of exogenous signals each sample carries (at least the highest
    /// scheduling index + 1).
    ///
    /// # Errors
    /// [`ModelError::Dimension`] when a scheduling index is not below `signals`.
    pub fn with_signals(self, signals: usize) -> Result<Self, ModelError> {
        Self::new(self.f, self.g, self.h, self.j, self.q, self.r, signals)
    }

    /// The six matrices, in the order F, G, H, J, Q, R.
    #[must_use]
    pub fn matrices(&self) -> [&LpvMatrix; 6] {
        [&self.f, &self.g, &self.h, &self.j, &self.q, &self.r]
    }
}

fn dim_err(what: &'static str, detail: String) -> ModelError {
    ModelError::Dimension { what, detail }
}

impl StateSpace for Lpv {
    fn dims(&self) -> Dims {
        self.dims
    }

    fn evaluate(&mut self, _k: u64, signals: &Signals<'_>, out: &mut SystemMatrices) {
        self.f.evaluate_into(signals.p, &mut out.f);
        self.g.evaluate_into(signals.p, &mut out.g);
        self.h.evaluate_into(signals.p, &mut out.h);
        self.j.evaluate_into(signals.p, &mut out.j);
        self.q.evaluate_into(signals.p, &mut out.q);
        self.r.evaluate_into(signals.p, &mut out.r);
    }

    fn is_constant(&self) -> bool {
        self.matrices().iter().all(|m| m.terms.is_empty())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn is_finite_rejects_each_non_finite_value_in_each_matrix() {
        let dims = Dims {
            states: 2,
            inputs: 1,
            outputs: 1,
            signals: 0,
        };
        let edge = [0.0, -0.0, f64::MAX, f64::MIN, f64::MIN_POSITIVE, 5e-324];
        for value in edge {
            let mut s = SystemMatrices::zeros(dims);
            s.q[(1, 1)] = value;
            assert!(s.is_finite(), "{value}");
        }
        for value in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for m in 0..6 {
                let mut s = SystemMatrices::zeros(dims);
                let target = [&mut s.f, &mut s.g, &mut s.h, &mut s.j, &mut s.q, &mut s.r];
                let last = target[m].len() - 1;
                target.into_iter().nth(m).unwrap()[last] = value;
                assert!(!s.is_finite(), "{value} in matrix {m}");
            }
        }
    }

    #[test]
    fn lpv_evaluates_affine_combination() {
        let f = LpvMatrix::new(
            DMatrix::identity(2, 2),
            vec![
                (0, DMatrix::from_element(2, 2, 1.0)),
                (1, DMatrix::identity(2, 2)),
            ],
        )
        .unwrap();
        let mut out = DMatrix::zeros(2, 2);
        f.evaluate_into(&[2.0, -1.0], &mut out);
        assert_eq!(out, DMatrix::from_row_slice(2, 2, &[2.0, 2.0, 2.0, 2.0]));
    }

    #[test]
    fn lpv_rejects_mismatched_shapes_and_naming_the_matrix() {
        let err = Lpv::lti(
            DMatrix::identity(3, 3),
            DMatrix::zeros(3, 0),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 0),
            DMatrix::identity(3, 3),
            DMatrix::identity(1, 1),
        )
        .unwrap_err();
        assert!(err.to_string().contains("H is 1×2 but F is 3×3"), "{err}");
    }

    #[test]
    fn lpv_rejects_scheduling_index_beyond_signals() {
        let f =
            LpvMatrix::new(DMatrix::identity(1, 1), vec![(3, DMatrix::identity(1, 1))]).unwrap();
        let c = |r, c| LpvMatrix::constant(DMatrix::identity(r, c));
        let err = Lpv::new(f, c(1, 0), c(1, 1), c(1, 0), c(1, 1), c(1, 1), 2).unwrap_err();
        assert!(err.to_string().contains("p3"), "{err}");
    }
}
