//! The fixture the configuration error tests share (errors.rs, hostile.rs,
//! locations.rs): a valid channel, and one line of it replaced.

/// A valid two-state channel; tests replace one line of it. Its line 1 is empty (the
/// one of the opening quote), `[[channels]]` is line 2.
pub(crate) const BASE: &str = r#"
[[channels]]
name = "pump3"

[channels.model]
F = [[0.5, 1.0], [0.0, 0.8]]
G = [[0.0], [1.0]]
H = [[1.0, 0.0]]
Q = 0.01
R = 0.04

[[channels.faults]]
name = "bias"
kind = "actuator_bias"
input = 0

[[channels.faults]]
name = "custom"
psi = ["0.5*u0", 1.0]

[channels.glr]
window = 50
min_lag = 1
"#;

/// BASE with its first `replace` replaced by `by` (the fixture must contain it).
pub(crate) fn with(replace: &str, by: &str) -> String {
    assert!(BASE.contains(replace), "fixture lacks {replace}");
    BASE.replacen(replace, by, 1)
}
