//! Sample CSV files: a header row, then one sample per row, columns `k` (optional),
//! a time column (optional), `u0…`, `y0…`, `p0…`. Numbers only, no quoting, but for
//! the time.
//!
//! # The time column
//!
//! The sample time `t` comes from the column named `t` or, in any case, `time`,
//! `timestamp` or `datetime` (an export's name for it), unless the
//! channel's `[channels.columns]` name that column as a signal. A file has at most one.
//! Each of its values is either a number of seconds (`t = 12.5`, as written by
//! [`write_row`]) or an ISO 8601 date and time, which becomes seconds since the Unix
//! epoch, 1970-01-01T00:00:00Z:
//!
//! | value | t |
//! |---|---|
//! | `2026-11-27T08:00:20Z` | 1795766420 |
//! | `2026-11-27T08:00:20.5+01:00` | 1795762820.5 (the offset applied: 07:00:20.5 UTC) |
//! | `2026-11-27 08:00:20` | 1795766420 (no offset: taken as UTC) |
//! | `2026-11-27T08:00` | 1795766400 |
//! | `2026-11-27` | 1795737600 (midnight, UTC) |
//!
//! The date and the time are separated by `T` or a space; the fraction of a second by
//! `.` or `,` (up to nanoseconds); the offset is `Z`, `±HH:MM`, `±HHMM` or `±HH`. A time
//! without an offset is taken as UTC: a plant historian set to local time must export
//! with its offset, or its times are off by it ([`CsvReader::naive_times`] tells whether
//! the file had such times). A time zone name (`…[Europe/Paris]`), a time out of range
//! (month 13, hour 25) or any other text is a bad row (`wrong_type`) naming the row, the
//! column and why, like a bad number. Values are parsed from the line as they are, with
//! no allocation (jiff's ISO 8601 parser).

use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;

use glrmon_core::Dims;
use glrmon_spec::Columns;
use glrmon_wire::{ErrorCode, Sample};

use crate::{InputError, InputErrorKind};

/// Where each column of the file goes.
#[derive(Debug, Clone, Copy)]
enum Slot {
    K,
    T,
    U(usize),
    Y(usize),
    P(usize),
    /// A column the configuration's `[channels.columns]` does not name: not read.
    Skip,
}

/// A streaming reader of sample rows; memory stays flat in the file size.
///
/// The header is checked against the channel's dimensions once, in
/// [`CsvReader::new`]; each row is then parsed into a caller's [`Sample`], so that a
/// long file is read without an allocation per row. A bad row is reported and
/// skipped: the next call goes on with the following row, as a live monitor goes on
/// after a refused payload.
///
/// # Examples
///
/// ```
/// use glrmon_core::Dims;
/// use glrmon_input::CsvReader;
/// use glrmon_wire::Sample;
///
/// let dims = Dims { states: 1, inputs: 0, outputs: 1, signals: 0 };
/// let file = "k,y0\n0,1.5\n1,oops\n2,2.5\n";
/// let mut rows = CsvReader::new(file.as_bytes(), dims)?;
/// let mut sample = Sample::default();
/// let mut good = Vec::new();
/// while let Some(row) = rows.next_into(&mut sample) {
///     match row {
///         Ok(()) => good.push((sample.k, sample.y[0])),
///         Err(bad) => assert_eq!(bad.message, r#"row 3: column y0: "oops" is not a number"#),
///     }
/// }
/// assert_eq!(good, [(Some(0), 1.5), (Some(2), 2.5)]);
/// # Ok::<(), glrmon_input::HeaderError>(())
/// ```
#[derive(Debug)]
pub struct CsvReader<R> {
    input: R,
    /// The field separator, found in the header ([`separator_of`]).
    separator: char,
    slots: Vec<Slot>,
    /// The header's column names, for messages.
    names: Vec<String>,
    line: String,
    row: u64,
    dims: Dims,
    /// Whether a time without an offset was read (taken as UTC).
    naive_times: bool,
}

/// A row that could not be turned into a sample: the monitor's answer to it is an
/// `error` record with this code and message, as for a refused live payload.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct RowError {
    /// The row's `k`, when it was read before the problem was found.
    pub k: Option<u64>,
    /// The wire's classification of the problem.
    pub code: ErrorCode,
    /// What is wrong and where: `row <n>: column <name>: …` (rows count from 1, the
    /// header being row 1).
    pub message: String,
}

