"""Encodes a simulated channel's CSV (k,t,<u>,<y0>,<y1>) as the binary payloads a
plant publishes, with the official libraries: ROS 2 CDR by mcap-ros2-support's
serializer (std_msgs/msg/Float64MultiArray, glrmon_msgs/msg/Sample), Sparkplug B by
Google's protobuf (a DBIRTH carrying names, aliases and data types, then DDATA by
alias). Writes one JSON line of hex strings per row: {"cdr", "sample", "sparkplug"}.

usage: payloads.py SAMPLES.csv OUT.jsonl
"""

import csv
import json
import sys

from mcap_ros2._dynamic import serialize_dynamic

from msgdefs import DOUBLE, FLOAT64_MULTI_ARRAY, GLRMON_SAMPLE, sparkplug_payload_class


def main(src, dst):
    multi_array = serialize_dynamic("std_msgs/msg/Float64MultiArray", FLOAT64_MULTI_ARRAY)
    sample = serialize_dynamic("glrmon_msgs/msg/Sample", GLRMON_SAMPLE)
    Payload = sparkplug_payload_class()
    with open(src) as f, open(dst, "w") as out:
        rows = csv.reader(f)
        header = next(rows)
        names = header[2:]
        for i, row in enumerate(rows):
            k, t = int(row[0]), float(row[1])
            values = [float(v) for v in row[2:]]
            cdr = multi_array["std_msgs/msg/Float64MultiArray"]({
                "layout": {"dim": [{"label": "u_y", "size": len(values),
                                    "stride": len(values)}], "data_offset": 0},
                "data": values,
            })
            glr = sample["glrmon_msgs/msg/Sample"](
                {"k": k, "t": t, "u": values[:1], "y": values[1:], "p": []})
            p = Payload()
            p.timestamp = 1_700_000_000_000 + 10 * k
            p.seq = i % 256
            for alias, (name, v) in enumerate(zip(names, values), start=1):
                m = p.metrics.add()
                if i == 0:
                    m.name, m.datatype = name, DOUBLE
                m.alias = alias
                m.timestamp = p.timestamp
                m.double_value = v
            out.write(json.dumps({
                "cdr": bytes(cdr).hex(),
                "sample": bytes(glr).hex(),
                "sparkplug": p.SerializeToString().hex(),
            }) + "\n")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
