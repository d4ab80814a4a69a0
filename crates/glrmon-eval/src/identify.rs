//! `glrmon identify`: fault-free recordings → an identified, validated channel
//! configuration (see [`glrmon_ident`] for the numerics).
//!
//! Each file is read as named columns ([`glrmon_input::read_table`]); every run of
//! consecutive samples is a separate experiment (never joined to the next); the chosen
//! inputs and outputs go to [`glrmon_ident::identify()`]; the identified innovation model,
//! its operating point and scales, and the columns become a commented configuration
//! ([`glrmon_spec::write::identified_channel`]) that is parsed back and whose detector is
//! checked against the identification before anything is returned.

use std::path::{Path, PathBuf};

use glrmon_ident::{
    Experiment, IdentError, IdentSettings, Identification, InnovationModel, Method, Signal,
    WarningKind, WorkEstimate, estimate_work,
};
use glrmon_input::{InputError, Table, read_table};
use glrmon_spec::limits::{
    CHANNEL_MEMORY_BUDGET, ChannelFootprint, MAX_FAULTS, MAX_INPUTS, MAX_OFFSET, MAX_OUTPUTS,
    MAX_SCALE, MAX_STATES, MAX_WINDOW, MIN_SCALE, human_bytes,
};
use glrmon_spec::write::{IdentifiedChannel, identified_channel};
use nalgebra::DMatrix;

/// Runs shorter than this are left out (with a note): they cannot fill the block
/// Hankel matrices of any useful horizon.
pub const MIN_RUN_SAMPLES: usize = 50;

/// Most working memory an identification may need, by [`estimate_work`]: a request
/// above it is refused before any work (a horizon of 20 000 on 10⁶ samples once grew past
/// 4.4 GB before it failed).
pub const IDENT_MEMORY_BUDGET: u64 = 2 << 30;

/// Most floating-point operations an identification may need, by [`estimate_work`]:
/// about ten minutes at [`ASSUMED_FLOPS_PER_SECOND`].
pub const IDENT_FLOP_BUDGET: f64 = 600.0 * ASSUMED_FLOPS_PER_SECOND;

/// The rate the time estimates assume, in counted operations per second: what a release
/// build reached on two cores for 9 inputs, 22 outputs and 3 × 5000 samples (PO-MOESP
/// 2.2e10 counted in 4.7 s, PBSID 4.1e10 in 9.3 s; glrmon-ident's
/// `the_work_estimate_next_to_the_time_taken`). A debug build is many times slower.
pub const ASSUMED_FLOPS_PER_SECOND: f64 = 4e9;

/// What to identify.
#[derive(Debug, Clone)]
pub struct IdentifyRequest {
    /// Name of the channel to write.
    pub channel: String,
    /// Fault-free recordings (CSV or MCAP), each a separate experiment.
    pub files: Vec<PathBuf>,
    /// Input columns; `None`: every `u<i>` column, in index order.
    pub inputs: Option<Vec<String>>,
    /// Output columns; `None`: every `y<i>` column, in index order.
    pub outputs: Option<Vec<String>>,
    /// Identification settings (order, horizon, hold-out, criterion, detrending).
    pub settings: IdentSettings,
    /// GLR window of the written channel.
    pub window: usize,
    /// Lines for the head of the written file (e.g. the command line).
    pub notes: Vec<String>,
    /// A channel whose `[channels.topics]` reads the MCAP recordings glrmon did not
    /// write among `files` (its model is not used); `None`: none are read so.
    pub topics: Option<glrmon_spec::Channel>,
}

/// A run that was used or left out.
#[derive(Debug, Clone, PartialEq)]
pub struct RunInfo {
    /// The file.
    pub file: PathBuf,
    /// Where the run starts in it.
    pub start: String,
    /// Its samples.
    pub samples: usize,
    /// Whether it was used (long enough).
    pub used: bool,
}

