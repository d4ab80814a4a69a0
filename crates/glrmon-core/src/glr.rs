//! The moving-window GLR bank: one Γ recursion, one (C, d) pair and one statistic per
//! candidate onset r (Zhang & Basseville 2014, §4.2 and §5).
//!
//! For each onset r in the window (eq. (37)):
//!
//! ```text
//! Γ_r(r)       = Ψ_{r−1}(r)                                   (Γ_{r−1}(r) = 0)
//! Γ_{k+1}(r)   = A_k Γ_k(r) + Ψ_k(r) − F_kK_k Φ_k(r)          (46), A_k = F_k(I − K_kH_k)
//! S_k(r)       = H_k Γ_k(r) + Φ_k(r)                          (45)
//! C_k(r)       = Σ_{j=r}^{k} S_jᵀ Σ_j⁻¹ S_j                     (32)
//! d_k(r)       = Σ_{j=r}^{k} S_jᵀ Σ_j⁻¹ ε_j                     (33)
//! l_k          = max_{k−w+1 ≤ r ≤ k−s} d_k(r)ᵀ C_k(r)⁺ d_k(r)    (35), (37)
//! r̂_k          = argmax (earliest on ties)                     (36)
//! θ̂_k          = C_k(r̂)⁺ d_k(r̂)                                (34)
//! ```
//!
//! In (46) each fault column enters through one factor: Ψ_k(r) − F_kK_kΦ_k(r) =
//! a(k − r)Ψ̃_k − b(k − r)F_kK_kΦ̃_k, and a = b for the step, ramp and known profiles
//! while a = 0 for an impulse, so it is b(k − r)·G_k with the forcing column
//! G_k = Ψ̃_k − F_kK_kΦ̃_k (G_k = −F_kK_kΦ̃_k for an impulse): one product per entry
//! of Γ instead of two and a difference ([`forcing`]).
//!
//! The sums start at j = r, not r + 1 as printed in (32)-(33): for a state step fault
//! S_r(r) = 0 and the two agree; for impulses and output faults the j = r term carries
//! the fault.
//!
//! # Layout
//! The window is a ring of w slots in structure-of-arrays layout: each scalar component
//! (an entry of Γ, of the whitened signature L⁻¹S, of C or d) is a contiguous array over
//! the slots, so every per-sample loop runs over slots innermost with no branches and
//! vectorises. Advancing k retires the oldest onset and starts the newest in its slot;
//! nothing is allocated per sample. For small n, m, p a measured step is one fused pass
//! over the slots ([`WindowBank::step`]) that keeps each register of onsets' Γ, S, C,
//! d and LDLᵀ factors in vector registers from eq. (45) to eq. (46).
//!
//! # Rank-deficient C
//! Until the signatures are persistently exciting (eq. (22)), C_k(r) is singular (for a
//! state step fault at lag 0 it is exactly 0). The statistic uses an LDLᵀ factorisation
//! of C in which pivots D_j ≤ τ·max_i C_ii are dropped (τ = the rank tolerance). For a
//! positive semi-definite C an exactly zero pivot comes with an exactly zero column of
//! the Schur complement, so the dropped-pivot factorisation is a generalised inverse
//! C⁻ (C C⁻ C = C); since d ∈ range(C), dᵀC⁻d = dᵀC⁺d is exactly 2 ln LR and is χ²
//! with dof = rank C = the number of kept pivots. The cut-off is never negative (τ > 0,
//! and C's diagonal is a sum of squares), so a kept pivot is positive without a test
//! of its own. The magnitude θ̂ at r̂ uses the Moore–Penrose pseudo-inverse
//! (eigenvalues ≤ τ·λ_max dropped) when C is deficient.
//!
//! # Stationary regime (LTI fast path)
//! When A_k, F_kK_k, L_k⁻¹H_k, Ψ̃_k and Φ̃_k are constant (an LTI model whose Riccati
//! recursion has converged), eq. (46) from Γ_r(r) = a_entry·Ψ̃ gives the same Γ for every
//! onset at the same lag ℓ = k − r, hence S_k(r) = S(ℓ) and C_k(r) = C(ℓ) (eq. (32)).
//! [`WindowBank::enter_steady`] tabulates S(ℓ), C(ℓ), a generalised inverse C(ℓ)⁻ (the
//! same dropped-pivot LDLᵀ) and Γ(ℓ + 1) once for ℓ = 0 … w − 1; each sample then only
//! adds S(ℓ)ᵀL⁻¹ε_k to d_k(r) (eq. (33)) and evaluates d_k(r)ᵀC(ℓ)⁻d_k(r) per onset.
//! [`WindowBank::leave_steady`] writes Γ, C and S back from the tables so that the
//! general recursion continues exactly where the tables stand.

use crate::fault::Onset;
use crate::linalg::{at, jacobi_eigen};
use crate::simd::VectorLevel as Level;

