//! The LTI stationary tables (fast path): must equal the general recursion at every lag.

use super::lanes::{mul_add, mul_add_as};
use super::statistic::{quad2, quad2_pivots};
use super::{WindowBank, WindowMax, forcing, tri};
use crate::linalg::at;

/// Per-lag tables of the stationary regime, lag-reversed: the entry for lag ℓ of
/// component c is at [c·w + (w − 1 − ℓ)], so that the slots of the ring, taken in
/// increasing order from the newest onset's slot, meet the table in increasing order.
/// Allocated with the bank, so entering the regime allocates nothing.
#[derive(Debug, Clone)]
pub(super) struct LagTables {
    /// L⁻¹S(ℓ) (p×m components).
    pub(super) signature: Vec<f64>,
    /// C(ℓ), packed lower triangle.
    pub(super) info: Vec<f64>,
    /// C(ℓ)⁻, the dropped-pivot generalised inverse, packed lower triangle, with the
    /// off-diagonal entries doubled (the coefficients of the quadratic form dᵀC⁻d).
    pub(super) inverse: Vec<f64>,
    /// rank C(ℓ).
    pub(super) rank: Vec<f64>,
    /// Γ(ℓ + 1) = Γ_{r+ℓ+1}(r), the value after the time update at lag ℓ (n×m).
    pub(super) gamma: Vec<f64>,
    /// Scratch for the construction: Γ(ℓ), C(ℓ), the m×m LDLᵀ.
    work_gamma: Vec<f64>,
    work_next: Vec<f64>,
    work_ldl: Vec<f64>,
    work_inv_pivot: Vec<f64>,
    work_linv: Vec<f64>,
}

impl LagTables {
    /// Zeroed tables for n states, m faults, p outputs and w slots.
    pub(super) fn new(n: usize, m: usize, p: usize, w: usize) -> Self {
        let t = m * (m + 1) / 2;
        let z = |len: usize| vec![0.0; len];
        Self {
            signature: z(p * m * w),
            info: z(t * w),
            inverse: z(t * w),
            rank: z(w),
            gamma: z(n * m * w),
            work_gamma: z(n * m),
            work_next: z(n * m),
            work_ldl: z(m * m),
            work_inv_pivot: z(m),
            work_linv: z(m * m),
        }
    }
}

impl WindowBank {
    /// The maximum over admissible onsets after [`WindowBank::accumulate_steady`].
    pub(crate) fn maximize_steady(&mut self, k: u64) -> Option<WindowMax> {
        wide_call!(self, best_body, best_avx2, best_avx512, (k))
    }

    wide!(best_body, best_avx2, best_avx512, (k: u64) -> Option<WindowMax>);

    #[inline(always)]
    fn best_body(&mut self, k: u64) -> Option<WindowMax> {
        self.best(k)
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
        let (tol, fused) = (self.tolerance, self.fused_mul_add);
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
                        v = mul_add_as(fused, h_white[at(p, i, l)], tb.work_gamma[l + n * j], v);
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
                        v = mul_add_as(
                            fused,
                            tb.signature[(i + p * a) * w + idx],
                            tb.signature[(i + p * b) * w + idx],
                            v,
                        );
                    }
                    tb.info[c * w + idx] = v;
                }
            }
            // C(ℓ)⁻ = L⁻ᵀD⁺L⁻¹ from the dropped-pivot LDLᵀ of `statistic_generic`, with
            // its scale-free rule D_j > τ·C_jj.
            let mut rank = 0.0;
            for j in 0..m {
                let mut d = tb.info[tri(j, j) * w + idx];
                for q in 0..j {
                    let l = tb.work_ldl[at(m, j, q)];
                    d -= l * l * tb.work_ldl[at(m, q, q)];
                }
                tb.work_ldl[at(m, j, j)] = d;
                let keep = d > tb.info[tri(j, j) * w + idx] * tol;
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
                let (keep_a, keep_c) = quad2_pivots(a, c, tol);
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
                        v = mul_add_as(
                            fused,
                            closed_loop[at(n, i, l)],
                            tb.work_gamma[l + n * j],
                            v,
                        );
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
        if self.fused_mul_add {
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
    /// rounded once if FUSED ([`mul_add`]).
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
                da[l] = mul_add::<FUSED>(x[l], *e, da[l]);
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
                t[l] = mul_add::<FUSED>(g[l], db[l], t[l]);
            }
        }
        for l in 0..L {
            st[l] = mul_add::<FUSED>(d[a][l], t[l], st[l]);
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
                *d = mul_add::<FUSED>(*x, *e, *d);
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
                t = mul_add::<FUSED>(
                    inverse[tri(a, b) * w + idx + s],
                    score[b * w + start + s],
                    t,
                );
            }
            st = mul_add::<FUSED>(score[a * w + start + s], t, st);
        }
        stat[s] = st;
    }
}
