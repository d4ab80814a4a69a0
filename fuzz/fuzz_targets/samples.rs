//! Sample payloads as a publisher sends them: decoding never panics, and a decoded
//! batch encodes and decodes back to the same samples. The bytes are decoded as a
//! channel without names would, and as one whose signals are named (positional arrays,
//! flat names `{"FI1": …}`, grouped `{"u": {"FI1": …}}`): a sample decoded by name
//! holds a finite value for every signal, and its positional encoding decodes back to
//! it.
#![no_main]

use glrmon_wire::{
    DecodeLimits, Sample, SignalNames, decode_samples, decode_samples_named, encode_samples,
};
use libfuzzer_sys::fuzz_target;

fn round_trip(samples: &[Sample]) {
    let mut json = Vec::new();
    if encode_samples("fuzz", samples, &mut json).is_ok() {
        let mut again = Vec::new();
        decode_samples("fuzz", &json, &DecodeLimits::default(), &mut again)
            .expect("an encoded batch decodes");
        assert_eq!(samples, again);
    }
}

fuzz_target!(|data: &[u8]| {
    let mut samples = Vec::new();
    if decode_samples("fuzz", data, &DecodeLimits::default(), &mut samples).is_ok() {
        round_trip(&samples);
    }
    let names = SignalNames::new(
        &["FI1".into(), "u".into()],
        &["y0".into(), "TI 2".into(), "\u{e9}".into()],
        &["p".into()],
    );
    if decode_samples_named("fuzz", data, &DecodeLimits::default(), &names, &mut samples).is_ok()
    {
        for s in &samples {
            assert!(s.check_finite("fuzz").is_ok(), "{s:?}");
        }
        round_trip(&samples);
    }
});
