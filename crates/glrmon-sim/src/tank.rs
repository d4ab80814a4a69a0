//! The quadruple-tank process, simulated nonlinearly, producing recordings in natural
//! units for identification, calibration and replay.
//!
//! The plant is that of K. H. Johansson, "The quadruple-tank process: a multivariable
//! laboratory process with an adjustable zero", IEEE Trans. Control Systems Technology
//! 8(3), 2000, eq. (1):
//!
//! ```text
//! dh1/dt = −a1/A1 √(2g h1) + a3/A1 √(2g h3) + γ1 k1/A1 v1
//! dh2/dt = −a2/A2 √(2g h2) + a4/A2 √(2g h4) + γ2 k2/A2 v2
//! dh3/dt = −a3/A3 √(2g h3) + (1−γ2) k2/A3 v2
//! dh4/dt = −a4/A4 √(2g h4) + (1−γ1) k1/A4 v1
//! ```
//!
//! Tanks 1 and 2 are the lower tanks, 3 and 4 the upper ones; pump 1 (voltage v1) feeds
//! tanks 1 and 4, pump 2 feeds tanks 2 and 3. In this module tanks, sensors and pumps are
//! indexed from 0: tank `i` is the paper's tank `i + 1`, measured by output `y_i`; pump `j`
//! is the paper's pump `j + 1`, driven by input `u_j`.
//!
//! **Units.** Levels h in cm, areas in cm², flows in cm³/s, time in s, pump voltages in V.
//! The recorded inputs are the commanded pump voltages (V, around the operating point
//! 3 V). The recorded outputs are the level sensors' voltages `y_i = kc h_i + noise`
//! (V, kc = 0.5 V/cm as in the paper's laboratory process), so the outputs sit on an
//! offset (the operating point's levels × kc ≈ 6.1, 6.4, 0.8, 0.7 V) that an
//! identification must remove. Optional pump-flow sensors add two outputs in cm³/s.
//!
//! **The paper's operating point.** The default parameters are the paper's minimum-phase
//! set P−. The steady state computed from the equations above at v = (3, 3) V is
//! h⁰ ≈ (12.26, 12.78, 1.63, 1.41) cm, where the paper's table gives (12.4, 12.7, 1.8,
//! 1.4): the lower-right pair agrees to the table's rounding, h1 and h3 do not (the
//! table's levels were measured on the rig; its constants k, γ fitted). The paper's time
//! constants (62, 90, 23, 30) s agree with the computed steady state to within a second.
//! This module uses the equations, not the table.

use crate::Rng;

/// Standard gravity in cm/s², as in the paper.
pub const GRAVITY: f64 = 981.0;

/// The paper's operating-point pump voltages for P− (V).
pub const OPERATING_INPUT: [f64; 2] = [3.0, 3.0];

/// Default sensor-bias magnitude, 0.125 V (0.25 cm of level): five times the default
/// sensor noise std ([`TankRun::sensor_noise_std`], 0.025 V), a step a GLR test on the
/// innovations should flag within a few samples while staying a realistic zero drift
/// (about 1 % of a 20 cm tank).
pub const DEFAULT_SENSOR_BIAS: f64 = 0.125;

/// Default actuator-bias magnitude, 0.25 V: the pump runs 8 % above its commanded 3 V
/// (a worn driver or a supply offset). It is half the excitation amplitude, so well
/// inside the range the linear model was identified on, and it moves the lower levels'
/// sensors by about 0.6 V at steady state (≈ 25 sensor-noise stds) with the plant's
/// time constants of 60–90 s (12–18 samples at Ts = 5 s), so a good detector finds it
/// within tens of samples.
pub const DEFAULT_ACTUATOR_BIAS: f64 = 0.25;

/// Default leak area, 0.003 cm² (≈ 4–5 % of the outlet areas 0.057–0.071 cm², a hole of
/// about 0.6 mm diameter). At the P− operating point a leak from lower tank 0 or 1
/// lowers its level at steady state by 1.0 or 1.25 cm (0.5 or 0.6 V, 20–25 sensor-noise
/// stds); a leak from upper tank 2 or 3 lowers it by 0.13–0.14 cm (≈ 8 %, 3 stds) and
/// the lower tank it drains into by 0.36–0.42 cm. A leak is not in the linear fault
/// dictionary (it changes the dynamics, not an additive input), a realistic extra.
pub const DEFAULT_LEAK_AREA: f64 = 0.003;

