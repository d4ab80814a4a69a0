//! `[channels.tags]`: a channel assembled from one key per signal.

use super::{Validator, join};
use crate::schema::{TagKeySpec, TagsSpec};
use crate::{Columns, Formation, Tag, TagTime, Tags, keys, locate};

/// Default `hold`: periods a silent signal keeps its last value.
const DEFAULT_HOLD: u32 = 3;
/// Largest `hold`.
const MAX_HOLD: u32 = 1_000_000;

/// A field path `data.speed` as its fields, or why it is not one.
fn path(text: &str) -> Result<Vec<String>, String> {
    let fields: Vec<String> = text.split('.').map(str::to_owned).collect();
    if fields.iter().any(|f| f.is_empty() || f.trim() != f) {
        return Err(format!(
            "\"{text}\" is not a field path (names joined by `.`, none empty or padded)"
        ));
    }
    Ok(fields)
}

impl Validator {
    /// `[channels.tags]` into [`Tags`]: every signal has a key, and only signals do.
    pub(super) fn tags(
        &mut self,
        prefix: &str,
        spec: &TagsSpec,
        columns: &Columns,
    ) -> Option<Tags> {
        let before = self.errors.len();
        let at = |field: &str| join(prefix, &format!("tags.{field}"));
        let signals: Vec<&str> = [&columns.u, &columns.y, &columns.p]
            .into_iter()
            .flatten()
            .map(String::as_str)
            .collect();
        let hold = spec.hold.unwrap_or(DEFAULT_HOLD);
        if !(1..=MAX_HOLD).contains(&hold) {
            self.error(
                at("hold"),
                format!("{hold} is not between 1 and {MAX_HOLD}"),
            );
        }
        let time = match spec.time.as_deref() {
            None | Some("zenoh") => TagTime::Zenoh,
            Some("arrival") => TagTime::Arrival,
            Some(other) => {
                self.error(at("time"), locate::not_one_of(other, &TagTime::NAMES));
                TagTime::Zenoh
            }
        };
        let formation = match (spec.period, spec.trigger.as_deref()) {
            (Some(p), None) if p.is_finite() && p > 0.0 => Some(Formation::Period(p)),
            (Some(p), None) => {
                self.error(
                    at("period"),
                    format!("{p} is not a finite, positive number of seconds"),
                );
                None
            }
            (None, Some(name)) => match signals.iter().position(|s| *s == name) {
                Some(i) => Some(Formation::Trigger(i)),
                None => {
                    self.error(at("trigger"), locate::not_one_of(name, &signals));
                    None
                }
            },
            (Some(_), Some(_)) => {
                self.error(
                    at("trigger"),
                    "forms samples at each value of a signal: give `period` or `trigger`, not both"
                        .into(),
                );
                None
            }
            (None, None) => {
                self.error(
                    join(prefix, "tags"),
                    "needs `period` (seconds between samples) or `trigger` (the signal whose \
                     values form samples)"
                        .into(),
                );
                None
            }
        };
        for name in spec.keys.keys() {
            if !signals.contains(&name.as_str()) {
                self.error(
                    at(&format!("keys.{name}")),
                    format!(
                        "is not a signal of the channel; its signals are {}",
                        signals.join(", ")
                    ),
                );
            }
        }
        let mut tags = Vec::with_capacity(signals.len());
        for signal in &signals {
            let field_at = at(&format!("keys.{signal}"));
            let Some(given) = spec.keys.get(*signal) else {
                self.error(
                    at("keys"),
                    format!("has no key for {signal}: every signal of the channel has one"),
                );
                continue;
            };
            let (key, field, time_field) = match given {
                TagKeySpec::Key(key) => (key.clone(), None, None),
                TagKeySpec::Fields(f) => {
                    (f.key.clone(), f.field.as_deref(), f.time_field.as_deref())
                }
            };
            if let Err(e) = keys::check_input_key(&key) {
                self.error(format!("{field_at}.key"), e);
            }
            let field = match field.map(path).transpose() {
                Ok(f) => f.unwrap_or_default(),
                Err(e) => {
                    self.error(format!("{field_at}.field"), e);
                    Vec::new()
                }
            };
            let time_field = match time_field.map(path).transpose() {
                Ok(f) => f,
                Err(e) => {
                    self.error(format!("{field_at}.time_field"), e);
                    None
                }
            };
            if let Some(other) = tags
                .iter()
                .find(|t: &&Tag| t.key == key && t.field == field)
            {
                self.error(
                    field_at,
                    format!("reads the same key and field as {}", other.signal),
                );
                continue;
            }
            tags.push(Tag {
                signal: (*signal).to_owned(),
                key,
                field,
                time_field,
            });
        }
        if self.errors.len() > before {
            return None;
        }
        Some(Tags {
            formation: formation?,
            hold,
            time,
            tags,
        })
    }
}
