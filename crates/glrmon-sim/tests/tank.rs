//! The quadruple-tank simulator against Johansson 2000 and against itself.

use glrmon_sim::tank::{
    Drive, Excitation, OPERATING_INPUT, QuadrupleTank, TankFault, TankFaultKind, TankRun,
};

fn noiseless(samples: usize) -> TankRun {
    TankRun {
        samples,
        excitation: Excitation::Constant,
        inflow_noise_std: 0.0,
        sensor_noise_std: 0.0,
        ..TankRun::default()
    }
}

#[test]
fn steady_state_is_an_equilibrium_and_matches_the_paper() {
    let plant = QuadrupleTank::default();
    for v in [OPERATING_INPUT, [2.5, 3.5], [3.4, 2.7], [1.0, 4.0]] {
        let h = plant.steady_state(v);
        let d = plant.derivative(&h, &Drive::pumps(v));
        let worst = d.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        println!("v = {v:?}: h⁰ = {h:?}, max |dh/dt| = {worst:e}");
        assert!(worst < 1e-12, "{d:?}");
    }
    let h = plant.steady_state(OPERATING_INPUT);
    // Johansson 2000, Table I, P−: (h1, h2) = (12.4, 12.7), (h3, h4) = (1.8, 1.4) cm.
    // h2 and h4 agree to the table's rounding (±0.05); the equations with the table's
    // constants give h1 = 12.26 and h3 = 1.63, so the table's measured levels are matched
    // within 0.15 and 0.2 cm only (see the module's documentation).
    let paper = [12.4, 12.7, 1.8, 1.4];
    let tol = [0.15, 0.1, 0.2, 0.05];
    for i in 0..4 {
        assert!(
            (h[i] - paper[i]).abs() <= tol[i],
            "h{} = {} vs paper {}",
            i + 1,
            h[i],
            paper[i]
        );
    }
    assert!((h[1] - 12.7).abs() <= 0.1 && (h[3] - 1.4).abs() <= 0.05);
}

#[test]
fn linearisation_matches_finite_differences_and_the_papers_linear_model() {
    let plant = QuadrupleTank::default();
    let v0 = OPERATING_INPUT;
    let h0 = plant.steady_state(v0);
    let (a, b) = plant.linearisation(v0);
    // Central differences of the nonlinear derivative.
    let eps = 1e-5;
    let mut worst = 0.0_f64;
    for j in 0..4 {
        let (mut hp, mut hm) = (h0, h0);
        hp[j] += eps;
        hm[j] -= eps;
        let (dp, dm) = (
            plant.derivative(&hp, &Drive::pumps(v0)),
            plant.derivative(&hm, &Drive::pumps(v0)),
        );
        for i in 0..4 {
            let fd = (dp[i] - dm[i]) / (2.0 * eps);
            worst = worst.max((fd - a[i][j]).abs());
        }
    }
    for j in 0..2 {
        let (mut vp, mut vm) = (v0, v0);
        vp[j] += eps;
        vm[j] -= eps;
        let (dp, dm) = (
            plant.derivative(&h0, &Drive::pumps(vp)),
            plant.derivative(&h0, &Drive::pumps(vm)),
        );
        for i in 0..4 {
            let fd = (dp[i] - dm[i]) / (2.0 * eps);
            worst = worst.max((fd - b[i][j]).abs());
        }
    }
    println!("max |finite-difference Jacobian − (A, B)| = {worst:e}");
    assert!(worst < 1e-8, "{worst}");
    // The paper's P− time constants (62, 90, 23, 30) s, to within a second.
    let t = plant.time_constants(&h0);
    println!("time constants T = {t:?} s");
    for (ti, paper) in t.iter().zip([62.0, 90.0, 23.0, 30.0]) {
        assert!((ti - paper).abs() < 1.0, "T = {ti} vs paper {paper}");
    }
    // The paper's P− transfer matrix at s = 0: [2.6, 1.5; 1.4, 2.8] (V/V), to rounding.
    let g = plant.dc_gain(v0);
    println!("dc gain (sensor V per pump V) = {g:?}");
    let paper = [[2.6, 1.5], [1.4, 2.8]];
    for i in 0..2 {
        for j in 0..2 {
            assert!(
                (g[i][j] - paper[i][j]).abs() <= 0.05 + 1e-9,
                "G({i},{j}) = {} vs paper {}",
                g[i][j],
                paper[i][j]
            );
        }
    }
    // −kc A⁻¹ B, solved by back substitution (A is upper triangular), equals dc_gain.
    let kc = plant.sensor_gain;
    for j in 0..2 {
        let mut x = [0.0; 4];
        x[3] = -b[3][j] / a[3][3];
        x[2] = -b[2][j] / a[2][2];
        x[1] = -(b[1][j] + a[1][3] * x[3]) / a[1][1];
        x[0] = -(b[0][j] + a[0][2] * x[2]) / a[0][0];
        for i in 0..4 {
            assert!((kc * x[i] - g[i][j]).abs() < 1e-12, "{i},{j}");
        }
    }
}

