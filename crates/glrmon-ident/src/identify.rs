//! `identify`: preprocessing, subspace identification for every candidate order, order
//! selection and validation of the chosen model.

use std::fmt::Write as _;

use nalgebra::{DMatrix, DVector};

use crate::data::{Experiment, PreprocessSettings, Scaling, Warning, preprocess};
use crate::error::IdentError;
use crate::model::InnovationModel;
use crate::pbsid::Pbsid;
use crate::subspace::{Subspace, min_samples};
use crate::validation::{LjungBox, ljung_box, nis_mean, nrmse};

/// Which data are held out for the prediction fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Holdout {
    /// The last fraction (in [0, 0.9]) of every experiment. The predictor still runs
    /// over the whole experiment (it is causal, so the held-out part only warms up on
    /// earlier data), but the model is estimated on the first part only. 0 means no
    /// held-out data: the fit is then in-sample.
    LastFraction(f64),
    /// The last experiment (needs at least two).
    LastExperiment,
}

/// The information criterion that picks the order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// Akaike: N log det Λ̂ + 2d.
    Aic,
    /// Schwarz (BIC/MDL): N log det Λ̂ + d log N; consistent, penalises more.
    Bic,
}

/// The subspace method that estimates the model of each candidate order.
///
/// PO-MOESP is consistent in open loop only: when the inputs are computed by a
/// controller from past outputs they are correlated with past noise, and its
/// projections are biased (Ljung & McKelvey 1996; van der Veen et al. 2013, *Closed-loop
/// subspace identification methods: an overview*, IET Control Theory Appl. 7(10), §1–3).
/// PBSID-opt is consistent in open and closed loop (Chiuso 2007, Automatica 43,
/// 1034–1048), at the price of a truncation bias of order ‖(A − KC)^p‖ for past window p.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// PO-MOESP ([`Subspace`]; Verhaegen 1994, Van Overschee & De Moor 1996 ch. 4):
    /// open-loop data (inputs independent of the noise).
    #[default]
    Moesp,
    /// Predictor-based subspace identification, PBSID-opt ([`Pbsid`]; Chiuso 2007, §5;
    /// van der Veen et al. 2013, §4.3): the choice for data recorded under feedback
    /// control. D is estimated for every input, so u_k must not depend on the current
    /// innovation: the controller must compute u_k from y_{k−1} and older (a one-sample
    /// delay in the loop; a controller acting on y_k biases D and the whole model, as it
    /// would the VARX of Chiuso 2007, who assumes a delay or a known D = 0). The driven
    /// input also needs excitation besides the feedback (a dither or setpoint changes): a
    /// noise-free linear controller of low order makes it a linear function of the past
    /// window, and [`Pbsid::new`] refuses the collinear data (an error, not a wrong model).
    ///
    /// Not the default: on the open-loop tests it is as accurate as PO-MOESP, but its
    /// default past window (20) needs more samples per experiment (2p = 40 instead of
    /// 2i = 20), and it is about 1.7× slower on wide systems (22 outputs, 9 inputs).
    Pbsid,
}

/// Settings of [`identify`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentSettings {
    /// Preprocessing (detrend, constant-column tolerance).
    pub preprocess: PreprocessSettings,
    /// The subspace method (default [`Method::Moesp`]).
    pub method: Method,
    /// [`Method::Moesp`]: past/future horizon i. `None`: i₀ = max(⌈(max_order + 1)/p⌉ + 1,
    /// 10), at least one more block row than the order needs, and long enough for the
    /// non-steady Kalman states of the projection to be close to the steady ones.
    ///
    /// [`Method::Pbsid`]: the past window p of the VARX predictor (Chiuso 2007, §3).
    /// `None`: max(i₀, 20), so that ‖(A − KC)^p‖ (the truncation bias) is small for
    /// predictor poles up to about 0.8 in modulus (0.8²⁰ ≈ 0.01); raise it for slower
    /// predictors. The future window is f = min(i₀, p), so that f·p > max_order.
    pub horizon: Option<usize>,
    /// Largest candidate order (clipped to what the data support).
    pub max_order: usize,
    /// A fixed order instead of the criterion's choice.
    pub order: Option<usize>,
    /// Held-out data.
    pub holdout: Holdout,
    /// The criterion that picks the order.
    pub criterion: Criterion,
    /// Lags of the Ljung–Box test (default 20).
    pub ljung_box_lags: usize,
}

