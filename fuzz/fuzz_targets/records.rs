//! Result records and intake events as `glrmon watch` or a replay reads them:
//! decoding never panics, and a decoded record round-trips.
#![no_main]

use glrmon_wire::{decode_intake, decode_record, encode_json};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = decode_intake(data);
    if let Ok(record) = decode_record(data) {
        let mut json = Vec::new();
        if encode_json(&record, &mut json).is_ok() {
            assert_eq!(decode_record(&json).expect("an encoded record decodes"), record);
        }
    }
});
