//! The fused single pass for small (n, m, p): must equal [`super::reference`] bit for bit.

use super::lanes::Lanes;
#[cfg(target_arch = "x86_64")]
use super::lanes::{Avx2Lanes, Lanes8};
use super::statistic::{ldl_statistic, quad2};
use super::{StepInputs, WindowBank, WindowMax, forcing, tri};
use crate::linalg::at;
use crate::model::fault::Onset;

/// The fused step at one vector width: an entry compiled with `$feature` that finds the
/// kernel of the bank's (n, m, p) (`for_fused_dims!`) and runs it around
/// `fused_body`, and the kernels themselves, each a function of its own (not inlined
/// into the dispatch, which keeps each function small for the compiler). One per
/// feature: a generic function cannot carry `#[target_feature]`.
macro_rules! fused_level {
    ($feature:literal, $entry:ident, $run:ident, $rest:ident, $lanes:ty, $half:ty, $doc:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        pub(super) unsafe fn $entry(
            &mut self,
            k: u64,
            inputs: &StepInputs<'_>,
        ) -> Option<WindowMax> {
            self.fused_body(k, inputs, |bank, inputs| {
                for_fused_dims!(dispatch_fused, $run, bank, inputs)
            })
        }

        #[doc = $doc]
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        #[inline(never)]
        unsafe fn $run<const N: usize, const M: usize, const P: usize>(
            &mut self,
            inputs: &StepInputs<'_>,
        ) {
            let coefs = Coefs::<N, M, P>::new(inputs, &self.kinds, self.tolerance);
            let rest = self.fused_run::<N, M, P, $lanes>(&coefs);
            if rest < self.slots {
                // SAFETY: compiled with the same feature as this kernel.
                unsafe { self.$rest::<N, M, P>(inputs, rest) };
            }
        }

        /// The slots after the kernel's last whole register (with coefficients of its
        /// own: a reference to the main loop's would keep them out of its registers).
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        #[inline(never)]
        unsafe fn $rest<const N: usize, const M: usize, const P: usize>(
            &mut self,
            inputs: &StepInputs<'_>,
            first: usize,
        ) {
            let coefs = Coefs::<N, M, P>::new(inputs, &self.kinds, self.tolerance);
            self.fused_rest::<N, M, P, $half>(&coefs, first);
        }
    };
}

/// Runs the kernel `$run::<n, m, p>` of the bank's dimensions (none beyond the list).
macro_rules! dispatch_fused {
    ($run:ident, $b:ident, $i:ident; $(($nn:literal, $mm:literal, $pp:literal)),*) => {
        match ($b.n, $b.m, $b.p) {
            // SAFETY: only called from the entry `fused_level!` compiles with the
            // kernel's feature, which runs only on a processor that has it (see `step`).
            $(($nn, $mm, $pp) => unsafe { $b.$run::<$nn, $mm, $pp>($i) },)*
            _ => {}
        }
    };
}

/// Calls `$mac!` with the (n, m, p) for which [`WindowBank::step`] has a fused pass:
/// n ≤ 4 states, m ≤ 4 faults, p ≤ 2 outputs. Each triple is compiled twice (AVX2 and
/// AVX-512F), about 0.25 s of release build per kernel, so the list is bounded by the
/// build time (32 triples: glrmon-core's release build 21 s → 36 s).
macro_rules! for_fused_dims {
    ($mac:ident $(, $arg:ident)*) => {
        $mac!($($arg),*;
            (1, 1, 1), (1, 2, 1), (1, 3, 1), (1, 4, 1),
            (2, 1, 1), (2, 2, 1), (2, 3, 1), (2, 4, 1),
            (3, 1, 1), (3, 2, 1), (3, 3, 1), (3, 4, 1),
            (4, 1, 1), (4, 2, 1), (4, 3, 1), (4, 4, 1),
            (1, 1, 2), (1, 2, 2), (1, 3, 2), (1, 4, 2),
            (2, 1, 2), (2, 2, 2), (2, 3, 2), (2, 4, 2),
            (3, 1, 2), (3, 2, 2), (3, 3, 2), (3, 4, 2),
            (4, 1, 2), (4, 2, 2), (4, 3, 2), (4, 4, 2)
        )
    };
}

