//! `glrmon replay`: the monitors over recorded samples, as fast as possible, to the same
//! numbers as live. Input: a CSV file of one channel, or an MCAP recording (all its
//! channels, with the configuration recorded in it unless `--config` is given). Every
//! result goes to each output sink: JSON lines (default: standard output), an MCAP file
//! (inputs and results, self-describing), an HTML report.

use std::collections::HashMap;
use std::io::{BufRead, IsTerminal as _, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use anyhow::Context as _;
use clap::Args;
use glrmon_monitor::Monitor;
use glrmon_record::{FileHeader, McapFileSink};
use glrmon_runtime::{InputItem, InputOutput, Output, Sink};
use glrmon_wire::{
    DecodeLimits, ErrorRecord, IntakeEvent, Record, Sample, Stage, encode_intake, encode_json,
    encode_sample,
};

use crate::csv::CsvReader;
use crate::mcapin::{McapInput, is_mcap};
use crate::readahead::ReadAhead;
use crate::simulate::pick;
use crate::{InvalidInput, load_config, print};

#[derive(Debug, Args)]
pub(crate) struct ReplayArgs {
    /// Configuration file (optional for MCAP input: the recorded one is used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Channel to replay (CSV: optional when the config has one channel; MCAP: default
    /// every recorded channel).
    #[arg(long)]
    channel: Option<String>,
    /// Recorded samples: CSV (one channel) or MCAP (a `glrmon run` or `demo` recording).
    input: PathBuf,
    /// Output: JSON lines, or an MCAP file when the name ends in .mcap (default: JSON
    /// lines on standard output).
    #[arg(long)]
    output: Option<PathBuf>,
    /// Also write a self-contained HTML report (plots of the innovation, l_k, onset and
    /// magnitude, isolation tests, Lasso paths).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write every N-th `stat` record to the output (0: none; alarms, diagnoses and
    /// errors are always written). The report keeps its own decimation.
    #[arg(long, value_name = "N", default_value_t = 1)]
    stat_every: u64,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// The result sinks of a replay, fed on this thread in order.
struct Outputs {
    sinks: Vec<Box<dyn Sink>>,
    inputs_wanted: bool,
    alarm_lines: Vec<String>,
    records: u64,
    json: Vec<u8>,
}

impl Outputs {
    fn new(sinks: Vec<Box<dyn Sink>>) -> Self {
        let inputs_wanted = sinks.iter().any(|s| s.interest().inputs);
        Self {
            sinks,
            inputs_wanted,
            alarm_lines: Vec::new(),
            records: 0,
            json: Vec::with_capacity(512),
        }
    }

    /// Whether any output keeps `stat` records (if none does, the monitors need not
    /// build them).
    fn wants_stats(&self) -> bool {
        self.sinks
            .iter()
            .any(|s| s.interest().stat_every.unwrap_or(1) != 0)
    }

    fn input(&mut self, name: &Arc<str>, item: &InputItem, log_time_ns: u64) -> anyhow::Result<()> {
        if !self.inputs_wanted {
            return Ok(());
        }
        let mut json = Vec::with_capacity(128);
        match item {
            InputItem::Sample(s) => encode_sample(name, s, &mut json)?,
            InputItem::Intake(e) => encode_intake(name, e, &mut json)?,
        }
        let input = InputOutput {
            channel: 0,
            name: name.clone(),
            item: item.clone(),
            json,
            log_time_ns,
        };
        for s in &mut self.sinks {
            if s.interest().inputs {
                s.write_input(&input).map_err(|e| anyhow::anyhow!("{e}"))?;
            }
        }
        Ok(())
    }

    /// Encodes and writes the records of one input; `stats` counts the channel's
    /// `stat` records so far (the sinks' decimation counts them).
    fn records(
        &mut self,
        stats: &mut u64,
        records: &mut Vec<Record>,
        log_time_ns: u64,
    ) -> anyhow::Result<()> {
        for record in records.drain(..) {
            if let Some(line) = print::line(&record) {
                if !matches!(record, Record::Error(_)) {
                    self.alarm_lines.push(line);
                }
            }
            let stat_index = if matches!(record, Record::Stat(_)) {
                *stats += 1;
                Some(*stats - 1)
            } else {
                None
            };
            let wanted = |s: &dyn Sink| match stat_index {
                Some(i) => {
                    let every = s.interest().stat_every.unwrap_or(1);
                    every != 0 && i % every == 0
                }
                None => true,
            };
            if !self.sinks.iter().any(|s| wanted(s.as_ref())) {
                continue;
            }
            self.records += 1;
            self.json.clear();
            encode_json(&record, &mut self.json)?;
            let output = Output {
                record,
                json: std::mem::take(&mut self.json),
                log_time_ns,
                stat_index,
            };
            for s in &mut self.sinks {
                if wanted(s.as_ref()) {
                    s.write(&output).map_err(|e| anyhow::anyhow!("{e}"))?;
                }
            }
            self.json = output.json;
        }
        Ok(())
    }

    fn finish(self) -> anyhow::Result<()> {
        for mut s in self.sinks {
            s.flush().map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        Ok(())
    }
}

/// JSON lines of every record (`stat` records decimated: every `.1`-th, 0 for none).
struct JsonLines<W: Write + Send>(W, u64);

impl<W: Write + Send + 'static> Sink for JsonLines<W> {
    fn name(&self) -> &str {
        "jsonl"
    }
    fn interest(&self) -> glrmon_runtime::Interest {
        glrmon_runtime::Interest {
            inputs: false,
            stat_every: Some(self.1),
        }
    }
    fn write(&mut self, output: &Output) -> Result<(), glrmon_runtime::SinkError> {
        self.0
            .write_all(&output.json)
            .and_then(|()| self.0.write_all(b"\n"))
            .map_err(|e| glrmon_runtime::SinkError {
                sink: "jsonl".into(),
                message: e.to_string(),
            })
    }
    fn flush(&mut self) -> Result<(), glrmon_runtime::SinkError> {
        self.0.flush().map_err(|e| glrmon_runtime::SinkError {
            sink: "jsonl".into(),
            message: e.to_string(),
        })
    }
}

/// An MCAP output, finished when the replay ends (`stat` records decimated as for
/// [`JsonLines`]).
struct McapOut(Option<McapFileSink>, u64);

impl Sink for McapOut {
    fn name(&self) -> &str {
        "mcap"
    }
    fn interest(&self) -> glrmon_runtime::Interest {
        glrmon_runtime::Interest {
            inputs: true,
            stat_every: Some(self.1),
        }
    }
    fn write(&mut self, output: &Output) -> Result<(), glrmon_runtime::SinkError> {
        self.0.as_mut().map_or(Ok(()), |s| s.write(output))
    }
    fn write_input(&mut self, input: &InputOutput) -> Result<(), glrmon_runtime::SinkError> {
        self.0.as_mut().map_or(Ok(()), |s| s.write_input(input))
    }
    fn flush(&mut self) -> Result<(), glrmon_runtime::SinkError> {
        match self.0.take() {
            Some(s) => s
                .finish()
                .map(|_| ())
                .map_err(|e| glrmon_runtime::SinkError {
                    sink: "mcap".into(),
                    message: e.to_string(),
                }),
            None => Ok(()),
        }
    }
}

fn output_sinks(args: &ReplayArgs, header: &FileHeader) -> anyhow::Result<Vec<Box<dyn Sink>>> {
    let mut sinks: Vec<Box<dyn Sink>> = Vec::new();
    match &args.output {
        Some(p) if is_mcap(p) => {
            let sink = McapFileSink::create(p, header)
                .with_context(|| format!("creating {}", p.display()))?;
            sinks.push(Box::new(McapOut(Some(sink), args.stat_every)));
        }
        Some(p) => {
            let file =
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
            sinks.push(Box::new(JsonLines(
                std::io::BufWriter::with_capacity(1 << 16, file),
                args.stat_every,
            )));
        }
        None => sinks.push(Box::new(JsonLines(
            std::io::BufWriter::with_capacity(1 << 16, std::io::stdout()),
            args.stat_every,
        ))),
    }
    if let Some(p) = &args.report {
        sinks.push(Box::new(crate::report::ReportSink::new(p, &args.input)));
    }
    Ok(sinks)
}

pub(crate) fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    if is_mcap(&args.input) {
        replay_mcap(args)
    } else {
        replay_csv(args)
    }
}

fn replay_csv(args: &ReplayArgs) -> anyhow::Result<()> {
    let Some(config) = &args.config else {
        return Err(InvalidInput(format!(
            "{}: a CSV file needs --config (only MCAP recordings carry their configuration)",
            args.input.display()
        ))
        .into());
    };
    let cfg = load_config(config)?;
    let channel = pick(&cfg, args.channel.as_deref())?;
    let file = std::fs::File::open(&args.input)
        .with_context(|| format!("opening {}", args.input.display()))?;
    let reader = std::io::BufReader::with_capacity(1 << 16, file);
    let csv = CsvReader::new(reader, channel.dims)
        .map_err(|e| InvalidInput(format!("{}: {e}", args.input.display())))?;
    let mut monitor = Monitor::from_channel(channel)?;
    let header = FileHeader {
        config: cfg.source.clone(),
        channels: vec![channel.name.clone()],
        extra: std::collections::BTreeMap::from([(
            "source".to_owned(),
            args.input.display().to_string(),
        )]),
    };
    let mut outputs = Outputs::new(output_sinks(args, &header)?);
    monitor.set_stat_records(outputs.wants_stats());
    let (rows, rejected) = replay_csv_into(csv, &mut monitor, &mut outputs)?;
    let alarm_lines = std::mem::take(&mut outputs.alarm_lines);
    outputs.finish()?;
    let c = monitor.counters();
    let errors: u64 = c.errors.values().sum::<u64>() + rejected;
    eprintln!(
        "glrmon replay: channel \"{}\": {rows} rows, {} samples, {} alarms, {errors} errors",
        channel.name, c.samples, c.alarms,
    );
    if args.output.is_some() {
        for line in &alarm_lines {
            eprintln!("  {line}");
        }
    }
    Ok(())
}

/// Feeds every row to the monitor, the rows parsed ahead on a reader thread; bad rows
/// become `error` records and the replay continues. Returns the number of rows and of
/// rows rejected.
fn replay_csv_into<R: BufRead + Send + 'static>(
    csv: CsvReader<R>,
    monitor: &mut Monitor,
    outputs: &mut Outputs,
) -> anyhow::Result<(u64, u64)> {
    let name: Arc<str> = Arc::from(monitor.channel());
    let mut rows_ahead = ReadAhead::spawn(csv, |csv, spare| {
        let mut sample = match spare {
            Some(Ok(sample)) => sample,
            _ => Sample::default(),
        };
        // A bad row keeps the time it may have carried, for the record's log time.
        Ok(csv.next_into(&mut sample).map(|row| match row {
            Ok(()) => Ok(sample),
            Err(e) => Err((e, sample.t)),
        }))
    })?;
    let mut records = Vec::new();
    let (mut rows, mut rejected, mut stats) = (0, 0, 0);
    while let Some(row) = rows_ahead.next()? {
        rows += 1;
        match row {
            Ok(sample) => {
                let log_time = glrmon_record::publish_time(sample.t, 0);
                if outputs.inputs_wanted {
                    outputs.input(&name, &InputItem::Sample(sample.clone()), log_time)?;
                }
                monitor.on_sample(&sample, &mut records);
                outputs.records(&mut stats, &mut records, log_time)?;
                rows_ahead.recycle(Ok(sample));
            }
            Err((e, t)) => {
                rejected += 1;
                let log_time = glrmon_record::publish_time(t, 0);
                let message = format!("channel \"{}\": {}", monitor.channel(), e.message);
                outputs.input(
                    &name,
                    &InputItem::Intake(IntakeEvent::Rejected {
                        code: e.code,
                        message: message.clone(),
                        payload: None,
                    }),
                    log_time,
                )?;
                records.push(Record::Error(ErrorRecord {
                    channel: monitor.channel().to_owned(),
                    k: e.k,
                    code: e.code,
                    message,
                    stage: Stage::Receiving,
                }));
                outputs.records(&mut stats, &mut records, log_time)?;
            }
        }
    }
    rows_ahead.finish()?;
    Ok((rows, rejected))
}

