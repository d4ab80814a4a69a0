//! Writing configurations: a commented channel for an identified model
//! (`glrmon identify`).

use std::fmt::Write as _;

use nalgebra::DMatrix;

/// An identified channel, in the terms a configuration needs: the innovation model
/// x⁺ = A x + B u + K e, y = C x + D u + e, cov(e) = Re in the model's (centred,
/// scaled) units, the scaling from the plant's raw units and the CSV columns.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentifiedChannel {
    /// Channel name.
    pub name: String,
    /// Sample period in seconds, if known.
    pub period: Option<f64>,
    /// A (n×n).
    pub a: DMatrix<f64>,
    /// B (n×l).
    pub b: DMatrix<f64>,
    /// C (p×n).
    pub c: DMatrix<f64>,
    /// D (p×l).
    pub d: DMatrix<f64>,
    /// Steady Kalman gain K (n×p).
    pub k: DMatrix<f64>,
    /// Innovation covariance Re (p×p).
    pub re: DMatrix<f64>,
    /// Initial state covariance P0 (n×n).
    pub p0: DMatrix<f64>,
    /// CSV column of each input.
    pub inputs: Vec<String>,
    /// CSV column of each output.
    pub outputs: Vec<String>,
    /// Write `[channels.columns]` even when the columns are the numbered `u0…`/`y0…`:
    /// the recordings hold other columns too (left out, or not chosen), which a reader
    /// must then skip.
    pub other_columns: bool,
    /// Operating point of each input.
    pub u_offset: Vec<f64>,
    /// Scale of each input.
    pub u_scale: Vec<f64>,
    /// Operating point of each output.
    pub y_offset: Vec<f64>,
    /// Scale of each output.
    pub y_scale: Vec<f64>,
    /// GLR window w.
    pub window: usize,
    /// Comment lines for the head of the file (how the model was found).
    pub notes: Vec<String>,
}

