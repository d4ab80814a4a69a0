//! `glrmon recover FILE`: a recording left unfinished by a crash (`kill -9`, power
//! loss) or with damaged chunks, rewritten as a finished MCAP file (summary, index,
//! footer) holding every readable message.

use std::path::PathBuf;

use clap::Args;
use glrmon_record::ReadEnd;

use crate::common::InvalidInput;

#[derive(Debug, Args)]
pub(crate) struct RecoverArgs {
    /// The damaged or unfinished recording (e.g. `glrmon-….mcap.tmp`).
    input: PathBuf,
    /// Where to write the finished file (default: the input's name ending in
    /// `.recovered.mcap`).
    #[arg(long)]
    output: Option<PathBuf>,
}

pub(crate) fn run(args: &RecoverArgs) -> anyhow::Result<()> {
    let output = args.output.clone().unwrap_or_else(|| {
        let name = args.input.to_string_lossy();
        let stem = name
            .strip_suffix(glrmon_record::PARTIAL_SUFFIX)
            .or_else(|| name.strip_suffix(".mcap"))
            .unwrap_or(&name);
        PathBuf::from(format!("{stem}.recovered.mcap"))
    });
    if output == args.input {
        return Err(InvalidInput("--output must differ from the input".into()).into());
    }
    let r =
        glrmon_record::recover(&args.input, &output).map_err(|e| InvalidInput(e.to_string()))?;
    let end = match &r.end {
        ReadEnd::Finished | ReadEnd::Reading => "the input was finished".to_owned(),
        ReadEnd::Truncated { at, partial } => format!(
            "the input was unfinished: readable up to byte {at}, {partial} bytes of an \
             incomplete record dropped"
        ),
        ReadEnd::Unreadable { at, reason } => format!("unreadable from byte {at}: {reason}"),
    };
    println!(
        "glrmon recover: {} messages from {} chunks written to {}; {end}",
        r.messages,
        r.chunks,
        output.display()
    );
    for d in &r.damage {
        println!("  damaged, skipped: {d}");
    }
    Ok(())
}
