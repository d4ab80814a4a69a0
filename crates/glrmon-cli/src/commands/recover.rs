//! `glrmon recover FILE`: a recording left unfinished by a crash (`kill -9`, power
//! loss) or with damaged records, rewritten as a finished MCAP file (summary, index,
//! footer) holding every readable message. Damaged records are skipped by
//! resynchronising on the next valid chunk; the report says what was lost.
//!
//! Exit codes: 0 when nothing was lost (a finished file, or an unfinished one whose
//! only loss is the incomplete record being written when the recorder died); 1 when
//! data was lost to damage — the output is written all the same, with every readable
//! message, and the damage (regions, bytes, lost time ranges) is reported on stderr.

use std::path::PathBuf;

use clap::Args;
use glrmon_record::ReadEnd;
use glrmon_wire::text::{Escaped, escape_control};

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
    let r = glrmon_record::recover(&args.input, &output)
        .map_err(|e| InvalidInput(escape_control(&e.to_string()).into_owned()))?;
    let end = match &r.end {
        ReadEnd::Finished | ReadEnd::Reading => "the input was finished".to_owned(),
        ReadEnd::Truncated { at, partial } => format!(
            "the input was unfinished: readable up to byte {at}, {partial} bytes of an \
             incomplete record dropped"
        ),
        ReadEnd::Unreadable { at, reason } => {
            format!(
                "unreadable from byte {at}: {}; no valid chunk follows",
                Escaped(reason)
            )
        }
    };
    println!(
        "glrmon recover: {} messages from {} chunks written to {}; {end}",
        r.messages,
        r.chunks,
        output.display()
    );
    for d in &r.damage {
        eprintln!(
            "glrmon recover: damaged, skipped: {}",
            Escaped(&d.to_string())
        );
    }
    if r.lost_data() || r.salvage.summary_note.is_some() {
        eprintln!("glrmon recover: salvage: {}", r.salvage);
    }
    if r.lost_data() {
        return Err(InvalidInput(format!(
            "{}: the file is damaged and data was lost; every readable message was \
             written to {}",
            args.input.display(),
            output.display()
        ))
        .into());
    }
    Ok(())
}
