//! A channel assembled from tags (`[channels.tags]`): each signal arrives on a key of
//! its own, as a bare JSON number (`12.5`, `true`) or a field of a JSON object, at its
//! own rate and with its own time; samples are formed
//! - on a fixed period P: the sample at t_j = j·P holds each signal's last value at or
//!   before t_j. It is formed as soon as every signal has sent a value timed at or
//!   after t_j, or once any signal's time has passed t_j + hold·P; a signal silent
//!   since before t_j − hold·P is stale and the sample is a gap (its index is skipped,
//!   so the monitor sees the gap). `k` is j counted from the first sample.
//! - or at each value of a trigger signal, the others at their latest values; one
//!   silent for more than `hold` triggers is stale, and the sample a gap.
//!
//! Times are the publication's Zenoh timestamp, glrmon's arrival time, or a field of
//! the payload (`time_field`), per the configuration. The tag buffers are sized once:
//! assembling allocates nothing after the first samples.

use std::collections::VecDeque;
use std::fmt;

use glrmon_spec::{Formation, TagTime, Tags};
use glrmon_wire::{DecodeError, DecodeErrorKind, DecodeLimits, Sample};
use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Visitor};

use super::{Arrival, PayloadDecoder, within_limit};

/// Values a tag keeps that are timed after the last formed sample: beyond, the oldest
/// is folded into the held value.
const HISTORY: usize = 64;
/// Most grid instants one payload may close (a time far ahead of the others skips
/// the instants between as one gap).
const MAX_FORMED: i64 = 100_000;

/// One signal's tag: its values not yet passed by a sample, the last one that was,
/// and whether its silence was reported.
#[derive(Debug, Clone)]
struct TagState {
    /// (time, value), increasing in time, all after the last formed instant.
    history: VecDeque<(f64, f64)>,
    /// The latest value at or before the last formed instant.
    held: Option<(f64, f64)>,
    /// Trigger counts at its latest value (trigger formation).
    at_trigger: u64,
    stale: bool,
}

impl TagState {
    fn newest(&self) -> Option<(f64, f64)> {
        self.history.back().copied().or(self.held)
    }

    fn oldest_time(&self) -> Option<f64> {
        self.held.or(self.history.front().copied()).map(|(t, _)| t)
    }

    /// The latest value at or before time `t`, with its time.
    fn at(&self, t: f64) -> Option<(f64, f64)> {
        self.history
            .iter()
            .rev()
            .find(|(s, _)| *s <= t)
            .or(self.held.as_ref().filter(|(s, _)| *s <= t))
            .copied()
    }

    /// Folds the values at or before `t` into the held one.
    fn pass(&mut self, t: f64) {
        while let Some(&(s, v)) = self.history.front() {
            if s > t {
                break;
            }
            self.held = Some((s, v));
            self.history.pop_front();
        }
    }
}

/// The decoder of a channel assembled from tags.
#[derive(Debug, Clone)]
pub struct TagDecoder {
    spec: Tags,
    dims: [usize; 3],
    tags: Vec<TagState>,
    /// The next grid index to form (period formation), once every tag has a value.
    next: Option<i64>,
    /// The grid index of the first sample: `k` counts from it.
    origin: Option<i64>,
    /// The latest time any tag gave.
    watermark: f64,
    /// Triggers so far (trigger formation).
    triggers: u64,
    /// The values of the sample being formed.
    values: Vec<f64>,
    /// Samples whose buffers the next formed samples reuse.
    spare: Vec<Sample>,
    /// Each input key's tags, the trigger last ([`Tags::keys`]).
    keys: Vec<Vec<usize>>,
    /// The values of the payload being read: (tag, time, value).
    pending: Vec<(usize, f64, f64)>,
    notice: Option<DecodeError>,
}

