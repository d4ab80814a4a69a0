//! What [`parse`](crate::parse) reports: every problem of a configuration, each with the
//! path of the offending field and, when known, its line and column.

use std::fmt;

/// One problem in a configuration, with the path of the offending field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Where, e.g. `channels[1] "pump3": faults[2].psi[0]`.
    pub path: String,
    /// Why.
    pub message: String,
    /// The line and column of the offending key (or of the deepest enclosing key the
    /// file has) in the TOML text, when known.
    pub location: Option<Location>,
}

/// A position in the configuration's text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Location {
    /// Line, from 1.
    pub line: usize,
    /// Column in characters, from 1.
    pub column: usize,
}

impl Problem {
    /// The problem as a compiler prints it, `file.toml:12:5: channels[0] "a": …` (the
    /// file alone when the location is unknown).
    ///
    /// ```
    /// let text = "[[channels]]\nname = \"a\"\n[channels.model]\nF = [[0.9]]\nH = [[1.0, 0.0]]\nQ = 0.01\nR = 0.04\n";
    /// let errors = glrmon_spec::parse(text).unwrap_err();
    /// assert!(errors.errors.iter().any(|e| e
    ///     .in_file("plant.toml")
    ///     .starts_with("plant.toml:4:1: channels[0] \"a\": model.F is 1×1 but H has 2 columns")));
    /// ```
    #[must_use]
    pub fn in_file(&self, file: &str) -> String {
        match self.location {
            Some(l) => format!("{file}:{}:{}: {}", l.line, l.column, Body(self)),
            None => format!("{file}: {}", Body(self)),
        }
    }
}

/// A problem's path and message, without its location.
struct Body<'a>(&'a Problem);

impl fmt::Display for Body<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.0;
        // "model.F is 3×2 but …" reads as a sentence; other reasons follow a colon.
        let verb = ["is ", "has ", "names ", "cannot ", "evaluates ", "drives "];
        if p.path.is_empty() {
            write!(f, "{}", p.message)
        } else if verb.iter().any(|v| p.message.starts_with(v)) {
            write!(f, "{} {}", p.path, p.message)
        } else {
            write!(f, "{}: {}", p.path, p.message)
        }
    }
}

impl fmt::Display for Problem {
    /// The path and the message, `channels[0] "a": …`; [`Problem::in_file`] adds the
    /// file and the location, `file:12:5: …`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", Body(self))
    }
}

/// Every error found in a configuration.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct SpecErrors {
    /// The errors, in file order.
    pub errors: Vec<Problem>,
}

impl SpecErrors {
    /// Every problem as [`Problem::in_file`] prints it, one per line:
    /// `file.toml:12:5: channels[0] "a": …`.
    #[must_use]
    pub fn in_file(&self, file: &str) -> String {
        let lines: Vec<String> = self.errors.iter().map(|e| e.in_file(file)).collect();
        lines.join("\n")
    }
}

impl fmt::Display for SpecErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.errors.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}
