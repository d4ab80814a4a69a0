"""Writes a simulated DC motor run (CSV: k,t,<u0>,<y0>,<y1>) as a ROS 2 bag in MCAP,
with the official writer (mcap-ros2-support, ROS 2 profile, zstd chunks): topic
/dc_motor/u carries [u0] and /dc_motor/y [y0, y1], both std_msgs/msg/Float64MultiArray,
u 1 ms after each sample's time and y 2 ms after, from 1 800 000 000 s on. With
--json the same messages are written as Foxglove JSON (message encoding "json", a JSON
Schema) with the mcap library alone.

usage: ros2_bag.py SAMPLES.csv OUT.mcap [--json]
"""

import csv
import json
import sys

from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer

from msgdefs import FLOAT64_MULTI_ARRAY

ORIGIN_NS = 1_800_000_000 * 10**9


def rows(path):
    with open(path) as f:
        reader = csv.reader(f)
        next(reader)
        for row in reader:
            yield float(row[1]), [float(v) for v in row[2:]]


def message(values):
    return {
        "layout": {"dim": [{"label": "signals", "size": len(values), "stride": len(values)}],
                   "data_offset": 0},
        "data": values,
    }


def main(src, dst, as_json):
    with open(dst, "wb") as out:
        if as_json:
            writer = McapWriter(out)
            writer.start(profile="", library="glrmon test")
            schema = writer.register_schema(
                name="std_msgs/msg/Float64MultiArray", encoding="jsonschema",
                data=json.dumps({"type": "object"}).encode())
            channels = {topic: writer.register_channel(topic=topic, message_encoding="json",
                                                       schema_id=schema)
                        for topic in ("/dc_motor/u", "/dc_motor/y")}
            for seq, (t, v) in enumerate(rows(src)):
                base = ORIGIN_NS + round(t * 1e9)
                for topic, values, dt in (("/dc_motor/u", v[:1], 1), ("/dc_motor/y", v[1:], 2)):
                    when = base + dt * 10**6
                    writer.add_message(channels[topic], log_time=when, publish_time=when,
                                       data=json.dumps(message(values)).encode(), sequence=seq)
            writer.finish()
        else:
            writer = Writer(out)
            schema = writer.register_msgdef("std_msgs/msg/Float64MultiArray", FLOAT64_MULTI_ARRAY)
            for seq, (t, v) in enumerate(rows(src)):
                base = ORIGIN_NS + round(t * 1e9)
                for topic, values, dt in (("/dc_motor/u", v[:1], 1), ("/dc_motor/y", v[1:], 2)):
                    when = base + dt * 10**6
                    writer.write_message(topic, schema, message(values), log_time=when,
                                         publish_time=when, sequence=seq)
            writer.finish()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], "--json" in sys.argv[3:])