/// Defines `$avx2` and `$avx512`: the method `$body` (an `#[inline(always)]` method of
/// the bank) compiled for AVX2 and for AVX-512F (see crate::simd). `$wide => $avx512`
/// compiles another body for AVX-512F (eight lanes instead of four).
macro_rules! wide {
    ($body:ident, $avx2:ident, $avx512:ident, ($($a:ident: $t:ty),*) $(-> $r:ty)?) => {
        wide!($body, $avx2, $body => $avx512, ($($a: $t),*) $(-> $r)?);
    };
    ($body:ident, $avx2:ident, $wide:ident => $avx512:ident, ($($a:ident: $t:ty),*) $(-> $r:ty)?) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $avx2(&mut self, $($a: $t),*) $(-> $r)? {
            self.$body($($a),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,fma")]
        unsafe fn $avx512(&mut self, $($a: $t),*) $(-> $r)? {
            self.$wide($($a),*)
        }
    };
}

/// Calls the variant of a [`wide!`] method for the bank's vector level.
macro_rules! wide_call {
    ($this:ident, $body:ident, $avx2:ident, $avx512:ident, ($($a:expr),*)) => {
        match $this.level {
            // SAFETY: the level is Avx2 or Avx512 only when the processor has the
            // feature (`VectorLevel::detect`, or `Detector::set_vector_level`, which
            // checks `VectorLevel::supported`).
            #[cfg(target_arch = "x86_64")]
            Level::Avx2 => unsafe { $this.$avx2($($a),*) },
            #[cfg(target_arch = "x86_64")]
            Level::Avx512 => unsafe { $this.$avx512($($a),*) },
            _ => $this.$body($($a),*),
        }
    };
}

/// The fused step at one vector width: an entry compiled with `$feature` that finds the
/// kernel of the bank's (n, m, p) ([`for_fused_dims!`]) and runs it around
/// `fused_body`, and the kernels themselves, each a function of its own (not inlined
/// into the dispatch, which keeps each function small for the compiler). One per
/// feature: a generic function cannot carry `#[target_feature]`.
macro_rules! fused_level {
    ($feature:literal, $entry:ident, $run:ident, $rest:ident, $lanes:ty, $half:ty, $doc:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        unsafe fn $entry(&mut self, k: u64, inputs: &StepInputs<'_>) -> Option<WindowMax> {
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
fn fused_dims(n: usize, m: usize, p: usize) -> bool {
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

/// Default relative tolerance τ for the rank decision on C_k(r).
pub const DEFAULT_RANK_TOLERANCE: f64 = 1e-9;

/// Index of C_ab (a ≥ b) in the packed lower triangle.
#[inline(always)]
fn tri(a: usize, b: usize) -> usize {
    a * (a + 1) / 2 + b
}

/// The window of candidate onsets and its sufficient statistics.
#[derive(Debug, Clone)]
pub(crate) struct WindowBank {
    n: usize,
    m: usize,
    p: usize,
    /// Number of slots: w (moving window) or 1 (known profile).
    slots: usize,
    /// s: the youngest admissible onset is k − s.
    min_lag: u64,
    known: bool,
    tolerance: f64,
    kinds: Vec<Onset>,
    first: Option<u64>,
    /// Onset r held by each slot.
    onset: Vec<u64>,
    /// 1.0 for a slot holding an onset, 0.0 before the window has filled.
    active: Vec<f64>,
    /// k − r for each slot at the current step, as f64 (for ramp factors).
    lag: Vec<f64>,
    /// Γ_k(r): component (i, j) of slot s at [(i + n j)·slots + s].
    gamma: Vec<f64>,
    gamma_next: Vec<f64>,
    /// L_k⁻¹S_k(r): component (i, j) at [(i + p j)·slots + s]. The passes' scratch
    /// between the signatures and C, d; the fused pass writes it only for
    /// `keep_signatures`.
    signature: Vec<f64>,
    /// C_k(r), packed lower triangle: [tri(a, b)·slots + s].
    info: Vec<f64>,
    /// d_k(r): [a·slots + s].
    score: Vec<f64>,
    // Per-step scratch over slots.
    /// b_j(k − r): the factor of L⁻¹Φ̃ in the signature (eq. (45)) and of the forcing
    /// column in Γ's time update (eq. (46), [`forcing`]).
    output_factor: Vec<f64>,
    /// The impulse output factor of the fused pass: 0 except at the slot of onset k.
    impulse: Vec<f64>,
    /// The forcing columns G_k of eq. (46) (n×m, [`forcing`]) of the time update.
    forcing: Vec<f64>,
    ldl: Vec<f64>,
    inv_pivot: Vec<f64>,
    solved: Vec<f64>,
    stat: Vec<f64>,
    rank: Vec<f64>,
    cutoff: Vec<f64>,
    /// Onset k + 1 announced by the last time update, entered at the next step so that
    /// the oldest onset's statistics stay readable between steps.
    pending: Option<u64>,
    /// Γ_{k+1}(k+1) = Ψ_k(k+1) for the pending onset (n×m).
    entry: Vec<f64>,
    // Eigen scratch for θ̂ when C(r̂) is deficient.
    eig_a: Vec<f64>,
    eig_vals: Vec<f64>,
    eig_vecs: Vec<f64>,
    /// Sample index of the last measured step (the k of `lag = k − r` in the tables).
    current: u64,
    /// Whether the stationary tables are in force.
    steady: bool,
    tables: LagTables,
    /// Vector width of the window loops (same bits at every width).
    level: Level,
    /// Whether the passes round a·b + c once ([`madd`], crate::simd): always at the AVX
    /// levels, whose fused pass does.
    fused_madd: bool,
    /// Whether a measured step runs the fused single pass ([`WindowBank::step`]); set
    /// when (n, m, p) is one of the fused dimensions, cleared only to compare with the
    /// passes.
    fused: bool,
    /// Whether `ldl`, `inv_pivot` and `solved` hold the last step's factorisation of
    /// every slot (the passes for m ≠ 2) or of none (the fused pass keeps it in
    /// registers; m = 2 has none). θ̂ reads it only for m ≥ 5: for m = 1, 3, 4 it
    /// factors C(r̂) in registers ([`WindowBank::solve_regular`]).
    factored: bool,
    /// Whether measured steps keep every onset's L_k⁻¹S_k(r) readable
    /// ([`WindowBank::whitened_signature`]); off by default, see
    /// `Detector::keep_signatures`.
    keep_signatures: bool,
    /// Set when `keep_signatures` is switched on, until the next measured step: the
    /// signatures in store are not the last step's.
    signatures_stale: bool,
}

/// The matrices of measured step k that the window needs, all column-major.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StepInputs<'a> {
    /// L_k⁻¹H_k (p×n).
    pub(crate) h_white: &'a [f64],
    /// L_k⁻¹Φ̃_k (p×m).
    pub(crate) phi_white: &'a [f64],
    /// L_k⁻¹ε_k (p).
    pub(crate) eps_white: &'a [f64],
    /// A_k = F_k(I − K_kH_k) (n×n).
    pub(crate) closed_loop: &'a [f64],
    /// Ψ̃_k (n×m).
    pub(crate) psi: &'a [f64],
    /// F_kK_kΦ̃_k (n×m).
    pub(crate) fk_phi: &'a [f64],
}

/// Per-lag tables of the stationary regime, lag-reversed: the entry for lag ℓ of
/// component c is at [c·w + (w − 1 − ℓ)], so that the slots of the ring, taken in
/// increasing order from the newest onset's slot, meet the table in increasing order.
/// Allocated with the bank, so entering the regime allocates nothing.
#[derive(Debug, Clone)]
struct LagTables {
    /// L⁻¹S(ℓ) (p×m components).
    signature: Vec<f64>,
    /// C(ℓ), packed lower triangle.
    info: Vec<f64>,
    /// C(ℓ)⁻, the dropped-pivot generalised inverse, packed lower triangle, with the
    /// off-diagonal entries doubled (the coefficients of the quadratic form dᵀC⁻d).
    inverse: Vec<f64>,
    /// rank C(ℓ).
    rank: Vec<f64>,
    /// Γ(ℓ + 1) = Γ_{r+ℓ+1}(r), the value after the time update at lag ℓ (n×m).
    gamma: Vec<f64>,
    /// Scratch for the construction: Γ(ℓ), C(ℓ), the m×m LDLᵀ.
    work_gamma: Vec<f64>,
    work_next: Vec<f64>,
    work_ldl: Vec<f64>,
    work_inv_pivot: Vec<f64>,
    work_linv: Vec<f64>,
}

/// The GLR decision quantities of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WindowMax {
    pub(crate) glr: f64,
    pub(crate) onset: u64,
    pub(crate) rank: usize,
}

impl WindowBank {
    pub(crate) fn new(
        n: usize,
        m: usize,
        p: usize,
        window: usize,
        min_lag: usize,
        kinds: Vec<Onset>,
        tolerance: f64,
    ) -> Self {
        debug_assert!(tolerance > 0.0, "the rank cut-off needs τ > 0");
        let known = kinds.iter().all(|k| *k == Onset::Known);
        let slots = if known { 1 } else { window };
        let t = m * (m + 1) / 2;
        let z = |len: usize| vec![0.0; len];
        Self {
            n,
            m,
            p,
            slots,
            min_lag: min_lag as u64,
            known,
            tolerance,
            kinds,
            first: None,
            onset: vec![0; slots],
            active: z(slots),
            lag: z(slots),
            gamma: z(n * m * slots),
            gamma_next: z(n * m * slots),
            signature: z(p * m * slots),
            info: z(t * slots),
            score: z(m * slots),
            output_factor: z(m * slots),
            impulse: z(slots),
            forcing: z(n * m),
            ldl: z(t * slots),
            inv_pivot: z(m * slots),
            solved: z(m * slots),
            stat: z(slots),
            rank: z(slots),
            cutoff: z(slots),
            pending: None,
            entry: z(n * m),
            eig_a: z(m * m),
            eig_vals: z(m),
            eig_vecs: z(m * m),
            current: 0,
            steady: false,
            level: Level::detect(),
            fused_madd: crate::simd::fused_multiply_add(),
            fused: fused_dims(n, m, p),
            factored: false,
            keep_signatures: false,
            signatures_stale: false,
            tables: LagTables {
                signature: z(p * m * slots),
                info: z(t * slots),
                inverse: z(t * slots),
                rank: z(slots),
                gamma: z(n * m * slots),
                work_gamma: z(n * m),
                work_next: z(n * m),
                work_ldl: z(m * m),
                work_inv_pivot: z(m),
                work_linv: z(m * m),
            },
        }
    }

    fn slot_of(&self, onset: u64) -> usize {
        let first = self.first.unwrap_or(0);
        ((onset - first) % self.slots as u64) as usize
    }

    /// The slot holding onset r at the current step k, if r is still in the window.
    pub(crate) fn slot_for(&self, onset: u64) -> Option<usize> {
        let first = self.first?;
        if onset < first {
            return None;
        }
        let s = self.slot_of(onset);
        (self.active[s] != 0.0 && self.onset[s] == onset).then_some(s)
    }

    /// Starts the bank at the first sample k0 with onset k0 (Γ_{k0}(k0) = 0: an impulse
    /// entering X_{k0} cannot be told from the initial-state error covered by P_0).
    pub(crate) fn start(&mut self, k0: u64) {
        self.first = Some(k0);
        self.onset[0] = k0;
        self.active[0] = 1.0;
        self.lag[0] = 0.0;
    }

    /// Per-slot profile factors b_j(k − r) at step k, one loop per profile kind so that
    /// the loops over slots are branch-free. (The state factor a_j is b_j, or 0 for an
    /// impulse, and enters only through the forcing column.)
    #[inline(always)]
    fn compute_factors(&mut self, k: u64) {
        let slots = self.slots;
        let newest = self.first.map(|_| self.slot_of(k));
        for (j, kind) in self.kinds.iter().enumerate() {
            let of = &mut self.output_factor[j * slots..(j + 1) * slots];
            match kind {
                Onset::Step | Onset::Known => of.copy_from_slice(&self.active),
                Onset::Ramp => {
                    for ((f, a), l) in of.iter_mut().zip(&self.active).zip(&self.lag) {
                        *f = a * (l + 1.0);
                    }
                }
                Onset::Impulse => {
                    of.fill(0.0);
                    if let Some(s) = newest {
                        if self.onset[s] == k {
                            of[s] = self.active[s];
                        }
                    }
                }
            }
        }
    }

    /// Measurement step k: whitened signatures L⁻¹S_k(r) = (L⁻¹H_k)Γ_k(r) + b(k−r)L⁻¹Φ̃_k
    /// and the accumulation of C_k(r), d_k(r) (eqs. (32)-(33) from j = r).
    ///
    /// `h_white` is L⁻¹H_k (p×n), `phi_white` is L⁻¹Φ̃_k (p×m), `eps_white` is L⁻¹ε_k.
    pub(crate) fn accumulate(
        &mut self,
        k: u64,
        h_white: &[f64],
        phi_white: &[f64],
        eps_white: &[f64],
    ) {
        wide_call!(
            self,
            accumulate_body,
            accumulate_avx2,
            accumulate_avx512,
            (k, h_white, phi_white, eps_white)
        )
    }

    wide!(accumulate_body, accumulate_avx2, accumulate_avx512, (k: u64, h_white: &[f64], phi_white: &[f64], eps_white: &[f64]));

    #[inline(always)]
    fn accumulate_body(&mut self, k: u64, h_white: &[f64], phi_white: &[f64], eps_white: &[f64]) {
        if self.fused_madd {
            self.accumulate_in::<true>(k, h_white, phi_white, eps_white);
        } else {
            self.accumulate_in::<false>(k, h_white, phi_white, eps_white);
        }
    }

    #[inline(always)]
    fn accumulate_in<const FUSED: bool>(
        &mut self,
        k: u64,
        h_white: &[f64],
        phi_white: &[f64],
        eps_white: &[f64],
    ) {
        self.current = k;
        self.compute_factors(k);
        let (n, m, p, w) = (self.n, self.m, self.p, self.slots);
        for j in 0..m {
            let of = &self.output_factor[j * w..(j + 1) * w];
            for i in 0..p {
                let dst = &mut self.signature[(i + p * j) * w..(i + p * j + 1) * w];
                let phi = phi_white[at(p, i, j)];
                for (d, f) in dst.iter_mut().zip(of) {
                    *d = phi * f;
                }
                for l in 0..n {
                    let h = h_white[at(p, i, l)];
                    let g = &self.gamma[(l + n * j) * w..(l + n * j + 1) * w];
                    for (d, g) in dst.iter_mut().zip(g) {
                        *d = madd::<FUSED>(h, *g, *d);
                    }
                }
            }
        }
        if m == 2 && p == 1 {
            self.accumulate_m2_p1::<FUSED>(eps_white[0]);
            return;
        }
        for a in 0..m {
            for b in 0..=a {
                let c = &mut self.info[tri(a, b) * w..(tri(a, b) + 1) * w];
                for i in 0..p {
                    let sa = &self.signature[(i + p * a) * w..(i + p * a + 1) * w];
                    let sb = &self.signature[(i + p * b) * w..(i + p * b + 1) * w];
                    for ((c, x), y) in c.iter_mut().zip(sa).zip(sb) {
                        *c = madd::<FUSED>(*x, *y, *c);
                    }
                }
            }
            let d = &mut self.score[a * w..(a + 1) * w];
            for (i, e) in eps_white.iter().enumerate().take(p) {
                let sa = &self.signature[(i + p * a) * w..(i + p * a + 1) * w];
                for (d, x) in d.iter_mut().zip(sa) {
                    *d = madd::<FUSED>(*x, *e, *d);
                }
            }
        }
    }

    /// C and d updates for m = 2, p = 1 in one pass (same operations and order as the
    /// generic loops).
    #[inline(always)]
    fn accumulate_m2_p1<const FUSED: bool>(&mut self, e: f64) {
        let w = self.slots;
        let (s0, s1) = self.signature.split_at(w);
        let (c00, rest) = self.info.split_at_mut(w);
        let (c10, c11) = rest.split_at_mut(w);
        let (d0, d1) = self.score.split_at_mut(w);
        let (s1, c10, c11, d1) = (&s1[..w], &mut c10[..w], &mut c11[..w], &mut d1[..w]);
        for s in 0..w {
            let (x0, x1) = (s0[s], s1[s]);
            c00[s] = madd::<FUSED>(x0, x0, c00[s]);
            c10[s] = madd::<FUSED>(x1, x0, c10[s]);
            c11[s] = madd::<FUSED>(x1, x1, c11[s]);
            d0[s] = madd::<FUSED>(x0, e, d0[s]);
            d1[s] = madd::<FUSED>(x1, e, d1[s]);
        }
    }

    /// d_k(r)ᵀC_k(r)⁺d_k(r) and rank C_k(r) for every slot (batched LDLᵀ with dropped
    /// pivots, vectorised over slots), then the maximum over admissible onsets.
    pub(crate) fn maximize(&mut self, k: u64) -> Option<WindowMax> {
        wide_call!(self, maximize_body, maximize_avx2, maximize_avx512, (k))
    }

    wide!(maximize_body, maximize_avx2, maximize_avx512, (k: u64) -> Option<WindowMax>);

    #[inline(always)]
    fn maximize_body(&mut self, k: u64) -> Option<WindowMax> {
        // The m = 2 statistic (`quad2`) keeps no factorisation: θ̂ uses adj(C)/δ.
        self.factored = self.m != 2;
        match self.m {
            1 => self.statistic_m1(),
            2 => self.statistic_m2(),
            _ => self.statistic_generic(),
        }
        self.best(k)
    }

    /// The maximum over admissible onsets after [`WindowBank::accumulate_steady`].
    pub(crate) fn maximize_steady(&mut self, k: u64) -> Option<WindowMax> {
        wide_call!(self, best_body, best_avx2, best_avx512, (k))
    }

    wide!(best_body, best_avx2, best_avx512, (k: u64) -> Option<WindowMax>);

    #[inline(always)]
    fn best_body(&mut self, k: u64) -> Option<WindowMax> {
        self.best(k)
    }

    /// The LDLᵀ statistic for m = 1 in one pass: d²/C where C > τ·C.
    #[inline(always)]
    fn statistic_m1(&mut self) {
        let w = self.slots;
        let tol = self.tolerance;
        let (c, d) = (&self.info[..w], &self.score[..w]);
        let it = self
            .stat
            .iter_mut()
            .zip(self.rank.iter_mut())
            .zip(&mut self.inv_pivot[..w]);
        for (((st, rk), iv), (c, z)) in it.zip(c.iter().zip(d)) {
            let keep = *c > tol * c;
            *iv = if keep { 1.0 / c } else { 0.0 };
            *rk = if keep { 1.0 } else { 0.0 };
            *st = z * z * *iv;
        }
        self.solved[..w].copy_from_slice(&self.score[..w]);
    }

    /// The statistic for m = 2 in one branch-free pass over the slots: [`quad2`], the
    /// operations of the fused pass.
    #[inline(always)]
    fn statistic_m2(&mut self) {
        let w = self.slots;
        let tol = self.tolerance;
        let (c00, rest) = self.info.split_at(w);
        let (c10, c11) = rest.split_at(w);
        let (d0, d1) = self.score.split_at(w);
        let (c11, d1) = (&c11[..w], &d1[..w]);
        let (stat, rank) = (&mut self.stat[..w], &mut self.rank[..w]);
        for s in 0..w {
            (stat[s], rank[s]) = quad2(c00[s], c10[s], c11[s], d0[s], d1[s], tol);
        }
    }

    /// The batched LDLᵀ statistic for any m.
    #[inline(always)]
    fn statistic_generic(&mut self) {
        let (m, w) = (self.m, self.slots);
        // Rank cut-off per slot: τ·max_a C_aa.
        self.cutoff.iter_mut().for_each(|c| *c = 0.0);
        for a in 0..m {
            let caa = &self.info[tri(a, a) * w..(tri(a, a) + 1) * w];
            for (c, x) in self.cutoff.iter_mut().zip(caa) {
                *c = larger(*c, *x);
            }
        }
        let tol = self.tolerance;
        self.cutoff.iter_mut().for_each(|c| *c *= tol);
        self.stat.iter_mut().for_each(|x| *x = 0.0);
        self.rank.iter_mut().for_each(|x| *x = 0.0);
        for j in 0..m {
            // D_j = C_jj − Σ_{q<j} L_jq² D_q
            self.ldl[tri(j, j) * w..(tri(j, j) + 1) * w]
                .copy_from_slice(&self.info[tri(j, j) * w..(tri(j, j) + 1) * w]);
            for q in 0..j {
                let (head, tail) = self.ldl.split_at_mut(tri(j, j) * w);
                let djj = &mut tail[..w];
                let ljq = &head[tri(j, q) * w..(tri(j, q) + 1) * w];
                let dq = &head[tri(q, q) * w..(tri(q, q) + 1) * w];
                for ((d, l), dd) in djj.iter_mut().zip(ljq).zip(dq) {
                    *d -= l * l * dd;
                }
            }
            {
                let djj = &self.ldl[tri(j, j) * w..(tri(j, j) + 1) * w];
                let inv = &mut self.inv_pivot[j * w..(j + 1) * w];
                for (((iv, d), c), r) in inv
                    .iter_mut()
                    .zip(djj)
                    .zip(&self.cutoff)
                    .zip(self.rank.iter_mut())
                {
                    let keep = *d > *c;
                    *iv = if keep { 1.0 / d } else { 0.0 };
                    *r += if keep { 1.0 } else { 0.0 };
                }
            }
            // L_ij = (C_ij − Σ_{q<j} L_iq L_jq D_q) / D_j for i > j (0 for a dropped pivot).
            for i in (j + 1)..m {
                self.ldl[tri(i, j) * w..(tri(i, j) + 1) * w]
                    .copy_from_slice(&self.info[tri(i, j) * w..(tri(i, j) + 1) * w]);
                for q in 0..j {
                    let (head, tail) = self.ldl.split_at_mut(tri(i, j) * w);
                    let lij = &mut tail[..w];
                    let liq = &head[tri(i, q) * w..(tri(i, q) + 1) * w];
                    let ljq = &head[tri(j, q) * w..(tri(j, q) + 1) * w];
                    let dq = &head[tri(q, q) * w..(tri(q, q) + 1) * w];
                    for (((x, a), b), d) in lij.iter_mut().zip(liq).zip(ljq).zip(dq) {
                        *x -= a * b * d;
                    }
                }
                let inv = &self.inv_pivot[j * w..(j + 1) * w];
                let lij = &mut self.ldl[tri(i, j) * w..(tri(i, j) + 1) * w];
                for (x, iv) in lij.iter_mut().zip(inv) {
                    *x *= iv;
                }
            }
        }
        // z = L⁻¹d (unit lower triangular), statistic Σ_j z_j²/D_j over kept pivots.
        for j in 0..m {
            let (done, rest) = self.solved.split_at_mut(j * w);
            let zj = &mut rest[..w];
            zj.copy_from_slice(&self.score[j * w..(j + 1) * w]);
            for q in 0..j {
                let zq = &done[q * w..(q + 1) * w];
                let ljq = &self.ldl[tri(j, q) * w..(tri(j, q) + 1) * w];
                for ((z, l), x) in zj.iter_mut().zip(ljq).zip(zq) {
                    *z -= l * x;
                }
            }
            let inv = &self.inv_pivot[j * w..(j + 1) * w];
            for ((st, z), iv) in self.stat.iter_mut().zip(zj.iter()).zip(inv) {
                *st += z * z * iv;
            }
        }
    }

    /// Earliest onset with the largest statistic among r ∈ {max(k−w+1, k0), …, k − s}.
    #[inline(always)]
    fn best(&self, k: u64) -> Option<WindowMax> {
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
    fn rank_at(&self, s: usize) -> f64 {
        if self.steady {
            self.tables.rank[self.table_index(s)]
        } else {
            self.rank[s]
        }
    }

    /// Measured step k of the whole window (eqs. (45), (32)-(36), (46)): the signatures,
    /// C and d, the statistic and rank of every onset, the maximum, and the time update
    /// of Γ to k + 1 with the onset k + 1 announced. For the fused dimensions at the
    /// AVX2 and AVX-512F levels one pass over the slots does it all, four or eight
    /// onsets at a time in registers ([`fused_lanes`]): no intermediate arrays, and C,
    /// d and Γ are read and written once. Otherwise (and at the baseline level, where
    /// 2-lane registers spill and the passes measured as fast)
    /// [`WindowBank::accumulate`], [`WindowBank::maximize`] and
    /// [`WindowBank::time_update`] run as passes. Both do the same operations per onset
    /// in the same order, so they give the same bits.
    pub(crate) fn step(&mut self, k: u64, inputs: &StepInputs<'_>) -> Option<WindowMax> {
        self.signatures_stale = false;
        if !self.fused || self.level == Level::Baseline {
            self.accumulate(k, inputs.h_white, inputs.phi_white, inputs.eps_white);
            let best = self.maximize(k);
            self.time_update(k, inputs.closed_loop, inputs.psi, inputs.fk_phi, false);
            return best;
        }
        match self.level {
            // SAFETY: as in `wide_call!`: the level is Avx2 or Avx512 only when the
            // processor has the feature.
            #[cfg(target_arch = "x86_64")]
            Level::Avx2 => unsafe { self.fused_avx2(k, inputs) },
            #[cfg(target_arch = "x86_64")]
            Level::Avx512 => unsafe { self.fused_avx512(k, inputs) },
            _ => unreachable!("the baseline level runs the passes"),
        }
    }

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

    /// The dropped-pivot LDLᵀ of C_k(r) and z = L⁻¹d_k(r) for slot s alone, into `ldl`,
    /// `inv_pivot` and `solved`, with the operations of the statistic passes: after the
    /// fused pass, which keeps them in registers, [`WindowBank::magnitude`] needs them
    /// at r̂ only.
    fn factor_slot(&mut self, s: usize) {
        let (m, w) = (self.m, self.slots);
        let cut = pivot_cutoff(m, |a| self.info[tri(a, a) * w + s], self.tolerance);
        for j in 0..m {
            let mut d = self.info[tri(j, j) * w + s];
            for q in 0..j {
                let l = self.ldl[tri(j, q) * w + s];
                d -= l * l * self.ldl[tri(q, q) * w + s];
            }
            self.ldl[tri(j, j) * w + s] = d;
            let keep = d > cut;
            let inv = if keep { 1.0 / d } else { 0.0 };
            self.inv_pivot[j * w + s] = inv;
            for i in (j + 1)..m {
                let mut x = self.info[tri(i, j) * w + s];
                for q in 0..j {
                    x -= self.ldl[tri(i, q) * w + s]
                        * self.ldl[tri(j, q) * w + s]
                        * self.ldl[tri(q, q) * w + s];
                }
                self.ldl[tri(i, j) * w + s] = x * inv;
            }
        }
        for j in 0..m {
            let mut z = self.score[j * w + s];
            for q in 0..j {
                z -= self.ldl[tri(j, q) * w + s] * self.solved[q * w + s];
            }
            self.solved[j * w + s] = z;
        }
    }

    /// θ̂ = C_k(r)⁺d_k(r) for the slot holding onset r (eq. (34)); false when r is not in
    /// the window.
    pub(crate) fn magnitude(&mut self, onset: u64, out: &mut [f64]) -> bool {
        let Some(s) = self.slot_for(onset) else {
            return false;
        };
        let (m, w) = (self.m, self.slots);
        // Where C(r) is stored: the slot of the ring, or the lag's entry of the tables.
        let (info, at_index) = if self.steady {
            let t = self.table_index(s);
            if self.tables.rank[t] as usize == m {
                // θ = C⁻d with the tabulated inverse (C is regular here, C⁻ = C⁻¹).
                for (a, o) in out.iter_mut().enumerate().take(m) {
                    *o = (0..m)
                        .map(|b| {
                            let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
                            // The table holds 2·C⁻_ab off the diagonal (halving is exact).
                            let g = self.tables.inverse[tri(hi, lo) * w + t];
                            let g = if a == b { g } else { 0.5 * g };
                            g * self.score[b * w + s]
                        })
                        .sum();
                }
                return true;
            }
            (&self.tables.info, t)
        } else if self.rank[s] as usize == m && m == 2 {
            // C⁻¹d = adj(C)d/δ, the regular case of `quad2`.
            let info = |i| self.info[i * w + s];
            let (a, b, c, d1, d2) = (info(0), info(1), info(2), self.score[s], self.score[w + s]);
            let det = a * c - b * b;
            out[0] = (c * d1 - b * d2) / det;
            out[1] = (a * d2 - b * d1) / det;
            return true;
        } else if self.rank[s] as usize == m {
            match m {
                1 => self.solve_regular::<1>(s, out),
                3 => self.solve_regular::<3>(s, out),
                4 => self.solve_regular::<4>(s, out),
                _ => self.solve_factored(s, out),
            }
            return true;
        } else {
            (&self.info, s)
        };
        for a in 0..m {
            for b in 0..=a {
                let c = info[tri(a, b) * w + at_index];
                self.eig_a[at(m, a, b)] = c;
                self.eig_a[at(m, b, a)] = c;
            }
        }
        jacobi_eigen(&mut self.eig_a, m, &mut self.eig_vals, &mut self.eig_vecs);
        let lmax = self.eig_vals.iter().fold(0.0_f64, |a, b| a.max(*b));
        let cut = self.tolerance * lmax;
        out.iter_mut().for_each(|x| *x = 0.0);
        for e in 0..m {
            let lam = self.eig_vals[e];
            if lam > cut && lam > 0.0 {
                let v = &self.eig_vecs[e * m..(e + 1) * m];
                let proj: f64 = (0..m).map(|a| v[a] * self.score[a * w + s]).sum();
                for a in 0..m {
                    out[a] += v[a] * proj / lam;
                }
            }
        }
        true
    }

    /// θ̂ = C⁻¹d for slot s with a regular C of any m: back-substitution on the slot's
    /// LDLᵀ (computed by [`WindowBank::factor_slot`] unless the passes left it).
    fn solve_factored(&mut self, s: usize, out: &mut [f64]) {
        let (m, w) = (self.m, self.slots);
        if !self.factored {
            self.factor_slot(s);
        }
        // Back-substitution on the slot's LDLᵀ: θ = L⁻ᵀ D⁻¹ z.
        for (j, o) in out.iter_mut().enumerate().take(m) {
            *o = self.solved[j * w + s] * self.inv_pivot[j * w + s];
        }
        for j in (0..m).rev() {
            let mut v = out[j];
            for (i, o) in out.iter().enumerate().take(m).skip(j + 1) {
                v -= self.ldl[tri(i, j) * w + s] * o;
            }
            out[j] = v;
        }
    }

    /// θ̂ = C⁻¹d for slot s with a regular C and m = M: [`WindowBank::factor_slot`]'s
    /// LDLᵀ and [`WindowBank::solve_factored`]'s back-substitution, the same operations
    /// in the same order (so the same bits), on copies the compiler keeps in registers
    /// instead of the strided slot arrays: about a tenth of the instructions at m = 4.
    // Index loops over the (i, j, q) of the factorisation, as in `factor_slot`.
    #[allow(clippy::needless_range_loop)]
    fn solve_regular<const M: usize>(&self, s: usize, out: &mut [f64]) {
        let w = self.slots;
        let info = |a: usize, b: usize| self.info[tri(a, b) * w + s];
        let cut = pivot_cutoff(M, |a| info(a, a), self.tolerance);
        // L below the diagonal, D on it.
        let mut ldl = [[0.0; M]; M];
        let mut inv = [0.0; M];
        for j in 0..M {
            let mut d = info(j, j);
            for q in 0..j {
                let l = ldl[j][q];
                d -= l * l * ldl[q][q];
            }
            ldl[j][j] = d;
            inv[j] = if d > cut { 1.0 / d } else { 0.0 };
            for i in (j + 1)..M {
                let mut x = info(i, j);
                for q in 0..j {
                    x -= ldl[i][q] * ldl[j][q] * ldl[q][q];
                }
                ldl[i][j] = x * inv[j];
            }
        }
        let mut z = [0.0; M];
        for j in 0..M {
            let mut v = self.score[j * w + s];
            for q in 0..j {
                v -= ldl[j][q] * z[q];
            }
            z[j] = v;
        }
        for j in 0..M {
            out[j] = z[j] * inv[j];
        }
        for j in (0..M).rev() {
            let mut v = out[j];
            for i in (j + 1)..M {
                v -= ldl[i][j] * out[i];
            }
            out[j] = v;
        }
    }

    /// Time update k → k+1 (eq. (46)): Γ_{k+1}(r) = A_kΓ_k(r) + a(k−r)Ψ̃_k − b(k−r)F_kK_kΦ̃_k,
    /// then the onset k − w + 1 leaves the window and onset k + 1 enters it with
    /// Γ_{k+1}(k+1) = Ψ_k(k+1) and C = 0, d = 0.
    ///
    /// `closed_loop` is A_k (n×n), `psi` is Ψ̃_k (n×m), `fk_phi` is F_kK_kΦ̃_k (n×m).
    /// After a predict-only step `fk_phi` is zero and the factors are recomputed here.
    pub(crate) fn time_update(
        &mut self,
        k: u64,
        closed_loop: &[f64],
        psi: &[f64],
        fk_phi: &[f64],
        recompute_factors: bool,
    ) {
        wide_call!(
            self,
            time_update_body,
            time_update_avx2,
            time_update_avx512,
            (k, closed_loop, psi, fk_phi, recompute_factors)
        )
    }

    wide!(time_update_body, time_update_avx2, time_update_avx512,
        (k: u64, closed_loop: &[f64], psi: &[f64], fk_phi: &[f64], recompute_factors: bool));

    #[inline(always)]
    fn time_update_body(
        &mut self,
        k: u64,
        closed_loop: &[f64],
        psi: &[f64],
        fk_phi: &[f64],
        recompute_factors: bool,
    ) {
        if recompute_factors {
            self.compute_factors(k);
        }
        let (n, w) = (self.n, self.slots);
        for (j, kind) in self.kinds.iter().enumerate() {
            for i in 0..n {
                self.forcing[i + n * j] = forcing(*kind, psi[at(n, i, j)], fk_phi[at(n, i, j)]);
            }
            let factor = &self.output_factor[j * w..(j + 1) * w];
            let src = &self.gamma[n * j * w..n * (j + 1) * w];
            let dst = &mut self.gamma_next[n * j * w..n * (j + 1) * w];
            let g = &self.forcing[n * j..n * (j + 1)];
            if self.fused_madd {
                gamma_column_of::<true>(n, closed_loop, g, factor, src, dst);
            } else {
                gamma_column_of::<false>(n, closed_loop, g, factor, src, dst);
            }
        }
        std::mem::swap(&mut self.gamma, &mut self.gamma_next);
        self.lag.iter_mut().for_each(|l| *l += 1.0);
        self.announce(k, psi);
    }

    /// After the time update at k: Γ_{k+1}(k+1) = a(0)Ψ̃_k for the onset k + 1, which
    /// [`WindowBank::begin`] enters at the next step.
    #[inline(always)]
    fn announce(&mut self, k: u64, psi: &[f64]) {
        if self.known {
            return;
        }
        let n = self.n;
        for (j, kind) in self.kinds.iter().enumerate() {
            let factor = kind.entry_factor();
            for i in 0..n {
                self.entry[i + n * j] = factor * psi[at(n, i, j)];
            }
        }
        self.pending = Some(k + 1);
    }

    /// Enters the onset announced by the last time update (it replaces the oldest,
    /// k − w): Γ_k(k) = Ψ_{k−1}(k), C = 0, d = 0. Called at the start of each step.
    pub(crate) fn begin(&mut self, k: u64) {
        if self.pending != Some(k) {
            return;
        }
        self.pending = None;
        let (n, m, w) = (self.n, self.m, self.slots);
        let s = self.slot_of(k);
        self.onset[s] = k;
        self.active[s] = 1.0;
        self.lag[s] = 0.0;
        for c in 0..n * m {
            self.gamma[c * w + s] = self.entry[c];
        }
        for a in 0..m {
            self.score[a * w + s] = 0.0;
        }
        for t in 0..m * (m + 1) / 2 {
            self.info[t * w + s] = 0.0;
        }
    }

    /// Copies Γ(r) for onset r (n×m, column-major): Γ_{k+1}(r) after a step at k.
    pub(crate) fn gamma(&self, onset: u64, out: &mut [f64]) -> bool {
        let Some(s) = self.slot_for(onset) else {
            return false;
        };
        let (src, i) = self.stored(&self.gamma, &self.tables.gamma, s);
        for (c, o) in out.iter_mut().enumerate().take(self.n * self.m) {
            *o = src[c * self.slots + i];
        }
        true
    }

    /// Copies L_k⁻¹S_k(r) (p×m) of the last measured step; false when r is not in the
    /// window or the signatures are not kept ([`WindowBank::set_keep_signatures`]).
    pub(crate) fn whitened_signature(&self, onset: u64, out: &mut [f64]) -> bool {
        if !self.keep_signatures || self.signatures_stale {
            return false;
        }
        let Some(s) = self.slot_for(onset) else {
            return false;
        };
        let (src, i) = self.stored(&self.signature, &self.tables.signature, s);
        for (c, o) in out.iter_mut().enumerate().take(self.p * self.m) {
            *o = src[c * self.slots + i];
        }
        true
    }

    /// Copies C_k(r) (m×m, full symmetric, column-major) and d_k(r).
    pub(crate) fn information(&self, onset: u64, info: &mut [f64], score: &mut [f64]) -> bool {
        let Some(s) = self.slot_for(onset) else {
            return false;
        };
        let (m, w) = (self.m, self.slots);
        let (src, i) = self.stored(&self.info, &self.tables.info, s);
        for a in 0..m {
            for b in 0..=a {
                let c = src[tri(a, b) * w + i];
                info[at(m, a, b)] = c;
                info[at(m, b, a)] = c;
            }
            score[a] = self.score[a * w + s];
        }
        true
    }

    /// Rank of C_k(r) decided at the last [`WindowBank::maximize`].
    pub(crate) fn rank_of(&self, onset: u64) -> Option<usize> {
        self.slot_for(onset).map(|s| self.rank_at(s) as usize)
    }

    /// Statistic of onset r at the last [`WindowBank::maximize`].
    pub(crate) fn statistic_of(&self, onset: u64) -> Option<f64> {
        self.slot_for(onset).map(|s| self.stat[s])
    }

    /// The array holding a per-onset quantity of slot s and the index within a component:
    /// the ring itself, or the lag's entry of the stationary tables.
    fn stored<'a>(&self, ring: &'a [f64], table: &'a [f64], s: usize) -> (&'a [f64], usize) {
        if self.steady {
            (table, self.table_index(s))
        } else {
            (ring, s)
        }
    }

    /// Entry of the lag-reversed tables for slot s at the last measured step.
    fn table_index(&self, s: usize) -> usize {
        let lag = (self.current - self.onset[s]) as usize;
        self.slots - 1 - lag
    }

    /// The vector width of the window loops.
    pub(crate) fn level(&self) -> Level {
        self.level
    }

    /// Sets the vector width; the caller has checked that the processor supports it.
    pub(crate) fn set_level(&mut self, level: Level) {
        self.level = level;
        // The AVX levels' fused pass always rounds a·b + c once; their passes must too.
        self.fused_madd |= level != Level::Baseline;
    }

    /// Runs the passes at the baseline level with a·b + c rounded twice, as on a
    /// processor without FMA (for the test of that case).
    pub(crate) fn set_separate_rounding(&mut self) {
        self.level = Level::Baseline;
        self.fused_madd = false;
    }

    /// Keeps (or stops keeping) the signatures of every onset readable after each
    /// measured step, from the next one on.
    pub(crate) fn set_keep_signatures(&mut self, keep: bool) {
        self.signatures_stale |= keep && !self.keep_signatures;
        self.keep_signatures = keep;
    }

    /// Whether measured steps run the fused pass.
    pub(crate) fn fused(&self) -> bool {
        self.fused
    }

    /// Runs measured steps as the fused pass (where the dimensions have one) or as the
    /// three passes; the two give the same bits, so this only serves to compare them.
    pub(crate) fn set_fused(&mut self, enabled: bool) {
        self.fused = enabled && fused_dims(self.n, self.m, self.p);
    }

    /// Whether the stationary tables are in force.
    pub(crate) fn is_steady(&self) -> bool {
        self.steady
    }

    /// Tabulates the stationary regime after the time update at step k and switches to
    /// it (see the module docs). The arguments are the constant A (n×n), Ψ̃ (n×m),
    /// FKΦ̃ (n×m), L⁻¹H (p×n) and L⁻¹Φ̃ (p×m). Returns false, changing nothing, when the
    /// window is not yet full or the profile is known (C then grows without bound).
    pub(crate) fn enter_steady(
        &mut self,
        k: u64,
        closed_loop: &[f64],
        psi: &[f64],
        fk_phi: &[f64],
        h_white: &[f64],
        phi_white: &[f64],
    ) -> bool {
        let Some(first) = self.first else {
            return false;
        };
        if self.known || self.steady || k + 1 < first + self.slots as u64 || self.current != k {
            return false;
        }
        let (n, m, p, w) = (self.n, self.m, self.p, self.slots);
        let (tol, fused) = (self.tolerance, self.fused_madd);
        let tb = &mut self.tables;
        for (j, kind) in self.kinds.iter().enumerate() {
            let f = kind.entry_factor();
            for i in 0..n {
                tb.work_gamma[i + n * j] = f * psi[at(n, i, j)];
            }
        }
        for lag in 0..w {
            let idx = w - 1 - lag;
            // S(ℓ) = L⁻¹H Γ(ℓ) + b(ℓ) L⁻¹Φ̃ (eq. (45)), in the order of `accumulate`.
            for (j, kind) in self.kinds.iter().enumerate() {
                let of = kind.output_factor(lag as u64);
                for i in 0..p {
                    let mut v = phi_white[at(p, i, j)] * of;
                    for l in 0..n {
                        v = madd_as(fused, h_white[at(p, i, l)], tb.work_gamma[l + n * j], v);
                    }
                    tb.signature[(i + p * j) * w + idx] = v;
                }
            }
            // C(ℓ) = C(ℓ − 1) + S(ℓ)ᵀS(ℓ) (eq. (32)).
            for a in 0..m {
                for b in 0..=a {
                    let c = tri(a, b);
                    let mut v = if lag == 0 {
                        0.0
                    } else {
                        tb.info[c * w + idx + 1]
                    };
                    for i in 0..p {
                        v = madd_as(
                            fused,
                            tb.signature[(i + p * a) * w + idx],
                            tb.signature[(i + p * b) * w + idx],
                            v,
                        );
                    }
                    tb.info[c * w + idx] = v;
                }
            }
            // C(ℓ)⁻ = L⁻ᵀD⁺L⁻¹ from the dropped-pivot LDLᵀ of `statistic_generic`.
            let cut = (0..m)
                .map(|a| tb.info[tri(a, a) * w + idx])
                .fold(0.0_f64, larger)
                * tol;
            let mut rank = 0.0;
            for j in 0..m {
                let mut d = tb.info[tri(j, j) * w + idx];
                for q in 0..j {
                    let l = tb.work_ldl[at(m, j, q)];
                    d -= l * l * tb.work_ldl[at(m, q, q)];
                }
                tb.work_ldl[at(m, j, j)] = d;
                let keep = d > cut;
                tb.work_inv_pivot[j] = if keep { 1.0 / d } else { 0.0 };
                rank += if keep { 1.0 } else { 0.0 };
                for i in (j + 1)..m {
                    let mut x = tb.info[tri(i, j) * w + idx];
                    for q in 0..j {
                        x -= tb.work_ldl[at(m, i, q)]
                            * tb.work_ldl[at(m, j, q)]
                            * tb.work_ldl[at(m, q, q)];
                    }
                    tb.work_ldl[at(m, i, j)] = x * tb.work_inv_pivot[j];
                }
            }
            if m == 2 {
                // The pivot decisions of `quad2` (the rank of the general path).
                let info = |i| tb.info[i * w + idx];
                let (a, b, c) = (info(0), info(1), info(2));
                let (_, r) = quad2(a, b, c, 0.0, 0.0, tol);
                let cut = larger(a, c) * tol;
                let (keep_a, keep_c) = (a > cut, c > cut);
                (tb.work_inv_pivot[0], tb.work_inv_pivot[1]) = match (keep_a, r as usize) {
                    (true, 2) => (1.0 / a, a / (a * c - b * b)),
                    (true, _) => (1.0 / a, 0.0),
                    (false, _) if keep_c => (0.0, 1.0 / c),
                    _ => (0.0, 0.0),
                };
                rank = r;
            }
            tb.rank[idx] = rank;
            // L⁻¹ (unit lower triangular).
            for j in 0..m {
                for i in 0..m {
                    tb.work_linv[at(m, i, j)] = if i == j { 1.0 } else { 0.0 };
                }
                for i in (j + 1)..m {
                    let mut x = 0.0;
                    for q in j..i {
                        x -= tb.work_ldl[at(m, i, q)] * tb.work_linv[at(m, q, j)];
                    }
                    tb.work_linv[at(m, i, j)] = x;
                }
            }
            for a in 0..m {
                for b in 0..=a {
                    let mut g = 0.0;
                    for j in a..m {
                        g += tb.work_linv[at(m, j, a)]
                            * tb.work_inv_pivot[j]
                            * tb.work_linv[at(m, j, b)];
                    }
                    // Off the diagonal the table holds 2·C⁻_ab, the factor of d_a d_b in
                    // the quadratic form.
                    tb.inverse[tri(a, b) * w + idx] = if a == b { g } else { 2.0 * g };
                }
            }
            // Γ(ℓ + 1) = AΓ(ℓ) + b(ℓ)G (eq. (46), [`forcing`]), in the order of
            // `gamma_column`.
            for (j, kind) in self.kinds.iter().enumerate() {
                let b = kind.output_factor(lag as u64);
                for i in 0..n {
                    let g = forcing(*kind, psi[at(n, i, j)], fk_phi[at(n, i, j)]);
                    let mut v = g * b;
                    for l in 0..n {
                        v = madd_as(fused, closed_loop[at(n, i, l)], tb.work_gamma[l + n * j], v);
                    }
                    tb.work_next[i + n * j] = v;
                    tb.gamma[(i + n * j) * w + idx] = v;
                }
            }
            std::mem::swap(&mut tb.work_gamma, &mut tb.work_next);
        }
        self.steady = true;
        true
    }

    /// Measurement step k in the stationary regime: d_k(r) += S(ℓ)ᵀL⁻¹ε_k (eq. (33))
    /// and the statistic d_k(r)ᵀC(ℓ)⁻d_k(r) for every slot, two contiguous runs of the
    /// ring against two contiguous runs of the tables.
    pub(crate) fn accumulate_steady(&mut self, k: u64, eps_white: &[f64]) {
        self.signatures_stale = false;
        wide_call!(self, steady_4, steady_avx2, steady_avx512, (k, eps_white))
    }

    wide!(steady_4, steady_avx2, steady_8 => steady_avx512, (k: u64, eps_white: &[f64]));

    #[inline(always)]
    fn steady_4(&mut self, k: u64, eps_white: &[f64]) {
        if self.fused_madd {
            self.accumulate_steady_body::<4, true>(k, eps_white);
        } else {
            self.accumulate_steady_body::<4, false>(k, eps_white);
        }
    }

    #[inline(always)]
    fn steady_8(&mut self, k: u64, eps_white: &[f64]) {
        self.accumulate_steady_body::<8, true>(k, eps_white);
    }

    /// [`WindowBank::accumulate_steady`] with L onsets per step of the fused loop, a·b + c
    /// rounded once if FUSED ([`madd`]).
    #[inline(always)]
    fn accumulate_steady_body<const L: usize, const FUSED: bool>(
        &mut self,
        k: u64,
        eps_white: &[f64],
    ) {
        self.current = k;
        let (m, p, w) = (self.m, self.p, self.slots);
        let base = self.slot_of(k);
        for (start, len, idx) in [(0, base + 1, w - 1 - base), (base + 1, w - 1 - base, 0)] {
            if len == 0 {
                continue;
            }
            let run = SteadyRun { w, start, idx, len };
            let (score, stat) = (&mut self.score[..], &mut self.stat[..]);
            let (sig, inv) = (&self.tables.signature[..], &self.tables.inverse[..]);
            macro_rules! fused {
                ($(($mm:literal, $pp:literal)),*) => {
                    match (m, p) {
                        $(($mm, $pp) => steady_fused::<$mm, $pp, L, FUSED>(
                            run, score, stat, sig, inv, eps_white[..$pp].try_into().unwrap_or(&[0.0; $pp]),
                        ),)*
                        _ => steady_passes::<FUSED>(run, m, p, score, stat, sig, inv, eps_white),
                    }
                };
            }
            fused!(
                (1, 1),
                (1, 2),
                (1, 3),
                (1, 4),
                (2, 1),
                (2, 2),
                (2, 3),
                (2, 4),
                (3, 1),
                (3, 2),
                (3, 3),
                (3, 4),
                (4, 1),
                (4, 2),
                (4, 3),
                (4, 4)
            );
        }
    }

    /// Time update k → k + 1 in the stationary regime: Γ lives in the tables, so only
    /// the next onset is announced.
    pub(crate) fn advance_steady(&mut self, k: u64) {
        self.pending = Some(k + 1);
    }

    /// Leaves the stationary regime between steps: Γ, C, S and the rank of every onset are
    /// written back from the tables (d was kept in the ring), and the general
    /// recursion goes on from there.
    pub(crate) fn leave_steady(&mut self) {
        if !self.steady {
            return;
        }
        let (n, m, p, w) = (self.n, self.m, self.p, self.slots);
        let t = m * (m + 1) / 2;
        for s in 0..w {
            if self.active[s] == 0.0 || self.onset[s] > self.current {
                continue;
            }
            let idx = self.table_index(s);
            for c in 0..n * m {
                self.gamma[c * w + s] = self.tables.gamma[c * w + idx];
            }
            for c in 0..t {
                self.info[c * w + s] = self.tables.info[c * w + idx];
            }
            for c in 0..p * m {
                self.signature[c * w + s] = self.tables.signature[c * w + idx];
            }
            self.rank[s] = self.tables.rank[idx];
            self.lag[s] = (self.current + 1 - self.onset[s]) as f64;
        }
        self.steady = false;
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

/// A contiguous run of slots [start, start + len) of the ring against the table entries
/// [idx, idx + len), components w apart.
#[derive(Debug, Clone, Copy)]
struct SteadyRun {
    w: usize,
    start: usize,
    idx: usize,
    len: usize,
}

/// The stationary measurement step over a run, m = M and p = P known at compile time:
/// one pass, L slots at a time (loaded into registers, so the lanes vectorise), then
/// the remainder one slot at a time with the same operations.
#[inline(always)]
fn steady_fused<const M: usize, const P: usize, const L: usize, const FUSED: bool>(
    run: SteadyRun,
    score: &mut [f64],
    stat: &mut [f64],
    signature: &[f64],
    inverse: &[f64],
    eps: &[f64; P],
) {
    // Checked once here so that the lanes load and store unchecked: every component
    // of the run's slots and table entries is inside its array.
    let w = run.w;
    assert!(
        run.start <= w
            && run.len <= w - run.start
            && run.idx <= w - run.len
            && score.len() >= M * w
            && stat.len() >= w
            && signature.len() >= P * M * w
            && inverse.len() >= M * (M + 1) / 2 * w,
        "stationary run inside the window arrays"
    );
    let mut s = 0;
    while s + L <= run.len {
        // SAFETY: checked above, s + L ≤ len.
        unsafe { steady_lanes::<M, P, L, FUSED>(run, s, score, stat, signature, inverse, eps) };
        s += L;
    }
    while s < run.len {
        // SAFETY: checked above, s + 1 ≤ len.
        unsafe { steady_lanes::<M, P, 1, FUSED>(run, s, score, stat, signature, inverse, eps) };
        s += 1;
    }
}

/// L slots from offset s of the run: d += S(ℓ)ᵀL⁻¹ε (eq. (33)), then dᵀC(ℓ)⁻d.
///
/// # Safety
/// The run lies inside the arrays (as `steady_fused` checks) and s + L ≤ run.len.
#[inline(always)]
unsafe fn steady_lanes<const M: usize, const P: usize, const L: usize, const FUSED: bool>(
    run: SteadyRun,
    s: usize,
    score: &mut [f64],
    stat: &mut [f64],
    signature: &[f64],
    inverse: &[f64],
    eps: &[f64; P],
) {
    let (w, at_slot, at_table) = (run.w, run.start + s, run.idx + s);
    // SAFETY (every access): the caller's contract; indices are (component)·w + an
    // offset of the run, below the array's size.
    let load = |x: &[f64], at: usize| -> [f64; L] {
        unsafe { std::ptr::read_unaligned(x.as_ptr().add(at).cast::<[f64; L]>()) }
    };
    let mut d = [[0.0; L]; M];
    for (a, da) in d.iter_mut().enumerate() {
        *da = load(score, a * w + at_slot);
        for (i, e) in eps.iter().enumerate() {
            let x = load(signature, (i + P * a) * w + at_table);
            for l in 0..L {
                da[l] = madd::<FUSED>(x[l], *e, da[l]);
            }
        }
        unsafe {
            std::ptr::write_unaligned(
                score.as_mut_ptr().add(a * w + at_slot).cast::<[f64; L]>(),
                *da,
            );
        }
    }
    // dᵀC⁻d = Σ_a d_a Σ_{b≤a} G_ab d_b with G_ab = 2·C⁻_ab off the diagonal.
    let mut st = [0.0; L];
    for a in 0..M {
        let mut t = [0.0; L];
        for (b, db) in d.iter().enumerate().take(a + 1) {
            let g = load(inverse, tri(a, b) * w + at_table);
            for l in 0..L {
                t[l] = madd::<FUSED>(g[l], db[l], t[l]);
            }
        }
        for l in 0..L {
            st[l] = madd::<FUSED>(d[a][l], t[l], st[l]);
        }
    }
    unsafe { std::ptr::write_unaligned(stat.as_mut_ptr().add(at_slot).cast::<[f64; L]>(), st) };
}

/// The stationary measurement step over a run for any m, p: one pass per component.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn steady_passes<const FUSED: bool>(
    run: SteadyRun,
    m: usize,
    p: usize,
    score: &mut [f64],
    stat: &mut [f64],
    signature: &[f64],
    inverse: &[f64],
    eps: &[f64],
) {
    let SteadyRun { w, start, idx, len } = run;
    for a in 0..m {
        let d = &mut score[a * w + start..a * w + start + len];
        for (i, e) in eps.iter().enumerate().take(p) {
            let c = (i + p * a) * w + idx;
            for (d, x) in d.iter_mut().zip(&signature[c..c + len]) {
                *d = madd::<FUSED>(*x, *e, *d);
            }
        }
    }
    let stat = &mut stat[start..start + len];
    stat.fill(0.0);
    for s in 0..len {
        let mut st = 0.0;
        for a in 0..m {
            let mut t = 0.0;
            for b in 0..=a {
                t = madd::<FUSED>(
                    inverse[tri(a, b) * w + idx + s],
                    score[b * w + start + s],
                    t,
                );
            }
            st = madd::<FUSED>(score[a * w + start + s], t, st);
        }
        stat[s] = st;
    }
}

/// Column j of eq. (46) for every slot, n known at compile time: one fused pass.
/// `src`/`dst` hold the n rows of Γ(:, j) as n consecutive arrays over the slots.
#[inline(always)]
fn gamma_column<const N: usize, const FUSED: bool>(
    a: &[f64],
    forcing: &[f64],
    factor: &[f64],
    src: &[f64],
    dst: &mut [f64],
) {
    let w = factor.len();
    let rows: [&[f64]; N] = std::array::from_fn(|l| &src[l * w..(l + 1) * w]);
    let mut coef = [[0.0; N]; N];
    for (i, row) in coef.iter_mut().enumerate() {
        for (l, c) in row.iter_mut().enumerate() {
            *c = a[at(N, i, l)];
        }
    }
    for (i, out) in dst.chunks_exact_mut(w).take(N).enumerate() {
        let (g, ci) = (forcing[i], coef[i]);
        for s in 0..w {
            let mut v = g * factor[s];
            for l in 0..N {
                v = madd::<FUSED>(ci[l], rows[l][s], v);
            }
            out[s] = v;
        }
    }
}

/// Column j of eq. (46): [`gamma_column`] for n ≤ 4, [`gamma_column_generic`] beyond.
#[inline(always)]
fn gamma_column_of<const FUSED: bool>(
    n: usize,
    a: &[f64],
    forcing: &[f64],
    factor: &[f64],
    src: &[f64],
    dst: &mut [f64],
) {
    match n {
        1 => gamma_column::<1, FUSED>(a, forcing, factor, src, dst),
        2 => gamma_column::<2, FUSED>(a, forcing, factor, src, dst),
        3 => gamma_column::<3, FUSED>(a, forcing, factor, src, dst),
        4 => gamma_column::<4, FUSED>(a, forcing, factor, src, dst),
        _ => gamma_column_generic::<FUSED>(n, a, forcing, factor, src, dst),
    }
}

/// Column j of eq. (46) for any n, in the same operation order as [`gamma_column`].
#[inline(always)]
fn gamma_column_generic<const FUSED: bool>(
    n: usize,
    a: &[f64],
    forcing: &[f64],
    factor: &[f64],
    src: &[f64],
    dst: &mut [f64],
) {
    let w = factor.len();
    for (i, out) in dst.chunks_exact_mut(w).take(n).enumerate() {
        let g = forcing[i];
        for (d, f) in out.iter_mut().zip(factor) {
            *d = g * f;
        }
        for l in 0..n {
            let c = a[at(n, i, l)];
            for (d, x) in out.iter_mut().zip(&src[l * w..(l + 1) * w]) {
                *d = madd::<FUSED>(c, *x, *d);
            }
        }
    }
}

/// c + a·b as the window's recursions take it: rounded once (`f64::mul_add`), or twice
/// on an x86-64 processor without AVX2 and FMA (crate::simd).
#[inline(always)]
fn madd<const FUSED: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FUSED { a.mul_add(b, c) } else { a * b + c }
}

/// [`madd`] with the rounding chosen at run time (off the per-sample path).
#[inline(always)]
fn madd_as(fused: bool, a: f64, b: f64, c: f64) -> f64 {
    if fused {
        madd::<true>(a, b, c)
    } else {
        madd::<false>(a, b, c)
    }
}

/// Entry i of fault j's forcing column G in eq. (46), a(ℓ)Ψ̃ − b(ℓ)FKΦ̃ = b(ℓ)·G: the
/// state and output factors are equal for the step, ramp and known profiles (G = Ψ̃ −
/// FKΦ̃), and the state factor is 0 for an impulse (G = −FKΦ̃).
#[inline(always)]
fn forcing(kind: Onset, psi: f64, fk_phi: f64) -> f64 {
    if kind == Onset::Impulse {
        -fk_phi
    } else {
        psi - fk_phi
    }
}

/// The rank cut-off τ·max_a C_aa of the dropped-pivot LDLᵀ, in the operation order of
/// the statistic passes ([`WindowBank::statistic_m2`] for m = 2, else
/// [`WindowBank::statistic_generic`]; the m = 1 pass compares C > τ·C, which decides
/// the same for every C).
#[inline(always)]
fn pivot_cutoff(m: usize, diag: impl Fn(usize) -> f64, tol: f64) -> f64 {
    if m == 2 {
        larger(diag(0), diag(1)) * tol
    } else {
        (0..m).fold(0.0_f64, |c, a| larger(c, diag(a))) * tol
    }
}

/// y if y > x, else x: the larger of two, as the rank cut-offs take it in every path
/// (and `maxpd` computes it). A NaN y is passed over, so a maximum folded from 0 over
/// C's diagonal ignores NaN entries as `f64::max` would; max(C₁₁, C₂₂) for m = 2 is NaN
/// when C₁₁ is, and then no pivot is kept.
#[inline(always)]
fn larger(x: f64, y: f64) -> f64 {
    if y > x { y } else { x }
}

/// The coefficients of measured step k for the fused pass, with n = N, m = M, p = P
/// known at compile time, copied out of the column-major matrices once per step.
#[derive(Debug, Clone, Copy)]
struct Coefs<const N: usize, const M: usize, const P: usize> {
    /// (L⁻¹H)_il at [i][l].
    h: [[f64; N]; P],
    /// (L⁻¹Φ̃)_ij at [i][j].
    phi: [[f64; M]; P],
    /// L⁻¹ε.
    eps: [f64; P],
    /// A_il at [i][l].
    a: [[f64; N]; N],
    /// The forcing column G_ij of eq. (46) ([`forcing`]) at [j][i].
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

/// One vector register of onsets for the fused pass: the f64 operations it needs, each
/// lane rounded as the scalar operation (`mul_add` as `f64::mul_add`), so every width
/// gives the same bits.
trait Lanes: Copy {
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
    /// self + a·b rounded once (`f64::mul_add` per lane): what the passes compute.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// self > o (false for NaN).
    fn gt(self, o: Self) -> Self::Mask;
    /// m ? a : b per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;

    /// [`larger`] per lane: one compare and one blend (or one `maxpd`), where
    /// `f64::max`'s NaN rule costs two compares more.
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Self::select(o.gt(self), o, self)
    }
}

/// One onset: the passes' per-slot loops share the fused pass's kernels ([`quad2`]) and
/// with them its operations.
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
        a.mul_add(b, self)
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
struct Lanes8([f64; 8]);

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
            r[l] = a.0[l].mul_add(b.0[l], self.0[l]);
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
                $ty(unsafe { arch::$fmadd(a.0, b.0, self.0) })
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
struct Avx2Lanes(arch::__m256d);

#[cfg(target_arch = "x86_64")]
x86_lanes!(Avx2Lanes, arch::__m256d, 4, _mm256_set1_pd, _mm256_loadu_pd, _mm256_storeu_pd,
    _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd, _mm256_fmadd_pd,
    gt: |a, b| arch::_mm256_cmp_pd::<{ arch::_CMP_GT_OQ }>(a, b),
    select: |m, a, b| arch::_mm256_blendv_pd(b, a, m));

/// Slots s0 … s0 + L − 1 of measured step k in registers: the profile factors
/// (`compute_factors`), L⁻¹S = (L⁻¹H)Γ + b·L⁻¹Φ̃ (eq. (45)), C += SᵀS and d += SᵀL⁻¹ε
/// (eqs. (32)-(33)), the dropped-pivot LDLᵀ statistic dᵀC⁻d and rank (eq. (35); for
/// m ≥ 3 in a loop of its own, [`split_statistic`]), and Γ ← AΓ + b·G (eq. (46),
/// [`forcing`]); each onset gets the operations of the passes in their order, so the
/// results are the same bits. L⁻¹S stays in registers unless the signatures are kept
/// (`Detector::keep_signatures`).
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
                x = x.mul_add(sig[a][i], sig[b][i]);
            }
            st!(x, v.info, at);
            info[a][b] = x;
        }
        let mut x = ld!(v.score, a * w + s0);
        for i in 0..P {
            x = x.mul_add(sig[a][i], S::splat(c.eps[i]));
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
        x = x.mul_add(S::splat(row[q]), col[q]);
    }
    x
}

