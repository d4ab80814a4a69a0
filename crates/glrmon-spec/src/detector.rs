//! The detector kinds a channel can run (`[channels.glr] detector`) and the factory
//! that builds a channel's [`Detector`].
//!
//! A new kind, once its numerics are a module of `glrmon_core::detector`, is one
//! variant of [`DetectorKind`] with its name and the law of its statistic below, and
//! one arm of [`Channel::detector`]; the schema's `detector` field lists the names
//! from [`DetectorKind::NAMES`].

use glrmon_core::detector::parity::{Disturbance, ParityDetector};
use glrmon_core::detector::{FdfDetector, FdfGains, RlsDetector, UioDetector};
use glrmon_core::{Chi2Detector, CusumDetector, Detector, GlrDetector, KernelDetector, ModelError};

use crate::Channel;

/// The detection method of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DetectorKind {
    /// The moving-window GLR of Zhang & Basseville 2014 on the Kalman (or Kitanidis)
    /// innovation: onset, magnitude and isolation.
    #[default]
    Glr,
    /// The classical χ² test of one sample's εᵀΣ⁻¹ε (the baseline to compare with).
    Chi2,
    /// Page's CUSUM of the innovation for faults of known magnitude.
    Cusum,
    /// The parity-space residual of Ahmad & Mohd-Mokhtar 2021, eqs. (4)-(8).
    Parity,
    /// The observer fault-detection filter of the survey, eqs. (9)-(10), (18).
    Fdf,
    /// The unknown-input observer of Chen, Patton & Zhang 1996.
    Uio,
    /// Parameter estimation: recursive least squares on the model's ARX form.
    Rls,
    /// The kernel-based deadbeat detection and isolation of Li, Boem, Pin & Parisini
    /// on a continuous-time model with bounded noises: r_FD/σ_FD against 1.
    Kernel,
}

impl DetectorKind {
    /// Every kind, in declaration order (a kind's index is its discriminant).
    pub const ALL: [Self; 8] = [
        Self::Glr,
        Self::Chi2,
        Self::Cusum,
        Self::Parity,
        Self::Fdf,
        Self::Uio,
        Self::Rls,
        Self::Kernel,
    ];

    /// The names the configuration accepts, as [`DetectorKind::ALL`].
    pub const NAMES: [&'static str; 8] = [
        "glr", "chi2", "cusum", "parity", "fdf", "uio", "rls", "kernel",
    ];

    /// The configuration's name of the kind.
    #[must_use]
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The kind named `name` in a configuration.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The degrees of freedom of the statistic's χ² law under no fault, for one tested
    /// onset: m for the GLR (the number of faults: l_k(r) ~ χ²(rank C_k(r)) ≤ χ²(m),
    /// Zhang & Basseville 2014 §5), the dimension of the residual it tests for the
    /// others (`residual_dof`: the innovation's p − q for the χ² test, the parity
    /// space's for `parity`); 1 for `kernel`, whose statistic is one ratio r_FD/σ_FD
    /// with no χ² law (its threshold is the bound 1, [`crate::ThresholdSource::Bounded`]).
    #[must_use]
    pub fn statistic_dof(self, faults: usize, residual_dof: usize) -> usize {
        match self {
            Self::Glr => faults.max(1),
            Self::Kernel => 1,
            Self::Chi2 | Self::Cusum | Self::Parity | Self::Fdf | Self::Uio | Self::Rls => {
                residual_dof.max(1)
            }
        }
    }

    /// Whether the kind runs the Kalman (or Kitanidis) filter, whose innovation the
    /// consistency test and sparse diagnosis read, and estimates magnitudes for
    /// isolation.
    #[must_use]
    pub fn runs_kalman_filter(self) -> bool {
        match self {
            Self::Glr | Self::Chi2 | Self::Cusum => true,
            Self::Parity | Self::Fdf | Self::Uio | Self::Rls | Self::Kernel => false,
        }
    }

    /// Whether the statistic is a maximum over the window's candidate onsets, so that
    /// a false-alarm probability per sample is shared among them (Bonferroni).
    #[must_use]
    pub fn maximises_over_onsets(self) -> bool {
        match self {
            Self::Glr => true,
            Self::Chi2
            | Self::Cusum
            | Self::Parity
            | Self::Fdf
            | Self::Uio
            | Self::Rls
            | Self::Kernel => false,
        }
    }
}

