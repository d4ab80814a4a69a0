//! `glrmon simulate`: a channel's model driven as its config says, with an optional
//! injected fault, written to CSV. Seeded: the same seed gives the same file.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use glrmon_sim::SimSample;
use glrmon_spec::Channel;

use crate::common::{InvalidInput, load_config, pick, simulator};
use crate::flags::FaultArg;

#[derive(Debug, Args)]
pub(crate) struct SimulateArgs {
    /// Configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Channel to simulate (optional when the file has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// Number of samples.
    #[arg(long)]
    samples: u64,
    /// Seed of every random draw (noise, random signals).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// A fault of the channel's dictionary to inject and its magnitude θ,
    /// `NAME:MAGNITUDE`; repeat (or separate with commas) to inject several at once.
    #[arg(
        long = "fault",
        value_name = "NAME:MAGNITUDE",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    faults: Vec<FaultArg>,
    /// Onset r of the injected fault(s).
    #[arg(long, default_value_t = 0)]
    onset: u64,
    /// The sample at which the injected fault(s) end: they act on onset ≤ k < END
    /// (an intermittent fault, an actuator stuck for a while). Default: never.
    #[arg(long, value_name = "END", requires = "faults")]
    end: Option<u64>,
    /// Replaced by `--fault NAME:MAGNITUDE`.
    #[arg(long, hide = true, allow_hyphen_values = true)]
    pub(crate) magnitude: Vec<String>,
    /// Exogenous signals p(k) from a CSV file (header `p0,p1,…`, one row per sample)
    /// instead of the config's `simulation.signals` expressions.
    #[arg(long)]
    signals: Option<PathBuf>,
    /// Output file: CSV, or an MCAP recording of the samples (with the configuration) when the name ends in .mcap.
    #[arg(long, required_unless_present = "publish")]
    output: Option<PathBuf>,
    /// Publish the samples as the channel's plant would, on its key expression in its
    /// payload format (or one tag per key for a channel assembled from tags), instead
    /// of (or as well as) writing a file.
    #[arg(long)]
    publish: bool,
    /// Samples per second when publishing (0: as fast as possible; for a channel
    /// assembled from tags on a period, one per period).
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Keep each key's last N samples for a glrmon instance that takes a channel over
    /// (`glrmon run --shard auto`), which asks for them to start warm (a zenoh-ext
    /// advanced publisher cache); 0: none.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    cache: usize,
    #[command(flatten)]
    zenoh: crate::flags::ZenohArgs,
}

impl SimulateArgs {
    /// Whether the samples go to Zenoh (`--publish`) rather than to a file.
    pub(crate) fn publishes(&self) -> bool {
        self.publish
    }
}

pub(crate) fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args.config)?;
    let channel = pick(&cfg, args.channel.as_deref())?;
    let mut sim = simulator(channel, args.seed, &args.faults, args.onset)?;
    if let Some(end) = args.end {
        if end <= args.onset {
            return Err(InvalidInput(format!(
                "--end {end} must come after --onset {}: the fault acts on onset ≤ k < end",
                args.onset
            ))
            .into());
        }
        sim = sim.with_fault_end(end);
    }
    if let Some(path) = &args.signals {
        let rows = read_signals(path, channel.dims.signals, args.samples)?;
        sim = sim.with_signals(Box::new(move |k, out: &mut [f64]| {
            if let Some(row) = rows.get(k as usize) {
                out.copy_from_slice(row);
            }
        }));
    }
    // An MCAP output holds the samples as a recording's inputs, with the configuration:
    // `glrmon replay OUT.mcap` needs nothing else.
    let mut mcap_out = match &args.output {
        Some(path) if glrmon_input::OutputFormat::of(path) == glrmon_input::OutputFormat::Mcap => {
            Some(
                glrmon_record::McapFile::create(
                    path,
                    glrmon_record::FileOptions::default(),
                    &glrmon_record::FileHeader {
                        config: cfg.source.clone(),
                        channels: vec![channel.name.clone()],
                        extra: std::collections::BTreeMap::from([(
                            "source".to_owned(),
                            format!("glrmon simulate --seed {}", args.seed),
                        )]),
                    },
                )
                .with_context(|| format!("creating {}", path.display()))?,
            )
        }
        _ => None,
    };
    let mut json = Vec::new();
    let mut csv_out = match &args.output {
        Some(path) if mcap_out.is_none() => {
            let file = std::fs::File::create(path)
                .with_context(|| format!("creating {}", path.display()))?;
            let mut out = std::io::BufWriter::new(file);
            glrmon_input::write_header_named(&mut out, &channel.columns, channel.period.is_some())?;
            Some(out)
        }
        _ => None,
    };
    let mut x = SimSample {
        k: 0,
        u: vec![],
        y: vec![],
        p: vec![],
    };
    let mut samples = Vec::new();
    for _ in 0..args.samples {
        sim.next_into(&mut x);
        let t = channel.period.map(|dt| x.k as f64 * dt);
        if let Some(out) = &mut csv_out {
            glrmon_input::write_row(out, x.k, t, &x.u, &x.y, &x.p)?;
        }
        if let Some(out) = &mut mcap_out {
            let sample = glrmon_wire::Sample {
                k: Some(x.k),
                t,
                u: x.u.clone(),
                y: x.y.clone(),
                p: x.p.clone(),
            };
            json.clear();
            glrmon_wire::encode_sample(&channel.name, &sample, &mut json)?;
            let time = glrmon_record::sample_time_ns(t, x.k);
            out.write(
                &channel.name,
                glrmon_record::TopicKind::Inputs,
                time,
                time,
                &json,
            )?;
        }
        if args.publish {
            samples.push(glrmon_wire::Sample {
                k: Some(x.k),
                t,
                u: x.u.clone(),
                y: x.y.clone(),
                p: x.p.clone(),
            });
        }
    }
    if let Some(mut out) = csv_out {
        out.flush()?;
    }
    if let Some(out) = mcap_out {
        out.finish()?;
    }
    if args.publish {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()?;
        rt.block_on(publish(channel, &samples, args))?;
    }
    eprintln!(
        "glrmon simulate: {} samples of channel \"{}\"{}{}",
        args.samples,
        channel.name,
        args.output
            .as_ref()
            .map_or_else(String::new, |p| format!(" written to {}", p.display())),
        if args.publish {
            format!(" published on {}", channel.input_keys().join(", "))
        } else {
            String::new()
        }
    );
    Ok(())
}

