//! Instance status replies as `glrmon status` reads them: decoding never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = glrmon_wire::status::decode(data);
});
