#![doc = include_str!("../README.md")]
#![warn(missing_docs)]

// By concept: the plant's model and faults; the filters that whiten it; the detectors
// (a residual and its decision statistic) with the GLR's window bank; thresholds and
// their calibration; isolation (minmax tests, isolability, Fisher information); sparse
// diagnosis (residual filters and Lasso); alarm episodes.
pub mod alarm;
pub mod detector;
pub mod error;
pub mod filter;
pub mod isolation;
mod linalg;
pub mod model;
mod simd;
pub mod sparse;
pub mod threshold;
mod window;

pub use alarm::{AlarmSettings, AlarmState, AlarmTransition, EpisodeEnd};
pub use detector::{
    ArxForm, Candidate, CandidateFn, Chi2Detector, CusumDetector, DEFAULT_STEADY_TOLERANCE,
    Detector, FdfDetector, FdfGains, GlrDetector, KernelDetector, KernelModel, KernelSettings,
    KernelVerdict, ResidualIsolation, RlsDetector, RlsSettings, Sample, StepOutput, UioDesign,
    UioDetector, WindowSettings,
};
pub use error::{ModelError, StepError};
pub use filter::innovation::InnovationFilter;
pub use isolation::{FisherStatistics, TestStatistic};
pub use model::continuous::{ContinuousError, Discretisation};
pub use model::fault::{Column, ColumnFn, Fault, FaultDictionary, Onset};
pub use model::scaling::SignalScaling;
pub use model::{Dims, Lpv, LpvMatrix, Signals, StateSpace, SystemMatrices};
pub use simd::{VectorLevel, fused_multiply_add};
pub use window::DEFAULT_RANK_TOLERANCE;
pub use window::FollowedEvidence;