/// The dropped-pivot LDLᵀ statistic dᵀC⁻d and rank C of L onsets (eq. (35)), with the
/// operations of [`WindowBank::statistic_generic`].
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn ldl_statistic<const M: usize, S: Lanes>(info: &[[S; M]; M], score: &[S; M], tol: S) -> (S, S) {
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let cut = {
        let mut x = zero;
        for (a, row) in info.iter().enumerate() {
            x = x.max(row[a]);
        }
        x.mul(tol)
    };
    let mut dd = [zero; M];
    let mut inv = [zero; M];
    let mut low = [[zero; M]; M];
    let mut rank = zero;
    // Loops of constant length with the triangle as conditions, so that the compiler
    // unrolls them completely and keeps every entry in a register.
    for j in 0..M {
        let mut d = info[j][j];
        for q in 0..M {
            if q < j {
                d = d.sub(low[j][q].mul(low[j][q]).mul(dd[q]));
            }
        }
        dd[j] = d;
        let keep = d.gt(cut);
        inv[j] = S::select(keep, one.div(d), zero);
        rank = rank.add(S::select(keep, one, zero));
        for i in 0..M {
            if i > j {
                let mut x = info[i][j];
                for q in 0..M {
                    if q < j {
                        x = x.sub(low[i][q].mul(low[j][q]).mul(dd[q]));
                    }
                }
                low[i][j] = x.mul(inv[j]);
            }
        }
    }
    // z = L⁻¹d, statistic Σ_j z_j²/D_j over kept pivots.
    let mut z = [zero; M];
    let mut stat = zero;
    for j in 0..M {
        let mut x = score[j];
        for q in 0..M {
            if q < j {
                x = x.sub(low[j][q].mul(z[q]));
            }
        }
        z[j] = x;
        stat = stat.add(x.mul(x).mul(inv[j]));
    }
    (stat, rank)
}

