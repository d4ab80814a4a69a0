//! Volterra images on sampled data: the integrals
//! I_{r,d}(s)(t) = ∫₀ᵗ e^{−r(t−τ)} e^{−dτ} s(τ) dτ
//! from which every kernel image of the method is a fixed combination, integrated
//! exactly over each sample period under a first-order hold on s.
//!
//! Li, Boem, Pin & Parisini write the images as the ODEs (9) and (18): İ = −rI +
//! e^{−dt}s(t), I(0) = 0, with r > 0 (internally stable). Between two samples s is
//! taken linear (first-order hold), so one step is
//! I_{k+1} = e^{−rΔ} I_k + e^{−d t_k} (α₀ s_k + α₁ s_{k+1}),
//! with α₀ = J₀ − J₁/Δ, α₁ = J₁/Δ, J₀ = ∫₀^Δ e^{−r(Δ−σ)}e^{−dσ} dσ and
//! J₁ = ∫₀^Δ σ e^{−r(Δ−σ)}e^{−dσ} dσ. The only error is the hold's: zero for signals
//! linear between samples, O(Δ²) for smooth ones.

/// The largest rΔ accepted: e^{−rΔ} below e^{−50} means the sample period is far
/// too long for the kernel, whose memory would be under one sample.
pub const MAX_RATE_STEP: f64 = 50.0;

/// J₀ and J₁ of a step of length `dt` for the rates r and d (module doc), exact in
/// closed form when |(r − d)Δ| ≥ 1 and by their series otherwise (no cancellation
/// near r = d, where the closed form divides by r − d).
#[must_use]
pub fn step_moments(r: f64, d: f64, dt: f64) -> (f64, f64) {
    let g = r - d;
    let c = g * dt;
    if c.abs() >= 1.0 {
        let ed = (-d * dt).exp();
        let er = (-r * dt).exp();
        let j0 = (ed - er) / g;
        let j1 = dt * ed / g - (ed - er) / (g * g);
        (j0, j1)
    } else {
        // e^{−rΔ} ∫₀^Δ e^{gσ} dσ and e^{−rΔ} ∫₀^Δ σ e^{gσ} dσ, term by term in c = gΔ.
        let er = (-r * dt).exp();
        let mut term = 1.0; // c^k / k!
        let mut s0 = 0.0;
        let mut s1 = 0.0;
        for k in 0..40 {
            let kf = f64::from(k);
            s0 += term / (kf + 1.0);
            s1 += term / (kf + 2.0);
            term *= c / (kf + 1.0);
            if term.abs() < 1e-18 {
                break;
            }
        }
        (er * dt * s0, er * dt * dt * s1)
    }
}

/// The image integrals I_{r,d}(s) of a set of signals for a set of rate pairs, all
/// sharing one time origin: pair j of signal i lives at `state[j·m + i]`.
///
/// Signals at index `bound_from` and beyond are noise bounds, not measurements: they
/// are held at the larger of their two end values over a step (a zero-order hold
/// from above), so the image of a bound stays a bound for the nonnegative kernels it
/// is used with.
#[derive(Debug, Clone)]
pub struct ImageBank {
    dt: f64,
    rates: Vec<(f64, f64)>,
    decay: Vec<f64>,
    alpha: Vec<(f64, f64)>,
    bound_alpha: Vec<f64>,
    signals: usize,
    bound_from: usize,
    state: Vec<f64>,
    previous: Vec<f64>,
    steps: u64,
    started: bool,
}

impl ImageBank {
    /// A bank for `signals` signals and the rate pairs (r, d), sample period `dt`.
    #[must_use]
    pub fn new(dt: f64, rates: &[(f64, f64)], signals: usize, bound_from: usize) -> Self {
        let mut decay = Vec::with_capacity(rates.len());
        let mut alpha = Vec::with_capacity(rates.len());
        let mut bound_alpha = Vec::with_capacity(rates.len());
        for &(r, d) in rates {
            let (j0, j1) = step_moments(r, d, dt);
            decay.push((-r * dt).exp());
            alpha.push((j0 - j1 / dt, j1 / dt));
            bound_alpha.push(j0);
        }
        Self {
            dt,
            rates: rates.to_vec(),
            decay,
            alpha,
            bound_alpha,
            signals,
            bound_from: bound_from.min(signals),
            state: vec![0.0; rates.len() * signals],
            previous: vec![0.0; signals],
            steps: 0,
            started: false,
        }
    }

    /// Forgets everything: the next sample is the new time origin t = 0.
    pub fn reset(&mut self) {
        self.state.fill(0.0);
        self.previous.fill(0.0);
        self.steps = 0;
        self.started = false;
    }

