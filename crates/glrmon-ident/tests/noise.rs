//! Autocovariance least squares (`estimate_noise`) on simulated known systems.

mod support;

use glrmon_ident::{
    CrossCovariance, Experiment, IdentError, NoiseEstimate, NoiseSettings, NoiseStructure,
    PhysicalModel, Structure, estimate_noise, nis_mean, solve_riccati,
};
use nalgebra::{DMatrix, DVector};
use support::Rng;

/// A plant with its true noise: w = G_w ξ, cov([ξ; v]) = [[Q_w, S_w], [S_wᵀ, R]].
struct Plant {
    model: PhysicalModel,
    gw: DMatrix<f64>,
    qw: DMatrix<f64>,
    r: DMatrix<f64>,
    sw: DMatrix<f64>,
}

impl Plant {
    fn q(&self) -> DMatrix<f64> {
        &self.gw * &self.qw * self.gw.transpose()
    }

    fn s(&self) -> DMatrix<f64> {
        &self.gw * &self.sw
    }

    /// True steady Kalman gain and innovation covariance.
    fn kalman(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let sol = solve_riccati(&self.model.f, &self.model.h, &self.q(), &self.s(), &self.r)
            .expect("true Riccati");
        (sol.k, sol.re)
    }

    /// Outputs for `u` from state `x0`, after `burn` zero-input steps.
    fn simulate(
        &self,
        u: &DMatrix<f64>,
        x0: &DVector<f64>,
        burn: usize,
        rng: &mut Rng,
    ) -> DMatrix<f64> {
        let m = &self.model;
        let (g, p) = (self.gw.ncols(), m.outputs());
        let mut joint = DMatrix::zeros(g + p, g + p);
        joint.view_mut((0, 0), (g, g)).copy_from(&self.qw);
        joint.view_mut((g, g), (p, p)).copy_from(&self.r);
        joint.view_mut((0, g), (g, p)).copy_from(&self.sw);
        joint
            .view_mut((g, 0), (p, g))
            .copy_from(&self.sw.transpose());
        let chol = joint.cholesky().expect("joint noise covariance PD").l();
        let mut x = x0.clone();
        let mut y = DMatrix::zeros(u.nrows(), p);
        let zero_u = DVector::zeros(u.ncols());
        for k in 0..burn + u.nrows() {
            let uk = if k < burn {
                zero_u.clone()
            } else {
                u.row(k - burn).transpose()
            };
            let z = &chol * DVector::from_fn(g + p, |_, _| rng.normal());
            let xi = z.rows(0, g);
            let v = z.rows(g, p);
            let yk = &m.h * &x + &m.j * &uk + v;
            if k >= burn {
                y.set_row(k - burn, &yk.transpose());
            }
            x = &m.f * &x + &m.g * &uk + &self.gw * xi;
        }
        y
    }

    /// A stationary experiment of `n` samples with a white normal input.
    fn experiment(&self, n: usize, rng: &mut Rng) -> Experiment {
        let u = rng.normals(n, self.model.inputs());
        let x0 = DVector::zeros(self.model.order());
        let y = self.simulate(&u, &x0, 500, rng);
        Experiment::new(u, y)
    }
}

/// Rows of a matrix on one line.
fn show(m: &DMatrix<f64>) -> String {
    let rows: Vec<String> = m
        .row_iter()
        .map(|r| {
            let v: Vec<String> = r.iter().map(|x| format!("{x:.4}")).collect();
            v.join(", ")
        })
        .collect();
    format!("[{}]", rows.join("; "))
}

fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

/// 3 states, 1 input, 2 outputs; poles 0.9, 0.6 ± 0.3i; full Q, full R, S = 0.
fn three_state() -> Plant {
    Plant {
        model: PhysicalModel::new(
            DMatrix::from_row_slice(3, 3, &[0.9, 0.1, 0.0, 0.0, 0.6, 0.3, 0.0, -0.3, 0.6]),
            DMatrix::from_row_slice(3, 1, &[1.0, 0.5, 0.0]),
            DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.5, 0.0, 1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.1, 0.0]),
        ),
        gw: DMatrix::identity(3, 3),
        qw: DMatrix::from_row_slice(3, 3, &[0.5, 0.1, 0.0, 0.1, 0.3, 0.05, 0.0, 0.05, 0.2]),
        r: DMatrix::from_row_slice(2, 2, &[0.4, 0.1, 0.1, 0.3]),
        sw: DMatrix::zeros(3, 2),
    }
}

