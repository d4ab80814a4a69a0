//! A configured channel ([`glrmon_spec::Channel`]) as a [`Simulator`]: the channel's
//! model started at X_0 = x̂_0, its `simulation` expressions for the inputs U_k, the
//! signals p(k) and the unknown input d_k, its PI controller, and optionally a fault of
//! its own dictionary injected.
//!
//! Every consumer of a configuration (`glrmon simulate`, the demo, calibration,
//! evaluation, the paper examples) simulates through these functions, so that the same
//! configuration and seed give the same samples everywhere.

use glrmon_core::ModelError;
use glrmon_spec::Channel;
use glrmon_spec::expr::{Env, Expr, RandomSource, SignalHistory};
use nalgebra::DVector;

use crate::{Injection, PiController, Rng, SignalFn, SimError, Simulator};

/// Seed offsets of the independent random streams of the inputs, the signals and the
/// unknown input (the noise uses the seed itself).
const INPUT_STREAM: u64 = 0x1111_1111_1111_1111;
const SIGNAL_STREAM: u64 = 0x2222_2222_2222_2222;
const UNKNOWN_INPUT_STREAM: u64 = 0x3333_3333_3333_3333;

/// Why a channel's simulator could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ChannelError {
    /// The simulator rejected the channel's dimensions.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The channel's fault dictionary could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A fault name is not in the channel's dictionary.
    #[error("channel \"{channel}\" has no fault \"{name}\" (faults: {})", faults.join(", "))]
    UnknownFault {
        /// The channel's name.
        channel: String,
        /// The name asked for.
        name: String,
        /// The channel's fault names, in dictionary order.
        faults: Vec<String>,
    },
}

/// The expressions' random draws (`uniform`, `normal`) from a seeded [`Rng`].
struct ExprRandom(Rng);

impl RandomSource for ExprRandom {
    fn uniform(&mut self) -> f64 {
        self.0.uniform()
    }
    fn normal(&mut self) -> f64 {
        self.0.normal()
    }
}

/// A signal source that evaluates `exprs` at each k, entry i from `exprs[i]` (entries
/// beyond the list are 0), with its own random stream seeded by `seed` so that adding a
/// random expression to one source leaves the others' draws unchanged.
#[must_use]
pub fn expression_source(exprs: Vec<Expr>, seed: u64) -> SignalFn {
    let mut random = ExprRandom(Rng::new(seed));
    let history = SignalHistory::new(0, 0, 0);
    Box::new(move |k, out: &mut [f64]| {
        for (o, e) in out
            .iter_mut()
            .zip(exprs.iter().map(Some).chain(std::iter::repeat(None)))
        {
            *o = match e {
                Some(e) => e.eval(&mut Env {
                    k,
                    u: &[],
                    p: &[],
                    history: &history,
                    random: Some(&mut random),
                }),
                None => 0.0,
            };
        }
    })
}

/// The fault-free simulator of `channel`: X_0 = x̂_0, the `simulation` plan's inputs,
/// signals, controller and unknown input (through E, when the channel has one), noise
/// (correlated through S, when given) and expressions drawn from independent streams
/// derived from `seed`. With `[channels.scaling]` the plan's inputs and the published
/// outputs are in raw units, as the plant's would be.
///
/// # Errors
/// [`SimError::Dimension`] when x̂_0, the controller or E do not fit the model.
pub fn from_channel(channel: &Channel, seed: u64) -> Result<Simulator, SimError> {
    let plan = &channel.simulation;
    let mut sim = Simulator::new(Box::new(channel.model.clone()), channel.x0.clone(), seed)?
        .with_inputs(expression_source(plan.inputs.clone(), seed ^ INPUT_STREAM))
        .with_signals(expression_source(
            plan.signals.clone(),
            seed ^ SIGNAL_STREAM,
        ));
    if let Some(c) = plan.controller {
        sim = sim.with_controller(PiController {
            output: c.output,
            input: c.input,
            setpoint: c.setpoint,
            kp: c.kp,
            ki: c.ki,
        })?;
    }
    if let Some(s) = &channel.cross_covariance {
        sim = sim.with_cross_covariance(s.clone())?;
    }
    if let Some(s) = &channel.scaling {
        sim = sim.with_scaling(s.clone())?;
    }
    if let Some(e) = &channel.unknown_input {
        sim = sim.with_unknown_input(
            e.clone(),
            expression_source(plan.unknown_input.clone(), seed ^ UNKNOWN_INPUT_STREAM),
        )?;
        if let Some(fd) = &channel.unknown_input_outputs {
            sim = sim.with_unknown_input_on_outputs(fd.clone())?;
        }
    }
    Ok(sim)
}

