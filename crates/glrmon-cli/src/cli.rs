//! The command line: the `glrmon` parser and its subcommands (each parsed into the
//! `Args` of its module under `commands/`).

use clap::{Parser, Subcommand};
use glrmon_report::clock::Zone;

use crate::commands::config;
use crate::commands::{
    calibrate, demo, diagnose, docs, evaluate, identify, recover, replay, run, simulate, status,
    validate, watch,
};
use crate::commands::{info, play};
use crate::log::{ColorChoice, LogFormat};

/// Detect, date, isolate and size additive faults in live plant data: a Kalman
/// innovation filter, the moving-window GLR test and minmax isolation (Zhang &
/// Basseville 2014) and sparse diagnosis (Zhang 2021), per channel, on Eclipse Zenoh.
#[derive(Debug, Parser)]
#[command(
    name = "glrmon",
    version = crate::version::long(),
    about,
    long_about = None,
    after_help = concat!(
        "Examples:\n",
        "  glrmon demo                                     the main job on an embedded default\n",
        "  glrmon validate --config plant.toml             check a configuration\n",
        "  glrmon run --config plant.toml                  the daemon\n",
        "  glrmon watch                                    alarms of the local daemon\n",
        "  glrmon replay --config plant.toml rec.csv --report report.html\n",
        "  glrmon identify --channel tank --output tank.toml run1.csv run2.csv\n",
        "\n",
        "Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime failure."
    )
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
    /// Log lines as text or as one JSON object per line.
    #[arg(
        long,
        global = true,
        value_enum,
        default_value_t = LogFormat::Text,
        env = "GLRMON_LOG_FORMAT"
    )]
    pub(crate) log_format: LogFormat,
    /// Colour in log lines: `auto` only on a terminal and without `NO_COLOR`.
    #[arg(long, global = true, value_enum, default_value_t = ColorChoice::Auto)]
    pub(crate) color: ColorChoice,
    /// Show wall-clock times in the system's time zone instead of UTC (logs, alarm
    /// lines, reports, summaries).
    #[arg(long, global = true)]
    pub(crate) local_time: bool,
}

