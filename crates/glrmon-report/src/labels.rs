//! What a report says of a channel's signals and faults: their names and units, so that
//! its figures speak of `LI201 [cm]` rather than `ε_k[0]` in model units.
//!
//! Records carry indices and numbers only: the innovation ε_k in the model's units
//! ((raw − offset)/scale with `[channels.scaling]`), the magnitudes θ̂ in each fault's
//! own unit. The configuration knows the rest, and [`ChannelLabels::from_channel`]
//! reads it: the output names and raw units of `[channels.columns]`, the output scales
//! of `[channels.scaling]`, and each fault's unit from its kind. With a scaling, a
//! `sensor_*` or `actuator_bias` fault's column is divided by its signal's scale, so its
//! magnitude is in the signal's raw unit (a bias of LI201 in cm, of FIC101 in m³/h);
//! `actuator_gain` is a fraction of the input; a hand-written `psi`/`phi` column is in
//! the model's units.

use glrmon_spec::Channel;
use glrmon_spec::schema::{ConfigFile, FaultSpec};

/// One output of a channel.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalLabel {
    /// Its name (`[channels.columns] y`, else `y0`, `y1`, …).
    pub name: String,
    /// Its raw unit (`[channels.columns] y_units`), if given.
    pub unit: Option<String>,
    /// Raw units per model unit (`[channels.scaling] y_scale`; 1 without a scaling):
    /// an innovation ε in model units is ε·scale in raw units (the offset cancels in a
    /// difference).
    pub scale: f64,
}

impl SignalLabel {
    /// The name with the unit in brackets when known: `LI201 [cm]`.
    #[must_use]
    pub fn label(&self) -> String {
        match &self.unit {
            Some(unit) => format!("{} [{unit}]", self.name),
            None => self.name.clone(),
        }
    }
}

/// The unit of a fault's magnitude θ̂.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MagnitudeUnit {
    /// The raw unit of a signal: a `sensor_bias` of an output, an `actuator_bias` of an
    /// input. `unit` is `None` when the configuration gives none.
    Signal {
        /// The signal's name.
        signal: String,
        /// Its raw unit, if given.
        unit: Option<String>,
    },
    /// The raw unit of an output per sample: a `sensor_drift` (a ramp).
    PerSample {
        /// The signal's name.
        signal: String,
        /// Its raw unit, if given.
        unit: Option<String>,
    },
    /// A fraction of an input: an `actuator_gain` (0.1 is a loss of 10 %).
    Fraction,
    /// The model's units: a fault with hand-written `psi`/`phi` columns.
    Model,
    /// Not known (no configuration, or one that does not describe this dictionary).
    Unknown,
}

impl MagnitudeUnit {
    /// The unit as an axis shows it, and by which faults are grouped on one axis:
    /// `cm`, `cm per sample`, `fraction of the input`, `model units`; a signal's raw
    /// unit that is not given reads `raw units of LI201`.
    #[must_use]
    pub fn label(&self) -> String {
        match self {
            MagnitudeUnit::Signal {
                unit: Some(unit), ..
            } => unit.clone(),
            MagnitudeUnit::Signal { signal, unit: None } => format!("raw units of {signal}"),
            MagnitudeUnit::PerSample {
                unit: Some(unit), ..
            } => format!("{unit} per sample"),
            MagnitudeUnit::PerSample { signal, unit: None } => {
                format!("raw units of {signal} per sample")
            }
            MagnitudeUnit::Fraction => "fraction of the input".to_owned(),
            MagnitudeUnit::Model => "model units".to_owned(),
            MagnitudeUnit::Unknown => "units not known".to_owned(),
        }
    }

    /// The unit written after a number (`1.32 cm`), when it is a named one.
    #[must_use]
    pub fn suffix(&self) -> Option<String> {
        match self {
            MagnitudeUnit::Signal {
                unit: Some(unit), ..
            } => Some(unit.clone()),
            MagnitudeUnit::PerSample {
                unit: Some(unit), ..
            } => Some(format!("{unit}/sample")),
            _ => None,
        }
    }
}

/// One fault of the dictionary.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FaultLabel {
    /// The fault's name, as records give it.
    pub name: String,
    /// The unit of its magnitude.
    pub unit: MagnitudeUnit,
}

/// A residual of the `stat` records drawn against its threshold, as the kernel
/// method's papers draw r_FD with σ_FD and r_FI,i with σ_FI,i: positions in
/// `stat.residual`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResidualBound {
    /// What the residual is, for the figure's title (`detection r_FD`).
    pub name: String,
    /// Index of the residual in `stat.residual`.
    pub residual: usize,
    /// Index of its threshold in `stat.residual`.
    pub threshold: usize,
}

/// The names and units of a channel's outputs and faults, in the order of the records'
/// `innovation` and `magnitude` vectors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChannelLabels {
    /// The outputs, in the order of ε_k.
    pub outputs: Vec<SignalLabel>,
    /// The faults, in dictionary order (the order of θ̂).
    pub faults: Vec<FaultLabel>,
    /// Whether the channel has a `[channels.scaling]`: its model works in
    /// (raw − offset)/scale.
    pub scaled: bool,
    /// The residuals the channel's detector kind pairs with thresholds in
    /// `stat.residual` (empty for the kinds that do not).
    pub residual_bounds: Vec<ResidualBound>,
}

