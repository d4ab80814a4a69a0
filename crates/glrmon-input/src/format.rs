//! The one rule that tells a file's format from its name, for what glrmon reads
//! ([`InputFormat`]) and what it writes ([`OutputFormat`]).
//!
//! Every command that reads a recording or writes results decides here; a new
//! format is a variant (the compiler then names every place that must handle it).

use std::path::Path;

use glrmon_spec::Config;

use crate::{InputError, McapInput};

/// The format of a recording to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputFormat {
    /// Comma-separated values with a header row naming the columns.
    Csv,
    /// An MCAP recording: `.mcap` (any case), or a recording still being written
    /// (`.mcap.tmp`), read as an unfinished file.
    Mcap,
}

impl InputFormat {
    /// The format of the file at `path`, from its name.
    #[must_use]
    pub fn of(path: &Path) -> Self {
        if has_mcap_extension(path)
            || path
                .to_string_lossy()
                .ends_with(glrmon_record::PARTIAL_SUFFIX)
        {
            Self::Mcap
        } else {
            Self::Csv
        }
    }

    /// Whether files of this format carry the configuration they were made with (so
    /// that a command needs no `--config` for them).
    #[must_use]
    pub fn carries_config(self) -> bool {
        match self {
            Self::Csv => false,
            Self::Mcap => true,
        }
    }
}

/// The format a command writes its results in, for an output path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// An MCAP recording (`.mcap`, any case): inputs and records, replayable.
    Mcap,
    /// The command's text format: JSON lines of records (`replay`, `demo`), CSV
    /// samples (`simulate`).
    Text,
}

impl OutputFormat {
    /// The format of the output at `path`, from its name.
    #[must_use]
    pub fn of(path: &Path) -> Self {
        if has_mcap_extension(path) {
            Self::Mcap
        } else {
            Self::Text
        }
    }
}

fn has_mcap_extension(path: &Path) -> bool {
    path.extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("mcap"))
}

/// The configuration a recording carries, if its format carries one
/// ([`InputFormat::carries_config`]): `Ok(None)` for a CSV file.
///
/// # Errors
/// [`InputError`] when the recording cannot be read or its configuration is invalid.
pub fn embedded_config(path: &Path) -> Result<Option<Config>, InputError> {
    match InputFormat::of(path) {
        InputFormat::Csv => Ok(None),
        InputFormat::Mcap => McapInput::open(path)?.recorded_config().map(Some),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_follow_the_name() {
        for (path, input, output) in [
            ("a/b.MCAP", InputFormat::Mcap, OutputFormat::Mcap),
            ("x.mcap", InputFormat::Mcap, OutputFormat::Mcap),
            ("x.mcap.tmp", InputFormat::Mcap, OutputFormat::Text),
            ("b.csv", InputFormat::Csv, OutputFormat::Text),
            ("mcap", InputFormat::Csv, OutputFormat::Text),
            ("out.jsonl", InputFormat::Csv, OutputFormat::Text),
        ] {
            let p = Path::new(path);
            assert_eq!(
                (InputFormat::of(p), OutputFormat::of(p)),
                (input, output),
                "{path}"
            );
        }
    }
}
