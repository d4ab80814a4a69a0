//! The GLR step of a channel (`[channels.glr]`): ranges, the detector, the detection
//! threshold (explicit, calibrated, or from a false-alarm probability) and the
//! isolation groups and calibrated isolation thresholds.

use glrmon_core::threshold::calibration::Target;
use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{DEFAULT_RANK_TOLERANCE, Onset};

use super::{Validator, join, suggest};
use crate::channel::FaultPlan;
use crate::schema::{self, CalibratedSpec, GlrSpec};
use crate::{DetectorKind, ThresholdSource, limits, locate};

/// The GLR settings of a channel that need its model and faults.
pub(super) struct Glr {
    pub(super) rank_tolerance: f64,
    pub(super) detector_kind: DetectorKind,
    pub(super) threshold: f64,
    pub(super) threshold_source: ThresholdSource,
    /// Isolation groups `(name, fault indices)`.
    pub(super) groups: Vec<(String, Vec<usize>)>,
    pub(super) episode_end: glrmon_core::EpisodeEnd,
    /// The onsets the isolation level is divided among (`isolation_law`).
    pub(super) isolation_onsets: u64,
}

fn positive(t: f64) -> bool {
    t.is_finite() && t > 0.0
}

impl Validator {
    /// Checks of the GLR settings that need no model, done first so that they are
    /// reported together with model errors.
    pub(super) fn glr_ranges(&mut self, prefix: &str, glr: &GlrSpec) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        if glr.window > limits::MAX_WINDOW {
            self.error(
                gpath("window"),
                format!(
                    "w = {} is more than {} (limits::MAX_WINDOW)",
                    glr.window,
                    limits::MAX_WINDOW
                ),
            );
        }
        for (field, value, max) in [
            ("max_gap", glr.max_gap, limits::MAX_GAP),
            ("max_reorder", glr.max_reorder, limits::MAX_REORDER),
        ] {
            if value > max {
                self.error(
                    gpath(field),
                    format!(
                        "{value} is more than {max} (limits::{})",
                        field.to_uppercase()
                    ),
                );
            }
        }
        if let Some(n) = glr.settle
            && n > limits::MAX_SETTLE
        {
            self.error(
                gpath("settle"),
                format!(
                    "{n} is more than {} (limits::MAX_SETTLE)",
                    limits::MAX_SETTLE
                ),
            );
        }
        if let Some(schema::WarmUpSpec::Samples(n)) = glr.warm_up
            && n > limits::MAX_WARM_UP
        {
            self.error(
                gpath("warm_up"),
                format!(
                    "{n} is more than {} (limits::MAX_WARM_UP)",
                    limits::MAX_WARM_UP
                ),
            );
        }
        if glr.window < 2 {
            self.error(
                gpath("window"),
                format!("w = {} must be at least 2", glr.window),
            );
        }
        if glr.min_lag >= glr.window {
            self.error(
                gpath("min_lag"),
                format!("s = {} must be below w = {}", glr.min_lag, glr.window),
            );
        }
        if !(0.0..1.0).contains(&glr.hysteresis) {
            self.error(
                gpath("hysteresis"),
                format!("{} is not in [0, 1)", glr.hysteresis),
            );
        }
        if !(glr.isolation_alpha > 0.0 && glr.isolation_alpha < 1.0) {
            self.error(
                gpath("isolation_alpha"),
                format!("{} is not in (0, 1)", glr.isolation_alpha),
            );
        }
    }

    /// The rank tolerance, the detector, the threshold, and the groups and calibrated
    /// isolation thresholds against the fault dictionary; `innovation_dof` is p minus
    /// the unknown inputs.
    pub(super) fn glr(
        &mut self,
        prefix: &str,
        glr: &GlrSpec,
        faults: &[FaultPlan],
        innovation_dof: usize,
    ) -> Glr {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let tolerance = glr.rank_tolerance.unwrap_or(DEFAULT_RANK_TOLERANCE);
        if !(tolerance > 0.0 && tolerance < 1.0) {
            self.error(
                gpath("rank_tolerance"),
                format!("{tolerance} is not in (0, 1)"),
            );
        }
        let detector_kind = match glr.detector.as_deref() {
            None => DetectorKind::default(),
            Some(name) => DetectorKind::from_name(name).unwrap_or_else(|| {
                self.error(
                    gpath("detector"),
                    locate::not_one_of(name, &DetectorKind::NAMES),
                );
                DetectorKind::default()
            }),
        };
        let m = detector_kind.statistic_dof(faults.len(), innovation_dof);
        let known = faults.iter().all(|f| f.onset == Onset::Known);
        let (threshold, threshold_source) = self.threshold(prefix, glr, detector_kind, m, known);
        let groups = self.groups(prefix, glr, faults);
        self.calibrated_isolation(prefix, glr, faults);
        let episode_end = self.episode_end(prefix, glr);
        let one_onset = known || !detector_kind.maximises_over_onsets();
        let isolation_onsets = match glr.isolation_law.as_deref() {
            None | Some("bonferroni") if !one_onset => {
                glr.window.saturating_sub(glr.min_lag).max(1) as u64
            }
            None | Some("bonferroni" | "chi2") => 1,
            Some(other) => {
                self.error(
                    gpath("isolation_law"),
                    locate::not_one_of(other, &["bonferroni", "chi2"]),
                );
                1
            }
        };
        Glr {
            rank_tolerance: tolerance,
            detector_kind,
            threshold,
            threshold_source,
            groups,
            episode_end,
            isolation_onsets,
        }
    }

    /// `episode_end`, `gone_alpha` and `gone_samples`: how an alarm episode ends.
    fn episode_end(&mut self, prefix: &str, glr: &GlrSpec) -> glrmon_core::EpisodeEnd {
        use glrmon_core::EpisodeEnd;
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let alpha = glr.gone_alpha.unwrap_or(0.01);
        if !(alpha > 0.0 && alpha < 0.5) {
            self.error(gpath("gone_alpha"), format!("{alpha} is not in (0, 0.5)"));
        }
        let samples = glr
            .gone_samples
            .unwrap_or_else(|| u32::try_from(2 * glr.window).unwrap_or(u32::MAX));
        if samples == 0 {
            self.error(gpath("gone_samples"), "must be at least 1".into());
        }
        match glr.episode_end.as_deref() {
            None | Some("fault_gone") => EpisodeEnd::FaultGone { alpha, samples },
            Some("below_threshold") => {
                for (key, given) in [
                    ("gone_alpha", glr.gone_alpha.is_some()),
                    ("gone_samples", glr.gone_samples.is_some()),
                ] {
                    if given {
                        self.error(
                            gpath(key),
                            "applies to `episode_end = \"fault_gone\"`, not to \
                             `below_threshold` (whose episodes end after `clear_samples`)"
                                .into(),
                        );
                    }
                }
                EpisodeEnd::BelowThreshold
            }
            Some(other) => {
                self.error(
                    gpath("episode_end"),
                    locate::not_one_of(other, &["fault_gone", "below_threshold"]),
                );
                EpisodeEnd::BelowThreshold
            }
        }
    }

    /// The detection threshold and how it was set: given, calibrated, or the χ²
    /// quantile of `false_alarm` (at most one of the three).
    fn threshold(
        &mut self,
        prefix: &str,
        glr: &GlrSpec,
        detector_kind: DetectorKind,
        m: usize,
        known: bool,
    ) -> (f64, ThresholdSource) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let given = [
            glr.threshold.is_some(),
            glr.false_alarm.is_some(),
            glr.calibrated.is_some(),
        ];
        if given.iter().filter(|&&g| g).count() > 1 {
            self.error(
                gpath("threshold"),
                "give one of `threshold`, `false_alarm` and `[channels.glr.calibrated]`".into(),
            );
        }
        if glr.threshold_mode.is_some() && glr.threshold.is_some() {
            self.error(
                gpath("threshold_mode"),
                "applies to `false_alarm`, not to an explicit `threshold`".into(),
            );
        }
        if detector_kind == DetectorKind::Kernel {
            for (key, given) in [
                ("false_alarm", glr.false_alarm.is_some()),
                ("threshold_mode", glr.threshold_mode.is_some()),
            ] {
                if given {
                    self.error(
                        gpath(key),
                        "the `kernel` detector's statistic r_FD/σ_FD has no probability law \
                         to set a threshold from: its threshold is 1, which no noise within \
                         `kernel.output_noise` and `kernel.state_noise` can cross (leave \
                         `false_alarm` out, or give `threshold`)"
                            .into(),
                    );
                }
            }
            if glr.threshold.is_none() && glr.calibrated.is_none() {
                return (1.0, ThresholdSource::Bounded);
            }
        }
        if let Some(t) = glr.threshold {
            if !positive(t) {
                self.error(
                    gpath("threshold"),
                    format!("{t} must be finite and positive"),
                );
            }
            (t, ThresholdSource::Explicit)
        } else if let Some(c) = &glr.calibrated {
            self.calibrated(prefix, c)
        } else {
            self.false_alarm(prefix, glr, detector_kind, m, known)
        }
    }

    /// `[channels.glr.calibrated]`: the threshold `glrmon calibrate` found, inside its
    /// interval, and its target (exactly one of `mtbfa` and `sample_far`).
    fn calibrated(&mut self, prefix: &str, c: &CalibratedSpec) -> (f64, ThresholdSource) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        if !positive(c.threshold) {
            self.error(
                gpath("calibrated.threshold"),
                format!("{} must be finite and positive", c.threshold),
            );
        }
        if !(c.interval[0] <= c.threshold && c.threshold <= c.interval[1]) {
            self.error(
                gpath("calibrated.interval"),
                format!(
                    "[{}, {}] does not contain the threshold {}",
                    c.interval[0], c.interval[1], c.threshold
                ),
            );
        }
        let target = match (c.mtbfa, c.sample_far) {
            (Some(m), None) => {
                if !(m.is_finite() && m > 1.0) {
                    self.error(
                        gpath("calibrated.mtbfa"),
                        format!("{m} must be more than 1 sample"),
                    );
                }
                Target::Mtbfa(m)
            }
            (None, Some(f)) => {
                if !(f > 0.0 && f < 1.0) {
                    self.error(
                        gpath("calibrated.sample_far"),
                        format!("{f} must be in (0, 1)"),
                    );
                }
                Target::SampleFar(f)
            }
            (m, f) => {
                self.error(
                    gpath("calibrated"),
                    format!(
                        "give exactly one target, mtbfa or sample_far (got {})",
                        if m.is_some() && f.is_some() {
                            "both"
                        } else {
                            "neither"
                        }
                    ),
                );
                Target::Mtbfa(f64::NAN)
            }
        };
        (
            c.threshold,
            ThresholdSource::Calibrated {
                target,
                samples: c.samples,
                episodes: c.episodes,
                exceedances: c.exceedances,
                interval: c.interval,
            },
        )
    }

    /// The χ²(m) quantile for the per-sample false-alarm probability `false_alarm`,
    /// divided among the window's onsets (Bonferroni) unless the onset is known, the
    /// mode is `chi2` or the detector tests one onset.
    fn false_alarm(
        &mut self,
        prefix: &str,
        glr: &GlrSpec,
        detector_kind: DetectorKind,
        m: usize,
        known: bool,
    ) -> (f64, ThresholdSource) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let a = glr.false_alarm.unwrap_or(1e-4);
        let chi2 = match glr.threshold_mode.as_deref() {
            None | Some("bonferroni") => false,
            Some("chi2") => true,
            Some(other) => {
                self.error(
                    gpath("threshold_mode"),
                    locate::not_one_of(other, &["bonferroni", "chi2"]),
                );
                false
            }
        };
        let per_onset = !detector_kind.maximises_over_onsets();
        let onsets = if known || chi2 || per_onset {
            1
        } else {
            glr.window.saturating_sub(glr.min_lag).max(1)
        };
        match chi2_upper_quantile(m as f64, a / onsets as f64) {
            Ok(t) if chi2 || per_onset => (t, ThresholdSource::Chi2 { false_alarm: a }),
            Ok(t) if known => (t, ThresholdSource::KnownOnset { false_alarm: a }),
            Ok(t) => (t, ThresholdSource::Bonferroni { false_alarm: a }),
            Err(e) => {
                self.error(gpath("false_alarm"), e.to_string());
                (0.0, ThresholdSource::Explicit)
            }
        }
    }

    /// The isolation groups, each naming at least one fault of the dictionary.
    fn groups(
        &mut self,
        prefix: &str,
        glr: &GlrSpec,
        faults: &[FaultPlan],
    ) -> Vec<(String, Vec<usize>)> {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        let mut groups = Vec::new();
        for (gi, g) in glr.groups.iter().enumerate() {
            let mut idx = Vec::new();
            for name in &g.faults {
                match faults.iter().position(|f| &f.name == name) {
                    Some(i) => idx.push(i),
                    None => {
                        let names: Vec<&str> = faults.iter().map(|f| f.name.as_str()).collect();
                        self.error(
                            gpath(&format!("groups[{gi}].faults")),
                            suggest(format!("unknown fault \"{name}\""), name, &names),
                        );
                    }
                }
            }
            if idx.is_empty() {
                self.error(gpath(&format!("groups[{gi}]")), "names no fault".into());
            }
            groups.push((g.name.clone(), idx));
        }
        groups
    }

    /// `[channels.glr.calibrated] isolation`: one positive threshold per isolation test
    /// (a group, or a fault when there are no groups).
    fn calibrated_isolation(&mut self, prefix: &str, glr: &GlrSpec, faults: &[FaultPlan]) {
        let gpath = |f: &str| join(prefix, &format!("glr.{f}"));
        if let Some(cal) = &glr.calibrated {
            let tests: Vec<&str> = if glr.groups.is_empty() {
                faults.iter().map(|f| f.name.as_str()).collect()
            } else {
                glr.groups.iter().map(|g| g.name.as_str()).collect()
            };
            for (name, t) in &cal.isolation {
                if !tests.contains(&name.as_str()) {
                    self.error(
                        gpath(&format!("calibrated.isolation.{name}")),
                        suggest(
                            format!("no isolation test \"{name}\" (tests: {})", tests.join(", ")),
                            name,
                            &tests,
                        ),
                    );
                } else if !(t.is_finite() && *t > 0.0) {
                    self.error(
                        gpath(&format!("calibrated.isolation.{name}")),
                        format!("{t} must be finite and positive"),
                    );
                }
            }
        }
    }
}
