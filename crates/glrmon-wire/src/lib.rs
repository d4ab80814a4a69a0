#![doc = include_str!("../README.md")]

mod error;
mod intake;
mod json_schema;
mod key;
mod record;
mod sample;
mod source;
pub mod status;
pub mod text;

pub use error::{
    ChannelNameError, ChannelNameErrorKind, DecodeError, DecodeErrorKind, EncodeError,
    EncodeErrorKind, ErrorCode, SizeLimit, Stage,
};
pub use intake::{IntakeEvent, decode_intake, encode_intake};
pub use json_schema::{intake_schema, record_schema, sample_schema};
pub use key::{
    DEFAULT_INPUT_PREFIX, RESULT_PREFIX, default_input_key, parse_result_key, result_key,
    validate_channel_name,
};
pub use record::{
    Alarm, AlarmEnd, Consistency, Diagnosis, EpisodeEstimate, ErrorRecord, IsolationResult,
    IsolationUpdate, RECORD_KINDS, Record, Stat, decode_record, encode_json,
};
pub use sample::{
    DecodeLimits, Sample, SignalNames, decode_samples, decode_samples_named, encode_sample,
    encode_samples,
};
pub use source::Source;
pub use status::{Assignment, ChannelStatus, InstanceStatus, StatusError, ZenohSessions};

#[cfg(test)]
mod tests {
    //! Robustness of both decoders against hostile input: bad input is a counted event,
    //! never a panic. The cargo-fuzz targets in `fuzz/` run the same checks for longer.

    use super::*;
    use proptest::prelude::*;

    /// What every decode must satisfy, whatever the input: no panic (implicit), and on
    /// success a result that re-encodes and decodes to itself.
    fn check_samples(payload: &[u8], limits: &DecodeLimits) {
        let mut out = vec![Sample {
            y: vec![1.0; 3],
            ..Sample::default()
        }];
        match decode_samples("fuzz", payload, limits, &mut out) {
            Ok(()) => {
                assert!(out.len() <= limits.max_batch.max(1));
                for s in &out {
                    assert!(s.check_finite("fuzz").is_ok(), "{s:?}");
                    assert!(
                        [&s.u, &s.y, &s.p]
                            .iter()
                            .all(|v| v.len() <= limits.max_vector_len)
                    );
                }
                let mut bytes = Vec::new();
                encode_samples("fuzz", &out, &mut bytes).unwrap();
                let mut back = Vec::new();
                decode_samples("fuzz", &bytes, &DecodeLimits::default(), &mut back).unwrap();
                assert_eq!(back, out);
            }
            Err(err) => {
                assert!(out.is_empty());
                assert_eq!(err.channel, "fuzz");
                assert!(!err.to_string().is_empty());
                assert!(ErrorCode::ALL.contains(&err.code()));
            }
        }
    }

    fn check_record(payload: &[u8]) {
        match decode_record(payload) {
            Ok(record) => {
                let mut bytes = Vec::new();
                encode_json(&record, &mut bytes).unwrap();
                assert_eq!(decode_record(&bytes).unwrap(), record);
            }
            Err(err) => {
                assert!(!err.to_string().is_empty());
                assert!(ErrorCode::ALL.contains(&err.code()));
            }
        }
    }

    const SMALL: DecodeLimits = DecodeLimits {
        max_payload_bytes: 4096,
        max_batch: 3,
        max_vector_len: 4,
    };

    /// Pieces of sample and record JSON, valid and broken, that random concatenation
    /// turns into near-misses a byte-level generator would rarely reach.
    const PUNCT: &[&str] = &[
        "{", "}", "[", "]", ",", ":", " ", "\"", "[[[[", "]]]]", "\u{0}",
    ];
    const KEYS: &[&str] = &[
        "\"k\":",
        "\"t\":",
        "\"u\":",
        "\"y\":",
        "\"p\":",
        "\"Y\":",
        "\"type\":",
        "\"channel\":",
        "\"code\":",
        "\"stage\":",
        "\"message\":",
        "\"glr\":",
        "\"plateau\":",
        "\"estimate\":",
        "\"isolation\":",
        "\"alarm_k\":",
        "\"update_k\":",
        "\"\\u0079\":",
    ];
    const LEAVES: &[&str] = &[
        "\"stat\"",
        "\"alarm\"",
        "\"isolation\"",
        "\"alarm_end\"",
        "\"diagnosis\"",
        "\"error\"",
        "\"pump3\"",
        "\"gap\"",
        "\"sending\"",
        "0",
        "1",
        "-1",
        "12",
        "0.5",
        "-0.0",
        "-0",
        "1e999",
        "-1e999",
        "1e-999",
        "5e-324",
        "18446744073709551615",
        "18446744073709551616",
        "1.",
        ".5",
        "01",
        "NaN",
        "Infinity",
        "null",
        "true",
        "false",
        "\"\\ud800\"",
        "\"é\"",
        "[1,2,3]",
        "{\"y\":[1]}",
    ];

    fn fragment_soup() -> impl Strategy<Value = String> {
        let all: Vec<&str> = PUNCT.iter().chain(KEYS).chain(LEAVES).copied().collect();
        proptest::collection::vec(proptest::sample::select(all), 0..40).prop_map(|v| v.concat())
    }

    /// Structurally plausible JSON from a small grammar: values nested a few levels, with
    /// keys drawn from both formats.
    fn json_ish() -> impl Strategy<Value = String> {
        let leaf = prop_oneof![
            proptest::sample::select(LEAVES).prop_map(str::to_owned),
            any::<f64>().prop_map(|v| format!("{v:?}")),
            any::<i64>().prop_map(|v| v.to_string()),
        ];
        leaf.prop_recursive(4, 48, 6, |inner| {
            prop_oneof![
                proptest::collection::vec(inner.clone(), 0..6)
                    .prop_map(|v| format!("[{}]", v.join(","))),
                proptest::collection::vec((proptest::sample::select(KEYS), inner), 0..6).prop_map(
                    |v| {
                        let body: Vec<String> =
                            v.into_iter().map(|(k, v)| format!("{k}{v}")).collect();
                        format!("{{{}}}", body.join(","))
                    }
                ),
            ]
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2048))]

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
            check_samples(&bytes, &DecodeLimits::default());
            check_samples(&bytes, &SMALL);
            check_record(&bytes);
        }

        #[test]
        fn json_fragments_never_panic(text in fragment_soup()) {
            check_samples(text.as_bytes(), &DecodeLimits::default());
            check_samples(text.as_bytes(), &SMALL);
            check_record(text.as_bytes());
        }

        #[test]
        fn json_grammar_never_panics(text in json_ish()) {
            check_samples(text.as_bytes(), &DecodeLimits::default());
            check_samples(text.as_bytes(), &SMALL);
            check_record(text.as_bytes());
        }
    }
}
