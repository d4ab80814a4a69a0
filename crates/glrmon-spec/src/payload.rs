//! How a channel's payloads are encoded (`[[channels]] payload`).
//!
//! A new format is one variant here with its name, and one arm of the runtime's
//! decoder factory (`glrmon_runtime::decoder`).

/// The encoding of the payloads a channel receives on its key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PayloadFormat {
    /// A JSON sample object or an array of them (docs/WIRE.md).
    #[default]
    Json,
}

impl PayloadFormat {
    /// Every format, in declaration order (a format's index is its discriminant).
    pub const ALL: [Self; 1] = [Self::Json];

    /// The names the configuration accepts, as [`PayloadFormat::ALL`].
    pub const NAMES: [&'static str; 1] = ["json"];

    /// The configuration's name of the format.
    #[must_use]
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The format named `name` in a configuration.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_format_round_trips_through_its_name() {
        assert_eq!(PayloadFormat::ALL.len(), PayloadFormat::NAMES.len());
        for (format, name) in PayloadFormat::ALL.into_iter().zip(PayloadFormat::NAMES) {
            assert_eq!(PayloadFormat::from_name(name), Some(format));
        }
        let cfg = crate::parse(
            r#"
[[channels]]
name = "tank"
payload = "cbor"
model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }
faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]
"#,
        );
        let err = cfg.unwrap_err().to_string();
        assert!(
            err.contains("payload") && err.contains("\"cbor\" is not one of json"),
            "{err}"
        );
    }
}
