"""numpy arrays <-> protobuf messages (gngdt's own and foxglove's) without per-element loops.

Every encoder takes ``timestamp_ns`` (int, nanoseconds since the epoch) and fills the protobuf
``Timestamp``; decoders give nanoseconds back. Every decoder accepts the message or its serialized
``bytes`` (what zenoh delivers) and raises :class:`MessageError` -- never another exception type --
for anything malformed: undecodable bytes, unknown dtype strings, inconsistent sizes, indices out of
range. Sizes are validated before anything is allocated, so a hostile header cannot make a decoder
allocate gigabytes.

Arrays returned by :func:`unpack_array` and :func:`decode_topology` are read-only views on the
message bytes (zero-copy); ``.copy()`` them to modify. Images and clouds are returned as fresh,
writable, C-contiguous arrays, except ``msg_to_cloud(..., copy=False)``: read-only strided views.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.message import Message
from google.protobuf.timestamp_pb2 import Timestamp

from gngdt_core.geometry import CameraIntrinsics, TransformError, matrix_to_pose, pose_to_matrix
from schemas import gngdt_pb2

__all__ = [
    "CLOUD_POINT_STRIDE",
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

NANOS_PER_SECOND = 1_000_000_000

#: dtypes a PackedArray may carry (numpy names, always little-endian on the wire).
PACKED_DTYPES = frozenset(
    {"float32", "float64", "uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64"}
)

#: Bytes per point of the clouds gngdt publishes: x, y, z float32 at 0, 4, 8 and red, green, blue
#: uint8 at 12, 13, 14 -- unpadded (15), which keeps clouds 6 % smaller than a 16-byte stride.
CLOUD_POINT_STRIDE = 15

#: Largest image a decoder accepts (width * height), 64 megapixels.
MAX_IMAGE_PIXELS = 64 * 1024 * 1024

#: Largest cloud a learner accepts by default and a capture publishes: 30 MB on the wire,
#: within zenoh's message limit (services.plumbing.MAX_MESSAGE_BYTES).
MAX_CLOUD_POINTS = 2_000_000

#: What a GNG-DT learner can send, enforced before anything is allocated: a node keeps at most
#: 16 neighbours (``gngdt_core._kernels.MAX_DEGREE``), so an edge set holds at most 8 edges a
#: node; a learner publishes a handful of named edge sets and clusterings.
MAX_TOPOLOGY_NODES = 1_000_000
MAX_EDGES_PER_NODE = 8
MAX_EDGE_SETS = 16
MAX_CLUSTERINGS = 16
MAX_NAME_LENGTH = 64

_MessageT = TypeVar("_MessageT", bound=Message)


class MessageError(ValueError):
    """A payload is malformed: undecodable, inconsistent or out of the accepted limits."""


# --------------------------------------------------------------------------------------- generic
def parse_message(message_type: type[_MessageT], data: _MessageT | bytes) -> _MessageT:
    """Return ``data`` as a ``message_type``: parsed if bytes, as it is if already that message."""
    if isinstance(data, message_type):
        return data
    if not isinstance(data, bytes | bytearray | memoryview):
        raise MessageError(
            f"expected bytes or {message_type.DESCRIPTOR.full_name}, got {type(data).__name__}"
        )
    try:
        return message_type.FromString(bytes(data))
    except Exception as error:  # DecodeError, invalid UTF-8, ... all mean the same here
        raise MessageError(
            f"cannot decode {message_type.DESCRIPTOR.full_name} ({len(data)} bytes): {error}"
        ) from error


def ns_to_timestamp(timestamp_ns: int, target: Timestamp | None = None) -> Timestamp:
    """Fill (or create) a protobuf ``Timestamp`` from integer nanoseconds."""
    timestamp_ns = int(timestamp_ns)
    target = Timestamp() if target is None else target
    target.seconds, target.nanos = divmod(timestamp_ns, NANOS_PER_SECOND)
    return target


def timestamp_to_ns(timestamp: Timestamp) -> int:
    """Integer nanoseconds of a protobuf ``Timestamp``."""
    return timestamp.seconds * NANOS_PER_SECOND + timestamp.nanos


def _little_endian(dtype: np.dtype) -> np.dtype:
    return dtype.newbyteorder("<") if dtype.itemsize > 1 else dtype


# ---------------------------------------------------------------------------------- PackedArray
def pack_array(array: np.ndarray, dtype: np.typing.DTypeLike = None) -> gngdt_pb2.PackedArray:
    """Pack an array (cast to ``dtype`` if given) as little-endian C-order bytes with its shape."""
    array = np.asarray(array, dtype=dtype)
    if array.dtype.name not in PACKED_DTYPES:
        raise ValueError(f"pack_array: dtype {array.dtype} is not one of {sorted(PACKED_DTYPES)}")
    wire = np.ascontiguousarray(array, dtype=_little_endian(array.dtype))
    return gngdt_pb2.PackedArray(
        dtype=array.dtype.name, shape=list(array.shape), data=wire.tobytes()
    )


def unpack_array(
    message: gngdt_pb2.PackedArray | bytes,
    *,
    dtype: np.typing.DTypeLike = None,
    ndim: int | None = None,
    max_elements: int | None = None,
    name: str = "array",
) -> np.ndarray:
    """Read-only array view of a PackedArray, validated before anything is allocated.

    dtype/ndim: required dtype and number of dimensions (``None`` accepts any).
    max_elements: upper bound on the number of elements. ``name`` appears in error messages.
    """
    message = parse_message(gngdt_pb2.PackedArray, message)
    if message.dtype not in PACKED_DTYPES:
        raise MessageError(f"{name}: unknown dtype {message.dtype!r}")
    wire_dtype = _little_endian(np.dtype(message.dtype))
    if dtype is not None and np.dtype(dtype) != np.dtype(message.dtype):
        raise MessageError(f"{name}: dtype {message.dtype}, expected {np.dtype(dtype).name}")
    shape = tuple(int(size) for size in message.shape)
    if ndim is not None and len(shape) != ndim:
        raise MessageError(f"{name}: shape {shape} has {len(shape)} dimensions, expected {ndim}")
    elements = math.prod(shape)
    if max_elements is not None and elements > max_elements:
        raise MessageError(f"{name}: {elements} elements exceed the limit of {max_elements}")
    expected_bytes = elements * wire_dtype.itemsize
    if len(message.data) != expected_bytes:
        raise MessageError(
            f"{name}: {len(message.data)} bytes of data, shape {shape} {message.dtype} "
            f"needs {expected_bytes}"
        )
    return np.frombuffer(message.data, dtype=wire_dtype).reshape(shape)


# ----------------------------------------------------------------------------------------- images
#: encoding -> (numpy dtype, channels) of the pixel layouts gngdt decodes.
_PIXEL_LAYOUTS: dict[str, tuple[np.dtype, int]] = {
    "rgb8": (np.dtype(np.uint8), 3),
    "bgr8": (np.dtype(np.uint8), 3),
    "8UC3": (np.dtype(np.uint8), 3),
    "rgba8": (np.dtype(np.uint8), 4),
    "bgra8": (np.dtype(np.uint8), 4),
    "mono8": (np.dtype(np.uint8), 1),
    "8UC1": (np.dtype(np.uint8), 1),
    "mono16": (np.dtype(np.uint16), 1),
    "16UC1": (np.dtype(np.uint16), 1),
    "32FC1": (np.dtype(np.float32), 1),
}
_BLUE_FIRST = frozenset({"bgr8", "8UC3", "bgra8"})


def decode_pixels(
    data: bytes,
    *,
    width: int,
    height: int,
    step: int,
    encoding: str,
    big_endian: bool = False,
) -> np.ndarray:
    """Pixels of a raw image buffer as a writable C-contiguous array.

    Returns (H, W, 3) uint8 RGB for colour encodings (bgr8/8UC3 reordered, alpha dropped),
    (H, W) uint8 for mono8/8UC1, (H, W) uint16 for mono16/16UC1, (H, W) float32 for 32FC1.
    Shared by foxglove RawImage and ROS 2 sensor_msgs/Image (which may be big-endian).
    """
    if encoding not in _PIXEL_LAYOUTS:
        raise MessageError(
            f"image encoding {encoding!r} is not supported (supported: {sorted(_PIXEL_LAYOUTS)})"
        )
    pixel_dtype, channels = _PIXEL_LAYOUTS[encoding]
    if width <= 0 or height <= 0:
        raise MessageError(f"image size {width}x{height} is empty")
    if width * height > MAX_IMAGE_PIXELS:
        raise MessageError(f"image size {width}x{height} exceeds {MAX_IMAGE_PIXELS} pixels")
    row_bytes = width * channels * pixel_dtype.itemsize
    if step < row_bytes:
        raise MessageError(f"image step {step} is less than {row_bytes} bytes per {encoding} row")
    if len(data) < step * height:
        raise MessageError(
            f"image data has {len(data)} bytes, {width}x{height} {encoding} with step {step} "
            f"needs {step * height}"
        )
    rows = np.frombuffer(data, dtype=np.uint8, count=step * height).reshape(height, step)
    byte_order = ">" if big_endian else "<"
    pixels = rows[:, :row_bytes].view(pixel_dtype.newbyteorder(byte_order))
    pixels = pixels.reshape((height, width, channels) if channels > 1 else (height, width))
    if channels > 1:
        pixels = pixels[..., 2::-1] if encoding in _BLUE_FIRST else pixels[..., :3]
    return np.array(pixels, dtype=pixel_dtype, order="C")  # a writable copy, native order


def image_to_raw(
    image: np.ndarray,
    *,
    timestamp_ns: int,
    frame_id: str = "camera",
    encoding: str | None = None,
) -> RawImage:
    """Wrap an image in a foxglove RawImage.

    image: (H, W, 3) uint8 RGB -> ``rgb8``; (H, W) uint16 -> ``16UC1`` (pass ``encoding="mono16"``
    for label images); (H, W) float32 -> ``32FC1``; (H, W) uint8 -> ``mono8``.
    """
    image = np.asarray(image)
    if encoding is None:
        defaults = {
            ("uint8", 3): "rgb8",
            ("uint8", 2): "mono8",
            ("uint16", 2): "16UC1",
            ("float32", 2): "32FC1",
        }
        encoding = defaults.get((image.dtype.name, image.ndim))
        if encoding is None:
            raise ValueError(
                f"image_to_raw: no encoding for a {image.dtype} image of shape {image.shape}"
            )
    layout = _PIXEL_LAYOUTS.get(encoding)
    if layout is None or encoding in _BLUE_FIRST or encoding in {"rgba8"}:
        raise ValueError(f"image_to_raw: cannot encode {encoding!r}")
    pixel_dtype, channels = layout
    expected_ndim = 3 if channels > 1 else 2
    if (
        image.dtype != pixel_dtype
        or image.ndim != expected_ndim
        or (channels > 1 and image.shape[2] != channels)
    ):
        raise ValueError(
            f"image_to_raw: {encoding} needs a {pixel_dtype} array of shape "
            f"{'(H, W, 3)' if channels > 1 else '(H, W)'}, got {image.dtype} {image.shape}"
        )
    height, width = image.shape[:2]
    wire = np.ascontiguousarray(image, dtype=_little_endian(pixel_dtype))
    return RawImage(
        timestamp=ns_to_timestamp(timestamp_ns),
        frame_id=frame_id,
        width=width,
        height=height,
        encoding=encoding,
        step=width * channels * pixel_dtype.itemsize,
        data=wire.tobytes(),
    )


def raw_to_image(message: RawImage | bytes) -> np.ndarray:
    """Pixels of a foxglove RawImage; see :func:`decode_pixels` for the shapes per encoding."""
    message = parse_message(RawImage, message)
    return decode_pixels(
        message.data,
        width=message.width,
        height=message.height,
        step=message.step,
        encoding=message.encoding,
    )


# ------------------------------------------------------------------------------------ calibration
def intrinsics_to_calibration(
    intrinsics: CameraIntrinsics, *, timestamp_ns: int, frame_id: str = "camera"
) -> CameraCalibration:
    """foxglove CameraCalibration of a pinhole camera: K (3x3) and P (3x4) row-major, R = I."""
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    return CameraCalibration(
        timestamp=ns_to_timestamp(timestamp_ns),
        frame_id=frame_id,
        width=intrinsics.width,
        height=intrinsics.height,
        distortion_model="plumb_bob",
        D=list(intrinsics.distortion) or [0.0] * 5,
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def intrinsics_from_k(
    width: int, height: int, k: list[float] | tuple[float, ...], distortion: tuple[float, ...]
) -> CameraIntrinsics:
    """CameraIntrinsics from a row-major 3x3 K (foxglove CameraCalibration and ROS CameraInfo)."""
    if len(k) != 9:
        raise MessageError(f"calibration K has {len(k)} values, expected 9")
    if width <= 0 or height <= 0:
        raise MessageError(f"calibration image size {width}x{height} is empty")
    fx, fy, cx, cy = float(k[0]), float(k[4]), float(k[2]), float(k[5])
    if not (fx > 0 and fy > 0 and math.isfinite(fx) and math.isfinite(fy)):
        raise MessageError(f"calibration is uncalibrated or invalid: fx={fx}, fy={fy}")
    return CameraIntrinsics(
        width=int(width),
        height=int(height),
        fx=fx,
        fy=fy,
        cx=cx,
        cy=cy,
        distortion=tuple(float(value) for value in distortion),
    )


def calibration_to_intrinsics(message: CameraCalibration | bytes) -> CameraIntrinsics:
    """Pinhole intrinsics of a foxglove CameraCalibration (from K; D kept as ``distortion``)."""
    message = parse_message(CameraCalibration, message)
    distortion = tuple(message.D)
    if not any(distortion):
        distortion = ()
    return intrinsics_from_k(message.width, message.height, list(message.K), distortion)


# ------------------------------------------------------------------------------------ point cloud
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
    positions = np.asarray(positions)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"cloud_to_msg: positions must be (N, 3), got {positions.shape}")
    count = positions.shape[0]
    xyz = np.ascontiguousarray(positions, dtype="<f4")
    if colors is None:
        stride, cloud_fields, data = 12, _GNGDT_CLOUD_FIELDS[:3], xyz.tobytes()
    else:
        colors = np.asarray(colors)
        if colors.shape != (count, 3):
            raise ValueError(
                f"cloud_to_msg: colors must be ({count}, 3) like positions, got {colors.shape}"
            )
        if colors.dtype != np.uint8:
            raise ValueError(f"cloud_to_msg: colors must be uint8, got {colors.dtype}")
        packed = np.empty(count, dtype=_GNGDT_POINT)
        packed["xyz"] = xyz
        packed["rgb"] = colors
        stride, cloud_fields, data = CLOUD_POINT_STRIDE, _GNGDT_CLOUD_FIELDS, packed.tobytes()
    message = PointCloud(
        timestamp=ns_to_timestamp(timestamp_ns),
        frame_id=frame_id,
        point_stride=stride,
        fields=cloud_fields,
        data=data,
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


def cloud_pose(message: PointCloud | bytes) -> np.ndarray:
    """(4, 4) float64 pose of a PointCloud: maps its points into its ``frame_id``.

    An unset orientation (all zero, as a publisher that never set the pose leaves it) is the
    identity. Raises :class:`MessageError` naming the frame for non-finite numbers or a quaternion
    that is not of unit length (see ``gngdt_core.geometry.QUATERNION_TOLERANCE``).
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


