//! `glrmon validate`'s report of a channel: its settings in words and the isolability
//! of its fault dictionary, computed on the channel's own simulated samples.

use std::fmt::Write as _;

use glrmon_core::Onset;
use glrmon_core::StepError;
use glrmon_core::isolation::information::{InformationError, warmup_samples, window_information};
use glrmon_core::isolation::isolability::{DEFAULT_CORRELATION_LIMIT, isolability};
use glrmon_core::threshold::calibration::Target;
use glrmon_spec::{Channel, DetectorKind, Formation, ThresholdSource};
use nalgebra::DMatrix;

/// Widest matrix printed on one line.
const INLINE_COLUMNS: usize = 6;
/// Widest matrix printed in full, one aligned row per line; a wider one is summarised.
const FULL_COLUMNS: usize = 12;

/// A matrix for the report, after `label = `: up to [`INLINE_COLUMNS`] columns on the
/// same line (`[[a, b], [c, d]]`); up to [`FULL_COLUMNS`], one aligned row per line
/// under the label, indented by `indent`; wider, a summary (shape, diagonal, extreme
/// entries, condition number), never one line of hundreds of numbers.
fn fmt_matrix(m: &DMatrix<f64>, indent: &str) -> String {
    if m.ncols() <= INLINE_COLUMNS {
        let rows: Vec<String> = m
            .row_iter()
            .map(|r| {
                let v: Vec<String> = r.iter().map(|x| format!("{x:.6e}")).collect();
                format!("[{}]", v.join(", "))
            })
            .collect();
        return format!("[{}]", rows.join(", "));
    }
    let cell = |x: f64| format!("{x:.3e}");
    let width = m
        .iter()
        .map(|x| cell(*x).chars().count())
        .max()
        .unwrap_or(0);
    let mut out = format!("{}×{}", m.nrows(), m.ncols());
    if m.ncols() <= FULL_COLUMNS {
        for r in m.row_iter() {
            let v: Vec<String> = r.iter().map(|x| format!("{:>width$}", cell(*x))).collect();
            let _ = write!(out, "\n{indent}  {}", v.join(" "));
        }
        return out;
    }
    let diagonal: Vec<f64> = m.diagonal().iter().copied().collect();
    let _ = write!(out, ", summarised (more than {FULL_COLUMNS} columns):");
    let _ = write!(out, "\n{indent}  diagonal:");
    for chunk in diagonal.chunks(INLINE_COLUMNS) {
        let v: Vec<String> = chunk
            .iter()
            .map(|x| format!("{:>width$}", cell(*x)))
            .collect();
        let _ = write!(out, "\n{indent}    {}", v.join(" "));
    }
    let (min, max) = m
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(*x), hi.max(*x))
        });
    let off_diagonal = (0..m.nrows())
        .flat_map(|i| (0..m.ncols()).filter(move |&j| j != i).map(move |j| (i, j)))
        .map(|(i, j)| m[(i, j)].abs())
        .fold(0.0_f64, f64::max);
    let _ = write!(
        out,
        "\n{indent}  entries in [{}, {}], largest off-diagonal |entry| {}",
        cell(min),
        cell(max),
        cell(off_diagonal)
    );
    if m.is_square() && m.iter().all(|x| x.is_finite()) {
        let sv = m.clone().singular_values();
        let (lo, hi) = sv.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), x| {
            (lo.min(*x), hi.max(*x))
        });
        let condition = if lo > 0.0 { hi / lo } else { f64::INFINITY };
        let _ = write!(out, "\n{indent}  condition number {condition:.3e}");
    }
    out
}

/// Most arithmetic operations the isolability report may take (about 2 s on one core
/// of a 2020s machine in a release build): beyond it, the report is skipped and only
/// the filter is checked (see [`report_work`]).
const REPORT_WORK_BUDGET: f64 = 2e9;