/// Reads `samples` rows of the channel's `q` signals from a CSV file with a `p0…p{q−1}`
/// header (other columns are ignored).
fn read_signals(path: &std::path::Path, q: usize, samples: u64) -> anyhow::Result<Vec<Vec<f64>>> {
    let bad =
        |m: String| -> anyhow::Error { InvalidInput(format!("{}: {m}", path.display())).into() };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::trim)
        .collect();
    let cols: Vec<usize> = (0..q)
        .map(|i| {
            header
                .iter()
                .position(|h| *h == format!("p{i}"))
                .ok_or_else(|| bad(format!("column p{i} is missing from the header")))
        })
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate().take(samples as usize) {
        let fields: Vec<&str> = line.split(',').collect();
        let row = cols
            .iter()
            .map(|&c| {
                let f = fields.get(c).map_or("", |f| f.trim());
                f.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        bad(format!(
                            "row {}: column {}: \"{f}\" is not a finite number",
                            n + 2,
                            header[c]
                        ))
                    })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push(row);
    }
    if (rows.len() as u64) < samples {
        return Err(bad(format!(
            "has {} rows of signals, {samples} samples requested",
            rows.len()
        )));
    }
    Ok(rows)
}

/// Publishes the samples on the channel's input keys as its plant would
/// ([`glrmon_runtime::publications`]: whole samples in its payload format, or one tag
/// per key), once a subscriber matches each key (so that the first samples are not
/// lost), paced at `--rate`. A channel assembled from tags on a period is published in
/// the middle of each period of the Zenoh clock, so that a sample's tags are never
/// split between two periods.
async fn publish(
    channel: &Channel,
    samples: &[glrmon_wire::Sample],
    args: &SimulateArgs,
) -> anyhow::Result<()> {
    use zenoh::Wait as _;
    let session = glrmon_zenoh::open(&args.zenoh.client_settings()).await?;
    let mut publishers = Vec::new();
    let mut out = Vec::new();
    if let Some(first) = samples.first() {
        glrmon_runtime::publications(channel, first, &mut out)?;
    }
    for (key, encoding) in channel
        .input_keys()
        .into_iter()
        .zip(out.iter().map(|p| p.encoding))
    {
        let publisher = crate::common::matched_publisher(
            &session,
            &key,
            zenoh::bytes::Encoding::from(encoding),
            args.cache,
        )
        .await?;
        publishers.push(publisher);
    }
    if let Some(glrmon_spec::Formation::Period(p)) = channel.tags.as_ref().map(|t| t.formation) {
        let since = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default()
            .as_secs_f64();
        let to_middle = (p * 1.5 - since.rem_euclid(p)).rem_euclid(p);
        tokio::time::sleep(std::time::Duration::from_secs_f64(to_middle)).await;
    }
    let rate = match channel.tags.as_ref().map(|t| t.formation) {
        Some(glrmon_spec::Formation::Period(p)) if args.rate == 0.0 => 1.0 / p,
        _ => args.rate,
    };
    let mut interval =
        (rate > 0.0).then(|| tokio::time::interval(std::time::Duration::from_secs_f64(1.0 / rate)));
    for s in samples {
        if let Some(i) = &mut interval {
            i.tick().await;
        }
        out.clear();
        glrmon_runtime::publications(channel, s, &mut out)?;
        for p in out.drain(..) {
            publishers[p.key]
                .put(p.bytes)
                .wait()
                .map_err(|e| anyhow::anyhow!("publishing: {e}"))?;
        }
    }
    drop(publishers);
    let _ = session.close().await;
    Ok(())
}
