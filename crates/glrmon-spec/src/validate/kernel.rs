//! `[channels.kernel]`: the kernel deadbeat detector's fault channels, noise bounds,
//! kernels and candidate fault functions, checked against the continuous-time model,
//! each problem named at its field (`kernel.E`, `kernel.candidates[0].f[2]`, …).

use glrmon_core::{KernelModel, KernelSettings, ModelError, Onset};
use nalgebra::DMatrix;

use super::model::Matrices;
use super::{Validator, join};
use crate::channel::{ColumnPlan, FaultPlan, KernelCandidate, KernelChannelSettings};
use crate::expr::{Expr, ExprContext};
use crate::schema::{ChannelSpec, KernelSpec};

/// The paper's ω̄ (Section V), the default of `kernel.omega_bar`.
const DEFAULT_OMEGA_BAR: f64 = 2.5;
/// θ_a as a fraction of its limit |det Γ(∞)|: the paper's 0.7 for the rates 1, 2, whose
/// limit is 1.
const DEFAULT_ACTIVATION_FRACTION: f64 = 0.7;
/// The paper's rearm time, in seconds.
const DEFAULT_REARM: f64 = 5.0;

/// |det Γ(∞)| = |det V| with V[h][j] = (−1)^{n⋆−1−j} ω_h^{n⋆−1−j}: the limit θ_a must
/// stay below (as the core computes it).
fn activation_limit(rates: &[f64]) -> f64 {
    let order = rates.len();
    DMatrix::from_fn(order, order, |h, j| {
        let e = order - 1 - j;
        let s = if e.is_multiple_of(2) { 1.0 } else { -1.0 };
        s * rates[h].powi(e as i32)
    })
    .determinant()
    .abs()
}

impl Validator {
    /// The kernel kind's faults: its candidates (or one fault `f`), step onsets with no
    /// columns, since the detector carries its own signatures; `[[channels.faults]]`
    /// must be left out.
    pub(super) fn kernel_faults(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
    ) -> (Vec<FaultPlan>, Vec<String>) {
        if !spec.faults.is_empty() {
            self.error(
                join(prefix, "faults"),
                "the `kernel` detector's faults are its candidate functions \
                 (`[[channels.kernel.candidates]]`): leave `[[channels.faults]]` out"
                    .into(),
            );
        }
        let plan = |name: &str| FaultPlan {
            name: name.to_owned(),
            onset: Onset::Step,
            state: ColumnPlan::Zero,
            output: ColumnPlan::Zero,
        };
        let candidates = spec.kernel.as_ref().map_or(&[][..], |k| &k.candidates[..]);
        if candidates.is_empty() {
            return (vec![plan("f")], vec![join(prefix, "kernel")]);
        }
        candidates
            .iter()
            .enumerate()
            .map(|(i, c)| {
                (
                    plan(&c.name),
                    join(prefix, &format!("kernel.candidates[{i}]")),
                )
            })
            .unzip()
    }

    /// The dictionary another kind takes from `[channels.kernel]`: one step fault per
    /// fault channel, `E0`, `E1`, …, entering the state through the column of E sampled
    /// by zero-order hold, Ψ_j = ∫₀ᵀe^{As}ds·E_j (the fault held over each period).
    pub(super) fn fault_channels(
        &mut self,
        prefix: &str,
        kernel: &KernelChannelSettings,
    ) -> (Vec<FaultPlan>, Vec<String>) {
        let model = &kernel.model;
        match glrmon_core::model::continuous::zero_order_hold(
            &model.a,
            &model.e,
            kernel.settings.period,
        ) {
            Ok((_, psi)) => (0..psi.ncols())
                .map(|j| {
                    (
                        FaultPlan {
                            name: format!("E{j}"),
                            onset: Onset::Step,
                            state: ColumnPlan::Constant(psi.column(j).into_owned()),
                            output: ColumnPlan::Zero,
                        },
                        join(prefix, "kernel.E"),
                    )
                })
                .unzip(),
            Err(e) => {
                self.error(join(prefix, "kernel.E"), format!("cannot be sampled: {e}"));
                (Vec::new(), Vec::new())
            }
        }
    }