/// dᵀC⁺d and rank C for m = 2, C = [[a, b], [b, c]], with one division: the
/// dropped-pivot LDLᵀ of [`WindowBank::statistic_generic`] (eq. (35)) with its two
/// pivots a and δ/a, δ = ac − b², kept when above the cut-off τ·max(a, c), written over
/// one denominator: with z = a·d₂ − b·d₁,
///
///   d₁²/a + (d₂ − (b/a)d₁)²/(δ/a) = (d₁²δ + z²) / (aδ)   (both pivots kept),
///
/// d₁²/a when only the first is kept, and d₂²/c when the first is dropped (then the
/// second pivot is c itself). A sum of two non-negative terms over a positive
/// denominator: no cancellation beyond δ's own, which the LDLᵀ shares. The
/// comparisons test δ against τ·max(a, c)·a instead of δ/a against the cut-off, so no
/// division decides a rank. One division instead of the LDLᵀ's two: division is the
/// slowest operation of the window pass (issue 9).
#[inline(always)]
fn quad2<S: Lanes>(a: S, b: S, c: S, d1: S, d2: S, tol: S) -> (S, S) {
    let zero = S::splat(0.0);
    let one = S::splat(1.0);
    let cut = a.max(c).mul(tol);
    let keep_a = a.gt(cut);
    let keep_c = c.gt(cut);
    let det = a.mul(c).sub(b.mul(b));
    let keep_det = det.gt(cut.mul(a));
    let z = a.mul(d2).sub(b.mul(d1));
    let d1s = d1.mul(d1);
    let (full_num, full_den) = (d1s.mul(det).add(z.mul(z)), a.mul(det));
    let num_a = S::select(keep_det, full_num, d1s);
    let den_a = S::select(keep_det, full_den, a);
    let num = S::select(keep_a, num_a, S::select(keep_c, d2.mul(d2), zero));
    let den = S::select(keep_a, den_a, S::select(keep_c, c, one));
    let second = S::select(
        keep_a,
        S::select(keep_det, one, zero),
        S::select(keep_c, one, zero),
    );
    let rank = S::select(keep_a, one, zero).add(second);
    (num.div(den), rank)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bank with random C, d in every slot (PSD, some slots rank-deficient).
    fn bank_with_random_stats(m: usize, seed: u64) -> WindowBank {
        let w = 37;
        let mut b = WindowBank::new(1, m, 1, w, 0, vec![Onset::Step; m], DEFAULT_RANK_TOLERANCE);
        let mut x = seed;
        let mut rnd = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for s in 0..w {
            let rank = s % (m + 1);
            let vecs: Vec<Vec<f64>> = (0..rank).map(|_| (0..m).map(|_| rnd()).collect()).collect();
            for a in 0..m {
                for c in 0..=a {
                    b.info[tri(a, c) * w + s] = vecs.iter().map(|v| v[a] * v[c]).sum();
                }
                // d in range(C): d = C z.
            }
            let z: Vec<f64> = (0..m).map(|_| rnd()).collect();
            for a in 0..m {
                b.score[a * w + s] = (0..m)
                    .map(|c| {
                        let (hi, lo) = if a >= c { (a, c) } else { (c, a) };
                        b.info[tri(hi, lo) * w + s] * z[c]
                    })
                    .sum();
            }
        }
        b
    }

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

    /// θ̂ of a regular C from the LDLᵀ in registers (`solve_regular`) is the θ̂ of the
    /// slot's stored factorisation (`solve_factored`) bit for bit.
    #[test]
    fn regular_magnitude_in_registers_equals_the_stored_factorisation_bit_for_bit() {
        for m in [1, 3, 4] {
            let mut compared = 0;
            for seed in 1..5 {
                let mut bank = bank_with_random_stats(m, seed);
                bank.statistic_generic();
                bank.factored = true;
                for s in 0..bank.slots {
                    if bank.rank[s] as usize != m {
                        continue;
                    }
                    let (mut fast, mut slow) = (vec![0.0; m], vec![0.0; m]);
                    match m {
                        1 => bank.solve_regular::<1>(s, &mut fast),
                        3 => bank.solve_regular::<3>(s, &mut fast),
                        _ => bank.solve_regular::<4>(s, &mut fast),
                    }
                    bank.solve_factored(s, &mut slow);
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&fast), bits(&slow), "m = {m}, slot {s}");
                    assert!(fast.iter().any(|x| *x != 0.0));
                    compared += 1;
                }
            }
            assert!(compared >= 10, "m = {m}: only {compared} regular slots");
        }
    }

    #[test]
    fn m1_statistic_equals_generic_ldl_bit_for_bit() {
        let mut fast = bank_with_random_stats(1, 3);
        let mut slow = fast.clone();
        fast.statistic_m1();
        slow.statistic_generic();
        assert_eq!(fast.stat, slow.stat);
        assert_eq!(fast.rank, slow.rank);
    }

    /// The one-division 2×2 form (`quad2`) is the dropped-pivot LDLᵀ statistic written
    /// over one denominator: the same ranks and the same value to rounding, over
    /// regular, rank-one and zero C.
    #[test]
    fn m2_one_division_form_equals_generic_ldl() {
        for seed in 1..40 {
            let mut fast = bank_with_random_stats(2, seed);
            let mut slow = fast.clone();
            fast.statistic_m2();
            slow.statistic_generic();
            assert_eq!(fast.rank, slow.rank, "seed {seed}");
            for (s, (f, g)) in fast.stat.iter().zip(&slow.stat).enumerate() {
                assert!(
                    (f - g).abs() <= 1e-12 * (1.0 + g.abs()),
                    "seed {seed}, slot {s}: {f} vs {g}"
                );
            }
        }
    }

    /// The dropped-pivot LDLᵀ statistic equals dᵀC⁺d from the eigendecomposition for
    /// rank-deficient C with d ∈ range(C) (the generalised-inverse argument in the
    /// module docs).
    #[test]
    fn dropped_pivot_ldl_equals_moore_penrose_quadratic_form() {
        for m in [2, 3, 5] {
            let mut b = bank_with_random_stats(m, 11);
            if m == 2 {
                b.statistic_m2();
            } else {
                b.statistic_generic();
            }
            let w = b.slots;
            for s in 0..w {
                let mut a = vec![0.0; m * m];
                for i in 0..m {
                    for j in 0..=i {
                        a[at(m, i, j)] = b.info[tri(i, j) * w + s];
                        a[at(m, j, i)] = b.info[tri(i, j) * w + s];
                    }
                }
                let (mut vals, mut vecs) = (vec![0.0; m], vec![0.0; m * m]);
                jacobi_eigen(&mut a, m, &mut vals, &mut vecs);
                let lmax = vals.iter().fold(0.0_f64, |x, y| x.max(*y));
                let mut q = 0.0;
                let mut rank = 0;
                for e in 0..m {
                    if vals[e] > 1e-9 * lmax && vals[e] > 0.0 {
                        let proj: f64 = (0..m).map(|i| vecs[e * m + i] * b.score[i * w + s]).sum();
                        q += proj * proj / vals[e];
                        rank += 1;
                    }
                }
                assert_eq!(b.rank[s] as usize, rank, "m = {m}, slot {s}");
                assert!(
                    (b.stat[s] - q).abs() <= 1e-9 * (1.0 + q),
                    "m = {m}, slot {s}: {} vs {q}",
                    b.stat[s]
                );
            }
        }
    }
}
