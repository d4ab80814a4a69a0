//! Seeded simulation of a channel's plant with an optional injected fault and an
//! optional PI controller, for the demo, the tests and the benchmarks.
//!
//! The plant is the faulty model of Zhang & Basseville 2014, eq. (44):
//!
//! ```text
//! X_{k+1} = F_k X_k + G_k U_k + W_k + Ψ_k(r) θ,   W_k ~ N(0, Q_k)
//! Y_k     = H_k X_k + J_k U_k + V_k + Φ_k(r) θ,   V_k ~ N(0, R_k)
//! ```
//!
//! with Ψ_k(r), Φ_k(r) built from the same [`FaultDictionary`] and [`Onset`] profiles
//! the detector uses, so a simulated fault is exactly the fault the detector looks for.
#![warn(missing_docs)]

pub mod channel;
pub mod kernel_example;
pub mod rng;
pub mod scenarios;
pub mod tank;
pub mod two_tanks;

use glrmon_core::{
    Dims, FaultDictionary, LpvMatrix, Onset, SignalScaling, Signals, StateSpace, SystemMatrices,
};
use nalgebra::{DMatrix, DVector};

pub use channel::{
    ChannelError, expression_source, fault_magnitudes, faulty_simulator, from_channel, inject,
};
pub use rng::Rng;

/// A fault to inject: which fault of the dictionary, from which sample, how large.
#[derive(Debug, Clone, PartialEq)]
pub struct Injection {
    /// θ, one magnitude per fault of the dictionary (zero for the faults not injected).
    pub magnitude: DVector<f64>,
    /// Onset r (ignored for known-profile faults, which act from the first sample).
    pub onset: u64,
}

/// A PI controller `u_k[input] = k_p e_k + I_k`, `I_{k+1} = I_k + k_i e_k`, with
/// `e_k = setpoint − y_k[output]` (the controller of Zhang & Basseville 2014, §6.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PiController {
    /// Output index measured.
    pub output: usize,
    /// Input index driven.
    pub input: usize,
    /// Setpoint.
    pub setpoint: f64,
    /// Proportional gain k_p.
    pub kp: f64,
    /// Integral gain k_i.
    pub ki: f64,
}

/// A source of known signals (inputs or exogenous signals) as a function of k.
pub type SignalFn = Box<dyn FnMut(u64, &mut [f64]) + Send>;

/// Errors of the simulator's configuration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// An index or dimension does not fit the model.
    #[error("simulator: {0}")]
    Dimension(String),
}

/// One simulated sample.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSample {
    /// Sample index k.
    pub k: u64,
    /// U_k.
    pub u: Vec<f64>,
    /// Y_k.
    pub y: Vec<f64>,
    /// p(k).
    pub p: Vec<f64>,
}

impl SimSample {
    /// The sample as the monitors and filters take it.
    #[must_use]
    pub fn sample(&self) -> glrmon_core::Sample<'_> {
        glrmon_core::Sample {
            k: self.k,
            u: &self.u,
            y: &self.y,
            p: &self.p,
        }
    }
}

/// A fault that is a function of the state ([`Simulator::with_state_fault`]).
struct StateFault {
    psi: DMatrix<f64>,
    function: Box<dyn glrmon_core::CandidateFn>,
    magnitude: f64,
    onset: u64,
    period: f64,
    value: Vec<f64>,
}

/// A seeded plant simulator.
pub struct Simulator {
    model: Box<dyn StateSpace>,
    faults: Option<FaultDictionary>,
    injection: Option<Injection>,
    /// The first sample the injected fault no longer acts on, if it ends.
    fault_end: Option<u64>,
    /// Faults that are functions of the state (the kernel method's candidates).
    state_faults: Vec<StateFault>,
    controller: Option<PiController>,
    integral: f64,
    held_control: f64,
    inputs: Option<SignalFn>,
    signals: Option<SignalFn>,
    /// E (constant or LPV), d_k, d_k's buffer and E_k's.
    unknown: Option<(LpvMatrix, SignalFn, DVector<f64>, DMatrix<f64>)>,
    /// F_d, the unknown input's effect on the outputs (p×q), when it has one.
    unknown_output: Option<DMatrix<f64>>,
    dims: Dims,
    rng: Rng,
    k: u64,
    x: DVector<f64>,
    sys: SystemMatrices,
    psi: DMatrix<f64>,
    phi: DMatrix<f64>,
    noise_w: DVector<f64>,
    noise_v: DVector<f64>,
    sqrt_q: DMatrix<f64>,
    sqrt_r: DMatrix<f64>,
    /// S = E(W_kV_kᵀ), when the noises are correlated.
    cross_covariance: Option<DMatrix<f64>>,
    /// Raw plant units ↔ model units: inputs are produced and outputs published raw.
    scaling: Option<SignalScaling>,
    /// U_k in model units (the raw U_k is the sample's).
    u_model: Vec<f64>,
}

