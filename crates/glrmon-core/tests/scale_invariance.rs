//! Scale invariance: the units in which a fault magnitude, an output or an
//! input is expressed change no decision of the detector (l_k, r̂, rank C_k(r̂)), of the
//! isolation tests (Zhang & Basseville 2014, eq. (41)) or of the isolability report that
//! `glrmon validate` prints, and θ̂ follows the change of units. Then the gas-pipeline
//! channel of the 2014 paper, §6.2, in its natural units.
//!
//! Exact arithmetic gives exactly equal statistics; floating point gives them to
//! rounding, so values are compared to 10⁻⁹ relative and decisions for equality.

use glrmon_core::isolation::information::window_information;
use glrmon_core::isolation::isolability::{
    DEFAULT_CORRELATION_LIMIT, IsolabilityReport, isolability,
};
use glrmon_core::threshold::chi2_upper_quantile;
use glrmon_core::{
    Column, ColumnFn, Dims, Fault, FaultDictionary, FisherStatistics, GlrDetector, Onset, Sample,
    Signals, StateSpace, StepOutput, SystemMatrices, WindowSettings,
};
use glrmon_sim::{Injection, Rng, SimSample, Simulator};
use nalgebra::{DMatrix, DVector};

/// Type-I probability of each isolation test: the 1 % of the paper's §6.2 (threshold
/// 6.6349 for one degree of freedom).
const ISOLATION_ALPHA: f64 = 0.01;

/// Relative tolerance of every compared statistic: rounding of two runs whose inputs
/// differ by a change of units (the observed deviations are below 10⁻¹²).
const REL: f64 = 1e-9;

// ------------------------------------------------------------------- the plants

/// A plant given by its matrices at each step, cycled (one step: LTI).
#[derive(Debug, Clone)]
struct Plant {
    dims: Dims,
    steps: Vec<SystemMatrices>,
}

impl StateSpace for Plant {
    fn dims(&self) -> Dims {
        self.dims
    }
    fn evaluate(&mut self, k: u64, _signals: &Signals<'_>, out: &mut SystemMatrices) {
        out.clone_from(&self.steps[k as usize % self.steps.len()]);
    }
    fn is_constant(&self) -> bool {
        self.steps.len() == 1
    }
}

/// How a fault of the random dictionary enters.
#[derive(Debug, Clone)]
enum Part {
    Constant(DVector<f64>),
    InputBias(usize),
    Zero,
}

/// One fault of the random dictionary: name, profile, state part Ψ̃, output part Φ̃.
#[derive(Debug, Clone)]
struct FaultSpec {
    name: &'static str,
    onset: Onset,
    state: Part,
    output: Part,
}

/// A change of units: fault j's constant columns times `fault[j]` (θ_j divided by
/// it), output i times `output[i]` (y_i, row i of H, J and Φ̃, row and column i of R),
/// input i divided by `input[i]` (u_i; column i of G and J times it).
#[derive(Debug, Clone)]
struct Units {
    fault: Vec<f64>,
    output: Vec<f64>,
    input: Vec<f64>,
}

impl Units {
    fn identity(m: usize, p: usize, l: usize) -> Self {
        Self {
            fault: vec![1.0; m],
            output: vec![1.0; p],
            input: vec![1.0; l],
        }
    }

    fn plant(&self, plant: &Plant) -> Plant {
        let so = DMatrix::from_diagonal(&DVector::from_column_slice(&self.output));
        let si = DMatrix::from_diagonal(&DVector::from_column_slice(&self.input));
        let steps = plant
            .steps
            .iter()
            .map(|s| SystemMatrices {
                f: s.f.clone(),
                g: &s.g * &si,
                h: &so * &s.h,
                j: &so * &s.j * &si,
                q: s.q.clone(),
                r: &so * &s.r * &so,
            })
            .collect();
        Plant {
            dims: plant.dims,
            steps,
        }
    }