/// The quadruple-tank plant's physical parameters (Johansson 2000, Table I).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadrupleTank {
    /// Cross-sections A_i of the tanks (cm²).
    pub area: [f64; 4],
    /// Outlet hole areas a_i (cm²).
    pub outlet: [f64; 4],
    /// Pump gains k_j (cm³/(V s)): pump j delivers k_j v_j.
    pub pump_gain: [f64; 2],
    /// Valve splits γ_j: the fraction of pump j's flow going to lower tank j (the rest
    /// goes to upper tank 3 − j, i.e. pump 0 → tanks 0 and 3, pump 1 → tanks 1 and 2).
    pub valve: [f64; 2],
    /// Level-sensor gain kc (V/cm).
    pub sensor_gain: f64,
    /// Gravity g (cm/s²).
    pub gravity: f64,
}

impl Default for QuadrupleTank {
    /// The paper's minimum-phase parameter set P−.
    fn default() -> Self {
        Self::minimum_phase()
    }
}

/// What drives the plant over one sample period: pump voltages actually applied and the
/// unmeasured extras (disturbance inflows, leaks).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Drive {
    /// Pump voltages actually applied (V). A negative voltage gives no flow.
    pub v: [f64; 2],
    /// Extra inflow into each tank (cm³/s, negative = outflow): the process noise.
    pub disturbance: [f64; 4],
    /// Area of a leak from each tank (cm²), an extra outflow a_leak √(2 g h).
    pub leak: [f64; 4],
}

impl Drive {
    /// Just the pump voltages `v`, no disturbance, no leak.
    #[must_use]
    pub fn pumps(v: [f64; 2]) -> Self {
        Self {
            v,
            ..Self::default()
        }
    }
}

impl QuadrupleTank {
    /// The paper's minimum-phase set P−: A1 = A3 = 28, A2 = A4 = 32 cm², a1 = a3 =
    /// 0.071, a2 = a4 = 0.057 cm², kc = 0.5 V/cm, g = 981 cm/s², k1 = 3.33, k2 = 3.35
    /// cm³/(V s), γ1 = 0.70, γ2 = 0.60 (γ1 + γ2 > 1: minimum phase).
    #[must_use]
    pub fn minimum_phase() -> Self {
        Self {
            area: [28.0, 32.0, 28.0, 32.0],
            outlet: [0.071, 0.057, 0.071, 0.057],
            pump_gain: [3.33, 3.35],
            valve: [0.70, 0.60],
            sensor_gain: 0.5,
            gravity: GRAVITY,
        }
    }

    /// The pumps' inflows into each tank (cm³/s) for voltages `v` (negative voltages
    /// give no flow).
    #[must_use]
    pub fn pump_inflows(&self, v: [f64; 2]) -> [f64; 4] {
        let q0 = self.pump_gain[0] * v[0].max(0.0);
        let q1 = self.pump_gain[1] * v[1].max(0.0);
        let [g0, g1] = self.valve;
        [g0 * q0, g1 * q1, (1.0 - g1) * q1, (1.0 - g0) * q0]
    }

    /// The steady levels (cm) for constant voltages `v`, in closed form: each tank's
    /// outflow a_i √(2 g h_i) equals its total inflow (upper tanks: their pump share;
    /// lower tanks: their pump share plus the upper tank's outflow).
    #[must_use]
    pub fn steady_state(&self, v: [f64; 2]) -> [f64; 4] {
        let q = self.pump_inflows(v);
        let total = [q[0] + q[2], q[1] + q[3], q[2], q[3]];
        std::array::from_fn(|i| {
            let r = total[i] / self.outlet[i];
            r * r / (2.0 * self.gravity)
        })
    }

    /// dh/dt (cm/s) at levels `h` under `drive`. Negative levels count as empty (the
    /// square roots see max(h, 0)).
    #[must_use]
    pub fn derivative(&self, h: &[f64; 4], drive: &Drive) -> [f64; 4] {
        let two_g = 2.0 * self.gravity;
        let root: [f64; 4] = std::array::from_fn(|i| (two_g * h[i].max(0.0)).sqrt());
        let q = self.pump_inflows(drive.v);
        let outflow: [f64; 4] = std::array::from_fn(|i| self.outlet[i] * root[i]);
        let from_above = [outflow[2], outflow[3], 0.0, 0.0];
        std::array::from_fn(|i| {
            (q[i] + from_above[i] + drive.disturbance[i] - outflow[i] - drive.leak[i] * root[i])
                / self.area[i]
        })
    }

