//! Results read back by programs that were away: the instances' caches (a zenoh-ext
//! advanced subscriber with history, [`Results`]) and the Zenoh storages
//! ([`stored_results`]).

use std::time::Duration;

use zenoh::Session;
use zenoh::query::QueryTarget;

use crate::source::Subscription;
use crate::{ZenohError, session_err};

/// A subscription to results (`glrmon/<channel>/<type>` records), with the records of
/// the last `since` seconds that the live instances kept first when asked ([`crate::RESULT_HISTORY`]
/// per kind and channel), in order, then the live ones; dropping it undeclares it.
pub struct Results {
    /// Held to be dropped (which undeclares it).
    _subscription: Subscription,
}

impl std::fmt::Debug for Results {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Results")
    }
}

impl Results {
    /// Subscribes to `key` (e.g. `glrmon/**`), calling `callback` with each sample.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when the subscriber cannot be declared.
    pub async fn subscribe(
        session: &Session,
        key: &str,
        since: Option<f64>,
        callback: impl Fn(zenoh::sample::Sample) + Send + Sync + 'static,
    ) -> Result<Self, ZenohError> {
        let subscription = match since {
            Some(seconds) => {
                use zenoh_ext::AdvancedSubscriberBuilderExt as _;
                Subscription::Advanced(
                    session
                        .declare_subscriber(key.to_owned())
                        .history(zenoh_ext::HistoryConfig::default().max_age(seconds))
                        .callback(callback)
                        .await
                        .map_err(session_err("declare subscriber"))?,
                )
            }
            None => Subscription::Plain(
                session
                    .declare_subscriber(key.to_owned())
                    .callback(callback)
                    .await
                    .map_err(session_err("declare subscriber"))?,
            ),
        };
        Ok(Self {
            _subscription: subscription,
        })
    }
}

/// The results under `key` that Zenoh storages keep (deploy/zenohd-history.json5: each
/// channel's last record of each kind), published within the last `since` seconds,
/// oldest first; those without a timestamp are kept. Waits at most `timeout` for the
/// storages' answers.
///
/// # Errors
/// [`ZenohError::Session`] when the query fails.
pub async fn stored_results(
    session: &Session,
    key: &str,
    since: f64,
    timeout: Duration,
) -> Result<Vec<zenoh::sample::Sample>, ZenohError> {
    let replies = session
        .get(key.to_owned())
        .target(QueryTarget::All)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .await
        .map_err(session_err("query"))?;
    let now = std::time::SystemTime::now();
    let oldest = now
        .checked_sub(Duration::from_secs_f64(since.clamp(0.0, 1e9)))
        .unwrap_or(std::time::UNIX_EPOCH);
    let mut kept = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.into_result()
            && sample
                .timestamp()
                .is_none_or(|t| t.get_time().to_system_time() >= oldest)
        {
            kept.push(sample);
        }
    }
    kept.sort_by_key(|s| s.timestamp().map(|t| *t.get_time()));
    Ok(kept)
}
