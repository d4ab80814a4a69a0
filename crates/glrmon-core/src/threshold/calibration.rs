//! Calibration of the detection threshold on fault-free data.
//!
//! The windowed GLR l_k = max over w − s onsets is not χ²(m) under no fault (it is a
//! maximum of correlated χ² statistics), so a χ² quantile gives far more false alarms
//! than its nominal rate, and the Bonferroni bound α/(w − s) far fewer. A user states a
//! [`Target`] instead, and the threshold is read off fault-free l_k:
//!
//! - a mean time between false alarms M ([`calibrate`]): the mean number of samples
//!   between the starts of false-alarm *episodes* (with the channel's hysteresis). The
//!   episode count E(λ) over N samples is non-increasing in λ; bisection finds the λ at
//!   which E(λ) = N / M. The count is Poisson, so the achieved rate carries an exact
//!   (Garwood) confidence interval, mapped back to a threshold interval;
//! - a per-sample false-alarm fraction f ([`calibrate_sample_far`]): the (1 − f)
//!   empirical quantile of l_k, so that a fraction f of the samples has l_k > λ. Its
//!   interval comes from the order statistics, with the count of exceedances taken as
//!   compound Poisson (Poisson clusters, runs closer than the window, of unequal
//!   sizes), because consecutive l_k share w − 1 innovations and exceed λ in runs: a
//!   plain binomial interval would treat each sample of a run as independent evidence
//!   and be several times too narrow.
//!
//! l_k itself does not depend on λ: the detector never restarts or clears its window at
//! an alarm (only a gap or a numerical failure restarts it), so one run's statistics
//! serve every candidate λ.
//!
//! Either target is met more loosely the fewer events the data hold at it: fewer than
//! [`MIN_EVENTS`] expected events is allowed, and [`Calibration::well_supported`] says so.

use crate::alarm::{AlarmSettings, AlarmState};
use crate::threshold::chi2_quantile;

/// Events (episodes, or exceedances) that the data should hold at the target for the
/// rate to be known within about ±60 % (95 %); fewer are loosely supported.
pub const MIN_EVENTS: f64 = 10.0;

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

/// Samples of `glr` with l_k > λ, and the clusters they form: runs of exceedances in
/// which consecutive ones are at most `memory` samples apart (a NaN, the end of a
/// segment or of a run of inadmissible onsets, ends a cluster).
#[must_use]
pub fn count_exceedances(glr: &[f64], threshold: f64, memory: usize) -> (u64, u64) {
    let (exceedances, clusters, _) = clusters(glr, threshold, memory);
    (exceedances, clusters)
}

/// [`count_exceedances`] with the sum of the squared cluster sizes: the compound Poisson
/// count whose equivalent number of events is exceedances² / Σ size².
#[must_use]
pub fn clusters(glr: &[f64], threshold: f64, memory: usize) -> (u64, u64, f64) {
    let (mut exceedances, mut clusters, mut squares) = (0, 0, 0.0);
    let mut size = 0.0;
    let mut since: Option<usize> = None;
    for &l in glr {
        if l.is_nan() {
            since = None;
        } else if l > threshold {
            exceedances += 1;
            if since.is_none_or(|s| s >= memory) {
                clusters += 1;
                squares += size * size;
                size = 0.0;
            }
            size += 1.0;
            since = Some(0);
        } else if let Some(s) = &mut since {
            *s += 1;
        }
    }
    (exceedances, clusters, squares + size * size)
}

/// What a threshold is calibrated for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// A mean number of samples between the starts of false-alarm episodes.
    Mtbfa(f64),
    /// A fraction of the fault-free samples (with an admissible onset) whose l_k
    /// exceeds λ.
    SampleFar(f64),
}

