//! Correlated process and measurement noise (S = E[WVᵀ]): an identified innovation
//! model x⁺ = Ax + Bu + Ke, y = Cx + Du + e runs as Q = K Re Kᵀ, R = Re, S = K Re at its
//! own order, with the exact one-step predictor (Anderson & Moore 1979, §5.5) feeding the
//! GLR of Zhang & Basseville 2014.

use glrmon_core::{
    Column, Fault, FaultDictionary, GlrDetector, Lpv, Onset, Sample, StateSpace, StepOutput,
    WindowSettings,
};
use nalgebra::{DMatrix, DVector};

struct Innovation {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
    k: DMatrix<f64>,
    re: DMatrix<f64>,
}

fn system() -> Innovation {
    Innovation {
        a: DMatrix::from_row_slice(2, 2, &[0.8, 0.3, -0.2, 0.6]),
        b: DMatrix::from_row_slice(2, 1, &[1.0, 0.5]),
        c: DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.4, 1.0]),
        d: DMatrix::from_row_slice(2, 1, &[0.0, 0.2]),
        k: DMatrix::from_row_slice(2, 2, &[0.5, 0.1, -0.2, 0.4]),
        re: DMatrix::from_row_slice(2, 2, &[0.04, 0.01, 0.01, 0.09]),
    }
}

/// splitmix64 + Box-Muller.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (((z ^ (z >> 31)) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Samples (u, y) and the true innovations e, with a sensor bias `bias` on y1 from
/// `onset`.
fn simulate(
    sys: &Innovation,
    len: usize,
    seed: u64,
    bias: f64,
    onset: usize,
) -> Vec<(f64, [f64; 2], [f64; 2])> {
    let mut rng = Rng(seed);
    let l = sys.re.clone().cholesky().unwrap().l();
    let mut x = DVector::zeros(2);
    (0..len)
        .map(|k| {
            let u = (0.07 * k as f64).sin() + 0.3 * rng.normal();
            let e = &l * DVector::from_fn(2, |_, _| rng.normal());
            let mut y = &sys.c * &x + &sys.d * u + &e;
            if k >= onset {
                y[1] += bias;
            }
            x = &sys.a * &x + &sys.b * u + &sys.k * &e;
            (u, [y[0], y[1]], [e[0], e[1]])
        })
        .collect()
}

fn detector(sys: &Innovation, p0: f64, steady_tolerance: f64) -> GlrDetector {
    let q = &sys.k * &sys.re * sys.k.transpose();
    let model = Lpv::lti(
        sys.a.clone(),
        sys.b.clone(),
        sys.c.clone(),
        sys.d.clone(),
        q,
        sys.re.clone(),
    )
    .unwrap();
    let faults = FaultDictionary::new(
        model.dims(),
        vec![
            Fault::output(
                "y0_bias",
                Onset::Step,
                Column::Constant(DVector::from_column_slice(&[1.0, 0.0])),
            ),
            Fault::output(
                "y1_bias",
                Onset::Step,
                Column::Constant(DVector::from_column_slice(&[0.0, 1.0])),
            ),
            Fault::state("u0_bias", Onset::Step, Column::InputBias { input: 0 }),
        ],
    )
    .unwrap();
    GlrDetector::new(
        Box::new(model),
        faults,
        DVector::zeros(2),
        DMatrix::identity(2, 2) * p0,
        WindowSettings {
            window: 200,
            min_lag: 0,
            steady_tolerance,
            ..WindowSettings::default()
        },
    )
    .unwrap()
    .with_cross_covariance(&sys.k * &sys.re)
    .unwrap()
}

/// Started at the true state with P₀ = 0, the predictor of the innovation form is
/// exact: Σ_k = Re and ε_k = e_k at every sample (to rounding). Started with P₀ = I, Σ_k
/// converges to Re. A detector of the same model without S (Q = K Re Kᵀ, R = Re
/// treated as independent) has a larger steady Σ.
#[test]
fn the_innovation_form_has_the_exact_predictor_and_sigma_equal_to_re() {
    let sys = system();
    let data = simulate(&sys, 400, 1, 0.0, usize::MAX);
    let mut exact = detector(&sys, 0.0, 0.0);
    let mut start = detector(&sys, 1.0, 0.0);
    let mut out = StepOutput::new(2, 3);
    let (mut worst_sigma, mut worst_eps) = (0.0_f64, 0.0_f64);
    for (k, (u, y, e)) in data.iter().enumerate() {
        let sample = Sample {
            k: k as u64,
            u: &[*u],
            y,
            p: &[],
        };
        exact.step(&sample, &mut out).unwrap();
        worst_sigma = worst_sigma.max((exact.filter().innovation_covariance() - &sys.re).amax());
        worst_eps = worst_eps.max(
            (out.innovation[0] - e[0])
                .abs()
                .max((out.innovation[1] - e[1]).abs()),
        );
        start.step(&sample, &mut out).unwrap();
    }
    assert!(worst_sigma < 1e-14, "Σ − Re up to {worst_sigma:e}");
    assert!(worst_eps < 1e-12, "ε − e up to {worst_eps:e}");
    let converged = (start.filter().innovation_covariance() - &sys.re).amax();
    assert!(
        converged < 1e-12,
        "Σ − Re = {converged:e} after 400 samples from P₀ = I"
    );
}

