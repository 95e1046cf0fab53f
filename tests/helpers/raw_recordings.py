"""MCAP recordings written message by message, payload bytes as given, so that they can be
wrong: 40x30 frames of random colour and depth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.writer import Writer as McapWriter
from mcap_protobuf.writer import register_schema

from gngdt.io.frame import CameraIntrinsics
from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration
from helpers.recordings import PERIOD_NS, START_NS

#: the frames' size (pixels) and calibration
WIDTH, HEIGHT = 40, 30
INTRINSICS = CameraIntrinsics(WIDTH, HEIGHT, 40.0, 40.0, 19.5, 14.5)


class RawRecording:
    """An MCAP written message by message, payload bytes as given (so they can be wrong)."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")
        self._writer = McapWriter(self._file, chunk_size=16 * 1024)  # several chunks
        self._writer.start(profile="", library="gngdt-tests")
        self._channels: dict[str, int] = {}

    def _channel(self, topic: str, message_type: type) -> int:
        if topic not in self._channels:
            schema_id = register_schema(self._writer, message_type)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="protobuf", schema_id=schema_id)
        return self._channels[topic]

    def write(self, topic: str, message_type: type, data: bytes, stamp_ns: int) -> None:
        self._writer.add_message(channel_id=self._channel(topic, message_type), log_time=stamp_ns,
                                 publish_time=stamp_ns, data=data)

    def write_frame(self, index: int, *, color: np.ndarray | None = None,
                    depth: np.ndarray | None = None, calibration: bool = True,
                    color_bytes: bytes | None = None) -> int:
        """Calibration, colour and depth of frame ``index`` (defaults: a valid frame)."""
        stamp = START_NS + index * PERIOD_NS
        rng = np.random.default_rng(index)
        if color is None:
            color = rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
        if depth is None:
            depth = rng.integers(500, 3000, (HEIGHT, WIDTH), dtype=np.uint16)
        if calibration:
            self.write("/camera/calibration", CameraCalibration, intrinsics_to_calibration(
                INTRINSICS, timestamp_ns=stamp).SerializeToString(), stamp)
        if color_bytes is None:
            color_bytes = image_to_raw(color, timestamp_ns=stamp).SerializeToString()
        self.write("/camera/color", RawImage, color_bytes, stamp)
        self.write("/camera/depth", RawImage,
                   image_to_raw(depth, timestamp_ns=stamp).SerializeToString(), stamp)
        return stamp

    def close(self) -> None:
        self._writer.finish()
        self._file.close()
