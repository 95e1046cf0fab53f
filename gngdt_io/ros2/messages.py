"""The ROS 2 messages gngdt sends and receives, as CDR bytes, through rosbags' Jazzy type store.

Out: sensor_msgs/PointCloud2 (points; nodes with normals and one uint32 label field per
clustering), tf2_msgs/TFMessage, diagnostic_msgs/DiagnosticArray (MarkerArray: `markers`).
In: sensor_msgs/Image (decoded by `gngdt.schemas.images.decode_pixels`, as bags are), sensor_msgs/
CameraInfo (to `CameraIntrinsics`), TFMessage.

Type hashes (RIHS01) are computed by rosbags from the message definitions, never typed in.
Every ``encode_*`` returns the CDR payload (header ``00 01 00 00``: little-endian); every
``decode_*`` raises :class:`Ros2MessageError` for bytes that are not a valid message of its
type, whatever the damage.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics

__all__ = [
    "CAMERA_INFO",
    "DIAGNOSTIC_ARRAY",
    "IMAGE",
    "MARKER_ARRAY",
    "POINT_CLOUD2",
    "TF_MESSAGE",
    "CameraInfo",
    "ImageMessage",
    "Ros2MessageError",
    "Status",
    "Transform",
    "decode_camera_info",
    "decode_image",
    "decode_tf",
    "encode_camera_info",
    "encode_diagnostics",
    "encode_image",
    "encode_pointcloud2",
    "encode_tf",
    "type_hash",
]

POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"

#: sensor_msgs/PointField datatypes (PointField.msg constants) and their numpy types
UINT32, FLOAT32 = 6, 7

#: diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3


class Ros2MessageError(ValueError):
    """Bytes that are not a valid ROS 2 message of the expected type (or one gngdt refuses)."""


@functools.cache
def typestore() -> Any:
    """rosbags' ROS 2 Jazzy type store (built once)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def msg_type(name: str) -> Any:
    """The rosbags dataclass of a message type, e.g. ``msg_type("std_msgs/msg/Header")``."""
    return typestore().types[name]


def type_hash(ros_type: str) -> str:
    """``RIHS01_<sha256 hex>`` of a message type, computed by rosbags from its definition."""
    return typestore().hash_rihs01(ros_type)


def serialize(message: Any, ros_type: str) -> bytes:
    """CDR bytes (little-endian) of a rosbags message object."""
    return bytes(typestore().serialize_cdr(message, ros_type))


def deserialize(data: bytes, ros_type: str) -> Any:
    """The rosbags message object of CDR bytes (its arrays are read-only views of ``data``);
    :class:`Ros2MessageError` for anything malformed."""
    try:
        # a memoryview: rosbags slices off the CDR header, which would copy bytes (an image)
        return typestore().deserialize_cdr(memoryview(data), ros_type)
    except Exception as error:  # rosbags raises assorted errors on damaged bytes
        raise Ros2MessageError(f"not a valid {ros_type}: {type(error).__name__}: {error}"
                               ) from None


def stamp(ns: int) -> Any:
    """builtin_interfaces/Time of integer nanoseconds since the epoch."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return msg_type("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def stamp_ns(time: Any) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(time.sec) * 1_000_000_000 + int(time.nanosec)


def header(ns: int, frame_id: str) -> Any:
    """std_msgs/Header."""
    return msg_type("std_msgs/msg/Header")(stamp=stamp(ns), frame_id=frame_id)


# --- PointCloud2 ----------------------------------------------------------------------------


def label_field_name(clustering: str) -> str:
    """PointCloud2 field of a clustering's labels: ``col+nor`` -> ``label_col_nor``."""
    return "label_" + "".join(c if c.isalnum() or c == "_" else "_" for c in clustering)