/// The operations [`window_information`] takes on `channel`: (warm-up + w) measured
/// steps, each updating up to w onsets at about n²m + pnm + pm² + m³/3 operations, plus
/// the filter's n³ + n²p per step.
fn report_work(channel: &Channel) -> f64 {
    let known = channel.onsets().iter().all(|o| *o == Onset::Known);
    let w = channel.window.window as f64;
    let steps = warmup_samples(channel.window.window, known) as f64 + w;
    let slots = if known { 1.0 } else { w };
    let d = channel.dims;
    let (n, p, m) = (
        d.states as f64,
        d.outputs as f64,
        (channel.fault_names.len() as f64).max(1.0),
    );
    let per_slot = n * n * m + p * n * m + p * m * m + m * m * m / 3.0 + 1.0;
    steps * (slots * per_slot + n * n * n + n * n * p)
}

/// Why the filter run of `glrmon validate` failed, as a configuration error naming the
/// field (a configuration that validates must run).
fn filter_error(channel: &Channel, e: &InformationError, k: u64) -> ReportError {
    let text = match e {
        InformationError::Step(StepError::Numerical { what }) => {
            let f = channel.model.matrices()[0].base().clone();
            let radius = f
                .complex_eigenvalues()
                .iter()
                .map(|z| z.norm())
                .fold(0.0_f64, f64::max);
            if radius >= 1.0 {
                format!(
                    "model.F: unstable (spectral radius {radius:.4} ≥ 1) and the Kalman filter \
                     diverges on it: {what} at k = {k} (a mode of F on or outside the unit \
                     circle that H does not observe makes P_k grow without bound: measure it, \
                     or stabilise the model)"
                )
            } else {
                format!(
                    "model: the Kalman filter fails: {what} at k = {k} (check Q, R, P0 and \
                     the range of the scheduling signals in [channels.simulation])"
                )
            }
        }
        InformationError::Step(step) => {
            format!("simulation: the simulated sample k = {k} is refused: {step}")
        }
        other => format!("model: {other}"),
    };
    ReportError(text)
}

/// The Fisher information of the dictionary over one window, the steady-state Σ of an
/// LTI model whose Riccati recursion converged, and the samples it took.
struct ChannelInformation {
    information: DMatrix<f64>,
    steady: Option<DMatrix<f64>>,
    samples: usize,
}

/// The Fisher information C_k(r) of the dictionary over one window
/// ([`window_information`]), on the channel's simulated inputs and signals, with the
/// steady-state Σ when the model is LTI and the Riccati recursion has converged. With
/// `window = Some(w)`, the window setting is replaced by w (a short window that checks
/// the filter only).
fn channel_information(
    channel: &Channel,
    window: Option<usize>,
) -> Result<ChannelInformation, ReportError> {
    let mut short;
    let channel = match window {
        Some(w) => {
            short = channel.clone();
            short.window.window = w;
            short.window.min_lag = short.window.min_lag.min(w - 1);
            &short
        }
        None => channel,
    };
    let mut det = channel
        .glr_detector()
        .map_err(|e| ReportError(format!("model: {e}")))?;
    let mut sim = glrmon_sim::from_channel(channel, 1)
        .map_err(|e| ReportError(format!("simulation: {e}")))?;
    let count = std::cell::Cell::new(0_u64);
    let samples = std::iter::repeat_with(|| {
        let s = sim.next_sample();
        count.set(count.get() + 1);
        (s.u, s.y, s.p)
    });
    let info = window_information(&mut det, samples)
        .map_err(|e| filter_error(channel, &e, count.get().saturating_sub(1)))?;
    let steady = (channel.model_is_constant() && info.converged).then_some(info.covariance);
    Ok(ChannelInformation {
        information: info.information,
        steady,
        samples: info.samples,
    })
}

/// The faults whose own information (diagonal entry) is not finite, by their paths; or,
/// should every diagonal entry be finite, those with a non-finite entry in their row.
fn non_finite_faults(channel: &Channel, info: &DMatrix<f64>) -> Vec<String> {
    let mut bad: Vec<usize> = (0..info.nrows())
        .filter(|&j| !info[(j, j)].is_finite())
        .collect();
    if bad.is_empty() {
        bad = (0..info.nrows())
            .filter(|&j| info.row(j).iter().any(|x| !x.is_finite()))
            .collect();
    }
    bad.into_iter()
        .map(|j| {
            channel
                .fault_path(j)
                .map(|p| p.split_once(": ").map_or(p, |(_, f)| f).to_owned())
                .unwrap_or_else(|| format!("faults \"{}\"", channel.fault_names[j]))
        })
        .collect()
}

