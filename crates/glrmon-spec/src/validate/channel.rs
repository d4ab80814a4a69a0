//! A channel's validation: [`Validator::channel`] runs the steps in order, which is
//! the order their problems are reported in, and assembles the [`Channel`].

use glrmon_core::filter::consistency::{Consistency, ConsistencySettings};
use glrmon_core::{AlarmSettings, Dims, Lpv, LpvMatrix, WindowSettings};
use nalgebra::DMatrix;

use super::model::Matrices;
use super::{Validator, join};
use crate::names::validate_name;
use crate::schema::{self, ChannelSpec, ConsistencySpec, GlrSpec};
use crate::{Channel, DetectorKind, ThresholdSource, limits};
use glrmon_core::detector::Evaluation;
use glrmon_core::threshold::chi2_upper_quantile;

impl Validator {
    /// A channel, or `None` when it has an error. The model comes first: the shapes
    /// every later step checks derive from it. The steps up to the fault dictionary
    /// report together; the memory budget and the model as a whole need them error-free.
    pub(super) fn channel(&mut self, prefix: &str, spec: &ChannelSpec) -> Option<Channel> {
        let before = self.errors.len();
        if let Err(e) = validate_name(&spec.name) {
            self.error(join(prefix, "name"), e);
        }
        self.glr_ranges(prefix, &spec.glr);
        let m = self.model(prefix, &spec.model, spec.period)?;
        let kind = (spec.glr.detector.as_deref())
            .and_then(DetectorKind::from_name)
            .unwrap_or_default();
        let diagnosis = self.diagnosis(
            prefix,
            spec,
            &m.h,
            m.e.as_ref().map(LpvMatrix::base),
            kind.runs_kalman_filter(),
        );
        let dims = self.dims(prefix, spec.signals, &m)?;
        let scaling = spec
            .scaling
            .as_ref()
            .and_then(|sc| self.scaling(prefix, sc, dims));
        let columns = self.columns(prefix, spec.columns.as_ref(), dims);
        // With another kind, `[channels.kernel]` describes the same plant: its fault
        // channels give the dictionary when `[[channels.faults]]` is left out, and its
        // candidates are what the simulator injects (the kinds side by side).
        let kernel = if kind == DetectorKind::Kernel || spec.kernel.is_some() {
            self.kernel(prefix, spec, &m)
        } else {
            None
        };
        let (faults, fault_paths) = if kind == DetectorKind::Kernel {
            self.kernel_faults(prefix, spec)
        } else if let (true, Some(k)) = (spec.faults.is_empty(), &kernel) {
            self.fault_channels(prefix, k)
        } else {
            self.faults(prefix, spec, dims, (&m.g, &m.j), scaling.as_ref(), &columns)
        };
        if self.errors.len() > before {
            return None;
        }
        let (window, history) = (spec.glr.window, diagnosis.history);
        if !self.memory_budget(prefix, dims, faults.len(), window, history) {
            return None;
        }
        let Matrices {
            f,
            g,
            h,
            j,
            q,
            r,
            e,
            fd,
            cross,
            p0,
            x0,
            discretised,
        } = m;
        let lpv = match Lpv::new(f, g, h, j, q, r, dims.signals) {
            Ok(model) => model,
            Err(err) => {
                self.error(join(prefix, "model"), err.to_string());
                return None;
            }
        };
        self.observability(prefix, &lpv);
        let glr = &spec.glr;
        let innovation_dof = dims.outputs - e.as_ref().map_or(0, |e| e.shape().1).min(dims.outputs);
        let (mut parity, mut observer, mut rls, mut residual_dof) =
            (None, None, None, innovation_dof);
        match kind {
            DetectorKind::Parity => {
                let (settings, dof) =
                    self.parity(prefix, spec.parity.as_ref(), &lpv, e.as_ref(), fd.as_ref())?;
                (parity, residual_dof) = (Some(settings), dof);
            }
            DetectorKind::Fdf | DetectorKind::Uio => {
                let (settings, dof) = self.observer(
                    prefix,
                    kind,
                    spec.observer.as_ref(),
                    (&lpv, e.as_ref(), cross.as_ref()),
                )?;
                (observer, residual_dof) = (Some(settings), dof);
            }
            DetectorKind::Rls => {
                let (settings, dof) = self.rls(prefix, spec.rls.as_ref(), &lpv, cross.as_ref())?;
                (rls, residual_dof) = (Some(settings), dof);
            }
            DetectorKind::Kernel => residual_dof = 1,
            DetectorKind::Glr | DetectorKind::Chi2 | DetectorKind::Cusum => {}
        }
        for (table, given, kinds) in [
            ("parity", spec.parity.is_some(), "\"parity\""),
            ("observer", spec.observer.is_some(), "\"fdf\" or \"uio\""),
            ("rls", spec.rls.is_some(), "\"rls\""),
        ] {
            let applies = match table {
                "parity" => kind == DetectorKind::Parity,
                "rls" => kind == DetectorKind::Rls,
                _ => matches!(kind, DetectorKind::Fdf | DetectorKind::Uio),
            };
            if given && !applies {
                self.error(
                    join(prefix, table),
                    format!("applies to `glr.detector = {kinds}`"),
                );
            }
        }
        if fd.is_some()
            && matches!(
                kind,
                DetectorKind::Glr | DetectorKind::Chi2 | DetectorKind::Uio
            )
        {
            self.error(
                join(prefix, "model.Fd"),
                format!(
                    "the `{}` detector decouples unknown inputs of the state only (F_d = 0); \
                     the `parity` detector decouples F_d too",
                    kind.name()
                ),
            );
        }
        let detection = self.glr(prefix, glr, &faults, residual_dof);
        let energy = parity.is_some_and(|p| matches!(p.evaluation, Evaluation::Energy { .. }))
            || observer
                .as_ref()
                .is_some_and(|o| matches!(o.evaluation, Evaluation::Energy { .. }))
            || rls.is_some_and(|r| matches!(r.evaluation, Evaluation::Energy { .. }));
        if energy
            && !matches!(
                detection.threshold_source,
                ThresholdSource::Explicit | ThresholdSource::Calibrated { .. }
            )
        {
            self.error(
                join(prefix, "glr.threshold"),
                "a residual's windowed energy (`evaluation = \"energy\"`) has no χ² law \
                 for `false_alarm` to set its threshold: give `threshold` \
                 (e.g. the bound J_th = δ_d on the disturbance's energy, or any positive \
                 value that `glrmon calibrate --write` then replaces)"
                    .into(),
            );
        }
        if !kind.runs_kalman_filter() && diagnosis.enabled {
            self.error(
                join(prefix, "diagnosis.enabled"),
                format!(
                    "sparse diagnosis runs on the Kalman filter, which the `{}` detector \
                     does not run",
                    kind.name()
                ),
            );
        }
        let simulation = self.simulation(prefix, spec, dims, e.as_ref().map(LpvMatrix::base));
        let consistency = if kind.runs_kalman_filter() {
            self.consistency(prefix, spec.consistency, innovation_dof)
        } else {
            None
        };
        let warm_up = self.warm_up(prefix, glr);
        let payload = self.payload(prefix, spec, &columns);
        let tags = spec.tags.as_ref().and_then(|t| {
            if spec.key.is_some() {
                self.error(
                    join(prefix, "key"),
                    "is not read: the channel's signals arrive on `[channels.tags] keys`".into(),
                );
            }
            if spec.payload.as_deref().is_some_and(|p| p != "json") {
                self.error(
                    join(prefix, "payload"),
                    "is not read: the tags of `[channels.tags]` are JSON numbers or objects".into(),
                );
            }
            self.tags(prefix, "tags", t, &columns)
        });
        let topics = spec
            .topics
            .as_ref()
            .and_then(|t| self.tags(prefix, "topics", t, &columns));
        if self.errors.len() > before {
            return None;
        }
        let n = dims.states;
        let cusum_magnitudes = match (kind, &spec.cusum) {
            (DetectorKind::Cusum, None) => {
                self.error(
                    join(prefix, "cusum"),
                    "`glr.detector = \"cusum\"` needs `[channels.cusum] magnitudes`, the \
                     magnitude each fault's CUSUM is tuned for"
                        .into(),
                );
                return None;
            }
            (DetectorKind::Cusum, Some(c)) => {
                if c.magnitudes.len() != faults.len() {
                    self.error(
                        join(prefix, "cusum.magnitudes"),
                        format!(
                            "has {} values for {} faults: one per fault, in dictionary order",
                            c.magnitudes.len(),
                            faults.len()
                        ),
                    );
                    return None;
                }
                Some(c.magnitudes.clone())
            }
            (_, Some(_)) => {
                self.error(
                    join(prefix, "cusum"),
                    "applies to `glr.detector = \"cusum\"`".into(),
                );
                return None;
            }
            (_, None) => None,
        };
        let mut channel = Channel {
            name: spec.name.clone(),
            payload,
            tags,
            topics,
            key: spec
                .key
                .clone()
                .unwrap_or_else(|| format!("plant/{}", spec.name)),
            period: spec.period,
            dims,
            model: lpv,
            discretised,
            unknown_input: e,
            unknown_input_outputs: fd,
            cross_covariance: cross,
            scaling,
            columns,
            x0,
            p0: p0
                .map(|m| m.base().clone())
                .unwrap_or_else(|| DMatrix::identity(n, n)),
            window: WindowSettings {
                window: glr.window,
                min_lag: glr.min_lag,
                rank_tolerance: detection.rank_tolerance,
                warm_up,
                ..WindowSettings::default()
            },
            alarm: AlarmSettings {
                threshold: detection.threshold,
                hysteresis: glr.hysteresis,
                clear_samples: glr.clear_samples.max(1),
            },
            threshold_source: detection.threshold_source,
            episode_end: detection.episode_end,
            // The kernel kind publishes an update at each exclusion: no fixed delay.
            isolation_delay: glr
                .isolation_delay
                .unwrap_or(if kind == DetectorKind::Kernel {
                    0
                } else {
                    n as u32
                }),
            isolation_alpha: glr.isolation_alpha,
            isolation_onsets: detection.isolation_onsets,
            detector_kind: detection.detector_kind,
            statistic_dof: detection
                .detector_kind
                .statistic_dof(faults.len(), residual_dof),
            parity,
            observer,
            rls,
            cusum_magnitudes,
            kernel,
            isolation_thresholds: glr
                .calibrated
                .as_ref()
                .map(|c| c.isolation.iter().map(|(k, v)| (k.clone(), *v)).collect())
                .unwrap_or_default(),
            groups: detection.groups,
            max_gap: glr.max_gap,
            max_reorder: glr.max_reorder,
            settle: glr.settle,
            fault_names: faults.iter().map(|f| f.name.clone()).collect(),
            fault_paths,
            simulation,
            diagnosis,
            consistency,
            faults,
        };
        if kind == DetectorKind::Cusum {
            self.cusum_threshold(prefix, &mut channel);
        } else if !kind.runs_kalman_filter() {
            self.residual_generator(prefix, &mut channel);
        }
        (self.errors.len() == before).then_some(channel)
    }