/// The result: the identification, the configuration text and what was checked.
#[derive(Debug, Clone)]
pub struct Identified {
    /// The identification (model, order selection, validation).
    pub identification: Identification,
    /// The chosen input columns (before constant ones were dropped).
    pub inputs: Vec<String>,
    /// The chosen output columns (before constant ones were dropped).
    pub outputs: Vec<String>,
    /// The channel as written.
    pub channel: IdentifiedChannel,
    /// The configuration text.
    pub config: String,
    /// The runs found in the files.
    pub runs: Vec<RunInfo>,
    /// Columns left out of the model, in words, named.
    pub dropped: Vec<String>,
    /// Largest relative difference between the written channel's detector's innovation
    /// covariance Σ_k after one pass over the first experiment and the identified Re
    /// (the configuration's Kalman filter is the identified predictor: ≈ 0).
    pub sigma_mismatch: f64,
    /// The work estimated before identifying.
    pub work: WorkEstimate,
    /// The method used and why, in one line (inputs named).
    pub method_line: String,
    /// The held-out validation's failures in words, one per failed check, the number next
    /// to the verdict (empty: validation passed).
    pub validation_failures: Vec<String>,
}

/// Why identification failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IdentifyError {
    /// A file could not be read.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A requested or expected column is missing, or none was found.
    #[error("{file}: {why}")]
    Columns {
        /// The file.
        file: PathBuf,
        /// What is missing.
        why: String,
    },
    /// No run is long enough.
    #[error(
        "no run of consecutive samples has at least {MIN_RUN_SAMPLES} samples (runs: {0}): \
         identification needs longer recordings"
    )]
    TooShort(String),
    /// The numerics refused (the message names the columns).
    #[error("identification failed: {0}")]
    Ident(String),
    /// A setting or size of the request is out of range: refused before any work.
    /// `option` is the request's field (`window`, `order`, `max_order`, `inputs`,
    /// `outputs`, `horizon`, or `files` for the recordings' size).
    #[error("{option}: {why}")]
    Request {
        /// The request's field at fault.
        option: &'static str,
        /// What is wrong and what is accepted.
        why: String,
    },
    /// The written configuration does not validate (a bug: please report it).
    #[error("the written configuration does not validate:\n{0}")]
    Written(String),
}