/// A header that does not fit the channel: nothing can be read from such a file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HeaderError {
    /// The header row could not be read.
    #[error("cannot read the header: {0}")]
    Read(std::io::Error),
    /// The file has no header row.
    #[error("the file is empty: expected a header row (k, t, u0…, y0…, p0…)")]
    Empty,
    /// A column name appears twice: the row's value would be ambiguous.
    #[error("column \"{0}\" appears twice in the header")]
    Duplicate(String),
    /// A column name that is none of `k`, `t`, `u<i>`, `y<i>`, `p<i>`.
    #[error("column \"{0}\" is not one of k, t, u<i>, y<i>, p<i>")]
    Unknown(String),
    /// Two columns give the sample time (say `t` and `timestamp`): which to read would
    /// be a guess.
    #[error(
        "columns \"{0}\" and \"{1}\" both give the sample time (t, time, timestamp, \
         datetime): keep one"
    )]
    TwoTimes(String, String),
    /// A column beyond the channel's dimension (say `y3` for two outputs).
    #[error("column \"{column}\": the channel has {count} {what}")]
    OutOfRange {
        /// The column's name.
        column: String,
        /// How many of its kind the channel has.
        count: usize,
        /// Its kind: `inputs`, `outputs` or `signals`.
        what: &'static str,
    },
    /// A column the channel needs is absent.
    #[error("column \"{0}\" is missing from the header")]
    Missing(String),
}

impl CsvReader<BufReader<File>> {
    /// Opens a file and reads its header (see [`CsvReader::new`]).
    ///
    /// # Errors
    /// [`InputErrorKind::OpenCsv`] when the file cannot be opened,
    /// [`InputErrorKind::Header`] when its header does not fit `dims`.
    pub fn open(path: &Path, dims: Dims) -> Result<Self, InputError> {
        Self::open_with_columns(path, dims, &Columns::numbered(dims))
    }

    /// Opens a file and reads its header with the channel's column names (see
    /// [`CsvReader::with_columns`]).
    ///
    /// # Errors
    /// As [`CsvReader::open`].
    pub fn open_with_columns(
        path: &Path,
        dims: Dims,
        columns: &Columns,
    ) -> Result<Self, InputError> {
        let file =
            File::open(path).map_err(|e| InputError::new(path, InputErrorKind::OpenCsv(e)))?;
        let reader = BufReader::with_capacity(1 << 16, file);
        Self::with_columns(reader, dims, columns)
            .map_err(|e| InputError::new(path, InputErrorKind::Header(e)))
    }
}

impl<R: BufRead> CsvReader<R> {
    /// Reads the header and maps it onto the channel's dimensions: every `u<i>`,
    /// `y<i>` and `p<i>` of the channel must be there, in any order; `k` and `t` are
    /// optional.
    ///
    /// # Errors
    /// A [`HeaderError`] when the header cannot be read or does not fit `dims`.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_core::Dims;
    /// use glrmon_input::{CsvReader, HeaderError};
    ///
    /// let dims = Dims { states: 1, inputs: 0, outputs: 2, signals: 0 };
    /// let err = CsvReader::new("k,y0\n".as_bytes(), dims).unwrap_err();
    /// assert!(matches!(err, HeaderError::Missing(ref c) if c == "y1"));
    /// assert_eq!(err.to_string(), r#"column "y1" is missing from the header"#);
    /// ```
    pub fn new(input: R, dims: Dims) -> Result<Self, HeaderError> {
        Self::with_columns(input, dims, &Columns::numbered(dims))
    }

