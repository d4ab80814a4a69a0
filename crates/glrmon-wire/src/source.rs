//! Who published a result: the Zenoh attachment of every record an instance publishes
//! on `glrmon/<channel>/<type>` (`{"instance":"a","generation":3}`), so that a reader
//! can tell a live instance's records from anyone else's and see which assignment
//! produced them.

use serde::{Deserialize, Serialize};

/// The instance that produced a record and its assignment generation then (0 for an
/// instance of a static shard or none, whose assignment never changes).
///
/// # Examples
///
/// ```
/// use glrmon_wire::Source;
///
/// let s = Source { instance: "plant-a".into(), generation: 3 };
/// let bytes = s.encode();
/// assert_eq!(bytes, br#"{"instance":"plant-a","generation":3}"#);
/// assert_eq!(Source::decode(&bytes).unwrap(), s);
/// assert!(Source::decode(br#"{"instance":"a"}"#).is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// The instance's name.
    pub instance: String,
    /// Its assignment generation when it published the record.
    pub generation: u64,
}

impl Source {
    /// The attachment's JSON.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        // A struct of a string and an integer always serialises.
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// Reads an attachment strictly (both fields, nothing else).
    ///
    /// # Errors
    /// serde_json's error naming what is wrong.
    pub fn decode(bytes: &[u8]) -> Result<Self, serde_json::Error> {
        serde_json::from_slice(bytes)
    }
}