# --------------------------------------------------------------------------------------- topology
@dataclass
class TopologySnapshot:
    """One decoded ``gngdt.Topology``.

    positions: (N, 3) float32 metres; colors: (N, 3) uint8 RGB; normals: (N, 3) float32;
    errors: (N,) float32; node_ids: (N,) int64 persistent node ids -- each None if the publisher
    left it out. edges: property -> (E, 2) uint32 node-index pairs. clusterings: name -> (N,) int32
    labels; cluster_ids: name -> (K,) int64 persistent id of each label 0..K-1, for the
    clusterings whose publisher tracks them.
    """

    positions: np.ndarray
    colors: np.ndarray | None
    normals: np.ndarray | None
    errors: np.ndarray | None
    edges: dict[str, np.ndarray]
    clusterings: dict[str, np.ndarray]
    steps: int
    frame_sequence: int
    timestamp_ns: int
    frame_id: str
    quantization_error: dict[str, float] = field(default_factory=dict)
    cluster_counts: dict[str, int] = field(default_factory=dict)
    node_ids: np.ndarray | None = None
    cluster_ids: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def node_count(self) -> int:
        return int(self.positions.shape[0])


def _node_array(values: np.ndarray | None, name: str, count: int, width: int | None) -> np.ndarray:
    array = np.asarray(values)
    expected = (count,) if width is None else (count, width)
    if array.shape != expected:
        raise ValueError(f"encode_topology: {name} must have shape {expected}, got {array.shape}")
    return array


