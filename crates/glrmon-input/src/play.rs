//! Playing a recording back (`glrmon play`): its recorded input samples, each with the
//! Zenoh key of its channel (from the recorded configuration) and its recorded time
//! relative to the first one played.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use glrmon_runtime::InputItem;
use glrmon_spec::Config;
use glrmon_wire::Sample;

use crate::mcap::{McapInput, RecordedInput};
use crate::{InputError, InputErrorKind};

/// One recorded sample to publish again.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayedSample {
    /// Its channel.
    pub channel: Arc<str>,
    /// The channel's key expression in the recorded configuration.
    pub key: Arc<str>,
    /// The sample as the monitor saw it.
    pub sample: Sample,
    /// Its recorded log time (receive time, ns since the Unix epoch).
    pub log_time_ns: u64,
    /// Its log time less the first played sample's (0 for a log time earlier than it).
    pub offset_ns: u64,
}

/// A recording's input samples in file order (the order the monitors saw them), with
/// their channel's key: what `glrmon play` publishes. Intake events (drops, refused
/// payloads) are not samples and are skipped ([`Playback::skipped`]); result topics
/// (alarms, the `foxglove.Log` topic) are output and are never played.
///
/// # Examples
///
/// ```no_run
/// use glrmon_input::{Playback, due};
///
/// let mut play = Playback::open("run.mcap".as_ref(), &[])?;
/// while let Some(s) = play.next_sample()? {
///     // Real time: wait until `due(s.offset_ns, 1.0)` after the start, then publish.
///     let _wait = due(s.offset_ns, 1.0);
///     println!("{} ← k={:?}", s.key, s.sample.k);
/// }
/// # Ok::<(), glrmon_input::InputError>(())
/// ```
#[derive(Debug)]
pub struct Playback {
    input: McapInput,
    config: Config,
    /// Key of each played channel.
    keys: HashMap<Arc<str>, Arc<str>>,
    first_ns: Option<u64>,
    skipped: u64,
    spare: Option<RecordedInput>,
}

impl Playback {
    /// Opens a recording and reads its configuration; `channels` restricts the playback
    /// to those channels (empty: every channel of the configuration).
    ///
    /// # Errors
    /// The errors of [`McapInput::open`] and [`McapInput::recorded_config`] (a file
    /// that is not a glrmon recording), [`InputErrorKind::UnknownChannel`] for a
    /// channel the configuration does not have.
    pub fn open(path: &Path, channels: &[String]) -> Result<Self, InputError> {
        let input = McapInput::open(path)?;
        let config = input.recorded_config()?;
        let known: Vec<String> = config.channels.iter().map(|c| c.name.clone()).collect();
        for name in channels {
            if !known.contains(name) {
                return Err(InputError::new(
                    path,
                    InputErrorKind::UnknownChannel {
                        name: name.clone(),
                        known,
                    },
                ));
            }
        }
        let keys = config
            .channels
            .iter()
            .filter(|c| channels.is_empty() || channels.contains(&c.name))
            .map(|c| (Arc::from(c.name.as_str()), Arc::from(c.key.as_str())))
            .collect();
        Ok(Self {
            input,
            config,
            keys,
            first_ns: None,
            skipped: 0,
            spare: None,
        })
    }

    /// The recorded configuration.
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The played channels and their keys, in configuration order.
    #[must_use]
    pub fn channels(&self) -> Vec<(String, String)> {
        self.config
            .channels
            .iter()
            .filter(|c| self.keys.contains_key(c.name.as_str()))
            .map(|c| (c.name.clone(), c.key.clone()))
            .collect()
    }

    /// Intake events skipped so far (not samples: nothing to publish).
    #[must_use]
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The next sample of a played channel, `None` at the end of what is readable.
    ///
    /// # Errors
    /// [`InputErrorKind::Read`] on an I/O error (damage is skipped and reported by
    /// [`Playback::damage_report`]).
    pub fn next_sample(&mut self) -> Result<Option<PlayedSample>, InputError> {
        loop {
            let Some(recorded) = self.input.next_input(self.spare.take())? else {
                return Ok(None);
            };
            let Some(key) = self.keys.get(&recorded.channel).cloned() else {
                self.spare = Some(recorded);
                continue;
            };
            let InputItem::Sample(sample) = &recorded.item else {
                self.skipped += 1;
                continue;
            };
            let first = *self.first_ns.get_or_insert(recorded.log_time_ns);
            let played = PlayedSample {
                channel: recorded.channel.clone(),
                key,
                sample: sample.clone(),
                log_time_ns: recorded.log_time_ns,
                offset_ns: recorded.log_time_ns.saturating_sub(first),
            };
            self.spare = Some(recorded);
            return Ok(Some(played));
        }
    }

    /// What damage or an unfinished end cost, as lines, and whether data was lost
    /// ([`McapInput::damage_report`]).
    #[must_use]
    pub fn damage_report(&self) -> (Vec<String>, bool) {
        self.input.damage_report()
    }
}

/// When a sample recorded `offset_ns` after the first should be published, from the
/// start of the playback, at `rate` times real time; `None` when `rate` is 0 (or not a
/// positive finite number): as fast as possible.
///
/// # Examples
///
/// ```
/// use std::time::Duration;
///
/// assert_eq!(glrmon_input::due(2_000_000_000, 1.0), Some(Duration::from_secs(2)));
/// assert_eq!(glrmon_input::due(2_000_000_000, 4.0), Some(Duration::from_millis(500)));
/// assert_eq!(glrmon_input::due(2_000_000_000, 0.0), None);
/// ```
#[must_use]
pub fn due(offset_ns: u64, rate: f64) -> Option<Duration> {
    (rate.is_finite() && rate > 0.0)
        .then(|| Duration::from_secs_f64((offset_ns as f64 / 1e9 / rate).min(1e12)))
}
