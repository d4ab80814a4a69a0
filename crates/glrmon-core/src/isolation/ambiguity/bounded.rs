//! [`best_onsets`] without building the Fisher statistics of every onset: for each
//! group the onsets are visited in decreasing order of an upper bound of the group's
//! statistic there, and the search stops once no onset left can beat the group's best,
//! or reach the floor below which the caller has no use for a group's exact best.
//!
//! The bounds come from what the detector's window holds for every onset without a
//! factorisation: a single fault j alone has the statistic ζ_j²/F_jj, and any group's
//! statistic is a projection of the GLR statistic ζᵀF⁺ζ, which it never exceeds
//! (Basseville 1996, Lemma 3.10: the global statistic is the minmax statistic of the
//! others plus the sensitivity statistic of the group). Both agree with
//! [`FisherStatistics::sensitivity`] to rounding where F has full rank; the caller gives
//! no bound (`None`) where it has not, and such an onset is always visited.
//!
//! The floor is what makes it pay during a fault, when every onset's GLR statistic is
//! large: the onset-free check needs a group's L_h only where it may be an alternative
//! (L_h ≥ G − τ_g) or a rival's own (L_g ≥ L_h − τ_h), never below
//! min_g(G − τ_g) − max_h τ_h. Below the floor a group's best is the largest among the
//! onsets visited, itself below the floor, and every verdict is the same. At or above
//! it the result is that of [`best_onsets`] over all onsets, including the earliest onset
//! on ties (tested against it).

use super::{BestOnset, best_onsets};
use crate::detector::Detector;
use crate::isolation::FisherStatistics;

/// Relative and absolute slack added to each bound, far above the rounding by which the
/// window's quantities and [`FisherStatistics`] differ at full rank.
const SLACK: (f64, f64) = (1e-6, 1e-6);

/// [`best_onsets`] over `onsets`, building the statistics (`statistics(r)`, `None` when
/// the onset has none) only of the onsets that may hold a group's best at or above
/// `floor` (`f64::NEG_INFINITY`: every group's best exactly). `bound(r, g)` is an upper
/// bound of group g's statistic at onset r, `None` when unknown. A group whose best is
/// below the floor gets the best of the onsets visited (below the floor too) or `None`.
///
/// # Examples
/// ```
/// use glrmon_core::isolation::FisherStatistics;
/// use glrmon_core::isolation::ambiguity::best_onsets_bounded;
/// use nalgebra::{DMatrix, DVector};
/// // F = I: fault j alone has the statistic ζ_j², which is also its bound.
/// let data: [(u64, [f64; 2]); 3] = [(7, [3.0, 1.0]), (8, [1.0, 4.0]), (9, [0.1, 0.2])];
/// let score = |r: u64| data.iter().find(|d| d.0 == r).unwrap().1;
/// let mut built = 0;
/// let best = best_onsets_bounded(
///     &[7, 8, 9],
///     |r, g| Some(score(r)[g].powi(2)),
///     |r| {
///         built += 1;
///         let s = score(r);
///         FisherStatistics::new(DMatrix::identity(2, 2), DVector::from_vec(s.to_vec())).ok()
///     },
///     &[&[0], &[1]],
///     f64::NEG_INFINITY,
/// );
/// assert_eq!((best[0].unwrap().onset, best[1].unwrap().onset), (7, 8));
/// assert_eq!(built, 2, "onset 9 (bounds 0.01, 0.04) cannot beat 9 and 16");
/// ```
pub fn best_onsets_bounded(
    onsets: &[u64],
    mut bound: impl FnMut(u64, usize) -> Option<f64>,
    mut statistics: impl FnMut(u64) -> Option<FisherStatistics>,
    groups: &[&[usize]],
    floor: f64,
) -> Vec<Option<BestOnset>> {
    let mut best: Vec<Option<BestOnset>> = vec![None; groups.len()];
    let mut visited = vec![false; onsets.len()];
    let mut order: Vec<(f64, usize)> = Vec::with_capacity(onsets.len());
    for g in 0..groups.len() {
        order.clear();
        order.extend((0..onsets.len()).filter(|&i| !visited[i]).map(|i| {
            let reach =
                bound(onsets[i], g).map_or(f64::INFINITY, |b| b + SLACK.0 * b.abs() + SLACK.1);
            (reach, i)
        }));
        order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(reach, i) in &order {
            // Every onset left has a bound at most this one: none can reach the floor
            // or the group's best (a tie would need equality, which the slack
            // excludes).
            if reach < floor || best[g].is_some_and(|b| b.statistic > reach) {
                break;
            }
            visited[i] = true;
            let Some(fisher) = statistics(onsets[i]) else {
                continue;
            };
            let here = best_onsets([(onsets[i], fisher)], groups);
            for (slot, new) in best.iter_mut().zip(here) {
                let Some(new) = new else { continue };
                let better = match slot {
                    None => true,
                    Some(b) => {
                        new.statistic > b.statistic
                            || (new.statistic == b.statistic && new.onset < b.onset)
                    }
                };
                if better {
                    *slot = Some(new);
                }
            }
        }
    }
    best
}

/// The bounds of [`best_onsets_bounded`] from `detector`'s window after its last step,
/// for `groups`: ζ_j²/F_jj for a single fault j, the onset's GLR statistic for a larger
/// group, `None` where F is rank-deficient or the kind keeps no window of onsets.
pub fn window_bounds<'a>(
    detector: &'a dyn Detector,
    groups: &'a [&'a [usize]],
) -> impl FnMut(u64, usize) -> Option<f64> + 'a {
    let m = detector.faults().len();
    let (mut information, mut score) = (vec![0.0; m * m], vec![0.0; m]);
    move |onset, g| {
        let (statistic, rank) = detector.onset_statistic(onset)?;
        if rank != m {
            return None;
        }
        match groups.get(g)? {
            [j] if detector.onset_information(onset, &mut information, &mut score) => {
                let f = information.get(j * m + j).copied()?;
                Some(if f > 0.0 {
                    score[*j] * score[*j] / f
                } else {
                    0.0
                })
            }
            _ => Some(statistic),
        }
    }
}