/// Identifies `request.channel` from the files (see the [module](self) docs).
///
/// # Errors
/// [`IdentifyError`]: unreadable files, missing columns, too little data, numerical
/// refusals (naming the columns), or a written configuration that does not validate.
pub fn identify_channel(request: &IdentifyRequest) -> Result<Identified, IdentifyError> {
    check_request(request)?;
    let mut tables: Vec<(PathBuf, Table)> = Vec::new();
    for file in &request.files {
        let runs = match &request.topics {
            Some(channel) => glrmon_input::read_table_for_channel(file, channel)?,
            None => read_runs(file, &request.channel)?,
        };
        for table in runs {
            tables.push((file.clone(), table));
        }
    }
    let first = tables
        .first()
        .ok_or_else(|| IdentifyError::TooShort("none".into()))?;
    let (inputs, outputs) = signal_columns(request, first)?;
    let Experiments {
        runs,
        experiments,
        mut periods,
    } = experiments(&tables, &inputs, &outputs)?;
    if experiments.is_empty() {
        let sizes: Vec<String> = runs.iter().map(|r| r.samples.to_string()).collect();
        return Err(IdentifyError::TooShort(sizes.join(", ")));
    }
    let work = check_sizes(request, &experiments, inputs.len(), outputs.len())?;
    check_scaling(request, &experiments, &inputs, &outputs)?;
    let identification =
        glrmon_ident::identify(&experiments, &request.settings).map_err(|e| match e {
            IdentError::DuplicateColumns {
                signal,
                first,
                second,
            } => {
                let (option, names) = match signal {
                    Signal::Input => ("inputs", &inputs),
                    Signal::Output => ("outputs", &outputs),
                };
                IdentifyError::Request {
                    option,
                    why: format!(
                        "columns \"{}\" and \"{}\" carry the same signal (correlation ±1 \
                         once each one's operating point and scale are removed): no model can \
                         tell them apart; leave one out",
                        names[first], names[second]
                    ),
                }
            }
            IdentError::InvalidSetting { name, why }
                if matches!(name, "horizon" | "holdout" | "max_order" | "order") =>
            {
                IdentifyError::Request { option: name, why }
            }
            e => IdentifyError::Ident(describe(&e, &inputs, &outputs)),
        })?;
    let scaling = &identification.scaling;
    let kept_inputs: Vec<String> = scaling
        .input_columns
        .iter()
        .map(|&i| inputs[i].clone())
        .collect();
    let kept_outputs: Vec<String> = scaling
        .output_columns
        .iter()
        .map(|&i| outputs[i].clone())
        .collect();
    let dropped = left_out(&identification, &inputs, &outputs);
    // The operating point written is the samples-weighted mean of the experiments'.
    let total: f64 = experiments.iter().map(|e| e.samples() as f64).sum();
    let pooled = |pick: &dyn Fn(&glrmon_ident::OperatingPoint) -> &nalgebra::DVector<f64>,
                  len: usize| {
        let mut mean = vec![0.0; len];
        for (op, e) in scaling.operating_points.iter().zip(&experiments) {
            for (m, v) in mean.iter_mut().zip(pick(op).iter()) {
                *m += v * e.samples() as f64 / total;
            }
        }
        mean
    };
    let u_offset = pooled(&|op| &op.input_mean, kept_inputs.len());
    let y_offset = pooled(&|op| &op.output_mean, kept_outputs.len());
    let model = &identification.scaled_model;
    periods.sort_by(f64::total_cmp);
    let other_columns = tables.iter().any(|(_, t)| {
        t.names
            .iter()
            .any(|n| !kept_inputs.contains(n) && !kept_outputs.contains(n))
    });
    let method_line = identification.method.line(&kept_inputs);
    let validation_failures = identification.validation.verdicts(&kept_outputs, false);
    let mut notes = request.notes.clone();
    notes.push(format!("Method: {method_line}."));
    notes.extend(summary(&identification, &kept_outputs, &runs, &dropped));
    if !validation_failures.is_empty() {
        notes.push(format!(
            "WARNING: this model fails its {} validation ({} check(s)); calibrate its \
             threshold on fault-free data before use:",
            if identification.validation.in_sample {
                "in-sample"
            } else {
                "held-out"
            },
            validation_failures.len()
        ));
        notes.extend(validation_failures.iter().map(|l| format!("  {l}")));
    }
    let channel = IdentifiedChannel {
        name: request.channel.clone(),
        period: periods.get(periods.len() / 2).copied(),
        a: model.a.clone(),
        b: model.b.clone(),
        c: model.c.clone(),
        d: model.d.clone(),
        k: model.k.clone(),
        re: model.re.clone(),
        p0: state_spread(model, &experiments, scaling, &u_offset, &y_offset)
            .unwrap_or_else(|| initial_covariance(model)),
        inputs: kept_inputs,
        outputs: kept_outputs,
        other_columns,
        u_offset,
        u_scale: scaling.input_scale.iter().copied().collect(),
        y_offset,
        y_scale: scaling.output_scale.iter().copied().collect(),
        window: request.window,
        notes,
    };
    let config = identified_channel(&channel);
    let parsed = glrmon_spec::parse(&config).map_err(|e| IdentifyError::Written(e.to_string()))?;
    let sigma_mismatch = sigma_mismatch(&parsed.channels[0], experiments[0].samples(), model)
        .map_err(IdentifyError::Written)?;
    Ok(Identified {
        identification,
        inputs,
        outputs,
        channel,
        config,
        runs,
        dropped,
        sigma_mismatch,
        work,
        method_line,
        validation_failures,
    })
}

