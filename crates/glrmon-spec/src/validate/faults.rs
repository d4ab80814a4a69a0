//! The fault dictionary of a channel (`faults`): shortcuts expanded, each fault's
//! onset and columns (shortcut kinds, or `psi`/`phi` expressions), in raw units for a
//! scaled channel.

use glrmon_core::{Dims, LpvMatrix, Onset, SignalScaling};
use nalgebra::DVector;

use super::{Validator, join};
use crate::Columns;
use crate::channel::{ColumnPlan, FaultPlan};
use crate::expr::{Expr, ExprContext};
use crate::limits;
use crate::locate;
use crate::schema::{ChannelSpec, EntrySpec, FaultSpec};

impl Validator {
    /// The fault dictionary, each fault with its configuration path: names unique,
    /// known profiles not mixed with the other onsets, at most [`limits::MAX_FAULTS`]
    /// faults once the shortcuts are expanded.
    pub(super) fn faults(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        dims: Dims,
        (g, j): (&LpvMatrix, &LpvMatrix),
        scaling: Option<&SignalScaling>,
        columns: &Columns,
    ) -> (Vec<FaultPlan>, Vec<String>) {
        if spec.faults.is_empty() {
            self.error(
                join(prefix, "faults"),
                "the fault dictionary is empty".into(),
            );
        }
        let expanded = self.expand_shortcuts(prefix, &spec.faults, dims, columns);
        let mut out = Vec::new();
        let mut paths = Vec::new();
        for (i, (path, f)) in expanded.iter().enumerate() {
            if expanded[..i].iter().any(|(_, g)| g.name == f.name) {
                self.error(path.clone(), format!("duplicate fault name \"{}\"", f.name));
            }
            if f.name.is_empty() {
                self.error(
                    format!("{path}.name"),
                    "is missing: every fault needs a name".into(),
                );
                continue;
            }
            if let Some(plan) = self.fault(path, f, dims, j)
                && let Some(plan) = self.in_raw_units(path, f, plan, g, scaling)
            {
                out.push(plan);
                paths.push(path.clone());
            }
        }
        let known = out.iter().filter(|f| f.onset == Onset::Known).count();
        if known != 0 && known != out.len() {
            self.error(
                join(prefix, "faults"),
                "known-profile faults cannot be mixed with step/impulse/ramp faults in one channel"
                    .into(),
            );
        }
        if out.len() > limits::MAX_FAULTS {
            self.error(
                join(prefix, "faults"),
                format!(
                    "holds {} faults (shortcuts expanded): at most {} (limits::MAX_FAULTS)",
                    out.len(),
                    limits::MAX_FAULTS
                ),
            );
        }
        (out, paths)
    }

    /// The dictionary with the `all_sensors` / `all_actuators` shortcuts expanded into
    /// one `sensor_bias` per output / `actuator_bias` per input, each with its path
    /// (`faults[i]`, or `faults[i] (y2)` for an expanded entry). A fault without a name
    /// is named after its signal: `y2_bias`, or `<column>_bias` when
    /// `[channels.columns]` names the columns.
    fn expand_shortcuts(
        &mut self,
        prefix: &str,
        faults: &[FaultSpec],
        dims: Dims,
        columns: &Columns,
    ) -> Vec<(String, FaultSpec)> {
        let mut out = Vec::with_capacity(faults.len());
        for (i, f) in faults.iter().enumerate() {
            let path = join(prefix, &format!("faults[{i}]"));
            let (kind, letter, count) = match f.kind.as_deref() {
                Some("all_sensors") => ("sensor_bias", 'y', dims.outputs),
                Some("all_actuators") => ("actuator_bias", 'u', dims.inputs),
                _ => {
                    out.push((path, f.clone()));
                    continue;
                }
            };
            if f.input.is_some() || f.output.is_some() || f.psi.is_some() || f.phi.is_some() {
                self.error(
                    path,
                    format!(
                        "kind \"{}\" makes one fault per signal: remove input/output/psi/phi",
                        f.kind.as_deref().unwrap_or_default()
                    ),
                );
                continue;
            }
            if count == 0 {
                self.error(
                    format!("{path}.kind"),
                    "\"all_actuators\": the channel has no inputs".into(),
                );
                continue;
            }
            for s in 0..count {
                let name = if f.name.is_empty() {
                    let list = if letter == 'u' {
                        &columns.u
                    } else {
                        &columns.y
                    };
                    match list.get(s) {
                        Some(column) if columns.named => format!("{column}_bias"),
                        _ => format!("{letter}{s}_bias"),
                    }
                } else {
                    format!("{}{s}", f.name)
                };
                out.push((
                    format!("{path} ({letter}{s})"),
                    FaultSpec {
                        name,
                        kind: Some(kind.to_owned()),
                        onset: f.onset.clone(),
                        input: (letter == 'u').then_some(s),
                        output: (letter == 'y').then_some(s),
                        psi: None,
                        phi: None,
                    },
                ));
            }
        }
        out
    }

