//! The model step of a channel (`[channels.model]`): F and H, G and J, the noise
//! covariances Q and R, the initial state, E and S, each against the shapes the others
//! imply; then the dimensions, and the model's observability.

use glrmon_core::{Dims, Lpv, LpvMatrix};
use nalgebra::{DMatrix, DVector};

use super::{Validator, join};
use crate::covariance;
use crate::limits;
use crate::schema::ModelSpec;

/// The matrices of a channel's model, each of the shape the others imply.
pub(super) struct Matrices {
    pub(super) f: LpvMatrix,
    pub(super) g: LpvMatrix,
    pub(super) h: LpvMatrix,
    pub(super) j: LpvMatrix,
    pub(super) q: LpvMatrix,
    pub(super) r: LpvMatrix,
    /// The unknown-input matrix E, if given and n×q.
    pub(super) e: Option<LpvMatrix>,
    /// The cross-covariance S, if given and valid.
    pub(super) cross: Option<DMatrix<f64>>,
    /// P_0 (the identity when not given), unless it was refused.
    pub(super) p0: Option<LpvMatrix>,
    /// X̂_0 (zeros when not given or refused).
    pub(super) x0: DVector<f64>,
}

impl Validator {
    /// The model's matrices; `None` when F, H, G or J is refused or Q or R cannot be
    /// read, since the shapes of the rest (and of the faults) derive from them.
    pub(super) fn model(&mut self, prefix: &str, model: &ModelSpec) -> Option<Matrices> {
        // Dimensions: n from F (or H), p from H, l from G (or J).
        let (f, h) = self.state_and_outputs(prefix, model)?;
        let (n, p) = (f.shape().0, h.shape().0);
        let (g, j) = self.inputs(prefix, model, n, p)?;
        let (q, r) = self.noise(prefix, model, n, p)?;
        let (p0, x0) = self.initial_state(prefix, model, n);
        let e = model
            .e
            .as_ref()
            .and_then(|e| self.matrix(prefix, "E", e, None));
        let e =
            e.filter(|e| self.shape(prefix, "E", e, (n, e.shape().1), &format!("F is {n}×{n}")));
        let cross = self.cross_covariance(prefix, model, (n, p), e.is_some(), (&q, &r));
        Some(Matrices {
            f,
            g,
            h,
            j,
            q,
            r,
            e,
            cross,
            p0,
            x0,
        })
    }

    /// F and H: F square and non-empty, H with n columns and at least one row, and n
    /// and p within the limits.
    fn state_and_outputs(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let h = self.matrix(prefix, "H", &model.h, None);
        let n_hint = h.as_ref().map(|h| h.shape().1);
        let f = self.matrix(prefix, "F", &model.f, n_hint);
        let (Some(f), Some(h)) = (f, h) else {
            return None;
        };
        let (n, n2) = f.shape();
        if n != n2 || n == 0 {
            let hc = h.shape().1;
            let why = if hc != n2 {
                format!("is {n}×{n2} but H has {hc} columns")
            } else {
                format!("is {n}×{n2}: it must be square and non-empty")
            };
            self.error(join(prefix, "model.F"), why);
            return None;
        }
        let p = h.shape().0;
        if h.shape().1 != n {
            self.error(
                join(prefix, "model.F"),
                format!("is {n}×{n} but H has {} columns", h.shape().1),
            );
            return None;
        }
        if p == 0 {
            self.error(
                join(prefix, "model.H"),
                "has no rows: the channel needs at least one output".into(),
            );
            return None;
        }
        if !self.dimension_limits(prefix, n, p) {
            return None;
        }
        Some((f, h))
    }

