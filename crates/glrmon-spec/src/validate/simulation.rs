//! The simulation settings of a channel (`[channels.simulation]`), for `glrmon simulate`.

use glrmon_core::Dims;
use nalgebra::DMatrix;

use super::{Validator, join};
use crate::expr::{Expr, ExprContext};
use crate::schema::ChannelSpec;
use crate::{Controller, SimulationPlan};

impl Validator {
    /// `[channels.simulation]`: the input, signal and unknown-input expressions (at most
    /// one per input, signal and column of E) and the PI controller's signals.
    pub(super) fn simulation(
        &mut self,
        prefix: &str,
        spec: &ChannelSpec,
        dims: Dims,
        e: Option<&DMatrix<f64>>,
    ) -> SimulationPlan {
        let sim = &spec.simulation;
        let ctx = ExprContext {
            inputs: 0,
            signals: 0,
            allow_k: true,
            allow_lags: false,
            allow_random: true,
            states: 0,
            allow_t: false,
        };
        let list =
            |v: &mut Self, field: &str, src: &[String], max: usize, what: &str| -> Vec<Expr> {
                let path = join(prefix, &format!("simulation.{field}"));
                if src.len() > max {
                    v.error(
                        path.clone(),
                        format!(
                            "has {} expressions but the channel has {max} {what}",
                            src.len()
                        ),
                    );
                }
                src.iter()
                    .enumerate()
                    .filter_map(|(i, s)| match Expr::parse(s, &ctx) {
                        Ok(x) => Some(x),
                        Err(err) => {
                            v.error(format!("{path}[{i}]"), err.to_string());
                            None
                        }
                    })
                    .collect()
            };
        let inputs = list(self, "inputs", &sim.inputs, dims.inputs, "inputs");
        let signals = list(self, "signals", &sim.signals, dims.signals, "signals");
        let d = e.map_or(0, |e| e.ncols());
        let unknown_input = list(self, "unknown_input", &sim.unknown_input, d, "columns in E");
        let controller = sim.controller.as_ref().map(|c| Controller {
            output: c.output,
            input: c.input,
            setpoint: c.setpoint,
            kp: c.kp,
            ki: c.ki,
        });
        if let Some(c) = controller
            && (c.input >= dims.inputs || c.output >= dims.outputs)
        {
            self.error(
                join(prefix, "simulation.controller"),
                format!(
                    "drives u{} from y{} but the channel has {} inputs and {} outputs",
                    c.input, c.output, dims.inputs, dims.outputs
                ),
            );
        }
        SimulationPlan {
            inputs,
            signals,
            unknown_input,
            controller,
        }
    }
}
