//! Zhang 2021, Example 2: leak localisation among 30 delayed-input candidates in a gas
//! pipeline (eqs. (43)-(49), Figs 6-7), on the stand-in model of
//! config/examples/paper2021-example2.toml (the paper's LPV model and records are not
//! printed; the configuration says what is made up).
//!
//! Leaks 10 and 15 (Φ_k columns −u_{k−10} and −u_{k−15}, eq. (48)) of magnitude θ are
//! simulated over N = 500 samples from the channel's configuration, as
//! `glrmon simulate` does, and diagnosed from the Kalman innovations (Proposition 1)
//! by the monitor's [`glrmon_monitor::DiagnosisEngine`], the engine behind
//! `glrmon diagnose`: Lasso path (eq. (39)), λ at the middle of the widest plateau,
//! least-squares refit.
//!
//! - The first run (seed 1, θ = 1e-4 as the paper) prints Fig. 6 (number of non-zero
//!   components of θ̂(λ) along the path, the chosen plateau marked) and Fig. 7 (the
//!   Lasso estimates of the isolated leaks at the plateau's ends and middle, the
//!   least-squares refit, the truth).
//! - Then, for each θ of `--magnitudes`, `--trials` seeded runs: the rate at which the
//!   isolated leaks are exactly 10 and 15, how often leaks were missed or added, and the
//!   mean refitted magnitudes. The SNR column is that of the leaks' contribution to the
//!   output against the sensor noise, 10·log₁₀(var(y_leaks)/var v) over the run.
//!
//! ```text
//! cargo run --release -p glrmon-cli --example example2 -- --trials 200
//! ```

use std::path::PathBuf;

use clap::Parser;
use glrmon_core::sparse::PlateauScale;
use glrmon_monitor::{DiagnosisEngine, SpanDiagnosis};
use glrmon_sim::{Injection, SimSample};
use glrmon_spec::Channel;
use nalgebra::DVector;

/// The leaks the paper simulates (1-based delays, its θ_10 and θ_15).
pub(crate) const LEAKS: [usize; 2] = [10, 15];

/// N, the data length of the paper's Example 2.
pub(crate) const SAMPLES: usize = 500;

#[derive(Debug, Parser)]
#[command(about = "Zhang 2021, Example 2: 2 leaks among 30 delayed-input candidates")]
struct Args {
    /// Runs per magnitude.
    #[arg(long, default_value_t = 200)]
    trials: u64,
    /// Leak magnitudes θ (both leaks), the paper's 1e-4 first.
    #[arg(long, value_delimiter = ',', default_values_t = [1e-4, 7e-5, 5e-5, 3e-5, 2e-5])]
    magnitudes: Vec<f64>,
    /// Override the configuration's plateau scale (`log` or `linear`).
    #[arg(long)]
    plateau_scale: Option<String>,
    /// The Example 2 configuration.
    #[arg(long)]
    config: Option<PathBuf>,
}

/// The shipped Example 2 configuration.
pub(crate) fn example2_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/examples/paper2021-example2.toml")
}

/// One run's diagnosis and the SNR of the leaks' contribution (dB).
pub(crate) fn run(
    channel: &Channel,
    theta: f64,
    seed: u64,
) -> Result<(SpanDiagnosis, f64), String> {
    let m = channel.fault_names.len();
    let mut magnitude = DVector::zeros(m);
    for leak in LEAKS {
        magnitude[leak - 1] = theta;
    }
    // The same seed with and without the leaks: the difference of the outputs is the
    // leaks' contribution, the noise being drawn identically.
    let outputs = |magnitude: DVector<f64>| -> Result<Vec<SimSample>, String> {
        let sim = glrmon_sim::from_channel(channel, seed).map_err(|e| e.to_string())?;
        let mut sim = glrmon_sim::inject(
            sim,
            channel,
            Injection {
                magnitude,
                onset: 0,
            },
        )
        .map_err(|e| e.to_string())?;
        Ok((0..SAMPLES).map(|_| sim.next_sample()).collect())
    };
    let faulty = outputs(magnitude)?;
    let clean = outputs(DVector::zeros(m))?;
    let mut engine = DiagnosisEngine::new(channel, SAMPLES).map_err(|e| e.to_string())?;
    for x in &faulty {
        engine.step(&x.sample()).map_err(|e| e.to_string())?;
    }
    let last = SAMPLES as u64 - 1;
    let d = engine
        .diagnose(last, 0, 0, last)
        .map_err(|e| e.to_string())?;
    let leak: Vec<f64> = faulty
        .iter()
        .zip(&clean)
        .map(|(f, c)| f.y[0] - c.y[0])
        .collect();
    let var = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64
    };
    let r = channel.model.matrices()[5].base()[(0, 0)];
    Ok((d, 10.0 * (var(&leak) / r).log10()))
}

