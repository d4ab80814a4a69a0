//! The fault of one onset followed past the window: is it still in the data?
//!
//! The window bank forgets an onset w samples after it. A fault that persists is then
//! seen only through onsets inside the window, whose signatures begin with the
//! transient of a fault that starts there, while the data show the settled response of
//! one that started long ago. When the filter absorbs most of a fault (a sensor bias on
//! a stable channel: the settled innovation is a fraction of the bias), l_k falls below
//! the threshold although the fault is still there, and noise lifts it back later: one
//! persistent fault made a stream of alarms, each with a new onset.
//!
//! [`FollowedOnset`] continues eqs. (45)-(46) for one onset r̂ (the alarm's) for as long
//! as it is followed, splits the evidence of its signature into the last w samples
//! (recent) and everything before them (past, from r̂ on), and asks whether the recent
//! samples still carry the fault the past ones estimate:
//!
//! ```text
//! S_j(r̂)     = H_jΓ_j(r̂) + b(j − r̂)Φ̃_j                 (45), whitened by L_j⁻¹
//! Γ_{j+1}(r̂) = A_jΓ_j(r̂) + b(j − r̂)G_j                 (46)
//! recent:  C̄ = Σ_{j>k−w} S_jᵀS_j,       d̄ = Σ_{j>k−w} S_jᵀL_j⁻¹ε_j
//! past:    C° = Σ_{r̂≤j≤k−w} S_jᵀS_j,    d° = …,   θ° = C°⁻d°   (eq. (34) on the past)
//! z_k      = θ°ᵀd̄ / √(θ°ᵀC̄θ°)
//! ```
//!
//! z_k is the score test, along the direction of the fault's past magnitude θ°, of
//! "no fault in the last w samples": given θ° (which depends on other samples, the
//! innovations being independent) it is N(0, 1) when the recent samples carry no fault
//! and N(√δ, 1), δ = θ°ᵀC̄θ°, when the fault goes on with magnitude θ°. It is the
//! magnitude estimate of the recent samples along θ°, divided by its standard
//! deviation. One degree of freedom whatever the number of faults m (a χ²(m) test of
//! the recent θ̄ ≠ 0 would lose power with m), scale-free (a change of fault units
//! scales θ° and S inversely), and 0 when the recent samples cannot see the fault at
//! all (δ = 0: a state jump the filter has absorbed). [`FollowedEvidence::continues`]
//! turns (z, δ) into the decision an episode's end needs.
//!
//! The same sums give the fault's magnitude over the whole episode: θ̂ = (C° + C̄)⁺
//! (d° + d̄), eq. (34) at r̂ over every sample from r̂ on ([`FollowedOnset::magnitude`]).
//! The window's own θ̂ at its best onset slides with the window once r̂ has left it, and
//! fits the settled response of a fault that persists with the transient of one that
//! starts inside the window: it shrinks while the fault does not. The followed θ̂ does
//! not.
//!
//! The past evidence starts with the bank's C_k(r̂), d_k(r̂) at the alarm, so θ° is
//! first the alarm's θ̂ and then improves as samples leave the recent ring. C̄ and d̄ are
//! summed afresh from the ring at every step (no running subtraction, whose rounding
//! would drift over a long episode), O(w·m²); θ° is solved by the scale-free
//! dropped-pivot LDLᵀ of the bank (pivot D_j ≤ τ·C°_jj dropped, see the module
//! documentation of [`crate::window`]). Nothing is allocated after construction.

use crate::linalg::at;
use crate::model::fault::Onset;

/// One onset's fault followed past the window, with the statistic of its evidence over
/// the last w samples.
#[derive(Debug, Clone)]
pub(crate) struct FollowedOnset {
    n: usize,
    p: usize,
    m: usize,
    window: usize,
    kinds: Vec<Onset>,
    tol: f64,
    onset: Option<u64>,
    /// Γ_k(r̂) (n×m) before the step at k.
    gamma: Vec<f64>,
    gamma_next: Vec<f64>,
    /// L_k⁻¹S_k(r̂) (p×m).
    signature: Vec<f64>,
    /// The ring of S_jᵀS_j (m×m each) and S_jᵀL⁻¹ε_j (m each) of the last w samples.
    ring_info: Vec<f64>,
    ring_score: Vec<f64>,
    /// Samples in the ring (≤ w) and the slot of the next one.
    held: usize,
    next: usize,
    /// C̄, d̄ (recent), C°, d° (past) and the LDLᵀ workspace.
    info: Vec<f64>,
    score: Vec<f64>,
    past_info: Vec<f64>,
    past_score: Vec<f64>,
    factor: Vec<f64>,
    solved: Vec<f64>,
    /// C° + C̄, d° + d̄ and θ̂ = (C° + C̄)⁺(d° + d̄): the magnitude over every sample from
    /// r̂ on.
    total_info: Vec<f64>,
    total_score: Vec<f64>,
    magnitude: Vec<f64>,
    statistic: Option<FollowedEvidence>,
}

