//! ROS 2 messages of a recording, by the `ros2msg` schema the recording carries: the
//! message definition text (the type's fields, then each dependency after a line of
//! `=` and `MSG: pkg/Type`), parsed once per schema; each message in CDR is read by
//! `cdr-encoding`'s deserializer, driven by the parsed definition, into a JSON value
//! (numbers, strings, arrays, objects), which the channel's field paths then read.

use std::collections::HashMap;
use std::fmt;

use byteorder::{BigEndian, LittleEndian};
use cdr_encoding::CdrDeserializer;
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, SeqAccess, Visitor};
use serde_json::Value;

/// A field's type.
#[derive(Debug, Clone, PartialEq)]
enum Type {
    Bool,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    String,
    /// A message type, by its full name `pkg/Type`.
    Message(String),
}

/// How many of a type a field holds.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Count {
    One,
    /// `T[N]`.
    Fixed(usize),
    /// `T[]` or `T[<=N]`.
    Sequence,
}

#[derive(Debug, Clone, PartialEq)]
struct Field {
    name: String,
    ty: Type,
    count: Count,
}

/// A parsed message definition with its dependencies.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Schema {
    root: String,
    messages: HashMap<String, Vec<Field>>,
}

/// Why a definition or a message could not be read.
pub(crate) type Ros2Error = String;

fn primitive(name: &str) -> Option<Type> {
    Some(match name {
        "bool" => Type::Bool,
        "int8" => Type::I8,
        "uint8" | "byte" | "char" => Type::U8,
        "int16" => Type::I16,
        "uint16" => Type::U16,
        "int32" => Type::I32,
        "uint32" => Type::U32,
        "int64" => Type::I64,
        "uint64" => Type::U64,
        "float32" => Type::F32,
        "float64" => Type::F64,
        "string" => Type::String,
        _ => return None,
    })
}

/// `pkg/msg/Type` or `pkg/Type` as `pkg/Type`.
fn canonical(name: &str) -> String {
    name.replacen("/msg/", "/", 1)
}

impl Schema {
    /// Parses the definition of `name` (`pkg/msg/Type`) as a recording stores it.
    pub(crate) fn parse(name: &str, text: &str) -> Result<Self, Ros2Error> {
        let root = canonical(name);
        let mut messages = HashMap::new();
        let mut current = root.clone();
        let mut fields = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if raw.trim_start().starts_with("===") {
                messages.insert(std::mem::take(&mut current), std::mem::take(&mut fields));
                continue;
            }
            if line.is_empty() {
                continue;
            }
            if let Some(dep) = line.strip_prefix("MSG:") {
                // A definition that starts without its `===` separator ends the one
                // before all the same.
                let before = std::mem::replace(&mut current, canonical(dep.trim()));
                if !fields.is_empty() || !before.is_empty() {
                    messages.insert(before, std::mem::take(&mut fields));
                }
                continue;
            }
            let mut words = line.split_whitespace();
            let (Some(ty), Some(name)) = (words.next(), words.next()) else {
                return Err(format!("line {}: \"{line}\" is not `type name`", n + 1));
            };
            // A constant (`int32 MODE=1`, or `int32 MODE = 1`) is not in the message.
            if name.contains('=') || words.next() == Some("=") {
                continue;
            }
            let package = current.split('/').next().unwrap_or("");
            fields.push(field(ty, name, package).map_err(|e| format!("line {}: {e}", n + 1))?);
        }
        messages.insert(current, fields);
        messages.retain(|k, _| !k.is_empty());
        for (name, fields) in builtin() {
            messages.entry(name.to_owned()).or_insert(fields);
        }
        if !messages.contains_key(&root) {
            return Err(format!("the schema does not define {root} itself"));
        }
        let schema = Self { root, messages };
        for fields in schema.messages.values() {
            for f in fields {
                if let Type::Message(m) = &f.ty
                    && !schema.messages.contains_key(m)
                {
                    return Err(format!(
                        "field {} has type {m}, which the schema does not define",
                        f.name
                    ));
                }
            }
        }
        // Every value decoded takes bytes of the message, so a message decodes to at
        // most as many values as it has bytes: but for the elements of a type that
        // takes none (a message without fields), whose count only the data or the
        // schema would bound.
        for fields in schema.messages.values() {
            for f in fields {
                if let Count::Fixed(n) = f.count
                    && n > MAX_FIXED
                {
                    return Err(format!(
                        "field {} is an array of {n} values, more than {MAX_FIXED}",
                        f.name
                    ));
                }
                if f.count != Count::One && schema.min_size(&f.ty, 0) == 0 {
                    return Err(format!(
                        "field {} is an array of a message without fields, which takes \
                         no byte: its length would not be bounded by the message",
                        f.name
                    ));
                }
            }
        }
        Ok(schema)
    }

    /// The fewest bytes a value of `ty` takes in CDR (0 for a message without fields,
    /// or nested too deep to tell).
    fn min_size(&self, ty: &Type, depth: usize) -> usize {
        match ty {
            Type::Bool | Type::I8 | Type::U8 => 1,
            Type::I16 | Type::U16 => 2,
            Type::I32 | Type::U32 | Type::F32 | Type::String => 4,
            Type::I64 | Type::U64 | Type::F64 => 8,
            Type::Message(m) if depth < MAX_DEPTH => self.messages.get(m).map_or(0, |fields| {
                fields
                    .iter()
                    .map(|f| match f.count {
                        Count::One => self.min_size(&f.ty, depth + 1),
                        Count::Fixed(n) => n.saturating_mul(self.min_size(&f.ty, depth + 1)),
                        Count::Sequence => 4,
                    })
                    .fold(0, usize::saturating_add)
            }),
            Type::Message(_) => 0,
        }
    }

    /// A message (after its 4-byte CDR encapsulation header) as a JSON value.
    pub(crate) fn decode(&self, data: &[u8]) -> Result<Value, Ros2Error> {
        let (little, body) = match data {
            [0, 1, _, _, body @ ..] => (true, body),
            [0, 0, _, _, body @ ..] => (false, body),
            _ => return Err("not plain CDR (header 00 01 or 00 00)".into()),
        };
        let seed = MessageSeed {
            schema: self,
            name: &self.root,
            depth: 0,
        };
        let value = if little {
            seed.deserialize(&mut CdrDeserializer::<LittleEndian>::new(body))
        } else {
            seed.deserialize(&mut CdrDeserializer::<BigEndian>::new(body))
        };
        value.map_err(|e| e.to_string())
    }
}

