//! Errors of the numerical core: building a detector, stepping it, and the sparse
//! isolation with its residual generators (Zhang 2021).

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
    /// A design condition of a residual generator fails for this model (e.g. the
    /// unknown-input observer's matching condition rank(HE) = rank(E)): no such
    /// generator exists, or it would not be stable.
    #[error("{condition} fails: {detail}")]
    Condition {
        /// The condition, as the method's literature names it (e.g. `"the matching
        /// condition rank(HE) = rank(E)"`).
        condition: &'static str,
        /// What was found, and what would satisfy it.
        detail: String,
    },
}

/// A sample that the detector refused. The detector's state is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StepError {
    /// A vector of the sample has the wrong length. An empty one that the model needs
    /// reads "field u is missing or empty (the model has 1 input)": a payload without
    /// `u` decodes to an empty `u`.
    #[error("field {field} {}", wrong_dimension(field, *expected, *got))]
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
    /// The sample index is 2⁶⁴ − 1, which leaves no next index.
    #[error("sample index {k} is the largest 64-bit index: no sample could follow it")]
    IndexTooLarge {
        /// The index received.
        k: u64,
    },
    /// The filter cannot proceed (e.g. an innovation covariance that is not positive
    /// definite after evaluating the model at this sample's signals).
    #[error("numerical failure: {what}")]
    Numerical {
        /// What failed.
        what: &'static str,
    },
    /// Sample k is missing on a plant with an unknown input: d moves the state
    /// unobserved over the gap, so the filter cannot bridge it and must restart.
    #[error(
        "sample {k} is missing and the model has an unknown input: the state cannot be \
         predicted over the gap"
    )]
    UnknownInputGap {
        /// The missing sample.
        k: u64,
    },
    /// Sample k is missing and the detector cannot bridge a gap (e.g. the kernel
    /// method's images integrate every sample): it must restart.
    #[error("sample {k} is missing and cannot be bridged: {reason}")]
    GapNotBridged {
        /// The missing sample.
        k: u64,
        /// Why the kind cannot bridge it.
        reason: &'static str,
    },
}

/// The predicate of [`StepError::WrongDimension`].
fn wrong_dimension(field: &str, expected: usize, got: usize) -> String {
    if got == 0 && expected > 0 {
        let what = match field {
            "u" => "input",
            "y" => "output",
            _ => "signal",
        };
        let plural = if expected == 1 { "" } else { "s" };
        format!("is missing or empty (the model has {expected} {what}{plural})")
    } else {
        format!("has {got} values, model expects {expected}")
    }
}

/// Threshold of the Assumption (iv) check of Zhang 2021
/// ([`crate::sparse::residual::unknown_input_rank`], reported by
/// [`SparseError::UnknownInputRank`]): C_{k+1}E_k has full column rank when every
/// singular value of C_{k+1}Ê_k exceeds 1e-9·‖C_{k+1}‖_F, Ê_k being E_k with its
/// columns scaled to unit norm (the filter depends only on the range of E_k, and the
/// test then does not depend on the units of d_k or of the outputs as a whole).
pub const UNKNOWN_INPUT_RANK_TOLERANCE: f64 = 1e-9;

/// Errors of the sparse isolation ([`crate::sparse`]) and of its residual generators
/// ([`crate::sparse::residual`]). A failing call leaves the state of its receiver unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SparseError {
    /// A matrix or vector has the wrong shape.
    #[error("{what}: {detail}")]
    Dimension {
        /// The matrix or vector concerned (e.g. `"upsilon"`, `"E"`).
        what: &'static str,
        /// What disagrees with what.
        detail: String,
    },
    /// An input holds NaN or ±∞.
    #[error("{what} holds a non-finite value (NaN or infinity)")]
    NonFinite {
        /// The input concerned.
        what: &'static str,
    },
    /// A setting is out of range.
    #[error("{what}: {detail}")]
    Setting {
        /// The setting concerned (e.g. `"ratio"`).
        what: &'static str,
        /// Why it is rejected.
        detail: String,
    },
    /// Assumption (iv) of Zhang 2021 fails: C_{k+1}E_k does not have full column rank,
    /// so the Kitanidis filter cannot reject the unknown input (see
    /// [`crate::sparse::residual::unknown_input_rank`]).
    #[error(
        "Assumption (iv) of Zhang 2021 fails: C_{{k+1}}E_k ({outputs}×{unknown_inputs}) has \
         numerical rank {rank}, not full column rank {unknown_inputs} (smallest singular value \
         {ratio:.3e}·‖C_{{k+1}}‖_F with E_k's columns normalised, limit {limit:.0e}); the unknown \
         input cannot be decoupled from the residual: the outputs must see every unknown-input \
         direction independently, so at least as many independent output directions as \
         unknown-input columns are needed",
        limit = UNKNOWN_INPUT_RANK_TOLERANCE
    )]
    UnknownInputRank {
        /// p, the rows of C_{k+1}E_k.
        outputs: usize,
        /// s, the columns of C_{k+1}E_k (unknown-input directions; d_k ∈ ℝ^s).
        unknown_inputs: usize,
        /// The numerical rank found.
        rank: usize,
        /// σ_min(C_{k+1}Ê_k)/‖C_{k+1}‖_F, Ê_k being E_k with unit-norm columns (0 when
        /// s > p or a column of E_k is zero).
        ratio: f64,
    },
    /// A filter covariance lost positive definiteness, or a similar numerical failure.
    #[error("numerical failure: {what}")]
    Numerical {
        /// What failed.
        what: &'static str,
    },
    /// No sample has been accumulated.
    #[error("no samples accumulated: the regression is empty")]
    Empty,
    /// Xᵀy = 0: every Lasso solution is θ̂ = 0, there is no fault to isolate.
    #[error("Xᵀy = 0: the residuals carry no component along any fault signature")]
    NoSignal,
}

#[cfg(test)]
mod tests {
    use super::StepError;

    /// `{"y":[1,2]}` on a channel with an input lacks the field u: it is reported
    /// missing, not as "field u has 0 values".
    #[test]
    fn an_empty_field_is_reported_missing() {
        let missing = StepError::WrongDimension {
            field: "u",
            expected: 1,
            got: 0,
        };
        assert_eq!(
            missing.to_string(),
            "field u is missing or empty (the model has 1 input)"
        );
        let short = StepError::WrongDimension {
            field: "y",
            expected: 2,
            got: 1,
        };
        assert_eq!(short.to_string(), "field y has 1 values, model expects 2");
    }
}
