//! The isolation tests' real level on fault-free data.
//!
//! The minmax test is χ²(dof) under "no fault of the tested group" at a given onset,
//! but it runs at the onset r̂ the data chose among w − s. On fault-free DC-motor data
//! the nominal 1 % quantile was exceeded on 9.4 % and 4.2 % of samples by the two
//! faults' tests. The default law (`isolation_law = "bonferroni"`) divides α among the
//! window's onsets, a bound on the level of the maximum over them; this test measures
//! both on the DC motor of the survey example (config/examples/dc-motor.toml).

use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_wire::Sample;

const CONFIG: &str = include_str!("../../../config/examples/dc-motor.toml");

#[test]
fn fault_free_exceedance_of_the_isolation_thresholds_is_within_the_level_in_force() {
    let c = glrmon_spec::parse(CONFIG).unwrap().channels[0].clone();
    assert_eq!(c.isolation_onsets, 99, "w − s of the example");
    let alpha = c.isolation_alpha;
    let nominal = chi2_upper_quantile(1.0, alpha).unwrap();
    let bonferroni = chi2_upper_quantile(1.0, alpha / c.isolation_onsets as f64).unwrap();
    let names = c.fault_names.clone();
    let (mut samples, mut above_nominal, mut above_bonferroni) = (0usize, vec![0; 2], vec![0; 2]);
    for seed in 0..4 {
        let mut sim = glrmon_sim::from_channel(&c, seed).unwrap();
        let mut mon = glrmon_monitor::Monitor::from_channel(&c).unwrap();
        let mut records = Vec::new();
        for k in 0..5000u64 {
            let x = sim.next_sample();
            let s = Sample {
                k: Some(k),
                t: None,
                u: x.u,
                y: x.y,
                p: x.p,
            };
            records.clear();
            mon.on_sample(&s, &mut records);
            if k < 200 {
                continue;
            }
            let stats = mon.isolation_statistics();
            if stats.is_empty() {
                continue;
            }
            samples += 1;
            for (i, name) in names.iter().enumerate() {
                let v = stats.iter().find(|(n, _)| n == name).unwrap().1;
                above_nominal[i] += usize::from(v > nominal);
                above_bonferroni[i] += usize::from(v > bonferroni);
            }
        }
    }
    let rate = |n: usize| n as f64 / samples as f64;
    for (i, name) in names.iter().enumerate() {
        let (nominal_rate, level_rate) = (rate(above_nominal[i]), rate(above_bonferroni[i]));
        eprintln!(
            "{name}: above χ²(1) at {alpha}: {:.2} %; above the law in force \
             (at {alpha}/{}): {:.3} % of {samples} samples",
            100.0 * nominal_rate,
            c.isolation_onsets,
            100.0 * level_rate
        );
        // The level in force holds (its bound α, with room for sampling error on
        // clustered exceedances); the nominal one is exceeded well beyond α by one
        // of the tests at least, which is why it is not the default.
        assert!(level_rate <= 1.5 * alpha, "{name}: {level_rate}");
    }
    assert!(
        (0..names.len()).any(|i| rate(above_nominal[i]) > 2.0 * alpha),
        "the nominal law held: {above_nominal:?} of {samples}"
    );
}
