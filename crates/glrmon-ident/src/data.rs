//! Recordings and their preprocessing: validation, operating point, trend, scale and
//! the detection of constant columns.
//!
//! Each experiment is treated on its own (its own operating point and trend), because
//! separate recordings may sit at different operating points and their joins are not
//! plant behaviour; only the scale is pooled, so that all experiments share one model.

use std::fmt;

use nalgebra::{DMatrix, DVector};

use crate::error::{IdentError, Signal};

/// One recording: `inputs` is N × l, `outputs` N × p, one row per sample, same rows.
///
/// l = 0 (a pure time series) is written as an N × 0 input matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Inputs u_k, one row per sample (N × l, l ≥ 0).
    pub inputs: DMatrix<f64>,
    /// Outputs y_k, one row per sample (N × p, p ≥ 1).
    pub outputs: DMatrix<f64>,
}

impl Experiment {
    /// An experiment from its input and output matrices (rows are samples).
    #[must_use]
    pub fn new(inputs: DMatrix<f64>, outputs: DMatrix<f64>) -> Self {
        Self { inputs, outputs }
    }

    /// A pure time series (no input): `outputs` is N × p.
    #[must_use]
    pub fn time_series(outputs: DMatrix<f64>) -> Self {
        Self {
            inputs: DMatrix::zeros(outputs.nrows(), 0),
            outputs,
        }
    }

    /// Number of samples N.
    #[must_use]
    pub fn samples(&self) -> usize {
        self.outputs.nrows()
    }

    /// Rows `range` of both matrices, as a new experiment.
    pub(crate) fn rows(&self, start: usize, len: usize) -> Self {
        Self {
            inputs: self.inputs.rows(start, len).into_owned(),
            outputs: self.outputs.rows(start, len).into_owned(),
        }
    }
}

/// What is removed from each experiment's signals before identification.
///
/// The identified model has no constant term, so at least the operating point (mean)
/// is always removed, per experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Detrend {
    /// Each experiment's mean per signal (its operating point).
    #[default]
    Constant,
    /// Each experiment's least-squares line a + b·(k − (N − 1)/2) per signal: slow drifts
    /// that the model is not meant to explain.
    Linear,
}

/// Settings of [`preprocess`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreprocessSettings {
    /// What to remove per experiment.
    pub detrend: Detrend,
    /// A column whose pooled standard deviation (after detrending) is at most this times
    /// its largest absolute raw value is *nearly constant*: it carries no information a
    /// linear model can use, only rounding or quantisation noise, so it is dropped with a
    /// warning. Default 1e-8.
    pub constant_tolerance: f64,
}

impl Default for PreprocessSettings {
    fn default() -> Self {
        Self {
            detrend: Detrend::Constant,
            constant_tolerance: 1e-8,
        }
    }
}

/// Why a column was dropped.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum WarningKind {
    /// Every sample equals `value` in every experiment (after detrending: zero spread).
    Constant {
        /// The (first experiment's) value.
        value: f64,
    },
    /// The spread is tiny relative to the level: `std` ≤ tolerance · `level`.
    NearlyConstant {
        /// Pooled standard deviation after detrending.
        std: f64,
        /// Largest absolute raw value.
        level: f64,
    },
}

/// A column that identification leaves out, and why. Never an error: the rest is
/// identified.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Warning {
    /// Input or output.
    pub signal: Signal,
    /// Column index in the caller's matrices.
    pub column: usize,
    /// Why it was dropped.
    pub kind: WarningKind,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            WarningKind::Constant { value } => write!(
                f,
                "{} column {} is constant ({value}) after detrending; left out of the model",
                self.signal, self.column
            ),
            WarningKind::NearlyConstant { std, level } => write!(
                f,
                "{} column {} is nearly constant (std {std:.3e} at level {level:.3e}); left out \
                 of the model",
                self.signal, self.column
            ),
        }
    }
}

/// What was removed from one experiment: the signal at row k was
/// `mean + slope·(k − (N − 1)/2)` (slope zero with [`Detrend::Constant`]).
#[derive(Debug, Clone, PartialEq)]
pub struct OperatingPoint {
    /// Mean of each kept input column.
    pub input_mean: DVector<f64>,
    /// Slope per sample of each kept input column.
    pub input_slope: DVector<f64>,
    /// Mean of each kept output column.
    pub output_mean: DVector<f64>,
    /// Slope per sample of each kept output column.
    pub output_slope: DVector<f64>,
}