    /// The residual generator built on the channel, so that a design the checks before
    /// could not judge (an LPV model, the optimal parity vector's faults) is refused
    /// here rather than when the daemon starts; for `parity`, the χ² threshold set
    /// again if the detector's parity space differs from the one validated.
    fn residual_generator(&mut self, prefix: &str, channel: &mut Channel) {
        if channel.detector_kind == DetectorKind::Kernel {
            if let Err(err) = channel.kernel_detector() {
                self.kernel_error(prefix, &err);
            }
            return;
        }
        let built = if channel.detector_kind == DetectorKind::Parity {
            channel.parity_detector().map(|det| {
                let dof = det.dof();
                if dof != channel.statistic_dof {
                    channel.statistic_dof = dof;
                    if let ThresholdSource::Chi2 { false_alarm } = channel.threshold_source
                        && let Ok(t) = chi2_upper_quantile(dof as f64, false_alarm)
                    {
                        channel.alarm.threshold = t;
                    }
                }
            })
        } else {
            channel.detector().map(|_| ())
        };
        if let Err(err) = built {
            self.error(
                join(prefix, "glr.detector"),
                format!(
                    "the `{}` detector cannot be built on this model: {err}",
                    channel.detector_kind.name()
                ),
            );
        }
    }

    /// The CUSUM built on the channel (its design errors named at `cusum`), and its
    /// threshold from `false_alarm` by Siegmund's approximation, replacing the χ²
    /// quantile the GLR's settings gave (an explicit or calibrated one is kept).
    fn cusum_threshold(&mut self, prefix: &str, channel: &mut Channel) {
        let detector = match channel.glr_detector().and_then(|glr| {
            glrmon_core::CusumDetector::new(
                glr,
                channel.cusum_magnitudes.clone().unwrap_or_default(),
            )
        }) {
            Ok(d) => d,
            Err(err) => {
                self.error(join(prefix, "cusum"), err.to_string());
                return;
            }
        };
        let false_alarm = match channel.threshold_source {
            ThresholdSource::Chi2 { false_alarm }
            | ThresholdSource::Bonferroni { false_alarm }
            | ThresholdSource::KnownOnset { false_alarm } => false_alarm,
            _ => return,
        };
        match glrmon_core::detector::siegmund_threshold(detector.information(), false_alarm) {
            Some(h) => {
                channel.alarm.threshold = h;
                channel.threshold_source = ThresholdSource::Siegmund { false_alarm };
            }
            None => self.error(
                join(prefix, "glr.false_alarm"),
                format!("{false_alarm} gives no CUSUM threshold"),
            ),
        }
    }

