//! The one reading of the channels' counters ([`ChannelStats`]) into the wire's
//! [`ChannelStatus`]: the status queryable, `glrmon status`, the Prometheus endpoint and
//! the demo's summary all show the same numbers, read the same way.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use glrmon_wire::ChannelStatus;

use crate::{ChannelStats, Runtime};

impl ChannelStats {
    /// The counters of the channel `name` now. Each counter is read once (relaxed): the
    /// workers keep counting meanwhile, so two counters may be a sample apart.
    #[must_use]
    pub fn status(&self, name: &str) -> ChannelStatus {
        let errors = self
            .errors
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .map(|(code, count)| ((*code).to_owned(), *count))
            .collect();
        ChannelStatus {
            channel: name.to_owned(),
            samples: self.samples.load(Ordering::Relaxed),
            alarms: self.alarms.load(Ordering::Relaxed),
            alarm_active: self.alarm_active.load(Ordering::Relaxed) != 0,
            dropped: self.dropped.load(Ordering::Relaxed),
            last_k: self.next_k.load(Ordering::Relaxed).checked_sub(1),
            errors,
        }
    }
}

/// The status of every channel monitored now (not [`ChannelStats::idle`]): `names[i]`
/// with the counters `stats[i]` (as
/// [`Runtime::channel_names`] and [`Runtime::stats`] give them, which stay readable
/// after the runtime has shut down).
#[must_use]
pub fn channel_statuses(names: &[String], stats: &[Arc<ChannelStats>]) -> Vec<ChannelStatus> {
    names
        .iter()
        .zip(stats)
        .filter(|(_, st)| !st.idle.load(Ordering::Relaxed))
        .map(|(name, st)| st.status(name))
        .collect()
}

impl Runtime {
    /// The status of every channel, in configuration order.
    #[must_use]
    pub fn channel_statuses(&self) -> Vec<ChannelStatus> {
        channel_statuses(&self.names, &self.stats)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    #[test]
    fn counters_become_the_channel_status() {
        let st = ChannelStats::default();
        let fresh = st.status("c1");
        assert_eq!(
            fresh,
            ChannelStatus {
                channel: "c1".into(),
                samples: 0,
                alarms: 0,
                alarm_active: false,
                dropped: 0,
                last_k: None,
                errors: BTreeMap::new(),
            }
        );
        st.samples.store(10, Ordering::Relaxed);
        st.alarms.store(2, Ordering::Relaxed);
        st.alarm_active.store(1, Ordering::Relaxed);
        st.dropped.store(3, Ordering::Relaxed);
        st.next_k.store(10, Ordering::Relaxed);
        st.errors.lock().unwrap().insert("non_finite", 4);
        let s = st.status("c1");
        assert_eq!(
            (s.samples, s.alarms, s.alarm_active, s.dropped, s.last_k),
            (10, 2, true, 3, Some(9))
        );
        assert_eq!(s.errors, BTreeMap::from([("non_finite".to_owned(), 4)]));
        let all = channel_statuses(
            &["a".into(), "b".into()],
            &[Arc::new(ChannelStats::default()), Arc::new(st)],
        );
        assert_eq!(
            all.iter().map(|c| c.channel.as_str()).collect::<Vec<_>>(),
            ["a", "b"]
        );
        assert_eq!(
            all[1],
            ChannelStatus {
                channel: "b".into(),
                ..s
            }
        );
    }
}
