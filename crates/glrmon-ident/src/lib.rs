#![doc = include_str!("../README.md")]
#![warn(missing_docs)]

pub mod data;
pub mod error;
pub mod feedback;
pub mod identify;
pub mod model;
pub mod noise;
pub mod pbsid;
pub mod subspace;
pub mod validation;

pub use data::{
    Detrend, Experiment, OperatingPoint, PreprocessSettings, Preprocessed, Scaling, Warning,
    WarningKind, preprocess,
};
pub use error::{IdentError, Signal};
pub use feedback::{DEFAULT_FEEDBACK_LAGS, DEFAULT_FEEDBACK_LEVEL, FeedbackTest, feedback_test};
pub use identify::{
    Candidate, Criterion, Holdout, IdentSettings, Identification, Method, MethodChoice,
    OrderSelection, ValidationReport, WorkEstimate, estimate_work, fmt_p, identify, to_physical,
    validate,
};
pub use model::{
    InnovationModel, Prediction, RiccatiSolution, solve_riccati, sorted_eigenvalues,
    spectral_radius,
};
pub use noise::{
    AlsIteration, CrossCovariance, InitialGuess, NoiseEstimate, NoiseSettings, NoiseStructure,
    PhysicalModel, Structure, estimate_noise,
};
pub use pbsid::Pbsid;
pub use subspace::Subspace;
pub use validation::{LjungBox, ljung_box, nis_mean, nrmse};