impl Channel {
    /// The channel's detector, of the kind the configuration names: the one factory
    /// the monitor, `calibrate`, `evaluate` and `validate` build detectors with.
    ///
    /// # Errors
    /// As [`GlrDetector::new`] (not expected after validation).
    pub fn detector(&self) -> Result<Box<dyn Detector>, ModelError> {
        Ok(match self.detector_kind {
            DetectorKind::Glr => Box::new(self.glr_detector()?),
            DetectorKind::Chi2 => Box::new(Chi2Detector::new(self.glr_detector()?)),
            DetectorKind::Cusum => Box::new(CusumDetector::new(
                self.glr_detector()?,
                self.cusum_magnitudes.clone().ok_or(ModelError::Setting {
                    what: "cusum",
                    detail: "the channel has no CUSUM magnitudes".into(),
                })?,
            )?),
            DetectorKind::Parity => Box::new(self.parity_detector()?),
            DetectorKind::Fdf => {
                let observer = self.observer_settings()?;
                let (sys, _) = self.matrices_at_zero();
                let gains = match &observer.gains {
                    Some((l, v)) => FdfGains {
                        l: l.clone(),
                        v: v.clone(),
                    },
                    None => FdfGains::optimal(
                        &sys.f,
                        &sys.h,
                        &sys.q,
                        &sys.r,
                        &self.cross_covariance.clone().unwrap_or_else(|| {
                            nalgebra::DMatrix::zeros(self.dims.states, self.dims.outputs)
                        }),
                    )?,
                };
                let detector = FdfDetector::new(
                    Box::new(self.model.clone()),
                    self.dictionary()?,
                    gains,
                    self.x0.clone(),
                    self.p0.clone(),
                    observer.evaluation,
                )?;
                Box::new(match &self.cross_covariance {
                    Some(s) => detector.with_cross_covariance(s.clone())?,
                    None => detector,
                })
            }
            DetectorKind::Rls => {
                let settings = self.rls.as_ref().ok_or(ModelError::Setting {
                    what: "rls",
                    detail: "the channel has no RLS settings".into(),
                })?;
                Box::new(rls_detector(
                    &self.model,
                    self.cross_covariance.as_ref(),
                    self.dictionary()?,
                    settings,
                )?)
            }
            DetectorKind::Kernel => Box::new(self.kernel_detector()?),
            DetectorKind::Uio => {
                let observer = self.observer_settings()?;
                let e = self.unknown_input.as_ref().ok_or(ModelError::Setting {
                    what: "uio",
                    detail: "the unknown-input observer needs model.E".into(),
                })?;
                Box::new(UioDetector::new(
                    Box::new(self.model.clone()),
                    e.base().clone(),
                    self.dictionary()?,
                    self.x0.clone(),
                    observer.evaluation,
                )?)
            }
        })
    }

    /// The channel's parity detector (`detector = "parity"`).
    ///
    /// # Errors
    /// As [`ParityDetector::new`]; a channel without parity settings.
    pub fn parity_detector(&self) -> Result<ParityDetector, ModelError> {
        ParityDetector::new(
            Box::new(self.model.clone()),
            self.dictionary()?,
            self.unknown_input.as_ref().map(|e| Disturbance {
                state: e.base().clone(),
                output: self
                    .unknown_input_outputs
                    .clone()
                    .unwrap_or_else(|| nalgebra::DMatrix::zeros(self.dims.outputs, e.shape().1)),
            }),
            self.cross_covariance.clone(),
            self.parity.ok_or(ModelError::Setting {
                what: "parity",
                detail: "the channel has no parity settings".into(),
            })?,
        )
    }

    /// The channel's kernel detector (`detector = "kernel"`), its candidates'
    /// expressions compiled afresh.
    ///
    /// # Errors
    /// As [`KernelDetector::new`]; a channel without kernel settings.
    pub fn kernel_detector(&self) -> Result<KernelDetector, ModelError> {
        let kernel = self.kernel.as_ref().ok_or(ModelError::Setting {
            what: "kernel",
            detail: "the channel has no kernel settings".into(),
        })?;
        KernelDetector::new(
            &kernel.model,
            self.dims.signals,
            kernel.settings.clone(),
            kernel.candidates(self.dims.inputs),
        )
    }

    fn observer_settings(&self) -> Result<&crate::channel::ObserverSettings, ModelError> {
        self.observer.as_ref().ok_or(ModelError::Setting {
            what: "observer",
            detail: "the channel has no observer settings".into(),
        })
    }

