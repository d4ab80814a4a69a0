//! The multiply-add in `f64::mul_add`'s order, and registers whose lanes each equal `f64`.

/// x·a + b as the window's recursions take it, in the argument order of
/// `f64::mul_add` (and of [`Lanes::mul_add`]): rounded once if FUSED, else twice, as on
/// an x86-64 processor without AVX2 and FMA (crate::simd).
#[inline(always)]
pub(super) fn mul_add<const FUSED: bool>(x: f64, a: f64, b: f64) -> f64 {
    if FUSED { x.mul_add(a, b) } else { x * a + b }
}

/// [`mul_add`] with the rounding chosen at run time (off the per-sample path).
#[inline(always)]
pub(super) fn mul_add_as(fused: bool, x: f64, a: f64, b: f64) -> f64 {
    if fused {
        mul_add::<true>(x, a, b)
    } else {
        mul_add::<false>(x, a, b)
    }
}

/// One vector register of onsets for the fused pass: the f64 operations it needs, each
/// lane rounded as the scalar operation (`mul_add` as `f64::mul_add`), so every width
/// gives the same bits.
pub(super) trait Lanes: Copy {
    /// A per-lane condition.
    type Mask: Copy;
    /// Onsets per register.
    const L: usize;
    fn splat(x: f64) -> Self;
    /// The L values from `x` on, unchecked (the fused pass checks its arrays' sizes
    /// once per step instead of at every access).
    ///
    /// # Safety
    /// `x` must be valid for reading L f64.
    unsafe fn load_ptr(x: *const f64) -> Self;
    /// Writes the L values from `x` on, unchecked.
    ///
    /// # Safety
    /// `x` must be valid for writing L f64.
    unsafe fn store_ptr(self, x: *mut f64);
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// self·a + b rounded once (`f64::mul_add` per lane, same argument order): the
    /// passes' [`mul_add`] with FUSED.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// self > o (false for NaN).
    fn gt(self, o: Self) -> Self::Mask;
    /// m ? a : b per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
}

/// One onset: the passes' per-slot loops share the fused pass's kernels ([`quad2`]) and
/// with them its operations.
///
/// [`quad2`]: super::statistic::quad2
impl Lanes for f64 {
    type Mask = bool;
    const L: usize = 1;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    unsafe fn load_ptr(x: *const f64) -> Self {
        // SAFETY: the caller guarantees one readable f64 at x.
        unsafe { x.read_unaligned() }
    }
    #[inline(always)]
    unsafe fn store_ptr(self, x: *mut f64) {
        // SAFETY: the caller guarantees one writable f64 at x.
        unsafe { x.write_unaligned(self) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self + o
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self - o
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self * o
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        f64::mul_add(self, a, b)
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self / o
    }
    #[inline(always)]
    fn gt(self, o: Self) -> bool {
        self > o
    }
    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m { a } else { b }
    }
}

/// Eight onsets as a plain array, for the AVX-512F level: each operation is a loop
/// over the lanes that the compiler turns into one 512-bit instruction (written
/// without the 512-bit intrinsics, which need Rust 1.89, above the workspace's MSRV).
#[derive(Clone, Copy)]
pub(super) struct Lanes8([f64; 8]);

impl Lanes8 {
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut r = [0.0; 8];
        for l in 0..8 {
            r[l] = f(self.0[l], o.0[l]);
        }
        Lanes8(r)
    }
}

