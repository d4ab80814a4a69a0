//! θ̂ = C⁺d at r̂ (eq. (34)); the LDLᵀ in registers must equal the slot's stored one.

use super::{WindowBank, tri};
use crate::linalg::{at, jacobi_eigen};

impl WindowBank {
    /// The dropped-pivot LDLᵀ of C_k(r) and z = L⁻¹d_k(r) for slot s alone, into `ldl`,
    /// `inv_pivot` and `solved`, with the operations of the statistic passes: after the
    /// fused pass, which keeps them in registers, [`WindowBank::magnitude`] needs them
    /// at r̂ only.
    fn factor_slot(&mut self, s: usize) {
        let (m, w) = (self.m, self.slots);
        for j in 0..m {
            let mut d = self.info[tri(j, j) * w + s];
            for q in 0..j {
                let l = self.ldl[tri(j, q) * w + s];
                d -= l * l * self.ldl[tri(q, q) * w + s];
            }
            self.ldl[tri(j, j) * w + s] = d;
            let keep = d > self.info[tri(j, j) * w + s] * self.tolerance;
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
        // C deficient: θ̂ = D^{-1/2}Ĉ⁺D^{-1/2}d with Ĉ = D^{-1/2}CD^{-1/2}, D = diag C,
        // the equilibrated C (unit diagonal; a fault with C_aa = 0 keeps a zero row
        // and column and gets θ̂_a = 0), eigenvalues ≤ τ·λ_max(Ĉ) dropped. Equilibrating
        // first makes the decision scale-free as the statistic's: a fault's
        // column times s gives its θ̂ divided by s and changes no other entry.
        for a in 0..m {
            let caa = info[tri(a, a) * w + at_index];
            self.eig_scale[a] = if caa > 0.0 { 1.0 / caa.sqrt() } else { 0.0 };
        }
        for a in 0..m {
            for b in 0..=a {
                let c = info[tri(a, b) * w + at_index] * self.eig_scale[a] * self.eig_scale[b];
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
                let proj: f64 = (0..m)
                    .map(|a| v[a] * self.eig_scale[a] * self.score[a * w + s])
                    .sum();
                for a in 0..m {
                    out[a] += v[a] * proj / lam;
                }
            }
        }
        for (o, scale) in out.iter_mut().zip(&self.eig_scale).take(m) {
            *o *= scale;
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
            inv[j] = if d > info(j, j) * self.tolerance {
                1.0 / d
            } else {
                0.0
            };
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
}

#[cfg(test)]
mod tests {
    use super::super::bank_with_random_stats;

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
}