def _count_clusters(labels: np.ndarray) -> int:
    return int(np.unique(labels[labels >= 0]).size)


def encode_topology(
    *,
    positions: np.ndarray,
    colors: np.ndarray | None,
    normals: np.ndarray | None,
    errors: np.ndarray | None,
    edges: Mapping[str, np.ndarray],
    clusterings: Mapping[str, np.ndarray],
    steps: int,
    frame_sequence: int,
    timestamp_ns: int,
    frame_id: str,
    quantization_error: Mapping[str, float] | None = None,
    node_ids: np.ndarray | None = None,
    cluster_ids: Mapping[str, np.ndarray] | None = None,
) -> gngdt_pb2.Topology:
    """Build a ``gngdt.Topology``; see :class:`TopologySnapshot` for shapes.

    Casts positions/normals/errors to float32, clips and rounds colours to uint8, edges to uint32,
    labels to int32. Raises ValueError naming the parameter for wrong shapes or edge indices >= N.
    ``cluster_count`` per clustering counts the distinct labels >= 0.
    """
    positions = _node_array(positions, "positions", np.shape(positions)[0], 3)
    count = positions.shape[0]
    message = gngdt_pb2.Topology(
        frame_sequence=int(frame_sequence), steps=int(steps), frame_id=frame_id
    )
    ns_to_timestamp(timestamp_ns, message.timestamp)
    message.positions.CopyFrom(pack_array(positions, np.float32))
    if colors is not None:
        colors = _node_array(colors, "colors", count, 3)
        message.colors.CopyFrom(pack_array(np.clip(np.rint(colors), 0, 255), np.uint8))
    if normals is not None:
        message.normals.CopyFrom(pack_array(_node_array(normals, "normals", count, 3), np.float32))
    if errors is not None:
        message.errors.CopyFrom(pack_array(_node_array(errors, "errors", count, None), np.float32))
    if node_ids is not None:
        message.node_ids.CopyFrom(
            pack_array(_node_array(node_ids, "node_ids", count, None), np.int64))
    cluster_ids = cluster_ids or {}
    unknown = sorted(set(cluster_ids) - set(clusterings))
    if unknown:
        raise ValueError(f"encode_topology: cluster_ids for unknown clusterings {unknown}")
    for prop, pairs in edges.items():
        pairs = np.asarray(pairs)
        if pairs.size == 0:
            pairs = pairs.reshape(0, 2)
        if pairs.ndim != 2 or pairs.shape[1] != 2:
            raise ValueError(f"encode_topology: edges[{prop!r}] must be (E, 2), got {pairs.shape}")
        if pairs.size and (pairs.min() < 0 or pairs.max() >= count):
            raise ValueError(
                f"encode_topology: edges[{prop!r}] has node indices outside 0..{count - 1}"
            )
        message.edges.add(property=prop, pairs=pack_array(pairs, np.uint32))
    for name, labels in clusterings.items():
        labels = _node_array(labels, f"clusterings[{name!r}]", count, None).astype(np.int32)
        clustering = message.clusterings.add(
            name=name, labels=pack_array(labels), cluster_count=_count_clusters(labels)
        )
        if name in cluster_ids:
            ids = np.asarray(cluster_ids[name])
            n_labels = int(labels.max()) + 1 if labels.size else 0
            if ids.shape != (n_labels,):
                raise ValueError(f"encode_topology: cluster_ids[{name!r}] must have shape "
                                 f"({n_labels},), one id per label, got {ids.shape}")
            clustering.cluster_ids.CopyFrom(pack_array(ids, np.int64))
    for prop, value in (quantization_error or {}).items():
        message.quantization_error[prop] = float(value)
    return message


