//! Raw records of little-endian f64 values in the order `[channels.raw] layout` gives
//! (`k`, `t`, the channel's signals, `_` for 8 bytes not read); a payload holds one or
//! more whole records, one sample each.

use glrmon_spec::{Columns, PayloadFormat, RawField, RawLayout};
use glrmon_wire::{DecodeError, DecodeErrorKind, DecodeLimits, Sample, SizeLimit};

use super::{PayloadDecoder, slot, within_limit};

/// Largest `k` an f64 holds exactly (2⁵³).
const MAX_EXACT_INDEX: f64 = 9_007_199_254_740_992.0;

/// The decoder of a `raw` channel.
#[derive(Debug, Clone)]
pub struct RawDecoder {
    layout: RawLayout,
    /// The name of each field, for errors: `k`, `t` or the signal's column name.
    names: Vec<String>,
    dims: [usize; 3],
}

impl RawDecoder {
    /// A decoder of records laid out as `layout`, naming fields as `columns` does.
    #[must_use]
    pub fn new(layout: RawLayout, columns: &Columns) -> Self {
        let names = layout
            .fields
            .iter()
            .map(|f| match *f {
                RawField::K => "k".to_owned(),
                RawField::T => "t".to_owned(),
                RawField::U(i) => columns.u[i].clone(),
                RawField::Y(i) => columns.y[i].clone(),
                RawField::P(i) => columns.p[i].clone(),
                RawField::Skip => "_".to_owned(),
            })
            .collect();
        let dims = [columns.u.len(), columns.y.len(), columns.p.len()];
        Self {
            layout,
            names,
            dims,
        }
    }
}

impl PayloadDecoder for RawDecoder {
    fn format(&self) -> &'static str {
        PayloadFormat::Raw(RawLayout::default()).name()
    }

    fn decode(
        &mut self,
        channel: &str,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        let fail = |out: &mut Vec<Sample>, field: Option<String>, kind| {
            out.clear();
            Err(DecodeError::new(channel, field, kind))
        };
        if let Err(e) = within_limit(channel, None, payload, limits) {
            out.clear();
            return Err(e);
        }
        let size = self.layout.record_bytes();
        if payload.is_empty() || !payload.len().is_multiple_of(size) {
            return fail(
                out,
                None,
                DecodeErrorKind::WrongType {
                    expected: format!(
                        "whole records of {size} bytes ({} little-endian f64), not {} bytes",
                        self.layout.fields.len(),
                        payload.len()
                    ),
                },
            );
        }
        let count = payload.len() / size;
        if count > limits.max_batch {
            let (what, limit) = (SizeLimit::BatchLen, limits.max_batch);
            return fail(
                out,
                None,
                DecodeErrorKind::TooLarge {
                    what,
                    limit,
                    got: count,
                },
            );
        }
        let [l, m, q] = self.dims;
        for (r, record) in payload.chunks_exact(size).enumerate() {
            let sample = slot(out, r);
            sample.u.resize(l, 0.0);
            sample.y.resize(m, 0.0);
            sample.p.resize(q, 0.0);
            for ((field, bytes), name) in self
                .layout
                .fields
                .iter()
                .zip(record.chunks_exact(8))
                .zip(&self.names)
            {
                let mut le = [0u8; 8];
                le.copy_from_slice(bytes);
                let v = f64::from_le_bytes(le);
                let at = || {
                    if count == 1 {
                        name.clone()
                    } else {
                        format!("[{r}].{name}")
                    }
                };
                if *field != RawField::Skip && !v.is_finite() {
                    return fail(out, Some(at()), DecodeErrorKind::NonFinite);
                }
                match *field {
                    RawField::K => {
                        if v < 0.0 || v.fract() != 0.0 || v >= MAX_EXACT_INDEX {
                            return fail(
                                out,
                                Some(at()),
                                DecodeErrorKind::WrongType {
                                    expected: "a non-negative integer below 2^53".into(),
                                },
                            );
                        }
                        // Exact: an integer below 2⁵³.
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        let k = v as u64;
                        sample.k = Some(k);
                    }
                    RawField::T => sample.t = Some(v),
                    RawField::U(i) => sample.u[i] = v,
                    RawField::Y(i) => sample.y[i] = v,
                    RawField::P(i) => sample.p[i] = v,
                    RawField::Skip => {}
                }
            }
        }
        out.truncate(count);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_wire::ErrorCode;

    fn decoder() -> RawDecoder {
        let columns = Columns {
            u: vec!["volts".into()],
            y: vec!["amps".into(), "speed".into()],
            p: vec![],
            named: true,
            u_units: vec![],
            y_units: vec![],
            p_units: vec![],
        };
        let layout = RawLayout {
            fields: vec![
                RawField::K,
                RawField::T,
                RawField::Skip,
                RawField::Y(1),
                RawField::U(0),
                RawField::Y(0),
            ],
        };
        RawDecoder::new(layout, &columns)
    }

    fn bytes(values: &[f64]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    #[test]
    fn records_become_samples_in_the_layouts_order() {
        let mut d = decoder();
        let mut out = Vec::new();
        let payload = bytes(&[
            7.0,
            0.07,
            f64::NAN,
            120.5,
            12.0,
            0.8, //
            8.0,
            0.08,
            1e300,
            121.0,
            12.5,
            0.9,
        ]);
        d.decode("dc", &payload, &DecodeLimits::default(), &mut out)
            .unwrap();
        assert_eq!(out.len(), 2);
        assert_eq!(
            (out[1].k, out[1].t, &out[1].u[..], &out[1].y[..]),
            (Some(8), Some(0.08), &[12.5][..], &[0.9, 121.0][..])
        );
        // A single record after two: the buffers are reused, the extra sample dropped.
        d.decode("dc", &payload[..48], &DecodeLimits::default(), &mut out)
            .unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].y, [0.8, 120.5]);
    }

    #[test]
    fn a_bad_record_is_refused_naming_the_field() {
        let mut d = decoder();
        let mut out = Vec::new();
        let limits = DecodeLimits::default();
        let e = d.decode("dc", &[0u8; 20], &limits, &mut out).unwrap_err();
        assert_eq!(e.code(), ErrorCode::WrongType);
        assert!(
            e.to_string()
                .contains("whole records of 48 bytes (6 little-endian f64), not 20 bytes"),
            "{e}"
        );
        let e = d
            .decode(
                "dc",
                &bytes(&[1.0, 0.0, 0.0, 1.0, f64::INFINITY, 0.0]),
                &limits,
                &mut out,
            )
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "channel \"dc\": field volts is not a finite number"
        );
        let two = bytes(&[1.0, 0.0, 0.0, 1.0, 1.0, 0.0, -2.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
        let e = d.decode("dc", &two, &limits, &mut out).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("[1].k"));
        assert!(out.is_empty());
        let e = d.decode("dc", &[], &limits, &mut out).unwrap_err();
        assert_eq!(e.code(), ErrorCode::WrongType);
    }
}