    /// G and J: l from G (or J), no inputs when neither is given; G n×l and J p×l,
    /// and l within the limits.
    fn inputs(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        n: usize,
        p: usize,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let g = model
            .g
            .as_ref()
            .and_then(|g| self.matrix(prefix, "G", g, None));
        let j = model
            .j
            .as_ref()
            .and_then(|j| self.matrix(prefix, "J", j, None));
        let l = g
            .as_ref()
            .map(|g| g.shape().1)
            .or(j.as_ref().map(|j| j.shape().1))
            .unwrap_or(0);
        if (model.g.is_some() && g.is_none()) || (model.j.is_some() && j.is_none()) {
            // The error is recorded; l is unknown, so nothing below can be checked.
            return None;
        }
        let g = g.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(n, l)));
        let j = j.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(p, l)));
        // Every later product (faults, E, S, diagnosis) assumes these shapes: a
        // mismatch ends the channel's checks here instead of panicking in nalgebra.
        let g_ok = self.shape(
            prefix,
            "G",
            &g,
            (n, l),
            &format!("F is {n}×{n} and there are {l} inputs"),
        );
        let j_ok = self.shape(
            prefix,
            "J",
            &j,
            (p, l),
            &format!("H has {p} rows and there are {l} inputs"),
        );
        if !(g_ok && j_ok) {
            return None;
        }
        if l > limits::MAX_INPUTS {
            self.error(
                join(prefix, "model.G"),
                format!(
                    "has {l} columns (inputs): at most {} (limits::MAX_INPUTS)",
                    limits::MAX_INPUTS
                ),
            );
            return None;
        }
        Some((g, j))
    }

    /// Q (n×n, positive semi-definite) and R (p×p, positive definite), each replaced
    /// by its projection when it is only near that (see [`Validator::covariance`]).
    fn noise(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        n: usize,
        p: usize,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let mut q = self.matrix(prefix, "Q", &model.q, Some(n))?;
        let mut r = self.matrix(prefix, "R", &model.r, Some(p))?;
        if self.shape(prefix, "Q", &q, (n, n), &format!("F is {n}×{n}"))
            && let Some(projected) = self.covariance(prefix, "Q", &q, false)
        {
            q = projected;
        }
        if self.shape(prefix, "R", &r, (p, p), &format!("H has {p} rows"))
            && let Some(projected) = self.covariance(prefix, "R", &r, true)
        {
            r = projected;
        }
        Some((q, r))
    }

    /// P_0 (constant, n×n, positive definite; the identity when not given) and X̂_0
    /// (n finite entries; zeros when not given or refused).
    fn initial_state(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        n: usize,
    ) -> (Option<LpvMatrix>, DVector<f64>) {
        let p0 = match &model.p0 {
            Some(s) => self.matrix(prefix, "P0", s, Some(n)),
            None => Some(LpvMatrix::constant(DMatrix::identity(n, n))),
        };
        let p0 = p0.filter(|m| {
            m.terms().is_empty() || {
                self.error(
                    join(prefix, "model.P0"),
                    "cannot depend on scheduling signals".into(),
                );
                false
            }
        });
        let p0 = match p0 {
            Some(m) if self.shape(prefix, "P0", &m, (n, n), &format!("F is {n}×{n}")) => {
                Some(self.covariance(prefix, "P0", &m, true).unwrap_or(m))
            }
            other => other,
        };
        let x0 = match &model.x0 {
            Some(x) if x.len() != n => {
                self.error(
                    join(prefix, "model.x0"),
                    format!("has {} entries but F is {n}×{n}", x.len()),
                );
                DVector::zeros(n)
            }
            Some(x) if x.iter().any(|v| !v.is_finite()) => {
                self.error(join(prefix, "model.x0"), "is not finite".into());
                DVector::zeros(n)
            }
            Some(x) => DVector::from_column_slice(x),
            None => DVector::zeros(n),
        };
        (p0, x0)
    }

    /// The dimensions of the channel: n, p and l from the model, and the number of
    /// scheduling signals.
    pub(super) fn dims(
        &mut self,
        prefix: &str,
        signals: Option<usize>,
        m: &Matrices,
    ) -> Option<Dims> {
        // Signals: explicit, or the highest LPV index + 1.
        let lpv_max = [&m.f, &m.g, &m.h, &m.j, &m.q, &m.r]
            .into_iter()
            .chain(m.e.as_ref())
            .flat_map(|matrix| matrix.terms().iter().map(|(i, _)| *i + 1))
            .max()
            .unwrap_or(0);
        let signals = signals.unwrap_or(lpv_max);
        if signals > limits::MAX_SIGNALS {
            self.error(
                join(prefix, "signals"),
                format!(
                    "is {signals}: at most {} (limits::MAX_SIGNALS)",
                    limits::MAX_SIGNALS
                ),
            );
            return None;
        }
        if signals < lpv_max {
            self.error(
                join(prefix, "signals"),
                format!(
                    "is {signals} but the model uses scheduling signal p{}",
                    lpv_max - 1
                ),
            );
        }
        Some(Dims {
            states: m.f.shape().0,
            inputs: m.g.shape().1,
            outputs: m.h.shape().0,
            signals,
        })
    }

    /// `model.S`: constant, n×p, not with E, and the joint noise covariance
    /// `[[Q, S], [Sᵀ, R]]` positive semi-definite (checked at the base point of Q and R,
    /// with the relative tolerance of the near-PSD rule).
    fn cross_covariance(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        (n, p): (usize, usize),
        with_e: bool,
        (q, r): (&LpvMatrix, &LpvMatrix),
    ) -> Option<DMatrix<f64>> {
        let s = model
            .s
            .as_ref()
            .and_then(|s| self.matrix(prefix, "S", s, None))?;
        let path = join(prefix, "model.S");
        if !s.terms().is_empty() {
            self.error(path, "cannot depend on scheduling signals".into());
            return None;
        }
        if !self.shape(
            prefix,
            "S",
            &s,
            (n, p),
            &format!("F is {n}×{n} and H has {p} rows"),
        ) {
            return None;
        }
        if with_e {
            self.error(
                path,
                "cannot be combined with an unknown input (model.E): the decoupled filter \
                 assumes uncorrelated noises"
                    .into(),
            );
            return None;
        }
        let s = s.base().clone();
        if q.base().shape() == (n, n) && r.base().shape() == (p, p) {
            let mut joint = DMatrix::zeros(n + p, n + p);
            joint.view_mut((0, 0), (n, n)).copy_from(q.base());
            joint.view_mut((n, n), (p, p)).copy_from(r.base());
            joint.view_mut((0, n), (n, p)).copy_from(&s);
            joint.view_mut((n, 0), (p, n)).copy_from(&s.transpose());
            let eig = joint.symmetric_eigenvalues();
            let top = eig.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            let low = eig.iter().copied().fold(f64::INFINITY, f64::min);
            if low < -covariance::PSD_TOLERANCE * top {
                self.error(
                    path,
                    format!(
                        "makes the joint noise covariance [[Q, S], [Sᵀ, R]] indefinite \
                         (smallest eigenvalue {low:.3e}, largest {top:.3e}): |S| is too large \
                         for Q and R (for an innovation model, Q = K·Re·Kᵀ, R = Re, S = K·Re)"
                    ),
                );
                return None;
            }
        }
        Some(s)
    }

    /// n and p within [`limits::MAX_STATES`] and [`limits::MAX_OUTPUTS`].
    fn dimension_limits(&mut self, prefix: &str, n: usize, p: usize) -> bool {
        let mut ok = true;
        if n > limits::MAX_STATES {
            self.error(
                join(prefix, "model.F"),
                format!(
                    "is {n}×{n}: at most {} states (limits::MAX_STATES)",
                    limits::MAX_STATES
                ),
            );
            ok = false;
        }
        if p > limits::MAX_OUTPUTS {
            self.error(
                join(prefix, "model.H"),
                format!(
                    "has {p} rows: at most {} outputs (limits::MAX_OUTPUTS)",
                    limits::MAX_OUTPUTS
                ),
            );
            ok = false;
        }
        ok
    }

    pub(super) fn observability(&mut self, prefix: &str, model: &Lpv) {
        let [f, _, h, ..] = model.matrices();
        let (f, h) = (f.base(), h.base());
        let n = f.nrows();
        let mut o = observability_matrix(f, h, false);
        if !o.iter().all(|x| x.is_finite()) {
            // The powers of a large F overflow, and an SVD of a matrix with infinite
            // entries does not terminate: each block H F^i scaled to a largest entry
            // of 1 has the same rank.
            o = observability_matrix(f, h, true);
        }
        if !o.iter().all(|x| x.is_finite()) {
            self.warn(
                join(prefix, "model"),
                "the observability of (F, H) could not be checked: the products H F^i \
                 overflow"
                    .into(),
            );
            return;
        }
        let sv = o.singular_values();
        let smax = sv.max();
        let rank = sv.iter().filter(|s| **s > 1e-9 * smax).count();
        if rank < n {
            self.warn(
                join(prefix, "model"),
                format!(
                    "(F, H) is not observable at the base point: the observability matrix has rank {rank} < n = {n}"
                ),
            );
        }
    }
}

/// [H; HF; …; HF^(n−1)], each block scaled to a largest entry of 1 if `scaled`.
fn observability_matrix(f: &DMatrix<f64>, h: &DMatrix<f64>, scaled: bool) -> DMatrix<f64> {
    let (n, p) = (f.nrows(), h.nrows());
    let mut o = DMatrix::zeros(p * n, n);
    let mut block = h.clone();
    for i in 0..n {
        o.view_mut((i * p, 0), (p, n)).copy_from(&block);
        block = &block * f;
        let largest = block.amax();
        if scaled && largest > 0.0 && largest.is_finite() {
            block /= largest;
        }
    }
    o
}
