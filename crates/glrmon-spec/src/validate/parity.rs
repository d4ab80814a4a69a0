//! `[channels.parity]`: the parity detector's order and evaluation, checked against the
//! model (the parity space must not be empty), and the χ² degrees of freedom of its
//! statistic.

use glrmon_core::detector::Evaluation;
use glrmon_core::detector::parity::{
    DEFAULT_PARITY_RANK_TOLERANCE, Disturbance, ParitySettings, parity_dimension, smallest_order,
};
use glrmon_core::{Lpv, LpvMatrix, Signals, StateSpace, SystemMatrices};

use super::{Validator, join};
use crate::limits;
use crate::locate;
use crate::schema::ParitySpec;

/// The largest parity order accepted.
const MAX_ORDER: usize = 64;

/// The bytes a parity detector of order `order` allocates: with N = (s + 1)p rows, four
/// N×N matrices (M, chol Σ_r, Σ_Y, MΣ_Y), [H_o,s H_d,s] and its Householder vectors
/// (N × (n + (s + 1)q) each), H_w,s and its product with Q (N × sn each), H_u,s
/// (N × (s + 1)l), and the window's s + 1 sets of model matrices.
fn parity_bytes(dims: glrmon_core::Dims, q: usize, order: usize) -> u64 {
    let (n, l, p) = (dims.states as u64, dims.inputs as u64, dims.outputs as u64);
    let (s, q) = (order as u64, q as u64);
    let rows = (s + 1) * p;
    let matrices = 4 * rows * rows
        + 2 * rows * (n + (s + 1) * q)
        + 2 * rows * s * n
        + rows * (s + 1) * l
        + (s + 1) * (2 * n * n + n * l + p * n + p * l + p * p);
    8 * matrices
}

impl Validator {
    /// Whether a parity window of `order` fits a channel's memory budget (an error at
    /// `path` when not).
    fn parity_fits(&mut self, path: &str, dims: glrmon_core::Dims, q: usize, order: usize) -> bool {
        let bytes = parity_bytes(dims, q, order);
        if bytes <= limits::CHANNEL_MEMORY_BUDGET {
            return true;
        }
        self.error(
            path.to_owned(),
            format!(
                "s = {order} needs about {} for the parity window's matrices ((s + 1)p = {} \
                 rows), more than a channel's {}: lower the order",
                limits::human_bytes(bytes),
                (order + 1) * dims.outputs,
                limits::human_bytes(limits::CHANNEL_MEMORY_BUDGET)
            ),
        );
        false
    }

    /// `evaluation` and `energy_window` of a residual generator's table (`paths` name
    /// them in errors).
    pub(super) fn evaluation(
        &mut self,
        evaluation_path: &str,
        window_path: &str,
        evaluation: Option<&str>,
        energy_window: Option<usize>,
    ) -> Evaluation {
        let evaluation = match evaluation {
            None | Some("chi2") => Evaluation::Chi2,
            Some("energy") => {
                let window = energy_window.unwrap_or(10);
                if window == 0 || window > limits::MAX_WINDOW {
                    self.error(
                        window_path.to_owned(),
                        format!("{window} is not in 1..={}", limits::MAX_WINDOW),
                    );
                }
                Evaluation::Energy { window }
            }
            Some(other) => {
                self.error(
                    evaluation_path.to_owned(),
                    locate::not_one_of(other, &["chi2", "energy"]),
                );
                Evaluation::Chi2
            }
        };
        if energy_window.is_some() && !matches!(evaluation, Evaluation::Energy { .. }) {
            self.error(
                window_path.to_owned(),
                "applies to `evaluation = \"energy\"`".into(),
            );
        }
        evaluation
    }

    /// `[channels.rls]`, checked by building the detector on the model (its ARX form:
    /// an LTI model with inputs reaching every output, noise that can be whitened),
    /// and the number of parameters the χ² evaluation tests.
    pub(super) fn rls(
        &mut self,
        prefix: &str,
        spec: Option<&crate::schema::RlsSpec>,
        model: &Lpv,
        cross: Option<&nalgebra::DMatrix<f64>>,
    ) -> Option<(crate::RlsChannelSettings, usize)> {
        use glrmon_core::{Column, Detector as _, Fault, FaultDictionary, Onset, RlsSettings};
        let before = self.errors.len();
        let path = |f: &str| join(prefix, &format!("rls.{f}"));
        let spec = spec.cloned().unwrap_or_default();
        let defaults = RlsSettings::default();
        let settings = RlsSettings {
            forgetting: spec.forgetting.unwrap_or(defaults.forgetting),
            p0: spec.p0.unwrap_or(defaults.p0),
            excitation: spec.excitation.unwrap_or(defaults.excitation),
        };
        if !(settings.forgetting > 0.0 && settings.forgetting <= 1.0) {
            self.error(
                path("forgetting"),
                format!("{} is not in (0, 1]", settings.forgetting),
            );
        }
        if !(settings.p0.is_finite() && settings.p0 > 0.0) {
            self.error(
                path("p0"),
                format!("{} must be finite and positive", settings.p0),
            );
        }
        if !(settings.excitation > 0.0 && settings.excitation < 1.0) {
            self.error(
                path("excitation"),
                format!("{} is not in (0, 1)", settings.excitation),
            );
        }
        let evaluation = self.evaluation(
            &path("evaluation"),
            &path("energy_window"),
            spec.evaluation.as_deref(),
            spec.energy_window,
        );
        if self.errors.len() > before {
            return None;
        }
        let channel = crate::RlsChannelSettings {
            rls: settings,
            evaluation,
        };
        let probe = FaultDictionary::new(
            model.dims(),
            vec![Fault::output("probe", Onset::Step, Column::Zero)],
        )
        .ok()?;
        match crate::detector::rls_detector(model, cross, probe, &channel) {
            Ok(detector) => Some((channel, detector.residual_len())),
            Err(err) => {
                self.error(join(prefix, "rls"), err.to_string());
                None
            }
        }
    }

