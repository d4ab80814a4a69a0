//! The JSON Schema of `glrmon_spec::json_schema`: valid JSON, and every shipped
//! configuration (config/*.toml, config/examples/*.toml), read as JSON, validates
//! against it.
//!
//! The validator below covers the keywords the generated schema uses (`$ref` into
//! `definitions`, `type`, `enum`, `properties`, `required`, `additionalProperties`,
//! `propertyNames` patterns of the form `^(a|b[0-9]+)$`, `items`, `minItems`,
//! `minLength`, `minimum`, `anyOf`, `allOf`); an unknown keyword fails the test, so a
//! schema change that it does not check cannot pass unnoticed.

use std::path::{Path, PathBuf};

use serde_json::Value;

fn schema() -> Value {
    serde_json::from_str(&glrmon_spec::json_schema()).expect("the schema is valid JSON")
}

fn shipped_configs() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let mut files = Vec::new();
    for dir in [root.clone(), root.join("examples")] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                files.push(path);
            }
        }
    }
    files.sort();
    assert!(files.len() >= 4, "{files:?}");
    files
}

/// TOML → JSON, as an editor's TOML support does before it validates.
fn toml_to_json(text: &str) -> Value {
    let table: toml::Table = text.parse().unwrap();
    serde_json::to_value(table).unwrap()
}

struct Validator<'a> {
    root: &'a Value,
}

impl Validator<'_> {
    fn resolve<'s>(&'s self, schema: &'s Value) -> &'s Value {
        match schema.get("$ref").and_then(Value::as_str) {
            Some(r) => {
                let name = r.strip_prefix("#/definitions/").expect("local $ref");
                &self.root["definitions"][name]
            }
            None => schema,
        }
    }

    /// The errors of `value` against `schema`, each with its JSON path.
    fn check(&self, schema: &Value, value: &Value, path: &str, errors: &mut Vec<String>) {
        if schema == &Value::Bool(true) {
            return;
        }
        let schema = self.resolve(schema);
        let Some(obj) = schema.as_object() else {
            errors.push(format!("{path}: schema is not an object"));
            return;
        };
        for (key, rule) in obj {
            match key.as_str() {
                "$ref" | "$schema" | "title" | "description" | "default" | "examples"
                | "definitions" | "format" => {}
                "type" => {
                    let types: Vec<&str> = match rule {
                        Value::String(t) => vec![t.as_str()],
                        Value::Array(a) => a.iter().filter_map(Value::as_str).collect(),
                        _ => panic!("{path}: bad type {rule}"),
                    };
                    if !types.iter().any(|t| has_type(value, t)) {
                        errors.push(format!("{path}: {value} is not of type {types:?}"));
                    }
                }
                "enum" => {
                    if !rule.as_array().unwrap().contains(value) {
                        errors.push(format!("{path}: {value} is not one of {rule}"));
                    }
                }
                "properties" => {
                    if let Some(v) = value.as_object() {
                        for (k, sub) in rule.as_object().unwrap() {
                            if let Some(x) = v.get(k) {
                                self.check(sub, x, &format!("{path}.{k}"), errors);
                            }
                        }
                    }
                }
                "required" => {
                    if let Some(v) = value.as_object() {
                        for k in rule.as_array().unwrap() {
                            if !v.contains_key(k.as_str().unwrap()) {
                                errors.push(format!("{path}: missing {k}"));
                            }
                        }
                    }
                }
                "additionalProperties" => {
                    if let Some(v) = value.as_object() {
                        let known = obj.get("properties").and_then(Value::as_object);
                        for (k, x) in v {
                            if known.is_some_and(|p| p.contains_key(k)) {
                                continue;
                            }
                            if rule == &Value::Bool(false) {
                                errors.push(format!("{path}: unknown key {k}"));
                            } else {
                                self.check(rule, x, &format!("{path}.{k}"), errors);
                            }
                        }
                    }
                }
                "propertyNames" => {
                    if let Some(v) = value.as_object() {
                        let pattern = rule["pattern"].as_str().unwrap();
                        for k in v.keys() {
                            if !matches_key_pattern(pattern, k) {
                                errors.push(format!("{path}: key {k} does not match {pattern}"));
                            }
                        }
                    }
                }
                "items" => {
                    if let Some(a) = value.as_array() {
                        match rule {
                            Value::Array(tuple) => {
                                for (i, (s, x)) in tuple.iter().zip(a).enumerate() {
                                    self.check(s, x, &format!("{path}[{i}]"), errors);
                                }
                            }
                            _ => {
                                for (i, x) in a.iter().enumerate() {
                                    self.check(rule, x, &format!("{path}[{i}]"), errors);
                                }
                            }
                        }
                    }
                }
                "minItems" | "maxItems" => {
                    if let Some(a) = value.as_array() {
                        let n = rule.as_u64().unwrap() as usize;
                        let bad = if key == "minItems" {
                            a.len() < n
                        } else {
                            a.len() > n
                        };
                        if bad {
                            errors.push(format!("{path}: {} items, {key} {n}", a.len()));
                        }
                    }
                }
                "minLength" => {
                    if let Some(s) = value.as_str()
                        && (s.chars().count() as u64) < rule.as_u64().unwrap()
                    {
                        errors.push(format!("{path}: string shorter than {rule}"));
                    }
                }
                "minimum" => {
                    if let Some(x) = value.as_f64()
                        && x < rule.as_f64().unwrap()
                    {
                        errors.push(format!("{path}: {x} below {rule}"));
                    }
                }
                "anyOf" => {
                    let ok = rule.as_array().unwrap().iter().any(|s| {
                        let mut e = Vec::new();
                        self.check(s, value, path, &mut e);
                        e.is_empty()
                    });
                    if !ok {
                        errors.push(format!("{path}: {value} matches no alternative"));
                    }
                }
                "allOf" => {
                    for s in rule.as_array().unwrap() {
                        self.check(s, value, path, errors);
                    }
                }
                other => panic!("{path}: the test's validator does not know `{other}`"),
            }
        }
    }
}

