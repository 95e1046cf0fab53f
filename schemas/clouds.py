"""Point clouds and rigid transforms: numpy points <-> foxglove PointCloud (gngdt's packed
layout and any other), a cloud's pose, (4, 4) matrices -> foxglove FrameTransform.

Decoded clouds are fresh, writable, C-contiguous arrays, except ``msg_to_cloud(..., copy=False)``:
read-only strided views. Decoders raise :class:`~gngdt.schemas.messages.MessageError` for anything
malformed (see :mod:`gngdt.schemas.messages`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

from gngdt.core.sensor.geometry import TransformError, matrix_to_pose, pose_to_matrix
from gngdt.schemas.messages import MessageError, ns_to_timestamp, parse_message

__all__ = [
    "CLOUD_POINT_STRIDE",
    "MAX_CLOUD_POINTS",
    "cloud_pose",
    "cloud_to_msg",
    "cloud_to_wire",
    "msg_to_cloud",
    "pose_to_transform",
    "transform_to_pose",
]

#: Bytes per point of the clouds gngdt publishes: x, y, z float32 at 0, 4, 8 and red, green, blue
#: uint8 at 12, 13, 14 -- unpadded (15), which keeps clouds 6 % smaller than a 16-byte stride.
CLOUD_POINT_STRIDE = 15

#: Largest cloud a learner accepts by default and a capture publishes: 30 MB on the wire,
#: within zenoh's message limit (gngdt.services.plumbing.MAX_MESSAGE_BYTES).
MAX_CLOUD_POINTS = 2_000_000

_NUMERIC_TYPES: dict[int, np.dtype] = {
    PackedElementField.UINT8: np.dtype("u1"),
    PackedElementField.INT8: np.dtype("i1"),
    PackedElementField.UINT16: np.dtype("<u2"),
    PackedElementField.INT16: np.dtype("<i2"),
    PackedElementField.UINT32: np.dtype("<u4"),
    PackedElementField.INT32: np.dtype("<i4"),
    PackedElementField.FLOAT32: np.dtype("<f4"),
    PackedElementField.FLOAT64: np.dtype("<f8"),
}

#: One point of a gngdt cloud as a numpy record (filling records beats strided byte copies 2x).
_GNGDT_POINT = np.dtype(
    {
        "names": ["xyz", "rgb"],
        "formats": [("<f4", (3,)), ("u1", (3,))],
        "offsets": [0, 12],
        "itemsize": CLOUD_POINT_STRIDE,
    }
)

_GNGDT_CLOUD_FIELDS = [
    PackedElementField(name="x", offset=0, type=PackedElementField.FLOAT32),
    PackedElementField(name="y", offset=4, type=PackedElementField.FLOAT32),
    PackedElementField(name="z", offset=8, type=PackedElementField.FLOAT32),
    PackedElementField(name="red", offset=12, type=PackedElementField.UINT8),
    PackedElementField(name="green", offset=13, type=PackedElementField.UINT8),
    PackedElementField(name="blue", offset=14, type=PackedElementField.UINT8),
]


def cloud_to_msg(
    positions: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    timestamp_ns: int,
    frame_id: str = "camera",
    pose: np.ndarray | None = None,
) -> PointCloud:
    """foxglove PointCloud of ``positions`` (N, 3) float32 metres and ``colors`` (N, 3) uint8 RGB.

    Layout: x, y, z FLOAT32 at offsets 0, 4, 8 and red, green, blue UINT8 at 12, 13, 14,
    point_stride 15 (12 and no colour fields when ``colors`` is None). ``pose``: (4, 4) transform
    from the points' own frame (the camera's) into ``frame_id`` (foxglove's "origin of the point
    cloud relative to the frame of reference"); None: the identity, the points are in ``frame_id``.
    """
    xyz, colors = _checked_cloud(positions, colors)
    message = _cloud_header(colors is not None, timestamp_ns, frame_id, pose)
    if colors is None:
        message.data = xyz.tobytes()
    else:
        packed = np.empty(len(xyz), dtype=_GNGDT_POINT)
        packed["xyz"] = xyz
        packed["rgb"] = colors
        message.data = packed.tobytes()
    return message


def cloud_to_wire(
    positions: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    timestamp_ns: int,
    frame_id: str = "camera",
    pose: np.ndarray | None = None,
) -> bytearray:
    """``cloud_to_msg(...).SerializeToString()``, byte for byte, with the points written once,
    straight into the returned buffer (no intermediate copies of a cloud of megabytes).

    The PointCloud's ``data`` is its last field (number 6), so the message is its other fields
    serialised by protobuf, then ``data``'s tag, length and the packed points.
    """
    xyz, colors = _checked_cloud(positions, colors)
    wire, start = cloud_wire_buffer(len(xyz), colors is not None, timestamp_ns=timestamp_ns,
                                    frame_id=frame_id, pose=pose)
    if colors is None:
        np.frombuffer(wire, dtype="<f4", count=len(xyz) * 3, offset=start)[:] = xyz.ravel()
    else:
        packed = np.frombuffer(wire, dtype=_GNGDT_POINT, count=len(xyz), offset=start)
        packed["xyz"] = xyz
        packed["rgb"] = colors
        del packed  # the buffer is handed on: no view of it stays behind
    return wire


def cloud_wire_buffer(count: int, with_colors: bool, *, timestamp_ns: int, frame_id: str,
                      pose: np.ndarray | None) -> tuple[bytearray, int]:
    """A serialised PointCloud of ``count`` points whose packed points are still to be written:
    (the buffer, where its points start); the points take the rest of it."""
    head = _cloud_header(with_colors, timestamp_ns, frame_id, pose).SerializeToString()
    size = count * (CLOUD_POINT_STRIDE if with_colors else 12)
    prefix = _DATA_TAG + _varint(size) if size else b""  # proto3 leaves an empty field out
    start = len(head) + len(prefix)
    wire = bytearray(start + size)
    wire[:start] = head + prefix
    return wire, start


#: the tag of PointCloud's ``data`` (length-delimited field 6): one byte
_DATA_TAG = bytes([PointCloud.DESCRIPTOR.fields_by_name["data"].number << 3 | 2])


def _varint(value: int) -> bytes:
    """Protobuf's base-128 varint of a non-negative integer."""
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _checked_cloud(positions: np.ndarray, colors: np.ndarray | None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) little-endian float32 positions and (N, 3) uint8 colours (or None), checked."""
    positions = np.asarray(positions)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"cloud_to_msg: positions must be (N, 3), got {positions.shape}")
    count = positions.shape[0]
    xyz = np.ascontiguousarray(positions, dtype="<f4")
    if colors is None:
        return xyz, None
    colors = np.asarray(colors)
    if colors.shape != (count, 3):
        raise ValueError(
            f"cloud_to_msg: colors must be ({count}, 3) like positions, got {colors.shape}"
        )
    if colors.dtype != np.uint8:
        raise ValueError(f"cloud_to_msg: colors must be uint8, got {colors.dtype}")
    return xyz, colors


def _cloud_header(with_colors: bool, timestamp_ns: int, frame_id: str,
                  pose: np.ndarray | None) -> PointCloud:
    """A PointCloud with everything but its ``data``."""
    message = PointCloud(
        timestamp=ns_to_timestamp(timestamp_ns),
        frame_id=frame_id,
        point_stride=CLOUD_POINT_STRIDE if with_colors else 12,
        fields=_GNGDT_CLOUD_FIELDS if with_colors else _GNGDT_CLOUD_FIELDS[:3],
    )
    if pose is None:
        message.pose.orientation.w = 1.0
    else:
        _set_rigid(message.pose.position, message.pose.orientation, pose)
    return message


def _set_rigid(translation: Vector3, rotation: Quaternion, matrix: np.ndarray) -> None:
    """Fill a foxglove translation/position and quaternion from a (4, 4) rigid transform."""
    offset, quaternion = matrix_to_pose(matrix)
    translation.x, translation.y, translation.z = offset.tolist()
    rotation.x, rotation.y, rotation.z, rotation.w = quaternion.tolist()


def wire_pose(matrix: np.ndarray) -> np.ndarray:
    """(4, 4) float64: a rigid ``matrix`` as a cloud's receiver reads it back (it travels as a
    translation and a unit quaternion), for replays that must learn exactly what the learner
    learns from the wire."""
    offset, quaternion = matrix_to_pose(matrix)
    return pose_to_matrix(offset.tolist(), quaternion.tolist())


def cloud_pose(message: PointCloud | bytes) -> np.ndarray:
    """(4, 4) float64 pose of a PointCloud: maps its points into its ``frame_id``.

    An unset orientation (all zero, as a publisher that never set the pose leaves it) is the
    identity. Raises :class:`MessageError` naming the frame for non-finite numbers or a quaternion
    that is not of unit length (see ``gngdt.core.sensor.geometry.QUATERNION_TOLERANCE``).
    """
    message = parse_message(PointCloud, message)
    position, rotation = message.pose.position, message.pose.orientation
    quaternion = [rotation.x, rotation.y, rotation.z, rotation.w]
    if not any(quaternion):
        quaternion = [0.0, 0.0, 0.0, 1.0]
    try:
        return pose_to_matrix([position.x, position.y, position.z], quaternion,
                              f"point cloud pose in {message.frame_id!r}")
    except TransformError as error:
        raise MessageError(str(error)) from error


def pose_to_transform(
    matrix: np.ndarray, parent_frame_id: str, child_frame_id: str, *, timestamp_ns: int
) -> FrameTransform:
    """foxglove FrameTransform ``parent -> child`` of a (4, 4) child-to-parent transform."""
    message = FrameTransform(
        timestamp=ns_to_timestamp(timestamp_ns),
        parent_frame_id=parent_frame_id,
        child_frame_id=child_frame_id,
    )
    _set_rigid(message.translation, message.rotation, matrix)
    return message


def transform_to_pose(message: FrameTransform | bytes) -> tuple[str, str, np.ndarray]:
    """``(parent, child, matrix)`` of a foxglove FrameTransform: ``matrix`` (4, 4) float64 maps
    points of the child frame into the parent frame (`pose_to_transform` inverted). Raises
    :class:`MessageError` naming the frames for non-finite numbers or a non-unit rotation."""
    message = parse_message(FrameTransform, message)
    t, q = message.translation, message.rotation
    what = f"transform {message.parent_frame_id!r} -> {message.child_frame_id!r}"
    try:
        matrix = pose_to_matrix([t.x, t.y, t.z], [q.x, q.y, q.z, q.w], what)
    except TransformError as error:
        raise MessageError(str(error)) from error
    return message.parent_frame_id, message.child_frame_id, matrix


def _field_column(data: bytes, count: int, stride: int, element: PackedElementField) -> np.ndarray:
    """Strided (count,) view of one field of a packed point buffer (no copy)."""
    dtype = _NUMERIC_TYPES.get(element.type)
    if dtype is None:
        raise MessageError(f"point field {element.name!r} has unknown numeric type {element.type}")
    if element.offset + dtype.itemsize > stride:
        raise MessageError(
            f"point field {element.name!r} at offset {element.offset} exceeds stride {stride}"
        )
    return np.ndarray((count,), dtype=dtype, buffer=data, offset=element.offset, strides=(stride,))


def _is_gngdt_layout(cloud_fields: Iterable[PackedElementField]) -> bool:
    layout = {(element.name, element.offset, element.type) for element in cloud_fields}
    expected = {(element.name, element.offset, element.type) for element in _GNGDT_CLOUD_FIELDS}
    return layout == expected


def _color_channel(column: np.ndarray) -> np.ndarray:
    if column.dtype == np.uint8:
        return column
    if column.dtype.kind == "f":  # foxglove's convention for float colour fields: 0..1
        return np.clip(np.rint(np.nan_to_num(column) * 255.0), 0, 255).astype(np.uint8)
    return np.clip(column, 0, 255).astype(np.uint8)


def msg_to_cloud(
    message: PointCloud | bytes, *, max_points: int = 10_000_000, copy: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """``(positions, colors)`` of a foxglove PointCloud in any field order and stride.

    positions: (N, 3) float32 (x, y, z required; other numeric types are converted).
    colors: (N, 3) uint8 RGB from red/green/blue fields, or None when the cloud has none
    (float colour fields are taken as 0..1). The point count is checked against ``max_points``
    before any allocation. The pose is not applied.
    copy=False: for gngdt's own layout, read-only strided views into the payload instead of
    copies (a consumer that samples or decimates the cloud then copies only what it uses).
    """
    message = parse_message(PointCloud, message)
    by_name = {element.name: element for element in message.fields}
    missing = [axis for axis in ("x", "y", "z") if axis not in by_name]
    if missing:
        raise MessageError(f"point cloud has no {'/'.join(missing)} field")
    stride, data = message.point_stride, message.data
    if stride <= 0:
        raise MessageError(f"point cloud stride {stride} must be positive")
    if len(data) % stride:
        raise MessageError(
            f"point cloud data of {len(data)} bytes is not a multiple of stride {stride}"
        )
    count = len(data) // stride
    if count > max_points:
        raise MessageError(f"point cloud has {count} points, more than the limit of {max_points}")
    if stride == CLOUD_POINT_STRIDE and _is_gngdt_layout(message.fields):
        points = np.frombuffer(data, dtype=_GNGDT_POINT, count=count)
        if not copy:
            return points["xyz"], points["rgb"]
        return np.array(points["xyz"], dtype=np.float32), np.array(points["rgb"], dtype=np.uint8)
    x, y, z = (by_name[axis] for axis in ("x", "y", "z"))
    float32_xyz = all(element.type == PackedElementField.FLOAT32 for element in (x, y, z))
    if float32_xyz and y.offset == x.offset + 4 and z.offset == x.offset + 8:
        if x.offset + 12 > stride:
            raise MessageError(f"point fields x/y/z at offset {x.offset} exceed stride {stride}")
        view = np.ndarray(
            (count, 3), dtype="<f4", buffer=data, offset=x.offset, strides=(stride, 4)
        )
        positions = np.array(view, dtype=np.float32)
    else:
        positions = np.empty((count, 3), dtype=np.float32)
        for axis, element in enumerate((x, y, z)):
            positions[:, axis] = _field_column(data, count, stride, element)
    if not all(name in by_name for name in ("red", "green", "blue")):
        return positions, None
    colors = np.empty((count, 3), dtype=np.uint8)
    for channel, name in enumerate(("red", "green", "blue")):
        colors[:, channel] = _color_channel(_field_column(data, count, stride, by_name[name]))
    return positions, colors