    /// The model's matrices at k = 0 with zero signals (an LTI model's matrices).
    pub(crate) fn matrices_at_zero(&self) -> (glrmon_core::SystemMatrices, ()) {
        use glrmon_core::StateSpace as _;
        let mut sys = glrmon_core::SystemMatrices::zeros(self.dims);
        let (u, p) = (vec![0.0; self.dims.inputs], vec![0.0; self.dims.signals]);
        self.model
            .clone()
            .evaluate(0, &glrmon_core::Signals { u: &u, p: &p }, &mut sys);
        (sys, ())
    }

    /// The GLR detector of the channel's model and faults, whatever its kind: for the
    /// analyses of the GLR window itself (its Fisher information, Σ_k).
    ///
    /// # Errors
    /// As [`GlrDetector::new`] (not expected after validation).
    pub fn glr_detector(&self) -> Result<GlrDetector, ModelError> {
        let detector = GlrDetector::new(
            Box::new(self.model.clone()),
            self.dictionary()?,
            self.x0.clone(),
            self.p0.clone(),
            self.window,
        )?;
        match (&self.unknown_input, &self.cross_covariance) {
            (Some(e), _) => detector.with_unknown_input(e.clone()),
            (None, Some(s)) => detector.with_cross_covariance(s.clone()),
            (None, None) => Ok(detector),
        }
    }
}

