//! The model step of a channel (`[channels.model]`): F and H, G and J, the noise
//! covariances Q and R, the initial state, E and S, each against the shapes the others
//! imply; then the dimensions, and the model's observability.
//!
//! A state equation written in continuous time (A, B, Qc with the channel's `period`)
//! goes through the same checks under its own letters, and is then discretised with a
//! zero-order hold ([`glrmon_core::model::continuous`]): everything after this step sees
//! F, G and Q.

use glrmon_core::model::continuous::{self, ContinuousError, Discretisation};
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
    /// F_d, the unknown input's effect on the outputs, if given and p×q.
    pub(super) fd: Option<DMatrix<f64>>,
    /// The cross-covariance S, if given and valid.
    pub(super) cross: Option<DMatrix<f64>>,
    /// P_0 (the identity when not given), unless it was refused.
    pub(super) p0: Option<LpvMatrix>,
    /// X̂_0 (zeros when not given or refused).
    pub(super) x0: DVector<f64>,
    /// How F, G (and Q) were computed from a continuous-time model, if it was one.
    pub(super) discretised: Option<Discretisation>,
}

/// How the state equation is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Form {
    /// X_{k+1} = F X_k + G U_k + W_k, cov(W_k) = Q.
    Discrete,
    /// dx/dt = A x + B u + w, E[w(t)w(s)ᵀ] = Qc δ(t − s), sampled every `period` s.
    Continuous,
}

impl Form {
    /// The letters of the state and input matrices as written.
    fn letters(self) -> (&'static str, &'static str) {
        match self {
            Form::Discrete => ("F", "G"),
            Form::Continuous => ("A", "B"),
        }
    }
}

impl Validator {
    /// The model's matrices; `None` when F, H, G or J is refused or Q or R cannot be
    /// read, since the shapes of the rest (and of the faults) derive from them. A
    /// continuous-time model (A, B, Qc) is checked the same way under its letters and
    /// discretised with the channel's `period`.
    pub(super) fn model(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        period: Option<f64>,
    ) -> Option<Matrices> {
        let before = self.errors.len();
        if let Some(t) = period
            && !(t.is_finite() && t > 0.0)
        {
            self.error(
                join(prefix, "period"),
                format!("is {t}: the sample period must be a finite, positive number of seconds"),
            );
        }
        let form = self.form(prefix, model)?;
        // Dimensions: n from F or A (or H), p from H, l from G or B (or J).
        let (f, h) = self.state_and_outputs(prefix, model, form)?;
        let (n, p) = (f.shape().0, h.shape().0);
        let (g, j) = self.inputs(prefix, model, form, n, p)?;
        let (q, r) = self.noise(prefix, model, form, n, p)?;
        let (f, g, q, discretised) = match form {
            Form::Discrete => (f, g, q, None),
            // A, B, Qc with an error already reported (a shape, a Qc that is not PSD)
            // are not discretised: the error would come twice, or the result be wrong.
            Form::Continuous if self.errors.len() > before => return None,
            Form::Continuous => {
                let (f, g, q, d) =
                    self.discretise(prefix, period, (&f, &g, &q), model.qc.is_some())?;
                (f, g, q, Some(d))
            }
        };
        let (p0, x0) = self.initial_state(prefix, model, n);
        let e = model
            .e
            .as_ref()
            .and_then(|e| self.matrix(prefix, "E", e, None));
        let e =
            e.filter(|e| self.shape(prefix, "E", e, (n, e.shape().1), &format!("F is {n}×{n}")));
        let cross = self.cross_covariance(prefix, model, (n, p), e.is_some(), (&q, &r));
        let fd = model.fd.as_ref().and_then(|fd| {
            let Some(e) = &e else {
                self.error(
                    join(prefix, "model.Fd"),
                    "needs model.E: F_d is the effect on the outputs of E's unknown input \
                     (give E = zeros if it reaches only the outputs)"
                        .into(),
                );
                return None;
            };
            let q_cols = e.shape().1;
            let m = self.matrix(prefix, "Fd", fd, None)?;
            if !m.terms().is_empty() {
                self.error(join(prefix, "model.Fd"), "must be constant".into());
                return None;
            }
            self.shape(
                prefix,
                "Fd",
                &m,
                (p, q_cols),
                &format!("H has {p} rows and E {q_cols} columns"),
            )
            .then(|| m.base().clone())
        });
        Some(Matrices {
            f,
            g,
            h,
            j,
            q,
            r,
            e,
            fd,
            cross,
            p0,
            x0,
            discretised,
        })
    }