/// A calibrated threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// λ for the target on the data.
    pub threshold: f64,
    /// The target.
    pub target: Target,
    /// Fault-free samples used (with an admissible onset).
    pub samples: u64,
    /// Episodes at λ on the data (with the hysteresis given; for a
    /// [`Target::SampleFar`], the exceedance clusters).
    pub episodes: u64,
    /// Samples with l_k > λ on the data.
    pub exceedances: u64,
    /// Events the target expects on this much data: episodes N / M, or exceedances
    /// N · f.
    pub expected: f64,
    /// 95 % confidence interval of the rate achieved at λ, in the target's unit
    /// `(low, high)`: mean samples between episodes (Garwood interval of a Poisson
    /// count), or the fraction of samples above λ (the exceedance count taken as
    /// compound Poisson: the Garwood interval of r² / Σ size² equivalent clusters,
    /// times r over that number). An end the data cannot bound is infinite.
    pub rate_interval: (f64, f64),
    /// Thresholds giving the ends of that interval's rates on the data: the uncertainty
    /// of λ itself `(low, high)`; `high` is infinite when the data hold too few events
    /// to bound it (the rate's low end lies beyond the largest l_k).
    pub threshold_interval: (f64, f64),
}

impl Calibration {
    /// Whether the data hold at least [`MIN_EVENTS`] events at the target: expected
    /// episodes, or expected exceedances forming as many clusters (a few long runs of
    /// exceedances are little evidence, however many samples they hold).
    #[must_use]
    pub fn well_supported(&self) -> bool {
        match self.target {
            Target::Mtbfa(_) => self.expected >= MIN_EVENTS,
            Target::SampleFar(_) => {
                self.expected >= MIN_EVENTS && self.episodes as f64 >= MIN_EVENTS
            }
        }
    }
}

/// Errors of [`calibrate`] and [`calibrate_sample_far`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationError {
    /// The target is impossible (the message says why).
    #[error("{0}")]
    Target(String),
    /// No sample has an admissible onset (no l_k at all).
    #[error("no fault-free sample has an admissible onset, so there is no l_k to calibrate on")]
    NoSamples,
    /// Every admissible l_k is 0 (or less): no positive λ is ever exceeded, so no false
    /// alarm can be formed.
    #[error(
        "all {samples} admissible l_k are at most {max}: no positive threshold is exceeded, \
         so no false-alarm episode can be formed"
    )]
    NoEpisode {
        /// Samples with an admissible onset.
        samples: u64,
        /// Their largest l_k.
        max: f64,
    },
}

/// The admissible l_k's count and maximum, or the error when no positive λ can be
/// exceeded.
fn admissible(glr: &[f64]) -> Result<(u64, f64), CalibrationError> {
    let (samples, max) = glr
        .iter()
        .filter(|l| !l.is_nan())
        .fold((0u64, f64::NEG_INFINITY), |(n, m), &l| (n + 1, m.max(l)));
    if samples == 0 {
        return Err(CalibrationError::NoSamples);
    }
    if max.is_nan() || max <= 0.0 {
        return Err(CalibrationError::NoEpisode { samples, max });
    }
    Ok((samples, max))
}

/// Garwood 95 % interval `(low, high)` of a Poisson mean with `events` counted.
fn garwood(events: u64) -> (f64, f64) {
    garwood_events(events as f64)
}

/// The Garwood 95 % interval `(low, high)` of a Poisson mean with `e` events counted, a
/// count that may be fractional (an equivalent number of events).
#[must_use]
pub fn garwood_events(e: f64) -> (f64, f64) {
    let low = if e <= 0.0 {
        0.0
    } else {
        chi2_quantile(2.0 * e, 0.025).map_or(0.0, |q| q / 2.0)
    };
    let high = chi2_quantile(2.0 * e + 2.0, 0.975).map_or(f64::INFINITY, |q| q / 2.0);
    (low, high)
}

