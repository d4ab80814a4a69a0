//! Streaming min/max decimation of per-sample series on a shared grid of k buckets.
//!
//! Every series of a channel (l_k, r̂, t, each ε_k and θ̂ component) is cut into the same
//! buckets of `width` consecutive sample indices. A bucket keeps only the smallest and the
//! largest value it saw (with their k), so drawing both in k order traces the visual
//! envelope of the series: a one-sample spike of l_k survives any amount of decimation.
//! When a sample falls beyond the last of `max_cells` buckets, the width doubles and
//! neighbouring buckets merge pairwise, so memory stays at `max_cells` buckets per series
//! whatever the length of the replay, and each bucket covers at most two of the pixels
//! the series is drawn on once `max_cells` is about the figure width.

/// One bucket of one series.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cell {
    /// Values seen (saturating).
    n: u32,
    /// The line must not join this bucket to the previous one: a `None` or a stretch of
    /// buckets without a value came between them.
    gap: bool,
    min: f64,
    min_k: u64,
    max: f64,
    max_k: u64,
}

impl Cell {
    const EMPTY: Cell = Cell {
        n: 0,
        gap: false,
        min: f64::INFINITY,
        min_k: 0,
        max: f64::NEG_INFINITY,
        max_k: 0,
    };

    fn add(&mut self, k: u64, v: f64) {
        if self.n == 0 || v < self.min {
            self.min = v;
            self.min_k = k;
        }
        if self.n == 0 || v > self.max {
            self.max = v;
            self.max_k = k;
        }
        self.n = self.n.saturating_add(1);
    }

    /// The bucket covering `left` then `right`. A break inside the merged bucket is moved
    /// to its start: at one bucket per pixel the difference is invisible.
    fn merge(left: Cell, right: Cell) -> Cell {
        match (left.n, right.n) {
            (0, _) => Cell {
                gap: left.gap || right.gap,
                ..right
            },
            (_, 0) => left,
            _ => {
                let mut out = left;
                out.gap = left.gap || right.gap;
                if right.min < out.min {
                    out.min = right.min;
                    out.min_k = right.min_k;
                }
                if right.max > out.max {
                    out.max = right.max;
                    out.max_k = right.max_k;
                }
                out.n = left.n.saturating_add(right.n);
                out
            }
        }
    }
}

/// One decimated series.
#[derive(Debug, Clone, Default)]
struct Column {
    cells: Vec<Cell>,
    /// A `None` arrived since the last value.
    pending_gap: bool,
    /// Bucket of the last value, to detect buckets skipped without a value.
    last_slot: Option<usize>,
}

impl Column {
    fn push(&mut self, slot: usize, k: u64, value: Option<f64>) {
        let Some(v) = value.filter(|v| v.is_finite()) else {
            self.pending_gap = true;
            return;
        };
        if self.cells.len() <= slot {
            self.cells.resize(slot + 1, Cell::EMPTY);
        }
        let skipped = self.last_slot.is_some_and(|last| slot > last + 1);
        if let Some(cell) = self.cells.get_mut(slot) {
            if self.pending_gap || skipped {
                cell.gap = true;
            }
            cell.add(k, v);
        }
        self.pending_gap = false;
        self.last_slot = Some(self.last_slot.map_or(slot, |last| last.max(slot)));
    }

    fn halve(&mut self) {
        let new_len = self.cells.len().div_ceil(2);
        for i in 0..new_len {
            let left = self.cells.get(2 * i).copied().unwrap_or(Cell::EMPTY);
            let right = self.cells.get(2 * i + 1).copied().unwrap_or(Cell::EMPTY);
            if let Some(cell) = self.cells.get_mut(i) {
                *cell = Cell::merge(left, right);
            }
        }
        self.cells.truncate(new_len);
        self.last_slot = self.last_slot.map(|s| s / 2);
    }
}

/// Handle of a series in a [`Grid`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ColumnId(usize);

/// Series sharing one bucketing of k.
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    origin: Option<u64>,
    width: u64,
    max_cells: usize,
    columns: Vec<Column>,
}

/// Polylines of a series: each inner vector is drawn joined, `(k, value)` in k order.
pub(crate) type Segments = Vec<Vec<(u64, f64)>>;

impl Grid {
    /// A grid drawing each series with at most `max_points` points (at least 4).
    pub(crate) fn new(max_points: usize) -> Self {
        Grid {
            origin: None,
            width: 1,
            max_cells: (max_points / 2).max(2),
            columns: Vec::new(),
        }
    }

    /// Adds an empty series.
    pub(crate) fn add_column(&mut self) -> ColumnId {
        self.columns.push(Column::default());
        ColumnId(self.columns.len() - 1)
    }

    /// The bucket of sample `k`, coarsening the grid until it fits. Samples before the
    /// first one seen (out of order) go to the first bucket.
    pub(crate) fn slot(&mut self, k: u64) -> usize {
        let origin = *self.origin.get_or_insert(k);
        let offset = k.saturating_sub(origin);
        // max_cells >= 2, and once width saturates at u64::MAX the index is at most 1.
        loop {
            let index = offset / self.width;
            match usize::try_from(index) {
                Ok(i) if i < self.max_cells => return i,
                _ => self.coarsen(),
            }
        }
    }

    fn coarsen(&mut self) {
        self.width = self.width.saturating_mul(2);
        for column in &mut self.columns {
            column.halve();
        }
    }

