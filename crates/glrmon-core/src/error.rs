//! Errors of the numerical core: building a detector, and stepping it.

/// A model or fault dictionary that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A matrix or column has the wrong shape.
    #[error("{what}: {detail}")]
    Dimension {
        /// The matrix or column concerned (e.g. `"H"`, `"fault column"`).
        what: &'static str,
        /// What disagrees with what.
        detail: String,
    },
    /// A matrix holds NaN or ±∞.
    #[error("{what} holds a non-finite value (NaN or infinity)")]
    NonFinite {
        /// The matrix concerned.
        what: &'static str,
    },
    /// A detector setting is out of range.
    #[error("{what}: {detail}")]
    Setting {
        /// The setting concerned (e.g. `"window"`).
        what: &'static str,
        /// Why it is rejected.
        detail: String,
    },
}

/// A sample that the detector refused. The detector's state is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StepError {
    /// A vector of the sample has the wrong length.
    #[error("field {field} has {got} values, model expects {expected}")]
    WrongDimension {
        /// `"u"`, `"y"` or `"p"`.
        field: &'static str,
        /// Length the model expects.
        expected: usize,
        /// Length received.
        got: usize,
    },
    /// A value of the sample is NaN or ±∞.
    #[error("field {field}[{index}] is not finite")]
    NonFinite {
        /// `"u"`, `"y"` or `"p"`.
        field: &'static str,
        /// Index within the vector.
        index: usize,
    },
    /// The sample index is not the next one expected.
    #[error("sample index {got} is not the next expected index {expected}")]
    OutOfOrder {
        /// The index the detector expects next.
        expected: u64,
        /// The index received.
        got: u64,
    },
    /// The filter cannot proceed (e.g. an innovation covariance that is not positive
    /// definite after evaluating the model at this sample's signals).
    #[error("numerical failure: {what}")]
    Numerical {
        /// What failed.
        what: &'static str,
    },
}
