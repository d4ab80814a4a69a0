//! `glrmon watch [KEYEXPR] [--json]`: alarms (at the crossing), their isolation
//! updates, alarm ends, diagnoses and consistency changes, one line each; with `--raw`
//! (or a key outside `glrmon/**`, such as a plant's tags) every publication as it
//! arrives: its time, key, encoding and payload.
//!
//! Each record line names its source: the instance that published it and its
//! assignment generation (the Zenoh attachment of glrmon's records), flagged when no
//! live instance has that name or the record carries no source: a record anyone else
//! published (or one a storage kept of an instance that stopped). `--since 1h` first
//! prints the records of the last hour that the storages kept, then those the live
//! instances kept (their publishers' caches), then the live ones.
//!
//! Any Zenoh peer can publish under the watched key, so nothing received reaches the
//! terminal raw: lines, key expressions and decode errors are escaped
//! ([`glrmon_wire::text`]), and records passed on as JSON keep their value with their
//! control and bidi characters as JSON escapes.

use clap::Args;
use glrmon_wire::text::{Escaped, escape_json};
use glrmon_wire::{Record, decode_record};

use crate::flags::ZenohArgs;
use crate::print;

#[derive(Debug, Args)]
pub(crate) struct WatchArgs {
    /// Key expression to watch.
    #[arg(default_value = "glrmon/**")]
    key: String,
    /// Print the records as JSON lines instead of text.
    #[arg(long)]
    json: bool,
    /// Also print `stat` and `error` records.
    #[arg(long)]
    all: bool,
    /// Exit after this many printed records.
    #[arg(long)]
    count: Option<u64>,
    /// Print every publication as it arrives (Zenoh timestamp, key, encoding, payload as
    /// text or, when binary, hexadecimal), to see what a plant publishes before
    /// configuring it: the default for a key outside glrmon/**.
    #[arg(long)]
    raw: bool,
    /// First print the records of this last time (`1h`, `30min`, `2d`) that Zenoh
    /// storages kept (each channel's last of each kind: deploy/zenohd-history.json5),
    /// then those the live instances kept (the last 32 of each kind per channel).
    #[arg(long, value_name = "TIME", value_parser = crate::span::parse_time)]
    since: Option<f64>,
    #[command(flatten)]
    zenoh: ZenohArgs,
}

pub(crate) fn run(args: &WatchArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(watch(args))
}

async fn watch(args: &WatchArgs) -> anyhow::Result<()> {
    let session = glrmon_zenoh::open(&args.zenoh.client_settings()).await?;
    // What the storages keep (deploy/zenohd-history.json5) comes first; the instances'
    // caches then bring what they kept, of which a record already printed is not
    // printed again.
    let mut stored = std::collections::HashSet::new();
    let mut first = std::collections::VecDeque::new();
    if let Some(seconds) = args.since {
        for sample in glrmon_zenoh::stored_results(
            &session,
            &args.key,
            seconds,
            std::time::Duration::from_secs(2),
        )
        .await
        .map_err(|e| anyhow::anyhow!("asking the storages for {}: {e}", args.key))?
        {
            stored.insert(sample.payload().to_bytes().into_owned());
            first.push_back(sample);
        }
    }
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    let sub = glrmon_zenoh::Results::subscribe(&session, &args.key, args.since, move |s| {
        let _ = tx.send(s);
    })
    .await
    .map_err(|e| anyhow::anyhow!("subscribing to {}: {e}", args.key))?;
    let live = glrmon_zenoh::LiveInstances::watch(&session)
        .await
        .map_err(|e| anyhow::anyhow!("following the live instances: {e}"))?;
    let raw = args.raw || !glrmon_spec::keys::intersects(&args.key, "glrmon/**");
    let mut printed = 0u64;
    loop {
        let (sample, from_storage) = match first.pop_front() {
            Some(s) => (s, true),
            None => {
                let s = tokio::select! {
                    s = rx.recv() => match s { Some(s) => s, None => break },
                    _ = tokio::signal::ctrl_c() => break,
                };
                if stored.contains(&*s.payload().to_bytes()) {
                    continue;
                }
                (s, false)
            }
        };
        let bytes = sample.payload().to_bytes();
        if raw {
            println!("{}", raw_line(&sample, &bytes));
            printed += 1;
            if args.count.is_some_and(|c| printed >= c) {
                break;
            }
            continue;
        }
        let record = match decode_record(&bytes) {
            Ok(r) => r,
            Err(e) => {
                eprintln!(
                    "glrmon watch: {}: {}",
                    Escaped(sample.key_expr().as_str()),
                    Escaped(&e.to_string())
                );
                continue;
            }
        };
        if !args.all && matches!(record, Record::Stat(_) | Record::Error(_)) {
            continue;
        }
        let source = source_note(&sample, &live, from_storage);
        match print::line(&record) {
            Some(line) if !args.json => println!("{line}  [{source}]"),
            _ => {
                println!("{}", escape_json(&String::from_utf8_lossy(&bytes)));
                if source.starts_with('!') {
                    eprintln!(
                        "glrmon watch: {}: {source}",
                        Escaped(sample.key_expr().as_str())
                    );
                }
            }
        }
        printed += 1;
        if args.count.is_some_and(|c| printed >= c) {
            break;
        }
    }
    drop((sub, live));
    let _ = session.close().await;
    Ok(())
}

/// Who published `sample`: `from a g3` for a live instance's record, else a warning
/// that starts with `!`. A storage keeps no attachment: a record `from_storage` without
/// one is said to be stored.
fn source_note(
    sample: &zenoh::sample::Sample,
    live: &glrmon_zenoh::LiveInstances,
    from_storage: bool,
) -> String {
    let Some(source) = sample
        .attachment()
        .and_then(|a| glrmon_wire::Source::decode(&a.to_bytes()).ok())
    else {
        return if from_storage {
            "stored by a Zenoh storage, which keeps no source".to_owned()
        } else {
            "! no source: not published by a glrmon instance".to_owned()
        };
    };
    let name = Escaped(&source.instance);
    if live.contains(&source.instance) {
        format!("from {name} g{}", source.generation)
    } else {
        format!("! from \"{name}\", which is not a live glrmon instance")
    }
}

/// One publication as it arrived: `<time> <key> [<encoding>] <payload>`, the time its
/// Zenoh timestamp (UTC) or `-`, the payload as (escaped) text when it is UTF-8, else
/// `0x` and its bytes in hexadecimal (at most 256 shown).
fn raw_line(sample: &zenoh::sample::Sample, bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    let time = sample.timestamp().map_or_else(
        || "-".to_owned(),
        |t| {
            let since = t
                .get_time()
                .to_system_time()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap_or_default();
            glrmon_report::clock::format_time(since.as_secs_f64(), glrmon_report::clock::Zone::Utc)
        },
    );
    let payload = match std::str::from_utf8(bytes) {
        Ok(text) => Escaped(text).to_string(),
        Err(_) => {
            let mut hex = String::from("0x");
            for b in bytes.iter().take(256) {
                let _ = write!(hex, "{b:02x}");
            }
            if bytes.len() > 256 {
                let _ = write!(hex, "… ({} bytes)", bytes.len());
            }
            hex
        }
    };
    format!(
        "{time} {} [{}] {payload}",
        Escaped(sample.key_expr().as_str()),
        Escaped(&sample.encoding().to_string())
    )
}
