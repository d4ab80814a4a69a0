"""Writes a simulated DC motor run (CSV: k,t,<u0>,<y0>,<y1>) as an MCAP file in the
protobuf profile, with the official writer (mcap-protobuf-support, zstd chunks): topic
/dc_motor/u carries [u0] and /dc_motor/y [y0, y1], both glrmon_test.Float64Array (a
google.protobuf.Timestamp `stamp`, so that the schema's FileDescriptorSet holds a
dependency, and a `repeated double data`), u 1 ms after each sample's time and y 2 ms
after, from 1 800 000 000 s on, as ros2_bag.py writes them. With --garbage-schema the
same messages are written with bytes that are no FileDescriptorSet as their schema, by
the mcap library alone.

usage: protobuf_bag.py SAMPLES.csv OUT.mcap [--garbage-schema]
"""

import sys

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory, timestamp_pb2
from mcap.writer import Writer as McapWriter
from mcap_protobuf.writer import Writer

from ros2_bag import ORIGIN_NS, rows


def float64_array_class():
    """The class of `glrmon_test.Float64Array`, built from descriptors (no compiler)."""
    pool = descriptor_pool.DescriptorPool()
    timestamp = descriptor_pb2.FileDescriptorProto()
    timestamp_pb2.DESCRIPTOR.CopyToProto(timestamp)
    pool.Add(timestamp)
    f = descriptor_pb2.FileDescriptorProto()
    f.name = "glrmon_test/float64_array.proto"
    f.package = "glrmon_test"
    f.syntax = "proto3"
    f.dependency.append(timestamp.name)
    m = f.message_type.add()
    m.name = "Float64Array"
    T = descriptor_pb2.FieldDescriptorProto
    stamp = m.field.add()
    stamp.name, stamp.number, stamp.type, stamp.label = "stamp", 1, T.TYPE_MESSAGE, T.LABEL_OPTIONAL
    stamp.type_name = ".google.protobuf.Timestamp"
    data = m.field.add()
    data.name, data.number, data.type, data.label = "data", 2, T.TYPE_DOUBLE, T.LABEL_REPEATED
    pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("glrmon_test.Float64Array"))


def messages(src, Float64Array):
    """(sequence, topic, time in ns, message) in the order they are written."""
    for seq, (t, v) in enumerate(rows(src)):
        base = ORIGIN_NS + round(t * 1e9)
        for topic, values, dt in (("/dc_motor/u", v[:1], 1), ("/dc_motor/y", v[1:], 2)):
            when = base + dt * 10**6
            m = Float64Array()
            m.stamp.seconds, m.stamp.nanos = divmod(when, 10**9)
            m.data.extend(values)
            yield seq, topic, when, m


def main(src, dst, garbage_schema):
    Float64Array = float64_array_class()
    with open(dst, "wb") as out:
        if garbage_schema:
            writer = McapWriter(out)
            writer.start(profile="", library="glrmon test")
            schema = writer.register_schema(
                name="glrmon_test.Float64Array", encoding="protobuf",
                data=b"garbage, not a FileDescriptorSet")
            channels = {topic: writer.register_channel(topic=topic, message_encoding="protobuf",
                                                       schema_id=schema)
                        for topic in ("/dc_motor/u", "/dc_motor/y")}
            for seq, topic, when, m in messages(src, Float64Array):
                writer.add_message(channels[topic], log_time=when, publish_time=when,
                                   data=m.SerializeToString(), sequence=seq)
            writer.finish()
        else:
            writer = Writer(out)
            for seq, topic, when, m in messages(src, Float64Array):
                writer.write_message(topic, m, log_time=when, publish_time=when, sequence=seq)
            writer.finish()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], "--garbage-schema" in sys.argv[3:])
