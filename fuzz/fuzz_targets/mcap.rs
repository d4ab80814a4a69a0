//! Damaged MCAP recordings as `glrmon replay` and `glrmon recover` read them: the
//! reader never panics, stops on its own, and its salvage report is always available.
#![no_main]

use glrmon_record::McapReader;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Read + Seek: the reader looks for the summary at the end before it resynchronises.
    if let Ok(mut reader) = McapReader::new(std::io::Cursor::new(data)) {
        while let Ok(Some(_)) = reader.next_event() {}
        let _ = reader.salvage();
    }
});
