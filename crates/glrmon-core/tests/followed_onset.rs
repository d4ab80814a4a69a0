//! The fault followed past the window (`Detector::follow`/`followed`), on which an
//! episode ends when the data say the fault is gone.
//!
//! - Identity: while the followed onset is still in the window, z_k is the bank's
//!   magnitude estimate at the start (eq. (34)) scored on the C_k(r), d_k(r) the bank
//!   accumulated since (eqs. (32)-(33)), to rounding.
//! - The LTI stationary fast path gives the z of the general recursion.
//! - Under no fault z_k follows its law, N(0, 1) (mean, variance and 1 % tail on
//!   disjoint windows).
//! - A persistent sensor bias that the filter mostly absorbs stays in evidence for as
//!   long as it lasts, and once it is removed z_k returns to N(0, 1).

use glrmon_core::detector::{GlrDetector, Sample, StepOutput, WindowSettings};
use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
use glrmon_core::model::{Lpv, StateSpace};
use nalgebra::{DMatrix, DVector};

const W: usize = 20;

/// A stable two-state plant, both states measured: a step on x0 (state fault) and a
/// bias on y1 (output fault).
fn detector(steady_tolerance: f64) -> GlrDetector {
    let f = DMatrix::from_row_slice(2, 2, &[0.8, 0.2, 0.0, 0.7]);
    let model = Lpv::lti(
        f,
        DMatrix::zeros(2, 0),
        DMatrix::identity(2, 2),
        DMatrix::zeros(2, 0),
        DMatrix::identity(2, 2) * 0.01,
        DMatrix::identity(2, 2) * 0.04,
    )
    .unwrap();
    let faults = FaultDictionary::new(
        model.dims(),
        vec![
            Fault::state(
                "x0_step",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![1.0, 0.0])),
            ),
            Fault::output(
                "y1_bias",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![0.0, 1.0])),
            ),
        ],
    )
    .unwrap();
    let settings = WindowSettings {
        window: W,
        min_lag: 0,
        steady_tolerance,
        ..Default::default()
    };
    GlrDetector::new(
        Box::new(model),
        faults,
        DVector::zeros(2),
        DMatrix::identity(2, 2),
        settings,
    )
    .unwrap()
}

/// Samples of the plant with `bias` added to y1 on [from, to).
struct Plant {
    x: [f64; 2],
    seed: u64,
}

impl Plant {
    fn new(seed: u64) -> Self {
        Self { x: [0.0; 2], seed }
    }

    fn normal(&mut self) -> f64 {
        let mut u = || {
            self.seed = self
                .seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(), u());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }

    fn next(&mut self, bias: f64) -> [f64; 2] {
        let y = [
            self.x[0] + 0.2 * self.normal(),
            self.x[1] + 0.2 * self.normal() + bias,
        ];
        let w = [0.1 * self.normal(), 0.1 * self.normal()];
        self.x = [
            0.8 * self.x[0] + 0.2 * self.x[1] + w[0],
            0.7 * self.x[1] + w[1],
        ];
        y
    }
}

fn step(det: &mut GlrDetector, out: &mut StepOutput, k: u64, y: [f64; 2]) {
    det.step(
        &Sample {
            k,
            u: &[],
            y: &y,
            p: &[],
        },
        out,
    )
    .unwrap();
}

/// The normal upper quantile at 1 %.
const Z99: f64 = 2.326_347_874_040_841;

#[test]
fn followed_evidence_equals_the_banks_information_over_the_same_samples() {
    for tolerance in [0.0, 1e-12] {
        let mut det = detector(tolerance);
        let mut out = StepOutput::new(2, 2);
        let mut plant = Plant::new(7);
        let start = 100;
        for k in 0..=start {
            step(
                &mut det,
                &mut out,
                k,
                plant.next(if k >= 60 { 0.5 } else { 0.0 }),
            );
        }
        let r = start - 3;
        assert!(det.follow(Some(r)));
        let at_start = det.fisher_statistics(r).unwrap();
        let theta = at_start
            .information()
            .clone()
            .lu()
            .solve(at_start.score())
            .unwrap();
        for k in start + 1..start + 1 + (W as u64 - 4) {
            step(&mut det, &mut out, k, plant.next(0.5));
            let now = det.fisher_statistics(r).unwrap();
            let c = now.information() - at_start.information();
            let d = now.score() - at_start.score();
            let want = theta.dot(&d) / theta.dot(&(&c * &theta)).sqrt();
            let got = det.followed().unwrap().score;
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                "τ = {tolerance}, k = {k}: followed {got}, bank {want}"
            );
        }
    }
}

