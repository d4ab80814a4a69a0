//! `glrmon diagnose`: batch sparse fault diagnosis (Zhang 2021) over a recorded span of
//! a CSV file or of one channel of an MCAP recording. The channel's residual filter (Kitanidis when the model has E, else
//! Kalman, or as `[channels.diagnosis]` says) runs from the first row; the regression
//! of Zhang 2021, eq. (36), is stacked over `--from`…`--to` (default: the whole file);
//! a χ² test of θ = 0 says whether the span shows any fault (if not, the support is
//! empty); the Lasso path (eq. (39)), the plateau λ (§IV) and the least-squares refit
//! (§V) give the isolated faults and their magnitudes. Step, impulse and ramp faults are taken to
//! begin at `--onset` (default `--from`); known-profile faults act from the first row.
//! The same engine runs in the monitor at every alarm ([`glrmon_monitor::diagnosis`]).

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use glrmon_monitor::{DiagnosisEngine, SpanDiagnosis};
use glrmon_spec::ResidualKind;
use glrmon_wire::{Record, Sample, encode_json};

use glrmon_input::{Samples, embedded_config};

use crate::common::pick;
use crate::common::{InvalidInput, input_error, load_config};

#[derive(Debug, Args)]
pub(crate) struct DiagnoseArgs {
    /// Configuration file (optional for MCAP input: the recorded one is used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Channel the samples belong to (optional when the configuration has one channel).
    #[arg(long)]
    channel: Option<String>,
    /// Recorded samples: CSV (k, t, u0…, y0…, p0…) or an MCAP recording.
    input: PathBuf,
    /// First sample index of the regression (default: the first row).
    #[arg(long)]
    from: Option<u64>,
    /// Last sample index of the regression (default: the last row).
    #[arg(long)]
    to: Option<u64>,
    /// Onset r of step, impulse and ramp faults (default: --from; ignored for
    /// known-profile faults).
    #[arg(long)]
    onset: Option<u64>,
    /// Residual generator, overriding the configuration.
    #[arg(long, value_enum)]
    residual: Option<Residual>,
    /// Print the `diagnosis` record as JSON instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Residual {
    /// Kalman filter (Zhang 2021, §III-A): no unknown input.
    Kalman,
    /// Kitanidis filter (§III-B): rejects the unknown input E d_k; needs E.
    Kitanidis,
}

/// Index, first and last sample of a file, after checking that the rows are usable.
struct Extent {
    first: u64,
    last: u64,
}

/// Calls `visit` with every sample of the file and its index k (the row's `k`, or its
/// position). Bad rows and gaps are errors: the regression needs consecutive samples.
fn for_each_sample(
    path: &Path,
    channel: &glrmon_spec::Channel,
    mut visit: impl FnMut(u64, &Sample) -> anyhow::Result<bool>,
) -> anyhow::Result<Option<Extent>> {
    let mut samples = Samples::for_channel(path, channel).map_err(input_error)?;
    let mut sample = Sample::default();
    let mut extent: Option<Extent> = None;
    let mut position = 0u64;
    while let Some(row) = samples.next_into(&mut sample).map_err(input_error)? {
        if let Err(e) = row {
            return Err(InvalidInput(format!("{}: {e}", path.display())).into());
        }
        let k = sample.k.unwrap_or(position);
        position = k + 1;
        match &mut extent {
            None => extent = Some(Extent { first: k, last: k }),
            Some(x) if k == x.last + 1 => x.last = k,
            Some(x) => {
                return Err(InvalidInput(format!(
                    "{}: sample k = {k} follows k = {}: sparse diagnosis needs consecutive \
                     samples (no gaps, no repeats)",
                    path.display(),
                    x.last
                ))
                .into());
            }
        }
        if !visit(k, &sample)? {
            break;
        }
    }
    Ok(extent)
}

