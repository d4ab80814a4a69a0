//! `glrmon identify`: a channel's model from fault-free recordings (subspace
//! identification of an innovation model, order selection, validation), written as a
//! commented configuration. See [`glrmon_eval::identify`].
//!
//! With `--model CONFIG`: the noise covariances Q, R (and S) of the user's own model
//! (F, G, H, J kept) from fault-free recordings, written into a copy of the
//! configuration. See [`glrmon_eval::noise`].

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use glrmon_eval::identify::{Identified, IdentifyError, IdentifyRequest, identify_channel};
use glrmon_ident::{Criterion, Detrend, Holdout, IdentSettings, Method, PreprocessSettings};
use serde::Serialize;

use crate::common::InvalidInput;

#[derive(Debug, Args)]
pub(crate) struct IdentifyArgs {
    /// Name of the channel to write (with --model: the channel whose noise is estimated,
    /// optional when the configuration has one channel).
    #[arg(long, required_unless_present = "model")]
    channel: Option<String>,
    /// Keep this configuration's model (F, G, H, J) and estimate only its noise
    /// covariances Q, R (and S) from the recordings (autocovariance least squares); the
    /// configuration is written to --output with the estimate in place of its Q, R, S.
    #[arg(long, value_name = "CONFIG", conflicts_with_all = [
        "order", "max_order", "inputs", "outputs", "criterion", "horizon", "detrend",
        "window", "holdout", "holdout_last",
    ])]
    model: Option<PathBuf>,
    /// With --model: the structure of Q (full: every entry; diagonal: uncorrelated
    /// process noises, fewer parameters when a full Q is not identifiable).
    #[arg(long, value_enum, default_value_t = QStructureArg::Full, requires = "model")]
    q_structure: QStructureArg,
    /// With --model: also estimate the cross covariance S = E[w vᵀ] (otherwise S = 0
    /// and any S of the configuration is removed).
    #[arg(long, requires = "model")]
    cross_covariance: bool,
    /// With --model: autocovariance lags fitted.
    #[arg(long, default_value_t = 15, requires = "model")]
    lags: usize,
    /// Fault-free recordings, CSV (named columns) or MCAP; each file, and each run of
    /// consecutive samples in it, is a separate experiment (never joined).
    #[arg(required = true)]
    input: Vec<PathBuf>,
    /// Read MCAP recordings glrmon did not write (ROS 2 bags, Foxglove MCAP) through
    /// the [channels.topics] of --channel in this configuration: only its mapping is
    /// used (the columns are then u0…, y0…, p0…); the model identified is written in
    /// place of its own. With --model, that configuration's mapping is used instead.
    #[arg(long, value_name = "CONFIG", conflicts_with = "model")]
    topics: Option<PathBuf>,
    /// The configuration file to write.
    #[arg(long)]
    output: PathBuf,
    /// Overwrite --output if it exists.
    #[arg(long)]
    force: bool,
    /// Input columns, in order (default: the u0, u1, … columns).
    #[arg(long, value_delimiter = ',')]
    inputs: Option<Vec<String>>,
    /// Output columns, in order (default: the y0, y1, … columns).
    #[arg(long, value_delimiter = ',')]
    outputs: Option<Vec<String>>,
    /// Model order n (default: chosen by --criterion up to --max-order).
    #[arg(long, conflicts_with = "max_order")]
    order: Option<usize>,
    /// Largest candidate order.
    #[arg(long, default_value_t = 10)]
    max_order: usize,
    /// Subspace method: auto (a Granger test of y → u at 1 % decides whether the data
    /// were recorded under feedback: pbsid if so, moesp otherwise; the report says which
    /// and why), moesp (PO-MOESP, open-loop data) or pbsid (predictor-based, consistent
    /// on data recorded under feedback control).
    #[arg(long, value_enum, default_value_t = MethodArg::Auto, conflicts_with = "model")]
    method: MethodArg,
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum QStructureArg {
    Full,
    Diagonal,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum MethodArg {
    Auto,
    Moesp,
    Pbsid,
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
    if let Some(config) = &args.model {
        return noise::run(args, config, &files);
    }
    let Some(channel) = args.channel.clone() else {
        // clap refuses this already (required_unless_present): a usage error, exit 2.
        clap::Error::raw(
            clap::error::ErrorKind::MissingRequiredArgument,
            "--channel NAME is required (unless --model CONFIG is given)\n",
        )
        .exit();
    };
    let topics = match &args.topics {
        Some(path) => {
            let cfg = crate::common::load_config(path)?;
            let c = cfg
                .pick_channel(Some(&channel))
                .map_err(|e| InvalidInput(format!("--topics {}: {e}", path.display())))?;
            if c.topics.is_none() {
                return Err(InvalidInput(format!(
                    "--topics {}: channel \"{channel}\" has no [channels.topics] mapping a \
                     recording's topics to its signals",
                    path.display()
                ))
                .into());
            }
            Some(c.clone())
        }
        None => None,
    };
    let request = IdentifyRequest {
        channel: channel.clone(),
        topics,
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
            method: match args.method {
                MethodArg::Auto => Method::Auto,
                MethodArg::Moesp => Method::Moesp,
                MethodArg::Pbsid => Method::Pbsid,
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
                channel,
                files.join(", ")
            ),
            format!(
                "Next: {}",
                next_calibrate(&args.output.display().to_string(), &channel, Some(1.0))
            ),
        ],
    };
    let mut identified = identify_channel(&request).map_err(|e| match e {
        IdentifyError::Written(_) => anyhow::Error::from(e),
        IdentifyError::Input(e) => crate::common::input_error(e),
        IdentifyError::Request { option, why } => InvalidInput(format!(
            "{}: {why}",
            match option {
                "files" => "the input files".to_owned(),
                flag => format!("--{}", flag.replace('_', "-")),
            }
        ))
        .into(),
        other => InvalidInput(other.to_string()).into(),
    })?;
    if identified.channel.period.is_none() {
        // The header's Next line was written before the period was known.
        identified.config = identified.config.replace(
            &next_calibrate(&args.output.display().to_string(), &channel, Some(1.0)),
            &next_calibrate(&args.output.display().to_string(), &channel, None),
        );
    }
    std::fs::write(&args.output, &identified.config)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", args.output.display()))?;
    warn_if_invalid(&identified, &args.output);
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&Report::of(&identified))?
        );
    } else {
        print_report(&identified);
        println!(
            "\nwrote {} (a valid configuration{}). Next, its threshold from fault-free \
             recordings other than these (a threshold set on the data the model was fitted \
             to gives more false alarms on new data than it promises):\n  {}\n\
             then monitor: glrmon replay --config {} NEW.csv   or   glrmon run --config {}",
            args.output.display(),
            if identified.validation_failures.is_empty() {
                ""
            } else {
                "; its model FAILED the held-out validation: see the WARNING"
            },
            next_calibrate(
                &args.output.display().to_string(),
                &channel,
                identified.channel.period
            ),
            args.output.display(),
            args.output.display(),
        );
    }
    Ok(())
}

