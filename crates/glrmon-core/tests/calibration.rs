//! Trustworthy thresholds on the §6.1 plant of Zhang & Basseville (2014)
//! (n = 2, m = 2 state faults, w = 100, s = 1): the per-onset χ²(2) quantile gives far
//! more false alarms than its nominal rate, the Bonferroni bound never more, and a
//! threshold calibrated on one fault-free run gives its target rate on another.

use glrmon_core::StepOutput;
use glrmon_core::alarm::AlarmSettings;
use glrmon_core::threshold::calibration::{calibrate, count_episodes};
use glrmon_core::threshold::chi2_upper_quantile;

/// l_k (NaN before an onset is admissible) over `n` fault-free samples.
fn fault_free_glr(seed: u64, n: usize) -> Vec<f64> {
    let sc = glrmon_sim::scenarios::paper2014_unstable();
    let mut det = sc.detector().unwrap();
    let mut sim = sc.simulator(seed).unwrap();
    let mut out = StepOutput::new(1, 2);
    let mut glr = Vec::with_capacity(n);
    for _ in 0..n {
        let x = sim.next_sample();
        let s = glrmon_core::Sample {
            k: x.k,
            u: &x.u,
            y: &x.y,
            p: &x.p,
        };
        det.step(&s, &mut out).unwrap();
        glr.push(out.glr.unwrap_or(f64::NAN));
    }
    glr
}

fn exceedances(glr: &[f64], h: f64) -> f64 {
    glr.iter().filter(|&&l| l > h).count() as f64 / glr.len() as f64
}

#[test]
fn calibrated_threshold_gives_its_target_rate_on_an_independent_run() {
    let n = 1_000_000;
    let calibration_run = fault_free_glr(1, n);
    let c = calibrate(&calibration_run, 1e4, 0.1, 1).unwrap();
    let independent = fault_free_glr(2, n);
    let settings = AlarmSettings::with_threshold(c.threshold);
    let episodes = count_episodes(&independent, settings);
    let rate = episodes as f64 / n as f64;
    eprintln!(
        "calibrated λ = {:.3} (95 % interval {:.3}–{:.3}) from {} episodes in {} samples; \
         independent run: {episodes} episodes in {n} samples = one per {:.0} samples (target 10 000)",
        c.threshold,
        c.threshold_interval.0,
        c.threshold_interval.1,
        c.episodes,
        c.samples,
        1.0 / rate
    );
    assert!((rate * 1e4 - 1.0).abs() <= 0.3, "rate {rate} vs 1e-4");

    // The per-onset χ²(2) quantile at 1e-4 (18.42) is exceeded far more often than
    // 1e-4; the Bonferroni bound (χ²(2) at 1e-4/99) never more.
    let chi2 = chi2_upper_quantile(2.0, 1e-4).unwrap();
    let bonferroni = chi2_upper_quantile(2.0, 1e-4 / 99.0).unwrap();
    let (p_chi2, p_bonf) = (
        exceedances(&independent, chi2),
        exceedances(&independent, bonferroni),
    );
    eprintln!(
        "fraction of fault-free samples above: χ²(2) 1e-4 quantile {chi2:.2}: {p_chi2:.2e}; \
         Bonferroni {bonferroni:.2}: {p_bonf:.2e}; calibrated {:.2}: {:.2e}",
        c.threshold,
        exceedances(&independent, c.threshold)
    );
    assert!(p_chi2 > 10.0 * 1e-4, "{p_chi2}");
    assert!(p_bonf <= 1e-4, "{p_bonf}");
    assert!(c.threshold > chi2 && c.threshold < bonferroni, "{c:?}");
}
