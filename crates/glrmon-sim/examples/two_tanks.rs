//! A week of a two-tank plant's history as a historian exports it (see
//! `glrmon_sim::two_tanks`): `mon.csv` … `sun.csv` fault-free, and `fault.csv`, a
//! day with a +1.5 cm bias on LI202 from sample 1200 (08:00 UTC at 20-s samples).
//!
//! ```sh
//! cargo run -q -p glrmon-sim --example two_tanks -- DIR [SAMPLES_PER_DAY]
//! ```

use glrmon_sim::two_tanks::{PlantFault, TwoTanks};

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(dir) = args.next() else {
        eprintln!("usage: two_tanks DIR [SAMPLES_PER_DAY (default 4320: a day at 20 s)]");
        std::process::exit(2);
    };
    let samples = match args.next().map(|s| s.parse::<usize>()) {
        None => 4320,
        Some(Ok(n)) if n > 0 => n,
        Some(_) => {
            eprintln!("SAMPLES_PER_DAY must be a positive integer");
            std::process::exit(2);
        }
    };
    let dir = std::path::Path::new(&dir);
    if let Err(e) = std::fs::create_dir_all(dir) {
        eprintln!("{}: {e}", dir.display());
        std::process::exit(1);
    }
    let plant = TwoTanks::default();
    let days = ["mon", "tue", "wed", "thu", "fri", "sat", "sun"];
    let fault = PlantFault::SensorBias {
        output: 1,
        bias: 1.5,
    };
    let runs = days
        .iter()
        .enumerate()
        .map(|(i, name)| (format!("{name}.csv"), i as u32, None))
        .chain(std::iter::once((
            "fault.csv".to_string(),
            7,
            Some((fault, 1200)),
        )));
    for (name, day, fault) in runs {
        let path = dir.join(&name);
        let text = plant.day(day, samples, 1000 + u64::from(day), fault).csv();
        if let Err(e) = std::fs::write(&path, text) {
            eprintln!("{}: {e}", path.display());
            std::process::exit(1);
        }
        println!("wrote {}", path.display());
    }
}
