//! The deadbeat state estimator of Li, Boem, Pin & Parisini, §III-A: the state
//! reconstructed exactly (noise-free, continuous time) from the time Γ becomes
//! invertible, without an observer's asymptotic convergence and independently of the
//! fault.
//!
//! ζ̂₁ = S_{I,1}y and η̂₂ = S_{I,2}y come from the outputs (4). The fault-free part
//! in observer form obeys η₂^{(n⋆)} = Σ aᵢη₂^{(i)} + Σ_j w_j^{(n⋆−j)}, w = A_{c21}ζ₁ +
//! B_c u. Multiplying by the kernels K_h(t, τ) = e^{−ω_h(t−τ)}(1 − e^{−ω̄τ})^N (6)
//! (h = 1…n⋆; printed in t, but (9) and (26) need τ) and integrating by parts, the
//! terms at τ = 0 vanish (K_h^{(i)}(t, 0) = 0 for i < N) and those at τ = t leave (7):
//! Γ(t) z(t) = ν(t), with Γ_{hj} = (−1)^{n⋆−j} K_h^{(n⋆−j)}(t, t) and
//! ν_h = (−1)^{n⋆+1} ξ_{η,n⋆} + Σᵢ aᵢ(−1)ⁱ ξ_{η,i} + Σ_j (−1)^{n⋆−j}[A_{c21}ξ_{ζ₁,n⋆−j}
//! \+ B_c ξ_{u,n⋆−j}]_j (8), ξ_{s,i} = ∫₀ᵗ K_h^{(i)}(t, τ) s(τ) dτ. With
//! K_h^{(i)}(t, τ) = e^{−ω_h(t−τ)} Σ_q C(N,q)(−1)^q λ_q^i e^{−qω̄τ}, λ_q = ω_h − qω̄,
//! every ξ is a combination of the images I_{ω_h, qω̄} of [`super::volterra`], the
//! internally stable realisation (9). Once |det Γ| ≥ θ_a (Remark 4.1) z = Γ⁻¹ν,
//! ζ̂₂ = P⁻¹z and x̂ = T₁ζ̂₁ + T₂ζ̂₂ (11).
//!
//! N ≥ n⋆ is required: the derivatives up to order n⋆ enter (8), and the boundary
//! terms at τ = 0 vanish only up to order N − 1 (the paper's N ≥ n⋆ − 1 leaves one
//! nonzero term).

use super::decomposition::Decomposition;
use super::volterra::{AbsKernelIntegral, ImageBank};

/// The binomial coefficient C(n, k).
fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// The kernel's coefficients c_q λ_q^i of K^{(i)}(t, τ) = e^{−ω_h(t−τ)} Σ_q c_q λ_q^i
/// e^{−qω̄τ}, for q = 0…N.
#[must_use]
pub fn kernel_coefficients(omega_h: f64, omega_bar: f64, n: usize, i: usize) -> Vec<f64> {
    (0..=n)
        .map(|q| {
            let sign = if q % 2 == 0 { 1.0 } else { -1.0 };
            let lambda = omega_h - q as f64 * omega_bar;
            sign * binomial(n, q) * lambda.powi(i as i32)
        })
        .collect()
}

/// K^{(i)}(t, τ) by its coefficients (the τ-derivative of order i of the kernel (6)).
#[must_use]
pub fn kernel_derivative(
    coefficients: &[f64],
    omega_h: f64,
    omega_bar: f64,
    t: f64,
    tau: f64,
) -> f64 {
    let x = (-omega_bar * tau).exp();
    let p = coefficients.iter().rev().fold(0.0, |acc, c| acc * x + c);
    (-omega_h * (t - tau)).exp() * p
}

/// The deadbeat estimator's state and buffers. Allocation-free per sample.
#[derive(Debug, Clone)]
pub struct DeadbeatEstimator {
    order: usize,
    faults: usize,
    inputs: usize,
    terms: usize,
    /// c_q λ_{h,q}^i at [(h·(n⋆+1) + i)·(N+1) + q].
    coefficients: Vec<f64>,
    omega_bar: f64,
    activation: f64,
    bank: ImageBank,
    abs: Vec<AbsKernelIntegral>,
    signal: Vec<f64>,
    gamma: Vec<f64>,
    gamma_inv: Vec<f64>,
    scratch: Vec<f64>,
    nu: Vec<f64>,
    z: Vec<f64>,
    zeta1: Vec<f64>,
    zeta2: Vec<f64>,
    eps_mu: Vec<f64>,
    determinant: f64,
    active_since: Option<f64>,
    eps_zeta2: f64,
    /// ε̄_ζ₁ = ‖S_{I,1}‖₂ d̄_y, ε̄_η = ‖S_{I,2}‖ d̄_y, d̄_{x,2} = ‖T⁻¹ (ζ₂ rows)‖₂ d̄_x.
    eps_zeta1: f64,
    eps_eta: f64,
    dx2: f64,
    ac21_rows: Vec<f64>,
    p_rows: Vec<f64>,
}

