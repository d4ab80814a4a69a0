//! One channel's samples from a CSV file or an MCAP recording, for the batch tools
//! (diagnosis, calibration) that read a channel from start to end.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use glrmon_core::Dims;
use glrmon_runtime::InputItem;
use glrmon_spec::{Channel, Columns};
use glrmon_wire::{IntakeEvent, Sample};

use crate::{CsvReader, ForeignSamples, InputError, InputErrorKind, InputFormat, McapInput};

/// The samples of one channel from a CSV file or an MCAP recording (chosen by
/// [`InputFormat::of`]), one at a time, with the problems of each in the order they occur.
///
/// # Examples
///
/// ```
/// use glrmon_core::Dims;
/// use glrmon_input::Samples;
/// use glrmon_wire::Sample;
///
/// let path = std::env::temp_dir().join(format!("glrmon-input-doc-{}.csv", std::process::id()));
/// std::fs::write(&path, "k,y0\n0,1\n1,x\n2,3\n")?;
/// let dims = Dims { states: 1, inputs: 0, outputs: 1, signals: 0 };
/// let mut samples = Samples::open(&path, "plant", dims)?;
/// let mut sample = Sample::default();
/// let mut seen = Vec::new();
/// while let Some(row) = samples.next_into(&mut sample)? {
///     seen.push(row.map(|()| sample.y[0]));
/// }
/// assert_eq!(seen[0], Ok(1.0));
/// assert_eq!(seen[1], Err(r#"row 3: column y0: "x" is not a number (wrong_type)"#.to_owned()));
/// assert_eq!(seen[2], Ok(3.0));
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct Samples {
    source: Source,
    /// Rows or recorded inputs of the channel read so far.
    read: u64,
}

/// A row or recorded input that gives no sample, and why: what a batch tool counts and
/// reports per reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// The reason as the wire's error code (`non_finite`, `wrong_type`, `too_large`, …),
    /// or `dropped` for payloads a recording says were lost at intake.
    pub reason: &'static str,
    /// What is wrong and where: `row <n>: column <name>: …` for a CSV row.
    pub message: String,
}

impl std::fmt::Display for Skipped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.message, self.reason)
    }
}

#[derive(Debug)]
enum Source {
    Csv(CsvReader<BufReader<File>>),
    Mcap(Box<McapInput>, String),
    Foreign(Box<ForeignSamples>),
}

impl Samples {
    /// Opens `path`: a CSV file of `channel`'s samples (its header checked against
    /// `dims`), or an MCAP recording, of which `channel`'s inputs are read.
    ///
    /// # Errors
    /// An [`InputError`] when the file cannot be opened, is not a recording, or its
    /// CSV header does not fit `dims`.
    pub fn open(path: &Path, channel: &str, dims: Dims) -> Result<Self, InputError> {
        Self::open_columns(path, channel, dims, &Columns::numbered(dims))
    }

    /// [`Samples::open`] for a configured channel: a CSV file's columns are the
    /// channel's `[channels.columns]` names; an MCAP recording glrmon did not write is
    /// read through the channel's `[channels.topics]` ([`ForeignSamples`]) when it has
    /// them.
    ///
    /// # Errors
    /// As [`Samples::open`] and [`ForeignSamples::open`].
    pub fn for_channel(path: &Path, channel: &Channel) -> Result<Self, InputError> {
        if channel.topics.is_some() && InputFormat::of(path) == InputFormat::Mcap {
            return Ok(Self {
                source: Source::Foreign(Box::new(ForeignSamples::open(path, channel)?)),
                read: 0,
            });
        }
        Self::open_columns(path, &channel.name, channel.dims, &channel.columns)
    }

    fn open_columns(
        path: &Path,
        channel: &str,
        dims: Dims,
        columns: &Columns,
    ) -> Result<Self, InputError> {
        let source = match InputFormat::of(path) {
            InputFormat::Mcap => Source::Mcap(Box::new(McapInput::open(path)?), channel.to_owned()),
            InputFormat::Csv => Source::Csv(CsvReader::open_with_columns(path, dims, columns)?),
        };
        Ok(Self { source, read: 0 })
    }

    /// Where the last row or input read came from: `row <n>` of a CSV file (the header
    /// being row 1), `input <n>` of the channel in a recording (from 1).
    #[must_use]
    pub fn position(&self) -> String {
        match &self.source {
            Source::Csv(csv) => format!("row {}", csv.row()),
            Source::Mcap(..) => format!("input {}", self.read),
            Source::Foreign(f) => format!("message {}", f.messages()),
        }
    }

    /// The next sample into `sample`; `Ok(None)` at the end, `Ok(Some(Err))` for a
    /// sample that cannot be used — a bad row (`row <n>: … (<code>)`), a refused or
    /// dropped payload in the recording — after which reading goes on.
    ///
    /// # Errors
    /// As [`Samples::next_checked`].
    pub fn next_into(
        &mut self,
        sample: &mut Sample,
    ) -> Result<Option<Result<(), String>>, InputError> {
        Ok(self
            .next_checked(sample)?
            .map(|r| r.map_err(|skip| skip.to_string())))
    }

    /// [`Samples::next_into`] with the reason of a skipped row or input kept apart
    /// from its message, for counting skips by reason.
    ///
    /// # Errors
    /// [`InputErrorKind::Read`] on an I/O error of a recording, and
    /// [`InputErrorKind::Damaged`] at the end of a recording that lost data to damage
    /// (its samples would not be the channel's consecutive samples).
    pub fn next_checked(
        &mut self,
        sample: &mut Sample,
    ) -> Result<Option<Result<(), Skipped>>, InputError> {
        match &mut self.source {
            Source::Csv(csv) => {
                let row = csv.next_into(sample).map(|r| {
                    r.map_err(|e| Skipped {
                        reason: e.code.as_str(),
                        message: e.message,
                    })
                });
                self.read += u64::from(row.is_some());
                Ok(row)
            }
            Source::Foreign(foreign) => {
                let item = foreign.next_sample()?;
                self.read += u64::from(item.is_some());
                Ok(item.map(|r| {
                    r.map(|s| {
                        *sample = s;
                    })
                }))
            }
            Source::Mcap(input, channel) => loop {
                let Some(recorded) = input.next_input(None)? else {
                    let (lines, damaged) = input.damage_report();
                    if damaged {
                        return Err(InputError::new(
                            input.path(),
                            InputErrorKind::Damaged(lines),
                        ));
                    }
                    return Ok(None);
                };
                if *recorded.channel != **channel {
                    continue;
                }
                self.read += 1;
                let at = self.read;
                return Ok(Some(match recorded.item {
                    InputItem::Sample(s) => {
                        *sample = s;
                        Ok(())
                    }
                    InputItem::Intake(IntakeEvent::Dropped { count }) => Err(Skipped {
                        reason: "dropped",
                        message: format!(
                            "input {at}: {count} payload(s) of channel \"{channel}\" were \
                             dropped at intake here"
                        ),
                    }),
                    InputItem::Intake(IntakeEvent::Rejected { code, message, .. }) => {
                        Err(Skipped {
                            reason: code.as_str(),
                            message: format!("input {at}: a refused payload: {message}"),
                        })
                    }
                    InputItem::Intake(IntakeEvent::Resumed { instance, .. }) => Err(Skipped {
                        reason: "resumed",
                        message: format!(
                            "input {at}: instance \"{instance}\" took channel \"{channel}\" \
                             over here, after samples it never saw"
                        ),
                    }),
                }));
            },
        }
    }
}