/// The RLS detector of `settings` for `model` (with the noises' cross-covariance S if
/// given): the factory's, and validation's check of the model's ARX form.
pub(crate) fn rls_detector(
    model: &glrmon_core::Lpv,
    cross: Option<&nalgebra::DMatrix<f64>>,
    faults: glrmon_core::FaultDictionary,
    settings: &crate::channel::RlsChannelSettings,
) -> Result<RlsDetector, ModelError> {
    let detector = RlsDetector::new(
        Box::new(model.clone()),
        faults,
        settings.rls,
        settings.evaluation,
    )?;
    match cross {
        Some(s) => detector.with_cross_covariance(s.clone()),
        None => Ok(detector),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_round_trips_through_its_name() {
        assert_eq!(DetectorKind::ALL.len(), DetectorKind::NAMES.len());
        for (kind, name) in DetectorKind::ALL.into_iter().zip(DetectorKind::NAMES) {
            assert_eq!(kind.name(), name);
            assert_eq!(DetectorKind::from_name(name), Some(kind));
        }
        assert_eq!(DetectorKind::from_name("kalman"), None);
    }

    /// The observer kinds: the FDF with the optimal gains or given ones (an unstable
    /// F − LH refused, naming L), the UIO only with `model.E` and with the existence
    /// condition that fails named; the χ² dof is the residual's (p − rank HE for the
    /// UIO).
    #[test]
    fn observer_settings_are_validated_against_the_model() {
        let text = |model_extra: &str, glr: &str, observer: &str| {
            format!(
                r#"
[[channels]]
name = "motor"
model = {{ F = [[0.2231, 0.0109], [-0.0022, 0.5488]], G = [[0.0047], [0.4512]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.0001, R = 0.0025{model_extra} }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 0 }}]
glr = {{ detector = "{glr}" }}
{observer}
"#
            )
        };
        let cfg = crate::parse(&text("", "fdf", "")).unwrap();
        assert_eq!(cfg.channels[0].statistic_dof, 2);
        assert!(cfg.channels[0].observer.as_ref().unwrap().gains.is_none());
        assert_eq!(cfg.channels[0].detector().unwrap().kind(), "fdf");
        let cfg = crate::parse(&text(
            "",
            "fdf",
            "observer = { L = [[0.1, 0.0], [0.0, 0.3]], V = [[1.0, 0.0]] }",
        ))
        .unwrap();
        assert_eq!(cfg.channels[0].statistic_dof, 1);
        let err = crate::parse(&text(
            "",
            "fdf",
            "observer = { L = [[3.0, 0.0], [0.0, 0.3]] }",
        ))
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("observer.L") && err.contains("not stable"),
            "{err}"
        );
        let err = crate::parse(&text("", "uio", "")).unwrap_err().to_string();
        assert!(
            err.contains("model.E") && err.contains("give `model.E`"),
            "{err}"
        );
        let cfg = crate::parse(&text(", E = [[-1.5537], [0.0]]", "uio", "")).unwrap();
        assert_eq!(cfg.channels[0].statistic_dof, 1);
        assert_eq!(cfg.channels[0].detector().unwrap().kind(), "uio");
        let err = crate::parse(&text(", E = [[1.0, 0.0], [0.0, 1.0]]", "uio", ""))
            .unwrap_err()
            .to_string();
        assert!(err.contains("model.E"), "{err}");
        let cfg = crate::parse(&text("", "rls", "rls = { forgetting = 0.98 }")).unwrap();
        assert_eq!(
            cfg.channels[0].statistic_dof, 8,
            "2 outputs × (a1, a2, b1, b2)"
        );
        let det = cfg.channels[0].detector().unwrap();
        assert_eq!((det.kind(), det.memory()), ("rls", 50));
        let err = crate::parse(&text("", "rls", "rls = { forgetting = 1.5 }"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("rls.forgetting") && err.contains("not in (0, 1]"),
            "{err}"
        );
        let err = crate::parse(&text("", "glr", "observer = { evaluation = \"chi2\" }"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("applies to `glr.detector = \"fdf\" or \"uio\"`"),
            "{err}"
        );
    }

    /// `model.Fd`, the unknown input's effect on the outputs: the parity kind decouples
    /// it (perfectly from order 2 on for the DC motor with d on the speed sensor), the
    /// Kitanidis-based kinds refuse it, and it needs E.
    #[test]
    fn the_output_unknown_input_is_for_the_parity_kind() {
        let text = |model_extra: &str, detector: &str| {
            format!(
                r#"
[[channels]]
name = "motor"
model = {{ F = [[0.2231, 0.0109], [-0.0022, 0.5488]], G = [[0.0047], [0.4512]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.0001, R = 0.0025{model_extra} }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 1 }}]
glr = {{ detector = "{detector}" }}
"#
            )
        };
        let fd = ", E = [[0.0], [0.0]], Fd = [[1.0], [0.0]]";
        let cfg = crate::parse(&text(fd, "parity")).unwrap();
        let c = &cfg.channels[0];
        assert_eq!(c.parity.unwrap().order, 2);
        assert!(
            c.detector()
                .unwrap()
                .describe()
                .contains("disturbance decoupled")
        );
        let with_e = ", E = [[-1.5537], [0.0]], Fd = [[1.0], [0.0]]";
        for kind in ["glr", "chi2", "uio"] {
            let err = crate::parse(&text(with_e, kind)).unwrap_err().to_string();
            assert!(
                err.contains("model.Fd") && err.contains("state only"),
                "{kind}: {err}"
            );
        }
        let err = crate::parse(&text(", Fd = [[1.0], [0.0]]", "parity"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("model.Fd") && err.contains("needs model.E"),
            "{err}"
        );
    }

    /// Designs the earlier checks cannot judge are refused when the configuration is
    /// read, not when the daemon starts: a parity space of an LPV model that needs the
    /// optimal vector (LTI only); an FDF weight V with dependent rows (its χ² would
    /// have fewer degrees of freedom than its threshold assumes).
    #[test]
    fn residual_generators_that_cannot_be_built_are_refused() {
        let lpv = r#"
[[channels]]
name = "plant"
signals = 1
model = { F = { base = [[0.5, 1.0], [0.0, 0.8]], p0 = [[0.1, 0.0], [0.0, 0.0]] }, G = [[0.0], [1.0]], H = [[1.0, 0.0]], Q = 0.0025, R = 0.0025, E = [[1.0], [0.0]] }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
glr = { detector = "parity" }
parity = { order = 2 }
"#;
        let err = crate::parse(lpv).unwrap_err().to_string();
        assert!(
            err.contains("glr.detector") && err.contains("LTI models only"),
            "{err}"
        );
        let fdf = r#"
[[channels]]
name = "motor"
model = { F = [[0.2231, 0.0109], [-0.0022, 0.5488]], G = [[0.0047], [0.4512]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.0001, R = 0.0025 }
faults = [{ name = "bias", kind = "sensor_bias", output = 0 }]
glr = { detector = "fdf" }
observer = { L = [[0.1, 0.0], [0.0, 0.3]], V = [[1.0, 0.0], [2.0, 0.0]] }
"#;
        let err = crate::parse(fdf).unwrap_err().to_string();
        assert!(
            err.contains("observer.V") && err.contains("rank 1"),
            "{err}"
        );
    }

    /// A parity window too large for a channel's memory budget is refused at
    /// `parity.order`, before any design work: 64 outputs, 64 states and 64 unknown
    /// inputs at s = 64 need about 1.1 GB of matrices.
    #[test]
    fn a_parity_window_over_the_memory_budget_is_refused() {
        let eye = |scale: f64| {
            let rows: Vec<String> = (0..64)
                .map(|i| {
                    let row: Vec<String> = (0..64)
                        .map(|j| {
                            if i == j {
                                format!("{scale}")
                            } else {
                                "0.0".into()
                            }
                        })
                        .collect();
                    format!("[{}]", row.join(", "))
                })
                .collect();
            format!("[{}]", rows.join(", "))
        };
        let text = format!(
            r#"
[[channels]]
name = "big"
model = {{ F = {f}, H = {h}, E = {h}, Q = 0.01, R = 0.01 }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 0 }}]
glr = {{ detector = "parity", window = 10 }}
parity = {{ order = 64 }}
"#,
            f = eye(0.5),
            h = eye(1.0)
        );
        let err = crate::parse(&text).unwrap_err().to_string();
        assert!(
            err.contains("parity.order") && err.contains("more than a channel's"),
            "{err}"
        );
    }

    /// The CUSUM kind: magnitudes one per fault, step faults only (a ramp refused by
    /// name), and a threshold from `false_alarm` by Siegmund's approximation, larger for
    /// a smaller α.
    #[test]
    fn cusum_settings_are_validated() {
        let text = |fault_kind: &str, cusum: &str, glr: &str| {
            format!(
                r#"
[[channels]]
name = "motor"
model = {{ F = [[0.2231, 0.0109], [-0.0022, 0.5488]], G = [[0.0047], [0.4512]], H = [[1.0, 0.0], [0.0, 1.0]], Q = 0.0001, R = 0.0025 }}
faults = [{{ name = "speed", kind = "{fault_kind}", output = 0 }}]
glr = {{ detector = "cusum"{glr} }}
{cusum}
"#
            )
        };
        let cfg = crate::parse(&text("sensor_bias", "cusum = { magnitudes = [0.1] }", "")).unwrap();
        let c = &cfg.channels[0];
        assert!(matches!(
            c.threshold_source,
            crate::ThresholdSource::Siegmund { false_alarm } if false_alarm == 1e-4
        ));
        let h4 = c.alarm.threshold;
        let cfg = crate::parse(&text(
            "sensor_bias",
            "cusum = { magnitudes = [0.1] }",
            ", false_alarm = 1e-6",
        ))
        .unwrap();
        assert!(cfg.channels[0].alarm.threshold > h4);
        assert_eq!(cfg.channels[0].detector().unwrap().kind(), "cusum");
        let err = crate::parse(&text(
            "sensor_bias",
            "cusum = { magnitudes = [0.1, 2.0] }",
            "",
        ))
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("cusum.magnitudes") && err.contains("2 values for 1 faults"),
            "{err}"
        );
        let err = crate::parse(&text("sensor_drift", "cusum = { magnitudes = [0.1] }", ""))
            .unwrap_err()
            .to_string();
        assert!(err.contains("cusum") && err.contains("ramp"), "{err}");
        let err = crate::parse(&text("sensor_bias", "", ""))
            .unwrap_err()
            .to_string();
        assert!(err.contains("needs `[channels.cusum] magnitudes`"), "{err}");
    }

    /// The parity kind's order is checked against the model (naming the smallest order
    /// with a parity space), its χ² law has the parity space's dimension, and its
    /// windowed energy, which has no χ² law, needs a given threshold.
    #[test]
    fn parity_settings_are_validated_against_the_model() {
        let text = |parity: &str, glr: &str| {
            format!(
                r#"
[[channels]]
name = "plant"
model = {{ F = [[0.5, 1.0], [0.0, 1.2]], G = [[0.0], [1.0]], H = [[1.0, 0.0]], Q = 0.0025, R = 0.0025 }}
faults = [{{ name = "bias", kind = "sensor_bias", output = 0 }}]
glr = {{ detector = "parity"{glr} }}
{parity}
"#
            )
        };
        let cfg = crate::parse(&text("", "")).unwrap();
        let c = &cfg.channels[0];
        assert_eq!(c.parity.unwrap().order, 2);
        assert_eq!(c.statistic_dof, 1);
        let cfg = crate::parse(&text("parity = { order = 4 }", "")).unwrap();
        assert_eq!(cfg.channels[0].statistic_dof, 3);
        let expected = glrmon_core::threshold::chi2_upper_quantile(3.0, 1e-4).unwrap();
        assert!((cfg.channels[0].alarm.threshold - expected).abs() < 1e-12);
        let err = crate::parse(&text("parity = { order = 64 }", ""));
        assert!(err.is_ok(), "64 × 1 output is small: {err:?}");
        let err = crate::parse(&text("parity = { order = 1 }", ""))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("parity.order") && err.contains("smallest order that gives one is 2"),
            "{err}"
        );
        let err = crate::parse(&text("parity = { evaluation = \"energy\" }", ""))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("glr.threshold") && err.contains("no χ² law"),
            "{err}"
        );
        let cfg = crate::parse(&text(
            "parity = { evaluation = \"energy\", energy_window = 20 }",
            ", threshold = 0.5",
        ))
        .unwrap();
        assert_eq!(cfg.channels[0].detector().unwrap().memory(), 22);
    }

    #[test]
    fn the_factory_builds_the_configured_kind() {
        for (kind, memory) in [("glr", 30), ("chi2", 1), ("parity", 2), ("fdf", 1)] {
            let cfg = crate::parse(&format!(
                r#"
[[channels]]
name = "tank"
model = {{ F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }}
faults = [{{ name = "level_bias", kind = "sensor_bias", output = 0 }}]
glr = {{ window = 30, detector = "{kind}" }}
"#
            ))
            .unwrap();
            let det = cfg.channels[0].detector().unwrap();
            assert_eq!((det.kind(), det.memory()), (kind, memory));
            assert_eq!(det.faults().len(), 1);
        }
    }
}

