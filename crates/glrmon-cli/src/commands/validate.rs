//! `glrmon validate FILE`: every error with its path, or per channel a summary and the
//! isolability report (Basseville 1996 §5-6) of its fault dictionary.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use glrmon_core::Onset;
use glrmon_core::calibration::Target;
use glrmon_core::information::window_information;
use glrmon_core::isolability::{DEFAULT_CORRELATION_LIMIT, isolability};
use glrmon_spec::{Channel, ThresholdSource};
use nalgebra::DMatrix;

use crate::common::InvalidInput;
use crate::common::simulator;

#[derive(Debug, Args)]
pub(crate) struct ValidateArgs {
    /// Configuration file.
    file: PathBuf,
}

pub(crate) fn run(args: &ValidateArgs) -> anyhow::Result<()> {
    let cfg = match glrmon_spec::load(&args.file) {
        Ok(c) => c,
        Err(errors) => {
            println!(
                "{}: invalid ({} error(s))",
                args.file.display(),
                errors.errors.len()
            );
            for e in &errors.errors {
                println!("  error: {e}");
            }
            return Err(InvalidInput(format!("{} is invalid", args.file.display())).into());
        }
    };
    println!(
        "{}: valid, {} channel(s)",
        args.file.display(),
        cfg.channels.len()
    );
    let mut warnings: Vec<String> = cfg.warnings.iter().map(ToString::to_string).collect();
    for channel in &cfg.channels {
        print!("{}", report(channel, &mut warnings)?);
    }
    for w in &warnings {
        println!("warning: {w}");
    }
    Ok(())
}