/// 2 states, 1 input, 2 outputs; full Q, full R, S = 0.
fn two_state() -> Plant {
    Plant {
        model: PhysicalModel::new(
            DMatrix::from_row_slice(2, 2, &[0.8, 0.2, -0.1, 0.7]),
            DMatrix::from_row_slice(2, 1, &[1.0, 0.5]),
            DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.3, 1.0]),
            DMatrix::from_row_slice(2, 1, &[0.1, 0.0]),
        ),
        gw: DMatrix::identity(2, 2),
        qw: DMatrix::from_row_slice(2, 2, &[0.5, 0.15, 0.15, 0.3]),
        r: DMatrix::from_row_slice(2, 2, &[0.4, 0.1, 0.1, 0.3]),
        sw: DMatrix::zeros(2, 2),
    }
}

/// three_state's F, G, H with one noise source w = G_w ξ correlated with v (S ≠ 0).
fn correlated() -> Plant {
    let base = three_state();
    Plant {
        model: base.model,
        gw: DMatrix::from_row_slice(3, 1, &[1.0, 0.5, 0.2]),
        qw: DMatrix::from_element(1, 1, 0.5),
        r: DMatrix::from_row_slice(2, 2, &[0.4, 0.1, 0.1, 0.3]),
        sw: DMatrix::from_row_slice(1, 2, &[0.2, -0.1]),
    }
}

fn correlated_settings() -> NoiseSettings {
    NoiseSettings {
        structure: NoiseStructure {
            noise_input: Some(correlated().gw),
            q: Structure::Full,
            r: Structure::Full,
            s: CrossCovariance::Free,
        },
        ..NoiseSettings::default()
    }
}

/// Relative Frobenius errors of Q, R, K, Re against the truth.
fn errors(plant: &Plant, est: &NoiseEstimate) -> (f64, f64, f64, f64) {
    let (k, re) = plant.kalman();
    (
        rel(&est.q, &plant.q()),
        rel(&est.r, &plant.r),
        rel(&est.k, &k),
        rel(&est.re, &re),
    )
}

/// NIS mean of the estimated filter on a fresh record of 20 000 samples (first 200
/// skipped) and its z-score against p, with σ = √(2p/N) (white innovations, χ²_p).
fn fresh_nis(plant: &Plant, est: &NoiseEstimate, rng: &mut Rng) -> (f64, f64) {
    let fresh = plant.experiment(20_000, rng);
    let pred = est
        .innovation_model(&plant.model)
        .predict(&fresh.inputs, &fresh.outputs, None)
        .unwrap();
    let used = pred.innovations.rows(200, 19_800).into_owned();
    let nis = nis_mean(&used, &est.re).unwrap();
    let p = plant.model.outputs() as f64;
    (nis, (nis - p) / (2.0 * p / used.nrows() as f64).sqrt())
}

fn concatenate(experiments: &[Experiment]) -> Experiment {
    let total: usize = experiments.iter().map(Experiment::samples).sum();
    let (l, p) = (
        experiments[0].inputs.ncols(),
        experiments[0].outputs.ncols(),
    );
    let (mut u, mut y) = (DMatrix::zeros(total, l), DMatrix::zeros(total, p));
    let mut row = 0;
    for e in experiments {
        u.rows_mut(row, e.samples()).copy_from(&e.inputs);
        y.rows_mut(row, e.samples()).copy_from(&e.outputs);
        row += e.samples();
    }
    Experiment::new(u, y)
}

// Tolerances below come from `seed_sweep` (20 seeds, 40 000 samples
// each, plus 20 more seeds of the correlated case in an earlier run): the worst relative
// Frobenius errors seen were, full Q: Q 3.4 %, R 5.1 %, K 3.0 %, Re 1.3 %, |z(NIS)| 2.2;
// correlated: Q 3.3 %, R 6.6 %, S 9.6 %, K 1.8 %, Re 1.75 %, |z(NIS)| 3.4. Each
// tolerance is about twice the worst seen. The fresh-data NIS z-score contains the
// estimation error of Re as well as the sampling error, hence the wide worst case; the
// 4σ bound was asked for and holds on all 40 correlated seeds.