#[cfg(test)]
mod kernel_tests {
    use crate::ThresholdSource;

    const EXAMPLE: &str = include_str!("../../../config/examples/kernel-paper.toml");

    /// The paper's example with `from` replaced by `to` (which must occur).
    fn edited(from: &str, to: &str) -> String {
        assert!(EXAMPLE.contains(from), "{from}");
        EXAMPLE.replacen(from, to, 1)
    }

    fn refused(text: &str) -> String {
        crate::parse(text).unwrap_err().to_string()
    }

    /// config/examples/kernel-paper.toml: the kernel kind with threshold 1 (a bound,
    /// not a χ² quantile), no Kalman filter, the candidates as the faults, and a
    /// detector whose faults are phi1 and phi2.
    #[test]
    fn the_paper_example_builds_the_kernel_detector() {
        let cfg = crate::parse(EXAMPLE).unwrap();
        let c = &cfg.channels[0];
        assert_eq!(c.detector_kind, crate::DetectorKind::Kernel);
        assert_eq!(c.alarm.threshold, 1.0);
        assert_eq!(c.threshold_source, ThresholdSource::Bounded);
        assert_eq!(c.statistic_dof, 1);
        assert!(c.consistency.is_none());
        assert_eq!(c.fault_names, ["phi1", "phi2"]);
        let k = c.kernel.as_ref().unwrap();
        assert_eq!((k.model.e.nrows(), k.model.e.ncols()), (5, 3));
        assert_eq!((k.model.c.nrows(), k.model.b.ncols()), (4, 1));
        assert_eq!(k.model.a[(2, 1)], -6.2354);
        let mut paper = glrmon_core::KernelSettings::paper_example(0.001);
        paper.output_noise = 1.0;
        assert!((k.settings.state_noise - 0.2 * 5.0_f64.sqrt()).abs() < 1e-15);
        paper.state_noise = k.settings.state_noise;
        assert_eq!(k.settings, paper);
        let det = c.detector().unwrap();
        assert_eq!(det.kind(), "kernel");
        let names: Vec<&str> = det
            .faults()
            .faults()
            .iter()
            .map(|f| f.name.as_str())
            .collect();
        assert_eq!(names, ["phi1", "phi2"]);
        let built = c.kernel_detector().unwrap();
        assert_eq!(built.candidates()[1].lipschitz, 402.25_f64.sqrt());
    }

