//! `glrmon info FILE.mcap`: what a recording holds (size, finished or salvaged, time
//! range, each topic's messages, the recorded channels, the glrmon version), like
//! `mcap info`; `--json` for scripts. The reading is `glrmon_record::summarize`.
//!
//! A recording may come from anywhere, so its file name, metadata, channel, topic and
//! schema names and damage reasons are shown escaped ([`glrmon_wire::text`]).

use std::path::PathBuf;

use clap::Args;
use glrmon_record::{ReadEnd, RecordingSummary, iso8601_utc};
use glrmon_report::clock::{Zone, format_time};
use glrmon_wire::text::{Escaped, escape_control, escape_json};

use crate::common::InvalidInput;

#[derive(Debug, Args)]
#[command(after_help = "Examples:
  glrmon info recordings/glrmon-20261202T162419Z-0000.mcap
  glrmon info --json run.mcap | jq '.topics[] | {topic, messages}'
  glrmon info recordings/glrmon-20261202T162419Z-0003.mcap.tmp   # an unfinished file")]
pub(crate) struct InfoArgs {
    /// The recording (`.mcap`, or an unfinished `.mcap.tmp`).
    file: PathBuf,
    /// One JSON object on stdout instead of the table.
    #[arg(long)]
    json: bool,
}

/// Summarises `args.file`; the table shows wall-clock times in `zone` (JSON: UTC).
pub(crate) fn run(args: &InfoArgs, zone: Zone) -> anyhow::Result<()> {
    let s = match glrmon_record::summarize(&args.file) {
        Ok(s) => s,
        Err(glrmon_record::SummaryError::NotGlrmon {
            messages,
            found,
            library,
            ..
        }) if !found.is_empty() && !args.json => {
            print_foreign(&args.file, messages, &found, library.as_deref(), zone);
            return Ok(());
        }
        Err(e) => return Err(InvalidInput(escape_control(&e.to_string()).into_owned()).into()),
    };
    if args.json {
        // serde_json escapes U+0000–U+001F only; each line of its output is made safe
        // alone, so that the pretty-printing's own line breaks stay.
        for line in serde_json::to_string_pretty(&to_json(&s))?.lines() {
            println!("{}", escape_json(line));
        }
    } else {
        print_table(&s, zone);
    }
    Ok(())
}

/// A recording glrmon did not write (a ROS 2 bag, a Foxglove MCAP): its topics, with
/// what a `[channels.topics]` mapping needs (schema, encodings, messages, times).
fn print_foreign(
    path: &std::path::Path,
    messages: u64,
    topics: &[glrmon_record::TopicSummary],
    library: Option<&str>,
    zone: Zone,
) {
    let time =
        |t: Option<u64>| t.map_or_else(|| "-".to_owned(), |ns| format_time(ns as f64 / 1e9, zone));
    println!("file:      {}", Escaped(&path.to_string_lossy()));
    println!(
        "written:   not by glrmon{}",
        library.map_or_else(String::new, |l| format!(" ({})", Escaped(l)))
    );
    println!("messages:  {messages} on {} topic(s)", topics.len());
    println!("topics:");
    for t in topics {
        println!(
            "  {}  {} (schema {}, messages {})  {} messages  {} .. {}",
            Escaped(&t.topic),
            Escaped(&t.schema),
            Escaped(&t.schema_encoding),
            Escaped(&t.message_encoding),
            t.messages,
            time(t.first_ns),
            time(t.last_ns)
        );
    }
    println!(
        "replay:    map its topics to a channel's signals with [channels.topics] (docs/WIRE.md, \
         \"Recordings glrmon did not write\"; config/examples/ros2-bag.toml), then \
         glrmon replay --config FILE {}",
        Escaped(&path.to_string_lossy())
    );
}

