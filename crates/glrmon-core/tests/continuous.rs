//! The zero-order-hold discretisation of continuous-time models (`model::continuous`)
//! against closed forms (scalar, integrator, double integrator), a fine-step numerical
//! integration of Q on a stiff model, the semigroup law of e^{At} and the composition
//! law of (F, G, Q) over two periods, and Q's symmetry and definiteness.

use glrmon_core::model::continuous::{
    ContinuousError, Discretisation, expm, process_noise, zero_order_hold,
};
use nalgebra::{DMatrix, DVector};

fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_row_slice(rows, cols, v)
}

/// max |x − y| / max |y|.
fn relative(x: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
    (x - y).amax() / y.amax()
}

/// dx/dt = a x + b u + w, E[w w] = q δ: F = e^{aT}, G = (e^{aT} − 1)/a · b,
/// Q = q (e^{2aT} − 1)/(2a), for a stable and an unstable a.
#[test]
fn scalar_model_matches_the_closed_form() {
    for (a, b, q, t) in [
        (-0.05, 2.0, 0.3, 1.7),
        (-1.0 / 600.0, 1.0 / 0.5, 1e-4, 20.0),
        (0.1, -0.5, 2.0, 3.0),
        (-40.0, 1.0, 1.0, 0.5),
    ] {
        let d = Discretisation::zero_order_hold(
            &m(1, 1, &[a]),
            &m(1, 1, &[b]),
            Some(&m(1, 1, &[q])),
            t,
        )
        .unwrap();
        let f = (a * t).exp();
        let g = (a * t).exp_m1() / a * b;
        let qd = q * (2.0 * a * t).exp_m1() / (2.0 * a);
        let (ef, eg, eq) = (
            (d.f()[(0, 0)] - f).abs() / f,
            (d.g()[(0, 0)] - g).abs() / g.abs(),
            (d.q().unwrap()[(0, 0)] - qd).abs() / qd,
        );
        assert!(ef < 1e-14, "a = {a}: F {} vs {f} ({ef:e})", d.f()[(0, 0)]);
        assert!(eg < 1e-13, "a = {a}: G {} vs {g} ({eg:e})", d.g()[(0, 0)]);
        assert!(
            eq < 1e-13,
            "a = {a}: Q {} vs {qd} ({eq:e})",
            d.q().unwrap()[(0, 0)]
        );
    }
}

/// a = 0, an integrator: F = 1, G = bT, Q = qT, exactly.
#[test]
fn integrator_gives_bt_and_qt() {
    let (b, q, t) = (0.75, 0.02, 20.0);
    let d =
        Discretisation::zero_order_hold(&m(1, 1, &[0.0]), &m(1, 1, &[b]), Some(&m(1, 1, &[q])), t)
            .unwrap();
    assert_eq!(d.f()[(0, 0)], 1.0);
    assert!((d.g()[(0, 0)] - b * t).abs() < 1e-15 * b * t);
    assert!((d.q().unwrap()[(0, 0)] - q * t).abs() < 1e-15 * q * t);
    assert!(d.to_string().contains("marginally stable"), "{d}");
}

/// The double integrator (position, velocity; force input; white acceleration noise of
/// intensity q): F = [[1, T], [0, 1]], G = [T²/2, T], Q = q [[T³/3, T²/2], [T²/2, T]].
#[test]
fn double_integrator_matches_the_closed_form() {
    let a = m(2, 2, &[0.0, 1.0, 0.0, 0.0]);
    let b = m(2, 1, &[0.0, 1.0]);
    let q = 0.3;
    let qc = m(2, 2, &[0.0, 0.0, 0.0, q]);
    for t in [1e-3, 0.1, 1.0, 20.0, 3600.0] {
        let d = Discretisation::zero_order_hold(&a, &b, Some(&qc), t).unwrap();
        let f = m(2, 2, &[1.0, t, 0.0, 1.0]);
        let g = m(2, 1, &[t * t / 2.0, t]);
        let qd = m(2, 2, &[t.powi(3) / 3.0, t * t / 2.0, t * t / 2.0, t]) * q;
        assert!(relative(d.f(), &f) < 1e-15, "T = {t}: F = {}", d.f());
        assert!(relative(d.g(), &g) < 1e-15, "T = {t}: G = {}", d.g());
        let e = relative(d.q().unwrap(), &qd);
        assert!(e < 1e-14, "T = {t}: Q = {} ({e:e})", d.q().unwrap());
    }
}