/// θ with `magnitudes[i]` at the dictionary index of the fault named `faults[i]` and 0
/// elsewhere (a name given twice keeps its last magnitude). Pairs beyond the shorter
/// list are ignored.
///
/// # Errors
/// [`ChannelError::UnknownFault`] for a name not in the channel's dictionary.
pub fn fault_magnitudes(
    channel: &Channel,
    faults: &[String],
    magnitudes: &[f64],
) -> Result<DVector<f64>, ChannelError> {
    let mut theta = DVector::zeros(channel.fault_names.len());
    for (name, v) in faults.iter().zip(magnitudes) {
        let j = channel
            .fault_names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| ChannelError::UnknownFault {
                channel: channel.name.clone(),
                name: name.clone(),
                faults: channel.fault_names.clone(),
            })?;
        theta[j] = *v;
    }
    Ok(theta)
}

/// `sim` with `injection` of the channel's own fault dictionary: the simulated fault is
/// exactly the one the channel's detector looks for.
///
/// # Errors
/// [`ChannelError::Model`] when the dictionary cannot be built, [`ChannelError::Sim`]
/// when θ does not have one entry per fault.
pub fn inject(
    sim: Simulator,
    channel: &Channel,
    injection: Injection,
) -> Result<Simulator, ChannelError> {
    Ok(sim.with_fault(channel.dictionary()?, injection)?)
}

/// The channel's simulator ([`from_channel`], noise seeded with `seed`) with the
/// faults named in `faults` injected from `onset` at the given magnitudes (none for an
/// empty list): the one set-up `glrmon simulate`, `demo`, `evaluate` and calibration
/// share.
///
/// # Errors
/// [`ChannelError::UnknownFault`] for a name not in the dictionary (the caller's
/// input), [`ChannelError::Sim`] or [`ChannelError::Model`] when the simulator cannot
/// be built.
pub fn faulty_simulator(
    channel: &Channel,
    seed: u64,
    faults: &[(String, f64)],
    onset: u64,
) -> Result<Simulator, ChannelError> {
    let sim = from_channel(channel, seed)?;
    if faults.is_empty() {
        return Ok(sim);
    }
    // A kernel section's candidates are functions of the state; the other names are
    // the dictionary's.
    let is_candidate = |name: &str| {
        channel
            .kernel
            .as_ref()
            .is_some_and(|k| k.candidates.iter().any(|c| c.name == name))
    };
    let mut candidates = Vec::new();
    let mut dictionary = Vec::new();
    for fault in faults {
        if is_candidate(&fault.0) {
            candidates.push(fault.clone());
        } else {
            dictionary.push(fault.clone());
        }
    }
    let mut sim = sim;
    if let Some(kernel) = &channel.kernel
        && !candidates.is_empty()
    {
        sim = inject_candidates(sim, channel, kernel, &candidates, onset)?;
    }
    if dictionary.is_empty() {
        return Ok(sim);
    }
    let (names, magnitudes): (Vec<String>, Vec<f64>) = dictionary.into_iter().unzip();
    let magnitude = fault_magnitudes(channel, &names, &magnitudes)?;
    inject(sim, channel, Injection { magnitude, onset })
}

