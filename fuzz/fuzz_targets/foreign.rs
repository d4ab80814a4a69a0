//! One message of a recording glrmon did not write, with a hostile schema and message:
//! ROS 2 CDR by a `ros2msg` schema, protobuf by a descriptor set. Reading never panics
//! (nor overflows its stack); a message read is a JSON document. The bytes are cut into
//! (selector, schema length, schema, message); the schema name is fixed per encoding,
//! so that a descriptor set the fuzzer builds can name it.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [selector, a, b, rest @ ..] = data else {
        return;
    };
    let len = usize::from(u16::from_le_bytes([*a, *b])).min(rest.len());
    let (schema, message) = rest.split_at(len);
    let (encoding, schema_encoding, name) = match selector % 3 {
        0 => ("cdr", "ros2msg", "std_msgs/msg/Float64MultiArray"),
        1 => ("protobuf", "protobuf", "fuzz.Message"),
        _ => ("json", "", ""),
    };
    if let Ok(json) =
        glrmon_input::foreign_message_json(encoding, schema_encoding, name, schema, message.to_vec())
        && encoding != "json"
    {
        serde_json::from_slice::<serde_json::Value>(&json).expect("a JSON document");
    }
});
