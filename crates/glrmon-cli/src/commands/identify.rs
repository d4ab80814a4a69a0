//! `glrmon identify`: a channel's model from fault-free recordings (subspace
//! identification of an innovation model, order selection, validation), written as a
//! commented configuration. See [`glrmon_eval::identify`].

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use glrmon_eval::identify::{Identified, IdentifyError, IdentifyRequest, identify_channel};
use glrmon_ident::{Criterion, Detrend, Holdout, IdentSettings, PreprocessSettings};
use serde::Serialize;

use crate::common::InvalidInput;

#[derive(Debug, Args)]
pub(crate) struct IdentifyArgs {
    /// Name of the channel to write.
    #[arg(long)]
    channel: String,
    /// Fault-free recordings, CSV (named columns) or MCAP; each file, and each run of
    /// consecutive samples in it, is a separate experiment (never joined).
    #[arg(required = true)]
    input: Vec<PathBuf>,
    /// The configuration file to write.
    #[arg(long)]
    output: PathBuf,
    /// Overwrite --output if it exists.
    #[arg(long)]
    force: bool,
    /// Input columns, in order (default: every u<i> column).
    #[arg(long, value_delimiter = ',')]
    inputs: Option<Vec<String>>,
    /// Output columns, in order (default: every y<i> column).
    #[arg(long, value_delimiter = ',')]
    outputs: Option<Vec<String>>,
    /// Model order n (default: chosen by --criterion up to --max-order).
    #[arg(long, conflicts_with = "max_order")]
    order: Option<usize>,
    /// Largest candidate order.
    #[arg(long, default_value_t = 10)]
    max_order: usize,
    /// Criterion that picks the order.
    #[arg(long, value_enum, default_value_t = CriterionArg::Bic)]
    criterion: CriterionArg,
    /// Past/future horizon i of the block Hankel matrices (default: from the order).
    #[arg(long)]
    horizon: Option<usize>,
    /// Fraction of each experiment held out for the prediction fit (0: in-sample).
    #[arg(long, default_value_t = 0.2)]
    holdout: f64,
    /// Hold out the last experiment instead of a fraction of each.
    #[arg(long, conflicts_with = "holdout")]
    holdout_last: bool,
    /// Remove each experiment's linear trend (slow drifts), not only its mean.
    #[arg(long)]
    detrend: bool,
    /// GLR window of the written channel.
    #[arg(long, default_value_t = 50)]
    window: usize,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum CriterionArg {
    Bic,
    Aic,
}

pub(crate) fn run(args: &IdentifyArgs) -> anyhow::Result<()> {
    if args.output.exists() && !args.force {
        return Err(InvalidInput(format!(
            "{} exists: give --force to overwrite it, or another --output",
            args.output.display()
        ))
        .into());
    }
    let files: Vec<String> = args.input.iter().map(|p| p.display().to_string()).collect();
    let request = IdentifyRequest {
        channel: args.channel.clone(),
        files: args.input.clone(),
        inputs: args.inputs.clone(),
        outputs: args.outputs.clone(),
        settings: IdentSettings {
            preprocess: PreprocessSettings {
                detrend: if args.detrend {
                    Detrend::Linear
                } else {
                    Detrend::Constant
                },
                ..PreprocessSettings::default()
            },
            horizon: args.horizon,
            max_order: args.max_order,
            order: args.order,
            holdout: if args.holdout_last {
                Holdout::LastExperiment
            } else {
                Holdout::LastFraction(args.holdout)
            },
            criterion: match args.criterion {
                CriterionArg::Bic => Criterion::Bic,
                CriterionArg::Aic => Criterion::Aic,
            },
            ..IdentSettings::default()
        },
        window: args.window,
        notes: vec![
            format!(
                "Identified by `glrmon identify --channel {}` from {}.",
                args.channel,
                files.join(", ")
            ),
            format!(
                "Next: glrmon calibrate --config {} --channel {} {} --sample-far 0.01 --write",
                args.output.display(),
                args.channel,
                files.join(" ")
            ),
        ],
    };
    let identified = identify_channel(&request).map_err(|e| match e {
        IdentifyError::Written(_) => anyhow::Error::from(e),
        IdentifyError::Input(e) => crate::common::input_error(e),
        other => InvalidInput(other.to_string()).into(),
    })?;
    std::fs::write(&args.output, &identified.config)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", args.output.display()))?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&Report::of(&identified))?
        );
    } else {
        print_report(&identified);
        println!(
            "\nwrote {} (it validates). Next, thresholds from fault-free data:\n  \
             glrmon calibrate --config {} --channel {} {} --sample-far 0.01 --write\n\
             then monitor: glrmon replay --config {} NEW.csv   or   glrmon run --config {}",
            args.output.display(),
            args.output.display(),
            args.channel,
            files.join(" "),
            args.output.display(),
            args.output.display(),
        );
    }
    Ok(())
}