    /// `[channels.observer]` for the `fdf` or `uio` kind, checked against the model
    /// at k = 0 (the gains' stability, the UIO's existence conditions, each named),
    /// and the dimension of the residual the χ² evaluation tests.
    pub(super) fn observer(
        &mut self,
        prefix: &str,
        kind: crate::DetectorKind,
        spec: Option<&crate::schema::ObserverSpec>,
        (model, e, cross): (&Lpv, Option<&LpvMatrix>, Option<&nalgebra::DMatrix<f64>>),
    ) -> Option<(crate::ObserverSettings, usize)> {
        use glrmon_core::detector::{FdfGains, UioDesign};
        let before = self.errors.len();
        let path = |f: &str| join(prefix, &format!("observer.{f}"));
        let spec = spec.cloned().unwrap_or_default();
        let evaluation = self.evaluation(
            &path("evaluation"),
            &path("energy_window"),
            spec.evaluation.as_deref(),
            spec.energy_window,
        );
        let dims = model.dims();
        let rows = |this: &mut Self, key: &str, m: &Option<Vec<Vec<f64>>>, cols: usize| {
            let m = m.as_ref()?;
            let ok = !m.is_empty() && m.iter().all(|r| r.len() == cols);
            if !ok {
                this.error(
                    path(key),
                    format!("must be rows of {cols} numbers each (at least one row)"),
                );
                return None;
            }
            if m.iter().flatten().any(|x| !x.is_finite()) {
                this.error(path(key), "holds a value that is not finite".into());
                return None;
            }
            Some(nalgebra::DMatrix::from_fn(m.len(), cols, |i, j| m[i][j]))
        };
        let mut sys = SystemMatrices::zeros(dims);
        let (u, p) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
        model
            .clone()
            .evaluate(0, &Signals { u: &u, p: &p }, &mut sys);
        let (gains, dof) = match kind {
            crate::DetectorKind::Uio => {
                for (key, given) in [("L", spec.l.is_some()), ("V", spec.v.is_some())] {
                    if given {
                        self.error(
                            path(key),
                            "applies to `detector = \"fdf\"`: the unknown-input observer \
                             designs its gain from the model"
                                .into(),
                        );
                    }
                }
                let Some(e) = e else {
                    self.error(
                        join(prefix, "model.E"),
                        "the `uio` detector decouples its residual from the unknown input \
                         E d_k: give `model.E`"
                            .into(),
                    );
                    return None;
                };
                if !e.terms().is_empty() {
                    self.error(
                        join(prefix, "model.E"),
                        "the `uio` detector needs a constant E (its gains are designed once)"
                            .into(),
                    );
                    return None;
                }
                match UioDesign::new(&sys, e.base()) {
                    Ok(design) => (None, design.rank()),
                    Err(err) => {
                        self.error(join(prefix, "model.E"), err.to_string());
                        return None;
                    }
                }
            }
            _ => {
                let l = rows(self, "L", &spec.l, dims.outputs);
                let v = rows(self, "V", &spec.v, dims.outputs);
                if self.errors.len() > before {
                    return None;
                }
                match (l, v) {
                    (Some(l), v) => {
                        let v = v.unwrap_or_else(|| {
                            nalgebra::DMatrix::identity(dims.outputs, dims.outputs)
                        });
                        let rank = v
                            .clone()
                            .svd(false, false)
                            .rank(1e-9 * v.amax().max(f64::MIN_POSITIVE));
                        if rank < v.nrows() {
                            self.error(
                                path("V"),
                                format!(
                                    "has {} rows of rank {rank}: give independent rows (the χ² \
                                     test has one degree of freedom per row)",
                                    v.nrows()
                                ),
                            );
                            return None;
                        }
                        let gains = FdfGains { l, v };
                        if let Err(err) = gains.check(&sys.f, &sys.h) {
                            self.error(path("L"), err.to_string());
                            return None;
                        }
                        let dof = gains.v.nrows().min(dims.outputs);
                        (Some((gains.l, gains.v)), dof)
                    }
                    (None, Some(_)) => {
                        self.error(
                            path("V"),
                            "give `L` with `V` (the optimal gains come as a pair)".into(),
                        );
                        return None;
                    }
                    (None, None) => {
                        let s = cross
                            .cloned()
                            .unwrap_or_else(|| nalgebra::DMatrix::zeros(dims.states, dims.outputs));
                        if let Err(err) = FdfGains::optimal(&sys.f, &sys.h, &sys.q, &sys.r, &s) {
                            self.error(join(prefix, "model"), err.to_string());
                            return None;
                        }
                        (None, dims.outputs)
                    }
                }
            }
        };
        if self.errors.len() > before {
            return None;
        }
        Some((crate::ObserverSettings { gains, evaluation }, dof))
    }