/// The evidence of a followed fault in the last w samples: z_k and δ = θ°ᵀC̄θ°.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowedEvidence {
    /// z_k: N(0, 1) when the samples carry no fault, N(√δ, 1) when it goes on.
    pub score: f64,
    /// δ: what the samples can tell of the fault at its earlier magnitude θ°.
    pub information: f64,
    /// Whether the evidence spans w samples (it starts empty at the follow).
    pub full: bool,
}

impl FollowedEvidence {
    /// Whether the fault goes on: the last w samples could see it at its earlier
    /// magnitude (√δ ≥ `z_alpha`, the normal upper quantile of the level α: a fault
    /// there would lift z above the level's quantile on average), and they are closer
    /// to it than to no fault (z ≥ √δ/2, the likelihood-ratio decision between θ = θ°
    /// and θ = 0 on them). A fault still there is judged gone with probability
    /// Φ(−√δ/2) (under 5 % once √δ ≥ 3.3); one removed is judged going on with the same
    /// probability; one the samples cannot see enough of is gone.
    #[must_use]
    pub fn continues(&self, z_alpha: f64) -> bool {
        let visible = self.information.max(0.0).sqrt();
        visible >= z_alpha && self.score >= visible / 2.0
    }
}

impl FollowedOnset {
    /// Buffers for n states, p outputs, the faults' onset profiles and window w.
    pub(crate) fn new(n: usize, p: usize, kinds: Vec<Onset>, window: usize, tol: f64) -> Self {
        let m = kinds.len();
        Self {
            n,
            p,
            m,
            window,
            kinds,
            tol,
            onset: None,
            gamma: vec![0.0; n * m],
            gamma_next: vec![0.0; n * m],
            signature: vec![0.0; p * m],
            ring_info: vec![0.0; window * m * m],
            ring_score: vec![0.0; window * m],
            held: 0,
            next: 0,
            info: vec![0.0; m * m],
            score: vec![0.0; m],
            past_info: vec![0.0; m * m],
            past_score: vec![0.0; m],
            factor: vec![0.0; m * m],
            solved: vec![0.0; m],
            total_info: vec![0.0; m * m],
            total_score: vec![0.0; m],
            magnitude: vec![0.0; m],
            statistic: None,
        }
    }

    /// Follows onset r̂ from the next measured step on, with Γ_{k+1}(r̂) (n×m,
    /// column-major) after the step at k and the bank's C_k(r̂) (m×m, full, column-major)
    /// and d_k(r̂) as the past evidence; the recent evidence starts empty.
    pub(crate) fn start(&mut self, onset: u64, gamma_next: &[f64], info: &[f64], score: &[f64]) {
        let (n, m) = (self.n, self.m);
        self.onset = Some(onset);
        self.gamma.copy_from_slice(&gamma_next[..n * m]);
        self.past_info.copy_from_slice(&info[..m * m]);
        self.past_score.copy_from_slice(&score[..m]);
        self.held = 0;
        self.next = 0;
        self.statistic = None;
    }

    /// Stops following.
    pub(crate) fn stop(&mut self) {
        self.onset = None;
        self.statistic = None;
    }

    /// The onset followed, if any.
    pub(crate) fn onset(&self) -> Option<u64> {
        self.onset
    }

    /// The evidence after the last measured step (`None` before the first).
    pub(crate) fn statistic(&self) -> Option<FollowedEvidence> {
        self.statistic
    }

    /// θ̂ = C_k(r̂)⁺d_k(r̂) over every sample from the followed onset r̂ to the last
    /// measured one (eq. (34), past and recent evidence together), one value per fault;
    /// `None` before the first measured step.
    pub(crate) fn magnitude(&self) -> Option<&[f64]> {
        self.statistic.map(|_| self.magnitude.as_slice())
    }

