//! Sample CSV files (docs/CLI.md): a header row, then one sample per row, columns
//! `k` (optional), `t` (optional), `u0…`, `y0…`, `p0…`. Numbers only, no quoting.

use std::io::{BufRead, Write};

use glrmon_core::Dims;
use glrmon_wire::{ErrorCode, Sample};

/// Where each column of the file goes.
#[derive(Debug, Clone, Copy)]
enum Slot {
    K,
    T,
    U(usize),
    Y(usize),
    P(usize),
}

impl std::fmt::Display for Slot {
    /// The column's header name.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Slot::K => write!(f, "k"),
            Slot::T => write!(f, "t"),
            Slot::U(i) => write!(f, "u{i}"),
            Slot::Y(i) => write!(f, "y{i}"),
            Slot::P(i) => write!(f, "p{i}"),
        }
    }
}

/// A streaming reader of sample rows; memory stays flat in the file size.
pub(crate) struct CsvReader<R> {
    input: R,
    slots: Vec<Slot>,
    line: String,
    row: u64,
    dims: Dims,
}

/// A row that could not be turned into a sample.
#[derive(Debug)]
pub(crate) struct RowError {
    pub(crate) k: Option<u64>,
    pub(crate) code: ErrorCode,
    pub(crate) message: String,
}

impl<R: BufRead> CsvReader<R> {
    /// Reads the header and maps it onto the channel's dimensions.
    pub(crate) fn new(mut input: R, dims: Dims) -> Result<Self, String> {
        let mut header = String::new();
        input
            .read_line(&mut header)
            .map_err(|e| format!("cannot read the header: {e}"))?;
        let header = header.trim_end_matches(['\n', '\r']);
        if header.is_empty() {
            return Err("the file is empty: expected a header row (k, t, u0…, y0…, p0…)".into());
        }
        let mut slots = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for name in header.split(',').map(str::trim) {
            if !seen.insert(name.to_owned()) {
                return Err(format!("column \"{name}\" appears twice in the header"));
            }
            let index = |prefix: &str, count: usize, what: &str| -> Result<usize, String> {
                let i: usize = name[prefix.len()..].parse().map_err(|_| {
                    format!("column \"{name}\" is not one of k, t, u<i>, y<i>, p<i>")
                })?;
                if i >= count {
                    return Err(format!("column \"{name}\": the channel has {count} {what}"));
                }
                Ok(i)
            };
            let slot = match name {
                "k" => Slot::K,
                "t" => Slot::T,
                n if n.starts_with('u') => Slot::U(index("u", dims.inputs, "inputs")?),
                n if n.starts_with('y') => Slot::Y(index("y", dims.outputs, "outputs")?),
                n if n.starts_with('p') => Slot::P(index("p", dims.signals, "signals")?),
                n => {
                    return Err(format!(
                        "column \"{n}\" is not one of k, t, u<i>, y<i>, p<i>"
                    ));
                }
            };
            slots.push(slot);
        }
        for (prefix, count) in [("u", dims.inputs), ("y", dims.outputs), ("p", dims.signals)] {
            for i in 0..count {
                if !seen.contains(&format!("{prefix}{i}")) {
                    return Err(format!("column \"{prefix}{i}\" is missing from the header"));
                }
            }
        }
        Ok(Self {
            input,
            slots,
            line: String::new(),
            row: 1,
            dims,
        })
    }

    /// The next row into `sample`: `None` at the end of the file, `Some(Err)` for a bad
    /// row (the next call continues with the following row).
    pub(crate) fn next_into(&mut self, sample: &mut Sample) -> Option<Result<(), RowError>> {
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
        let fields = line.split(',').count();
        if fields != self.slots.len() {
            let msg = format!("has {fields} columns, the header has {}", self.slots.len());
            return Some(Err(self.err(None, ErrorCode::WrongDimension, msg)));
        }
        // k first, so that errors in other columns can name it.
        let mut k = None;
        for (text, slot) in line.split(',').zip(&self.slots) {
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
        for (text, slot) in line.split(',').zip(&self.slots) {
            let target: &mut f64 = match *slot {
                Slot::K => continue,
                Slot::T => sample.t.insert(0.0),
                Slot::U(i) => &mut sample.u[i],
                Slot::Y(i) => &mut sample.y[i],
                Slot::P(i) => &mut sample.p[i],
            };
            // The column's name is only formatted for an error (not for every value).
            match text.trim().parse::<f64>() {
                Ok(v) if v.is_finite() => *target = v,
                Ok(_) => {
                    let msg = format!("column {slot}: \"{}\" is not finite", text.trim());
                    return Some(Err(self.err(k, ErrorCode::NonFinite, msg)));
                }
                Err(_) => {
                    let msg = format!("column {slot}: \"{}\" is not a number", text.trim());
                    return Some(Err(self.err(k, ErrorCode::WrongType, msg)));
                }
            }
        }
        Some(Ok(()))
    }

    fn err(&self, k: Option<u64>, code: ErrorCode, message: String) -> RowError {
        RowError {
            k,
            code,
            message: format!("row {}: {message}", self.row),
        }
    }
}

/// Writes the header for a channel: `k`, then `t` when a period is known.
pub(crate) fn write_header(out: &mut impl Write, dims: Dims, with_t: bool) -> std::io::Result<()> {
    let mut cols = vec!["k".to_owned()];
    if with_t {
        cols.push("t".into());
    }
    cols.extend((0..dims.inputs).map(|i| format!("u{i}")));
    cols.extend((0..dims.outputs).map(|i| format!("y{i}")));
    cols.extend((0..dims.signals).map(|i| format!("p{i}")));
    writeln!(out, "{}", cols.join(","))
}

/// Writes one row; floats in their shortest exactly round-tripping form.
pub(crate) fn write_row(
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