fn status(s: &RecordingSummary) -> String {
    let mut status = match &s.end {
        ReadEnd::Finished | ReadEnd::Reading => "finished".to_owned(),
        ReadEnd::Truncated { at, partial } => format!(
            "unfinished (no footer): readable up to byte {at}, {partial} byte(s) of an incomplete record; `glrmon recover` finishes it"
        ),
        ReadEnd::Unreadable { at, reason } => format!("unreadable from byte {at}: {reason}"),
    };
    if s.lost_data() {
        status.push_str(&format!("; damaged: {}", s.salvage));
    }
    status
}

fn seconds(ns: u64) -> String {
    format!("{:.3} s", ns as f64 / 1e9)
}

fn print_table(s: &RecordingSummary, zone: Zone) {
    // A recording of simulated samples has log times of seconds since 0: shown as such.
    let time =
        |t: Option<u64>| t.map_or_else(|| "-".to_owned(), |ns| format_time(ns as f64 / 1e9, zone));
    let path = s.path.to_string_lossy();
    println!("file:      {}", Escaped(&path));
    println!("size:      {} bytes", s.bytes);
    println!("status:    {}", Escaped(&status(s)));
    if let Some(v) = s.glrmon_version() {
        println!("version:   glrmon {}", Escaped(&v));
    }
    if let Some(i) = s.header.extra.get("instance") {
        println!("instance:  {}", Escaped(i));
    }
    if let Some(src) = s.header.extra.get("source") {
        println!("source:    {}", Escaped(src));
    }
    let channels: Vec<_> = s
        .header
        .channels
        .iter()
        .map(|c| escape_control(c))
        .collect();
    println!("channels:  {}", channels.join(", "));
    println!("start:     {}", time(s.start_ns));
    println!("end:       {}", time(s.end_ns));
    println!("duration:  {}", seconds(s.duration_ns()));
    println!("messages:  {}", s.messages);
    let topics: Vec<_> = s.topics.iter().map(|t| escape_control(&t.topic)).collect();
    let width = topics
        .iter()
        .map(|t| t.chars().count())
        .max()
        .unwrap_or(5)
        .max(5);
    println!("topics:    {}", s.topics.len());
    let head = ["topic", "messages", "schema", "first", "last"];
    println!(
        "  {:<width$}  {:>9}  {:<20}  {:<30}  {}",
        head[0], head[1], head[2], head[3], head[4]
    );
    for (t, topic) in s.topics.iter().zip(&topics) {
        println!(
            "  {:<width$}  {:>9}  {:<20}  {:<30}  {}",
            topic,
            t.messages,
            escape_control(&t.schema),
            time(t.first_ns),
            time(t.last_ns)
        );
    }
    for d in &s.damage {
        println!("damaged:   {}", Escaped(&d.to_string()));
    }
}

fn to_json(s: &RecordingSummary) -> serde_json::Value {
    let time = |t: Option<u64>| t.map(iso8601_utc);
    let end = match &s.end {
        ReadEnd::Finished | ReadEnd::Reading => "finished",
        ReadEnd::Truncated { .. } => "unfinished",
        ReadEnd::Unreadable { .. } => "unreadable",
    };
    serde_json::json!({
        "file": s.path.display().to_string(),
        "bytes": s.bytes,
        "finished": s.finished(),
        "read_end": end,
        "status": status(s),
        "lost_data": s.lost_data(),
        "damage": s.damage.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "glrmon_version": s.glrmon_version(),
        "library": s.library,
        "metadata": s.header.extra,
        "channels": s.header.channels,
        "messages": s.messages,
        "start_ns": s.start_ns,
        "end_ns": s.end_ns,
        "start": time(s.start_ns),
        "end": time(s.end_ns),
        "duration_s": s.duration_ns() as f64 / 1e9,
        "topics": s.topics.iter().map(|t| serde_json::json!({
            "topic": t.topic,
            "schema": t.schema,
            "channel": t.channel,
            "kind": t.kind.map(|k| k.as_str()),
            "messages": t.messages,
            "first_ns": t.first_ns,
            "last_ns": t.last_ns,
            "first": time(t.first_ns),
            "last": time(t.last_ns),
        })).collect::<Vec<_>>(),
    })
}
