#![doc = include_str!("../README.md")]
#![warn(missing_docs)]

pub mod alarm;
pub mod calibration;
pub mod consistency;
pub mod decoupling;
pub mod detector;
pub mod error;
pub mod fault;
mod glr;
pub mod information;
pub mod innovation;
pub mod isolability;
pub mod isolation;
pub mod kitanidis;
mod linalg;
mod simd;
pub use simd::{VectorLevel, fused_multiply_add};
pub mod model;
pub mod scaling;
pub mod sparse;
pub mod threshold;

pub use alarm::{AlarmSettings, AlarmState, AlarmTransition};
pub use detector::{
    Chi2Detector, DEFAULT_STEADY_TOLERANCE, Detector, GlrDetector, Sample, StepOutput,
    WindowSettings,
};
pub use error::{ModelError, StepError};
pub use fault::{Column, ColumnFn, Fault, FaultDictionary, Onset};
pub use glr::DEFAULT_RANK_TOLERANCE;
pub use innovation::InnovationFilter;
pub use isolation::{FisherStatistics, TestStatistic};
pub use model::{Dims, Lpv, LpvMatrix, Signals, StateSpace, SystemMatrices};
pub use scaling::SignalScaling;