    /// Levels after `ts` seconds from `h` under a constant `drive`, by `substeps` fixed
    /// steps of classical RK4 (at least one). Levels are clamped at ≥ 0 after each
    /// sub-step: a tank cannot hold a negative volume, and √h needs h ≥ 0. Overflow at
    /// the top of a tank is not modelled.
    #[must_use]
    pub fn step(&self, h: [f64; 4], drive: &Drive, ts: f64, substeps: u32) -> [f64; 4] {
        let n = substeps.max(1);
        let dt = ts / f64::from(n);
        let mut h = h;
        for _ in 0..n {
            let add = |x: &[f64; 4], k: &[f64; 4], c: f64| -> [f64; 4] {
                std::array::from_fn(|i| x[i] + c * k[i])
            };
            let k1 = self.derivative(&h, drive);
            let k2 = self.derivative(&add(&h, &k1, 0.5 * dt), drive);
            let k3 = self.derivative(&add(&h, &k2, 0.5 * dt), drive);
            let k4 = self.derivative(&add(&h, &k3, dt), drive);
            h = std::array::from_fn(|i| {
                (h[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])).max(0.0)
            });
        }
        h
    }

    /// The linearisation's time constants T_i = A_i/a_i √(2 h_i⁰ / g) (s) at levels `h0`.
    #[must_use]
    pub fn time_constants(&self, h0: &[f64; 4]) -> [f64; 4] {
        std::array::from_fn(|i| self.area[i] / self.outlet[i] * (2.0 * h0[i] / self.gravity).sqrt())
    }

    /// The paper's linear model at the steady state of `v` (eq. (2)): d(Δh)/dt = A Δh +
    /// B Δv with A = [−1/T1, 0, A3/(A1 T3), 0; 0, −1/T2, 0, A4/(A2 T4); 0, 0, −1/T3, 0;
    /// 0, 0, 0, −1/T4] and B = [γ1 k1/A1, 0; 0, γ2 k2/A2; 0, (1−γ2) k2/A3;
    /// (1−γ1) k1/A4, 0]. Returns (A, B), row-major.
    #[must_use]
    pub fn linearisation(&self, v: [f64; 2]) -> ([[f64; 4]; 4], [[f64; 2]; 4]) {
        let t = self.time_constants(&self.steady_state(v));
        let ar = &self.area;
        let mut a = [[0.0; 4]; 4];
        for (i, row) in a.iter_mut().enumerate() {
            row[i] = -1.0 / t[i];
        }
        a[0][2] = ar[2] / (ar[0] * t[2]);
        a[1][3] = ar[3] / (ar[1] * t[3]);
        let (k, g) = (self.pump_gain, self.valve);
        let b = [
            [g[0] * k[0] / ar[0], 0.0],
            [0.0, g[1] * k[1] / ar[1]],
            [0.0, (1.0 - g[1]) * k[1] / ar[2]],
            [(1.0 - g[0]) * k[0] / ar[3], 0.0],
        ];
        (a, b)
    }

    /// The linear model's steady-state gains from pump voltages to level-sensor voltages
    /// (V/V) at the steady state of `v`: −kc A⁻¹ B, row i = sensor i. The lower tanks'
    /// rows are the paper's G(0) = [γ1 c1, (1−γ2) c1 k2/k1; (1−γ1) c2 k1/k2, γ2 c2] with
    /// c_j = T_j k_j kc / A_j (the paper writes the off-diagonal entries without the
    /// k2/k1, k1/k2 ratios, which differ from 1 by 0.6 %).
    #[must_use]
    pub fn dc_gain(&self, v: [f64; 2]) -> [[f64; 2]; 4] {
        let t = self.time_constants(&self.steady_state(v));
        let (ar, k, g, kc) = (self.area, self.pump_gain, self.valve, self.sensor_gain);
        [
            [
                kc * t[0] / ar[0] * g[0] * k[0],
                kc * t[0] / ar[0] * (1.0 - g[1]) * k[1],
            ],
            [
                kc * t[1] / ar[1] * (1.0 - g[0]) * k[0],
                kc * t[1] / ar[1] * g[1] * k[1],
            ],
            [0.0, kc * t[2] / ar[2] * (1.0 - g[1]) * k[1]],
            [kc * t[3] / ar[3] * (1.0 - g[0]) * k[0], 0.0],
        ]
    }
}