/// Whether [`WindowBank::step`] has a fused pass for these dimensions (x86-64 only).
pub(super) fn fused_dims(n: usize, m: usize, p: usize) -> bool {
    if cfg!(not(target_arch = "x86_64")) {
        return false;
    }
    macro_rules! listed {
        ($n:ident, $m:ident, $p:ident; $(($nn:literal, $mm:literal, $pp:literal)),*) => {
            matches!(($n, $m, $p), $(($nn, $mm, $pp))|*)
        };
    }
    for_fused_dims!(listed, n, m, p)
}

impl WindowBank {
    fused_level!(
        "avx2,fma",
        fused_avx2,
        fused_run_avx2,
        fused_rest_avx2,
        Avx2Lanes,
        f64,
        "The fused pass for one (n, m, p) with AVX2, four onsets per register."
    );
    fused_level!(
        "avx512f,fma",
        fused_avx512,
        fused_run_avx512,
        fused_rest_avx512,
        Lanes8,
        Avx2Lanes,
        "The fused pass for one (n, m, p) with AVX-512F, eight onsets per register."
    );

    /// [`WindowBank::step`] in one pass: the bookkeeping around `run`, the fused pass of
    /// the bank's dimensions.
    #[inline(always)]
    fn fused_body(
        &mut self,
        k: u64,
        inputs: &StepInputs<'_>,
        run: impl FnOnce(&mut Self, &StepInputs<'_>),
    ) -> Option<WindowMax> {
        self.current = k;
        self.factored = false;
        // The slot whose impulse output factor is 1 at k (as in `compute_factors`).
        let impulse_slot = match self.first {
            Some(_) if self.onset[self.slot_of(k)] == k => Some(self.slot_of(k)),
            _ => None,
        };
        if let Some(s) = impulse_slot {
            self.impulse[s] = self.active[s];
        }
        run(self, inputs);
        if let Some(s) = impulse_slot {
            self.impulse[s] = 0.0;
        }
        self.announce(k, inputs.psi);
        self.best(k)
    }

    /// The per-slot arrays of the fused pass, checked once for n = N, m = M, p = P.
    #[inline(always)]
    fn slot_arrays<const N: usize, const M: usize, const P: usize>(&mut self) -> SlotArrays<'_> {
        let slots = SlotArrays {
            w: self.slots,
            active: &self.active,
            impulse: &self.impulse,
            lag: &mut self.lag,
            gamma: &mut self.gamma,
            signature: &mut self.signature,
            keep_signature: self.keep_signatures,
            info: &mut self.info,
            score: &mut self.score,
            stat: &mut self.stat,
            rank: &mut self.rank,
        };
        assert!(slots.sized(N, M, P), "window arrays sized for the bank");
        slots
    }

    /// The fused pass with n = N, m = M, p = P over whole registers of S from the
    /// first slot; returns the first slot left (fewer than a register).
    #[inline(always)]
    fn fused_run<const N: usize, const M: usize, const P: usize, S: Lanes>(
        &mut self,
        coefs: &Coefs<N, M, P>,
    ) -> usize {
        let w = self.slots;
        let mut slots = self.slot_arrays::<N, M, P>();
        let mut s = 0;
        while s + S::L <= w {
            // SAFETY: sized (checked by `slot_arrays`) and s + L ≤ w.
            unsafe { fused_lanes::<N, M, P, S>(coefs, &mut slots, s) };
            s += S::L;
        }
        if split_statistic(M) {
            let mut t = 0;
            while t + S::L <= w {
                // SAFETY: as above.
                unsafe { statistic_lanes::<M, S>(coefs.tol, &mut slots, t) };
                t += S::L;
            }
        }
        s
    }

