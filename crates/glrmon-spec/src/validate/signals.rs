//! The signals of a channel: their CSV column names (`[channels.columns]`) and their
//! raw-unit scaling (`[channels.scaling]`).

use glrmon_core::{Dims, SignalScaling};

use super::{Validator, join};
use crate::Columns;
use crate::limits;
use crate::schema::{ColumnsSpec, ScalingSpec};

impl Validator {
    /// `[channels.columns]` into [`Columns`]: one unique, non-empty name per signal,
    /// none of them `k` or `t` and none with a comma.
    pub(super) fn columns(
        &mut self,
        prefix: &str,
        spec: Option<&ColumnsSpec>,
        dims: Dims,
    ) -> Columns {
        let mut columns = Columns::numbered(dims);
        let Some(spec) = spec else {
            return columns;
        };
        columns.named = spec.u.is_some() || spec.y.is_some() || spec.p.is_some();
        for (field, given, target, count, what) in [
            (
                "u_units",
                &spec.u_units,
                &mut columns.u_units,
                dims.inputs,
                "inputs",
            ),
            (
                "y_units",
                &spec.y_units,
                &mut columns.y_units,
                dims.outputs,
                "outputs",
            ),
            (
                "p_units",
                &spec.p_units,
                &mut columns.p_units,
                dims.signals,
                "signals",
            ),
        ] {
            let Some(units) = given else { continue };
            let path = join(prefix, &format!("columns.{field}"));
            if units.len() == count {
                target.clone_from(units);
            } else {
                self.error(
                    path.clone(),
                    format!(
                        "has {} units but the channel has {count} {what}",
                        units.len()
                    ),
                );
            }
            for (i, unit) in units.iter().enumerate() {
                if unit.chars().any(char::is_control) || unit.chars().count() > 32 {
                    self.error(
                        format!("{path}[{i}]"),
                        "is not a unit label (a control character, or longer than 32 characters)"
                            .to_string(),
                    );
                }
            }
        }
        let mut all: Vec<(String, String)> = Vec::new();
        for (field, given, target, count, what) in [
            ("u", &spec.u, &mut columns.u, dims.inputs, "inputs"),
            ("y", &spec.y, &mut columns.y, dims.outputs, "outputs"),
            ("p", &spec.p, &mut columns.p, dims.signals, "signals"),
        ] {
            let path = join(prefix, &format!("columns.{field}"));
            if let Some(names) = given {
                if names.len() != count {
                    self.error(
                        path.clone(),
                        format!(
                            "has {} names but the channel has {count} {what}",
                            names.len()
                        ),
                    );
                }
                target.clone_from(names);
            }
            for (i, name) in target.iter().enumerate() {
                let at = format!("{path}[{i}]");
                if name.trim().is_empty() || name.trim() != name || name.contains(',') {
                    self.error(
                        at,
                        format!("\"{name}\" is not a column name (empty, padded or with a comma)"),
                    );
                } else if name == "k" || name == "t" {
                    self.error(at, format!("\"{name}\" is the sample index or time column"));
                } else if let Some((other, _)) = all.iter().find(|(_, n)| n == name) {
                    self.error(at, format!("\"{name}\" is also {other}"));
                } else {
                    all.push((format!("{field}{i}"), name.clone()));
                }
            }
        }
        columns
    }

    /// `[channels.scaling]` into a [`SignalScaling`]: absent lists are offset 0 and
    /// scale 1, present ones have one entry per input (u_*) or output (y_*).
    pub(super) fn scaling(
        &mut self,
        prefix: &str,
        spec: &ScalingSpec,
        dims: Dims,
    ) -> Option<SignalScaling> {
        let before = self.errors.len();
        let list =
            |v: &mut Self, field: &str, given: &Option<Vec<f64>>, len: usize, default: f64| {
                let path = join(prefix, &format!("scaling.{field}"));
                let what = if field.starts_with('u') {
                    "inputs"
                } else {
                    "outputs"
                };
                match given {
                    Some(x) if x.len() != len => {
                        v.error(
                            path,
                            format!("has {} entries but the channel has {len} {what}", x.len()),
                        );
                        Vec::new()
                    }
                    Some(x) => {
                        let scale = field.ends_with("scale");
                        for (i, value) in x.iter().enumerate() {
                            if !value.is_finite() || (scale && *value <= 0.0) {
                                v.error(
                                    format!("{path}[{i}]"),
                                    format!(
                                        "{value} must be {}",
                                        if scale {
                                            "finite and positive"
                                        } else {
                                            "finite"
                                        }
                                    ),
                                );
                            } else if scale
                                && !(limits::MIN_SCALE..=limits::MAX_SCALE).contains(value)
                            {
                                v.error(
                                    format!("{path}[{i}]"),
                                    format!(
                                        "{value:e} is outside [{:e}, {:e}] (limits::MIN_SCALE, \
                                         MAX_SCALE): a raw-unit fault's signature is 1/scale in \
                                         model units, and its information (squared, summed over \
                                         the window) would leave floating-point range; give the \
                                         signal in other units",
                                        limits::MIN_SCALE,
                                        limits::MAX_SCALE
                                    ),
                                );
                            } else if !scale && value.abs() > limits::MAX_OFFSET {
                                v.error(
                                    format!("{path}[{i}]"),
                                    format!(
                                        "{value:e} is beyond ±{:e} (limits::MAX_OFFSET): a raw \
                                         sample near 0 would be −offset/scale in model units, \
                                         refused by the monitor as too large; is the operating \
                                         point in the signal's units?",
                                        limits::MAX_OFFSET
                                    ),
                                );
                            }
                        }
                        x.clone()
                    }
                    None => vec![default; len],
                }
            };
        let u_offset = list(self, "u_offset", &spec.u_offset, dims.inputs, 0.0);
        let u_scale = list(self, "u_scale", &spec.u_scale, dims.inputs, 1.0);
        let y_offset = list(self, "y_offset", &spec.y_offset, dims.outputs, 0.0);
        let y_scale = list(self, "y_scale", &spec.y_scale, dims.outputs, 1.0);
        if self.errors.len() > before {
            return None;
        }
        match SignalScaling::new(u_offset, u_scale, y_offset, y_scale) {
            Ok(s) => Some(s),
            Err(e) => {
                self.error(join(prefix, "scaling"), e.to_string());
                None
            }
        }
    }
}
