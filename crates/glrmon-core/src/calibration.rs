//! Calibration of the detection threshold on fault-free data.
//!
//! The windowed GLR l_k = max over w − s onsets is not χ²(m) under no fault (it is a
//! maximum of correlated χ² statistics), so a χ² quantile gives far more false alarms
//! than its nominal rate, and the Bonferroni bound α/(w − s) far fewer. A user asks for a
//! mean time between false alarms instead: the mean number of samples between the starts
//! of false-alarm *episodes* (with the channel's hysteresis). Given l_k over N fault-free
//! samples, the episode count E(λ) is non-increasing in λ; bisection finds the λ at which
//! E(λ) = N / M. The count is Poisson, so the achieved rate carries an exact (Garwood)
//! confidence interval, mapped back to a threshold interval.

use crate::alarm::{AlarmSettings, AlarmState};
use crate::threshold::chi2_quantile;

/// Alarm episodes started over a sequence of l_k (`NaN` where no onset is admissible)
/// with the given settings.
#[must_use]
pub fn count_episodes(glr: &[f64], settings: AlarmSettings) -> u64 {
    let mut state = AlarmState::new(settings);
    let mut n = 0;
    for (k, &l) in glr.iter().enumerate() {
        let l = (!l.is_nan()).then_some(l);
        if matches!(
            state.update(k as u64, l),
            crate::alarm::AlarmTransition::Started
        ) {
            n += 1;
        }
    }
    n
}

/// A calibrated threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// λ whose episode count on the data is closest to the target.
    pub threshold: f64,
    /// Fault-free samples used (with an admissible onset).
    pub samples: u64,
    /// Episodes at λ on the data.
    pub episodes: u64,
    /// Target mean number of samples between false-alarm episodes.
    pub mtbfa: f64,
    /// 95 % confidence interval of the episode rate at λ, as mean samples between
    /// episodes `(low, high)` (Garwood interval of a Poisson count).
    pub mtbfa_interval: (f64, f64),
    /// Thresholds giving the ends of that interval's rates on the data: the uncertainty
    /// of λ itself `(low, high)`.
    pub threshold_interval: (f64, f64),
    /// Episodes the target expects on this much data, N / M.
    pub expected_episodes: f64,
}

/// Errors of [`calibrate`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// Too little data for the target: the numbers say how much is needed.
    #[error(
        "{samples} fault-free samples hold only {expected:.1} false-alarm episodes at a mean of \
         one per {mtbfa} samples; at least {needed} samples are needed for 10 episodes (about \
         ±60 % on the rate), {needed_30} for ±30 %"
    )]
    TooLittleData {
        /// Samples given.
        samples: u64,
        /// Episodes expected at the target.
        expected: f64,
        /// The target.
        mtbfa: f64,
        /// Samples for 10 episodes.
        needed: u64,
        /// Samples for about ±30 % (43 episodes).
        needed_30: u64,
    },
    /// The target or the data is unusable.
    #[error("{0}")]
    Invalid(String),
}

/// Finds λ for a mean of `mtbfa` samples between false-alarm episodes on the fault-free
/// statistics `glr` (see the module documentation). `hysteresis` and `clear_samples` are
/// the channel's.
///
/// # Errors
/// [`CalibrationError::TooLittleData`] when the data holds fewer than 10 episodes at the
/// target; [`CalibrationError::Invalid`] for a non-positive target or no admissible l_k.
pub fn calibrate(
    glr: &[f64],
    mtbfa: f64,
    hysteresis: f64,
    clear_samples: u32,
) -> Result<Calibration, CalibrationError> {
    if !(mtbfa.is_finite() && mtbfa > 1.0) {
        return Err(CalibrationError::Invalid(format!(
            "the mean time between false alarms must be more than 1 sample, got {mtbfa}"
        )));
    }
    let samples = glr.iter().filter(|l| !l.is_nan()).count() as u64;
    if samples == 0 {
        return Err(CalibrationError::Invalid(
            "no sample has an admissible onset".into(),
        ));
    }
    let expected = samples as f64 / mtbfa;
    if expected < 10.0 {
        return Err(CalibrationError::TooLittleData {
            samples,
            expected,
            mtbfa,
            needed: (10.0 * mtbfa).ceil() as u64,
            needed_30: (43.0 * mtbfa).ceil() as u64,
        });
    }
    let settings = |threshold| AlarmSettings {
        threshold,
        hysteresis,
        clear_samples: clear_samples.max(1),
    };
    let count = |h: f64| count_episodes(glr, settings(h));
    // λ with at most `target` episodes (the smallest such λ, to bisection precision).
    let solve = |target: f64| -> f64 {
        let mut hi = glr
            .iter()
            .copied()
            .filter(|l| !l.is_nan())
            .fold(0.0_f64, f64::max)
            .max(1e-12);
        let mut lo = 0.0;
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if (count(mid) as f64) <= target {
                hi = mid;
            } else {
                lo = mid;
            }
            if hi - lo <= 1e-9 * hi {
                break;
            }
        }
        hi
    };
    let threshold = solve(expected);
    let episodes = count(threshold);
    // Garwood 95 % interval of a Poisson mean for `episodes` events.
    let e = episodes as f64;
    let low_events = if episodes == 0 {
        0.0
    } else {
        chi2_quantile(2.0 * e, 0.025).map_or(0.0, |q| q / 2.0)
    };
    let high_events = chi2_quantile(2.0 * e + 2.0, 0.975).map_or(f64::INFINITY, |q| q / 2.0);
    let n = samples as f64;
    Ok(Calibration {
        threshold,
        samples,
        episodes,
        mtbfa,
        mtbfa_interval: (n / high_events, n / low_events.max(f64::MIN_POSITIVE)),
        // More events than counted would come from a lower λ, fewer from a higher one.
        threshold_interval: (solve(high_events), solve(low_events)),
        expected_episodes: expected,
    })
}

