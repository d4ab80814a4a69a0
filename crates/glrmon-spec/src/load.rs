//! Reading a configuration: the TOML text into the schema's types, then validated.

use std::path::Path;

use crate::schema::ConfigFile;
use crate::{Config, Problem, SpecErrors, locate, validate};

/// Reads and validates a configuration file.
///
/// # Errors
/// [`SpecErrors`] with every problem found (an unreadable file is one problem).
pub fn load(path: &Path) -> Result<Config, SpecErrors> {
    let text = std::fs::read_to_string(path).map_err(|e| SpecErrors {
        errors: vec![Problem {
            path: path.display().to_string(),
            message: format!("cannot read: {e}"),
            location: None,
        }],
    })?;
    parse(&text)
}

/// Parses and validates a configuration from TOML text.
///
/// # Errors
/// [`SpecErrors`] with every problem found.
pub fn parse(text: &str) -> Result<Config, SpecErrors> {
    let file: ConfigFile = toml::from_str(text).map_err(|e| SpecErrors {
        errors: vec![schema_error(text, &e)],
    })?;
    validate::config(file, text)
}

/// A file toml cannot deserialise: a syntax error keeps toml's rendering (its line, and
/// the line quoted with a caret); an error of the schema (an unknown key, a wrong type)
/// is located and, for an unknown key, gets the closest known one.
fn schema_error(text: &str, e: &toml::de::Error) -> Problem {
    let spans = locate::Spans::new(text);
    match e.span() {
        Some(span) if spans.parsed() => Problem {
            path: String::new(),
            message: locate::with_field_suggestion(e.message().trim_end()),
            location: Some(spans.location(span.start)),
        },
        _ => Problem {
            path: String::new(),
            message: e.to_string().trim_end().to_owned(),
            location: None,
        },
    }
}
