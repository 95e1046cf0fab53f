"""MCAP messages of the camera -- foxglove protobuf and ROS 2 CDR images and calibrations --
into roles (colour, depth, labels, calibration), numpy images and :class:`CameraIntrinsics`."""

from __future__ import annotations

from typing import Any

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.mcap.limits import ReadLimits

__all__ = [
    "FOXGLOVE_SCHEMAS",
    "ROS_SCHEMAS",
    "DecodeFailure",
    "MessageDecoder",
    "decode_compressed",
    "normalize_color",
    "normalize_depth",
]

_COLOR_ENCODINGS = frozenset({"rgb8", "bgr8", "8UC3", "rgba8", "bgra8", "mono8", "8UC1"})
_DEPTH_ENCODINGS = frozenset({"16UC1", "mono16", "32FC1"})
#: schemas of the camera messages decoded: foxglove protobuf, ROS 2 CDR
FOXGLOVE_SCHEMAS = frozenset(
    {"foxglove.RawImage", "foxglove.CompressedImage", "foxglove.CameraCalibration"}
)
ROS_SCHEMAS = frozenset(
    {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo"}
)


class DecodeFailure(Exception):
    """One message could not be decoded (wraps MessageError, OpenCV and CDR errors)."""


def normalize_depth(depth: np.ndarray, units_per_metre: float | None = None) -> np.ndarray:
    """(H, W) depth as uint16 millimetres: float input is metres (NaN, inf, <= 0 -> 0); 16-bit
    input is millimetres, or ``units_per_metre`` (e.g. 10000 for 0.1 mm) when given."""
    if depth.dtype == np.uint16 and units_per_metre not in (None, 1000.0):
        millimetres = depth.astype(np.float64) * (1000.0 / units_per_metre)
        return np.clip(np.rint(millimetres), 0, np.iinfo(np.uint16).max).astype(np.uint16)
    if depth.dtype == np.uint16:
        return depth
    if depth.dtype.kind == "f":
        millimetres = np.where(np.isfinite(depth) & (depth > 0), depth * 1000.0, 0.0)
        return np.clip(np.rint(millimetres), 0, np.iinfo(np.uint16).max).astype(np.uint16)
    raise DecodeFailure(f"depth of dtype {depth.dtype} is not supported")


def normalize_color(color: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB from RGB or grey (H, W) uint8."""
    if color.ndim == 2:
        return np.repeat(color[:, :, None], 3, axis=2)
    return color


def decode_compressed(data: bytes, image_format: str,
                      max_pixels: int = ReadLimits.max_frame_pixels) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a jpeg/png image of at most ``max_pixels`` (OpenCV's own ceiling,
    ``OPENCV_IO_MAX_IMAGE_PIXELS``, which `gngdt` sets, bounds what decoding allocates)."""
    import cv2

    if "depth" in image_format.lower():
        raise DecodeFailure(f"compressed depth ({image_format!r}) is not supported")
    buffer = np.frombuffer(data, dtype=np.uint8)
    try:
        image = cv2.imdecode(buffer, cv2.IMREAD_COLOR) if buffer.size else None
    except cv2.error as error:  # e.g. larger than OpenCV's ceiling
        raise DecodeFailure(f"OpenCV cannot decode the {image_format or 'compressed'} image: "
                             f"{str(error).strip().splitlines()[-1]}") from error
    if image is None:
        raise DecodeFailure(f"OpenCV cannot decode the {image_format or 'compressed'} image")
    if image.shape[0] * image.shape[1] > max_pixels:
        raise DecodeFailure(f"image {image.shape[1]}x{image.shape[0]} exceeds the limit of "
                             f"{max_pixels} pixels (--max-frame-pixels)")
    return image[..., ::-1].copy()


class MessageDecoder:
    """Turns MCAP messages into roles and numpy images, for foxglove protobuf and ROS 2 CDR."""

    def __init__(self) -> None:
        from mcap_ros2.decoder import DecoderFactory

        self._ros_factory = DecoderFactory()
        self._ros_decoders: dict[int, Any] = {}

    def role(self, schema_name: str, topic: str, payload: Any) -> str | None:
        """``"color"``, ``"depth"``, ``"labels"``, ``"calibration"`` or None (ignored)."""
        if schema_name in ("foxglove.CameraCalibration", "sensor_msgs/msg/CameraInfo"):
            return "calibration"
        if schema_name in ("foxglove.CompressedImage", "sensor_msgs/msg/CompressedImage"):
            return None if "depth" in payload.format.lower() else "color"
        if topic.rstrip("/").endswith("/labels"):
            return "labels"
        if payload.encoding in _COLOR_ENCODINGS:
            return "color"
        if payload.encoding in _DEPTH_ENCODINGS:
            return "depth"
        return None

    def parse(self, schema: Any, message: Any) -> Any:
        """The decoded message object (protobuf message or ROS 2 dynamic message)."""
        from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        from gngdt.schemas.messages import MessageError, parse_message

        foxglove_types = {
            "foxglove.RawImage": RawImage,
            "foxglove.CompressedImage": CompressedImage,
            "foxglove.CameraCalibration": CameraCalibration,
        }
        try:
            if schema.name in foxglove_types:
                return parse_message(foxglove_types[schema.name], message.data)
            decoder = self._ros_decoders.get(schema.id)
            if decoder is None:
                decoder = self._ros_factory.decoder_for("cdr", schema)
                if decoder is None:
                    raise DecodeFailure(f"no CDR decoder for schema {schema.name}")
                self._ros_decoders[schema.id] = decoder
            return decoder(message.data)
        except MessageError as error:
            raise DecodeFailure(str(error)) from error
        except DecodeFailure:
            raise
        except Exception as error:  # CDR parsing raises assorted errors on corrupt bytes
            raise DecodeFailure(f"cannot decode {schema.name}: {error}") from error

    @staticmethod
    def frame_id(schema_name: str, payload: Any) -> str:
        """The image's coordinate frame name (foxglove ``frame_id``, ROS ``header.frame_id``)."""
        if schema_name in FOXGLOVE_SCHEMAS:
            return str(payload.frame_id)
        return str(payload.header.frame_id)

    @staticmethod
    def stamp_ns(schema_name: str, payload: Any, log_time_ns: int) -> int:
        """The message's own stamp in ns, or ``log_time_ns`` when it carries none."""
        if schema_name in FOXGLOVE_SCHEMAS:
            stamp = payload.timestamp.seconds * 1_000_000_000 + payload.timestamp.nanos
        else:
            stamp = payload.header.stamp.sec * 1_000_000_000 + payload.header.stamp.nanosec
        return stamp if stamp else log_time_ns

    @staticmethod
    def pixels(schema_name: str, payload: Any,
               max_pixels: int = ReadLimits.max_frame_pixels) -> np.ndarray:
        """Pixels of an image message (see ``gngdt.schemas.images.decode_pixels`` for shapes), of at
        most ``max_pixels``, checked before decoding."""
        from gngdt.schemas.images import decode_pixels
        from gngdt.schemas.messages import MessageError

        if schema_name.endswith("CompressedImage"):
            return decode_compressed(bytes(payload.data), payload.format, max_pixels)
        if payload.width * payload.height > max_pixels:
            raise DecodeFailure(f"image {payload.width}x{payload.height} exceeds the limit of "
                                 f"{max_pixels} pixels (--max-frame-pixels)")
        try:
            return decode_pixels(
                bytes(payload.data),
                width=payload.width,
                height=payload.height,
                step=payload.step,
                encoding=payload.encoding,
                big_endian=bool(getattr(payload, "is_bigendian", False)),
            )
        except MessageError as error:
            raise DecodeFailure(str(error)) from error

    @staticmethod
    def intrinsics(schema_name: str, payload: Any) -> CameraIntrinsics:
        from gngdt.schemas.images import calibration_to_intrinsics, intrinsics_from_k
        from gngdt.schemas.messages import MessageError

        try:
            if schema_name == "foxglove.CameraCalibration":
                return calibration_to_intrinsics(payload)
            distortion = tuple(float(value) for value in payload.d)
            return intrinsics_from_k(
                payload.width,
                payload.height,
                list(payload.k),
                distortion if any(distortion) else (),
            )
        except MessageError as error:
            raise DecodeFailure(str(error)) from error