/// The pump voltages' excitation around the operating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Excitation {
    /// Constant inputs at the operating point.
    Constant,
    /// Each pump independently: a level drawn uniformly in [−amplitude, amplitude] V
    /// around the operating point, held for a number of samples drawn uniformly in
    /// [min_hold, max_hold]; a random multi-level signal, persistently exciting of any
    /// order, for identification.
    RandomSteps {
        /// Half-width of the levels (V).
        amplitude: f64,
        /// Shortest hold (samples, ≥ 1).
        min_hold: u32,
        /// Longest hold (samples, ≥ min_hold).
        max_hold: u32,
    },
}

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TankFaultKind {
    /// `magnitude` (in the output's units) added to measured output `output`.
    SensorBias {
        /// Output index (0–3 level sensors, 4–5 pump-flow sensors when measured).
        output: usize,
        /// Bias (V for a level sensor).
        magnitude: f64,
    },
    /// Pump `input` actually receives v + `magnitude` while the recorded input stays the
    /// commanded v.
    ActuatorBias {
        /// Input (pump) index, 0 or 1.
        input: usize,
        /// Voltage offset (V).
        magnitude: f64,
    },
    /// An extra outflow `area` √(2 g h) from tank `tank` (to the basin).
    Leak {
        /// Tank index, 0–3.
        tank: usize,
        /// Leak hole area (cm²).
        area: f64,
    },
}

/// A fault acting from sample `onset` on: a sensor bias is in y_onset onwards; an
/// actuator bias or a leak acts over the periods [t_k, t_{k+1}) with k ≥ onset, so it
/// first shows in y_{onset+1}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TankFault {
    /// What the fault does.
    pub kind: TankFaultKind,
    /// First sample affected.
    pub onset: u64,
}

impl TankFault {
    /// A level-sensor bias of [`DEFAULT_SENSOR_BIAS`] on `output` from `onset`.
    #[must_use]
    pub fn sensor_bias(output: usize, onset: u64) -> Self {
        Self {
            kind: TankFaultKind::SensorBias {
                output,
                magnitude: DEFAULT_SENSOR_BIAS,
            },
            onset,
        }
    }

    /// A pump-voltage bias of [`DEFAULT_ACTUATOR_BIAS`] on `input` from `onset`.
    #[must_use]
    pub fn actuator_bias(input: usize, onset: u64) -> Self {
        Self {
            kind: TankFaultKind::ActuatorBias {
                input,
                magnitude: DEFAULT_ACTUATOR_BIAS,
            },
            onset,
        }
    }

    /// A leak of [`DEFAULT_LEAK_AREA`] from `tank` from `onset`.
    #[must_use]
    pub fn leak(tank: usize, onset: u64) -> Self {
        Self {
            kind: TankFaultKind::Leak {
                tank,
                area: DEFAULT_LEAK_AREA,
            },
            onset,
        }
    }
}

/// Errors of a [`TankRun`]'s settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TankError {
    /// A setting is out of range.
    #[error("quadruple tank: {0}")]
    Setting(String),
}

/// One simulated experiment on the quadruple tank: its settings. `Default` is an
/// identification experiment at the P− operating point: 2 000 samples of 5 s, random
/// steps of ±0.5 V held 3–30 samples, inflow noise 0.1 cm³/s, sensor noise 0.025 V,
/// no fault.
#[derive(Debug, Clone, PartialEq)]
pub struct TankRun {
    /// The plant.
    pub plant: QuadrupleTank,
    /// Seed of every random draw (excitation, process noise and sensor noise come from
    /// separate streams derived from it, so changing the excitation or adding a fault
    /// leaves the noise sequences unchanged).
    pub seed: u64,
    /// Number of samples recorded.
    pub samples: usize,
    /// Sample period Ts (s).
    pub sample_period: f64,
    /// RK4 sub-steps per sample period (≥ 1).
    pub substeps: u32,
    /// Operating-point pump voltages (V) the excitation is centred on.
    pub operating_input: [f64; 2],
    /// The commanded inputs' excitation.
    pub excitation: Excitation,
    /// Std of the disturbance inflow into each tank (cm³/s), drawn independently each
    /// sample and held over the period.
    pub inflow_noise_std: f64,
    /// Std of each level sensor's noise (V; 0.025 V is 0.05 cm at kc = 0.5 V/cm).
    pub sensor_noise_std: f64,
    /// Also measure the two pumps' flows k_j v_j (cm³/s, of the voltage actually
    /// applied) as outputs 4 and 5.
    pub measure_pump_flow: bool,
    /// Std of the pump-flow sensors' noise (cm³/s).
    pub flow_noise_std: f64,
    /// Levels at t = 0 (cm); `None`: the steady state of the operating point.
    pub initial_levels: Option<[f64; 4]>,
    /// Faults injected (any number, each from its onset).
    pub faults: Vec<TankFault>,
}

