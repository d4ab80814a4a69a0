//! The data of the numerical example of Li, Boem, Pin & Parisini, Section V, as a CSV
//! file `glrmon replay` reads with config/examples/kernel-paper.toml: the 5-state plant
//! driven by u = 10 sin 10t + sin 2t, the candidate fault φ₁ or φ₂ from `--onset`
//! seconds, uniform noise scaled by `--noise-scale` (1: d_y within ±0.5 per output and
//! d_x within ±0.2 per state, the paper's), integrated by RK4
//! (`glrmon_sim::kernel_example`), sampled every millisecond.
//!
//! ```text
//! cargo run --release -p glrmon-cli --example kernel_paper -- --output paper.csv
//! glrmon replay --config config/examples/kernel-paper.toml paper.csv --output results.jsonl
//! ```

use std::io::Write as _;
use std::path::PathBuf;

use clap::Parser;
use glrmon_sim::kernel_example::{ExampleRun, OUTPUTS, simulate};

#[derive(Parser)]
#[command(about = "Writes the data of Li, Boem, Pin & Parisini's Section V example as CSV")]
struct Args {
    /// The CSV file to write (columns k, t, u0, y0…y3).
    #[arg(long)]
    output: PathBuf,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Noise amplitudes as a multiple of the paper's (0: noise-free).
    #[arg(long, default_value_t = 1.0)]
    noise_scale: f64,
    /// The acting candidate: 1, 2, or 0 for none.
    #[arg(long, default_value_t = 2)]
    fault: usize,
    /// The fault's start in seconds.
    #[arg(long, default_value_t = 5.0)]
    onset: f64,
    /// Duration in seconds.
    #[arg(long, default_value_t = 15.0)]
    seconds: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if !(args.noise_scale.is_finite() && args.noise_scale >= 0.0) {
        return Err("--noise-scale must be a non-negative number".into());
    }
    if args.fault > 2 {
        return Err("--fault must be 0, 1 or 2".into());
    }
    let period = 1e-3;
    let noisy = args.noise_scale > 0.0;
    let run = ExampleRun {
        period,
        substeps: if noisy { 4 } else { 20 },
        samples: (args.seconds / period).round() as usize + 1,
        fault: (args.fault > 0).then_some((args.fault, args.onset)),
        state_noise: 0.2 * args.noise_scale,
        output_noise: 0.5 * args.noise_scale,
        seed: args.seed,
    };
    let data = simulate(&run);
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args.output)?);
    writeln!(out, "k,t,u0,y0,y1,y2,y3")?;
    for k in 0..data.u.len() {
        write!(out, "{k},{},{}", k as f64 * period, data.u[k])?;
        for y in &data.y[OUTPUTS * k..OUTPUTS * (k + 1)] {
            write!(out, ",{y}")?;
        }
        writeln!(out)?;
    }
    out.flush()?;
    Ok(())
}
