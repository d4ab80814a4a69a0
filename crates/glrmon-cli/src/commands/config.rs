//! `glrmon config schema` and `glrmon config init`: the configuration's JSON Schema and
//! a commented template (both written by glrmon-spec; this module parses the flags and
//! prints).

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, Subcommand};

use crate::common::InvalidInput;

#[derive(Debug, Args)]
#[command(after_help = "Examples:
  glrmon config init --channel tank --output glrmon.toml
  glrmon validate --config glrmon.toml
  glrmon config schema > glrmon.schema.json

To have VS Code's Even Better TOML (taplo) check and complete the file, put
#:schema ./glrmon.schema.json as its first line.")]
pub(crate) struct ConfigArgs {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(Debug, Subcommand)]
enum ConfigCommand {
    /// Print the JSON Schema (draft 7) of a configuration file, for editors.
    Schema,
    /// Write a commented configuration template: one channel with a small model, a
    /// sensor bias and an actuator bias fault, every optional section commented out
    /// with its default.
    Init(InitArgs),
}

#[derive(Debug, Args)]
struct InitArgs {
    /// Name of the channel.
    #[arg(long, default_value = "plant")]
    channel: String,
    /// Write to this file instead of standard output.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Overwrite the output file if it exists.
    #[arg(long)]
    force: bool,
}

pub(crate) fn run(args: &ConfigArgs) -> anyhow::Result<()> {
    match &args.command {
        ConfigCommand::Schema => {
            println!("{}", glrmon_spec::json_schema());
            Ok(())
        }
        ConfigCommand::Init(init) => write_template(init),
    }
}

fn write_template(args: &InitArgs) -> anyhow::Result<()> {
    let text = glrmon_spec::template::config_template(&args.channel);
    // The channel name is the user's: the template must still be a valid configuration.
    if let Err(errors) = glrmon_spec::parse(&text) {
        return Err(InvalidInput(format!("--channel \"{}\": {errors}", args.channel)).into());
    }
    let Some(path) = &args.output else {
        print!("{text}");
        return Ok(());
    };
    let mut options = std::fs::OpenOptions::new();
    options.write(true);
    if args.force {
        options.create(true).truncate(true);
    } else {
        options.create_new(true);
    }
    let mut file = match options.open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            return Err(InvalidInput(format!(
                "{} exists: use --force to overwrite it",
                path.display()
            ))
            .into());
        }
        Err(e) => return Err(e).with_context(|| format!("cannot create {}", path.display())),
    };
    file.write_all(text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!(
        "wrote {}: check it with `glrmon validate --config {}`",
        path.display(),
        path.display()
    );
    Ok(())
}