/// What `glrmon validate` reports of a valid channel: its text, and the verdicts that
/// are warnings too (faults the minmax test cannot tell apart).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelReport {
    /// The report, one indented line per item.
    pub text: String,
    /// The isolability verdicts, each naming the channel.
    pub warnings: Vec<String>,
}

/// A channel that parses but cannot run: the field at fault and why (a diverging
/// filter, a fault signature that is not finite, an impossible simulation).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ReportError(pub String);

/// The report of a validated channel: dimensions, model and window, threshold and
/// detector, faults, diagnosis and consistency settings, units, and the isolability
/// of its fault dictionary over one window of simulated samples (the Fisher
/// information, Basseville 1996 §5-6), which runs the filter and so also refuses a
/// model it diverges on.
///
/// # Errors
/// [`ReportError`] naming the field when the filter or the simulation fails on the
/// channel, or a fault's signature is not finite.
pub fn channel_report(channel: &Channel) -> Result<ChannelReport, ReportError> {
    let mut text = settings(channel);
    let mut warnings = Vec::new();
    isolability_section(channel, &mut text, &mut warnings)?;
    Ok(ChannelReport { text, warnings })
}

/// The channel's settings, one line each.
fn settings(channel: &Channel) -> String {
    let d = channel.dims;
    let mut s = String::new();
    let input = match (&channel.tags, &channel.topics) {
        (None, None) => format!("key {}, {}", channel.key, channel.payload.name()),
        (Some(tags), _) | (None, Some(tags)) => {
            let what = if channel.tags.is_some() {
                "tags"
            } else {
                "recording topics"
            };
            let formed = match tags.formation {
                Formation::Period(p) => format!("every {p} s"),
                Formation::Trigger(i) => format!("at each {}", tags.tags[i].signal),
            };
            let keys: Vec<String> = tags
                .tags
                .iter()
                .map(|t| {
                    let field = if t.field.is_empty() {
                        String::new()
                    } else {
                        format!(" .{}", t.field.join("."))
                    };
                    format!("{} ← {}{field}", t.signal, t.key)
                })
                .collect();
            format!("{what} {}, {formed}, held {} ", keys.join(", "), tags.hold)
                + if matches!(tags.formation, Formation::Period(_)) {
                    "periods"
                } else {
                    "triggers"
                }
        }
    };
    let _ = writeln!(
        s,
        "channel \"{}\" ({input}): n = {} states, l = {} inputs, p = {} outputs, q = {} signals, m = {} faults",
        channel.name,
        d.states,
        d.inputs,
        d.outputs,
        d.signals,
        channel.fault_names.len()
    );
    let model = if channel.model_is_constant() {
        "LTI"
    } else {
        "LPV (time-varying)"
    };
    let known = channel.onsets().iter().all(|o| *o == Onset::Known);
    let mut window = if known {
        "known profiles: GLR over all samples (no onset search)".to_owned()
    } else {
        format!(
            "window w = {}, s = {}",
            channel.window.window, channel.window.min_lag
        )
    };
    if channel.window.warm_up > 0 {
        let _ = write!(
            window,
            ", GLR held off for the first {} samples after a (re)start",
            channel.window.warm_up
        );
    }
    let threshold = threshold_text(channel);
    let _ = writeln!(s, "  model: {model}; {window}; threshold {threshold}");
    if let Some(d) = &channel.discretised {
        let _ = writeln!(s, "  continuous-time model {d}");
    }
    if let Some(advice) = threshold_advice(channel) {
        let _ = writeln!(s, "  threshold: {advice}");
    }
    match channel.detector_kind {
        DetectorKind::Glr => {}
        DetectorKind::Chi2 => {
            let _ = writeln!(
                s,
                "  detector: the plain χ²({}) test of εᵀΣ⁻¹ε on each sample (baseline; no onset estimate, no isolation)",
                channel.statistic_dof
            );
        }
        kind => {
            let described = channel
                .detector()
                .map_or_else(|e| format!("cannot be built: {e}"), |d| d.describe());
            let _ = writeln!(
                s,
                "  detector: {} — {described}{}",
                kind.name(),
                if kind.runs_kalman_filter() {
                    " (Page's onset; the GLR's magnitudes and isolation)"
                } else if kind == DetectorKind::Kernel {
                    " (isolation by exclusion among the candidate fault functions; no magnitude)"
                } else {
                    " (detection only: no magnitude, no isolation)"
                }
            );
        }
    }
    let faults: Vec<String> = channel
        .fault_names
        .iter()
        .zip(channel.onsets())
        .map(|(n, o)| format!("{n} ({})", format!("{o:?}").to_lowercase()))
        .collect();
    let _ = writeln!(s, "  faults: {}", faults.join(", "));
    if channel.detector_kind == DetectorKind::Glr {
        let _ = writeln!(s, "  isolation: {}", isolation_law_text(channel));
    }
    let _ = writeln!(s, "  episodes: {}", episode_end_text(channel));
    let diag = &channel.diagnosis;
    if diag.enabled {
        let span = diag.span.map_or_else(
            || "from r̂ to the alarm".to_owned(),
            |n| format!("at most {n} samples"),
        );
        let _ = writeln!(
            s,
            "  sparse diagnosis at alarms: {:?} residual, span {span}, history {} samples, no-fault test at α = {}, λ path of {} points down to {:e}·λ_max, widest plateau in {} λ",
            diag.residual,
            diag.history,
            diag.alpha,
            diag.lasso.path_points,
            diag.lasso.ratio,
            diag.lasso.plateau_scale.as_str()
        );
    } else {
        let _ = writeln!(s, "  sparse diagnosis at alarms: off");
    }
    match channel.consistency {
        Some(c) => {
            let band =
                glrmon_core::filter::consistency::Consistency::new(channel.innovation_dof(), c)
                    .map(|t| t.band())
                    .unwrap_or((f64::NAN, f64::NAN));
            let _ = writeln!(
                s,
                "  model consistency: blocks of {} samples, mean of εᵀΣ⁻¹ε expected {} within [{:.3}, {:.3}] (α = {:e})",
                c.window,
                channel.innovation_dof(),
                band.0,
                band.1,
                c.alpha
            );
        }
        None => {
            let _ = writeln!(s, "  model consistency: off");
        }
    }
    if let Some(e) = &channel.unknown_input
        && !channel.detector_kind.runs_kalman_filter()
    {
        let _ = writeln!(
            s,
            "  unknown input: E has {} column(s){}; what the `{}` detector does with it is on its `detector:` line",
            e.shape().1,
            if channel.unknown_input_outputs.is_some() {
                " and reaches the outputs through Fd"
            } else {
                ""
            },
            channel.detector_kind.name()
        );
    } else if let Some(e) = &channel.unknown_input {
        let _ = writeln!(
            s,
            "  unknown input: E has {} column(s), decoupled from the innovation: the GLR runs on {} of the {} output directions (Zhang 2021 §III-B); faults in range(E) are not detectable",
            e.shape().1,
            channel.innovation_dof(),
            channel.dims.outputs
        );
    }
    if channel.cross_covariance.is_some() {
        let _ = writeln!(
            s,
            "  correlated noises: S = E[w vᵀ] given, the predictor gain is (F P Hᵀ + S) Σ⁻¹ (an innovation model runs at its own order; sparse diagnosis's residual filters ignore S)"
        );
    }
    if let Some(scaling) = &channel.scaling {
        let list = |label: &dyn Fn(usize) -> String, offset: &[f64], scale: &[f64]| {
            offset
                .iter()
                .zip(scale)
                .enumerate()
                .map(|(i, (o, s))| format!("{}: operating point {o:.4}, scale {s:.4}", label(i)))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let _ = writeln!(
            s,
            "  natural units: on intake each raw value becomes (raw − operating point)/scale, \
             the model's units, in which Q, R and the innovations are; inputs {}; outputs {}; \
             sensor/actuator bias magnitudes are in raw units",
            list(
                &|i| channel.columns.input_label(i),
                scaling.u_offset(),
                scaling.u_scale()
            ),
            list(
                &|i| channel.columns.output_label(i),
                scaling.y_offset(),
                scaling.y_scale()
            )
        );
    } else if channel.columns.y_units.iter().any(|u| !u.is_empty()) {
        let labels: Vec<String> = (0..channel.dims.outputs)
            .map(|i| channel.columns.output_label(i))
            .collect();
        let _ = writeln!(
            s,
            "  units: the model is in the plant's units ({}); Q, R and magnitudes too",
            labels.join(", ")
        );
    }
    if channel.columns.named {
        let _ = writeln!(
            s,
            "  CSV columns: u = [{}], y = [{}]{} (other columns are skipped)",
            channel.columns.u.join(", "),
            channel.columns.y.join(", "),
            if channel.columns.p.is_empty() {
                String::new()
            } else {
                format!(", p = [{}]", channel.columns.p.join(", "))
            }
        );
    }
    s
}

/// Which law the isolation tests' thresholds follow, in words: calibrated ones, and
/// the χ² quantile (Bonferroni over the window's onsets or nominal) for the others.
fn isolation_law_text(channel: &Channel) -> String {
    let onsets = channel.isolation_onsets.max(1);
    let law = if onsets > 1 {
        format!(
            "χ²(dof) upper quantile at {:e}/(w − s) = {:e} (Bonferroni over the {onsets} \
             onsets: the tests run at the onset r̂ the data chose, where the quantile at \
             {:e} is exceeded more often than that under no fault; `isolation_law = \
             \"chi2\"` for the nominal law)",
            channel.isolation_alpha,
            channel.isolation_alpha / onsets as f64,
            channel.isolation_alpha
        )
    } else {
        format!(
            "χ²(dof) upper quantile at {:e} (the nominal law of a test at a known onset)",
            channel.isolation_alpha
        )
    };
    let calibrated: Vec<&str> = (channel.isolation_thresholds.iter())
        .map(|(n, _)| n.as_str())
        .collect();
    let tests = channel.groups.len().max(channel.fault_names.len());
    match calibrated.len() {
        0 => format!("every test at the {law}; calibrate them with `glrmon calibrate`"),
        n if n >= tests => format!(
            "every test at its calibrated threshold ({})",
            calibrated.join(", ")
        ),
        _ => format!(
            "calibrated thresholds for {}; the others at the {law}",
            calibrated.join(", ")
        ),
    }
}

/// How an alarm episode ends, in words.
fn episode_end_text(channel: &Channel) -> String {
    match channel.episode_end {
        glrmon_core::EpisodeEnd::FaultGone { alpha, samples }
            if channel.detector_kind == DetectorKind::Glr =>
        {
            format!(
                "one per fault: an episode ends when the fault followed from its onset has \
                 not gone on (not visible at {alpha:e}, or closer to none than to its \
                 magnitude) in the last w samples for {samples} samples and l_k is below \
                 λ(1 − h)"
            )
        }
        _ => format!(
            "an episode ends when l_k stays below λ(1 − h) = {:.4} for {} samples",
            channel.alarm.threshold * (1.0 - channel.alarm.hysteresis),
            channel.alarm.clear_samples
        ),
    }
}

/// How the threshold was set, in words.
fn threshold_text(channel: &Channel) -> String {
    match channel.threshold_source {
        ThresholdSource::Explicit => format!("{:.4} (explicit)", channel.alarm.threshold),
        ThresholdSource::Bounded => format!(
            "{:.4} (the bound no noise within the declared bounds crosses: no false alarm \
             under them)",
            channel.alarm.threshold
        ),
        ThresholdSource::Siegmund { false_alarm } => format!(
            "{:.4} (Siegmund's approximation of the CUSUM's mean time to a false alarm: \
             {false_alarm:e} per sample)",
            channel.alarm.threshold
        ),
        ThresholdSource::Bonferroni { false_alarm } => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e}/(w − s), Bonferroni: conservative)",
            channel.alarm.threshold,
            channel.fault_names.len()
        ),
        ThresholdSource::KnownOnset { false_alarm } => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e}: the faults' profile is known, \
             no onset is searched, so the level is exact)",
            channel.alarm.threshold,
            channel.fault_names.len()
        ),
        ThresholdSource::Chi2 { false_alarm } if !channel.detector_kind.maximises_over_onsets() => {
            format!(
                "{:.4} (χ²({}) upper quantile at {false_alarm:e} per sample)",
                channel.alarm.threshold, channel.statistic_dof
            )
        }
        ThresholdSource::Chi2 { false_alarm } => format!(
            "{:.4} (χ²({}) upper quantile at {false_alarm:e} per onset: optimistic, the window's \
             maximum exceeds it far more often; see `glrmon calibrate`)",
            channel.alarm.threshold,
            channel.fault_names.len()
        ),
        ThresholdSource::Calibrated {
            target: Target::Mtbfa(mtbfa),
            samples,
            episodes,
            interval,
            ..
        } => format!(
            "{:.4} (calibrated for one false-alarm episode per {} on {}, {episodes} \
             episodes; 95 % interval {:.4}–{:.4})",
            channel.alarm.threshold,
            in_time(mtbfa, "samples", channel.period),
            in_time(samples as f64, "fault-free samples", channel.period),
            interval[0],
            interval[1]
        ),
        ThresholdSource::Calibrated {
            target: Target::SampleFar(fraction),
            samples,
            episodes,
            exceedances,
            interval,
        } => format!(
            "{:.4} (calibrated for a fraction {fraction} of fault-free samples above it on \
             {samples} fault-free samples, {} above in {episodes} clusters; 95 % interval \
             {:.4}–{:.4})",
            channel.alarm.threshold,
            exceedances.map_or_else(|| "?".to_owned(), |n| n.to_string()),
            interval[0],
            interval[1]
        ),
    }
}

