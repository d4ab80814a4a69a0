//! The command line: the `glrmon` parser and its subcommands (each parsed into the
//! `Args` of its module under `commands/`).

use clap::{Parser, Subcommand};

use crate::commands::{
    calibrate, demo, diagnose, evaluate, identify, recover, replay, run, simulate, status,
    validate, watch,
};
use crate::commands::{info, play};

/// Model-based fault detection and isolation (GLR, Zhang & Basseville 2014) on plant data.
#[derive(Debug, Parser)]
#[command(
    name = "glrmon",
    version,
    about,
    after_help = "Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime failure."
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
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
    /// Identify a channel's model from fault-free recordings (subspace identification
    /// of an innovation model, order selection, validation) and write it as a
    /// configuration with signal scaling and one bias fault per signal; or, with
    /// --model CONFIG, keep your model's F, G, H, J and estimate its noise covariances
    /// Q, R (and S).
    Identify(identify::IdentifyArgs),
    /// Find a channel's detection threshold for a target mean time between false
    /// alarms or a per-sample false-alarm fraction, on fault-free data (recordings,
    /// each an independent run, or simulated).
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
    /// Summarise a recording: size, finished or damaged, time range, messages per topic.
    Info(info::InfoArgs),
    /// Publish a recording's input samples again on their Zenoh keys, at recorded pace.
    Play(play::PlayArgs),
}

impl Command {
    /// Commands that talk to nobody but files and the terminal: a closed stdout may end
    /// them (see `quiet_broken_pipe` in main.rs). The daemon and the Zenoh commands
    /// are not among them.
    pub(crate) fn writes_to_a_pipe_only(&self) -> bool {
        match self {
            Command::Validate(_)
            | Command::Replay(_)
            | Command::Identify(_)
            | Command::Calibrate(_)
            | Command::Evaluate(_)
            | Command::Recover(_)
            | Command::Diagnose(_) => true,
            Command::Info(_) => true,
            Command::Simulate(args) => !args.publishes(),
            Command::Demo(_) | Command::Run(_) | Command::Watch(_) | Command::Status(_) => false,
            Command::Play(_) => false,
        }
    }
}
