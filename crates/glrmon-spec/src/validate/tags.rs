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
    /// `[channels.tags]` (or `[channels.topics]`, `table`) into [`Tags`]: every signal
    /// has a key, and only signals do. Topics are names in a recording, not key
    /// expressions: only their being non-empty is checked.
    pub(super) fn tags(
        &mut self,
        prefix: &str,
        table: &str,
        spec: &TagsSpec,
        columns: &Columns,
    ) -> Option<Tags> {
        let before = self.errors.len();
        let at = |field: &str| join(prefix, &format!("{table}.{field}"));
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
                    join(prefix, table),
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
            let checked = if table == "topics" {
                if key.is_empty() {
                    Err("is empty: give the topic's name".to_owned())
                } else {
                    Ok(())
                }
            } else {
                keys::check_input_key(&key)
            };
            if let Err(e) = checked {
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

#[cfg(test)]
mod tests {
    use crate::{Formation, TagTime};

    fn channel(tags: &str) -> Result<crate::Channel, String> {
        let (top, tags) = match tags.strip_prefix("key = \"plant/motor\"\n") {
            Some(rest) => ("key = \"plant/motor\"", rest),
            None => ("", tags),
        };
        let text = format!(
            r#"
[[channels]]
name = "motor"
{top}
model = {{ F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 0 }}]
[channels.columns]
u = ["volts"]
y = ["amps", "speed"]
{tags}"#
        );
        crate::parse(&text)
            .map(|mut c| c.channels.remove(0))
            .map_err(|e| e.to_string())
    }

    const KEYS: &str = "[channels.tags.keys]\nvolts = \"plant/dc/voltage\"\namps = \"plant/dc/current\"\nspeed = { key = \"plant/dc/json\", field = \"data.speed\", time_field = \"ts\" }\n";

    #[test]
    fn tags_are_read_in_the_samples_order() {
        let c = channel(&format!("[channels.tags]\nperiod = 0.01\n{KEYS}")).unwrap();
        let tags = c.tags.unwrap();
        assert_eq!(
            (tags.formation, tags.hold, tags.time),
            (Formation::Period(0.01), 3, TagTime::Zenoh)
        );
        let keys: Vec<(&str, &str, String)> = tags
            .tags
            .iter()
            .map(|t| (t.signal.as_str(), t.key.as_str(), t.field.join(".")))
            .collect();
        assert_eq!(
            keys,
            [
                ("volts", "plant/dc/voltage", String::new()),
                ("amps", "plant/dc/current", String::new()),
                ("speed", "plant/dc/json", "data.speed".to_owned()),
            ]
        );
        assert_eq!(
            tags.tags[2].time_field.as_deref(),
            Some(&["ts".to_owned()][..])
        );
        let c = channel(&format!(
            "[channels.tags]\ntrigger = \"speed\"\ntime = \"arrival\"\nhold = 5\n{KEYS}"
        ))
        .unwrap();
        let tags = c.tags.as_ref().unwrap();
        assert_eq!(
            (tags.formation, tags.hold, tags.time),
            (Formation::Trigger(2), 5, TagTime::Arrival)
        );
        assert_eq!(
            c.input_keys(),
            ["plant/dc/voltage", "plant/dc/current", "plant/dc/json"]
        );
    }

    #[test]
    fn a_wrong_tags_table_names_its_field() {
        for (tags, want) in [
            (format!("[channels.tags]\n{KEYS}"), "tags needs `period`"),
            (format!("[channels.tags]\nperiod = 0.01\ntrigger = \"amps\"\n{KEYS}"), "tags.trigger forms samples"),
            (format!("[channels.tags]\nperiod = -1.0\n{KEYS}"), "tags.period: -1 is not a finite, positive"),
            (format!("[channels.tags]\ntrigger = \"torque\"\n{KEYS}"), "tags.trigger: \"torque\" is not one of volts, amps, speed"),
            (format!("[channels.tags]\nperiod = 0.01\nhold = 0\n{KEYS}"), "tags.hold: 0 is not between 1 and 1000000"),
            (format!("[channels.tags]\nperiod = 0.01\ntime = \"gps\"\n{KEYS}"), "tags.time: \"gps\" is not one of zenoh, arrival"),
            (
                "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nvolts = \"plant/dc/voltage\"\namps = \"plant/dc/current\"\n".to_owned(),
                "tags.keys has no key for speed",
            ),
            (
                format!("[channels.tags]\nperiod = 0.01\n{KEYS}torque = \"plant/dc/torque\"\n"),
                "tags.keys.torque is not a signal of the channel; its signals are volts, amps, speed",
            ),
            (
                "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nvolts = \"plant/dc/voltage\"\namps = \"glrmon/dc/current\"\nspeed = \"plant/dc/speed\"\n".to_owned(),
                "tags.keys.amps.key: \"glrmon/dc/current\" intersects glrmon's own key space",
            ),
            (
                "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nvolts = \"plant/dc/voltage\"\namps = \"plant/dc/voltage\"\nspeed = { key = \"plant/dc/speed\", field = \"a..b\" }\n".to_owned(),
                "tags.keys.amps reads the same key and field as volts",
            ),
            (
                "[channels.tags]\nperiod = 0.01\n[channels.tags.keys]\nvolts = \"plant/dc/voltage\"\namps = \"plant/dc/current\"\nspeed = { key = \"plant/dc/speed\", field = \"a..b\" }\n".to_owned(),
                "tags.keys.speed.field: \"a..b\" is not a field path",
            ),
            (
                format!("key = \"plant/motor\"\n[channels.tags]\nperiod = 0.01\n{KEYS}"),
                "key is not read: the channel's signals arrive on `[channels.tags] keys`",
            ),
        ] {
            let err = channel(&tags).unwrap_err();
            // The path, then the reason (after `: `, or a space before a verb).
            let (path, reason) = want.split_once(' ').unwrap();
            let path = path.trim_end_matches(':');
            assert!(
                err.contains(&format!("{path}: {reason}")) || err.contains(&format!("{path} {reason}")),
                "{tags}\n→ {err}"
            );
        }
    }
}