    /// The parity settings and the dimension of the residual the χ² evaluation tests
    /// (the parity space's; 1 for the optimal vector of eq. (7)), from the model at
    /// k = 0 with zero signals (an LPV model's parity space is checked again at every
    /// window by the detector).
    pub(super) fn parity(
        &mut self,
        prefix: &str,
        spec: Option<&ParitySpec>,
        model: &Lpv,
        e: Option<&LpvMatrix>,
        fd: Option<&nalgebra::DMatrix<f64>>,
    ) -> Option<(ParitySettings, usize)> {
        let before = self.errors.len();
        let path = |f: &str| join(prefix, &format!("parity.{f}"));
        let spec = spec.cloned().unwrap_or_default();
        let tolerance = spec.rank_tolerance.unwrap_or(DEFAULT_PARITY_RANK_TOLERANCE);
        if !(tolerance > 0.0 && tolerance < 1.0) {
            self.error(
                path("rank_tolerance"),
                format!("{tolerance} is not in (0, 1)"),
            );
        }
        if let Some(e) = e
            && !e.terms().is_empty()
        {
            self.error(
                join(prefix, "model.E"),
                "the parity detector needs a constant E (its H_d,s is built once)".into(),
            );
        }
        let evaluation = self.evaluation(
            &path("evaluation"),
            &path("energy_window"),
            spec.evaluation.as_deref(),
            spec.energy_window,
        );
        if self.errors.len() > before {
            return None;
        }
        let dims = model.dims();
        let mut sys = SystemMatrices::zeros(dims);
        let (u, p) = (vec![0.0; dims.inputs], vec![0.0; dims.signals]);
        model
            .clone()
            .evaluate(0, &Signals { u: &u, p: &p }, &mut sys);
        let disturbance = e.map(|e| Disturbance {
            state: e.base().clone(),
            output: fd
                .cloned()
                .unwrap_or_else(|| nalgebra::DMatrix::zeros(dims.outputs, e.shape().1)),
        });
        let q = disturbance.as_ref().map_or(0, |d| d.state.ncols());
        if let Some(order) = spec.order.filter(|&o| o <= MAX_ORDER)
            && !self.parity_fits(&path("order"), dims, q, order)
        {
            return None;
        }
        let free = smallest_order(&sys, None, MAX_ORDER, tolerance);
        let Some(free) = free else {
            self.error(
                join(prefix, "model"),
                format!(
                    "no parity order up to {MAX_ORDER} gives a parity space (is (H, F) observable?)"
                ),
            );
            return None;
        };
        // The smallest order decoupling the disturbance, only when the order is to be
        // chosen (a QR per order tried).
        let decoupled = disturbance
            .as_ref()
            .filter(|_| spec.order.is_none())
            .and_then(|d| smallest_order(&sys, Some(d), MAX_ORDER, tolerance));
        let order = match spec.order {
            Some(s) if s > MAX_ORDER => {
                self.error(path("order"), format!("{s} is more than {MAX_ORDER}"));
                return None;
            }
            Some(s) if s < free => {
                self.error(
                    path("order"),
                    format!(
                        "s = {s} gives no parity space: the smallest order that gives one \
                         is {free}"
                    ),
                );
                return None;
            }
            Some(s) => s,
            None => decoupled.unwrap_or(free),
        };
        if !self.parity_fits(&path("order"), dims, q, order) {
            return None;
        }
        let dof = match &disturbance {
            None => parity_dimension(&sys, None, order, tolerance),
            Some(d) => match parity_dimension(&sys, Some(d), order, tolerance) {
                0 => 1,
                dim => dim,
            },
        };
        Some((
            ParitySettings {
                order,
                evaluation,
                rank_tolerance: tolerance,
            },
            dof,
        ))
    }
}
