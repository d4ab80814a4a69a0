//! Recordings as named columns, for `glrmon identify`: every numeric column of a CSV
//! file, or a channel's u, y, p of an MCAP recording, cut into runs of consecutive
//! samples (identification must never join two runs).

use std::io::BufRead;
use std::path::Path;

use glrmon_runtime::InputItem;

use crate::{InputError, InputErrorKind, InputFormat, McapInput};

/// One run of consecutive samples: column names and their values, in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// The column names (`k` and the time column are not columns: `k` cuts runs, the
    /// time gives [`Table::period`]).
    pub names: Vec<String>,
    /// The values, one vector per column, all of the same length.
    pub columns: Vec<Vec<f64>>,
    /// The median time step of the time column (`t`, `time`, `timestamp` or `datetime`,
    /// in seconds or ISO 8601), when there is one.
    pub period: Option<f64>,
    /// Where the run starts: `row <n>` of a CSV file or `k = <k>` of a recording.
    pub start: String,
}

impl Table {
    /// Number of samples.
    #[must_use]
    pub fn samples(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// The column named `name`.
    #[must_use]
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(&self.columns[i])
    }
}

/// Reads `path` as runs of consecutive samples: a CSV file (a header, numbers only but
/// for the time column, `t`, `time`, `timestamp` or `datetime`, whose values may be
/// seconds or ISO 8601 times as in the sample reader, see [`crate::CsvReader`]; a new
/// run starts where the `k` column jumps), or channel `channel`'s inputs in an MCAP
/// recording (columns `u0…`, `y0…`, `p0…`; a new run starts after a refused, dropped or
/// missing sample). `channel` may be omitted when the recording has one channel.
///
/// # Examples
///
/// ```
/// let path = std::env::temp_dir().join(format!("glrmon-table-doc-{}.csv", std::process::id()));
/// std::fs::write(&path, "k,t,FI101,TI7\n0,0.0,1.5,20\n1,0.5,1.7,21\n5,2.5,1.6,22\n")?;
/// let runs = glrmon_input::read_table(&path, None)?;
/// assert_eq!(runs.len(), 2); // k jumps from 1 to 5
/// assert_eq!(runs[0].names, ["FI101", "TI7"]);
/// assert_eq!(runs[0].column("TI7"), Some(&[20.0, 21.0][..]));
/// assert_eq!(runs[0].period, Some(0.5));
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// An [`InputError`] naming the file and, for a bad value, its row and column
/// ([`InputErrorKind::Table`]); for a recording, one without channel `channel` (or with
/// several channels and none named).
pub fn read_table(path: &Path, channel: Option<&str>) -> Result<Vec<Table>, InputError> {
    match InputFormat::of(path) {
        InputFormat::Mcap => read_recording(path, channel),
        InputFormat::Csv => {
            read_csv(path).map_err(|why| InputError::new(path, InputErrorKind::Table(why)))
        }
    }
}

/// [`read_table`] for a configured channel: an MCAP recording glrmon did not write is
/// read through the channel's `[channels.topics]` ([`crate::ForeignSamples`]), with
/// the columns `u0…`, `y0…`, `p0…`, a new run starting after a message that could not
/// be read, a refused payload or a gap; any other file as [`read_table`] reads it for
/// the channel's name.
///
/// # Errors
/// As [`read_table`] and [`crate::ForeignSamples::open`]; a foreign recording that
/// gives the channel no sample.
pub fn read_table_for_channel(
    path: &Path,
    channel: &glrmon_spec::Channel,
) -> Result<Vec<Table>, InputError> {
    if channel.topics.is_none() || InputFormat::of(path) != InputFormat::Mcap {
        return read_table(path, Some(&channel.name));
    }
    let mut samples = crate::ForeignSamples::open(path, channel)?;
    let d = channel.dims;
    let names: Vec<String> = (0..d.inputs)
        .map(|i| format!("u{i}"))
        .chain((0..d.outputs).map(|i| format!("y{i}")))
        .chain((0..d.signals).map(|i| format!("p{i}")))
        .collect();
    let mut runs = Vec::new();
    let mut current: Option<Run> = None;
    let mut last_k: Option<u64> = None;
    while let Some(item) = samples.next_sample()? {
        let Ok(s) = item else {
            runs.extend(current.take());
            continue;
        };
        if matches!((s.k, last_k), (Some(k), Some(last)) if k != last + 1) {
            runs.extend(current.take());
        }
        last_k = s.k;
        let run =
            current.get_or_insert_with(|| Run::new(&names, format!("k = {}", s.k.unwrap_or(0))));
        for (c, v) in run
            .columns
            .iter_mut()
            .zip(s.u.iter().chain(&s.y).chain(&s.p))
        {
            c.push(*v);
        }
        if let Some(t) = s.t {
            run.t.push(t);
        }
    }
    runs.extend(current);
    let runs: Vec<Table> = runs
        .into_iter()
        .filter(|r| r.samples() > 0)
        .map(Run::finish)
        .collect();
    if runs.is_empty() {
        return Err(InputError::new(
            path,
            InputErrorKind::Table(format!(
                "the recording gives channel \"{}\" no sample through its [channels.topics]",
                channel.name
            )),
        ));
    }
    Ok(runs)
}

