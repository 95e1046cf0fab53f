"""gngdt's wire schemas: generated protobuf bindings and numpy packing helpers.

``gngdt_pb2`` is generated from ``gngdt.proto`` by ``python -m schemas.generate`` and checked in.
Foxglove's own messages come from the ``foxglove-schemas-protobuf`` package.
"""

from schemas import gngdt_pb2
from schemas.packing import (
    LearnerStatusInfo,
    MessageError,
    StreamEndInfo,
    TopologySnapshot,
    calibration_to_intrinsics,
    cloud_to_msg,
    decode_status,
    decode_stream_end,
    decode_topology,
    encode_status,
    encode_stream_end,
    encode_topology,
    image_to_raw,
    intrinsics_to_calibration,
    msg_to_cloud,
    pack_array,
    parse_message,
    raw_to_image,
    unpack_array,
)

__all__ = [
    "LearnerStatusInfo",
    "MessageError",
    "StreamEndInfo",
    "TopologySnapshot",
    "calibration_to_intrinsics",
    "cloud_to_msg",
    "decode_status",
    "decode_stream_end",
    "decode_topology",
    "encode_status",
    "encode_stream_end",
    "encode_topology",
    "gngdt_pb2",
    "image_to_raw",
    "intrinsics_to_calibration",
    "msg_to_cloud",
    "pack_array",
    "parse_message",
    "raw_to_image",
    "unpack_array",
]