impl TagDecoder {
    /// A decoder for a channel with these tags and `inputs`, `outputs`, `signals`.
    #[must_use]
    pub fn new(spec: Tags, inputs: usize, outputs: usize, signals: usize) -> Self {
        let n = spec.tags.len();
        let trigger = match spec.formation {
            Formation::Trigger(i) => Some(i),
            Formation::Period(_) => None,
        };
        let keys = spec
            .keys()
            .into_iter()
            .map(|(_, mut tags)| {
                tags.sort_by_key(|&i| Some(i) == trigger);
                tags
            })
            .collect();
        let state = TagState {
            history: VecDeque::with_capacity(HISTORY),
            held: None,
            at_trigger: 0,
            stale: false,
        };
        Self {
            spec,
            dims: [inputs, outputs, signals],
            tags: vec![state; n],
            next: None,
            origin: None,
            watermark: f64::NEG_INFINITY,
            triggers: 0,
            values: vec![0.0; n],
            spare: Vec::new(),
            keys,
            pending: Vec::with_capacity(n),
            notice: None,
        }
    }

    fn push_sample(&mut self, k: u64, t: f64, out: &mut Vec<Sample>, limits: &DecodeLimits) {
        if out.len() >= limits.max_batch {
            return;
        }
        let [l, m, _] = self.dims;
        let mut s = self.spare.pop().unwrap_or_default();
        s.k = Some(k);
        s.t = Some(t);
        for (v, values) in [
            (&mut s.u, &self.values[..l]),
            (&mut s.y, &self.values[l..l + m]),
            (&mut s.p, &self.values[l + m..]),
        ] {
            v.clear();
            v.extend_from_slice(values);
        }
        out.push(s);
    }

    /// Reports tag `i` stale once, until it sends again.
    fn went_stale(&mut self, channel: &str, i: usize, unit: &'static str) {
        if self.tags[i].stale {
            return;
        }
        self.tags[i].stale = true;
        let tag = &self.spec.tags[i];
        self.notice.get_or_insert_with(|| {
            DecodeError::new(
                channel,
                Some(tag.signal.clone()),
                DecodeErrorKind::Stale {
                    key: tag.key.clone(),
                    hold: self.spec.hold,
                    unit,
                },
            )
        });
    }

    /// Forms the samples of the grid instants this value closed.
    fn form_periodic(
        &mut self,
        channel: &str,
        period: f64,
        out: &mut Vec<Sample>,
        limits: &DecodeLimits,
    ) {
        let hold = f64::from(self.spec.hold) * period;
        if self.next.is_none() {
            // The first instant at which every tag has a value.
            let mut start = f64::NEG_INFINITY;
            for tag in &self.tags {
                match tag.oldest_time() {
                    Some(t) => start = start.max(t),
                    None => return,
                }
            }
            #[allow(clippy::cast_possible_truncation)]
            let j = (start / period).ceil() as i64;
            self.next = Some(j);
        }
        let mut formed = 0;
        while let Some(j) = self.next {
            #[allow(clippy::cast_precision_loss)]
            let t = j as f64 * period;
            if formed == MAX_FORMED {
                // A time far ahead: skip to the instants it can still fill.
                #[allow(clippy::cast_possible_truncation)]
                let skip = ((self.watermark - hold) / period).floor() as i64;
                self.next = Some(skip.max(j));
                formed = 0;
                if skip <= j {
                    break;
                }
                continue;
            }
            let closed = self.watermark >= t + hold;
            let mut gap = false;
            let mut decided = true;
            for i in 0..self.tags.len() {
                let tag = &self.tags[i];
                let Some((newest, last)) = tag.newest() else {
                    decided = false;
                    break;
                };
                if newest >= t {
                    match tag.at(t) {
                        Some((s, v)) if t - s <= hold => self.values[i] = v,
                        // Silent until after t (reported when it went stale, if the
                        // others' times showed it), or not started yet.
                        _ => gap = true,
                    }
                } else if closed {
                    if t - newest <= hold {
                        self.values[i] = last;
                    } else {
                        gap = true;
                        self.went_stale(channel, i, "periods");
                    }
                } else {
                    decided = false;
                    break;
                }
            }
            if !decided {
                break;
            }
            if !gap {
                let origin = *self.origin.get_or_insert(j);
                #[allow(clippy::cast_sign_loss)]
                let k = (j - origin) as u64;
                self.push_sample(k, t, out, limits);
            }
            for tag in &mut self.tags {
                tag.pass(t);
            }
            self.next = Some(j + 1);
            formed += 1;
        }
    }

