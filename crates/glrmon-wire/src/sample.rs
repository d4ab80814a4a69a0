//! Plant samples and their strict JSON decoder.
//!
//! A payload is one sample object `{"k":12,"t":1732200000.25,"u":[..],"y":[..],"p":[..]}`
//! or an array of them (a batch, in order). `y` is required; `k`, `t`, `u` and `p` are
//! optional, and `null` counts as absent for them. Anything else is an error with a path
//! to the offending field, so a publisher's mistake is reported, counted and never
//! guessed around.
//!
//! A channel whose signals have names (`[channels.columns]`) may also receive them by
//! name, with [`decode_samples_named`] and the channel's [`SignalNames`]: flat,
//! `{"t": 1.5, "FIC101": 2.1, "FIC102": 1.0, "LI201": 62.3, "LI202": 48.1, "FI301": 1.9}`,
//! or grouped, `{"u": {"FIC101": 2.1, "FIC102": 1.0}, "y": {"LI201": 62.3, …}}`. A
//! payload that names any signal must name every signal of each group it does not give
//! as an array; a name that is not the channel's (or not of that group), or given twice,
//! is an error at that name.
//!
//! The decoder is a set of serde visitors driven directly by serde_json's parser: no
//! intermediate `serde_json::Value`, the caller's sample buffers are reused, and the
//! visitors keep track of where the parser is, so that even a syntax error or an
//! out-of-range number is reported at `y[2]` rather than "line 1 column 40".

use std::borrow::Cow;
use std::fmt;

use schemars::JsonSchema;
use serde::Serialize;
use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Visitor};

use crate::error::{DecodeError, DecodeErrorKind, EncodeError, EncodeErrorKind, SizeLimit};

/// One plant sample: what a channel's model consumes at one instant.
///
/// Letters follow the config: `u` known inputs (length l), `y` outputs (length p), `p`
/// scheduling or other known exogenous signals (length q). Optional vectors are empty
/// when absent.
///
/// On the wire: `{"k": 12, "t": 1732200000.25, "u": [..], "y": [..], "p": [..]}`, where
/// only `y` is required and `null` counts as absent; see [`decode_samples`] and
/// [`encode_sample`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sample {
    /// Sample index. When absent the monitor numbers samples from 0 in order of arrival.
    pub k: Option<u64>,
    /// Time in seconds (any epoch; carried through to results, never used in the math).
    pub t: Option<f64>,
    /// Known inputs u_k.
    pub u: Vec<f64>,
    /// Measured outputs y_k (required).
    pub y: Vec<f64>,
    /// Scheduling / exogenous signals p_k.
    pub p: Vec<f64>,
}

/// Size bounds applied while decoding, so that one bad publisher cannot make the daemon
/// allocate without limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Largest accepted payload in bytes, checked before parsing. Default 1 MiB.
    pub max_payload_bytes: usize,
    /// Most sample objects in one batch array. A single object is always accepted.
    /// Default 10 000.
    pub max_batch: usize,
    /// Most values in one `u`, `y` or `p` array. Default 4096.
    pub max_vector_len: usize,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        DecodeLimits {
            max_payload_bytes: 1 << 20,
            max_batch: 10_000,
            max_vector_len: 4096,
        }
    }
}

impl Sample {
    /// Checks that `u`, `y` and `p` have the lengths of the channel's model (l inputs,
    /// p outputs, q scheduling signals), in that order.
    ///
    /// # Errors
    ///
    /// [`DecodeErrorKind::WrongDimension`] naming the first field whose length differs.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_wire::Sample;
    ///
    /// let s = Sample { y: vec![1.0, 2.0, 3.0], ..Sample::default() };
    /// let err = s.check_dimensions("pump3", 0, 4, 0).unwrap_err();
    /// assert_eq!(err.to_string(), r#"channel "pump3": field y has 3 values, model expects 4"#);
    /// ```
    pub fn check_dimensions(
        &self,
        channel: &str,
        inputs: usize,
        outputs: usize,
        scheduling: usize,
    ) -> Result<(), DecodeError> {
        for (name, values, expected) in [
            ("u", &self.u, inputs),
            ("y", &self.y, outputs),
            ("p", &self.p, scheduling),
        ] {
            if values.len() != expected {
                return Err(DecodeError::new(
                    channel,
                    Some(name.to_owned()),
                    DecodeErrorKind::WrongDimension {
                        expected,
                        got: values.len(),
                    },
                ));
            }
        }
        Ok(())
    }

    /// Checks that `t` and every value of `u`, `y` and `p` are finite.
    ///
    /// [`decode_samples`] already guarantees this; the check is for samples built from
    /// other sources (CSV, MCAP, the simulator).
    ///
    /// # Errors
    ///
    /// [`DecodeErrorKind::NonFinite`] naming the first offending value, e.g. `y[2]`.
    ///
    /// # Examples
    ///
    /// ```
    /// use glrmon_wire::Sample;
    ///
    /// let s = Sample { y: vec![1.0, 2.0, f64::NAN], ..Sample::default() };
    /// let err = s.check_finite("pump3").unwrap_err();
    /// assert_eq!(err.field.as_deref(), Some("y[2]"));
    /// ```
    pub fn check_finite(&self, channel: &str) -> Result<(), DecodeError> {
        match self.first_non_finite() {
            None => Ok(()),
            Some((field, _)) => Err(DecodeError::new(
                channel,
                Some(field),
                DecodeErrorKind::NonFinite,
            )),
        }
    }

    fn first_non_finite(&self) -> Option<(String, f64)> {
        if let Some(t) = self.t.filter(|t| !t.is_finite()) {
            return Some(("t".to_owned(), t));
        }
        for (name, values) in [("u", &self.u), ("y", &self.y), ("p", &self.p)] {
            if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Some((format!("{name}[{i}]"), *v));
            }
        }
        None
    }
}

/// Decodes a Zenoh sample payload (one object or a batch array) into `out`.
///
/// On success `out` holds exactly the payload's samples in order; its previous elements
/// are overwritten in place, so their vectors' capacity is reused and a steady stream of
/// same-shaped payloads decodes without allocating. On error `out` is empty.
///
/// Every number is finite on success: serde_json has no NaN or Infinity literals, and a
/// number beyond the `f64` range (`1e999`) is reported as [`DecodeErrorKind::NonFinite`]
/// at its field. A number below the smallest subnormal (`1e-999`) rounds to 0 as IEEE 754
/// prescribes. Floats are parsed correctly rounded, so a value printed by
/// [`encode_sample`] comes back bit-identical. Integers are accepted where floats are
/// expected. An empty batch `[]` decodes to no samples.
///
/// # Errors
///
/// A [`DecodeError`] for `channel` whose `field` is the path of the first fault:
/// `TooLarge` (payload, batch or vector over `limits`), `InvalidJson`, `WrongType`
/// (including a negative, fractional or float-literal `k`), `MissingField` (`y`),
/// `UnknownField`, `DuplicateField`, `NonFinite`.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{decode_samples, DecodeLimits};
///
/// let mut out = Vec::new();
/// decode_samples("pump3", br#"[{"k":1,"y":[0.5]},{"k":2,"y":[0.25],"u":[1]}]"#,
///                &DecodeLimits::default(), &mut out)?;
/// assert_eq!(out.len(), 2);
/// assert_eq!(out[1].u, [1.0]);
/// # Ok::<(), glrmon_wire::DecodeError>(())
/// ```
pub fn decode_samples(
    channel: &str,
    payload: &[u8],
    limits: &DecodeLimits,
    out: &mut Vec<Sample>,
) -> Result<(), DecodeError> {
    decode(channel, payload, limits, None, out)
}