    /// A `sensor_*` / `actuator_*` fault of a scaled channel, with its magnitude in the
    /// signal's raw units: a raw bias b of y_j is b / y_scale_j in model units, so the
    /// column is e_j / y_scale_j (G·e_i / u_scale_i, J·e_i / u_scale_i for an input).
    /// An actuator gain loss θ is unit-free, but with an input offset the model input is
    /// no longer proportional to the raw one, so that case is refused.
    fn in_raw_units(
        &mut self,
        path: &str,
        f: &FaultSpec,
        plan: FaultPlan,
        g: &LpvMatrix,
        scaling: Option<&SignalScaling>,
    ) -> Option<FaultPlan> {
        let Some(scaling) = scaling else {
            return Some(plan);
        };
        let divide = |c: ColumnPlan, s: f64| match c {
            ColumnPlan::Constant(v) => ColumnPlan::Constant(v / s),
            other => other,
        };
        match (f.kind.as_deref(), f.input, f.output) {
            (Some("sensor_bias" | "sensor_drift"), _, Some(j)) => {
                let s = scaling.y_scale().get(j).copied().unwrap_or(1.0);
                Some(FaultPlan {
                    output: divide(plan.output, s),
                    ..plan
                })
            }
            (Some("actuator_bias"), Some(i), _) => {
                let s = scaling.u_scale().get(i).copied().unwrap_or(1.0);
                if s == 1.0 {
                    return Some(plan);
                }
                if !g.terms().is_empty() {
                    self.error(
                        path.to_owned(),
                        format!(
                            "kind \"actuator_bias\" on a scaled input (scaling.u_scale[{i}] = {s}) \
                             needs a constant G: write psi/phi for an LPV G"
                        ),
                    );
                    return None;
                }
                Some(FaultPlan {
                    state: ColumnPlan::Constant(g.base().column(i) / s),
                    output: divide(plan.output, s),
                    ..plan
                })
            }
            (Some("actuator_gain"), Some(i), _) => {
                if scaling.u_offset().get(i).is_some_and(|o| *o != 0.0) {
                    self.error(
                        path.to_owned(),
                        format!(
                            "kind \"actuator_gain\" on an input with an operating point \
                             (scaling.u_offset[{i}] ≠ 0) is not supported: write psi/phi"
                        ),
                    );
                    return None;
                }
                Some(plan)
            }
            _ => Some(plan),
        }
    }

