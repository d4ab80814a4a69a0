//! Protobuf messages of a recording (MCAP's protobuf profile), by the schema the
//! recording carries: the message type's fully qualified name and a serialized
//! `google.protobuf.FileDescriptorSet` holding its file and the files it depends on,
//! parsed once per schema by `prost-reflect`; each message is decoded as a dynamic
//! message of that type and written as JSON (proto field names, every field present,
//! numbers as numbers), which the channel's field paths then read (`data.0`, the first
//! value of a `repeated double data`).

use std::collections::HashMap;

use prost_reflect::prost::Message as _;
use prost_reflect::prost_types::{Any, DescriptorProto, FieldDescriptorProto, FileDescriptorSet};
use prost_reflect::{
    DescriptorPool, DynamicMessage, MessageDescriptor, ReflectMessage as _, SerializeOptions,
};
use serde_json::Value;

/// A message type with the descriptors it needs.
#[derive(Debug, Clone)]
pub(super) struct Schema {
    message: MessageDescriptor,
    /// Whether its descriptors define `google.protobuf.Any`, whose JSON form holds the
    /// message packed in it: its nesting is then bounded before writing ([`MAX_DEPTH`]).
    has_any: bool,
}

/// How many message types an error lists before it counts the rest.
const LISTED: usize = 12;

/// Longer chains of imports (a file importing a file importing …) are refused: a
/// generated set has a few, and prost-reflect 0.16 follows public imports recursively.
const MAX_IMPORT_DEPTH: usize = 64;

/// Deeper nesting of messages, counting those packed in a `google.protobuf.Any`, is
/// refused: prost-reflect bounds the nesting of one message it decodes (at 100), not the
/// `Any` it unpacks again for each level while writing JSON.
const MAX_DEPTH: usize = 100;

const ANY: &str = "google.protobuf.Any";

/// The JSON form a field path reads: numbers wherever the message has them.
const JSON: SerializeOptions = SerializeOptions::new()
    // The names the `.proto` file gives (`motor_speed`), not their camelCase.
    .use_proto_field_name(true)
    // A proto3 field at its default (0, empty) is absent from the wire: it is still a
    // value of the message, and a path to it should find it.
    .skip_default_fields(false)
    // int64 and uint64 as numbers, not the canonical mapping's strings.
    .stringify_64_bit_integers(false)
    // An enum as its number (a signal can be a state), not its name.
    .use_enum_numbers(true);

impl Schema {
    /// The message type `name` (`package.Type`) of a serialized `FileDescriptorSet`.
    pub(super) fn parse(name: &str, descriptor_set: &[u8]) -> Result<Self, String> {
        let mut set = FileDescriptorSet::decode(descriptor_set)
            .map_err(|e| format!("not a FileDescriptorSet: {e}"))?;
        check_files(&mut set)?;
        let pool = DescriptorPool::from_file_descriptor_set(set)
            .map_err(|e| format!("its FileDescriptorSet is not consistent: {e}"))?;
        // A leading dot, as a field's type name has it, names the same type.
        let full = name.strip_prefix('.').unwrap_or(name);
        let message = pool.get_message_by_name(full).ok_or_else(|| {
            let mut known: Vec<String> = pool
                .all_messages()
                .map(|m| m.full_name().to_owned())
                .collect();
            known.sort_unstable();
            let more = known.len().saturating_sub(LISTED);
            known.truncate(LISTED);
            format!(
                "not in its descriptor set (its messages: {}{})",
                if known.is_empty() {
                    "none".to_owned()
                } else {
                    known.join(", ")
                },
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            )
        })?;
        let has_any = pool.get_message_by_name(ANY).is_some();
        Ok(Self { message, has_any })
    }

    /// A message in the protobuf wire format as a JSON value.
    pub(super) fn decode(&self, data: &[u8]) -> Result<Value, String> {
        let name = self.message.full_name();
        let message = DynamicMessage::decode(self.message.clone(), data)
            .map_err(|e| format!("message does not decode as {name}: {e}"))?;
        if self.has_any && !within_depth(&message, MAX_DEPTH) {
            return Err(format!(
                "message does not decode as {name}: its messages, with those packed in \
                 google.protobuf.Any, nest deeper than {MAX_DEPTH}"
            ));
        }
        message
            .serialize_with_options(serde_json::value::Serializer, &JSON)
            .map_err(|e| format!("{name} message as JSON: {e}"))
    }
}