    /// Forms the sample of a trigger value at `t`.
    fn form_triggered(
        &mut self,
        channel: &str,
        t: f64,
        out: &mut Vec<Sample>,
        limits: &DecodeLimits,
    ) {
        self.triggers += 1;
        let mut gap = false;
        for i in 0..self.tags.len() {
            let Some((_, v)) = self.tags[i].newest() else {
                // Not started: no sample until every tag has a value.
                return;
            };
            if self.triggers - self.tags[i].at_trigger > u64::from(self.spec.hold) {
                gap = true;
                self.went_stale(channel, i, "triggers");
            } else {
                self.values[i] = v;
            }
        }
        #[allow(clippy::cast_possible_wrap)]
        let j = self.triggers as i64;
        let origin = *self.origin.get_or_insert(j);
        if !gap {
            #[allow(clippy::cast_sign_loss)]
            self.push_sample((j - origin) as u64, t, out, limits);
        }
    }
}

impl TagDecoder {
    /// Tag `tag`'s value `value` at `t`: kept, then the samples it completes formed.
    fn apply(
        &mut self,
        channel: &str,
        tag: usize,
        t: f64,
        value: f64,
        out: &mut Vec<Sample>,
        limits: &DecodeLimits,
    ) {
        let state = &mut self.tags[tag];
        state.stale = false;
        match self.spec.formation {
            Formation::Period(p) => {
                match self.next {
                    // Already passed by a formed sample: the latest value for the next.
                    #[allow(clippy::cast_precision_loss)]
                    Some(next) if t <= (next - 1) as f64 * p => state.held = Some((t, value)),
                    _ => {
                        if state.history.len() == HISTORY
                            && let Some(oldest) = state.history.pop_front()
                        {
                            state.held = Some(oldest);
                        }
                        state.history.push_back((t, value));
                    }
                }
                self.watermark = self.watermark.max(t);
                self.form_periodic(channel, p, out, limits);
            }
            Formation::Trigger(trigger) => {
                state.held = Some((t, value));
                state.at_trigger = self.triggers;
                if tag == trigger {
                    self.form_triggered(channel, t, out, limits);
                }
            }
        }
    }
}

impl PayloadDecoder for TagDecoder {
    fn format(&self) -> &'static str {
        "tags"
    }

    fn decode(
        &mut self,
        channel: &str,
        _payload: &[u8],
        _limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        out.clear();
        Err(DecodeError::new(
            channel,
            None,
            DecodeErrorKind::WrongType {
                expected: "a tag's value with its tag (the channel is assembled from tags)".into(),
            },
        ))
    }

    fn decode_tag(
        &mut self,
        channel: &str,
        tag: usize,
        arrival: Arrival,
        payload: &[u8],
        limits: &DecodeLimits,
        out: &mut Vec<Sample>,
    ) -> Result<(), DecodeError> {
        // Most payloads form no sample: the samples' buffers wait here, not freed.
        self.spare.append(out);
        let Some(group) = self.keys.get(tag) else {
            return Err(DecodeError::new(
                channel,
                None,
                DecodeErrorKind::WrongType {
                    expected: format!("one of the channel's {} tag keys", self.keys.len()),
                },
            ));
        };
        let fail = |field: Option<String>, kind| Err(DecodeError::new(channel, field, kind));
        within_limit(
            channel,
            Some(&self.spec.tags[group[0]].signal),
            payload,
            limits,
        )?;
        // Every value of the payload is read before any is used: a payload with one
        // bad field changes nothing.
        self.pending.clear();
        for &i in group {
            let spec = &self.spec.tags[i];
            let (value, time) = match read(payload, &spec.field, spec.time_field.as_deref()) {
                Ok(read) => read,
                Err((path, kind)) => {
                    let field = if path.is_empty() {
                        spec.signal.clone()
                    } else {
                        format!("{} ({})", spec.signal, path)
                    };
                    return fail(Some(field), kind);
                }
            };
            let t = time.unwrap_or(match self.spec.time {
                TagTime::Zenoh => arrival.source_time.unwrap_or(arrival.received),
                TagTime::Arrival => arrival.received,
            });
            if let Some((previous, _)) = self.tags[i].newest()
                && t <= previous
            {
                #[allow(clippy::cast_possible_truncation)]
                let ns = |s: f64| (s * 1e9).round() as i64;
                let (t_ns, previous_ns) = (ns(t), ns(previous));
                return fail(
                    Some(spec.signal.clone()),
                    DecodeErrorKind::NotAfter { t_ns, previous_ns },
                );
            }
            self.pending.push((i, t, value));
        }
        // The trigger last, so that it forms its sample with the other values of its
        // own payload.
        for n in 0..self.pending.len() {
            let (i, t, value) = self.pending[n];
            self.apply(channel, i, t, value, out, limits);
        }
        Ok(())
    }

    fn take_notice(&mut self) -> Option<DecodeError> {
        self.notice.take()
    }
}