    /// Measured step k: S_k(r̂), its terms into the ring, T_k, then Γ_{k+1}(r̂).
    /// The arguments are those of the bank's step (L⁻¹H_k, L⁻¹Φ̃_k, L⁻¹ε_k, A_k, Ψ̃_k,
    /// F_kK_kΦ̃_k).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn measure(
        &mut self,
        k: u64,
        h_white: &[f64],
        phi_white: &[f64],
        eps_white: &[f64],
        closed_loop: &[f64],
        psi: &[f64],
        fk_phi: &[f64],
    ) {
        let Some(onset) = self.onset.filter(|&r| r <= k) else {
            return;
        };
        let (n, p, m) = (self.n, self.p, self.m);
        let lag = k - onset;
        for j in 0..m {
            let b = self.kinds[j].output_factor(lag);
            for i in 0..p {
                let mut v = b * phi_white[at(p, i, j)];
                for l in 0..n {
                    v = h_white[at(p, i, l)].mul_add(self.gamma[at(n, l, j)], v);
                }
                self.signature[at(p, i, j)] = v;
            }
        }
        let slot = self.next;
        if self.held == self.window {
            // The oldest recent sample becomes past evidence.
            let old = slot * m * m..(slot + 1) * m * m;
            for (p, x) in self.past_info.iter_mut().zip(&self.ring_info[old]) {
                *p += x;
            }
            for (p, x) in
                (self.past_score.iter_mut()).zip(&self.ring_score[slot * m..(slot + 1) * m])
            {
                *p += x;
            }
        }
        let (ri, rs) = (
            &mut self.ring_info[slot * m * m..(slot + 1) * m * m],
            &mut self.ring_score[slot * m..(slot + 1) * m],
        );
        for a in 0..m {
            for b in 0..m {
                let mut c = 0.0;
                for i in 0..p {
                    c = self.signature[at(p, i, a)].mul_add(self.signature[at(p, i, b)], c);
                }
                ri[at(m, a, b)] = c;
            }
            let mut d = 0.0;
            for (i, e) in eps_white.iter().enumerate().take(p) {
                d = self.signature[at(p, i, a)].mul_add(*e, d);
            }
            rs[a] = d;
        }
        self.next = (slot + 1) % self.window;
        self.held = (self.held + 1).min(self.window);
        self.statistic = Some(self.evaluate());
        self.time_update(lag, closed_loop, psi, fk_phi);
    }

    /// A missing sample k: Γ's time update only (no evidence added).
    pub(crate) fn predict(&mut self, k: u64, closed_loop: &[f64], psi: &[f64], fk_phi: &[f64]) {
        if let Some(onset) = self.onset.filter(|&r| r <= k) {
            self.time_update(k - onset, closed_loop, psi, fk_phi);
        }
    }

    /// Γ_{k+1}(r̂) = A_kΓ_k(r̂) + b(k − r̂)G_k (eq. (46)).
    fn time_update(&mut self, lag: u64, closed_loop: &[f64], psi: &[f64], fk_phi: &[f64]) {
        let n = self.n;
        for j in 0..self.m {
            let kind = self.kinds[j];
            let b = kind.output_factor(lag);
            for i in 0..n {
                let g = if kind == Onset::Impulse {
                    -fk_phi[at(n, i, j)]
                } else {
                    psi[at(n, i, j)] - fk_phi[at(n, i, j)]
                };
                let mut v = b * g;
                for l in 0..n {
                    v = closed_loop[at(n, i, l)].mul_add(self.gamma[at(n, l, j)], v);
                }
                self.gamma_next[at(n, i, j)] = v;
            }
        }
        std::mem::swap(&mut self.gamma, &mut self.gamma_next);
    }

    /// z = θ°ᵀd̄ / √(θ°ᵀC̄θ°), with C̄, d̄ summed from the ring and θ° = C°⁻d° by the
    /// dropped-pivot LDLᵀ (a generalised inverse of the positive semi-definite C°).
    fn evaluate(&mut self) -> FollowedEvidence {
        let m = self.m;
        self.info.fill(0.0);
        self.score.fill(0.0);
        for s in 0..self.held {
            let ri = &self.ring_info[s * m * m..(s + 1) * m * m];
            for (c, x) in self.info.iter_mut().zip(ri) {
                *c += x;
            }
            for (d, x) in self
                .score
                .iter_mut()
                .zip(&self.ring_score[s * m..(s + 1) * m])
            {
                *d += x;
            }
        }
        self.solve_total();
        self.solve_past();
        let theta = &self.solved;
        let mut along = 0.0;
        let mut information = 0.0;
        for (a, (t, d)) in theta.iter().zip(&self.score).enumerate() {
            along += t * d;
            let column = &self.info[a * m..(a + 1) * m];
            let row: f64 = column.iter().zip(theta).map(|(c, t)| c * t).sum();
            information += t * row;
        }
        let full = self.held == self.window;
        if information > 0.0 && information.is_finite() {
            FollowedEvidence {
                score: along / information.sqrt(),
                information,
                full,
            }
        } else {
            FollowedEvidence {
                score: 0.0,
                information: 0.0,
                full,
            }
        }
    }

    /// θ° = C°⁻d° into `solved` ([`ldl_solve`]).
    fn solve_past(&mut self) {
        ldl_solve(
            self.m,
            self.tol,
            &self.past_info,
            &self.past_score,
            &mut self.factor,
            &mut self.solved,
        );
    }

    /// θ̂ = (C° + C̄)⁺(d° + d̄) into `magnitude`, with C̄, d̄ summed already.
    fn solve_total(&mut self) {
        for ((t, p), r) in self
            .total_info
            .iter_mut()
            .zip(&self.past_info)
            .zip(&self.info)
        {
            *t = p + r;
        }
        for ((t, p), r) in (self.total_score.iter_mut())
            .zip(&self.past_score)
            .zip(&self.score)
        {
            *t = p + r;
        }
        ldl_solve(
            self.m,
            self.tol,
            &self.total_info,
            &self.total_score,
            &mut self.factor,
            &mut self.magnitude,
        );
    }
}

