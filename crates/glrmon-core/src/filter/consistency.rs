//! Filter consistency: does the model still fit the plant?
//!
//! Under the fault-free model the innovations of the Kalman filter are white with
//! covariance Σ_k (Zhang & Basseville 2014, eq. (10) and Propositions 1–2), so the
//! normalised innovation squared q_k = ε_kᵀΣ_k⁻¹ε_k is χ²(p) with mean p, and the sum of
//! q_k over a block of W samples is χ²(W·p). A block sum outside the two-sided χ²(W·p)
//! band at level α says the model no longer fits: too large when Q or R (or the model)
//! are too optimistic, too small when they are too pessimistic. It is a warning about
//! the model, distinct from fault alarms (a fault also inflates q_k). Non-overlapping
//! blocks keep the law exact (overlapping windows would be correlated tests).

use crate::error::ModelError;
use crate::threshold::chi2_quantile;

/// Settings of the consistency test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsistencySettings {
    /// Samples per block, W.
    pub window: usize,
    /// Probability that a block of a fitting model falls outside the band (split
    /// equally between both tails).
    pub alpha: f64,
}

impl Default for ConsistencySettings {
    fn default() -> Self {
        Self {
            window: 500,
            alpha: 1e-6,
        }
    }
}

/// The verdict on a block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The block mean of q_k lies in the band.
    Consistent,
    /// Above the band: the innovations are larger than Σ_k says.
    TooLarge,
    /// Below the band: the innovations are smaller than Σ_k says.
    TooSmall,
}

impl Verdict {
    /// `consistent`, `too_large` or `too_small`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Verdict::Consistent => "consistent",
            Verdict::TooLarge => "too_large",
            Verdict::TooSmall => "too_small",
        }
    }
}

/// The result of a completed block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Block {
    /// Mean of q_k over the block (p under a fitting model).
    pub mean: f64,
    /// The band on the mean: [χ²_{α/2}(W·p), χ²_{1−α/2}(W·p)] / W.
    pub band: (f64, f64),
    /// The verdict.
    pub verdict: Verdict,
    /// Whether the verdict differs from the previous block's.
    pub changed: bool,
}

/// Block-wise χ² test of the normalised innovation squared; no allocation per sample.
///
/// # Examples
/// ```
/// use glrmon_core::filter::consistency::{Consistency, ConsistencySettings, Verdict};
/// let mut c = Consistency::new(1, ConsistencySettings { window: 100, alpha: 1e-6 })?;
/// let mut last = None;
/// for _ in 0..100 {
///     last = c.update(16.0); // q_k 16 times its mean: R is 16 times too small
/// }
/// assert_eq!(last.unwrap().verdict, Verdict::TooLarge);
/// # Ok::<(), glrmon_core::ModelError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Consistency {
    settings: ConsistencySettings,
    band: (f64, f64),
    sum: f64,
    count: usize,
    verdict: Verdict,
}

impl Consistency {
    /// A test for `outputs` = p outputs.
    ///
    /// # Errors
    /// [`ModelError::Setting`] when the window is 0 or α is not in (0, 1).
    pub fn new(outputs: usize, settings: ConsistencySettings) -> Result<Self, ModelError> {
        if settings.window == 0 {
            return Err(ModelError::Setting {
                what: "consistency.window",
                detail: "the block must hold at least one sample".into(),
            });
        }
        let dof = (settings.window * outputs.max(1)) as f64;
        let quantile = |p: f64| {
            chi2_quantile(dof, p).map_err(|e| ModelError::Setting {
                what: "consistency.alpha",
                detail: e.to_string(),
            })
        };
        if !(settings.alpha > 0.0 && settings.alpha < 1.0) {
            return Err(ModelError::Setting {
                what: "consistency.alpha",
                detail: format!("α must be in (0, 1), got {}", settings.alpha),
            });
        }
        let w = settings.window as f64;
        let band = (
            quantile(settings.alpha / 2.0)? / w,
            quantile(1.0 - settings.alpha / 2.0)? / w,
        );
        Ok(Self {
            settings,
            band,
            sum: 0.0,
            count: 0,
            verdict: Verdict::Consistent,
        })
    }

    /// The band on a block mean.
    #[must_use]
    pub fn band(&self) -> (f64, f64) {
        self.band
    }

    /// The settings.
    #[must_use]
    pub fn settings(&self) -> ConsistencySettings {
        self.settings
    }

    /// The verdict of the last completed block.
    #[must_use]
    pub fn verdict(&self) -> Verdict {
        self.verdict
    }

    /// Adds q_k; returns the block's result when this sample completes a block.
    pub fn update(&mut self, nis: f64) -> Option<Block> {
        self.sum += nis;
        self.count += 1;
        if self.count < self.settings.window {
            return None;
        }
        let mean = self.sum / self.count as f64;
        self.sum = 0.0;
        self.count = 0;
        let verdict = if mean > self.band.1 {
            Verdict::TooLarge
        } else if mean < self.band.0 {
            Verdict::TooSmall
        } else {
            Verdict::Consistent
        };
        let changed = verdict != self.verdict;
        self.verdict = verdict;
        Some(Block {
            mean,
            band: self.band,
            verdict,
            changed,
        })
    }

    /// Starts a new block, forgetting the partial one (after a gap or a restart); the
    /// last verdict is kept.
    pub fn reset_block(&mut self) {
        self.sum = 0.0;
        self.count = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_is_the_two_sided_chi2_band_of_the_block_sum() {
        let c = Consistency::new(
            2,
            ConsistencySettings {
                window: 50,
                alpha: 0.01,
            },
        )
        .unwrap();
        let (lo, hi) = c.band();
        // χ²(100): 0.5 % and 99.5 % quantiles 67.3276 and 140.1695 (tables).
        assert!((lo * 50.0 - 67.3276).abs() < 1e-3, "{lo}");
        assert!((hi * 50.0 - 140.1695).abs() < 1e-3, "{hi}");
        assert!(lo < 2.0 && 2.0 < hi);
    }

    #[test]
    fn verdicts_and_changes() {
        let mut c = Consistency::new(
            1,
            ConsistencySettings {
                window: 10,
                alpha: 1e-3,
            },
        )
        .unwrap();
        let block = |c: &mut Consistency, q: f64| (0..10).filter_map(|_| c.update(q)).last();
        let b = block(&mut c, 1.0).unwrap();
        assert_eq!((b.verdict, b.changed), (Verdict::Consistent, false));
        let b = block(&mut c, 10.0).unwrap();
        assert_eq!((b.verdict, b.changed), (Verdict::TooLarge, true));
        let b = block(&mut c, 10.0).unwrap();
        assert_eq!((b.verdict, b.changed), (Verdict::TooLarge, false));
        let b = block(&mut c, 0.01).unwrap();
        assert_eq!((b.verdict, b.changed), (Verdict::TooSmall, true));
        assert!(
            Consistency::new(
                1,
                ConsistencySettings {
                    window: 0,
                    alpha: 0.1
                }
            )
            .is_err()
        );
        assert!(
            Consistency::new(
                1,
                ConsistencySettings {
                    window: 5,
                    alpha: 1.5
                }
            )
            .is_err()
        );
    }
}