/// `builtin_interfaces` types a definition may use without including them.
fn builtin() -> [(&'static str, Vec<Field>); 2] {
    let f = |name: &str, ty| Field {
        name: name.into(),
        ty,
        count: Count::One,
    };
    [
        (
            "builtin_interfaces/Time",
            vec![f("sec", Type::I32), f("nanosec", Type::U32)],
        ),
        (
            "builtin_interfaces/Duration",
            vec![f("sec", Type::I32), f("nanosec", Type::U32)],
        ),
    ]
}

fn field(ty: &str, name: &str, package: &str) -> Result<Field, String> {
    let (base, count) = match ty.split_once('[') {
        None => (ty, Count::One),
        Some((base, rest)) => {
            let inside = rest
                .strip_suffix(']')
                .ok_or_else(|| format!("\"{ty}\" is not an array type"))?;
            let count = if inside.is_empty() || inside.starts_with("<=") {
                Count::Sequence
            } else {
                Count::Fixed(
                    inside
                        .parse()
                        .map_err(|_| format!("\"{ty}\": \"{inside}\" is not an array length"))?,
                )
            };
            (base, count)
        }
    };
    // `string<=10`: a bounded string.
    let base = base.split("<=").next().unwrap_or(base);
    let ty = match primitive(base) {
        Some(t) => t,
        None if base == "wstring" => return Err("wstring fields are not read".into()),
        None if base == "Header" => Type::Message("std_msgs/Header".into()),
        None if base.contains('/') => Type::Message(canonical(base)),
        None => Type::Message(format!("{package}/{base}")),
    };
    Ok(Field {
        name: name.to_owned(),
        ty,
        count,
    })
}

/// Deeper nesting is refused (a definition that includes itself).
const MAX_DEPTH: usize = 32;

/// The longest fixed-size array `T[N]` a schema may declare.
const MAX_FIXED: usize = 1 << 20;

struct MessageSeed<'s> {
    schema: &'s Schema,
    name: &'s str,
    depth: usize,
}

impl<'de> DeserializeSeed<'de> for MessageSeed<'_> {
    type Value = Value;

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        let fields = self.schema.messages.get(self.name).map_or(0, Vec::len);
        d.deserialize_tuple(fields, self)
    }
}