    /// The detector's model (A, B of the continuous-time state equation, H, E) and
    /// settings, defaults filled in; `None` after an error. The design itself (H E's
    /// rank, the assumptions) is checked when the detector is built.
    pub(super) fn kernel(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        m: &Matrices,
    ) -> Option<KernelChannelSettings> {
        let before = self.errors.len();
        let path = |f: &str| join(prefix, &format!("kernel.{f}"));
        let Some(k) = spec.kernel.as_ref() else {
            self.error(
                join(prefix, "kernel"),
                "`glr.detector = \"kernel\"` needs `[channels.kernel]` with at least `E`, \
                 the fault channels"
                    .into(),
            );
            return None;
        };
        let Some(d) = m.discretised.as_ref() else {
            self.error(
                join(prefix, "model.F"),
                "the `kernel` detector works on the continuous-time model: write the state \
                 equation as `A`, `B` (with the channel's `period`) instead of `F`, `G`"
                    .into(),
            );
            return None;
        };
        for (field, given) in [
            ("model.E", m.e.is_some()),
            ("model.Fd", m.fd.is_some()),
            ("model.S", m.cross.is_some()),
        ] {
            if given {
                self.error(
                    join(prefix, field),
                    "is not part of the `kernel` detector's model (dx/dt = A x + B u + E f, \
                     y = H x, with bounded noises): leave it out"
                        .into(),
                );
            }
        }
        if !m.j.terms().is_empty() || m.j.base().iter().any(|v| *v != 0.0) {
            self.error(
                join(prefix, "model.J"),
                "the `kernel` detector's outputs are y = H x: J must be zero".into(),
            );
        }
        for (field, terms) in [("model.B", m.g.terms()), ("model.H", m.h.terms())] {
            if !terms.is_empty() {
                self.error(
                    join(prefix, field),
                    "the `kernel` detector needs an LTI model: an LPV table is refused".into(),
                );
            }
        }
        let n = d.a().nrows();
        let e = match &k.e {
            None => {
                self.error(
                    path("E"),
                    "is required: the fault channels, n×p⋆ (rows)".into(),
                );
                None
            }
            Some(rows) => self.dense(&path("E"), rows).and_then(|e| {
                if e.nrows() == n {
                    Some(e)
                } else {
                    self.error(
                        path("E"),
                        format!(
                            "has {} rows, expected n = {n} (one per state of model.A)",
                            e.nrows()
                        ),
                    );
                    None
                }
            }),
        };
        let faults = e.as_ref().map_or(0, DMatrix::ncols);
        if e.is_some() && faults >= n {
            self.error(
                path("E"),
                format!("has {faults} columns: fewer fault channels than the {n} states"),
            );
        }
        let bound = |v: &mut Self, field: &str, x: Option<f64>| -> f64 {
            let x = x.unwrap_or(0.0);
            if !(x.is_finite() && x >= 0.0) {
                v.error(path(field), format!("{x} must be finite and non-negative"));
            }
            x
        };
        let output_noise = bound(self, "output_noise", k.output_noise);
        let state_noise = bound(self, "state_noise", k.state_noise);
        let floor = bound(self, "floor", k.floor);
        if output_noise == 0.0 && state_noise == 0.0 && floor == 0.0 {
            self.error(
                path("floor"),
                "with zero noise bounds (`output_noise`, `state_noise`) the threshold is 0 \
                 and the sampling error alone would alarm: give a noise bound or a positive \
                 `floor`"
                    .into(),
            );
        }
        let order = n.saturating_sub(faults);
        let rates = k
            .rates
            .clone()
            .unwrap_or_else(|| (1..=order).map(|h| h as f64).collect());
        let activation = match k.activation {
            Some(a) => a,
            None if rates.len() == order && rates.iter().all(|w| w.is_finite()) => {
                DEFAULT_ACTIVATION_FRACTION * activation_limit(&rates)
            }
            None => 0.0,
        };
        let candidates = self.kernel_candidates(prefix, k, m.g.base().ncols(), n, faults);
        if self.errors.len() > before {
            return None;
        }
        Some(KernelChannelSettings {
            model: KernelModel {
                a: d.a().clone(),
                b: d.b().clone(),
                c: m.h.base().clone(),
                e: e?,
            },
            settings: KernelSettings {
                period: d.period(),
                estimator_rates: rates,
                omega_bar: k.omega_bar.unwrap_or(DEFAULT_OMEGA_BAR),
                kernel_order: k.order.unwrap_or(order),
                detection_rate: k.detection_rate.unwrap_or(1.0),
                activation,
                state_noise,
                output_noise,
                floor,
                rearm: k.rearm.unwrap_or(DEFAULT_REARM),
            },
            candidates,
        })
    }

    /// The candidates: unique names, a finite non-negative Lipschitz constant, one
    /// expression of (t, x, u) per fault channel.
    fn kernel_candidates(
        &mut self,
        prefix: &str,
        k: &KernelSpec,
        inputs: usize,
        states: usize,
        faults: usize,
    ) -> Vec<KernelCandidate> {
        let ctx = ExprContext::candidate(inputs, states);
        let mut out = Vec::new();
        for (i, c) in k.candidates.iter().enumerate() {
            let cpath = join(prefix, &format!("kernel.candidates[{i}]"));
            if c.name.is_empty() {
                self.error(format!("{cpath}.name"), "is empty".into());
            } else if k.candidates[..i].iter().any(|o| o.name == c.name) {
                self.error(
                    format!("{cpath}.name"),
                    format!("duplicate candidate name \"{}\"", c.name),
                );
            }
            if !(c.lipschitz.is_finite() && c.lipschitz >= 0.0) {
                self.error(
                    format!("{cpath}.lipschitz"),
                    format!("{} must be finite and non-negative", c.lipschitz),
                );
            }
            if faults > 0 && c.f.len() != faults {
                self.error(
                    format!("{cpath}.f"),
                    format!(
                        "has {} expressions, expected p⋆ = {faults}: one per fault channel \
                         (column of kernel.E)",
                        c.f.len()
                    ),
                );
            }
            let mut f = Vec::new();
            for (j, src) in c.f.iter().enumerate() {
                match Expr::parse(src, &ctx) {
                    Ok(e) => f.push(e),
                    Err(err) => self.error(
                        format!("{cpath}.f[{j}]"),
                        format!("candidate \"{}\": {err}", c.name),
                    ),
                }
            }
            out.push(KernelCandidate {
                name: c.name.clone(),
                lipschitz: c.lipschitz,
                f,
            });
        }
        out
    }

    /// A design error of the core's [`glrmon_core::KernelDetector::new`] at the field
    /// it concerns: a setting at `kernel.<setting>` (`period` at the channel's), the
    /// design's conditions at `kernel.E`.
    pub(super) fn kernel_error(&mut self, prefix: &str, err: &ModelError) {
        let field = match err {
            ModelError::Setting { what: "period", .. } => "period".to_owned(),
            ModelError::Setting {
                what: "lipschitz" | "candidates",
                ..
            } => "kernel.candidates".to_owned(),
            ModelError::Setting { what, .. } => format!("kernel.{what}"),
            _ => "kernel.E".to_owned(),
        };
        self.error(
            join(prefix, &field),
            format!("the `kernel` detector cannot be built: {err}"),
        );
    }
}
