//! JSON Schemas (draft 7) of the wire's messages, derived from their types with schemars:
//! the serde attributes give the shape (names, the `type` tag, which fields may be
//! absent, `null` or unknown) and the doc comments the descriptions.
//!
//! Recordings carry them as each topic's schema, and [`decode_record`](crate::decode_record)
//! walks them to name the field of a wrongly typed value. Every subschema is inline (no
//! `$ref`), so that a reader that does not resolve references (Foxglove's JSON Schema
//! support) still sees every field.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use schemars::JsonSchema;
use schemars::generate::{Contract, SchemaSettings};
use serde_json::{Map, Value};

use crate::IntakeEvent;
use crate::record::Record;
use crate::sample::SampleJson;

/// The schema of a result record of type `kind` (one of [`RECORD_KINDS`](crate::RECORD_KINDS)):
/// an object with the `type` tag and the fields of its struct ([`Stat`](crate::Stat),
/// [`Alarm`](crate::Alarm), …). Fields that are `Option`s are not required and may be
/// `null`. Unknown fields are allowed (no `additionalProperties: false`), as
/// [`decode_record`](crate::decode_record) ignores them.
///
/// ```
/// let stat = glrmon_wire::record_schema("stat").unwrap();
/// assert_eq!(stat["title"], "glrmon stat");
/// assert_eq!(stat["properties"]["type"]["const"], "stat");
/// assert!(stat["properties"]["glr"]["description"].as_str().unwrap().contains("eq. (35)"));
/// assert!(glrmon_wire::record_schema("status").is_none());
/// ```
#[must_use]
pub fn record_schema(kind: &str) -> Option<&'static Value> {
    static SCHEMAS: OnceLock<BTreeMap<String, Value>> = OnceLock::new();
    SCHEMAS.get_or_init(record_schemas).get(kind)
}

/// The schema of a sample as [`encode_sample`](crate::encode_sample) writes it (and a
/// recording holds it): `y` always, `k` and `t` when known, `u` and `p` when not empty,
/// nothing else. [`decode_samples`](crate::decode_samples) accepts these and also `null`
/// for the optional fields.
#[must_use]
pub fn sample_schema() -> &'static Value {
    static SCHEMA: OnceLock<Value> = OnceLock::new();
    SCHEMA.get_or_init(|| root_schema::<SampleJson<'static>>(Contract::Serialize))
}

/// The schema of an [`IntakeEvent`]: one object schema whose `properties` are those of
/// both events (the shape a reader that ignores `oneOf` sees), with `oneOf` the two
/// events exactly.
#[must_use]
pub fn intake_schema() -> &'static Value {
    static SCHEMA: OnceLock<Value> = OnceLock::new();
    SCHEMA.get_or_init(|| {
        let mut schema = root_schema::<IntakeEvent>(Contract::Deserialize);
        merge_alternatives(&mut schema);
        schema
    })
}

/// Draft 7, every subschema inline, for `contract`.
fn settings(contract: Contract) -> SchemaSettings {
    SchemaSettings::draft07().with(|s| {
        s.inline_subschemas = true;
        s.contract = contract;
    })
}

/// `T`'s root schema, its descriptions tidied and its string enums plain.
fn root_schema<T: JsonSchema + ?Sized>(contract: Contract) -> Value {
    let mut schema = settings(contract)
        .into_generator()
        .into_root_schema_for::<T>()
        .to_value();
    tidy(&mut schema);
    schema
}

/// One schema per alternative of [`Record`]'s: serde's `type` tag comes from the enum, the
/// fields, title and description from the variant's struct (its variants have an empty
/// schema description for that).
fn record_schemas() -> BTreeMap<String, Value> {
    let mut root = root_schema::<Record>(Contract::Deserialize);
    let meta_schema = root.get("$schema").cloned().unwrap_or(Value::Null);
    let Some(Value::Array(alternatives)) = root.get_mut("oneOf").map(Value::take) else {
        return BTreeMap::new();
    };
    alternatives
        .into_iter()
        .filter_map(|mut schema| {
            let kind = schema["properties"]["type"]["const"].as_str()?.to_owned();
            let object = schema.as_object_mut()?;
            object.insert("$schema".to_owned(), meta_schema.clone());
            Some((kind, schema))
        })
        .collect()
}

