//! `glrmon identify --model`: the noise covariances Q, R (and S) of a user's own model
//! from fault-free recordings, written back into the user's configuration (see
//! [`glrmon_ident::estimate_noise`] for the numerics, the autocovariance least-squares
//! method).
//!
//! The channel's F, G, H, J are kept. Each file is read as runs of consecutive samples
//! ([`glrmon_input::read_table`]), each run a separate experiment (runs shorter than
//! [`MIN_RUN_SAMPLES`] are left out): a CSV file's columns are picked by the channel's
//! column names (`[channels.columns]`, else `u0…`, `y0…`), a recording's by the
//! numbered names of its channel's samples. The channel's scaling (raw → model units)
//! is applied before the estimation, since the matrices are in model units. The
//! estimate replaces `model.Q` and `model.R` (and sets or removes `model.S`) in the
//! configuration's text ([`glrmon_spec::edit::set_noise`]), which is validated.

use std::path::{Path, PathBuf};

use glrmon_ident::{Experiment, IdentError, NoiseEstimate, NoiseSettings, PhysicalModel};
use glrmon_input::{InputError, Table, read_table};
use glrmon_spec::Channel;
use glrmon_spec::edit::EditError;
use nalgebra::DMatrix;

pub use crate::identify::{MIN_RUN_SAMPLES, RunInfo};

/// What to estimate.
#[derive(Debug, Clone)]
pub struct NoiseRequest {
    /// The configuration's text (edited and returned).
    pub config: String,
    /// The channel; `None`: the configuration's only channel.
    pub channel: Option<String>,
    /// Fault-free recordings (CSV or MCAP), each run of consecutive samples a separate
    /// experiment.
    pub files: Vec<PathBuf>,
    /// Settings of the estimation (structure, lags, iterations).
    pub settings: NoiseSettings,
    /// Where the values come from, for the comment left in the configuration.
    pub source: String,
}

/// The estimate and the edited configuration.
#[derive(Debug, Clone)]
pub struct NoiseReport {
    /// The channel's name.
    pub channel: String,
    /// The columns read into u, in order.
    pub inputs: Vec<String>,
    /// The columns read into y, in order.
    pub outputs: Vec<String>,
    /// Whether the channel's scaling was applied to the data.
    pub scaled: bool,
    /// The runs found in the files.
    pub runs: Vec<RunInfo>,
    /// The estimate (Q, R, S, the Kalman filter it gives, the checks on the data).
    pub estimate: NoiseEstimate,
    /// The configuration's text with the estimated Q, R (and S).
    pub config: String,
}

