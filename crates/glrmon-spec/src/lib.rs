//! glrmon's configuration: a strict TOML file describing a deployment (Zenoh and
//! recording settings, and a list of channels with their model, fault dictionary and
//! GLR settings), parsed and validated into core types.
//!
//! Every error names its path and the reason, e.g.
//! `channels[1] "pump3": model.F is 3×2 but H has 3 columns`; all errors of a file are
//! reported, not only the first.
//!
//! ```
//! let cfg = glrmon_spec::parse(r#"
//! [[channels]]
//! name = "tank"
//! model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
//! faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
//! "#).unwrap();
//! assert_eq!(cfg.channels[0].key, "plant/tank");
//! let detector = cfg.channels[0].detector().unwrap();
//! assert_eq!((detector.kind(), detector.faults().len()), ("glr", 1));
//! ```
#![warn(missing_docs)]

mod channel;
mod config;
pub mod covariance;
mod detector;
pub mod edit;
mod error;
pub mod expr;
mod json_schema;
pub mod keys;
pub mod limits;
mod load;
mod locate;
mod names;
mod payload;
pub mod reference;
mod rendezvous;
pub mod schema;
mod shard;
pub mod template;
mod validate;
pub mod write;

pub use crate::channel::{
    Channel, Columns, Controller, DEFAULT_DIAGNOSIS_ALPHA, DiagnosisSettings, KernelCandidate,
    KernelChannelSettings, ObserverSettings, ResidualKind, RlsChannelSettings, SimulationPlan,
    ThresholdSource,
};
pub use crate::config::{ChannelChoiceError, Config, RELOADABLE_GLR_KEYS};
pub use crate::covariance::PSD_TOLERANCE;
pub use crate::detector::DetectorKind;
pub use crate::error::{Location, Problem, SpecErrors};
pub use crate::json_schema::json_schema;
pub use crate::load::{load, parse};
pub use crate::locate::did_you_mean;
pub use crate::names::{MAX_INSTANCE_LEN, check_endpoint, validate_instance};
pub use crate::payload::{
    CdrMessage, Formation, PayloadFormat, RawField, RawLayout, Tag, TagTime, Tags,
};
pub use crate::rendezvous::{rendezvous_order, rendezvous_owner, rendezvous_score};
pub use crate::shard::{Shard, ShardMode, shard_hash};
