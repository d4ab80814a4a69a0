//! The passes of eqs. (45), (32)-(35), (46): the reference every fast path must equal.

use super::lanes::mul_add;
use super::statistic::quad2;
use super::{WindowBank, WindowMax, forcing, tri};
use crate::linalg::at;
use crate::model::fault::Onset;

impl WindowBank {
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
                    if let Some(s) = newest
                        && self.onset[s] == k
                    {
                        of[s] = self.active[s];
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
        if self.fused_mul_add {
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
                        *d = mul_add::<FUSED>(h, *g, *d);
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
                        *c = mul_add::<FUSED>(*x, *y, *c);
                    }
                }
            }
            let d = &mut self.score[a * w..(a + 1) * w];
            for (i, e) in eps_white.iter().enumerate().take(p) {
                let sa = &self.signature[(i + p * a) * w..(i + p * a + 1) * w];
                for (d, x) in d.iter_mut().zip(sa) {
                    *d = mul_add::<FUSED>(*x, *e, *d);
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
            c00[s] = mul_add::<FUSED>(x0, x0, c00[s]);
            c10[s] = mul_add::<FUSED>(x1, x0, c10[s]);
            c11[s] = mul_add::<FUSED>(x1, x1, c11[s]);
            d0[s] = mul_add::<FUSED>(x0, e, d0[s]);
            d1[s] = mul_add::<FUSED>(x1, e, d1[s]);
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

    /// The LDLᵀ statistic for m = 1 in one pass: d²/C where C > τ·C (C > 0).
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
    pub(super) fn statistic_generic(&mut self) {
        let (m, w) = (self.m, self.slots);
        let tol = self.tolerance;
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
                // Pivot j is kept when D_j > τ·C_jj: the scale-free rule of
                // `statistic`.
                let djj = &self.ldl[tri(j, j) * w..(tri(j, j) + 1) * w];
                let cjj = &self.info[tri(j, j) * w..(tri(j, j) + 1) * w];
                let inv = &mut self.inv_pivot[j * w..(j + 1) * w];
                for (((iv, d), c), r) in inv.iter_mut().zip(djj).zip(cjj).zip(self.rank.iter_mut())
                {
                    let keep = *d > *c * tol;
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
            if self.fused_mul_add {
                gamma_column_of::<true>(n, closed_loop, g, factor, src, dst);
            } else {
                gamma_column_of::<false>(n, closed_loop, g, factor, src, dst);
            }
        }
        std::mem::swap(&mut self.gamma, &mut self.gamma_next);
        self.lag.iter_mut().for_each(|l| *l += 1.0);
        self.announce(k, psi);
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
                v = mul_add::<FUSED>(ci[l], rows[l][s], v);
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
                *d = mul_add::<FUSED>(c, *x, *d);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::bank_with_random_stats;
    use super::*;
    use crate::linalg::jacobi_eigen;

    /// Fault j's column times s_j (C_ab ↦ s_a s_b C_ab, d_a ↦ s_a d_a, s from
    /// 10⁻⁸ to 10⁸) changes no rank and leaves the statistic equal to 1e-9 relative, in
    /// the LDLᵀ of any m and in the one-division form of m = 2, over regular, rank-deficient
    /// and zero C. (With the cut-off τ·max_a C_aa of before, a column scaled by 10⁻⁸ next
    /// to one by 10⁸ lost its pivot.)
    #[test]
    fn pivot_decisions_ignore_fault_units() {
        for m in [2, 3, 5] {
            for seed in 1..6 {
                let mut base = bank_with_random_stats(m, seed);
                let w = base.slots;
                let units: Vec<f64> = (0..m)
                    .map(|a| 10f64.powi(8 - 16 * (a as i32 % 2)))
                    .collect();
                let mut scaled = base.clone();
                for a in 0..m {
                    for b in 0..=a {
                        for s in 0..w {
                            scaled.info[tri(a, b) * w + s] *= units[a] * units[b];
                        }
                    }
                    for s in 0..w {
                        scaled.score[a * w + s] *= units[a];
                    }
                }
                let passes: &[fn(&mut WindowBank)] = if m == 2 {
                    &[WindowBank::statistic_m2, WindowBank::statistic_generic]
                } else {
                    &[WindowBank::statistic_generic]
                };
                for pass in passes {
                    pass(&mut base);
                    pass(&mut scaled);
                    assert_eq!(base.rank, scaled.rank, "m = {m}, seed {seed}");
                    for (s, (x, y)) in base.stat.iter().zip(&scaled.stat).enumerate() {
                        assert!(
                            (x - y).abs() <= 1e-9 * (1.0 + x.abs()),
                            "m = {m}, seed {seed}, slot {s}: {x} vs {y}"
                        );
                    }
                }
                // Every rank from 0 to m occurs (`bank_with_random_stats`).
                assert!((0..=m).all(|r| base.rank.contains(&(r as f64))), "m = {m}");
            }
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