/// The map between the caller's columns and the identification's scaled signals.
///
/// Identification works on u_s = (u − u₀)/σ_u and y_s = (y − y₀)/σ_y of the kept
/// columns, so that singular values and least squares are not dominated by units.
#[derive(Debug, Clone, PartialEq)]
pub struct Scaling {
    /// The caller's input columns the model uses, in order.
    pub input_columns: Vec<usize>,
    /// The caller's output columns the model uses, in order.
    pub output_columns: Vec<usize>,
    /// σ_u of each kept input (pooled over experiments, after detrending).
    pub input_scale: DVector<f64>,
    /// σ_y of each kept output.
    pub output_scale: DVector<f64>,
    /// One per experiment, in the given order.
    pub operating_points: Vec<OperatingPoint>,
}

/// The output of [`preprocess`]: scaled, detrended experiments of the kept columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Preprocessed {
    /// The experiments, detrended and scaled, kept columns only.
    pub experiments: Vec<Experiment>,
    /// How to map back to the caller's units.
    pub scaling: Scaling,
    /// Dropped columns.
    pub warnings: Vec<Warning>,
}

/// Checks the experiments' shapes and values, removes each experiment's operating point
/// (and trend), scales every column to unit pooled standard deviation, and drops constant
/// or nearly constant columns with a [`Warning`].
///
/// # Errors
/// [`IdentError::NoExperiment`], [`IdentError::RowMismatch`],
/// [`IdentError::ColumnMismatch`], [`IdentError::NoOutput`], [`IdentError::NonFinite`]
/// (naming experiment, column and row), [`IdentError::AllOutputsConstant`],
/// [`IdentError::DuplicateColumns`] (two columns of one signal), [`IdentError::Overflow`],
/// [`IdentError::InvalidSetting`].
pub fn preprocess(
    experiments: &[Experiment],
    settings: &PreprocessSettings,
) -> Result<Preprocessed, IdentError> {
    if !(settings.constant_tolerance >= 0.0 && settings.constant_tolerance < 1.0) {
        return Err(IdentError::InvalidSetting {
            name: "constant_tolerance",
            why: format!("must be in [0, 1), got {}", settings.constant_tolerance),
        });
    }
    let first = experiments.first().ok_or(IdentError::NoExperiment)?;
    let (l, p) = (first.inputs.ncols(), first.outputs.ncols());
    if p == 0 {
        return Err(IdentError::NoOutput);
    }
    for (e, exp) in experiments.iter().enumerate() {
        check_experiment(e, exp, l, p)?;
    }

    let mut warnings = Vec::new();
    let (input_columns, input_scale) =
        kept_columns(experiments, Signal::Input, l, settings, &mut warnings)?;
    let (output_columns, output_scale) =
        kept_columns(experiments, Signal::Output, p, settings, &mut warnings)?;
    if output_columns.is_empty() {
        return Err(IdentError::AllOutputsConstant { outputs: p });
    }

    let mut scaled = Vec::with_capacity(experiments.len());
    let mut operating_points = Vec::with_capacity(experiments.len());
    for exp in experiments {
        let (u, u_mean, u_slope) =
            detrend_scale(&exp.inputs, &input_columns, &input_scale, settings.detrend);
        let (y, y_mean, y_slope) = detrend_scale(
            &exp.outputs,
            &output_columns,
            &output_scale,
            settings.detrend,
        );
        scaled.push(Experiment::new(u, y));
        operating_points.push(OperatingPoint {
            input_mean: u_mean,
            input_slope: u_slope,
            output_mean: y_mean,
            output_slope: y_slope,
        });
    }
    for signal in [Signal::Input, Signal::Output] {
        let kept = match signal {
            Signal::Input => &input_columns,
            Signal::Output => &output_columns,
        };
        if let Some((a, b)) = duplicate_pair(&scaled, signal) {
            return Err(IdentError::DuplicateColumns {
                signal,
                first: kept[a],
                second: kept[b],
            });
        }
    }
    Ok(Preprocessed {
        experiments: scaled,
        scaling: Scaling {
            input_columns,
            output_columns,
            input_scale,
            output_scale,
            operating_points,
        },
        warnings,
    })
}

