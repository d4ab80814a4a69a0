//! Two tanks in series with Torricelli outflows, recorded as a plant historian exports
//! them: named columns in natural units, an ISO 8601 time column, a day per file.
//!
//! ```text
//! dh1/dt = (q1 + d1 − k1 √h1) / A1
//! dh2/dt = (q2 + d2 + k1 √h1 − k2 √h2) / A2
//! ```
//!
//! with inflows q1 (`FIC101`), q2 (`FIC102`) and the unmeasured disturbance inflows d1,
//! d2 in m³/h, levels h in cm (`LI201`, `LI202`), tank areas A in m², and the outflow
//! of the second tank `FI301` = k2 √h2 in m³/h. The flow controllers hold their
//! setpoints, which an operator moves now and then (a random step every few minutes):
//! the excitation of an ordinary day. Sensors add white noise. This is the plant a
//! newcomer brings on a first afternoon: nonlinear, in its own units, never seen by
//! glrmon's fault dictionary, sampled every 20 s.

use std::fmt::Write as _;

use crate::Rng;

/// Seconds in a day.
pub const DAY: f64 = 86_400.0;

/// The column names of an export, in order.
pub const COLUMNS: [&str; 6] = ["timestamp", "FIC101", "FIC102", "LI201", "LI202", "FI301"];

/// The plant and how it is recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoTanks {
    /// Tank cross-sections A1, A2 (m²).
    pub area: [f64; 2],
    /// Outflow coefficients k1, k2 (m³/h per √cm).
    pub outflow: [f64; 2],
    /// Operating inflows q1, q2 (m³/h) the setpoints move around.
    pub operating_inflow: [f64; 2],
    /// Largest setpoint move away from the operating inflow (m³/h).
    pub setpoint_range: f64,
    /// Mean number of samples between setpoint moves.
    pub setpoint_hold: f64,
    /// Standard deviation of the disturbance inflows d1, d2 (m³/h), redrawn each sample.
    pub disturbance_std: f64,
    /// Standard deviation of the level sensors' noise (cm).
    pub level_noise_std: f64,
    /// Standard deviation of FI301's noise (m³/h).
    pub flow_noise_std: f64,
    /// Sample period (s).
    pub period: f64,
    /// Time of the first sample of day 0, seconds since 1970-01-01T00:00:00Z.
    pub start: i64,
}

impl Default for TwoTanks {
    /// A1 = A2 = 0.5 m², levels about 60 and 80 cm at q = (2, 1) m³/h (time constants
    /// of about 18 and 16 minutes), setpoint moves of up to ±0.1 m³/h every ~5 minutes,
    /// sensor noise 0.2 cm and 0.02 m³/h, 20-s samples, day 0 = 2026-11-23.
    fn default() -> Self {
        Self {
            area: [0.5, 0.5],
            outflow: [2.0 / 60f64.sqrt(), 3.0 / 80f64.sqrt()],
            operating_inflow: [2.0, 1.0],
            setpoint_range: 0.1,
            setpoint_hold: 15.0,
            disturbance_std: 0.05,
            level_noise_std: 0.2,
            flow_noise_std: 0.02,
            period: 20.0,
            start: 1_795_392_000,
        }
    }
}

/// A fault of the plant from a sample on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantFault {
    /// A constant bias added to a measured output (0 `LI201`, 1 `LI202`, 2 `FI301`), in
    /// its unit.
    SensorBias {
        /// The output.
        output: usize,
        /// The bias.
        bias: f64,
    },
    /// The flow actually delivered by a controller differs from the recorded one by a
    /// constant (0 `FIC101`, 1 `FIC102`), in m³/h.
    ActuatorBias {
        /// The input.
        input: usize,
        /// The bias.
        bias: f64,
    },
}

/// One day's samples: the time of each, the inputs and the outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Day {
    /// Sample times, seconds since the Unix epoch.
    pub t: Vec<f64>,
    /// Recorded inputs (FIC101, FIC102), m³/h.
    pub u: Vec<[f64; 2]>,
    /// Measured outputs (LI201 cm, LI202 cm, FI301 m³/h).
    pub y: Vec<[f64; 3]>,
}