    /// The fused pass over the slots from s on, fewer than a register: one register of
    /// H if that many are left, then one slot at a time. The kernel is the same at
    /// every width, so every slot gets the same bits whichever register it falls in,
    /// and nothing is copied or padded. A function of its own, apart from the main
    /// loop, so that its registers do not crowd the main loop's.
    #[inline(always)]
    fn fused_rest<const N: usize, const M: usize, const P: usize, H: Lanes>(
        &mut self,
        coefs: &Coefs<N, M, P>,
        mut s: usize,
    ) {
        let mut slots = self.slot_arrays::<N, M, P>();
        let w = slots.w;
        if s + H::L <= w {
            // SAFETY: sized (checked by `slot_arrays`) and s + L ≤ w.
            unsafe { fused_lanes::<N, M, P, H>(coefs, &mut slots, s) };
            if split_statistic(M) {
                // SAFETY: as above.
                unsafe { statistic_lanes::<M, H>(coefs.tol, &mut slots, s) };
            }
            s += H::L;
        }
        while s < w {
            // SAFETY: as above, one slot.
            unsafe { fused_lanes::<N, M, P, f64>(coefs, &mut slots, s) };
            if split_statistic(M) {
                // SAFETY: as above.
                unsafe { statistic_lanes::<M, f64>(coefs.tol, &mut slots, s) };
            }
            s += 1;
        }
    }
}

/// The coefficients of measured step k for the fused pass, with n = N, m = M, p = P
/// known at compile time, copied out of the column-major matrices once per step.
#[derive(Debug, Clone, Copy)]
struct Coefs<const N: usize, const M: usize, const P: usize> {
    /// (L⁻¹H)_il at `[i][l]`.
    h: [[f64; N]; P],
    /// (L⁻¹Φ̃)_ij at `[i][j]`.
    phi: [[f64; M]; P],
    /// L⁻¹ε.
    eps: [f64; P],
    /// A_il at `[i][l]`.
    a: [[f64; N]; N],
    /// The forcing column G_ij of eq. (46) ([`forcing`]) at `[j][i]`.
    forcing: [[f64; N]; M],
    kinds: [Onset; M],
    tol: f64,
}

impl<const N: usize, const M: usize, const P: usize> Coefs<N, M, P> {
    #[inline(always)]
    fn new(inputs: &StepInputs<'_>, kinds: &[Onset], tol: f64) -> Self {
        let mut c = Self {
            h: [[0.0; N]; P],
            phi: [[0.0; M]; P],
            eps: [0.0; P],
            a: [[0.0; N]; N],
            forcing: [[0.0; N]; M],
            kinds: [Onset::Step; M],
            tol,
        };
        for i in 0..P {
            for l in 0..N {
                c.h[i][l] = inputs.h_white[at(P, i, l)];
            }
            for j in 0..M {
                c.phi[i][j] = inputs.phi_white[at(P, i, j)];
            }
            c.eps[i] = inputs.eps_white[i];
        }
        for i in 0..N {
            for l in 0..N {
                c.a[i][l] = inputs.closed_loop[at(N, i, l)];
            }
            for (j, kind) in kinds[..M].iter().enumerate() {
                c.forcing[j][i] =
                    forcing(*kind, inputs.psi[at(N, i, j)], inputs.fk_phi[at(N, i, j)]);
            }
        }
        c.kinds.copy_from_slice(&kinds[..M]);
        c
    }
}

/// The per-slot arrays the fused pass reads and writes (components w apart).
struct SlotArrays<'a> {
    w: usize,
    active: &'a [f64],
    /// b(k − r) of the impulse faults: 1 at the onset k (if active), 0 elsewhere.
    impulse: &'a [f64],
    lag: &'a mut [f64],
    gamma: &'a mut [f64],
    signature: &'a mut [f64],
    /// Whether to store L⁻¹S (the fused pass holds it in registers for C and d).
    keep_signature: bool,
    info: &'a mut [f64],
    score: &'a mut [f64],
    stat: &'a mut [f64],
    rank: &'a mut [f64],
}

