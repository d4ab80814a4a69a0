//! `glrmon play FILE.mcap`: a recording's input samples published again on their
//! channels' Zenoh keys (from the recorded configuration), with their recorded timing
//! scaled by `--rate`, like `ros2 bag play`. The samples are read by
//! `glrmon_input::Playback`; they are published as `simulate --publish` does (JSON
//! samples, blocking congestion control, once a subscriber matches).

use std::collections::HashMap;
use std::path::PathBuf;

use clap::Args;
use glrmon_wire::text::Escaped;
use zenoh::Wait as _;

use crate::common::{InvalidInput, input_error};

#[derive(Debug, Args)]
#[command(after_help = "Examples:
  glrmon play recordings/glrmon-20261202T162419Z-0000.mcap
  glrmon play run.mcap --rate 10 --channel pump3 --connect tcp/10.0.0.5:7447
  glrmon play run.mcap --rate 0 --loop      # as fast as possible, over and over")]
pub(crate) struct PlayArgs {
    /// The recording whose inputs to publish.
    file: PathBuf,
    /// Speed relative to the recording: 1 real time, 10 ten times faster, 0 as fast as
    /// possible.
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
    /// Publish only this channel's samples (repeatable; default: every channel).
    #[arg(long)]
    channel: Vec<String>,
    /// Start again from the beginning at the end, until interrupted.
    #[arg(long = "loop")]
    repeat: bool,
    /// Keep each key's last N samples for a glrmon instance that takes a channel over
    /// (`glrmon run --shard auto`), which asks for them to start warm (a zenoh-ext
    /// advanced publisher cache); 0: none.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    cache: usize,
    #[command(flatten)]
    zenoh: crate::flags::ZenohArgs,
}

pub(crate) fn run(args: &PlayArgs) -> anyhow::Result<()> {
    if !(args.rate.is_finite() && args.rate >= 0.0) {
        return Err(InvalidInput(format!(
            "--rate {}: give a speed ≥ 0 (1 real time, 0 as fast as possible)",
            args.rate
        ))
        .into());
    }
    // Read the configuration (and check --channel) before opening a session.
    let playback = glrmon_input::Playback::open(&args.file, &args.channel).map_err(input_error)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(play(playback, args))
}

async fn play(mut playback: glrmon_input::Playback, args: &PlayArgs) -> anyhow::Result<()> {
    let channels = playback.channels();
    let session = glrmon_zenoh::open(&args.zenoh.client_settings()).await?;
    let mut publishers = HashMap::new();
    for (_, key) in &channels {
        let publisher = crate::common::matched_publisher(
            &session,
            key,
            zenoh::bytes::Encoding::APPLICATION_JSON,
            args.cache,
        )
        .await?;
        publishers.insert(key.clone(), publisher);
    }
    let mut buf = Vec::new();
    let mut pass = 0u64;
    loop {
        let start = tokio::time::Instant::now();
        let mut published = 0u64;
        let mut last = 0u64;
        while let Some(s) = playback.next_sample().map_err(input_error)? {
            if let Some(due) = glrmon_input::due(s.offset_ns, args.rate) {
                tokio::time::sleep_until(start + due).await;
            }
            let Some(publisher) = publishers.get(&*s.key) else {
                continue;
            };
            buf.clear();
            glrmon_wire::encode_sample(&s.channel, &s.sample, &mut buf)?;
            publisher
                .put(buf.clone())
                .wait()
                .map_err(|e| anyhow::anyhow!("publishing on {}: {e}", s.key))?;
            published += 1;
            last = s.offset_ns;
        }
        pass += 1;
        let (lines, _) = playback.damage_report();
        for line in lines {
            eprintln!(
                "glrmon play: {}: {line}",
                Escaped(&args.file.to_string_lossy())
            );
        }
        eprintln!(
            "glrmon play: {published} samples of {} channel(s) ({}) published in {:.3} s \
             (recorded over {:.3} s){}",
            channels.len(),
            channels
                .iter()
                .map(|(c, k)| format!("{} on {}", Escaped(c), Escaped(k)))
                .collect::<Vec<_>>()
                .join(", "),
            start.elapsed().as_secs_f64(),
            last as f64 / 1e9,
            if args.repeat {
                format!(", pass {pass}")
            } else {
                String::new()
            }
        );
        if !args.repeat || published == 0 {
            break;
        }
        playback = glrmon_input::Playback::open(&args.file, &args.channel).map_err(input_error)?;
    }
    drop(publishers);
    let _ = session.close().await;
    Ok(())
}