impl Default for IdentSettings {
    fn default() -> Self {
        Self {
            preprocess: PreprocessSettings::default(),
            method: Method::default(),
            horizon: None,
            max_order: 10,
            order: None,
            holdout: Holdout::LastFraction(0.2),
            criterion: Criterion::Bic,
            ljung_box_lags: 20,
        }
    }
}

/// One candidate order and how it did.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// The order n.
    pub order: usize,
    /// N log det Λ̂ + 2d on the estimation data (+∞ if the model failed).
    pub aic: f64,
    /// N log det Λ̂ + d log N on the estimation data (+∞ if the model failed).
    pub bic: f64,
    /// Free parameters d = n(2p + l) + pl.
    pub parameters: usize,
    /// One-step prediction NRMSE per output on the held-out data.
    pub holdout_nrmse: DVector<f64>,
    /// Spectral radius of A − KC.
    pub predictor_spectral_radius: f64,
    /// Why this order gave no model, if it did not.
    pub failure: Option<String>,
}

impl Candidate {
    /// Usable: a model with a stable predictor and finite criteria.
    #[must_use]
    pub fn usable(&self) -> bool {
        self.failure.is_none()
            && self.predictor_spectral_radius < 1.0
            && self.aic.is_finite()
            && self.bic.is_finite()
    }

    fn criterion(&self, criterion: Criterion) -> f64 {
        match criterion {
            Criterion::Aic => self.aic,
            Criterion::Bic => self.bic,
        }
    }
}

/// The order chosen and the evidence.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderSelection {
    /// Singular values of the method's weighted block (descending): the PO-MOESP block
    /// L₃₂ ([`Subspace::singular_values`]) or Γ_f 𝒦_p Z_p ([`Pbsid::singular_values`]).
    pub singular_values: DVector<f64>,
    /// One per order 1..=max.
    pub candidates: Vec<Candidate>,
    /// The criterion used.
    pub criterion: Criterion,
    /// The chosen order.
    pub chosen: usize,
    /// Why, in words (criterion value, held-out fit, the best held-out order).
    pub reason: String,
}

/// The chosen model's innovations on the held-out data.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationReport {
    /// Samples scored.
    pub samples: usize,
    /// One-step prediction NRMSE per output.
    pub nrmse: DVector<f64>,
    /// Ljung–Box whiteness test per output.
    pub ljung_box: Vec<LjungBox>,
    /// Mean of e_kᵀ Re⁻¹ e_k (close to p when consistent); `None` if Re is singular.
    pub nis_mean: Option<f64>,
    /// p, the NIS mean's reference.
    pub outputs: usize,
    /// Spectral radius of A − KC.
    pub predictor_spectral_radius: f64,
    /// True when no data were held out and the scores are in-sample.
    pub in_sample: bool,
}

/// The result of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The model in the caller's units, on deviations from each experiment's operating
    /// point (see [`Scaling::operating_points`]), kept columns only.
    pub model: InnovationModel,
    /// The same model in the scaled coordinates identification worked in.
    pub scaled_model: InnovationModel,
    /// Kept columns, scales and operating points.
    pub scaling: Scaling,
    /// Dropped columns.
    pub warnings: Vec<Warning>,
    /// The horizon i used ([`Method::Moesp`]) or the past window p ([`Method::Pbsid`]);
    /// also the predictor's warm-up skipped when scoring.
    pub horizon: usize,
    /// Candidate orders and the choice.
    pub order: OrderSelection,
    /// The chosen model on the held-out data.
    pub validation: ValidationReport,
}

