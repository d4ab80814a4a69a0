//! The diagnosis step of a channel (`[channels.diagnosis]`): the residual generator,
//! Assumption (iv) of Zhang 2021 for E, the regression's history and span, and the
//! Lasso path.

use glrmon_core::LpvMatrix;
use glrmon_core::sparse::residual::unknown_input_rank;
use glrmon_core::sparse::{LassoSettings, PlateauScale};
use nalgebra::DMatrix;

use super::{Validator, join};
use crate::schema::{ChannelSpec, DiagnosisSpec, LassoSpec};
use crate::{DEFAULT_DIAGNOSIS_ALPHA, DiagnosisSettings, ResidualKind, limits, locate};

impl Validator {
    /// `[channels.diagnosis]`: ranges, the residual kind, and Assumption (iv) of Zhang
    /// 2021 for the Kitanidis residual (H·E of full column rank, checked at the base
    /// point of H).
    pub(super) fn diagnosis(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        h: &LpvMatrix,
        e: Option<&DMatrix<f64>>,
        kalman: bool,
    ) -> DiagnosisSettings {
        let d: &DiagnosisSpec = &spec.diagnosis;
        let dpath = |f: &str| join(prefix, &format!("diagnosis.{f}"));
        let residual = self.residual(prefix, spec);
        // The Kitanidis filter's condition, for the kinds that run it and for the
        // Kitanidis residual of sparse diagnosis when it is asked for; the other kinds
        // check their own.
        let kitanidis_asked =
            residual == ResidualKind::Kitanidis && (d.enabled || d.residual.is_some());
        if let Some(e) = e
            && (kalman || kitanidis_asked)
        {
            self.decoupling(prefix, h, e);
        }
        let history = self.history(prefix, d, spec.glr.window);
        let lasso = self.lasso(prefix, &d.lasso);
        let alpha = d.alpha.unwrap_or(DEFAULT_DIAGNOSIS_ALPHA);
        if !(alpha > 0.0 && alpha <= 1.0) {
            self.error(
                dpath("alpha"),
                format!("{alpha} is not in (0, 1] (1 turns the no-fault test off)"),
            );
        }
        DiagnosisSettings {
            enabled: d.enabled,
            residual,
            span: d.span,
            history,
            lasso,
            alpha,
        }
    }

    /// `diagnosis.residual`: Kitanidis when the model has E, Kalman otherwise, unless
    /// given (and Kitanidis needs E).
    fn residual(&mut self, prefix: &str, spec: &ChannelSpec) -> ResidualKind {
        let d: &DiagnosisSpec = &spec.diagnosis;
        let dpath = |f: &str| join(prefix, &format!("diagnosis.{f}"));
        match d.residual.as_deref() {
            None if spec.model.e.is_some() => ResidualKind::Kitanidis,
            None => ResidualKind::Kalman,
            Some("kalman") => ResidualKind::Kalman,
            Some("kitanidis") => {
                if spec.model.e.is_none() {
                    self.error(
                        dpath("residual"),
                        "is \"kitanidis\" but the model has no unknown-input matrix E: \
                         add model.E or use residual = \"kalman\""
                            .into(),
                    );
                }
                ResidualKind::Kitanidis
            }
            Some(other) => {
                self.error(
                    dpath("residual"),
                    locate::not_one_of(other, &["kalman", "kitanidis"]),
                );
                ResidualKind::Kalman
            }
        }
    }

    /// Assumption (iv): H·E of full column rank (at the base point of H), and fewer
    /// columns in E than outputs, so that an output direction is left once the unknown
    /// input is decoupled.
    fn decoupling(&mut self, prefix: &str, h: &LpvMatrix, e: &DMatrix<f64>) {
        if let Err(err) = unknown_input_rank(h.base(), e) {
            let text = format!(
                "{err} (H·E must have full column rank: the detector and the Kitanidis \
                 residual decouple the unknown input{})",
                if h.terms().is_empty() {
                    ""
                } else {
                    "; checked at the base point of H"
                }
            );
            self.error(join(prefix, "model.E"), text);
        } else if e.ncols() >= h.shape().0 {
            self.error(
                join(prefix, "model.E"),
                format!(
                    "has {} columns and H has {} rows: once the unknown input is \
                     decoupled no output direction is left to detect faults with \
                     (E needs fewer columns than there are outputs)",
                    e.ncols(),
                    h.shape().0
                ),
            );
        }
    }

    /// The samples kept for the regression (`diagnosis.history`, 2w by default) and
    /// the span within them.
    fn history(&mut self, prefix: &str, d: &DiagnosisSpec, window: usize) -> usize {
        let dpath = |f: &str| join(prefix, &format!("diagnosis.{f}"));
        let history = d.history.unwrap_or(window.saturating_mul(2));
        // The default 2w is bounded by the window's own limit: only explicit values are
        // checked here, so that an oversized window is blamed on glr.window alone.
        for (field, value) in [("history", d.history), ("span", d.span)] {
            if let Some(value) = value
                && value > limits::MAX_HISTORY
            {
                self.error(
                    dpath(field),
                    format!(
                        "{value} samples is more than {} (limits::MAX_HISTORY)",
                        limits::MAX_HISTORY
                    ),
                );
            }
        }
        if history < 2 {
            self.error(
                dpath("history"),
                format!("{history} must be at least 2 samples"),
            );
        }
        if d.span == Some(0) {
            self.error(dpath("span"), "0 must be at least 1 sample".into());
        }
        if let Some(span) = d.span
            && span > history
        {
            self.warn(
                dpath("span"),
                format!(
                    "{span} exceeds diagnosis.history = {history}: the regression holds at \
                         most {history} samples"
                ),
            );
        }
        history
    }

    /// `diagnosis.lasso`: the λ path's length, ratio and plateau scale.
    fn lasso(&mut self, prefix: &str, spec: &LassoSpec) -> LassoSettings {
        let dpath = |f: &str| join(prefix, &format!("diagnosis.{f}"));
        let defaults = LassoSettings::default();
        let plateau_scale = match spec.plateau_scale.as_deref() {
            None => defaults.plateau_scale,
            Some("log") => PlateauScale::Log,
            Some("linear") => PlateauScale::Linear,
            Some(other) => {
                self.error(
                    dpath("lasso.plateau_scale"),
                    locate::not_one_of(other, &["log", "linear"]),
                );
                defaults.plateau_scale
            }
        };
        let lasso = LassoSettings {
            path_points: spec.path_points.unwrap_or(defaults.path_points),
            ratio: spec.ratio.unwrap_or(defaults.ratio),
            plateau_scale,
            ..defaults
        };
        if lasso.path_points < 2 {
            self.error(
                dpath("lasso.path_points"),
                format!("{} must be at least 2", lasso.path_points),
            );
        }
        if lasso.path_points > limits::MAX_PATH_POINTS {
            self.error(
                dpath("lasso.path_points"),
                format!(
                    "{} is more than {} (limits::MAX_PATH_POINTS)",
                    lasso.path_points,
                    limits::MAX_PATH_POINTS
                ),
            );
        }
        if !(lasso.ratio > 0.0 && lasso.ratio < 1.0) {
            self.error(
                dpath("lasso.ratio"),
                format!("{} is not in (0, 1) (λ_min/λ_max)", lasso.ratio),
            );
        }
        lasso
    }
}