fn read_csv(path: &Path) -> Result<Vec<Table>, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("cannot open: {e}"))?;
    let mut lines = std::io::BufReader::new(file).lines();
    let header = match lines.next() {
        Some(line) => line.map_err(|e| format!("cannot read: {e}"))?,
        None => return Err("the file is empty: expected a header row".into()),
    };
    let separator = crate::separator_of(&header);
    let header: Vec<String> = (header.split(separator))
        .map(|s| s.trim().to_owned())
        .collect();
    for (i, name) in header.iter().enumerate() {
        if name.is_empty() {
            return Err(format!("column {} of the header has no name", i + 1));
        }
        if header[..i].contains(name) {
            return Err(format!("column \"{name}\" appears twice in the header"));
        }
    }
    let k_at = header.iter().position(|n| n == "k");
    let mut times = header
        .iter()
        .enumerate()
        .filter(|(_, n)| crate::csv::is_time_column(n));
    let t_at = times.next().map(|(i, _)| i);
    if let (Some(first), Some((_, second))) = (t_at, times.next()) {
        return Err(format!(
            "columns \"{}\" and \"{second}\" both give the sample time (t, time, timestamp, \
             datetime): keep one",
            header[first]
        ));
    }
    let names: Vec<String> = header
        .iter()
        .enumerate()
        .filter(|(i, _)| Some(*i) != k_at && Some(*i) != t_at)
        .map(|(_, n)| n.clone())
        .collect();
    let mut runs = Vec::new();
    let mut current = Run::new(&names, "row 2".into());
    let mut last_k: Option<u64> = None;
    let mut values = vec![0.0; header.len()];
    for (index, line) in lines.enumerate() {
        let row = index + 2;
        let line = line.map_err(|e| format!("row {row}: cannot read: {e}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(separator).collect();
        if fields.len() != header.len() {
            return Err(format!(
                "row {row}: has {} columns, the header has {}",
                fields.len(),
                header.len()
            ));
        }
        let mut k = None;
        for (i, text) in fields.iter().enumerate() {
            let text = text.trim();
            if Some(i) == k_at {
                k = Some(text.parse::<u64>().map_err(|_| {
                    format!("row {row}: column k: \"{text}\" is not a non-negative integer")
                })?);
                continue;
            }
            if Some(i) == t_at && crate::parse_value(text, separator).is_err() {
                // Not seconds: an ISO 8601 time (the sample reader's rule).
                values[i] = crate::csv::parse_time(text)
                    .map_err(|why| {
                        format!(
                            "row {row}: column {}: \"{text}\" is neither seconds nor an ISO \
                             8601 time (2026-11-27T08:00:20Z, 2026-11-27 08:00:20.5+01:00): {why}",
                            header[i]
                        )
                    })?
                    .seconds;
                continue;
            }
            values[i] = match crate::parse_value(text, separator) {
                Ok(v) if v.is_finite() => v,
                Ok(_) => {
                    return Err(format!(
                        "row {row}: column {}: \"{text}\" is not finite (identification needs \
                         complete data: cut the file there or fill the value)",
                        header[i]
                    ));
                }
                Err(_) => {
                    return Err(format!(
                        "row {row}: column {}: \"{text}\" is not a number",
                        header[i]
                    ));
                }
            };
        }
        if let (Some(k), Some(last)) = (k, last_k)
            && k != last + 1
        {
            if k <= last {
                return Err(format!(
                    "row {row}: k = {k} does not follow k = {last}: rows must be in order"
                ));
            }
            runs.push(std::mem::replace(
                &mut current,
                Run::new(&names, format!("row {row}")),
            ));
        }
        last_k = k;
        let mut column = 0;
        for (i, v) in values.iter().enumerate() {
            if Some(i) == k_at {
                continue;
            }
            if Some(i) == t_at {
                current.t.push(*v);
                continue;
            }
            current.columns[column].push(*v);
            column += 1;
        }
    }
    runs.push(current);
    Ok(runs
        .into_iter()
        .filter(|r| r.samples() > 0)
        .map(Run::finish)
        .collect())
}

fn read_recording(path: &Path, channel: Option<&str>) -> Result<Vec<Table>, InputError> {
    let mut input = McapInput::open(path)?;
    let config = input.recorded_config().ok();
    let channel = match (channel, &config) {
        (Some(c), _) => c.to_owned(),
        (None, Some(cfg)) if cfg.channels.len() == 1 => cfg.channels[0].name.clone(),
        (None, _) => {
            return Err(InputError::new(
                path,
                InputErrorKind::Table(
                    "the recording does not hold exactly one channel: name it with --channel"
                        .into(),
                ),
            ));
        }
    };
    let mut runs = Vec::new();
    let mut current: Option<Run> = None;
    let mut last_k: Option<u64> = None;
    let mut seen = false;
    let mut spare = None;
    while let Some(recorded) = input.next_input(spare.take())? {
        if *recorded.channel == *channel {
            seen = true;
            match &recorded.item {
                InputItem::Sample(s) => {
                    let k = s.k;
                    let cut = matches!((k, last_k), (Some(k), Some(last)) if k != last + 1);
                    if cut && let Some(run) = current.take() {
                        runs.push(run);
                    }
                    last_k = k;
                    let run = current.get_or_insert_with(|| {
                        let names: Vec<String> = (0..s.u.len())
                            .map(|i| format!("u{i}"))
                            .chain((0..s.y.len()).map(|i| format!("y{i}")))
                            .chain((0..s.p.len()).map(|i| format!("p{i}")))
                            .collect();
                        Run::new(&names, format!("k = {}", k.unwrap_or(0)))
                    });
                    if run.columns.len() == s.u.len() + s.y.len() + s.p.len() {
                        for (c, v) in run
                            .columns
                            .iter_mut()
                            .zip(s.u.iter().chain(&s.y).chain(&s.p))
                        {
                            c.push(*v);
                        }
                        if let Some(t) = s.t {
                            run.t.push(t);
                        }
                    } else if let Some(run) = current.take() {
                        runs.push(run);
                    }
                }
                _ => {
                    if let Some(run) = current.take() {
                        runs.push(run);
                    }
                }
            }
        }
        spare = Some(recorded);
    }
    if let Some(run) = current {
        runs.push(run);
    }
    if !seen {
        return Err(InputError::new(
            path,
            InputErrorKind::Table(format!(
                "the recording has no input of channel \"{channel}\""
            )),
        ));
    }
    Ok(runs
        .into_iter()
        .filter(|r| r.samples() > 0)
        .map(Run::finish)
        .collect())
}

struct Run {
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
    t: Vec<f64>,
    start: String,
}

impl Run {
    fn new(names: &[String], start: String) -> Self {
        Self {
            names: names.to_vec(),
            columns: vec![Vec::new(); names.len()],
            t: Vec::new(),
            start,
        }
    }

    fn samples(&self) -> usize {
        self.columns.first().map_or(self.t.len(), Vec::len)
    }

    fn finish(self) -> Table {
        let mut steps: Vec<f64> = self
            .t
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| d.is_finite() && *d > 0.0)
            .collect();
        steps.sort_by(f64::total_cmp);
        let period = steps.get(steps.len() / 2).copied();
        Table {
            names: self.names,
            columns: self.columns,
            period,
            start: self.start,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> std::path::PathBuf {
        let path = std::env::temp_dir().join(format!(
            "glrmon-table-{}-{}.csv",
            std::process::id(),
            text.len()
        ));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn bad_values_name_row_and_column() {
        let path = write("k,a,b\n0,1,2\n1,3,x\n");
        let e = read_table(&path, None).unwrap_err().to_string();
        assert!(e.contains("row 3: column b: \"x\" is not a number"), "{e}");
        let path = write("k,a,b\n0,1,2\n1,inf,1\n2,1,1\n");
        let e = read_table(&path, None).unwrap_err().to_string();
        assert!(e.contains("row 3: column a: \"inf\" is not finite"), "{e}");
        let path = write("k,a\n3,1\n2,1\n");
        let e = read_table(&path, None).unwrap_err().to_string();
        assert!(e.contains("k = 2 does not follow k = 3"), "{e}");
    }

    /// Identification reads a `;`-separated export with decimal commas as the
    /// `,`-separated one.
    #[test]
    fn semicolon_exports_with_decimal_commas_read_as_comma_separated_ones() {
        let comma =
            read_table(&write("t,FIC101,LI201\n0,1.5,20.25\n20,1.75,20.5\n"), None).unwrap();
        let semicolon =
            read_table(&write("t;FIC101;LI201\n0;1,5;20,25\n20;1,75;20,5\n"), None).unwrap();
        assert_eq!(comma.len(), 1);
        assert_eq!(semicolon.len(), 1);
        for name in ["FIC101", "LI201"] {
            assert_eq!(semicolon[0].column(name), comma[0].column(name), "{name}");
        }
        assert_eq!(comma[0].column("LI201"), Some(&[20.25, 20.5][..]));
    }

    /// An export's ISO 8601 time column is the time, whatever its case: it gives the
    /// period and is not a column; a malformed time names its row and column.
    #[test]
    fn iso_time_columns_give_the_period() {
        let runs = read_table(
            &write(
                "Timestamp,FIC101,LI201\n2026-11-27T08:00:00Z,1.5,20\n\
                 2026-11-27T08:00:20Z,1.6,21\n2026-11-27 08:00:40,1.7,22\n",
            ),
            None,
        )
        .unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].names, ["FIC101", "LI201"]);
        assert_eq!(runs[0].period, Some(20.0));
        let e = read_table(
            &write("k,time,FIC101\n0,2026-11-27T08:00:00Z,1\n1,2026-11-27T8:00:20Z,1\n"),
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains(
                "row 3: column time: \"2026-11-27T8:00:20Z\" is neither seconds nor an ISO \
                 8601 time"
            ),
            "{e}"
        );
        let e = read_table(&write("t,a,datetime\n0,1,2\n"), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("columns \"t\" and \"datetime\" both give the sample time"),
            "{e}"
        );
    }

    #[test]
    fn runs_without_k_are_one_run() {
        let path = write("a,b\n1,2\n3,4\n\n5,6\n");
        let runs = read_table(&path, None).unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].columns, [vec![1.0, 3.0, 5.0], vec![2.0, 4.0, 6.0]]);
        assert_eq!(runs[0].period, None);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// Any bytes, and any mix of CSV-like tokens, give runs or an error: never a
        /// panic, and every run's columns have one length.
        #[test]
        fn arbitrary_files_never_panic(
            bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
            tokens in proptest::collection::vec(
                proptest::sample::select(vec!["k", "t", "a", ",", "\n", "1", "-2.5", "1e308", "nan", "9", " ", "\r", "x"]),
                0..80,
            ),
        ) {
            let dir = std::env::temp_dir();
            for (i, content) in [bytes, tokens.concat().into_bytes()].into_iter().enumerate() {
                let path = dir.join(format!("glrmon-table-prop-{}-{i}.csv", std::process::id()));
                std::fs::write(&path, &content).unwrap();
                if let Ok(runs) = read_table(&path, None) {
                    for run in runs {
                        let n = run.samples();
                        proptest::prop_assert!(run.columns.iter().all(|c| c.len() == n));
                        proptest::prop_assert!(run.columns.iter().flatten().all(|v| v.is_finite()));
                    }
                }
            }
        }
    }
}
