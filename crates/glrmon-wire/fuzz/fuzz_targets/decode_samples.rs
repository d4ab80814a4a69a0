//! Fuzzes the sample decoder: it must never panic, must keep its size limits, and a
//! successful decode must re-encode and decode to the same samples (bit for bit).

#![no_main]

use glrmon_wire::{DecodeLimits, Sample, decode_samples, encode_samples};
use libfuzzer_sys::fuzz_target;

/// Small limits, so that the limit paths are reached with small inputs too.
const SMALL: DecodeLimits = DecodeLimits {
    max_payload_bytes: 4096,
    max_batch: 3,
    max_vector_len: 4,
};

/// A sample with every float as its bits: `PartialEq` on f64 says 0.0 == -0.0.
type SampleBits = (Option<u64>, Option<u64>, Vec<u64>, Vec<u64>, Vec<u64>);

fn bits(samples: &[Sample]) -> Vec<SampleBits> {
    let b = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    samples
        .iter()
        .map(|s| (s.k, s.t.map(f64::to_bits), b(&s.u), b(&s.y), b(&s.p)))
        .collect()
}

fn check(data: &[u8], limits: &DecodeLimits, out: &mut Vec<Sample>) {
    match decode_samples("fuzz", data, limits, out) {
        Ok(()) => {
            assert!(out.len() <= limits.max_batch.max(1));
            for s in out.iter() {
                assert!(s.check_finite("fuzz").is_ok());
                assert!(
                    [&s.u, &s.y, &s.p]
                        .iter()
                        .all(|v| v.len() <= limits.max_vector_len)
                );
            }
            let mut bytes = Vec::new();
            encode_samples("fuzz", out, &mut bytes).expect("decoded samples are finite");
            let mut back = Vec::new();
            decode_samples("fuzz", &bytes, &DecodeLimits::default(), &mut back)
                .expect("encoded samples decode");
            assert_eq!(bits(&back), bits(out));
        }
        Err(err) => {
            assert!(out.is_empty());
            assert!(!err.to_string().is_empty());
        }
    }
}

fuzz_target!(|data: &[u8]| {
    // One buffer across both calls, as the daemon reuses it across payloads.
    let mut out = Vec::new();
    check(data, &DecodeLimits::default(), &mut out);
    check(data, &SMALL, &mut out);
});