impl DeadbeatEstimator {
    /// The estimator for `design`, kernel rates ω_h (n⋆ of them), ω̄, N, activation
    /// level θ_a, sample period Δ and the noise bounds ε̄_ζ₁, ε̄_η, d̄_{x,2}.
    #[allow(clippy::too_many_arguments)]
    #[must_use]
    pub fn new(
        design: &Decomposition,
        inputs: usize,
        rates: &[f64],
        omega_bar: f64,
        n: usize,
        activation: f64,
        dt: f64,
        bounds: [f64; 3],
    ) -> Self {
        let order = design.order;
        let faults = design.faults;
        let mut coefficients = Vec::with_capacity(order * (order + 1) * (n + 1));
        let mut pairs = Vec::with_capacity(order * (n + 1));
        let mut abs = Vec::with_capacity(order * (order + 1));
        for &w in rates {
            for i in 0..=order {
                let c = kernel_coefficients(w, omega_bar, n, i);
                abs.push(AbsKernelIntegral::new(dt, w, omega_bar, &c));
                coefficients.extend_from_slice(&c);
            }
            for q in 0..=n {
                pairs.push((w, q as f64 * omega_bar));
            }
        }
        let signals = 1 + faults + inputs;
        let row_norms =
            |m: &nalgebra::DMatrix<f64>| (0..m.nrows()).map(|j| m.row(j).norm()).collect();
        Self {
            order,
            faults,
            inputs,
            terms: n + 1,
            coefficients,
            omega_bar,
            activation,
            bank: ImageBank::new(dt, &pairs, signals, signals),
            abs,
            signal: vec![0.0; signals],
            gamma: vec![0.0; order * order],
            gamma_inv: vec![0.0; order * order],
            scratch: vec![0.0; order * order],
            nu: vec![0.0; order],
            z: vec![0.0; order],
            zeta1: vec![0.0; faults],
            zeta2: vec![0.0; order],
            eps_mu: vec![0.0; order],
            determinant: 0.0,
            active_since: None,
            eps_zeta2: 0.0,
            eps_zeta1: bounds[0],
            eps_eta: bounds[1],
            dx2: bounds[2],
            ac21_rows: row_norms(&design.ac21),
            p_rows: row_norms(&design.p),
        }
    }

    /// Back to t = 0: the next sample is the kernels' origin.
    pub fn reset(&mut self) {
        self.bank.reset();
        for a in &mut self.abs {
            a.reset();
        }
        self.active_since = None;
        self.determinant = 0.0;
        self.eps_zeta2 = 0.0;
        self.zeta2.fill(0.0);
    }

    /// The time since the origin.
    #[must_use]
    pub fn time(&self) -> f64 {
        self.bank.time()
    }

    /// det Γ(t) at the last sample.
    #[must_use]
    pub fn determinant(&self) -> f64 {
        self.determinant
    }

    /// T_a: the time since the origin at which |det Γ| first reached θ_a.
    #[must_use]
    pub fn active_since(&self) -> Option<f64> {
        self.active_since
    }

    /// ζ̂₁ = S_{I,1}y of the last sample.
    #[must_use]
    pub fn zeta1(&self) -> &[f64] {
        &self.zeta1
    }

    /// ζ̂₂ = P⁻¹Γ⁻¹ν (zeros before activation).
    #[must_use]
    pub fn zeta2(&self) -> &[f64] {
        &self.zeta2
    }

    /// The bound ε̄_ζ₂(t) = ‖P⁻¹Γ⁻¹‖_F ‖ε̄_μ‖ on ‖ζ̂₂ − ζ₂‖ (from (23)-(28)), the
    /// Frobenius norm standing in for the spectral one (larger by at most √n⋆) so that
    /// it costs no decomposition per sample.
    #[must_use]
    pub fn eps_zeta2(&self) -> f64 {
        self.eps_zeta2
    }