    fn dictionary(&self, dims: Dims, specs: &[FaultSpec]) -> FaultDictionary {
        let column = |part: &Part, s: f64, rows: Option<&[f64]>| match part {
            Part::Constant(v) => Column::Constant(DVector::from_fn(v.len(), |i, _| {
                v[i] * s * rows.map_or(1.0, |r| r[i])
            })),
            Part::InputBias(i) => Column::InputBias { input: *i },
            Part::Zero => Column::Zero,
        };
        let faults = specs
            .iter()
            .zip(&self.fault)
            .map(|(f, &s)| Fault {
                name: f.name.into(),
                onset: f.onset,
                state: column(&f.state, s, None),
                output: column(&f.output, s, Some(&self.output)),
            })
            .collect();
        FaultDictionary::new(dims, faults).unwrap()
    }

    fn sample(&self, x: &SimSample) -> SimSample {
        SimSample {
            k: x.k,
            u: x.u.iter().zip(&self.input).map(|(u, s)| u / s).collect(),
            y: x.y.iter().zip(&self.output).map(|(y, s)| y * s).collect(),
            p: x.p.clone(),
        }
    }

    /// θ'_j = θ_j / factor_j under this change of units.
    fn magnitude_factor(&self, specs: &[FaultSpec]) -> Vec<f64> {
        specs
            .iter()
            .zip(&self.fault)
            .map(|(f, &s)| match f.state {
                // Ψ̃ = G[:, i], whose column is times input[i].
                Part::InputBias(i) => self.input[i],
                _ => s,
            })
            .collect()
    }
}

/// A random plant (n = 3, l = 2, p = 2): LTI, or LTV cycling through 13 steps.
fn random_plant(rng: &mut Rng, lti: bool) -> Plant {
    let (n, l, p) = (3, 2, 2);
    let mut rand = |r: usize, c: usize, s: f64| DMatrix::from_fn(r, c, |_, _| s * rng.normal());
    let steps = (0..if lti { 1 } else { 13 })
        .map(|_| {
            let a = rand(n, n, 0.3);
            let b = rand(p, p, 0.4);
            SystemMatrices {
                f: rand(n, n, 0.35),
                g: rand(n, l, 1.0),
                h: rand(p, n, 1.0),
                j: rand(p, l, 0.5),
                q: &a * a.transpose() + DMatrix::identity(n, n) * 0.02,
                r: &b * b.transpose() + DMatrix::identity(p, p) * 0.1,
            }
        })
        .collect();
    Plant {
        dims: Dims {
            states: n,
            inputs: l,
            outputs: p,
            signals: 0,
        },
        steps,
    }
}

/// The first m of: a state step, an output step, an actuator bias on u₀ (Ψ̃ = G[:, 0]),
/// a ramp with both parts, a state impulse. m = 2 takes the one-division statistic,
/// m = 3 and 5 the LDLᵀ (fused and general).
fn random_faults(rng: &mut Rng, m: usize) -> Vec<FaultSpec> {
    let mut col = |len: usize| Part::Constant(DVector::from_fn(len, |_, _| rng.normal()));
    let all = vec![
        FaultSpec {
            name: "drift",
            onset: Onset::Step,
            state: col(3),
            output: Part::Zero,
        },
        FaultSpec {
            name: "bias",
            onset: Onset::Step,
            state: Part::Zero,
            output: col(2),
        },
        FaultSpec {
            name: "actuator",
            onset: Onset::Step,
            state: Part::InputBias(0),
            output: Part::Zero,
        },
        FaultSpec {
            name: "ramp",
            onset: Onset::Ramp,
            state: col(3),
            output: col(2),
        },
        FaultSpec {
            name: "jump",
            onset: Onset::Impulse,
            state: col(3),
            output: Part::Zero,
        },
    ];
    all.into_iter().take(m).collect()
}

/// 10^u with u uniform in [−6, 6].
fn random_scale(rng: &mut Rng) -> f64 {
    10f64.powf(rng.uniform_in(-6.0, 6.0))
}

// ------------------------------------------------------------- the comparison