    /// Left out, the kernel settings take the paper's values for n⋆ = 2 (rates 1, 2,
    /// ω̄ = 2.5, N = n⋆, ω = 1, θ_a = 0.7 × |det Γ(∞)| = 0.7, rearm 5 s); without
    /// candidates the detector still runs, with one fault `f`.
    #[test]
    fn kernel_defaults_are_the_papers() {
        let mut text = EXAMPLE.to_owned();
        for line in [
            "rates = [1.0, 2.0]\n",
            "omega_bar = 2.5\n",
            "order = 2\n",
            "detection_rate = 1.0\n",
            "activation = 0.7\n",
            "rearm = 5.0\n",
        ] {
            assert!(text.contains(line), "{line}");
            text = text.replacen(line, "", 1);
        }
        let cfg = crate::parse(&text).unwrap();
        let s = &cfg.channels[0].kernel.as_ref().unwrap().settings;
        assert_eq!(s.estimator_rates, [1.0, 2.0]);
        assert_eq!(
            (s.omega_bar, s.kernel_order, s.detection_rate),
            (2.5, 2, 1.0)
        );
        assert!((s.activation - 0.7).abs() < 1e-12, "{}", s.activation);
        assert_eq!(s.rearm, 5.0);
        let cut = text.find("[[channels.kernel.candidates]]").unwrap();
        let end = text.find("[channels.simulation]").unwrap();
        let bare = format!("{}{}", &text[..cut], &text[end..]);
        let cfg = crate::parse(&bare).unwrap();
        assert_eq!(cfg.channels[0].fault_names, ["f"]);
        let det = cfg.channels[0].detector().unwrap();
        assert_eq!(det.faults().len(), 1);
    }

