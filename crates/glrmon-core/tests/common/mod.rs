//! Helpers shared by the core's path-comparison tests (fused pass, vector levels, small
//! windows, LTI fast path): every output of a step as bits, a run of a detector over a
//! simulator with predict-only gaps, and a run of two detectors in lockstep.

// Each test crate that includes this module uses a part of it.
#![allow(dead_code)]

use glrmon_core::{GlrDetector, Sample, StepOutput};
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
    det: &mut GlrDetector,
    sim: &mut Simulator,
    out: &mut StepOutput,
    steps: u64,
    gap: impl Fn(u64) -> bool,
    mut each: impl FnMut(&GlrDetector, &StepOutput) -> T,
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

/// Samples 0 … steps − 1 of `sim` through two detectors in lockstep (predict-only on
/// both where `gap(k)`), with `each(k, measured, detectors, outputs)` called after
/// every sample.
pub(crate) fn run_pair(
    detectors: [&mut GlrDetector; 2],
    outputs: [&mut StepOutput; 2],
    sim: &mut Simulator,
    steps: u64,
    gap: impl Fn(u64) -> bool,
    mut each: impl FnMut(u64, bool, [&GlrDetector; 2], [&StepOutput; 2]),
) {
    let [first, second] = detectors;
    let [a, b] = outputs;
    for k in 0..steps {
        let x = sim.next_sample();
        let measured = !gap(k);
        if measured {
            let s = Sample {
                k,
                u: &x.u,
                y: &x.y,
                p: &x.p,
            };
            first.step(&s, a).unwrap();
            second.step(&s, b).unwrap();
        } else {
            first.predict_only(k).unwrap();
            second.predict_only(k).unwrap();
        }
        each(k, measured, [&*first, &*second], [&*a, &*b]);
    }
}
