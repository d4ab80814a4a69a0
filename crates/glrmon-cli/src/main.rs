//! `glrmon`: detect, date, isolate and size additive faults in live plant data.
//!
//! Exit codes: 0 success, 1 invalid input or configuration, 2 usage error, 3 runtime
//! failure.

mod cli;
mod commands;
mod common;
mod flags;
mod log;
mod print;
mod span;
mod version;

use std::process::ExitCode;

use clap::{CommandFactory as _, Parser as _};

use crate::cli::{Cli, Command};
use crate::commands::config;
use crate::commands::{
    calibrate, demo, diagnose, docs, evaluate, identify, recover, replay, run, simulate, status,
    validate, watch,
};
use crate::commands::{info, play};
use crate::common::InvalidInput;

/// mimalloc: samples, records and message buffers are allocated on one thread (the
/// replay reader, the Zenoh callbacks) and freed on another (the monitors), which
/// glibc's allocator does slowly (a quarter of a replay's CPU time, measured).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some((name, hint)) = cli.command.old_spelling() {
        let mut cmd = Cli::command();
        cmd.build();
        let kind = clap::error::ErrorKind::ArgumentConflict;
        match cmd.find_subcommand_mut(name) {
            Some(sub) => sub.error(kind, hint).exit(),
            None => cmd.error(kind, hint).exit(),
        }
    }
    if cli.command.writes_to_a_pipe_only() {
        quiet_broken_pipe();
    }
    log::init(cli.log_format, cli.color, cli.zone());
    print::set_zone(cli.zone());
    let result = match &cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Validate(args) => validate::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Replay(args) => replay::run(args, cli.zone()),
        Command::Recover(args) => recover::run(args),
        Command::Identify(args) => identify::run(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Evaluate(args) => evaluate::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Run(args) => run::run(args),
        Command::Watch(args) => watch::run(args),
        Command::Status(args) => status::run(args),
        Command::Config(args) => config::run(args),
        Command::Completions(args) => docs::completions(args),
        Command::Man(args) => docs::man(args),
        Command::Info(args) => info::run(args, cli.zone()),
        Command::Play(args) => play::run(args),
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

/// `glrmon validate … | head -1`: an offline command whose reader went away ends
/// quietly, as `cat` does (the default SIGPIPE action), instead of panicking in
/// `println!`. Not for the daemon and the Zenoh commands, whose sockets must see EPIPE
/// as an error to handle.
fn quiet_broken_pipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
