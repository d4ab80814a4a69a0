//! `glrmon replay`: the monitors over recorded samples, as fast as possible, to the same
//! numbers as live. Input: a CSV file of one channel, or an MCAP recording (all its
//! channels, with the configuration recorded in it unless `--config` is given). Every
//! result goes to each output sink: JSON lines (default: standard output), an MCAP file
//! (inputs and results, self-describing), an HTML report.

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::Context as _;
use clap::Args;
use glrmon_input::{
    CsvReader, CsvReplayed, InputFormat, McapInput, McapReplayed, OutputFormat, ReplayError,
};
use glrmon_monitor::Monitor;
use glrmon_record::{FileHeader, McapFileSink};
use glrmon_report::clock::Zone;
use glrmon_report::{ChannelLabels, Provenance, Report, ReportOptions, ReportSink};
use glrmon_runtime::{ChannelPipeline, Fanout, FnSink, Interest, JsonLinesSink, Output, Sink};
use glrmon_wire::text::Escaped;
use glrmon_wire::{DecodeLimits, Record};

use crate::common::pick;
use crate::common::{InvalidInput, input_error, load_config, read_ahead_error};
use crate::print;

#[derive(Debug, Args)]
pub(crate) struct ReplayArgs {
    /// Configuration file (optional for MCAP input: the recorded one is used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Channel to replay (CSV: optional when the config has one channel; MCAP: default
    /// every recorded channel).
    #[arg(long)]
    channel: Option<String>,
    /// Recorded samples: CSV exports of one channel (several: each a run of its own,
    /// from a fresh start, in the order given, into the same outputs), or one MCAP
    /// recording (a `glrmon run` or `demo` recording).
    #[arg(required = true, num_args = 1..)]
    input: Vec<PathBuf>,
    /// Output: JSON lines, or an MCAP file when the name ends in .mcap; `-` is
    /// standard output. Default: JSON lines on standard output, none when `--report`
    /// is given.
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

impl ReplayArgs {
    /// The first input file (the only one for MCAP).
    fn first(&self) -> &Path {
        &self.input[0]
    }

