//! The filters that turn a channel's samples into white residuals under no fault: the
//! Kalman innovation filter (with correlated noises S), its decoupling from an unknown
//! input E (the Kitanidis gain, Zhang 2021 §III-B), and the consistency test of the
//! normalized innovation against its χ² law.

pub mod consistency;
pub mod decoupling;
pub mod innovation;