/// Refuses what prost-reflect 0.16 would not survive in a hostile set, which protoc
/// never writes (prost-reflect panics on a file of unknown syntax and on a malformed map
/// entry, and recurses without end through a cycle of public imports): a file of a
/// syntax other than proto2 and proto3 (an empty one is proto2, as `descriptor.proto`
/// says), a map entry that is not `key = 1` of an integer, bool or string type and
/// `value = 2`, two files of one name, imports in a cycle or chained deeper than
/// [`MAX_IMPORT_DEPTH`]. An import the set does not hold is left to prost-reflect, which
/// names it.
fn check_files(set: &mut FileDescriptorSet) -> Result<(), String> {
    let mut index: HashMap<&str, usize> = HashMap::new();
    for file in &mut set.file {
        match file.syntax.as_deref() {
            None | Some("proto2" | "proto3") => {}
            Some("") => file.syntax = None,
            Some(other) => {
                return Err(format!(
                    "file \"{}\" has syntax \"{other}\": proto2 and proto3 are read",
                    file.name()
                ));
            }
        }
        for message in &file.message_type {
            check_map_entries(message).map_err(|e| format!("file \"{}\": {e}", file.name()))?;
        }
    }
    for (i, file) in set.file.iter().enumerate() {
        if index.insert(file.name(), i).is_some() {
            return Err(format!("file \"{}\" is in it twice", file.name()));
        }
    }
    // Files whose imports are all placed go next, each one import deeper than the
    // deepest of them (Kahn's topological order): files left over import in a cycle.
    let n = set.file.len();
    let mut importers: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut pending = vec![0_usize; n];
    for (i, file) in set.file.iter().enumerate() {
        for d in file.dependency.iter().filter_map(|d| index.get(d.as_str())) {
            importers[*d].push(i);
            pending[i] += 1;
        }
    }
    let mut depth = vec![0_usize; n];
    let mut ready: Vec<usize> = (0..n).filter(|&i| pending[i] == 0).collect();
    let mut placed = 0;
    while let Some(i) = ready.pop() {
        placed += 1;
        if depth[i] > MAX_IMPORT_DEPTH {
            return Err(format!(
                "file \"{}\" imports through a chain of more than {MAX_IMPORT_DEPTH} files",
                set.file[i].name()
            ));
        }
        for &j in &importers[i] {
            depth[j] = depth[j].max(depth[i] + 1);
            pending[j] -= 1;
            if pending[j] == 0 {
                ready.push(j);
            }
        }
    }
    if placed < n {
        let looped = (0..n)
            .find(|&i| pending[i] > 0)
            .map_or("", |i| set.file[i].name());
        return Err(format!(
            "file \"{looped}\" imports itself, through its imports or directly"
        ));
    }
    Ok(())
}