    /// Whether a sample has been taken since the origin.
    #[must_use]
    pub fn started(&self) -> bool {
        self.started
    }

    /// The time since the origin, t = (samples − 1)·Δ (0 before the second sample).
    #[must_use]
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// Takes the signals' values at the next sample (the first one is the origin,
    /// where every image is 0) and integrates the images up to it. Allocation-free.
    pub fn push(&mut self, s: &[f64]) {
        debug_assert_eq!(s.len(), self.signals);
        if !self.started {
            self.previous.copy_from_slice(s);
            self.started = true;
            return;
        }
        let t = self.time();
        let m = self.signals;
        for (j, &(_, d)) in self.rates.iter().enumerate() {
            let w = (-d * t).exp();
            let decay = self.decay[j];
            let (a0, a1) = self.alpha[j];
            let b = self.bound_alpha[j];
            let row = &mut self.state[j * m..(j + 1) * m];
            for (i, value) in row.iter_mut().enumerate() {
                let input = if i < self.bound_from {
                    a0 * self.previous[i] + a1 * s[i]
                } else {
                    b * self.previous[i].max(s[i])
                };
                *value = decay * *value + w * input;
            }
        }
        self.previous.copy_from_slice(s);
        self.steps += 1;
    }

    /// I_{r_j, d_j}(s_i) at the last sample.
    #[must_use]
    pub fn image(&self, pair: usize, signal: usize) -> f64 {
        self.state[pair * self.signals + signal]
    }
}

/// Ā(t) = ∫₀ᵗ e^{−r(t−τ)} |p(e^{−ω̄τ})| dτ for a polynomial p(x) = Σ_q c_q x^q: the
/// L¹ norm of a kernel K(t, τ) = e^{−r(t−τ)} p(e^{−ω̄τ}) over [0, t], which scales the
/// noise bounds (Li et al., (23)-(31)). Integrated exactly: p keeps its sign between
/// its roots in x ∈ (0, 1), found once (at times τ = −ln x / ω̄), and on each piece
/// the integrand is a sum of exponentials.
#[derive(Debug, Clone)]
pub struct AbsKernelIntegral {
    dt: f64,
    r: f64,
    omega_bar: f64,
    coefficients: Vec<f64>,
    /// The moments J₀(r, qω̄, Δ) of a whole step, per q.
    step_j0: Vec<f64>,
    roots: Vec<f64>,
    value: f64,
    steps: u64,
}

impl AbsKernelIntegral {
    /// Ā for p with `coefficients` c_0…c_N, rate r, ω̄ and period `dt`.
    #[must_use]
    pub fn new(dt: f64, r: f64, omega_bar: f64, coefficients: &[f64]) -> Self {
        let step_j0 = (0..coefficients.len())
            .map(|q| step_moments(r, q as f64 * omega_bar, dt).0)
            .collect();
        Self {
            dt,
            r,
            omega_bar,
            coefficients: coefficients.to_vec(),
            step_j0,
            roots: root_times(coefficients, omega_bar),
            value: 0.0,
            steps: 0,
        }
    }

    fn poly(&self, x: f64) -> f64 {
        self.coefficients
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * x + c)
    }

    /// Back to t = 0, Ā = 0.
    pub fn reset(&mut self) {
        self.value = 0.0;
        self.steps = 0;
    }

    /// Ā at the current time.
    #[must_use]
    pub fn value(&self) -> f64 {
        self.value
    }

    /// Advances by one sample period. Allocation-free.
    pub fn advance(&mut self) {
        let t0 = self.steps as f64 * self.dt;
        let t1 = t0 + self.dt;
        let first = self.roots.partition_point(|&x| x <= t0);
        let last = self.roots.partition_point(|&x| x < t1);
        let mut piece = 0.0;
        if first == last {
            let sign = self
                .poly((-self.omega_bar * (0.5 * (t0 + t1))).exp())
                .signum();
            for (q, c) in self.coefficients.iter().enumerate() {
                let d = q as f64 * self.omega_bar;
                piece += c * (-d * t0).exp() * self.step_j0[q];
            }
            piece *= sign;
        } else {
            let mut a = t0;
            for idx in first..=last {
                let b = if idx < last { self.roots[idx] } else { t1 };
                if b > a {
                    let sign = self
                        .poly((-self.omega_bar * (0.5 * (a + b))).exp())
                        .signum();
                    let to_end = (-self.r * (t1 - b)).exp();
                    for (q, c) in self.coefficients.iter().enumerate() {
                        let d = q as f64 * self.omega_bar;
                        let (j0, _) = step_moments(self.r, d, b - a);
                        piece += sign * c * to_end * (-d * a).exp() * j0;
                    }
                }
                a = b;
            }
        }
        self.value = (-self.r * self.dt).exp() * self.value + piece.max(0.0);
        self.steps += 1;
    }
}

