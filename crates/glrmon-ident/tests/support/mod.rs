//! Test support: a seeded generator, a known innovation-form system and its simulation,
//! and comparison helpers.

#![allow(dead_code, unreachable_pub)]

use glrmon_ident::{InnovationModel, sorted_eigenvalues};
use nalgebra::{Complex, DMatrix, DVector};

/// xoshiro256++ seeded through splitmix64, with Box–Muller normals: deterministic on
/// every machine.
pub struct Rng {
    s: [u64; 4],
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        let mut z = seed;
        let mut next = || {
            z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^ (x >> 31)
        };
        Self {
            s: [next(), next(), next(), next()],
            spare: None,
        }
    }

    pub fn next_u64(&mut self) -> u64 {
        let result = (self.s[0].wrapping_add(self.s[3]))
            .rotate_left(23)
            .wrapping_add(self.s[0]);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    pub fn normal(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }

    pub fn normals(&mut self, rows: usize, cols: usize) -> DMatrix<f64> {
        // Row-major draw order: sample k's values are consecutive.
        let mut m = DMatrix::zeros(rows, cols);
        for r in 0..rows {
            for c in 0..cols {
                m[(r, c)] = self.normal();
            }
        }
        m
    }
}

/// A true innovation-form system.
#[derive(Clone, Debug)]
pub struct Truth {
    pub a: DMatrix<f64>,
    pub b: DMatrix<f64>,
    pub c: DMatrix<f64>,
    pub d: DMatrix<f64>,
    pub k: DMatrix<f64>,
    pub re: DMatrix<f64>,
}

impl Truth {
    /// 4 states, 2 inputs, 3 outputs; poles 0.9, 0.7 ± 0.2i, 0.5; colored output noise
    /// through K.
    pub fn four_state() -> Self {
        Self {
            a: DMatrix::from_row_slice(
                4,
                4,
                &[
                    0.9, 0.0, 0.0, 0.0, //
                    0.0, 0.7, 0.2, 0.0, //
                    0.0, -0.2, 0.7, 0.0, //
                    0.0, 0.0, 0.0, 0.5,
                ],
            ),
            b: DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 0.5, 1.0, 0.0, 0.8, 1.0, -0.5]),
            c: DMatrix::from_row_slice(
                3,
                4,
                &[
                    1.0, 0.5, 0.0, 0.3, //
                    0.0, 1.0, 0.4, 0.0, //
                    0.2, 0.0, 1.0, 1.0,
                ],
            ),
            d: DMatrix::from_row_slice(3, 2, &[0.1, 0.0, 0.0, 0.2, 0.0, 0.0]),
            k: DMatrix::from_row_slice(
                4,
                3,
                &[
                    0.3, 0.0, 0.0, //
                    0.0, 0.2, 0.0, //
                    0.0, 0.0, 0.2, //
                    0.1, 0.0, 0.1,
                ],
            ),
            re: DMatrix::from_row_slice(
                3,
                3,
                &[
                    0.5, 0.1, 0.0, //
                    0.1, 0.4, 0.05, //
                    0.0, 0.05, 0.3,
                ],
            ),
        }
    }

    /// The true model as an [`InnovationModel`] (Q, S, R of the innovation form).
    pub fn model(&self) -> InnovationModel {
        InnovationModel {
            a: self.a.clone(),
            b: self.b.clone(),
            c: self.c.clone(),
            d: self.d.clone(),
            k: self.k.clone(),
            re: self.re.clone(),
            q: &self.k * &self.re * self.k.transpose(),
            s: &self.k * &self.re,
            r: self.re.clone(),
            p: DMatrix::zeros(self.a.nrows(), self.a.nrows()),
        }
    }

    /// Outputs for inputs `u` (N × l) with innovations drawn from `rng`, from x₀ = 0
    /// after a 500-sample burn-in (so the record is stationary).
    pub fn simulate(&self, u: &DMatrix<f64>, rng: &mut Rng) -> DMatrix<f64> {
        let (n, p) = (self.a.nrows(), self.c.nrows());
        let chol = self
            .re
            .clone()
            .cholesky()
            .expect("Re positive definite")
            .l();
        let burn = 500;
        let mut x = DVector::zeros(n);
        let mut y = DMatrix::zeros(u.nrows(), p);
        let zero_u = DVector::zeros(u.ncols());
        for k in 0..burn + u.nrows() {
            let uk = if k < burn {
                zero_u.clone()
            } else {
                u.row(k - burn).transpose()
            };
            let e = &chol * DVector::from_fn(p, |_, _| rng.normal());
            let yk = &self.c * &x + &self.d * &uk + &e;
            if k >= burn {
                y.set_row(k - burn, &yk.transpose());
            }
            x = &self.a * &x + &self.b * &uk + &self.k * &e;
        }
        y
    }
}

