//! `glrmon validate --config FILE`: every error with its path, or per channel a summary and the
//! isolability report (Basseville 1996 §5-6) of its fault dictionary.

use std::path::PathBuf;

use clap::Args;
use glrmon_eval::validation::channel_report;

use crate::common::InvalidInput;

#[derive(Debug, Args)]
pub(crate) struct ValidateArgs {
    /// Configuration file.
    #[arg(long, required_unless_present = "file")]
    config: Option<PathBuf>,
    /// The file as a positional argument, as earlier versions took it (refused with
    /// a hint: `Command::old_spelling`).
    #[arg(hide = true)]
    pub(crate) file: Option<PathBuf>,
}

pub(crate) fn run(args: &ValidateArgs) -> anyhow::Result<()> {
    let path = args
        .config
        .as_deref()
        .ok_or_else(|| InvalidInput("--config FILE is required".into()))?;
    let file = path.display().to_string();
    let cfg = match glrmon_spec::load(path) {
        Ok(c) => c,
        Err(errors) => {
            println!("{file}: invalid ({} error(s))", errors.errors.len());
            for e in &errors.errors {
                match e.location {
                    Some(_) => println!("  error: {}", e.in_file(&file)),
                    None => println!("  error: {e}"),
                }
            }
            return Err(InvalidInput(format!("{} is invalid", file)).into());
        }
    };
    // The model checks that need the filter run (a diverging Σ_k, a fault signature
    // that is not finite) are configuration errors too: exit 1 with the channel and the
    // field, like the schema's.
    let mut warnings: Vec<String> = cfg
        .warnings
        .iter()
        .map(|w| match w.location {
            Some(_) => w.in_file(&file),
            None => w.to_string(),
        })
        .collect();
    let mut reports = String::new();
    let mut errors = Vec::new();
    for (i, channel) in cfg.channels.iter().enumerate() {
        let prefix = format!("channels[{i}] \"{}\"", channel.name);
        match channel_report(channel) {
            Ok(report) => {
                reports.push_str(&report.text);
                warnings.extend(report.warnings);
            }
            Err(e) => errors.push(format!("{prefix}: {e}")),
        }
    }
    if !errors.is_empty() {
        println!("{}: invalid ({} error(s))", file, errors.len());
        for e in &errors {
            println!("  error: {e}");
        }
        return Err(InvalidInput(format!("{} is invalid", file)).into());
    }
    println!("{}: valid, {} channel(s)", file, cfg.channels.len());
    print!("{reports}");
    for w in &warnings {
        println!("warning: {w}");
    }
    Ok(())
}