/// x = C⁻d for the m×m positive semi-definite C (column-major): LDLᵀ of C in `f` (L
/// below the diagonal, D on it, pivots D_j ≤ τ·C_jj dropped), then L⁻¹, D⁻¹ on the
/// kept pivots, L⁻ᵀ: a generalised inverse, scale-free as the bank's.
fn ldl_solve(m: usize, tol: f64, c: &[f64], d: &[f64], f: &mut [f64], x: &mut [f64]) {
    for j in 0..m {
        let mut dj = c[at(m, j, j)];
        for l in 0..j {
            let ljl = f[at(m, j, l)];
            dj -= ljl * ljl * f[at(m, l, l)];
        }
        let keep = dj > tol * c[at(m, j, j)] && dj > 0.0;
        f[at(m, j, j)] = if keep { dj } else { 0.0 };
        for i in j + 1..m {
            let mut v = c[at(m, i, j)];
            for l in 0..j {
                v -= f[at(m, i, l)] * f[at(m, j, l)] * f[at(m, l, l)];
            }
            f[at(m, i, j)] = if keep { v / dj } else { 0.0 };
        }
    }
    for j in 0..m {
        let mut v = d[j];
        for l in 0..j {
            v -= f[at(m, j, l)] * x[l];
        }
        x[j] = v;
    }
    for j in 0..m {
        let dj = f[at(m, j, j)];
        x[j] = if dj > 0.0 { x[j] / dj } else { 0.0 };
    }
    for j in (0..m).rev() {
        let mut v = x[j];
        for i in j + 1..m {
            v -= f[at(m, i, j)] * x[i];
        }
        x[j] = v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// z equals θ°ᵀd̄/√(θ°ᵀC̄θ°) computed with nalgebra from the signature recursion
    /// written out by hand (scalar LTI model, sensor bias), over more samples than the
    /// window: the ring wraps and its oldest samples move to the past evidence.
    #[test]
    fn z_matches_the_past_estimate_scored_on_the_recent_window() {
        // x_{k+1} = 0.9x_k, y = x + bias; a fixed gain K: A = F(1 − KH) = 0.9·0.6.
        let (f, kgain) = (0.9, 0.4);
        let a = f * (1.0 - kgain);
        let fk = f * kgain;
        let w = 5;
        let mut fo = FollowedOnset::new(1, 1, vec![Onset::Step], w, 1e-9);
        // Past evidence at the start: C = 2, d = 1.
        fo.start(10, &[0.0], &[2.0], &[1.0]);
        let eps: Vec<f64> = (0..12).map(|i| 0.3 + 0.1 * ((i * 7) % 5) as f64).collect();
        let mut sigs = Vec::new();
        let mut gamma = 0.0;
        for (i, e) in eps.iter().enumerate() {
            let k = 10 + i as u64;
            // S = Γ + Φ̃ (H = 1, Φ̃ = 1, whitening 1); Γ' = AΓ + (0 − FKΦ̃).
            sigs.push(gamma + 1.0);
            gamma = a * gamma - fk;
            fo.measure(k, &[1.0], &[1.0], &[*e], &[a], &[0.0], &[fk]);
            let split = sigs.len().saturating_sub(w);
            let s = DVector::from_column_slice(&sigs);
            let z = DVector::from_column_slice(&eps[..=i]);
            let (past_c, past_d) = (
                2.0 + s.rows(0, split).dot(&s.rows(0, split)),
                1.0 + s.rows(0, split).dot(&z.rows(0, split)),
            );
            let n = sigs.len() - split;
            let (c, d) = (
                s.rows(split, n).dot(&s.rows(split, n)),
                s.rows(split, n).dot(&z.rows(split, n)),
            );
            let theta = past_d / past_c;
            let want = theta * d / (theta * theta * c).sqrt();
            let got = fo.statistic().unwrap();
            assert!(
                (got.score - want).abs() <= 1e-12,
                "k = {k}: {got:?} vs {want}"
            );
            let delta = theta * theta * c;
            assert!((got.information - delta).abs() <= 1e-12 * delta, "{got:?}");
            // The magnitude over every sample from the onset on, the start's evidence
            // included: (2 + ΣS²)⁻¹(1 + ΣSε).
            let whole = (1.0 + s.dot(&z)) / (2.0 + s.dot(&s));
            let magnitude = fo.magnitude().unwrap()[0];
            assert!(
                (magnitude - whole).abs() <= 1e-12 * whole.abs(),
                "k = {k}: {magnitude} vs {whole}"
            );
        }
        let settled = 1.0 - fk / (1.0 - a);
        assert!((sigs.last().unwrap() - settled).abs() < 0.01, "{sigs:?}");
    }

    /// Two faults with the same signature: the past estimate keeps one pivot, and z is
    /// that of one fault.
    #[test]
    fn collinear_faults_count_once() {
        let mut fo = FollowedOnset::new(1, 1, vec![Onset::Step, Onset::Step], 4, 1e-9);
        let info = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
        fo.start(0, &[0.0, 0.0], info.as_slice(), &[1.0, 2.0]);
        for k in 0..4 {
            fo.measure(
                k,
                &[1.0],
                &[1.0, 2.0],
                &[0.5],
                &[0.5],
                &[0.0, 0.0],
                &[0.0, 0.0],
            );
        }
        // Four samples with S = 1 along θ°: z = Σε/√4 = 2/2.
        let z = fo.statistic().unwrap().score;
        assert!((z - 1.0).abs() < 1e-12, "{z}");
        // The second fault's pivot is dropped: θ̂ = (C₁₁ + 4)⁻¹(d₁ + Σε)·e₁ = 3/5 e₁,
        // whose fit C θ̂ equals that of any other solution.
        let magnitude = fo.magnitude().unwrap();
        assert!((magnitude[0] - 0.6).abs() < 1e-12, "{magnitude:?}");
        assert_eq!(magnitude[1], 0.0);
    }

    #[test]
    fn without_past_evidence_z_is_zero() {
        let mut fo = FollowedOnset::new(1, 1, vec![Onset::Step], 4, 1e-9);
        fo.start(0, &[0.0], &[0.0], &[0.0]);
        assert_eq!(fo.magnitude(), None, "nothing measured yet");
        fo.measure(0, &[1.0], &[1.0], &[3.0], &[0.5], &[0.0], &[0.0]);
        let e = fo.statistic().unwrap();
        assert_eq!((e.score, e.information), (0.0, 0.0));
        assert!(!e.continues(2.33));
    }

    #[test]
    fn a_fault_continues_when_visible_and_closer_to_its_magnitude_than_to_none() {
        let e = |score, information| FollowedEvidence {
            score,
            information,
            full: true,
        };
        // √δ = 4: continues from z = 2 on.
        assert!(e(2.0, 16.0).continues(2.33));
        assert!(!e(1.9, 16.0).continues(2.33));
        // √δ = 2 < 2.33: not visible enough, gone whatever z.
        assert!(!e(5.0, 4.0).continues(2.33));
    }
}