impl Default for TankRun {
    fn default() -> Self {
        Self {
            plant: QuadrupleTank::default(),
            seed: 0,
            samples: 2000,
            sample_period: 5.0,
            substeps: 5,
            operating_input: OPERATING_INPUT,
            excitation: Excitation::RandomSteps {
                amplitude: 0.5,
                min_hold: 3,
                max_hold: 30,
            },
            inflow_noise_std: 0.1,
            sensor_noise_std: 0.025,
            measure_pump_flow: false,
            flow_noise_std: 0.05,
            initial_levels: None,
            faults: Vec::new(),
        }
    }
}

/// A simulated recording: one row per sample.
#[derive(Debug, Clone, PartialEq)]
pub struct TankRecording {
    /// Sample index k, from 0.
    pub k: Vec<u64>,
    /// Time t = k Ts (s).
    pub t: Vec<f64>,
    /// Commanded pump voltages u_k = (v1, v2) (V), held over [t_k, t_{k+1}).
    pub u: Vec<Vec<f64>>,
    /// Measured outputs y_k: the four level sensors (V), then the two pump flows
    /// (cm³/s) when measured.
    pub y: Vec<Vec<f64>>,
    /// True levels h(t_k) (cm), for tests and plots.
    pub levels: Vec<[f64; 4]>,
}

impl TankRecording {
    /// Column names of a CSV row: `k,t,u0,u1,y0,…`.
    #[must_use]
    pub fn columns(&self) -> Vec<String> {
        let p = self.y.first().map_or(4, Vec::len);
        let mut c = vec!["k".to_string(), "t".to_string(), "u0".into(), "u1".into()];
        c.extend((0..p).map(|i| format!("y{i}")));
        c
    }

    /// The recording as glrmon's CSV sample format: the [`TankRecording::columns`]
    /// header, then one row per sample, values to 6 decimals (1 µV: well below the
    /// sensor noise).
    #[must_use]
    pub fn csv(&self) -> String {
        use std::fmt::Write as _;
        let mut s = self.columns().join(",");
        s.push('\n');
        for i in 0..self.k.len() {
            let _ = write!(s, "{},{}", self.k[i], self.t[i]);
            for x in self.u[i].iter().chain(&self.y[i]) {
                let _ = write!(s, ",{x:.6}");
            }
            s.push('\n');
        }
        s
    }
}

struct StepInput {
    level: f64,
    left: u32,
}

impl TankRun {
    fn check(&self) -> Result<usize, TankError> {
        let bad = |m: String| Err(TankError::Setting(m));
        if !(self.sample_period > 0.0 && self.sample_period.is_finite()) {
            return bad(format!(
                "sample period {} s is not positive",
                self.sample_period
            ));
        }
        if self.substeps == 0 {
            return bad("substeps must be at least 1".into());
        }
        for (name, s) in [
            ("inflow noise std", self.inflow_noise_std),
            ("sensor noise std", self.sensor_noise_std),
            ("flow noise std", self.flow_noise_std),
        ] {
            if !(s >= 0.0 && s.is_finite()) {
                return bad(format!("{name} {s} is not a non-negative number"));
            }
        }
        if let Excitation::RandomSteps {
            amplitude,
            min_hold,
            max_hold,
        } = self.excitation
            && (min_hold == 0 || max_hold < min_hold || amplitude.is_nan() || amplitude < 0.0)
        {
            return bad(format!(
                "random steps need amplitude ≥ 0 and 1 ≤ min_hold ≤ max_hold, got {amplitude}, {min_hold}, {max_hold}"
            ));
        }
        let p = if self.measure_pump_flow { 6 } else { 4 };
        for f in &self.faults {
            match f.kind {
                TankFaultKind::SensorBias { output, .. } if output >= p => {
                    return bad(format!(
                        "sensor bias on y{output}, outputs are y0–y{}",
                        p - 1
                    ));
                }
                TankFaultKind::ActuatorBias { input, .. } if input >= 2 => {
                    return bad(format!("actuator bias on u{input}, inputs are u0, u1"));
                }
                TankFaultKind::Leak { tank, area } if tank >= 4 || area.is_nan() || area < 0.0 => {
                    return bad(format!(
                        "leak of {area} cm² from tank {tank}, tanks are 0–3"
                    ));
                }
                _ => {}
            }
        }
        Ok(p)
    }

