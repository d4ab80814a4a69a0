//! The vector width of the window loops, chosen once per bank at run time.
//!
//! The loops over the onsets of the window are written for the portable x86-64 baseline
//! (SSE2, two f64 per instruction) and vectorised by the compiler; on a processor with
//! AVX2 and FMA, or AVX-512F, the same loops are also compiled for four or eight f64 per
//! instruction and the widest is taken. Every loop does the same operations per onset
//! at every width, and no floating-point sum runs across onsets (the compiler never
//! reorders one), so all widths give the same bits: a recording replays to the same
//! numbers on any machine with FMA.
//!
//! The accumulations a·b + c of the window's recursions (the signatures, C, d and Γ,
//! eqs. (32), (33), (45), (46)) are fused multiply-adds, rounded once
//! ([`fused_multiply_add`]): one instruction at AVX2 and AVX-512F, and `f64::mul_add`
//! at the baseline (a call to the C library's correctly rounded `fma`; on such a
//! processor the baseline runs only to compare the levels). An x86-64 processor
//! without AVX2 and FMA (older or low-power parts) runs the baseline with a·b + c
//! rounded twice, since a call per operation would make it several times slower: its
//! numbers differ from the others' in the last bits. Everything else is separate
//! multiplies and adds (`f64::mul_add` is the only way to get a fused one: the
//! compiler never contracts).

/// A vector width the window loops are compiled for. Every level gives the same
/// bits; the choice only changes the speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VectorLevel {
    /// The build's baseline (SSE2 on x86-64).
    Baseline,
    /// AVX2 with FMA: four f64 per instruction.
    Avx2,
    /// AVX-512F (with FMA): eight f64 per instruction.
    Avx512,
}

/// Whether the window's recursions round each a·b + c once on this processor: on an
/// x86-64 processor with AVX2 and FMA (or AVX-512F), at every [`VectorLevel`], so that
/// every such machine gives the same bits, and on AArch64. Elsewhere (older or
/// low-power x86-64 parts) they run at the baseline and round twice, since a software
/// `fma` would make them several times slower; the last bits then differ.
#[must_use]
pub fn fused_multiply_add() -> bool {
    if cfg!(target_arch = "x86_64") {
        VectorLevel::detect() != VectorLevel::Baseline
    } else {
        cfg!(any(target_arch = "aarch64", target_feature = "fma"))
    }
}

impl VectorLevel {
    /// The widest level this processor supports (what a new detector uses).
    #[must_use]
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if !std::arch::is_x86_feature_detected!("fma") {
                return VectorLevel::Baseline;
            }
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
