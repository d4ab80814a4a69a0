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
//! of C in which pivots D_j ≤ τ·C_jj are dropped (τ = the rank tolerance): D_j/C_jj =
//! 1 − R_j², R_j the multiple correlation of fault j's signature with the faults kept
//! before it, so the decision does not depend on the units of the faults (see
//! [`statistic`]). For a positive semi-definite C an exactly zero pivot comes with an
//! exactly zero column of the Schur complement, so the dropped-pivot factorisation is a
//! generalised inverse C⁻ (C C⁻ C = C); since d ∈ range(C), dᵀC⁻d = dᵀC⁺d is exactly
//! 2 ln LR and is χ² with dof = rank C = the number of kept pivots. The magnitude θ̂
//! at r̂ uses, when C is deficient, the pseudo-inverse of the equilibrated C
//! (D^{-1/2}CD^{-1/2}, D = diag C, eigenvalues ≤ τ·λ_max of it dropped), so that θ̂
//! follows a change of units too.
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
//!
//! # Files
//! [`mod@reference`] holds the passes, the general recursion one component at a time over
//! the slots, which every faster path must equal bit for bit: the fused single pass of
//! small dimensions ([`fused`], on the registers of [`lanes`]) and the stationary
//! tables ([`steady`]). The statistic of eq. (35) and its rank are written once for all
//! paths ([`statistic`]), as is the maximum of eq. (36) ([`argmax`]); [`magnitude`]
//! computes θ̂ (eq. (34)) at r̂.

use crate::linalg::at;
use crate::model::fault::Onset;
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
            // feature (`VectorLevel::detect`, or `GlrDetector::set_vector_level`, which
            // checks `VectorLevel::supported`).
            #[cfg(target_arch = "x86_64")]
            crate::simd::VectorLevel::Avx2 => unsafe { $this.$avx2($($a),*) },
            #[cfg(target_arch = "x86_64")]
            crate::simd::VectorLevel::Avx512 => unsafe { $this.$avx512($($a),*) },
            _ => $this.$body($($a),*),
        }
    };
}

mod argmax;
mod followed;
mod fused;
mod lanes;
mod magnitude;
mod reference;
mod statistic;
mod steady;

pub use followed::FollowedEvidence;
pub(crate) use followed::FollowedOnset;
use fused::fused_dims;
use steady::LagTables;

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
    /// Onset k + 1 announced by the last time update, entered at the next step so that
    /// the oldest onset's statistics stay readable between steps.
    pending: Option<u64>,
    /// Γ_{k+1}(k+1) = Ψ_k(k+1) for the pending onset (n×m).
    entry: Vec<f64>,
    // Eigen scratch for θ̂ when C(r̂) is deficient: the equilibrated C, its spectrum,
    // and D^{-1/2} (D = diag C).
    eig_a: Vec<f64>,
    eig_vals: Vec<f64>,
    eig_vecs: Vec<f64>,
    eig_scale: Vec<f64>,
    /// Sample index of the last measured step (the k of `lag = k − r` in the tables).
    current: u64,
    /// Whether the stationary tables are in force.
    steady: bool,
    tables: LagTables,
    /// Vector width of the window loops (same bits at every width).
    level: Level,
    /// Whether the passes round a·b + c once ([`lanes::mul_add`], crate::simd): always
    /// at the AVX levels, whose fused pass does.
    fused_mul_add: bool,
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
    /// `GlrDetector::keep_signatures`.
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
            pending: None,
            entry: z(n * m),
            eig_a: z(m * m),
            eig_vals: z(m),
            eig_vecs: z(m * m),
            eig_scale: z(m),
            current: 0,
            steady: false,
            level: Level::detect(),
            fused_mul_add: crate::simd::fused_multiply_add(),
            fused: fused_dims(n, m, p),
            factored: false,
            keep_signatures: false,
            signatures_stale: false,
            tables: LagTables::new(n, m, p, slots),
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

    /// Measured step k of the whole window (eqs. (45), (32)-(36), (46)): the signatures,
    /// C and d, the statistic and rank of every onset, the maximum, and the time update
    /// of Γ to k + 1 with the onset k + 1 announced. For the fused dimensions at the
    /// AVX2 and AVX-512F levels one pass over the slots does it all, four or eight
    /// onsets at a time in registers ([`fused`]): no intermediate arrays, and C,
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

    /// Forgets every onset up to the last measured step: only the onset announced by
    /// the last time update (k + 1) enters the window next, as if the bank had started
    /// there, while the filter behind it goes on. For the end of a settling period after
    /// a restart, whose innovations carry the initial-state transient. False for the
    /// known-onset bank, whose single onset is the run's start.
    pub(crate) fn forget(&mut self) -> bool {
        let Some(next) = self.pending.filter(|_| !self.known) else {
            return false;
        };
        self.leave_steady();
        self.active.fill(0.0);
        self.first = Some(next);
        true
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
        self.fused_mul_add |= level != Level::Baseline;
    }

    /// Runs the passes at the baseline level with a·b + c rounded twice, as on a
    /// processor without FMA (for the test of that case).
    pub(crate) fn set_separate_rounding(&mut self) {
        self.level = Level::Baseline;
        self.fused_mul_add = false;
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

/// A bank with random C, d in every slot (PSD, some slots rank-deficient), for the
/// tests of the statistic and of θ̂.
#[cfg(test)]
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