/// What a run decides and estimates at one step, with the isolation tests and the
/// isolability report at r̂.
#[derive(Debug)]
struct Decisions {
    glr: Option<f64>,
    onset: Option<u64>,
    rank: usize,
    /// θ̂ of the step and of the isolation (F⁺ζ), in the run's units.
    magnitude: DVector<f64>,
    fisher_magnitude: DVector<f64>,
    /// √C_jj(r̂): θ̂_j times it is free of the units of fault j.
    unit: DVector<f64>,
    /// (minmax, sensitivity) of each single fault and of the first two together, with
    /// their degrees of freedom.
    tests: Vec<(f64, usize, f64, usize)>,
    global: f64,
    isolability: Option<IsolabilityReport>,
}

fn decisions(det: &GlrDetector, out: &StepOutput) -> Decisions {
    let m = det.fault_count();
    let mut d = Decisions {
        glr: out.glr,
        onset: out.onset,
        rank: out.rank,
        magnitude: out.magnitude.clone(),
        fisher_magnitude: DVector::zeros(m),
        unit: DVector::zeros(m),
        tests: Vec::new(),
        global: 0.0,
        isolability: None,
    };
    let Some(onset) = out.onset.filter(|_| out.glr.is_some()) else {
        return d;
    };
    let (mut info, mut score) = (DMatrix::zeros(m, m), DVector::zeros(m));
    assert!(det.information(onset, &mut info, &mut score));
    d.unit = info.diagonal().map(f64::sqrt);
    let fisher: FisherStatistics = det.fisher_statistics(onset).expect("onset in the window");
    d.fisher_magnitude = fisher.magnitude();
    d.global = fisher.global().value;
    let mut subsets: Vec<Vec<usize>> = (0..m).map(|j| vec![j]).collect();
    subsets.push(vec![0, 1]);
    for a in subsets {
        let mm = fisher.minmax(&a).unwrap();
        let se = fisher.sensitivity(&a).unwrap();
        d.tests.push((mm.value, mm.dof, se.value, se.dof));
    }
    d.isolability = Some(isolability(&info, DEFAULT_CORRELATION_LIMIT).unwrap());
    d
}

/// |a − b| ≤ REL·scale.
fn close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= REL * scale
}

/// Whether a test of `dof` degrees of freedom names its faults (the monitor's rule).
fn isolates(value: f64, dof: usize) -> bool {
    value > chi2_upper_quantile(dof.max(1) as f64, ISOLATION_ALPHA).unwrap()
}

/// Asserts that `b` (the run in other units) decides as `a` and estimates θ̂_j / factor_j.
fn assert_same(a: &Decisions, b: &Decisions, factor: &[f64], names: &[&str], what: &str) {
    assert_eq!(a.onset, b.onset, "{what}: r̂");
    assert_eq!(a.rank, b.rank, "{what}: rank");
    match (a.glr, b.glr) {
        (None, None) => return,
        (Some(x), Some(y)) => assert!(close(x, y, x.abs()), "{what}: l_k {x} vs {y}"),
        _ => panic!("{what}: l_k {:?} vs {:?}", a.glr, b.glr),
    }
    // θ̂ in units of each fault's own information (θ̂_j·√C_jj), so that faults of any
    // size are compared alike; the scaled run's θ̂_j·factor_j must match.
    for (mag_a, mag_b, which) in [
        (&a.magnitude, &b.magnitude, "step"),
        (&a.fisher_magnitude, &b.fisher_magnitude, "isolation"),
    ] {
        let free = mag_a.component_mul(&a.unit);
        let scale = free.amax().max(a.glr.unwrap_or(0.0).sqrt());
        for j in 0..factor.len() {
            let back = mag_b[j] * factor[j];
            assert!(
                close(back * a.unit[j], free[j], scale),
                "{what}: {which} θ̂_{j} {} vs {} (θ̂' = {})",
                back,
                mag_a[j],
                mag_b[j]
            );
        }
    }
    assert_eq!(a.tests.len(), b.tests.len());
    for (i, (x, y)) in a.tests.iter().zip(&b.tests).enumerate() {
        assert_eq!(
            (x.1, x.3),
            (y.1, y.3),
            "{what}: test {i} degrees of freedom"
        );
        assert!(
            close(x.0, y.0, a.global),
            "{what}: minmax {i} {} vs {}",
            x.0,
            y.0
        );
        assert!(close(x.2, y.2, a.global), "{what}: sensitivity {i}");
        assert_eq!(
            isolates(x.0, x.1),
            isolates(y.0, y.1),
            "{what}: isolation {i}"
        );
    }
    let (ra, rb) = (
        a.isolability.as_ref().unwrap(),
        b.isolability.as_ref().unwrap(),
    );
    assert_eq!(ra.rank, rb.rank, "{what}: isolability rank");
    assert_eq!(ra.undetectable, rb.undetectable, "{what}: undetectable");
    let sep = |r: &IsolabilityReport| r.pairs.iter().map(|p| p.separable).collect::<Vec<_>>();
    assert_eq!(sep(ra), sep(rb), "{what}: separable pairs");
    assert_eq!(
        ra.verdicts(names, 40),
        rb.verdicts(names, 40),
        "{what}: verdicts"
    );
}