/// Gives a `oneOf` of object schemas (an internally tagged enum) the `type`, `properties`
/// and `required` of all of them: each property as the first alternative that has it
/// describes it, but the tag, whose constants become one `enum`.
fn merge_alternatives(schema: &mut Value) {
    let Some(alternatives) = schema.get("oneOf").and_then(Value::as_array) else {
        return;
    };
    let mut properties = Map::new();
    let mut tag: Option<(String, Vec<Value>)> = None;
    let mut required: Option<Vec<Value>> = None;
    for alternative in alternatives {
        for (name, property) in alternative["properties"].as_object().into_iter().flatten() {
            match property.get("const") {
                Some(value) => tag
                    .get_or_insert_with(|| (name.clone(), Vec::new()))
                    .1
                    .push(value.clone()),
                None => {
                    properties
                        .entry(name.clone())
                        .or_insert_with(|| property.clone());
                }
            }
        }
        let names = alternative["required"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        required = Some(match required {
            None => names,
            Some(all) => all.into_iter().filter(|n| names.contains(n)).collect(),
        });
    }
    if let Some((name, values)) = tag {
        properties.insert(name, serde_json::json!({"type": "string", "enum": values}));
    }
    let Some(object) = schema.as_object_mut() else {
        return;
    };
    object.insert("type".to_owned(), "object".into());
    object.insert("properties".to_owned(), Value::Object(properties));
    object.insert(
        "required".to_owned(),
        Value::Array(required.unwrap_or_default()),
    );
}

/// Makes the generated schema read as a description of JSON rather than of Rust:
///
/// - a `oneOf` of string constants (a unit-variant enum whose variants have doc comments,
///   such as [`ErrorCode`](crate::ErrorCode)) becomes a plain `enum` of them;
/// - descriptions lose rustdoc sections (`# Examples` and after), the line breaks of
///   wrapped doc comments (paragraphs stay) and the brackets of intra-doc links.
fn tidy(value: &mut Value) {
    match value {
        Value::Object(map) => {
            if let Some(values) = string_constants(map.get("oneOf")) {
                map.remove("oneOf");
                map.insert("type".to_owned(), "string".into());
                map.insert("enum".to_owned(), Value::Array(values));
            }
            for (key, v) in map.iter_mut() {
                match v {
                    Value::String(text) if key == "description" => *text = plain_text(text),
                    _ => tidy(v),
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(tidy),
        _ => {}
    }
}

/// The constants of a `oneOf` whose alternatives are all string constants.
fn string_constants(one_of: Option<&Value>) -> Option<Vec<Value>> {
    one_of?
        .as_array()?
        .iter()
        .map(|alternative| alternative.get("const").filter(|c| c.is_string()).cloned())
        .collect()
}

/// A doc comment as plain text: up to its first rustdoc heading, paragraphs unwrapped,
/// ``[`Name`]`` and ``[`Name`](path)`` as `` `Name` ``.
fn plain_text(doc: &str) -> String {
    let body = doc
        .split('\n')
        .take_while(|line| !line.starts_with("# "))
        .collect::<Vec<_>>()
        .join("\n");
    let unwrapped = body
        .trim()
        .split("\n\n")
        .map(|paragraph| paragraph.split('\n').collect::<Vec<_>>().join(" "))
        .collect::<Vec<_>>()
        .join("\n\n");
    let mut out = String::with_capacity(unwrapped.len());
    let mut rest = unwrapped.as_str();
    while let Some(start) = rest.find("[`") {
        let Some(len) = rest[start + 2..].find("`]") else {
            break;
        };
        out.push_str(&rest[..start]);
        out.push_str(&rest[start + 1..start + 2 + len + 1]);
        rest = &rest[start + 2 + len + 2..];
        if let Some(target) = rest.strip_prefix('(')
            && let Some(end) = target.find(')')
        {
            rest = &target[end + 1..];
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptions_read_as_plain_text() {
        assert_eq!(
            plain_text(
                "One line\nwrapped, see [`Stat`].\n\nAnd [`Foo::bar`](crate::Foo::bar).\n\n# Examples\n\n```\nx\n```"
            ),
            "One line wrapped, see `Stat`.\n\nAnd `Foo::bar`."
        );
        assert_eq!(plain_text("[`unclosed"), "[`unclosed");
    }
}