/// Largest distance between sorted eigenvalue lists (∞ if the lengths differ).
pub fn pole_error(estimated: &[Complex<f64>], truth: &DMatrix<f64>) -> f64 {
    let t = sorted_eigenvalues(truth);
    if t.len() != estimated.len() {
        return f64::INFINITY;
    }
    t.iter()
        .zip(estimated)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max)
}

/// max_j ‖Ĥ_j − H_j‖_F / max_j ‖H_j‖_F over D and C A^j B, j = 0..count−1.
pub fn markov_error(model: &InnovationModel, truth: &Truth, count: usize) -> f64 {
    let t = truth.model().markov_parameters(count);
    let m = model.markov_parameters(count);
    let scale = t.iter().map(|h| h.norm()).fold(0.0, f64::max);
    t.iter()
        .zip(&m)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max)
        / if scale > 0.0 { scale } else { 1.0 }
}

/// Same for the noise path C A^j K (basis-free, unlike K itself).
pub fn noise_markov_error(model: &InnovationModel, truth: &Truth, count: usize) -> f64 {
    let noise = |a: &DMatrix<f64>, c: &DMatrix<f64>, k: &DMatrix<f64>| {
        let mut out = Vec::new();
        let mut ak = k.clone();
        for _ in 0..count {
            out.push(c * &ak);
            ak = a * ak;
        }
        out
    };
    let t = noise(&truth.a, &truth.c, &truth.k);
    let m = noise(&model.a, &model.c, &model.k);
    let scale = t.iter().map(|h| h.norm()).fold(0.0, f64::max);
    t.iter()
        .zip(&m)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max)
        / scale
}

/// Largest relative element error of Re against the truth, relative to max |Re_ij|.
pub fn re_error(re: &DMatrix<f64>, truth: &DMatrix<f64>) -> f64 {
    (re - truth).amax() / truth.amax()
}

/// ‖K̂ − K‖_F / ‖K‖_F with K̂ brought into the truth's state basis: x̂ = T x, so
/// Ô = O T⁻¹ for the extended observability matrices and T⁻¹ = O^† Ô, K = T⁻¹ K̂.
/// ∞ when the orders differ.
pub fn k_error(model: &InnovationModel, truth: &Truth) -> f64 {
    let n = truth.a.nrows();
    if model.order() != n {
        return f64::INFINITY;
    }
    let observability = |a: &DMatrix<f64>, c: &DMatrix<f64>| {
        let p = c.nrows();
        let mut o = DMatrix::zeros(2 * n * p, n);
        let mut ca = c.clone();
        for j in 0..2 * n {
            o.rows_mut(j * p, p).copy_from(&ca);
            ca = &ca * a;
        }
        o
    };
    let o_true = observability(&truth.a, &truth.c);
    let o_id = observability(&model.a, &model.c);
    let t_inv = o_true.pseudo_inverse(1e-12).expect("SVD") * o_id;
    (t_inv * &model.k - &truth.k).norm() / truth.k.norm()
}