/// Why the noise covariances could not be estimated.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseError {
    /// The configuration does not validate.
    #[error("the configuration is invalid:\n{0}")]
    Config(String),
    /// The channel asked for is not in the configuration (or none was named and it has
    /// several).
    #[error("{0}")]
    Channel(String),
    /// The channel's model is of a kind whose noise cannot be estimated (the field
    /// and the reason).
    #[error("channel \"{channel}\": {field} {why}")]
    Unsupported {
        /// The channel.
        channel: String,
        /// The configuration field, e.g. `model.F` or `model.E`.
        field: String,
        /// Why it is refused.
        why: String,
    },
    /// A file could not be read.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A column of the channel is missing from a file.
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
         noise estimation needs longer recordings"
    )]
    TooShort(String),
    /// The estimation refused (e.g. [`IdentError::NotIdentifiable`], naming the
    /// parameters that the data do not determine).
    #[error("noise estimation failed: {0}")]
    Ident(#[source] IdentError),
    /// The estimate could not be written into the configuration (e.g. an R that is
    /// only semi-definite).
    #[error("the estimate cannot be written into the configuration: {0}")]
    Edit(#[from] EditError),
}

/// Estimates the noise covariances of `request.channel`'s model from the files and
/// writes them into the configuration (see the [module](self) docs).
///
/// # Errors
/// [`NoiseError`]: an invalid configuration or unknown channel; a time-varying (LPV)
/// model or one with an unknown input E ([`NoiseError::Unsupported`], naming the field);
/// unreadable files, missing columns, too little data; refusals of
/// [`glrmon_ident::estimate_noise`] (e.g. not identifiable); an estimate that does not
/// make a valid configuration.
pub fn estimate_channel_noise(request: &NoiseRequest) -> Result<NoiseReport, NoiseError> {
    let cfg = glrmon_spec::parse(&request.config).map_err(|e| NoiseError::Config(e.to_string()))?;
    let channel = cfg
        .pick_channel(request.channel.as_deref())
        .map_err(|e| NoiseError::Channel(e.to_string()))?;
    let model = physical_model(channel)?;
    let mut runs = Vec::new();
    let mut experiments = Vec::new();
    let (mut inputs, mut outputs) = (Vec::new(), Vec::new());
    for file in &request.files {
        let (tables, names) = read_runs(file, channel)?;
        (inputs, outputs) = names;
        for table in tables {
            let used = table.samples() >= MIN_RUN_SAMPLES;
            runs.push(RunInfo {
                file: file.clone(),
                start: table.start.clone(),
                samples: table.samples(),
                used,
            });
            if used {
                experiments.push(experiment(file, &table, &inputs, &outputs, channel)?);
            }
        }
    }
    if experiments.is_empty() {
        let sizes: Vec<String> = runs.iter().map(|r| r.samples.to_string()).collect();
        return Err(NoiseError::TooShort(if sizes.is_empty() {
            "none".to_owned()
        } else {
            sizes.join(", ")
        }));
    }
    let estimate = glrmon_ident::estimate_noise(&model, &experiments, &request.settings)
        .map_err(NoiseError::Ident)?;
    let config = glrmon_spec::edit::set_noise(
        &request.config,
        &channel.name,
        &estimate.q,
        &estimate.r,
        estimate.s.as_ref(),
        &request.source,
    )?;
    Ok(NoiseReport {
        channel: channel.name.clone(),
        inputs,
        outputs,
        scaled: channel.scaling.is_some(),
        runs,
        estimate,
        config,
    })
}

/// F, G, H, J of the channel, refusing what the estimation cannot handle.
fn physical_model(channel: &Channel) -> Result<PhysicalModel, NoiseError> {
    let unsupported = |field: &str, why: String| NoiseError::Unsupported {
        channel: channel.name.clone(),
        field: field.to_owned(),
        why,
    };
    let matrices = channel.model.matrices();
    for (name, m) in ["F", "G", "H", "J", "Q", "R"].iter().zip(matrices) {
        if !m.terms().is_empty() {
            let signals: Vec<String> = m.terms().iter().map(|(i, _)| format!("p{i}")).collect();
            return Err(unsupported(
                &format!("model.{name}"),
                format!(
                    "has scheduling terms ({}): noise estimation needs a time-invariant \
                     (LTI) model, and this one is LPV",
                    signals.join(", ")
                ),
            ));
        }
    }
    if channel.unknown_input.is_some() {
        return Err(unsupported(
            "model.E",
            "is given: noise estimation needs a model without an unknown input (the \
             innovations of the decoupled filter are not those of F, G, H, J)"
                .to_owned(),
        ));
    }
    let [f, g, h, j, ..] = matrices;
    Ok(PhysicalModel::new(
        f.base().clone(),
        g.base().clone(),
        h.base().clone(),
        j.base().clone(),
    ))
}

/// The column names of u and y.
type Names = (Vec<String>, Vec<String>);

/// The runs of `file` and the names of its u and y columns: a recording's channel
/// samples (glrmon's, or a foreign one's through `[channels.topics]`) are `u0…`,
/// `y0…`; a CSV file's columns are the channel's.
fn read_runs(file: &Path, channel: &Channel) -> Result<(Vec<Table>, Names), InputError> {
    if glrmon_input::InputFormat::of(file) == glrmon_input::InputFormat::Mcap {
        let numbered = glrmon_spec::Columns::numbered(channel.dims);
        let tables = glrmon_input::read_table_for_channel(file, channel)?;
        return Ok((tables, (numbered.u, numbered.y)));
    }
    let tables = read_table(file, None)?;
    Ok((
        tables,
        (channel.columns.u.clone(), channel.columns.y.clone()),
    ))
}

/// One run as an experiment in model units.
fn experiment(
    file: &Path,
    table: &Table,
    inputs: &[String],
    outputs: &[String],
    channel: &Channel,
) -> Result<Experiment, NoiseError> {
    let column = |name: &String| {
        table.column(name).ok_or_else(|| NoiseError::Columns {
            file: file.to_path_buf(),
            why: format!(
                "no column \"{name}\" of channel \"{}\" (columns: {})",
                channel.name,
                table.names.join(", ")
            ),
        })
    };
    let n = table.samples();
    let u_cols: Vec<&[f64]> = inputs.iter().map(column).collect::<Result<_, _>>()?;
    let y_cols: Vec<&[f64]> = outputs.iter().map(column).collect::<Result<_, _>>()?;
    let mut u = DMatrix::zeros(n, inputs.len());
    let mut y = DMatrix::zeros(n, outputs.len());
    let (mut raw_u, mut raw_y) = (vec![0.0; inputs.len()], vec![0.0; outputs.len()]);
    let (mut mu, mut my) = (vec![0.0; inputs.len()], vec![0.0; outputs.len()]);
    for k in 0..n {
        for (v, c) in raw_u.iter_mut().zip(&u_cols) {
            *v = c[k];
        }
        for (v, c) in raw_y.iter_mut().zip(&y_cols) {
            *v = c[k];
        }
        match &channel.scaling {
            Some(s) => s.to_model(&raw_u, &raw_y, &mut mu, &mut my),
            None => {
                mu.copy_from_slice(&raw_u);
                my.copy_from_slice(&raw_y);
            }
        }
        for (j, v) in mu.iter().enumerate() {
            u[(k, j)] = *v;
        }
        for (j, v) in my.iter().enumerate() {
            y[(k, j)] = *v;
        }
    }
    Ok(Experiment::new(u, y))
}