/// The GLR on the innovation form: the LTI fast path (held gain and tables) gives what
/// the general recursion gives to 1e-9; over 2·10⁴ fault-free samples the mean NIS is
/// within 4σ of p = 2; a y1 bias of 1.0 (3.3 innovation standard deviations) from
/// k = 1 000 is dated within 5 samples and sized within 4 standard errors.
#[test]
fn the_glr_on_the_innovation_form_detects_and_sizes_a_sensor_bias() {
    let sys = system();
    let n = 20_000usize;
    let free = simulate(&sys, n, 2, 0.0, usize::MAX);
    let mut det = detector(&sys, 1.0, glrmon_core::DEFAULT_STEADY_TOLERANCE);
    let mut out = StepOutput::new(2, 3);
    let mut nis = 0.0;
    for (k, (u, y, _)) in free.iter().enumerate() {
        det.step(
            &Sample {
                k: k as u64,
                u: &[*u],
                y,
                p: &[],
            },
            &mut out,
        )
        .unwrap();
        nis += out.normalized_innovation;
    }
    let mean = nis / n as f64;
    assert!(
        (mean - 2.0).abs() < 4.0 * (4.0 / n as f64).sqrt(),
        "mean NIS {mean}"
    );
    assert!(det.is_stationary());

    let faulty = simulate(&sys, 1_100, 3, 1.0, 1_000);
    let (mut fast, mut general) = (
        detector(&sys, 1.0, glrmon_core::DEFAULT_STEADY_TOLERANCE),
        detector(&sys, 1.0, 0.0),
    );
    let (mut a, mut b) = (StepOutput::new(2, 3), StepOutput::new(2, 3));
    let mut worst = 0.0_f64;
    for (k, (u, y, _)) in faulty.iter().enumerate() {
        let sample = Sample {
            k: k as u64,
            u: &[*u],
            y,
            p: &[],
        };
        fast.step(&sample, &mut a).unwrap();
        general.step(&sample, &mut b).unwrap();
        assert_eq!((a.onset, a.rank), (b.onset, b.rank), "k = {k}");
        let (x, y) = (a.glr.unwrap_or(0.0), b.glr.unwrap_or(0.0));
        worst = worst.max((x - y).abs() / x.abs().max(1.0));
    }
    assert!(worst < 1e-9, "fast path vs general: {worst:e}");
    let onset = a.onset.unwrap();
    assert!(onset.abs_diff(1_000) <= 5, "onset {onset}");
    let fisher = fast.fisher_statistics(onset).unwrap();
    let info = fisher.information()[(1, 1)];
    let (theta, se) = (fisher.score()[1] / info, info.sqrt().recip());
    assert!((theta - 1.0).abs() < 4.0 * se, "θ̂ = {theta}, se {se}");
    assert!(a.glr.unwrap() > 30.0, "l_k = {:?}", a.glr);
}

#[test]
fn correlated_noise_and_an_unknown_input_are_refused_together() {
    let sys = system();
    let det = detector(&sys, 1.0, 0.0);
    let e = glrmon_core::LpvMatrix::constant(DMatrix::from_row_slice(2, 1, &[1.0, 0.0]));
    let err = det.with_unknown_input(e).unwrap_err();
    assert!(err.to_string().contains("correlated noises"), "{err}");
    let q = DMatrix::identity(2, 2);
    let model = Lpv::lti(
        sys.a.clone(),
        sys.b.clone(),
        sys.c.clone(),
        sys.d.clone(),
        q,
        sys.re.clone(),
    )
    .unwrap();
    let faults = FaultDictionary::new(
        model.dims(),
        vec![Fault::output(
            "b",
            Onset::Step,
            Column::Constant(DVector::from_column_slice(&[1.0, 0.0])),
        )],
    )
    .unwrap();
    let err = GlrDetector::new(
        Box::new(model),
        faults,
        DVector::zeros(2),
        DMatrix::identity(2, 2),
        WindowSettings::default(),
    )
    .unwrap()
    .with_cross_covariance(DMatrix::zeros(3, 2))
    .unwrap_err();
    assert!(err.to_string().contains("S is 3×2"), "{err}");
}
