//! Signals in natural units: the affine map between what the plant publishes and what
//! the model is written in.
//!
//! A model identified from recordings (or written around an operating point) works in
//! centred and scaled units, model value = (raw value − offset) / scale, one offset and
//! one scale per input and output. [`SignalScaling`] applies that map to every sample on
//! intake, so the plant's raw signals go in unchanged, and its inverse to simulated
//! samples, so that simulated files look like the plant's.
//!
//! The map is a change of units of U_k and Y_k only: the Kalman filter and the GLR run
//! on the model's units, and the GLR is invariant under it (the whitened innovation does
//! not change), which `tests/scale_invariance.rs` checks.

use crate::error::ModelError;

/// Per-signal operating point and scale: model = (raw − offset) / scale.
///
/// # Examples
///
/// ```
/// use glrmon_core::SignalScaling;
///
/// // One input around 3 V, two levels around 12 cm and 1400 cm.
/// let scaling = SignalScaling::new(vec![3.0], vec![0.5], vec![12.0, 1400.0], vec![0.1, 20.0])?;
/// let (mut u, mut y) = ([0.0], [0.0; 2]);
/// scaling.to_model(&[3.5], &[12.2, 1380.0], &mut u, &mut y);
/// assert_eq!(u, [1.0]);
/// assert!((y[0] - 2.0).abs() < 1e-12 && (y[1] + 1.0).abs() < 1e-12);
/// # Ok::<(), glrmon_core::ModelError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SignalScaling {
    u_offset: Vec<f64>,
    u_scale: Vec<f64>,
    y_offset: Vec<f64>,
    y_scale: Vec<f64>,
}

impl SignalScaling {
    /// A scaling of l inputs (`u_offset`, `u_scale`) and p outputs (`y_offset`,
    /// `y_scale`).
    ///
    /// # Errors
    /// [`ModelError::Setting`] when an offset and its scale have different lengths, an
    /// offset is not finite, or a scale is not finite and positive (the message names
    /// the entry).
    pub fn new(
        u_offset: Vec<f64>,
        u_scale: Vec<f64>,
        y_offset: Vec<f64>,
        y_scale: Vec<f64>,
    ) -> Result<Self, ModelError> {
        for (what, offset, scale) in [("u", &u_offset, &u_scale), ("y", &y_offset, &y_scale)] {
            if offset.len() != scale.len() {
                return Err(setting(format!(
                    "{what}_offset has {} entries but {what}_scale has {}",
                    offset.len(),
                    scale.len()
                )));
            }
            if let Some(i) = offset.iter().position(|v| !v.is_finite()) {
                return Err(setting(format!(
                    "{what}_offset[{i}] = {} is not finite",
                    offset[i]
                )));
            }
            if let Some(i) = scale.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(setting(format!(
                    "{what}_scale[{i}] = {} must be finite and positive",
                    scale[i]
                )));
            }
        }
        Ok(Self {
            u_offset,
            u_scale,
            y_offset,
            y_scale,
        })
    }

    /// Number of inputs l.
    #[must_use]
    pub fn inputs(&self) -> usize {
        self.u_offset.len()
    }

    /// Number of outputs p.
    #[must_use]
    pub fn outputs(&self) -> usize {
        self.y_offset.len()
    }

    /// Input offsets (the operating point of U).
    #[must_use]
    pub fn u_offset(&self) -> &[f64] {
        &self.u_offset
    }

    /// Input scales.
    #[must_use]
    pub fn u_scale(&self) -> &[f64] {
        &self.u_scale
    }

    /// Output offsets (the operating point of Y).
    #[must_use]
    pub fn y_offset(&self) -> &[f64] {
        &self.y_offset
    }

    /// Output scales.
    #[must_use]
    pub fn y_scale(&self) -> &[f64] {
        &self.y_scale
    }

    /// Raw U, Y → model U, Y. Entries past the shorter of a raw slice, its output slice
    /// and the scaling are left untouched: the caller checks dimensions (the detector
    /// reports a wrong one). Allocation-free.
    pub fn to_model(&self, raw_u: &[f64], raw_y: &[f64], u: &mut [f64], y: &mut [f64]) {
        forward(raw_u, &self.u_offset, &self.u_scale, u);
        forward(raw_y, &self.y_offset, &self.y_scale, y);
    }

    /// Model U, Y → raw U, Y in place (for simulated samples).
    pub fn to_raw(&self, u: &mut [f64], y: &mut [f64]) {
        backward(u, &self.u_offset, &self.u_scale);
        backward(y, &self.y_offset, &self.y_scale);
    }

    /// Raw U → model U in place (a simulated raw input entering the model).
    pub fn input_to_model(&self, u: &mut [f64]) {
        for ((x, o), s) in u.iter_mut().zip(&self.u_offset).zip(&self.u_scale) {
            *x = (*x - o) / s;
        }
    }
}

fn forward(raw: &[f64], offset: &[f64], scale: &[f64], out: &mut [f64]) {
    for (((o, r), off), s) in out.iter_mut().zip(raw).zip(offset).zip(scale) {
        *o = (r - off) / s;
    }
}

fn backward(values: &mut [f64], offset: &[f64], scale: &[f64]) {
    for ((x, off), s) in values.iter_mut().zip(offset).zip(scale) {
        *x = x.mul_add(*s, *off);
    }
}

fn setting(detail: String) -> ModelError {
    ModelError::Setting {
        what: "scaling",
        detail,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn to_raw_inverts_to_model() {
        let s = SignalScaling::new(vec![3.0, -1.0], vec![0.5, 2.0], vec![1e3], vec![1e-1])
            .expect("valid");
        let (raw_u, raw_y) = ([3.7, 0.25], [1000.123]);
        let (mut u, mut y) = ([0.0; 2], [0.0]);
        s.to_model(&raw_u, &raw_y, &mut u, &mut y);
        s.to_raw(&mut u, &mut y);
        for (a, b) in u.iter().chain(&y).zip(raw_u.iter().chain(&raw_y)) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} vs {b}");
        }
    }

    #[test]
    fn bad_entries_are_named() {
        let e = SignalScaling::new(vec![0.0], vec![0.0], vec![], vec![]).unwrap_err();
        assert!(e.to_string().contains("u_scale[0] = 0"), "{e}");
        let e = SignalScaling::new(vec![], vec![], vec![f64::NAN], vec![1.0]).unwrap_err();
        assert!(e.to_string().contains("y_offset[0]"), "{e}");
        let e = SignalScaling::new(vec![1.0], vec![], vec![], vec![]).unwrap_err();
        assert!(e.to_string().contains("u_scale has 0"), "{e}");
    }

    #[test]
    fn non_finite_raw_values_stay_non_finite() {
        let s = SignalScaling::new(vec![], vec![], vec![5.0], vec![2.0]).expect("valid");
        let mut y = [0.0];
        s.to_model(&[], &[f64::INFINITY], &mut [], &mut y);
        assert!(y[0].is_infinite());
    }
}
