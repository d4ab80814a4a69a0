//! The χ² detector kind against the GLR it is built on.

use glrmon_core::{Chi2Detector, Detector, StepOutput};

/// The χ² kind is the GLR's filter and window with the decision statistic
/// replaced: εᵀΣ⁻¹ε and the onset k, every other output bit for bit the GLR's
/// (what the monitor's former χ² switch produced, so records are unchanged).
#[test]
fn the_chi2_kind_is_the_glr_with_the_one_sample_statistic() {
    let sc = glrmon_sim::scenarios::paper2014_unstable();
    let mut sim = sc.faulty_simulator(3, "x0_jump", 150, 4.0).unwrap();
    let mut glr = sc.detector().unwrap();
    let mut chi2 = Chi2Detector::new(sc.detector().unwrap());
    let (p, m) = (glr.dims().outputs, glr.fault_count());
    let (mut a, mut b) = (StepOutput::new(p, m), StepOutput::new(p, m));
    for _ in 0..300 {
        let x = sim.next_sample();
        glr.step(&x.sample(), &mut a).unwrap();
        Detector::step(&mut chi2, &x.sample(), &mut b).unwrap();
        assert_eq!(b.glr, Some(a.normalized_innovation));
        assert_eq!(b.onset, Some(x.k));
        assert_eq!(
            (&b.innovation, b.normalized_innovation, &b.magnitude, b.rank),
            (&a.innovation, a.normalized_innovation, &a.magnitude, a.rank)
        );
    }
    assert_eq!((chi2.kind(), chi2.memory()), ("chi2", 1));
    assert_eq!(Detector::memory(&glr), glr.settings().window);
}