/// A stiff model, eigenvalues about −1000 s⁻¹ and −0.03 s⁻¹ sampled at T = 20 s
/// (‖A‖₁T = 2·10⁴), against an independent computation: e^{As} = V e^{Λs} V⁻¹ from the
/// closed-form eigenvectors of the 2×2 A, and Q = ∫₀ᵀ e^{As}Q_c e^{Aᵀs} ds by composite
/// Simpson on a graded mesh (10⁴ steps over the fast transient [0, 0.05 s], 2·10⁴ over
/// the rest). Van Loan's formula over the whole period would need e^{−AT} = e^{2·10⁴}:
/// that overflows, which is why Q is built from τ = T/2^j.
#[test]
fn stiff_model_matches_simpson_integration() {
    let a = m(2, 2, &[-1000.0, 40.0, 0.5, -0.05]);
    let b = m(2, 1, &[3.0, 0.1]);
    let qc = m(2, 2, &[4.0, 0.5, 0.5, 0.01]);
    let t = 20.0;
    let d = Discretisation::zero_order_hold(&a, &b, Some(&qc), t).unwrap();

    // Eigen-decomposition of A: λ = (tr ± √(tr² − 4 det))/2, v = [a12, λ − a11].
    let (tr, det) = (a.trace(), a.determinant());
    let disc = (tr * tr - 4.0 * det).sqrt();
    let lambda = [(tr - disc) / 2.0, (tr + disc) / 2.0];
    let v = m(
        2,
        2,
        &[
            a[(0, 1)],
            a[(0, 1)],
            lambda[0] - a[(0, 0)],
            lambda[1] - a[(0, 0)],
        ],
    );
    let v_inv = v.clone().try_inverse().unwrap();
    let exp_at = |s: f64| {
        &v * DMatrix::from_diagonal(&DVector::from_vec(vec![
            (lambda[0] * s).exp(),
            (lambda[1] * s).exp(),
        ])) * &v_inv
    };
    assert!(relative(d.f(), &exp_at(t)) < 5e-12, "F = {}", d.f());
    // G = ∫₀ᵀ e^{As} ds B = V diag((e^{λT} − 1)/λ) V⁻¹ B.
    let integral =
        &v * DMatrix::from_diagonal(&DVector::from_vec(vec![
            (lambda[0] * t).exp_m1() / lambda[0],
            (lambda[1] * t).exp_m1() / lambda[1],
        ])) * &v_inv;
    let g = integral * &b;
    assert!(relative(d.g(), &g) < 5e-12, "G = {} vs {g}", d.g());

    let integrand = |s: f64| {
        let e = exp_at(s);
        &e * &qc * e.transpose()
    };
    let simpson = |from: f64, to: f64, steps: usize| {
        let h = (to - from) / steps as f64;
        let mut sum = integrand(from) + integrand(to);
        for i in 1..steps {
            let w = if i % 2 == 1 { 4.0 } else { 2.0 };
            sum += integrand(from + i as f64 * h) * w;
        }
        sum * (h / 3.0)
    };
    let q = simpson(0.0, 0.05, 10_000) + simpson(0.05, t, 20_000);
    let e = relative(d.q().unwrap(), &q);
    assert!(e < 1e-10, "Q = {} vs Simpson {q} ({e:e})", d.q().unwrap());

    // Van Loan over the whole period: e^{−AT} overflows.
    let mut block = DMatrix::zeros(4, 4);
    block.view_mut((0, 0), (2, 2)).copy_from(&(&a * -t));
    block.view_mut((0, 2), (2, 2)).copy_from(&(&qc * t));
    block
        .view_mut((2, 2), (2, 2))
        .copy_from(&(a.transpose() * t));
    assert!(matches!(
        expm(&block),
        Err(ContinuousError::Overflow { .. })
    ));
}