/// A number of samples with the time it spans when the period is known:
/// `4320 samples (1.00 d)`.
fn in_time(samples: f64, what: &str, period: Option<f64>) -> String {
    let Some(p) = period.filter(|p| *p > 0.0 && samples.is_finite()) else {
        return format!("{samples} {what}");
    };
    let seconds = samples * p;
    let time = if seconds < 120.0 {
        format!("{seconds:.0} s")
    } else if seconds < 7200.0 {
        format!("{:.1} min", seconds / 60.0)
    } else if seconds < 172_800.0 {
        format!("{:.2} h", seconds / 3600.0)
    } else {
        format!("{:.2} d", seconds / 86_400.0)
    };
    format!("{samples} {what} ({time})")
}

/// What to do about a threshold that was not calibrated on data, or was calibrated
/// for a per-sample fraction (which does not fix how often an operator is alarmed);
/// `None` for a threshold calibrated for a mean time between false alarms, or given.
fn threshold_advice(channel: &Channel) -> Option<&'static str> {
    match channel.threshold_source {
        ThresholdSource::Calibrated {
            target: Target::Mtbfa(_),
            ..
        }
        | ThresholdSource::Explicit
        | ThresholdSource::Bounded => None,
        ThresholdSource::Calibrated {
            target: Target::SampleFar(_),
            ..
        } => Some(
            "calibrated for a fraction of samples, which does not set how often alarms \
             come (exceedances cluster into episodes); for an operator's target calibrate \
             with --mtbfa (e.g. 1d: one false alarm a day at most)",
        ),
        _ => Some(
            "not calibrated on data: a χ² level is exact only for a model that is exactly \
             right; run `glrmon calibrate --mtbfa 1d --write` on fault-free recordings other \
             than the model's identification data",
        ),
    }
}