    /// A reader whose columns are named by `columns` (a channel's `[channels.columns]`):
    /// the named columns are read into u, y, p in the given order, `k` and `t` as
    /// usual, and when the names were given explicitly (`columns.named`) every other
    /// column is skipped, so that a plant's export with more signals than the model
    /// reads as it is. With numbered columns ([`Columns::numbered`]) an unknown column
    /// is an error, as in [`CsvReader::new`].
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_core::Dims;
    /// use glrmon_input::CsvReader;
    /// use glrmon_spec::Columns;
    /// use glrmon_wire::Sample;
    ///
    /// let dims = Dims { states: 1, inputs: 1, outputs: 1, signals: 0 };
    /// let columns = Columns {
    ///     u: vec!["FIC101".into()],
    ///     y: vec!["TI205".into()],
    ///     p: vec![],
    ///     named: true,
    ///     ..Columns::numbered(dims)
    /// };
    /// let file = "t,TI205,spare,FIC101\n0.5,71.2,9,3.1\n";
    /// let mut rows = CsvReader::with_columns(file.as_bytes(), dims, &columns)?;
    /// let mut sample = Sample::default();
    /// rows.next_into(&mut sample).unwrap().unwrap();
    /// assert_eq!((sample.u[0], sample.y[0]), (3.1, 71.2));
    /// # Ok::<(), glrmon_input::HeaderError>(())
    /// ```
    ///
    /// # Errors
    /// As [`CsvReader::new`]; a missing column is named as the configuration names it.
    pub fn with_columns(mut input: R, dims: Dims, columns: &Columns) -> Result<Self, HeaderError> {
        let mut header = String::new();
        input.read_line(&mut header).map_err(HeaderError::Read)?;
        let header = header.trim_end_matches(['\n', '\r']);
        if header.is_empty() {
            return Err(HeaderError::Empty);
        }
        let mut slots = Vec::new();
        let mut names: Vec<String> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let separator = separator_of(header);
        let mut time_at: Option<usize> = None;
        let mut time = |name: &str, names: &[String]| match time_at {
            Some(first) => Err(HeaderError::TwoTimes(names[first].clone(), name.to_owned())),
            None => {
                time_at = Some(names.len() - 1);
                Ok(Slot::T)
            }
        };
        for name in header.split(separator).map(str::trim) {
            if !seen.insert(name.to_owned()) {
                return Err(HeaderError::Duplicate(name.to_owned()));
            }
            names.push(name.to_owned());
            if columns.named {
                let find = |list: &[String]| list.iter().position(|c| c == name);
                let slot = match name {
                    "k" => Slot::K,
                    "t" => time(name, &names)?,
                    _ => match find(&columns.u)
                        .map(Slot::U)
                        .or_else(|| find(&columns.y).map(Slot::Y))
                        .or_else(|| find(&columns.p).map(Slot::P))
                    {
                        Some(slot) => slot,
                        None if is_time_column(name) => time(name, &names)?,
                        None => Slot::Skip,
                    },
                };
                slots.push(slot);
                continue;
            }
            let index = |prefix: &str, count: usize, what: &'static str| {
                let i: usize = name[prefix.len()..]
                    .parse()
                    .map_err(|_| HeaderError::Unknown(name.to_owned()))?;
                if i >= count {
                    return Err(HeaderError::OutOfRange {
                        column: name.to_owned(),
                        count,
                        what,
                    });
                }
                Ok(i)
            };
            let slot = match name {
                "k" => Slot::K,
                n if is_time_column(n) => time(n, &names)?,
                n if n.starts_with('u') => Slot::U(index("u", dims.inputs, "inputs")?),
                n if n.starts_with('y') => Slot::Y(index("y", dims.outputs, "outputs")?),
                n if n.starts_with('p') => Slot::P(index("p", dims.signals, "signals")?),
                n => return Err(HeaderError::Unknown(n.to_owned())),
            };
            slots.push(slot);
        }
        for list in [&columns.u, &columns.y, &columns.p] {
            if let Some(missing) = list.iter().find(|c| !seen.contains(c.as_str())) {
                return Err(HeaderError::Missing(missing.clone()));
            }
        }
        Ok(Self {
            input,
            separator,
            slots,
            names,
            line: String::new(),
            row: 1,
            dims,
            naive_times: false,
        })
    }

    /// Whether a time without a UTC offset (`2026-11-27 08:00:20`) was read so far:
    /// such times are taken as UTC, which a caller may want to say once.
    #[must_use]
    pub fn naive_times(&self) -> bool {
        self.naive_times
    }

    /// The next row into `sample`: `None` at the end of the file, `Some(Err)` for a bad
    /// row (the next call continues with the following row). Blank lines are skipped;
    /// `sample`'s vectors are resized to the channel's dimensions and overwritten, so
    /// one sample can be reused for the whole file.
    ///
    /// A read error of the underlying input is a bad row too (`cannot read: …`).
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_core::Dims;
    /// use glrmon_input::CsvReader;
    /// use glrmon_wire::{ErrorCode, Sample};
    ///
    /// let dims = Dims { states: 1, inputs: 1, outputs: 1, signals: 0 };
    /// let mut rows = CsvReader::new("t,u0,y0\n0.1,1,nan\n".as_bytes(), dims)?;
    /// let mut sample = Sample::default();
    /// let bad = rows.next_into(&mut sample).unwrap().unwrap_err();
    /// assert_eq!(bad.code, ErrorCode::NonFinite);
    /// assert_eq!(bad.message, r#"row 2: column y0: "nan" is not finite"#);
    /// assert!(rows.next_into(&mut sample).is_none());
    /// # Ok::<(), glrmon_input::HeaderError>(())
    /// ```
    pub fn next_into(&mut self, sample: &mut Sample) -> Option<Result<(), RowError>> {
        loop {
            self.line.clear();
            match self.input.read_line(&mut self.line) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(e) => {
                    self.row += 1;
                    return Some(Err(self.err(
                        None,
                        ErrorCode::InvalidJson,
                        format!("cannot read: {e}"),
                    )));
                }
            }
            self.row += 1;
            if !self.line.trim().is_empty() {
                break;
            }
        }
        sample.k = None;
        sample.t = None;
        sample.u.resize(self.dims.inputs, 0.0);
        sample.y.resize(self.dims.outputs, 0.0);
        sample.p.resize(self.dims.signals, 0.0);
        let line = self.line.trim_end_matches(['\n', '\r']);
        let fields = line.split(self.separator).count();
        if fields != self.slots.len() {
            let msg = format!("has {fields} columns, the header has {}", self.slots.len());
            return Some(Err(self.err(None, ErrorCode::WrongDimension, msg)));
        }
        // k first, so that errors in other columns can name it.
        let mut k = None;
        for (text, slot) in line.split(self.separator).zip(&self.slots) {
            if let Slot::K = slot {
                match text.trim().parse::<u64>() {
                    Ok(v) => k = Some(v),
                    Err(_) => {
                        let msg = format!(
                            "column k: \"{}\" is not a non-negative integer",
                            text.trim()
                        );
                        return Some(Err(self.err(None, ErrorCode::WrongType, msg)));
                    }
                }
            }
        }
        sample.k = k;
        let separator = self.separator;
        for ((text, slot), name) in line.split(separator).zip(&self.slots).zip(&self.names) {
            let target: &mut f64 = match *slot {
                Slot::K | Slot::Skip => continue,
                Slot::T => {
                    // Seconds, else an ISO 8601 time.
                    let text = text.trim();
                    match parse_value(text, separator) {
                        Ok(v) if v.is_finite() => sample.t = Some(v),
                        Ok(_) => {
                            let msg = format!("column {name}: \"{text}\" is not finite");
                            return Some(Err(self.err(k, ErrorCode::NonFinite, msg)));
                        }
                        Err(_) => match parse_time(text) {
                            Ok(time) => {
                                self.naive_times |= time.naive;
                                sample.t = Some(time.seconds);
                            }
                            Err(why) => {
                                let msg = format!(
                                    "column {name}: \"{text}\" is neither seconds nor an ISO \
                                     8601 time (2026-11-27T08:00:20Z, 2026-11-27 \
                                     08:00:20.5+01:00): {why}"
                                );
                                return Some(Err(self.err(k, ErrorCode::WrongType, msg)));
                            }
                        },
                    }
                    continue;
                }
                Slot::U(i) => &mut sample.u[i],
                Slot::Y(i) => &mut sample.y[i],
                Slot::P(i) => &mut sample.p[i],
            };
            // The column's name is only formatted for an error (not for every value).
            match parse_value(text.trim(), separator) {
                Ok(v) if v.is_finite() => *target = v,
                Ok(_) => {
                    let msg = format!("column {name}: \"{}\" is not finite", text.trim());
                    return Some(Err(self.err(k, ErrorCode::NonFinite, msg)));
                }
                Err(_) => {
                    let msg = format!("column {name}: \"{}\" is not a number", text.trim());
                    return Some(Err(self.err(k, ErrorCode::WrongType, msg)));
                }
            }
        }
        Some(Ok(()))
    }

    /// The row number (the header being row 1) of the row last read, blank lines
    /// counted: where a sample the monitor then refuses came from.
    #[must_use]
    pub fn row(&self) -> u64 {
        self.row
    }

    fn err(&self, k: Option<u64>, code: ErrorCode, message: String) -> RowError {
        RowError {
            k,
            code,
            message: format!("row {}: {message}", self.row),
        }
    }
}

