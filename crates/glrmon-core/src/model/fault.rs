//! The fault dictionary: m additive faults, each a state column Ψ̃ and an output
//! column Φ̃ with an onset profile.
//!
//! The faulty plant is (Zhang & Basseville 2014, eq. (44)):
//!
//! ```text
//! X_{k+1} = F_k X_k + G_k U_k + W_k + Ψ_k(r) θ
//! Y_k     = H_k X_k + J_k U_k + V_k + Φ_k(r) θ
//! ```
//!
//! Column j of Ψ_k(r) is a_j(k − r)·Ψ̃_k[:, j] and of Φ_k(r) is b_j(k − r)·Φ̃_k[:, j],
//! where the factors a, b come from the fault's [`Onset`] profile (eq. (4) for steps,
//! eq. (51) for impulses). Letters are the 2014 paper's: Ψ state, Φ output (the 2021
//! paper calls its state-fault matrix Φ; see docs/NOTATION.md).

use nalgebra::DVector;

use crate::error::ModelError;
use crate::model::{Dims, Signals, SystemMatrices};

/// How a fault enters after its onset r.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Onset {
    /// Step, eq. (4): Ψ_k(r) = Ψ̃_k·1{k ≥ r}; output part Φ_k(r) = Φ̃_k·1{k ≥ r}.
    Step,
    /// Impulse, eq. (51): Ψ_k(r) = δ_{r,k+1}Ψ̃_k, a jump that enters X_r; output part
    /// Φ_k(r) = δ_{r,k}Φ̃_k.
    Impulse,
    /// Ramp: Ψ_k(r) = (k − r + 1)Ψ̃_k·1{k ≥ r}, likewise for Φ (a drift).
    Ramp,
    /// Known profile with no onset: Ψ_k = Ψ̃_k, Φ_k = Φ̃_k from the first sample on;
    /// the GLR then sums over all samples (eqs. (24)-(30)).
    Known,
}

impl Onset {
    /// a(lag): the factor of Ψ̃_k in Ψ_k(r) at lag = k − r ≥ 0.
    #[inline]
    #[must_use]
    pub fn state_factor(self, lag: u64) -> f64 {
        match self {
            Onset::Step | Onset::Known => 1.0,
            Onset::Ramp => (lag + 1) as f64,
            Onset::Impulse => 0.0,
        }
    }

