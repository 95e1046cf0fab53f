"""Write RGB-D frames to an MCAP recording in gngdt's foxglove-protobuf layout (docs/contracts.md).

Per frame, in this order and all with ``log_time`` = the frame's capture time:
``/tf`` (foxglove.FrameTransform from the fixed frame to the images' ``frame_id``, frames with a
pose only), ``/camera/calibration`` (foxglove.CameraCalibration, every frame), ``/camera/labels``
(foxglove.RawImage mono16, synthetic scenes only), ``/camera/depth`` (foxglove.RawImage 16UC1
millimetres) and ``/camera/color`` (foxglove.RawImage rgb8, or foxglove.CompressedImage jpeg/png).
MCAP chunks are written as they fill, so a crash leaves a readable prefix of whole chunks.
Metadata records (``add_metadata``) carry what is known about the whole recording, e.g. a
synthetic scene's segment names and motions (``gngdt.scene``).
"""

from __future__ import annotations

import logging
from pathlib import Path
from types import TracebackType
from typing import IO

import numpy as np

from gngdt.io.frame import Frame

logger = logging.getLogger(__name__)

COLOR_FORMATS = ("raw", "jpeg", "png")
COMPRESSIONS = ("zstd", "lz4", "none")
DEFAULT_CAMERA_PREFIX = "/camera"
TF_TOPIC = "/tf"
JPEG_QUALITY = 95


def encode_color(color: np.ndarray, color_format: str) -> bytes:
    """jpeg/png bytes of an (H, W, 3) uint8 RGB image (OpenCV, which expects BGR)."""
    import cv2

    extension = {"jpeg": ".jpg", "png": ".png"}[color_format]
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY] if color_format == "jpeg" else []
    ok, encoded = cv2.imencode(extension, np.ascontiguousarray(color[..., ::-1]), params)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {color.shape} image as {color_format}")
    return encoded.tobytes()


class RecordingWriter:
    """Context manager writing :class:`Frame` objects to an MCAP file.

    ``compression``: ``"zstd"`` (default), ``"lz4"`` or ``"none"``. ``color_format``: ``"raw"``
    (RawImage rgb8, default), ``"jpeg"`` or ``"png"`` (CompressedImage). ``camera_prefix`` is the
    topic prefix and ``frame_id`` the foxglove frame id of every message; ``chunk_size`` (bytes)
    is the MCAP chunk size, the unit a crash can lose.
    """

    def __init__(
        self,
        path: str | Path,
        compression: str = "zstd",
        color_format: str = "raw",
        *,
        camera_prefix: str = DEFAULT_CAMERA_PREFIX,
        frame_id: str = "camera",
        chunk_size: int = 1024 * 1024,
    ) -> None:
        from mcap.writer import CompressionType
        from mcap_protobuf.writer import Writer

        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
        if color_format not in COLOR_FORMATS:
            raise ValueError(f"color_format must be one of {COLOR_FORMATS}, got {color_format!r}")
        self.path = Path(path)
        self.color_format = color_format
        self.frame_id = frame_id
        self.frames_written = 0
        self._topics = {
            name: f"{camera_prefix.rstrip('/')}/{name}"
            for name in ("color", "depth", "calibration", "labels")
        }
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = open(self.path, "wb")
        self._writer = Writer(
            self._file, compression=CompressionType[compression.upper()], chunk_size=chunk_size
        )

    def write_frame(self, frame: Frame) -> None:
        """Append one frame; raises ValueError naming the frame if its arrays are inconsistent."""
        from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration

        self._check_frame(frame)
        stamp = int(frame.timestamp_ns)
        if frame.pose is not None:
            self.write_transform(
                frame.pose.matrix, frame.pose.frame_id, self.frame_id, stamp, frame.index
            )
        messages = [
            (
                "calibration",
                intrinsics_to_calibration(
                    frame.intrinsics, timestamp_ns=stamp, frame_id=self.frame_id
                ),
            )
        ]
        if frame.labels is not None:
            labels = image_to_raw(
                frame.labels, timestamp_ns=stamp, frame_id=self.frame_id, encoding="mono16"
            )
            messages.append(("labels", labels))
        depth = image_to_raw(frame.depth, timestamp_ns=stamp, frame_id=self.frame_id)
        messages += [("depth", depth), ("color", self._color_message(frame.color, stamp))]
        for name, message in messages:
            self._writer.write_message(
                self._topics[name],
                message,
                log_time=stamp,
                publish_time=stamp,
                sequence=frame.index,
            )
        self.frames_written += 1

    def write_transform(
        self,
        matrix: np.ndarray,
        parent_frame_id: str,
        child_frame_id: str,
        timestamp_ns: int,
        sequence: int = 0,
        topic: str = TF_TOPIC,
    ) -> None:
        """Append a ``foxglove.FrameTransform`` ``parent -> child``: ``matrix`` (4, 4) maps
        points of the child frame into the parent frame."""
        from gngdt.schemas.clouds import pose_to_transform

        transform = pose_to_transform(
            matrix, parent_frame_id, child_frame_id, timestamp_ns=timestamp_ns
        )
        self._writer.write_message(
            topic, transform, log_time=timestamp_ns, publish_time=timestamp_ns, sequence=sequence
        )

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Store a named set of strings about the whole recording (an MCAP metadata record)."""
        self._writer.add_metadata(name, data)

    def _color_message(self, color: np.ndarray, timestamp_ns: int):
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        from gngdt.schemas.images import image_to_raw
        from gngdt.schemas.messages import ns_to_timestamp

        if self.color_format == "raw":
            return image_to_raw(color, timestamp_ns=timestamp_ns, frame_id=self.frame_id)
        return CompressedImage(
            timestamp=ns_to_timestamp(timestamp_ns),
            frame_id=self.frame_id,
            format=self.color_format,
            data=encode_color(color, self.color_format),
        )

    def _check_frame(self, frame: Frame) -> None:
        def fail(reason: str) -> ValueError:
            return ValueError(f"{self.path}: frame {frame.index}: {reason}")

        color, depth = np.asarray(frame.color), np.asarray(frame.depth)
        if color.dtype != np.uint8 or color.ndim != 3 or color.shape[2] != 3:
            raise fail(f"color must be (H, W, 3) uint8, got {color.dtype} {color.shape}")
        if depth.dtype != np.uint16 or depth.shape != color.shape[:2]:
            raise fail(
                f"depth must be {color.shape[:2]} uint16 like color, got "
                f"{depth.dtype} {depth.shape}"
            )
        if frame.labels is not None and (
            frame.labels.dtype != np.uint16 or frame.labels.shape != color.shape[:2]
        ):
            raise fail(
                f"labels must be {color.shape[:2]} uint16, got "
                f"{frame.labels.dtype} {frame.labels.shape}"
            )
        if frame.pose is not None:
            matrix = np.asarray(frame.pose.matrix)
            if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
                raise fail(f"pose must be a finite (4, 4) matrix, got {matrix.shape}")
        size = (frame.intrinsics.width, frame.intrinsics.height)
        if size != (color.shape[1], color.shape[0]):
            raise fail(
                f"intrinsics are for {size[0]}x{size[1]}, color is "
                f"{color.shape[1]}x{color.shape[0]}"
            )

    def close(self) -> None:
        """Write the MCAP summary and footer and close the file (idempotent)."""
        if self._file.closed:
            return
        try:
            self._writer.finish()
        finally:
            self._file.close()
        logger.debug("wrote %d frames to %s", self.frames_written, self.path)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
