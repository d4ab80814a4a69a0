//! r̂_k of eq. (36), earliest on ties: a lane scan that must equal a strict `>` scan.

use super::{WindowBank, WindowMax};

impl WindowBank {
    /// Earliest onset with the largest statistic among r ∈ {max(k−w+1, k0), …, k − s}.
    #[inline(always)]
    pub(super) fn best(&self, k: u64) -> Option<WindowMax> {
        let first = self.first?;
        if self.known {
            return Some(WindowMax {
                glr: self.stat[0],
                onset: first,
                rank: self.rank[0] as usize,
            });
        }
        let newest = k.checked_sub(self.min_lag)?;
        let oldest = (k + 1).saturating_sub(self.slots as u64).max(first);
        if newest < oldest {
            return None;
        }
        // Scan the ring in onset order as two contiguous runs: the largest value first
        // (branch-free, in independent lanes), then its earliest position. Statistics
        // that are NaN never win, as with a strict `>` scan.
        let start = self.slot_of(oldest);
        let count = (newest - oldest + 1) as usize;
        let first_run = count.min(self.slots - start);
        let runs = [
            &self.stat[start..start + first_run],
            &self.stat[..count - first_run],
        ];
        let (_, best_pos) = lane_argmax(runs[0], runs[1]);
        let slot = (start + best_pos) % self.slots;
        Some(WindowMax {
            glr: self.stat[slot],
            onset: oldest + best_pos as u64,
            rank: self.rank_at(slot) as usize,
        })
    }

    /// The rank of C_k(r) of slot s: the ring's, or in the stationary regime the
    /// tabulated rank of its lag (not copied into the ring at every step).
    #[inline(always)]
    pub(super) fn rank_at(&self, s: usize) -> f64 {
        if self.steady {
            self.tables.rank[self.table_index(s)]
        } else {
            self.rank[s]
        }
    }
}

/// The largest value of the concatenation `first ++ second` and its first position
/// (NaN ignored; (−∞, 0) when empty or all NaN), i.e. exactly what a strict `>` scan
/// finds, without a chain of compare-and-select through every value: first the largest
/// value over sixteen independent lanes (each a vector max; the last sixteen values of
/// a run are taken again instead of a partial register, which leaves a maximum
/// unchanged) reduced once by halving, then the first block of eight holding it (one
/// vector compare per block) and its position inside the block. The window's ring is
/// two such runs in onset order; both go through one reduction.
#[inline(always)]
fn lane_argmax(first: &[f64], second: &[f64]) -> (f64, usize) {
    const L: usize = 16;
    const H: usize = L / 2;
    // Two registers of eight lanes (`Lanes8`'s shape, which the compiler keeps in
    // vector registers; one array of sixteen it splits into pairs).
    let mut lo = [f64::NEG_INFINITY; H];
    let mut hi = [f64::NEG_INFINITY; H];
    #[inline(always)]
    fn fold8(best: &mut [f64; H], c: &[f64]) {
        for l in 0..H {
            best[l] = if c[l] > best[l] { c[l] } else { best[l] };
        }
    }
    for run in [first, second] {
        let n = run.len();
        if n >= L {
            let mut chunks = run.chunks_exact(L);
            for c in &mut chunks {
                fold8(&mut lo, &c[..H]);
                fold8(&mut hi, &c[H..]);
            }
            let last = &run[n - L..];
            fold8(&mut lo, &last[..H]);
            fold8(&mut hi, &last[H..]);
        } else {
            for (l, v) in run.iter().enumerate() {
                let b = if l < H { &mut lo[l] } else { &mut hi[l - H] };
                *b = if *v > *b { *v } else { *b };
            }
        }
    }
    // A tree of halvings (no lane holds NaN, so the order of the maxima is free).
    fold8(&mut lo, &hi);
    let mut best = lo;
    let mut width = H;
    while width > 1 {
        width /= 2;
        for l in 0..width {
            best[l] = if best[l + width] > best[l] {
                best[l + width]
            } else {
                best[l]
            };
        }
    }
    let value = best[0];
    if value == f64::NEG_INFINITY {
        return (value, 0);
    }
    match first_position(first, value) {
        Some(pos) => (first[pos], pos),
        None => {
            let pos = first_position(second, value).unwrap_or(0);
            (second.get(pos).copied().unwrap_or(value), first.len() + pos)
        }
    }
}

/// The first position of `value` in `values`: the first block of eight that holds it
/// (one vector compare per block), then the position inside the block.
#[inline(always)]
fn first_position(values: &[f64], value: f64) -> Option<usize> {
    const B: usize = 8;
    let n = values.len();
    let mut base = 0;
    while base + B <= n {
        if values[base..base + B]
            .iter()
            .fold(false, |hit, v| hit | (*v == value))
        {
            break;
        }
        base += B;
    }
    values[base..]
        .iter()
        .position(|v| *v == value)
        .map(|p| base + p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lane scan finds what a plain strict-`>` scan finds: the largest value and
    /// its earliest position, NaN ignored, ties to the earliest, however the values
    /// are split into the two runs.
    #[test]
    fn lane_argmax_equals_the_earliest_strict_maximum() {
        let mut x = 5_u64;
        let mut rnd = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 33) % 7
        };
        for len in 0_usize..80 {
            for _ in 0..50 {
                let v: Vec<f64> = (0..len)
                    .map(|_| match rnd() {
                        0 => f64::NAN,
                        6 => f64::NEG_INFINITY,
                        5 => -0.0,
                        4 => 0.0,
                        r => r as f64,
                    })
                    .collect();
                let (mut value, mut pos) = (f64::NEG_INFINITY, 0);
                for (i, x) in v.iter().enumerate() {
                    if *x > value {
                        value = *x;
                        pos = i;
                    }
                }
                for split in [0, len / 3, len / 2, len.saturating_sub(5), len] {
                    let (got_value, got_pos) = lane_argmax(&v[..split], &v[split..]);
                    assert_eq!(
                        (got_value.to_bits(), got_pos),
                        (value.to_bits(), pos),
                        "{v:?} split at {split}"
                    );
                }
            }
        }
    }
}