    /// b(lag): the factor of Φ̃_k in Φ_k(r) at lag = k − r ≥ 0.
    #[inline]
    #[must_use]
    pub fn output_factor(self, lag: u64) -> f64 {
        match self {
            Onset::Step | Onset::Known => 1.0,
            Onset::Ramp => (lag + 1) as f64,
            Onset::Impulse => {
                if lag == 0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The factor of Ψ̃_{r−1} in Ψ_{r−1}(r), which starts Γ_r(r) (lag −1): 1 for an
    /// impulse (δ_{r,k+1} at k = r − 1), 0 otherwise.
    #[inline]
    #[must_use]
    pub fn entry_factor(self) -> f64 {
        if self == Onset::Impulse { 1.0 } else { 0.0 }
    }
}

/// A user-defined fault column, e.g. an expression over the sample's signals.
///
/// Must be deterministic and must not allocate: it runs on every sample, including
/// predict-only steps for missing samples (where `signals` repeats the last sample's).
pub trait ColumnFn: Send + std::fmt::Debug {
    /// Writes the column at sample `k` into `out` (length n for a state column, p for
    /// an output column), every entry: on entry `out` may hold an earlier sample's
    /// column. `system` holds the model matrices already evaluated at k.
    fn evaluate(&mut self, k: u64, signals: &Signals<'_>, system: &SystemMatrices, out: &mut [f64]);
}

/// One fault column Ψ̃_k[:, j] (length n) or Φ̃_k[:, j] (length p).
#[derive(Debug)]
#[non_exhaustive]
pub enum Column {
    /// No effect on this equation.
    Zero,
    /// A constant column.
    Constant(DVector<f64>),
    /// Actuator bias on input i: column i of G_k (state columns only;
    /// Zhang & Basseville 2014 §2.1, Ψ̃_k = G_k).
    InputBias {
        /// Input index i.
        input: usize,
    },
    /// Actuator gain loss on input i: `−G_k[:, i]·U_k[i]` (state columns only;
    /// §2.1, Ψ̃_k = −G_k diag(U_k)).
    GainLoss {
        /// Input index i.
        input: usize,
    },
    /// A user-defined column.
    Custom(Box<dyn ColumnFn>),
}

/// A named fault of the dictionary.
#[derive(Debug)]
pub struct Fault {
    /// Unique name, used in alarms and isolation results.
    pub name: String,
    /// Onset profile, shared by the state and output parts.
    pub onset: Onset,
    /// Ψ̃: the column entering the state equation.
    pub state: Column,
    /// Φ̃: the column entering the output equation.
    pub output: Column,
}

impl Fault {
    /// A state-equation fault (Φ̃ = 0).
    #[must_use]
    pub fn state(name: &str, onset: Onset, column: Column) -> Self {
        Self {
            name: name.to_owned(),
            onset,
            state: column,
            output: Column::Zero,
        }
    }

    /// An output-equation fault (Ψ̃ = 0).
    #[must_use]
    pub fn output(name: &str, onset: Onset, column: Column) -> Self {
        Self {
            name: name.to_owned(),
            onset,
            state: Column::Zero,
            output: column,
        }
    }
}

/// The dictionary of m faults of one channel.
///
/// # Examples
/// ```
/// use glrmon_core::model::fault::{Column, Fault, FaultDictionary, Onset};
/// use glrmon_core::model::Dims;
/// use nalgebra::DVector;
/// let dims = Dims { states: 2, inputs: 1, outputs: 1, signals: 0 };
/// let faults = FaultDictionary::new(dims, vec![
///     Fault::state("jump_x0", Onset::Impulse, Column::Constant(DVector::from_vec(vec![1.0, 0.0]))),
///     Fault::output("sensor_bias", Onset::Step, Column::Constant(DVector::from_vec(vec![1.0]))),
/// ]).unwrap();
/// assert_eq!(faults.len(), 2);
/// ```
#[derive(Debug)]
pub struct FaultDictionary {
    dims: Dims,
    faults: Vec<Fault>,
}

impl FaultDictionary {
    /// Checks every column against the model's dimensions.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] for an empty dictionary, a duplicate name, a column of
    /// the wrong length, an input index beyond l, a bias or gain column in the output
    /// equation, or a mix of [`Onset::Known`] with onset profiles (the first sums over
    /// all samples, the others over a moving window: one detector cannot do both).
    pub fn new(dims: Dims, faults: Vec<Fault>) -> Result<Self, ModelError> {
        let err = |detail: String| ModelError::Dimension {
            what: "fault dictionary",
            detail,
        };
        if faults.is_empty() {
            return Err(err("no faults: the dictionary needs at least one".into()));
        }
        let known = faults.iter().filter(|f| f.onset == Onset::Known).count();
        if known != 0 && known != faults.len() {
            return Err(err(
                "known-profile faults cannot be mixed with step/impulse/ramp faults in one channel"
                    .into(),
            ));
        }
        for (j, fault) in faults.iter().enumerate() {
            if faults[..j].iter().any(|f| f.name == fault.name) {
                return Err(err(format!("duplicate fault name \"{}\"", fault.name)));
            }
            for (part, column, len) in [
                ("state column Ψ", &fault.state, dims.states),
                ("output column Φ", &fault.output, dims.outputs),
            ] {
                match column {
                    Column::Constant(v) if v.len() != len => {
                        return Err(err(format!(
                            "fault \"{}\": {part} has {} entries, expected {len}",
                            fault.name,
                            v.len()
                        )));
                    }
                    Column::Constant(v) if v.iter().any(|x| !x.is_finite()) => {
                        return Err(err(format!(
                            "fault \"{}\": {part} is not finite",
                            fault.name
                        )));
                    }
                    Column::InputBias { input } | Column::GainLoss { input } => {
                        if len != dims.states {
                            return Err(err(format!(
                                "fault \"{}\": actuator columns belong to the state equation",
                                fault.name
                            )));
                        }
                        if *input >= dims.inputs {
                            return Err(err(format!(
                                "fault \"{}\": input u{input} does not exist (model has {} inputs)",
                                fault.name, dims.inputs
                            )));
                        }
                    }
                    _ => {}
                }
            }
        }
        Ok(Self { dims, faults })
    }

    /// m, the number of faults.
    #[must_use]
    pub fn len(&self) -> usize {
        self.faults.len()
    }

    /// Always false: a dictionary holds at least one fault.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.faults.is_empty()
    }

    /// The faults, in the order of θ's components.
    #[must_use]
    pub fn faults(&self) -> &[Fault] {
        &self.faults
    }

    /// Whether every fault has a known profile (no onset to search).
    #[must_use]
    pub fn is_known_profile(&self) -> bool {
        self.faults.iter().all(|f| f.onset == Onset::Known)
    }

    /// True when every column is the same at every sample given constant model
    /// matrices (zero, constant, or an actuator bias column of G): with an LTI model
    /// the stationary regime then need not evaluate the columns at all.
    #[must_use]
    pub fn is_constant(&self) -> bool {
        self.faults.iter().all(|f| {
            [&f.state, &f.output].iter().all(|c| {
                matches!(
                    c,
                    Column::Zero | Column::Constant(_) | Column::InputBias { .. }
                )
            })
        })
    }

    /// The dimensions the columns were checked against.
    #[must_use]
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// Writes Ψ̃_k (n×m) and Φ̃_k (p×m), column-major, for sample `k`.
    pub fn evaluate(
        &mut self,
        k: u64,
        signals: &Signals<'_>,
        system: &SystemMatrices,
        psi: &mut [f64],
        phi: &mut [f64],
    ) {
        let (n, p) = (self.dims.states, self.dims.outputs);
        for (j, fault) in self.faults.iter_mut().enumerate() {
            let psi_j = &mut psi[j * n..(j + 1) * n];
            evaluate_column(&mut fault.state, k, signals, system, psi_j);
            let phi_j = &mut phi[j * p..(j + 1) * p];
            evaluate_column(&mut fault.output, k, signals, system, phi_j);
        }
    }
}

fn evaluate_column(
    column: &mut Column,
    k: u64,
    signals: &Signals<'_>,
    system: &SystemMatrices,
    out: &mut [f64],
) {
    match column {
        Column::Zero => out.iter_mut().for_each(|x| *x = 0.0),
        Column::Constant(v) => out.copy_from_slice(v.as_slice()),
        Column::InputBias { input } => out.copy_from_slice(system.g.column(*input).as_slice()),
        Column::GainLoss { input } => {
            let u = signals.u.get(*input).copied().unwrap_or(0.0);
            for (o, g) in out.iter_mut().zip(system.g.column(*input).iter()) {
                *o = -g * u;
            }
        }
        Column::Custom(f) => f.evaluate(k, signals, system, out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn dims() -> Dims {
        Dims {
            states: 2,
            inputs: 1,
            outputs: 1,
            signals: 0,
        }
    }

    #[test]
    fn onset_factors_follow_the_paper_profiles() {
        assert_eq!(Onset::Step.state_factor(0), 1.0);
        assert_eq!(Onset::Ramp.state_factor(4), 5.0);
        assert_eq!(Onset::Impulse.state_factor(0), 0.0);
        assert_eq!(Onset::Impulse.entry_factor(), 1.0);
        assert_eq!(Onset::Step.entry_factor(), 0.0);
        assert_eq!(Onset::Impulse.output_factor(0), 1.0);
        assert_eq!(Onset::Impulse.output_factor(1), 0.0);
    }

    #[test]
    fn actuator_columns_follow_g_and_u() {
        let mut d = FaultDictionary::new(
            dims(),
            vec![
                Fault::state("bias", Onset::Step, Column::InputBias { input: 0 }),
                Fault::state("gain", Onset::Step, Column::GainLoss { input: 0 }),
            ],
        )
        .unwrap();
        let mut sys = SystemMatrices::zeros(dims());
        sys.g = DMatrix::from_row_slice(2, 1, &[0.5, 2.0]);
        let (mut psi, mut phi) = ([0.0; 4], [9.0; 2]);
        let s = Signals { u: &[3.0], p: &[] };
        d.evaluate(0, &s, &sys, &mut psi, &mut phi);
        assert_eq!(psi, [0.5, 2.0, -1.5, -6.0]);
        assert_eq!(phi, [0.0, 0.0]);
    }

    #[test]
    fn dictionary_rejects_bad_columns_with_reasons() {
        let e = FaultDictionary::new(
            dims(),
            vec![Fault::state(
                "a",
                Onset::Step,
                Column::Constant(DVector::zeros(3)),
            )],
        )
        .unwrap_err();
        assert!(e.to_string().contains("has 3 entries, expected 2"), "{e}");
        let e = FaultDictionary::new(
            dims(),
            vec![
                Fault::state("a", Onset::Known, Column::InputBias { input: 0 }),
                Fault::state("b", Onset::Step, Column::InputBias { input: 0 }),
            ],
        )
        .unwrap_err();
        assert!(e.to_string().contains("cannot be mixed"), "{e}");
        let e = FaultDictionary::new(
            dims(),
            vec![Fault::state(
                "a",
                Onset::Step,
                Column::GainLoss { input: 1 },
            )],
        )
        .unwrap_err();
        assert!(e.to_string().contains("input u1 does not exist"), "{e}");
    }
}