    /// The example's detector, noise-free (bounds 0, `floor` = 1e-3), on the paper's
    /// noise-free run (φ₂ from t = 5 s, glrmon-sim's RK4 plant): no alarm before
    /// 5 s, a detection within 50 ms of it, and φ₂ isolated by the candidates'
    /// expressions.
    #[test]
    fn the_configured_detector_detects_and_isolates_the_papers_fault() {
        use glrmon_core::{Detector, Sample, StepOutput};
        use glrmon_sim::kernel_example::{self as example, ExampleRun};
        let text = edited(
            "output_noise = 1.0\nstate_noise = 0.4472135954999579\n",
            "floor = 1e-3\n",
        );
        let cfg = crate::parse(&text).unwrap();
        let mut det = cfg.channels[0].kernel_detector().unwrap();
        let mut out = StepOutput::for_detector(&det);
        let data = example::simulate(&ExampleRun {
            samples: 8001,
            ..ExampleRun::paper(0)
        });
        let (mut first_alarm, mut isolated) = (None, None);
        for (k, u) in data.u.iter().enumerate() {
            let sample = Sample {
                k: k as u64,
                u: std::slice::from_ref(u),
                y: &data.y[4 * k..4 * k + 4],
                p: &[],
            };
            det.step(&sample, &mut out).unwrap();
            if first_alarm.is_none() && out.glr.is_some_and(|s| s > 1.0) {
                first_alarm = Some(k);
            }
            if isolated.is_none() {
                isolated = det.verdict().isolated().map(|i| (k, i));
            }
        }
        let t_d = first_alarm.expect("detected") as f64 * 1e-3;
        assert!((5.0..5.05).contains(&t_d), "T_d = {t_d}");
        let (k_i, which) = isolated.expect("isolated");
        assert_eq!(det.candidates()[which].name, "phi2", "at k = {k_i}");
    }

    /// `glrmon evaluate --detector kernel` on a kernel channel: the edit gives the
    /// kind no `false_alarm` (its threshold is the bound 1) and keeps its table.
    #[test]
    fn setting_the_kernel_kind_keeps_its_bound() {
        let text = crate::edit::set_detector(
            EXAMPLE,
            "plane",
            crate::DetectorKind::Kernel,
            Some(1e-3),
            None,
        )
        .unwrap();
        assert!(!text.contains("false_alarm") && text.contains("[channels.kernel]"));
        let cfg = crate::parse(&text).unwrap();
        assert_eq!(cfg.channels[0].threshold_source, ThresholdSource::Bounded);
    }