    /// Simulates the experiment.
    ///
    /// At each sample k: the commanded u_k is drawn (excitation); y_k is measured from
    /// the levels h(t_k) (plus active sensor biases); the plant is integrated over
    /// [t_k, t_{k+1}) with the applied voltages (u_k plus active actuator biases), the
    /// sample's disturbance inflows and the active leaks.
    ///
    /// # Errors
    /// [`TankError::Setting`] for a non-positive period, zero sub-steps, negative noise,
    /// bad hold lengths, or a fault naming an output, input or tank that does not exist.
    pub fn simulate(&self) -> Result<TankRecording, TankError> {
        let p = self.check()?;
        let plant = &self.plant;
        let mut master = Rng::new(self.seed);
        let mut exc = Rng::new(master.next_u64());
        let mut proc = Rng::new(master.next_u64());
        let mut meas = Rng::new(master.next_u64());
        let n = self.samples;
        let mut rec = TankRecording {
            k: Vec::with_capacity(n),
            t: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            levels: Vec::with_capacity(n),
        };
        let mut h = self
            .initial_levels
            .unwrap_or_else(|| plant.steady_state(self.operating_input));
        let mut steps = [0, 1].map(|_| StepInput {
            level: 0.0,
            left: 0,
        });
        for k in 0..n as u64 {
            // Commanded inputs.
            let mut u = self.operating_input;
            if let Excitation::RandomSteps {
                amplitude,
                min_hold,
                max_hold,
            } = self.excitation
            {
                for (j, s) in steps.iter_mut().enumerate() {
                    if s.left == 0 {
                        s.level = exc.uniform_in(-amplitude, amplitude);
                        let span = f64::from(max_hold - min_hold + 1);
                        s.left =
                            min_hold + ((exc.uniform() * span) as u32).min(max_hold - min_hold);
                    }
                    s.left -= 1;
                    u[j] += s.level;
                }
            }
            // Applied inputs and leaks.
            let mut drive = Drive::pumps(u);
            let mut sensor_bias = [0.0; 6];
            for f in self.faults.iter().filter(|f| k >= f.onset) {
                match f.kind {
                    TankFaultKind::SensorBias { output, magnitude } => {
                        sensor_bias[output] += magnitude;
                    }
                    TankFaultKind::ActuatorBias { input, magnitude } => {
                        drive.v[input] += magnitude;
                    }
                    TankFaultKind::Leak { tank, area } => drive.leak[tank] += area,
                }
            }
            // Measurements y_k.
            let mut y = Vec::with_capacity(p);
            for level in h {
                y.push(plant.sensor_gain * level + self.sensor_noise_std * meas.normal());
            }
            if self.measure_pump_flow {
                for j in 0..2 {
                    y.push(
                        plant.pump_gain[j] * drive.v[j].max(0.0)
                            + self.flow_noise_std * meas.normal(),
                    );
                }
            }
            for (yi, b) in y.iter_mut().zip(sensor_bias) {
                if b != 0.0 {
                    *yi += b;
                }
            }
            rec.k.push(k);
            rec.t.push(k as f64 * self.sample_period);
            rec.u.push(u.to_vec());
            rec.y.push(y);
            rec.levels.push(h);
            // Integrate over [t_k, t_{k+1}).
            for d in &mut drive.disturbance {
                *d = self.inflow_noise_std * proc.normal();
            }
            h = plant.step(h, &drive, self.sample_period, self.substeps);
        }
        Ok(rec)
    }
}