/// The calibration to run next, on fault-free recordings other than the identification
/// data, for an operator's target: at most one false alarm a day on average (`1d` when
/// the channel has a period, else 10 000 samples).
fn next_calibrate(config: &str, channel: &str, period: Option<f64>) -> String {
    format!(
        "glrmon calibrate --config {config} --channel {channel} OTHER-DAYS.csv --mtbfa {} \
         --write",
        if period.is_some() { "1d" } else { "10000" }
    )
}

/// The loud warning of a model that fails its validation: written all the same (a
/// calibrated threshold can still make it a usable monitor), but on standard error, each
/// failed check in words.
fn warn_if_invalid(id: &Identified, output: &std::path::Path) {
    if id.validation_failures.is_empty() {
        return;
    }
    let v = &id.identification.validation;
    eprintln!(
        "WARNING: the identified model FAILS its {} validation ({} failed check(s)); {} was \
         written all the same:",
        if v.in_sample { "in-sample" } else { "held-out" },
        id.validation_failures.len(),
        output.display()
    );
    for line in &id.validation_failures {
        eprintln!("WARNING:   {line}");
    }
    let v = &id.identification.validation;
    let level = v.per_output_level();
    if v.ljung_box.iter().any(|t| t.p_value < level) {
        eprintln!(
            "WARNING: what to do: innovations that are not white mean dynamics the model \
             misses: try a higher order (--order N, or a larger --max-order), --detrend for \
             slow drifts, --method pbsid if a controller acts on these outputs, or longer or \
             more varied recordings (inputs that move)"
        );
    }
    if v.nis_mean
        .is_none_or(|m| m < v.nis_interval.0 || m > v.nis_interval.1)
    {
        eprintln!(
            "WARNING: what to do: innovations of another size than Re says make a χ² \
             threshold wrong: a threshold calibrated on fault-free data absorbs that \
             (below); if the plant's noise changes from day to day, identify from more days"
        );
    }
    eprintln!(
        "WARNING: calibrate its threshold on fault-free data other than these (glrmon \
         calibrate --mtbfa 1d --write) and check the false-alarm rate on an independent run \
         before trusting its alarms"
    );
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
    println!("method: {}", id.method_line);
    println!(
        "estimated work: {} of memory, ~{:.1} s at {:.0e} floating-point operations/s",
        glrmon_spec::limits::human_bytes(id.work.bytes),
        id.work.flops / glrmon_eval::identify::ASSUMED_FLOPS_PER_SECOND,
        glrmon_eval::identify::ASSUMED_FLOPS_PER_SECOND
    );
    let sv: Vec<String> = ident
        .order
        .singular_values
        .iter()
        .take(16)
        .map(|s| format!("{s:.3}"))
        .collect();
    println!("singular values: {}", sv.join(" "));
    println!(
        "order        AIC          BIC   held-out NRMSE (mean)   ρ(A−KC)  not white  NIS (interval)"
    );
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
            None => {
                let (white, nis) = c.validation.as_ref().map_or_else(
                    || ("-".to_owned(), "-".to_owned()),
                    |v| {
                        (
                            v.not_white().len().to_string(),
                            format!(
                                "{:.2} [{:.2}, {:.2}]{}",
                                v.nis_mean.unwrap_or(f64::NAN),
                                v.nis_interval.0,
                                v.nis_interval.1,
                                if v.nis_consistent() { "" } else { " ✗" }
                            ),
                        )
                    },
                );
                println!(
                    "{:>5} {:>10.1} {:>12.1} {:>22.4} {:>9.3} {white:>10}  {nis}{mark}",
                    c.order, c.aic, c.bic, mean, c.predictor_spectral_radius
                );
            }
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
    println!(
        "validation on {} {what} samples ({}):",
        v.samples,
        if v.passed() { "passed" } else { "FAILED" }
    );
    println!(
        "  one-step NRMSE (prediction error over the output's spread; 0 perfect, 1 no \
         better than the mean): {}",
        fits.join(", ")
    );
    println!(
        "    {}",
        nrmse_verdict(&id.channel.outputs, v.nrmse.as_slice())
    );
    if let Some(first) = v.ljung_box.first() {
        println!(
            "  innovation whiteness (Ljung–Box, {} lags) and consistency (NIS):",
            first.lags
        );
    }
    for line in v.verdicts(&id.channel.outputs, true) {
        println!("    {line}");
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

/// What the one-step NRMSE says, in words: how much of each output's spread the
/// model predicts one sample ahead. A high NRMSE is not a failure in itself (an output
/// driven mostly by noise cannot be predicted, and the whiteness and NIS checks say
/// whether the model has captured what can be); it says which sensors will show small
/// faults and which only large ones.
fn nrmse_verdict(outputs: &[String], nrmse: &[f64]) -> String {
    let part = |name: &String, e: f64| {
        if e.is_finite() {
            format!("{name} {:.0} %", 100.0 * (1.0 - (e * e).min(1.0)))
        } else {
            format!("{name} (no spread)")
        }
    };
    let list: Vec<String> = outputs
        .iter()
        .zip(nrmse)
        .map(|(n, &e)| part(n, e))
        .collect();
    let noisy: Vec<&str> = outputs
        .iter()
        .zip(nrmse)
        .filter(|(_, e)| **e > 0.7)
        .map(|(n, _)| n.as_str())
        .collect();
    let mut s = format!(
        "→ share of each output's variance predicted one sample ahead: {}",
        list.join(", ")
    );
    if !noisy.is_empty() {
        s.push_str(&format!(
            "; {} mostly noise, so only faults large against that noise show there (not a \
             failure: whiteness and NIS decide whether the model is right)",
            noisy.join(", ")
        ));
    }
    s
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
    method: MethodReport,
    estimated_bytes: u64,
    estimated_flops: f64,
}

#[derive(Debug, Serialize)]
struct MethodReport {
    requested: &'static str,
    used: &'static str,
    reason: String,
    feedback: Option<FeedbackReport>,
    fallback: Option<String>,
    untested: Option<String>,
}

#[derive(Debug, Serialize)]
struct FeedbackReport {
    statistic: Option<f64>,
    dof: usize,
    p_value: f64,
    lags: usize,
    level: f64,
    feedback: bool,
    per_input_p: Vec<Option<f64>>,
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
    not_white: Option<usize>,
    nis_mean: Option<f64>,
    nis_interval: Option<[f64; 2]>,
    validation_passed: Option<bool>,
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
    nis_interval: [f64; 2],
    not_white: Vec<String>,
    level: f64,
    passed: bool,
    failures: Vec<String>,
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
                    not_white: c.validation.as_ref().map(|v| v.not_white().len()),
                    nis_mean: c.validation.as_ref().and_then(|v| v.nis_mean),
                    nis_interval: c
                        .validation
                        .as_ref()
                        .map(|v| [v.nis_interval.0, v.nis_interval.1]),
                    validation_passed: c.validation.as_ref().map(|v| v.passed()),
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
                nis_interval: [v.nis_interval.0, v.nis_interval.1],
                not_white: v
                    .not_white()
                    .into_iter()
                    .map(|j| id.channel.outputs[j].clone())
                    .collect(),
                level: v.level,
                passed: v.passed(),
                failures: id.validation_failures.clone(),
                predictor_spectral_radius: v.predictor_spectral_radius,
            },
            sigma_mismatch: id.sigma_mismatch,
            period: id.channel.period,
            method: MethodReport {
                requested: ident.method.requested.name(),
                used: ident.method.used.name(),
                reason: id.method_line.clone(),
                feedback: ident.method.feedback.as_ref().map(|t| FeedbackReport {
                    statistic: finite(t.statistic),
                    dof: t.dof,
                    p_value: t.p_value,
                    lags: t.lags,
                    level: t.level,
                    feedback: t.feedback(),
                    per_input_p: t.per_input.clone(),
                }),
                fallback: ident.method.fallback.clone(),
                untested: ident.method.untested.clone(),
            },
            estimated_bytes: id.work.bytes,
            estimated_flops: id.work.flops,
        }
    }
}

