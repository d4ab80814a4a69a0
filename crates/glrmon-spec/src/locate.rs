//! Where an error is in the file, and what the user may have meant.
//!
//! Errors found after deserialisation carry a path (`channels[0] "a": faults[1].psi`);
//! [`Spans`] parses the same text again with toml_edit, which keeps the byte spans of
//! keys and values, and maps such a path to the line and column of the deepest key it
//! names that the file has. [`did_you_mean`] picks the closest of the valid names by
//! edit distance, when one is close.

use std::ops::Range;

use toml_edit::{Item, Table, Value};

use crate::Location;

/// The spans of a configuration's keys (toml_edit's parse of the same text).
pub(crate) struct Spans<'a> {
    text: &'a str,
    doc: Option<toml_edit::Document<&'a str>>,
}

/// A step of a path: a key, or an index into an array (of tables).
#[derive(Debug, PartialEq)]
enum Step<'p> {
    Key(&'p str),
    Index(usize),
}

/// Where the walk is: a table, an item or a value.
#[derive(Clone, Copy)]
enum Node<'d> {
    Table(&'d Table),
    Item(&'d Item),
    Value(&'d Value),
}

impl<'d> Node<'d> {
    fn child(self, key: &str) -> Option<(Option<Range<usize>>, Node<'d>)> {
        let table = match self {
            Node::Table(t) => Some(t as &dyn toml_edit::TableLike),
            Node::Item(i) => i.as_table_like(),
            Node::Value(v) => v.as_inline_table().map(|t| t as &dyn toml_edit::TableLike),
        }?;
        let (k, item) = table.get_key_value(key)?;
        Some((k.span(), Node::Item(item)))
    }

    fn element(self, index: usize) -> Option<(Option<Range<usize>>, Node<'d>)> {
        match self {
            Node::Item(Item::ArrayOfTables(a)) => {
                let t = a.get(index)?;
                Some((t.span(), Node::Table(t)))
            }
            Node::Item(Item::Value(v)) | Node::Value(v) => {
                let e = v.as_array()?.get(index)?;
                Some((e.span(), Node::Value(e)))
            }
            _ => None,
        }
    }
}

impl<'a> Spans<'a> {
    /// Parses `text` (again); a text toml_edit refuses has no spans.
    pub(crate) fn new(text: &'a str) -> Self {
        Self {
            text,
            doc: toml_edit::Document::parse(text).ok(),
        }
    }

    /// Whether toml_edit parsed the text.
    pub(crate) fn parsed(&self) -> bool {
        self.doc.is_some()
    }

    /// The location of the field at `path`, a problem's path; `channels` are the
    /// channels' names in file order, to take the `channels[i] "name"` prefix apart.
    pub(crate) fn locate(&self, path: &str, channels: &[&str]) -> Option<Location> {
        let doc = self.doc.as_ref()?;
        let mut steps = Vec::new();
        let mut rest = path;
        for (i, name) in channels.iter().enumerate() {
            let prefix = format!("channels[{i}] \"{name}\"");
            if let Some(tail) = path.strip_prefix(&prefix) {
                steps.push(Step::Key("channels"));
                steps.push(Step::Index(i));
                rest = tail.strip_prefix(": ").unwrap_or("");
                if rest.is_empty() || tail.is_empty() {
                    // The channel itself: point at its name.
                    rest = "name";
                }
                break;
            }
        }
        parse_path(rest, &mut steps);
        let mut node = Node::Table(doc.as_table());
        let mut span = None;
        for step in &steps {
            let next = match step {
                Step::Key(k) => node.child(k),
                Step::Index(i) => node.element(*i),
            };
            let Some((s, n)) = next else { break };
            span = s.or(span);
            node = n;
        }
        span.map(|s| self.location(s.start))
    }

    /// The 1-based line and column (in characters) of byte `offset`.
    pub(crate) fn location(&self, offset: usize) -> Location {
        let before = self.text.get(..offset).unwrap_or(self.text);
        let line = before.matches('\n').count() + 1;
        let start = before.rfind('\n').map_or(0, |i| i + 1);
        let column = before[start..].chars().count() + 1;
        Location { line, column }
    }
}

/// `faults[2].psi[0]`, `glr.calibrated.isolation.x`, `faults[1] (y0)`, `model.H.p0`:
/// keys separated by dots, each with optional `[n]` indices; a trailing ` (…)` note
/// is dropped. A key that is not an identifier ends the path (it is prose).
fn parse_path<'p>(path: &'p str, steps: &mut Vec<Step<'p>>) {
    let path = path.split(" (").next().unwrap_or("");
    for part in path.split('.') {
        let (key, mut indices) = part.split_once('[').map_or((part, ""), |(k, i)| (k, i));
        let identifier = !key.is_empty()
            && key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !identifier {
            return;
        }
        steps.push(Step::Key(key));
        while let Some((index, tail)) = indices.split_once(']') {
            match index.parse() {
                Ok(i) => steps.push(Step::Index(i)),
                Err(_) => return,
            }
            indices = tail.strip_prefix('[').unwrap_or(tail);
        }
    }
}

/// Edit distance between `a` and `b`, in characters: insertions, deletions,
/// substitutions and transpositions of adjacent characters (`stpe` → `step` is 1) each
/// count 1 (the optimal string alignment distance).
fn distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let width = b.len() + 1;
    let mut d: Vec<usize> = vec![0; (a.len() + 1) * width];
    for i in 0..=a.len() {
        for j in 0..=b.len() {
            d[i * width + j] = if i == 0 || j == 0 {
                i + j
            } else {
                let cost = usize::from(a[i - 1] != b[j - 1]);
                let mut best = (d[(i - 1) * width + j] + 1)
                    .min(d[i * width + j - 1] + 1)
                    .min(d[(i - 1) * width + j - 1] + cost);
                if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                    best = best.min(d[(i - 2) * width + j - 2] + 1);
                }
                best
            };
        }
    }
    d[a.len() * width + b.len()]
}

