"""numpy arrays <-> protobuf messages: the names of the former single module, re-exported.

The code lives by message family: :mod:`schemas.messages` (parsing, timestamps, PackedArray),
:mod:`schemas.images` (raw images, calibration), :mod:`schemas.clouds` (point clouds, cloud poses,
transforms), :mod:`schemas.topology` (``gngdt.Topology``) and :mod:`schemas.status`
(``gngdt.LearnerStatus``, ``gngdt.StreamEnd``). Import from those in new code.
"""

from schemas.clouds import (
    CLOUD_POINT_STRIDE,
    MAX_CLOUD_POINTS,
    cloud_pose,
    cloud_to_msg,
    msg_to_cloud,
    pose_to_transform,
)
from schemas.images import (
    MAX_IMAGE_PIXELS,
    calibration_to_intrinsics,
    decode_pixels,
    image_to_raw,
    intrinsics_from_k,
    intrinsics_to_calibration,
    raw_to_image,
)
from schemas.messages import (
    NANOS_PER_SECOND,
    PACKED_DTYPES,
    MessageError,
    ns_to_timestamp,
    pack_array,
    parse_message,
    timestamp_to_ns,
    unpack_array,
)
from schemas.status import (
    LearnerStatusInfo,
    StreamEndInfo,
    decode_status,
    decode_stream_end,
    encode_status,
    encode_stream_end,
)
from schemas.topology import (
    MAX_CLUSTERINGS,
    MAX_EDGE_SETS,
    MAX_EDGES_PER_NODE,
    MAX_NAME_LENGTH,
    MAX_TOPOLOGY_NODES,
    TopologySnapshot,
    decode_topology,
    encode_topology,
)

__all__ = [
    "CLOUD_POINT_STRIDE",
    "MAX_CLOUD_POINTS",
    "MAX_CLUSTERINGS",
    "MAX_EDGES_PER_NODE",
    "MAX_EDGE_SETS",
    "MAX_IMAGE_PIXELS",
    "MAX_NAME_LENGTH",
    "MAX_TOPOLOGY_NODES",
    "NANOS_PER_SECOND",
    "PACKED_DTYPES",
    "LearnerStatusInfo",
    "MessageError",
    "StreamEndInfo",
    "TopologySnapshot",
    "calibration_to_intrinsics",
    "cloud_pose",
    "cloud_to_msg",
    "decode_pixels",
    "decode_status",
    "decode_stream_end",
    "decode_topology",
    "encode_status",
    "encode_stream_end",
    "encode_topology",
    "image_to_raw",
    "intrinsics_from_k",
    "intrinsics_to_calibration",
    "msg_to_cloud",
    "ns_to_timestamp",
    "pack_array",
    "parse_message",
    "pose_to_transform",
    "raw_to_image",
    "timestamp_to_ns",
    "unpack_array",
]