#[test]
fn full_q_and_r_of_a_two_state_system_with_an_input() {
    let plant = two_state();
    let mut rng = Rng::new(7);
    let exp = plant.experiment(40_000, &mut rng);
    let est = estimate_noise(&plant.model, &[exp], &NoiseSettings::default()).unwrap();
    let (eq, er, ek, ere) = errors(&plant, &est);
    let (nis, z) = fresh_nis(&plant, &est, &mut rng);
    eprintln!(
        "Q̂ = {} (true {}), R̂ = {} (true {}); errors Q {eq:.4} R {er:.4} K {ek:.4} \
         Re {ere:.4}; fresh NIS {nis:.4} (z {z:.2})",
        show(&est.q),
        show(&plant.q()),
        show(&est.r),
        show(&plant.r)
    );
    assert_eq!(est.parameters.len(), 6);
    assert_eq!(est.design_rank, 6);
    assert_eq!(est.iterations.len(), 3);
    assert!(est.s.is_none());
    assert!(eq < 0.08, "Q error {eq}");
    assert!(er < 0.10, "R error {er}");
    assert!(ek < 0.06, "K error {ek}");
    assert!(ere < 0.03, "Re error {ere}");
    assert!(z.abs() < 4.0, "fresh NIS {nis}, z {z}");
    // The in-sample statistics of the final filter are consistent too.
    let in_sample = est.nis_mean.unwrap();
    assert!(
        (in_sample - 2.0).abs() < 4.0 * (4.0_f64 / 39_000.0).sqrt(),
        "{in_sample}"
    );
    assert!(
        est.ljung_box.iter().all(|lb| lb.p_value > 1e-3),
        "{:?}",
        est.ljung_box
    );
}

#[test]
fn correlated_noises_give_s_through_a_noise_input_matrix() {
    let plant = correlated();
    let mut rng = Rng::new(107);
    let exp = plant.experiment(40_000, &mut rng);
    let est = estimate_noise(&plant.model, &[exp], &correlated_settings()).unwrap();
    let (eq, er, ek, ere) = errors(&plant, &est);
    let s_hat = est.s.as_ref().expect("S estimated");
    let es = rel(s_hat, &plant.s());
    let (nis, z) = fresh_nis(&plant, &est, &mut rng);
    eprintln!(
        "Q_w {:.4} (true 0.5), S_w = {} (true [0.2, −0.1]), R̂ = {} (true {}); errors \
         Q {eq:.4} R {er:.4} S {es:.4} K {ek:.4} Re {ere:.4}; fresh NIS {nis:.4} (z {z:.2})",
        est.q_w[(0, 0)],
        show(est.s_w.as_ref().unwrap()),
        show(&est.r),
        show(&plant.r)
    );
    assert_eq!(
        est.parameters,
        [
            "Q_w[0,0]", "R[0,0]", "R[0,1]", "R[1,1]", "S_w[0,0]", "S_w[0,1]"
        ]
    );
    assert!(eq < 0.08, "Q error {eq}");
    assert!(er < 0.13, "R error {er}");
    assert!(es < 0.20, "S error {es}");
    assert!(ek < 0.05, "K error {ek}");
    assert!(ere < 0.04, "Re error {ere}");
    assert!(z.abs() < 4.0, "fresh NIS {nis}, z {z}");
    // Ignoring the correlation (S = 0) gives a worse gain than estimating it.
    let mut no_s = correlated_settings();
    no_s.structure.s = CrossCovariance::Zero;
    let exp = plant.experiment(40_000, &mut Rng::new(107));
    let without = estimate_noise(&plant.model, &[exp], &no_s).unwrap();
    let (_, _, ek0, _) = errors(&plant, &without);
    eprintln!("K error with S forced to 0: {ek0:.4}");
    assert!(ek0 > 2.0 * ek, "K error {ek0} with S = 0 vs {ek} with S");
}

