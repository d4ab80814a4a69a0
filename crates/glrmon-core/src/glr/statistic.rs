//! dᵀC⁻d and rank C (eq. (35)), written once so that every path decides the same rank.

use super::lanes::Lanes;

/// The rank cut-off τ·max_a C_aa of the dropped-pivot LDLᵀ, in the operation order of
/// the statistic passes ([`WindowBank::statistic_m2`] for m = 2, else
/// [`WindowBank::statistic_generic`]; the m = 1 pass compares C > τ·C, which decides
/// the same for every C).
///
/// [`WindowBank::statistic_m2`]: super::WindowBank::statistic_m2
/// [`WindowBank::statistic_generic`]: super::WindowBank::statistic_generic
#[inline(always)]
pub(super) fn pivot_cutoff(m: usize, diag: impl Fn(usize) -> f64, tol: f64) -> f64 {
    if m == 2 {
        larger(diag(0), diag(1)) * tol
    } else {
        (0..m).fold(0.0_f64, |c, a| larger(c, diag(a))) * tol
    }
}

/// y if y > x, else x: the larger of two, as the rank cut-offs take it in every path
/// (and `maxpd` computes it). A NaN y is passed over, so a maximum folded from 0 over
/// C's diagonal ignores NaN entries as `f64::max` would; max(C₁₁, C₂₂) for m = 2 is NaN
/// when C₁₁ is, and then no pivot is kept.
#[inline(always)]
pub(super) fn larger(x: f64, y: f64) -> f64 {
    if y > x { y } else { x }
}

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
    let cut = {
        let mut x = zero;
        for (a, row) in info.iter().enumerate() {
            x = x.max(row[a]);
        }
        x.mul(tol)
    };
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
        let keep = d.gt(cut);
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
/// pivots a and δ/a, δ = ac − b², kept when above the cut-off τ·max(a, c), written over
/// one denominator: with z = a·d₂ − b·d₁,
///
///   d₁²/a + (d₂ − (b/a)d₁)²/(δ/a) = (d₁²δ + z²) / (aδ)   (both pivots kept),
///
/// d₁²/a when only the first is kept, and d₂²/c when the first is dropped (then the
/// second pivot is c itself). A sum of two non-negative terms over a positive
/// denominator: no cancellation beyond δ's own, which the LDLᵀ shares. The
/// comparisons test δ against τ·max(a, c)·a instead of δ/a against the cut-off, so no
/// division decides a rank. One division instead of the LDLᵀ's two: division is the
/// slowest operation of the window pass (issue 9).
///
/// [`WindowBank::statistic_generic`]: super::WindowBank::statistic_generic
#[inline(always)]
pub(super) fn quad2<S: Lanes>(a: S, b: S, c: S, d1: S, d2: S, tol: S) -> (S, S) {
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let cut = a.max(c).mul(tol);
    let keep_a = a.gt(cut);
    let keep_c = c.gt(cut);
    let det = a.mul(c).sub(b.mul(b));
    let keep_det = det.gt(cut.mul(a));
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
