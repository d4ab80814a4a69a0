//! Wall-clock time of [`glrmon_ident::identify`] at the sizes docs/PERFORMANCE.md
//! reports: 3 000 and 100 000 samples of a random stable 12-state system with 9 inputs
//! and 22 outputs (31 signals), every order up to 40; best of three runs.
//!
//! ```text
//! cargo run --release -p glrmon-ident --example identify_timing
//! ```

use std::time::Instant;

use glrmon_ident::{Experiment, IdentSettings, identify};
use nalgebra::{DMatrix, DVector};

/// splitmix64 and Box–Muller: deterministic normals without a dependency.
struct Normals(u64);

impl Normals {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }

    fn matrix(&mut self, rows: usize, cols: usize) -> DMatrix<f64> {
        DMatrix::from_fn(rows, cols, |_, _| self.normal())
    }
}

fn experiment(samples: usize, rng: &mut Normals) -> Experiment {
    let (n, l, p) = (12, 9, 22);
    let mut a = rng.matrix(n, n);
    let radius = glrmon_ident::spectral_radius(&a);
    a *= 0.9 / radius;
    let (b, c, k) = (rng.matrix(n, l), rng.matrix(p, n), rng.matrix(n, p) * 0.02);
    let u = rng.matrix(samples, l);
    let mut y = DMatrix::zeros(samples, p);
    let mut x = DVector::zeros(n);
    for t in 0..samples {
        let e = DVector::from_fn(p, |_, _| 0.3 * rng.normal());
        let ut = u.row(t).transpose();
        y.set_row(t, &(&c * &x + &e).transpose());
        x = &a * &x + &b * &ut + &k * &e;
    }
    Experiment::new(u, y)
}

fn main() {
    let settings = IdentSettings {
        max_order: 40,
        ..IdentSettings::default()
    };
    let only: Option<usize> = std::env::args().nth(1).and_then(|a| a.parse().ok());
    let max_order: Option<usize> = std::env::args().nth(2).and_then(|a| a.parse().ok());
    let settings = IdentSettings {
        max_order: max_order.unwrap_or(40),
        ..settings
    };
    for samples in only.map_or(vec![3_000, 100_000], |n| vec![n]) {
        let data = experiment(samples, &mut Normals(26));
        let mut best = f64::INFINITY;
        let mut chosen = 0;
        for _ in 0..3 {
            let start = Instant::now();
            let id = identify(std::slice::from_ref(&data), &settings).expect("identify");
            best = best.min(start.elapsed().as_secs_f64());
            chosen = id.order.chosen;
        }
        println!(
            "{samples} samples × 31 signals (l = 9, p = 22), orders 1..=40: {best:.3} s \
             (best of 3), chosen order {chosen}"
        );
    }
}