    /// ε̄_ζ₁.
    #[must_use]
    pub fn eps_zeta1(&self) -> f64 {
        self.eps_zeta1
    }

    /// Takes one sample (y, u) and updates the estimate; true once active.
    pub fn push(&mut self, design: &Decomposition, y: &[f64], u: &[f64]) -> bool {
        let n = self.order;
        let m = self.signal.len();
        // (4): ζ̂₁ = S_{I,1}y, η̂₂ = S_{I,2}y.
        let mut eta = 0.0;
        for (j, yj) in y.iter().enumerate() {
            eta += design.s2[(0, j)] * yj;
        }
        for (i, z) in self.zeta1.iter_mut().enumerate() {
            *z = (0..y.len()).map(|j| design.s1[(i, j)] * y[j]).sum();
        }
        self.signal[0] = eta;
        self.signal[1..=self.faults].copy_from_slice(&self.zeta1);
        self.signal[1 + self.faults..m].copy_from_slice(u);
        let first = !self.bank.started();
        self.bank.push(&self.signal);
        if !first {
            for a in &mut self.abs {
                a.advance();
            }
        }
        let t = self.bank.time();
        let x = (-self.omega_bar * t).exp();
        let terms = self.terms;
        let coef = |h: usize, i: usize| -> &[f64] {
            let at = (h * (n + 1) + i) * terms;
            &self.coefficients[at..at + terms]
        };
        let xi = |h: usize, i: usize, s: usize| -> f64 {
            coef(h, i)
                .iter()
                .enumerate()
                .map(|(q, c)| c * self.bank.image(h * terms + q, s))
                .sum()
        };
        let sign = |e: usize| if e.is_multiple_of(2) { 1.0 } else { -1.0 };
        for h in 0..n {
            // Γ[h][j] = (−1)^{n−j} K_h^{(n−j)}(t, t), j = 1…n (7).
            for j in 1..=n {
                let p = coef(h, n - j).iter().rev().fold(0.0, |acc, c| acc * x + c);
                self.gamma[h * n + j - 1] = sign(n - j) * p;
            }
            // ν_h (8).
            let mut nu = sign(n + 1) * xi(h, n, 0);
            for (i, a) in design.a.iter().enumerate() {
                nu += a * sign(i) * xi(h, i, 0);
            }
            for j in 1..=n {
                let mut w = 0.0;
                for c in 0..self.faults {
                    w += design.ac21[(j - 1, c)] * xi(h, n - j, 1 + c);
                }
                for c in 0..self.inputs {
                    w += design.bc[(j - 1, c)] * xi(h, n - j, 1 + self.faults + c);
                }
                nu += sign(n - j) * w;
            }
            self.nu[h] = nu;
            // ε̄_μ,h: the image of the noise bounds through |K_h^{(i)}|.
            let abs = |i: usize| self.abs[h * (n + 1) + i].value();
            let mut eps = abs(n);
            for (i, a) in design.a.iter().enumerate() {
                eps += a.abs() * abs(i);
            }
            eps *= self.eps_eta;
            for j in 1..=n {
                eps += abs(n - j)
                    * (self.ac21_rows[j - 1] * self.eps_zeta1 + self.p_rows[j - 1] * self.dx2);
            }
            self.eps_mu[h] = eps;
        }
        self.determinant = invert(&self.gamma, &mut self.scratch, &mut self.gamma_inv, n);
        if self.active_since.is_none() && self.determinant.abs() >= self.activation {
            self.active_since = Some(t);
        }
        if self.active_since.is_none() || self.determinant == 0.0 {
            self.zeta2.fill(0.0);
            self.eps_zeta2 = 0.0;
            return false;
        }
        for r in 0..n {
            self.z[r] = (0..n).map(|c| self.gamma_inv[r * n + c] * self.nu[c]).sum();
        }
        let mut frob = 0.0;
        for r in 0..n {
            self.zeta2[r] = (0..n).map(|c| design.p_inv[(r, c)] * self.z[c]).sum();
            for c in 0..n {
                let v: f64 = (0..n)
                    .map(|k| design.p_inv[(r, k)] * self.gamma_inv[k * n + c])
                    .sum();
                frob += v * v;
            }
        }
        let mu: f64 = self.eps_mu.iter().map(|e| e * e).sum::<f64>().sqrt();
        self.eps_zeta2 = frob.sqrt() * mu;
        true
    }

