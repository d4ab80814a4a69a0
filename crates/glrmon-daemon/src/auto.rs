//! The automatic shard (`daemon.shard = "auto"`): every instance started from one
//! configuration runs a pipeline for each channel, and monitors those that the live
//! instances' rendezvous assignment gives it ([`glrmon_spec::rendezvous_owner`]).
//!
//! ```text
//!  instance tokens ─Membership─▶ views ─▶ assignment task: each channel's owner in the view
//!  (glrmon/@instances/*)                   ├─ gained: ChannelSwitch::take (the monitor resumes),
//!                                          │          ZenohSource::open (the publishers' cached
//!                                          │          samples, then the live ones), owner token
//!                                          └─ lost:   ZenohSource::close, ChannelSwitch::release,
//!                                                     owner token withdrawn
//! ```
//!
//! A channel taken over gets twice its settling in recent samples from the publishers'
//! caches (zenoh-ext advanced publishers with a cache): it settles on them and its window
//! is full when the live samples come, so a fault going on is alarmed at once. Without a
//! cache it settles on the live samples, with alarms held off for its settling.
//!
//! Every instance computes the same owner from the same live set, so no instance asks
//! another: a takeover takes as long as the lost instance's token takes to disappear
//! (at once for a crash, which closes its connections; the Zenoh lease for a frozen
//! process or a lost machine). Two instances monitor one channel only while their views
//! differ: for the time a token takes to reach both (milliseconds on a LAN), or, on a
//! clean shutdown, until the leaving instance sees the channel claimed elsewhere.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glrmon_runtime::ChannelSwitch;
use glrmon_wire::Assignment;
use glrmon_zenoh::{Claims, Membership, ZenohError, ZenohSource};

/// How long a starting instance waits for the live instances to answer before its
/// first assignment (the query ends as soon as every reachable node has answered).
pub(crate) const VIEW_WAIT: Duration = Duration::from_secs(2);

/// The automatic shard of a running instance: dropping it stops following the fleet
/// (the channels stay as they are).
pub(crate) struct AutoShard {
    _membership: Membership,
    task: tokio::task::JoinHandle<()>,
    /// The latest view (live instances, sorted), for the hand-over.
    view: Arc<Mutex<Vec<String>>>,
    pub(crate) assignment: Arc<Mutex<Assignment>>,
    instance: String,
    channels: Vec<String>,
}

/// What the assignment task needs.
struct Assigner {
    instance: Arc<str>,
    channels: Vec<String>,
    switch: ChannelSwitch,
    source: Arc<ZenohSource>,
    claims: Claims,
    generation: Arc<AtomicU64>,
    assignment: Arc<Mutex<Assignment>>,
}

impl AutoShard {
    /// Follows the live instances on `session` and applies each view: the channels the
    /// view gives `instance` are taken (their monitors resume), the others released.
    /// All of `channels` must be idle in `switch` at the start.
    pub(crate) async fn start(
        session: &zenoh::Session,
        instance: &str,
        channels: Vec<String>,
        switch: ChannelSwitch,
        source: Arc<ZenohSource>,
        generation: Arc<AtomicU64>,
        assignment: Arc<Mutex<Assignment>>,
    ) -> Result<Self, ZenohError> {
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<Vec<String>>();
        let view = Arc::new(Mutex::new(vec![instance.to_owned()]));
        let latest = Arc::clone(&view);
        let membership = Membership::watch(session, Some(instance), VIEW_WAIT, move |live| {
            *latest
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = live.to_vec();
            let _ = tx.send(live.to_vec());
        })
        .await?;
        let mut assigner = Assigner {
            instance: Arc::from(instance),
            channels: channels.clone(),
            switch,
            source,
            claims: Claims::new(session, instance),
            generation,
            assignment: Arc::clone(&assignment),
        };
        // The first view is applied before start returns, so that a started instance
        // monitors its share.
        if let Some(first) = rx.recv().await {
            assigner.apply(&first).await;
        }
        let task = tokio::spawn(async move {
            while let Some(mut live) = rx.recv().await {
                // Views that queued up meanwhile: only the latest matters.
                while let Ok(next) = rx.try_recv() {
                    live = next;
                }
                assigner.apply(&live).await;
            }
        });
        Ok(Self {
            _membership: membership,
            task,
            view,
            assignment,
            instance: instance.to_owned(),
            channels,
        })
    }

    /// Whether another live instance is in the latest view (someone to hand over to).
    pub(crate) fn others_alive(&self) -> bool {
        self.view
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .any(|i| *i != self.instance)
    }

    /// The channels this instance monitors now.
    pub(crate) fn monitored(&self, switch: &ChannelSwitch) -> Vec<String> {
        (0..self.channels.len())
            .filter(|i| switch.is_monitored(*i))
            .map(|i| self.channels[i].clone())
            .collect()
    }

    /// Stops following the fleet and withdraws the claims (the channels stay as they
    /// are in the runtime).
    pub(crate) fn stop(self) {
        self.task.abort();
    }
}

impl Assigner {
    /// Applies one view of the live instances.
    async fn apply(&mut self, live: &[String]) {
        let generation = self.generation.fetch_add(1, Ordering::AcqRel) + 1;
        let first = generation == 1;
        let started = Instant::now();
        let (mut taken, mut released) = (Vec::new(), Vec::new());
        for (index, channel) in self.channels.iter().enumerate() {
            let mine = glrmon_spec::rendezvous_owner(channel, live) == Some(&*self.instance);
            if mine && self.switch.take(index, &self.instance, generation) {
                // The monitor resumes first: the history and the live samples that
                // the subscription brings come after it.
                if let Err(e) = self.source.open(index).await {
                    tracing::error!(channel, error = %e, "Could not subscribe to the channel's keys: it is not monitored.");
                }
                if let Err(e) = self.claims.claim(channel).await {
                    tracing::error!(channel, error = %e, "Could not declare the channel's owner token; it is monitored all the same.");
                }
                taken.push(channel.as_str());
            } else if !mine && self.switch.release(index) {
                self.source.close(index);
                self.claims.release(channel);
                released.push(channel.as_str());
            }
        }
        let monitored = (0..self.channels.len())
            .filter(|i| self.switch.is_monitored(*i))
            .count();
        {
            let mut a = self
                .assignment
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            a.generation = generation;
            a.instances = live.to_vec();
            if !first {
                a.takeovers += taken.len() as u64;
            }
            a.handovers += released.len() as u64;
        }
        tracing::info!(
            generation,
            instances = %live.join(", "),
            monitored,
            of = self.channels.len(),
            taken = taken.len(),
            released = released.len(),
            elapsed_ms = started.elapsed().as_secs_f64() * 1e3,
            "{}",
            if first {
                "Automatic shard: first assignment."
            } else {
                "Automatic shard: the live instances changed; channels moved."
            }
        );
        if !taken.is_empty() && !first {
            tracing::info!(generation, channels = %taken.join(", "), "Took channels over; each settles before it alarms.");
        }
        if !released.is_empty() {
            tracing::info!(generation, channels = %released.join(", "), "Handed channels over.");
        }
    }
}
