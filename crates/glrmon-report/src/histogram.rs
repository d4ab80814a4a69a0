//! Equal-width histograms, the binning behind the evaluation figures (Zhang & Basseville
//! 2014, Fig. 7: detection delays and onset-estimate errors over Monte-Carlo runs).

/// Counts of values in equal-width bins that cover the values' range.
///
/// Bin `i` is `[start + i·width, start + (i + 1)·width)`; the last bin also holds its
/// right edge, so the largest value is always counted. Values that are not finite are
/// left out and counted in [`Histogram::skipped`].
///
/// # Examples
///
/// ```
/// use glrmon_report::Histogram;
///
/// // Detection delays in samples: one bin per integer, centred on it.
/// let h = Histogram::integers(&[2, 3, 3, 7], 40);
/// assert_eq!((h.start, h.width), (1.5, 1.0));
/// assert_eq!(h.counts, [1, 2, 0, 0, 0, 1]);
/// assert_eq!(h.total(), 4);
///
/// let h = Histogram::new(&[0.0, 0.5, 1.0], 2);
/// assert_eq!(h.counts, [1, 2]);
/// assert!(Histogram::new(&[], 10).counts.is_empty());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Left edge of the first bin.
    pub start: f64,
    /// Width of every bin (positive).
    pub width: f64,
    /// Values per bin; empty when there were no finite values.
    pub counts: Vec<u64>,
    /// Values left out because they were NaN or infinite.
    pub skipped: u64,
}

impl Histogram {
    /// At most `max_bins` (at least 1) bins from the smallest to the largest finite
    /// value. When all values are equal, one bin of width 1 centred on them.
    #[must_use]
    pub fn new(values: &[f64], max_bins: usize) -> Self {
        let finite = || values.iter().copied().filter(|v| v.is_finite());
        let skipped = (values.len() - finite().count()) as u64;
        let Some((lo, hi)) = finite().fold(None, |acc: Option<(f64, f64)>, v| {
            Some(acc.map_or((v, v), |(l, h)| (l.min(v), h.max(v))))
        }) else {
            return Histogram::empty(skipped);
        };
        let bins = max_bins.max(1);
        let (start, width, bins) = if hi - lo > f64::EPSILON * hi.abs().max(lo.abs()) {
            (lo, (hi - lo) / bins as f64, bins)
        } else {
            (lo - 0.5, 1.0, 1)
        };
        let mut counts = vec![0; bins];
        for v in finite() {
            // The floor of a value in range is 0..=bins; the maximum goes to the last bin.
            let i = (((v - start) / width).floor().max(0.0) as usize).min(bins - 1);
            if let Some(c) = counts.get_mut(i) {
                *c += 1;
            }
        }
        Histogram {
            start,
            width,
            counts,
            skipped,
        }
    }

    /// `bins` (at least 1) equal bins over `[start, end]`, for values whose axis has a
    /// natural origin (the minmax statistics of Fig. 8 from 0). Values outside it, like
    /// those that are not finite, are left out and counted in [`Histogram::skipped`].
    /// No bins when the range is empty or not finite.
    ///
    /// ```
    /// use glrmon_report::Histogram;
    ///
    /// let h = Histogram::within(&[0.5, 1.5, 1.7, 4.0, 5.0], 0.0, 4.0, 4);
    /// assert_eq!(h.counts, [1, 2, 0, 1]);
    /// assert_eq!(h.skipped, 1);
    /// ```
    #[must_use]
    pub fn within(values: &[f64], start: f64, end: f64, bins: usize) -> Self {
        if !(start.is_finite() && end.is_finite() && end > start) {
            return Histogram::empty(values.len() as u64);
        }
        let bins = bins.max(1);
        let width = (end - start) / bins as f64;
        let mut counts = vec![0; bins];
        let mut skipped = 0;
        for v in values {
            if v.is_finite() && (start..=end).contains(v) {
                let i = (((v - start) / width).floor() as usize).min(bins - 1);
                counts[i] += 1;
            } else {
                skipped += 1;
            }
        }
        Histogram {
            start,
            width,
            counts,
            skipped,
        }
    }

    /// Bins of whole-number width centred on integers (edges at n − 0.5), so each
    /// integer falls in exactly one bin: width 1 while the range spans at most
    /// `max_bins` integers, else the smallest integer width that keeps `max_bins`.
    #[must_use]
    pub fn integers(values: &[i64], max_bins: usize) -> Self {
        let (Some(lo), Some(hi)) = (values.iter().min(), values.iter().max()) else {
            return Histogram::empty(0);
        };
        // i128: the span of two i64 values does not fit an i64.
        let span = (i128::from(*hi) - i128::from(*lo) + 1) as u128;
        let max_bins = max_bins.max(1) as u128;
        let width = span.div_ceil(max_bins);
        let bins = span.div_ceil(width) as usize;
        let mut counts = vec![0; bins];
        for v in values {
            let i = ((i128::from(*v) - i128::from(*lo)) as u128 / width) as usize;
            if let Some(c) = counts.get_mut(i) {
                *c += 1;
            }
        }
        Histogram {
            start: *lo as f64 - 0.5,
            width: width as f64,
            counts,
            skipped: 0,
        }
    }