    /// x̂ = T₁ζ̂₁ + T₂ζ̂₂ (11) into `out`.
    pub fn state(&self, design: &Decomposition, out: &mut [f64]) {
        let p = self.faults;
        for (r, o) in out.iter_mut().enumerate() {
            let mut v = 0.0;
            for c in 0..p {
                v += design.t[(r, c)] * self.zeta1[c];
            }
            for c in 0..self.order {
                v += design.t[(r, p + c)] * self.zeta2[c];
            }
            *o = v;
        }
    }
}

/// Inverts the row-major n × n `m` into `inv` by Gauss-Jordan elimination with
/// partial pivoting (`work` a copy of m), returning det m (0 for a singular m, `inv`
/// then meaningless). Allocation-free.
fn invert(m: &[f64], work: &mut [f64], inv: &mut [f64], n: usize) -> f64 {
    work.copy_from_slice(m);
    inv.fill(0.0);
    for i in 0..n {
        inv[i * n + i] = 1.0;
    }
    let mut det = 1.0;
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&a, &b| work[a * n + col].abs().total_cmp(&work[b * n + col].abs()))
            .unwrap_or(col);
        let v = work[pivot * n + col];
        if v == 0.0 || !v.is_finite() {
            return 0.0;
        }
        if pivot != col {
            for c in 0..n {
                work.swap(pivot * n + c, col * n + c);
                inv.swap(pivot * n + c, col * n + c);
            }
            det = -det;
        }
        det *= v;
        for c in 0..n {
            work[col * n + c] /= v;
            inv[col * n + c] /= v;
        }
        for r in 0..n {
            if r != col {
                let f = work[r * n + col];
                if f != 0.0 {
                    for c in 0..n {
                        work[r * n + c] -= f * work[col * n + c];
                        inv[r * n + c] -= f * inv[col * n + c];
                    }
                }
            }
        }
    }
    det
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_derivatives_vanish_at_the_origin_below_order_n() {
        // The decision on (6): the kernel is (1 − e^{−ω̄τ})^N in τ, so that K^{(i)}(t, 0)
        // = 0 for i < N, which the integration by parts of (7) needs. Printed in t, it
        // would not vanish at τ = 0 for t > 0.
        for &(wh, wb, n) in &[(1.0, 2.5, 2), (2.0, 2.5, 2), (0.7, 1.3, 4)] {
            for i in 0..n {
                let c = kernel_coefficients(wh, wb, n, i);
                let v = kernel_derivative(&c, wh, wb, 3.0, 0.0);
                assert!(v.abs() < 1e-12, "K^({i})(t,0) = {v}");
            }
            let c = kernel_coefficients(wh, wb, n, n);
            assert!(kernel_derivative(&c, wh, wb, 3.0, 0.0).abs() > 1e-3);
            // The coefficients are the derivatives: finite differences in τ.
            for i in 0..n {
                let c0 = kernel_coefficients(wh, wb, n, i);
                let c1 = kernel_coefficients(wh, wb, n, i + 1);
                let (t, tau, h) = (3.0, 1.2, 1e-6);
                let fd = (kernel_derivative(&c0, wh, wb, t, tau + h)
                    - kernel_derivative(&c0, wh, wb, t, tau - h))
                    / (2.0 * h);
                let exact = kernel_derivative(&c1, wh, wb, t, tau);
                assert!((fd - exact).abs() < 1e-7, "i = {i}: {fd} vs {exact}");
            }
        }
        // i = 0 is the kernel itself.
        let c = kernel_coefficients(1.0, 2.5, 2, 0);
        let direct = (-(3.0_f64 - 1.2)).exp() * (1.0 - (-2.5_f64 * 1.2).exp()).powi(2);
        assert!((kernel_derivative(&c, 1.0, 2.5, 3.0, 1.2) - direct).abs() < 1e-14);
    }

    #[test]
    fn gauss_jordan_inverse_and_determinant() {
        let m = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut w = [0.0; 9];
        let mut inv = [0.0; 9];
        let det = invert(&m, &mut w, &mut inv, 3);
        let exact = nalgebra::DMatrix::from_row_slice(3, 3, &m);
        assert!((det - exact.determinant()).abs() < 1e-14);
        let product = exact * nalgebra::DMatrix::from_row_slice(3, 3, &inv);
        assert!((product - nalgebra::DMatrix::<f64>::identity(3, 3)).amax() < 1e-14);
        assert_eq!(
            invert(&[1.0, 2.0, 2.0, 4.0], &mut [0.0; 4], &mut [0.0; 4], 2),
            0.0
        );
    }
}