impl ChannelLabels {
    /// The labels of a validated channel of the configuration whose TOML text is
    /// `source` (`glrmon_spec::Config::source`): each fault's unit follows from its kind
    /// in that text, shortcuts expanded as the configuration expands them. When the text
    /// does not describe the channel's dictionary (another file), the faults' units are
    /// [`MagnitudeUnit::Unknown`].
    ///
    /// ```
    /// use glrmon_report::{ChannelLabels, MagnitudeUnit};
    ///
    /// let source = r#"
    /// [[channels]]
    /// name = "tank"
    /// model = { F = [[0.9]], G = [[0.1]], H = [[1.0]], Q = 0.01, R = 0.01 }
    /// scaling = { y_offset = [120.0], y_scale = [0.5] }
    /// columns = { u = ["FIC101"], y = ["LI201"], u_units = ["m³/h"], y_units = ["cm"] }
    /// faults = [{ kind = "all_sensors" }, { name = "pump", kind = "actuator_bias", input = 0 }]
    /// "#;
    /// let config = glrmon_spec::parse(source).unwrap();
    /// let labels = ChannelLabels::from_channel(&config.channels[0], source);
    /// assert_eq!(labels.outputs[0].label(), "LI201 [cm]");
    /// assert_eq!(labels.outputs[0].scale, 0.5);
    /// assert_eq!(labels.faults[0].name, "LI201_bias");
    /// assert_eq!(labels.faults[0].unit.label(), "cm");
    /// assert_eq!(labels.faults[1].unit.label(), "m³/h");
    /// ```
    #[must_use]
    pub fn from_channel(channel: &Channel, source: &str) -> Self {
        let columns = &channel.columns;
        let y_scale = channel.scaling.as_ref().map(|s| s.y_scale().to_vec());
        let outputs = (0..channel.dims.outputs)
            .map(|i| SignalLabel {
                name: columns.y.get(i).cloned().unwrap_or_else(|| format!("y{i}")),
                unit: columns.output_unit(i).map(str::to_owned),
                scale: y_scale
                    .as_ref()
                    .and_then(|s| s.get(i).copied())
                    .filter(|s| s.is_finite() && *s > 0.0)
                    .unwrap_or(1.0),
            })
            .collect();
        let units = fault_units(channel, source)
            .filter(|units| units.len() == channel.fault_names.len())
            .unwrap_or_else(|| vec![MagnitudeUnit::Unknown; channel.fault_names.len()]);
        let faults = channel
            .fault_names
            .iter()
            .zip(units)
            .map(|(name, unit)| FaultLabel {
                name: name.clone(),
                unit,
            })
            .collect();
        ChannelLabels {
            outputs,
            faults,
            scaled: channel.scaling.is_some(),
            residual_bounds: residual_bounds(channel),
        }
    }

    /// The output of index i, if known.
    pub(crate) fn output(&self, i: usize) -> Option<&SignalLabel> {
        self.outputs.get(i)
    }

    /// The unit of the magnitude of fault i, [`MagnitudeUnit::Unknown`] when not known.
    pub(crate) fn fault_unit(&self, i: usize) -> MagnitudeUnit {
        self.faults
            .get(i)
            .map_or(MagnitudeUnit::Unknown, |f| f.unit.clone())
    }
}

/// Each fault's unit in dictionary order, from the channel's entry in the configuration
/// text: `all_sensors`/`all_actuators` make one bias per output/input, every other entry
/// one fault. `None` when the text cannot be read or has no such channel.
fn fault_units(channel: &Channel, source: &str) -> Option<Vec<MagnitudeUnit>> {
    let file: ConfigFile = toml::from_str(source).ok()?;
    let spec = file.channels.iter().find(|c| c.name == channel.name)?;
    let columns = &channel.columns;
    let output = |j: usize| MagnitudeUnit::Signal {
        signal: columns.y.get(j).cloned().unwrap_or_else(|| format!("y{j}")),
        unit: columns.output_unit(j).map(str::to_owned),
    };
    let input = |i: usize| MagnitudeUnit::Signal {
        signal: columns.u.get(i).cloned().unwrap_or_else(|| format!("u{i}")),
        unit: columns.input_unit(i).map(str::to_owned),
    };
    let mut units = Vec::new();
    for f in &spec.faults {
        match f.kind.as_deref() {
            Some("all_sensors") => units.extend((0..channel.dims.outputs).map(output)),
            Some("all_actuators") => units.extend((0..channel.dims.inputs).map(input)),
            _ => units.push(one_fault_unit(f, &output, &input)),
        }
    }
    Some(units)
}