/// One case: the plant, dictionary and a fault injected at k = 60 simulated in base
/// units; a detector in base units and one in `units`, fed the same samples converted,
/// compared at every step of 140.
fn check_case(seed: u64, lti: bool, m: usize, kind: &str) {
    let mut rng = Rng::new(seed);
    let plant = random_plant(&mut rng, lti);
    let specs = random_faults(&mut rng, m);
    let (l, p) = (plant.dims.inputs, plant.dims.outputs);
    let mut units = Units::identity(m, p, l);
    match kind {
        "fault" => units.fault = (0..m).map(|_| random_scale(&mut rng)).collect(),
        "output" => units.output = (0..p).map(|_| random_scale(&mut rng)).collect(),
        "input" => units.input = (0..l).map(|_| random_scale(&mut rng)).collect(),
        _ => unreachable!("kinds are listed below"),
    }
    let base = Units::identity(m, p, l);
    let theta = DVector::from_fn(m, |_, _| rng.uniform_in(1.5, 3.0) * rng.normal().signum());
    let mut sim = Simulator::new(Box::new(plant.clone()), DVector::zeros(3), seed ^ 0x19)
        .unwrap()
        .with_inputs(Box::new(|k, u: &mut [f64]| {
            u[0] = 1.0 + (0.3 * k as f64).sin();
            u[1] = (0.17 * k as f64).cos();
        }))
        .with_fault(
            base.dictionary(plant.dims, &specs),
            Injection {
                magnitude: theta,
                onset: 60,
            },
        )
        .unwrap();
    let settings = WindowSettings {
        window: 40,
        min_lag: 2,
        ..WindowSettings::default()
    };
    let detector = |u: &Units| {
        GlrDetector::new(
            Box::new(u.plant(&plant)),
            u.dictionary(plant.dims, &specs),
            DVector::zeros(3),
            DMatrix::identity(3, 3),
            settings,
        )
        .unwrap()
    };
    let (mut da, mut db) = (detector(&base), detector(&units));
    let (mut oa, mut ob) = (StepOutput::new(p, m), StepOutput::new(p, m));
    let names: Vec<&str> = specs.iter().map(|f| f.name).collect();
    let factor = units.magnitude_factor(&specs);
    let mut alarms = 0;
    for k in 0..140 {
        let x = sim.next_sample();
        let y = units.sample(&x);
        for (det, s, out) in [(&mut da, &x, &mut oa), (&mut db, &y, &mut ob)] {
            let sample = Sample {
                k,
                u: &s.u,
                y: &s.y,
                p: &s.p,
            };
            det.step(&sample, out).unwrap();
        }
        let what = format!("seed {seed}, {kind}, m = {m}, lti {lti}, k = {k}");
        let (a, b) = (decisions(&da, &oa), decisions(&db, &ob));
        assert_same(&a, &b, &factor, &names, &what);
        alarms += usize::from(a.glr.is_some_and(|g| g > 50.0));
    }
    // The injected fault was seen: the comparison covered faulty windows too.
    assert!(alarms > 10, "seed {seed}: {alarms} steps above 50");
}