/// The names of a channel's signals (its `[channels.columns]` `u`, `y` and `p`), by
/// which [`decode_samples_named`] reads payloads that give values by name. Built once
/// per channel: it indexes the names, so that decoding looks each one up without
/// allocating.
///
/// # Examples
///
/// ```
/// use glrmon_wire::SignalNames;
///
/// let names = SignalNames::new(&["FIC101".into()], &["LI201".into(), "LI202".into()], &[]);
/// assert_eq!(names.outputs(), ["LI201", "LI202"]);
/// ```
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SignalNames {
    groups: [Vec<String>; 3],
    /// Each name → (its group: 0 u, 1 y, 2 p; its index in the group). A name given
    /// twice keeps its first place.
    index: std::collections::HashMap<String, (usize, usize)>,
}

impl SignalNames {
    /// The names of the inputs `u`, outputs `y` and scheduling signals `p`, in the
    /// order of the sample's vectors.
    #[must_use]
    pub fn new(u: &[String], y: &[String], p: &[String]) -> Self {
        let groups = [u.to_vec(), y.to_vec(), p.to_vec()];
        let mut index = std::collections::HashMap::new();
        for (g, names) in groups.iter().enumerate() {
            for (i, name) in names.iter().enumerate() {
                index.entry(name.clone()).or_insert((g, i));
            }
        }
        Self { groups, index }
    }

    /// The names of the inputs `u`.
    #[must_use]
    pub fn inputs(&self) -> &[String] {
        &self.groups[0]
    }

    /// The names of the outputs `y`.
    #[must_use]
    pub fn outputs(&self) -> &[String] {
        &self.groups[1]
    }

    /// The names of the scheduling signals `p`.
    #[must_use]
    pub fn signals(&self) -> &[String] {
        &self.groups[2]
    }

    /// Where `name` goes: its group (0 u, 1 y, 2 p) and index, and the name as kept
    /// here (borrowed for error paths).
    fn find(&self, name: &str) -> Option<(usize, usize, &str)> {
        let &(g, i) = self.index.get(name)?;
        Some((g, i, self.groups[g][i].as_str()))
    }
}

/// [`decode_samples`] for a channel whose signals have names: each sample object may
/// give `u`, `y` and `p` as arrays (as [`decode_samples`] reads them), as objects by
/// name (`"u": {"FIC101": 2.1, …}`), or by name at the top level (`"FIC101": 2.1`),
/// and a batch may mix them. Values given by name are put in the order of `names`.
///
/// A payload that gives any value by name must give every signal of each group it does
/// not give as an array. As with [`decode_samples`], a steady stream of same-shaped
/// payloads decodes without allocating.
///
/// # Errors
///
/// As [`decode_samples`], with the field path at the name: `UnknownField` for a name
/// that is not the channel's (`FIC109`) or not of the group it is given in (`u.LI201`),
/// `MissingField` for a signal not given (`FIC102`), `DuplicateField` for a name given
/// twice or a group given both as an array and by name, `WrongType` for a value that is
/// not a number (a named value cannot be `null`).
///
/// # Examples
///
/// ```
/// use glrmon_wire::{DecodeLimits, SignalNames, decode_samples_named};
///
/// let names = SignalNames::new(&["FIC101".into()], &["LI201".into(), "LI202".into()], &[]);
/// let limits = DecodeLimits::default();
/// let mut out = Vec::new();
/// decode_samples_named("tanks", br#"{"t": 1.5, "LI202": 48.1, "FIC101": 2.1, "LI201": 62.3}"#,
///                      &limits, &names, &mut out)?;
/// assert_eq!((out[0].t, &out[0].u[..], &out[0].y[..]), (Some(1.5), &[2.1][..], &[62.3, 48.1][..]));
/// decode_samples_named("tanks", br#"{"u": {"FIC101": 2.1}, "y": {"LI201": 62.3, "LI202": 48.1}}"#,
///                      &limits, &names, &mut out)?;
/// assert_eq!(out[0].y, [62.3, 48.1]);
/// let err = decode_samples_named("tanks", br#"{"FIC101": 2.1, "LI201": 62.3}"#,
///                                &limits, &names, &mut out).unwrap_err();
/// assert_eq!(err.to_string(), r#"channel "tanks": field LI202 is missing"#);
/// # Ok::<(), glrmon_wire::DecodeError>(())
/// ```
pub fn decode_samples_named(
    channel: &str,
    payload: &[u8],
    limits: &DecodeLimits,
    names: &SignalNames,
    out: &mut Vec<Sample>,
) -> Result<(), DecodeError> {
    decode(channel, payload, limits, Some(names), out)
}

fn decode(
    channel: &str,
    payload: &[u8],
    limits: &DecodeLimits,
    names: Option<&SignalNames>,
    out: &mut Vec<Sample>,
) -> Result<(), DecodeError> {
    if payload.len() > limits.max_payload_bytes {
        out.clear();
        return Err(DecodeError::new(
            channel,
            None,
            DecodeErrorKind::TooLarge {
                what: SizeLimit::PayloadBytes,
                limit: limits.max_payload_bytes,
                got: payload.len(),
            },
        ));
    }
    let mut ctx = Ctx::new(limits, names);
    let mut filled = 0;
    let mut de = serde_json::Deserializer::from_slice(payload);
    let result = de::Deserializer::deserialize_any(
        &mut de,
        PayloadVisitor {
            ctx: &mut ctx,
            out,
            filled: &mut filled,
        },
    )
    .and_then(|()| de.end());
    match result {
        Ok(()) => {
            out.truncate(filled);
            Ok(())
        }
        Err(err) => {
            out.clear();
            Err(ctx.into_error(channel, &err))
        }
    }
}

/// Appends one sample as a JSON object to `out`, in the form [`decode_samples`] reads.
///
/// Absent `k` and `t` and empty `u` and `p` are left out. Floats are printed in the
/// shortest form that parses back to the same bits.
///
/// # Errors
///
/// [`EncodeErrorKind::NonFinite`] naming the first non-finite value (`t`, `y[2]`, …);
/// `out` is then unchanged.
///
/// # Examples
///
/// ```
/// use glrmon_wire::{encode_sample, Sample};
///
/// let mut out = Vec::new();
/// encode_sample("pump3", &Sample { k: Some(7), y: vec![0.1 + 0.2], ..Sample::default() }, &mut out)?;
/// assert_eq!(out, br#"{"k":7,"y":[0.30000000000000004]}"#);
/// # Ok::<(), glrmon_wire::EncodeError>(())
/// ```
pub fn encode_sample(channel: &str, sample: &Sample, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    check_encodable(channel, None, sample)?;
    write_json(channel, &SampleJson::from(sample), out)
}

/// Appends a batch of samples as one JSON array to `out`.
///
/// # Errors
///
/// As [`encode_sample`], with the batch index in the field path (`[2].y[0]`).
pub fn encode_samples(
    channel: &str,
    samples: &[Sample],
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    for (i, sample) in samples.iter().enumerate() {
        check_encodable(channel, Some(i), sample)?;
    }
    write_json(channel, &BatchJson(samples), out)
}

fn check_encodable(
    channel: &str,
    batch: Option<usize>,
    sample: &Sample,
) -> Result<(), EncodeError> {
    match sample.first_non_finite() {
        None => Ok(()),
        Some((field, value)) => Err(EncodeError {
            channel: channel.to_owned(),
            field: match batch {
                Some(i) => format!("[{i}].{field}"),
                None => field,
            },
            kind: EncodeErrorKind::NonFinite { value },
        }),
    }
}

pub(crate) fn write_json<T: Serialize + ?Sized>(
    channel: &str,
    value: &T,
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    let start = out.len();
    serde_json::to_writer(&mut *out, value).map_err(|e| {
        out.truncate(start);
        EncodeError {
            channel: channel.to_owned(),
            field: String::new(),
            kind: EncodeErrorKind::Serialize(e.to_string()),
        }
    })
}

