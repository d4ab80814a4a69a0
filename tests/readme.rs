//! The README's recipe, run verbatim: the `sh` block under "From recordings to a
//! calibrated monitor in three commands" is run by `sh` with the binary first on the
//! PATH, in a directory holding the week of plant history the README describes
//! (`glrmon_sim::two_tanks::write_week`: named columns in natural units, ISO 8601
//! timestamps, a day per file). Then what the README says of it is checked: the alarm
//! at the bias's onset with LI202 isolated, and a fault-free false-alarm rate on
//! independent days (other seeds) consistent with calibrate's 95 % interval.

#[path = "support.rs"]
mod support;

use std::path::Path;
use std::process::Command;

use glrmon_core::threshold::chi2_quantile;
use glrmon_sim::two_tanks::{TwoTanks, write_week};
use support::{Scratch, glrmon, run_ok};

const SAMPLES_PER_DAY: usize = 4320;

/// The first `sh` code block after `heading` in README.md, continuation lines kept.
fn readme_block(heading: &str) -> String {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .expect("README.md");
    let after = &readme[readme.find(heading).expect("the README has the heading")..];
    let start = after
        .find("```sh\n")
        .expect("an sh block after the heading")
        + 6;
    let len = after[start..].find("```").expect("the block ends");
    after[start..start + len].to_owned()
}

/// The 95 % Garwood interval of a Poisson mean from a count.
fn garwood(count: u64) -> (f64, f64) {
    let low = if count == 0 {
        0.0
    } else {
        chi2_quantile(2.0 * count as f64, 0.025).unwrap() / 2.0
    };
    (
        low,
        chi2_quantile(2.0 * count as f64 + 2.0, 0.975).unwrap() / 2.0,
    )
}

#[test]
fn the_readme_recipe_runs_verbatim_and_keeps_its_false_alarm_promise() {
    let dir = Scratch::new("readme-recipe");
    write_week(&dir.0, SAMPLES_PER_DAY).unwrap();
    let block = readme_block("## From recordings to a calibrated monitor in three commands");
    assert!(
        block.contains("glrmon identify") && block.contains("--mtbfa"),
        "{block}"
    );
    let bin = Path::new(env!("CARGO_BIN_EXE_glrmon")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = run_ok(
        Command::new("sh")
            .args(["-e", "-c", &block])
            .env("PATH", path)
            .current_dir(&dir.0),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(dir.0.join("fault.html").is_file(), "no report:\n{stderr}");
    // identify's Next line already names the safe calibration.
    assert!(
        stdout.contains("--mtbfa 1d --write") && stdout.contains("OTHER-DAYS.csv"),
        "{stdout}"
    );
    assert!(
        !stderr.contains("was identified from"),
        "the recipe calibrates on other days:\n{stderr}"
    );
    // Each validation figure with its verdict.
    assert!(
        stdout.contains("→ share of each output's variance predicted one sample ahead: LI201")
            && stdout.contains("→ LI202 innovations white"),
        "{stdout}"
    );
    // Calibrating on an identification day is warned of.
    let warned = run_ok(glrmon().current_dir(&dir.0).args([
        "calibrate",
        "--config",
        "tanks.toml",
        "mon.csv",
        "thu.csv",
        "--mtbfa",
        "1d",
    ]));
    let warned = String::from_utf8_lossy(&warned.stderr);
    assert!(
        warned.contains("mon.csv is data the model of tanks.toml was identified from")
            && !warned.contains("thu.csv is data"),
        "{warned}"
    );
    // The bias starts at sample 1200 of fault.csv, 06:40:00 UTC; LI202 is isolated by
    // the alarm or its update.
    let alarm = stderr
        .lines()
        .find(|l| l.trim_start().starts_with("ALARM") && l.contains("onset=1"))
        .unwrap_or_else(|| panic!("no alarm:\n{stderr}"));
    assert!(
        alarm.contains("k=1200") || alarm.contains("k=1201"),
        "{alarm}"
    );
    assert!(
        alarm.contains("06:40:"),
        "the alarm line carries the time: {alarm}"
    );
    assert!(
        stderr
            .lines()
            .any(|l| l.contains("k=12") && l.contains("isolated=[LI202_bias]")),
        "LI202 isolated:\n{stderr}"
    );

    // Calibrate's promise: the interval of the mean samples between false alarms.
    let json = run_ok(glrmon().current_dir(&dir.0).args([
        "calibrate",
        "--config",
        "tanks.toml",
        "thu.csv",
        "fri.csv",
        "sat.csv",
        "--mtbfa",
        "1d",
        "--json",
    ]));
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    let promised = (
        json["rate_interval"][0].as_f64().unwrap(),
        json["rate_interval"][1].as_f64().unwrap_or(f64::INFINITY),
    );
    assert_eq!(json["mtbfa"].as_f64(), Some(4320.0), "1d at 20 s");

    // Ten independent fault-free days.
    let plant = TwoTanks::default();
    let (mut episodes, mut samples) = (0u64, 0u64);
    for day in 0..10u32 {
        let name = format!("independent{day}.csv");
        std::fs::write(
            dir.0.join(&name),
            plant
                .day(20 + day, SAMPLES_PER_DAY, 9000 + u64::from(day), None)
                .csv(),
        )
        .unwrap();
        let out = run_ok(glrmon().current_dir(&dir.0).args([
            "replay",
            "--config",
            "tanks.toml",
            &name,
            "--output",
            "/dev/null",
        ]));
        let text = String::from_utf8_lossy(&out.stderr);
        episodes += text
            .lines()
            .filter(|l| l.trim_start().starts_with("ALARM"))
            .count() as u64;
        samples += SAMPLES_PER_DAY as u64;
    }
    let (low, high) = garwood(episodes);
    let observed = (
        samples as f64 / high,
        samples as f64 / low.max(f64::MIN_POSITIVE),
    );
    eprintln!(
        "independent days: {episodes} episodes in {samples} samples; mean samples between \
         false alarms {:.0}–{:.0} (95 %), calibrate promised {:.0}–{:.0}",
        observed.0, observed.1, promised.0, promised.1
    );
    assert!(
        observed.0 <= promised.1 && promised.0 <= observed.1,
        "{episodes} episodes in {samples} independent samples: mean samples between false \
         alarms {observed:?} does not meet calibrate's interval {promised:?}"
    );
    // An operator's scale: the recipe of before (calibrating at 1 % of samples on the
    // identification days) gave about 11 episodes a day on this plant; this one about
    // one, the target.
    assert!(
        episodes <= 30,
        "{episodes} false-alarm episodes in 10 days for a target of one a day"
    );
}