/// Σ and the isolability of the dictionary, or, over validate's work budget, the
/// filter checked on a short window.
fn isolability_section(
    channel: &Channel,
    s: &mut String,
    warnings: &mut Vec<String>,
) -> Result<(), ReportError> {
    if channel.detector_kind == DetectorKind::Kernel {
        let _ = writeln!(
            s,
            "  isolability: not computed (the `kernel` detector isolates by excluding \
             candidate fault functions, each against its own threshold)"
        );
        return Ok(());
    }
    if !channel.detector_kind.runs_kalman_filter() {
        // The GLR's window information is not what this kind runs on; its own design
        // was checked when the configuration was read (the `detector:` line above).
        let _ = writeln!(
            s,
            "  isolability: not computed (the `{}` detector does not isolate)",
            channel.detector_kind.name()
        );
        return Ok(());
    }
    let work = report_work(channel);
    if work > REPORT_WORK_BUDGET {
        // The filter alone (a 2-sample window), so that a diverging model is still
        // refused; the isolability report would take too long.
        let steady = channel_information(channel, Some(2))?.steady;
        if let Some(sigma) = steady {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance Σ = {}",
                fmt_matrix(&sigma, "  ")
            );
        }
        let _ = writeln!(
            s,
            "  isolability: not computed (about {work:.1e} operations for w = {} and m = {}, \
             more than validate's budget of {REPORT_WORK_BUDGET:.0e}; the filter was checked \
             over {} samples)",
            channel.window.window,
            channel.fault_names.len(),
            warmup_samples(2, false) + 2
        );
        return Ok(());
    }
    let ChannelInformation {
        information: info,
        steady,
        samples,
    } = channel_information(channel, None)?;
    let bad = non_finite_faults(channel, &info);
    if !bad.is_empty() {
        return Err(ReportError(format!(
            "{}: the fault signature is not finite over the window (information matrix has a \
             non-finite entry): an expression of the column divides by zero or overflows on \
             the simulated samples",
            bad.join(", ")
        )));
    }
    match steady {
        Some(sigma) => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance Σ = {}",
                fmt_matrix(&sigma, "  ")
            );
        }
        None if channel.model_is_constant() => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance: the Riccati recursion had not converged"
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  steady-state innovation covariance: none (the model varies with p(k))"
            );
        }
    }
    let rep = isolability(&info, DEFAULT_CORRELATION_LIMIT)
        .map_err(|e| ReportError(format!("faults: {e}")))?;
    let _ = writeln!(
        s,
        "  isolability over {samples} samples (Fisher information F = C_k(r), Basseville 1996 §5-6):"
    );
    let _ = writeln!(
        s,
        "    rank {} of {}, condition number {:.3e}, C1 = {:.4}, C2 = {:.4}, C3 = {:.4}",
        rep.rank,
        channel.fault_names.len(),
        rep.condition_number,
        rep.c1,
        rep.c2,
        rep.c3
    );
    if channel.fault_names.len() <= 12 {
        let _ = writeln!(s, "    F = {}", fmt_matrix(&info, "    "));
        let _ = writeln!(
            s,
            "    correlation = {}",
            fmt_matrix(&rep.correlation, "    ")
        );
    } else {
        let _ = writeln!(
            s,
            "    largest pairwise |correlation| {:.4} over {} pairs",
            rep.max_pair_correlation(),
            rep.pairs.len()
        );
    }
    let names: Vec<&str> = channel.fault_names.iter().map(String::as_str).collect();
    let verdicts = rep.verdicts(&names, samples);
    if verdicts.is_empty() {
        let _ = writeln!(
            s,
            "    verdict: every pair of faults is separable by the minmax test over {samples} samples (|correlation| ≤ {DEFAULT_CORRELATION_LIMIT})"
        );
    }
    for v in verdicts {
        let _ = writeln!(s, "    verdict: {v}");
        warnings.push(format!("channel \"{}\": {v}", channel.name));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCALED: &str = r#"
[[channels]]
name = "tank"
period = 20.0

[channels.model]
F = 0.9
G = [[1.0]]
H = [[1.0]]
Q = 0.01
R = 0.04

[channels.scaling]
u_offset = [2.0]
u_scale = [0.25]
y_offset = [60.0]
y_scale = [1.5]

[channels.columns]
u = ["FIC101"]
y = ["LI201"]
u_units = ["m³/h"]
y_units = ["cm"]

[[channels.faults]]
kind = "all_sensors"
"#;

    #[test]
    fn a_continuous_model_says_how_it_was_sampled() {
        let cfg =
            glrmon_spec::parse(include_str!("../../../config/examples/two-tanks.toml")).unwrap();
        let text = settings(&cfg.channels[0]);
        assert!(
            text.contains("continuous-time model sampled every T = 20 s")
                && text.contains("zero-order hold")
                && text.contains("Van Loan"),
            "{text}"
        );
        let text = settings(&glrmon_spec::parse(SCALED).unwrap().channels[0]);
        assert!(!text.contains("continuous-time"), "{text}");
    }

    #[test]
    fn units_are_named_and_a_scale_is_not_a_spread() {
        let cfg = glrmon_spec::parse(SCALED).unwrap();
        let text = settings(&cfg.channels[0]);
        assert!(
            text.contains("inputs FIC101 [m³/h]: operating point 2.0000, scale 0.2500"),
            "{text}"
        );
        assert!(
            text.contains("outputs LI201 [cm]: operating point 60.0000, scale 1.5000"),
            "{text}"
        );
        assert!(!text.contains('±'), "{text}");
    }

    #[test]
    fn a_threshold_not_calibrated_for_a_time_says_what_to_run() {
        let cfg = glrmon_spec::parse(SCALED).unwrap();
        let text = settings(&cfg.channels[0]);
        assert!(
            text.contains("threshold: not calibrated on data")
                && text.contains("glrmon calibrate --mtbfa 1d --write"),
            "{text}"
        );
        let calibrated = format!(
            "{SCALED}\n[channels.glr.calibrated]\nthreshold = 30.0\nmtbfa = 4320.0\n\
             samples = 12960\nepisodes = 3\ninterval = [25.0, 40.0]\n"
        );
        let cfg = glrmon_spec::parse(&calibrated).unwrap();
        let text = settings(&cfg.channels[0]);
        assert!(!text.contains("  threshold:"), "{text}");
        assert!(
            text.contains(
                "one false-alarm episode per 4320 samples (24.00 h) on 12960 fault-free \
                 samples (3.00 d)"
            ),
            "{text}"
        );
    }

    #[test]
    fn small_matrices_stay_on_one_line() {
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.5, 2.0]);
        assert_eq!(
            fmt_matrix(&m, "  "),
            "[[1.000000e0, 5.000000e-1], [5.000000e-1, 2.000000e0]]"
        );
    }

    #[test]
    fn wider_matrices_are_aligned_rows_on_their_own_lines() {
        let m = DMatrix::from_fn(8, 8, |i, j| if i == j { 1.0 } else { -0.25 });
        let text = fmt_matrix(&m, "    ");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "8×8");
        assert_eq!(lines.len(), 9);
        assert!(lines[1].starts_with("      "), "{text}");
        let widths: Vec<usize> = lines[1..].iter().map(|l| l.chars().count()).collect();
        assert!(widths.iter().all(|w| *w == widths[0]), "{text}");
    }

    #[test]
    fn a_22_by_22_covariance_is_summarised() {
        let m = DMatrix::from_fn(22, 22, |i, j| if i == j { 2.0 } else { 0.01 });
        let text = fmt_matrix(&m, "  ");
        assert!(text.starts_with("22×22, summarised"), "{text}");
        assert!(text.contains("condition number"), "{text}");
        assert!(text.lines().all(|l| l.chars().count() < 100), "{text}");
        // 22 diagonal entries, 6 a line.
        assert_eq!(text.lines().count(), 1 + 1 + 4 + 1 + 1, "{text}");
    }
}
