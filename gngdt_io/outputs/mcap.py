"""Record gngdt's zenoh streams into one MCAP file that Foxglove opens as it is.

Every sample is written as it arrived (its protobuf bytes, never re-encoded) on the channel
``/<cam>/<stream>`` (``/camera/color``, ``/camera/points``, ``/camera/scene``, ...), with the
protobuf schema its zenoh encoding names (``application/protobuf;foxglove.SceneUpdate``): foxglove
schemas for images, calibration, clouds, scene and objects, gngdt's own for topology, status and
end of stream; the camera poses (``gngdt/<cam>/tf``) go to ``/tf``, as in a recording.
``log_time`` is the frame's capture time (from the sample's attachment),
``publish_time`` the time it arrived. Camera streams keep the contract's recording layout, so
the file also replays with ``gngdt capture``.

Zenoh's callback only queues the bytes; a writer thread compresses (lz4) and writes them, so a
slow disk never blocks a subscriber. Bounded as the logger's ``.rrd`` is: the queue holds at
most ``max_queued_bytes`` (a sample that does not fit is dropped and counted before it is
copied); only gngdt's streams (`RECORDED_STREAMS`) of at most ``max_cameras`` cameras make
channels; writing stops, said once, when the file reaches ``max_bytes``, when its disk has less
than ``min_free_bytes`` free, or when a write fails (a full disk). The file is readable however
it stops: finished with its summary when it can be, else cut back to its last complete record
and closed with a footer (readers then scan it, as ``mcap`` does for a file without summary).
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.io.mcap.writer import TF_TOPIC
from gngdt.io.outputs.base import Output
from gngdt.schemas.wire import CAPTURE_STREAMS, LEARNER_STREAMS, FrameStamp

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: most bytes waiting for the writer thread (~100 full 640x480 frames)
DEFAULT_MAX_QUEUED_BYTES = 256 * 1024 * 1024
#: messages are compressed and written a chunk at a time: what a failed write can lose at most
DEFAULT_CHUNK_BYTES = 1024 * 1024
DEFAULT_MAX_CAMERAS = 16
#: how often the free space of the file's disk is checked, seconds
FREE_SPACE_EVERY_S = 1.0
#: the streams recorded (any other key under ``gngdt/`` makes no channel)
RECORDED_STREAMS = tuple(dict.fromkeys(CAPTURE_STREAMS + LEARNER_STREAMS))
PROTOBUF_PREFIX = "application/protobuf;"


def message_classes() -> dict[str, Any]:
    """protobuf full name -> message class of every type gngdt publishes."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from gngdt.schemas import gngdt_pb2

    classes = (CameraCalibration, CompressedImage, FrameTransform, PointCloud, RawImage,
               SceneUpdate,
               gngdt_pb2.Topology, gngdt_pb2.LearnerStatus, gngdt_pb2.StreamEnd)
    return {cls.DESCRIPTOR.full_name: cls for cls in classes}