/// Identifies an innovation model from one or more experiments.
///
/// Steps: [`preprocess`]; split each experiment into estimation and held-out parts
/// ([`Holdout`]); [`Subspace::new`] (or [`Pbsid::new`], see [`Method`]) on the
/// estimation parts; for every order 1..=max a [`Subspace::model`] (or
/// [`Pbsid::model`]), its one-step predictor on every experiment, the criterion on the
/// estimation parts' innovations (the first i samples of each, the predictor's
/// transient, are skipped) and the NRMSE on the held-out parts; the order minimising
/// the criterion among models with a stable predictor (or `settings.order`); then the
/// validation of that model on the held-out data.
///
/// # Math
/// Λ̂ = (1/N) Σ e_k e_kᵀ, d = n(2p + l) + pl (the free parameters of an innovation-form
/// model up to a change of state basis; K's np included). AIC = N log det Λ̂ + 2d,
/// BIC = N log det Λ̂ + d log N. Ref.: Ljung (1999), ch. 16 (criteria of the form
/// N log det Λ̂ + penalty, AIC and Rissanen's MDL/BIC); Akaike (1974); Schwarz (1978).
///
/// # Errors
/// The errors of [`preprocess`] and [`Subspace::new`] or [`Pbsid::new`];
/// [`IdentError::InvalidSetting`]
/// for a bad fraction, max order 0, or [`Holdout::LastExperiment`] with one experiment;
/// [`IdentError::ExperimentTooShort`] when an estimation part is shorter than 2i;
/// [`IdentError::OrderAboveRank`] for a fixed order the data do not support;
/// [`IdentError::NoUsableOrder`] when no order gave a stable predictor.
pub fn identify(
    experiments: &[Experiment],
    settings: &IdentSettings,
) -> Result<Identification, IdentError> {
    if settings.max_order == 0 && settings.order.is_none() {
        return Err(IdentError::InvalidSetting {
            name: "max_order",
            why: "must be at least 1".into(),
        });
    }
    let pre = preprocess(experiments, &settings.preprocess)?;
    let (l, p) = (
        pre.scaling.input_columns.len(),
        pre.scaling.output_columns.len(),
    );
    let max_order = settings.order.unwrap_or(settings.max_order);
    let i0 = ((max_order + 1).div_ceil(p) + 1).max(10);
    let horizon = match settings.method {
        Method::Moesp => settings.horizon.unwrap_or(i0),
        Method::Pbsid => settings.horizon.unwrap_or(i0.max(20)),
    };

    // Estimation parts and where each experiment's held-out part starts.
    let (estimation, holdout_start) = split(&pre.experiments, settings.holdout, horizon)?;
    let in_sample = holdout_start.iter().all(|&s| s == usize::MAX);
    let sub = match settings.method {
        Method::Moesp => Engine::Moesp(Subspace::new(&estimation, horizon)?),
        Method::Pbsid => Engine::Pbsid(Pbsid::new(&estimation, horizon, i0.min(horizon))?),
    };
    let supported = sub.max_order();

    let orders: Vec<usize> = match settings.order {
        Some(n) => vec![n],
        None => (1..=settings.max_order.min(supported)).collect(),
    };
    // Every order is independent of the others: they are spread over the cores, and
    // collected in order (the same result as one after the other, bit for bit).
    let outcomes = parallel_map(&orders, |&n| match sub.model(n) {
        Ok(model) => {
            let candidate = evaluate(&model, &pre.experiments, &holdout_start, horizon, l, p)?;
            Ok((candidate, Some(model)))
        }
        Err(err @ IdentError::OrderAboveRank { .. }) => Err(err),
        Err(err) => Ok((
            Candidate {
                order: n,
                aic: f64::INFINITY,
                bic: f64::INFINITY,
                parameters: parameters(n, l, p),
                holdout_nrmse: DVector::from_element(p, f64::NAN),
                predictor_spectral_radius: f64::NAN,
                failure: Some(err.to_string()),
            },
            None,
        )),
    });
    let mut candidates = Vec::with_capacity(orders.len());
    let mut models = Vec::with_capacity(orders.len());
    for outcome in outcomes {
        let (candidate, model) = outcome?;
        candidates.push(candidate);
        models.push(model);
    }

    let best = candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| c.usable())
        .min_by(|(_, a), (_, b)| {
            a.criterion(settings.criterion)
                .total_cmp(&b.criterion(settings.criterion))
        })
        .map(|(k, _)| k);
    let Some(best) = best else {
        let why = candidates
            .last()
            .map(|c| {
                c.failure.clone().unwrap_or_else(|| {
                    format!(
                        "order {}: predictor spectral radius {:.4} ≥ 1",
                        c.order, c.predictor_spectral_radius
                    )
                })
            })
            .unwrap_or_else(|| "no candidate".into());
        return Err(IdentError::NoUsableOrder {
            max_order: orders.last().copied().unwrap_or(0),
            why,
        });
    };
    let chosen = candidates[best].order;
    let reason = reason(&candidates, best, settings, in_sample);
    let scaled_model = models[best].take().ok_or(IdentError::NoUsableOrder {
        max_order: chosen,
        why: "the chosen order lost its model".into(),
    })?;

    let validation = validate_holdout(
        &scaled_model,
        &pre.experiments,
        &holdout_start,
        horizon,
        settings.ljung_box_lags,
    )?;
    let model = to_physical(&scaled_model, &pre.scaling);
    Ok(Identification {
        model,
        scaled_model,
        scaling: pre.scaling,
        warnings: pre.warnings,
        horizon,
        order: OrderSelection {
            singular_values: sub.singular_values().clone(),
            candidates,
            criterion: settings.criterion,
            chosen,
            reason,
        },
        validation,
    })
}

