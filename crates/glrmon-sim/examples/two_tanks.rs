//! A week of a two-tank plant's history as a historian exports it (see
//! `glrmon_sim::two_tanks`): `mon.csv` … `sun.csv` fault-free, and `fault.csv`, a
//! day with a +1.5 cm bias on LI202 from sample 1200 (06:40 UTC at 20-s samples).
//!
//! ```sh
//! cargo run -q -p glrmon-sim --example two_tanks -- DIR [SAMPLES_PER_DAY]
//! ```

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
    match std::fs::create_dir_all(dir)
        .and_then(|()| glrmon_sim::two_tanks::write_week(dir, samples))
    {
        Ok(paths) => {
            let names: Vec<String> = paths
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            println!("wrote {} in {}", names.join(", "), dir.display());
        }
        Err(e) => {
            eprintln!("{}: {e}", dir.display());
            std::process::exit(1);
        }
    }
}