#[test]
fn two_experiments_match_one_and_joins_are_never_used() {
    let plant = two_state();
    let settings = NoiseSettings::default();
    // One stationary record, and the same record cut in two: only the ≈ 2 × 15 lag
    // products across the cut and one transient differ.
    let mut rng = Rng::new(201);
    let exp = plant.experiment(40_000, &mut rng);
    let one = estimate_noise(&plant.model, std::slice::from_ref(&exp), &settings).unwrap();
    let halves: Vec<Experiment> = [0, 20_000]
        .iter()
        .map(|&start| {
            Experiment::new(
                exp.inputs.rows(start, 20_000).into_owned(),
                exp.outputs.rows(start, 20_000).into_owned(),
            )
        })
        .collect();
    let two = estimate_noise(&plant.model, &halves, &settings).unwrap();
    let diff = rel(&two.q, &one.q).max(rel(&two.r, &one.r));
    eprintln!("one vs two experiments: largest relative difference {diff:.5}");
    // Seen ≤ 0.00074 over 10 seeds; the statistical error itself is ≈ 0.02.
    assert!(diff < 0.005, "{diff}");

    // Ten short experiments, each starting far from equilibrium (x₀ ~ 20 σ): every
    // experiment's transient is skipped. Concatenated, the nine joins are state jumps
    // the predictor must recover from, and they bias the autocovariances.
    let experiments: Vec<Experiment> = (0..10)
        .map(|_| {
            let u = rng.normals(4000, 1);
            let x0 = DVector::from_fn(2, |_, _| 20.0 * rng.normal());
            let y = plant.simulate(&u, &x0, 0, &mut rng);
            Experiment::new(u, y)
        })
        .collect();
    let separate = estimate_noise(&plant.model, &experiments, &settings).unwrap();
    let joined = estimate_noise(&plant.model, &[concatenate(&experiments)], &settings).unwrap();
    let err = |e: &NoiseEstimate| rel(&e.q, &plant.q()).max(rel(&e.r, &plant.r));
    let (es, ej) = (err(&separate), err(&joined));
    eprintln!("ten experiments: error {es:.4} separately, {ej:.4} concatenated");
    // Seen over 10 seeds: separately ≤ 0.041, concatenated ≥ 0.13.
    assert!(es < 0.08, "{es}");
    assert!(ej > 2.0 * es, "concatenated {ej} vs separate {es}");
}

#[test]
fn non_identifiable_structures_are_an_error_naming_the_parameters() {
    // Three states seen through two outputs: a full Q (6) and R (3) give 9 unknowns but
    // the autocovariances fix only 8 combinations.
    let plant = three_state();
    let mut rng = Rng::new(3);
    let exp = plant.experiment(5_000, &mut rng);
    let err = estimate_noise(
        &plant.model,
        std::slice::from_ref(&exp),
        &NoiseSettings::default(),
    )
    .unwrap_err();
    eprintln!("{err}");
    match &err {
        IdentError::NotIdentifiable {
            rank,
            parameters,
            undetermined,
            ..
        } => {
            assert_eq!((*rank, *parameters), (8, 9));
            assert!(
                undetermined.iter().all(|p| p.starts_with("Q[")),
                "{undetermined:?}"
            );
            assert!(!undetermined.is_empty());
        }
        other => panic!("expected NotIdentifiable, got {other}"),
    }
    assert!(err.to_string().contains("rank 8 for 9 free parameters"));
    // Structural, not a matter of the tolerance: the same at 10⁻¹².
    let strict = NoiseSettings {
        rank_tolerance: 1e-12,
        ..NoiseSettings::default()
    };
    let err = estimate_noise(&plant.model, std::slice::from_ref(&exp), &strict).unwrap_err();
    assert!(
        matches!(err, IdentError::NotIdentifiable { rank: 8, .. }),
        "{err}"
    );
    // A diagonal Q (3 + 3 unknowns) is identifiable for the same system.
    let diagonal = NoiseSettings {
        structure: NoiseStructure {
            q: Structure::Diagonal,
            ..NoiseStructure::default()
        },
        ..NoiseSettings::default()
    };
    let est = estimate_noise(&plant.model, &[exp], &diagonal).unwrap();
    assert_eq!(est.design_rank, 6);

    // A free S with a full Q is never identifiable (more unknowns than K and Re have).
    let plant = two_state();
    let exp = plant.experiment(5_000, &mut rng);
    let free_s = NoiseSettings {
        structure: NoiseStructure {
            s: CrossCovariance::Free,
            ..NoiseStructure::default()
        },
        ..NoiseSettings::default()
    };
    let err = estimate_noise(&plant.model, &[exp], &free_s).unwrap_err();
    eprintln!("{err}");
    assert!(
        matches!(&err, IdentError::NotIdentifiable { rank, parameters: 10, .. } if *rank < 10),
        "{err}"
    );
    assert!(err.to_string().contains("noise input matrix"));
}