/// A plant sample, as the monitor decoded it (docs/WIRE.md).
//
// The serialized form of a `Sample`. Private, so that nothing serializes a sample without
// the finiteness check (serde_json would write NaN as `null`). Its JSON Schema
// (`sample_schema`) describes what is written, which never holds `null`: hence the
// serialize contract there and `with` below; `deny_unknown_fields` as `decode_samples`
// refuses unknown fields.
#[derive(Serialize, JsonSchema)]
#[schemars(title = "glrmon sample", deny_unknown_fields)]
pub(crate) struct SampleJson<'a> {
    /// Sample index k; absent when the publisher gave none (the monitor then numbers
    /// samples from 0 in order of arrival).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u64")]
    k: Option<u64>,
    /// Time in seconds (any epoch; carried through to results, never used in the math).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "f64")]
    t: Option<f64>,
    /// Known inputs u_k; absent when the model has none.
    #[serde(skip_serializing_if = "<[f64]>::is_empty")]
    u: &'a [f64],
    /// Measured outputs y_k.
    y: &'a [f64],
    /// Scheduling or other known exogenous signals p_k; absent when the model has none.
    #[serde(skip_serializing_if = "<[f64]>::is_empty")]
    p: &'a [f64],
}

/// A batch serialized as an array without collecting the [`SampleJson`]s first.
struct BatchJson<'a>(&'a [Sample]);

impl Serialize for BatchJson<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.0.iter().map(SampleJson::from))
    }
}

impl<'a> From<&'a Sample> for SampleJson<'a> {
    fn from(s: &'a Sample) -> Self {
        SampleJson {
            k: s.k,
            t: s.t,
            u: &s.u,
            y: &s.y,
            p: &s.p,
        }
    }
}

/// Where the parser is, and the precise error if a visitor rejected a value.
///
/// serde_json errors carry only a line and column; keeping the path here lets every
/// error, even one raised inside the parser, name the field it happened in.
struct Ctx<'l> {
    limits: &'l DecodeLimits,
    /// The channel's signal names, when payloads may give values by name.
    names: Option<&'l SignalNames>,
    /// Index in the batch array, when inside one.
    batch: Option<usize>,
    /// Current field name (a signal's borrowed from `names`); owned only for an unknown
    /// field (the error path).
    field: Option<Cow<'l, str>>,
    /// The name inside the current field's object (`u.FIC101`); owned only for an
    /// unknown name.
    sub: Option<Cow<'l, str>>,
    /// Index inside the current vector field.
    index: Option<usize>,
    /// What the format expects at the current position, for `WrongType`.
    expected: &'static str,
    /// Set by a visitor that rejects a value for a reason of its own; takes precedence
    /// over the serde_json error that carries it up.
    failure: Option<DecodeErrorKind>,
}

const EXPECT_PAYLOAD: &str = "a sample object or an array of sample objects";
const EXPECT_SAMPLE: &str = "a sample object";
const EXPECT_K: &str = "a non-negative integer or null";
const EXPECT_T: &str = "a number or null";
const EXPECT_VEC: &str = "an array of numbers";
const EXPECT_OPT_VEC: &str = "an array of numbers or null";
const EXPECT_NAMED_VEC: &str = "an array of numbers or an object of numbers by signal name";
const EXPECT_NAMED_OPT_VEC: &str =
    "an array of numbers, an object of numbers by signal name, or null";
const EXPECT_NUMBER: &str = "a number";

impl<'l> Ctx<'l> {
    fn new(limits: &'l DecodeLimits, names: Option<&'l SignalNames>) -> Self {
        Ctx {
            limits,
            names,
            batch: None,
            field: None,
            sub: None,
            index: None,
            expected: EXPECT_PAYLOAD,
            failure: None,
        }
    }

    /// Records `kind` and returns an error to unwind serde with; the text is never shown.
    fn fail<E: de::Error>(&mut self, kind: DecodeErrorKind) -> E {
        self.failure = Some(kind);
        E::custom("rejected by glrmon-wire")
    }

    fn path(&self) -> Option<String> {
        let mut path = String::new();
        if let Some(b) = self.batch {
            path.push_str(&format!("[{b}]"));
        }
        if let Some(field) = &self.field {
            if !path.is_empty() {
                path.push('.');
            }
            path.push_str(field);
            if let Some(sub) = &self.sub {
                path.push('.');
                path.push_str(sub);
            }
            if let Some(i) = self.index {
                path.push_str(&format!("[{i}]"));
            }
        }
        (!path.is_empty()).then_some(path)
    }

    fn in_float_field(&self) -> bool {
        match self.field.as_deref() {
            Some("t" | "u" | "y" | "p") => true,
            // A value given by name.
            Some(name) => self.names.is_some_and(|n| n.find(name).is_some()),
            None => false,
        }
    }

    fn into_error(mut self, channel: &str, err: &serde_json::Error) -> DecodeError {
        let kind = match self.failure.take() {
            Some(kind) => kind,
            None => match err.classify() {
                // Data errors come only from our visitors' default `invalid_type`.
                serde_json::error::Category::Data => DecodeErrorKind::WrongType {
                    expected: self.expected.to_owned(),
                },
                serde_json::error::Category::Syntax if is_out_of_range(err) => {
                    if self.in_float_field() {
                        DecodeErrorKind::NonFinite
                    } else {
                        DecodeErrorKind::WrongType {
                            expected: self.expected.to_owned(),
                        }
                    }
                }
                _ => DecodeErrorKind::InvalidJson(err.to_string()),
            },
        };
        DecodeError::new(channel, self.path(), kind)
    }
}

/// serde_json reports a number beyond the f64 range (`1e999`) as a syntax error with this
/// text and no dedicated category; it is the only way to tell it apart.
pub(crate) fn is_out_of_range(err: &serde_json::Error) -> bool {
    err.to_string().starts_with("number out of range")
}

/// Grows `out` to hold index `i` and returns that slot.
fn slot(out: &mut Vec<Sample>, i: usize) -> &mut Sample {
    if out.len() <= i {
        out.resize_with(i + 1, Sample::default);
    }
    &mut out[i]
}

struct PayloadVisitor<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
    out: &'c mut Vec<Sample>,
    filled: &'c mut usize,
}

impl<'de> Visitor<'de> for PayloadVisitor<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(EXPECT_PAYLOAD)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<(), A::Error> {
        SampleVisitor {
            ctx: self.ctx,
            sample: slot(self.out, 0),
        }
        .visit_map(map)?;
        *self.filled = 1;
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0;
        loop {
            if i == self.ctx.limits.max_batch {
                self.ctx.batch = None;
                let mut extra = 0;
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    extra += 1;
                }
                if extra == 0 {
                    break;
                }
                let limit = self.ctx.limits.max_batch;
                return Err(self.ctx.fail(DecodeErrorKind::TooLarge {
                    what: SizeLimit::BatchLen,
                    limit,
                    got: limit + extra,
                }));
            }
            self.ctx.batch = Some(i);
            self.ctx.expected = EXPECT_SAMPLE;
            let seed = SampleSeed {
                ctx: &mut *self.ctx,
                sample: slot(self.out, i),
            };
            let more = seq.next_element_seed(seed)?.is_some();
            self.ctx.batch = None;
            if !more {
                break;
            }
            i += 1;
        }
        *self.filled = i;
        Ok(())
    }
}

struct SampleSeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
    sample: &'c mut Sample,
}

impl<'de> DeserializeSeed<'de> for SampleSeed<'_, '_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<(), D::Error> {
        de.deserialize_map(SampleVisitor {
            ctx: self.ctx,
            sample: self.sample,
        })
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Field {
    K,
    T,
    U,
    Y,
    P,
}

impl Field {
    const fn name(self) -> &'static str {
        match self {
            Field::K => "k",
            Field::T => "t",
            Field::U => "u",
            Field::Y => "y",
            Field::P => "p",
        }
    }

    const fn bit(self) -> u8 {
        1 << (self as u8)
    }

    /// The group number of u, y, p (as [`SignalNames`] numbers them).
    const fn group(self) -> usize {
        match self {
            Field::U => 0,
            Field::Y => 1,
            _ => 2,
        }
    }
}

struct SampleVisitor<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
    sample: &'c mut Sample,
}