    /// One fault of the dictionary (a shortcut expanded) as a [`FaultPlan`]: its onset
    /// and its state and output columns.
    fn fault(
        &mut self,
        path: &str,
        f: &FaultSpec,
        dims: Dims,
        j_matrix: &LpvMatrix,
    ) -> Option<FaultPlan> {
        let kind = f.kind.as_deref().unwrap_or("custom");
        let onset = self.onset(path, f, kind)?;
        let shortcut = kind != "custom";
        if shortcut && (f.psi.is_some() || f.phi.is_some()) {
            self.error(
                path.to_owned(),
                format!("kind \"{kind}\" defines its own columns: remove psi/phi"),
            );
            return None;
        }
        let (state, output) = match kind {
            "actuator_bias" | "actuator_gain" => {
                self.actuator_columns(path, f, kind, dims, j_matrix)?
            }
            "sensor_bias" | "sensor_drift" => self.sensor_columns(path, f, kind, dims, onset)?,
            "custom" => self.custom_columns(path, f, dims)?,
            other => {
                self.error(
                    format!("{path}.kind"),
                    locate::not_one_of(
                        other,
                        &[
                            "custom",
                            "actuator_bias",
                            "actuator_gain",
                            "sensor_bias",
                            "sensor_drift",
                            "all_sensors",
                            "all_actuators",
                        ],
                    ),
                );
                return None;
            }
        };
        Some(FaultPlan {
            name: f.name.clone(),
            onset,
            state,
            output,
        })
    }

    /// A fault's onset profile: `onset`, or a ramp for a sensor drift and a step
    /// otherwise.
    fn onset(&mut self, path: &str, f: &FaultSpec, kind: &str) -> Option<Onset> {
        let default_onset = if kind == "sensor_drift" {
            "ramp"
        } else {
            "step"
        };
        let onset_name = f.onset.as_deref().unwrap_or(default_onset);
        match onset_name {
            "step" => Some(Onset::Step),
            "impulse" => Some(Onset::Impulse),
            "ramp" => Some(Onset::Ramp),
            "known" => Some(Onset::Known),
            other => {
                self.error(
                    format!("{path}.onset"),
                    locate::not_one_of(other, &["step", "impulse", "ramp", "known"]),
                );
                None
            }
        }
    }

    /// The input an `actuator_*` fault acts on: `input`, an input of the channel.
    fn fault_input(&mut self, path: &str, f: &FaultSpec, kind: &str, dims: Dims) -> Option<usize> {
        match f.input {
            Some(i) if i < dims.inputs => Some(i),
            Some(i) => {
                self.error(
                    format!("{path}.input"),
                    format!(
                        "input u{i} does not exist (the channel has {} inputs)",
                        dims.inputs
                    ),
                );
                None
            }
            None => {
                self.error(
                    format!("{path}.input"),
                    format!("kind \"{kind}\" needs `input`"),
                );
                None
            }
        }
    }

    /// The output a `sensor_*` fault acts on: `output`, an output of the channel.
    fn fault_output(&mut self, path: &str, f: &FaultSpec, kind: &str, dims: Dims) -> Option<usize> {
        match f.output {
            Some(j) if j < dims.outputs => Some(j),
            Some(j) => {
                self.error(
                    format!("{path}.output"),
                    format!(
                        "output y{j} does not exist (the channel has {} outputs)",
                        dims.outputs
                    ),
                );
                None
            }
            None => {
                self.error(
                    format!("{path}.output"),
                    format!("kind \"{kind}\" needs `output`"),
                );
                None
            }
        }
    }

    /// The columns of an `actuator_bias` (G's column of the input, and J's) or an
    /// `actuator_gain` (the gain loss of the input; J's column must be zero).
    fn actuator_columns(
        &mut self,
        path: &str,
        f: &FaultSpec,
        kind: &str,
        dims: Dims,
        j_matrix: &LpvMatrix,
    ) -> Option<(ColumnPlan, ColumnPlan)> {
        let i = self.fault_input(path, f, kind, dims)?;
        let jcol = j_matrix.base().column(i).into_owned();
        let j_used = jcol.iter().any(|x| *x != 0.0) || !j_matrix.terms().is_empty();
        if j_used {
            if kind == "actuator_gain" || !j_matrix.terms().is_empty() {
                self.error(
                    path.to_owned(),
                    format!("kind \"{kind}\" with a non-zero J column for u{i} is not supported: write psi/phi expressions"),
                );
                return None;
            }
            Some((ColumnPlan::InputBias(i), ColumnPlan::Constant(jcol)))
        } else if kind == "actuator_bias" {
            Some((ColumnPlan::InputBias(i), ColumnPlan::Zero))
        } else {
            Some((ColumnPlan::GainLoss(i), ColumnPlan::Zero))
        }
    }

