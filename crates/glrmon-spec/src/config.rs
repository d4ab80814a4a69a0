//! The validated configuration, and what a reload or a tool asks of it.

use crate::locate::did_you_mean;
use crate::schema::{DaemonSpec, RecordingSpec, ZenohSpec};
use crate::{Channel, Problem};

/// A validated configuration.
#[derive(Debug, Clone)]
pub struct Config {
    /// Zenoh settings.
    pub zenoh: ZenohSpec,
    /// Recording settings.
    pub recording: RecordingSpec,
    /// Daemon settings.
    pub daemon: DaemonSpec,
    /// The channels.
    pub channels: Vec<Channel>,
    /// Problems that do not prevent running (e.g. an unobservable model).
    pub warnings: Vec<Problem>,
    /// The TOML text the configuration was parsed from (recorded with the data).
    pub source: String,
}

/// The keys of a channel's `[channels.glr]` table that a reload (SIGHUP) applies to the
/// running monitor: the detection threshold and how it is set, the alarm episode
/// settings, and the isolation tests' delay, level and thresholds. Everything else
/// shapes the filters and needs a restart.
pub const RELOADABLE_GLR_KEYS: [&str; 12] = [
    "threshold",
    "false_alarm",
    "threshold_mode",
    "calibrated",
    "hysteresis",
    "clear_samples",
    "episode_end",
    "gone_alpha",
    "gone_samples",
    "isolation_delay",
    "isolation_alpha",
    "isolation_law",
];

impl Config {
    /// What stands between this configuration and `new` for a reload without a
    /// restart (SIGHUP): every changed setting other than a channel's thresholds and
    /// alarm settings ([`RELOADABLE_GLR_KEYS`]), as a path with the reason, e.g.
    /// `channels "pump3".model: changed (needs a restart: the filters depend on it)`.
    /// Empty when `new` can be applied by retuning the running monitors.
    #[must_use]
    pub fn restart_needed(&self, new: &Config) -> Vec<String> {
        let parse = |text: &str| text.parse::<toml::Table>().unwrap_or_default();
        let (old, new) = (parse(&self.source), parse(&new.source));
        let mut out = Vec::new();
        let keys: std::collections::BTreeSet<&String> = old.keys().chain(new.keys()).collect();
        for key in keys.into_iter().filter(|k| *k != "channels") {
            if old.get(key) != new.get(key) {
                out.push(format!("[{key}]: changed (needs a restart)"));
            }
        }
        let channels = |t: &toml::Table| -> Vec<(String, toml::Table)> {
            t.get("channels")
                .and_then(toml::Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(toml::Value::as_table)
                        .map(|c| {
                            let name = c.get("name").and_then(toml::Value::as_str).unwrap_or("");
                            (name.to_owned(), c.clone())
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        let (before, after) = (channels(&old), channels(&new));
        for (name, _) in &before {
            if !after.iter().any(|(n, _)| n == name) {
                out.push(format!("channels \"{name}\": removed (needs a restart)"));
            }
        }
        for (name, table) in &after {
            let Some((_, was)) = before.iter().find(|(n, _)| n == name) else {
                out.push(format!("channels \"{name}\": added (needs a restart)"));
                continue;
            };
            let strip = |t: &toml::Table| {
                let mut t = t.clone();
                if let Some(toml::Value::Table(glr)) = t.get_mut("glr") {
                    for k in RELOADABLE_GLR_KEYS {
                        glr.remove(k);
                    }
                }
                t
            };
            let (a, b) = (strip(was), strip(table));
            let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            for key in keys {
                if a.get(key) != b.get(key) {
                    out.push(format!(
                        "channels \"{name}\".{key}: changed (needs a restart: only glr.{} are reloaded)",
                        RELOADABLE_GLR_KEYS.join(", glr.")
                    ));
                }
            }
        }
        out
    }

    /// The channel named `name`.
    #[must_use]
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }

    /// The channel a tool works on: the one named, or the only one when no name is
    /// given.
    ///
    /// # Errors
    /// [`ChannelChoiceError`] when the name is not a channel of the configuration,
    /// or no name is given and there are several channels (or none).
    ///
    /// # Examples
    /// ```
    /// let cfg = glrmon_spec::parse(include_str!("../../../config/demo.toml")).unwrap();
    /// assert_eq!(cfg.pick_channel(Some("unstable")).unwrap().name, "unstable");
    /// let err = cfg.pick_channel(None).unwrap_err();
    /// assert_eq!(err.to_string(), "the configuration has several channels: choose one with --channel");
    /// ```
    pub fn pick_channel(&self, name: Option<&str>) -> Result<&Channel, ChannelChoiceError> {
        match name {
            Some(n) => self.channel(n).ok_or_else(|| ChannelChoiceError::Unknown {
                name: n.to_owned(),
                channels: self.channels.iter().map(|c| c.name.clone()).collect(),
            }),
            None => match self.channels.as_slice() {
                [only] => Ok(only),
                _ => Err(ChannelChoiceError::Ambiguous),
            },
        }
    }
}

/// Why [`Config::pick_channel`] found no channel.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ChannelChoiceError {
    /// No channel has that name.
    #[error(
        "no channel \"{name}\" in the configuration (channels: {}){}",
        channels.join(", "),
        channel_suggestion(name, channels)
    )]
    Unknown {
        /// The name asked for.
        name: String,
        /// The configuration's channels.
        channels: Vec<String>,
    },
    /// No name was given and the configuration does not have exactly one channel.
    #[error("the configuration has several channels: choose one with --channel")]
    Ambiguous,
}

/// `; did you mean "x"?` when a channel's name is close to `name`.
fn channel_suggestion(name: &str, channels: &[String]) -> String {
    let names: Vec<&str> = channels.iter().map(String::as_str).collect();
    did_you_mean(name, &names).map_or_else(String::new, |s| format!("; did you mean \"{s}\"?"))
}