impl Cli {
    /// The zone wall-clock times are shown in.
    pub(crate) fn zone(&self) -> Zone {
        if self.local_time {
            Zone::Local
        } else {
            Zone::Utc
        }
    }
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// The main job on an embedded default: an in-process Zenoh session, simulated
    /// channels with an injected fault, the monitor; alarms printed.
    #[command(
        after_help = "Examples:\n  glrmon demo\n  glrmon demo --seconds 30 --listen tcp/127.0.0.1:7447   # and `glrmon watch` elsewhere\n  glrmon demo --output demo.mcap --output demo.jsonl"
    )]
    Demo(demo::DemoArgs),
    /// Validate a configuration; print each channel's summary and isolability report.
    #[command(
        after_help = "Examples:\n  glrmon validate --config plant.toml\n  glrmon validate --config /etc/glrmon/glrmon.toml"
    )]
    Validate(validate::ValidateArgs),
    /// Simulate a channel's model, optionally with a fault, to a CSV or MCAP file or to Zenoh.
    #[command(
        after_help = "Examples:\n  glrmon simulate --config plant.toml --samples 2000 --output clean.csv\n  glrmon simulate --config plant.toml --samples 2000 --fault y0_bias:2.5 --onset 1000 --output faulty.mcap\n  glrmon simulate --config plant.toml --samples 0 --publish --rate 100   # publish forever"
    )]
    Simulate(simulate::SimulateArgs),
    /// Run the monitors over recorded samples (CSV, or an MCAP recording with its
    /// configuration) to the same numbers as live; JSON lines, MCAP, HTML report.
    #[command(
        after_help = "Examples:\n  glrmon replay --config plant.toml faulty.csv > records.jsonl\n  glrmon replay glrmon-demo.mcap --report report.html\n  glrmon replay recording.mcap --output rerun.mcap --stat-every 10"
    )]
    Replay(replay::ReplayArgs),
    /// Identify a channel's model from fault-free recordings (subspace identification
    /// of an innovation model, order selection, validation) and write it as a
    /// configuration with signal scaling and one bias fault per signal; or, with
    /// --model CONFIG, keep your model's F, G, H, J and estimate its noise covariances
    /// Q, R (and S).
    #[command(
        after_help = "Examples:\n  glrmon identify --channel tank --output tank.toml run1.csv run2.csv\n  glrmon identify --channel tank --inputs u_pump1,u_pump2 --outputs h1,h2 --max-order 8 --output tank.toml run.csv\n  glrmon identify --model plant.toml --output plant-noise.toml clean.csv"
    )]
    Identify(identify::IdentifyArgs),
    /// Find a channel's detection threshold for a target mean time between false
    /// alarms or a per-sample false-alarm fraction, on fault-free data (recordings,
    /// each an independent run, or simulated).
    #[command(
        after_help = "Examples:\n  glrmon calibrate --config tank.toml thu.csv fri.csv sat.csv --mtbfa 1d --write\n  glrmon calibrate --config plant.toml --simulate 200000 --mtbfa 10000\n  glrmon calibrate --config tank.toml run1.csv run2.csv --sample-far 0.01\n\nCalibrate on fault-free data the model was not identified from: a threshold set on the\nidentification data gives more false alarms on new data than it promises."
    )]
    Calibrate(calibrate::CalibrateArgs),
    /// Monte-Carlo fault injection through the simulator and the monitor: detection
    /// rate, delay, onset error, false alarms and the isolation confusion matrix.
    #[command(
        after_help = "Examples:\n  glrmon evaluate --config plant.toml --runs 500 --report evaluation.html\n  glrmon evaluate --config plant.toml --fault y0_bias:2 --fault x0_jump:4 --json-out runs.json"
    )]
    Evaluate(evaluate::EvaluateArgs),
    /// Rewrite an unfinished or damaged MCAP recording as a finished file with
    /// everything readable in it.
    #[command(
        after_help = "Examples:\n  glrmon recover glrmon-20261202T101500Z.mcap.tmp\n  glrmon recover damaged.mcap --output repaired.mcap"
    )]
    Recover(recover::RecoverArgs),
    /// Batch sparse fault diagnosis (Zhang 2021) over a recorded span of a CSV file or
    /// an MCAP recording; prints the isolated faults and their magnitudes (JSON with --json).
    #[command(
        after_help = "Examples:\n  glrmon diagnose --config plant.toml faulty.csv --from 1000 --to 1100\n  glrmon diagnose recording.mcap --channel pump3 --json"
    )]
    Diagnose(diagnose::DiagnoseArgs),
    /// The daemon: monitor every configured channel on Zenoh, publish the results.
    #[command(
        after_help = "Examples:\n  glrmon run --config /etc/glrmon/glrmon.toml\n  glrmon run --config plant.toml --listen tcp/0.0.0.0:7447 --metrics 127.0.0.1:9464\n  glrmon --log-format json run --config plant.toml"
    )]
    Run(run::RunArgs),
    /// Subscribe to alarms and diagnoses and print them.
    #[command(
        after_help = "Examples:\n  glrmon watch\n  glrmon watch 'glrmon/pump3/**' --json\n  glrmon watch --connect tcp/10.0.0.5:7447 --count 1"
    )]
    Watch(watch::WatchArgs),
    /// Ask every running instance for its status and print a table (instance, shard,
    /// channels, samples/s, alarms, errors, drops, reconnections, uptime).
    #[command(
        after_help = "Examples:\n  glrmon status\n  glrmon status 'plant-*' --json --connect tcp/10.0.0.5:7447"
    )]
    Status(status::StatusArgs),
    /// The configuration's JSON Schema, and a commented template to start from.
    Config(config::ConfigArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    #[command(
        after_help = "Examples:\n  glrmon completions bash > /etc/bash_completion.d/glrmon\n  glrmon completions zsh > \"${fpath[1]}/_glrmon\"\n  glrmon completions fish > ~/.config/fish/completions/glrmon.fish"
    )]
    Completions(docs::CompletionsArgs),
    /// Write the manual pages (glrmon.1 and one per command) to a directory.
    #[command(
        after_help = "Examples:\n  glrmon man --out-dir /usr/local/share/man/man1\n  glrmon man --out-dir man && man -l man/glrmon.1"
    )]
    Man(docs::ManArgs),
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
            | Command::Diagnose(_)
            | Command::Config(_)
            | Command::Info(_) => true,
            Command::Simulate(args) => !args.publishes(),
            Command::Completions(_) | Command::Man(_) => true,
            Command::Demo(_) | Command::Run(_) | Command::Watch(_) | Command::Status(_) => false,
            Command::Play(_) => false,
        }
    }

    /// The hint for a spelling of an earlier version that this one refuses (a usage
    /// error, exit code 2), so that scripts break loudly with the fix in the message.
    pub(crate) fn old_spelling(&self) -> Option<(&'static str, String)> {
        match self {
            Command::Validate(a) => a.file.as_ref().map(|f| {
                (
                    "validate",
                    format!(
                    "validate takes the configuration as --config FILE: glrmon validate --config {}",
                        f.display()
                    ),
                )
            }),
            Command::Simulate(a) if !a.magnitude.is_empty() => Some((
                "simulate",
                "--magnitude is gone: give each fault with its magnitude, \
                 --fault NAME:MAGNITUDE (e.g. --fault y0_bias:2.5 --fault x0_jump:-1)"
                    .to_owned(),
            )),
            Command::Evaluate(a) if !a.stray.is_empty() => Some((
                "evaluate",
                format!(
                "unexpected argument {:?}: --json is a switch (JSON on standard output); \
                 write the JSON to a file with --json-out {}",
                    a.stray[0], a.stray[0]
                ),
            )),
            Command::Demo(a) => a.record.as_ref().map(|p| {
                (
                    "demo",
                    format!(
                    "--record is gone: the recording is an --output ending in .mcap: --output {}",
                        p.display()
                    ),
                )
            }),
            _ => None,
        }
    }
}
