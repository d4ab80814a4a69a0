//! Plant samples into the runtime: the subscribers of each channel's input keys
//! ([`ZenohSource`]), with the publishers' cached samples first for a channel taken
//! over, and the plant publisher that keeps such a cache ([`plant_publisher`]).

use std::sync::{Arc, Mutex};
use std::time::Instant;

use glrmon_runtime::{Declared, Intake, Payload};
use zenoh::Session;
use zenoh::bytes::Encoding;
use zenoh::pubsub::Subscriber;
use zenoh::qos::CongestionControl;

use crate::{ZenohError, session_err};

/// The subscribers feeding the runtime, per channel; dropping it undeclares them
/// (stops intake).
///
/// A static instance opens every channel at once ([`ZenohSource::declare`]). An
/// instance of an automatic shard opens a channel when it takes it over and closes it
/// when it hands it over ([`ZenohSource::idle`], [`ZenohSource::open`],
/// [`ZenohSource::close`]): then it asks the publishers' caches (zenoh-ext advanced
/// publishers with a cache) for the channel's recent samples, which reach the channel
/// before the live ones, in order, so that its filter and window are warm when the live
/// samples come.
pub struct ZenohSource {
    session: Session,
    keys: Vec<Vec<String>>,
    intake: Intake,
    encodings: Arc<DeclaredTypes>,
    /// Samples per input key asked from the publishers' caches at [`ZenohSource::open`],
    /// by channel (0: none).
    history: Vec<usize>,
    open: Mutex<Vec<Vec<Subscription>>>,
}

impl std::fmt::Debug for ZenohSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohSource")
            .field("channels", &self.keys.len())
            .field("subscriptions", &self.len())
            .finish_non_exhaustive()
    }
}

/// One input key's subscriber, held to be dropped (which undeclares it).
#[allow(dead_code)]
pub(crate) enum Subscription {
    Plain(Subscriber<()>),
    /// With history from the publishers' caches.
    Advanced(zenoh_ext::AdvancedSubscriber<()>),
}

/// The Zenoh encodings that declare a message type a decoder reads, built once: a
/// payload's encoding is compared with them (an id and a few schema bytes), so the
/// common cases allocate nothing.
struct DeclaredTypes {
    cdr: Vec<(Encoding, Declared)>,
}

impl DeclaredTypes {
    fn new() -> Self {
        let cdr = Declared::cdr_schemas()
            .into_iter()
            .map(|(schema, d)| (Encoding::APPLICATION_CDR.with_schema(schema), d))
            .collect();
        Self { cdr }
    }

    /// What `encoding` declares: a CDR type glrmon reads, another CDR type
    /// (`application/cdr;<schema>`: only this rare case formats the encoding), or
    /// nothing.
    fn of(&self, encoding: &Encoding) -> Declared {
        if let Some((_, d)) = self.cdr.iter().find(|(e, _)| e == encoding) {
            return *d;
        }
        if *encoding == Encoding::APPLICATION_CDR || *encoding == Encoding::default() {
            return Declared::Nothing;
        }
        let text = std::borrow::Cow::from(encoding);
        if text.starts_with("application/cdr;") {
            Declared::OtherCdr
        } else {
            Declared::Nothing
        }
    }
}

impl ZenohSource {
    /// Subscribes to each channel's input keys (`keys[i]` for channel index i: its
    /// `key`, or its tags' keys, `glrmon_spec::Channel::input_keys`); a payload
    /// carries the index of the key it arrived on as its `tag`. The callbacks never
    /// block: a full queue drops (counted by the runtime).
    ///
    /// # Errors
    /// [`ZenohError::Session`] when a declaration fails.
    pub async fn declare(
        session: &Session,
        keys: &[Vec<String>],
        intake: &Intake,
    ) -> Result<Self, ZenohError> {
        let source = Self::idle(session, keys, intake, vec![0; keys.len()]);
        for channel in 0..keys.len() {
            source.open(channel).await?;
        }
        Ok(source)
    }

    /// The source of these channels with none open yet; `history[i]` samples per
    /// input key of channel i are asked from the publishers' caches when it opens.
    #[must_use]
    pub fn idle(
        session: &Session,
        keys: &[Vec<String>],
        intake: &Intake,
        history: Vec<usize>,
    ) -> Self {
        Self {
            session: session.clone(),
            keys: keys.to_vec(),
            intake: intake.clone(),
            encodings: Arc::new(DeclaredTypes::new()),
            history,
            open: Mutex::new(keys.iter().map(|_| Vec::new()).collect()),
        }
    }

