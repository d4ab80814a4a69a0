//! Closed-loop identification (fixed seeds): PBSID-opt (Chiuso 2007) against PO-MOESP on
//! data recorded under PI control, and PBSID-opt on open-loop data.

mod support;

use glrmon_ident::{Experiment, IdentSettings, Identification, Method, identify, spectral_radius};
use nalgebra::{DMatrix, DVector};
use support::{Rng, Truth, markov_error, noise_markov_error, pole_error, re_error};

/// Controller gains, dither and samples of the closed-loop record. The dither is needed:
/// without it the PI law makes u0_k an exact linear function of the past window and
/// the VARX regression is collinear (asserted in the sweep); σ = 0.3 is small next to
/// the feedback part of u0 (a unit dither makes the loop nearly open and PO-MOESP's
/// Markov error falls to 0.035–0.046, inside the tolerance).
const KP: f64 = 0.2;
const KI: f64 = 0.02;
const DITHER: f64 = 0.3;
const SAMPLES: usize = 30_000;

fn settings(method: Method) -> IdentSettings {
    IdentSettings {
        method,
        max_order: 8,
        ..IdentSettings::default()
    }
}

/// The loop u0 ← y0 around the truth: the PI controller acts on the previous sample,
/// u0_k = kp (r − y0_{k−1}) + I_k + d_k, I_{k+1} = I_k + ki (r − y0_{k−1}) (r = 0, the
/// setpoint is removed with the operating point anyway), d_k a white dither of standard
/// deviation `dither`; u1 open-loop white noise of unit variance. The one-sample delay
/// keeps the loop well posed although D[0,0] = 0.1: u0_k depends on e_{k−1} and older
/// innovations only, never on e_k. Returns (u, y), N × 2 and N × 3, after a 500-sample
/// burn-in.
fn closed_loop(
    truth: &Truth,
    samples: usize,
    dither: f64,
    rng: &mut Rng,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, p) = (truth.a.nrows(), truth.c.nrows());
    let chol = truth
        .re
        .clone()
        .cholesky()
        .expect("Re positive definite")
        .l();
    let burn = 500;
    let mut x = DVector::zeros(n);
    let mut integral = 0.0;
    let mut y_prev = 0.0;
    let mut u = DMatrix::zeros(samples, 2);
    let mut y = DMatrix::zeros(samples, p);
    for k in 0..burn + samples {
        let error = -y_prev;
        let uk = DVector::from_vec(vec![
            KP * error + integral + dither * rng.normal(),
            rng.normal(),
        ]);
        integral += KI * error;
        let e = &chol * DVector::from_fn(p, |_, _| rng.normal());
        let yk = &truth.c * &x + &truth.d * &uk + &e;
        y_prev = yk[0];
        if k >= burn {
            u.set_row(k - burn, &uk.transpose());
            y.set_row(k - burn, &yk.transpose());
        }
        x = &truth.a * &x + &truth.b * &uk + &truth.k * &e;
    }
    (u, y)
}

/// Spectral radius of the closed loop: state [x; I; y0_{k−1}].
fn loop_radius(truth: &Truth) -> f64 {
    let n = truth.a.nrows();
    let mut m = DMatrix::zeros(n + 2, n + 2);
    let b0 = truth.b.column(0);
    let c0 = truth.c.row(0);
    let d00 = truth.d[(0, 0)];
    m.view_mut((0, 0), (n, n)).copy_from(&truth.a);
    // u0 = −kp m + I.
    for r in 0..n {
        m[(r, n)] = b0[r];
        m[(r, n + 1)] = -KP * b0[r];
    }
    m[(n, n)] = 1.0;
    m[(n, n + 1)] = -KI;
    for c in 0..n {
        m[(n + 1, c)] = c0[c];
    }
    m[(n + 1, n)] = d00;
    m[(n + 1, n + 1)] = -KP * d00;
    spectral_radius(&m)
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
        id.order
            .singular_values
            .rows(0, id.order.singular_values.len().min(10))
            .transpose()
    );
    println!("{name}: poles {:.4?}", id.model.poles());
    println!(
        "{name}: pole error {poles:.4}, Markov error (D, CA^jB, j<6) {markov:.4}, noise Markov \
         error (CA^jK) {noise:.4}, Re error {re:.4}, predictor radius {:.4}, NIS {:.3}",
        id.validation.predictor_spectral_radius,
        id.validation.nis_mean.unwrap_or(f64::NAN)
    );
    (poles, markov, noise, re)
}