/// (a) A fault column times s (θ divided by s), for every fault with a constant
/// column, s = 10^u, u uniform in [−6, 6]: same l_k, r̂, rank, isolation decisions and
/// isolability verdicts, θ̂_j divided by s_j. Fixed seeds, LTI (stationary tables) and
/// LTV (general recursion), m = 2, 3 and 5.
#[test]
fn fault_units_change_no_decision() {
    for seed in 0..8 {
        check_case(
            1900 + seed,
            seed % 2 == 0,
            [2, 3, 5][seed as usize % 3],
            "fault",
        );
    }
}

/// (b) Output i times σ_i (y_i, rows of H, J and Φ̃, rows and columns of R): the
/// whitened innovations and signatures are unchanged, so is everything decided.
#[test]
fn output_units_change_no_decision() {
    for seed in 0..8 {
        check_case(
            1910 + seed,
            seed % 2 == 1,
            [3, 5, 2][seed as usize % 3],
            "output",
        );
    }
}

/// (c) Input i divided by s_i (columns i of G and J times s_i): the actuator-bias
/// fault, whose column is G[:, 0], has its θ divided by s₀; nothing is decided
/// differently.
#[test]
fn input_units_change_no_decision() {
    for seed in 0..8 {
        check_case(
            1920 + seed,
            seed % 2 == 0,
            [5, 2, 3][seed as usize % 3],
            "input",
        );
    }
}

// ------------------------------------------------------------ the gas pipeline

/// Mean inlet mass flow U (Nm³ per 2-minute sample) of §6.2's gas pipe: an outlet
/// bias of −43 980 Nm³ is "10 % of the average output mass flow".
const INLET_FLOW: f64 = 4.0e5;

/// The simulated outlet leak of §6.2 (Nm³), injected at the 700th minute (sample 350).
const LEAK: f64 = -43_980.0;

/// The inlet-leak fault columns of §6.2: Ψ̃ = (U_k, 0) for a change of G₀(1) and
/// (p_k·U_k, 0) for a change of G_p(1), in the natural units of the model (U in Nm³).
#[derive(Debug)]
struct InletColumn {
    scheduled: bool,
}

impl ColumnFn for InletColumn {
    fn evaluate(
        &mut self,
        _k: u64,
        signals: &Signals<'_>,
        _system: &SystemMatrices,
        out: &mut [f64],
    ) {
        let u = signals.u[0];
        out[0] = if self.scheduled { signals.p[0] * u } else { u };
        out[1] = 0.0;
    }
}

/// A plausible two-state LPV gas pipe after eq. (53): state (inlet-section mass flow,
/// pressure drop), G = G₀ + G_p·p_k with §6.2's G₀(1) = −7.8297·10⁻⁴ and
/// G_p(1) = 3.8290·10⁻⁵ (Table 1), output = outlet mass flow ≈ 1.1·U + H·X, Q of §6.2
/// (its Q₂₂ rounded up in the fourth decimal so that Q is positive semi-definite:
/// as printed, det Q = −0.004) and R = 3.0273·10⁵. F, H, J and G₀(2) are ours (the
/// identified values of the paper's reference [37] are not printed).
#[derive(Debug, Clone)]
struct GasPipe;

impl StateSpace for GasPipe {
    fn dims(&self) -> Dims {
        Dims {
            states: 2,
            inputs: 1,
            outputs: 1,
            signals: 1,
        }
    }
    fn evaluate(&mut self, _k: u64, signals: &Signals<'_>, out: &mut SystemMatrices) {
        let p = signals.p[0];
        out.f.copy_from_slice(&[0.85, 0.05, 0.10, 0.70]);
        out.g.copy_from_slice(&[-7.8297e-4 + 3.8290e-5 * p, 2.0e-4]);
        out.h.copy_from_slice(&[1.0, -0.5]);
        out.j.copy_from_slice(&[1.1]);
        out.q
            .copy_from_slice(&[100.2766, -66.1165, -66.1165, 43.5934]);
        out.r.copy_from_slice(&[3.0273e5]);
    }
}