    /// Which form the state equation is written in: F (with G, Q) or A (with B, Qc or
    /// Q). Each key of the other form, and each pair given twice (F and A, G and B, Q
    /// and Qc), is an error naming both; so is a missing F or A, Q or Qc.
    fn form(&mut self, prefix: &str, model: &ModelSpec) -> Option<Form> {
        let before = self.errors.len();
        let path = |key: &str| join(prefix, &format!("model.{key}"));
        let form = if model.a.is_some() {
            Form::Continuous
        } else {
            Form::Discrete
        };
        if form == Form::Continuous {
            if model.f.is_some() {
                self.error(
                    path("A"),
                    "is given with model.F: write the state equation either in discrete time \
                     (F, G, Q) or in continuous time (A, B, Qc, discretised with the channel's \
                     `period`), not both"
                        .into(),
                );
            }
            if model.g.is_some() {
                let why = if model.b.is_some() {
                    "is given with model.B: with the continuous-time model.A give B only \
                     (G = ∫₀ᵀ e^{As} ds·B is computed from it)"
                } else {
                    "is the discrete-time input matrix but the model is written in continuous \
                     time (model.A): give B instead (G = ∫₀ᵀ e^{As} ds·B is computed from it)"
                };
                self.error(path("G"), why.into());
            }
            if model.q.is_some() && model.qc.is_some() {
                self.error(
                    path("Qc"),
                    "is given with model.Q: give the continuous intensity Qc (Q = \
                     ∫₀ᵀ e^{As}·Qc·e^{Aᵀs} ds is computed from it) or the discrete Q per sample, \
                     not both"
                        .into(),
                );
            }
            if model.q.is_none() && model.qc.is_none() {
                self.error(
                    path("Qc"),
                    "is required with model.A: the process-noise intensity (or Q, the \
                     covariance per sample)"
                        .into(),
                );
            }
        } else {
            if model.f.is_none() {
                self.error(
                    path("F"),
                    "is required: the state transition matrix (or model.A, to write the state \
                     equation in continuous time)"
                        .into(),
                );
            }
            if model.b.is_some() {
                let why = if model.g.is_some() {
                    "is given with model.G: B is the continuous-time input matrix and needs \
                     model.A; with model.F give G only"
                } else {
                    "is the continuous-time input matrix (dx/dt = A x + B u) and needs \
                     model.A: with model.F, give the discrete G"
                };
                self.error(path("B"), why.into());
            }
            if model.qc.is_some() {
                let why = if model.q.is_some() {
                    "is given with model.Q: Qc is a continuous-time noise intensity and needs \
                     model.A; with model.F give Q only"
                } else {
                    "is a continuous-time noise intensity and needs model.A: with model.F, \
                     give the discrete Q"
                };
                self.error(path("Qc"), why.into());
            } else if model.q.is_none() {
                self.error(
                    path("Q"),
                    "is required: the process-noise covariance cov(W_k)".into(),
                );
            }
        }
        (self.errors.len() == before).then_some(form)
    }

