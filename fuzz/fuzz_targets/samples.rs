//! Sample payloads as a publisher sends them: decoding never panics, and a decoded
//! batch encodes and decodes back to the same samples.
#![no_main]

use glrmon_wire::{DecodeLimits, decode_samples, encode_samples};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut samples = Vec::new();
    if decode_samples("fuzz", data, &DecodeLimits::default(), &mut samples).is_ok() {
        let mut json = Vec::new();
        if encode_samples("fuzz", &samples, &mut json).is_ok() {
            let mut again = Vec::new();
            decode_samples("fuzz", &json, &DecodeLimits::default(), &mut again)
                .expect("an encoded batch decodes");
            assert_eq!(samples, again);
        }
    }
});
