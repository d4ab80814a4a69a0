//! The one error type of the crate.

use std::fmt;

/// Which kind of signal a column belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// An input u (a column of [`Experiment::inputs`](crate::Experiment::inputs)).
    Input,
    /// An output y (a column of [`Experiment::outputs`](crate::Experiment::outputs)).
    Output,
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Input => "input",
            Self::Output => "output",
        })
    }
}

/// Why identification, validation or a model evaluation was refused.
///
/// Every variant names what was wrong and where (experiment, column, row) and, where it
/// helps, what would be accepted. Nothing in this crate panics on data: bad data is one
/// of these.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IdentError {
    /// No experiment was given.
    #[error("no experiment given: identification needs at least one recording")]
    NoExperiment,
    /// An experiment's input and output matrices have different numbers of rows (samples).
    #[error(
        "experiment {experiment}: inputs have {input_rows} rows and outputs {output_rows}; \
         each row is one sample of both"
    )]
    RowMismatch {
        /// Index of the experiment.
        experiment: usize,
        /// Rows of the input matrix.
        input_rows: usize,
        /// Rows of the output matrix.
        output_rows: usize,
    },
    /// An experiment has a different number of input or output columns than the first.
    #[error("experiment {experiment}: {signal}s have {got} columns, experiment 0 has {expected}")]
    ColumnMismatch {
        /// Index of the experiment.
        experiment: usize,
        /// Inputs or outputs.
        signal: Signal,
        /// Columns of this experiment.
        got: usize,
        /// Columns of experiment 0.
        expected: usize,
    },
    /// There is no output column (p = 0).
    #[error("no output column: identification needs at least one output signal")]
    NoOutput,
    /// A sample is NaN or infinite.
    #[error(
        "experiment {experiment}: {signal} column {column}, row {row} is {value}; \
         identification needs finite samples"
    )]
    NonFinite {
        /// Index of the experiment.
        experiment: usize,
        /// Inputs or outputs.
        signal: Signal,
        /// Column of the signal.
        column: usize,
        /// Row (sample index within the experiment).
        row: usize,
        /// The offending value.
        value: f64,
    },
    /// Every output column is constant: there is nothing to identify.
    #[error("all {outputs} output columns are constant (see the warnings); nothing to identify")]
    AllOutputsConstant {
        /// Number of output columns.
        outputs: usize,
    },
    /// A setting is out of its range.
    #[error("setting `{name}`: {why}")]
    InvalidSetting {
        /// The setting's field name.
        name: &'static str,
        /// What is accepted.
        why: String,
    },
    /// An experiment is too short for the horizon: it yields no Hankel column.
    #[error(
        "experiment {experiment} has {samples} samples{part}; horizon {horizon} needs at least \
         {needed} (2·horizon) per experiment"
    )]
    ExperimentTooShort {
        /// Index of the experiment.
        experiment: usize,
        /// Samples available in it (in the part used).
        samples: usize,
        /// Which part was used (empty, or " in its estimation part").
        part: &'static str,
        /// The past/future horizon i.
        horizon: usize,
        /// Minimum samples.
        needed: usize,
    },
    /// Fewer Hankel columns than Hankel rows: the LQ factor would be rank deficient.
    #[error(
        "{columns} Hankel columns for {rows} Hankel rows (horizon {horizon}, {inputs} inputs, \
         {outputs} outputs): give more samples or a shorter horizon"
    )]
    TooFewSamples {
        /// Hankel columns over all experiments (Σ N_e − 2i + 1).
        columns: usize,
        /// Hankel rows 2i(l + p).
        rows: usize,
        /// The past/future horizon i.
        horizon: usize,
        /// Inputs l used.
        inputs: usize,
        /// Outputs p used.
        outputs: usize,
    },
    /// The requested order is 0 or above what the data and horizon support.
    #[error(
        "order {order} is not identifiable: the numerical rank of the weighted projection is \
         {rank} and the horizon allows at most {horizon_limit} ((i − 1)·p); order must be in 1..={max}"
    )]
    OrderAboveRank {
        /// Requested order.
        order: usize,
        /// Numerical rank of the SVD'd block.
        rank: usize,
        /// (i − 1)·p: shift invariance needs Γ_{i−1} of full column rank.
        horizon_limit: usize,
        /// The largest acceptable order.
        max: usize,
    },
    /// A covariance that must be positive definite is not.
    #[error("{what} is not positive definite: the noise model is degenerate")]
    NotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
    },
    /// The Riccati difference equation did not converge.
    #[error(
        "Riccati iteration did not converge in {iterations} iterations (last relative change \
         {change:.3e}); the identified (A, C) may not be detectable"
    )]
    RiccatiNotConverged {
        /// Iterations performed.
        iterations: usize,
        /// Last relative change ‖P_{k+1} − P_k‖ / (1 + ‖P_k‖).
        change: f64,
    },
    /// Data handed to a model does not have the model's dimensions.
    #[error("{signal}s have {got} columns, the model has {expected}")]
    DimensionMismatch {
        /// Inputs or outputs.
        signal: Signal,
        /// Columns given.
        got: usize,
        /// Columns the model expects.
        expected: usize,
    },
    /// A column's spread overflows f64 or its square does (values beyond about ±1e154):
    /// it cannot be scaled, nor its covariances written.
    #[error(
        "{signal} column {column}: its values are too large to scale (the square of its \
         standard deviation overflows); rescale the recording"
    )]
    Overflow {
        /// Inputs or outputs.
        signal: Signal,
        /// Column of the signal.
        column: usize,
    },
    /// Two kept columns carry the same signal (correlation ±1 after scaling): the same
    /// column named twice, or a copy of it.
    #[error(
        "{signal} columns {first} and {second} are the same signal (correlation ±1 after \
         removing the operating point and scale): no model can tell them apart; leave one out"
    )]
    DuplicateColumns {
        /// Inputs or outputs.
        signal: Signal,
        /// The first column (caller's index).
        first: usize,
        /// The column that repeats it.
        second: usize,
    },
    /// An SVD did not converge (only on pathological, near-overflowing data).
    #[error("the SVD of {what} did not converge")]
    SvdNotConverged {
        /// Which matrix.
        what: &'static str,
    },
    /// The noise covariances' least-squares design matrix is rank deficient: the chosen
    /// noise structure has more free parameters than the innovation autocovariances
    /// determine.
    #[error(
        "noise covariances not identifiable from the output autocovariances: the design \
         matrix has rank {rank} for {parameters} free parameters; parameters in the undetermined \
         combinations: {undetermined:?}; {hint}"
    )]
    NotIdentifiable {
        /// Numerical rank of the (column-normalised) design matrix.
        rank: usize,
        /// Number of free parameters.
        parameters: usize,
        /// Names of the parameters with a share in the null space (`Q[i,j]`, `R[i,j]`,
        /// `S[i,j]`, or `Q_w`, `S_w` with a noise input matrix).
        undetermined: Vec<String>,
        /// What would make the problem identifiable.
        hint: String,
    },
    /// No candidate order gave a usable model.
    #[error("no order in 1..={max_order} gave a usable model: {why}")]
    NoUsableOrder {
        /// Largest order tried.
        max_order: usize,
        /// The last candidate's failure.
        why: String,
    },
}