/// The times τ > 0 at which p(e^{−ω̄τ}) changes sign: the roots of p in (0, 1), by
/// a scan of 10⁴ points and bisection to rounding.
fn root_times(coefficients: &[f64], omega_bar: f64) -> Vec<f64> {
    let poly = |x: f64| coefficients.iter().rev().fold(0.0, |acc, c| acc * x + c);
    let grid = 10_000;
    let mut times = Vec::new();
    let mut x0 = 0.0_f64;
    let mut p0 = poly(x0);
    for i in 1..=grid {
        let x1 = f64::from(i) / f64::from(grid);
        let p1 = poly(x1);
        if p0 != 0.0 && p1 != 0.0 && p0.signum() != p1.signum() && x1 < 1.0 {
            let (mut lo, mut hi) = (x0, x1);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if poly(mid).signum() == p0.signum() {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let x = 0.5 * (lo + hi);
            if x > 0.0 {
                times.push(-x.ln() / omega_bar);
            }
        }
        x0 = x1;
        p0 = p1;
    }
    times.sort_by(f64::total_cmp);
    times
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Composite Simpson on n (even) intervals.
    fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            let w = if i % 2 == 1 { 4.0 } else { 2.0 };
            s += w * f(a + i as f64 * h);
        }
        s * h / 3.0
    }

    #[test]
    fn step_moments_match_quadrature_on_both_branches() {
        for &(r, d, dt) in &[
            (1.0, 0.0, 0.01),
            (2.0, 2.0, 0.5),
            (1.0, 2.5, 0.001),
            (3.0, 0.0, 1.0),
            (0.5, 7.5, 0.4),
            (4.0, 1.0, 2.0),
        ] {
            let (j0, j1) = step_moments(r, d, dt);
            let q0 = simpson(|s| (-r * (dt - s)).exp() * (-d * s).exp(), 0.0, dt, 2000);
            let q1 = simpson(
                |s| s * (-r * (dt - s)).exp() * (-d * s).exp(),
                0.0,
                dt,
                2000,
            );
            assert!(
                (j0 - q0).abs() <= 1e-12 * q0.abs().max(1e-300),
                "J0 r={r} d={d}"
            );
            assert!(
                (j1 - q1).abs() <= 1e-11 * q1.abs().max(1e-300),
                "J1 r={r} d={d}"
            );
        }
    }

    #[test]
    fn bank_is_exact_for_signals_linear_between_samples() {
        // s(τ) = 1 + 3τ is linear: the first-order hold is exact, so the bank equals
        // the closed form of ∫₀ᵗ e^{−r(t−τ)}e^{−dτ}(1 + 3τ) dτ by quadrature.
        let dt = 0.01;
        let rates = [(1.0, 0.0), (2.0, 2.5), (1.0, 1.0)];
        let mut bank = ImageBank::new(dt, &rates, 1, 1);
        let steps = 700;
        for k in 0..=steps {
            bank.push(&[1.0 + 3.0 * k as f64 * dt]);
        }
        let t = steps as f64 * dt;
        for (j, &(r, d)) in rates.iter().enumerate() {
            let exact = simpson(
                |s| (-r * (t - s)).exp() * (-d * s).exp() * (1.0 + 3.0 * s),
                0.0,
                t,
                20_000,
            );
            assert!(
                (bank.image(j, 0) - exact).abs() < 1e-11,
                "pair {j}: {} vs {exact}",
                bank.image(j, 0)
            );
        }
    }

    #[test]
    fn abs_kernel_integral_matches_quadrature_across_sign_changes() {
        // p(x) = 1 − 3x + 1.5x² changes sign in (0, 1) once.
        let c = [1.0, -3.0, 1.5];
        let (dt, r, wb) = (0.01, 1.5, 2.5);
        let mut a = AbsKernelIntegral::new(dt, r, wb, &c);
        assert_eq!(a.roots.len(), 1);
        let steps = 400;
        for _ in 0..steps {
            a.advance();
        }
        let t = steps as f64 * dt;
        let p = |x: f64| c[0] + c[1] * x + c[2] * x * x;
        let exact = simpson(
            |s| (-r * (t - s)).exp() * p((-wb * s).exp()).abs(),
            0.0,
            t,
            200_000,
        );
        assert!((a.value() - exact).abs() < 1e-9, "{} vs {exact}", a.value());
    }
}