/// The factored data of the chosen method.
enum Engine {
    Moesp(Subspace),
    Pbsid(Pbsid),
}

impl Engine {
    fn max_order(&self) -> usize {
        match self {
            Self::Moesp(s) => s.max_order(),
            Self::Pbsid(s) => s.max_order(),
        }
    }

    fn model(&self, n: usize) -> Result<InnovationModel, IdentError> {
        match self {
            Self::Moesp(s) => s.model(n),
            Self::Pbsid(s) => s.model(n),
        }
    }

    fn singular_values(&self) -> &DVector<f64> {
        match self {
            Self::Moesp(s) => s.singular_values(),
            Self::Pbsid(s) => s.singular_values(),
        }
    }
}

/// d = n(2p + l) + pl.
fn parameters(n: usize, l: usize, p: usize) -> usize {
    n * (2 * p + l) + p * l
}

/// Estimation parts, and per experiment the first held-out row (usize::MAX: none).
fn split(
    experiments: &[Experiment],
    holdout: Holdout,
    horizon: usize,
) -> Result<(Vec<Experiment>, Vec<usize>), IdentError> {
    let mut estimation = Vec::with_capacity(experiments.len());
    let mut starts = Vec::with_capacity(experiments.len());
    match holdout {
        Holdout::LastFraction(f) => {
            if !(0.0..=0.9).contains(&f) {
                return Err(IdentError::InvalidSetting {
                    name: "holdout",
                    why: format!("the held-out fraction must be in [0, 0.9], got {f}"),
                });
            }
            for (e, exp) in experiments.iter().enumerate() {
                let n = exp.samples();
                let held = (n as f64 * f).floor() as usize;
                let keep = n - held;
                if keep < min_samples(horizon) {
                    return Err(IdentError::ExperimentTooShort {
                        experiment: e,
                        samples: keep,
                        part: " in its estimation part",
                        horizon,
                        needed: min_samples(horizon),
                    });
                }
                estimation.push(exp.rows(0, keep));
                starts.push(if held == 0 { usize::MAX } else { keep });
            }
        }
        Holdout::LastExperiment => {
            if experiments.len() < 2 {
                return Err(IdentError::InvalidSetting {
                    name: "holdout",
                    why: "holding out the last experiment needs at least two".into(),
                });
            }
            let last = experiments.len() - 1;
            estimation.extend(experiments[..last].iter().cloned());
            starts.extend(std::iter::repeat_n(usize::MAX, last));
            starts.push(0);
        }
    }
    Ok((estimation, starts))
}

/// Innovations of the estimation parts (after the transient) and of the held-out parts.
struct Scored {
    estimation: Vec<DMatrix<f64>>,
    held_out_y: Vec<DMatrix<f64>>,
    held_out_pred: Vec<DMatrix<f64>>,
    held_out_innov: Vec<DMatrix<f64>>,
}