def decode_topology(
    message: gngdt_pb2.Topology | bytes, max_nodes: int = MAX_TOPOLOGY_NODES
) -> TopologySnapshot:
    """Decode and validate a ``gngdt.Topology`` (consistent N, edge indices < N, label lengths).

    At most ``max_nodes`` nodes, ``MAX_EDGES_PER_NODE`` edges per node in each of at most
    ``MAX_EDGE_SETS`` edge sets, and ``MAX_CLUSTERINGS`` clusterings, names of at most
    ``MAX_NAME_LENGTH`` characters, are accepted: what a learner really sends.
    """
    message = parse_message(gngdt_pb2.Topology, message)
    if not message.HasField("positions"):
        raise MessageError("topology has no positions")
    if len(message.edges) > MAX_EDGE_SETS or len(message.clusterings) > MAX_CLUSTERINGS:
        raise MessageError(f"topology has {len(message.edges)} edge sets and "
                           f"{len(message.clusterings)} clusterings; at most {MAX_EDGE_SETS} and "
                           f"{MAX_CLUSTERINGS} are accepted")
    names = [edge_set.property for edge_set in message.edges]
    names += [clustering.name for clustering in message.clusterings]
    if any(len(name) > MAX_NAME_LENGTH for name in names):
        raise MessageError(f"topology has a name longer than {MAX_NAME_LENGTH} characters")
    positions = unpack_array(
        message.positions, dtype=np.float32, ndim=2, max_elements=3 * max_nodes, name="positions"
    )
    count = positions.shape[0]
    if positions.shape[1] != 3:
        raise MessageError(f"positions: shape {positions.shape}, expected (N, 3)")

    def node_array(name: str, dtype: type, width: int | None) -> np.ndarray | None:
        if not message.HasField(name):
            return None
        expected = (count,) if width is None else (count, width)
        array = unpack_array(
            getattr(message, name),
            dtype=dtype,
            ndim=len(expected),
            max_elements=math.prod(expected),
            name=name,
        )
        if array.shape != expected:
            raise MessageError(f"{name}: shape {array.shape}, expected {expected} like positions")
        return array

    edges: dict[str, np.ndarray] = {}
    for edge_set in message.edges:
        label = f"edges[{edge_set.property!r}]"
        if edge_set.property in edges:
            raise MessageError(f"{label} appears twice")
        pairs = unpack_array(edge_set.pairs, dtype=np.uint32, ndim=2,
                             max_elements=2 * MAX_EDGES_PER_NODE * count, name=label)
        if pairs.shape[1] != 2:
            raise MessageError(f"{label}: shape {pairs.shape}, expected (E, 2)")
        if pairs.size and int(pairs.max()) >= count:
            raise MessageError(f"{label}: node index {int(pairs.max())} >= node count {count}")
        edges[edge_set.property] = pairs
    clusterings: dict[str, np.ndarray] = {}
    cluster_counts: dict[str, int] = {}
    cluster_ids: dict[str, np.ndarray] = {}
    for clustering in message.clusterings:
        label = f"clusterings[{clustering.name!r}]"
        if clustering.name in clusterings:
            raise MessageError(f"{label} appears twice")
        labels = unpack_array(
            clustering.labels, dtype=np.int32, ndim=1, max_elements=count, name=label
        )
        if labels.shape != (count,):
            raise MessageError(f"{label}: {labels.shape[0]} labels for {count} nodes")
        if labels.size and int(labels.min()) < -1:
            raise MessageError(f"{label}: label {int(labels.min())} < -1")
        clusterings[clustering.name] = labels
        cluster_counts[clustering.name] = int(clustering.cluster_count)
        if clustering.HasField("cluster_ids"):
            n_labels = int(labels.max()) + 1 if labels.size else 0
            ids = unpack_array(clustering.cluster_ids, dtype=np.int64, ndim=1,
                               max_elements=n_labels, name=f"{label}.cluster_ids")
            if ids.shape != (n_labels,):
                raise MessageError(f"{label}.cluster_ids: {ids.shape[0]} ids for {n_labels} "
                                   "labels")
            cluster_ids[clustering.name] = ids
    return TopologySnapshot(
        positions=positions,
        colors=node_array("colors", np.uint8, 3),
        normals=node_array("normals", np.float32, 3),
        errors=node_array("errors", np.float32, None),
        edges=edges,
        clusterings=clusterings,
        steps=int(message.steps),
        frame_sequence=int(message.frame_sequence),
        timestamp_ns=timestamp_to_ns(message.timestamp),
        frame_id=message.frame_id,
        quantization_error=dict(message.quantization_error),
        cluster_counts=cluster_counts,
        node_ids=node_array("node_ids", np.int64, None),
        cluster_ids=cluster_ids,
    )


