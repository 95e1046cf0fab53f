"""Images and camera calibration: numpy pixels <-> foxglove RawImage, CameraIntrinsics <->
foxglove CameraCalibration (and ROS CameraInfo's K).

Decoded images are fresh, writable, C-contiguous arrays; decoders raise
:class:`~gngdt.schemas.messages.MessageError` for anything malformed (see
:mod:`gngdt.schemas.messages`).
"""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.schemas.messages import MessageError, little_endian, ns_to_timestamp, parse_message

__all__ = [
    "MAX_IMAGE_PIXELS",
    "calibration_to_intrinsics",
    "decode_pixels",
    "image_to_raw",
    "intrinsics_from_k",
    "intrinsics_to_calibration",
    "raw_to_image",
]

#: Largest image a decoder accepts (width * height), 64 megapixels.
MAX_IMAGE_PIXELS = 64 * 1024 * 1024

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
    data: bytes | np.ndarray,
    *,
    width: int,
    height: int,
    step: int,
    encoding: str,
    big_endian: bool = False,
) -> np.ndarray:
    """Pixels of a raw image buffer (bytes, or a uint8 array viewing them) as a writable
    C-contiguous array (the one copy made).

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
    wire = np.ascontiguousarray(image, dtype=little_endian(pixel_dtype))
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
    """CameraIntrinsics from a row-major 3x3 K (foxglove CameraCalibration and ROS CameraInfo);
    MessageError unless they can be a camera's (`CameraIntrinsics.problem`: finite, a plausible
    field of view, the principal point near the image)."""
    if len(k) != 9:
        raise MessageError(f"calibration K has {len(k)} values, expected 9")
    if width <= 0 or height <= 0:
        raise MessageError(f"calibration image size {width}x{height} is empty")
    intrinsics = CameraIntrinsics(
        width=int(width),
        height=int(height),
        fx=float(k[0]),
        fy=float(k[4]),
        cx=float(k[2]),
        cy=float(k[5]),
        distortion=tuple(float(value) for value in distortion),
    )
    problem = intrinsics.problem()
    if problem:
        raise MessageError(f"calibration is uncalibrated or invalid: {problem}")
    return intrinsics


def calibration_to_intrinsics(message: CameraCalibration | bytes) -> CameraIntrinsics:
    """Pinhole intrinsics of a foxglove CameraCalibration (from K; D kept as ``distortion``)."""
    message = parse_message(CameraCalibration, message)
    distortion = tuple(message.D)
    if not any(distortion):
        distortion = ()
    return intrinsics_from_k(message.width, message.height, list(message.K), distortion)