/// Inlet flow U_k around [`INLET_FLOW`] (±25 % daily-like swing, ±10 % faster) and the
/// pressure pattern p_k around 20: the "record of 1000 min" of §6.2 is not published.
fn gas_inputs() -> (glrmon_sim::SignalFn, glrmon_sim::SignalFn) {
    use std::f64::consts::TAU;
    (
        Box::new(|k, u: &mut [f64]| {
            let t = k as f64;
            u[0] =
                INLET_FLOW * (1.0 + 0.25 * (TAU * t / 360.0).sin() + 0.1 * (TAU * t / 37.0).sin());
        }),
        Box::new(|k, p: &mut [f64]| {
            let t = k as f64;
            p[0] = 20.0 + 4.0 * (TAU * t / 250.0 + 1.0).sin() + 1.5 * (TAU * t / 23.0).sin();
        }),
    )
}

/// The dictionary of §6.2: inlet leaks as changes of G₀(1) and G_p(1) (θ ≈ 10⁻⁵,
/// columns ≈ 4·10⁵ and 8·10⁶) and the outlet leak as an output bias Φ̃ = 1 (θ ≈ −4·10⁴).
fn gas_faults() -> FaultDictionary {
    FaultDictionary::new(
        GasPipe.dims(),
        vec![
            Fault::state(
                "inlet_g0",
                Onset::Step,
                Column::Custom(Box::new(InletColumn { scheduled: false })),
            ),
            Fault::state(
                "inlet_gp",
                Onset::Step,
                Column::Custom(Box::new(InletColumn { scheduled: true })),
            ),
            Fault::output(
                "outlet_leak",
                Onset::Step,
                Column::Constant(DVector::from_vec(vec![1.0])),
            ),
        ],
    )
    .unwrap()
}

fn gas_detector() -> GlrDetector {
    // §6.2: a moving window of w = 160 samples (320 min).
    let settings = WindowSettings {
        window: 160,
        min_lag: 1,
        ..WindowSettings::default()
    };
    GlrDetector::new(
        Box::new(GasPipe),
        gas_faults(),
        DVector::zeros(2),
        DMatrix::from_row_slice(2, 2, &[100.2766, -66.1165, -66.1165, 43.5934]) * 10.0,
        settings,
    )
    .unwrap()
}

