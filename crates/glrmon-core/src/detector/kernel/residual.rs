//! Detection and isolation residuals of Li, Boem, Pin & Parisini, §III-B and §IV:
//! the image of the fault through the bilateral kernel (13)-(14), its norm r_FD (19)
//! against the bound σ_FD(t) (32), and the isolation residuals r_FI,i (35) against
//! σ_FI,i (37).
//!
//! The BC-NK kernel F(t, τ) = (e^{−ω(t−τ)} − e^{−2ω(t−τ)})(1 − e^{−ωτ}) vanishes at
//! τ = 0 and τ = t, so integrating ζ̇₁ = A₁₁ζ₁ + A₁₂ζ₂ + B₁u + E₁f against it leaves no
//! boundary term: E₁V_F f = −V_{F'}ζ₁ − A₁₁V_Fζ₁ − A₁₂V_Fζ₂ − B₁V_F u (15), with
//! F' = ∂F/∂τ (B₁ belongs inside the bracket: the printed parentheses of (15) do not
//! balance). Expanded (the split (17)), V_F s = I_{ω,0} − I_{ω,ω} − I_{2ω,0} +
//! I_{2ω,ω} and V_{F'}s = ω(I_{ω,0} − 2I_{2ω,0} + I_{2ω,ω}), images of the internally
//! stable realisation (18) ([`super::volterra::ImageBank`]).
//!
//! With the estimates, χ̂ = E₁⁻¹(−V_{F'}ζ̂₁ − A₁₁V_Fζ̂₁ − A₁₂V_Fζ̂₂ − B₁V_F u) (16)
//! differs from V_F f by the images of the estimation errors and the state noise:
//! ‖χ̂ − V_F f‖ ≤ σ_FD = ‖E₁⁻¹‖ε̄_ζ₁B₁(t) + ‖E₁⁻¹A₁₁‖ε̄_ζ₁B₀(t) + ‖E₁⁻¹A₁₂‖V_F[ε̄_ζ₂]
//! \+ ‖E₁⁻¹‖d̄_{x,1}B₀(t), where B₀ = ∫|F| = (1 − e^{−2ωt})/(2ω) − te^{−ωt} and
//! B₁ = ∫|F'| = (1 − e^{−ωt})²/2, ε̄_ζ₁ = ‖C₁₁⁻¹‖d̄_y (the paper prints ‖C₁₁‖: the
//! error of ζ̂₁ = C₁₁⁻¹η₁ scales with the inverse).

use super::decomposition::Decomposition;
use super::volterra::ImageBank;

/// B₀(t) = ∫₀ᵗ |F(t, τ)| dτ.
#[must_use]
pub fn kernel_mass(omega: f64, t: f64) -> f64 {
    (1.0 - (-2.0 * omega * t).exp()) / (2.0 * omega) - t * (-omega * t).exp()
}

/// B₁(t) = ∫₀ᵗ |∂F/∂τ(t, τ)| dτ (F rises from 0 and falls back to 0 once: twice its
/// maximum).
#[must_use]
pub fn kernel_variation(omega: f64, t: f64) -> f64 {
    let e = 1.0 - (-omega * t).exp();
    0.5 * e * e
}

/// The constant factors of σ_FD.
#[derive(Debug, Clone, Copy)]
pub struct FaultImageBounds {
    /// ‖E₁⁻¹‖₂.
    pub e1_inv: f64,
    /// ‖E₁⁻¹A₁₁‖₂.
    pub e1_inv_a11: f64,
    /// ‖E₁⁻¹A₁₂‖₂.
    pub e1_inv_a12: f64,
    /// ε̄_ζ₁.
    pub eps_zeta1: f64,
    /// d̄_{x,1} = ‖T⁻¹ (ζ₁ rows)‖₂ d̄_x.
    pub dx1: f64,
}

/// The images of one filter bank with its own origin (the estimator's activation
/// for detection, the detection time T_D for isolation (20)): ζ̂₁, ζ̂₂, u, the
/// candidates φ̂ᵢ and the bounds ε̄_ζ₂, ε̄_x.
#[derive(Debug, Clone)]
pub struct FaultImage {
    omega: f64,
    faults: usize,
    order: usize,
    inputs: usize,
    candidates: usize,
    bank: ImageBank,
    signal: Vec<f64>,
    vf_zeta1: Vec<f64>,
    vf_zeta2: Vec<f64>,
    vf_u: Vec<f64>,
    g: Vec<f64>,
    chi: Vec<f64>,
}

impl FaultImage {
    /// A bank for p⋆ = `faults`, n⋆ = `order`, l = `inputs` and `candidates`
    /// candidate functions, rate ω, period Δ.
    #[must_use]
    pub fn new(
        omega: f64,
        dt: f64,
        faults: usize,
        order: usize,
        inputs: usize,
        candidates: usize,
    ) -> Self {
        let rates = [
            (omega, 0.0),
            (omega, omega),
            (2.0 * omega, 0.0),
            (2.0 * omega, omega),
        ];
        let measured = faults + order + inputs + candidates * faults;
        Self {
            omega,
            faults,
            order,
            inputs,
            candidates,
            bank: ImageBank::new(dt, &rates, measured + 2, measured),
            signal: vec![0.0; measured + 2],
            vf_zeta1: vec![0.0; faults],
            vf_zeta2: vec![0.0; order],
            vf_u: vec![0.0; inputs],
            g: vec![0.0; faults],
            chi: vec![0.0; faults],
        }
    }

    /// The next sample is the new origin.
    pub fn reset(&mut self) {
        self.bank.reset();
        self.chi.fill(0.0);
    }