impl<'de> Visitor<'de> for SampleVisitor<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(EXPECT_SAMPLE)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let Self { ctx, sample } = self;
        sample.k = None;
        sample.t = None;
        sample.u.clear();
        sample.y.clear();
        sample.p.clear();
        let mut seen = 0_u8;
        // Which of u, y, p were given by name (an object, or names at the top level).
        let mut by_name = [false; 3];
        while let Some(key) = map.next_key_seed(KeySeed { ctx: &mut *ctx })? {
            let field = match key {
                Key::Field(field) => field,
                Key::Signal { group, index, name } => {
                    ctx.field = Some(Cow::Borrowed(name));
                    if seen & GROUPS[group].bit() != 0 && !by_name[group] {
                        // The group was given as an array already.
                        return Err(ctx.fail(DecodeErrorKind::DuplicateField));
                    }
                    let values = group_values(sample, group);
                    named_value(ctx, &mut map, values, &mut by_name[group], group, index)?;
                    ctx.field = None;
                    continue;
                }
            };
            ctx.field = Some(Cow::Borrowed(field.name()));
            if seen & field.bit() != 0 {
                return Err(ctx.fail(DecodeErrorKind::DuplicateField));
            }
            seen |= field.bit();
            match field {
                Field::K => {
                    ctx.expected = EXPECT_K;
                    sample.k = map.next_value_seed(KSeed)?;
                }
                Field::T => {
                    ctx.expected = EXPECT_T;
                    sample.t = map.next_value_seed(TSeed { ctx: &mut *ctx })?;
                }
                Field::U | Field::Y | Field::P => {
                    let group = field.group();
                    if by_name[group] {
                        // Some of its values were given by name already.
                        return Err(ctx.fail(DecodeErrorKind::DuplicateField));
                    }
                    let optional = field != Field::Y;
                    ctx.expected = match (ctx.names.is_some(), optional) {
                        (true, true) => EXPECT_NAMED_OPT_VEC,
                        (true, false) => EXPECT_NAMED_VEC,
                        (false, true) => EXPECT_OPT_VEC,
                        (false, false) => EXPECT_VEC,
                    };
                    map.next_value_seed(VecSeed {
                        ctx: &mut *ctx,
                        values: group_values(sample, group),
                        optional,
                        group,
                        by_name: &mut by_name[group],
                    })?;
                }
            }
            ctx.field = None;
        }
        if let (Some(names), true) = (ctx.names, by_name.contains(&true)) {
            // Every signal of a group not given as an array must have been named.
            for (group, field) in GROUPS.into_iter().enumerate() {
                if seen & field.bit() != 0 && !by_name[group] {
                    continue;
                }
                let values = group_values(sample, group);
                if !by_name[group] {
                    unnamed(values, names.groups[group].len());
                }
                if let Some(i) = values.iter().position(|v| v.is_nan()) {
                    ctx.field = Some(Cow::Borrowed(names.groups[group][i].as_str()));
                    return Err(ctx.fail(DecodeErrorKind::MissingField));
                }
            }
        } else if seen & Field::Y.bit() == 0 {
            ctx.field = Some(Cow::Borrowed("y"));
            return Err(ctx.fail(DecodeErrorKind::MissingField));
        }
        Ok(())
    }
}

/// The fields of u, y, p by group number (as [`SignalNames`] numbers them).
const GROUPS: [Field; 3] = [Field::U, Field::Y, Field::P];

fn group_values(sample: &mut Sample, group: usize) -> &mut Vec<f64> {
    match group {
        0 => &mut sample.u,
        1 => &mut sample.y,
        _ => &mut sample.p,
    }
}

/// A group's values before any is given by name: one slot per signal, NaN until given
/// (a decoded value is never NaN). Allocates only when the vector is smaller.
fn unnamed(values: &mut Vec<f64>, signals: usize) {
    values.clear();
    values.resize(signals, f64::NAN);
}

/// The value of the signal `index` of `group`, given by name: a number, which goes in
/// its slot unless one was given for it already (a duplicate).
fn named_value<'de, 'l, A: MapAccess<'de>>(
    ctx: &mut Ctx<'l>,
    map: &mut A,
    values: &mut Vec<f64>,
    by_name: &mut bool,
    group: usize,
    index: usize,
) -> Result<(), A::Error> {
    if !*by_name {
        let signals = ctx.names.map_or(0, |n| n.groups[group].len());
        unnamed(values, signals);
        *by_name = true;
    }
    ctx.expected = EXPECT_NUMBER;
    let v = map.next_value_seed(NumberSeed { ctx: &mut *ctx })?;
    match values.get_mut(index) {
        Some(slot) if slot.is_nan() => {
            *slot = v;
            Ok(())
        }
        _ => Err(ctx.fail(DecodeErrorKind::DuplicateField)),
    }
}

/// A key of a sample object: a field of the format, or a signal's name.
enum Key<'l> {
    Field(Field),
    Signal {
        /// 0 u, 1 y, 2 p.
        group: usize,
        index: usize,
        /// The name, borrowed from the channel's [`SignalNames`].
        name: &'l str,
    },
}

struct KeySeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
}

impl<'de, 'l> DeserializeSeed<'de> for KeySeed<'_, 'l> {
    type Value = Key<'l>;

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<Key<'l>, D::Error> {
        de.deserialize_str(self)
    }
}

impl<'de, 'l> Visitor<'de> for KeySeed<'_, 'l> {
    type Value = Key<'l>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a field name")
    }

    fn visit_str<E: de::Error>(self, name: &str) -> Result<Key<'l>, E> {
        match name {
            "k" => Ok(Key::Field(Field::K)),
            "t" => Ok(Key::Field(Field::T)),
            "u" => Ok(Key::Field(Field::U)),
            "y" => Ok(Key::Field(Field::Y)),
            "p" => Ok(Key::Field(Field::P)),
            other => match self.ctx.names.and_then(|n| n.find(other)) {
                Some((group, index, name)) => Ok(Key::Signal { group, index, name }),
                None => {
                    self.ctx.field = Some(Cow::Owned(other.to_owned()));
                    Err(self.ctx.fail(DecodeErrorKind::UnknownField))
                }
            },
        }
    }
}

/// A name inside a group's object (`"u": {"FIC101": …}`): one of that group's signals.
struct GroupKeySeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
    group: usize,
}

impl<'de, 'l> DeserializeSeed<'de> for GroupKeySeed<'_, 'l> {
    type Value = (usize, &'l str);

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<Self::Value, D::Error> {
        de.deserialize_str(self)
    }
}

impl<'de, 'l> Visitor<'de> for GroupKeySeed<'_, 'l> {
    type Value = (usize, &'l str);

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a signal's name")
    }

    fn visit_str<E: de::Error>(self, name: &str) -> Result<Self::Value, E> {
        match self.ctx.names.and_then(|n| n.find(name)) {
            Some((group, index, name)) if group == self.group => Ok((index, name)),
            _ => {
                self.ctx.sub = Some(Cow::Owned(name.to_owned()));
                Err(self.ctx.fail(DecodeErrorKind::UnknownField))
            }
        }
    }
}

struct KSeed;