# ------------------------------------------------------------------------ status and stream end
@dataclass
class LearnerStatusInfo:
    """One ``gngdt.LearnerStatus``: the message's field names, ``timestamp_ns`` for its stamp."""

    timestamp_ns: int = 0
    frame_sequence: int = 0
    frame_id: str = ""
    steps: int = 0
    steps_per_second: float = 0.0
    nodes: int = 0
    frames_received: int = 0
    frames_used: int = 0
    frames_dropped: int = 0
    malformed_messages: int = 0
    latency_ms: float = 0.0
    latency_p50_ms: float = 0.0
    latency_p99_ms: float = 0.0
    quantization_error: dict[str, float] = field(default_factory=dict)
    cluster_counts: dict[str, int] = field(default_factory=dict)
    #: after the stream ended: how learning on its last frame stopped ("" while streaming)
    settled: str = ""
    seen_nodes: int = 0
    ghost_share: float = 0.0
    ghost_distance_m: float = 0.0
    nodes_forgotten: int = 0
    frames_other_frame: int = 0


@dataclass
class StreamEndInfo:
    """One ``gngdt.StreamEnd``: a capture finished sending a recording."""

    timestamp_ns: int = 0
    frames_sent: int = 0
    last_frame_sequence: int = 0
    recording: str = ""
    frame_id: str = ""


