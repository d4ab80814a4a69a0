//! Renders the JSONL records of `glrmon replay --output OUT.jsonl` as an HTML report.
//!
//! ```text
//! cargo run -p glrmon-report --example jsonl_to_html -- records.jsonl report.html [title]
//! ```
//!
//! Lines that do not decode are counted and reported on stderr, never fatal: the report
//! of the rest is still written.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::process::ExitCode;

use glrmon_report::{Report, ReportOptions};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(input), Some(output)) = (args.first(), args.get(1)) else {
        eprintln!("usage: jsonl_to_html RECORDS.jsonl REPORT.html [TITLE]");
        return ExitCode::from(2);
    };
    let title = args
        .get(2)
        .cloned()
        .unwrap_or_else(|| format!("glrmon replay report: {input}"));
    match run(input, output, title) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(1)
        }
    }
}

fn run(input: &str, output: &str, title: String) -> Result<(), Box<dyn std::error::Error>> {
    let reader = BufReader::new(File::open(input).map_err(|e| format!("{input}: {e}"))?);
    let mut report = Report::new(ReportOptions {
        title,
        ..ReportOptions::default()
    });
    let (mut records, mut bad) = (0u64, 0u64);
    for (number, line) in reader.split(b'\n').enumerate() {
        let line = line.map_err(|e| format!("{input}: {e}"))?;
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        match glrmon_wire::decode_record(&line) {
            Ok(record) => {
                report.add(&record);
                records += 1;
            }
            Err(err) => {
                bad += 1;
                if bad <= 10 {
                    eprintln!("{input}:{}: skipped: {err}", number + 1);
                }
            }
        }
    }
    let mut out = BufWriter::new(File::create(output).map_err(|e| format!("{output}: {e}"))?);
    report.write_html(&mut out)?;
    out.flush()?;
    eprintln!("{records} records rendered to {output}; {bad} lines skipped.");
    Ok(())
}
