//! The fleet on Zenoh: which instances are alive and which one monitors each channel,
//! through liveliness tokens only (no consensus of glrmon's own).
//!
//! - `glrmon/@instances/<instance>`: one per running instance ([`crate::Presence`]);
//!   [`Membership`] follows them.
//! - `glrmon/@owners/<channel>/<instance>`: one per channel an instance monitors, held
//!   for the whole run by a static shard ([`Ownership`]) or as the automatic shard's
//!   assignment moves ([`Claims`]).
//!
//! A token disappears when its instance undeclares it, closes its session, or is cut
//! off from the network for longer than the Zenoh lease (a crash closes the TCP
//! connection at once; a frozen process or a lost machine takes the lease).

use std::collections::{BTreeSet, HashMap};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use zenoh::Session;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Subscriber;
use zenoh::sample::SampleKind;

use crate::{ZenohError, liveliness_key, session_err};

/// The prefix of the instances' liveliness tokens.
const INSTANCES: &str = "glrmon/@instances/";

/// Key of the token by which `instance` claims `channel`.
#[must_use]
pub fn owner_key(channel: &str, instance: &str) -> String {
    format!("glrmon/@owners/{channel}/{instance}")
}

/// The channels an instance claims: one liveliness token per channel, and a watch that
/// reports any other instance claiming one of them later.
#[derive(Debug)]
pub struct Ownership {
    _tokens: Vec<LivelinessToken>,
    _watch: Subscriber<()>,
}

impl Ownership {
    /// Refuses, with a message naming the channel and the other instance, when a live
    /// instance already has this instance's name or claims one of `channels`; otherwise
    /// claims them. Then calls `on_overlap(channel, other_instance)` whenever another
    /// instance claims one of them (two instances started at the same moment: both are
    /// told, and so is the operator through the status). `wait` bounds the query for
    /// existing claims (it ends as soon as every reachable node has answered).
    ///
    /// # Errors
    /// [`ZenohError::Overlap`] as above; [`ZenohError::Session`] when a query or
    /// declaration fails.
    pub async fn claim(
        session: &Session,
        instance: &str,
        channels: &[String],
        wait: Duration,
        on_overlap: impl Fn(&str, &str) + Send + Sync + 'static,
    ) -> Result<Self, ZenohError> {
        let replies = session
            .liveliness()
            .get(liveliness_key(instance))
            .timeout(wait)
            .await
            .map_err(session_err("liveliness query"))?;
        if let Ok(reply) = replies.recv_async().await
            && reply.result().is_ok()
        {
            return Err(ZenohError::Overlap(format!(
                "an instance named \"{instance}\" is already running (liveliness token {}): give each instance its own name (--instance or daemon.instance)",
                liveliness_key(instance)
            )));
        }
        let mut clashes: Vec<String> = owners_elsewhere(session, instance, wait)
            .await?
            .into_iter()
            .filter(|(channel, _)| channels.contains(channel))
            .map(|(channel, other)| format!("\"{channel}\" (instance \"{other}\")"))
            .collect();
        if !clashes.is_empty() {
            clashes.sort();
            return Err(ZenohError::Overlap(format!(
                "{} channel(s) of this instance are already monitored elsewhere: {}; give each instance a disjoint set of channels (daemon.shard = \"i/N\" or --shard)",
                clashes.len(),
                clashes.join(", ")
            )));
        }
        let mut tokens = Vec::with_capacity(channels.len());
        for c in channels {
            tokens.push(
                session
                    .liveliness()
                    .declare_token(owner_key(c, instance))
                    .await
                    .map_err(session_err("declare liveliness token"))?,
            );
        }
        let mine: Vec<String> = channels.to_vec();
        let me = instance.to_owned();
        let watch = session
            .liveliness()
            .declare_subscriber("glrmon/@owners/**")
            .history(true)
            .callback(move |sample| {
                if sample.kind() != SampleKind::Put {
                    return;
                }
                if let Some((channel, other)) = parse_owner(sample.key_expr().as_str())
                    && other != me
                    && mine.iter().any(|c| c == channel)
                {
                    on_overlap(channel, other);
                }
            })
            .await
            .map_err(session_err("declare liveliness subscriber"))?;
        Ok(Self {
            _tokens: tokens,
            _watch: watch,
        })
    }
}

/// (channel, instance) of every owner token alive now of an instance other than
/// `instance`, as the nodes that answer within `wait` tell.
async fn owners_elsewhere(
    session: &Session,
    instance: &str,
    wait: Duration,
) -> Result<Vec<(String, String)>, ZenohError> {
    let replies = session
        .liveliness()
        .get("glrmon/@owners/**")
        .timeout(wait)
        .await
        .map_err(session_err("liveliness query"))?;
    let mut owners = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result()
            && let Some((channel, other)) = parse_owner(sample.key_expr().as_str())
            && other != instance
        {
            owners.push((channel.to_owned(), other.to_owned()));
        }
    }
    Ok(owners)
}

/// (channel, instance) of an owner token's key.
fn parse_owner(key: &str) -> Option<(&str, &str)> {
    let rest = key.strip_prefix("glrmon/@owners/")?;
    rest.rsplit_once('/')
}

/// The live instances, as their liveliness tokens say; dropping it stops following
/// them.
#[derive(Debug)]
pub struct Membership {
    _watch: Subscriber<()>,
}

/// The live set and whether the first view was reported.
type View = (BTreeSet<String>, bool);