/// The shape checks of an identification method over `experiments`: at least one, with
/// outputs; every experiment with the first one's inputs and outputs, as many input as
/// output rows, and at least `needed` samples for the method's `horizon`. Returns the
/// numbers of inputs and outputs (l, p).
pub(crate) fn check_shapes(
    experiments: &[Experiment],
    horizon: usize,
    needed: usize,
) -> Result<(usize, usize), IdentError> {
    let first = experiments.first().ok_or(IdentError::NoExperiment)?;
    let (l, p) = (first.inputs.ncols(), first.outputs.ncols());
    if p == 0 {
        return Err(IdentError::NoOutput);
    }
    for (e, exp) in experiments.iter().enumerate() {
        for (signal, got, expected) in [
            (Signal::Input, exp.inputs.ncols(), l),
            (Signal::Output, exp.outputs.ncols(), p),
        ] {
            if got != expected {
                return Err(IdentError::ColumnMismatch {
                    experiment: e,
                    signal,
                    got,
                    expected,
                });
            }
        }
        let n = exp.samples();
        if exp.inputs.nrows() != n {
            return Err(IdentError::RowMismatch {
                experiment: e,
                input_rows: exp.inputs.nrows(),
                output_rows: n,
            });
        }
        if n < needed {
            return Err(IdentError::ExperimentTooShort {
                experiment: e,
                samples: n,
                part: "",
                horizon,
                needed,
            });
        }
    }
    Ok((l, p))
}