impl std::fmt::Debug for Simulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulator")
            .field("dims", &self.dims)
            .field("k", &self.k)
            .field("injection", &self.injection)
            .field("fault_end", &self.fault_end)
            .field("controller", &self.controller)
            .finish_non_exhaustive()
    }
}

impl Simulator {
    /// A simulator of `model` started in state `x0` (X_0 is exactly `x0`; draw it from
    /// N(x̂0, P0) yourself if wanted), with noise drawn from a generator seeded by `seed`.
    ///
    /// # Errors
    /// [`SimError::Dimension`] when `x0` does not fit the model.
    pub fn new(model: Box<dyn StateSpace>, x0: DVector<f64>, seed: u64) -> Result<Self, SimError> {
        let dims = model.dims();
        if x0.len() != dims.states {
            return Err(SimError::Dimension(format!(
                "x0 has {} entries, model has {} states",
                x0.len(),
                dims.states
            )));
        }
        let (n, p) = (dims.states, dims.outputs);
        Ok(Self {
            model,
            faults: None,
            injection: None,
            fault_end: None,
            state_faults: Vec::new(),
            controller: None,
            integral: 0.0,
            held_control: 0.0,
            inputs: None,
            signals: None,
            unknown: None,
            unknown_output: None,
            dims,
            rng: Rng::new(seed),
            k: 0,
            x: x0,
            sys: SystemMatrices::zeros(dims),
            psi: DMatrix::zeros(n, 0),
            phi: DMatrix::zeros(p, 0),
            noise_w: DVector::zeros(n),
            noise_v: DVector::zeros(p),
            sqrt_q: DMatrix::zeros(n, n),
            sqrt_r: DMatrix::zeros(p, p),
            cross_covariance: None,
            scaling: None,
            u_model: Vec::new(),
        })
    }

    /// Correlated process and measurement noises, E(W_kV_kᵀ) = S (n×p): W_k is drawn as
    /// S R_k⁻¹ V_k + (Q_k − S R_k⁻¹ Sᵀ)^{1/2} ξ_k, so that cov(W_k) = Q_k and
    /// cov(W_k, V_k) = S (an identified innovation model, Q = K Re Kᵀ, S = K Re,
    /// R = Re, gives W_k = K V_k exactly).
    ///
    /// # Errors
    /// [`SimError::Dimension`] when S is not n×p.
    pub fn with_cross_covariance(mut self, s: DMatrix<f64>) -> Result<Self, SimError> {
        if s.shape() != (self.dims.states, self.dims.outputs) {
            return Err(SimError::Dimension(format!(
                "S is {}×{}, model has {} states and {} outputs",
                s.nrows(),
                s.ncols(),
                self.dims.states,
                self.dims.outputs
            )));
        }
        self.cross_covariance = Some(s);
        Ok(self)
    }

    /// Signals in the plant's raw units: U_k (from the input functions and the
    /// controller) is raw and enters the model as (U_k − offset) / scale; Y_k is
    /// computed in model units and published as offset + scale·Y_k, as a scaled
    /// channel's monitor expects (`[channels.scaling]`).
    ///
    /// # Errors
    /// [`SimError::Dimension`] when the scaling does not have the model's inputs and
    /// outputs.
    pub fn with_scaling(mut self, scaling: SignalScaling) -> Result<Self, SimError> {
        if scaling.inputs() != self.dims.inputs || scaling.outputs() != self.dims.outputs {
            return Err(SimError::Dimension(format!(
                "the scaling has {} inputs and {} outputs, model has {} and {}",
                scaling.inputs(),
                scaling.outputs(),
                self.dims.inputs,
                self.dims.outputs
            )));
        }
        self.scaling = Some(scaling);
        Ok(self)
    }