    /// Subscribes to channel `channel`'s input keys, with its history when it has
    /// one; false when it was open already or there is no such channel.
    ///
    /// # Errors
    /// [`ZenohError::Session`] when a declaration fails (nothing is left open then).
    pub async fn open(&self, channel: usize) -> Result<bool, ZenohError> {
        let Some(keys) = self.keys.get(channel) else {
            return Ok(false);
        };
        if !self.lock().get(channel).is_some_and(Vec::is_empty) {
            return Ok(false);
        }
        let history = self.history.get(channel).copied().unwrap_or(0);
        let mut subscriptions = Vec::with_capacity(keys.len());
        for (tag, key) in keys.iter().enumerate() {
            let callback = self.callback(channel, tag);
            subscriptions.push(if history > 0 {
                use zenoh_ext::AdvancedSubscriberBuilderExt as _;
                Subscription::Advanced(
                    self.session
                        .declare_subscriber(key.as_str())
                        .history(zenoh_ext::HistoryConfig::default().max_samples(history))
                        .callback(callback)
                        .await
                        .map_err(session_err("declare subscriber"))?,
                )
            } else {
                Subscription::Plain(
                    self.session
                        .declare_subscriber(key.as_str())
                        .callback(callback)
                        .await
                        .map_err(session_err("declare subscriber"))?,
                )
            });
        }
        let mut open = self.lock();
        match open.get_mut(channel) {
            Some(slot) if slot.is_empty() => {
                *slot = subscriptions;
                Ok(true)
            }
            _ => Ok(false),
        }
    }

    /// Undeclares channel `channel`'s subscribers; false when none was open.
    pub fn close(&self, channel: usize) -> bool {
        let taken = self
            .lock()
            .get_mut(channel)
            .map(std::mem::take)
            .unwrap_or_default();
        !taken.is_empty()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Vec<Subscription>>> {
        self.open
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The callback of channel `index`'s key `tag`: the payload to intake, never
    /// blocking.
    fn callback(
        &self,
        index: usize,
        tag: usize,
    ) -> impl Fn(zenoh::sample::Sample) + Send + Sync + 'static {
        let intake = self.intake.clone();
        let encodings = self.encodings.clone();
        move |sample| {
            let source_time = sample.timestamp().map(|t| {
                let st = t.get_time().to_system_time();
                st.duration_since(std::time::UNIX_EPOCH)
                    .map_or(0.0, |d| d.as_secs_f64())
            });
            let bytes = sample.payload().to_bytes().into_owned();
            let _ = intake.offer(
                index,
                Payload {
                    bytes,
                    received: Instant::now(),
                    source_time,
                    tag,
                    declared: encodings.of(sample.encoding()),
                },
            );
        }
    }

    /// Number of subscriptions open.
    #[must_use]
    pub fn len(&self) -> usize {
        self.lock().iter().map(Vec::len).sum()
    }

    /// Whether none is open.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A publisher of plant samples on `key` with `encoding` (reliable, blocking under
/// congestion) that keeps its last `cache` samples for a glrmon instance that takes a
/// channel over (a zenoh-ext advanced publisher with a cache and sequence numbers; 0:
/// no cache).
///
/// # Errors
/// [`ZenohError::Session`] when the declaration fails.
pub async fn plant_publisher(
    session: &Session,
    key: &str,
    encoding: Encoding,
    cache: usize,
) -> Result<zenoh_ext::AdvancedPublisher<'static>, ZenohError> {
    use zenoh_ext::AdvancedPublisherBuilderExt as _;
    let builder = session
        .declare_publisher(key.to_owned())
        .encoding(encoding)
        .congestion_control(CongestionControl::Block);
    let builder = if cache > 0 {
        builder
            .cache(zenoh_ext::CacheConfig::default().max_samples(cache))
            .sample_miss_detection(zenoh_ext::MissDetectionConfig::default())
    } else {
        builder.advanced()
    };
    builder.await.map_err(session_err("declare publisher"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The encodings that name a CDR type: both spellings of the types glrmon reads,
    /// any other schema under `application/cdr`, and the rest (no schema, JSON, a
    /// schema under another encoding) declaring nothing.
    #[test]
    fn an_encoding_declares_the_cdr_type_its_schema_names() {
        use glrmon_spec::CdrMessage;
        let types = DeclaredTypes::new();
        let cdr = |s: &str| Encoding::APPLICATION_CDR.with_schema(s);
        for (encoding, want) in [
            (
                cdr("glrmon_msgs/msg/Sample"),
                Declared::Cdr(CdrMessage::Sample),
            ),
            (cdr("glrmon_msgs/Sample"), Declared::Cdr(CdrMessage::Sample)),
            (
                cdr("std_msgs/msg/Float64MultiArray"),
                Declared::Cdr(CdrMessage::Float64MultiArray),
            ),
            (cdr("sensor_msgs/msg/Imu"), Declared::OtherCdr),
            (Encoding::APPLICATION_CDR, Declared::Nothing),
            (Encoding::default(), Declared::Nothing),
            (Encoding::APPLICATION_JSON, Declared::Nothing),
            (
                Encoding::APPLICATION_JSON.with_schema("glrmon_msgs/msg/Sample"),
                Declared::Nothing,
            ),
        ] {
            assert_eq!(types.of(&encoding), want, "{encoding}");
        }
    }
}
