//! Ready-made channels: the papers' examples and the benchmark plants.

use glrmon_core::{
    Column, Fault, FaultDictionary, GlrDetector, Lpv, LpvMatrix, ModelError, Onset, StateSpace,
    WindowSettings,
};
use nalgebra::{DMatrix, DVector};

use crate::{Injection, PiController, SignalFn, SimError, Simulator};

/// A fault of a scenario: name, onset profile, Ψ̃ column (or none), Φ̃ column (or none).
pub type FaultColumns = (String, Onset, Option<DVector<f64>>, Option<DVector<f64>>);

/// A channel: model, fault dictionary, filter start, window, and how it is driven.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The model.
    pub model: Lpv,
    /// The faults as (name, onset profile, Ψ̃ column or None, Φ̃ column or None).
    pub faults: Vec<FaultColumns>,
    /// X̂_0.
    pub x0: DVector<f64>,
    /// P_0.
    pub p0: DMatrix<f64>,
    /// GLR window.
    pub window: WindowSettings,
    /// Optional PI controller.
    pub controller: Option<PiController>,
    /// Open-loop input U_k = `input(k)` (all inputs), if any.
    pub input: Option<fn(u64, &mut [f64])>,
    /// Exogenous signals p(k), if any.
    pub signals: Option<fn(u64, &mut [f64])>,
}

impl Scenario {
    /// n, the number of states.
    #[must_use]
    pub fn model_states(&self) -> usize {
        self.model.dims().states
    }

    /// p, the number of outputs.
    #[must_use]
    pub fn model_outputs(&self) -> usize {
        self.model.dims().outputs
    }

    /// A fresh fault dictionary (the dictionary owns per-channel state, so the detector
    /// and the simulator each get their own).
    ///
    /// # Errors
    /// As [`FaultDictionary::new`].
    pub fn dictionary(&self) -> Result<FaultDictionary, ModelError> {
        let col = |c: &Option<DVector<f64>>| c.clone().map_or(Column::Zero, Column::Constant);
        let faults = self
            .faults
            .iter()
            .map(|(name, onset, psi, phi)| Fault {
                name: name.clone(),
                onset: *onset,
                state: col(psi),
                output: col(phi),
            })
            .collect();
        FaultDictionary::new(self.model.dims(), faults)
    }

    /// The detector of this channel.
    ///
    /// # Errors
    /// As [`GlrDetector::new`].
    pub fn detector(&self) -> Result<GlrDetector, ModelError> {
        GlrDetector::new(
            Box::new(self.model.clone()),
            self.dictionary()?,
            self.x0.clone(),
            self.p0.clone(),
            self.window,
        )
    }

    /// A fault-free simulator started at X_0 = x̂_0.
    ///
    /// # Errors
    /// As [`Simulator::new`].
    pub fn simulator(&self, seed: u64) -> Result<Simulator, SimError> {
        let mut sim = Simulator::new(Box::new(self.model.clone()), self.x0.clone(), seed)?;
        if let Some(c) = self.controller {
            sim = sim.with_controller(c)?;
        }
        if let Some(f) = self.input {
            let f: SignalFn = Box::new(f);
            sim = sim.with_inputs(f);
        }
        if let Some(f) = self.signals {
            let f: SignalFn = Box::new(f);
            sim = sim.with_signals(f);
        }
        Ok(sim)
    }

    /// A simulator with fault `name` of magnitude `magnitude` from sample `onset`.
    ///
    /// # Errors
    /// [`SimError::Dimension`] for an unknown fault name.
    pub fn faulty_simulator(
        &self,
        seed: u64,
        name: &str,
        onset: u64,
        magnitude: f64,
    ) -> Result<Simulator, SimError> {
        let j = self
            .faults
            .iter()
            .position(|f| f.0 == name)
            .ok_or_else(|| SimError::Dimension(format!("no fault named \"{name}\"")))?;
        let mut theta = DVector::zeros(self.faults.len());
        theta[j] = magnitude;
        self.simulator(seed)?.with_fault(
            self.dictionary()
                .map_err(|e| SimError::Dimension(e.to_string()))?,
            Injection {
                magnitude: theta,
                onset,
            },
        )
    }
}

fn m(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_row_slice(rows, cols, v)
}