/// `glrmon identify --model CONFIG`: the noise covariances of the user's own model.
mod noise {
    use std::path::Path;

    use glrmon_eval::noise::{NoiseError, NoiseReport, NoiseRequest, estimate_channel_noise};
    use glrmon_ident::{CrossCovariance, IdentError, NoiseSettings, NoiseStructure, Structure};
    use nalgebra::DMatrix;
    use serde::Serialize;

    use super::{IdentifyArgs, QStructureArg};
    use crate::common::InvalidInput;

    pub(super) fn run(args: &IdentifyArgs, config: &Path, files: &[String]) -> anyhow::Result<()> {
        let text = std::fs::read_to_string(config)
            .map_err(|e| InvalidInput(format!("reading {}: {e}", config.display())))?;
        let request = NoiseRequest {
            config: text,
            channel: args.channel.clone(),
            files: args.input.clone(),
            settings: NoiseSettings {
                structure: NoiseStructure {
                    q: match args.q_structure {
                        QStructureArg::Full => Structure::Full,
                        QStructureArg::Diagonal => Structure::Diagonal,
                    },
                    s: if args.cross_covariance {
                        CrossCovariance::Free
                    } else {
                        CrossCovariance::Zero
                    },
                    ..NoiseStructure::default()
                },
                lags: args.lags,
                ..NoiseSettings::default()
            },
            source: format!(
                "`glrmon identify --model {}` (autocovariance least squares) on {}",
                config.display(),
                files.join(", ")
            ),
        };
        let report = estimate_channel_noise(&request).map_err(|e| error(e, args))?;
        std::fs::write(&args.output, &report.config)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", args.output.display()))?;
        let next = super::next_calibrate(
            &args.output.display().to_string(),
            &report.channel,
            glrmon_spec::parse(&report.config).ok().and_then(|c| {
                c.channels
                    .iter()
                    .find(|ch| ch.name == report.channel)
                    .and_then(|ch| ch.period)
            }),
        );
        if args.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&Report::of(&report, args, &next))?
            );
        } else {
            print_report(&report, args);
            println!(
                "\nwrote {} (it validates): {}'s model with the estimated noise. Next, \
                 thresholds from fault-free data:\n  {next}",
                args.output.display(),
                config.display()
            );
        }
        Ok(())
    }

    /// The exit code of a refusal: a runtime failure reading a file is 3, everything
    /// else (the configuration, the data, an unidentifiable structure) is the user's
    /// input (1).
    fn error(e: NoiseError, args: &IdentifyArgs) -> anyhow::Error {
        match e {
            NoiseError::Input(e) => crate::common::input_error(e),
            NoiseError::Ident(IdentError::NotIdentifiable { .. }) => {
                let hint = if args.cross_covariance {
                    "leave out --cross-covariance (S with a full Q is never identifiable)"
                } else if args.q_structure == QStructureArg::Full {
                    "try --q-structure diagonal"
                } else {
                    "the data cannot separate these parameters for this model"
                };
                InvalidInput(format!("{e}\nhint: {hint}")).into()
            }
            other => InvalidInput(other.to_string()).into(),
        }
    }

    /// A number for a person: 4 decimals, or 4 significant digits when far from 1.
    fn num(v: f64) -> String {
        if v == 0.0 || (1e-2..1e5).contains(&v.abs()) {
            format!("{v:.4}")
        } else {
            format!("{v:.3e}")
        }
    }

    fn print_matrix(name: &str, m: &DMatrix<f64>) {
        println!("{name} =");
        for row in m.row_iter() {
            let cells: Vec<String> = row.iter().map(|&v| format!("{:>11}", num(v))).collect();
            println!("  [{} ]", cells.join(""));
        }
    }

    /// ‖a − b‖ / ‖b‖ (Frobenius).
    fn change(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
        (a - b).norm() / b.norm().max(f64::MIN_POSITIVE)
    }

    /// σ of the mean of N χ²_p values, sqrt(2p / N).
    fn nis_sigma(p: usize, samples: usize) -> f64 {
        (2.0 * p as f64 / samples.max(1) as f64).sqrt()
    }

    fn print_report(report: &NoiseReport, args: &IdentifyArgs) {
        let est = &report.estimate;
        let used: Vec<_> = report.runs.iter().filter(|r| r.used).collect();
        println!(
            "channel \"{}\": F, G, H, J kept (n = {}, {} input(s), {} output(s)); estimating \
             Q ({}), R (full), S ({})",
            report.channel,
            est.q.nrows(),
            report.inputs.len(),
            report.outputs.len(),
            match args.q_structure {
                QStructureArg::Full => "full",
                QStructureArg::Diagonal => "diagonal",
            },
            if args.cross_covariance {
                "free"
            } else {
                "zero"
            },
        );
        println!(
            "{} experiment(s), {} samples; u [{}], y [{}]; {}",
            used.len(),
            used.iter().map(|r| r.samples).sum::<usize>(),
            report.inputs.join(", "),
            report.outputs.join(", "),
            if report.scaled {
                "the channel's scaling applied (model units)"
            } else {
                "no scaling"
            }
        );
        for r in report.runs.iter().filter(|r| !r.used) {
            println!(
                "  left out: {} from {} ({} samples, fewer than {})",
                r.file.display(),
                r.start,
                r.samples,
                glrmon_eval::noise::MIN_RUN_SAMPLES
            );
        }
        println!(
            "design matrix: rank {} for {} parameters ({}); {} lags",
            est.design_rank,
            est.parameters.len(),
            est.parameters.join(" "),
            est.lags
        );
        println!("iteration  ρ(F−LH)  samples  residual  cond      ΔQ       ΔR");
        let mut previous: Option<(&DMatrix<f64>, &DMatrix<f64>)> = None;
        for (i, it) in est.iterations.iter().enumerate() {
            let (dq, dr) = match previous {
                Some((q, r)) => (
                    format!("{:>8.4}", change(&it.q, q)),
                    format!("{:>8.4}", change(&it.r, r)),
                ),
                None => (format!("{:>8}", "—"), format!("{:>8}", "—")),
            };
            println!(
                "{:>9} {:>8.4} {:>8} {:>9.4} {:>9.2e} {dq} {dr}{}",
                i + 1,
                it.predictor_spectral_radius,
                it.samples,
                it.residual,
                it.design_condition,
                if it.projected {
                    "  (projected onto PSD)"
                } else {
                    ""
                }
            );
            previous = Some((&it.q, &it.r));
        }
        print_matrix("Q", &est.q);
        print_matrix("R", &est.r);
        if let Some(s) = &est.s {
            print_matrix("S", s);
        }
        print_matrix("steady Kalman gain K (predictor form)", &est.k);
        print_matrix("innovation covariance Re", &est.re);
        let p = report.outputs.len();
        let samples = est.iterations.last().map_or(0, |it| it.samples);
        if let Some(nis) = est.nis_mean {
            let sigma = nis_sigma(p, samples);
            let z = (nis - p as f64) / sigma;
            println!(
                "mean NIS on the data {nis:.4} (expected p = {p}; σ ≈ {sigma:.4}, z = {z:.2}{})",
                if z.abs() <= 4.0 {
                    ": consistent"
                } else {
                    ": NOT consistent"
                }
            );
        }
        if let Some(first) = est.ljung_box.first() {
            let lb: Vec<String> = report
                .outputs
                .iter()
                .zip(&est.ljung_box)
                .map(|(n, t)| format!("{n} p = {:.3}", t.p_value))
                .collect();
            println!(
                "innovation whiteness (Ljung–Box, {} lags): {}",
                first.lags,
                lb.join(", ")
            );
        }
    }

    fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
        m.row_iter().map(|r| r.iter().copied().collect()).collect()
    }

    /// `--json`: the printed report.
    #[derive(Debug, Serialize)]
    struct Report {
        channel: String,
        inputs: Vec<String>,
        outputs: Vec<String>,
        scaled: bool,
        runs: Vec<super::RunReport>,
        q_structure: &'static str,
        cross_covariance: bool,
        lags: usize,
        parameters: Vec<String>,
        design_rank: usize,
        iterations: Vec<Iteration>,
        q: Vec<Vec<f64>>,
        r: Vec<Vec<f64>>,
        s: Option<Vec<Vec<f64>>>,
        k: Vec<Vec<f64>>,
        re: Vec<Vec<f64>>,
        p: Vec<Vec<f64>>,
        nis_mean: Option<f64>,
        expected_nis: usize,
        nis_sigma: f64,
        ljung_box_p: Vec<f64>,
        ljung_box_lags: usize,
        output: String,
        next: String,
    }

    #[derive(Debug, Serialize)]
    struct Iteration {
        predictor_spectral_radius: f64,
        transient: usize,
        samples: usize,
        residual: f64,
        design_condition: f64,
        projected: bool,
        q_change: Option<f64>,
        r_change: Option<f64>,
    }

    impl Report {
        fn of(report: &NoiseReport, args: &IdentifyArgs, next: &str) -> Self {
            let est = &report.estimate;
            let p = report.outputs.len();
            let samples = est.iterations.last().map_or(0, |it| it.samples);
            Self {
                channel: report.channel.clone(),
                inputs: report.inputs.clone(),
                outputs: report.outputs.clone(),
                scaled: report.scaled,
                runs: report
                    .runs
                    .iter()
                    .map(|r| super::RunReport {
                        file: r.file.display().to_string(),
                        start: r.start.clone(),
                        samples: r.samples,
                        used: r.used,
                    })
                    .collect(),
                q_structure: match args.q_structure {
                    QStructureArg::Full => "full",
                    QStructureArg::Diagonal => "diagonal",
                },
                cross_covariance: args.cross_covariance,
                lags: est.lags,
                parameters: est.parameters.clone(),
                design_rank: est.design_rank,
                iterations: est
                    .iterations
                    .iter()
                    .enumerate()
                    .map(|(i, it)| {
                        let before = i.checked_sub(1).map(|j| &est.iterations[j]);
                        Iteration {
                            predictor_spectral_radius: it.predictor_spectral_radius,
                            transient: it.transient,
                            samples: it.samples,
                            residual: it.residual,
                            design_condition: it.design_condition,
                            projected: it.projected,
                            q_change: before.map(|b| change(&it.q, &b.q)),
                            r_change: before.map(|b| change(&it.r, &b.r)),
                        }
                    })
                    .collect(),
                q: rows(&est.q),
                r: rows(&est.r),
                s: est.s.as_ref().map(rows),
                k: rows(&est.k),
                re: rows(&est.re),
                p: rows(&est.p),
                nis_mean: est.nis_mean,
                expected_nis: p,
                nis_sigma: nis_sigma(p, samples),
                ljung_box_p: est.ljung_box.iter().map(|t| t.p_value).collect(),
                ljung_box_lags: est.ljung_box.first().map_or(0, |t| t.lags),
                output: args.output.display().to_string(),
                next: next.to_owned(),
            }
        }
    }
}