/// An upper quantile estimated from samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantile {
    /// The value exceeded by a fraction α of the samples.
    pub value: f64,
    /// 95 % interval from the order statistics, for independent samples (consecutive
    /// statistics of a window test are correlated, so it is optimistic).
    pub interval: (f64, f64),
    /// Samples used.
    pub samples: u64,
}

/// The (1 − α) quantile of `values` (sorted in place), for thresholds that fault-free
/// statistics exceed with probability α: e.g. the isolation tests' minmax statistic at
/// r̂, which is larger than χ² under no fault (the maximising onset is selected on the
/// same data). `None` with fewer than 10/α samples (fewer than 10 exceedances).
#[must_use]
pub fn upper_quantile(values: &mut [f64], alpha: f64) -> Option<Quantile> {
    let n = values.len();
    if !(alpha > 0.0 && alpha < 1.0) || (n as f64) * alpha < 10.0 {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let at = |rank: f64| values[(rank.round().max(0.0) as usize).min(n - 1)];
    let centre = (n as f64) * (1.0 - alpha);
    let spread = 1.96 * ((n as f64) * alpha * (1.0 - alpha)).sqrt();
    Some(Quantile {
        value: at(centre),
        interval: (at(centre - spread), at(centre + spread)),
        samples: n as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_follow_the_hysteresis() {
        let s = AlarmSettings {
            threshold: 10.0,
            hysteresis: 0.5,
            clear_samples: 1,
        };
        // 11 starts; 6 stays above 5, 4 ends; 12 starts again; NaN ends.
        let glr = [1.0, 11.0, 6.0, 4.0, 12.0, f64::NAN, 11.0, 3.0];
        assert_eq!(count_episodes(&glr, s), 3);
    }

    #[test]
    fn upper_quantile_of_a_uniform_grid() {
        let mut v: Vec<f64> = (0..10_000).map(f64::from).collect();
        let q = upper_quantile(&mut v, 0.01).unwrap();
        assert_eq!(q.value, 9900.0);
        assert!(q.interval.0 < 9900.0 && q.interval.1 > 9900.0);
        assert!(upper_quantile(&mut v[..500], 0.01).is_none());
    }

    /// On i.i.d. exponential-like statistics with no hysteresis, an episode is a run
    /// above λ; for λ where crossings are rare the calibrated count matches the target.
    #[test]
    fn calibrates_to_the_target_count_and_brackets_it() {
        // A deterministic sequence with a known tail: l_k = −2 ln u_k (χ²(2)) from a
        // Weyl sequence of u.
        let glr: Vec<f64> = (1..=200_000u64)
            .map(|i| {
                let u = ((i as f64) * 0.618_033_988_749_894_9).fract().max(1e-300);
                -2.0 * u.ln()
            })
            .collect();
        let c = calibrate(&glr, 1000.0, 0.0, 1).unwrap();
        assert!((c.episodes as f64 - 200.0).abs() <= 2.0, "{c:?}");
        // χ²(2) tail: P(l > λ) = exp(−λ/2) = 1/1000 → λ ≈ 13.8.
        assert!((c.threshold - 13.8155).abs() < 0.2, "{c:?}");
        assert!(c.threshold_interval.0 < c.threshold && c.threshold < c.threshold_interval.1);
        assert!(
            c.mtbfa_interval.0 < 1000.0 && 1000.0 < c.mtbfa_interval.1,
            "{c:?}"
        );
        assert!(matches!(
            calibrate(&glr[..5000], 1000.0, 0.0, 1),
            Err(CalibrationError::TooLittleData { needed: 10000, .. })
        ));
    }
}