/// Whether a column of this name gives the sample time: `t`, or `time`, `timestamp` or
/// `datetime` in any case (`Time`, `TIMESTAMP`), as exports name it.
#[must_use]
pub(crate) fn is_time_column(name: &str) -> bool {
    name == "t"
        || ["time", "timestamp", "datetime"]
            .iter()
            .any(|n| name.eq_ignore_ascii_case(n))
}

/// A time read from an ISO 8601 text.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Time {
    /// Seconds since 1970-01-01T00:00:00Z.
    pub(crate) seconds: f64,
    /// The text had no UTC offset (taken as UTC).
    pub(crate) naive: bool,
}

/// An ISO 8601 date and time (the module's table: `2026-11-27T08:00:20Z`,
/// `2026-11-27 08:00:20`, `2026-11-27T08:00:20.5+01:00`, a date alone) as seconds since
/// the Unix epoch; a time without an offset is UTC. Allocates nothing but for an error.
///
/// # Errors
/// Why the text is not such a time (jiff's reason, or a time zone name given instead of
/// an offset).
pub(crate) fn parse_time(text: &str) -> Result<Time, String> {
    use jiff::fmt::temporal::Pieces;
    let pieces = Pieces::parse(text).map_err(|e| e.to_string())?;
    if pieces.time_zone_annotation().is_some() {
        return Err("a time zone name is not read: give the UTC offset (+01:00)".into());
    }
    let date_time = pieces
        .date()
        .to_datetime(pieces.time().unwrap_or(jiff::civil::Time::midnight()));
    let offset = pieces.to_numeric_offset();
    let instant = offset
        .unwrap_or(jiff::tz::Offset::UTC)
        .to_timestamp(date_time)
        .map_err(|e| e.to_string())?;
    Ok(Time {
        seconds: instant.as_second() as f64 + f64::from(instant.subsec_nanosecond()) * 1e-9,
        naive: offset.is_none(),
    })
}

