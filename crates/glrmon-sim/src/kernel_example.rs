//! The numerical example of Li, Boem, Pin & Parisini, Section V: a continuous-time
//! LTI plant ẋ = Ax + Bu + E f(t, x, u) + d_x, y = Cx + d_y with 5 states, 4
//! outputs (x₀…x₃ measured) and 3 fault channels, input u = 10 sin 10t + sin 2t,
//! and the state-dependent candidate faults
//! φ₁ = [x₁ + x₂, cos x₃, cos 0.5x₄]ᵀ, φ₂ = [x₁ + x₂, 20e^{−|x₃|}, sin 0.5x₄]ᵀ
//! (states numbered from 0, as the paper does).
//!
//! The plant is integrated by classical Runge-Kutta (RK4) with `substeps` steps per
//! sample period, the fault evaluated at the true state; the process noise is held
//! over each period and the output noise drawn per sample, each component uniform in
//! ±its amplitude. Plain `f64` buffers: the simulation shares nothing with the
//! detector it is used to test. [`detector`] builds that detector from the same
//! constants, for the tests, examples and benchmarks outside glrmon-core.

use glrmon_core::{
    Candidate, CandidateFn, KernelDetector, KernelModel, KernelSettings, ModelError, Sample,
};
use nalgebra::DMatrix;

use crate::Rng;

/// A: Section V.
pub const A: [[f64; 5]; 5] = [
    [-0.6344, 0.0022, -0.0001, 0.9871, 0.0010],
    [0.0, -0.2912, 0.1026, 0.0, -0.3707],
    [0.0, -6.2354, -0.4312, 0.0, -4.1270],
    [-0.5971, 0.0003, 0.0001, -0.5099, 0.0006],
    [0.0, -0.4528, -0.0481, 0.0, -0.9513],
];
/// B (one input).
pub const B: [f64; 5] = [-0.0459, -0.0047, 3.7830, -2.5115, -0.0453];
/// E (three fault channels).
pub const E: [[f64; 3]; 5] = [
    [-0.0395, -0.0133, -1.0],
    [0.0, 0.0031, 0.0],
    [0.0, 1.8255, -0.5],
    [-1.9042, -0.9494, -1.0],
    [0.0, -0.2081, 0.0],
];
/// Outputs: C = [I₄ 0].
pub const OUTPUTS: usize = 4;

/// The input u(t) = 10 sin 10t + sin 2t.
#[must_use]
pub fn input(t: f64) -> f64 {
    10.0 * (10.0 * t).sin() + (2.0 * t).sin()
}

/// Candidate fault i (1 or 2) at state x.
#[must_use]
pub fn candidate(i: usize, x: &[f64]) -> [f64; 3] {
    match i {
        1 => [x[1] + x[2], x[3].cos(), (0.5 * x[4]).cos()],
        _ => [x[1] + x[2], 20.0 * (-x[3].abs()).exp(), (0.5 * x[4]).sin()],
    }
}

/// The Lipschitz constant in x of candidate i: the largest Frobenius norm of its
/// Jacobian, √(2 + 1 + 0.25) for φ₁ and √(2 + 400 + 0.25) for φ₂.
#[must_use]
pub fn lipschitz(i: usize) -> f64 {
    if i == 1 {
        3.25_f64.sqrt()
    } else {
        402.25_f64.sqrt()
    }
}

/// Candidate 1 or 2 of the paper as a detector's candidate function.
#[derive(Debug, Clone, Copy)]
pub struct PaperCandidate(pub usize);

impl CandidateFn for PaperCandidate {
    fn evaluate(&mut self, _t: f64, x: &[f64], _u: &[f64], out: &mut [f64]) {
        out.copy_from_slice(&candidate(self.0, x));
    }
}

/// The continuous-time model (A, B, C = [I₄ 0], E) for the kernel detector.
#[must_use]
pub fn model() -> KernelModel {
    KernelModel {
        a: DMatrix::from_fn(5, 5, |i, j| A[i][j]),
        b: DMatrix::from_column_slice(5, 1, &B),
        c: DMatrix::from_fn(OUTPUTS, 5, |i, j| if i == j { 1.0 } else { 0.0 }),
        e: DMatrix::from_fn(5, 3, |i, j| E[i][j]),
    }
}

/// The kernel detector of the example with `settings` and the candidates φ₁, φ₂
/// (named `phi1`, `phi2`, with their Lipschitz constants).
///
/// # Errors
/// As [`KernelDetector::new`] (a setting out of range).
pub fn detector(settings: KernelSettings) -> Result<KernelDetector, ModelError> {
    let candidates = (1..=2)
        .map(|i| Candidate {
            name: format!("phi{i}"),
            lipschitz: lipschitz(i),
            function: Box::new(PaperCandidate(i)),
        })
        .collect();
    KernelDetector::new(&model(), 0, settings, candidates)
}

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct ExampleRun {
    /// Sample period Δ (s).
    pub period: f64,
    /// RK4 steps per period.
    pub substeps: usize,
    /// Number of samples (the first at t = 0).
    pub samples: usize,
    /// The acting fault: candidate 1 or 2 from the given time (s).
    pub fault: Option<(usize, f64)>,
    /// Amplitude of each state-noise component (the paper: 0.2).
    pub state_noise: f64,
    /// Amplitude of each output-noise component (the paper: 0.5).
    pub output_noise: f64,
    /// Noise seed.
    pub seed: u64,
}

