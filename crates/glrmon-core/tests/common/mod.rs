//! Helpers shared by the core's bit-identity tests (fused pass, vector levels, small
//! windows): every output of a step as bits, and a run of a detector over a simulator
//! with predict-only gaps.

use glrmon_core::{Detector, Sample, StepOutput};
use glrmon_sim::Simulator;

/// Every output of a step as bits: ε, εᵀΣ⁻¹ε, l_k, r̂, rank, θ̂.
pub(crate) fn bits(out: &StepOutput) -> Vec<u64> {
    let mut v: Vec<u64> = out.innovation.iter().map(|x| x.to_bits()).collect();
    v.push(out.normalized_innovation.to_bits());
    v.push(out.glr.map_or(u64::MAX, f64::to_bits));
    v.push(out.onset.unwrap_or(u64::MAX));
    v.push(out.rank as u64);
    v.extend(out.magnitude.iter().map(|x| x.to_bits()));
    v
}

/// Samples 0 … steps − 1 of `sim` through `det` (a predict-only step where `gap(k)`),
/// with `each` called after every measured step; returns what `each` returned, in order.
pub(crate) fn run_steps<T>(
    det: &mut Detector,
    sim: &mut Simulator,
    out: &mut StepOutput,
    steps: u64,
    gap: impl Fn(u64) -> bool,
    mut each: impl FnMut(&Detector, &StepOutput) -> T,
) -> Vec<T> {
    let mut all = Vec::new();
    for k in 0..steps {
        let x = sim.next_sample();
        if gap(k) {
            det.predict_only(k).unwrap();
            continue;
        }
        let s = Sample {
            k,
            u: &x.u,
            y: &x.y,
            p: &x.p,
        };
        det.step(&s, out).unwrap();
        all.push(each(det, out));
    }
    all
}
