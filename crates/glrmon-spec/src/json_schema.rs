//! The JSON Schema of a configuration file, for editors.

use crate::schema;

/// The JSON Schema (draft 7) of a configuration file, pretty-printed: derived from the
/// very types the TOML is deserialised into ([`schema::ConfigFile`]), with their doc
/// comments as descriptions and their defaults. Editors that validate TOML against a
/// JSON Schema (taplo, VS Code's Even Better TOML) complete and check keys with it;
/// `glrmon config schema` prints it.
///
/// It checks what the types check (keys, types, the keyword lists); the rest (shapes
/// against n, p and l, expressions, limits) is [`parse`](crate::parse)'s.
///
/// ```
/// let schema: serde_json::Value = serde_json::from_str(&glrmon_spec::json_schema()).unwrap();
/// assert_eq!(schema["title"], "glrmon configuration");
/// ```
#[must_use]
pub fn json_schema() -> String {
    let generator = schemars::generate::SchemaSettings::draft07().into_generator();
    let mut schema = generator.into_root_schema_for::<schema::ConfigFile>();
    schema.insert("title".into(), "glrmon configuration".into());
    let mut value = schema.to_value();
    unwrap_descriptions(&mut value);
    // Serialising a `serde_json::Value` cannot fail.
    serde_json::to_string_pretty(&value).unwrap_or_default()
}

/// Doc comments are wrapped at 88 columns: their line breaks become spaces in the
/// schema's descriptions (an editor wraps them itself); blank lines stay paragraphs.
fn unwrap_descriptions(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map.iter_mut() {
                if key == "description"
                    && let serde_json::Value::String(text) = v
                {
                    *text = text
                        .split("\n\n")
                        .map(|p| p.split('\n').collect::<Vec<_>>().join(" "))
                        .collect::<Vec<_>>()
                        .join("\n\n");
                } else {
                    unwrap_descriptions(v);
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(unwrap_descriptions),
        _ => {}
    }
}
