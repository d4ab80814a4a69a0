//! Cost of one sparse diagnosis (Zhang 2021) on the paper's Example 1: m = 50 candidate
//! faults, N = 100 samples of Kitanidis residuals (p = 2 rows each).
//!
//! `cargo bench -p glrmon-core --bench diagnose`. Benchmarks:
//! - `diagnose`: the whole chain of [`glrmon_core::sparse::diagnose`] on the Gram
//!   statistics — the Lasso path of eq. (39) (100 λ from λ_max down to 10⁻⁴λ_max,
//!   coordinate descent with warm starts), the plateau λ of §IV and the least-squares
//!   refit of §V;
//! - `gram_and_diagnose`: the same preceded by stacking the N regression rows
//!   (Υ_k^r, ỹ_k) into XᵀX, Xᵀy (eq. (36)), i.e. all the work done at an alarm once the
//!   rows are known.
//!
//! The data are those of Example 1 (§V, eqs. (40)-(42)): 3-state LTV system, unknown
//! input d_k = 10 sin(0.1k) + N(0, 1) + 100 through E = [−1, 0, 0]ᵀ, Ψ_k (the paper's
//! Φ_k) uniform in [−17.3, 17.3], five faults of magnitude 1.

use criterion::{Criterion, criterion_group, criterion_main};
use glrmon_core::model::{Dims, SystemMatrices};
use glrmon_core::sparse::residual::{KitanidisResidual, ResidualRow, ResidualSample};
use glrmon_core::sparse::{GramAccumulator, LassoSettings, diagnose};
use glrmon_sim::Rng;
use nalgebra::{DMatrix, DVector};

/// The regression rows (Υ_k^r, ỹ_k), k = 1…N, of one Example 1 trial.
fn example1_rows(seed: u64) -> Vec<ResidualRow> {
    let (n, p, m, big_n) = (3, 2, 50, 100);
    let mut rng = Rng::new(seed);
    let mut theta = DVector::zeros(m);
    for j in [3, 11, 20, 33, 47] {
        theta[j] = 1.0;
    }
    let c = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    let e = DMatrix::from_row_slice(3, 1, &[-1.0, 0.0, 0.0]);
    let dims = Dims {
        states: n,
        inputs: 0,
        outputs: p,
        signals: 0,
    };
    let mut sys = SystemMatrices::zeros(dims);
    sys.h = c.clone();
    sys.q = DMatrix::identity(n, n);
    sys.r = DMatrix::identity(p, p) * 0.5;
    let mut filter =
        KitanidisResidual::new(DVector::zeros(n), DMatrix::identity(n, n), p, m, 1).unwrap();
    let mut x = DVector::from_fn(n, |_, _| rng.normal());
    let mut row = ResidualRow::zeros(p, m);
    let mut rows = Vec::new();
    for k in 0..=big_n {
        let kf = f64::from(k);
        sys.f = DMatrix::from_row_slice(
            3,
            3,
            &[
                -0.8,
                0.7,
                0.1 * (-kf).exp(),
                -0.6,
                0.0,
                0.1 * kf.cos(),
                0.1 * kf.sin(),
                -0.5,
                -0.4,
            ],
        );
        let psi = DMatrix::from_fn(n, m, |_, _| rng.uniform_in(-17.3, 17.3));
        let y = &c * &x + DVector::from_fn(p, |_, _| 0.5f64.sqrt() * rng.normal());
        let s = ResidualSample {
            sys: &sys,
            u: &[],
            y: y.as_slice(),
            psi: &psi,
            phi: None,
        };
        filter.step(&s, &e, &mut row).unwrap();
        if k >= 1 {
            rows.push(row.clone());
        }
        let d = 10.0 * (0.1 * kf).sin() + rng.normal() + 100.0;
        let w = DVector::from_fn(n, |_, _| rng.normal());
        x = &sys.f * &x + &e * d + w + &psi * &theta;
    }
    rows
}

fn gram(rows: &[ResidualRow]) -> GramAccumulator {
    let mut g = GramAccumulator::new(rows[0].upsilon.ncols());
    for r in rows {
        g.push(&r.upsilon, &r.residual).unwrap();
    }
    g
}

fn benches(c: &mut Criterion) {
    let rows = example1_rows(2021);
    let settings = LassoSettings::default();
    let g = gram(&rows);
    let d = diagnose(&g, &settings).unwrap();
    assert_eq!(d.support, [3, 11, 20, 33, 47], "{:?}", d.path);
    let mut group = c.benchmark_group("example1_m50_n100");
    group.bench_function("diagnose", |b| {
        b.iter(|| diagnose(std::hint::black_box(&g), &settings).unwrap());
    });
    group.bench_function("gram_and_diagnose", |b| {
        b.iter(|| diagnose(&gram(std::hint::black_box(&rows)), &settings).unwrap());
    });
    group.finish();
}

criterion_group!(diagnosis, benches);
criterion_main!(diagnosis);
