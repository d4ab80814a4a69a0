//! Validation of a deserialised configuration into [`Config`]: every check, each
//! problem with the path of its field, all of them reported (not only the first).
//!
//! [`config`] checks the file's top-level tables ([`deployment`]), then each channel
//! ([`Validator::channel`], a driver over the steps of the submodules), then locates
//! every problem in the text.

mod channel;
mod deployment;
mod diagnosis;
mod faults;
mod glr;
mod kernel;
mod matrix;
mod model;
mod parity;
mod payload;
mod signals;
mod simulation;
mod tags;

use crate::locate::{self, did_you_mean};
use crate::schema::{ChannelSpec, ConfigFile};
use crate::{Channel, Config, Problem, SpecErrors, keys};

/// Validates a deserialised configuration; `text` is the TOML it was read from (kept
/// in the [`Config`], and used to locate the problems).
pub(crate) fn config(file: ConfigFile, text: &str) -> Result<Config, SpecErrors> {
    let mut v = Validator::default();
    if file.channels.is_empty() {
        v.error(
            String::new(),
            "no channels: add at least one [[channels]] table".into(),
        );
    }
    v.zenoh(&file.zenoh);
    v.daemon(&file.daemon);
    v.recording(&file.recording);
    let channels = v.channels(&file.channels);
    v.locate_problems(text, &file.channels);
    if v.errors.is_empty() {
        Ok(Config {
            zenoh: file.zenoh,
            recording: file.recording,
            daemon: file.daemon,
            channels,
            warnings: v.warnings,
            source: text.to_owned(),
        })
    } else {
        Err(SpecErrors { errors: v.errors })
    }
}

/// `message`, with `; did you mean "x"?` when a candidate is close to `word`.
fn suggest(mut message: String, word: &str, candidates: &[&str]) -> String {
    if let Some(s) = did_you_mean(word, candidates) {
        message.push_str(&format!("; did you mean \"{s}\"?"));
    }
    message
}

#[derive(Default)]
struct Validator {
    errors: Vec<Problem>,
    warnings: Vec<Problem>,
}

fn join(prefix: &str, field: &str) -> String {
    format!("{prefix}: {field}")
}

impl Validator {
    fn error(&mut self, path: String, message: String) {
        self.errors.push(Problem {
            path,
            message,
            location: None,
        });
    }

    fn warn(&mut self, path: String, message: String) {
        self.warnings.push(Problem {
            path,
            message,
            location: None,
        });
    }

    /// The channels that pass their checks, in file order; a duplicate name or a bad
    /// input key is reported before the channel's own checks.
    fn channels(&mut self, specs: &[ChannelSpec]) -> Vec<Channel> {
        let mut channels = Vec::new();
        for (i, spec) in specs.iter().enumerate() {
            let prefix = format!("channels[{i}] \"{}\"", spec.name);
            if specs[..i].iter().any(|c| c.name == spec.name) {
                self.error(
                    prefix.clone(),
                    format!("duplicate channel name \"{}\"", spec.name),
                );
            }
            if let Some(key) = &spec.key
                && let Err(e) = keys::check_input_key(key)
            {
                self.error(join(&prefix, "key"), e);
            }
            if let Some(c) = self.channel(&prefix, spec) {
                channels.push(c);
            }
        }
        channels
    }

    /// Gives every error and warning the line and column in `text` of the field its
    /// path names.
    fn locate_problems(&mut self, text: &str, specs: &[ChannelSpec]) {
        if !(self.errors.is_empty() && self.warnings.is_empty()) {
            let spans = locate::Spans::new(text);
            let names: Vec<&str> = specs.iter().map(|c| c.name.as_str()).collect();
            for p in self.errors.iter_mut().chain(self.warnings.iter_mut()) {
                p.location = spans.locate(&p.path, &names);
            }
        }
    }
}