impl<'de> DeserializeSeed<'de> for KSeed {
    type Value = Option<u64>;

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<Option<u64>, D::Error> {
        de.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for KSeed {
    type Value = Option<u64>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(EXPECT_K)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Option<u64>, E> {
        Ok(Some(v))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Option<u64>, E> {
        Ok(None)
    }
    // Negative (visit_i64) and float-literal (visit_f64) values, `12.0` and `1e3`
    // included, fall to serde's default `invalid_type`, i.e. WrongType: an index is
    // written as a plain non-negative integer.
}

struct TSeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
}

impl<'de> DeserializeSeed<'de> for TSeed<'_, '_> {
    type Value = Option<f64>;

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<Option<f64>, D::Error> {
        de.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for TSeed<'_, '_> {
    type Value = Option<f64>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(EXPECT_T)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Option<f64>, E> {
        finite(self.ctx, v).map(Some)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Option<f64>, E> {
        // Integers are numbers too; above 2^53 they round like any JSON reader's.
        Ok(Some(v as f64))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Option<f64>, E> {
        Ok(Some(v as f64))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Option<f64>, E> {
        Ok(None)
    }
}

fn finite<E: de::Error>(ctx: &mut Ctx<'_>, v: f64) -> Result<f64, E> {
    // serde_json never yields a non-finite f64 (it rejects 1e999 itself); this guards
    // against a future parser change rather than a known input.
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ctx.fail(DecodeErrorKind::NonFinite))
    }
}

struct VecSeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
    values: &'c mut Vec<f64>,
    optional: bool,
    /// The group (0 u, 1 y, 2 p), for values given by name.
    group: usize,
    /// Set when the values were given by name.
    by_name: &'c mut bool,
}

impl<'de> DeserializeSeed<'de> for VecSeed<'_, '_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<(), D::Error> {
        de.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for VecSeed<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.optional {
            EXPECT_OPT_VEC
        } else {
            EXPECT_VEC
        })
    }

    fn visit_unit<E: de::Error>(self) -> Result<(), E> {
        if self.optional {
            Ok(())
        } else {
            Err(E::invalid_type(de::Unexpected::Unit, &self))
        }
    }

    /// `"u": {"FIC101": 2.1, …}`: values by name, on a channel that names its signals.
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        if self.ctx.names.is_none() {
            return Err(de::Error::invalid_type(de::Unexpected::Map, &self));
        }
        let Self {
            ctx,
            values,
            group,
            by_name,
            ..
        } = self;
        let signals = ctx.names.map_or(0, |n| n.groups[group].len());
        unnamed(values, signals);
        *by_name = true;
        while let Some((index, name)) = map.next_key_seed(GroupKeySeed {
            ctx: &mut *ctx,
            group,
        })? {
            ctx.sub = Some(Cow::Borrowed(name));
            ctx.expected = EXPECT_NUMBER;
            let v = map.next_value_seed(NumberSeed { ctx: &mut *ctx })?;
            match values.get_mut(index) {
                Some(slot) if slot.is_nan() => *slot = v,
                _ => return Err(ctx.fail(DecodeErrorKind::DuplicateField)),
            }
            ctx.sub = None;
        }
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let Self { ctx, values, .. } = self;
        let limit = ctx.limits.max_vector_len;
        loop {
            if values.len() == limit {
                ctx.index = None;
                let mut extra = 0;
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    extra += 1;
                }
                if extra == 0 {
                    break;
                }
                return Err(ctx.fail(DecodeErrorKind::TooLarge {
                    what: SizeLimit::VectorLen,
                    limit,
                    got: limit + extra,
                }));
            }
            ctx.index = Some(values.len());
            ctx.expected = EXPECT_NUMBER;
            match seq.next_element_seed(NumberSeed { ctx: &mut *ctx })? {
                Some(v) => values.push(v),
                None => break,
            }
        }
        ctx.index = None;
        Ok(())
    }
}

struct NumberSeed<'c, 'l> {
    ctx: &'c mut Ctx<'l>,
}

impl<'de> DeserializeSeed<'de> for NumberSeed<'_, '_> {
    type Value = f64;

    fn deserialize<D: de::Deserializer<'de>>(self, de: D) -> Result<f64, D::Error> {
        de.deserialize_f64(self)
    }
}