/// The request's settings against the configuration's limits, before any file is read:
/// the window, the orders, and no column named twice.
fn check_request(request: &IdentifyRequest) -> Result<(), IdentifyError> {
    if !(1..=MAX_WINDOW).contains(&request.window) {
        return Err(IdentifyError::Request {
            option: "window",
            why: format!(
                "{} is not a GLR window: it must be in 1..={MAX_WINDOW} (the \
                 configuration's limit on glr.window)",
                request.window
            ),
        });
    }
    let settings = &request.settings;
    for (option, value) in [
        ("order", settings.order),
        (
            "max_order",
            settings.order.is_none().then_some(settings.max_order),
        ),
    ] {
        if let Some(n) = value
            && !(1..=MAX_STATES).contains(&n)
        {
            return Err(IdentifyError::Request {
                option,
                why: format!(
                    "{n} states cannot be written: a channel has 1..={MAX_STATES} states (the \
                     configuration's limit on n)"
                ),
            });
        }
    }
    for (option, list) in [("inputs", &request.inputs), ("outputs", &request.outputs)] {
        let Some(list) = list else { continue };
        for (i, name) in list.iter().enumerate() {
            if list[..i].contains(name) {
                return Err(IdentifyError::Request {
                    option,
                    why: format!(
                        "column \"{name}\" is given twice: a duplicate column is collinear \
                         with itself, and no model can tell the two apart"
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Each kept column's scale (its spread) and operating point (its mean) against the
/// limits of `[channels.scaling]` ([`MIN_SCALE`], [`MAX_SCALE`], [`MAX_OFFSET`]), before
/// identifying: a column the written configuration could not hold is refused by name
/// instead of failing after the work (the written file would not validate).
fn check_scaling(
    request: &IdentifyRequest,
    experiments: &[Experiment],
    inputs: &[String],
    outputs: &[String],
) -> Result<(), IdentifyError> {
    let pre = match glrmon_ident::preprocess(experiments, &request.settings.preprocess) {
        Ok(pre) => pre,
        // The identification reports it, with the columns named.
        Err(_) => return Ok(()),
    };
    let sc = &pre.scaling;
    let columns = sc
        .input_columns
        .iter()
        .zip(sc.input_scale.iter())
        .map(|(&c, &s)| ("inputs", &inputs[c], Signal::Input, c, s))
        .chain(
            sc.output_columns
                .iter()
                .zip(sc.output_scale.iter())
                .map(|(&c, &s)| ("outputs", &outputs[c], Signal::Output, c, s)),
        );
    for (option, name, signal, column, scale) in columns {
        if !(MIN_SCALE..=MAX_SCALE).contains(&scale) {
            return Err(IdentifyError::Request {
                option,
                why: format!(
                    "column \"{name}\" varies by {scale:.3e} (its standard deviation), outside \
                     the scales a channel can hold, [{MIN_SCALE:e}, {MAX_SCALE:e}] \
                     (glrmon_spec::limits): give it in other units, or leave it out"
                ),
            });
        }
        for op in &sc.operating_points {
            let (kept, means) = match signal {
                Signal::Input => (&sc.input_columns, &op.input_mean),
                Signal::Output => (&sc.output_columns, &op.output_mean),
            };
            let Some(at) = kept.iter().position(|&c| c == column) else {
                continue;
            };
            if means[at].abs() > MAX_OFFSET {
                return Err(IdentifyError::Request {
                    option,
                    why: format!(
                        "column \"{name}\" sits at {:.3e}, beyond the offsets a channel can \
                         hold, ±{MAX_OFFSET:e} (glrmon_spec::limits): give it in other units, \
                         or leave it out",
                        means[at]
                    ),
                });
            }
        }
    }
    Ok(())
}

/// The sizes of the data and of the channel to write against the configuration's limits
/// ([`glrmon_spec::limits`]) and the work against [`IDENT_MEMORY_BUDGET`] and
/// [`IDENT_FLOP_BUDGET`], before identifying.
fn check_sizes(
    request: &IdentifyRequest,
    experiments: &[Experiment],
    l: usize,
    p: usize,
) -> Result<WorkEstimate, IdentifyError> {
    for (option, count, max, what) in [
        ("outputs", p, MAX_OUTPUTS, "outputs p"),
        ("inputs", l, MAX_INPUTS, "inputs l"),
    ] {
        if count > max {
            return Err(IdentifyError::Request {
                option,
                why: format!(
                    "{count} columns, but a channel has at most {max} {what} (the \
                     configuration's limit): choose fewer columns"
                ),
            });
        }
    }
    if l + p > MAX_FAULTS {
        return Err(IdentifyError::Request {
            option: "inputs",
            why: format!(
                "{p} outputs and {l} inputs give {} bias faults, but a dictionary has at most \
                 {MAX_FAULTS} (the configuration's limit): choose fewer columns",
                l + p
            ),
        });
    }
    let settings = &request.settings;
    let states = settings.order.unwrap_or(settings.max_order);
    let footprint = ChannelFootprint {
        states,
        outputs: p,
        inputs: l,
        faults: l + p,
        window: request.window,
        history: 2 * request.window,
    };
    if footprint.bytes() > CHANNEL_MEMORY_BUDGET {
        return Err(IdentifyError::Request {
            option: "window",
            why: format!(
                "the written channel's monitor would need {} with up to {states} states ({}), \
                 more than the {} a channel may use: lower --window or the order",
                human_bytes(footprint.bytes()),
                footprint.breakdown(),
                human_bytes(CHANNEL_MEMORY_BUDGET)
            ),
        });
    }
    let samples: Vec<usize> = experiments.iter().map(Experiment::samples).collect();
    let work = estimate_work(&samples, l, p, settings);
    let total: usize = samples.iter().sum();
    let (option, lever) = if settings.horizon.is_some() {
        (
            "horizon",
            "a shorter --horizon, fewer samples or fewer columns",
        )
    } else {
        (
            "files",
            "fewer samples (shorter or fewer recordings) or fewer columns",
        )
    };
    let method = match settings.method {
        Method::Auto => "either method",
        other => other.title(),
    };
    let what = format!(
        "{total} samples of {l} inputs and {p} outputs, {method} with horizon {} (widest \
         factored matrix {} columns), orders up to {states}",
        work.horizon, work.width
    );
    if work.bytes > IDENT_MEMORY_BUDGET {
        return Err(IdentifyError::Request {
            option,
            why: format!(
                "identification would need about {} of memory, more than its limit {}: \
                 {what}; give {lever}",
                human_bytes(work.bytes),
                human_bytes(IDENT_MEMORY_BUDGET)
            ),
        });
    }
    if work.flops > IDENT_FLOP_BUDGET {
        return Err(IdentifyError::Request {
            option: if option == "files" && settings.order.is_none() && states > 10 {
                "max_order"
            } else {
                option
            },
            why: format!(
                "identification would take about {:.0} s ({:.1e} floating-point operations \
                 at {:.0e}/s), more than its limit of {:.0} s: {what}; give {lever}",
                work.flops / ASSUMED_FLOPS_PER_SECOND,
                work.flops,
                ASSUMED_FLOPS_PER_SECOND,
                IDENT_FLOP_BUDGET / ASSUMED_FLOPS_PER_SECOND
            ),
        });
    }
    Ok(work)
}

/// The input and output column names: the request's, else the numbered `u…`, `y…`
/// of the first run.
fn signal_columns(
    request: &IdentifyRequest,
    first: &(PathBuf, Table),
) -> Result<(Vec<String>, Vec<String>), IdentifyError> {
    let inputs = match &request.inputs {
        Some(list) => list.clone(),
        None => numbered(&first.1.names, 'u'),
    };
    let outputs = match &request.outputs {
        Some(list) => list.clone(),
        None => numbered(&first.1.names, 'y'),
    };
    if outputs.is_empty() {
        return Err(IdentifyError::Columns {
            file: first.0.clone(),
            why: format!(
                "no output column: name them with --outputs (columns: {})",
                first.1.names.join(", ")
            ),
        });
    }
    if let Some(name) = inputs.iter().find(|n| outputs.contains(n)) {
        return Err(IdentifyError::Columns {
            file: first.0.clone(),
            why: format!("column \"{name}\" is both an input and an output"),
        });
    }
    Ok((inputs, outputs))
}

/// Every run with its size and whether it is long enough to identify from, the
/// experiments of those that are (never joined to one another), and their periods.
struct Experiments {
    runs: Vec<RunInfo>,
    experiments: Vec<Experiment>,
    periods: Vec<f64>,
}

/// The [`Experiments`] of the runs `tables`, with these input and output columns.
fn experiments(
    tables: &[(PathBuf, Table)],
    inputs: &[String],
    outputs: &[String],
) -> Result<Experiments, IdentifyError> {
    let mut runs = Vec::new();
    let mut experiments = Vec::new();
    let mut periods = Vec::new();
    for (file, table) in tables {
        let used = table.samples() >= MIN_RUN_SAMPLES;
        runs.push(RunInfo {
            file: file.clone(),
            start: table.start.clone(),
            samples: table.samples(),
            used,
        });
        if !used {
            continue;
        }
        let column = |name: &String| {
            table.column(name).ok_or_else(|| IdentifyError::Columns {
                file: file.clone(),
                why: format!("no column \"{name}\" (columns: {})", table.names.join(", ")),
            })
        };
        let n = table.samples();
        let mut u = DMatrix::zeros(n, inputs.len());
        for (j, name) in inputs.iter().enumerate() {
            u.column_mut(j).copy_from_slice(column(name)?);
        }
        let mut y = DMatrix::zeros(n, outputs.len());
        for (j, name) in outputs.iter().enumerate() {
            y.column_mut(j).copy_from_slice(column(name)?);
        }
        experiments.push(Experiment::new(u, y));
        periods.extend(table.period);
    }
    Ok(Experiments {
        runs,
        experiments,
        periods,
    })
}

/// Why each left-out column is out of the model, by its name.
fn left_out(identification: &Identification, inputs: &[String], outputs: &[String]) -> Vec<String> {
    identification
        .warnings
        .iter()
        .map(|w| {
            let name = match w.signal {
                Signal::Input => &inputs[w.column],
                Signal::Output => &outputs[w.column],
            };
            match w.kind {
                WarningKind::Constant { value } => {
                    format!("{name} is constant ({value}): left out of the model")
                }
                WarningKind::NearlyConstant { std, level } => format!(
                    "{name} is nearly constant (std {std:.3e} at level {level:.3e}): left out \
                     of the model"
                ),
                _ => format!("{name}: left out of the model"),
            }
        })
        .collect::<Vec<_>>()
}

/// The runs of `file`; for a recording, channel `channel`'s if it has one, else its
/// only channel's.
fn read_runs(file: &Path, channel: &str) -> Result<Vec<Table>, InputError> {
    if glrmon_input::InputFormat::of(file) == glrmon_input::InputFormat::Mcap {
        match read_table(file, Some(channel)) {
            Ok(runs) => return Ok(runs),
            Err(e) if matches!(e.kind(), glrmon_input::InputErrorKind::Table(_)) => {}
            Err(e) => return Err(e),
        }
    }
    read_table(file, None)
}

/// `u0, u1, …` (or `y…`) among `names`, in index order.
fn numbered(names: &[String], letter: char) -> Vec<String> {
    let mut found: Vec<(usize, String)> = names
        .iter()
        .filter_map(|n| {
            let rest = n.strip_prefix(letter)?;
            let i: usize = rest.parse().ok()?;
            (rest == i.to_string()).then(|| (i, n.clone()))
        })
        .collect();
    found.sort();
    found.into_iter().map(|(_, n)| n).collect()
}

/// An identification error with the caller's column names in place of indices.
fn describe(e: &IdentError, inputs: &[String], outputs: &[String]) -> String {
    let inputs = inputs.join(", ");
    let outputs = outputs.join(", ");
    format!(
        "{e} (inputs, in order: [{inputs}]; outputs: [{outputs}]; experiments count from 0 in file order)"
    )
}

/// The comment lines that say how the model was found.
fn summary(
    id: &Identification,
    outputs: &[String],
    runs: &[RunInfo],
    dropped: &[String],
) -> Vec<String> {
    let used: Vec<&RunInfo> = runs.iter().filter(|r| r.used).collect();
    let samples: usize = used.iter().map(|r| r.samples).sum();
    let mut lines = vec![
        format!(
            "{} experiment(s), {samples} samples; order n = {} ({}); horizon i = {}.",
            used.len(),
            id.model.order(),
            id.order.reason,
            id.horizon
        ),
        format!(
            "One-step prediction NRMSE ({}): {}.",
            if id.validation.in_sample {
                "in-sample"
            } else {
                "held-out"
            },
            outputs
                .iter()
                .zip(id.validation.nrmse.iter())
                .map(|(n, v)| format!("{n} {v:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    ];
    if let Some(nis) = id.validation.nis_mean {
        let (lo, hi) = id.validation.nis_interval;
        lines.push(format!(
            "Mean normalised innovation square {nis:.3} (p = {} outputs; a right model's is in \
             [{lo:.3}, {hi:.3}] with probability {}: {}).",
            id.validation.outputs,
            1.0 - id.validation.level,
            if id.validation.nis_consistent() {
                "consistent"
            } else {
                "NOT consistent"
            }
        ));
    }
    lines.extend(dropped.iter().cloned());
    lines
}

/// P0 from the data: the second moment about zero of the steady predictor's state
/// x̂⁺ = A x̂ + B u + K (y − C x̂ − D u) run over the identification experiments in the
/// written channel's coordinates ((raw − pooled operating point)/scale). The filter
/// starts at x̂_0 = 0 on any sample of any day, where the plant's state holds the
/// response to inputs the filter never saw (the setpoint moves of the hours before) as
/// well as the noise: a P0 of the noise part alone (`initial_covariance`) made the
/// first window of a file a false alarm whenever the day began away from the operating
/// point. The first 10 % of each experiment (the predictor's own start from zero) is
/// left out. `None` when A is unstable or the data give no finite, positive definite
/// moment.
fn state_spread(
    model: &InnovationModel,
    experiments: &[glrmon_ident::Experiment],
    scaling: &glrmon_ident::Scaling,
    u_offset: &[f64],
    y_offset: &[f64],
) -> Option<DMatrix<f64>> {
    if glrmon_ident::spectral_radius(&model.a) >= 0.999 {
        return None;
    }
    let n = model.order();
    let (l, p) = (scaling.input_columns.len(), scaling.output_columns.len());
    let mut moment = DMatrix::<f64>::zeros(n, n);
    let mut count = 0usize;
    let mut u = nalgebra::DVector::<f64>::zeros(l);
    let mut y = nalgebra::DVector::<f64>::zeros(p);
    for e in experiments {
        let mut x = nalgebra::DVector::<f64>::zeros(n);
        let skip = e.samples() / 10;
        for k in 0..e.samples() {
            for (j, &c) in scaling.input_columns.iter().enumerate() {
                u[j] = (e.inputs[(k, c)] - u_offset[j]) / scaling.input_scale[j];
            }
            for (j, &c) in scaling.output_columns.iter().enumerate() {
                y[j] = (e.outputs[(k, c)] - y_offset[j]) / scaling.output_scale[j];
            }
            if k >= skip {
                moment += &x * x.transpose();
                count += 1;
            }
            let innovation = &y - &model.c * &x - &model.d * &u;
            x = &model.a * &x + &model.b * &u + &model.k * innovation;
        }
    }
    if count == 0 {
        return None;
    }
    let moment = moment / count as f64;
    let floor = 1e-6 * moment.diagonal().max().max(1e-12);
    let p0 = (&moment + moment.transpose()) * 0.5 + DMatrix::identity(n, n) * floor;
    (p0.iter().all(|v| v.is_finite()) && p0.clone().cholesky().is_some()).then_some(p0)
}

/// P0: the stationary state covariance of x⁺ = A x + K e (the spread of an unknown
/// start), by doubling; the identity when A is not stable enough for it to exist.
fn initial_covariance(model: &InnovationModel) -> DMatrix<f64> {
    let n = model.order();
    if glrmon_ident::spectral_radius(&model.a) >= 0.999 {
        return DMatrix::identity(n, n);
    }
    let mut p = &model.k * &model.re * model.k.transpose();
    let mut a = model.a.clone();
    for _ in 0..64 {
        let next = &p + &a * &p * a.transpose();
        let change = (&next - &p).amax();
        p = next;
        a = &a * &a;
        if change <= 1e-14 * p.amax() {
            break;
        }
    }
    // Never singular: a state that noise does not excite still starts unknown.
    let floor = 1e-6 * p.diagonal().max().max(1e-12);
    p + DMatrix::identity(n, n) * floor
}

/// max |Σ_N − Re| / max |Re| after the written channel's detector has taken `steps`
/// steps. Σ_k depends on the model and the number of steps only, not on the data, so
/// the steps are fed zeros (model units).
fn sigma_mismatch(
    channel: &glrmon_spec::Channel,
    steps: usize,
    model: &InnovationModel,
) -> Result<f64, String> {
    let mut detector = channel.glr_detector().map_err(|e| e.to_string())?;
    let dims = channel.dims;
    let mut out = glrmon_core::StepOutput::new(dims.outputs, detector.fault_count());
    let (u, y) = (vec![0.0; dims.inputs], vec![0.0; dims.outputs]);
    for k in 0..steps {
        let sample = glrmon_core::Sample {
            k: k as u64,
            u: &u,
            y: &y,
            p: &[],
        };
        detector
            .step(&sample, &mut out)
            .map_err(|e| e.to_string())?;
    }
    let sigma = detector.filter().innovation_covariance();
    Ok((sigma - &model.re).amax() / model.re.amax())
}