_InfoT = TypeVar("_InfoT", LearnerStatusInfo, StreamEndInfo)


def _info_to_message(
    info_type: type, message_type: type[_MessageT], values: dict[str, Any]
) -> _MessageT:
    known = {item.name for item in fields(info_type)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(
            f"{message_type.DESCRIPTOR.full_name} has no field(s) {', '.join(unknown)}"
        )
    values = dict(values)
    timestamp_ns = values.pop("timestamp_ns", 0)
    maps = {
        name: values.pop(name)
        for name in ("quantization_error", "cluster_counts")
        if name in values
    }
    try:
        message = message_type(**values)
        for name, mapping in maps.items():
            getattr(message, name).update(mapping)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{message_type.DESCRIPTOR.full_name}: {error}") from error
    ns_to_timestamp(timestamp_ns, message.timestamp)
    return message


def _message_to_info(info_type: type[_InfoT], message: Message) -> _InfoT:
    values: dict[str, Any] = {}
    for item in fields(info_type):
        if item.name == "timestamp_ns":
            values[item.name] = timestamp_to_ns(message.timestamp)
        elif item.name in ("quantization_error", "cluster_counts"):
            values[item.name] = dict(getattr(message, item.name))
        else:
            values[item.name] = getattr(message, item.name)
    return info_type(**values)


def encode_status(**fields_: Any) -> gngdt_pb2.LearnerStatus:
    """``gngdt.LearnerStatus`` from keyword fields named as in :class:`LearnerStatusInfo`."""
    return _info_to_message(LearnerStatusInfo, gngdt_pb2.LearnerStatus, fields_)


def decode_status(message: gngdt_pb2.LearnerStatus | bytes) -> LearnerStatusInfo:
    """Decode a ``gngdt.LearnerStatus``."""
    return _message_to_info(LearnerStatusInfo, parse_message(gngdt_pb2.LearnerStatus, message))


def encode_stream_end(**fields_: Any) -> gngdt_pb2.StreamEnd:
    """``gngdt.StreamEnd`` from keyword fields named as in :class:`StreamEndInfo`."""
    return _info_to_message(StreamEndInfo, gngdt_pb2.StreamEnd, fields_)


def decode_stream_end(message: gngdt_pb2.StreamEnd | bytes) -> StreamEndInfo:
    """Decode a ``gngdt.StreamEnd``."""
    return _message_to_info(StreamEndInfo, parse_message(gngdt_pb2.StreamEnd, message))