#[allow(clippy::needless_range_loop)]
impl Lanes for Lanes8 {
    type Mask = [bool; 8];
    const L: usize = 8;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        Lanes8([x; 8])
    }
    #[inline(always)]
    unsafe fn load_ptr(x: *const f64) -> Self {
        // SAFETY: the caller guarantees 8 readable f64 at x.
        Lanes8(unsafe { std::ptr::read_unaligned(x.cast::<[f64; 8]>()) })
    }
    #[inline(always)]
    unsafe fn store_ptr(self, x: *mut f64) {
        // SAFETY: the caller guarantees 8 writable f64 at x.
        unsafe { std::ptr::write_unaligned(x.cast::<[f64; 8]>(), self.0) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        let mut r = [0.0; 8];
        for l in 0..8 {
            r[l] = self.0[l].mul_add(a.0[l], b.0[l]);
        }
        Lanes8(r)
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self.zip(o, |a, b| a / b)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> [bool; 8] {
        let mut r = [false; 8];
        for l in 0..8 {
            r[l] = self.0[l] > o.0[l];
        }
        r
    }
    #[inline(always)]
    fn select(m: [bool; 8], a: Self, b: Self) -> Self {
        let mut r = [0.0; 8];
        for l in 0..8 {
            r[l] = if m[l] { a.0[l] } else { b.0[l] };
        }
        Lanes8(r)
    }
}

/// Implements [`Lanes`] for an x86-64 register type whose intrinsics are only ever
/// inlined into the `#[target_feature]` functions of the fused pass.
#[cfg(target_arch = "x86_64")]
macro_rules! x86_lanes {
    ($ty:ident, $mask:ty, $l:literal, $set1:ident, $loadu:ident, $storeu:ident,
     $add:ident, $sub:ident, $mul:ident, $div:ident, $fmadd:ident,
     gt: |$ga:ident, $gb:ident| $gt:expr,
     select: |$sm:ident, $sa:ident, $sb:ident| $sel:expr) => {
        // SAFETY (every method): the intrinsics need the register type's feature, which
        // its only callers enable: `Avx2Lanes` is used only inside
        // `WindowBank::fused_run_avx2` and `fused_run_avx512`, which run only on a
        // processor with AVX2, resp. AVX-512F, which implies it (see `WindowBank::step`).
        // Loads and stores read and write L values at a pointer the caller vouches for
        // (`Lanes::load_ptr`).
        impl Lanes for $ty {
            type Mask = $mask;
            const L: usize = $l;
            #[inline(always)]
            fn splat(x: f64) -> Self {
                $ty(unsafe { arch::$set1(x) })
            }
            #[inline(always)]
            unsafe fn load_ptr(x: *const f64) -> Self {
                $ty(unsafe { arch::$loadu(x) })
            }
            #[inline(always)]
            unsafe fn store_ptr(self, x: *mut f64) {
                unsafe { arch::$storeu(x, self.0) }
            }
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                $ty(unsafe { arch::$add(self.0, o.0) })
            }
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                $ty(unsafe { arch::$sub(self.0, o.0) })
            }
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                $ty(unsafe { arch::$mul(self.0, o.0) })
            }
            #[inline(always)]
            fn mul_add(self, a: Self, b: Self) -> Self {
                $ty(unsafe { arch::$fmadd(self.0, a.0, b.0) })
            }
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                $ty(unsafe { arch::$div(self.0, o.0) })
            }
            #[inline(always)]
            fn gt(self, o: Self) -> $mask {
                let ($ga, $gb) = (self.0, o.0);
                unsafe { $gt }
            }
            #[inline(always)]
            fn select($sm: $mask, a: Self, b: Self) -> Self {
                let ($sa, $sb) = (a.0, b.0);
                $ty(unsafe { $sel })
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64 as arch;

/// Four onsets in an AVX register (used only in the AVX2 and AVX-512F variants).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx2Lanes(arch::__m256d);

#[cfg(target_arch = "x86_64")]
x86_lanes!(Avx2Lanes, arch::__m256d, 4, _mm256_set1_pd, _mm256_loadu_pd, _mm256_storeu_pd,
    _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd, _mm256_fmadd_pd,
    gt: |a, b| arch::_mm256_cmp_pd::<{ arch::_CMP_GT_OQ }>(a, b),
    select: |m, a, b| arch::_mm256_blendv_pd(b, a, m));
