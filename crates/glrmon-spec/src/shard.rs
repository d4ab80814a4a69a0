//! Shards: how a fleet of daemons started from one configuration splits its channels.

use std::fmt;

use crate::Config;

/// A shard of the channels of a configuration: the channels whose name hashes to
/// `index` modulo `count` (FNV-1a, 64 bits, over the name's UTF-8 bytes: the same on
/// every machine and in every release, so a fleet started from one configuration
/// splits it the same way every time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// i, from 0.
    pub index: u32,
    /// N, at least 1.
    pub count: u32,
}

impl Shard {
    /// Whether the channel named `name` belongs to this shard.
    #[must_use]
    pub fn owns(&self, name: &str) -> bool {
        shard_hash(name) % u64::from(self.count) == u64::from(self.index)
    }
}

/// FNV-1a (64 bits) of the name: the stable hash that assigns channels to shards.
#[must_use]
pub fn shard_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `"i/N"` with 0 ≤ i < N.
    fn from_str(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("\"{s}\" is not of the form i/N (e.g. 0/2)"))?;
        let index: u32 = i
            .trim()
            .parse()
            .map_err(|_| format!("\"{s}\": shard index \"{i}\" is not a whole number"))?;
        let count: u32 = n
            .trim()
            .parse()
            .map_err(|_| format!("\"{s}\": shard count \"{n}\" is not a whole number"))?;
        if count == 0 || index >= count {
            return Err(format!(
                "\"{s}\": the index must be below the count (shards 0/{count} … {}/{count})",
                count.saturating_sub(1)
            ));
        }
        Ok(Self { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// How an instance picks its channels among a fleet's: a static shard `i/N`, or `auto`.
///
/// `auto`: the instances find each other on Zenoh (their liveliness tokens) and each
/// channel is monitored by the live instance of highest rendezvous score
/// ([`crate::rendezvous_owner`]), which every instance computes alike from the same
/// live set: when an instance leaves, only its channels move, each to its next
/// instance; when one joins, it takes about 1/(N+1) of the channels, from all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardMode {
    /// The channels of a fixed shard (`i/N`).
    Static(Shard),
    /// Channels assigned among the live instances, moving as instances come and go.
    Auto,
}

impl ShardMode {
    /// The static shard, if this is one.
    #[must_use]
    pub fn fixed(self) -> Option<Shard> {
        match self {
            Self::Static(s) => Some(s),
            Self::Auto => None,
        }
    }
}

impl std::str::FromStr for ShardMode {
    type Err = String;

    /// `"auto"`, or a static shard `"i/N"`.
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim() == "auto" {
            return Ok(Self::Auto);
        }
        s.parse::<Shard>()
            .map(Self::Static)
            .map_err(|e| format!("{e}; or \"auto\" (channels assigned among the live instances)"))
    }
}

impl fmt::Display for ShardMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Static(s) => s.fmt(f),
            Self::Auto => f.write_str("auto"),
        }
    }
}

impl Config {
    /// The channels of `shard` only (all when `None`), the others dropped.
    #[must_use]
    pub fn into_shard(mut self, shard: Option<Shard>) -> Self {
        if let Some(s) = shard {
            self.channels.retain(|c| s.owns(&c.name));
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shard_mode_is_auto_or_static() {
        assert_eq!("auto".parse::<ShardMode>(), Ok(ShardMode::Auto));
        assert_eq!(
            "1/3".parse::<ShardMode>(),
            Ok(ShardMode::Static(Shard { index: 1, count: 3 }))
        );
        let e = "automatic".parse::<ShardMode>().unwrap_err();
        assert!(e.contains("i/N") && e.contains("\"auto\""), "{e}");
        assert_eq!(ShardMode::Auto.to_string(), "auto");
        assert_eq!(ShardMode::Auto.fixed(), None);
    }

    #[test]
    fn shards_partition_the_channels_and_parse_strictly() {
        let names: Vec<String> = (0..1000).map(|i| format!("pump{i:03}")).collect();
        for count in [1_u32, 2, 3, 7] {
            let shards: Vec<Shard> = (0..count).map(|index| Shard { index, count }).collect();
            let mut sizes = vec![0usize; count as usize];
            for n in &names {
                let owners: Vec<&Shard> = shards.iter().filter(|s| s.owns(n)).collect();
                assert_eq!(owners.len(), 1, "{n} in {count} shards");
                sizes[owners[0].index as usize] += 1;
            }
            // A fair split: every shard within 25 % of 1000/N.
            let fair = 1000.0 / f64::from(count);
            assert!(
                sizes
                    .iter()
                    .all(|s| (*s as f64 - fair).abs() <= 0.25 * fair),
                "{sizes:?}"
            );
        }
        // Fixed values: the assignment must never change between releases.
        assert_eq!(shard_hash(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(shard_hash("a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!("1/2".parse::<Shard>(), Ok(Shard { index: 1, count: 2 }));
        for bad in ["2/2", "1", "x/2", "0/0", "-1/2"] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains(bad), "{e}");
        }
    }
}