impl TwoTanks {
    /// The steady levels (cm) for constant inflows `q`: k1 √h1 = q1, k2 √h2 = q1 + q2.
    #[must_use]
    pub fn steady_levels(&self, q: [f64; 2]) -> [f64; 2] {
        let r1 = q[0] / self.outflow[0];
        let r2 = (q[0] + q[1]) / self.outflow[1];
        [r1 * r1, r2 * r2]
    }

    /// dh/dt (cm/s) at levels `h` with total inflows `q` (m³/h) into each tank from
    /// outside (controller flow plus disturbance). An empty tank has no outflow.
    #[must_use]
    pub fn derivative(&self, h: [f64; 2], q: [f64; 2]) -> [f64; 2] {
        // m³/h into a tank of A m² raise it by 100/(3600 A) cm/s.
        let rate = |i: usize| 100.0 / (3600.0 * self.area[i]);
        let out1 = self.outflow[0] * h[0].max(0.0).sqrt();
        let out2 = self.outflow[1] * h[1].max(0.0).sqrt();
        [(q[0] - out1) * rate(0), (q[1] + out1 - out2) * rate(1)]
    }

    /// Levels after one period from `h` under constant inflows `q`: 20 steps of
    /// classical RK4, levels clamped at ≥ 0.
    #[must_use]
    pub fn step(&self, h: [f64; 2], q: [f64; 2]) -> [f64; 2] {
        let n = 20;
        let dt = self.period / f64::from(n);
        let mut h = h;
        for _ in 0..n {
            let add = |x: [f64; 2], k: [f64; 2], c: f64| [x[0] + c * k[0], x[1] + c * k[1]];
            let k1 = self.derivative(h, q);
            let k2 = self.derivative(add(h, k1, 0.5 * dt), q);
            let k3 = self.derivative(add(h, k2, 0.5 * dt), q);
            let k4 = self.derivative(add(h, k3, dt), q);
            h = std::array::from_fn(|i| {
                (h[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])).max(0.0)
            });
        }
        h
    }

    /// Day `day` (0, 1, …) of `samples` samples from seed `seed`, with `fault` from
    /// sample `onset` of the day on, if any. The plant starts at its operating point
    /// and runs 200 samples before the first recorded one.
    #[must_use]
    pub fn day(
        &self,
        day: u32,
        samples: usize,
        seed: u64,
        fault: Option<(PlantFault, usize)>,
    ) -> Day {
        let mut rng = Rng::new(seed);
        let mut h = self.steady_levels(self.operating_inflow);
        let mut setpoint = self.operating_inflow;
        let t0 = self.start as f64 + f64::from(day) * DAY;
        let burn_in = 200;
        let mut out = Day {
            t: Vec::with_capacity(samples),
            u: Vec::with_capacity(samples),
            y: Vec::with_capacity(samples),
        };
        for i in 0..burn_in + samples {
            for (j, s) in setpoint.iter_mut().enumerate() {
                if rng.uniform() < 1.0 / self.setpoint_hold {
                    *s = self.operating_inflow[j]
                        + rng.uniform_in(-self.setpoint_range, self.setpoint_range);
                }
            }
            let active = match fault {
                Some((f, onset)) if i >= burn_in + onset => Some(f),
                _ => None,
            };
            let mut delivered = setpoint;
            if let Some(PlantFault::ActuatorBias { input, bias }) = active {
                delivered[input] += bias;
            }
            let level = |h: f64, rng: &mut Rng| h + self.level_noise_std * rng.normal();
            let mut y = [
                level(h[0], &mut rng),
                level(h[1], &mut rng),
                self.outflow[1] * h[1].max(0.0).sqrt() + self.flow_noise_std * rng.normal(),
            ];
            if let Some(PlantFault::SensorBias { output, bias }) = active {
                y[output] += bias;
            }
            if i >= burn_in {
                let k = i - burn_in;
                out.t.push(t0 + self.period * k as f64);
                out.u.push(setpoint);
                out.y.push(y);
            }
            let d = [
                self.disturbance_std * rng.normal(),
                self.disturbance_std * rng.normal(),
            ];
            h = self.step(h, [delivered[0] + d[0], delivered[1] + d[1]]);
        }
        out
    }
}