    /// The columns of a `sensor_bias` or `sensor_drift`: the output's unit vector.
    fn sensor_columns(
        &mut self,
        path: &str,
        f: &FaultSpec,
        kind: &str,
        dims: Dims,
        onset: Onset,
    ) -> Option<(ColumnPlan, ColumnPlan)> {
        let unit =
            |len: usize, at: usize| DVector::from_fn(len, |r, _| if r == at { 1.0 } else { 0.0 });
        let j = self.fault_output(path, f, kind, dims)?;
        if kind == "sensor_drift" && onset != Onset::Ramp {
            self.error(
                format!("{path}.onset"),
                "a sensor drift is a ramp: remove `onset`".into(),
            );
        }
        Some((
            ColumnPlan::Zero,
            ColumnPlan::Constant(unit(dims.outputs, j)),
        ))
    }

    /// The columns of a custom fault: `psi` (state) and `phi` (output), at least one.
    fn custom_columns(
        &mut self,
        path: &str,
        f: &FaultSpec,
        dims: Dims,
    ) -> Option<(ColumnPlan, ColumnPlan)> {
        if f.psi.is_none() && f.phi.is_none() {
            self.error(
                path.to_owned(),
                "a custom fault needs `psi` (state column) and/or `phi` (output column)".into(),
            );
            return None;
        }
        let state = self.column(&format!("{path}.psi"), f.psi.as_deref(), dims.states, dims)?;
        let output = self.column(&format!("{path}.phi"), f.phi.as_deref(), dims.outputs, dims)?;
        Some((state, output))
    }

    fn column(
        &mut self,
        path: &str,
        entries: Option<&[EntrySpec]>,
        len: usize,
        dims: Dims,
    ) -> Option<ColumnPlan> {
        let Some(entries) = entries else {
            return Some(ColumnPlan::Zero);
        };
        if entries.len() != len {
            self.error(
                path.to_owned(),
                format!("has {} entries, expected {len}", entries.len()),
            );
            return None;
        }
        let ctx = ExprContext {
            inputs: dims.inputs,
            signals: dims.signals,
            allow_k: true,
            allow_lags: true,
            allow_random: false,
            states: 0,
            allow_t: false,
        };
        let mut exprs = Vec::new();
        let mut all_constant = true;
        let mut ok = true;
        for (i, e) in entries.iter().enumerate() {
            let parsed = match e {
                EntrySpec::Number(x) if !x.is_finite() => {
                    self.error(format!("{path}[{i}]"), "is not finite".into());
                    ok = false;
                    continue;
                }
                EntrySpec::Number(x) => Expr::parse(&format!("{x:?}"), &ctx),
                EntrySpec::Expr(s) => Expr::parse(s, &ctx),
            };
            match parsed {
                Ok(x) => {
                    all_constant &= x.constant_value().is_some();
                    exprs.push(x);
                }
                Err(err) => {
                    self.error(format!("{path}[{i}]"), err.to_string());
                    ok = false;
                }
            }
        }
        if !ok {
            return None;
        }
        if all_constant {
            let v = DVector::from_iterator(
                len,
                exprs.iter().map(|e| e.constant_value().unwrap_or(0.0)),
            );
            if v.iter().any(|x| !x.is_finite()) {
                self.error(path.to_owned(), "evaluates to a non-finite value".into());
                return None;
            }
            return Some(if v.iter().all(|x| *x == 0.0) {
                ColumnPlan::Zero
            } else {
                ColumnPlan::Constant(v)
            });
        }
        Some(ColumnPlan::Exprs(exprs))
    }
}
