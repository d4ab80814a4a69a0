//! Damaged MCAP recordings as `glrmon replay` and `glrmon recover` read them: the
//! reader never panics and stops on its own.
#![no_main]

use glrmon_record::McapReader;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mut reader) = McapReader::new(data) {
        while let Ok(Some(_)) = reader.next_event() {}
    }
});
