//! Isolation when the onset is uncertain: which faults the data cannot yet tell apart
//! once each may have its own onset.
//!
//! The minmax test (eq. (41)) runs at the onset estimate r̂ of the detection statistic:
//! it asks whether fault a is needed *given that every fault started at r̂*. Right after
//! a crossing few samples carry the fault, and a fault b with another onset may explain
//! them as well as a does at r̂. In the §6.1 plant of Zhang & Basseville (2014) a jump of
//! x0 at k = 201 and a jump of x1 at 200 give the same first innovation; the alarm's r̂
//! is 200, where only the x1 jump fits, and the test at r̂ isolates x1 decisively (minmax
//! ≈ 92 against 6.6 over 30 of 30 runs) while the truth is x0.
//!
//! The onset-free comparison: for each isolation group g, the single-group statistic
//! (the sensitivity test, Basseville 1996, §3.2, Lemma 3.5) is maximised over the
//! onsets of the window,
//!
//! ```text
//! L_g = max_r ζ_g(r)ᵀ F_gg(r)⁺ ζ_g(r)     = 2 ln of the GLR of "g alone, from its own onset"
//! ```
//!
//! and L_g − L_h is 2 ln of the generalised likelihood ratio of "g alone, at its best
//! onset and magnitude" against "h alone, at its".
//!
//! A group g isolated at r̂ (minmax above its threshold τ_g) is confirmed only if the
//! data need it once onsets are free: the joint fit of every fault at r̂, the global
//! statistic G = ζ(r̂)ᵀF(r̂)⁺ζ(r̂), must beat every group h disjoint from g, alone at its
//! own best onset, by more than τ_g. Since G minus the fit of the others at r̂ is
//! exactly the minmax statistic (Basseville 1996, Lemma 3.10), this is the minmax test
//! with the nuisance's onset set free as far as single groups go:
//!
//! ```text
//! isolated(g)  ⇔  minmax_g(r̂) > τ_g  and  G − L_h > τ_g for every h disjoint from g
//! ```
//!
//! The groups h that fail it are the *alternatives* of g ([`alternatives`]): they
//! explain the data without g. When g alone is as good as such an h (L_g ≥ L_h − τ_h),
//! the two are *rivals*: reported as ambiguous with each other, not isolated. The
//! isolation update, with more samples, narrows the set.
//!
//! Two faults present together still pass: no single one explains the data of both.
//! The comparison is between single groups; a pair of faults at another onset that
//! explains the data as well as g with others at r̂ is not searched (the cost would grow
//! with the number of subsets).

use super::FisherStatistics;

mod bounded;
pub use bounded::{best_onsets_bounded, window_bounds};

/// The best single-group explanation of the data: the largest sensitivity statistic of a
/// group over the onsets searched, and where it is reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BestOnset {
    /// L_g: 2 ln of the likelihood ratio of "the group alone, from `onset`" against "no
    /// fault".
    pub statistic: f64,
    /// The onset maximising it (the earliest on ties).
    pub onset: u64,
    /// Degrees of freedom of the statistic at that onset.
    pub dof: usize,
}

/// For each group (fault indices into the dictionary), its best onset among `per_onset`
/// (the sufficient statistics of each onset searched, in any order): `None` for a group
/// without a finite statistic at any of them (an invalid group, or no onset given).
///
/// # Examples
/// ```
/// use glrmon_core::isolation::FisherStatistics;
/// use glrmon_core::isolation::ambiguity::best_onsets;
/// use nalgebra::{DMatrix, DVector};
/// // Two orthogonal faults; at onset 7 the data carry fault 0, at onset 8 fault 1 more.
/// let at = |d0: f64, d1: f64| {
///     FisherStatistics::new(DMatrix::identity(2, 2), DVector::from_vec(vec![d0, d1])).unwrap()
/// };
/// let best = best_onsets([(7, at(3.0, 1.0)), (8, at(1.0, 4.0))], &[&[0], &[1]]);
/// assert_eq!(best[0].unwrap().onset, 7);
/// assert!((best[0].unwrap().statistic - 9.0).abs() < 1e-12);
/// assert_eq!(best[1].unwrap().onset, 8);
/// ```
#[must_use]
pub fn best_onsets(
    per_onset: impl IntoIterator<Item = (u64, FisherStatistics)>,
    groups: &[&[usize]],
) -> Vec<Option<BestOnset>> {
    let mut best: Vec<Option<BestOnset>> = vec![None; groups.len()];
    for (onset, fisher) in per_onset {
        for (slot, group) in best.iter_mut().zip(groups) {
            let Ok(s) = fisher.sensitivity(group) else {
                continue;
            };
            if !s.value.is_finite() {
                continue;
            }
            let better = match slot {
                None => true,
                Some(b) => s.value > b.statistic || (s.value == b.statistic && onset < b.onset),
            };
            if better {
                *slot = Some(BestOnset {
                    statistic: s.value,
                    onset,
                    dof: s.dof,
                });
            }
        }
    }
    best
}