    /// F (or A) and H: F square and non-empty, H with n columns and at least one row,
    /// and n and p within the limits; A constant.
    fn state_and_outputs(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        form: Form,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let (name, _) = form.letters();
        let spec = match form {
            Form::Discrete => model.f.as_ref(),
            Form::Continuous => model.a.as_ref(),
        }?;
        let field = format!("model.{name}");
        let h = self.matrix(prefix, "H", &model.h, None);
        let n_hint = h.as_ref().map(|h| h.shape().1);
        let f = self.matrix(prefix, name, spec, n_hint);
        let (Some(f), Some(h)) = (f, h) else {
            return None;
        };
        if form == Form::Continuous && !f.terms().is_empty() {
            self.error(
                join(prefix, &field),
                "cannot depend on scheduling signals: F = e^{A(p)T} is not affine in p, so \
                 it would not be an LPV table; discretise A(p) at the scheduling points you \
                 need and write an LPV F (with G, Q) fitted to them"
                    .into(),
            );
            return None;
        }
        let (n, n2) = f.shape();
        if n != n2 || n == 0 {
            let hc = h.shape().1;
            let why = if hc != n2 {
                format!("is {n}×{n2} but H has {hc} columns")
            } else {
                format!("is {n}×{n2}: it must be square and non-empty")
            };
            self.error(join(prefix, &field), why);
            return None;
        }
        let p = h.shape().0;
        if h.shape().1 != n {
            self.error(
                join(prefix, &field),
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
        if !self.dimension_limits(prefix, name, n, p) {
            return None;
        }
        Some((f, h))
    }

    /// G (or B) and J: l from G (or J), no inputs when neither is given; G n×l and J
    /// p×l, and l within the limits.
    fn inputs(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        form: Form,
        n: usize,
        p: usize,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let (state, name) = form.letters();
        let spec = match form {
            Form::Discrete => model.g.as_ref(),
            Form::Continuous => model.b.as_ref(),
        };
        let g = spec.and_then(|g| self.matrix(prefix, name, g, None));
        let j = model
            .j
            .as_ref()
            .and_then(|j| self.matrix(prefix, "J", j, None));
        let l = g
            .as_ref()
            .map(|g| g.shape().1)
            .or(j.as_ref().map(|j| j.shape().1))
            .unwrap_or(0);
        if (spec.is_some() && g.is_none()) || (model.j.is_some() && j.is_none()) {
            // The error is recorded; l is unknown, so nothing below can be checked.
            return None;
        }
        let g = g.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(n, l)));
        let j = j.unwrap_or_else(|| LpvMatrix::constant(DMatrix::zeros(p, l)));
        // Every later product (faults, E, S, diagnosis) assumes these shapes: a
        // mismatch ends the channel's checks here instead of panicking in nalgebra.
        let g_ok = self.shape(
            prefix,
            name,
            &g,
            (n, l),
            &format!("{state} is {n}×{n} and there are {l} inputs"),
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
                join(prefix, &format!("model.{name}")),
                format!(
                    "has {l} columns (inputs): at most {} (limits::MAX_INPUTS)",
                    limits::MAX_INPUTS
                ),
            );
            return None;
        }
        Some((g, j))
    }

    /// Q or Qc (n×n, positive semi-definite) and R (p×p, positive definite), each
    /// replaced by its projection when it is only near that (see
    /// [`Validator::covariance`]).
    fn noise(
        &mut self,
        prefix: &str,
        model: &ModelSpec,
        form: Form,
        n: usize,
        p: usize,
    ) -> Option<(LpvMatrix, LpvMatrix)> {
        let (state, _) = form.letters();
        let (name, spec) = match (&model.qc, &model.q) {
            (Some(qc), _) => ("Qc", qc),
            (None, Some(q)) => ("Q", q),
            (None, None) => return None,
        };
        let mut q = self.matrix(prefix, name, spec, Some(n))?;
        let mut r = self.matrix(prefix, "R", &model.r, Some(p))?;
        if self.shape(prefix, name, &q, (n, n), &format!("{state} is {n}×{n}"))
            && let Some(projected) = self.covariance(prefix, name, &q, false)
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

    /// The continuous-time A, B and Qc (or Q as given) → F, G and Q, with the channel's
    /// `period` T and a zero-order hold ([`Discretisation::zero_order_hold`]). An LPV B
    /// or Qc gives an LPV G or Q exactly: G = ∫₀ᵀ e^{As} ds·B and Q are linear in B and
    /// Qc, so each term M_i becomes its own discretisation (A is constant).
    fn discretise(
        &mut self,
        prefix: &str,
        period: Option<f64>,
        (a, b, noise): (&LpvMatrix, &LpvMatrix, &LpvMatrix),
        noise_is_intensity: bool,
    ) -> Option<(LpvMatrix, LpvMatrix, LpvMatrix, Discretisation)> {
        let Some(t) = period else {
            self.error(
                join(prefix, "period"),
                "is required with a continuous-time model (model.A): the sample period T \
                 in seconds, over which F = e^{AT}, G and Q are computed"
                    .into(),
            );
            return None;
        };
        if !(t.is_finite() && t > 0.0) {
            return None; // reported by `model`
        }
        let a = a.base();
        let qc = noise_is_intensity.then(|| noise.base());
        // Shapes, finiteness and symmetry were checked above: what is left is an
        // overflow of e^{AT}, named at A with the period.
        let fail = |v: &mut Self, e: ContinuousError| {
            let (field, message) = match &e {
                ContinuousError::Period { .. } => ("period".to_owned(), e.to_string()),
                ContinuousError::Dimension { what, detail } => {
                    (format!("model.{what}"), detail.clone())
                }
                ContinuousError::NonFinite { what }
                | ContinuousError::NotSymmetric { what, .. } => {
                    (format!("model.{what}"), e.to_string())
                }
                _ => ("model.A".to_owned(), e.to_string()),
            };
            v.error(join(prefix, &field), format!("{message} (T = {t} s)"));
        };
        let d = match Discretisation::zero_order_hold(a, b.base(), qc, t) {
            Ok(d) => d,
            Err(e) => {
                fail(self, e);
                return None;
            }
        };
        let mut g_terms = Vec::new();
        for (i, bi) in b.terms() {
            match continuous::zero_order_hold(a, bi, t) {
                Ok((_, gi)) => g_terms.push((*i, gi)),
                Err(e) => {
                    fail(self, e);
                    return None;
                }
            }
        }
        let q = if let Some(q0) = d.q() {
            let mut q_terms = Vec::new();
            for (i, qci) in noise.terms() {
                match continuous::process_noise(a, qci, t) {
                    Ok(qi) => q_terms.push((*i, qi)),
                    Err(e) => {
                        fail(self, e);
                        return None;
                    }
                }
            }
            LpvMatrix::new(q0.clone(), q_terms)
        } else {
            Ok(noise.clone())
        };
        let g = LpvMatrix::new(d.g().clone(), g_terms);
        match (g, q) {
            (Ok(g), Ok(q)) => Some((LpvMatrix::constant(d.f().clone()), g, q, d)),
            (Err(e), _) | (_, Err(e)) => {
                self.error(join(prefix, "model"), e.to_string());
                None
            }
        }
    }

    /// n and p within [`limits::MAX_STATES`] and [`limits::MAX_OUTPUTS`]; `state` names
    /// the matrix n comes from (F or A).
    fn dimension_limits(&mut self, prefix: &str, state: &str, n: usize, p: usize) -> bool {
        let mut ok = true;
        if n > limits::MAX_STATES {
            self.error(
                join(prefix, &format!("model.{state}")),
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