/// The field separator of a CSV file, from its header: `,` unless the header has
/// none and has `;` (the export of a spreadsheet or historian set to a locale whose
/// decimal mark is a comma) or a tab.
///
/// ```
/// use glrmon_input::separator_of;
/// assert_eq!(separator_of("k,t,FIC101"), ',');
/// assert_eq!(separator_of("k;t;FIC101"), ';');
/// assert_eq!(separator_of("k\tt\tFIC101"), '\t');
/// ```
#[must_use]
pub fn separator_of(header: &str) -> char {
    if header.contains(',') {
        ','
    } else if header.contains(';') {
        ';'
    } else if header.contains('\t') {
        '\t'
    } else {
        ','
    }
}

/// A value of a field: a number with a decimal point, or, in a file whose separator
/// is not `,`, with a decimal comma (`71,2` as 71.2). Allocates nothing.
///
/// ```
/// use glrmon_input::parse_value;
/// assert_eq!(parse_value("71.2", ','), Ok(71.2));
/// assert_eq!(parse_value("71,2", ';'), Ok(71.2));
/// assert_eq!(parse_value("-1,5e-3", ';'), Ok(-1.5e-3));
/// assert!(parse_value("71,2", ',').is_err());
/// ```
///
/// # Errors
/// The text is not a number.
pub fn parse_value(text: &str, separator: char) -> Result<f64, std::num::ParseFloatError> {
    match text.parse::<f64>() {
        Ok(v) => Ok(v),
        Err(e) if separator == ',' || !text.contains(',') || text.len() > 64 => Err(e),
        Err(_) => {
            let mut buf = [0u8; 64];
            let bytes = text.as_bytes();
            for (b, c) in buf.iter_mut().zip(bytes) {
                *b = if *c == b',' { b'.' } else { *c };
            }
            // The bytes are those of `text` with one ASCII byte for another: UTF-8 still.
            std::str::from_utf8(&buf[..bytes.len()])
                .unwrap_or("")
                .parse::<f64>()
        }
    }
}

/// Writes the header for a channel: `k`, then `t` when a period is known, then
/// `u0…`, `y0…`, `p0…` — the layout [`CsvReader`] reads.
///
/// # Errors
/// The writer's error.
pub fn write_header(out: &mut impl Write, dims: Dims, with_t: bool) -> std::io::Result<()> {
    let mut cols = vec!["k".to_owned()];
    if with_t {
        cols.push("t".into());
    }
    cols.extend((0..dims.inputs).map(|i| format!("u{i}")));
    cols.extend((0..dims.outputs).map(|i| format!("y{i}")));
    cols.extend((0..dims.signals).map(|i| format!("p{i}")));
    writeln!(out, "{}", cols.join(","))
}

/// Writes the header for a channel with its `[channels.columns]` names: `k`, `t` when a
/// period is known, then the columns read into u, y and p, so that
/// [`CsvReader::with_columns`] reads the file back (with numbered names this is
/// [`write_header`]).
///
/// # Errors
/// The writer's error.
pub fn write_header_named(
    out: &mut impl Write,
    columns: &glrmon_spec::Columns,
    with_t: bool,
) -> std::io::Result<()> {
    let mut cols = vec!["k"];
    if with_t {
        cols.push("t");
    }
    cols.extend(columns.u.iter().map(String::as_str));
    cols.extend(columns.y.iter().map(String::as_str));
    cols.extend(columns.p.iter().map(String::as_str));
    writeln!(out, "{}", cols.join(","))
}