/// The unstable plant of Zhang & Basseville 2014, §6.1 (eqs. (51)-(52)): F =
/// [[0.5, 1], [0, 1.2]] (eigenvalues 0.5 and 1.2 > 1; the paper's text says 1.2808,
/// which this printed F does not have), G = [0, 1]ᵀ, H = [1, 0], Q = 0.0025 I,
/// R = 0.0025, closed by the PI controller u_k = 0.209 e_k + I_k, I_{k+1} = I_k +
/// 0.0011 e_k, e_k = 1 − y_k; impulse faults on each state (Ψ̃ = e₁, e₂); w = 100, s = 1.
#[must_use]
pub fn paper2014_unstable() -> Scenario {
    let model = Lpv::lti(
        m(2, 2, &[0.5, 1.0, 0.0, 1.2]),
        m(2, 1, &[0.0, 1.0]),
        m(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(1, 1),
        DMatrix::identity(2, 2) * 0.0025,
        m(1, 1, &[0.0025]),
    )
    .expect("static model is valid");
    Scenario {
        model,
        faults: vec![
            (
                "x0_jump".into(),
                Onset::Impulse,
                Some(DVector::from_vec(vec![1.0, 0.0])),
                None,
            ),
            (
                "x1_jump".into(),
                Onset::Impulse,
                Some(DVector::from_vec(vec![0.0, 1.0])),
                None,
            ),
        ],
        x0: DVector::from_vec(vec![1.0, 0.5]),
        p0: DMatrix::identity(2, 2) * 0.0025,
        window: WindowSettings {
            window: 100,
            min_lag: 1,
            ..WindowSettings::default()
        },
        controller: Some(PiController {
            output: 0,
            input: 0,
            setpoint: 1.0,
            kp: 0.209,
            ki: 0.0011,
        }),
        input: None,
        signals: None,
    }
}

/// bench-A: an LPV channel, n = 2, p = 1, m = 2 step faults (actuator bias, sensor
/// bias), one scheduling signal p0(k) = sin(0.01k), input u0(k) = sin(0.05k), w = 100.
#[must_use]
pub fn bench_a() -> Scenario {
    let f = LpvMatrix::new(
        m(2, 2, &[0.8, 0.1, -0.2, 0.7]),
        vec![(0, m(2, 2, &[0.05, 0.0, 0.0, -0.05]))],
    )
    .expect("shapes agree");
    let h = LpvMatrix::new(m(1, 2, &[1.0, 0.0]), vec![(0, m(1, 2, &[0.0, 0.1]))])
        .expect("shapes agree");
    let c = LpvMatrix::constant;
    let model = Lpv::new(
        f,
        c(m(2, 1, &[1.0, 0.5])),
        h,
        c(DMatrix::zeros(1, 1)),
        c(DMatrix::identity(2, 2) * 0.01),
        c(m(1, 1, &[0.04])),
        1,
    )
    .expect("static model is valid");
    Scenario {
        model,
        faults: vec![
            (
                "actuator_bias".into(),
                Onset::Step,
                Some(DVector::from_vec(vec![1.0, 0.5])),
                None,
            ),
            (
                "sensor_bias".into(),
                Onset::Step,
                None,
                Some(DVector::from_vec(vec![1.0])),
            ),
        ],
        x0: DVector::zeros(2),
        p0: DMatrix::identity(2, 2),
        window: WindowSettings {
            window: 100,
            min_lag: 1,
            ..WindowSettings::default()
        },
        controller: None,
        input: Some(|k, u| u[0] = (0.05 * k as f64).sin()),
        signals: Some(|k, p| p[0] = (0.01 * k as f64).sin()),
    }
}

/// A larger LPV channel for benchmarks: n = 3, p = 2, m = 4 (two actuator biases, two
/// sensor biases), two scheduling signals, w = 160.
#[must_use]
pub fn lpv_n3_p2_m4() -> Scenario {
    let f = LpvMatrix::new(
        m(3, 3, &[0.7, 0.1, 0.0, -0.1, 0.8, 0.1, 0.0, -0.1, 0.6]),
        vec![
            (0, DMatrix::identity(3, 3) * 0.05),
            (1, m(3, 3, &[0.0, 0.02, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0])),
        ],
    )
    .expect("shapes agree");
    let c = LpvMatrix::constant;
    let model = Lpv::new(
        f,
        c(m(3, 2, &[1.0, 0.0, 0.0, 1.0, 0.5, 0.5])),
        c(m(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 1.0])),
        c(DMatrix::zeros(2, 2)),
        c(DMatrix::identity(3, 3) * 0.01),
        c(DMatrix::identity(2, 2) * 0.04),
        2,
    )
    .expect("static model is valid");
    let e2 = |i: usize| DVector::from_fn(2, |r, _| if r == i { 1.0 } else { 0.0 });
    Scenario {
        model,
        faults: vec![
            (
                "actuator0_bias".into(),
                Onset::Step,
                Some(DVector::from_vec(vec![1.0, 0.0, 0.5])),
                None,
            ),
            (
                "actuator1_bias".into(),
                Onset::Step,
                Some(DVector::from_vec(vec![0.0, 1.0, 0.5])),
                None,
            ),
            ("sensor0_bias".into(), Onset::Step, None, Some(e2(0))),
            ("sensor1_bias".into(), Onset::Step, None, Some(e2(1))),
        ],
        x0: DVector::zeros(3),
        p0: DMatrix::identity(3, 3),
        window: WindowSettings {
            window: 160,
            min_lag: 1,
            ..WindowSettings::default()
        },
        controller: None,
        input: Some(|k, u| {
            u[0] = (0.05 * k as f64).sin();
            u[1] = (0.031 * k as f64).cos();
        }),
        signals: Some(|k, p| {
            p[0] = (0.01 * k as f64).sin();
            p[1] = (0.007 * k as f64).cos();
        }),
    }
}

/// An LTI channel for the stationary fast path: n = 3, p = 2, m = 3 (an actuator bias
/// step, a drift of sensor 0, a bias step of sensor 1), constant matrices (those of
/// [`lpv_n3_p2_m4`] at p = 0), w = 160.
#[must_use]
pub fn lti_n3_p2_m3() -> Scenario {
    let lpv = lpv_n3_p2_m4();
    let [f, g, h, j, q, r] = lpv
        .model
        .matrices()
        .map(|m| LpvMatrix::constant(m.base().clone()));
    let model = Lpv::new(f, g, h, j, q, r, 0).expect("static model is valid");
    let e2 = |i: usize| DVector::from_fn(2, |r, _| if r == i { 1.0 } else { 0.0 });
    Scenario {
        model,
        faults: vec![
            (
                "actuator0_bias".into(),
                Onset::Step,
                Some(DVector::from_vec(vec![1.0, 0.0, 0.5])),
                None,
            ),
            ("sensor0_drift".into(), Onset::Ramp, None, Some(e2(0))),
            ("sensor1_bias".into(), Onset::Step, None, Some(e2(1))),
        ],
        signals: None,
        ..lpv
    }
}
