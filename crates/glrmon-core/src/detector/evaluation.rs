//! Residual evaluation shared by the residual-generator kinds (parity space, observer
//! fault-detection filter, unknown-input observer, parameter estimation): how a
//! residual r_k becomes the one decision statistic the monitor compares with the
//! channel's threshold.
//!
//! - [`Evaluation::Chi2`]: rᵀΣ_r⁺r with the residual's own covariance Σ_r under the
//!   noise model, χ²(rank Σ_r) under no fault, so a false-alarm probability sets the
//!   threshold;
//! - [`Evaluation::Energy`]: the windowed energy of Ahmad & Mohd-Mokhtar 2021, eqs.
//!   (12)-(13), J_k = (Σ_{i=k−w+1..k} r_iᵀr_i)^{1/2}, compared with a bound J_th (their
//!   (8), (19): the residual's response to the worst disturbance of bounded energy δ_d),
//!   or with a threshold `calibrate` sets from fault-free data.

/// How a residual is turned into the decision statistic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Evaluation {
    /// rᵀΣ_r⁺r on each sample.
    Chi2,
    /// The windowed energy J_k over the last `window` samples (survey eq. (12)).
    Energy {
        /// w ≥ 1 samples.
        window: usize,
    },
}

impl Evaluation {
    /// The configuration's name: `chi2` or `energy`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Chi2 => "chi2",
            Self::Energy { .. } => "energy",
        }
    }

    /// How many consecutive residuals one value of the statistic depends on.
    #[must_use]
    pub fn memory(self) -> usize {
        match self {
            Self::Chi2 => 1,
            Self::Energy { window } => window.max(1),
        }
    }
}

/// The running sum of r_iᵀr_i over the last w samples (survey eq. (12)).
///
/// The sum is kept by adding the new term and subtracting the one that leaves, and
/// recomputed from the stored terms each time the ring wraps, so rounding cannot
/// accumulate over months; the same terms give the same bits. Allocation-free after
/// [`EnergyWindow::new`].
#[derive(Debug, Clone)]
pub struct EnergyWindow {
    terms: Vec<f64>,
    next: usize,
    filled: usize,
    sum: f64,
}

impl EnergyWindow {
    /// An empty window of `window` samples (at least 1).
    #[must_use]
    pub fn new(window: usize) -> Self {
        Self {
            terms: vec![0.0; window.max(1)],
            next: 0,
            filled: 0,
            sum: 0.0,
        }
    }

    /// w.
    #[must_use]
    pub fn window(&self) -> usize {
        self.terms.len()
    }

    /// Adds r_kᵀr_k and returns J_k = (Σ r_iᵀr_i)^{1/2} over the last w samples once w
    /// samples have been seen (`None` before).
    pub fn push(&mut self, square: f64) -> Option<f64> {
        let w = self.terms.len();
        let old = std::mem::replace(&mut self.terms[self.next], square);
        self.next += 1;
        if self.next == w {
            self.next = 0;
            self.sum = self.terms.iter().sum();
        } else {
            self.sum += square - old;
        }
        self.filled = (self.filled + 1).min(w);
        (self.filled == w).then(|| self.sum.max(0.0).sqrt())
    }

    /// Forgets every term.
    pub fn clear(&mut self) {
        self.terms.fill(0.0);
        self.next = 0;
        self.filled = 0;
        self.sum = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_energy_is_the_root_of_the_last_w_squares() {
        let mut e = EnergyWindow::new(3);
        assert_eq!(e.push(1.0), None);
        assert_eq!(e.push(4.0), None);
        assert_eq!(e.push(4.0), Some(3.0));
        assert_eq!(e.push(16.0), Some(24f64.sqrt()));
        let squares: Vec<f64> = (0..10_000).map(|i| f64::from(i % 7) * 0.1).collect();
        let mut e = EnergyWindow::new(5);
        for (i, &s) in squares.iter().enumerate() {
            let j = e.push(s);
            if i >= 4 {
                let direct: f64 = squares[i - 4..=i].iter().sum();
                assert!((j.unwrap() - direct.sqrt()).abs() < 1e-12);
            }
        }
        e.clear();
        assert_eq!(e.push(1.0), None);
    }

    #[test]
    fn evaluations_have_names_and_memories() {
        assert_eq!(Evaluation::Chi2.memory(), 1);
        assert_eq!(Evaluation::Energy { window: 20 }.memory(), 20);
        assert_eq!(Evaluation::Energy { window: 20 }.name(), "energy");
    }
}