impl<'de> Visitor<'de> for MessageSeed<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a {} message", self.name)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        if self.depth > MAX_DEPTH {
            return Err(de::Error::custom("messages nested too deep"));
        }
        let Some(fields) = self.schema.messages.get(self.name) else {
            return Err(de::Error::custom(format!(
                "the schema does not define {}",
                self.name
            )));
        };
        let mut object = serde_json::Map::new();
        for f in fields {
            let seed = FieldSeed {
                schema: self.schema,
                field: f,
                depth: self.depth,
            };
            let v = seq
                .next_element_seed(seed)?
                .ok_or_else(|| de::Error::custom(format!("field {} is missing", f.name)))?;
            object.insert(f.name.clone(), v);
        }
        Ok(Value::Object(object))
    }
}

struct FieldSeed<'s> {
    schema: &'s Schema,
    field: &'s Field,
    depth: usize,
}

impl<'de> DeserializeSeed<'de> for FieldSeed<'_> {
    type Value = Value;

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        let one = One {
            schema: self.schema,
            ty: &self.field.ty,
            depth: self.depth,
        };
        match self.field.count {
            Count::One => one.deserialize(d),
            Count::Fixed(n) => d.deserialize_tuple(n, Many(one)),
            Count::Sequence => d.deserialize_seq(Many(one)),
        }
    }
}

/// One value of a type.
#[derive(Clone, Copy)]
struct One<'s> {
    schema: &'s Schema,
    ty: &'s Type,
    depth: usize,
}

impl<'de> DeserializeSeed<'de> for One<'_> {
    type Value = Value;

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        Ok(match self.ty {
            Type::Bool => Value::from(bool::deserialize(d)?),
            Type::I8 => Value::from(i8::deserialize(d)?),
            Type::U8 => Value::from(u8::deserialize(d)?),
            Type::I16 => Value::from(i16::deserialize(d)?),
            Type::U16 => Value::from(u16::deserialize(d)?),
            Type::I32 => Value::from(i32::deserialize(d)?),
            Type::U32 => Value::from(u32::deserialize(d)?),
            Type::I64 => Value::from(i64::deserialize(d)?),
            Type::U64 => Value::from(u64::deserialize(d)?),
            Type::F32 => number(f64::from(f32::deserialize(d)?)),
            Type::F64 => number(f64::deserialize(d)?),
            Type::String => Value::from(String::deserialize(d)?),
            Type::Message(name) => MessageSeed {
                schema: self.schema,
                name,
                depth: self.depth + 1,
            }
            .deserialize(d)?,
        })
    }
}

/// A float as JSON: a non-finite one (which JSON cannot hold) as `null`, which a field
/// path then reports as not a number.
fn number(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

/// The values of an array or sequence.
struct Many<'s>(One<'s>);

