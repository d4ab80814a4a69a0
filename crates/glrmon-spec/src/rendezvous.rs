//! Channels assigned to a changing set of live instances by rendezvous (highest random
//! weight) hashing (Thaler & Ravishankar, 1998): every instance scores each channel as
//! w(c, i) = h(c, i) and the channel goes to the live instance of highest score, the
//! next ones in score order being its stand-ins. Every instance that sees the same live
//! set computes the same owner for every channel without talking to the others, and a
//! change of the set moves only the channels that must move: an instance that leaves
//! gives each of its channels to that channel's next instance, one that joins takes
//! only the channels it now scores highest (about 1/(N+1) of them), from whoever held
//! them.
//!
//! The score is a fixed 64-bit hash (FNV-1a over the channel's and the instance's
//! names, then the splitmix64 finaliser, which spreads FNV's poorly mixed high bits),
//! the same on every machine and in every release, as [`crate::shard_hash`] is.

/// The score w(c, i) of instance `instance` for channel `channel`.
#[must_use]
pub fn rendezvous_score(channel: &str, instance: &str) -> u64 {
    let fnv = |h: u64, bytes: &[u8]| {
        bytes.iter().fold(h, |h, b| {
            (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
    };
    // The 0xff byte, never in UTF-8, keeps ("ab", "c") and ("a", "bc") apart.
    let h = fnv(
        fnv(fnv(0xcbf2_9ce4_8422_2325, channel.as_bytes()), &[0xff]),
        instance.as_bytes(),
    );
    let mut z = h.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The instances of `live` in decreasing score for `channel` (ties, which need equal
/// 64-bit hashes, broken by name): the owner first, then its stand-ins in the order
/// they would take it over.
#[must_use]
pub fn rendezvous_order<'a>(channel: &str, live: &'a [String]) -> Vec<&'a str> {
    let mut ranked: Vec<(u64, &str)> = live
        .iter()
        .map(|i| (rendezvous_score(channel, i), i.as_str()))
        .collect();
    ranked.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(b.1)));
    ranked.dedup_by(|a, b| a.1 == b.1);
    ranked.into_iter().map(|(_, i)| i).collect()
}

/// The owner of `channel` among the live instances `live`: the one of highest score;
/// `None` when none is live.
#[must_use]
pub fn rendezvous_owner<'a>(channel: &str, live: &'a [String]) -> Option<&'a str> {
    live.iter()
        .map(|i| (rendezvous_score(channel, i), i.as_str()))
        .max_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(a.1)))
        .map(|(_, i)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(prefix: &str, n: usize) -> Vec<String> {
        (0..n).map(|i| format!("{prefix}{i}")).collect()
    }

    fn owners(channels: &[String], live: &[String]) -> Vec<String> {
        channels
            .iter()
            .map(|c| rendezvous_owner(c, live).unwrap().to_owned())
            .collect()
    }

    /// The owner is the first of the order; the split of 3 000 channels is fair: each of
    /// N instances holds 3000/N within 4 standard deviations of the binomial count.
    #[test]
    fn channels_are_split_fairly_and_the_owner_heads_the_order() {
        let channels = names("pump", 3000);
        for n in [1, 2, 3, 5, 8] {
            let live = names("glrmon-", n);
            let mut sizes = std::collections::HashMap::new();
            for c in &channels {
                let owner = rendezvous_owner(c, &live).unwrap();
                assert_eq!(rendezvous_order(c, &live)[0], owner);
                assert_eq!(rendezvous_order(c, &live).len(), n);
                *sizes.entry(owner).or_insert(0usize) += 1;
            }
            let (fair, p) = (3000.0 / n as f64, 1.0 / n as f64);
            let sigma = (3000.0 * p * (1.0 - p)).sqrt();
            assert_eq!(sizes.len(), n);
            assert!(
                sizes
                    .values()
                    .all(|s| (*s as f64 - fair).abs() <= 4.0 * sigma + 1e-9),
                "{n} instances: {sizes:?}"
            );
        }
        assert_eq!(rendezvous_owner("pump1", &[]), None);
    }

    /// A change of the live set moves only what must move: an instance that leaves
    /// hands each of its channels to the channel's second in order, and nothing else
    /// moves; one that joins takes about 1/(N+1) of the channels and only takes.
    #[test]
    fn a_change_of_the_live_set_moves_only_the_channels_that_must_move() {
        let channels = names("valve", 3000);
        let live = names("glrmon-", 4);
        let before = owners(&channels, &live);
        // glrmon-2 is lost.
        let after_loss: Vec<String> = live.iter().filter(|i| *i != "glrmon-2").cloned().collect();
        let after = owners(&channels, &after_loss);
        for ((c, b), a) in channels.iter().zip(&before).zip(&after) {
            if b == "glrmon-2" {
                assert_eq!(a, rendezvous_order(c, &live)[1], "{c}");
            } else {
                assert_eq!(a, b, "{c} moved although its owner lives");
            }
        }
        // glrmon-9 joins.
        let mut joined = live.clone();
        joined.push("glrmon-9".into());
        let after = owners(&channels, &joined);
        let moved = before.iter().zip(&after).filter(|(b, a)| b != a).count();
        assert!(
            after
                .iter()
                .zip(&before)
                .all(|(a, b)| a == b || a == "glrmon-9")
        );
        let (fair, sigma) = (3000.0 / 5.0, (3000.0_f64 * 0.2 * 0.8).sqrt());
        assert!((moved as f64 - fair).abs() <= 4.0 * sigma, "{moved} moved");
    }

    /// The assignment must never change between releases or machines: fixed values.
    #[test]
    fn scores_are_fixed() {
        assert_eq!(rendezvous_score("", ""), rendezvous_score("", ""));
        assert_ne!(rendezvous_score("ab", "c"), rendezvous_score("a", "bc"));
        // Computed by an independent implementation of the same definition (Python).
        assert_eq!(rendezvous_score("pump1", "glrmon-0"), 0x4e03_9e64_13ca_ef8c);
        let live = names("glrmon-", 3);
        assert_eq!(
            rendezvous_order("pump1", &live),
            ["glrmon-2", "glrmon-0", "glrmon-1"]
        );
    }
}