impl SlotArrays<'_> {
    /// Whether every array holds its components for w slots: Γ n·m, L⁻¹S p·m, C
    /// m(m+1)/2, d m, the others one.
    fn sized(&self, n: usize, m: usize, p: usize) -> bool {
        let w = self.w;
        [
            (self.active.len(), 1),
            (self.impulse.len(), 1),
            (self.lag.len(), 1),
            (self.gamma.len(), n * m),
            (self.signature.len(), p * m),
            (self.info.len(), m * (m + 1) / 2),
            (self.score.len(), m),
            (self.stat.len(), 1),
            (self.rank.len(), 1),
        ]
        .iter()
        .all(|&(len, components)| len >= components * w)
    }
}

/// Slots s0 … s0 + L − 1 of measured step k in registers: the profile factors
/// (`compute_factors`), L⁻¹S = (L⁻¹H)Γ + b·L⁻¹Φ̃ (eq. (45)), C += SᵀS and d += SᵀL⁻¹ε
/// (eqs. (32)-(33)), the dropped-pivot LDLᵀ statistic dᵀC⁻d and rank (eq. (35); for
/// m ≥ 3 in a loop of its own, [`split_statistic`]), and Γ ← AΓ + b·G (eq. (46),
/// [`forcing`]); each onset gets the operations of the passes in their order, so the
/// results are the same bits. L⁻¹S stays in registers unless the signatures are kept
/// (`GlrDetector::keep_signatures`).
///
/// # Safety
/// `v.sized(N, M, P)` and s0 + L ≤ `v.w` (checked once per step by the caller, so the
/// loads and stores here go unchecked).
// Index loops over the (i, j, q) of the equations, written as in the passes.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
unsafe fn fused_lanes<const N: usize, const M: usize, const P: usize, S: Lanes>(
    c: &Coefs<N, M, P>,
    v: &mut SlotArrays<'_>,
    s0: usize,
) {
    let w = v.w;
    debug_assert!(v.sized(N, M, P) && s0 + S::L <= w);
    // SAFETY (every access): the caller checked `v.sized` and s0 + L ≤ w, and every
    // index is (component)·w + s0 with the component below the array's count.
    macro_rules! ld {
        ($arr:expr, $i:expr) => {
            unsafe { S::load_ptr($arr.as_ptr().add($i)) }
        };
    }
    macro_rules! st {
        ($x:expr, $arr:expr, $i:expr) => {
            unsafe { $x.store_ptr($arr.as_mut_ptr().add($i)) }
        };
    }
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let active = ld!(v.active, s0);
    let lag = ld!(v.lag, s0);
    // The output factors b_j(k − r), which are also the factors of the forcing
    // columns (eq. (46), [`forcing`]).
    let mut of = [zero; M];
    for j in 0..M {
        of[j] = match c.kinds[j] {
            Onset::Step | Onset::Known => active,
            Onset::Ramp => active.mul(lag.add(one)),
            Onset::Impulse => ld!(v.impulse, s0),
        };
    }
    let mut gamma = [[zero; N]; M];
    for (j, g) in gamma.iter_mut().enumerate() {
        for (q, g) in g.iter_mut().enumerate() {
            *g = ld!(v.gamma, (q + N * j) * w + s0);
        }
    }
    // L⁻¹S (eq. (45)), sig[j][i].
    let mut sig = [[zero; P]; M];
    for j in 0..M {
        for i in 0..P {
            let x = affine(c.phi[i][j], of[j], &c.h[i], &gamma[j]);
            if v.keep_signature {
                st!(x, v.signature, (i + P * j) * w + s0);
            }
            sig[j][i] = x;
        }
    }
    // C += SᵀS, d += SᵀL⁻¹ε (eqs. (32)-(33)); info[a][b] for b ≤ a.
    let mut info = [[zero; M]; M];
    let mut score = [zero; M];
    for a in 0..M {
        for b in 0..M {
            if b > a {
                continue;
            }
            let at = tri(a, b) * w + s0;
            let mut x = ld!(v.info, at);
            for i in 0..P {
                x = sig[a][i].mul_add(sig[b][i], x);
            }
            st!(x, v.info, at);
            info[a][b] = x;
        }
        let mut x = ld!(v.score, a * w + s0);
        for i in 0..P {
            x = sig[a][i].mul_add(S::splat(c.eps[i]), x);
        }
        st!(x, v.score, a * w + s0);
        score[a] = x;
    }
    if !split_statistic(M) {
        let tol = S::splat(c.tol);
        let (stat, rank) = if M == 2 {
            quad2(info[0][0], info[1][0], info[1][1], score[0], score[1], tol)
        } else {
            ldl_statistic(&info, &score, tol)
        };
        st!(stat, v.stat, s0);
        st!(rank, v.rank, s0);
    }
    // Γ ← AΓ + b·G (eq. (46)), in place (Γ_k is held above).
    for j in 0..M {
        for i in 0..N {
            let x = affine(c.forcing[j][i], of[j], &c.a[i], &gamma[j]);
            st!(x, v.gamma, (i + N * j) * w + s0);
        }
    }
    st!(lag.add(one), v.lag, s0);
}