#[test]
fn the_stationary_fast_path_follows_as_the_general_recursion() {
    let mut general = detector(0.0);
    let mut steady = detector(1e-12);
    let (mut out_g, mut out_s) = (StepOutput::new(2, 2), StepOutput::new(2, 2));
    let mut plant = Plant::new(11);
    for k in 0..400u64 {
        let y = plant.next(if k >= 150 { 0.6 } else { 0.0 });
        step(&mut general, &mut out_g, k, y);
        step(&mut steady, &mut out_s, k, y);
        if k == 155 {
            let r = out_g.onset.unwrap();
            assert!(general.follow(Some(r)) && steady.follow(Some(r)));
        }
        if k > 155 {
            let (g, s) = (general.followed().unwrap(), steady.followed().unwrap());
            let (g, s) = (g.score, s.score);
            assert!(
                (g - s).abs() <= 1e-9 * g.abs().max(1.0),
                "k = {k}: general {g}, stationary {s}"
            );
        }
    }
    assert!(steady.is_stationary(), "the fast path was not entered");
}

/// Under no fault z_k on disjoint windows is N(0, 1) (2000 windows: mean within ±0.1,
/// variance within ±0.15, 1 % tail within 0.3-2 %).
#[test]
fn without_a_fault_the_followed_statistic_follows_its_normal_law() {
    let mut det = detector(1e-12);
    let mut out = StepOutput::new(2, 2);
    let mut plant = Plant::new(3);
    let windows = 2000;
    let mut k = 0;
    for _ in 0..50 {
        step(&mut det, &mut out, k, plant.next(0.0));
        k += 1;
    }
    let (mut sum, mut squares, mut above) = (0.0, 0.0, 0);
    for _ in 0..windows {
        // The oldest onset of the window: a past estimate from w samples, scored on
        // the next w.
        assert!(det.follow(Some(k - W as u64)));
        for _ in 0..W {
            step(&mut det, &mut out, k, plant.next(0.0));
            k += 1;
        }
        let z = det.followed().unwrap().score;
        sum += z;
        squares += z * z;
        above += usize::from(z > Z99);
    }
    let n = windows as f64;
    let mean = sum / n;
    let variance = squares / n - mean * mean;
    let tail = above as f64 / n;
    assert!(mean.abs() < 0.1, "mean {mean}");
    assert!((variance - 1.0).abs() < 0.15, "variance {variance}");
    assert!((0.003..0.02).contains(&tail), "tail {tail}");
}

/// A sensor bias of 2.5 noise standard deviations on y1, which the filter partly
/// absorbs: followed from its onset, it goes on (`continues` at 1 %) on at least 97 %
/// of 2000 samples while it lasts, never judged gone for 10 samples in a row (an
/// episode ends after w = 20), and once removed z is back to N(0, 1) (from a window
/// after: mean within ±0.3) and the fault is judged gone on at least 90 % of samples.
#[test]
fn a_persistent_bias_stays_in_evidence_and_leaves_when_removed() {
    let mut det = detector(1e-12);
    let mut out = StepOutput::new(2, 2);
    let mut plant = Plant::new(5);
    let (on, off) = (200u64, 2300u64);
    let (mut going_on, mut lasting, mut run, mut longest) = (0, 0, 0, 0);
    let (mut after, mut after_sum, mut after_gone) = (0, 0.0, 0);
    for k in 0..off + 1000 {
        let bias = if (on..off).contains(&k) { 0.5 } else { 0.0 };
        step(&mut det, &mut out, k, plant.next(bias));
        if k == on + 5 {
            assert!(det.follow(Some(on)));
        }
        let evidence = det.followed();
        if k > on + 5 && k < off {
            let continues = evidence.unwrap().continues(Z99);
            lasting += 1;
            going_on += usize::from(continues);
            run = if continues { 0 } else { run + 1 };
            longest = longest.max(run);
        }
        if k >= off + W as u64 {
            let e = evidence.unwrap();
            after += 1;
            after_sum += e.score;
            after_gone += usize::from(!e.continues(Z99));
        }
    }
    assert!(
        going_on * 100 >= 97 * lasting && longest < 10,
        "going on at {going_on} of {lasting}, longest run judged gone: {longest}"
    );
    let mean_after = after_sum / after as f64;
    assert!(mean_after.abs() < 0.3, "mean z after removal {mean_after}");
    assert!(
        after_gone * 10 >= 9 * after,
        "gone at {after_gone} of {after}"
    );
}
