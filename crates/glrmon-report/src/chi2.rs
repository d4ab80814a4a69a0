//! The χ² density drawn over the histograms of the minmax isolation statistics: under
//! θ_a = 0 the minmax statistic l_a of a test (Zhang & Basseville 2014, eq. (41)) is
//! centred χ² with dim θ_a degrees of freedom, the dashed curve of Fig. 8.

use std::f64::consts::PI;

/// ln Γ(ν/2) for ν ≥ 1 degrees of freedom, exact up to the rounding of its sum: Γ(1) = 1,
/// Γ(1/2) = √π and Γ(x + 1) = x Γ(x) reach every half-integer, so no series is needed.
fn ln_gamma_half(dof: u32) -> f64 {
    let (start, ln_start) = if dof.is_multiple_of(2) {
        (1.0, 0.0)
    } else {
        (0.5, 0.5 * PI.ln())
    };
    // Γ(ν/2) = Γ(start) · start · (start + 1) ⋯ (ν/2 − 1): (ν − 1) / 2 factors.
    (0..(dof.saturating_sub(1) / 2)).fold(ln_start, |acc, j| acc + (start + f64::from(j)).ln())
}

/// The density of the centred χ²(ν) distribution at `x`: x^{ν/2−1} e^{−x/2} /
/// (2^{ν/2} Γ(ν/2)) for x > 0, 0 below. At x = 0 it is +∞ for ν = 1, ½ for ν = 2 and 0
/// above. NaN for ν = 0 or a NaN `x`.
#[must_use]
pub(crate) fn chi2_pdf(x: f64, dof: u32) -> f64 {
    if dof == 0 || x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return 0.0;
    }
    if x == 0.0 {
        return match dof {
            1 => f64::INFINITY,
            2 => 0.5,
            _ => 0.0,
        };
    }
    let half = 0.5 * f64::from(dof);
    ((half - 1.0) * x.ln() - 0.5 * x - half * std::f64::consts::LN_2 - ln_gamma_half(dof)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_at_half_integers() {
        let cases = [
            (1, PI.sqrt()),
            (2, 1.0),
            (3, 0.5 * PI.sqrt()),
            (4, 1.0),
            (5, 0.75 * PI.sqrt()),
            (6, 2.0),
            (10, 24.0),
        ];
        for (dof, gamma) in cases {
            let got = ln_gamma_half(dof).exp();
            assert!((got - gamma).abs() <= 1e-14 * gamma, "Γ({dof}/2) = {got}");
        }
    }

    #[test]
    fn known_values() {
        let e = std::f64::consts::E;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs().max(1e-300);
        assert!(close(chi2_pdf(2.0, 2), 0.5 / e));
        assert!(close(chi2_pdf(1.0, 1), (-0.5f64).exp() / (2.0 * PI).sqrt()));
        assert!(close(chi2_pdf(3.0, 4), 3.0 * (-1.5f64).exp() / 4.0));
        assert_eq!(chi2_pdf(0.0, 1), f64::INFINITY);
        assert_eq!(chi2_pdf(0.0, 2), 0.5);
        assert_eq!(chi2_pdf(0.0, 3), 0.0);
        assert_eq!(chi2_pdf(-1.0, 2), 0.0);
        assert!(chi2_pdf(1.0, 0).is_nan());
    }

    /// ∫₀⁶⁰ of the density is 1 to 10⁻⁶ (the tail beyond 60 is below 10⁻¹⁰ for ν ≤ 3);
    /// with x = t² the integrand 2t·f(t²) is smooth even for ν = 1, so the midpoint rule
    /// converges.
    #[test]
    fn integrates_to_one() {
        for dof in [1, 2, 3] {
            let n = 200_000;
            let (a, b) = (0.0, 60f64.sqrt());
            let h = (b - a) / f64::from(n);
            let integral: f64 = (0..n)
                .map(|i| {
                    let t = a + (f64::from(i) + 0.5) * h;
                    2.0 * t * chi2_pdf(t * t, dof) * h
                })
                .sum();
            assert!((integral - 1.0).abs() < 1e-6, "ν = {dof}: {integral}");
        }
    }
}
