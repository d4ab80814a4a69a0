//! Alarm episodes: one alarm per fault episode, not one per sample.
//!
//! An episode starts when l_k crosses the threshold λ. How it ends is the channel's
//! [`EpisodeEnd`]:
//! - [`EpisodeEnd::BelowThreshold`]: when l_k falls below λ·(1 − h) (hysteresis h) for
//!   `clear_samples` consecutive samples, so a statistic that hovers around λ does not
//!   flap. A fault that persists longer than the window can end its episode this way
//!   (its onset leaves the window and the onsets inside it fit the settled response
//!   badly) and raise a new one later: a stream of alarms for one fault.
//! - [`EpisodeEnd::FaultGone`]: when the data say the fault is gone: the fault followed
//!   from the alarm's onset past the window ([`crate::Detector::followed`]) does not go
//!   on in the last w samples ([`FollowedEvidence::continues`]: they are closer to no
//!   fault than to it) for `samples` consecutive samples, and l_k is below λ·(1 − h)
//!   then (so the end is not followed at once by an alarm on the same data). When the
//!   last w samples cannot see the fault at all at level α (a jump the filter has
//!   absorbed) there is nothing to wait for: the episode ends by the threshold rule. Until its followed fault has gone on for `samples`/2 samples in a
//!   row (a fault confirmed; noise that raised a false alarm does not do that), a new
//!   crossing (l_k > λ) whose onset r̂ comes after the alarm, at a sample where the
//!   fault does not go on and the data do not show it reversing (z_k ≥ −z_α), is a new
//!   change: it ends the episode and starts the next at once
//!   ([`AlarmTransition::Replaced`]), so that a false alarm's episode does not hide a
//!   fault that begins during it. The crossing a confirmed fault's removal causes is
//!   its end, not a new fault. Without a
//!   followed statistic (a kind that cannot follow an onset) it falls back to the first
//!   rule.

use crate::threshold::chi2_upper_quantile;
use crate::window::FollowedEvidence;

/// How an alarm episode ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EpisodeEnd {
    /// l_k below λ·(1 − h) for `clear_samples` consecutive samples.
    BelowThreshold,
    /// The followed fault does not go on ([`FollowedEvidence::continues`] at `alpha`)
    /// for `samples` consecutive samples, with l_k below λ·(1 − h) at the last.
    FaultGone {
        /// Level at which the last w samples must be able to see the fault, in (0, 0.5).
        alpha: f64,
        /// Consecutive samples without evidence that end the episode (at least 1).
        samples: u32,
    },
}

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
    /// The episode ended at this sample and a new one started at it: a crossing with
    /// an onset after the ended episode's alarm, whose fault was not confirmed.
    Replaced {
        /// Index of the sample that started the ended episode.
        started: u64,
        /// Largest l_k during the ended episode.
        peak: f64,
    },
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
    end: EpisodeEnd,
    started: Option<u64>,
    peak: f64,
    below: u32,
    /// Consecutive samples of the episode without evidence of the followed fault.
    gone: u32,
    /// Consecutive samples the followed fault has gone on, and whether it has done so
    /// for `samples`/2 of them in a row in this episode (confirmed).
    continued: u32,
    confirmed: bool,
    /// The normal upper quantile of the fault-gone test: (α, value).
    quantile: Option<(f64, f64)>,
}

impl AlarmState {
    /// A quiet alarm state whose episodes end below the threshold
    /// ([`EpisodeEnd::BelowThreshold`]; see [`AlarmState::set_end`]).
    #[must_use]
    pub fn new(settings: AlarmSettings) -> Self {
        Self {
            settings,
            end: EpisodeEnd::BelowThreshold,
            started: None,
            peak: 0.0,
            below: 0,
            gone: 0,
            continued: 0,
            confirmed: false,
            quantile: None,
        }
    }

    /// Sets how episodes end, from the next sample on (an episode going on continues).
    pub fn set_end(&mut self, end: EpisodeEnd) {
        self.end = end;
    }

    /// How episodes end.
    #[must_use]
    pub fn end(&self) -> EpisodeEnd {
        self.end
    }

    /// Feeds l_k of sample k (`None` when no onset is admissible), with no followed
    /// fault: episodes end below the threshold.
    pub fn update(&mut self, k: u64, glr: Option<f64>) -> AlarmTransition {
        self.update_followed(k, glr, None, None)
    }