fn main() -> std::process::ExitCode {
    match main_inner() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("example2: {e}");
            std::process::ExitCode::from(1)
        }
    }
}

fn main_inner() -> Result<(), String> {
    let args = Args::parse();
    let path = args.config.clone().unwrap_or_else(example2_path);
    let cfg = glrmon_spec::load(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut channel = cfg
        .channels
        .first()
        .cloned()
        .ok_or_else(|| format!("{}: no channel", path.display()))?;
    match args.plateau_scale.as_deref() {
        None => {}
        Some("log") => channel.diagnosis.lasso.plateau_scale = PlateauScale::Log,
        Some("linear") => channel.diagnosis.lasso.plateau_scale = PlateauScale::Linear,
        Some(other) => return Err(format!("--plateau-scale {other}: log or linear")),
    }
    let names = &channel.fault_names;
    let truth: Vec<String> = LEAKS.iter().map(|&l| names[l - 1].clone()).collect();
    println!(
        "Zhang 2021, Example 2: leaks {} among {} delayed-input candidates, N = {SAMPLES}, \
         {} residual, plateau in {} λ",
        truth.join(" and "),
        names.len(),
        channel.diagnosis.residual,
        channel.diagnosis.lasso.plateau_scale.as_str()
    );

    // Figs 6 and 7: one run at the paper's magnitude.
    let theta = args.magnitudes.first().copied().unwrap_or(1e-4);
    let (d, snr) = run(&channel, theta, 1)?;
    let detail = &d.detail;
    println!(
        "\nFig. 6 (seed 1, θ = {theta:e}, leak SNR {snr:.1} dB): non-zero components of θ̂(λ) along the path"
    );
    println!("  count  points  λ from       λ to");
    let (low, high) = detail.plateau;
    let mut start = 0;
    for i in 1..=detail.path.len() {
        if i < detail.path.len() && detail.path[i].1 == detail.path[start].1 {
            continue;
        }
        let (first, last) = (detail.path[start].0, detail.path[i - 1].0);
        let mark = if first == high && last == low {
            format!("  <- the widest plateau; λ = {:.4e} chosen", detail.lambda)
        } else {
            String::new()
        };
        println!(
            "  {:5}  {:6}  {first:10.4e}  {last:10.4e}{mark}",
            detail.path[start].1,
            i - start
        );
        start = i;
    }
    let lasso = &detail.lasso_path;
    let at = |lambda: f64| {
        (0..lasso.len())
            .find(|&i| lasso.lambdas()[i] == lambda)
            .and_then(|i| lasso.coefficients(i))
    };
    println!(
        "\nFig. 7: isolated leaks, Lasso θ̂(λ) at the plateau's ends and middle, least squares, truth"
    );
    println!("  leak     θ̂(λ_high)   θ̂(λ_mid)    θ̂(λ_low)    least squares  truth");
    for &(j, ls) in &detail.estimate {
        let value = |lambda| at(lambda).map_or(f64::NAN, |c| c[j]);
        let true_value = if LEAKS.contains(&(j + 1)) { theta } else { 0.0 };
        println!(
            "  {:6}  {:10.4e}  {:10.4e}  {:10.4e}  {ls:12.4e}  {true_value:8.1e}",
            names[j],
            value(high),
            value(detail.lambda),
            value(low)
        );
    }

    println!(
        "\nExact isolation of {} over {} runs per magnitude (seeds 1…{}):",
        truth.join(" and "),
        args.trials,
        args.trials
    );
    println!("  θ          leak SNR   exact    rate   missed  added   mean θ̂ (least squares)");
    for &theta in &args.magnitudes {
        let (mut exact, mut missed, mut added, mut snr_sum) = (0u64, 0u64, 0u64, 0.0);
        let mut sums = [0.0; 2];
        let mut found = [0u64; 2];
        for t in 0..args.trials {
            let (d, snr) = run(&channel, theta, t + 1)?;
            snr_sum += snr;
            let support: Vec<usize> = d.detail.support.clone();
            let want: Vec<usize> = LEAKS.iter().map(|l| l - 1).collect();
            exact += u64::from(support == want);
            missed += u64::from(want.iter().any(|j| !support.contains(j)));
            added += u64::from(support.iter().any(|j| !want.contains(j)));
            for (i, j) in want.iter().enumerate() {
                if let Some(&(_, v)) = d.detail.estimate.iter().find(|(k, _)| k == j) {
                    sums[i] += v;
                    found[i] += 1;
                }
            }
        }
        let n = args.trials.max(1) as f64;
        let mean = |i: usize| sums[i] / found[i].max(1) as f64;
        println!(
            "  {theta:8.1e}  {:6.1} dB  {exact:4}/{:<4} {:5.1} %  {missed:5}  {added:5}   {:.3e}, {:.3e}",
            snr_sum / n,
            args.trials,
            100.0 * exact as f64 / n,
            mean(0),
            mean(1)
        );
    }
    Ok(())
}
