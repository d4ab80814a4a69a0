//! The vector width of the window loops, chosen once per bank at run time.
//!
//! The loops over the onsets of the window are written for the portable x86-64 baseline
//! (SSE2, two f64 per instruction) and vectorised by the compiler; on a processor with
//! AVX2 or AVX-512F the same loops are also compiled for four or eight f64 per
//! instruction and the widest is taken. Every loop does the same operations per onset
//! at every width, and no floating-point sum runs across onsets (the compiler never
//! reorders one), so all widths give the same bits: a recording replays to the same
//! numbers on any x86-64 machine. FMA is never used for that reason (it rounds a·b + c
//! once instead of twice; enabling the feature does not let the compiler contract).

/// A vector width the window loops are compiled for. Every level gives the same
/// bits; the choice only changes the speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VectorLevel {
    /// The build's baseline (SSE2 on x86-64).
    Baseline,
    /// AVX2: four f64 per instruction.
    Avx2,
    /// AVX-512F: eight f64 per instruction.
    Avx512,
}

impl VectorLevel {
    /// The widest level this processor supports (what a new detector uses).
    #[must_use]
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                return VectorLevel::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                return VectorLevel::Avx2;
            }
        }
        VectorLevel::Baseline
    }

    /// Every level this processor supports, narrowest first.
    #[must_use]
    pub fn supported() -> Vec<Self> {
        let mut v = vec![VectorLevel::Baseline];
        let best = Self::detect();
        if best != VectorLevel::Baseline {
            v.push(VectorLevel::Avx2);
        }
        if best == VectorLevel::Avx512 {
            v.push(VectorLevel::Avx512);
        }
        v
    }

    /// f64 lanes per instruction.
    #[must_use]
    pub fn lanes(self) -> usize {
        match self {
            VectorLevel::Baseline => 2,
            VectorLevel::Avx2 => 4,
            VectorLevel::Avx512 => 8,
        }
    }
}