impl Day {
    /// The day as a historian's CSV export: `timestamp,FIC101,FIC102,LI201,LI202,FI301`,
    /// times in ISO 8601 UTC (`2026-11-23T00:00:20Z`), values with 4 decimals.
    #[must_use]
    pub fn csv(&self) -> String {
        let mut text = COLUMNS.join(",");
        text.push('\n');
        for ((t, u), y) in self.t.iter().zip(&self.u).zip(&self.y) {
            let _ = writeln!(
                text,
                "{},{:.4},{:.4},{:.4},{:.4},{:.4}",
                iso8601(*t as i64),
                u[0],
                u[1],
                y[0],
                y[1],
                y[2]
            );
        }
        text
    }
}

/// The names of the days [`write_week`] writes, in order, then `fault`.
pub const WEEK: [&str; 7] = ["mon", "tue", "wed", "thu", "fri", "sat", "sun"];

/// Writes a week of the default plant's history into `dir` as `mon.csv` … `sun.csv`
/// (fault-free, days 0–6, seeds 1000–1006) and `fault.csv` (day 7, seed 1007, a
/// +1.5 cm bias on LI202 from sample 1200), each of `samples` samples (4320: a day at
/// 20 s); returns the paths written.
///
/// # Errors
/// The first file that cannot be written.
pub fn write_week(
    dir: &std::path::Path,
    samples: usize,
) -> std::io::Result<Vec<std::path::PathBuf>> {
    let plant = TwoTanks::default();
    let fault = PlantFault::SensorBias {
        output: 1,
        bias: 1.5,
    };
    let mut written = Vec::new();
    for (day, name) in WEEK.iter().chain(&["fault"]).enumerate() {
        let day = day as u32;
        let path = dir.join(format!("{name}.csv"));
        let fault = (day == 7).then_some((fault, 1200));
        std::fs::write(
            &path,
            plant.day(day, samples, 1000 + u64::from(day), fault).csv(),
        )?;
        written.push(path);
    }
    Ok(written)
}

/// `seconds` since the Unix epoch as `YYYY-MM-DDThh:mm:ssZ` (proleptic Gregorian, UTC),
/// by the days-to-civil algorithm of H. Hinnant ("chrono-Compatible Low-Level Date
/// Algorithms").
#[must_use]
pub fn iso8601(seconds: i64) -> String {
    let days = seconds.div_euclid(86_400);
    let secs = seconds.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso8601_of_known_instants() {
        assert_eq!(iso8601(0), "1970-01-01T00:00:00Z");
        assert_eq!(iso8601(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(iso8601(1_795_392_000), "2026-11-23T00:00:00Z");
        assert_eq!(iso8601(1_795_392_000 + 86_399), "2026-11-23T23:59:59Z");
        assert_eq!(iso8601(-1), "1969-12-31T23:59:59Z");
    }

    #[test]
    fn the_operating_point_is_a_steady_state() {
        let plant = TwoTanks::default();
        let h = plant.steady_levels(plant.operating_inflow);
        assert!(
            (h[0] - 60.0).abs() < 1e-9 && (h[1] - 80.0).abs() < 1e-9,
            "{h:?}"
        );
        let next = plant.step(h, plant.operating_inflow);
        assert!((next[0] - h[0]).abs() < 1e-9 && (next[1] - h[1]).abs() < 1e-9);
    }

    #[test]
    fn a_sensor_bias_shows_in_its_column_only_from_its_onset() {
        let plant = TwoTanks::default();
        let clean = plant.day(0, 300, 7, None);
        let fault = PlantFault::SensorBias {
            output: 1,
            bias: 1.5,
        };
        let faulty = plant.day(0, 300, 7, Some((fault, 100)));
        for k in 0..300 {
            let want = if k >= 100 { 1.5 } else { 0.0 };
            assert!((faulty.y[k][1] - clean.y[k][1] - want).abs() < 1e-12);
            assert_eq!(faulty.y[k][0], clean.y[k][0]);
        }
        assert_eq!(clean.t[1] - clean.t[0], 20.0);
        assert!(
            clean
                .csv()
                .starts_with("timestamp,FIC101,FIC102,LI201,LI202,FI301\n2026-11-23T00:00:00Z,")
        );
    }
}