    /// The memory the channel needs (GLR window bank, diagnosis history) within
    /// [`limits::CHANNEL_MEMORY_BUDGET`]; over it, the larger of the two is blamed.
    fn memory_budget(
        &mut self,
        prefix: &str,
        dims: Dims,
        faults: usize,
        window: usize,
        history: usize,
    ) -> bool {
        let footprint = limits::ChannelFootprint {
            states: dims.states,
            outputs: dims.outputs,
            inputs: dims.inputs,
            faults,
            window,
            history,
        };
        let bytes = footprint.bytes();
        if bytes > limits::CHANNEL_MEMORY_BUDGET {
            let (field, what) = if footprint.history_bytes() > footprint.window_bytes() {
                ("diagnosis.history", "lower diagnosis.history")
            } else {
                ("glr.window", "lower glr.window (or use fewer faults)")
            };
            self.error(
                join(prefix, field),
                format!(
                    "makes the channel need about {} ({}), more than the budget of {} per \
                     channel: {what}",
                    limits::human_bytes(bytes),
                    footprint.breakdown(),
                    limits::human_bytes(limits::CHANNEL_MEMORY_BUDGET),
                ),
            );
            return false;
        }
        true
    }

    /// The filter-consistency test (`[channels.consistency]`), when enabled;
    /// `innovation_dof` is the dimension of the innovation it tests.
    fn consistency(
        &mut self,
        prefix: &str,
        c: ConsistencySpec,
        innovation_dof: usize,
    ) -> Option<ConsistencySettings> {
        if c.window > limits::MAX_CONSISTENCY_WINDOW {
            self.error(
                join(prefix, "consistency.window"),
                format!(
                    "{} samples is more than {} (limits::MAX_CONSISTENCY_WINDOW)",
                    c.window,
                    limits::MAX_CONSISTENCY_WINDOW
                ),
            );
        }
        if c.enabled {
            let settings = ConsistencySettings {
                window: c.window,
                alpha: c.alpha,
            };
            match Consistency::new(innovation_dof.max(1), settings) {
                Ok(_) => Some(settings),
                Err(e) => {
                    let field = if c.window == 0 { "window" } else { "alpha" };
                    self.error(join(prefix, &format!("consistency.{field}")), e.to_string());
                    None
                }
            }
        } else {
            None
        }
    }

    /// `glr.warm_up`: a number of samples, or `"window"` for w.
    fn warm_up(&mut self, prefix: &str, glr: &GlrSpec) -> u64 {
        match &glr.warm_up {
            None => 0,
            Some(schema::WarmUpSpec::Samples(n)) => *n,
            Some(schema::WarmUpSpec::Keyword(w)) if w == "window" => glr.window as u64,
            Some(schema::WarmUpSpec::Keyword(other)) => {
                self.error(
                    join(prefix, "glr.warm_up"),
                    format!("\"{other}\" is not \"window\" or a number of samples"),
                );
                0
            }
        }
    }
}
