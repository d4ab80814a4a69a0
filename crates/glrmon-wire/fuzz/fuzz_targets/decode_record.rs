//! Fuzzes the record decoder: it must never panic, and a successful decode must
//! re-encode and decode to the same record.

#![no_main]

use glrmon_wire::{decode_record, encode_json};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match decode_record(data) {
        Ok(record) => {
            let mut bytes = Vec::new();
            encode_json(&record, &mut bytes).expect("a decoded record has only finite floats");
            let back = decode_record(&bytes).expect("an encoded record decodes");
            assert_eq!(back, record);
        }
        Err(err) => assert!(!err.to_string().is_empty()),
    }
});