fn check_experiment(e: usize, exp: &Experiment, l: usize, p: usize) -> Result<(), IdentError> {
    if exp.inputs.nrows() != exp.outputs.nrows() {
        return Err(IdentError::RowMismatch {
            experiment: e,
            input_rows: exp.inputs.nrows(),
            output_rows: exp.outputs.nrows(),
        });
    }
    for (signal, m, expected) in [
        (Signal::Input, &exp.inputs, l),
        (Signal::Output, &exp.outputs, p),
    ] {
        if m.ncols() != expected {
            return Err(IdentError::ColumnMismatch {
                experiment: e,
                signal,
                got: m.ncols(),
                expected,
            });
        }
        // Column-major storage: report the first bad sample of the first bad column.
        for (column, col) in m.column_iter().enumerate() {
            if let Some((row, &value)) = col.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(IdentError::NonFinite {
                    experiment: e,
                    signal,
                    column,
                    row,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// The least-squares line of `x` against k − (N − 1)/2: (mean, slope).
fn line(x: &[f64], detrend: Detrend) -> (f64, f64) {
    let n = x.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    if detrend == Detrend::Constant || n < 2 {
        return (mean, 0.0);
    }
    let mid = (n as f64 - 1.0) / 2.0;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, v) in x.iter().enumerate() {
        let t = k as f64 - mid;
        sxy += t * (v - mean);
        sxx += t * t;
    }
    (mean, sxy / sxx)
}

/// Pooled standard deviation of each column after detrending; drops constant columns.
fn kept_columns(
    experiments: &[Experiment],
    signal: Signal,
    columns: usize,
    settings: &PreprocessSettings,
    warnings: &mut Vec<Warning>,
) -> Result<(Vec<usize>, DVector<f64>), IdentError> {
    let mut kept = Vec::new();
    let mut scales = Vec::new();
    for column in 0..columns {
        let col = |exp| column_slice(exp, signal, column);
        // The deviations are summed relative to the column's largest magnitude, so that
        // the test is relative: a column of size 1e-300 is not constant because its
        // squares underflow, nor does one of size 1e200 overflow.
        let level = experiments
            .iter()
            .flat_map(|exp| col(exp).iter())
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let unit = if level > 0.0 && level.is_finite() {
            level
        } else {
            1.0
        };
        let (mut sum_sq, mut count) = (0.0, 0usize);
        let mut first_value = None;
        let mut spread = false;
        for exp in experiments {
            let x = col(exp);
            let (mean, slope) = line(x, settings.detrend);
            let mid = (x.len() as f64 - 1.0) / 2.0;
            for (k, v) in x.iter().enumerate() {
                let d = (v - mean - slope * (k as f64 - mid)) / unit;
                sum_sq += d * d;
                match first_value {
                    None => first_value = Some(*v),
                    Some(f) => spread |= f != *v,
                }
            }
            count += x.len();
        }
        let std = if count > 1 {
            unit * (sum_sq / (count - 1) as f64).sqrt()
        } else {
            0.0
        };
        // The physical covariances are σ² times the scaled ones.
        if !(std * std).is_finite() {
            return Err(IdentError::Overflow { signal, column });
        }
        let kind = if std == 0.0 || (!spread && count > 0) {
            Some(WarningKind::Constant {
                value: first_value.unwrap_or(0.0),
            })
        } else if std <= settings.constant_tolerance * level {
            Some(WarningKind::NearlyConstant { std, level })
        } else {
            None
        };
        match kind {
            Some(kind) => warnings.push(Warning {
                signal,
                column,
                kind,
            }),
            None => {
                kept.push(column);
                scales.push(std);
            }
        }
    }
    Ok((kept, DVector::from_vec(scales)))
}

/// Correlation above which two scaled columns are the same signal (up to sign and
/// rounding): no model can tell them apart, and their covariances are singular.
const DUPLICATE_CORRELATION: f64 = 1.0 - 1e-10;

/// The first pair (a < b) of kept columns of `signal` whose pooled correlation over the
/// scaled experiments is ±1 to [`DUPLICATE_CORRELATION`].
fn duplicate_pair(scaled: &[Experiment], signal: Signal) -> Option<(usize, usize)> {
    let cols = match signal {
        Signal::Input => scaled.first()?.inputs.ncols(),
        Signal::Output => scaled.first()?.outputs.ncols(),
    };
    if cols < 2 {
        return None;
    }
    let mut gram = DMatrix::<f64>::zeros(cols, cols);
    for exp in scaled {
        let m = match signal {
            Signal::Input => &exp.inputs,
            Signal::Output => &exp.outputs,
        };
        gram += m.transpose() * m;
    }
    for b in 1..cols {
        for a in 0..b {
            let r = gram[(a, b)] / (gram[(a, a)] * gram[(b, b)]).sqrt();
            if r.abs() > DUPLICATE_CORRELATION {
                return Some((a, b));
            }
        }
    }
    None
}

/// Column `column` of an experiment's inputs or outputs (column-major: contiguous).
fn column_slice(exp: &Experiment, signal: Signal, column: usize) -> &[f64] {
    let m = match signal {
        Signal::Input => &exp.inputs,
        Signal::Output => &exp.outputs,
    };
    let n = m.nrows();
    &m.as_slice()[column * n..(column + 1) * n]
}

/// The kept columns of `m`, detrended and divided by their scale; with the removed
/// means and slopes.
fn detrend_scale(
    m: &DMatrix<f64>,
    columns: &[usize],
    scale: &DVector<f64>,
    detrend: Detrend,
) -> (DMatrix<f64>, DVector<f64>, DVector<f64>) {
    let n = m.nrows();
    let mut out = DMatrix::zeros(n, columns.len());
    let mut means = DVector::zeros(columns.len());
    let mut slopes = DVector::zeros(columns.len());
    let mid = (n as f64 - 1.0) / 2.0;
    for (j, (&c, &s)) in columns.iter().zip(scale.iter()).enumerate() {
        let col = m.column(c);
        let (mean, slope) = line(col.as_slice(), detrend);
        means[j] = mean;
        slopes[j] = slope;
        for k in 0..n {
            out[(k, j)] = (col[k] - mean - slope * (k as f64 - mid)) / s;
        }
    }
    (out, means, slopes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_is_an_error_naming_column_and_row() {
        let mut y = DMatrix::from_element(10, 2, 1.0);
        y[(7, 1)] = f64::NAN;
        let err = preprocess(
            &[Experiment::time_series(y)],
            &PreprocessSettings::default(),
        )
        .unwrap_err();
        assert!(matches!(
            err,
            IdentError::NonFinite {
                experiment: 0,
                signal: Signal::Output,
                column: 1,
                row: 7,
                ..
            }
        ));
        assert!(err.to_string().contains("column 1, row 7"), "{err}");
    }

    #[test]
    fn constant_and_nearly_constant_columns_are_warnings() {
        let n = 50;
        let u = DMatrix::from_fn(n, 3, |k, j| match j {
            0 => (k as f64 * 0.7).sin(),
            1 => 5.0,
            _ => 1e3 + 1e-9 * ((k % 2) as f64),
        });
        let y = DMatrix::from_fn(n, 1, |k, _| (k as f64 * 0.3).cos());
        let pre = preprocess(&[Experiment::new(u, y)], &PreprocessSettings::default()).unwrap();
        assert_eq!(pre.scaling.input_columns, vec![0]);
        assert_eq!(pre.warnings.len(), 2);
        assert_eq!(pre.warnings[0].column, 1);
        assert!(matches!(pre.warnings[0].kind, WarningKind::Constant { value } if value == 5.0));
        assert!(matches!(
            pre.warnings[1].kind,
            WarningKind::NearlyConstant { .. }
        ));
        assert!(
            pre.warnings[0]
                .to_string()
                .contains("input column 1 is constant")
        );
    }

    #[test]
    fn linear_detrend_removes_a_ramp_exactly() {
        let n = 40;
        let y = DMatrix::from_fn(n, 2, |k, j| {
            3.0 + 0.5 * k as f64 + if j == 0 { (k as f64).sin() } else { 0.0 }
        });
        let settings = PreprocessSettings {
            detrend: Detrend::Linear,
            ..PreprocessSettings::default()
        };
        let pre = preprocess(&[Experiment::time_series(y)], &settings).unwrap();
        // Column 1 is a pure ramp: constant after detrending.
        assert_eq!(pre.scaling.output_columns, vec![0]);
        let op = &pre.scaling.operating_points[0];
        assert!((op.output_mean[0] - (3.0 + 0.5 * 19.5)).abs() < 0.2);
        assert!((op.output_slope[0] - 0.5).abs() < 0.05);
    }

    #[test]
    fn overflowing_column_is_an_error_not_a_nan() {
        let y = DMatrix::from_fn(10, 1, |k, _| if k % 2 == 0 { 1.7e308 } else { -1.7e308 });
        let err = preprocess(
            &[Experiment::time_series(y)],
            &PreprocessSettings::default(),
        )
        .unwrap_err();
        assert_eq!(
            err,
            IdentError::Overflow {
                signal: Signal::Output,
                column: 0
            }
        );
    }

    #[test]
    fn the_constant_test_is_relative_to_the_size_of_the_data() {
        // Data of size 1e-300 vary (their squares underflow, their ratios do not); data of
        // size 1e150 do not overflow; a truly constant tiny column is still constant.
        let n = 200;
        let y = DMatrix::from_fn(n, 3, |k, j| {
            let s = (k as f64 * 0.37).sin();
            match j {
                0 => 1e-300 * (2.0 + s),
                1 => 1e150 * (2.0 + s * s * s),
                _ => 3e-300,
            }
        });
        let pre = preprocess(
            &[Experiment::time_series(y)],
            &PreprocessSettings::default(),
        )
        .unwrap();
        assert_eq!(pre.scaling.output_columns, vec![0, 1], "{:?}", pre.warnings);
        let s = &pre.scaling.output_scale;
        let spread = |f: &dyn Fn(f64) -> f64| {
            let x: Vec<f64> = (0..n).map(|k| f((k as f64 * 0.37).sin())).collect();
            let mean = x.iter().sum::<f64>() / n as f64;
            (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        };
        assert!((s[0] / 1e-300 / spread(&|v| v) - 1.0).abs() < 1e-9, "{s}");
        assert!(
            (s[1] / 1e150 / spread(&|v| v * v * v) - 1.0).abs() < 1e-9,
            "{s}"
        );
        assert!(matches!(
            pre.warnings[0].kind,
            WarningKind::Constant { value } if value == 3e-300
        ));
    }

    #[test]
    fn a_column_repeated_or_copied_is_an_error_naming_both() {
        let n = 100;
        let u = DMatrix::from_fn(n, 3, |k, j| match j {
            0 => (k as f64 * 0.7).sin(),
            1 => (k as f64 * 0.3).cos(),
            _ => 10.0 - 2.0 * (k as f64 * 0.3).cos(),
        });
        let y = DMatrix::from_fn(n, 1, |k, _| (k as f64 * 0.2).sin());
        let err = preprocess(&[Experiment::new(u, y)], &PreprocessSettings::default()).unwrap_err();
        assert_eq!(
            err,
            IdentError::DuplicateColumns {
                signal: Signal::Input,
                first: 1,
                second: 2
            }
        );
        assert!(err.to_string().contains("input columns 1 and 2"), "{err}");
    }

    #[test]
    fn all_outputs_constant_is_an_error() {
        let y = DMatrix::from_element(10, 2, 4.0);
        let err = preprocess(
            &[Experiment::time_series(y)],
            &PreprocessSettings::default(),
        )
        .unwrap_err();
        assert_eq!(err, IdentError::AllOutputsConstant { outputs: 2 });
    }
}