/// Finds λ for a mean of `mtbfa` samples between false-alarm episodes on the fault-free
/// statistics `glr` (see the module documentation). `hysteresis` and `clear_samples` are
/// the channel's. Data holding fewer than [`MIN_EVENTS`] episodes at the target give a
/// loosely supported λ ([`Calibration::well_supported`]), down to none: λ is then the
/// largest l_k and its upper end unbounded.
///
/// # Errors
/// [`CalibrationError::Target`] for a target of 1 sample or less,
/// [`CalibrationError::NoSamples`] without an admissible l_k and
/// [`CalibrationError::NoEpisode`] when none is positive.
pub fn calibrate(
    glr: &[f64],
    mtbfa: f64,
    hysteresis: f64,
    clear_samples: u32,
) -> Result<Calibration, CalibrationError> {
    if !(mtbfa.is_finite() && mtbfa > 1.0) {
        return Err(CalibrationError::Target(format!(
            "the mean time between false alarms must be more than 1 sample, got {mtbfa}"
        )));
    }
    let (samples, max) = admissible(glr)?;
    let expected = samples as f64 / mtbfa;
    let settings = |threshold| AlarmSettings {
        threshold,
        hysteresis,
        clear_samples: clear_samples.max(1),
    };
    let count = |h: f64| count_episodes(glr, settings(h));
    // λ with at most `target` episodes (the smallest such λ, to bisection precision);
    // infinite for a target under one episode that the data cannot resolve.
    let solve = |target: f64| -> f64 {
        let mut hi = max;
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
    let (low_events, high_events) = garwood(episodes);
    let n = samples as f64;
    Ok(Calibration {
        threshold,
        target: Target::Mtbfa(mtbfa),
        samples,
        episodes,
        exceedances: glr.iter().filter(|&&l| l > threshold).count() as u64,
        expected,
        rate_interval: (
            n / high_events,
            if low_events > 0.0 {
                n / low_events
            } else {
                f64::INFINITY
            },
        ),
        // More events than counted would come from a lower λ, fewer from a higher one;
        // under one episode on the data lies beyond its largest l_k.
        threshold_interval: (
            solve(high_events),
            if low_events >= 1.0 {
                solve(low_events)
            } else {
                f64::INFINITY
            },
        ),
    })
}

/// Finds λ exceeded by a fraction `fraction` of the fault-free statistics `glr` (NaN
/// where no onset is admissible, and between independent segments): the (1 − f)
/// empirical quantile: the (⌈N·f⌉ + 1)-th largest l_k, which ⌈N·f⌉ samples (ties aside)
/// exceed. `memory` is the l_k's memory in samples (the window w): exceedances
/// closer than that count as one cluster for the interval (see the module
/// documentation). Data expecting fewer than [`MIN_EVENTS`] exceedances give a loosely
/// supported λ ([`Calibration::well_supported`]); under one, λ is the largest l_k.
///
/// # Errors
/// [`CalibrationError::Target`] unless 0 < f < 1 or when the quantile is not positive,
/// [`CalibrationError::NoSamples`] without an admissible l_k and
/// [`CalibrationError::NoEpisode`] when no l_k is positive.
pub fn calibrate_sample_far(
    glr: &[f64],
    fraction: f64,
    memory: usize,
) -> Result<Calibration, CalibrationError> {
    if !(fraction > 0.0 && fraction < 1.0) {
        return Err(CalibrationError::Target(format!(
            "the per-sample false-alarm fraction must be in (0, 1), got {fraction}"
        )));
    }
    let (samples, _) = admissible(glr)?;
    let mut sorted: Vec<f64> = glr.iter().copied().filter(|l| !l.is_nan()).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    // l_k repeats exactly while its maximising onset stays in the window (and in the
    // stationary regime), so values tie in blocks: of the two thresholds around the
    // block holding the wanted rank, the one whose count above is nearer `above` (the
    // higher on a draw). Beyond the data, unbounded.
    let with_above = |above: f64| -> f64 {
        let above = above.ceil().max(0.0);
        if above < 1.0 {
            return f64::INFINITY;
        }
        let Some(&x) = sorted.get(n.saturating_sub(above as usize + 1)) else {
            return f64::NAN;
        };
        let first = sorted.partition_point(|&v| v < x);
        let past = sorted.partition_point(|&v| v <= x);
        let (at, below) = ((n - past) as f64, (n - first) as f64);
        match first.checked_sub(1).and_then(|i| sorted.get(i)) {
            Some(&lower) if below - above < above - at => lower,
            _ => x,
        }
    };
    let expected = n as f64 * fraction;
    let threshold = if expected < 1.0 {
        sorted[n - 1]
    } else {
        with_above(expected)
    };
    if threshold.is_nan() || threshold <= 0.0 {
        return Err(CalibrationError::Target(format!(
            "the {} quantile of l_k is {threshold}: fewer than a fraction {fraction} of the \
             {samples} admissible samples have a positive l_k, so no positive threshold is \
             exceeded that often",
            1.0 - fraction
        )));
    }
    let (exceedances, clusters, squares) = clusters(glr, threshold, memory);
    // The count of exceedances is compound Poisson: Poisson clusters of unequal sizes,
    // with variance Σ size². As many equal clusters with that variance relative to the
    // mean, r² / Σ size², carry its Garwood interval.
    let effective = if clusters == 0 {
        0.0
    } else {
        (exceedances as f64).powi(2) / squares
    };
    let (low, high) = garwood_events(effective);
    let per_event = if clusters == 0 {
        1.0 / n as f64
    } else {
        exceedances as f64 / effective / n as f64
    };
    let rate = ((per_event * low).min(1.0), (per_event * high).min(1.0));
    Ok(Calibration {
        threshold,
        target: Target::SampleFar(fraction),
        samples,
        episodes: clusters,
        exceedances,
        expected,
        rate_interval: rate,
        threshold_interval: (
            with_above(rate.1 * n as f64).min(threshold),
            with_above(rate.0 * n as f64).max(threshold),
        ),
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

    /// χ²(2) statistics from a Weyl sequence: l_k = −2 ln u_k, P(l > λ) = exp(−λ/2).
    fn weyl_chi2(n: u64) -> Vec<f64> {
        (1..=n)
            .map(|i| {
                let u = ((i as f64) * 0.618_033_988_749_894_9).fract().max(1e-300);
                -2.0 * u.ln()
            })
            .collect()
    }

    /// On i.i.d. exponential-like statistics with no hysteresis, an episode is a run
    /// above λ; for λ where crossings are rare the calibrated count matches the target.
    #[test]
    fn calibrates_to_the_target_count_and_brackets_it() {
        let glr = weyl_chi2(200_000);
        let c = calibrate(&glr, 1000.0, 0.0, 1).unwrap();
        assert!((c.episodes as f64 - 200.0).abs() <= 2.0, "{c:?}");
        // χ²(2) tail: P(l > λ) = exp(−λ/2) = 1/1000 → λ ≈ 13.8.
        assert!((c.threshold - 13.8155).abs() < 0.2, "{c:?}");
        assert!(c.threshold_interval.0 < c.threshold && c.threshold < c.threshold_interval.1);
        assert!(
            c.rate_interval.0 < 1000.0 && 1000.0 < c.rate_interval.1,
            "{c:?}"
        );
        assert!(c.well_supported());
        assert_eq!(c.target, Target::Mtbfa(1000.0));
    }

    /// 5 expected episodes are a warning, not a refusal: the interval says how loose the
    /// answer is, and with fewer than one episode λ is unbounded above.
    #[test]
    fn too_few_episodes_give_a_loosely_supported_threshold() {
        let glr = weyl_chi2(5_000);
        let c = calibrate(&glr, 1000.0, 0.0, 1).unwrap();
        assert!(!c.well_supported(), "{c:?}");
        assert_eq!(c.expected, 5.0);
        assert!(c.episodes.abs_diff(5) <= 1, "{c:?}");
        // Garwood for 5 events: 1.62–11.67, so a mean of 428–3080 samples.
        assert!(
            c.rate_interval.0 < 500.0 && c.rate_interval.1 > 2500.0,
            "{c:?}"
        );
        let c = calibrate(&glr[..500], 1000.0, 0.0, 1).unwrap();
        assert_eq!(c.episodes, 0, "{c:?}");
        let max = glr[..500].iter().copied().fold(0.0, f64::max);
        assert!((c.threshold - max).abs() <= 1e-9 * max, "{c:?}");
        assert_eq!(c.threshold_interval.1, f64::INFINITY);
        assert_eq!(c.rate_interval.1, f64::INFINITY);
        // No sample, no positive l_k, an impossible target: errors.
        assert_eq!(
            calibrate(&[f64::NAN; 3], 1000.0, 0.0, 1),
            Err(CalibrationError::NoSamples)
        );
        assert!(matches!(
            calibrate(&[0.0, f64::NAN, 0.0], 1000.0, 0.0, 1),
            Err(CalibrationError::NoEpisode { samples: 2, .. })
        ));
        assert!(matches!(
            calibrate(&glr, 0.5, 0.0, 1),
            Err(CalibrationError::Target(_))
        ));
    }

    /// Tied l_k: λ sits below or at the tied block, whichever count is nearer N·f.
    #[test]
    fn the_sample_far_threshold_steps_over_ties_to_the_nearer_count() {
        let mut v: Vec<f64> = (1..=90).map(f64::from).collect();
        v.extend([95.0; 8]);
        v.extend([96.0, 97.0]);
        let c = calibrate_sample_far(&v, 0.07, 1).unwrap();
        assert_eq!((c.threshold, c.exceedances), (90.0, 10), "{c:?}");
        let c = calibrate_sample_far(&v, 0.05, 1).unwrap();
        assert_eq!((c.threshold, c.exceedances), (95.0, 2), "{c:?}");
    }

    #[test]
    fn exceedances_are_clustered_within_the_memory_and_split_by_nan() {
        let glr = [5.0, 0.0, 5.0, 0.0, 0.0, 0.0, 5.0, f64::NAN, 5.0];
        assert_eq!(count_exceedances(&glr, 1.0, 2), (4, 3));
        assert_eq!(count_exceedances(&glr, 1.0, 3), (4, 3));
        assert_eq!(count_exceedances(&glr, 1.0, 4), (4, 2));
        assert_eq!(count_exceedances(&glr, 1.0, 1), (4, 4));
    }

    /// On i.i.d. χ²(2) statistics the (1 − f) quantile is λ = −2 ln f, exceeded by
    /// exactly ⌈N·f⌉ samples of the data, and the interval brackets both.
    #[test]
    fn the_sample_far_threshold_is_the_empirical_quantile() {
        let glr = weyl_chi2(100_000);
        let c = calibrate_sample_far(&glr, 0.01, 1).unwrap();
        assert_eq!(c.exceedances, 1000, "{c:?}");
        assert_eq!(c.expected, 1000.0);
        assert!((c.threshold - (-2.0 * 0.01f64.ln())).abs() < 0.1, "{c:?}");
        assert!(
            c.rate_interval.0 < 0.01 && 0.01 < c.rate_interval.1,
            "{c:?}"
        );
        // 1000 independent exceedances: Garwood ±6 %.
        assert!(
            c.rate_interval.0 > 0.0093 && c.rate_interval.1 < 0.0107,
            "{c:?}"
        );
        assert!(c.threshold_interval.0 < c.threshold && c.threshold < c.threshold_interval.1);
        // Every sample doubled into a run of two: 2000 exceedances that carry the
        // evidence of 1000, so the interval of the 1000 independent ones, √2 wider than
        // a binomial interval that took the 2000 as independent.
        let doubled: Vec<f64> = glr.iter().flat_map(|&l| [l, l]).collect();
        let d = calibrate_sample_far(&doubled, 0.01, 1).unwrap();
        assert_eq!((d.exceedances, d.episodes), (2000, 1000));
        let width = |c: &Calibration| c.rate_interval.1 - c.rate_interval.0;
        assert!((width(&d) - width(&c)).abs() < 1e-12, "{d:?} vs {c:?}");
        let (low, high) = garwood(2000);
        assert!(width(&d) > 1.35 * (high - low) / 200_000.0, "{d:?}");
        // Under one expected exceedance: the largest l_k, loosely supported.
        let s = calibrate_sample_far(&glr[..50], 0.01, 1).unwrap();
        assert!(!s.well_supported());
        assert_eq!(s.exceedances, 0);
        assert_eq!(s.threshold_interval.1, f64::INFINITY);
        assert!(matches!(
            calibrate_sample_far(&glr, 1.0, 1),
            Err(CalibrationError::Target(_))
        ));
        let mostly_zero: Vec<f64> = (0..200).map(|i| f64::from(u8::from(i == 7))).collect();
        assert!(matches!(
            calibrate_sample_far(&mostly_zero, 0.01, 1),
            Err(CalibrationError::Target(_))
        ));
    }
}
