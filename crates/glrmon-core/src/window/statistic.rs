//! dᵀC⁻d and rank C (eq. (35)), written once so that every path decides the same rank.
//!
//! # The rank decision is scale-free
//! Pivot j of the dropped-pivot LDLᵀ is kept when D_j > τ·C_jj: D_j = C_jj(1 − R_j²),
//! with R_j the multiple correlation of fault j's signature with the kept faults
//! before it, so the test asks whether 1 − R_j² > τ, a number without units. Changing
//! the units of a fault (its column times s, θ_j divided by s) multiplies C_jj and D_j
//! by s² and leaves every decision unchanged (the earlier cut-off τ·max_a C_aa made a
//! gas-pipeline leak of θ ≈ −4·10⁴ invisible next to faults of θ ≈ 10⁻⁵ whose columns
//! are ≈ 4·10⁵). A fault with no signature at all (C_jj = 0, so D_j = 0) is still
//! dropped: 0 > 0 is false. The cut-off is never negative (τ > 0, and C's diagonal is
//! a sum of squares), so a kept pivot is positive without a test of its own.

use super::lanes::Lanes;

/// The dropped-pivot LDLᵀ statistic dᵀC⁻d and rank C of L onsets (eq. (35)), with the
/// operations of [`WindowBank::statistic_generic`].
///
/// [`WindowBank::statistic_generic`]: super::WindowBank::statistic_generic
#[allow(clippy::needless_range_loop)]
#[inline(always)]
pub(super) fn ldl_statistic<const M: usize, S: Lanes>(
    info: &[[S; M]; M],
    score: &[S; M],
    tol: S,
) -> (S, S) {
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let mut dd = [zero; M];
    let mut inv = [zero; M];
    let mut low = [[zero; M]; M];
    let mut rank = zero;
    // Loops of constant length with the triangle as conditions, so that the compiler
    // unrolls them completely and keeps every entry in a register.
    for j in 0..M {
        let mut d = info[j][j];
        for q in 0..M {
            if q < j {
                d = d.sub(low[j][q].mul(low[j][q]).mul(dd[q]));
            }
        }
        dd[j] = d;
        // D_j > τ·C_jj (module docs).
        let keep = d.gt(info[j][j].mul(tol));
        inv[j] = S::select(keep, one.div(d), zero);
        rank = rank.add(S::select(keep, one, zero));
        for i in 0..M {
            if i > j {
                let mut x = info[i][j];
                for q in 0..M {
                    if q < j {
                        x = x.sub(low[i][q].mul(low[j][q]).mul(dd[q]));
                    }
                }
                low[i][j] = x.mul(inv[j]);
            }
        }
    }
    // z = L⁻¹d, statistic Σ_j z_j²/D_j over kept pivots.
    let mut z = [zero; M];
    let mut stat = zero;
    for j in 0..M {
        let mut x = score[j];
        for q in 0..M {
            if q < j {
                x = x.sub(low[j][q].mul(z[q]));
            }
        }
        z[j] = x;
        stat = stat.add(x.mul(x).mul(inv[j]));
    }
    (stat, rank)
}

/// dᵀC⁺d and rank C for m = 2, C = [[a, b], [b, c]], with one division: the
/// dropped-pivot LDLᵀ of [`WindowBank::statistic_generic`] (eq. (35)) with its two
/// pivots a and δ/a, δ = ac − b², written over one denominator: with z = a·d₂ − b·d₁,
///
///   d₁²/a + (d₂ − (b/a)d₁)²/(δ/a) = (d₁²δ + z²) / (aδ)   (both pivots kept),
///
/// d₁²/a when only the first is kept, and d₂²/c when the first is dropped (then the
/// second pivot is c itself). A sum of two non-negative terms over a positive
/// denominator: no cancellation beyond δ's own, which the LDLᵀ shares. One division
/// instead of the LDLᵀ's two: division is the slowest operation of the window pass
/// (docs/PERFORMANCE.md, second round).
///
/// The pivots are kept by the scale-free rule of the LDLᵀ, D_j > τ·C_jj (module docs):
/// a when a > τ·a (a > 0), δ/a when δ > τ·a·c (1 − ρ² > τ, ρ the correlation of the
/// two signatures), and c alone when c > τ·c; no division decides a rank.
///
/// [`WindowBank::statistic_generic`]: super::WindowBank::statistic_generic
#[inline(always)]
pub(super) fn quad2<S: Lanes>(a: S, b: S, c: S, d1: S, d2: S, tol: S) -> (S, S) {
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let (keep_a, keep_c) = quad2_pivots(a, c, tol);
    let ac = a.mul(c);
    let det = ac.sub(b.mul(b));
    let keep_det = det.gt(ac.mul(tol));
    let z = a.mul(d2).sub(b.mul(d1));
    let d1s = d1.mul(d1);
    let (full_num, full_den) = (d1s.mul(det).add(z.mul(z)), a.mul(det));
    let num_a = S::select(keep_det, full_num, d1s);
    let den_a = S::select(keep_det, full_den, a);
    let num = S::select(keep_a, num_a, S::select(keep_c, d2.mul(d2), zero));
    let den = S::select(keep_a, den_a, S::select(keep_c, c, one));
    let second = S::select(
        keep_a,
        S::select(keep_det, one, zero),
        S::select(keep_c, one, zero),
    );
    let rank = S::select(keep_a, one, zero).add(second);
    (num.div(den), rank)
}

/// [`quad2`]'s decisions on the diagonal: whether a is kept as the first pivot, and
/// whether c is kept as the second when a is dropped (D_j > τ·C_jj with D_j = C_jj).
/// The stationary tables take their generalised inverse from the same decisions.
#[inline(always)]
pub(super) fn quad2_pivots<S: Lanes>(a: S, c: S, tol: S) -> (S::Mask, S::Mask) {
    (a.gt(a.mul(tol)), c.gt(c.mul(tol)))
}
