//! The error of opening and reading an input file.

use std::path::{Path, PathBuf};

use glrmon_wire::text::Escaped;

use crate::HeaderError;

/// An input file that could not be opened or read: the file, and what went wrong
/// ([`InputErrorKind`]). Its message names the file, and the row, channel or
/// column where there is one.
#[derive(Debug)]
pub struct InputError {
    path: PathBuf,
    kind: InputErrorKind,
}

/// What went wrong with an input file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InputErrorKind {
    /// An MCAP recording could not be opened (missing, not permitted). Invalid input.
    #[error("cannot open: {0}")]
    OpenRecording(std::io::Error),
    /// A CSV file could not be opened. Not counted as invalid input: the message is
    /// `opening <file>: <why>`, like other failures to open a file.
    #[error("cannot open: {0}")]
    OpenCsv(std::io::Error),
    /// The file is not an MCAP recording (no MCAP magic), or its first bytes cannot
    /// be read. Invalid input.
    #[error("{0}")]
    NotRecording(glrmon_record::ReadError),
    /// An I/O error while reading a recording's records (damage is not an error: it
    /// is skipped and reported by [`crate::McapInput::damage_report`]).
    #[error("cannot read: {0}")]
    Read(std::io::Error),
    /// A CSV header that does not fit the channel. Invalid input.
    #[error("{0}")]
    Header(HeaderError),
    /// A recording without a `glrmon` configuration, read where one is needed.
    /// Invalid input.
    #[error("no glrmon configuration is recorded in this file: give --config")]
    NoRecordedConfig,
    /// The configuration recorded in the file is not valid (any more). Invalid input.
    #[error("the recorded configuration is invalid:\n{0}")]
    RecordedConfig(glrmon_spec::SpecErrors),
    /// Data of the recording was lost to damage: the lines of
    /// [`crate::McapInput::damage_report`], for readers that need every sample
    /// ([`crate::Samples`]). Invalid input.
    #[error("{}", .0.join("; "))]
    Damaged(Vec<String>),
    /// A file read as named columns ([`crate::read_table`]) that cannot be used: the
    /// row and column, and why. Invalid input.
    #[error("{0}")]
    Table(String),
    /// A channel asked for (`glrmon play --channel`) that the recorded configuration
    /// does not have. Invalid input.
    #[error("channel \"{name}\" is not in the recorded configuration (channels: {})", known.join(", "))]
    UnknownChannel {
        /// The channel asked for.
        name: String,
        /// The recorded configuration's channels.
        known: Vec<String>,
    },
    /// A recording glrmon did not write that cannot be read as the configuration's
    /// `[channels.topics]` say (a damaged file, a topic the mapping names that is not
    /// in it). Invalid input.
    #[error("{0}")]
    Foreign(String),
}

impl InputError {
    /// An error of the file at `path`.
    #[must_use]
    pub fn new(path: &Path, kind: InputErrorKind) -> Self {
        Self {
            path: path.to_owned(),
            kind,
        }
    }

    /// The file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What went wrong.
    #[must_use]
    pub fn kind(&self) -> &InputErrorKind {
        &self.kind
    }

    /// What went wrong, by value (to take out an I/O error).
    #[must_use]
    pub fn into_kind(self) -> InputErrorKind {
        self.kind
    }

    /// Whether the user's input is at fault (a missing recording, a file that is not
    /// MCAP, a bad header or configuration, damage), as opposed to a failure of the
    /// machine (an I/O error while reading, a CSV file that cannot be opened). The
    /// `glrmon` binary exits with code 1 for the former and 3 for the latter.
    #[must_use]
    pub fn is_invalid_input(&self) -> bool {
        match self.kind {
            InputErrorKind::OpenRecording(_)
            | InputErrorKind::NotRecording(_)
            | InputErrorKind::Header(_)
            | InputErrorKind::NoRecordedConfig
            | InputErrorKind::RecordedConfig(_)
            | InputErrorKind::Damaged(_)
            | InputErrorKind::Table(_)
            | InputErrorKind::UnknownChannel { .. }
            | InputErrorKind::Foreign(_) => true,
            InputErrorKind::OpenCsv(_) | InputErrorKind::Read(_) => false,
        }
    }
}

impl std::fmt::Display for InputError {
    /// `<file>: <what and why>`; a CSV file that cannot be opened reads
    /// `opening <file>: <why>`, and damage lists the damaged parts alone.
    ///
    /// The file's name and everything the message quotes from the file (column and
    /// channel names, damage, the recorded configuration's errors) are shown escaped
    /// ([`glrmon_wire::text`]); only the recorded configuration's errors keep their
    /// line breaks, one escaped line each.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let path = self.path.to_string_lossy();
        let path = Escaped(&path);
        match &self.kind {
            InputErrorKind::OpenCsv(e) => write!(f, "opening {path}: {}", Escaped(&e.to_string())),
            InputErrorKind::Damaged(_) => write!(f, "{}", Escaped(&self.kind.to_string())),
            kind @ InputErrorKind::RecordedConfig(_) => {
                write!(f, "{path}: ")?;
                for (i, line) in kind.to_string().split('\n').enumerate() {
                    let sep = if i == 0 { "" } else { "\n" };
                    write!(f, "{sep}{}", Escaped(line))?;
                }
                Ok(())
            }
            kind => write!(f, "{path}: {}", Escaped(&kind.to_string())),
        }
    }
}

impl std::error::Error for InputError {}

#[cfg(test)]
mod tests {
    use super::*;

    fn io() -> std::io::Error {
        std::io::Error::new(std::io::ErrorKind::NotFound, "gone")
    }

    /// The messages users see, and which kinds are the user's fault.
    #[test]
    fn messages_and_classes() {
        let p = Path::new("d/x");
        let cases = [
            (
                InputErrorKind::OpenRecording(io()),
                "d/x: cannot open: gone",
                true,
            ),
            (InputErrorKind::OpenCsv(io()), "opening d/x: gone", false),
            (InputErrorKind::Read(io()), "d/x: cannot read: gone", false),
            (
                InputErrorKind::NotRecording(glrmon_record::ReadError::NotMcap),
                "d/x: not an MCAP file: the first 8 bytes are not the MCAP magic",
                true,
            ),
            (
                InputErrorKind::Header(HeaderError::Duplicate("y0".into())),
                "d/x: column \"y0\" appears twice in the header",
                true,
            ),
            (
                InputErrorKind::NoRecordedConfig,
                "d/x: no glrmon configuration is recorded in this file: give --config",
                true,
            ),
            (
                InputErrorKind::Damaged(vec!["damaged: a".into(), "damaged: b".into()]),
                "damaged: a; damaged: b",
                true,
            ),
            (
                InputErrorKind::Header(HeaderError::Unknown("y\u{1b}]0;pwned\u{7}".into())),
                r#"d/x: column "y\x1b]0;pwned\x07" is not one of k, t, u<i>, y<i>, p<i>"#,
                true,
            ),
            (
                InputErrorKind::UnknownChannel {
                    name: "a".into(),
                    known: vec!["b\n\u{202e}c".into()],
                },
                r#"d/x: channel "a" is not in the recorded configuration (channels: b\n\u{202e}c)"#,
                true,
            ),
        ];
        for (kind, message, invalid) in cases {
            let e = InputError::new(p, kind);
            assert_eq!(e.to_string(), message);
            assert_eq!(e.is_invalid_input(), invalid, "{message}");
            assert_eq!(e.path(), p);
        }
    }
}