pub(crate) fn run(args: &DiagnoseArgs) -> anyhow::Result<()> {
    let cfg = match &args.config {
        Some(path) => load_config(path)?,
        None => embedded_config(&args.input)
            .map_err(input_error)?
            .ok_or_else(|| {
                InvalidInput(format!(
                    "{}: a CSV file needs --config (only MCAP recordings carry their \
                     configuration)",
                    args.input.display()
                ))
            })?,
    };
    let mut channel = pick(&cfg, args.channel.as_deref())?.clone();
    if let Some(r) = args.residual {
        channel.diagnosis.residual = match r {
            Residual::Kalman => ResidualKind::Kalman,
            Residual::Kitanidis => ResidualKind::Kitanidis,
        };
    }
    if channel.diagnosis.residual == ResidualKind::Kitanidis && channel.unknown_input.is_none() {
        return Err(InvalidInput(format!(
            "channel \"{}\" has no unknown-input matrix E: the Kitanidis residual needs one \
             (use --residual kalman)",
            channel.name
        ))
        .into());
    }
    if let Some(e) = &channel.unknown_input
        && channel.diagnosis.residual == ResidualKind::Kitanidis
    {
        glrmon_core::sparse::residual::unknown_input_rank(
            channel.model.matrices()[2].base(),
            e.base(),
        )
        .map_err(|e| InvalidInput(format!("channel \"{}\": {e}", channel.name)))?;
    }
    // First pass: the file's extent, so that the span and the history are known.
    let extent = for_each_sample(&args.input, &channel, |_, _| Ok(true))?
        .ok_or_else(|| InvalidInput(format!("{}: no samples", args.input.display())))?;
    let from = args.from.unwrap_or(extent.first);
    let to = args.to.unwrap_or(extent.last);
    if from > to || from < extent.first || to > extent.last {
        return Err(InvalidInput(format!(
            "span {from}..={to} is not within the file's samples {}..={}",
            extent.first, extent.last
        ))
        .into());
    }
    let onset = args.onset.unwrap_or(from);
    // The ring must hold the span and the sample before it (an impulse's entry).
    let history = usize::try_from(to - from + 2).unwrap_or(usize::MAX);
    let mut engine = DiagnosisEngine::new(&channel, history)
        .map_err(|e| InvalidInput(format!("channel \"{}\": {e}", channel.name)))?;
    for_each_sample(&args.input, &channel, |k, s| {
        let sample = glrmon_core::Sample {
            k,
            u: &s.u,
            y: &s.y,
            p: &s.p,
        };
        engine.step(&sample).map_err(|e| {
            InvalidInput(format!(
                "{}: sample k = {k}: residual filter: {e}",
                args.input.display()
            ))
        })?;
        Ok(k < to)
    })?;
    let d = engine.diagnose(to, onset, from, to).map_err(|e| {
        InvalidInput(format!(
            "channel \"{}\", samples {from}..={to}: {e}",
            channel.name
        ))
    })?;
    let mut out = std::io::stdout().lock();
    if args.json {
        let mut buf = Vec::new();
        encode_json(&Record::Diagnosis(d.record), &mut buf)?;
        buf.push(b'\n');
        out.write_all(&buf)?;
    } else {
        out.write_all(text(&d, channel.fault_names.len()).as_bytes())?;
    }
    out.flush()?;
    Ok(())
}

/// The human-readable report.
fn text(d: &SpanDiagnosis, faults: usize) -> String {
    let r = &d.record;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "sparse diagnosis of channel \"{}\" over k = {}..={} ({} samples), {} residual, {faults} candidate faults",
        r.channel, r.from, r.to, d.samples, r.residual
    );
    let _ = writeln!(
        s,
        "  support:   {}",
        if r.support.is_empty() {
            "(none)".to_owned()
        } else {
            let n = r.support.len();
            format!(
                "{} ({n} fault{})",
                r.support.join(", "),
                if n == 1 { "" } else { "s" }
            )
        }
    );
    if let Some(t) = &d.detail.test {
        let verdict = if t.fault() {
            "a fault (the λ rule picks the support)"
        } else {
            "no fault in the span (empty support)"
        };
        let _ = writeln!(
            s,
            "  test:      T = {:.4} {} {:.4}, the χ²({}) upper quantile at α = {}: {verdict}",
            t.statistic,
            if t.fault() { ">" } else { "≤" },
            t.threshold,
            t.dof,
            t.level
        );
    }
    let mut est = String::new();
    for name in &r.support {
        if let Some(v) = r.estimate.get(name) {
            let sep = if est.is_empty() { "" } else { ", " };
            let _ = write!(est, "{sep}{name} = {}", crate::print::magnitude(*v));
        }
    }
    if !r.support.is_empty() {
        let _ = writeln!(s, "  estimate:  {est}  (least squares on the support)");
    }
    let mut lasso = String::new();
    for (i, &(j, v)) in d.detail.lasso.iter().enumerate() {
        let sep = if i == 0 { "" } else { ", " };
        let name = r
            .support
            .get(i)
            .map_or_else(|| format!("#{j}"), Clone::clone);
        let _ = write!(lasso, "{sep}{name} = {}", crate::print::magnitude(v));
    }
    if !r.support.is_empty() {
        let _ = writeln!(s, "  lasso:     {lasso}  (θ̂(λ), shrunk by the penalty)");
    }
    let run = d
        .detail
        .path
        .iter()
        .filter(|&&(l, _)| l >= r.plateau[0] && l <= r.plateau[1])
        .count();
    if r.support.is_empty() {
        let _ = writeln!(
            s,
            "  lambda:    {:.4e} = λ_max, where θ̂(λ) becomes 0 (no λ chosen)",
            r.lambda
        );
    } else {
        let _ = writeln!(
            s,
            "  lambda:    {:.4e}, middle of the plateau [{:.4e}, {:.4e}] ({} of {} path points with {} faults)",
            r.lambda,
            r.plateau[0],
            r.plateau[1],
            run,
            d.detail.path.len(),
            r.support.len()
        );
    }
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for &c in &r.path_support_sizes {
        match runs.last_mut() {
            Some((last, n)) if *last == c => *n += 1,
            _ => runs.push((c, 1)),
        }
    }
    let summary: Vec<String> = runs.iter().map(|(c, n)| format!("{c}×{n}")).collect();
    let (hi, lo) = (
        d.detail.path.first().map_or(0.0, |p| p.0),
        d.detail.path.last().map_or(0.0, |p| p.0),
    );
    let _ = writeln!(
        s,
        "  path:      λ {hi:.3e} → {lo:.3e}, support size × points: {}{}",
        summary.join(" "),
        if d.detail.converged {
            ""
        } else {
            " (coordinate descent did not converge everywhere)"
        }
    );
    s
}
