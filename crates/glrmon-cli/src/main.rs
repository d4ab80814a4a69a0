//! `glrmon`: detect, date, isolate and size additive faults in live plant data.
//!
//! Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime
//! failure.

mod calibrate;
mod demo;
mod diagnose;
mod evaluate;
mod log;
mod net;
mod print;
mod recover;
mod replay;
mod run;
mod simulate;
mod status;
mod validate;
mod watch;

use std::path::Path;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// mimalloc: samples, records and message buffers are allocated on one thread (the
/// replay reader, the Zenoh callbacks) and freed on another (the monitors), which
/// glibc's allocator does slowly (a quarter of a replay's CPU time, measured).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Model-based fault detection and isolation (GLR, Zhang & Basseville 2014) on plant data.
#[derive(Debug, Parser)]
#[command(
    name = "glrmon",
    version,
    about,
    after_help = "Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime failure."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job on an embedded default: an in-process Zenoh session, simulated
    /// channels with an injected fault, the monitor; alarms printed.
    Demo(demo::DemoArgs),
    /// Validate a configuration; print each channel's summary and isolability report.
    Validate(validate::ValidateArgs),
    /// Simulate a channel's model, optionally with a fault, to a CSV or MCAP file or to Zenoh.
    Simulate(simulate::SimulateArgs),
    /// Run the monitors over recorded samples (CSV, or an MCAP recording with its
    /// configuration) to the same numbers as live; JSON lines, MCAP, HTML report.
    Replay(replay::ReplayArgs),
    /// Find a channel's detection threshold for a target mean time between false
    /// alarms, on fault-free data (recorded or simulated).
    Calibrate(calibrate::CalibrateArgs),
    /// Monte-Carlo fault injection through the simulator and the monitor: detection
    /// rate, delay, onset error, false alarms and the isolation confusion matrix.
    Evaluate(evaluate::EvaluateArgs),
    /// Rewrite an unfinished or damaged MCAP recording as a finished file with
    /// everything readable in it.
    Recover(recover::RecoverArgs),
    /// Batch sparse fault diagnosis (Zhang 2021) over a recorded span of a CSV file or
    /// an MCAP recording; prints the isolated faults and their magnitudes (JSON with --json).
    Diagnose(diagnose::DiagnoseArgs),
    /// The daemon: monitor every configured channel on Zenoh, publish the results.
    Run(run::RunArgs),
    /// Subscribe to alarms and diagnoses and print them.
    Watch(watch::WatchArgs),
    /// Ask every running instance for its status and print a table (instance, shard,
    /// channels, samples/s, alarms, errors, drops, reconnections, uptime).
    Status(status::StatusArgs),
}

/// Where `run` listens and `watch`/`simulate --publish` connect when nothing is given.
pub(crate) const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// A user's input or configuration is at fault (exit code 1).
#[derive(Debug)]
pub(crate) struct InvalidInput(pub(crate) String);

impl std::fmt::Display for InvalidInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for InvalidInput {}

/// An input file's error with its exit code: [`InvalidInput`] (1) when the user's file
/// is at fault, a runtime failure (3) otherwise.
pub(crate) fn input_error(e: glrmon_input::InputError) -> anyhow::Error {
    if e.is_invalid_input() {
        InvalidInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// An error of reading ahead: the source's as [`input_error`], the reader thread's a
/// runtime failure.
pub(crate) fn read_ahead_error(
    e: glrmon_input::ReadAheadError<glrmon_input::InputError>,
) -> anyhow::Error {
    match e {
        glrmon_input::ReadAheadError::Source(e) => input_error(e),
        e => e.into(),
    }
}

/// Loads a configuration; every problem becomes one line of an [`InvalidInput`].
pub(crate) fn load_config(path: &Path) -> anyhow::Result<glrmon_spec::Config> {
    glrmon_spec::load(path)
        .map_err(|e| InvalidInput(format!("{} is invalid:\n{e}", path.display())).into())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_env("GLRMON_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,zenoh=warn"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    let result = match &cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Validate(args) => validate::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Recover(args) => recover::run(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Evaluate(args) => evaluate::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Run(args) => run::run(args),
        Command::Watch(args) => watch::run(args),
        Command::Status(args) => status::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) if err.downcast_ref::<InvalidInput>().is_some() => {
            eprintln!("glrmon: {err:#}");
            ExitCode::from(1)
        }
        Err(err) => {
            eprintln!("glrmon: {err:#}");
            ExitCode::from(3)
        }
    }
}