impl<'de> Visitor<'de> for NumberSeed<'_, '_> {
    type Value = f64;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(EXPECT_NUMBER)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        finite(self.ctx, v)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        Ok(v as f64)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        Ok(v as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::ErrorCode;
    use proptest::prelude::*;

    fn decode(payload: &str) -> Result<Vec<Sample>, DecodeError> {
        decode_with(payload, &DecodeLimits::default())
    }

    fn decode_with(payload: &str, limits: &DecodeLimits) -> Result<Vec<Sample>, DecodeError> {
        let mut out = Vec::new();
        decode_samples("pump3", payload.as_bytes(), limits, &mut out).map(|()| out)
    }

    /// Asserts the code and field of a rejection and that the message names both.
    fn assert_rejects(payload: &str, code: ErrorCode, field: Option<&str>) -> DecodeError {
        let err = decode(payload).unwrap_err();
        assert_eq!(err.code(), code, "{payload}: {err}");
        assert_eq!(err.field.as_deref(), field, "{payload}: {err}");
        let msg = err.to_string();
        assert!(msg.starts_with(r#"channel "pump3": "#), "{msg}");
        if let Some(field) = field {
            assert!(msg.contains(&format!("field {field} ")), "{msg}");
        }
        err
    }

    #[test]
    fn decodes_a_full_object() {
        let s = decode(r#"{"k":12,"t":1732200000.25,"u":[1,2],"y":[0.5,-1e-3],"p":[3]}"#).unwrap();
        assert_eq!(
            s,
            [Sample {
                k: Some(12),
                t: Some(1_732_200_000.25),
                u: vec![1.0, 2.0],
                y: vec![0.5, -1e-3],
                p: vec![3.0],
            }]
        );
    }

    #[test]
    fn optional_fields_default_to_absent_and_null_means_absent() {
        let want = [Sample {
            y: vec![1.0],
            ..Sample::default()
        }];
        assert_eq!(decode(r#"{"y":[1]}"#).unwrap(), want);
        assert_eq!(
            decode(r#"{"k":null,"t":null,"u":null,"p":null,"y":[1]}"#).unwrap(),
            want
        );
        assert_eq!(decode(r#" { "y" : [ 1 ] } "#).unwrap(), want);
        assert_eq!(decode(r#"{"y":[]}"#).unwrap(), [Sample::default()]);
    }

    #[test]
    fn decodes_a_batch_in_order() {
        let s = decode(r#"[{"k":0,"y":[1]},{"k":1,"y":[2]},{"y":[3],"k":2}]"#).unwrap();
        let ks: Vec<_> = s.iter().map(|s| s.k).collect();
        assert_eq!(ks, [Some(0), Some(1), Some(2)]);
        assert_eq!(s[2].y, [3.0]);
        assert_eq!(decode("[]").unwrap(), []);
    }

    /// Counts this thread's allocations, so that tests running in parallel on other
    /// threads do not disturb the count.
    struct CountingAlloc;

    thread_local! {
        static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }

    // SAFETY: forwards to the system allocator unchanged; the counter is a const-initialised
    // thread-local `Cell` without destructor, whose access does not allocate.
    unsafe impl std::alloc::GlobalAlloc for CountingAlloc {
        unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
            ALLOCATIONS.with(|c| c.set(c.get() + 1));
            // SAFETY: same contract as the caller's.
            unsafe { std::alloc::System.alloc(layout) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
            // SAFETY: same contract as the caller's.
            unsafe { std::alloc::System.dealloc(ptr, layout) }
        }

        unsafe fn realloc(
            &self,
            ptr: *mut u8,
            layout: std::alloc::Layout,
            new_size: usize,
        ) -> *mut u8 {
            ALLOCATIONS.with(|c| c.set(c.get() + 1));
            // SAFETY: same contract as the caller's.
            unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
        }
    }

    #[global_allocator]
    static ALLOC: CountingAlloc = CountingAlloc;

    /// The claim in `decode_samples`' docs: once `out` has grown to the payload's shape,
    /// decoding more such payloads performs no allocation at all (serde_json borrows
    /// unescaped keys, and its scratch buffer is used only for numbers of more than 19
    /// significant digits, which shortest-roundtrip printing never produces).
    #[test]
    fn steady_stream_decodes_without_allocating() {
        let limits = DecodeLimits::default();
        let payloads: Vec<Vec<u8>> = (0..100_u32)
            .map(|i| {
                let x = f64::from(i) * 0.1 + 1e-300;
                let sample = Sample {
                    k: Some(u64::from(i)),
                    t: Some(x),
                    u: vec![x; 2],
                    y: vec![-x; 4],
                    p: vec![x],
                };
                let mut bytes = Vec::new();
                encode_samples("c", &[sample.clone(), sample], &mut bytes).unwrap();
                bytes
            })
            .collect();
        let count = || ALLOCATIONS.with(std::cell::Cell::get);
        let probe = count();
        drop(std::hint::black_box(vec![0_u8; 8]));
        assert_eq!(count(), probe + 1, "the counting allocator is installed");

        let mut out = Vec::new();
        decode_samples("c", &payloads[0], &limits, &mut out).unwrap();
        let before = count();
        for payload in &payloads {
            decode_samples("c", payload, &limits, &mut out).unwrap();
        }
        assert_eq!(count() - before, 0, "allocations while decoding");
        assert_eq!(out.len(), 2);
        assert_eq!(out[1].k, Some(99));
    }

    #[test]
    fn reuses_and_trims_the_output_buffer() {
        let limits = DecodeLimits::default();
        let mut out = Vec::new();
        decode_samples(
            "c",
            br#"[{"y":[1,2,3]},{"y":[4]},{"y":[5]}]"#,
            &limits,
            &mut out,
        )
        .unwrap();
        let cap = out[0].y.capacity();
        decode_samples("c", br#"{"y":[9],"u":[1]}"#, &limits, &mut out).unwrap();
        assert_eq!(
            out,
            [Sample {
                u: vec![1.0],
                y: vec![9.0],
                ..Sample::default()
            }]
        );
        assert_eq!(out[0].y.capacity(), cap, "buffer of slot 0 reused");
        decode_samples("c", b"{", &limits, &mut out).unwrap_err();
        assert!(out.is_empty(), "on error out is empty");
    }

    #[test]
    fn negative_zero_and_extremes_are_kept_bit_for_bit() {
        let s = decode(r#"{"y":[-0.0,-0,5e-324,1.7976931348623157e308,1e-999]}"#).unwrap();
        let bits: Vec<u64> = s[0].y.iter().map(|v| v.to_bits()).collect();
        assert_eq!(
            bits,
            [
                (-0.0_f64).to_bits(),
                (-0.0_f64).to_bits(),
                1,
                f64::MAX.to_bits(),
                0
            ],
            "1e-999 underflows to +0"
        );
    }

    #[test]
    fn invalid_json_is_invalid_json() {
        assert_rejects("", ErrorCode::InvalidJson, None);
        assert_rejects("{", ErrorCode::InvalidJson, None);
        assert_rejects(r#"{"y":[1]} x"#, ErrorCode::InvalidJson, None);
        assert_rejects(r#"{"y":[1,]}"#, ErrorCode::InvalidJson, Some("y[1]"));
        assert_rejects(r#"{"y":[NaN]}"#, ErrorCode::InvalidJson, Some("y[0]"));
        assert_rejects(r#"{"y":[Infinity]}"#, ErrorCode::InvalidJson, Some("y[0]"));
        assert_rejects(
            r#"[{"y":[1]},{"y":[1"#,
            ErrorCode::InvalidJson,
            Some("[1].y[1]"),
        );
        let err = assert_rejects("nope", ErrorCode::InvalidJson, None);
        assert!(err.to_string().contains("at line 1 column 2"), "{err}");
    }

    #[test]
    fn invalid_utf8_is_invalid_json() {
        let mut out = Vec::new();
        let err = decode_samples("c", b"{\"y\xff\":[1]}", &DecodeLimits::default(), &mut out)
            .unwrap_err();
        assert_eq!(err.code(), ErrorCode::InvalidJson);
    }

    #[test]
    fn wrong_types_name_the_field() {
        assert_rejects("42", ErrorCode::WrongType, None);
        assert_rejects(r#""y""#, ErrorCode::WrongType, None);
        assert_rejects("[1]", ErrorCode::WrongType, Some("[0]"));
        assert_rejects(r#"{"y":"1,2"}"#, ErrorCode::WrongType, Some("y"));
        assert_rejects(r#"{"y":null}"#, ErrorCode::WrongType, Some("y"));
        assert_rejects(r#"{"y":[1,2,"3"]}"#, ErrorCode::WrongType, Some("y[2]"));
        assert_rejects(r#"{"y":[1,null]}"#, ErrorCode::WrongType, Some("y[1]"));
        assert_rejects(r#"{"y":[[1]]}"#, ErrorCode::WrongType, Some("y[0]"));
        assert_rejects(r#"{"y":[1],"u":{}}"#, ErrorCode::WrongType, Some("u"));
        assert_rejects(r#"{"y":[1],"t":"now"}"#, ErrorCode::WrongType, Some("t"));
        assert_rejects(
            r#"[{"y":[1]},{"y":[1],"p":[true]}]"#,
            ErrorCode::WrongType,
            Some("[1].p[0]"),
        );
    }

    #[test]
    fn k_must_be_a_non_negative_integer() {
        for k in [
            "-1",
            "1.5",
            "12.0",
            "1e3",
            "\"12\"",
            "true",
            "18446744073709551616",
            "1e999",
        ] {
            let err = assert_rejects(
                &format!(r#"{{"k":{k},"y":[1]}}"#),
                ErrorCode::WrongType,
                Some("k"),
            );
            assert!(
                err.to_string().contains("expected a non-negative integer"),
                "{err}"
            );
        }
        let s = decode(r#"{"k":18446744073709551615,"y":[1]}"#).unwrap();
        assert_eq!(s[0].k, Some(u64::MAX));
    }

    #[test]
    fn y_is_required() {
        let err = assert_rejects(r#"{"k":1,"u":[1]}"#, ErrorCode::MissingField, Some("y"));
        assert_eq!(err.to_string(), r#"channel "pump3": field y is missing"#);
        assert_rejects(r#"[{"y":[1]},{}]"#, ErrorCode::MissingField, Some("[1].y"));
    }

    #[test]
    fn unknown_fields_are_rejected() {
        let err = assert_rejects(r#"{"y":[1],"Y":[2]}"#, ErrorCode::UnknownField, Some("Y"));
        assert!(err.to_string().contains("not a field of a sample"), "{err}");
        assert_rejects(
            r#"[{"y":[1]},{"y":[1]},{"y":[1]},{"y":[1],"x":{"deep":[1]}}]"#,
            ErrorCode::UnknownField,
            Some("[3].x"),
        );
    }

    #[test]
    fn duplicate_fields_are_rejected() {
        assert_rejects(r#"{"y":[1],"y":[2]}"#, ErrorCode::Duplicate, Some("y"));
        assert_rejects(r#"{"k":1,"y":[1],"k":2}"#, ErrorCode::Duplicate, Some("k"));
    }

    #[test]
    fn out_of_range_numbers_are_non_finite() {
        let err = assert_rejects(r#"{"y":[1,2,1e999]}"#, ErrorCode::NonFinite, Some("y[2]"));
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field y[2] is not a finite number"#
        );
        assert_rejects(r#"{"y":[1],"t":-1e400}"#, ErrorCode::NonFinite, Some("t"));
        assert_rejects(
            r#"[{"y":[1]},{"y":[1],"u":[-1E999]}]"#,
            ErrorCode::NonFinite,
            Some("[1].u[0]"),
        );
        // Outside a float field an out-of-range number is just the wrong type.
        assert_rejects("1e999", ErrorCode::WrongType, None);
        assert_rejects("[1e999]", ErrorCode::WrongType, Some("[0]"));
    }

    #[test]
    fn limits_are_enforced_with_exact_counts() {
        let limits = DecodeLimits {
            max_payload_bytes: 64,
            max_batch: 2,
            max_vector_len: 3,
        };
        let err =
            decode_with(&format!(r#"{{"y":[{}]}}"#, "1,".repeat(40) + "1"), &limits).unwrap_err();
        assert_eq!(
            err.kind,
            DecodeErrorKind::TooLarge {
                what: SizeLimit::PayloadBytes,
                limit: 64,
                got: 89
            }
        );
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": payload has 89 bytes, more than the limit of 64"#
        );

        let err = decode_with(r#"[{"y":[1]},{"y":[2]},{"y":[3]},4]"#, &limits).unwrap_err();
        assert_eq!(
            err.kind,
            DecodeErrorKind::TooLarge {
                what: SizeLimit::BatchLen,
                limit: 2,
                got: 4
            }
        );
        assert_eq!(err.field, None);
        assert_eq!(err.code(), ErrorCode::TooLarge);

        let err = decode_with(r#"[{"y":[1]},{"y":[1,2,3,4,5]}]"#, &limits).unwrap_err();
        assert_eq!(
            err.kind,
            DecodeErrorKind::TooLarge {
                what: SizeLimit::VectorLen,
                limit: 3,
                got: 5
            }
        );
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field [1].y has 5 values, more than the limit of 3"#
        );

        // Exactly at the limits is fine.
        assert_eq!(
            decode_with(r#"[{"y":[1,2,3]},{"y":[]}]"#, &limits)
                .unwrap()
                .len(),
            2
        );
        // A single object is always accepted, whatever max_batch says.
        let none = DecodeLimits {
            max_batch: 0,
            ..limits
        };
        assert_eq!(decode_with(r#"{"y":[1]}"#, &none).unwrap().len(), 1);
        assert_eq!(decode_with("[]", &none).unwrap().len(), 0);
    }

    /// The two-tank plant's signals: two inputs, three outputs, one scheduling signal.
    fn tank_names() -> SignalNames {
        let s = |v: &[&str]| v.iter().map(|n| (*n).to_owned()).collect::<Vec<_>>();
        SignalNames::new(
            &s(&["FIC101", "FIC102"]),
            &s(&["LI201", "LI202", "FI301"]),
            &s(&["TI401"]),
        )
    }

    fn decode_named(payload: &str) -> Result<Vec<Sample>, DecodeError> {
        let mut out = Vec::new();
        decode_samples_named(
            "tanks",
            payload.as_bytes(),
            &DecodeLimits::default(),
            &tank_names(),
            &mut out,
        )
        .map(|()| out)
    }

    fn tank_sample() -> Sample {
        Sample {
            k: Some(7),
            t: Some(1.5),
            u: vec![2.1, 1.0],
            y: vec![62.3, 48.1, 1.9],
            p: vec![20.5],
        }
    }

    /// Flat, grouped, mixed and positional payloads of a named channel give the same
    /// sample, its values in the order of the names whatever the payload's order.
    #[test]
    fn named_payloads_decode_in_the_order_of_the_names() {
        let want = [tank_sample()];
        for payload in [
            r#"{"k":7,"t":1.5,"FIC101":2.1,"FIC102":1.0,"LI201":62.3,"LI202":48.1,"FI301":1.9,"TI401":20.5}"#,
            r#"{"TI401":20.5,"FI301":1.9,"LI202":48.1,"LI201":62.3,"FIC102":1,"FIC101":2.1,"t":1.5,"k":7}"#,
            r#"{"k":7,"t":1.5,"u":{"FIC101":2.1,"FIC102":1.0},"y":{"LI201":62.3,"LI202":48.1,"FI301":1.9},"p":{"TI401":20.5}}"#,
            r#"{"k":7,"t":1.5,"u":{"FIC102":1.0},"FIC101":2.1,"y":[62.3,48.1,1.9],"TI401":20.5}"#,
            r#"{"k":7,"t":1.5,"u":[2.1,1.0],"y":[62.3,48.1,1.9],"p":[20.5]}"#,
        ] {
            assert_eq!(decode_named(payload).unwrap(), want, "{payload}");
        }
        // A batch mixes them; positional vectors keep their own lengths (the monitor
        // checks them against the model).
        let batch = decode_named(
            r#"[{"FIC101":1,"FIC102":2,"LI201":3,"LI202":4,"FI301":5,"TI401":6},{"y":[9]}]"#,
        )
        .unwrap();
        assert_eq!(
            (&batch[0].u[..], &batch[0].y[..], &batch[0].p[..]),
            (&[1.0, 2.0][..], &[3.0, 4.0, 5.0][..], &[6.0][..])
        );
        assert_eq!(
            (&batch[1].u[..], &batch[1].y[..], &batch[1].p[..]),
            (&[][..], &[9.0][..], &[][..])
        );
    }

    /// A missing, unknown, misplaced or repeated name, or a bad value, is an error at
    /// that name, naming the channel.
    #[test]
    fn named_payload_errors_name_the_channel_and_the_field() {
        let all = r#""FIC101":2.1,"FIC102":1.0,"LI201":62.3,"LI202":48.1,"FI301":1.9,"TI401":20.5"#;
        let cases = [
            (
                r#"{"t":1.5,"FIC101":2.1,"FIC102":1.0,"LI201":62.3,"FI301":1.9,"TI401":20.5}"#
                    .to_owned(),
                ErrorCode::MissingField,
                "LI202",
                "field LI202 is missing",
            ),
            (
                r#"{"u":{"FIC101":2.1,"FIC102":1.0},"y":{"LI201":1,"LI202":2,"FI301":3}}"#
                    .to_owned(),
                ErrorCode::MissingField,
                "TI401",
                "field TI401 is missing",
            ),
            (
                format!(r#"{{{all},"FIC109":3}}"#),
                ErrorCode::UnknownField,
                "FIC109",
                "field FIC109 is not a field of a sample",
            ),
            (
                r#"{"u":{"FIC101":2.1,"LI201":1.0}}"#.to_owned(),
                ErrorCode::UnknownField,
                "u.LI201",
                "field u.LI201 is not a field of a sample",
            ),
            (
                format!(r#"{{{all},"LI201":3}}"#),
                ErrorCode::Duplicate,
                "LI201",
                "field LI201 appears more than once",
            ),
            (
                r#"{"u":{"FIC101":2.1,"FIC101":1.0}}"#.to_owned(),
                ErrorCode::Duplicate,
                "u.FIC101",
                "field u.FIC101 appears more than once",
            ),
            (
                format!(r#"{{{all},"u":[1,2]}}"#),
                ErrorCode::Duplicate,
                "u",
                "field u appears more than once",
            ),
            (
                format!(r#"{{"y":[1,2,3],{all}}}"#),
                ErrorCode::Duplicate,
                "LI201",
                "field LI201 appears more than once",
            ),
            (
                r#"{"FIC101":"2.1"}"#.to_owned(),
                ErrorCode::WrongType,
                "FIC101",
                "field FIC101 has the wrong type: expected a number",
            ),
            (
                r#"{"FIC101":null}"#.to_owned(),
                ErrorCode::WrongType,
                "FIC101",
                "expected a number",
            ),
            (
                r#"{"y":{"LI201":1e999}}"#.to_owned(),
                ErrorCode::NonFinite,
                "y.LI201",
                "field y.LI201 is not a finite number",
            ),
            (
                r#"{"FI301":1e999}"#.to_owned(),
                ErrorCode::NonFinite,
                "FI301",
                "field FI301 is not a finite number",
            ),
            (
                r#"{"y":true}"#.to_owned(),
                ErrorCode::WrongType,
                "y",
                "expected an array of numbers or an object of numbers by signal name",
            ),
            (
                format!(r#"[{{{all}}},{{"FIC101":1}}]"#),
                ErrorCode::MissingField,
                "[1].FIC102",
                "field [1].FIC102 is missing",
            ),
        ];
        for (payload, code, field, message) in cases {
            let err = decode_named(&payload).unwrap_err();
            assert_eq!(
                (err.code(), err.field.as_deref()),
                (code, Some(field)),
                "{payload}: {err}"
            );
            let text = err.to_string();
            assert!(text.starts_with(r#"channel "tanks": "#), "{text}");
            assert!(text.contains(message), "{payload}: {text}");
        }
        // Without names, as before: a name is an unknown field, an object a wrong type.
        let e = assert_rejects(
            r#"{"y":[1],"LI201":2}"#,
            ErrorCode::UnknownField,
            Some("LI201"),
        );
        assert!(e.to_string().contains("LI201"));
        assert_rejects(r#"{"y":{"LI201":2}}"#, ErrorCode::WrongType, Some("y"));
    }

    /// Named payloads decode without allocating once the buffers have their shape, as
    /// positional ones do (names are looked up, not copied).
    #[test]
    fn steady_named_stream_decodes_without_allocating() {
        let limits = DecodeLimits::default();
        let names = tank_names();
        let payloads: Vec<Vec<u8>> = (0..50_u32)
            .flat_map(|i| {
                let x = f64::from(i) * 0.1;
                [
                    format!(
                        r#"{{"k":{i},"t":{x},"FIC101":{x},"FIC102":1,"LI201":{x},"LI202":2,"FI301":3,"TI401":4}}"#
                    ),
                    format!(
                        r#"[{{"u":{{"FIC102":{x},"FIC101":1}},"y":{{"FI301":{x},"LI202":2,"LI201":3}},"p":{{"TI401":4}}}}]"#
                    ),
                ]
            })
            .map(String::into_bytes)
            .collect();
        let count = || ALLOCATIONS.with(std::cell::Cell::get);
        let mut out = Vec::new();
        decode_samples_named("c", &payloads[0], &limits, &names, &mut out).unwrap();
        let before = count();
        for payload in &payloads {
            decode_samples_named("c", payload, &limits, &names, &mut out).unwrap();
        }
        assert_eq!(count() - before, 0, "allocations while decoding");
        assert_eq!(out[0].y, [3.0, 2.0, 4.9]);
    }

    #[test]
    fn check_dimensions_names_the_first_mismatch() {
        let s = Sample {
            u: vec![1.0],
            y: vec![1.0, 2.0, 3.0],
            p: vec![],
            ..Sample::default()
        };
        assert!(s.check_dimensions("pump3", 1, 3, 0).is_ok());
        let err = s.check_dimensions("pump3", 1, 4, 0).unwrap_err();
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field y has 3 values, model expects 4"#
        );
        assert_eq!(err.code(), ErrorCode::WrongDimension);
        let err = s.check_dimensions("pump3", 2, 4, 1).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("u"));
        let err = s.check_dimensions("pump3", 1, 3, 2).unwrap_err();
        assert_eq!(
            err.kind,
            DecodeErrorKind::WrongDimension {
                expected: 2,
                got: 0
            }
        );
    }

    #[test]
    fn check_finite_names_field_and_index() {
        let mut s = Sample {
            u: vec![0.0],
            y: vec![1.0, 2.0, f64::INFINITY],
            ..Sample::default()
        };
        let err = s.check_finite("pump3").unwrap_err();
        assert_eq!(
            err.to_string(),
            r#"channel "pump3": field y[2] is not a finite number"#
        );
        assert_eq!(err.code(), ErrorCode::NonFinite);
        s.t = Some(f64::NAN);
        assert_eq!(
            s.check_finite("pump3").unwrap_err().field.as_deref(),
            Some("t")
        );
        s.t = Some(0.0);
        s.y[2] = 0.0;
        s.p = vec![f64::NEG_INFINITY];
        assert_eq!(
            s.check_finite("pump3").unwrap_err().field.as_deref(),
            Some("p[0]")
        );
        s.p.clear();
        assert!(s.check_finite("pump3").is_ok());
    }

    #[test]
    fn encode_refuses_non_finite_and_leaves_out_unchanged() {
        let mut out = b"prefix".to_vec();
        let bad = Sample {
            y: vec![1.0, f64::NAN],
            ..Sample::default()
        };
        let err = encode_samples("pump3", &[Sample::default(), bad], &mut out).unwrap_err();
        assert_eq!(err.field, "[1].y[1]");
        assert_eq!(err.code(), ErrorCode::NonFinite);
        assert_eq!(out, b"prefix");
    }

    #[test]
    fn encode_then_decode_a_batch() {
        let batch = vec![
            Sample {
                k: Some(0),
                t: Some(0.1),
                u: vec![1.0],
                y: vec![-0.0],
                p: vec![2.5],
            },
            Sample {
                y: vec![1e-300, 0.1 + 0.2],
                ..Sample::default()
            },
        ];
        let mut out = Vec::new();
        encode_samples("c", &batch, &mut out).unwrap();
        assert_eq!(
            std::str::from_utf8(&out).unwrap(),
            r#"[{"k":0,"t":0.1,"u":[1.0],"y":[-0.0],"p":[2.5]},{"y":[1e-300,0.30000000000000004]}]"#
        );
        let back = decode(std::str::from_utf8(&out).unwrap()).unwrap();
        assert_eq!(back, batch);
        assert_eq!(back[0].y[0].to_bits(), (-0.0_f64).to_bits());
    }

    fn finite_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<u64>()
                .prop_map(f64::from_bits)
                .prop_filter("finite", |v| v.is_finite()),
            any::<f64>().prop_filter("finite", |v| v.is_finite()),
        ]
    }

    fn sample() -> impl Strategy<Value = Sample> {
        let vec = || proptest::collection::vec(finite_f64(), 0..6);
        (
            any::<Option<u64>>(),
            proptest::option::of(finite_f64()),
            vec(),
            vec(),
            vec(),
        )
            .prop_map(|(k, t, u, y, p)| Sample { k, t, u, y, p })
    }

    /// A sample with every float as its bits: `PartialEq` on f64 says 0.0 == -0.0.
    type SampleBits = (Option<u64>, Option<u64>, Vec<u64>, Vec<u64>, Vec<u64>);

    fn bits(s: &Sample) -> SampleBits {
        let b = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        (s.k, s.t.map(f64::to_bits), b(&s.u), b(&s.y), b(&s.p))
    }

    proptest! {
        /// A sample written by name (flat, in any order) decodes to the same bits as
        /// written positionally.
        #[test]
        fn named_and_positional_payloads_agree(
            values in proptest::collection::vec(finite_f64(), 6),
            t in proptest::option::of(finite_f64()),
            order in Just((0..6_usize).collect::<Vec<_>>()).prop_shuffle(),
        ) {
            let names = tank_names();
            let all: Vec<&String> = names.inputs().iter().chain(names.outputs()).chain(names.signals()).collect();
            // Rust's `{:?}` of a finite f64 is a JSON number that reads back exactly.
            let mut fields: Vec<String> = order.iter().map(|&i| format!("\"{}\":{:?}", all[i], values[i])).collect();
            if let Some(t) = t {
                fields.push(format!("\"t\":{t:?}"));
            }
            let named = format!("{{{}}}", fields.join(",")).into_bytes();
            let mut got = Vec::new();
            decode_samples_named("c", &named, &DecodeLimits::default(), &names, &mut got).unwrap();
            let want = Sample { k: None, t, u: values[..2].to_vec(), y: values[2..5].to_vec(), p: values[5..].to_vec() };
            prop_assert_eq!(bits(&got[0]), bits(&want));
        }

        /// encode_sample → decode_samples is the identity, bit for bit.
        #[test]
        fn sample_round_trip_is_bit_identical(batch in proptest::collection::vec(sample(), 1..5)) {
            let mut out = Vec::new();
            encode_samples("c", &batch, &mut out).unwrap();
            let mut back = Vec::new();
            decode_samples("c", &out, &DecodeLimits::default(), &mut back).unwrap();
            prop_assert_eq!(back.iter().map(bits).collect::<Vec<_>>(), batch.iter().map(bits).collect::<Vec<_>>());

            out.clear();
            encode_sample("c", &batch[0], &mut out).unwrap();
            decode_samples("c", &out, &DecodeLimits::default(), &mut back).unwrap();
            prop_assert_eq!(back.len(), 1);
            prop_assert_eq!(bits(&back[0]), bits(&batch[0]));
        }
    }
}