#[test]
fn scaling_the_outputs_scales_r_and_s_and_leaves_q() {
    // y → c y with H → c H, J → c J (a change of output units): Q is in state units and
    // unchanged, R → c² R, S → c S, K → K / c, Re → c² Re; the default initial gain
    // scales alike, so every iteration is the same up to rounding.
    let c = 1000.0;
    let plant = correlated();
    let mut rng = Rng::new(11);
    let exp = plant.experiment(20_000, &mut rng);
    let base = estimate_noise(
        &plant.model,
        std::slice::from_ref(&exp),
        &correlated_settings(),
    )
    .unwrap();
    let scaled_model = PhysicalModel::new(
        plant.model.f.clone(),
        plant.model.g.clone(),
        &plant.model.h * c,
        &plant.model.j * c,
    );
    let scaled_exp = Experiment::new(exp.inputs.clone(), &exp.outputs * c);
    let scaled = estimate_noise(&scaled_model, &[scaled_exp], &correlated_settings()).unwrap();
    let checks = [
        ("Q", rel(&scaled.q, &base.q)),
        ("R", rel(&(&scaled.r / (c * c)), &base.r)),
        (
            "S",
            rel(&(scaled.s.as_ref().unwrap() / c), base.s.as_ref().unwrap()),
        ),
        ("K", rel(&(&scaled.k * c), &base.k)),
        ("Re", rel(&(&scaled.re / (c * c)), &base.re)),
        ("P", rel(&scaled.p, &base.p)),
    ];
    eprintln!("relative differences after undoing the scale: {checks:?}");
    for (name, d) in checks {
        assert!(d < 1e-8, "{name}: {d}");
    }
    assert!((scaled.nis_mean.unwrap() - base.nis_mean.unwrap()).abs() < 1e-8);
}

#[test]
fn bad_settings_and_data_are_errors() {
    let plant = two_state();
    let mut rng = Rng::new(5);
    let exp = plant.experiment(100, &mut rng);
    let short = estimate_noise(
        &plant.model,
        std::slice::from_ref(&exp),
        &NoiseSettings {
            transient: Some(90),
            ..NoiseSettings::default()
        },
    )
    .unwrap_err();
    assert!(
        matches!(short, IdentError::InvalidSetting { name: "lags", .. }),
        "{short}"
    );
    assert!(
        short.to_string().contains("experiment 0 has 100 samples"),
        "{short}"
    );
    let err = estimate_noise(&plant.model, &[], &NoiseSettings::default()).unwrap_err();
    assert_eq!(err, IdentError::NoExperiment);
    let mut bad = exp.clone();
    bad.outputs[(3, 1)] = f64::NAN;
    let err = estimate_noise(&plant.model, &[bad], &NoiseSettings::default()).unwrap_err();
    assert!(
        matches!(
            err,
            IdentError::NonFinite {
                row: 3,
                column: 1,
                ..
            }
        ),
        "{err}"
    );
    let wrong_gw = NoiseSettings {
        structure: NoiseStructure {
            noise_input: Some(DMatrix::zeros(3, 1)),
            ..NoiseStructure::default()
        },
        ..NoiseSettings::default()
    };
    let err = estimate_noise(&plant.model, &[exp], &wrong_gw).unwrap_err();
    assert!(
        matches!(
            err,
            IdentError::InvalidSetting {
                name: "noise_input",
                ..
            }
        ),
        "{err}"
    );
}

/// The sweep the tolerances above were derived from, kept as a test: on every one of
/// 20 seeds the estimate stays within the single-seed tests' tolerances (a method that
/// is only right on average would fail here).
#[test]
fn seed_sweep() {
    for (name, settings) in [
        ("full Q", NoiseSettings::default()),
        ("correlated", correlated_settings()),
    ] {
        let plant = if name == "full Q" {
            two_state()
        } else {
            correlated()
        };
        let mut worst = [0.0_f64; 6];
        for seed in 1..=20 {
            let mut rng = Rng::new(seed);
            let exp = plant.experiment(40_000, &mut rng);
            let est = estimate_noise(&plant.model, &[exp], &settings).unwrap();
            let (eq, er, ek, ere) = errors(&plant, &est);
            let es = est.s.as_ref().map_or(0.0, |s| rel(s, &plant.s()));
            let (_, z) = fresh_nis(&plant, &est, &mut rng);
            for (w, v) in worst.iter_mut().zip([eq, er, es, ek, ere, z.abs()]) {
                *w = w.max(v);
            }
        }
        eprintln!("{name}: worst Q, R, S, K, Re, |z| = {worst:.4?}");
        let limits = if name == "full Q" {
            [0.08, 0.10, 0.0, 0.06, 0.03, 4.0]
        } else {
            [0.08, 0.13, 0.20, 0.05, 0.04, 4.0]
        };
        for ((w, limit), what) in worst
            .iter()
            .zip(limits)
            .zip(["Q", "R", "S", "K", "Re", "|z|"])
        {
            assert!(*w <= limit, "{name}: worst {what} error {w} above {limit}");
        }
    }
}