/// The alternatives of group `g`: the groups h sharing no fault with g that, alone at
/// their own best onset, explain the data within `threshold` (τ_g) of the joint fit
/// `global` (G, every fault at r̂): L_h ≥ G − τ_g. Non-empty means the data do not need
/// g once the onset is free. `groups` holds the faults of each group, as in
/// [`best_onsets`].
#[must_use]
pub fn alternatives(
    best: &[Option<BestOnset>],
    groups: &[&[usize]],
    g: usize,
    global: f64,
    threshold: f64,
) -> Vec<usize> {
    let Some(own) = groups.get(g) else {
        return Vec::new();
    };
    best.iter()
        .zip(groups)
        .enumerate()
        .filter(|&(h, (other, faults))| {
            h != g
                && !faults.iter().any(|f| own.contains(f))
                && other.is_some_and(|o| o.statistic >= global - threshold)
        })
        .map(|(h, _)| h)
        .collect()
}

/// Whether group g alone is as good an explanation as group h alone (each at its own
/// best onset) by h's threshold τ_h: L_g ≥ L_h − τ_h. An alternative h of g with which
/// g so competes is its rival: the two are ambiguous with each other.
#[must_use]
pub fn competes(best: &[Option<BestOnset>], g: usize, h: usize, threshold_h: f64) -> bool {
    match (best.get(g), best.get(h)) {
        (Some(Some(own)), Some(Some(other))) => own.statistic >= other.statistic - threshold_h,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    fn fisher(info: &[f64], score: &[f64]) -> FisherStatistics {
        let m = score.len();
        FisherStatistics::new(
            DMatrix::from_row_slice(m, m, info),
            DVector::from_column_slice(score),
        )
        .unwrap()
    }

    /// L_g is the largest single-group GLR ζ_gᵀF_gg⁻¹ζ_g over the onsets, computed here
    /// by hand for correlated faults (F_01 ≠ 0): the sensitivity test ignores the other
    /// fault, unlike minmax.
    #[test]
    fn best_onset_is_the_largest_single_group_statistic() {
        let a = fisher(&[2.0, 1.0, 1.0, 4.0], &[2.0, 2.0]);
        let b = fisher(&[1.0, 0.5, 0.5, 1.0], &[1.5, -1.0]);
        let best = best_onsets([(10, a), (11, b)], &[&[0], &[1], &[0, 1]]);
        // Fault 0: 2²/2 = 2 at 10, 1.5²/1 = 2.25 at 11.
        let g0 = best[0].unwrap();
        assert_eq!(g0.onset, 11);
        assert!((g0.statistic - 2.25).abs() < 1e-12, "{g0:?}");
        // Fault 1: 2²/4 = 1 at 10, 1 at 11: the earliest on ties.
        let g1 = best[1].unwrap();
        assert_eq!(g1.onset, 10);
        assert!((g1.statistic - 1.0).abs() < 1e-12, "{g1:?}");
        // Both: ζᵀF⁻¹ζ = [2 2]·[[4 −1][−1 2]]/7·[2 2]ᵀ = 16/7 at 10;
        // [1.5 −1]·[[1 −.5][−.5 1]]/.75·[1.5 −1]ᵀ = 4.75/.75 at 11.
        let both = best[2].unwrap();
        assert_eq!((both.onset, both.dof), (11, 2));
        assert!((both.statistic - 4.75 / 0.75).abs() < 1e-12, "{both:?}");
    }

    fn b(statistic: f64) -> Option<BestOnset> {
        Some(BestOnset {
            statistic,
            onset: 0,
            dof: 1,
        })
    }

    #[test]
    fn alternatives_explain_the_data_within_the_threshold_of_the_joint_fit() {
        let best = [b(50.0), b(45.0), b(30.0), None, b(52.0)];
        let groups: [&[usize]; 5] = [&[0], &[1], &[2], &[3], &[0, 1]];
        // G = 55: group 1 (45) is within 12 of it, not within 6.63.
        assert_eq!(
            alternatives(&best, &groups, 0, 55.0, 6.63),
            Vec::<usize>::new()
        );
        assert_eq!(alternatives(&best, &groups, 0, 55.0, 12.0), vec![1]);
        // Group 4 shares fault 0 with group 0 and fault 1 with group 1: never theirs.
        assert_eq!(alternatives(&best, &groups, 2, 55.0, 12.0), vec![0, 1, 4]);
        assert_eq!(alternatives(&best, &groups, 1, 55.0, 12.0), vec![0]);
        assert!(alternatives(&best, &groups, 9, 55.0, 12.0).is_empty());
    }

    #[test]
    fn competing_is_within_the_other_group_threshold() {
        let best = [b(50.0), b(45.0), None];
        assert!(competes(&best, 1, 0, 6.63));
        assert!(!competes(&best, 1, 0, 4.0));
        assert!(competes(&best, 0, 1, 0.0));
        assert!(!competes(&best, 2, 0, 100.0));
    }
}