def encode_pointcloud2(
    positions: np.ndarray,
    *,
    stamp_ns: int,
    frame_id: str,
    colors: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    labels: Mapping[str, np.ndarray] | None = None,
) -> bytes:
    """An unorganised cloud (height 1) as sensor_msgs/PointCloud2.

    positions: (N, 3) float32 metres -> ``x, y, z``. colors: (N, 3) uint8 RGB -> float32 ``rgb``
    holding ``0x00RRGGBB``. normals: (N, 3) float32 -> ``normal_x/y/z``. labels: clustering ->
    (N,) integer ids -> one uint32 ``label_<name>`` each (-1, no cluster, becomes 0xFFFFFFFF).
    Fields in that order, 4 bytes each, little-endian, no padding.
    """
    positions = np.asarray(positions)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions must be (N, 3), got {positions.shape}")
    count = positions.shape[0]
    fields: list[tuple[str, int]] = [("x", FLOAT32), ("y", FLOAT32), ("z", FLOAT32)]
    if colors is not None:
        colors = np.asarray(colors)
        if colors.shape != (count, 3) or colors.dtype != np.uint8:
            raise ValueError(f"colors must be ({count}, 3) uint8, got {colors.shape} "
                             f"{colors.dtype}")
        fields.append(("rgb", FLOAT32))
    if normals is not None:
        normals = np.asarray(normals)
        if normals.shape != (count, 3):
            raise ValueError(f"normals must be ({count}, 3), got {normals.shape}")
        fields += [("normal_x", FLOAT32), ("normal_y", FLOAT32), ("normal_z", FLOAT32)]
    label_columns = {label_field_name(name): np.asarray(values)
                     for name, values in (labels or {}).items()}
    if len(label_columns) != len(labels or {}):
        raise ValueError(f"clusterings {sorted(labels or {})} give the same field name")
    for name, values in label_columns.items():
        if values.shape != (count,):
            raise ValueError(f"labels {name!r} must be ({count},), got {values.shape}")
        fields.append((name, UINT32))
    # one row of 4-byte words per point, filled column by column (copies that are strided but
    # aligned on the destination: a numpy structured array was ~5x slower)
    table = np.empty((count, len(fields)), np.dtype("<u4"))
    floats = table.view(np.dtype("<f4"))
    floats[:, :3] = positions
    column = 3
    if colors is not None:  # float32 'rgb' whose bits are 0x00RRGGBB: bytes B, G, R, 0
        as_bytes = table.view(np.uint8).reshape(count, 4 * len(fields))
        for offset, channel in ((12, 2), (13, 1), (14, 0)):
            as_bytes[:, offset] = colors[:, channel]
        as_bytes[:, 15] = 0
        column += 1
    if normals is not None:
        floats[:, column:column + 3] = normals
        column += 3
    for values in label_columns.values():
        table[:, column] = values.astype(np.int64) & 0xFFFFFFFF  # -1 -> 0xFFFFFFFF
        column += 1
    point_step = 4 * len(fields)
    point_field = msg_type("sensor_msgs/msg/PointField")
    message = msg_type(POINT_CLOUD2)(
        header=header(stamp_ns, frame_id), height=1, width=count,
        fields=[point_field(name=name, offset=4 * k, datatype=kind, count=1)
                for k, (name, kind) in enumerate(fields)],
        is_bigendian=False, point_step=point_step, row_step=point_step * count,
        data=table.reshape(-1).view(np.uint8), is_dense=bool(np.isfinite(floats[:, :3]).all()))
    return serialize(message, POINT_CLOUD2)


# --- TF ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Transform:
    """``child``'s pose in ``parent`` at ``stamp_ns``: translation (3,) metres, rotation (4,)
    quaternion x, y, z, w (a geometry_msgs/TransformStamped)."""

    parent: str
    child: str
    stamp_ns: int
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


def encode_tf(transforms: Iterable[Transform]) -> bytes:
    """tf2_msgs/TFMessage (``header.frame_id`` = parent)."""
    vector, quaternion = msg_type("geometry_msgs/msg/Vector3"), msg_type(
        "geometry_msgs/msg/Quaternion")
    stamped = []
    for tf in transforms:
        tx, ty, tz = (float(v) for v in tf.translation)
        qx, qy, qz, qw = (float(v) for v in tf.rotation)
        stamped.append(msg_type("geometry_msgs/msg/TransformStamped")(
            header=header(tf.stamp_ns, tf.parent), child_frame_id=tf.child,
            transform=msg_type("geometry_msgs/msg/Transform")(
                translation=vector(x=tx, y=ty, z=tz), rotation=quaternion(x=qx, y=qy, z=qz, w=qw))))
    return serialize(msg_type(TF_MESSAGE)(transforms=stamped), TF_MESSAGE)


def decode_tf(data: bytes) -> list[Transform]:
    """The transforms of a tf2_msgs/TFMessage (``/tf``, ``/tf_static``)."""
    transforms = []
    for stamped in deserialize(data, TF_MESSAGE).transforms:
        t, q = stamped.transform.translation, stamped.transform.rotation
        transforms.append(Transform(stamped.header.frame_id, stamped.child_frame_id,
                                    stamp_ns(stamped.header.stamp), (t.x, t.y, t.z),
                                    (q.x, q.y, q.z, q.w)))
    return transforms


# --- Diagnostics ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Status:
    """One diagnostic_msgs/DiagnosticStatus; ``level`` OK, WARN, ERROR or STALE; values are
    sent as strings."""

    name: str
    level: int = OK
    message: str = ""
    hardware_id: str = ""
    values: Mapping[str, Any] = field(default_factory=dict)


def encode_diagnostics(statuses: Iterable[Status], *, stamp_ns: int, frame_id: str = "") -> bytes:
    """diagnostic_msgs/DiagnosticArray."""
    key_value = msg_type("diagnostic_msgs/msg/KeyValue")
    status_type = msg_type("diagnostic_msgs/msg/DiagnosticStatus")
    items = []
    for status in statuses:
        if status.level not in (OK, WARN, ERROR, STALE):
            raise ValueError(f"diagnostic level must be 0..3, got {status.level}")
        items.append(status_type(
            level=int(status.level), name=status.name, message=status.message,
            hardware_id=status.hardware_id,
            values=[key_value(key=str(k), value=str(v)) for k, v in status.values.items()]))
    message = msg_type(DIAGNOSTIC_ARRAY)(header=header(stamp_ns, frame_id), status=items)
    return serialize(message, DIAGNOSTIC_ARRAY)