fn replay_mcap(args: &ReplayArgs) -> anyhow::Result<()> {
    let mut input = McapInput::open(&args.input)?;
    let cfg = match (&args.config, &input.header) {
        (Some(path), _) => load_config(path)?,
        (None, Some(h)) if !h.config.is_empty() => glrmon_spec::parse(&h.config).map_err(|e| {
            InvalidInput(format!(
                "{}: the recorded configuration is invalid:\n{e}",
                args.input.display()
            ))
        })?,
        _ => {
            return Err(InvalidInput(format!(
                "{}: no glrmon configuration is recorded in this file: give --config",
                args.input.display()
            ))
            .into());
        }
    };
    if let Some(name) = &args.channel {
        if cfg.channel(name).is_none() {
            return Err(InvalidInput(format!(
                "no channel \"{name}\" in the configuration (channels: {})",
                cfg.channels
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
            .into());
        }
    }
    input.set_limits(DecodeLimits {
        max_payload_bytes: cfg.daemon.max_payload_bytes,
        ..DecodeLimits::default()
    });
    // The replayed channels with their `stat` counts, found by name (the last one
    // looked up is remembered: consecutive inputs of a channel share its name).
    let mut channels: Vec<(Monitor, u64)> = Vec::new();
    let mut order: Vec<Arc<str>> = Vec::new();
    let mut index: HashMap<Arc<str>, usize> = HashMap::new();
    for c in &cfg.channels {
        if args.channel.as_ref().is_none_or(|n| *n == c.name) {
            let name: Arc<str> = Arc::from(c.name.as_str());
            index.insert(name.clone(), channels.len());
            channels.push((Monitor::from_channel(c)?, 0));
            order.push(name);
        }
    }
    let mut last: Option<(Arc<str>, usize)> = None;
    let header = FileHeader {
        config: cfg.source.clone(),
        channels: order.iter().map(|c| c.to_string()).collect(),
        extra: std::collections::BTreeMap::from([(
            "source".to_owned(),
            args.input.display().to_string(),
        )]),
    };
    let mut outputs = Outputs::new(output_sinks(args, &header)?);
    for (monitor, _) in &mut channels {
        monitor.set_stat_records(outputs.wants_stats());
    }
    let progress = (!args.quiet && std::io::stderr().is_terminal()).then(|| {
        let bar = indicatif::ProgressBar::new(input.progress.1);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40} {bytes}/{total_bytes} {bytes_per_sec} eta {eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    let mut records = Vec::new();
    let mut unknown: HashMap<Arc<str>, u64> = HashMap::new();
    let mut rejected: HashMap<Arc<str>, u64> = HashMap::new();
    let mut inputs = 0u64;
    let started = std::time::Instant::now();
    let progress_bytes = input.progress.0.clone();
    let mut inputs_ahead = ReadAhead::spawn(input, |input, spare| input.next_input(spare))?;
    while let Some(recorded) = inputs_ahead.next()? {
        inputs += 1;
        if inputs % 65_536 == 0 {
            if let Some(bar) = &progress {
                bar.set_position(progress_bytes.load(Ordering::Relaxed));
            }
        }
        let found = match &last {
            Some((name, i)) if Arc::ptr_eq(name, &recorded.channel) => Some(*i),
            _ => index.get(&recorded.channel).copied().inspect(|i| {
                last = Some((recorded.channel.clone(), *i));
            }),
        };
        let Some((monitor, stats)) = found.map(|i| &mut channels[i]) else {
            if args.channel.is_none() {
                *unknown.entry(recorded.channel.clone()).or_insert(0) += 1;
            }
            inputs_ahead.recycle(recorded);
            continue;
        };
        let log_time = recorded.log_time_ns;
        outputs.input(&recorded.channel, &recorded.item, log_time)?;
        match &recorded.item {
            InputItem::Sample(s) => monitor.on_sample(s, &mut records),
            InputItem::Intake(IntakeEvent::Dropped { count }) => monitor.note_missing(*count),
            InputItem::Intake(IntakeEvent::Rejected { code, message, .. }) => {
                *rejected.entry(recorded.channel.clone()).or_insert(0) += 1;
                records.push(Record::Error(ErrorRecord {
                    channel: recorded.channel.to_string(),
                    k: None,
                    code: *code,
                    message: message.clone(),
                    stage: Stage::Receiving,
                }));
            }
        }
        outputs.records(stats, &mut records, log_time)?;
        inputs_ahead.recycle(recorded);
    }
    let input = inputs_ahead.finish()?;
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    let elapsed = started.elapsed().as_secs_f64();
    let alarm_lines = std::mem::take(&mut outputs.alarm_lines);
    let written = outputs.records;
    outputs.finish()?;
    eprintln!(
        "glrmon replay: {}: {} messages, {inputs} inputs replayed in {elapsed:.2} s, {written} records written",
        args.input.display(),
        input.messages(),
    );
    for (name, (monitor, _)) in order.iter().zip(&channels) {
        let c = monitor.counters();
        let errors: u64 = c.errors.values().sum::<u64>() + rejected.get(name).copied().unwrap_or(0);
        eprintln!(
            "  channel \"{name}\": {} samples, {} alarms, {errors} errors",
            c.samples, c.alarms
        );
    }
    for (name, n) in &unknown {
        eprintln!("  channel \"{name}\": {n} inputs skipped: not in the configuration");
    }
    if args.output.is_some() {
        for line in &alarm_lines {
            eprintln!("  {line}");
        }
    }
    let (lines, damaged) = input.damage_report();
    for line in &lines {
        eprintln!("glrmon replay: {}: {line}", args.input.display());
    }
    if damaged {
        return Err(InvalidInput(format!(
            "{}: the file is damaged; the readable part was replayed",
            args.input.display()
        ))
        .into());
    }
    Ok(())
}