    /// Records `value` (or a gap, for `None` or a non-finite value) of sample `k` in
    /// `slot`, as returned by [`Grid::slot`] for the same `k` with no coarsening since.
    pub(crate) fn push(&mut self, column: ColumnId, slot: usize, k: u64, value: Option<f64>) {
        if let Some(c) = self.columns.get_mut(column.0) {
            c.push(slot, k, value);
        }
    }

    /// The series as polylines: each bucket's minimum and maximum, in k order.
    pub(crate) fn segments(&self, column: ColumnId) -> Segments {
        let mut out: Segments = Vec::new();
        let Some(col) = self.columns.get(column.0) else {
            return out;
        };
        let mut current: Vec<(u64, f64)> = Vec::new();
        for cell in &col.cells {
            if cell.n == 0 {
                continue;
            }
            if cell.gap && !current.is_empty() {
                out.push(std::mem::take(&mut current));
            }
            let (a, b) = if cell.min_k <= cell.max_k {
                ((cell.min_k, cell.min), (cell.max_k, cell.max))
            } else {
                ((cell.max_k, cell.max), (cell.min_k, cell.min))
            };
            current.push(a);
            if b != a {
                current.push(b);
            }
        }
        if !current.is_empty() {
            out.push(current);
        }
        out
    }

    /// Smallest and largest value of a series, if it has any.
    pub(crate) fn range(&self, column: ColumnId) -> Option<(f64, f64)> {
        let col = self.columns.get(column.0)?;
        col.cells
            .iter()
            .filter(|c| c.n > 0)
            .fold(None, |acc, c| match acc {
                None => Some((c.min, c.max)),
                Some((lo, hi)) => Some((lo.min(c.min), hi.max(c.max))),
            })
    }

    /// Largest absolute value of a series (0 if it has none).
    pub(crate) fn peak_abs(&self, column: ColumnId) -> f64 {
        self.range(column)
            .map_or(0.0, |(lo, hi)| lo.abs().max(hi.abs()))
    }

    /// Buckets currently used by any series.
    #[cfg(test)]
    pub(crate) fn cells_used(&self) -> usize {
        self.columns
            .iter()
            .map(|c| c.cells.len())
            .max()
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(segments: &Segments) -> usize {
        segments.iter().map(Vec::len).sum()
    }

    #[test]
    fn short_series_is_kept_exactly() {
        let mut grid = Grid::new(100);
        let col = grid.add_column();
        for k in 0..10 {
            let slot = grid.slot(k);
            grid.push(col, slot, k, Some(k as f64 * 2.0));
        }
        let segs = grid.segments(col);
        assert_eq!(segs.len(), 1);
        assert_eq!(
            segs[0],
            (0..10).map(|k| (k, k as f64 * 2.0)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn budget_holds_and_spike_and_dip_survive() {
        let budget = 500;
        let mut grid = Grid::new(budget);
        let col = grid.add_column();
        for k in 0..1_000_000u64 {
            let v = match k {
                123_457 => 1e6,
                876_543 => -5e5,
                _ => (k as f64 * 0.01).sin(),
            };
            let slot = grid.slot(k);
            grid.push(col, slot, k, Some(v));
        }
        assert!(grid.cells_used() <= budget / 2);
        let segs = grid.segments(col);
        assert!(points(&segs) <= budget, "{} points", points(&segs));
        let all: Vec<(u64, f64)> = segs.concat();
        assert!(all.contains(&(123_457, 1e6)));
        assert!(all.contains(&(876_543, -5e5)));
        assert!(all.windows(2).all(|w| w[0].0 < w[1].0), "k increasing");
    }

    #[test]
    fn none_and_missing_samples_break_the_line() {
        let mut grid = Grid::new(1000);
        let col = grid.add_column();
        let values = [Some(1.0), Some(2.0), None, Some(3.0), Some(4.0)];
        for (k, v) in values.into_iter().enumerate() {
            let slot = grid.slot(k as u64);
            grid.push(col, slot, k as u64, v);
        }
        // Samples 5..=9 missing.
        for k in 10..12 {
            let slot = grid.slot(k);
            grid.push(col, slot, k, Some(5.0));
        }
        let segs = grid.segments(col);
        assert_eq!(
            segs,
            vec![
                vec![(0, 1.0), (1, 2.0)],
                vec![(3, 3.0), (4, 4.0)],
                vec![(10, 5.0), (11, 5.0)]
            ]
        );
    }

    #[test]
    fn gaps_survive_coarsening() {
        let mut grid = Grid::new(8);
        let col = grid.add_column();
        for k in 0..400u64 {
            let v = if (100..300).contains(&k) {
                None
            } else {
                Some(1.0)
            };
            let slot = grid.slot(k);
            grid.push(col, slot, k, v);
        }
        assert_eq!(grid.segments(col).len(), 2);
    }

    #[test]
    fn hostile_indices_do_not_panic() {
        let mut grid = Grid::new(4);
        let col = grid.add_column();
        for k in [5, 0, u64::MAX, 3, u64::MAX - 1, 7] {
            let slot = grid.slot(k);
            grid.push(col, slot, k, Some(k as f64));
            grid.push(col, slot, k, Some(f64::NAN));
        }
        assert!(points(&grid.segments(col)) <= 4);
        assert_eq!(grid.range(col).map(|r| r.1), Some(u64::MAX as f64));
    }
}