/// The candidate closest to `word` by edit distance, when it is close: at most a third
/// of the word's length away (at least 1, so `windw` → `window`), or the same but for
/// case. `None` when nothing is close, or `word` is itself a candidate.
#[must_use]
pub fn did_you_mean<'c>(word: &str, candidates: &[&'c str]) -> Option<&'c str> {
    if candidates.contains(&word) {
        return None;
    }
    let limit = (word.chars().count() / 3).max(1);
    candidates
        .iter()
        .map(|c| {
            let d = if c.eq_ignore_ascii_case(word) {
                0
            } else {
                distance(word, c)
            };
            (d, *c)
        })
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

/// `"x" is not one of a, b, c`, with `; did you mean "b"?` when one is close.
pub(crate) fn not_one_of(value: &str, choices: &[&str]) -> String {
    let mut text = format!("\"{value}\" is not one of {}", choices.join(", "));
    if let Some(s) = did_you_mean(value, choices) {
        text.push_str(&format!("; did you mean \"{s}\"?"));
    }
    text
}

/// serde's `unknown field `windw`, expected one of `window`, `min_lag`, …` (or
/// `expected `a` or `b``), with `; did you mean `window`?` when one is close.
pub(crate) fn with_field_suggestion(message: &str) -> String {
    let Some(rest) = message.strip_prefix("unknown field `") else {
        return message.to_owned();
    };
    let Some((field, expected)) = rest.split_once('`') else {
        return message.to_owned();
    };
    let candidates: Vec<&str> = expected.split('`').skip(1).step_by(2).collect();
    match did_you_mean(field, &candidates) {
        Some(s) => format!("{message}; did you mean `{s}`?"),
        None => message.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_levenshtein() {
        assert_eq!(distance("", ""), 0);
        assert_eq!(distance("windw", "window"), 1);
        assert_eq!(distance("kitten", "sitting"), 3);
        assert_eq!(distance("ψ", "φ"), 1);
        assert_eq!(distance("stpe", "step"), 1);
        assert_eq!(distance("abc", ""), 3);
    }

    #[test]
    fn suggestions_only_when_close() {
        let fields = ["window", "min_lag", "threshold"];
        assert_eq!(did_you_mean("windw", &fields), Some("window"));
        assert_eq!(did_you_mean("treshold", &fields), Some("threshold"));
        assert_eq!(did_you_mean("colour", &fields), None);
        assert_eq!(did_you_mean("window", &fields), None);
        assert_eq!(did_you_mean("Window", &fields), Some("window"));
        assert_eq!(did_you_mean("x", &fields), None);
    }

    #[test]
    fn serde_messages_get_the_closest_field() {
        assert_eq!(
            with_field_suggestion("unknown field `windw`, expected one of `window`, `min_lag`"),
            "unknown field `windw`, expected one of `window`, `min_lag`; did you mean `window`?"
        );
        assert_eq!(
            with_field_suggestion("unknown field `zzz`, expected `window` or `min_lag`"),
            "unknown field `zzz`, expected `window` or `min_lag`"
        );
    }

    #[test]
    fn paths_split_into_keys_and_indices() {
        let mut steps = Vec::new();
        parse_path("faults[2].psi[0]", &mut steps);
        assert_eq!(
            steps,
            [
                Step::Key("faults"),
                Step::Index(2),
                Step::Key("psi"),
                Step::Index(0)
            ]
        );
        steps.clear();
        parse_path("faults[1] (y0)", &mut steps);
        assert_eq!(steps, [Step::Key("faults"), Step::Index(1)]);
        steps.clear();
        parse_path("model.H.p0", &mut steps);
        assert_eq!(steps, [Step::Key("model"), Step::Key("H"), Step::Key("p0")]);
    }
}