# --- Image and CameraInfo (in) ------------------------------------------------------------------


@dataclass
class ImageMessage:
    """A decoded sensor_msgs/Image. pixels: see `gngdt.schemas.images.decode_pixels` ((H, W, 3)
    uint8 RGB for colour, bgr8 reordered; (H, W) uint16 for 16UC1/mono16, millimetres for depth;
    (H, W) float32 for 32FC1, metres)."""

    stamp_ns: int
    frame_id: str
    encoding: str
    pixels: np.ndarray


def decode_image(data: bytes, max_pixels: int) -> ImageMessage:
    """A sensor_msgs/Image of at most ``max_pixels`` pixels (checked before decoding), with
    ``step`` (row padding) and ``is_bigendian`` honoured."""
    from gngdt.schemas.images import decode_pixels
    from gngdt.schemas.messages import MessageError

    message = deserialize(data, IMAGE)
    if int(message.width) * int(message.height) > max_pixels:
        raise Ros2MessageError(f"image {message.width}x{message.height} exceeds the limit of "
                               f"{max_pixels} pixels")
    try:
        pixels = decode_pixels(  # the one copy: from the view of ``data``
            message.data, width=int(message.width), height=int(message.height),
            step=int(message.step), encoding=message.encoding,
            big_endian=bool(message.is_bigendian))
    except MessageError as error:
        raise Ros2MessageError(str(error)) from None
    return ImageMessage(stamp_ns(message.header.stamp), message.header.frame_id,
                        message.encoding, pixels)


def encode_image(pixels: np.ndarray, encoding: str, *, stamp_ns: int, frame_id: str) -> bytes:
    """sensor_msgs/Image, rows unpadded, little-endian: (H, W, 3) uint8 for rgb8/bgr8 (channels
    as given), (H, W) uint16 for 16UC1/mono16, (H, W) float32 for 32FC1."""
    layouts = {"rgb8": ("u1", 3), "bgr8": ("u1", 3), "16UC1": ("<u2", 1), "mono16": ("<u2", 1),
               "32FC1": ("<f4", 1)}
    if encoding not in layouts:
        raise ValueError(f"cannot encode {encoding!r}; one of {sorted(layouts)}")
    kind, channels = layouts[encoding]
    pixels = np.ascontiguousarray(pixels, dtype=np.dtype(kind))
    if pixels.ndim != (3 if channels > 1 else 2) or (channels > 1 and pixels.shape[2] != 3):
        raise ValueError(f"{encoding} needs shape (H, W{', 3' if channels > 1 else ''}), "
                         f"got {pixels.shape}")
    height, width = pixels.shape[:2]
    message = msg_type(IMAGE)(
        header=header(stamp_ns, frame_id), height=height, width=width, encoding=encoding,
        is_bigendian=0, step=width * channels * pixels.itemsize,
        data=pixels.reshape(-1).view(np.uint8))
    return serialize(message, IMAGE)


@dataclass(frozen=True)
class CameraInfo:
    """A decoded sensor_msgs/CameraInfo: the pinhole intrinsics of its K."""

    stamp_ns: int
    frame_id: str
    intrinsics: CameraIntrinsics


def decode_camera_info(data: bytes) -> CameraInfo:
    """A sensor_msgs/CameraInfo; refused when K is unset (an uncalibrated camera)."""
    from gngdt.schemas.images import intrinsics_from_k
    from gngdt.schemas.messages import MessageError

    message = deserialize(data, CAMERA_INFO)
    distortion = tuple(float(value) for value in message.d)
    try:
        intrinsics = intrinsics_from_k(int(message.width), int(message.height),
                                       [float(value) for value in message.k],
                                       distortion if any(distortion) else ())
    except MessageError as error:
        raise Ros2MessageError(str(error)) from None
    return CameraInfo(stamp_ns(message.header.stamp), message.header.frame_id, intrinsics)


def encode_camera_info(info: CameraInfo) -> bytes:
    """sensor_msgs/CameraInfo: K, P = [K | 0], R = identity, plumb_bob."""
    intrinsics = info.intrinsics
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    region = msg_type("sensor_msgs/msg/RegionOfInterest")(
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    message = msg_type(CAMERA_INFO)(
        header=header(info.stamp_ns, info.frame_id), height=intrinsics.height,
        width=intrinsics.width, distortion_model="plumb_bob",
        d=np.asarray(intrinsics.distortion or (0.0,) * 5, np.float64),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64),
        r=np.eye(3).reshape(-1),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], np.float64),
        binning_x=0, binning_y=0, roi=region)
    return serialize(message, CAMERA_INFO)