impl<'de> Visitor<'de> for Many<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an array")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut values = Vec::new();
        while let Some(v) = seq.next_element_seed(self.0)? {
            values.push(v);
        }
        Ok(Value::Array(values))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MULTI_ARRAY: &str = "# comment\nMultiArrayLayout  layout\nfloat64[]         data\n\
        ================================================================================\n\
        MSG: std_msgs/MultiArrayLayout\nMultiArrayDimension[] dim\nuint32 data_offset\n\
        ================================================================================\n\
        MSG: std_msgs/MultiArrayDimension\nstring label\nuint32 size\nuint32 stride\n";

    #[test]
    fn a_definition_with_dependencies_reads_its_messages() {
        let schema = Schema::parse("std_msgs/msg/Float64MultiArray", MULTI_ARRAY).unwrap();
        // layout.dim = [{label "x", size 2, stride 2}], data_offset 0, data [1.5, -2].
        let mut data = vec![0, 1, 0, 0];
        data.extend(1u32.to_le_bytes());
        data.extend(2u32.to_le_bytes());
        data.extend(b"x\0\0\0");
        data.extend(2u32.to_le_bytes());
        data.extend(2u32.to_le_bytes());
        data.extend(0u32.to_le_bytes());
        data.extend(2u32.to_le_bytes());
        data.extend([0u8; 4]);
        data.extend(1.5f64.to_le_bytes());
        data.extend((-2.0f64).to_le_bytes());
        let v = schema.decode(&data).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"layout": {"dim": [{"label": "x", "size": 2, "stride": 2}], "data_offset": 0}, "data": [1.5, -2.0]})
        );
        assert!(schema.decode(&data[..data.len() - 3]).is_err());
    }

    /// Found by fuzzing (it panicked: the root type was never defined, then indexed):
    /// a dependency's `MSG:` line before any `===` ends the root's definition as the
    /// separator would, so the root is always defined (with no field when the text
    /// starts with a dependency, as `std_msgs/Empty`), and decoding looks types up.
    #[test]
    fn a_schema_without_separators_or_its_root_is_read_or_refused() {
        let joined = MULTI_ARRAY.replacen(
            "================================================================================\n",
            "",
            1,
        );
        let schema = Schema::parse("std_msgs/msg/Float64MultiArray", &joined).unwrap();
        assert_eq!(schema.messages["std_msgs/Float64MultiArray"].len(), 2);
        let rootless = "MSG: std_msgs/MultiArrayDimension\nstring label\n";
        let empty = Schema::parse("std_msgs/msg/Float64MultiArray", rootless).unwrap();
        assert_eq!(empty.decode(&[0, 1, 0, 0]).unwrap(), serde_json::json!({}));
        // The fuzzer's input: the root's last line merged with a separator.
        let text = std::fs::read("../../fuzz/regressions/foreign/ros2-root-undefined").unwrap();
        let text = String::from_utf8_lossy(&text[3..]);
        let _ =
            Schema::parse("std_msgs/msg/Float64MultiArray", &text).map(|s| s.decode(&[0, 1, 0, 0]));
    }

    /// Found by fuzzing (it ran out of memory: a sequence length of 2³² read from the
    /// data, of a message without fields, allocates without consuming a byte): arrays
    /// of a type that takes no byte, and fixed arrays longer than 2²⁰, are refused with
    /// the schema, so that a message decodes to at most as many values as it has bytes.
    #[test]
    fn arrays_whose_length_the_message_would_not_bound_are_refused() {
        let empty = "Empty[] many\n===\nMSG: pkg/Empty\n";
        let e = Schema::parse("pkg/msg/Thing", empty).unwrap_err();
        assert!(
            e.starts_with("field many is an array of a message without fields"),
            "{e}"
        );
        let nested = "Outer[3] few\n===\nMSG: pkg/Outer\nEmpty inner\n===\nMSG: pkg/Empty\n";
        assert!(Schema::parse("pkg/msg/Thing", nested).is_err());
        let huge = "uint8[2000000] bytes\n";
        let e = Schema::parse("pkg/msg/Thing", huge).unwrap_err();
        assert_eq!(
            e,
            "field bytes is an array of 2000000 values, more than 1048576"
        );
        // A sequence of non-empty messages is read.
        let fine = "Pair[] pairs\n===\nMSG: pkg/Pair\nuint8 a\n";
        let schema = Schema::parse("pkg/msg/Thing", fine).unwrap();
        let mut data = vec![0, 1, 0, 0];
        data.extend(2u32.to_le_bytes());
        data.extend([7, 8]);
        assert_eq!(
            schema.decode(&data).unwrap(),
            serde_json::json!({"pairs": [{"a": 7}, {"a": 8}]})
        );
    }

    #[test]
    fn constants_bounds_and_fixed_arrays_are_read_as_ros_defines_them() {
        let text = "int32 MODE=1\nuint8 LIMIT = 2\nstring<=8 name\nfloat32[2] pair\nint16[<=4] few\nbuiltin_interfaces/Time stamp\n";
        let schema = Schema::parse("pkg/msg/Thing", text).unwrap();
        let mut data = vec![0, 1, 0, 0];
        data.extend(3u32.to_le_bytes());
        data.extend(b"ab\0\0");
        data.extend(0.5f32.to_le_bytes());
        data.extend(2.0f32.to_le_bytes());
        data.extend(1u32.to_le_bytes());
        data.extend((-3i16).to_le_bytes());
        data.extend([0u8; 2]);
        data.extend(7i32.to_le_bytes());
        data.extend(9u32.to_le_bytes());
        let v = schema.decode(&data).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"name": "ab", "pair": [0.5, 2.0], "few": [-3], "stamp": {"sec": 7, "nanosec": 9}})
        );
        let e = Schema::parse("pkg/msg/Bad", "Missing thing\n").unwrap_err();
        assert!(e.contains("pkg/Missing"), "{e}");
    }
}