    fn empty(skipped: u64) -> Self {
        Histogram {
            start: 0.0,
            width: 1.0,
            counts: Vec::new(),
            skipped,
        }
    }

    /// Values counted in the bins.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Right edge of the last bin (`start` when there are no bins).
    #[must_use]
    pub fn end(&self) -> f64 {
        self.start + self.width * self.counts.len() as f64
    }

    /// The largest bin count (0 when there are no bins).
    #[must_use]
    pub fn max_count(&self) -> u64 {
        self.counts.iter().copied().max().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The properties every histogram must have: counts add up to the finite values,
    /// the bins reach from at or below the minimum to at or above the maximum, and every
    /// value lies in the bin its count was put in.
    fn check(h: &Histogram, values: &[f64]) {
        let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        assert_eq!(h.total(), finite.len() as u64, "{h:?}");
        assert_eq!(h.skipped, (values.len() - finite.len()) as u64);
        assert!(h.width > 0.0);
        if let (Some(lo), Some(hi)) = (
            finite.iter().copied().reduce(f64::min),
            finite.iter().copied().reduce(f64::max),
        ) {
            assert!(h.start <= lo, "{h:?} starts after {lo}");
            assert!(h.end() >= hi, "{h:?} ends before {hi}");
            // Recount by edges: a bin holds at least the values strictly inside it and
            // at most those within rounding (1e-9 of a width) of it.
            let eps = h.width * 1e-9;
            for (i, c) in h.counts.iter().enumerate() {
                let (a, b) = (
                    h.start + h.width * i as f64,
                    h.start + h.width * (i + 1) as f64,
                );
                let count = |lo: f64, hi: f64, closed: bool| {
                    finite
                        .iter()
                        .filter(|v| {
                            if closed {
                                **v >= lo && **v <= hi
                            } else {
                                **v > lo && **v < hi
                            }
                        })
                        .count() as u64
                };
                let (inner, outer) = (
                    count(a + eps, b - eps, false),
                    count(a - eps, b + eps, true),
                );
                assert!(
                    (inner..=outer).contains(c),
                    "bin {i} [{a}, {b}) of {h:?}: {c} not in {inner}..={outer}"
                );
            }
        } else {
            assert!(h.counts.is_empty());
        }
    }

    #[test]
    fn bins_add_up_and_cover_min_to_max() {
        let values: Vec<f64> = (0..1000)
            .map(|i| ((i * 7919) % 1013) as f64 * 0.37 - 50.0)
            .collect();
        for bins in [1, 2, 7, 30, 5000] {
            let h = Histogram::new(&values, bins);
            assert_eq!(h.counts.len(), bins);
            check(&h, &values);
        }
        let h = Histogram::new(&[3.0, 3.0, 3.0], 10);
        assert_eq!(h.counts, [3]);
        check(&h, &[3.0, 3.0, 3.0]);
        let with_nan = [1.0, f64::NAN, 2.0, f64::INFINITY, 4.0];
        let h = Histogram::new(&with_nan, 3);
        assert_eq!(h.skipped, 2);
        check(&h, &with_nan);
    }

    #[test]
    fn integer_bins_are_centred_on_integers() {
        let delays: Vec<i64> = (0..500).map(|i| (i * i) % 37 - 9).collect();
        let as_f64: Vec<f64> = delays.iter().map(|v| *v as f64).collect();
        let h = Histogram::integers(&delays, 40);
        assert_eq!((h.start, h.width, h.counts.len()), (-9.5, 1.0, 37));
        check(&h, &as_f64);
        // 37 integers in at most 10 bins: width 4, 10 bins.
        let h = Histogram::integers(&delays, 10);
        assert_eq!((h.width, h.counts.len()), (4.0, 10));
        check(&h, &as_f64);
        let h = Histogram::integers(&[i64::MIN, 0, i64::MAX], 4);
        assert_eq!(h.total(), 3);
        assert_eq!(h.counts.len(), 4);
    }

    #[test]
    fn empty_input_gives_no_bins() {
        for h in [
            Histogram::new(&[], 10),
            Histogram::new(&[f64::NAN], 0),
            Histogram::integers(&[], 0),
        ] {
            assert!(h.counts.is_empty(), "{h:?}");
            assert_eq!((h.total(), h.max_count()), (0, 0));
            assert_eq!(h.end(), h.start);
        }
        let h = Histogram::integers(&[5], 0);
        assert_eq!(
            (h.start, h.width, h.counts.as_slice()),
            (4.5, 1.0, &[1][..])
        );
    }
}