#[test]
fn rk4_converges_with_order_four() {
    let plant = QuadrupleTank::default();
    let h = [5.0, 20.0, 4.0, 0.5];
    let drive = Drive {
        v: [3.5, 2.5],
        disturbance: [0.3, -0.2, 0.1, 0.0],
        leak: [0.0, 0.01, 0.0, 0.0],
    };
    let ts = 10.0;
    let s: Vec<[f64; 4]> = [1, 2, 4, 8]
        .iter()
        .map(|&n| plant.step(h, &drive, ts, n))
        .collect();
    let diff = |a: &[f64; 4], b: &[f64; 4]| {
        a.iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
    };
    let e: Vec<f64> = (0..3).map(|i| diff(&s[i], &s[i + 1])).collect();
    let ratios = [e[0] / e[1], e[1] / e[2]];
    println!("Ts = {ts} s, sub-steps 1,2,4,8: successive differences {e:?}, ratios {ratios:?}");
    for r in ratios {
        assert!((12.0..20.0).contains(&r), "ratio {r}");
    }
}

#[test]
fn long_fault_free_run_stays_near_the_operating_point() {
    let run = TankRun {
        seed: 11,
        samples: 100_000,
        ..TankRun::default()
    };
    let rec = run.simulate().unwrap();
    let h0 = run.plant.steady_state(OPERATING_INPUT);
    let mut lo = [f64::INFINITY; 4];
    let mut hi = [f64::NEG_INFINITY; 4];
    let mut mean = [0.0; 4];
    for h in &rec.levels {
        for i in 0..4 {
            lo[i] = lo[i].min(h[i]);
            hi[i] = hi[i].max(h[i]);
            mean[i] += h[i] / rec.levels.len() as f64;
        }
    }
    println!("h⁰ = {h0:?}\nmin = {lo:?}\nmax = {hi:?}\nmean = {mean:?}");
    for i in 0..4 {
        assert!(lo[i] > 0.2 * h0[i], "tank {i} fell to {}", lo[i]);
        assert!(hi[i] < 2.0 * h0[i], "tank {i} rose to {}", hi[i]);
        assert!(
            (mean[i] - h0[i]).abs() < 0.05 * h0[i],
            "tank {i} mean {}",
            mean[i]
        );
    }
    assert!(rec.y.iter().flatten().all(|y| y.is_finite()));
    let u_lo = rec.u.iter().flatten().fold(f64::INFINITY, |m, &x| m.min(x));
    let u_hi = rec
        .u
        .iter()
        .flatten()
        .fold(f64::NEG_INFINITY, |m, &x| m.max(x));
    assert!(u_lo >= 2.5 && u_hi < 3.5, "{u_lo} {u_hi}");
    assert_eq!(rec.k.last(), Some(&99_999));
    assert_eq!(rec.t[10], 50.0);
}

#[test]
fn sensor_bias_appears_exactly_in_its_output_from_the_onset() {
    let clean = TankRun {
        seed: 5,
        samples: 300,
        ..TankRun::default()
    };
    let onset = 120;
    let faulty = TankRun {
        faults: vec![TankFault::sensor_bias(2, onset)],
        ..clean.clone()
    };
    let (a, b) = (clean.simulate().unwrap(), faulty.simulate().unwrap());
    assert_eq!(a.u, b.u);
    assert_eq!(a.levels, b.levels);
    for k in 0..300 {
        for i in 0..4 {
            let d = b.y[k][i] - a.y[k][i];
            if i == 2 && k as u64 >= onset {
                assert!((d - 0.125).abs() < 1e-12, "k {k}: {d}");
            } else {
                assert_eq!(a.y[k][i].to_bits(), b.y[k][i].to_bits(), "k {k} y{i}");
            }
        }
    }
}