    /// Ends the injected fault at sample `end`: its additive terms act on samples
    /// r ≤ k < `end` only, Φ_k(r)θ on Y_k for k < `end` and Ψ_k(r)θ on X_{k+1} for
    /// k + 1 < `end` (Zhang & Basseville 2014, eq. (44), with the profile cut off), as an
    /// intermittent fault or an actuator stuck for a while and then released. What the
    /// fault did to the state before `end` dies out with the plant's own dynamics.
    #[must_use]
    pub fn with_fault_end(mut self, end: u64) -> Self {
        self.fault_end = Some(end);
        self
    }

    /// Injects a fault that is a function of the state, f_k = θ·φ(t_k, X_k, U_k) with
    /// t_k = k·`period`, entering the state through `psi` (n × the length of φ) from
    /// sample `onset` on: X_{k+1} += Ψ f_k (until [`Simulator::with_fault_end`]). For
    /// a continuous-time fault channel E sampled by zero-order hold, Ψ = ∫₀ᵀe^{As}ds·E:
    /// the fault held over each period at its value at the sample.
    ///
    /// # Errors
    /// [`SimError::Dimension`] when `psi` does not have n rows.
    pub fn with_state_fault(
        mut self,
        psi: DMatrix<f64>,
        function: Box<dyn glrmon_core::CandidateFn>,
        magnitude: f64,
        onset: u64,
        period: f64,
    ) -> Result<Self, SimError> {
        if psi.nrows() != self.dims.states {
            return Err(SimError::Dimension(format!(
                "the state fault's Ψ has {} rows, the model {} states",
                psi.nrows(),
                self.dims.states
            )));
        }
        let value = vec![0.0; psi.ncols()];
        self.state_faults.push(StateFault {
            psi,
            function,
            magnitude,
            onset,
            period,
            value,
        });
        Ok(self)
    }

    /// Injects `injection` of the faults in `faults` (a dictionary built like the
    /// detector's).
    ///
    /// # Errors
    /// [`SimError::Dimension`] when θ's length differs from the number of faults or the
    /// dictionary was built for other dimensions.
    pub fn with_fault(
        mut self,
        faults: FaultDictionary,
        injection: Injection,
    ) -> Result<Self, SimError> {
        if faults.dims() != self.dims {
            return Err(SimError::Dimension(
                "fault dictionary built for other dimensions".into(),
            ));
        }
        if injection.magnitude.len() != faults.len() {
            return Err(SimError::Dimension(format!(
                "θ has {} entries, dictionary has {} faults",
                injection.magnitude.len(),
                faults.len()
            )));
        }
        let m = faults.len();
        self.psi = DMatrix::zeros(self.dims.states, m);
        self.phi = DMatrix::zeros(self.dims.outputs, m);
        self.faults = Some(faults);
        self.injection = Some(injection);
        Ok(self)
    }

    /// Closes the loop with a PI controller. The driven input must not feed through to
    /// the outputs (J[:, input] = 0), or the loop would be algebraic. In closed loop the
    /// fault columns see the driven input's previous value (it is computed from Y_k).
    ///
    /// # Errors
    /// [`SimError::Dimension`] for indices beyond the model's inputs or outputs.
    pub fn with_controller(mut self, controller: PiController) -> Result<Self, SimError> {
        if controller.input >= self.dims.inputs || controller.output >= self.dims.outputs {
            return Err(SimError::Dimension(format!(
                "controller drives u{} from y{}, model has {} inputs and {} outputs",
                controller.input, controller.output, self.dims.inputs, self.dims.outputs
            )));
        }
        self.controller = Some(controller);
        Ok(self)
    }

    /// Open-loop inputs U_k as a function of k (default: zero).
    #[must_use]
    pub fn with_inputs(mut self, inputs: SignalFn) -> Self {
        self.inputs = Some(inputs);
        self
    }

    /// Exogenous signals p(k) as a function of k (default: zero).
    #[must_use]
    pub fn with_signals(mut self, signals: SignalFn) -> Self {
        self.signals = Some(signals);
        self
    }

    /// An unknown input E_kd_k added to the state equation (Zhang 2021, eq. (1)): the
    /// detector does not see d_k. E_k is `e` evaluated at the sample's signals p(k)
    /// ([`LpvMatrix::constant`] for a constant E).
    ///
    /// # Errors
    /// [`SimError::Dimension`] when E does not have n rows.
    pub fn with_unknown_input(mut self, e: LpvMatrix, d: SignalFn) -> Result<Self, SimError> {
        let (rows, cols) = e.shape();
        if rows != self.dims.states {
            return Err(SimError::Dimension(format!(
                "E has {rows} rows, model has {} states",
                self.dims.states
            )));
        }
        let at_k = e.base().clone();
        self.unknown = Some((e, d, DVector::zeros(cols), at_k));
        Ok(self)
    }