    /// The input files as the user named them, comma-separated.
    fn inputs_text(&self) -> String {
        self.input
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The alarm, end and diagnosis lines of a replay, printed after its summary.
type AlarmLines = Arc<Mutex<Vec<String>>>;

/// The HTML report of `args.input`: titled after it, wall-clock times in `zone`, with
/// the provenance line (this glrmon, the configuration, the data file, now) and each
/// replayed channel's signal names and units from `cfg`.
fn report(
    args: &ReplayArgs,
    zone: Zone,
    cfg: &glrmon_spec::Config,
    channels: &[&glrmon_spec::Channel],
) -> Report {
    let config = match &args.config {
        Some(path) => path.display().to_string(),
        None => format!("recorded in {}", args.first().display()),
    };
    let mut report = Report::new(ReportOptions {
        title: format!("glrmon replay of {}", args.inputs_text()),
        zone,
        provenance: Some(Provenance {
            version: crate::version::long().to_owned(),
            config,
            data: args.input.iter().map(|p| p.display().to_string()).collect(),
            made: jiff::Timestamp::now(),
        }),
        ..ReportOptions::default()
    });
    for channel in channels {
        report.label_channel(
            &channel.name,
            ChannelLabels::from_channel(channel, &cfg.source),
        );
    }
    report
}

/// The output sinks of `args` (the report's of the `channels` of `cfg`), and a sink
/// keeping the alarm lines for the summary.
fn output_sinks(
    args: &ReplayArgs,
    zone: Zone,
    header: &FileHeader,
    cfg: &glrmon_spec::Config,
    channels: &[&glrmon_spec::Channel],
) -> anyhow::Result<(Vec<Box<dyn Sink>>, AlarmLines)> {
    let mut sinks: Vec<Box<dyn Sink>> = Vec::new();
    match &args.output {
        Some(p) if p.as_os_str() == "-" => sinks.push(Box::new(JsonLinesSink::new(
            std::io::BufWriter::with_capacity(1 << 16, std::io::stdout()),
            args.stat_every,
        ))),
        Some(p) if OutputFormat::of(p) == OutputFormat::Mcap => {
            let sink = McapFileSink::create(p, header)
                .with_context(|| format!("creating {}", p.display()))?;
            sinks.push(Box::new(sink.with_stat_every(args.stat_every)));
        }
        Some(p) => {
            let file =
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
            sinks.push(Box::new(JsonLinesSink::new(
                std::io::BufWriter::with_capacity(1 << 16, file),
                args.stat_every,
            )));
        }
        // A report is what the user asked for: the terminal is not flooded with
        // records besides.
        None if args.report.is_some() => {}
        None => sinks.push(Box::new(JsonLinesSink::new(
            std::io::BufWriter::with_capacity(1 << 16, std::io::stdout()),
            args.stat_every,
        ))),
    }
    if let Some(p) = &args.report {
        sinks.push(Box::new(ReportSink::with_report(
            p,
            report(args, zone, cfg, channels),
        )));
    }
    let lines = AlarmLines::default();
    let kept = lines.clone();
    let alarm_lines = FnSink::new("alarm-lines", move |o: &Output| {
        if matches!(o.record, Record::Error(_)) {
            return;
        }
        if let Some(line) = print::line(&o.record) {
            kept.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(line);
        }
    })
    .with_interest(Interest {
        inputs: false,
        stat_every: Some(0),
    });
    sinks.push(Box::new(alarm_lines));
    Ok((sinks, lines))
}

/// Whether the alarm, isolation and diagnosis lines go to standard error after the
/// summary: whenever standard output is not the default JSON lines, i.e. with
/// `--output` or `--report`.
fn lines_on_stderr(args: &ReplayArgs) -> bool {
    args.output.is_some() || args.report.is_some()
}

/// Closes the sinks (files' summaries, the report); the first failure is the error.
fn close(fanout: Fanout) -> anyhow::Result<()> {
    let mut first = None;
    fanout.close(&mut |e| {
        first.get_or_insert(e);
    });
    first.map_or(Ok(()), |e| Err(e.into()))
}

fn take_lines(lines: &AlarmLines) -> Vec<String> {
    std::mem::take(
        &mut *lines
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner),
    )
}

/// Replays `args.input`; wall-clock times in the report are shown in `zone`.
pub(crate) fn run(args: &ReplayArgs, zone: Zone) -> anyhow::Result<()> {
    let mcap = args
        .input
        .iter()
        .filter(|p| InputFormat::of(p) == InputFormat::Mcap)
        .count();
    match (mcap, args.input.len()) {
        (0, _) => replay_csv(args, zone),
        (1, 1) => replay_mcap(args, zone),
        _ => Err(InvalidInput(format!(
            "{}: several inputs are CSV exports of one channel, each replayed as a run of \
             its own; an MCAP recording is replayed alone",
            args.inputs_text()
        ))
        .into()),
    }
}

fn replay_csv(args: &ReplayArgs, zone: Zone) -> anyhow::Result<()> {
    let Some(config) = &args.config else {
        return Err(InvalidInput(format!(
            "{}: a CSV file needs --config (only MCAP recordings carry their configuration)",
            args.first().display()
        ))
        .into());
    };
    let cfg = load_config(config)?;
    let channel = pick(&cfg, args.channel.as_deref())?;
    // Every header is read before any sample: a file that cannot be read costs nothing.
    let files = args
        .input
        .iter()
        .map(|p| CsvReader::open_with_columns(p, channel.dims, &channel.columns))
        .collect::<Result<Vec<_>, _>>()
        .map_err(input_error)?;
    let header = FileHeader {
        config: cfg.source.clone(),
        channels: vec![channel.name.clone()],
        extra: std::collections::BTreeMap::from([("source".to_owned(), args.inputs_text())]),
    };
    let (sinks, lines) = output_sinks(args, zone, &header, &cfg, &[channel])?;
    let mut fanout = Fanout::new(sinks, 1);
    // Each file is a run of its own, as identify and calibrate take them: its own
    // monitor from a fresh start (never an episode or a filter state carried across).
    // Its samples' indices follow the previous file's, so that the records of all
    // files read in one order.
    let mut summaries = Vec::with_capacity(files.len());
    let mut first_k = 0;
    for (path, csv) in args.input.iter().zip(files) {
        let mut pipeline = ChannelPipeline::new(0, Monitor::from_channel(channel)?, fanout.plan());
        let CsvReplayed { rows, next_k, .. } =
            glrmon_input::replay_csv_from(csv, first_k, &mut pipeline, &mut fanout)
                .map_err(replay_error)?;
        first_k = next_k.max(first_k);
        summaries.push(if args.input.len() > 1 {
            format!(
                "glrmon replay: channel \"{}\": {}: {rows} rows, {}",
                channel.name,
                path.display(),
                counts(&pipeline)
            )
        } else {
            format!(
                "glrmon replay: channel \"{}\": {rows} rows, {}",
                channel.name,
                counts(&pipeline)
            )
        });
    }
    close(fanout)?;
    for line in &summaries {
        eprintln!("{line}");
    }
    if lines_on_stderr(args) {
        for line in &take_lines(&lines) {
            eprintln!("  {line}");
        }
    }
    Ok(())
}

/// A replay's error with its exit code: a damaged input as [`input_error`], the rest a
/// runtime failure.
fn replay_error(e: ReplayError) -> anyhow::Error {
    match e {
        ReplayError::Read(e) => read_ahead_error(e),
        ReplayError::Input(e) => input_error(e),
        e => e.into(),
    }
}

fn replay_mcap(args: &ReplayArgs, zone: Zone) -> anyhow::Result<()> {
    // A configuration that maps a recording's topics to its channels reads a recording
    // glrmon did not write.
    if let Some(path) = &args.config {
        let cfg = load_config(path)?;
        if cfg
            .channels
            .iter()
            .any(|c| c.topics.is_some() && args.channel.as_ref().is_none_or(|n| *n == c.name))
        {
            return replay_foreign(args, zone, &cfg);
        }
    }
    let mut input = McapInput::open(args.first()).map_err(input_error)?;
    let cfg = match &args.config {
        Some(path) => load_config(path)?,
        None => input.recorded_config().map_err(input_error)?,
    };
    if let Some(name) = &args.channel
        && let Err(e) = cfg.pick_channel(Some(name))
    {
        // "no channel "x" in the configuration (channels: …)", with a suggestion.
        return Err(InvalidInput(e.to_string()).into());
    }
    input.set_limits(DecodeLimits {
        max_payload_bytes: cfg.daemon.max_payload_bytes,
        ..DecodeLimits::default()
    });
    let mut order: Vec<Arc<str>> = Vec::new();
    let mut monitors: Vec<Monitor> = Vec::new();
    let mut replayed: Vec<&glrmon_spec::Channel> = Vec::new();
    for c in &cfg.channels {
        if args.channel.as_ref().is_none_or(|n| *n == c.name) {
            order.push(Arc::from(c.name.as_str()));
            monitors.push(Monitor::from_channel(c)?);
            replayed.push(c);
        }
    }
    let header = FileHeader {
        config: cfg.source.clone(),
        channels: order.iter().map(|c| c.to_string()).collect(),
        extra: std::collections::BTreeMap::from([(
            "source".to_owned(),
            args.first().display().to_string(),
        )]),
    };
    let (sinks, lines) = output_sinks(args, zone, &header, &cfg, &replayed)?;
    let mut fanout = Fanout::new(sinks, 1);
    let mut channels: Vec<ChannelPipeline> = monitors
        .into_iter()
        .enumerate()
        .map(|(i, m)| ChannelPipeline::new(i, m, fanout.plan()))
        .collect();
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
    let started = std::time::Instant::now();
    let mut report_progress = |bytes: u64| {
        if let Some(bar) = &progress {
            bar.set_position(bytes);
        }
    };
    let McapReplayed {
        input,
        inputs,
        unknown,
        ..
    } = glrmon_input::replay_mcap(
        input,
        &mut channels,
        args.channel.is_none(),
        &mut fanout,
        &mut report_progress,
    )
    .map_err(replay_error)?;
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    let elapsed = started.elapsed().as_secs_f64();
    let written = fanout.records();
    close(fanout)?;
    eprintln!(
        "glrmon replay: {}: {} messages, {inputs} inputs replayed in {elapsed:.2} s, {written} records written",
        args.first().display(),
        input.messages(),
    );
    for (name, pipeline) in order.iter().zip(&channels) {
        eprintln!("  channel \"{name}\": {}", counts(pipeline));
    }
    // A recording's topics may name any channel: shown escaped.
    for (name, n) in &unknown {
        eprintln!(
            "  channel \"{}\": {n} inputs skipped: not in the configuration",
            Escaped(name)
        );
    }
    if lines_on_stderr(args) {
        for line in &take_lines(&lines) {
            eprintln!("  {line}");
        }
    }
    let (lines, damaged) = input.damage_report();
    for line in &lines {
        eprintln!(
            "glrmon replay: {}: {line}",
            Escaped(&args.first().to_string_lossy())
        );
    }
    if damaged {
        return Err(InvalidInput(format!(
            "{}: the file is damaged; the readable part was replayed",
            args.first().display()
        ))
        .into());
    }
    Ok(())
}

/// Replays a recording glrmon did not write (a ROS 2 bag, a Foxglove MCAP) into the
/// channels whose `[channels.topics]` map its topics.
fn replay_foreign(args: &ReplayArgs, zone: Zone, cfg: &glrmon_spec::Config) -> anyhow::Result<()> {
    if let Some(name) = &args.channel
        && let Err(e) = cfg.pick_channel(Some(name))
    {
        return Err(InvalidInput(e.to_string()).into());
    }
    let replayed: Vec<&glrmon_spec::Channel> = cfg
        .channels
        .iter()
        .filter(|c| c.topics.is_some() && args.channel.as_ref().is_none_or(|n| *n == c.name))
        .collect();
    let header = FileHeader {
        config: cfg.source.clone(),
        channels: replayed.iter().map(|c| c.name.clone()).collect(),
        extra: std::collections::BTreeMap::from([(
            "source".to_owned(),
            args.first().display().to_string(),
        )]),
    };
    let (sinks, lines) = output_sinks(args, zone, &header, cfg, &replayed)?;
    let mut fanout = Fanout::new(sinks, 1);
    let mut pipelines = Vec::with_capacity(replayed.len());
    for (i, c) in replayed.iter().enumerate() {
        let mut pipeline = ChannelPipeline::new(i, Monitor::from_channel(c)?, fanout.plan());
        if let Some(decoder) = glrmon_input::topics_decoder(c) {
            pipeline = pipeline.with_decoder(decoder);
        }
        pipelines.push(pipeline);
    }
    let started = std::time::Instant::now();
    let limits = DecodeLimits {
        max_payload_bytes: cfg.daemon.max_payload_bytes,
        ..DecodeLimits::default()
    };
    let done = glrmon_input::replay_foreign_mcap(
        args.first(),
        &replayed,
        &mut pipelines,
        &limits,
        &mut fanout,
    )
    .map_err(replay_error)?;
    let elapsed = started.elapsed().as_secs_f64();
    let written = fanout.records();
    close(fanout)?;
    let topics: Vec<String> = done
        .by_topic
        .iter()
        .map(|(t, n)| format!("{} {n}", Escaped(t)))
        .collect();
    eprintln!(
        "glrmon replay: {}: {} messages ({}) replayed in {elapsed:.2} s, {written} records written",
        args.first().display(),
        done.messages,
        topics.join(", "),
    );
    for (c, pipeline) in replayed.iter().zip(&pipelines) {
        eprintln!("  channel \"{}\": {}", c.name, counts(pipeline));
    }
    for (topic, (n, why)) in &done.unreadable {
        eprintln!(
            "  topic {}: {n} messages not read: {}",
            Escaped(topic),
            Escaped(why)
        );
    }
    if lines_on_stderr(args) {
        for line in &take_lines(&lines) {
            eprintln!("  {line}");
        }
    }
    for line in &done.damage {
        eprintln!(
            "glrmon replay: {}: {}",
            Escaped(&args.first().to_string_lossy()),
            Escaped(line)
        );
    }
    if !done.damage.is_empty() {
        return Err(InvalidInput(format!(
            "{}: the file is damaged; the readable part was replayed",
            args.first().display()
        ))
        .into());
    }
    Ok(())
}

/// `N samples, 1 alarm, 2 errors (non_finite 1, too_large 1)`: a channel's counts for the
/// summary line, each error code with its count.
fn counts(pipeline: &ChannelPipeline) -> String {
    let c = pipeline.monitor().counters();
    let plural = |n: u64, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    let errors = pipeline.error_total();
    let codes: Vec<String> = (pipeline.stats().errors.lock())
        .map(|m| m.iter().map(|(code, n)| format!("{code} {n}")).collect())
        .unwrap_or_default();
    let by_code = if codes.is_empty() {
        String::new()
    } else {
        format!(" ({})", codes.join(", "))
    };
    format!(
        "{}, {}, {}{by_code}",
        plural(c.samples, "sample"),
        plural(c.alarms, "alarm"),
        plural(errors, "error")
    )
}