/// Whether the fused pass leaves the statistic to a loop of its own after the main loop
/// ([`statistic_lanes`], reading back the C and d just stored): for m ≥ 3 the LDLᵀ's m
/// serial divisions make the statistic a dependency chain at the end of an iteration of
/// about 400 instructions (n3 p2 m4), too long for the reorder buffer to overlap with
/// the next register's work (in `perf annotate`, 28 % of the pass's samples sat on the
/// instructions after the four divisions). In a loop of their own, several registers'
/// chains run at once. Measured together with the signatures left in registers (the
/// window's arrays then fit the L1 data cache; neither alone gained): n3 p2 m4 w160 and
/// LTI general +14–18 % (docs/PERFORMANCE.md). Same operations, same bits.
const fn split_statistic(m: usize) -> bool {
    m >= 3
}

/// The statistic and rank of slots s0 … s0 + L − 1 from the stored C and d
/// ([`ldl_statistic`]), for the m of [`split_statistic`].
///
/// # Safety
/// `v.sized(N, M, P)` and s0 + L ≤ `v.w`.
// Index loops over the (a, b) of the packed triangle, as in `fused_lanes`.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
unsafe fn statistic_lanes<const M: usize, S: Lanes>(tol: f64, v: &mut SlotArrays<'_>, s0: usize) {
    let w = v.w;
    let zero = S::splat(0.0);
    let mut info = [[zero; M]; M];
    let mut score = [zero; M];
    for a in 0..M {
        for b in 0..=a {
            // SAFETY: as in `fused_lanes`.
            info[a][b] = unsafe { S::load_ptr(v.info.as_ptr().add(tri(a, b) * w + s0)) };
        }
        // SAFETY: as above.
        score[a] = unsafe { S::load_ptr(v.score.as_ptr().add(a * w + s0)) };
    }
    let (stat, rank) = ldl_statistic(&info, &score, S::splat(tol));
    // SAFETY: as above.
    unsafe {
        stat.store_ptr(v.stat.as_mut_ptr().add(s0));
        rank.store_ptr(v.rank.as_mut_ptr().add(s0));
    }
}

/// c₀·f + Σ_q row_q·col_q, the sum in q's order with fused multiply-adds: one entry of
/// L⁻¹S = (L⁻¹H)Γ + b·L⁻¹Φ̃ (eq. (45)) or of AΓ + b·G (eq. (46)) for a column of Γ, as
/// the passes compute it.
#[inline(always)]
fn affine<const N: usize, S: Lanes>(c0: f64, f: S, row: &[f64; N], col: &[S; N]) -> S {
    let mut x = S::splat(c0).mul(f);
    for q in 0..N {
        x = S::splat(row[q]).mul_add(col[q], x);
    }
    x
}