    /// The unknown input's effect on the outputs, Y_k gets + F_d d_k (Ahmad &
    /// Mohd-Mokhtar 2021, eq. (2)), with the d_k of [`Simulator::with_unknown_input`].
    ///
    /// # Errors
    /// [`SimError::Dimension`] without an unknown input, or when F_d is not p×q.
    pub fn with_unknown_input_on_outputs(mut self, fd: DMatrix<f64>) -> Result<Self, SimError> {
        let Some((e, ..)) = &self.unknown else {
            return Err(SimError::Dimension(
                "F_d needs the unknown input d_k of with_unknown_input".into(),
            ));
        };
        if fd.shape() != (self.dims.outputs, e.shape().1) {
            return Err(SimError::Dimension(format!(
                "F_d is {}×{}, expected {}×{} (outputs × unknown inputs)",
                fd.nrows(),
                fd.ncols(),
                self.dims.outputs,
                e.shape().1
            )));
        }
        self.unknown_output = Some(fd);
        Ok(self)
    }

    /// The model's dimensions.
    #[must_use]
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// The true state X_k of the next sample.
    #[must_use]
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }

    /// Simulates the next sample into `out` (vectors resized on first use).
    pub fn next_into(&mut self, out: &mut SimSample) {
        let d = self.dims;
        let k = self.k;
        out.k = k;
        out.u.resize(d.inputs, 0.0);
        out.y.resize(d.outputs, 0.0);
        out.p.resize(d.signals, 0.0);
        match &mut self.inputs {
            Some(f) => f(k, &mut out.u),
            None => out.u.iter_mut().for_each(|x| *x = 0.0),
        }
        if let Some(c) = self.controller {
            out.u[c.input] = self.held_control;
        }
        match &mut self.signals {
            Some(f) => f(k, &mut out.p),
            None => out.p.iter_mut().for_each(|x| *x = 0.0),
        }
        self.u_model.clear();
        self.u_model.extend_from_slice(&out.u);
        if let Some(s) = &self.scaling {
            s.input_to_model(&mut self.u_model);
        }
        let signals = Signals {
            u: &self.u_model,
            p: &out.p,
        };
        self.model.evaluate(k, &signals, &mut self.sys);
        if let Some(f) = &mut self.faults {
            f.evaluate(
                k,
                &signals,
                &self.sys,
                self.psi.as_mut_slice(),
                self.phi.as_mut_slice(),
            );
        }
        // d_k, shared by both equations.
        if let Some((e, d, buf, at_k)) = &mut self.unknown {
            d(k, buf.as_mut_slice());
            e.evaluate_into(&out.p, at_k);
        }
        // Y_k
        psd_sqrt(&self.sys.r, &mut self.sqrt_r);
        for v in self.noise_v.iter_mut() {
            *v = self.rng.normal();
        }
        let v = &self.sqrt_r * &self.noise_v;
        let mut u = DVector::from_column_slice(&self.u_model);
        let mut y = &self.sys.h * &self.x + &self.sys.j * &u + &v;
        if let (Some(fd), Some((_, _, buf, _))) = (&self.unknown_output, &self.unknown) {
            y += fd * buf;
        }
        if let (Some(f), Some(inj)) = (&self.faults, &self.injection)
            && self.fault_end.is_none_or(|e| k < e)
        {
            for (j, fault) in f.faults().iter().enumerate() {
                let factor = profile_factor(fault.onset, k, inj.onset, false);
                if factor != 0.0 {
                    y += self.phi.column(j) * (factor * inj.magnitude[j]);
                }
            }
        }
        out.y.copy_from_slice(y.as_slice());
        if let Some(s) = &self.scaling {
            s.to_raw(&mut [], &mut out.y);
        }
        // Closed loop: U_k from Y_k, both raw.
        if let Some(c) = self.controller {
            let e = c.setpoint - out.y[c.output];
            let control = c.kp * e + self.integral;
            self.integral += c.ki * e;
            out.u[c.input] = control;
            self.held_control = control;
            u[c.input] = match &self.scaling {
                Some(s) => (control - s.u_offset()[c.input]) / s.u_scale()[c.input],
                None => control,
            };
        }
        // X_{k+1}
        psd_sqrt(&self.sys.q, &mut self.sqrt_q);
        for w in self.noise_w.iter_mut() {
            *w = self.rng.normal();
        }
        let w = match &self.cross_covariance {
            None => &self.sqrt_q * &self.noise_w,
            Some(cross) => {
                // S R⁻¹ through R's Cholesky factor; R is positive definite (validated).
                let gain = self.sys.r.clone().cholesky().map_or_else(
                    || DMatrix::zeros(cross.nrows(), cross.ncols()),
                    |ch| ch.solve(&cross.transpose()).transpose(),
                );
                let conditional = &self.sys.q - &gain * cross.transpose();
                psd_sqrt(&conditional, &mut self.sqrt_q);
                &gain * &v + &self.sqrt_q * &self.noise_w
            }
        };
        let mut x = &self.sys.f * &self.x + &self.sys.g * &u + w;
        if let Some((_, _, buf, at_k)) = &self.unknown {
            x += at_k * buf;
        }
        if let (Some(f), Some(inj)) = (&self.faults, &self.injection)
            && self.fault_end.is_none_or(|e| k + 1 < e)
        {
            for (j, fault) in f.faults().iter().enumerate() {
                let factor = profile_factor(fault.onset, k, inj.onset, true);
                if factor != 0.0 {
                    x += self.psi.column(j) * (factor * inj.magnitude[j]);
                }
            }
        }
        if self.fault_end.is_none_or(|e| k + 1 < e) {
            for sf in &mut self.state_faults {
                if k >= sf.onset {
                    sf.function.evaluate(
                        k as f64 * sf.period,
                        self.x.as_slice(),
                        &self.u_model,
                        &mut sf.value,
                    );
                    for (j, v) in sf.value.iter().enumerate() {
                        x += sf.psi.column(j) * (sf.magnitude * v);
                    }
                }
            }
        }
        self.x = x;
        self.k += 1;
    }

    /// Simulates the next sample.
    #[must_use = "allocates a sample; next_into reuses one"]
    pub fn next_sample(&mut self) -> SimSample {
        let mut s = SimSample {
            k: 0,
            u: Vec::new(),
            y: Vec::new(),
            p: Vec::new(),
        };
        self.next_into(&mut s);
        s
    }
}

