"""Record gngdt's zenoh streams into one MCAP file that Foxglove opens as it is.

Every sample is written as it arrived (its protobuf bytes, never re-encoded) on the channel
``/<cam>/<stream>`` (``/camera/color``, ``/camera/points``, ``/camera/scene``, ...), with the
protobuf schema its zenoh encoding names (``application/protobuf;foxglove.SceneUpdate``): foxglove
schemas for images, calibration, clouds, scene and objects, gngdt's own for topology, status and
end of stream; the camera poses (``gngdt/<cam>/tf``) go to ``/tf``, as in a recording.
``log_time`` is the frame's capture time (from the sample's attachment),
``publish_time`` the time it arrived. Camera streams keep DESIGN's recording layout, so the file
also replays with ``gngdt capture``.

Zenoh's callback only queues the bytes; a writer thread compresses (lz4) and writes them, so a
slow disk never blocks a subscriber. The queue is bounded in bytes: beyond it, samples are dropped
and counted, never buffered without limit.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt_io.mcap_writer import TF_TOPIC
from gngdt_io.outputs.base import Output
from schemas.wire import FrameStamp

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: most bytes waiting for the writer thread (~100 full 640x480 frames)
DEFAULT_MAX_QUEUED_BYTES = 256 * 1024 * 1024
PROTOBUF_PREFIX = "application/protobuf;"


def message_classes() -> dict[str, Any]:
    """protobuf full name -> message class of every type gngdt publishes."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from schemas import gngdt_pb2

    classes = (CameraCalibration, CompressedImage, FrameTransform, PointCloud, RawImage,
               SceneUpdate,
               gngdt_pb2.Topology, gngdt_pb2.LearnerStatus, gngdt_pb2.StreamEnd)
    return {cls.DESCRIPTOR.full_name: cls for cls in classes}


def channel_topic(key: str) -> str | None:
    """MCAP topic of a zenoh key: ``gngdt/<cam>/<stream>`` -> ``/<cam>/<stream>``, and every
    camera's pose ``gngdt/<cam>/tf`` -> ``/tf`` (DESIGN's recording layout: the transforms say
    which camera by their child frame)."""
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != "gngdt":
        return None
    if parts[2:] == ["tf"]:
        return TF_TOPIC
    return "/" + "/".join(parts[1:])


@dataclass
class _Sample:
    key: str
    encoding: str
    payload: bytes
    attachment: bytes | None
    received_ns: int


class McapRecorder:
    """Writes queued samples to ``path`` from its own thread; `close` finishes the file."""

    def __init__(self, path: str | Path, max_queued_bytes: int = DEFAULT_MAX_QUEUED_BYTES,
                 chunk_size: int = 4 * 1024 * 1024) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "xb")  # never overwrites: the caller picks a free name
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.LZ4)
        self._writer.start(profile="", library="gngdt")
        self._classes = message_classes()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._schema_of_channel: dict[int, str] = {}
        self._sequences: dict[str, int] = {}
        self._queue: deque[_Sample] = deque()
        self._queued_bytes = 0
        self.max_queued_bytes = max_queued_bytes
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = False
        self.written = 0
        self.dropped = 0
        self.skipped = 0
        self.error: OSError | None = None
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()

    def put(self, sample: zenoh.Sample) -> None:
        """zenoh callback: queue the sample (dropped and counted when the queue is full)."""
        payload = sample.payload.to_bytes()
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        self.put_bytes(str(sample.key_expr), str(sample.encoding), payload, attachment)

    def put_bytes(self, key: str, encoding: str, payload: bytes,
                  attachment: bytes | None) -> None:
        """Queue one message (what `put` does with a zenoh sample)."""
        item = _Sample(key, encoding, payload, attachment, time.time_ns())
        with self._lock:
            if self._closing or self._queued_bytes + len(payload) > self.max_queued_bytes:
                self.dropped += 1
                return
            self._queue.append(item)
            self._queued_bytes += len(payload)
        self._wake.set()

    def _run(self) -> None:
        while True:
            self._wake.wait(0.1)
            with self._lock:
                items = list(self._queue)
                self._queue.clear()
                self._queued_bytes = 0
                self._wake.clear()
                closing = self._closing
            for item in items:
                if self.error is not None:
                    self.dropped += 1
                    continue
                try:
                    self._write(item)
                except OSError as error:  # disk full, ...: keep the rest of the logger running
                    self.error = error
                    self.dropped += 1
                    log.error("MCAP %s: writing stopped: %s", self.path, error)
            if closing and not items:
                return

    def _write(self, item: _Sample) -> None:
        topic = channel_topic(item.key)
        type_name = item.encoding.removeprefix(PROTOBUF_PREFIX).split(";")[0]
        message_class = self._classes.get(type_name) if item.encoding.startswith(
            PROTOBUF_PREFIX) else None
        if topic is None or message_class is None:
            self.skipped += 1
            log.debug("not recorded: %s (%s)", item.key, item.encoding)
            return
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._register(topic, message_class)
        elif self._schema_of_channel[channel] != type_name:
            self.skipped += 1  # a foreign publisher changed the type mid-stream
            return
        try:
            log_time = FrameStamp.from_attachment(item.attachment).capture_time_ns
        except ValueError:
            log_time = item.received_ns
        sequence = self._sequences.get(topic, 0)
        self._sequences[topic] = sequence + 1
        self._writer.add_message(channel_id=channel, log_time=log_time, data=item.payload,
                                 publish_time=item.received_ns, sequence=sequence)
        self.written += 1

    def _register(self, topic: str, message_class: Any) -> int:
        from mcap_protobuf.schema import register_schema

        name = message_class.DESCRIPTOR.full_name
        if name not in self._schemas:
            self._schemas[name] = register_schema(self._writer, message_class)
        channel = self._writer.register_channel(topic=topic, message_encoding="protobuf",
                                                schema_id=self._schemas[name])
        self._channels[topic] = channel
        self._schema_of_channel[channel] = name
        return channel

    def close(self) -> None:
        """Write what is queued, then the MCAP index and footer."""
        with self._lock:
            self._closing = True
        self._wake.set()
        self._thread.join()
        try:
            self._writer.finish()
        except OSError as error:
            self.error = self.error or error
            log.error("MCAP %s: could not write its index: %s", self.path, error)
        self._file.close()
        log.info("recorded %d messages to %s (%d dropped, %d not gngdt protobuf)", self.written,
                 self.path, self.dropped, self.skipped)


class McapOutput(Output):
    """``--mcap PATH``: every sample of ``gngdt/**`` as it arrived, into an MCAP file."""

    raw = True

    def __init__(self, path: Path) -> None:
        self.recorder = McapRecorder(path)

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--mcap", type=Path, metavar="PATH",
                            help="also record every gngdt stream as it is (images, clouds, "
                            "topology, scene, objects, status) into this MCAP file, which "
                            "Foxglove opens directly (rerun shows only its images and clouds); "
                            "<name>.1.mcap if it exists")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> McapOutput | None:
        from gngdt_io.outputs.rerun_output import unused_rrd_path

        return cls(unused_rrd_path(args.mcap)) if args.mcap else None

    def describe(self) -> str:
        return f"recording to {self.recorder.path}"

    def receive(self, sample: zenoh.Sample) -> None:
        self.recorder.put(sample)

    def close(self) -> None:
        self.recorder.close()  # writes the MCAP index and footer