#[test]
fn closed_loop_pbsid_recovers_the_system_and_moesp_does_not() {
    let truth = Truth::four_state();
    let radius = loop_radius(&truth);
    println!(
        "closed loop: kp {KP}, ki {KI}, dither σ {DITHER}; loop spectral radius {radius:.4}, \
         predictor A − KC radius {:.4}",
        truth.model().predictor_spectral_radius()
    );
    assert!(radius < 1.0);
    let mut rng = Rng::new(40);
    let (u, y) = closed_loop(&truth, SAMPLES, DITHER, &mut rng);
    let data = [Experiment::new(u, y)];

    let pbsid = identify(&data, &settings(Method::Pbsid)).unwrap();
    let (poles, markov, noise, re) = report("closed loop, PBSID", &pbsid, &truth);
    let moesp = identify(&data, &settings(Method::Moesp)).unwrap();
    let (moesp_poles, moesp_markov, _, moesp_re) = report("closed loop, MOESP", &moesp, &truth);

    assert_eq!(pbsid.order.chosen, 4, "{}", pbsid.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(noise < 0.15, "noise Markov error {noise}");
    assert!(re < 0.1, "Re error {re}");
    // Why PBSID exists: PO-MOESP on the same record is outside those tolerances.
    assert!(
        moesp.order.chosen != 4 || moesp_poles > 0.03,
        "MOESP: order {}, pole error {moesp_poles}",
        moesp.order.chosen
    );
    assert!(moesp_poles > 0.03, "MOESP pole error {moesp_poles}");
    assert!(moesp_markov > 0.05, "MOESP Markov error {moesp_markov}");
    println!("closed loop, MOESP: Markov {moesp_markov:.4}, Re {moesp_re:.4}");
    // At the true order PO-MOESP's bias is in B, D and the noise path: the Markov
    // parameters are 4× outside the tolerance on every seed of the sweep below; its poles
    // are off by more than 0.03 on 8 of those 12 seeds only, so they are printed.
    let fixed = identify(
        &data,
        &IdentSettings {
            order: Some(4),
            ..settings(Method::Moesp)
        },
    )
    .unwrap();
    let (_, fixed_markov, fixed_noise, _) = report("closed loop, MOESP order 4", &fixed, &truth);
    assert!(
        fixed_markov > 0.1,
        "MOESP order 4 Markov error {fixed_markov}"
    );
    assert!(
        fixed_noise > 0.15,
        "MOESP order 4 noise Markov error {fixed_noise}"
    );
}

#[test]
fn closed_loop_pbsid_on_two_experiments_never_uses_the_join() {
    // Two closed-loop records of half the length at different operating points (inputs
    // +5, outputs +50): each experiment's regressions stay inside it.
    let truth = Truth::four_state();
    let mut experiments = Vec::new();
    for (seed, offset) in [(41, 0.0), (42, 50.0)] {
        let mut rng = Rng::new(seed);
        let (u, y) = closed_loop(&truth, SAMPLES / 2, DITHER, &mut rng);
        experiments.push(Experiment::new(
            u.add_scalar(offset / 10.0),
            y.add_scalar(offset),
        ));
    }
    let id = identify(&experiments, &settings(Method::Pbsid)).unwrap();
    let (poles, markov, noise, re) = report("closed loop, two experiments, PBSID", &id, &truth);
    assert_eq!(id.order.chosen, 4, "{}", id.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(noise < 0.15, "noise Markov error {noise}");
    assert!(re < 0.1, "Re error {re}");
    let again = identify(&experiments, &settings(Method::Pbsid)).unwrap();
    assert_eq!(id, again, "identification is not deterministic");

    // Falsification: the same records joined into one experiment carry the step.
    let joined = Experiment::new(
        vstack(&experiments[0].inputs, &experiments[1].inputs),
        vstack(&experiments[0].outputs, &experiments[1].outputs),
    );
    let bad = identify(&[joined], &settings(Method::Pbsid)).unwrap();
    let markov_bad = markov_error(&bad.model, &truth, 6);
    println!(
        "closed loop, joined with a step: chosen order {}, Markov error {markov_bad:.4}",
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

#[test]
fn open_loop_pbsid_recovers_the_system() {
    let truth = Truth::four_state();
    let mut rng = Rng::new(20);
    let u = rng.normals(10_000, 2);
    let y = truth.simulate(&u, &mut rng);
    let id = identify(&[Experiment::new(u, y)], &settings(Method::Pbsid)).unwrap();
    let (poles, markov, noise, re) = report("open loop, PBSID", &id, &truth);
    assert_eq!(id.order.chosen, 4, "{}", id.order.reason);
    assert!(poles < 0.03, "pole error {poles}");
    assert!(markov < 0.05, "Markov error {markov}");
    assert!(noise < 0.15, "noise Markov error {noise}");
    assert!(re < 0.1, "Re error {re}");
}

#[test]
fn closed_loop_seed_sweep() {
    // Twelve seeds at the test's dither, and the same seeds without dither and with a
    // unit dither: what holds for every seed is asserted, the rest printed.
    let truth = Truth::four_state();
    let mut worst = [0.0_f64; 2];
    let mut beyond = 0;
    for seed in 100..112 {
        let mut rng = Rng::new(seed);
        let (u, y) = closed_loop(&truth, SAMPLES, DITHER, &mut rng);
        let data = [Experiment::new(u, y)];
        let id = identify(&data, &settings(Method::Pbsid)).unwrap();
        let fixed = identify(
            &data,
            &IdentSettings {
                order: Some(4),
                ..settings(Method::Moesp)
            },
        )
        .unwrap();
        let poles = pole_error(&id.model.poles(), &truth.a);
        let markov = markov_error(&id.model, &truth, 6);
        let noise = noise_markov_error(&id.model, &truth, 6);
        let re = re_error(&id.model.re, &truth.re);
        let moesp_poles = pole_error(&fixed.model.poles(), &truth.a);
        let moesp_markov = markov_error(&fixed.model, &truth, 6);
        println!(
            "seed {seed}: PBSID order {}, poles {poles:.4}, Markov {markov:.4}, noise {noise:.4}, \
             Re {re:.4} | MOESP order 4: poles {moesp_poles:.4}, Markov {moesp_markov:.4}",
            id.order.chosen
        );
        assert_eq!(id.order.chosen, 4, "seed {seed}: {}", id.order.reason);
        assert!(markov < 0.05, "seed {seed}: Markov error {markov}");
        assert!(noise < 0.15, "seed {seed}: noise Markov error {noise}");
        assert!(re < 0.1, "seed {seed}: Re error {re}");
        assert!(
            moesp_markov > 0.1,
            "seed {seed}: MOESP Markov error {moesp_markov}"
        );
        worst[0] = worst[0].max(poles);
        worst[1] = worst[1].max(markov);
        beyond += usize::from(poles >= 0.03);
    }
    println!(
        "sweep: worst PBSID pole error {:.4}, worst Markov error {:.4}, {beyond} of 12 seeds \
         with a pole error ≥ 0.03",
        worst[0], worst[1]
    );
    assert!(worst[0] < 0.05, "worst pole error {}", worst[0]);

    // Without dither, u0_k is an exact linear function of u0_{k−1}, y0_{k−1}, y0_{k−2}:
    // the past window is collinear, the data say nothing about u0's path (a PI
    // controller is not complex enough for a 4-state plant, Ljung 1999 §13.4). An
    // error, not a wrong model.
    let mut rng = Rng::new(100);
    let (u, y) = closed_loop(&truth, SAMPLES, 0.0, &mut rng);
    let err = identify(&[Experiment::new(u, y)], &settings(Method::Pbsid)).unwrap_err();
    println!("no dither: {err}");
    assert!(
        matches!(err, glrmon_ident::IdentError::NotPositiveDefinite { .. })
            && err.to_string().contains("collinear"),
        "{err}"
    );
}

#[test]
fn pbsid_bad_input_is_an_error_never_a_panic() {
    // Random shapes and values, some extreme, constant or collinear: Ok or Err.
    let mut rng = Rng::new(43);
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
        if case % 5 == 0 && l > 0 {
            // An input that copies the previous output: a collinear past window.
            for k in 1..n {
                u[(k, 0)] = y[(k - 1, 0)];
            }
        }
        if case % 11 == 0 {
            y.column_mut(0).fill(-1.0);
        }
        let settings = IdentSettings {
            method: Method::Pbsid,
            max_order: 1 + (rng.next_u64() % 6) as usize,
            horizon: Some((rng.next_u64() % 8) as usize),
            ..IdentSettings::default()
        };
        let _ = identify(&[Experiment::new(u, y)], &settings);
    }
}