/// Factor of Ψ̃_k (state) or Φ̃_k (output) at sample k for a fault with onset r.
fn profile_factor(kind: Onset, k: u64, r: u64, state: bool) -> f64 {
    if kind == Onset::Known {
        return 1.0;
    }
    if state && k + 1 == r {
        return kind.entry_factor();
    }
    if k < r {
        return 0.0;
    }
    if state {
        kind.state_factor(k - r)
    } else {
        kind.output_factor(k - r)
    }
}

/// A square root S of a symmetric positive semi-definite matrix (S Sᵀ = A): Cholesky
/// with zero pivots dropped, so rank-deficient noise covariances (e.g. noise entering
/// through one column) are fine.
fn psd_sqrt(a: &DMatrix<f64>, s: &mut DMatrix<f64>) {
    let n = a.nrows();
    s.fill(0.0);
    let scale = (0..n).map(|i| a[(i, i)].abs()).fold(0.0, f64::max);
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= s[(j, k)] * s[(j, k)];
        }
        if d <= 1e-14 * scale {
            continue;
        }
        let l = d.sqrt();
        s[(j, j)] = l;
        for i in (j + 1)..n {
            let mut v = a[(i, j)];
            for k in 0..j {
                v -= s[(i, k)] * s[(j, k)];
            }
            s[(i, j)] = v / l;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psd_sqrt_handles_rank_one() {
        let e = DVector::from_vec(vec![-1.5537, 0.0]);
        let a = &e * e.transpose() * 0.0012;
        let mut s = DMatrix::zeros(2, 2);
        psd_sqrt(&a, &mut s);
        assert!((&s * s.transpose() - &a).amax() < 1e-15);
    }

    #[test]
    fn same_seed_gives_same_samples() {
        let run = || {
            let sc = scenarios::paper2014_unstable();
            let mut sim = sc.simulator(3).unwrap();
            (0..50).map(|_| sim.next_sample()).collect::<Vec<_>>()
        };
        assert_eq!(run(), run());
    }
}
