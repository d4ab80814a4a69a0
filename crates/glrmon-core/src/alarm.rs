//! Alarm episodes: one alarm per fault episode, not one per sample.
//!
//! An episode starts when l_k crosses the threshold λ and ends when l_k falls below
//! λ·(1 − h) (hysteresis h) for `clear_samples` consecutive samples, so a statistic
//! that hovers around λ does not flap.

/// Alarm settings of a channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlarmSettings {
    /// λ: an episode starts when l_k > λ.
    pub threshold: f64,
    /// h ∈ [0, 1): an episode may end once l_k < λ·(1 − h).
    pub hysteresis: f64,
    /// Consecutive samples below λ·(1 − h) (or without an admissible onset) that end
    /// an episode. At least 1.
    pub clear_samples: u32,
}

impl AlarmSettings {
    /// Settings with threshold λ, 10% hysteresis and a single clearing sample.
    #[must_use]
    pub fn with_threshold(threshold: f64) -> Self {
        Self {
            threshold,
            hysteresis: 0.1,
            clear_samples: 1,
        }
    }
}

/// What one sample did to the alarm state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AlarmTransition {
    /// No episode, none started.
    Quiet,
    /// An episode started at this sample.
    Started,
    /// An episode is going on.
    Active,
    /// The episode ended at this sample.
    Ended {
        /// Index of the sample that started it.
        started: u64,
        /// Largest l_k during the episode.
        peak: f64,
    },
}

/// The alarm state machine of a channel.
///
/// # Examples
/// ```
/// use glrmon_core::alarm::{AlarmSettings, AlarmState, AlarmTransition};
/// let mut alarm = AlarmState::new(AlarmSettings::with_threshold(10.0));
/// assert_eq!(alarm.update(0, Some(3.0)), AlarmTransition::Quiet);
/// assert_eq!(alarm.update(1, Some(12.0)), AlarmTransition::Started);
/// assert_eq!(alarm.update(2, Some(9.5)), AlarmTransition::Active); // above λ(1 − h) = 9
/// assert_eq!(alarm.update(3, Some(2.0)), AlarmTransition::Ended { started: 1, peak: 12.0 });
/// ```
#[derive(Debug, Clone)]
pub struct AlarmState {
    settings: AlarmSettings,
    started: Option<u64>,
    peak: f64,
    below: u32,
}

impl AlarmState {
    /// A quiet alarm state.
    #[must_use]
    pub fn new(settings: AlarmSettings) -> Self {
        Self {
            settings,
            started: None,
            peak: 0.0,
            below: 0,
        }
    }

    /// Feeds l_k of sample k (`None` when no onset is admissible).
    pub fn update(&mut self, k: u64, glr: Option<f64>) -> AlarmTransition {
        let s = self.settings;
        match self.started {
            None => {
                if glr.is_some_and(|l| l > s.threshold) {
                    self.started = Some(k);
                    self.peak = glr.unwrap_or(0.0);
                    self.below = 0;
                    AlarmTransition::Started
                } else {
                    AlarmTransition::Quiet
                }
            }
            Some(started) => {
                let clear = s.threshold * (1.0 - s.hysteresis);
                match glr {
                    Some(l) if l >= clear => {
                        self.peak = self.peak.max(l);
                        self.below = 0;
                        AlarmTransition::Active
                    }
                    _ => {
                        self.below += 1;
                        if self.below >= s.clear_samples.max(1) {
                            self.started = None;
                            AlarmTransition::Ended {
                                started,
                                peak: self.peak,
                            }
                        } else {
                            AlarmTransition::Active
                        }
                    }
                }
            }
        }
    }

    /// Whether an episode is going on.
    #[must_use]
    pub fn is_active(&self) -> bool {
        self.started.is_some()
    }

    /// The settings in force.
    #[must_use]
    pub fn settings(&self) -> AlarmSettings {
        self.settings
    }

    /// Ends any episode at once (the detector restarts): returns its start and peak.
    pub fn reset(&mut self) -> Option<(u64, f64)> {
        let ended = self.started.take().map(|s| (s, self.peak));
        self.peak = 0.0;
        self.below = 0;
        ended
    }

    /// Replaces the settings (e.g. a reloaded threshold) without ending an episode.
    pub fn set_settings(&mut self, settings: AlarmSettings) {
        self.settings = settings;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_episode_gives_one_start_and_one_end() {
        let mut a = AlarmState::new(AlarmSettings {
            threshold: 5.0,
            hysteresis: 0.2,
            clear_samples: 2,
        });
        let trace = [1.0, 6.0, 7.0, 3.9, 4.5, 3.0, 3.0, 1.0];
        let t: Vec<_> = trace
            .iter()
            .enumerate()
            .map(|(k, l)| a.update(k as u64, Some(*l)))
            .collect();
        let starts = t.iter().filter(|x| **x == AlarmTransition::Started).count();
        let ends = t
            .iter()
            .filter(|x| matches!(x, AlarmTransition::Ended { .. }))
            .count();
        assert_eq!((starts, ends), (1, 1));
        assert_eq!(
            t[6],
            AlarmTransition::Ended {
                started: 1,
                peak: 7.0
            }
        );
    }

    #[test]
    fn missing_statistic_counts_towards_clearing() {
        let mut a = AlarmState::new(AlarmSettings::with_threshold(1.0));
        a.update(0, Some(2.0));
        assert!(matches!(a.update(1, None), AlarmTransition::Ended { .. }));
    }
}
