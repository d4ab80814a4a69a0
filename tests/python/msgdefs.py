"""ROS 2 message definitions (as a ROS 2 bag stores them: the type, then each
dependency after a line of '=' and `MSG: pkg/Type`) and the Sparkplug B protobuf
schema (Eclipse Tahu's `org.eclipse.tahu.protobuf.Payload`, the fields the tests use),
built with the official protobuf library's descriptors so that no compiler is needed."""

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

FLOAT64_MULTI_ARRAY = """\
# Please look at the MultiArrayLayout message definition for
# documentation on all multiarrays.

MultiArrayLayout  layout        # specification of data layout
float64[]         data          # array of data

================================================================================
MSG: std_msgs/MultiArrayLayout
MultiArrayDimension[] dim # Array of dimension properties
uint32 data_offset        # padding elements at front of data

================================================================================
MSG: std_msgs/MultiArrayDimension
string label   # label of given dimension
uint32 size    # size of given dimension (in type units)
uint32 stride  # stride of given dimension
"""

GLRMON_SAMPLE = """\
int64 k      # sample index; -1: none
float64 t    # time in seconds; NaN: none
float64[] u
float64[] y
float64[] p
"""


def sparkplug_payload_class():
    """The class of `org.eclipse.tahu.protobuf.Payload` (Sparkplug B)."""
    f = descriptor_pb2.FileDescriptorProto()
    f.name = "sparkplug_b_test.proto"
    f.package = "org.eclipse.tahu.protobuf"
    f.syntax = "proto2"
    payload = f.message_type.add()
    payload.name = "Payload"
    T = descriptor_pb2.FieldDescriptorProto
    opt = T.LABEL_OPTIONAL

    def field(msg, name, number, type_, label=opt, type_name=None, oneof=None):
        fd = msg.field.add()
        fd.name, fd.number, fd.type, fd.label = name, number, type_, label
        if type_name:
            fd.type_name = type_name
        if oneof is not None:
            fd.oneof_index = oneof

    metric = payload.nested_type.add()
    metric.name = "Metric"
    metric.oneof_decl.add().name = "value"
    field(metric, "name", 1, T.TYPE_STRING)
    field(metric, "alias", 2, T.TYPE_UINT64)
    field(metric, "timestamp", 3, T.TYPE_UINT64)
    field(metric, "datatype", 4, T.TYPE_UINT32)
    field(metric, "is_historical", 5, T.TYPE_BOOL)
    field(metric, "is_transient", 6, T.TYPE_BOOL)
    field(metric, "is_null", 7, T.TYPE_BOOL)
    field(metric, "int_value", 10, T.TYPE_UINT32, oneof=0)
    field(metric, "long_value", 11, T.TYPE_UINT64, oneof=0)
    field(metric, "float_value", 12, T.TYPE_FLOAT, oneof=0)
    field(metric, "double_value", 13, T.TYPE_DOUBLE, oneof=0)
    field(metric, "boolean_value", 14, T.TYPE_BOOL, oneof=0)
    field(metric, "string_value", 15, T.TYPE_STRING, oneof=0)
    field(metric, "bytes_value", 16, T.TYPE_BYTES, oneof=0)
    field(payload, "timestamp", 1, T.TYPE_UINT64)
    field(payload, "metrics", 2, T.TYPE_MESSAGE, T.LABEL_REPEATED,
          ".org.eclipse.tahu.protobuf.Payload.Metric")
    field(payload, "seq", 3, T.TYPE_UINT64)
    field(payload, "uuid", 4, T.TYPE_STRING)
    field(payload, "body", 5, T.TYPE_BYTES)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(f)
    return message_factory.GetMessageClass(
        pool.FindMessageTypeByName("org.eclipse.tahu.protobuf.Payload"))


# Sparkplug B data types (Sparkplug 3.0 §6.4.16).
DOUBLE = 10
INT32 = 3