/// The unit of one (not shortcut) fault of the configuration.
fn one_fault_unit(
    f: &FaultSpec,
    output: &dyn Fn(usize) -> MagnitudeUnit,
    input: &dyn Fn(usize) -> MagnitudeUnit,
) -> MagnitudeUnit {
    match (f.kind.as_deref(), f.input, f.output) {
        (Some("sensor_bias"), _, Some(j)) => output(j),
        (Some("sensor_drift"), _, Some(j)) => match output(j) {
            MagnitudeUnit::Signal { signal, unit } => MagnitudeUnit::PerSample { signal, unit },
            other => other,
        },
        (Some("actuator_bias"), Some(i), _) => input(i),
        (Some("actuator_gain"), Some(_), _) => MagnitudeUnit::Fraction,
        _ => MagnitudeUnit::Model,
    }
}

/// The kernel kind's residual layout (docs/WIRE.md): [r_FD, σ_FD, r_FI,1, σ_FI,1, …].
fn residual_bounds(channel: &Channel) -> Vec<ResidualBound> {
    if channel.detector_kind != glrmon_spec::DetectorKind::Kernel {
        return Vec::new();
    }
    let mut bounds = vec![ResidualBound {
        name: "detection r_FD".to_owned(),
        residual: 0,
        threshold: 1,
    }];
    if let Some(kernel) = &channel.kernel {
        for (i, candidate) in kernel.candidates.iter().enumerate() {
            bounds.push(ResidualBound {
                name: format!("isolation r_FI of {}", candidate.name),
                residual: 2 + 2 * i,
                threshold: 3 + 2 * i,
            });
        }
    }
    bounds
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_TANKS: &str = r#"
[[channels]]
name = "other"
model = { F = [[0.5]], H = [[1.0]], Q = 0.01, R = 0.01 }
faults = [{ name = "b", kind = "sensor_bias", output = 0 }]

[[channels]]
name = "tanks"
[channels.model]
F = [[0.9, 0.0], [0.05, 0.9]]
G = [[0.1, 0.0], [0.0, 0.1]]
H = [[1.0, 0.0], [0.0, 1.0], [0.0, 0.5]]
Q = 0.01
R = 0.01
[channels.scaling]
y_scale = [2.0, 2.0, 0.1]
[channels.columns]
u = ["FIC101", "FIC102"]
y = ["LI201", "LI202", "FI301"]
u_units = ["m³/h", "m³/h"]
y_units = ["cm", "cm", "m³/h"]
[[channels.faults]]
kind = "all_sensors"
[[channels.faults]]
name = "drift"
kind = "sensor_drift"
output = 1
[[channels.faults]]
name = "valve"
kind = "actuator_gain"
input = 1
[[channels.faults]]
name = "leak"
psi = [0.0, -0.1]
[[channels.faults]]
kind = "all_actuators"
"#;

    #[test]
    fn units_follow_the_kinds_with_shortcuts_expanded() {
        let config = glrmon_spec::parse(TWO_TANKS).unwrap();
        let labels = ChannelLabels::from_channel(&config.channels[1], TWO_TANKS);
        assert!(labels.scaled);
        let outputs: Vec<(String, f64)> = labels
            .outputs
            .iter()
            .map(|o| (o.label(), o.scale))
            .collect();
        assert_eq!(
            outputs,
            [
                ("LI201 [cm]".to_owned(), 2.0),
                ("LI202 [cm]".to_owned(), 2.0),
                ("FI301 [m³/h]".to_owned(), 0.1)
            ]
        );
        let faults: Vec<(&str, String)> = labels
            .faults
            .iter()
            .map(|f| (f.name.as_str(), f.unit.label()))
            .collect();
        assert_eq!(
            faults,
            [
                ("LI201_bias", "cm".to_owned()),
                ("LI202_bias", "cm".to_owned()),
                ("FI301_bias", "m³/h".to_owned()),
                ("drift", "cm per sample".to_owned()),
                ("valve", "fraction of the input".to_owned()),
                ("leak", "model units".to_owned()),
                ("FIC101_bias", "m³/h".to_owned()),
                ("FIC102_bias", "m³/h".to_owned()),
            ]
        );
        assert_eq!(labels.faults[3].unit.suffix().as_deref(), Some("cm/sample"));
        assert_eq!(labels.faults[4].unit.suffix(), None);
    }

    #[test]
    fn without_columns_or_a_matching_text_names_are_numbered_and_units_unknown() {
        let config = glrmon_spec::parse(TWO_TANKS).unwrap();
        let other = ChannelLabels::from_channel(&config.channels[0], TWO_TANKS);
        assert!(!other.scaled);
        assert_eq!(
            (other.outputs[0].label(), other.outputs[0].scale),
            ("y0".to_owned(), 1.0)
        );
        assert_eq!(other.faults[0].unit.label(), "raw units of y0");
        let unrelated = ChannelLabels::from_channel(&config.channels[1], "[[channels]]\n");
        assert!(
            unrelated
                .faults
                .iter()
                .all(|f| f.unit == MagnitudeUnit::Unknown),
            "{unrelated:?}"
        );
        assert_eq!(unrelated.faults.len(), 8);
    }
}