/// Writes one row under a [`write_header`] header; floats in their shortest exactly
/// round-tripping form, so that reading the file back gives the same bits.
///
/// # Errors
/// The writer's error.
pub fn write_row(
    out: &mut impl Write,
    k: u64,
    t: Option<f64>,
    u: &[f64],
    y: &[f64],
    p: &[f64],
) -> std::io::Result<()> {
    write!(out, "{k}")?;
    if let Some(t) = t {
        write!(out, ",{t:?}")?;
    }
    for v in u.iter().chain(y).chain(p) {
        write!(out, ",{v:?}")?;
    }
    writeln!(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DIMS: Dims = Dims {
        states: 2,
        inputs: 1,
        outputs: 2,
        signals: 1,
    };

    fn read_all(text: &[u8]) -> Result<Vec<Result<Sample, RowError>>, HeaderError> {
        let mut reader = CsvReader::new(text, DIMS)?;
        let mut rows = Vec::new();
        let mut sample = Sample::default();
        while let Some(row) = reader.next_into(&mut sample) {
            rows.push(row.map(|()| sample.clone()));
        }
        Ok(rows)
    }

    /// A `;`-separated export with decimal commas reads as the `,`-separated one (it
    /// once failed with "column … is missing": the whole header read as one column);
    /// a tab-separated one too.
    #[test]
    fn semicolon_and_tab_exports_read_as_comma_separated_ones() {
        let comma = "k,t,u0,y0,y1,p0\n0,0.5,1.25,-3.5,2e-3,7\n1,1.0,1.5,-3.25,1e3,7\n";
        let semicolon = "k;t;u0;y0;y1;p0\n0;0,5;1,25;-3,5;2e-3;7\n1;1,0;1,5;-3,25;1e3;7\n";
        let tab = comma.replace(',', "\t");
        let want = read_all(comma.as_bytes()).unwrap();
        assert_eq!(want.len(), 2);
        assert!(want.iter().all(Result::is_ok));
        assert_eq!(read_all(semicolon.as_bytes()).unwrap(), want);
        assert_eq!(read_all(tab.as_bytes()).unwrap(), want);
        // A decimal comma in a comma-separated file is a column too many, as before.
        let bad = read_all("k,t,u0,y0,y1,p0\n0,0,5,1,2,3,4\n".as_bytes()).unwrap();
        assert_eq!(bad[0].as_ref().unwrap_err().code, ErrorCode::WrongDimension);
    }

    /// Reads `text` with the numbered columns of [`DIMS`]: (t, message of a bad row).
    fn times(text: &str) -> Vec<Result<Option<f64>, String>> {
        read_all(text.as_bytes())
            .unwrap()
            .into_iter()
            .map(|r| r.map(|s| s.t).map_err(|e| e.message))
            .collect()
    }

    /// An export's ISO 8601 time column gives `t` in seconds since the Unix epoch, with
    /// the offset applied and a time without one taken as UTC; a numeric time column
    /// keeps giving seconds.
    #[test]
    fn iso_times_become_seconds_since_the_epoch() {
        let t0 = 1_795_766_420.0; // 2026-11-27T08:00:20Z
        let cases = [
            ("2026-11-27T08:00:20Z", t0),
            ("2026-11-27T08:00:20z", t0),
            ("2026-11-27 08:00:20", t0),
            ("2026-11-27t08:00:20", t0),
            ("2026-11-27T08:00:20.5+01:00", t0 - 3600.0 + 0.5),
            ("2026-11-27T08:00:20.25-0230", t0 + 9000.0 + 0.25),
            ("2026-11-27T08:00:20+00", t0),
            ("2026-11-27T08:00", t0 - 20.0),
            ("2026-11-27", t0 - 8.0 * 3600.0 - 20.0),
            ("1970-01-01T00:00:00Z", 0.0),
            ("1969-12-31T23:59:59.5Z", -0.5),
        ];
        for name in ["t", "time", "Time", "timestamp", "TIMESTAMP", "datetime"] {
            for (text, want) in cases {
                let file = format!("{name},u0,y0,y1,p0\n{text},1,2,3,4\n");
                assert_eq!(times(&file), [Ok(Some(want))], "{name}: {text}");
            }
        }
        assert_eq!(times("time,u0,y0,y1,p0\n12.5,1,2,3,4\n"), [Ok(Some(12.5))]);
        // A ';' export: a decimal comma in the seconds and in the time.
        assert_eq!(
            times("Time;u0;y0;y1;p0\n2026-11-27 08:00:20,5;1;2;3;4\n12,5;1;2;3;4\n"),
            [Ok(Some(t0 + 0.5)), Ok(Some(12.5))]
        );
        let mut reader = CsvReader::new(
            "timestamp,u0,y0,y1,p0\n2026-11-27T08:00:20Z,1,2,3,4\n2026-11-27 08:00:21,1,2,3,4\n"
                .as_bytes(),
            DIMS,
        )
        .unwrap();
        let mut sample = Sample::default();
        reader.next_into(&mut sample).unwrap().unwrap();
        assert!(!reader.naive_times(), "an offset was given");
        reader.next_into(&mut sample).unwrap().unwrap();
        assert!(reader.naive_times(), "no offset: taken as UTC");
    }

    /// A malformed time is a bad row naming the row, the column and why, and reading
    /// goes on.
    #[test]
    fn a_malformed_time_is_a_bad_row() {
        let file = "k,timestamp,u0,y0,y1,p0\n\
                    0,2026-11-27T08:00:20Z,1,2,3,4\n\
                    1,2026-13-27T08:00:20Z,1,2,3,4\n\
                    2,27.11.2026 08:00,1,2,3,4\n\
                    3,2026-11-27T08:00:20[Europe/Paris],1,2,3,4\n\
                    4,2026-11-27T08:00:20Z junk,1,2,3,4\n\
                    5,,1,2,3,4\n\
                    6,inf,1,2,3,4\n\
                    7,2026-11-27T08:00:27Z,1,2,3,4\n";
        let rows = read_all(file.as_bytes()).unwrap();
        let errs: Vec<_> = rows
            .iter()
            .filter_map(|r| r.as_ref().err())
            .map(|e| (e.k, e.code, e.message.as_str()))
            .collect();
        assert_eq!(errs.len(), 6, "{errs:#?}");
        assert_eq!(errs[0].0, Some(1));
        assert_eq!(errs[0].1, ErrorCode::WrongType);
        assert!(
            errs[0].2.starts_with(
                "row 3: column timestamp: \"2026-13-27T08:00:20Z\" is neither seconds nor an \
                 ISO 8601 time (2026-11-27T08:00:20Z, 2026-11-27 08:00:20.5+01:00): "
            ) && errs[0].2.contains("month"),
            "{}",
            errs[0].2
        );
        assert!(
            errs[1]
                .2
                .starts_with("row 4: column timestamp: \"27.11.2026 08:00\"")
        );
        assert!(
            errs[2]
                .2
                .ends_with("a time zone name is not read: give the UTC offset (+01:00)")
        );
        assert!(errs[3].2.contains("junk"), "{}", errs[3].2);
        assert!(
            errs[4]
                .2
                .starts_with("row 7: column timestamp: \"\" is neither")
        );
        assert_eq!(
            (errs[5].1, errs[5].2),
            (
                ErrorCode::NonFinite,
                "row 8: column timestamp: \"inf\" is not finite"
            )
        );
        let good: Vec<_> = rows.iter().filter_map(|r| r.as_ref().ok()?.t).collect();
        assert_eq!(good, [1_795_766_420.0, 1_795_766_427.0]);
    }

    /// Two time columns are refused; with named columns, a configured signal called
    /// `Time` is a signal, and other time columns are the time.
    #[test]
    fn time_columns_in_the_header() {
        let err = read_all(b"t,u0,y0,y1,p0,Timestamp\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "columns \"t\" and \"Timestamp\" both give the sample time (t, time, timestamp, \
             datetime): keep one"
        );
        let dims = Dims {
            states: 1,
            inputs: 1,
            outputs: 1,
            signals: 0,
        };
        let columns = Columns {
            u: vec!["Time".into()],
            y: vec!["LI201".into()],
            p: vec![],
            named: true,
            ..Columns::numbered(dims)
        };
        let file = "datetime,LI201,spare,Time\n2026-11-27 08:00:20,62.3,x,5\n";
        let mut rows = CsvReader::with_columns(file.as_bytes(), dims, &columns).unwrap();
        let mut sample = Sample::default();
        rows.next_into(&mut sample).unwrap().unwrap();
        assert_eq!(
            (sample.t, sample.u[0], sample.y[0]),
            (Some(1_795_766_420.0), 5.0, 62.3)
        );
        let err =
            CsvReader::with_columns("time,LI201,Time,t\n".as_bytes(), dims, &columns).unwrap_err();
        assert!(matches!(err, HeaderError::TwoTimes(ref a, ref b) if a == "time" && b == "t"));
    }

    /// What `write_header`/`write_row` write reads back to the same bits.
    #[test]
    fn written_rows_read_back_exactly() {
        let mut out = Vec::new();
        write_header(&mut out, DIMS, true).unwrap();
        let values = [0.1, -1e-300, 1e300, 1.0 / 3.0, -0.0];
        for (k, v) in values.iter().enumerate() {
            let k = k as u64;
            write_row(
                &mut out,
                k,
                Some(k as f64 * 0.5),
                &[*v],
                &[v * 2.0, -v],
                &[*v],
            )
            .unwrap();
        }
        let rows = read_all(&out).unwrap();
        assert_eq!(rows.len(), values.len());
        for (k, (row, v)) in rows.into_iter().zip(values).enumerate() {
            let s = row.unwrap();
            assert_eq!(s.k, Some(k as u64));
            assert_eq!(s.t.map(f64::to_bits), Some((k as f64 * 0.5).to_bits()));
            assert_eq!(s.u[0].to_bits(), v.to_bits());
            assert_eq!(s.y[0].to_bits(), (v * 2.0).to_bits());
            assert_eq!(s.y[1].to_bits(), (-v).to_bits());
            assert_eq!(s.p[0].to_bits(), v.to_bits());
        }
    }

    /// Each header problem, with its message.
    #[test]
    fn header_problems() {
        let cases = [
            (
                "",
                "the file is empty: expected a header row (k, t, u0…, y0…, p0…)",
            ),
            (
                "k,u0,y0,y1,p0,y0",
                "column \"y0\" appears twice in the header",
            ),
            (
                "k,u0,y0,y1,p0,x",
                "column \"x\" is not one of k, t, u<i>, y<i>, p<i>",
            ),
            (
                "k,u0,y0,yy,p0",
                "column \"yy\" is not one of k, t, u<i>, y<i>, p<i>",
            ),
            ("u0,y0,y1,y2,p0", "column \"y2\": the channel has 2 outputs"),
            ("u0,y1,p0", "column \"y0\" is missing from the header"),
        ];
        for (header, message) in cases {
            let err = read_all(format!("{header}\n").as_bytes()).unwrap_err();
            assert_eq!(err.to_string(), message);
        }
    }

    /// Bad rows are reported with their row, column and code, and skipped.
    #[test]
    fn bad_rows_are_reported_and_skipped() {
        let text =
            "k,u0,y0,y1,p0\n0,1,2,3,4\n\n1,1,2\n-1,1,2,3,4\n2,1,inf,3,4\n3,1,x,3,4\n4,1,2,3,4\n";
        let rows = read_all(text.as_bytes()).unwrap();
        let errs: Vec<_> = rows
            .iter()
            .filter_map(|r| r.as_ref().err())
            .map(|e| (e.k, e.code, e.message.as_str()))
            .collect();
        assert_eq!(
            errs,
            [
                (
                    None,
                    ErrorCode::WrongDimension,
                    "row 4: has 3 columns, the header has 5"
                ),
                (
                    None,
                    ErrorCode::WrongType,
                    "row 5: column k: \"-1\" is not a non-negative integer"
                ),
                (
                    Some(2),
                    ErrorCode::NonFinite,
                    "row 6: column y0: \"inf\" is not finite"
                ),
                (
                    Some(3),
                    ErrorCode::WrongType,
                    "row 7: column y0: \"x\" is not a number"
                ),
            ]
        );
        let good: Vec<_> = rows.iter().filter_map(|r| r.as_ref().ok()?.k).collect();
        assert_eq!(good, [0, 4]);
    }

    proptest! {
        /// Arbitrary bytes, after a valid header or as a whole file, never panic: every
        /// row is a sample of the channel's dimensions or a row error, and reading ends.
        #[test]
        fn arbitrary_bytes_never_panic(
            body in proptest::collection::vec(any::<u8>(), 0..2048),
            with_header in any::<bool>(),
        ) {
            let mut text = Vec::new();
            if with_header {
                text.extend_from_slice(b"k,t,u0,y0,y1,p0\n");
            }
            text.extend_from_slice(&body);
            if let Ok(rows) = read_all(&text) {
                prop_assert!(rows.len() <= text.len());
                for row in rows {
                    match row {
                        Ok(s) => {
                            prop_assert_eq!((s.u.len(), s.y.len(), s.p.len()), (1, 2, 1));
                            prop_assert!(s.y.iter().chain(&s.u).chain(&s.p).all(|v| v.is_finite()));
                        }
                        Err(e) => prop_assert!(e.message.starts_with("row ")),
                    }
                }
            }
        }

        /// Rows of numbers and junk fields mixed: good rows read back exactly.
        #[test]
        fn mixed_rows_read_back(values in proptest::collection::vec((any::<f64>(), any::<bool>()), 1..64)) {
            let mut out = Vec::new();
            write_header(&mut out, DIMS, false).unwrap();
            for (k, (v, junk)) in values.iter().enumerate() {
                if *junk {
                    out.extend_from_slice(format!("{k},1,?,2,3\n").as_bytes());
                } else {
                    write_row(&mut out, k as u64, None, &[*v], &[*v, *v], &[*v]).unwrap();
                }
            }
            let rows = read_all(&out).unwrap();
            prop_assert_eq!(rows.len(), values.len());
            for (row, (v, junk)) in rows.iter().zip(&values) {
                match row {
                    Ok(s) => {
                        prop_assert!(!junk && v.is_finite());
                        prop_assert_eq!(s.y[1].to_bits(), v.to_bits());
                    }
                    Err(_) => prop_assert!(*junk || !v.is_finite()),
                }
            }
        }
    }
}