fn fmt_matrix(m: &DMatrix<f64>) -> String {
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| {
            let v: Vec<String> = r.iter().map(|x| format!("{x:.6e}")).collect();
            format!("[{}]", v.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

/// The Fisher information C_k(r) of the dictionary over one window
/// ([`window_information`]), on the channel's simulated inputs and signals, with the
/// steady-state Σ when the model is LTI and the Riccati recursion has converged.
fn channel_information(
    channel: &Channel,
) -> anyhow::Result<(DMatrix<f64>, Option<DMatrix<f64>>, usize)> {
    let mut det = channel.detector()?;
    let mut sim = simulator(channel, 1, &[], 0, &[])?;
    let samples = std::iter::repeat_with(|| {
        let s = sim.next_sample();
        (s.u, s.y, s.p)
    });
    let info = window_information(&mut det, samples)?;
    let steady = (channel.model_is_constant() && info.converged).then_some(info.covariance);
    Ok((info.information, steady, info.samples))
}

fn report(channel: &Channel, warnings: &mut Vec<String>) -> anyhow::Result<String> {
    let d = channel.dims;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "channel \"{}\" (key {}): n = {} states, l = {} inputs, p = {} outputs, q = {} signals, m = {} faults",
        channel.name,
        channel.key,
        d.states,
        d.inputs,
        d.outputs,
        d.signals,
        channel.fault_names.len()
    );
    let model = if channel.model_is_constant() {
        "LTI"
    } else {
        "LPV (time-varying)"
    };
    let known = channel.onsets().iter().all(|o| *o == Onset::Known);
    let mut window = if known {
        "known profiles: GLR over all samples (no onset search)".to_owned()
    } else {
        format!(
            "window w = {}, s = {}",
            channel.window.window, channel.window.min_lag
        )
    };
    if channel.window.warm_up > 0 {
        let _ = write!(
            window,
            ", GLR held off for the first {} samples after a (re)start",
            channel.window.warm_up
        );
    }
    let threshold = match channel.threshold_source {
        ThresholdSource::Explicit => format!("{:.4} (explicit)", channel.alarm.threshold),
        ThresholdSource::Bonferroni { false_alarm } => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e}/(w − s), Bonferroni: conservative)",
            channel.alarm.threshold,
            channel.fault_names.len()
        ),
        ThresholdSource::Chi2 { false_alarm } if channel.chi2_detector => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e} per sample)",
            channel.alarm.threshold,
            channel.innovation_dof()
        ),
        ThresholdSource::Chi2 { false_alarm } => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e} per onset: optimistic, the window's \
             maximum exceeds it far more often; see `glrmon calibrate`)",
            channel.alarm.threshold,
            channel.fault_names.len()
        ),
        ThresholdSource::Calibrated {
            target: Target::Mtbfa(mtbfa),
            samples,
            episodes,
            interval,
            ..
        } => format!(
            "{:.4} (calibrated for one false-alarm episode per {mtbfa} samples on {samples} \
             fault-free samples, {episodes} episodes; 95 % interval {:.4}–{:.4})",
            channel.alarm.threshold, interval[0], interval[1]
        ),
        ThresholdSource::Calibrated {
            target: Target::SampleFar(fraction),
            samples,
            episodes,
            exceedances,
            interval,
        } => format!(
            "{:.4} (calibrated for a fraction {fraction} of fault-free samples above it on \
             {samples} fault-free samples, {} above in {episodes} clusters; 95 % interval \
             {:.4}–{:.4})",
            channel.alarm.threshold,
            exceedances.map_or_else(|| "?".to_owned(), |n| n.to_string()),
            interval[0],
            interval[1]
        ),
    };
    let _ = writeln!(s, "  model: {model}; {window}; threshold {threshold}");
    if channel.chi2_detector {
        let _ = writeln!(
            s,
            "  detector: the plain χ²({}) test of εᵀΣ⁻¹ε on each sample (baseline; no onset estimate, no isolation)",
            channel.dims.outputs
        );
    }
    let faults: Vec<String> = channel
        .fault_names
        .iter()
        .zip(channel.onsets())
        .map(|(n, o)| format!("{n} ({})", format!("{o:?}").to_lowercase()))
        .collect();
    let _ = writeln!(s, "  faults: {}", faults.join(", "));
    let diag = &channel.diagnosis;
    if diag.enabled {
        let span = diag.span.map_or_else(
            || "from r̂ to the alarm".to_owned(),
            |n| format!("at most {n} samples"),
        );
        let _ = writeln!(
            s,
            "  sparse diagnosis at alarms: {:?} residual, span {span}, history {} samples, no-fault test at α = {}, λ path of {} points down to {:e}·λ_max",
            diag.residual, diag.history, diag.alpha, diag.lasso.path_points, diag.lasso.ratio
        );
    } else {
        let _ = writeln!(s, "  sparse diagnosis at alarms: off");
    }
    match channel.consistency {
        Some(c) => {
            let band = glrmon_core::consistency::Consistency::new(channel.innovation_dof(), c)
                .map(|t| t.band())
                .unwrap_or((f64::NAN, f64::NAN));
            let _ = writeln!(
                s,
                "  model consistency: blocks of {} samples, mean of εᵀΣ⁻¹ε expected {} within [{:.3}, {:.3}] (α = {:e})",
                c.window,
                channel.innovation_dof(),
                band.0,
                band.1,
                c.alpha
            );
        }
        None => {
            let _ = writeln!(s, "  model consistency: off");
        }
    }
    if let Some(e) = &channel.unknown_input {
        let _ = writeln!(
            s,
            "  unknown input: E has {} column(s), decoupled from the innovation: the GLR runs on {} of the {} output directions (Zhang 2021 §III-B); faults in range(E) are not detectable",
            e.shape().1,
            channel.innovation_dof(),
            channel.dims.outputs
        );
    }
    if channel.cross_covariance.is_some() {
        let _ = writeln!(
            s,
            "  correlated noises: S = E[w vᵀ] given, the predictor gain is (F P Hᵀ + S) Σ⁻¹ (an innovation model runs at its own order; sparse diagnosis's residual filters ignore S)"
        );
    }
    if let Some(scaling) = &channel.scaling {
        let list = |names: &[String], offset: &[f64], scale: &[f64]| {
            names
                .iter()
                .zip(offset.iter().zip(scale))
                .map(|(n, (o, s))| format!("{n} {o:.4} ± {s:.4}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            s,
            "  natural units: model = (raw − offset)/scale on intake; inputs [{}], outputs [{}]; \
             sensor/actuator bias magnitudes in raw units",
            list(&channel.columns.u, scaling.u_offset(), scaling.u_scale()),
            list(&channel.columns.y, scaling.y_offset(), scaling.y_scale())
        );
    }
    if channel.columns.named {
        let _ = writeln!(
            s,
            "  CSV columns: u = [{}], y = [{}]{} (other columns are skipped)",
            channel.columns.u.join(", "),
            channel.columns.y.join(", "),
            if channel.columns.p.is_empty() {
                String::new()
            } else {
                format!(", p = [{}]", channel.columns.p.join(", "))
            }
        );
    }
    let (info, steady, samples) = channel_information(channel)?;
    match steady {
        Some(sigma) => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance Σ = {}",
                fmt_matrix(&sigma)
            );
        }
        None if channel.model_is_constant() => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance: the Riccati recursion had not converged"
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance: none (the model varies with p(k))"
            );
        }
    }
    let rep = isolability(&info, DEFAULT_CORRELATION_LIMIT)?;
    let _ = writeln!(
        s,
        "  isolability over {samples} samples (Fisher information F = C_k(r), Basseville 1996 §5-6):"
    );
    let _ = writeln!(
        s,
        "    rank {} of {}, condition number {:.3e}, C1 = {:.4}, C2 = {:.4}, C3 = {:.4}",
        rep.rank,
        channel.fault_names.len(),
        rep.condition_number,
        rep.c1,
        rep.c2,
        rep.c3
    );
    if channel.fault_names.len() <= 12 {
        let _ = writeln!(s, "    F = {}", fmt_matrix(&info));
        let _ = writeln!(s, "    correlation = {}", fmt_matrix(&rep.correlation));
    } else {
        let _ = writeln!(
            s,
            "    largest pairwise |correlation| {:.4} over {} pairs",
            rep.max_pair_correlation(),
            rep.pairs.len()
        );
    }
    let names: Vec<&str> = channel.fault_names.iter().map(String::as_str).collect();
    let verdicts = rep.verdicts(&names, samples);
    if verdicts.is_empty() {
        let _ = writeln!(
            s,
            "    verdict: every pair of faults is separable by the minmax test over {samples} samples (|correlation| ≤ {DEFAULT_CORRELATION_LIMIT})"
        );
    }
    for v in verdicts {
        let _ = writeln!(s, "    verdict: {v}");
        warnings.push(format!("channel \"{}\": {v}", channel.name));
    }
    Ok(s)
}