/// The `kernel` kind's faults: each named candidate φᵢ(t, x, u), times its magnitude,
/// through the fault channels E sampled by zero-order hold (Ψ = ∫₀ᵀe^{As}ds·E, the
/// fault held over each period at its value at the sample).
fn inject_candidates(
    mut sim: Simulator,
    channel: &Channel,
    kernel: &glrmon_spec::KernelChannelSettings,
    faults: &[(String, f64)],
    onset: u64,
) -> Result<Simulator, ChannelError> {
    let period = kernel.settings.period;
    let (_, psi) =
        glrmon_core::model::continuous::zero_order_hold(&kernel.model.a, &kernel.model.e, period)
            .map_err(|e| SimError::Dimension(format!("the fault channels E: {e}")))?;
    let mut candidates = kernel.candidates(channel.dims.inputs);
    for (name, magnitude) in faults {
        let i = candidates
            .iter()
            .position(|c| &c.name == name)
            .ok_or_else(|| ChannelError::UnknownFault {
                channel: channel.name.clone(),
                name: name.clone(),
                faults: channel.fault_names.clone(),
            })?;
        let candidate = candidates.swap_remove(i);
        sim = sim.with_state_fault(psi.clone(), candidate.function, *magnitude, onset, period)?;
    }
    Ok(sim)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SimSample;

    const CONFIG: &str = r#"
[[channels]]
name = "plant"

[channels.model]
F = [[0.5]]
G = [[1.0]]
H = [[1.0]]
Q = 0.01
R = 0.01

[channels.simulation]
inputs = ["1 + normal(0, 1)"]

[[channels.faults]]
name = "bias"
kind = "actuator_bias"
input = 0
"#;

    fn channel() -> Channel {
        let cfg = glrmon_spec::parse(CONFIG).expect("valid configuration");
        cfg.channels[0].clone()
    }

    fn run(mut sim: Simulator, n: usize) -> Vec<SimSample> {
        (0..n).map(|_| sim.next_sample()).collect()
    }

    #[test]
    fn same_seed_same_samples_other_seed_other_inputs() {
        let c = channel();
        let a = run(from_channel(&c, 7).unwrap(), 20);
        assert_eq!(a, run(from_channel(&c, 7).unwrap(), 20));
        assert_ne!(a, run(from_channel(&c, 8).unwrap(), 20));
    }

    #[test]
    fn inputs_follow_their_expression_stream() {
        // U_k = 1 + N(0, 1) from the input stream seeded by seed ^ INPUT_STREAM.
        let c = channel();
        let mut rng = Rng::new(7 ^ INPUT_STREAM);
        for s in run(from_channel(&c, 7).unwrap(), 10) {
            assert_eq!(s.u, vec![1.0 + rng.normal()]);
        }
    }

    #[test]
    fn injected_bias_shifts_the_output_by_the_dc_gain() {
        // x_{k+1} = 0.5 x_k + u_k + w_k + θ: with the same seed both runs draw the same
        // noise, so once settled the outputs differ by the bias's DC gain θ / (1 − 0.5).
        let c = channel();
        let theta = fault_magnitudes(&c, &["bias".to_owned()], &[3.0]).unwrap();
        assert_eq!(theta.as_slice(), &[3.0]);
        let faulty = inject(
            from_channel(&c, 7).unwrap(),
            &c,
            Injection {
                magnitude: theta,
                onset: 0,
            },
        )
        .unwrap();
        let (clean, faulty) = (run(from_channel(&c, 7).unwrap(), 60), run(faulty, 60));
        let shift = faulty[59].y[0] - clean[59].y[0];
        assert!((shift - 6.0).abs() < 1e-9, "shift {shift}");
    }

    /// An actuator bias from r = 5, released at 15 (`with_fault_end(15)`): X_{k+1} gets
    /// θ for k = 5 … 13 (Ψ_k(r)θ on X_{k+1} for r ≤ k and k + 1 < 15), so the outputs
    /// differ from the fault-free run's by θ·Σ 0.5^i over the steps taken, growing to
    /// Y_14 and halving each sample after: exactly, with the same noise.
    #[test]
    fn an_ended_fault_acts_from_its_onset_to_its_end_only() {
        let c = channel();
        let theta = fault_magnitudes(&c, &["bias".to_owned()], &[3.0]).unwrap();
        let faulty = inject(
            from_channel(&c, 7).unwrap(),
            &c,
            Injection {
                magnitude: theta,
                onset: 5,
            },
        )
        .unwrap()
        .with_fault_end(15);
        let (clean, faulty) = (run(from_channel(&c, 7).unwrap(), 30), run(faulty, 30));
        let mut expected = 0.0;
        for k in 0..30 {
            let shift = faulty[k].y[0] - clean[k].y[0];
            assert!(
                (shift - expected).abs() < 1e-9,
                "k = {k}: {shift} vs {expected}"
            );
            expected = 0.5 * expected + if (5..14).contains(&k) { 3.0 } else { 0.0 };
        }
        assert!((faulty[29].y[0] - clean[29].y[0]).abs() < 1e-3, "released");
    }

    /// `model.Fd`: the unknown input d_k reaches the outputs as Fd d_k (survey eq. (2))
    /// and the state as E d_k; with E = 0 and d_k = 2 + k the first output differs from
    /// the run without Fd by exactly 3(2 + k) and the second not at all (the same seeds,
    /// the same noise).
    #[test]
    fn the_unknown_input_reaches_the_outputs_through_fd() {
        let config = |fd: &str| {
            format!(
                r#"
[[channels]]
name = "plant"
[channels.model]
F = [[0.5, 0.0], [0.0, 0.5]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = 0.01
R = 0.01
E = [[0.0], [0.0]]
{fd}
[channels.glr]
detector = "parity"
[channels.simulation]
unknown_input = ["2 + k"]
[[channels.faults]]
name = "bias"
kind = "sensor_bias"
output = 1
"#
            )
        };
        let with = glrmon_spec::parse(&config("Fd = [[3.0], [0.0]]")).unwrap();
        let without = glrmon_spec::parse(&config("")).unwrap();
        let a = run(from_channel(&with.channels[0], 4).unwrap(), 20);
        let b = run(from_channel(&without.channels[0], 4).unwrap(), 20);
        for (k, (a, b)) in a.iter().zip(&b).enumerate() {
            assert!(
                (a.y[0] - b.y[0] - 3.0 * (2.0 + k as f64)).abs() < 1e-9,
                "k = {k}"
            );
            assert_eq!(a.y[1], b.y[1]);
        }
    }

    #[test]
    fn unknown_fault_names_the_dictionary() {
        let c = channel();
        let err = fault_magnitudes(&c, &["nope".to_owned()], &[1.0]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "channel \"plant\" has no fault \"nope\" (faults: bias)"
        );
    }

    /// An innovation model x⁺ = Ax + Ke, y = Cx + e written Q = K·Re·Kᵀ, S = K·Re,
    /// R = Re: the simulated W_k must equal K·V_k, so the exact predictor's innovation
    /// is V_k itself and its normalised square has mean p (here 2). Independent noises
    /// with the same Q and R would leave the filter with a larger, coloured innovation.
    #[test]
    fn correlated_noises_follow_the_cross_covariance() {
        // K = [[0.5, 0.1], [0.0, 0.3]], Re = diag(1, 4): K·Re = [[0.5, 0.4], [0, 1.2]],
        // K·Re·Kᵀ = [[0.29, 0.12], [0.12, 0.36]].
        let text = r#"
[[channels]]
name = "innovation"
[channels.model]
F = [[0.9, 0.2], [0.0, 0.7]]
H = [[1.0, 0.0], [0.0, 1.0]]
Q = [[0.29, 0.12], [0.12, 0.36]]
R = [[1.0, 0.0], [0.0, 4.0]]
S = [[0.5, 0.4], [0.0, 1.2]]
P0 = 1e-9
[[channels.faults]]
kind = "all_sensors"
"#;
        let c = glrmon_spec::parse(text).unwrap().channels[0].clone();
        let mut sim = from_channel(&c, 5).unwrap();
        let mut detector = c.glr_detector().unwrap();
        let mut out = glrmon_core::StepOutput::new(2, detector.fault_count());
        let n = 20_000;
        let mut nis = 0.0;
        for _ in 0..n {
            let x = sim.next_sample();
            detector.step(&x.sample(), &mut out).unwrap();
            nis += out.normalized_innovation;
        }
        // NIS ~ χ²(2): variance 4, so the mean's σ is √(4/n) = 0.014.
        let mean = nis / f64::from(n);
        assert!(
            (mean - 2.0).abs() < 4.0 * (4.0 / f64::from(n)).sqrt(),
            "mean NIS {mean}"
        );
    }

    /// A kernel channel's candidate is injected as a function of the simulated state:
    /// the same noise until the onset, then the states part by Ψ·φ(x) (φ₂'s second
    /// entry, 20e^{−|x₃|}, is far from zero near x₃ = 0).
    #[test]
    fn kernel_candidates_are_injected_as_functions_of_the_state() {
        let cfg = glrmon_spec::parse(include_str!(
            "../../../config/examples/kernel-paper-low-noise.toml"
        ))
        .unwrap();
        let channel = &cfg.channels[0];
        let mut clean = faulty_simulator(channel, 3, &[], 0).unwrap();
        let mut faulty = faulty_simulator(channel, 3, &[("phi2".into(), 1.0)], 100).unwrap();
        for k in 0..300 {
            let (a, b) = (clean.next_sample(), faulty.next_sample());
            if k <= 100 {
                assert_eq!(a, b, "k = {k}");
            } else {
                assert_ne!(a.y, b.y, "k = {k}");
            }
        }
        let err = faulty_simulator(channel, 3, &[("phi3".into(), 1.0)], 100).unwrap_err();
        assert!(err.to_string().contains("no fault \"phi3\""), "{err}");
    }
}