/// e^{A(T₁+T₂)} = e^{AT₁}e^{AT₂} to 1e-12 relative, for a non-normal 4×4 A with a
/// complex pair, an unstable and a fast mode; and the same law for the discretised
/// model: over T₁ then T₂, F = F₂F₁, G = F₂G₁ + G₂, Q = F₂Q₁F₂ᵀ + Q₂.
#[test]
fn semigroup_and_composition_laws_hold() {
    let a = m(
        4,
        4,
        &[
            -0.3, 2.0, 0.0, 5.0, //
            -2.0, -0.3, 1.0, 0.0, //
            0.0, 0.0, 0.05, 3.0, //
            0.0, 0.0, 0.0, -12.0,
        ],
    );
    let b = m(4, 2, &[1.0, 0.0, 0.0, 2.0, 0.5, 0.5, 1.0, -1.0]);
    let l = m(4, 2, &[1.0, 0.0, 0.3, 1.0, 0.0, 0.2, 2.0, 0.1]);
    let qc = &l * l.transpose();
    for (t1, t2) in [(0.37, 1.91), (0.001, 0.5), (2.5, 2.5)] {
        let e = |t: f64| expm(&(&a * t)).unwrap();
        let err = relative(&(e(t1) * e(t2)), &e(t1 + t2));
        assert!(err < 1e-12, "T1 = {t1}, T2 = {t2}: {err:e}");

        let d = |t: f64| Discretisation::zero_order_hold(&a, &b, Some(&qc), t).unwrap();
        let (d1, d2, d12) = (d(t1), d(t2), d(t1 + t2));
        let f = d2.f() * d1.f();
        let g = d2.f() * d1.g() + d2.g();
        let q = d2.f() * d1.q().unwrap() * d2.f().transpose() + d2.q().unwrap();
        assert!(relative(d12.f(), &f) < 1e-12, "F, {t1} + {t2}");
        assert!(relative(d12.g(), &g) < 1e-12, "G, {t1} + {t2}");
        let err = relative(d12.q().unwrap(), &q);
        assert!(err < 1e-12, "Q, {t1} + {t2}: {err:e}");
    }
}

/// Q is exactly symmetric and positive semi-definite (to rounding) for a PSD Q_c of
/// rank 1 and of full rank, with stable, unstable and oscillating modes, over short and
/// long periods.
#[test]
fn q_is_symmetric_positive_semidefinite() {
    let a = m(
        3,
        3,
        &[-0.5, 3.0, 0.0, -3.0, -0.5, 0.0, 1.0, 0.0, 0.2], // a complex pair, an unstable mode
    );
    let rank1 = {
        let v = m(3, 1, &[1.0, -2.0, 0.5]);
        &v * v.transpose()
    };
    let full = m(3, 3, &[2.0, 0.3, 0.1, 0.3, 1.0, -0.2, 0.1, -0.2, 0.5]);
    for qc in [rank1, full] {
        for t in [1e-4, 0.1, 1.0, 10.0, 50.0] {
            let q = process_noise(&a, &qc, t).unwrap();
            assert_eq!(q, q.transpose(), "T = {t}");
            let eig = q.clone().symmetric_eigenvalues();
            let (low, high) = (eig.min(), eig.max());
            assert!(high > 0.0, "T = {t}");
            assert!(low >= -1e-13 * high, "T = {t}: eigenvalues {eig}");
        }
    }
}

/// F and G from the public functions are those of the [`Discretisation`], and the
/// errors name their matrix.
#[test]
fn functions_and_errors() {
    let a = m(2, 2, &[-1.0, 0.5, 0.0, -2.0]);
    let b = m(2, 1, &[0.0, 1.0]);
    let (f, g) = zero_order_hold(&a, &b, 0.3).unwrap();
    let d = Discretisation::zero_order_hold(&a, &b, None, 0.3).unwrap();
    assert_eq!((&f, &g), (d.f(), d.g()));
    assert!(d.q().is_none());
    assert_eq!(d.period(), 0.3);
    let err = Discretisation::zero_order_hold(&a, &b, None, -1.0).unwrap_err();
    assert_eq!(
        err.to_string(),
        "the sample period T = -1 s must be finite and positive"
    );
    let err = process_noise(&a, &m(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]), 1.0).unwrap_err();
    assert_eq!(
        err.to_string(),
        "Qc holds a non-finite value (NaN or infinity)"
    );
}
