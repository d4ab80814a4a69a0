//! `glrmon replay`: the monitor over recorded samples, as fast as possible, writing every
//! result record as JSON lines. The same input gives byte-identical output.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_wire::{ErrorRecord, Record, Sample, Stage, encode_json};

use crate::csv::CsvReader;
use crate::simulate::pick;
use crate::{InvalidInput, load_config, print};

#[derive(Debug, Args)]
pub(crate) struct ReplayArgs {
    /// Configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Channel the samples belong to (optional when the file has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// Recorded samples (CSV).
    input: PathBuf,
    /// Output JSON lines (default: standard output).
    #[arg(long)]
    output: Option<PathBuf>,
}

pub(crate) fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args.config)?;
    let channel = pick(&cfg, args.channel.as_deref())?;
    let file = std::fs::File::open(&args.input)
        .with_context(|| format!("opening {}", args.input.display()))?;
    let reader = std::io::BufReader::with_capacity(1 << 16, file);
    let mut csv = CsvReader::new(reader, channel.dims)
        .map_err(|e| InvalidInput(format!("{}: {e}", args.input.display())))?;
    let mut monitor = Monitor::from_channel(channel)?;
    let to_stdout = args.output.is_none();
    let mut out: Box<dyn Write> = match &args.output {
        Some(p) => Box::new(std::io::BufWriter::with_capacity(
            1 << 16,
            std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?,
        )),
        None => Box::new(std::io::BufWriter::new(std::io::stdout().lock())),
    };
    let summary = replay_into(&mut csv, &mut monitor, &mut out)?;
    out.flush()?;
    drop(out);
    let c = monitor.counters();
    let errors: u64 = c.errors.values().sum();
    let msg = format!(
        "glrmon replay: channel \"{}\": {} rows, {} samples, {} alarms, {} errors{}",
        channel.name,
        summary.rows,
        c.samples,
        c.alarms,
        errors,
        if to_stdout { "" } else { "; alarms:" }
    );
    eprintln!("{msg}");
    if !to_stdout {
        for line in &summary.alarm_lines {
            eprintln!("  {line}");
        }
    }
    Ok(())
}

pub(crate) struct Summary {
    pub(crate) rows: u64,
    pub(crate) alarm_lines: Vec<String>,
}

/// Feeds every row to the monitor and writes the records; bad rows become `error`
/// records and the replay continues.
pub(crate) fn replay_into<R: BufRead>(
    csv: &mut CsvReader<R>,
    monitor: &mut Monitor,
    out: &mut dyn Write,
) -> anyhow::Result<Summary> {
    let mut sample = Sample::default();
    let mut records = Vec::new();
    let mut buf = Vec::with_capacity(512);
    let mut summary = Summary {
        rows: 0,
        alarm_lines: Vec::new(),
    };
    while let Some(row) = csv.next_into(&mut sample) {
        summary.rows += 1;
        match row {
            Ok(()) => monitor.on_sample(&sample, &mut records),
            Err(e) => records.push(Record::Error(ErrorRecord {
                channel: monitor.channel().to_owned(),
                k: e.k,
                code: e.code,
                message: format!("channel \"{}\": {}", monitor.channel(), e.message),
                stage: Stage::Receiving,
            })),
        }
        for r in records.drain(..) {
            if let Some(line) = print::line(&r) {
                summary.alarm_lines.push(line);
            }
            buf.clear();
            encode_json(&r, &mut buf)?;
            buf.push(b'\n');
            out.write_all(&buf)?;
        }
    }
    Ok(summary)
}
