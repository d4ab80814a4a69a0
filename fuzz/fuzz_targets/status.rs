//! Instance status replies as `glrmon status` reads them, and the source attachments of
//! records as `glrmon watch` reads them (anyone may publish either): decoding never
//! panics, and a decoded source encodes back to an attachment that decodes to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = glrmon_wire::status::decode(data);
    if let Ok(source) = glrmon_wire::Source::decode(data) {
        assert_eq!(glrmon_wire::Source::decode(&source.encode()).ok(), Some(source));
    }
});
