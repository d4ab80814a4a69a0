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

impl Validator {
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
        let evaluation = match spec.evaluation.as_deref() {
            None | Some("chi2") => Evaluation::Chi2,
            Some("energy") => {
                let window = spec.energy_window.unwrap_or(10);
                if window == 0 || window > limits::MAX_WINDOW {
                    self.error(
                        path("energy_window"),
                        format!("{window} is not in 1..={}", limits::MAX_WINDOW),
                    );
                }
                Evaluation::Energy { window }
            }
            Some(other) => {
                self.error(
                    path("evaluation"),
                    locate::not_one_of(other, &["chi2", "energy"]),
                );
                Evaluation::Chi2
            }
        };
        if spec.energy_window.is_some() && !matches!(evaluation, Evaluation::Energy { .. }) {
            self.error(
                path("energy_window"),
                "applies to `evaluation = \"energy\"`".into(),
            );
        }
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
            output: nalgebra::DMatrix::zeros(dims.outputs, e.shape().1),
        });
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
        let decoupled = disturbance
            .as_ref()
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
