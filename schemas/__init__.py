"""gngdt's wire schemas: generated protobuf bindings and numpy packing helpers (by message family
in ``messages``, ``images``, ``clouds``, ``topology``, ``status``).

``gngdt_pb2`` is generated from ``gngdt.proto`` by ``python -m gngdt.schemas.generate`` and checked
in. Foxglove's own messages come from the ``foxglove-schemas-protobuf`` package.
"""

from gngdt.schemas import gngdt_pb2
from gngdt.schemas.clouds import cloud_to_msg, msg_to_cloud
from gngdt.schemas.images import (
    calibration_to_intrinsics,
    image_to_raw,
    intrinsics_to_calibration,
    raw_to_image,
)
from gngdt.schemas.messages import MessageError, pack_array, parse_message, unpack_array
from gngdt.schemas.status import (
    LearnerStatusInfo,
    StreamEndInfo,
    decode_status,
    decode_stream_end,
    encode_status,
    encode_stream_end,
)
from gngdt.schemas.topology import TopologySnapshot, decode_topology, encode_topology

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