    /// Each mistake is refused with the path of its field.
    #[test]
    fn kernel_mistakes_name_their_field() {
        let cases = [
            (
                edited("\"cos(x3)\", \"cos(0.5*x4)\"]", "\"cos(x3)\"]"),
                vec![
                    "kernel.candidates[0].f",
                    "has 2 expressions, expected p⋆ = 3",
                ],
            ),
            (
                edited("\"cos(0.5*x4)\"", "\"cos(0.5*x5)\""),
                vec![
                    "kernel.candidates[0].f[2]",
                    "candidate \"phi1\"",
                    "\"x5\"",
                    "5 states: x0..x4",
                ],
            ),
            (
                edited("\"x1 + x2\", \"cos", "\"x1[-1] + x2\", \"cos"),
                vec!["kernel.candidates[0].f[0]", "lags not allowed"],
            ),
            (
                edited("\"sin(0.5*x4)\"", "\"sin(0.5*p0)\""),
                vec!["kernel.candidates[1].f[2]", "\"p0\""],
            ),
            (
                edited("inputs = [\"10*sin", "inputs = [\"t + 10*sin"),
                vec!["simulation.inputs[0]", "\"t\""],
            ),
            (
                edited("E = [\n  [-0.0395", "Ex = [\n  [-0.0395"),
                vec!["unknown field `Ex`"],
            ),
            (
                edited("  [0.0, -0.2081, 0.0],\n]", "]"),
                vec!["kernel.E", "has 4 rows, expected n = 5"],
            ),
            (
                edited("output_noise = 1.0\nstate_noise = 0.4472135954999579\n", ""),
                vec!["kernel.floor", "zero noise bounds"],
            ),
            (
                edited("output_noise = 1.0", "output_noise = -1.0"),
                vec!["kernel.output_noise", "non-negative"],
            ),
            (
                edited("activation = 0.7", "activation = 1.5"),
                vec!["kernel.activation", "not below the limit"],
            ),
            (
                edited("rates = [1.0, 2.0]", "rates = [1.0]"),
                vec!["kernel.rates", "n⋆ = 2"],
            ),
            (
                edited("name = \"phi2\"", "name = \"phi1\""),
                vec!["kernel.candidates[1].name", "duplicate"],
            ),
            (
                edited(
                    "detector = \"kernel\"",
                    "detector = \"kernel\"\nfalse_alarm = 1e-4",
                ),
                vec!["glr.false_alarm", "no probability law"],
            ),
            (
                edited(
                    "[channels.glr]",
                    "[[channels.faults]]\nname = \"b\"\nkind = \"sensor_bias\"\noutput = 0\n\n[channels.glr]",
                ),
                vec!["faults", "leave `[[channels.faults]]` out"],
            ),
        ];
        for (text, needles) in cases {
            let err = refused(&text);
            for needle in needles {
                assert!(err.contains(needle), "{needle}: {err}");
            }
        }
        let err = refused(&EXAMPLE.replacen("E = [\n  [-0.0395", "# E = [\n#  [-0.0395", 1)
            .replacen("  [0.0, 0.0031, 0.0],\n  [0.0, 1.8255, -0.5],\n  [-1.9042, -0.9494, -1.0],\n  [0.0, -0.2081, 0.0],\n]\noutput", "output", 1));
        assert!(
            err.contains("kernel.E") && err.contains("is required"),
            "{err}"
        );
    }

    /// The kernel kind needs the continuous-time model: a discrete-time one (`F`) is
    /// refused at `model.F`; `[channels.kernel]` is refused for another kind, and the
    /// kind without it.
    #[test]
    fn the_kernel_kind_needs_the_continuous_time_model_and_its_table() {
        let discrete = r#"
[[channels]]
name = "plane"
[channels.model]
F = [[0.9, 0.0], [0.1, 0.8]]
G = [[1.0], [0.0]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.01
R = 0.01
[channels.glr]
detector = "kernel"
[channels.kernel]
E = [[1.0], [0.0]]
output_noise = 0.1
"#;
        let err = refused(discrete);
        assert!(
            err.contains("model.F") && err.contains("continuous-time model"),
            "{err}"
        );
        // With another kind the table describes the plant: its dictionary is given by
        // `[[channels.faults]]`, else by the columns of E sampled by zero-order hold.
        let cfg = crate::parse(&edited(
            "[channels.glr]\ndetector = \"kernel\"",
            "[[channels.faults]]\nname = \"b\"\nkind = \"sensor_bias\"\noutput = 0\n\n\
             [channels.glr]\ndetector = \"glr\"",
        ))
        .unwrap();
        assert_eq!(cfg.channels[0].fault_names, ["b"]);
        assert!(cfg.channels[0].kernel.is_some());
        let cfg = crate::parse(&edited(
            "[channels.glr]\ndetector = \"kernel\"",
            "[channels.glr]\ndetector = \"glr\"",
        ))
        .unwrap();
        let ch = &cfg.channels[0];
        assert_eq!(ch.fault_names, ["E0", "E1", "E2"]);
        let kernel = ch.kernel.as_ref().unwrap();
        let (_, psi) = glrmon_core::model::continuous::zero_order_hold(
            &kernel.model.a,
            &kernel.model.e,
            kernel.settings.period,
        )
        .unwrap();
        let dictionary = ch.dictionary().unwrap();
        for (j, fault) in dictionary.faults().iter().enumerate() {
            let glrmon_core::Column::Constant(c) = &fault.state else {
                panic!("{fault:?}")
            };
            assert!((c - psi.column(j)).amax() < 1e-15);
        }
        assert_eq!(ch.detector().unwrap().kind(), "glr");
        let cut = EXAMPLE.find("\n[channels.kernel]\n").unwrap();
        let end = EXAMPLE.find("\n[channels.simulation]\n").unwrap();
        let err = refused(&format!("{}{}", &EXAMPLE[..cut], &EXAMPLE[end..]));
        assert!(err.contains("needs `[channels.kernel]`"), "{err}");
    }
}