def channel_topic(key: str) -> str | None:
    """MCAP topic of a zenoh key: ``gngdt/<cam>/<stream>`` -> ``/<cam>/<stream>``, and every
    camera's pose ``gngdt/<cam>/tf`` -> ``/tf`` (the contract's recording layout: the transforms say
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


class _UnbufferedFile:
    """What mcap's writer writes through: every write reaches the file at once or raises, and
    ``good`` is the offset after the last writer call that completed (a record boundary)."""

    def __init__(self, path: Path, overwrite: bool) -> None:
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
        self.fd = os.open(path, flags, 0o644)
        self.offset = 0
        self.good = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            written = os.write(self.fd, view)
            self.offset += written
            view = view[written:]
        return len(data)

    def tell(self) -> int:
        return self.offset

    def flush(self) -> None:
        return None

    def committed(self) -> None:
        """The last writer call completed: everything so far is whole records."""
        self.good = self.offset

    def cut_back(self) -> None:
        """Drop what a failed call left after the last complete record."""
        os.ftruncate(self.fd, self.good)
        os.lseek(self.fd, self.good, os.SEEK_SET)
        self.offset = self.good

    def close(self) -> None:
        os.close(self.fd)


class McapRecorder:
    """Writes queued samples to ``path`` from its own thread; `close` finishes the file (see
    the module docstring for the bounds). ``stopped``: why writing stopped early ("": it did
    not); ``written``, ``dropped``, ``skipped`` (not gngdt protobuf, or a stream or camera
    beyond the bounds): messages so far."""

    def __init__(self, path: str | Path, max_queued_bytes: int = DEFAULT_MAX_QUEUED_BYTES,
                 chunk_size: int = DEFAULT_CHUNK_BYTES, *, max_bytes: int = 0,
                 min_free_bytes: int = 0, max_cameras: int = DEFAULT_MAX_CAMERAS,
                 overwrite: bool = False) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.max_bytes = max_bytes
        self.min_free_bytes = min_free_bytes
        self.max_cameras = max_cameras
        # never overwrites unless told: the caller picks a free name (or reserved this one)
        self._file = _UnbufferedFile(self.path, overwrite)
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.LZ4)
        self._writer.start(profile="", library="gngdt")
        self._file.committed()
        self._classes = message_classes()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._schema_of_channel: dict[int, str] = {}
        self._sequences: dict[str, int] = {}
        self._cameras: set[str] = set()
        self._queue: deque[_Sample] = deque()
        self._queued_bytes = 0
        self.max_queued_bytes = max_queued_bytes
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = False
        self._last_free_check = 0.0
        self.written = 0
        self._pending = 0  # added to the chunk in memory, not yet on disk
        self.dropped = 0
        self.skipped = 0
        self.stopped = ""
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()

    def put(self, sample: zenoh.Sample) -> None:
        """zenoh callback: queue the sample (dropped and counted, before it is copied, when it
        does not fit the queue, is not a recorded stream or comes from one camera too many)."""
        key = str(sample.key_expr)
        if not self._admit(key, len(sample.payload)):
            return
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        self.put_bytes(key, str(sample.encoding), sample.payload.to_bytes(), attachment)

    def _admit(self, key: str, size: int) -> bool:
        """Whether a sample of ``key`` and ``size`` bytes may be queued (counted if not)."""
        parts = key.split("/", 2)
        with self._lock:
            if len(parts) < 3 or parts[0] != "gngdt" or parts[2] not in RECORDED_STREAMS:
                self.skipped += 1
                return False
            camera = parts[1]
            if camera not in self._cameras and len(self._cameras) >= self.max_cameras:
                self.skipped += 1
                return False
            if (self._closing or self.stopped
                    or self._queued_bytes + size > self.max_queued_bytes):
                self.dropped += 1
                return False
            self._cameras.add(camera)
            return True

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
                self._wake.clear()
                closing = self._closing
            while True:  # one at a time: queued bytes are freed as they are written
                with self._lock:
                    item = self._queue.popleft() if self._queue else None
                if item is None:
                    break
                self._write_or_drop(item)
                with self._lock:
                    self._queued_bytes -= len(item.payload)
            if closing:
                return

    def _write_or_drop(self, item: _Sample) -> None:
        if self.stopped or not self._within_bounds():
            self.dropped += 1
            return
        try:
            before = self._file.tell()
            self._write(item)
            self._file.committed()
            if self._file.tell() != before:  # a chunk was written: its messages are on disk
                self.written, self._pending = self.written + self._pending, 0
        except OSError as error:  # disk full, quota, ...: keep the rest of the logger running
            self.dropped += 1 + self._pending  # what the chunk in memory held is lost
            self._pending = 0
            self._stop(f"writing it failed ({error.strerror or error}; is the disk full?)",
                       failed=True)

    def _within_bounds(self) -> bool:
        """Check the size cap (every message) and the free space (every second); stop writing
        (the file finished) when one is passed."""
        size = self._file.tell()
        if self.max_bytes and size >= self.max_bytes:
            self._stop(f"it reached {size / 1e6:.0f} MB (--max-mcap-mb "
                       f"{self.max_bytes // 10**6})")
            return False
        if self.min_free_bytes and time.monotonic() - self._last_free_check >= FREE_SPACE_EVERY_S:
            self._last_free_check = time.monotonic()
            free = shutil.disk_usage(self.path.parent).free
            if free < self.min_free_bytes:
                self._stop(f"only {free / 1e6:.0f} MB are free on its disk (--min-free-mb "
                           f"{self.min_free_bytes // 10**6})")
                return False
        return True

    def _stop(self, reason: str, failed: bool = False) -> None:
        self.stopped = reason
        log.error("MCAP %s: stopped writing: %s; still running, nothing more is recorded "
                  "there", self.path, reason)
        self._finish(failed)

    def _finish(self, failed: bool = False) -> None:
        """Finish the file: its summary when writing works, else (or when that fails) cut back
        to the last complete record and end it with a footer; then close it."""
        if not failed:
            try:
                self._writer.finish()
                self._file.close()
                self.written, self._pending = self.written + self._pending, 0
                return
            except OSError as error:
                self.dropped, self._pending = self.dropped + self._pending, 0
                log.error("MCAP %s: could not write its summary (%s); ending it after its last "
                          "complete chunk", self.path, error.strerror or error)
        try:
            self._file.cut_back()
            self._file.write(footer_without_summary())
        except OSError as error:
            log.error("MCAP %s: could not end it (%s); readers recover what precedes",
                      self.path, error.strerror or error)
        self._file.close()

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
        self._pending += 1
        self._writer.add_message(channel_id=channel, log_time=log_time, data=item.payload,
                                 publish_time=item.received_ns, sequence=sequence)

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
        """Write what is queued (within the bounds), then finish the file; never raises."""
        with self._lock:
            self._closing = True
        self._wake.set()
        self._thread.join()
        if not self.stopped:
            self._finish()
        log.info("recorded %d messages to %s (%d dropped, %d not recorded: not gngdt's "
                 "protobuf streams, or cameras beyond %d)%s", self.written, self.path,
                 self.dropped, self.skipped, self.max_cameras,
                 f"; stopped early: {self.stopped}" if self.stopped else "")


def footer_without_summary() -> bytes:
    """The end of an MCAP file whose summary cannot be written: a data-end record, a footer
    pointing at no summary, and the closing magic (readers then scan the records)."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC

    builder = RecordBuilder()
    DataEnd(0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


class McapOutput(Output):
    """``--mcap PATH``: every sample of ``gngdt/**`` as it arrived, into an MCAP file."""

    raw = True

    def __init__(self, recorder: McapRecorder) -> None:
        self.recorder = recorder

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--mcap", type=Path, metavar="PATH",
                            help="also record every gngdt stream as it is (images, clouds, "
                            "topology, scene, objects, status) into this MCAP file, which "
                            "Foxglove opens directly (rerun shows only its images and clouds); "
                            "<name>.1.mcap if it exists")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> McapOutput | None:
        from gngdt.io.outputs.rerun_output import unused_rrd_path

        if not args.mcap:
            return None
        if args.max_mcap_mb < 0:
            raise ValueError(f"--max-mcap-mb must be >= 0, got {args.max_mcap_mb}")
        overwrite = getattr(args, "overwrite", False)
        path = args.mcap if overwrite else unused_rrd_path(args.mcap)
        return cls(McapRecorder(
            path, max_bytes=args.max_mcap_mb * 10**6,
            min_free_bytes=getattr(args, "min_free_mb", 0) * 10**6,
            max_cameras=getattr(args, "max_cameras", DEFAULT_MAX_CAMERAS), overwrite=overwrite))

    def describe(self) -> str:
        return f"recording to {self.recorder.path}"

    def receive(self, sample: zenoh.Sample) -> None:
        self.recorder.put(sample)

    def stopped_early(self) -> str:
        return self.recorder.stopped

    def close(self) -> None:
        self.recorder.close()  # writes the MCAP summary and footer