fn score(
    model: &InnovationModel,
    experiments: &[Experiment],
    holdout_start: &[usize],
    warmup: usize,
) -> Result<Scored, IdentError> {
    let mut s = Scored {
        estimation: Vec::new(),
        held_out_y: Vec::new(),
        held_out_pred: Vec::new(),
        held_out_innov: Vec::new(),
    };
    let in_sample = holdout_start.iter().all(|&h| h == usize::MAX);
    for (exp, &start) in experiments.iter().zip(holdout_start) {
        let pred = model.predict(&exp.inputs, &exp.outputs, None)?;
        let n = exp.samples();
        let est_end = start.min(n);
        // A held-out whole experiment starts cold: skip its transient too.
        let held_from = if start == 0 { warmup.min(n) } else { start };
        if est_end > warmup {
            s.estimation
                .push(pred.innovations.rows(warmup, est_end - warmup).into_owned());
        }
        let (from, to) = if in_sample {
            (warmup.min(n), n)
        } else if start == usize::MAX {
            continue;
        } else {
            (held_from, n)
        };
        if to > from {
            s.held_out_y
                .push(exp.outputs.rows(from, to - from).into_owned());
            s.held_out_pred
                .push(pred.predicted.rows(from, to - from).into_owned());
            s.held_out_innov
                .push(pred.innovations.rows(from, to - from).into_owned());
        }
    }
    Ok(s)
}

fn vstack(parts: &[DMatrix<f64>], cols: usize) -> DMatrix<f64> {
    let rows = parts.iter().map(DMatrix::nrows).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut r = 0;
    for part in parts {
        out.rows_mut(r, part.nrows()).copy_from(part);
        r += part.nrows();
    }
    out
}

fn evaluate(
    model: &InnovationModel,
    experiments: &[Experiment],
    holdout_start: &[usize],
    warmup: usize,
    l: usize,
    p: usize,
) -> Result<Candidate, IdentError> {
    let n = model.order();
    let radius = model.predictor_spectral_radius();
    let d = parameters(n, l, p);
    if radius >= 1.0 {
        return Ok(Candidate {
            order: n,
            aic: f64::INFINITY,
            bic: f64::INFINITY,
            parameters: d,
            holdout_nrmse: DVector::from_element(p, f64::NAN),
            predictor_spectral_radius: radius,
            failure: Some(format!(
                "predictor A − KC unstable (spectral radius {radius:.4})"
            )),
        });
    }
    let s = score(model, experiments, holdout_start, warmup)?;
    let e = vstack(&s.estimation, p);
    let samples = e.nrows() as f64;
    let lambda = e.transpose() * &e / samples.max(1.0);
    let log_det = lambda
        .clone()
        .cholesky()
        .map(|ch| 2.0 * ch.l().diagonal().iter().map(|v| v.ln()).sum::<f64>())
        .unwrap_or(f64::INFINITY);
    let fit = samples * log_det;
    let holdout_nrmse = nrmse(&vstack(&s.held_out_y, p), &vstack(&s.held_out_pred, p));
    Ok(Candidate {
        order: n,
        aic: fit + 2.0 * d as f64,
        bic: fit + d as f64 * samples.ln(),
        parameters: d,
        holdout_nrmse,
        predictor_spectral_radius: radius,
        failure: None,
    })
}

fn mean(v: &DVector<f64>) -> f64 {
    if v.is_empty() { f64::NAN } else { v.mean() }
}

fn reason(
    candidates: &[Candidate],
    best: usize,
    settings: &IdentSettings,
    in_sample: bool,
) -> String {
    let c = &candidates[best];
    let name = match settings.criterion {
        Criterion::Aic => "AIC",
        Criterion::Bic => "BIC",
    };
    let data = if in_sample { "in-sample" } else { "held-out" };
    let mut text = if settings.order.is_some() {
        format!("order {} fixed by the settings", c.order)
    } else {
        format!(
            "order {}: lowest {name} ({:.1}) among orders {}..={} with a stable predictor",
            c.order,
            c.criterion(settings.criterion),
            candidates.first().map_or(0, |c| c.order),
            candidates.last().map_or(0, |c| c.order),
        )
    };
    let _ = write!(text, "; {data} mean NRMSE {:.4}", mean(&c.holdout_nrmse));
    if let Some(fit_best) = candidates
        .iter()
        .filter(|c| c.usable())
        .min_by(|a, b| mean(&a.holdout_nrmse).total_cmp(&mean(&b.holdout_nrmse)))
        && fit_best.order != c.order
    {
        let _ = write!(
            text,
            " (best {data} fit {:.4} at order {})",
            mean(&fit_best.holdout_nrmse),
            fit_best.order
        );
    }
    let unusable: Vec<usize> = candidates
        .iter()
        .filter(|c| !c.usable())
        .map(|c| c.order)
        .collect();
    if !unusable.is_empty() {
        let _ = write!(text, "; orders {unusable:?} gave no usable model");
    }
    text
}