impl ExampleRun {
    /// The paper's run: φ₂ from t = 5 s, Δ = 1 ms, 20 RK4 steps per sample, 15 s,
    /// noise-free.
    #[must_use]
    pub fn paper(seed: u64) -> Self {
        Self {
            period: 1e-3,
            substeps: 20,
            samples: 15_001,
            fault: Some((2, 5.0)),
            state_noise: 0.0,
            output_noise: 0.0,
            seed,
        }
    }
}

/// The sampled record: per sample k, t_k = kΔ, u_k, y_k (4 values) and the true
/// state x_k (5 values), flat.
#[derive(Debug, Clone, Default)]
pub struct ExampleData {
    /// u_k.
    pub u: Vec<f64>,
    /// y_k, 4 per sample.
    pub y: Vec<f64>,
    /// x_k, 5 per sample.
    pub x: Vec<f64>,
}

impl ExampleData {
    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }

    /// Sample k as a detector takes it.
    #[must_use]
    pub fn sample(&self, k: usize) -> Sample<'_> {
        Sample {
            k: k as u64,
            u: &self.u[k..=k],
            y: &self.y[OUTPUTS * k..OUTPUTS * (k + 1)],
            p: &[],
        }
    }
}

fn derivative(t: f64, x: &[f64; 5], noise: &[f64; 5], fault: Option<(usize, f64)>) -> [f64; 5] {
    let u = input(t);
    let f = match fault {
        Some((i, onset)) if t >= onset => candidate(i, x),
        _ => [0.0; 3],
    };
    let mut dx = [0.0; 5];
    for r in 0..5 {
        let mut v = B[r] * u + noise[r];
        for c in 0..5 {
            v += A[r][c] * x[c];
        }
        for c in 0..3 {
            v += E[r][c] * f[c];
        }
        dx[r] = v;
    }
    dx
}

/// Simulates `run` from x(0) = 0.
#[must_use]
pub fn simulate(run: &ExampleRun) -> ExampleData {
    let mut rng = Rng::new(run.seed);
    let mut x = [0.0; 5];
    let mut data = ExampleData {
        u: Vec::with_capacity(run.samples),
        y: Vec::with_capacity(run.samples * OUTPUTS),
        x: Vec::with_capacity(run.samples * 5),
    };
    let h = run.period / run.substeps as f64;
    for k in 0..run.samples {
        let t = k as f64 * run.period;
        data.u.push(input(t));
        for value in x.iter().take(OUTPUTS) {
            let noise = if run.output_noise > 0.0 {
                rng.uniform_in(-run.output_noise, run.output_noise)
            } else {
                0.0
            };
            data.y.push(value + noise);
        }
        data.x.extend_from_slice(&x);
        let mut noise = [0.0; 5];
        if run.state_noise > 0.0 {
            for v in &mut noise {
                *v = rng.uniform_in(-run.state_noise, run.state_noise);
            }
        }
        for s in 0..run.substeps {
            let ts = t + s as f64 * h;
            let k1 = derivative(ts, &x, &noise, run.fault);
            let x2: [f64; 5] = std::array::from_fn(|i| x[i] + 0.5 * h * k1[i]);
            let k2 = derivative(ts + 0.5 * h, &x2, &noise, run.fault);
            let x3: [f64; 5] = std::array::from_fn(|i| x[i] + 0.5 * h * k2[i]);
            let k3 = derivative(ts + 0.5 * h, &x3, &noise, run.fault);
            let x4: [f64; 5] = std::array::from_fn(|i| x[i] + h * k3[i]);
            let k4 = derivative(ts + h, &x4, &noise, run.fault);
            for i in 0..5 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    data
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rk4_converges_at_fourth_order() {
        // Halving the step divides the error by about 16: 1 and 2 steps per 50 ms
        // period against 64, over the 5 s before the fault (steps large enough for the
        // truncation error to dominate rounding; a stage at the fault's onset would
        // make the error of its jump, first order, dominate).
        let run = |substeps| {
            simulate(&ExampleRun {
                period: 0.05,
                samples: 100,
                substeps,
                ..ExampleRun::paper(0)
            })
        };
        let (a, b, c) = (run(1), run(2), run(64));
        let err = |d: &ExampleData| {
            d.x.iter()
                .zip(&c.x)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max)
        };
        let ratio = err(&a) / err(&b);
        assert!((12.0..20.0).contains(&ratio), "ratio {ratio}");
    }
}