/// Zhang & Basseville 2014, §6.2 (leakage at the output end): in the natural units of
/// the gas pipe (U ≈ 4·10⁵ Nm³, inlet-fault columns (U, 0) and (p·U, 0) with θ ≈ 10⁻⁵,
/// an outlet bias Φ̃ = 1 with θ = −43 980, R = 3.0273·10⁵), the injected outlet leak
/// is detected (l_k above the paper's threshold 50 at the leak's first sample), its
/// onset found exactly, the minmax
/// test (41) at the 1 % level (threshold 6.6349) names the leak and neither inlet
/// fault, θ̂_leak is within one standard error √((F⁻¹)_leak,leak) of −43 980, and the
/// isolability report of `glrmon validate` calls the leak detectable.
///
/// With the earlier rank cut-offs relative to max_a C_aa (C_aa ≈ 10¹² for the inlet
/// faults, ≈ 10⁻⁴ for the leak) the leak's pivot was dropped, the leak was blamed on
/// the inlet faults (a user saw θ̂_leak = −0.07; here rank 2 and θ̂_leak ≈ −10⁻⁸),
/// and validate called it undetectable.
#[test]
fn gas_pipeline_outlet_leak_isolated_in_natural_units_2014_s6_2() {
    let leak_at = 350; // the 700th minute, 2-minute samples
    let (inputs, signals) = gas_inputs();
    let mut sim = Simulator::new(Box::new(GasPipe), DVector::zeros(2), 62_014)
        .unwrap()
        .with_inputs(inputs)
        .with_signals(signals)
        .with_fault(
            gas_faults(),
            Injection {
                magnitude: DVector::from_vec(vec![0.0, 0.0, LEAK]),
                onset: leak_at,
            },
        )
        .unwrap();
    let mut det = gas_detector();
    let mut out = StepOutput::new(1, 3);
    let mut first_alarm = None;
    let last = leak_at + 60;
    for k in 0..=last {
        let x = sim.next_sample();
        det.step(
            &Sample {
                k,
                u: &x.u,
                y: &x.y,
                p: &x.p,
            },
            &mut out,
        )
        .unwrap();
        if first_alarm.is_none() && out.glr.is_some_and(|g| g > 50.0) {
            first_alarm = Some(k);
        }
    }
    let alarm = first_alarm.expect("l_k crosses the paper's threshold 50");
    assert!(
        (leak_at..=leak_at + 2).contains(&alarm),
        "first alarm at {alarm}"
    );
    let onset = out.onset.unwrap();
    assert_eq!(onset, leak_at, "r̂");
    assert_eq!(out.rank, 3, "every fault keeps its pivot");

    // Minmax isolation (41) at r̂, as the monitor runs it.
    let fisher = det.fisher_statistics(onset).unwrap();
    let named: Vec<bool> = (0..3)
        .map(|j| {
            let t = fisher.minmax(&[j]).unwrap();
            assert_eq!(t.dof, 1, "fault {j}");
            isolates(t.value, t.dof)
        })
        .collect();
    assert_eq!(
        named,
        vec![false, false, true],
        "minmax tests name the leak alone"
    );
    assert!((chi2_upper_quantile(1.0, ISOLATION_ALPHA).unwrap() - 6.6349).abs() < 1e-4);

    // θ̂_leak within one standard error of −43 980. F spans 16 decades, so its inverse
    // is taken on the equilibrated F̂ = UFU (U = diag(F)^{-1/2}): F⁻¹ = UF̂⁻¹U.
    let f = fisher.information();
    let u = f.diagonal().map(|x| 1.0 / x.sqrt());
    let ud = DMatrix::from_diagonal(&u);
    let f_hat_inv = (&ud * f * &ud).try_inverse().expect("F regular");
    let se = u[2] * f_hat_inv[(2, 2)].sqrt();
    for (theta, which) in [
        (fisher.magnitude()[2], "isolation"),
        (out.magnitude[2], "step"),
    ] {
        assert!(
            (theta - LEAK).abs() <= se,
            "{which}: θ̂_leak = {theta}, standard error {se}"
        );
    }
    assert!(se < 0.05 * LEAK.abs(), "standard error {se}");
    println!(
        "2014 §6.2 units: leak θ = {LEAK}, θ̂ = {:.1} (isolation) / {:.1} (step), standard error {se:.1}",
        fisher.magnitude()[2],
        out.magnitude[2]
    );

    // `glrmon validate`'s verdict: the information of one window on fault-free data
    // with the same inputs, and the isolability report of it.
    let (inputs, signals) = gas_inputs();
    let mut clean = Simulator::new(Box::new(GasPipe), DVector::zeros(2), 7)
        .unwrap()
        .with_inputs(inputs)
        .with_signals(signals);
    let samples = std::iter::repeat_with(move || {
        let s = clean.next_sample();
        (s.u, s.y, s.p)
    });
    let window = window_information(&mut gas_detector(), samples).unwrap();
    let report = isolability(&window.information, DEFAULT_CORRELATION_LIMIT).unwrap();
    assert!(report.undetectable.is_empty(), "{:?}", report.undetectable);
    assert_eq!(report.rank, 3);
    let names = ["inlet_g0", "inlet_gp", "outlet_leak"];
    let verdicts = report.verdicts(&names, window.samples);
    assert!(
        verdicts.iter().all(|v| !v.contains("undetectable")),
        "{verdicts:?}"
    );
    // (Over one fault-free window the leak's signature is correlated with the inlet
    // faults' beyond the report's 0.95 limit, so the report says the pairs cannot be
    // told apart at every magnitude; a leak of 80 noise standard deviations still is,
    // as the minmax tests above show.)
}