fn validate_holdout(
    model: &InnovationModel,
    experiments: &[Experiment],
    holdout_start: &[usize],
    warmup: usize,
    lags: usize,
) -> Result<ValidationReport, IdentError> {
    let p = model.outputs();
    let s = score(model, experiments, holdout_start, warmup)?;
    let in_sample = holdout_start.iter().all(|&h| h == usize::MAX);
    // Whiteness and NIS per held-out part, pooled by concatenation: the few lag
    // products across a boundary are an O(lags/N) share of each sum.
    let innov = vstack(&s.held_out_innov, p);
    Ok(ValidationReport {
        samples: innov.nrows(),
        nrmse: nrmse(&vstack(&s.held_out_y, p), &vstack(&s.held_out_pred, p)),
        ljung_box: ljung_box(&innov, lags),
        nis_mean: nis_mean(&innov, &model.re),
        outputs: p,
        predictor_spectral_radius: model.predictor_spectral_radius(),
        in_sample,
    })
}

/// Validates `model` on deviation data (`inputs` N × l, `outputs` N × p, in the model's
/// units and columns): the one-step predictor from x̂₀ = 0, the first `warmup` samples
/// skipped, then NRMSE, Ljung–Box with `lags` lags, and the NIS mean.
///
/// # Errors
/// The errors of [`InnovationModel::predict`].
pub fn validate(
    model: &InnovationModel,
    inputs: &DMatrix<f64>,
    outputs: &DMatrix<f64>,
    warmup: usize,
    lags: usize,
) -> Result<ValidationReport, IdentError> {
    let pred = model.predict(inputs, outputs, None)?;
    let n = outputs.nrows();
    let from = warmup.min(n);
    let innov = pred.innovations.rows(from, n - from).into_owned();
    Ok(ValidationReport {
        samples: n - from,
        nrmse: nrmse(
            &outputs.rows(from, n - from).into_owned(),
            &pred.predicted.rows(from, n - from).into_owned(),
        ),
        ljung_box: ljung_box(&innov, lags),
        nis_mean: nis_mean(&innov, &model.re),
        outputs: model.outputs(),
        predictor_spectral_radius: model.predictor_spectral_radius(),
        in_sample: false,
    })
}

/// The scaled model in the caller's units: with u_s = Σ_u⁻¹ (u − u₀), y_s = Σ_y⁻¹ (y − y₀),
/// B = B_s Σ_u⁻¹, C = Σ_y C_s, D = Σ_y D_s Σ_u⁻¹, K = K_s Σ_y⁻¹, Re = Σ_y Re_s Σ_y,
/// S = S_s Σ_y, R = Σ_y R_s Σ_y; A, Q, P unchanged (the state is not rescaled).
#[must_use]
pub fn to_physical(scaled: &InnovationModel, scaling: &Scaling) -> InnovationModel {
    let su = &scaling.input_scale;
    let sy = &scaling.output_scale;
    let inv_u = DMatrix::from_diagonal(&su.map(|s| 1.0 / s));
    let sy_m = DMatrix::from_diagonal(sy);
    let inv_y = DMatrix::from_diagonal(&sy.map(|s| 1.0 / s));
    InnovationModel {
        a: scaled.a.clone(),
        b: &scaled.b * &inv_u,
        c: &sy_m * &scaled.c,
        d: &sy_m * &scaled.d * &inv_u,
        k: &scaled.k * &inv_y,
        re: &sy_m * &scaled.re * &sy_m,
        q: scaled.q.clone(),
        s: &scaled.s * &sy_m,
        r: &sy_m * &scaled.r * &sy_m,
        p: scaled.p.clone(),
    }
}

/// `f` of every item, in order, computed on up to as many threads as the machine has
/// cores (contiguous runs of items per thread); a thread that panicked has its items
/// computed again on the caller's.
fn parallel_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, std::num::NonZero::get)
        .min(items.len())
        .max(1);
    let chunk = items.len().div_ceil(threads).max(1);
    std::thread::scope(|scope| {
        let f = &f;
        let handles: Vec<_> = items
            .chunks(chunk)
            .map(|part| {
                (
                    part,
                    scope.spawn(move || part.iter().map(f).collect::<Vec<R>>()),
                )
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|(part, h)| h.join().unwrap_or_else(|_| part.iter().map(f).collect()))
            .collect()
    })
}