#[test]
fn actuator_bias_moves_the_steady_levels_by_the_linear_gains() {
    let run = noiseless(3000);
    let bias = 0.25;
    let faulty = TankRun {
        faults: vec![TankFault {
            kind: TankFaultKind::ActuatorBias {
                input: 0,
                magnitude: bias,
            },
            onset: 100,
        }],
        ..run.clone()
    };
    let (a, b) = (run.simulate().unwrap(), faulty.simulate().unwrap());
    // The recorded input is the commanded one, unchanged by the fault.
    assert!(b.u.iter().all(|u| u == &vec![3.0, 3.0]));
    assert_eq!(a.y[100], b.y[100]);
    assert_ne!(a.y[101], b.y[101]);
    let plant = run.plant;
    let g = plant.dc_gain(OPERATING_INPUT);
    let exact0 = plant.steady_state(OPERATING_INPUT);
    let exact1 = plant.steady_state([3.0 + bias, 3.0]);
    let last = b.y.len() - 1;
    for i in 0..4 {
        let dy = b.y[last][i] - a.y[last][i];
        let exact = plant.sensor_gain * (exact1[i] - exact0[i]);
        let linear = g[i][0] * bias;
        println!("y{i}: Δy = {dy:.5} V, exact steady {exact:.5}, linear {linear:.5}");
        // Converged to the nonlinear steady state …
        assert!((dy - exact).abs() < 1e-6, "y{i}: {dy} vs {exact}");
        // … which is the linear gain's change up to the quadratic term (≤ 6 %).
        if linear == 0.0 {
            assert!(dy.abs() < 1e-9);
        } else {
            assert!((dy / linear - 1.0).abs() < 0.06, "y{i}: {dy} vs {linear}");
        }
    }
}

#[test]
fn leak_lowers_its_tank() {
    let run = noiseless(3000);
    for tank in 0..4 {
        let faulty = TankRun {
            faults: vec![TankFault::leak(tank, 100)],
            ..run.clone()
        };
        let (a, b) = (run.simulate().unwrap(), faulty.simulate().unwrap());
        let last = b.levels.len() - 1;
        let drop: Vec<f64> = (0..4)
            .map(|i| b.levels[last][i] - a.levels[last][i])
            .collect();
        println!("leak from tank {tank}: steady level change {drop:.4?} cm");
        assert!(drop[tank] < -0.05, "{drop:?}");
        assert_eq!(a.levels[100], b.levels[100]);
    }
}

#[test]
fn same_seed_gives_identical_bits_and_another_seed_does_not() {
    let run = |seed| {
        TankRun {
            seed,
            samples: 2000,
            measure_pump_flow: true,
            faults: vec![TankFault::leak(1, 700), TankFault::actuator_bias(1, 900)],
            ..TankRun::default()
        }
        .simulate()
        .unwrap()
    };
    let bits = |r: &glrmon_sim::tank::TankRecording| -> Vec<u64> {
        r.u.iter()
            .chain(r.y.iter())
            .flatten()
            .map(|x| x.to_bits())
            .collect()
    };
    let (a, b, c) = (run(3), run(3), run(4));
    assert_eq!(bits(&a), bits(&b));
    assert_ne!(bits(&a), bits(&c));
    assert_eq!(a.y[0].len(), 6);
    assert_eq!(
        a.columns(),
        ["k", "t", "u0", "u1", "y0", "y1", "y2", "y3", "y4", "y5"]
    );
    // Pinned first values: a change of the random streams or the integration shows here.
    println!(
        "seed 3: u[0] = {:?}, y[0] = {:?}, y[1999] = {:?}",
        a.u[0], a.y[0], a.y[1999]
    );
}

#[test]
fn bad_settings_are_refused() {
    let bad = [
        TankRun {
            sample_period: 0.0,
            ..TankRun::default()
        },
        TankRun {
            substeps: 0,
            ..TankRun::default()
        },
        TankRun {
            faults: vec![TankFault::sensor_bias(4, 0)],
            ..TankRun::default()
        },
        TankRun {
            faults: vec![TankFault::actuator_bias(2, 0)],
            ..TankRun::default()
        },
        TankRun {
            faults: vec![TankFault::leak(4, 0)],
            ..TankRun::default()
        },
        TankRun {
            excitation: Excitation::RandomSteps {
                amplitude: 0.5,
                min_hold: 0,
                max_hold: 3,
            },
            ..TankRun::default()
        },
    ];
    for run in bad {
        assert!(run.simulate().is_err(), "{run:?}");
    }
}
