//! `glrmon`: detect, date, isolate and size additive faults in live plant data.
//!
//! Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime
//! failure.

mod demo;
mod print;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

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
    /// Run the main job on built-in simulated channels with an injected fault and print
    /// the alarms (offline until the Zenoh daemon lands).
    Demo(demo::DemoArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => demo::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("glrmon: {err:#}");
            ExitCode::from(3)
        }
    }
}