impl Membership {
    /// Follows the instances' tokens: `on_change` gets the live set (sorted, `me`, if
    /// given, always in it) once the instances that answer within `wait` are known, then at
    /// every token that appears or disappears. It runs on Zenoh's thread under a lock
    /// (views arrive in order): it must return quickly, e.g. by sending the view on.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when the subscriber or the query cannot be declared.
    pub async fn watch(
        session: &Session,
        me: Option<&str>,
        wait: Duration,
        on_change: impl Fn(&[String]) + Send + Sync + 'static,
    ) -> Result<Self, ZenohError> {
        let view: Arc<Mutex<View>> = Arc::new(Mutex::new((
            me.map(str::to_owned).into_iter().collect(),
            false,
        )));
        let on_change = Arc::new(on_change);
        let report = |v: &View, on_change: &dyn Fn(&[String])| {
            let live: Vec<String> = v.0.iter().cloned().collect();
            on_change(&live);
        };
        let (shared, me_owned, notify) = (
            Arc::clone(&view),
            me.map(str::to_owned),
            Arc::clone(&on_change),
        );
        let watch = session
            .liveliness()
            .declare_subscriber(format!("{INSTANCES}*"))
            .history(true)
            .callback(move |sample| {
                let Some(name) = sample.key_expr().as_str().strip_prefix(INSTANCES) else {
                    return;
                };
                let mut v = shared
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                let changed = match sample.kind() {
                    SampleKind::Put => v.0.insert(name.to_owned()),
                    SampleKind::Delete => me_owned.as_deref() != Some(name) && v.0.remove(name),
                };
                if changed && v.1 {
                    report(&v, notify.as_ref());
                }
            })
            .await
            .map_err(session_err("declare liveliness subscriber"))?;
        let replies = session
            .liveliness()
            .get(format!("{INSTANCES}*"))
            .timeout(wait)
            .await
            .map_err(session_err("liveliness query"))?;
        let mut answered = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result()
                && let Some(name) = sample.key_expr().as_str().strip_prefix(INSTANCES)
            {
                answered.push(name.to_owned());
            }
        }
        let mut v = view
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        v.0.extend(answered);
        v.1 = true;
        report(&v, on_change.as_ref());
        drop(v);
        Ok(Self { _watch: watch })
    }
}

/// The channels an instance of an automatic shard claims now: one liveliness token
/// each, declared and withdrawn as its assignment moves.
#[derive(Debug)]
pub struct Claims {
    session: Session,
    instance: String,
    tokens: HashMap<String, LivelinessToken>,
}

impl Claims {
    /// No claim yet, for `instance` on `session`.
    #[must_use]
    pub fn new(session: &Session, instance: &str) -> Self {
        Self {
            session: session.clone(),
            instance: instance.to_owned(),
            tokens: HashMap::new(),
        }
    }

    /// Claims `channel` (nothing when already claimed).
    ///
    /// # Errors
    /// [`ZenohError::Session`] when the token cannot be declared.
    pub async fn claim(&mut self, channel: &str) -> Result<(), ZenohError> {
        if !self.tokens.contains_key(channel) {
            let token = self
                .session
                .liveliness()
                .declare_token(owner_key(channel, &self.instance))
                .await
                .map_err(session_err("declare liveliness token"))?;
            self.tokens.insert(channel.to_owned(), token);
        }
        Ok(())
    }

    /// Withdraws the claim on `channel`; false when there was none.
    pub fn release(&mut self, channel: &str) -> bool {
        self.tokens.remove(channel).is_some()
    }

    /// The channels claimed now.
    pub fn held(&self) -> impl Iterator<Item = &str> {
        self.tokens.keys().map(String::as_str)
    }
}

/// Those of `channels` that no instance but `instance` claims now, as the owners'
/// tokens answer within `wait`: a leaving instance waits for this to be empty (its
/// channels taken over) before it stops.
///
/// # Errors
/// [`ZenohError::Session`] when the query fails.
pub async fn unclaimed(
    session: &Session,
    instance: &str,
    channels: &[String],
    wait: Duration,
) -> Result<Vec<String>, ZenohError> {
    let elsewhere: BTreeSet<String> = owners_elsewhere(session, instance, wait)
        .await?
        .into_iter()
        .map(|(channel, _)| channel)
        .collect();
    Ok(channels
        .iter()
        .filter(|c| !elsewhere.contains(c.as_str()))
        .cloned()
        .collect())
}

/// The names of the live instances, kept up to date (for readers that tell a live
/// instance's records from others').
#[derive(Debug)]
pub struct LiveInstances {
    _membership: Membership,
    names: Arc<Mutex<Vec<String>>>,
}

impl LiveInstances {
    /// Follows the instances' tokens (the ones alive now known within 1 s).
    ///
    /// # Errors
    /// As [`Membership::watch`].
    pub async fn watch(session: &Session) -> Result<Self, ZenohError> {
        let names = Arc::new(Mutex::new(Vec::new()));
        let kept = Arc::clone(&names);
        let membership = Membership::watch(session, None, Duration::from_secs(1), move |live| {
            *kept
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = live.to_vec();
        })
        .await?;
        Ok(Self {
            _membership: membership,
            names,
        })
    }

    /// Whether an instance of this name is alive.
    #[must_use]
    pub fn contains(&self, instance: &str) -> bool {
        self.names
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .any(|n| n == instance)
    }
}
