//! `payload` with `[channels.cdr]` and `[channels.raw]`: how the channel's samples are
//! encoded.

use super::{Validator, join};
use crate::schema::ChannelSpec;
use crate::{CdrMessage, Columns, PayloadFormat, RawField, RawLayout, locate};

impl Validator {
    /// The channel's [`PayloadFormat`]; a table of another format than the one named
    /// is an error, so that a setting is never silently ignored.
    pub(super) fn payload(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        columns: &Columns,
    ) -> PayloadFormat {
        let name = spec.payload.as_deref().unwrap_or("json");
        let format = match name {
            "json" => PayloadFormat::Json,
            "cdr" => PayloadFormat::Cdr(self.cdr_message(prefix, spec)),
            "sparkplug" => PayloadFormat::Sparkplug,
            "raw" => match &spec.raw {
                Some(raw) => PayloadFormat::Raw(self.raw_layout(prefix, &raw.layout, columns)),
                None => {
                    self.error(
                        join(prefix, "raw"),
                        "`payload = \"raw\"` needs `[channels.raw] layout`, the f64 fields \
                         of a record in byte order"
                            .into(),
                    );
                    PayloadFormat::Json
                }
            },
            other => {
                self.error(
                    join(prefix, "payload"),
                    locate::not_one_of(other, &PayloadFormat::NAMES),
                );
                return PayloadFormat::Json;
            }
        };
        for (table, given, format_name) in [
            ("cdr", spec.cdr.is_some(), "cdr"),
            ("raw", spec.raw.is_some(), "raw"),
        ] {
            if given && name != format_name {
                self.error(
                    join(prefix, table),
                    format!("applies to `payload = \"{format_name}\"`, not \"{name}\""),
                );
            }
        }
        format
    }

    fn cdr_message(&mut self, prefix: &str, spec: &ChannelSpec) -> CdrMessage {
        let Some(name) = spec.cdr.as_ref().and_then(|c| c.message.as_deref()) else {
            return CdrMessage::default();
        };
        CdrMessage::from_name(name).unwrap_or_else(|| {
            self.error(
                join(prefix, "cdr.message"),
                locate::not_one_of(name, &CdrMessage::NAMES),
            );
            CdrMessage::default()
        })
    }

    /// `raw.layout`: each name `k`, `t`, `_` or a column name; every signal exactly
    /// once, `k` and `t` at most once.
    fn raw_layout(&mut self, prefix: &str, layout: &[String], columns: &Columns) -> RawLayout {
        let path = join(prefix, "raw.layout");
        let mut fields = Vec::with_capacity(layout.len());
        let signals = [
            (&columns.u, RawField::U as fn(usize) -> RawField),
            (&columns.y, RawField::Y),
            (&columns.p, RawField::P),
        ];
        let mut names: Vec<&str> = vec!["k", "t", "_"];
        for (list, _) in &signals {
            names.extend(list.iter().map(String::as_str));
        }
        for (i, name) in layout.iter().enumerate() {
            let field = match name.as_str() {
                "k" => Some(RawField::K),
                "t" => Some(RawField::T),
                "_" => Some(RawField::Skip),
                name => signals
                    .iter()
                    .find_map(|(list, make)| list.iter().position(|c| c == name).map(make)),
            };
            let Some(field) = field else {
                self.error(format!("{path}[{i}]"), locate::not_one_of(name, &names));
                continue;
            };
            if field != RawField::Skip && fields.contains(&field) {
                self.error(
                    format!("{path}[{i}]"),
                    format!("\"{name}\" appears more than once"),
                );
                continue;
            }
            fields.push(field);
        }
        for (list, make) in signals {
            let missing: Vec<&str> = list
                .iter()
                .enumerate()
                .filter(|&(j, _)| !fields.contains(&make(j)))
                .map(|(_, n)| n.as_str())
                .collect();
            if !missing.is_empty() {
                self.error(
                    path.clone(),
                    format!(
                        "has no field for {}: every signal of the channel is in the record",
                        missing.join(", ")
                    ),
                );
            }
        }
        RawLayout { fields }
    }
}

#[cfg(test)]
mod tests {
    use crate::{CdrMessage, PayloadFormat, RawField};

    fn channel(extra: &str) -> Result<crate::Channel, String> {
        let text = format!(
            r#"
[[channels]]
name = "motor"
model = {{ F = [[0.9, 0.0], [0.0, 0.9]], G = [[1.0], [0.5]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.01, R = 0.04 }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 0 }}]
{extra}"#
        );
        crate::parse(&text)
            .map(|mut c| c.channels.remove(0))
            .map_err(|e| e.to_string())
    }

    #[test]
    fn each_format_is_read_with_its_table() {
        assert_eq!(channel("").unwrap().payload, PayloadFormat::Json);
        assert_eq!(
            channel("payload = \"cdr\"").unwrap().payload,
            PayloadFormat::Cdr(CdrMessage::Float64MultiArray)
        );
        assert_eq!(
            channel("payload = \"cdr\"\ncdr = { message = \"glrmon_msgs/msg/Sample\" }")
                .unwrap()
                .payload,
            PayloadFormat::Cdr(CdrMessage::Sample)
        );
        assert_eq!(
            channel("payload = \"sparkplug\"").unwrap().payload,
            PayloadFormat::Sparkplug
        );
        let raw = channel(
            "payload = \"raw\"\nraw = { layout = [\"t\", \"_\", \"current\", \"volts\", \"speed\"] }\n\
             [channels.columns]\nu = [\"volts\"]\ny = [\"current\", \"speed\"]",
        )
        .unwrap();
        let PayloadFormat::Raw(layout) = raw.payload else {
            panic!("{:?}", raw.payload)
        };
        assert_eq!(
            layout.fields,
            [
                RawField::T,
                RawField::Skip,
                RawField::Y(0),
                RawField::U(0),
                RawField::Y(1)
            ]
        );
        assert_eq!(layout.record_bytes(), 40);
    }

    #[test]
    fn a_wrong_payload_table_names_its_field() {
        for (extra, want) in [
            (
                "payload = \"raw\"",
                "raw: `payload = \"raw\"` needs `[channels.raw] layout`",
            ),
            (
                "payload = \"raw\"\nraw = { layout = [\"t\", \"u0\", \"y0\", \"y7\"] }",
                "raw.layout[3]: \"y7\" is not one of",
            ),
            (
                "payload = \"raw\"\nraw = { layout = [\"u0\", \"y0\"] }",
                "raw.layout has no field for y1",
            ),
            (
                "payload = \"raw\"\nraw = { layout = [\"u0\", \"y0\", \"y1\", \"y0\"] }",
                "raw.layout[3]: \"y0\" appears more than once",
            ),
            (
                "payload = \"cdr\"\ncdr = { message = \"std_msgs/msg/Float32MultiArray\" }",
                "cdr.message: \"std_msgs/msg/Float32MultiArray\" is not one of",
            ),
            (
                "cdr = { message = \"glrmon_msgs/msg/Sample\" }",
                "cdr: applies to `payload = \"cdr\"`, not \"json\"",
            ),
        ] {
            let err = channel(extra).unwrap_err();
            assert!(err.contains(want), "{extra}: {err}");
        }
    }
}