    /// The time since the origin.
    #[must_use]
    pub fn time(&self) -> f64 {
        self.bank.time()
    }

    fn vf(&self, s: usize) -> f64 {
        self.bank.image(0, s) - self.bank.image(1, s) - self.bank.image(2, s)
            + self.bank.image(3, s)
    }

    fn vf_prime(&self, s: usize) -> f64 {
        self.omega * (self.bank.image(0, s) - 2.0 * self.bank.image(2, s) + self.bank.image(3, s))
    }

    /// Integrates one sample: ζ̂₁, ζ̂₂, u, the candidates' values (p⋆ each, in
    /// order), ε̄_ζ₂ and ε̄_x; then χ̂ (16). Allocation-free.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        design: &Decomposition,
        zeta1: &[f64],
        zeta2: &[f64],
        u: &[f64],
        candidates: &[f64],
        eps_zeta2: f64,
        eps_x: f64,
    ) {
        let (p, n, l) = (self.faults, self.order, self.inputs);
        self.signal[..p].copy_from_slice(zeta1);
        self.signal[p..p + n].copy_from_slice(zeta2);
        self.signal[p + n..p + n + l].copy_from_slice(u);
        let c = self.candidates * p;
        self.signal[p + n + l..p + n + l + c].copy_from_slice(&candidates[..c]);
        self.signal[p + n + l + c] = eps_zeta2;
        self.signal[p + n + l + c + 1] = eps_x;
        self.bank.push(&self.signal);
        for i in 0..p {
            self.vf_zeta1[i] = self.vf(i);
        }
        for i in 0..n {
            self.vf_zeta2[i] = self.vf(p + i);
        }
        for i in 0..l {
            self.vf_u[i] = self.vf(p + n + i);
        }
        for r in 0..p {
            let mut g = -self.vf_prime(r);
            for c in 0..p {
                g -= design.a11[(r, c)] * self.vf_zeta1[c];
            }
            for c in 0..n {
                g -= design.a12[(r, c)] * self.vf_zeta2[c];
            }
            for c in 0..l {
                g -= design.b1[(r, c)] * self.vf_u[c];
            }
            self.g[r] = g;
        }
        for r in 0..p {
            self.chi[r] = (0..p).map(|c| design.e1_inv[(r, c)] * self.g[c]).sum();
        }
    }

    /// χ̂ = the estimated V_F f (16).
    #[must_use]
    pub fn chi(&self) -> &[f64] {
        &self.chi
    }

    /// r_FD = ‖χ̂‖ (19).
    #[must_use]
    pub fn residual(&self) -> f64 {
        self.chi.iter().map(|c| c * c).sum::<f64>().sqrt()
    }

    /// σ_FD(t) (32).
    #[must_use]
    pub fn threshold(&self, bounds: &FaultImageBounds) -> f64 {
        let t = self.time();
        let b0 = kernel_mass(self.omega, t);
        let b1 = kernel_variation(self.omega, t);
        let eps2 = self.vf(self.signal.len() - 2);
        bounds.e1_inv * bounds.eps_zeta1 * b1
            + bounds.e1_inv_a11 * bounds.eps_zeta1 * b0
            + bounds.e1_inv_a12 * eps2
            + bounds.e1_inv * bounds.dx1 * b0
    }

    /// r_FI,i = ‖V_F φ̂ᵢ − χ̂‖ (35; (21) writes the fault image without the estimate).
    #[must_use]
    pub fn isolation_residual(&self, candidate: usize) -> f64 {
        let p = self.faults;
        let at = p + self.order + self.inputs + candidate * p;
        (0..p)
            .map(|r| {
                let d = self.vf(at + r) - self.chi[r];
                d * d
            })
            .sum::<f64>()
            .sqrt()
    }

    /// V_F[ε̄_x]: with the Lipschitz constant Lᵢ of φᵢ in x, Lᵢ·V_F[ε̄_x] bounds
    /// ‖V_F(φᵢ(x) − φᵢ(x̂))‖ (33)-(34).
    #[must_use]
    pub fn state_error_image(&self) -> f64 {
        self.vf(self.signal.len() - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_mass_and_variation_match_quadrature() {
        let omega = 1.3;
        for &t in &[0.2, 1.0, 3.0, 9.0] {
            let n = 100_000;
            let h = t / n as f64;
            let f = |tau: f64| {
                ((-omega * (t - tau)).exp() - (-2.0 * omega * (t - tau)).exp())
                    * (1.0 - (-omega * tau).exp())
            };
            let mut mass = 0.0;
            let mut variation = 0.0;
            for i in 0..n {
                let (a, b) = (f(i as f64 * h), f((i + 1) as f64 * h));
                mass += 0.5 * (a + b) * h;
                variation += (b - a).abs();
            }
            assert!((kernel_mass(omega, t) - mass).abs() < 1e-8, "B0({t})");
            assert!(
                (kernel_variation(omega, t) - variation).abs() < 1e-9,
                "B1({t})"
            );
        }
    }

    #[test]
    fn the_bilateral_kernel_vanishes_at_both_ends() {
        // F(t, 0) = F(t, t) = 0: why (15) has no boundary term.
        let omega = 1.0;
        let f = |t: f64, tau: f64| {
            ((-omega * (t - tau)).exp() - (-2.0 * omega * (t - tau)).exp())
                * (1.0 - (-omega * tau).exp())
        };
        for &t in &[0.5, 2.0, 7.0] {
            assert_eq!(f(t, 0.0), 0.0);
            assert_eq!(f(t, t), 0.0);
        }
    }
}