/// Why a tag's payload was refused: the path of the field at fault (empty: the
/// payload) and the reason.
type Failure = (String, DecodeErrorKind);

/// A tag's value (and time, if `time_field`) from its payload: a bare JSON number or
/// boolean when `field` is empty, else the fields at those paths of a JSON object.
fn read(
    payload: &[u8],
    field: &[String],
    time_field: Option<&[String]>,
) -> Result<(f64, Option<f64>), Failure> {
    let mut found = [None, None];
    let mut problem = None;
    let mut de = serde_json::Deserializer::from_slice(payload);
    let walk = Walk {
        paths: [Some(field), time_field],
        found: &mut found,
        problem: &mut problem,
    };
    let result = walk.deserialize(&mut de).and_then(|()| de.end());
    if let Some(p) = problem {
        return Err(p);
    }
    if let Err(e) = result {
        let kind = match e.classify() {
            serde_json::error::Category::Data => DecodeErrorKind::WrongType {
                expected: "a number or boolean".into(),
            },
            _ => DecodeErrorKind::InvalidJson(e.to_string()),
        };
        return Err((String::new(), kind));
    }
    let [value, time] = found;
    let Some(value) = value else {
        return Err((field.join("."), DecodeErrorKind::MissingField));
    };
    match (time, time_field) {
        (None, Some(path)) => Err((path.join("."), DecodeErrorKind::MissingField)),
        (time, _) => Ok((value, time)),
    }
}

/// Walks a JSON value towards up to two paths (the value's, the time's), reading the
/// number at the end of each; everything else is skipped without being kept.
struct Walk<'p, 'o> {
    paths: [Option<&'p [String]>; 2],
    found: &'o mut [Option<f64>; 2],
    problem: &'o mut Option<Failure>,
}

impl Walk<'_, '_> {
    /// Sets the paths that end here to `v`.
    fn number<E: de::Error>(self, v: f64) -> Result<(), E> {
        if !v.is_finite() {
            return Err(self.fail(DecodeErrorKind::NonFinite));
        }
        for (path, found) in self.paths.iter().zip(self.found.iter_mut()) {
            if path.is_some_and(<[String]>::is_empty) {
                *found = Some(v);
            }
        }
        Ok(())
    }

    fn fail<E: de::Error>(self, kind: DecodeErrorKind) -> E {
        let message = kind.to_string();
        self.problem.get_or_insert((String::new(), kind));
        E::custom(message)
    }
}

impl<'de> DeserializeSeed<'de> for Walk<'_, '_> {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a number, a boolean or an object")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<(), E> {
        self.number(v)
    }

    #[allow(clippy::cast_precision_loss)]
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<(), E> {
        self.number(v as f64)
    }

    #[allow(clippy::cast_precision_loss)]
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<(), E> {
        self.number(v as f64)
    }

    fn visit_bool<E: de::Error>(self, v: bool) -> Result<(), E> {
        self.number(f64::from(u8::from(v)))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let Walk {
            paths,
            found,
            problem,
        } = self;
        while let Some(matched) = map.next_key_seed(KeyMatch { paths })? {
            let next = [0, 1].map(|i| paths[i].filter(|_| matched[i]).map(|p| &p[1..]));
            if next.iter().all(Option::is_none) {
                map.next_value::<IgnoredAny>()?;
            } else {
                map.next_value_seed(Walk {
                    paths: next,
                    found: &mut *found,
                    problem: &mut *problem,
                })?;
            }
        }
        Ok(())
    }