/// The configuration text of `channel`: a commented `[[channels]]` entry that
/// `glrmon validate` accepts, with the model in innovation form
/// (F = A, G = B, H = C, J = D, Q = K·Re·Kᵀ, S = K·Re, R = Re: its Kalman filter is the
/// identified steady predictor), `[channels.scaling]`, `[channels.columns]` when the
/// columns are not the numbered `u0…`/`y0…` or the files have others, one sensor bias per output and one
/// actuator bias per input, and a GLR that waits one window before alarming.
///
/// # Examples
///
/// ```
/// use glrmon_spec::write::{IdentifiedChannel, identified_channel};
/// use nalgebra::DMatrix;
///
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let text = identified_channel(&IdentifiedChannel {
///     name: "tank".into(),
///     period: Some(5.0),
///     a: one(0.9), b: one(0.5), c: one(1.0), d: one(0.0), k: one(0.4), re: one(0.2),
///     p0: one(1.0),
///     inputs: vec!["FIC101".into()], outputs: vec!["LI101".into()], other_columns: false,
///     u_offset: vec![3.0], u_scale: vec![0.5], y_offset: vec![12.0], y_scale: vec![0.8],
///     window: 30,
///     notes: vec!["identified from run1.csv".into()],
/// });
/// let config = glrmon_spec::parse(&text)?;
/// let channel = &config.channels[0];
/// assert_eq!(channel.fault_names, ["LI101_bias", "FIC101_bias"]);
/// assert_eq!(channel.columns.u, ["FIC101"]);
/// # Ok::<(), glrmon_spec::SpecErrors>(())
/// ```
#[must_use]
pub fn identified_channel(channel: &IdentifiedChannel) -> String {
    let mut out = String::new();
    for line in &channel.notes {
        let _ = writeln!(out, "# {line}");
    }
    let numbered = !channel.other_columns
        && channel
            .inputs
            .iter()
            .enumerate()
            .all(|(i, n)| *n == format!("u{i}"))
        && channel
            .outputs
            .iter()
            .enumerate()
            .all(|(i, n)| *n == format!("y{i}"));
    let _ = writeln!(out, "\n[[channels]]\nname = {}", quoted(&channel.name));
    if let Some(t) = channel.period {
        let _ = writeln!(out, "period = {t:?}");
    }
    out.push_str(
        "\n# Raw plant values go in unchanged: on intake each becomes (raw − offset) / scale,\n\
         # the units the model was identified in. Fault magnitudes are in raw units.\n\
         [channels.scaling]\n",
    );
    if !channel.inputs.is_empty() {
        let _ = writeln!(out, "u_offset = {}", row(&channel.u_offset));
        let _ = writeln!(out, "u_scale = {}", row(&channel.u_scale));
    }
    let _ = writeln!(out, "y_offset = {}", row(&channel.y_offset));
    let _ = writeln!(out, "y_scale = {}", row(&channel.y_scale));
    if !numbered {
        out.push_str(
            "\n# The CSV columns read into u0…, y0… (other columns are skipped); live\n\
             # payloads carry these signals in this order, or by name.\n[channels.columns]\n",
        );
        if !channel.inputs.is_empty() {
            let _ = writeln!(out, "u = {}", names(&channel.inputs));
        }
        let _ = writeln!(out, "y = {}", names(&channel.outputs));
        let blank = |n: usize| names(&vec![String::new(); n]);
        out.push_str(
            "# Their units as the plant gives them (reports draw each unit on its own axis and\n\
             # give magnitudes in it): uncomment and fill in, e.g. \"cm\", \"m³/h\".\n",
        );
        if !channel.inputs.is_empty() {
            let _ = writeln!(out, "# u_units = {}", blank(channel.inputs.len()));
        }
        let _ = writeln!(out, "# y_units = {}", blank(channel.outputs.len()));
    }
    let q = &channel.k * &channel.re * channel.k.transpose();
    let s = &channel.k * &channel.re;
    out.push_str(
        "\n# Innovation form x⁺ = A x + B u + K e, y = C x + D u + e, cov(e) = Re, written\n\
         # F = A, G = B, H = C, J = D, Q = K·Re·Kᵀ, S = K·Re, R = Re: the Kalman filter of\n\
         # this model is the identified steady predictor (gain K, innovation covariance Re).\n\
         [channels.model]\n",
    );
    let _ = writeln!(out, "F = {}", matrix(&channel.a));
    if !channel.inputs.is_empty() {
        let _ = writeln!(out, "G = {}", matrix(&channel.b));
    }
    let _ = writeln!(out, "H = {}", matrix(&channel.c));
    if !channel.inputs.is_empty() {
        let _ = writeln!(out, "J = {}", matrix(&channel.d));
    }
    let _ = writeln!(out, "Q = {}", matrix(&symmetric(&q)));
    let _ = writeln!(out, "R = {}", matrix(&symmetric(&channel.re)));
    let _ = writeln!(out, "S = {}", matrix(&s));
    let _ = writeln!(out, "P0 = {}", matrix(&symmetric(&channel.p0)));
    if !channel.inputs.is_empty() {
        let inputs: Vec<String> = channel
            .u_offset
            .iter()
            .zip(&channel.u_scale)
            .map(|(o, s)| quoted(&format!("{o:?} + {s:?} * normal(0, 1)")))
            .collect();
        let _ = writeln!(
            out,
            "\n# `glrmon simulate`, `evaluate` and `calibrate --simulate` drive the model with\n\
             # raw inputs of the recordings' mean and spread (white: edit to taste).\n\
             [channels.simulation]\ninputs = [{}]",
            inputs.join(", ")
        );
    }
    out.push_str(
        "\n# One bias per output and per input, named after its column.\n\
         [[channels.faults]]\nkind = \"all_sensors\"\n",
    );
    if !channel.inputs.is_empty() {
        out.push_str("\n[[channels.faults]]\nkind = \"all_actuators\"\n");
    }
    let _ = writeln!(
        out,
        "\n# The threshold is the Bonferroni χ² default until `glrmon calibrate --write`\n\
         # sets one from fault-free data; no alarm before one window of samples.\n\
         [channels.glr]\nwindow = {}\nwarm_up = \"window\"",
        channel.window
    );
    out
}

fn quoted(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn names(list: &[String]) -> String {
    let items: Vec<String> = list.iter().map(|n| quoted(n)).collect();
    format!("[{}]", items.join(", "))
}

/// `[a, b, …]` with each value's shortest round-trip form (`{:?}`: `0.1`, `1e-7`).
fn row(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", items.join(", "))
}

fn matrix(m: &DMatrix<f64>) -> String {
    if m.nrows() == 0 {
        return "[]".into();
    }
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| row(&r.iter().copied().collect::<Vec<_>>()))
        .collect();
    if rows.len() == 1 {
        return format!("[{}]", rows[0]);
    }
    format!("[\n  {},\n]", rows.join(",\n  "))
}

/// (M + Mᵀ)/2: products like K·Re·Kᵀ are symmetric only to rounding, and the
/// configuration's covariance check wants them exactly so.
fn symmetric(m: &DMatrix<f64>) -> DMatrix<f64> {
    (m + m.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbered_columns_need_no_column_table_and_values_round_trip() {
        let m = |r, c, v: &[f64]| DMatrix::from_row_slice(r, c, v);
        let channel = IdentifiedChannel {
            name: "plant \"a\"".into(),
            period: None,
            a: m(2, 2, &[0.5, 0.1, 0.0, 0.25]),
            b: m(2, 0, &[]),
            c: m(1, 2, &[1.0, 1e-7]),
            d: m(1, 0, &[]),
            k: m(2, 1, &[0.3, 0.1]),
            re: m(1, 1, &[2.0]),
            p0: DMatrix::identity(2, 2),
            inputs: vec![],
            outputs: vec!["y0".into()],
            other_columns: false,
            u_offset: vec![],
            u_scale: vec![],
            y_offset: vec![1e3],
            y_scale: vec![0.1],
            window: 20,
            notes: vec![],
        };
        let text = identified_channel(&channel);
        assert!(!text.contains("[channels.columns]"), "{text}");
        assert!(!text.contains("all_actuators"), "{text}");
        // The name needs escaping, which `parse` then rejects for a channel name:
        // check the TOML itself.
        let value: toml::Table = toml::from_str(&text).expect("valid TOML");
        let name = value["channels"][0]["name"].as_str().unwrap();
        assert_eq!(name, "plant \"a\"");
        let text = text.replace("plant \\\"a\\\"", "plant");
        let config = crate::parse(&text).expect("valid configuration");
        let c = &config.channels[0];
        assert_eq!(c.fault_names, ["y0_bias"]);
        assert_eq!(c.model.matrices()[2].base()[(0, 1)], 1e-7);
        assert_eq!(c.cross_covariance.as_ref().unwrap()[(0, 0)], 0.6);
    }

    #[test]
    fn named_columns_come_with_unit_lines_to_fill_in() {
        let m = |r, c, v: &[f64]| DMatrix::from_row_slice(r, c, v);
        let channel = IdentifiedChannel {
            name: "tanks".into(),
            period: Some(20.0),
            a: m(1, 1, &[0.9]),
            b: m(1, 1, &[0.1]),
            c: m(1, 1, &[1.0]),
            d: m(1, 1, &[0.0]),
            k: m(1, 1, &[0.3]),
            re: m(1, 1, &[2.0]),
            p0: DMatrix::identity(1, 1),
            inputs: vec!["FIC101".into()],
            outputs: vec!["LI201".into()],
            other_columns: true,
            u_offset: vec![2.0],
            u_scale: vec![0.2],
            y_offset: vec![60.0],
            y_scale: vec![1.5],
            window: 20,
            notes: vec![],
        };
        let text = identified_channel(&channel);
        assert!(
            text.contains("# u_units = [\"\"]\n# y_units = [\"\"]\n"),
            "{text}"
        );
        let filled = text
            .replace("# u_units = [\"\"]", "u_units = [\"m³/h\"]")
            .replace("# y_units = [\"\"]", "y_units = [\"cm\"]");
        let config = crate::parse(&filled).expect("the filled-in lines are valid");
        assert_eq!(config.channels[0].columns.output_label(0), "LI201 [cm]");
        assert_eq!(config.channels[0].columns.input_label(0), "FIC101 [m³/h]");
    }
}