fn print_report(id: &Identified) {
    let ident = &id.identification;
    let used: Vec<_> = id.runs.iter().filter(|r| r.used).collect();
    println!(
        "{} experiment(s), {} samples; inputs [{}], outputs [{}]",
        used.len(),
        used.iter().map(|r| r.samples).sum::<usize>(),
        id.channel.inputs.join(", "),
        id.channel.outputs.join(", ")
    );
    for r in id.runs.iter().filter(|r| !r.used) {
        println!(
            "  left out: {} from {} ({} samples, fewer than {})",
            r.file.display(),
            r.start,
            r.samples,
            glrmon_eval::identify::MIN_RUN_SAMPLES
        );
    }
    for line in &id.dropped {
        println!("  warning: {line}");
    }
    let sv: Vec<String> = ident
        .order
        .singular_values
        .iter()
        .take(16)
        .map(|s| format!("{s:.3}"))
        .collect();
    println!("singular values: {}", sv.join(" "));
    println!("order        AIC          BIC   held-out NRMSE (mean)   ρ(A−KC)");
    for c in &ident.order.candidates {
        let mean = if c.holdout_nrmse.is_empty() {
            f64::NAN
        } else {
            c.holdout_nrmse.mean()
        };
        let mark = if c.order == ident.model.order() {
            "  ◀"
        } else {
            ""
        };
        match &c.failure {
            Some(why) => println!("{:>5}   {why}", c.order),
            None => println!(
                "{:>5} {:>10.1} {:>12.1} {:>22.4} {:>9.3}{mark}",
                c.order, c.aic, c.bic, mean, c.predictor_spectral_radius
            ),
        }
    }
    println!(
        "chosen: n = {} — {}",
        ident.model.order(),
        ident.order.reason
    );
    let v = &ident.validation;
    let what = if v.in_sample { "in-sample" } else { "held-out" };
    let fits: Vec<String> = id
        .channel
        .outputs
        .iter()
        .zip(v.nrmse.iter())
        .map(|(n, e)| format!("{n} {e:.3}"))
        .collect();
    println!("validation on {} {what} samples:", v.samples);
    println!("  one-step NRMSE: {}", fits.join(", "));
    let lb: Vec<String> = id
        .channel
        .outputs
        .iter()
        .zip(&v.ljung_box)
        .map(|(n, t)| format!("{n} p = {:.3}", t.p_value))
        .collect();
    if let Some(first) = v.ljung_box.first() {
        println!(
            "  innovation whiteness (Ljung–Box, {} lags): {}",
            first.lags,
            lb.join(", ")
        );
    }
    if let Some(nis) = v.nis_mean {
        println!(
            "  mean normalised innovation square {nis:.3} (expected {})",
            v.outputs
        );
    }
    println!(
        "  predictor A − KC: spectral radius {:.4}{}",
        v.predictor_spectral_radius,
        if v.predictor_spectral_radius < 1.0 {
            " (stable)"
        } else {
            " (NOT stable)"
        }
    );
    println!(
        "  the written channel's Kalman filter: Σ = Re to {:.1e} (relative)",
        id.sigma_mismatch
    );
}

/// `--json`: what was found, in the terms of the printed report.
#[derive(Debug, Serialize)]
struct Report {
    channel: String,
    inputs: Vec<String>,
    outputs: Vec<String>,
    dropped: Vec<String>,
    runs: Vec<RunReport>,
    singular_values: Vec<f64>,
    candidates: Vec<CandidateReport>,
    order: usize,
    reason: String,
    horizon: usize,
    validation: ValidationReport,
    sigma_mismatch: f64,
    period: Option<f64>,
}

#[derive(Debug, Serialize)]
struct RunReport {
    file: String,
    start: String,
    samples: usize,
    used: bool,
}

#[derive(Debug, Serialize)]
struct CandidateReport {
    order: usize,
    aic: Option<f64>,
    bic: Option<f64>,
    holdout_nrmse: Vec<f64>,
    predictor_spectral_radius: Option<f64>,
    failure: Option<String>,
}

#[derive(Debug, Serialize)]
struct ValidationReport {
    samples: usize,
    in_sample: bool,
    nrmse: Vec<f64>,
    ljung_box_p: Vec<f64>,
    ljung_box_lags: usize,
    nis_mean: Option<f64>,
    expected_nis: usize,
    predictor_spectral_radius: f64,
}

impl Report {
    fn of(id: &Identified) -> Self {
        let ident = &id.identification;
        let finite = |v: f64| v.is_finite().then_some(v);
        let v = &ident.validation;
        Self {
            channel: id.channel.name.clone(),
            inputs: id.channel.inputs.clone(),
            outputs: id.channel.outputs.clone(),
            dropped: id.dropped.clone(),
            runs: id
                .runs
                .iter()
                .map(|r| RunReport {
                    file: r.file.display().to_string(),
                    start: r.start.clone(),
                    samples: r.samples,
                    used: r.used,
                })
                .collect(),
            singular_values: ident.order.singular_values.iter().copied().collect(),
            candidates: ident
                .order
                .candidates
                .iter()
                .map(|c| CandidateReport {
                    order: c.order,
                    aic: finite(c.aic),
                    bic: finite(c.bic),
                    holdout_nrmse: c.holdout_nrmse.iter().copied().collect(),
                    predictor_spectral_radius: finite(c.predictor_spectral_radius),
                    failure: c.failure.clone(),
                })
                .collect(),
            order: ident.model.order(),
            reason: ident.order.reason.clone(),
            horizon: ident.horizon,
            validation: ValidationReport {
                samples: v.samples,
                in_sample: v.in_sample,
                nrmse: v.nrmse.iter().copied().collect(),
                ljung_box_p: v.ljung_box.iter().map(|t| t.p_value).collect(),
                ljung_box_lags: v.ljung_box.first().map_or(0, |t| t.lags),
                nis_mean: v.nis_mean,
                expected_nis: v.outputs,
                predictor_spectral_radius: v.predictor_spectral_radius,
            },
            sigma_mismatch: id.sigma_mismatch,
            period: id.channel.period,
        }
    }
}