    /// Feeds l_k of sample k with its onset estimate r̂, and the followed fault's
    /// evidence of the episode, if any ([`crate::Detector::followed`]). The caller
    /// passes r̂ only when it dates a change inside the window (`None` for the window's
    /// oldest onset: a change older than the window, a fault going on).
    ///
    /// # Examples
    /// ```
    /// use glrmon_core::alarm::{AlarmSettings, AlarmState, AlarmTransition, EpisodeEnd};
    /// use glrmon_core::FollowedEvidence;
    /// let mut alarm = AlarmState::new(AlarmSettings::with_threshold(10.0));
    /// alarm.set_end(EpisodeEnd::FaultGone { alpha: 0.01, samples: 2 });
    /// let ev = |score| Some(FollowedEvidence { score, information: 25.0, full: true });
    /// assert_eq!(alarm.update_followed(0, Some(12.0), Some(0), None), AlarmTransition::Started);
    /// // l_k has fallen, but the followed fault is still in the data (z ≥ √δ/2 = 2.5).
    /// assert_eq!(alarm.update_followed(1, Some(2.0), Some(0), ev(4.0)), AlarmTransition::Active);
    /// assert_eq!(alarm.update_followed(2, Some(2.0), Some(0), ev(1.0)), AlarmTransition::Active);
    /// assert!(matches!(
    ///     alarm.update_followed(3, Some(2.0), Some(0), ev(-0.5)),
    ///     AlarmTransition::Ended { .. }
    /// ));
    /// ```
    pub fn update_followed(
        &mut self,
        k: u64,
        glr: Option<f64>,
        onset: Option<u64>,
        followed: Option<FollowedEvidence>,
    ) -> AlarmTransition {
        let s = self.settings;
        let Some(started) = self.started else {
            if glr.is_some_and(|l| l > s.threshold) {
                self.started = Some(k);
                self.peak = glr.unwrap_or(0.0);
                self.below = 0;
                self.gone = 0;
                self.continued = 0;
                self.confirmed = false;
                return AlarmTransition::Started;
            }
            return AlarmTransition::Quiet;
        };
        let clear = s.threshold * (1.0 - s.hysteresis);
        let high = glr.is_some_and(|l| l >= clear);
        if let Some(l) = glr.filter(|_| high) {
            self.peak = self.peak.max(l);
            self.below = 0;
        } else {
            self.below += 1;
        }
        let ended = match (self.end, followed) {
            // The evidence is gathered over w samples from the alarm on: no decision on
            // fewer.
            (EpisodeEnd::FaultGone { .. }, Some(evidence)) if !evidence.full => false,
            (EpisodeEnd::FaultGone { alpha, samples }, Some(evidence)) => {
                let z_alpha = self.z_alpha(alpha);
                if evidence.continues(z_alpha) {
                    self.gone = 0;
                    self.continued += 1;
                    self.confirmed |= self.continued >= (samples / 2).max(1);
                } else {
                    self.gone += 1;
                    self.continued = 0;
                    let crossing = glr.is_some_and(|l| l > s.threshold);
                    let new_change =
                        onset.is_some_and(|r| r > started) && evidence.score >= -z_alpha;
                    if !self.confirmed && crossing && new_change {
                        let peak = self.peak;
                        self.started = Some(k);
                        self.peak = glr.unwrap_or(0.0);
                        self.below = 0;
                        self.gone = 0;
                        return AlarmTransition::Replaced { started, peak };
                    }
                }
                if evidence.information.max(0.0).sqrt() < z_alpha {
                    // The data no longer see the fault at all (a jump the filter has
                    // absorbed): nothing to wait for, the threshold rule ends it.
                    self.below >= s.clear_samples.max(1)
                } else {
                    self.gone >= samples.max(1) && !high
                }
            }
            _ => self.below >= s.clear_samples.max(1),
        };
        if ended {
            self.started = None;
            AlarmTransition::Ended {
                started,
                peak: self.peak,
            }
        } else {
            AlarmTransition::Active
        }
    }