    /// An array: a path's next field that is a number (`data.0`) is an index into it.
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let Walk {
            paths,
            found,
            problem,
        } = self;
        let index = |p: Option<&[String]>| p.and_then(|p| p.first()?.parse::<usize>().ok());
        let wanted = [index(paths[0]), index(paths[1])];
        let mut i = 0usize;
        loop {
            let next = [0, 1].map(|j| paths[j].filter(|_| wanted[j] == Some(i)).map(|p| &p[1..]));
            let more = if next.iter().all(Option::is_none) {
                seq.next_element::<IgnoredAny>()?.is_some()
            } else {
                seq.next_element_seed(Walk {
                    paths: next,
                    found: &mut *found,
                    problem: &mut *problem,
                })?
                .is_some()
            };
            if !more {
                return Ok(());
            }
            i += 1;
        }
    }
}

/// A key of an object, matched against the next field of each path.
struct KeyMatch<'p> {
    paths: [Option<&'p [String]>; 2],
}

impl<'de> DeserializeSeed<'de> for KeyMatch<'_> {
    type Value = [bool; 2];

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<[bool; 2], D::Error> {
        d.deserialize_str(self)
    }
}

impl Visitor<'_> for KeyMatch<'_> {
    type Value = [bool; 2];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a field name")
    }

    fn visit_str<E: de::Error>(self, key: &str) -> Result<[bool; 2], E> {
        Ok(self
            .paths
            .map(|p| p.and_then(<[String]>::first).is_some_and(|f| f == key)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_spec::Tag;
    use glrmon_wire::ErrorCode;

    fn tag(signal: &str, key: &str, field: &str) -> Tag {
        Tag {
            signal: signal.into(),
            key: key.into(),
            field: if field.is_empty() {
                vec![]
            } else {
                field.split('.').map(str::to_owned).collect()
            },
            time_field: None,
        }
    }

    /// The DC motor's tags: u0 voltage, y0 current, y1 speed (a field of an object).
    fn motor(formation: Formation) -> TagDecoder {
        let spec = Tags {
            formation,
            hold: 3,
            time: TagTime::Zenoh,
            tags: vec![
                tag("u0", "plant/dc/voltage", ""),
                tag("y0", "plant/dc/current", ""),
                tag("y1", "plant/dc/speed", "data.speed"),
            ],
        };
        TagDecoder::new(spec, 1, 2, 0)
    }

    /// Feeds `(tag, time, payload)` and returns every sample formed, as (k, t, u, y).
    fn feed(
        d: &mut TagDecoder,
        values: &[(usize, f64, &str)],
    ) -> Vec<(u64, f64, Vec<f64>, Vec<f64>)> {
        let mut formed = Vec::new();
        let mut out = Vec::new();
        for &(tag, t, payload) in values {
            let arrival = Arrival {
                source_time: Some(t),
                received: t + 0.5,
                declared: Default::default(),
            };
            d.decode_tag(
                "dc_motor",
                tag,
                arrival,
                payload.as_bytes(),
                &DecodeLimits::default(),
                &mut out,
            )
            .unwrap();
            formed.extend(
                out.iter()
                    .map(|s| (s.k.unwrap(), s.t.unwrap(), s.u.clone(), s.y.clone())),
            );
        }
        formed
    }

    #[test]
    fn a_period_forms_samples_from_each_tags_last_value() {
        let mut d = motor(Formation::Period(0.01));
        // Jittered publications around each 10 ms, speed inside an object.
        let got = feed(
            &mut d,
            &[
                (0, 1.0001, "12.0"),
                (1, 1.0003, "0.5"),
                (
                    2,
                    1.0002,
                    r#"{"data":{"speed":100.0,"unit":"rad/s"},"q":"good"}"#,
                ),
                (0, 1.0102, "12.5"),
                (2, 1.0099, r#"{"data":{"speed":101.0}}"#),
                (1, 1.0104, "0.6"),
                (1, 1.0198, "0.7"),
                (0, 1.0201, "true"),
                (2, 1.0205, r#"{"data":{"speed":102}}"#),
                (1, 1.0212, "0.8"),
            ],
        );
        // The first instant every tag covers is 1.01: y1 at 1.0099, u0 and y0 from
        // before; 1.02 is closed by the value of every tag after it.
        assert_eq!(
            got,
            [
                (0, 1.01, vec![12.0], vec![0.5, 101.0]),
                (1, 1.02, vec![12.5], vec![0.7, 101.0]),
            ]
        );
    }

    #[test]
    fn a_silent_tag_is_held_then_the_samples_are_gaps() {
        let mut d = motor(Formation::Period(0.01));
        let mut values = Vec::new();
        let speed: Vec<String> = (0..40)
            .map(|j| format!(r#"{{"data":{{"speed":{j}}}}}"#))
            .collect();
        for j in 0..40 {
            let t = 1.0 + f64::from(j) * 0.01 + 0.001;
            values.push((0, t, "12.0"));
            // The current is silent from 1.1 to 1.2.
            if !(10..20).contains(&j) {
                values.push((1, t, "0.5"));
            }
            values.push((2, t, speed[j as usize].as_str()));
        }
        let mut out = Vec::new();
        let mut ks = Vec::new();
        let mut notices = Vec::new();
        for &(tag, t, payload) in &values {
            let arrival = Arrival {
                source_time: Some(t),
                received: t,
                declared: Default::default(),
            };
            d.decode_tag(
                "dc_motor",
                tag,
                arrival,
                payload.as_bytes(),
                &DecodeLimits::default(),
                &mut out,
            )
            .unwrap();
            ks.extend(out.iter().map(|s| s.k.unwrap()));
            notices.extend(d.take_notice());
        }
        // Instants 1.01 … 1.39 (k 0 … 38): the current's last value, at 1.091, is held
        // for 3 periods (1.10 … 1.12), then 1.13 … 1.20 (k 12 … 19) are gaps: its next
        // value is at 1.201.
        let want: Vec<u64> = (0..39).filter(|k| !(12..=19).contains(k)).collect();
        assert_eq!(ks, want);
        assert_eq!(notices.len(), 1);
        assert_eq!(notices[0].code(), ErrorCode::Gap);
        assert_eq!(
            notices[0].to_string(),
            "channel \"dc_motor\": field y0 (key plant/dc/current) sent no value for more than \
             3 periods: samples are gaps until it sends again"
        );
    }

    #[test]
    fn a_trigger_forms_a_sample_at_each_of_its_values() {
        let mut d = motor(Formation::Trigger(2));
        let got = feed(
            &mut d,
            &[
                (2, 0.5, r#"{"data":{"speed":1}}"#),
                (0, 1.0, "12.0"),
                (1, 1.1, "0.5"),
                (2, 1.2, r#"{"data":{"speed":2}}"#),
                (0, 1.3, "13.0"),
                (2, 1.4, r#"{"data":{"speed":3}}"#),
                (2, 1.5, r#"{"data":{"speed":4}}"#),
                (2, 1.6, r#"{"data":{"speed":5}}"#),
                (2, 1.7, r#"{"data":{"speed":6}}"#),
            ],
        );
        // The first trigger comes before the others have values; the current's value
        // (at trigger 1) is held for 3 triggers, then the fifth is a gap.
        assert_eq!(
            got,
            [
                (0, 1.2, vec![12.0], vec![0.5, 2.0]),
                (1, 1.4, vec![13.0], vec![0.5, 3.0]),
                (2, 1.5, vec![13.0], vec![0.5, 4.0]),
            ]
        );
        let _ = d.take_notice().expect("the current went stale");
    }

    #[test]
    fn a_bad_tag_value_names_the_signal_and_field() {
        let mut d = motor(Formation::Period(0.01));
        let mut out = Vec::new();
        let limits = DecodeLimits::default();
        let arrival = Arrival {
            source_time: Some(1.0),
            received: 1.0,
            declared: Default::default(),
        };
        let mut err = |tag: usize, payload: &str| {
            d.decode_tag(
                "dc_motor",
                tag,
                arrival,
                payload.as_bytes(),
                &limits,
                &mut out,
            )
            .unwrap_err()
        };
        let e = err(0, "\"12.0\"");
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field u0 has the wrong type: expected a number or boolean"
        );
        let e = err(2, r#"{"data":{"velocity":1}}"#);
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field y1 (data.speed) is missing"
        );
        let e = err(1, "0.5 0.6");
        assert_eq!(e.code(), ErrorCode::InvalidJson);
        let e = err(1, "");
        assert_eq!(e.code(), ErrorCode::InvalidJson);
        d.decode_tag("dc_motor", 1, arrival, b"0.5", &limits, &mut out)
            .unwrap();
        let e = d
            .decode_tag(
                "dc_motor",
                1,
                Arrival {
                    source_time: Some(0.9),
                    received: 1.0,
                    declared: Default::default(),
                },
                b"0.5",
                &limits,
                &mut out,
            )
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "channel \"dc_motor\": field y0 is timed at 0.9 s, not after its previous value at 1 s"
        );
        assert_eq!(e.code(), ErrorCode::OutOfOrder);
    }

    #[test]
    fn a_field_path_indexes_arrays() {
        let (v, t) = read(
            br#"{"layout":{"dim":[]},"data":[1.5,-2.5,{"x":[7,8]}],"stamp":[0,12.25]}"#,
            &["data".into(), "2".into(), "x".into(), "1".into()],
            Some(&["stamp".into(), "1".into()]),
        )
        .unwrap();
        assert_eq!((v, t), (8.0, Some(12.25)));
        let (v, _) = read(b"[3, 4]", &["1".into()], None).unwrap();
        assert_eq!(v, 4.0);
        let e = read(b"[3, 4]", &["2".into()], None).unwrap_err();
        assert_eq!(e.1, DecodeErrorKind::MissingField);
    }

    #[test]
    fn a_time_field_times_the_value() {
        let spec = Tags {
            formation: Formation::Period(1.0),
            hold: 1,
            time: TagTime::Arrival,
            tags: vec![Tag {
                time_field: Some(vec!["ts".into()]),
                ..tag("y0", "plant/x", "v")
            }],
        };
        let mut d = TagDecoder::new(spec, 0, 1, 0);
        let got = feed(
            &mut d,
            &[
                (0, 50.0, r#"{"v":1,"ts":9.5}"#),
                (0, 50.1, r#"{"ts":10.5,"v":2}"#),
            ],
        );
        assert_eq!(got, [(0, 10.0, vec![], vec![1.0])]);
    }

    #[test]
    /// Values of three tags timed with jitter inside each period form, at every
    /// instant, the values of the period before, exactly.
    fn jittered_tags_form_the_periods_values() {
        let tags = ["u0", "y0", "y1"]
            .iter()
            .map(|s| Tag {
                signal: (*s).into(),
                key: format!("k/{s}"),
                field: vec!["value".into()],
                time_field: Some(vec!["time".into()]),
            })
            .collect();
        let spec = Tags {
            formation: Formation::Period(0.01),
            hold: 3,
            time: TagTime::Zenoh,
            tags,
        };
        let mut d = TagDecoder::new(spec, 1, 2, 0);
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut out = Vec::new();
        let mut got = Vec::new();
        for j in 0..50u32 {
            for i in 0..3 {
                let f = 0.05 + 0.4 * (next() % 1000) as f64 / 1000.0;
                let t = 1_800_000_000.0 + (f64::from(j) + f) * 0.01;
                let p = format!(
                    r#"{{"time":{t:?},"quality":"good","value":{}}}"#,
                    1000 * i + j
                );
                d.decode_tag(
                    "c",
                    i as usize,
                    Arrival::default(),
                    p.as_bytes(),
                    &DecodeLimits::default(),
                    &mut out,
                )
                .unwrap();
                got.extend(out.iter().map(|s| (s.k.unwrap(), s.u[0], s.y[0], s.y[1])));
            }
        }
        for (k, u, y0, y1) in got {
            assert_eq!(
                (u, y0, y1),
                (k as f64, 1000.0 + k as f64, 2000.0 + k as f64),
                "{k}"
            );
        }
    }
}