/// Refuses a map entry (a message with the `map_entry` option, `map<K, V>`'s generated
/// `…Entry`) in `message` or its nested types that is not `K key = 1; V value = 2;`
/// with K an integer type, bool or string and V not repeated nor a group. The nesting is
/// bounded by the decoder of the set (prost's recursion limit).
fn check_map_entries(message: &DescriptorProto) -> Result<(), String> {
    use prost_reflect::prost_types::field_descriptor_proto::{Label, Type};
    if message.options.as_ref().is_some_and(|o| o.map_entry()) {
        let plain = |f: &&FieldDescriptorProto| {
            f.label() != Label::Repeated && f.r#type.is_some() && f.r#type() != Type::Group
        };
        let key = message.field.iter().filter(plain).find(|f| f.number() == 1);
        let value = message.field.iter().filter(plain).find(|f| f.number() == 2);
        let key_type = key.map(|k| k.r#type());
        let keyable = matches!(
            key_type,
            Some(
                Type::Int32
                    | Type::Int64
                    | Type::Uint32
                    | Type::Uint64
                    | Type::Sint32
                    | Type::Sint64
                    | Type::Fixed32
                    | Type::Fixed64
                    | Type::Sfixed32
                    | Type::Sfixed64
                    | Type::Bool
                    | Type::String
            )
        );
        if !keyable || value.is_none() || message.field.len() != 2 {
            return Err(format!(
                "map entry {} is not `key = 1` of an integer, bool or string type and \
                 `value = 2`",
                message.name()
            ));
        }
    }
    message.nested_type.iter().try_for_each(check_map_entries)
}

/// Whether `message` nests at most `budget` messages deep, counting those packed in
/// each `google.protobuf.Any` as the JSON form unpacks them. A packed message that does
/// not unpack is left to the JSON writer, which says why.
fn within_depth(message: &DynamicMessage, budget: usize) -> bool {
    let Some(budget) = budget.checked_sub(1) else {
        return false;
    };
    if message.descriptor().full_name() == ANY {
        let Ok(any) = message.transcode_to::<Any>() else {
            return true;
        };
        let name = any.type_url.rsplit('/').next().unwrap_or_default();
        let Some(packed) = message.descriptor().parent_pool().get_message_by_name(name) else {
            return true;
        };
        return DynamicMessage::decode(packed, any.value.as_slice())
            .map_or(true, |m| within_depth(&m, budget));
    }
    message.fields().all(|(_, v)| value_within_depth(v, budget))
        && message
            .extensions()
            .all(|(_, v)| value_within_depth(v, budget))
}

fn value_within_depth(value: &prost_reflect::Value, budget: usize) -> bool {
    match value {
        prost_reflect::Value::Message(m) => within_depth(m, budget),
        prost_reflect::Value::List(items) => items.iter().all(|v| value_within_depth(v, budget)),
        prost_reflect::Value::Map(map) => map.values().all(|v| value_within_depth(v, budget)),
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use prost_reflect::Value as Field;
    use prost_reflect::prost_types::field_descriptor_proto::{Label, Type};
    use prost_reflect::prost_types::{
        DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
        FileDescriptorProto,
    };

    use super::*;

    fn field(name: &str, number: i32, ty: Type, label: Label) -> FieldDescriptorProto {
        FieldDescriptorProto {
            name: Some(name.into()),
            number: Some(number),
            r#type: Some(ty.into()),
            label: Some(label.into()),
            ..FieldDescriptorProto::default()
        }
    }

    fn message_field(name: &str, number: i32, type_name: &str) -> FieldDescriptorProto {
        FieldDescriptorProto {
            type_name: Some(type_name.into()),
            ..field(name, number, Type::Message, Label::Optional)
        }
    }

    /// `glrmon_test.Motor { repeated double data = 1; double gain = 2; Status status = 3;
    /// Mode mode = 4; }`, `Motor.Status { int64 count = 1; string label = 2; }`, in a
    /// proto3 file, and `glrmon_test.Chain { Chain next = 1; Motor motor = 2;
    /// google.protobuf.Any packed = 3; }` in a second file that imports the first and
    /// `google/protobuf/any.proto`.
    fn descriptor_set() -> Vec<u8> {
        FileDescriptorSet {
            file: descriptor_files(),
        }
        .encode_to_vec()
    }

    fn descriptor_files() -> Vec<FileDescriptorProto> {
        let status = DescriptorProto {
            name: Some("Status".into()),
            field: vec![
                field("count", 1, Type::Int64, Label::Optional),
                field("label", 2, Type::String, Label::Optional),
            ],
            ..DescriptorProto::default()
        };
        let motor = DescriptorProto {
            name: Some("Motor".into()),
            field: vec![
                field("data", 1, Type::Double, Label::Repeated),
                field("gain", 2, Type::Double, Label::Optional),
                message_field("status", 3, ".glrmon_test.Motor.Status"),
                FieldDescriptorProto {
                    type_name: Some(".glrmon_test.Mode".into()),
                    ..field("mode", 4, Type::Enum, Label::Optional)
                },
            ],
            nested_type: vec![status],
            ..DescriptorProto::default()
        };
        let mode = EnumDescriptorProto {
            name: Some("Mode".into()),
            value: ["IDLE", "RUNNING"]
                .iter()
                .zip(0..)
                .map(|(name, number)| EnumValueDescriptorProto {
                    name: Some((*name).into()),
                    number: Some(number),
                    options: None,
                })
                .collect(),
            ..EnumDescriptorProto::default()
        };
        let motor_file = FileDescriptorProto {
            name: Some("glrmon_test/motor.proto".into()),
            package: Some("glrmon_test".into()),
            syntax: Some("proto3".into()),
            message_type: vec![motor],
            enum_type: vec![mode],
            ..FileDescriptorProto::default()
        };
        let chain_file = FileDescriptorProto {
            name: Some("glrmon_test/chain.proto".into()),
            package: Some("glrmon_test".into()),
            syntax: Some("proto3".into()),
            dependency: vec![
                "glrmon_test/motor.proto".into(),
                "google/protobuf/any.proto".into(),
            ],
            message_type: vec![DescriptorProto {
                name: Some("Chain".into()),
                field: vec![
                    message_field("next", 1, ".glrmon_test.Chain"),
                    message_field("motor", 2, ".glrmon_test.Motor"),
                    message_field("packed", 3, ".google.protobuf.Any"),
                ],
                ..DescriptorProto::default()
            }],
            ..FileDescriptorProto::default()
        };
        let any_file = FileDescriptorProto {
            name: Some("google/protobuf/any.proto".into()),
            package: Some("google.protobuf".into()),
            syntax: Some("proto3".into()),
            message_type: vec![DescriptorProto {
                name: Some("Any".into()),
                field: vec![
                    field("type_url", 1, Type::String, Label::Optional),
                    field("value", 2, Type::Bytes, Label::Optional),
                ],
                ..DescriptorProto::default()
            }],
            ..FileDescriptorProto::default()
        };
        vec![motor_file, any_file, chain_file]
    }

    fn encoded(files: Vec<FileDescriptorProto>) -> Vec<u8> {
        FileDescriptorSet { file: files }.encode_to_vec()
    }

    /// `data` packed in `Any`s `levels` deep, the innermost holding a Motor.
    fn packed(motor: Vec<u8>, levels: usize) -> Vec<u8> {
        let mut any = Any {
            type_url: "type.googleapis.com/glrmon_test.Motor".into(),
            value: motor,
        };
        for _ in 1..levels {
            any = Any {
                type_url: "type.googleapis.com/google.protobuf.Any".into(),
                value: any.encode_to_vec(),
            };
        }
        any.encode_to_vec()
    }

    /// A Motor with `data` [1.5, -2], `status` {count 2^40, label "x"}, mode RUNNING and
    /// `gain` left at its default, encoded by prost-reflect.
    fn motor(schema: &Schema) -> Vec<u8> {
        let status = (schema.message.parent_pool())
            .get_message_by_name("glrmon_test.Motor.Status")
            .unwrap();
        let mut s = DynamicMessage::new(status);
        s.set_field_by_name("count", Field::I64(1 << 40));
        s.set_field_by_name("label", Field::String("x".into()));
        let mut m = DynamicMessage::new(schema.message.clone());
        m.set_field_by_name("data", Field::List(vec![Field::F64(1.5), Field::F64(-2.0)]));
        m.set_field_by_name("status", Field::Message(s));
        m.set_field_by_name("mode", Field::EnumNumber(1));
        m.encode_to_vec()
    }

    #[test]
    fn a_message_reads_as_json_with_its_field_names_and_defaults() {
        let schema = Schema::parse("glrmon_test.Motor", &descriptor_set()).unwrap();
        let v = schema.decode(&motor(&schema)).unwrap();
        assert_eq!(
            v,
            serde_json::json!({
                "data": [1.5, -2.0],
                "gain": 0.0,
                "status": {"count": 1_u64 << 40, "label": "x"},
                "mode": 1,
            })
        );
        // An empty message has every field without presence at its default; a message
        // field that is not set stays absent.
        assert_eq!(
            schema.decode(&[]).unwrap(),
            serde_json::json!({"data": [], "gain": 0.0, "mode": 0})
        );
        // A type of a file that imports another, named with a leading dot.
        let chain = Schema::parse(".glrmon_test.Chain", &descriptor_set()).unwrap();
        let mut bytes = vec![0x12, 0];
        bytes.extend(motor(&schema));
        bytes[1] = u8::try_from(bytes.len() - 2).unwrap();
        let v = chain.decode(&bytes).unwrap();
        assert_eq!(v["motor"]["data"][1], -2.0);
    }

    #[test]
    fn bad_messages_and_schemas_are_errors() {
        let set = descriptor_set();
        let schema = Schema::parse("glrmon_test.Motor", &set).unwrap();
        let bytes = motor(&schema);
        for cut in 1..bytes.len() {
            // Every prefix either is a message (cut at a field's end) or says why not.
            if let Err(e) = schema.decode(&bytes[..cut]) {
                assert!(
                    e.starts_with("message does not decode as glrmon_test.Motor: "),
                    "{e}"
                );
            }
        }
        let e = schema.decode(&bytes[..bytes.len() - 1]).unwrap_err();
        assert!(
            e.starts_with("message does not decode as glrmon_test.Motor"),
            "{e}"
        );
        assert!(
            schema
                .decode(b"\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff")
                .is_err()
        );
        assert!(schema.decode(b"garbage").is_err());
        // A field with the wrong wire type (`data` as a varint).
        assert!(schema.decode(&[0x0b, 0x01]).is_err());

        let e = Schema::parse("glrmon_test.Engine", &set).unwrap_err();
        assert_eq!(
            e,
            "not in its descriptor set (its messages: \
             glrmon_test.Chain, glrmon_test.Motor, glrmon_test.Motor.Status, \
             google.protobuf.Any)"
        );
        let e = Schema::parse("glrmon_test.Motor", b"garbage").unwrap_err();
        assert!(e.starts_with("not a FileDescriptorSet: "), "{e}");
        let e = Schema::parse("glrmon_test.Motor", &set[..set.len() - 3]).unwrap_err();
        assert!(e.starts_with("not a FileDescriptorSet: "), "{e}");
        let e = Schema::parse("x.Y", &[]).unwrap_err();
        assert_eq!(e, "not in its descriptor set (its messages: none)");
        // A file that imports one the set does not hold.
        let mut files = descriptor_files();
        files.remove(0);
        let e = Schema::parse("glrmon_test.Chain", &encoded(files)).unwrap_err();
        assert!(
            e.starts_with("its FileDescriptorSet is not consistent: ")
                && e.contains("glrmon_test/motor.proto"),
            "{e}"
        );
    }

    /// What prost-reflect 0.16 would panic on or recurse through without end is refused
    /// first; an empty syntax is proto2.
    #[test]
    fn sets_prost_reflect_would_not_survive_are_refused() {
        let with = |change: &dyn Fn(&mut Vec<FileDescriptorProto>)| {
            let mut files = descriptor_files();
            change(&mut files);
            Schema::parse("glrmon_test.Motor", &encoded(files))
        };
        for (syntax, i) in [("qroto3", 2), ("editions", 0), ("proto4", 1)] {
            let e = with(&|f| f[i].syntax = Some(syntax.into())).unwrap_err();
            assert!(
                e.ends_with(&format!(
                    "has syntax \"{syntax}\": proto2 and proto3 are read"
                )),
                "{e}"
            );
        }
        let proto2 = with(&|f| f[1].syntax = Some(String::new())).unwrap();
        assert_eq!(proto2.decode(&[]).unwrap()["gain"], 0.0);
        let e = with(&|f| f[1].name = f[0].name.clone()).unwrap_err();
        assert_eq!(e, "file \"glrmon_test/motor.proto\" is in it twice");
        // Imports in a cycle, a public one onto itself first.
        let e = with(&|f| {
            f[0].dependency.push("glrmon_test/motor.proto".into());
            f[0].public_dependency.push(0);
        })
        .unwrap_err();
        assert_eq!(
            e,
            "file \"glrmon_test/motor.proto\" imports itself, through its imports or directly"
        );
        let e = with(&|f| f[1].dependency.push("glrmon_test/chain.proto".into())).unwrap_err();
        assert!(
            e.ends_with("imports itself, through its imports or directly"),
            "{e}"
        );
        // A chain of n files, each publicly importing the next.
        let chain = |n: usize| {
            move |f: &mut Vec<FileDescriptorProto>| {
                for i in 0..n {
                    f.push(FileDescriptorProto {
                        name: Some(format!("link{i}.proto")),
                        dependency: vec![format!("link{}.proto", i + 1)],
                        public_dependency: vec![0],
                        ..FileDescriptorProto::default()
                    });
                }
                f.push(FileDescriptorProto {
                    name: Some(format!("link{n}.proto")),
                    ..FileDescriptorProto::default()
                });
            }
        };
        let e = with(&chain(100)).unwrap_err();
        assert!(
            e.ends_with("imports through a chain of more than 64 files"),
            "{e}"
        );
        let short = with(&chain(10));
        assert!(short.is_ok());
        // Map entries: `map<string, double>` as protoc writes it reads; malformed ones,
        // which prost-reflect would panic on, are refused.
        let entry = |key: Type, fields: &[i32]| {
            let fields = fields.to_vec();
            move |f: &mut Vec<FileDescriptorProto>| {
                let types = [key, Type::Double];
                f[0].message_type[0].nested_type.push(DescriptorProto {
                    name: Some("GainsEntry".into()),
                    field: fields
                        .iter()
                        .map(|&n| {
                            field(
                                ["key", "value"][(n as usize - 1) % 2],
                                n,
                                types[(n as usize - 1) % 2],
                                Label::Optional,
                            )
                        })
                        .collect(),
                    options: Some(prost_reflect::prost_types::MessageOptions {
                        map_entry: Some(true),
                        ..Default::default()
                    }),
                    ..DescriptorProto::default()
                });
                f[0].message_type[0].field.push(FieldDescriptorProto {
                    type_name: Some(".glrmon_test.Motor.GainsEntry".into()),
                    ..field("gains", 5, Type::Message, Label::Repeated)
                });
            }
        };
        let schema = with(&entry(Type::String, &[1, 2])).unwrap();
        let v = schema
            .decode(&[
                0x2a, 0x0c, 0x0a, 0x01, b'p', 0x11, 0, 0, 0, 0, 0, 0, 0xf8, 0x3f,
            ])
            .unwrap();
        assert_eq!(v["gains"], serde_json::json!({"p": 1.5}));
        for (key, fields) in [
            (Type::Double, &[1, 2][..]),
            (Type::String, &[1]),
            (Type::String, &[2]),
            (Type::Int32, &[1, 2, 3]),
        ] {
            let e = with(&entry(key, fields)).unwrap_err();
            assert_eq!(
                e,
                "file \"glrmon_test/motor.proto\": map entry GainsEntry is not `key = 1` of an \
                 integer, bool or string type and `value = 2`"
            );
        }
    }

    #[test]
    fn a_message_packed_in_any_is_written_unpacked_to_a_bounded_depth() {
        let set = descriptor_set();
        let motor = motor(&Schema::parse("glrmon_test.Motor", &set).unwrap());
        let chain = Schema::parse("glrmon_test.Chain", &set).unwrap();
        let mut bytes = vec![0x1a];
        let any = packed(motor.clone(), 2);
        bytes.push(u8::try_from(any.len()).unwrap());
        bytes.extend(any);
        let v = chain.decode(&bytes).unwrap();
        assert_eq!(
            v["packed"]["@type"],
            "type.googleapis.com/google.protobuf.Any"
        );
        assert_eq!(v["packed"]["value"]["data"], serde_json::json!([1.5, -2.0]));
        // 5 000 `Any`s deep: each one decodes on its own; their JSON form would overflow
        // the stack.
        let any = packed(motor, 5_000);
        let mut bytes = vec![0x1a];
        let mut n = any.len();
        while n >= 0x80 {
            bytes.push(u8::try_from(n & 0x7f).unwrap() | 0x80);
            n >>= 7;
        }
        bytes.push(u8::try_from(n).unwrap());
        bytes.extend(any);
        let e = chain.decode(&bytes).unwrap_err();
        assert_eq!(
            e,
            "message does not decode as glrmon_test.Chain: its messages, with those packed \
             in google.protobuf.Any, nest deeper than 100"
        );
    }

    #[test]
    fn messages_nested_too_deep_are_refused() {
        let chain = Schema::parse("glrmon_test.Chain", &descriptor_set()).unwrap();
        // `next` inside `next`, 10 000 deep: each level is `0a <length>`.
        let mut bytes: Vec<u8> = Vec::new();
        for _ in 0..10_000 {
            let mut outer = vec![0x0a];
            let mut n = bytes.len();
            while n >= 0x80 {
                outer.push(u8::try_from(n & 0x7f).unwrap() | 0x80);
                n >>= 7;
            }
            outer.push(u8::try_from(n).unwrap());
            outer.extend(bytes);
            bytes = outer;
        }
        let e = chain.decode(&bytes).unwrap_err();
        assert!(e.contains("recursion limit"), "{e}");
    }

    proptest! {
        /// Hostile bytes, as a message or as a schema, are errors or values, never a
        /// panic.
        #[test]
        fn hostile_bytes_do_not_panic(
            data in proptest::collection::vec(any::<u8>(), 0..256),
            flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        ) {
            let set = descriptor_set();
            for name in ["glrmon_test.Motor", "glrmon_test.Chain"] {
                let schema = Schema::parse(name, &set).unwrap();
                let _ = schema.decode(&data);
                let mut bytes = motor(&Schema::parse("glrmon_test.Motor", &set).unwrap());
                for &(at, v) in &flips {
                    let n = bytes.len();
                    bytes[at % n] ^= v;
                }
                let _ = schema.decode(&bytes);
            }
            let _ = Schema::parse("glrmon_test.Motor", &data);
            let mut set = set;
            for &(at, v) in &flips {
                let n = set.len();
                set[at % n] ^= v;
            }
            if let Ok(schema) = Schema::parse("glrmon_test.Motor", &set) {
                let _ = schema.decode(&data);
            }
        }
    }
}