    /// The normal upper quantile at α, √(χ²(1) upper quantile at 2α) for α < 0.5.
    fn z_alpha(&mut self, alpha: f64) -> f64 {
        match self.quantile {
            Some((a, q)) if a == alpha => q,
            _ => {
                let q = chi2_upper_quantile(1.0, 2.0 * alpha).map_or(f64::INFINITY, f64::sqrt);
                self.quantile = Some((alpha, q));
                q
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
        self.gone = 0;
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

    /// Fault-gone ending: l_k below the threshold does not end the episode while the
    /// followed evidence is high; `samples` consecutive samples without evidence end it
    /// once l_k is below λ(1 − h) too; evidence in between starts the count again.
    #[test]
    fn a_followed_fault_keeps_its_episode_until_it_is_gone() {
        let mut a = AlarmState::new(AlarmSettings::with_threshold(10.0));
        a.set_end(EpisodeEnd::FaultGone {
            alpha: 0.01,
            samples: 3,
        });
        assert_eq!(
            a.update_followed(0, Some(11.0), Some(0), None),
            AlarmTransition::Started
        );
        // z per sample, δ = 16: the fault goes on while z ≥ 2.
        let trace = [
            (Some(3.0), 6.0),
            (Some(2.0), 2.0),
            (Some(2.0), 1.0),
            (Some(2.0), 2.5), // evidence again: the count restarts
            (Some(2.0), 0.1),
            (Some(9.5), -1.0), // l_k in the hysteresis band: not yet
            (Some(8.0), 0.3),
            (None, 0.0),
        ];
        let t: Vec<_> = trace
            .iter()
            .enumerate()
            .map(|(i, &(l, score))| {
                let evidence = FollowedEvidence {
                    score,
                    information: 16.0,
                    full: true,
                };
                a.update_followed(i as u64 + 1, l, Some(0), Some(evidence))
            })
            .collect();
        assert!(
            t[..6].iter().all(|x| *x == AlarmTransition::Active),
            "{t:?}"
        );
        // Gone at 5, 6, 7: the third is sample 7, where l_k = 8 < 9.
        assert_eq!(
            t[6],
            AlarmTransition::Ended {
                started: 0,
                peak: 11.0
            }
        );
        assert_eq!(t[7], AlarmTransition::Quiet);
    }

    /// Without a followed statistic the fault-gone rule falls back to the threshold.
    #[test]
    fn fault_gone_without_evidence_ends_below_the_threshold() {
        let mut a = AlarmState::new(AlarmSettings::with_threshold(1.0));
        a.set_end(EpisodeEnd::FaultGone {
            alpha: 0.01,
            samples: 50,
        });
        a.update_followed(0, Some(2.0), Some(0), None);
        assert!(matches!(
            a.update_followed(1, Some(0.1), Some(0), None),
            AlarmTransition::Ended { .. }
        ));
    }

    /// A crossing with a later onset while the followed fault has no evidence ends the
    /// episode and starts a new one; with the episode's own onset, or with the data
    /// showing the fault reversing, it does not; and once the fault is confirmed, no
    /// crossing replaces the episode.
    #[test]
    fn a_new_change_replaces_an_episode_whose_fault_is_gone() {
        let mut a = AlarmState::new(AlarmSettings::with_threshold(10.0));
        a.set_end(EpisodeEnd::FaultGone {
            alpha: 0.01,
            samples: 50,
        });
        let ev = |score| {
            Some(FollowedEvidence {
                score,
                information: 16.0,
                full: true,
            })
        };
        a.update_followed(5, Some(12.0), Some(3), None);
        // No evidence, but the crossing's onset is before the alarm: same episode.
        assert_eq!(
            a.update_followed(7, Some(30.0), Some(4), ev(0.0)),
            AlarmTransition::Active
        );
        // A later onset, but the data show the fault reversing (z < −2.33).
        assert_eq!(
            a.update_followed(7, Some(30.0), Some(7), ev(-3.0)),
            AlarmTransition::Active
        );
        assert_eq!(
            a.update_followed(8, Some(30.0), Some(8), ev(0.0)),
            AlarmTransition::Replaced {
                started: 5,
                peak: 30.0
            }
        );
        assert!(a.is_active());
        // The new episode's fault goes on for 25 = 50/2 samples: confirmed, no
        // crossing replaces it.
        for k in 9..34 {
            assert_eq!(
                a.update_followed(k, Some(30.0), Some(8), ev(4.0)),
                AlarmTransition::Active
            );
        }
        assert_eq!(
            a.update_followed(34, Some(30.0), Some(34), ev(0.0)),
            AlarmTransition::Active
        );
    }

    #[test]
    fn missing_statistic_counts_towards_clearing() {
        let mut a = AlarmState::new(AlarmSettings::with_threshold(1.0));
        a.update(0, Some(2.0));
        assert!(matches!(a.update(1, None), AlarmTransition::Ended { .. }));
    }
}