fn has_type(value: &Value, t: &str) -> bool {
    match t {
        "object" => value.is_object(),
        "array" => value.is_array(),
        "string" => value.is_string(),
        "number" => value.is_number(),
        "integer" => value.is_u64() || value.is_i64(),
        "boolean" => value.is_boolean(),
        "null" => value.is_null(),
        _ => panic!("unknown type {t}"),
    }
}

/// `^(base|p[0-9]+)$`: alternatives of a literal, optionally followed by `[0-9]+`.
fn matches_key_pattern(pattern: &str, key: &str) -> bool {
    let inner = pattern
        .strip_prefix("^(")
        .and_then(|p| p.strip_suffix(")$"))
        .expect("pattern of the form ^(a|b[0-9]+)$");
    inner
        .split('|')
        .any(|alt| match alt.strip_suffix("[0-9]+") {
            Some(prefix) => key
                .strip_prefix(prefix)
                .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())),
            None => key == alt,
        })
}

fn errors_of(value: &Value) -> Vec<String> {
    let root = schema();
    let v = Validator { root: &root };
    let mut errors = Vec::new();
    v.check(&root, value, "$", &mut errors);
    errors
}

#[test]
fn the_schema_is_json_with_the_top_level_sections() {
    let s = schema();
    assert_eq!(s["$schema"], "http://json-schema.org/draft-07/schema#");
    let props: Vec<&String> = s["properties"].as_object().unwrap().keys().collect();
    assert_eq!(props, ["channels", "daemon", "recording", "zenoh"]);
    assert_eq!(s["additionalProperties"], false);
    let defs = s["definitions"].as_object().unwrap();
    // Defaults and descriptions come through.
    let glr = &defs["GlrSpec"]["properties"];
    assert_eq!(glr["window"]["default"], 100);
    assert!(
        glr["window"]["description"]
            .as_str()
            .unwrap()
            .contains("eq. (37)")
    );
    // The keyword lists are enums.
    let kind = &defs["FaultSpec"]["properties"]["kind"]["enum"];
    assert!(kind.as_array().unwrap().contains(&"all_sensors".into()));
    // The hand-written schemas of the untagged types.
    assert!(defs["Matrix"]["anyOf"].as_array().unwrap().len() == 3);
    assert!(defs.contains_key("Entry"));
    // Every field of every object type has a description.
    for (name, def) in defs {
        if let Some(props) = def.get("properties").and_then(Value::as_object) {
            for (key, p) in props {
                let described = p.get("description").and_then(Value::as_str);
                assert!(
                    described.is_some_and(|d| d.len() > 10),
                    "{name}.{key} has no description"
                );
            }
        }
    }
}

#[test]
fn every_shipped_configuration_validates_against_the_schema() {
    for file in shipped_configs() {
        let text = std::fs::read_to_string(&file).unwrap();
        let errors = errors_of(&toml_to_json(&text));
        assert!(errors.is_empty(), "{}: {errors:#?}", file.display());
    }
}

#[test]
fn the_schema_refuses_what_the_parser_refuses() {
    let base = r#"
        [[channels]]
        name = "a"
        model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = { base = [[0.04]], p0 = [[0.01]] } }
        faults = [{ name = "b", kind = "sensor_bias", output = 0, psi = ["u0[-1]"] }]
        glr = { warm_up = "window" }
    "#;
    assert_eq!(errors_of(&toml_to_json(base)), Vec::<String>::new());
    for (bad, why) in [
        ("glr = { warm_up = \"window\" }", "glr = { windw = 3 }"),
        ("kind = \"sensor_bias\"", "kind = \"sensor_biass\""),
        ("p0 = [[0.01]]", "q0 = [[0.01]]"),
        (
            "glr = { warm_up = \"window\" }",
            "glr = { warm_up = \"full\" }",
        ),
        ("name = \"a\"", "nme = \"a\""),
    ] {
        let text = base.replace(bad, why);
        let errors = errors_of(&toml_to_json(&text));
        assert!(!errors.is_empty(), "{why} passed the schema");
        assert!(
            glrmon_spec::parse(&text).is_err(),
            "{why} passed the parser"
        );
    }
}
