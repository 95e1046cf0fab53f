"""Read RGB-D frames from an MCAP recording: gngdt's foxglove-protobuf layout or a ROS 2 bag.

Channels are recognised by schema, whatever their topic:

- foxglove protobuf: ``foxglove.RawImage`` (colour rgb8/bgr8/mono8, depth 16UC1/mono16/32FC1,
  labels on a topic ending in ``/labels``), ``foxglove.CompressedImage`` (jpeg/png colour),
  ``foxglove.CameraCalibration``;
- ROS 2 (CDR): ``sensor_msgs/msg/Image``, ``sensor_msgs/msg/CompressedImage``,
  ``sensor_msgs/msg/CameraInfo`` -- what ``ros2 bag record`` gives for Kinect and RealSense drivers.

The first channel seen in each role (colour, depth, calibration, labels) is used; other channels,
and channels of any other schema, are ignored. ``camera_prefix`` restricts the topics considered.

Camera poses come from transform channels, whatever their topic: ``foxglove.FrameTransform``
(gngdt's ``/tf``), ``foxglove.FrameTransforms`` and ROS 2 ``tf2_msgs/msg/TFMessage`` (``/tf``;
``/tf_static`` holds static transforms). They are read in a first pass, then each frame's pose is
the transform from the fixed frame to the colour image's ``frame_id`` at the frame's stamp,
through any chain of frames, interpolated (:mod:`gngdt_io.tf_tree`). The fixed frame
is ``fixed_frame``, or with ``"auto"`` the first of ``world``, ``map``, ``odom`` connected to the
camera, else the root of the camera's tree. A recording whose transforms never connect the
fixed frame and the camera gives frames without a pose, with one warning naming the frames; a
frame whose time the transforms do not cover has no pose either (warned), and says why in
``frame.extras["pose_error"]``: the recording has poses, only not for that frame.

Messages are read in file order, one chunk inflated at a time (MCAP writers write in log-time
order; see ``_open_messages`` for why not mcap's merge by log time). Frames: a colour image and a
depth image are paired when their stamps (the message's own
timestamp/header stamp, else the MCAP ``log_time``) differ by at most ``max_skew_ns`` (default
0: the same stamp, as gngdt writes them). The frame takes the colour stamp, the latest
calibration (frames wait for the first one, up to ``MAX_FRAMES_WITHOUT_CALIBRATION`` of them),
and labels carrying the colour stamp if they came before the pair. Depth is normalised to uint16
millimetres (32FC1 metres -> mm, NaN/negative -> 0), colour to RGB uint8.

A damaged file yields every frame before the damage, then raises :class:`RecordingError`.
With ``on_bad_frame``, a bad *frame* (an undecodable image or calibration message, colour/depth/
calibration sizes that disagree) is reported to it and skipped, and reading goes on with the next
good frame; only damage to the file itself (truncation, corrupt chunks) still ends the reading.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import IO, Any

import numpy as np

from gngdt_io.errors import RecordingError
from gngdt_io.frame import CameraIntrinsics, CameraPose, Frame
from gngdt_io.tf_tree import TransformError, TransformTree

__all__ = ["RecordingError", "check_recording", "read_frames", "recording_info",
           "recording_metadata"]

logger = logging.getLogger(__name__)

#: Unpaired colour or depth images kept while waiting for their partner.
MAX_PENDING_IMAGES = 32
MAX_FRAMES_WITHOUT_CALIBRATION = 64


@dataclass(frozen=True)
class ReadLimits:
    """What reading a recording may cost, however the file is made: a few kilobytes must not
    cost gigabytes or minutes. Each is checked before the memory is spent.

    max_frame_pixels: largest image (width x height); default 4096 x 2160.
    max_chunk_bytes: largest MCAP chunk once decompressed (and largest record).
    max_held_bytes: images held while they wait for their partner or for a calibration.
    max_transform_samples: transform samples read for camera poses (at most 64 bytes each kept;
    ~30-45 s to read a million); the rest are not read.
    """

    max_frame_pixels: int = 4096 * 2160
    max_chunk_bytes: int = 64 * 1024 * 1024
    max_held_bytes: int = 256 * 1024 * 1024
    max_transform_samples: int = 1_000_000

    def __post_init__(self) -> None:
        for item in fields(self):
            if getattr(self, item.name) <= 0:
                raise ValueError(f"{item.name} must be positive, got {getattr(self, item.name)}")

_COLOR_ENCODINGS = frozenset({"rgb8", "bgr8", "8UC3", "rgba8", "bgra8", "mono8", "8UC1"})
_DEPTH_ENCODINGS = frozenset({"16UC1", "mono16", "32FC1"})
_FOXGLOVE_SCHEMAS = frozenset(
    {"foxglove.RawImage", "foxglove.CompressedImage", "foxglove.CameraCalibration"}
)
_IMAGE_SCHEMAS = frozenset(
    {
        "foxglove.RawImage",
        "foxglove.CompressedImage",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
    }
)
_ROS_SCHEMAS = frozenset(
    {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo"}
)
_TRANSFORM_SCHEMAS = frozenset(
    {"foxglove.FrameTransform", "foxglove.FrameTransforms", "tf2_msgs/msg/TFMessage"}
)
#: fixed frames tried, in this order, when the caller asks for "auto"
FIXED_FRAME_CANDIDATES = ("world", "map", "odom")
#: frames without a pose are warned about one by one up to this many, then only counted
MAX_POSE_WARNINGS = 5


@dataclass
class _Image:
    """A decoded image: colour (H, W, 3) uint8 RGB, depth (H, W) uint16 mm or labels (H, W)."""

    stamp_ns: int
    pixels: np.ndarray
    frame_id: str = ""


class _DecodeFailure(Exception):
    """One message could not be decoded (wraps MessageError, OpenCV and CDR errors)."""


def normalize_depth(depth: np.ndarray) -> np.ndarray:
    """(H, W) depth as uint16 millimetres: float input is metres (NaN, inf, <= 0 -> 0)."""
    if depth.dtype == np.uint16:
        return depth
    if depth.dtype.kind == "f":
        millimetres = np.where(np.isfinite(depth) & (depth > 0), depth * 1000.0, 0.0)
        return np.clip(np.rint(millimetres), 0, np.iinfo(np.uint16).max).astype(np.uint16)
    raise _DecodeFailure(f"depth of dtype {depth.dtype} is not supported")


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
        raise _DecodeFailure(f"compressed depth ({image_format!r}) is not supported")
    buffer = np.frombuffer(data, dtype=np.uint8)
    try:
        image = cv2.imdecode(buffer, cv2.IMREAD_COLOR) if buffer.size else None
    except cv2.error as error:  # e.g. larger than OpenCV's ceiling
        raise _DecodeFailure(f"OpenCV cannot decode the {image_format or 'compressed'} image: "
                             f"{str(error).strip().splitlines()[-1]}") from error
    if image is None:
        raise _DecodeFailure(f"OpenCV cannot decode the {image_format or 'compressed'} image")
    if image.shape[0] * image.shape[1] > max_pixels:
        raise _DecodeFailure(f"image {image.shape[1]}x{image.shape[0]} exceeds the limit of "
                             f"{max_pixels} pixels (--max-frame-pixels)")
    return image[..., ::-1].copy()


class _MessageDecoder:
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

        from schemas.packing import MessageError, parse_message

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
                    raise _DecodeFailure(f"no CDR decoder for schema {schema.name}")
                self._ros_decoders[schema.id] = decoder
            return decoder(message.data)
        except MessageError as error:
            raise _DecodeFailure(str(error)) from error
        except _DecodeFailure:
            raise
        except Exception as error:  # CDR parsing raises assorted errors on corrupt bytes
            raise _DecodeFailure(f"cannot decode {schema.name}: {error}") from error

    @staticmethod
    def frame_id(schema_name: str, payload: Any) -> str:
        """The image's coordinate frame name (foxglove ``frame_id``, ROS ``header.frame_id``)."""
        if schema_name in _FOXGLOVE_SCHEMAS:
            return str(payload.frame_id)
        return str(payload.header.frame_id)

    @staticmethod
    def stamp_ns(schema_name: str, payload: Any, log_time_ns: int) -> int:
        """The message's own stamp in ns, or ``log_time_ns`` when it carries none."""
        if schema_name in _FOXGLOVE_SCHEMAS:
            stamp = payload.timestamp.seconds * 1_000_000_000 + payload.timestamp.nanos
        else:
            stamp = payload.header.stamp.sec * 1_000_000_000 + payload.header.stamp.nanosec
        return stamp if stamp else log_time_ns

    @staticmethod
    def pixels(schema_name: str, payload: Any,
               max_pixels: int = ReadLimits.max_frame_pixels) -> np.ndarray:
        """Pixels of an image message (see ``schemas.packing.decode_pixels`` for shapes), of at
        most ``max_pixels``, checked before decoding."""
        from schemas.packing import MessageError, decode_pixels

        if schema_name.endswith("CompressedImage"):
            return decode_compressed(bytes(payload.data), payload.format, max_pixels)
        if payload.width * payload.height > max_pixels:
            raise _DecodeFailure(f"image {payload.width}x{payload.height} exceeds the limit of "
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
            raise _DecodeFailure(str(error)) from error

    @staticmethod
    def intrinsics(schema_name: str, payload: Any) -> CameraIntrinsics:
        from schemas.packing import MessageError, calibration_to_intrinsics, intrinsics_from_k

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
            raise _DecodeFailure(str(error)) from error


def _open_messages(
    stream: IO[bytes], max_record_bytes: int = ReadLimits.max_chunk_bytes
) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) in file order, streamed one chunk at a time, so that a damaged
    file still delivers everything before the damage and memory stays within one chunk.

    Not mcap's log-time merge of the chunk index: it inflates every chunk whose time range
    overlaps the next message's time before yielding it, so chunks that each start early and end
    late are all held at once (12 such chunks in 18 kB held 480 MB). MCAP writers (gngdt's,
    rosbag2's) write messages in log-time order, and frames are paired by their stamps anyway.
    Records larger than ``max_record_bytes`` are refused (mcap raises).
    """
    from mcap.reader import NonSeekingReader

    return NonSeekingReader(stream, validate_crcs=True, record_size_limit=max_record_bytes
                            ).iter_messages(log_time_order=False)


def check_chunks(stream: IO[bytes], path: Path, max_chunk_bytes: int) -> None:
    """Refuse (``RecordingError``) a file holding a chunk that would inflate beyond
    ``max_chunk_bytes``, by the sizes its record and its zstd frame declare (an 8 kB chunk of
    zeros can declare 256 MB) or, for lz4, by inflating at most that much of it, before mcap
    inflates any chunk. Reads the file once, a chunk at a time;
    damage is left for the reading itself to report, after the frames before it."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    offset = 0
    try:
        reader = StreamReader(stream, emit_chunks=True, record_size_limit=max_chunk_bytes)
        for record in reader.records:
            if isinstance(record, Chunk):
                declared = max(record.uncompressed_size, _inflated_size(record, max_chunk_bytes))
                if declared > max_chunk_bytes:
                    raise RecordingError(
                        path, None, f"a {record.compression or 'raw'} chunk of "
                        f"{len(record.data)} bytes (at log time {record.message_start_time}) "
                        f"inflates to {declared} bytes or more, beyond the limit of "
                        f"{max_chunk_bytes} (--max-chunk-mb)")
            offset += 1
    except RecordingError:
        raise
    except Exception as error:  # damage: the reading itself reports it, with its place
        logger.debug("%s: chunk check stopped at record %d: %s", path, offset, error)
    finally:
        stream.seek(0)


def _inflated_size(chunk: Any, limit: int) -> int:
    """What the chunk inflates to, as far as matters before mcap inflates it (0: unknown).

    zstd: the size its frame header states (mcap inflates a frame that states none into at most
    the record's ``uncompressed_size``). lz4: mcap inflates the frame whole, whatever any header
    says (1 MB of lz4 is 256 MB of zeros), so the frame is inflated here, at most ``limit + 1``
    bytes of it, and counted.
    """
    try:
        if chunk.compression == "zstd":
            import zstandard

            return max(int(zstandard.frame_content_size(chunk.data)), 0)
        if chunk.compression == "lz4":
            import lz4.frame

            decompressor = lz4.frame.LZ4FrameDecompressor()
            return len(decompressor.decompress(chunk.data, max_length=limit + 1))
    except Exception:  # an unreadable frame fails decompression later, with its place
        return 0
    return 0


#: receives each bad frame's error when the caller chose to skip bad frames
BadFrameHandler = Callable[[RecordingError], None]


class _FrameAssembler:
    """Pairs colour and depth, attaches calibration and labels, and checks sizes."""

    def __init__(
        self,
        path: Path,
        intrinsics: CameraIntrinsics | None,
        max_skew_ns: int,
        on_bad_frame: BadFrameHandler | None = None,
        poses: PoseLookup | None = None,
        max_held_bytes: int = ReadLimits.max_held_bytes,
    ) -> None:
        self.path = path
        self.poses = poses
        self.max_held_bytes = max_held_bytes
        self.on_bad_frame = on_bad_frame
        self.calibration = intrinsics
        self.max_skew_ns = max_skew_ns
        self.pending: dict[str, deque[_Image]] = {
            "color": deque(maxlen=MAX_PENDING_IMAGES),
            "depth": deque(maxlen=MAX_PENDING_IMAGES),
        }
        self.labels: deque[_Image] = deque(maxlen=MAX_PENDING_IMAGES)
        self.awaiting_calibration: list[tuple[_Image, _Image, np.ndarray | None]] = []
        self.next_index = 0

    def error(self, reason: str) -> RecordingError:
        return RecordingError(self.path, self.next_index, reason)

    def skip_or_raise(self, error: RecordingError) -> None:
        """Report a bad frame to ``on_bad_frame`` (reading goes on), or raise it."""
        if self.on_bad_frame is None:
            raise error
        self.on_bad_frame(error)

    def add_calibration(self, intrinsics: CameraIntrinsics) -> Iterator[Frame]:
        self.calibration = intrinsics
        held, self.awaiting_calibration = self.awaiting_calibration, []
        for color, depth, labels in held:
            yield from self._checked_frame(color, depth, labels)

    def add_labels(self, image: _Image) -> None:
        self._make_room(image.pixels.nbytes)
        self.labels.append(image)

    def held_bytes(self) -> int:
        """Bytes of the images held: unpaired, and frames waiting for a calibration."""
        waiting = [image for queue in (*self.pending.values(), self.labels) for image in queue]
        held = sum(image.pixels.nbytes for image in waiting)
        for color, depth, labels in self.awaiting_calibration:
            held += color.pixels.nbytes + depth.pixels.nbytes
            held += 0 if labels is None else labels.nbytes
        return held

    def _make_room(self, nbytes: int) -> None:
        """Drop the oldest unpaired images until ``nbytes`` more fit in ``max_held_bytes``."""
        held = self.held_bytes()
        queues = [*self.pending.values(), self.labels]
        while held + nbytes > self.max_held_bytes and any(queues):
            oldest = min((queue for queue in queues if queue), key=lambda q: q[0].stamp_ns)
            dropped = oldest.popleft()
            held -= dropped.pixels.nbytes
            logger.debug("%s: dropping unpaired image at %d ns (--max-pending-mb)", self.path,
                         dropped.stamp_ns)

    def add_image(self, role: str, image: _Image) -> Iterator[Frame]:
        other = self.pending["depth" if role == "color" else "color"]
        partner = min(other, key=lambda item: abs(item.stamp_ns - image.stamp_ns), default=None)
        if partner is None or abs(partner.stamp_ns - image.stamp_ns) > self.max_skew_ns:
            self._make_room(image.pixels.nbytes)
            self.pending[role].append(image)
            return
        while other[0] is not partner:  # older unpaired images can no longer pair: drop them
            logger.debug(
                "%s: dropping unpaired image at %d ns", self.path, other.popleft().stamp_ns
            )
        other.popleft()
        color, depth = (image, partner) if role == "color" else (partner, image)
        labels = next(
            (item.pixels for item in self.labels if item.stamp_ns == color.stamp_ns), None
        )
        if self.calibration is None:
            frame_bytes = color.pixels.nbytes + depth.pixels.nbytes
            frame_bytes += 0 if labels is None else labels.nbytes
            if (len(self.awaiting_calibration) >= MAX_FRAMES_WITHOUT_CALIBRATION
                    or self.held_bytes() + frame_bytes > self.max_held_bytes):
                raise self.error(
                    f"no calibration channel (CameraCalibration/CameraInfo) in the first "
                    f"{len(self.awaiting_calibration) + 1} frames (at most "
                    f"{MAX_FRAMES_WITHOUT_CALIBRATION} frames or {self.max_held_bytes >> 20} "
                    "MB are held waiting for one, --max-pending-mb)"
                )
            self.awaiting_calibration.append((color, depth, labels))
            return
        yield from self._checked_frame(color, depth, labels)

    def finish(self) -> None:
        if self.awaiting_calibration:
            raise RecordingError(
                self.path, 0, "no calibration (foxglove CameraCalibration or ROS CameraInfo) found"
            )

    def _checked_frame(
        self, color: _Image, depth: _Image, labels: np.ndarray | None
    ) -> Iterator[Frame]:
        """The frame, or nothing when it is bad and bad frames are skipped (index still used)."""
        try:
            yield self._frame(color, depth, labels)
        except RecordingError as error:
            self.next_index += 1
            self.skip_or_raise(error)

    def _frame(self, color: _Image, depth: _Image, labels: np.ndarray | None) -> Frame:
        assert self.calibration is not None
        color_pixels = normalize_color(color.pixels)
        height, width = color_pixels.shape[:2]
        if depth.pixels.shape != (height, width):
            depth_height, depth_width = depth.pixels.shape[:2]
            raise self.error(
                f"depth {depth_width}x{depth_height} does not match colour {width}x{height}"
            )
        if labels is not None and labels.shape != (height, width):
            raise self.error(
                f"labels {labels.shape[1]}x{labels.shape[0]} do not match colour {width}x{height}"
            )
        if (self.calibration.width, self.calibration.height) != (width, height):
            raise self.error(
                f"calibration is for {self.calibration.width}x{self.calibration.height}, "
                f"colour is {width}x{height}"
            )
        pose, pose_error = None, None
        if self.poses is not None:
            pose, pose_error = self.poses(
                color.frame_id or depth.frame_id, color.stamp_ns, self.next_index
            )
        frame = Frame(
            index=self.next_index,
            timestamp_ns=color.stamp_ns,
            color=color_pixels,
            depth=normalize_depth(depth.pixels),
            intrinsics=self.calibration,
            labels=None if labels is None else labels.astype(np.uint16, copy=False),
            pose=pose,
            extras={} if pose_error is None else {"pose_error": pose_error},
        )
        self.next_index += 1
        return frame


MCAP_MAGIC = b"\x89MCAP0\r\n"


def check_recording(path: str | Path) -> None:
    """Raise :class:`RecordingError` saying why ``path`` cannot be an MCAP recording (missing,
    a folder, empty, another kind of file); cheap: reads 8 bytes."""
    path = Path(path)
    if path.is_dir():
        inside = sorted(item.name for item in path.glob("*.mcap"))[:5]
        hint = f"; inside: {', '.join(inside)}" if inside else "; it holds no .mcap file"
        raise RecordingError(path, None, f"is a folder, not an MCAP file{hint}")
    try:
        with open(path, "rb") as stream:
            start = stream.read(len(MCAP_MAGIC))
    except FileNotFoundError:
        raise RecordingError(path, None, "no such file") from None
    except OSError as error:
        raise RecordingError(path, None, f"cannot open: {error.strerror or error}") from error
    if not start:
        raise RecordingError(path, None, "is empty (0 bytes)")
    if start != MCAP_MAGIC:
        raise RecordingError(path, None, f"is not an MCAP file (it starts with {start!r}, an "
                             f"MCAP file with {MCAP_MAGIC!r})")


def _transform_samples(
    schema: Any, channel: Any, message: Any, decoder: _MessageDecoder
) -> Iterator[tuple[str, str, int, list[float], list[float], bool]]:
    """(parent, child, stamp_ns, translation, quaternion xyzw, static) of one transform message."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    from schemas.packing import MessageError, parse_message, timestamp_to_ns

    static = channel.topic.rstrip("/").endswith("tf_static")
    try:
        if schema.name == "foxglove.FrameTransform":
            transforms = [parse_message(FrameTransform, message.data)]
        elif schema.name == "foxglove.FrameTransforms":
            transforms = list(parse_message(FrameTransforms, message.data).transforms)
        else:
            for stamped in decoder.parse(schema, message).transforms:
                stamp = stamped.header.stamp.sec * 1_000_000_000 + stamped.header.stamp.nanosec
                t, q = stamped.transform.translation, stamped.transform.rotation
                yield (stamped.header.frame_id, stamped.child_frame_id, stamp or message.log_time,
                       [t.x, t.y, t.z], [q.x, q.y, q.z, q.w], static)
            return
    except MessageError as error:
        raise _DecodeFailure(str(error)) from error
    for transform in transforms:
        t, q = transform.translation, transform.rotation
        yield (transform.parent_frame_id, transform.child_frame_id,
               timestamp_to_ns(transform.timestamp) or message.log_time,
               [t.x, t.y, t.z], [q.x, q.y, q.z, q.w], static)


def _may_have_transforms(stream: IO[bytes]) -> bool:
    """False when the file's summary lists no transform channel (so no pass is needed)."""
    from mcap.reader import SeekingReader

    try:
        summary = SeekingReader(stream).get_summary()
    except Exception:  # no readable summary: only a full pass can tell
        summary = None
    finally:
        stream.seek(0)
    if summary is None:
        return True
    return any(
        schema.name in _TRANSFORM_SCHEMAS for schema in summary.schemas.values()
    )


def read_transforms(stream: IO[bytes], path: Path,
                    limits: ReadLimits | None = None) -> TransformTree:
    """Every transform of the recording (first pass), up to ``limits.max_transform_samples``
    (warned: later frames may have no pose). A bad transform message is warned about (naming its
    frames) and skipped; damage to the file ends the pass, the main pass reports it."""
    limits = limits or ReadLimits()
    tree = TransformTree()
    if not _may_have_transforms(stream):
        return tree
    decoder = _MessageDecoder()
    bad = read = 0
    try:
        for schema, channel, message in _open_messages(stream, limits.max_chunk_bytes):
            if schema is None or schema.name not in _TRANSFORM_SCHEMAS:
                continue
            try:
                for parent, child, stamp, translation, rotation, static in _transform_samples(
                    schema, channel, message, decoder
                ):
                    read += 1  # bad and replaced (static) samples cost the time too
                    if read > limits.max_transform_samples:
                        logger.warning(
                            "%s: more than %d transform samples (--max-transforms); the rest "
                            "(from log time %.3f s) are not read, so later frames may have no "
                            "pose", path, limits.max_transform_samples, message.log_time / 1e9)
                        return tree
                    tree.add(parent, child, stamp, translation, rotation, static)
            except (_DecodeFailure, TransformError) as error:
                bad += 1
                read += 1
                if bad <= MAX_POSE_WARNINGS:
                    logger.warning("%s: %s: %s; skipped", path, channel.topic, error)
    except Exception as error:  # damaged file: keep the transforms read so far
        logger.debug("%s: transform pass stopped: %s", path, error)
    if bad > MAX_POSE_WARNINGS:
        logger.warning("%s: %d bad transform messages skipped in all", path, bad)
    return tree


class PoseLookup:
    """Each frame's camera pose from the recording's transforms (see the module docstring)."""

    def __init__(self, path: Path, transforms: TransformTree, fixed_frame: str) -> None:
        self.path = path
        self.transforms = transforms
        self.requested = fixed_frame
        self.fixed_frames: dict[str, str | None] = {}  # camera frame -> fixed frame (None: none)
        self.missing = 0

    def fixed_frame_for(self, camera_frame: str) -> str | None:
        """The fixed frame poses of ``camera_frame`` are given in; None (warned once) when the
        transforms never connect them."""
        if camera_frame in self.fixed_frames:
            return self.fixed_frames[camera_frame]
        tree = self.transforms
        if self.requested == "auto":
            connected = [
                frame for frame in FIXED_FRAME_CANDIDATES
                if frame != camera_frame and tree.chain(frame, camera_frame) is not None
            ]
            root = tree.root(camera_frame) if camera_frame in tree.frames else None
            fixed = connected[0] if connected else (root if root != camera_frame else None)
        else:
            fixed = self.requested if tree.chain(self.requested, camera_frame) else None
        if fixed is None:
            wanted = (" or ".join(repr(f) for f in FIXED_FRAME_CANDIDATES)
                      if self.requested == "auto" else repr(self.requested))
            logger.warning(
                "%s: the transforms never connect %s to the images' frame %r (known frames: %s); "
                "frames have no pose", self.path, wanted, camera_frame,
                ", ".join(sorted(tree.frames)))
        else:
            logger.info("%s: camera poses of %r in %r (%s)", self.path, camera_frame, fixed,
                        " -> ".join(tree.chain(fixed, camera_frame) or []))
        self.fixed_frames[camera_frame] = fixed
        return fixed

    def __call__(self, camera_frame: str, stamp_ns: int, index: int
                 ) -> tuple[CameraPose | None, str | None]:
        """The camera's pose at ``stamp_ns``; or None and, when the recording has poses for
        this camera but not at this time, why (warned)."""
        if not camera_frame:
            if "" not in self.fixed_frames:
                self.fixed_frames[""] = None
                logger.warning("%s: the images carry no frame_id, so no pose can be attached",
                               self.path)
            return None, None
        fixed = self.fixed_frame_for(camera_frame)
        if fixed is None:
            return None, None
        try:
            return CameraPose(self.transforms.lookup(fixed, camera_frame, stamp_ns), fixed), None
        except TransformError as error:
            self.missing += 1
            if self.missing <= MAX_POSE_WARNINGS:
                logger.warning("%s: frame %d has no pose: %s", self.path, index, error)
            elif self.missing == MAX_POSE_WARNINGS + 1:
                logger.warning("%s: more frames without a pose; not warned one by one", self.path)
            return None, str(error)


def _topic_matches(topic: str, camera_prefix: str | None) -> bool:
    if camera_prefix is None:
        return True
    prefix = "/" + camera_prefix.strip("/")
    return topic == prefix or topic.startswith(prefix + "/")


def read_frames(
    path: str | Path,
    camera_prefix: str | None = None,
    *,
    intrinsics: CameraIntrinsics | None = None,
    max_skew_ns: int = 0,
    on_bad_frame: BadFrameHandler | None = None,
    fixed_frame: str | None = "auto",
    limits: ReadLimits | None = None,
) -> Iterator[Frame]:
    """Yield the frames of an MCAP recording in file order (see the module docstring).

    camera_prefix: only topics under it (``"/camera"``, ``"/kinect"``). intrinsics: used until a
    calibration message arrives (and when the recording has none). max_skew_ns: largest stamp
    difference between a paired colour and depth image. on_bad_frame: called with the
    RecordingError of each bad frame, which is then skipped (default: raise it). fixed_frame:
    the frame poses are given in (``"auto"``: see the module docstring; None: no poses).
    limits: what reading may cost (:class:`ReadLimits`; an image over the pixel limit is a bad
    frame, a chunk over the chunk limit refuses the file before anything is decompressed).
    Raises RecordingError naming the file and frame for missing calibration, mismatched sizes,
    undecodable messages and truncated or corrupt files -- after yielding the frames before.
    """
    limits = limits or ReadLimits()
    path = Path(path)
    try:
        stream = open(path, "rb")
    except OSError as error:
        raise RecordingError(path, None, f"cannot open: {error.strerror or error}") from error
    with stream:
        check_chunks(stream, path, limits.max_chunk_bytes)
        poses = None
        if fixed_frame is not None:
            transforms = read_transforms(stream, path, limits)
            if len(transforms):
                poses = PoseLookup(path, transforms, fixed_frame)
            stream.seek(0)
        assembler = _FrameAssembler(path, intrinsics, max_skew_ns, on_bad_frame, poses,
                                    limits.max_held_bytes)
        yield from _read_stream(path, stream, camera_prefix, assembler, limits)


def _read_stream(
    path: Path, stream: IO[bytes], camera_prefix: str | None, assembler: _FrameAssembler,
    limits: ReadLimits,
) -> Iterator[Frame]:
    max_skew_ns = assembler.max_skew_ns
    decoder = _MessageDecoder()
    chosen: dict[str, str] = {}  # role -> topic
    try:
        messages = _open_messages(stream, limits.max_chunk_bytes)
        for schema, channel, message in messages:
            if schema is None or schema.name not in _FOXGLOVE_SCHEMAS | _ROS_SCHEMAS:
                continue
            if not _topic_matches(channel.topic, camera_prefix):
                continue
            try:
                payload = decoder.parse(schema, message)
                role = decoder.role(schema.name, channel.topic, payload)
                if role is None or chosen.setdefault(role, channel.topic) != channel.topic:
                    continue
                if role == "calibration":
                    yield from assembler.add_calibration(decoder.intrinsics(schema.name, payload))
                    continue
                image = _Image(
                    decoder.stamp_ns(schema.name, payload, message.log_time),
                    decoder.pixels(schema.name, payload, limits.max_frame_pixels),
                    decoder.frame_id(schema.name, payload),
                )
            except _DecodeFailure as failure:
                error = assembler.error(f"{channel.topic}: {failure}")
                error.__cause__ = failure
                assembler.skip_or_raise(error)
                continue
            if role == "labels":
                assembler.add_labels(image)
            else:
                yield from assembler.add_image(role, image)
    except RecordingError:
        raise
    except Exception as error:  # mcap raises EndOfFile, McapError, zstd and CRC errors
        reason = "truncated file" if type(error).__name__ == "EndOfFile" else "corrupt file"
        raise assembler.error(f"{reason} ({type(error).__name__}: {error})") from error
    if "color" not in chosen or "depth" not in chosen:
        missing = [role for role in ("color", "depth") if role not in chosen]
        raise RecordingError(path, None, f"no {' or '.join(missing)} image channel found")
    assembler.finish()
    if assembler.next_index == 0:
        raise RecordingError(
            path,
            None,
            f"no colour image was paired with a depth image (stamps differ by more than "
            f"max_skew_ns={max_skew_ns})",
        )


def recording_info(path: str | Path) -> dict[str, Any]:
    """Cheap summary from the MCAP index: frames, duration_s, size_bytes, channels, start/end ns.

    ``frames`` is the largest message count of an image channel that is neither depth nor labels;
    ``channels`` maps topic -> {schema, messages}.
    Raises RecordingError if the file has no readable summary (e.g. truncated).
    """
    from mcap.reader import SeekingReader

    path = Path(path)
    try:
        with open(path, "rb") as stream:
            summary = SeekingReader(stream).get_summary()
    except OSError as error:
        raise RecordingError(path, None, f"cannot open: {error.strerror or error}") from error
    except Exception as error:
        raise RecordingError(path, None, f"no readable MCAP summary ({error})") from error
    if summary is None or summary.statistics is None:
        raise RecordingError(path, None, "no MCAP summary statistics (truncated file?)")
    statistics = summary.statistics
    channels: dict[str, dict[str, Any]] = {}
    frames = 0
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        count = statistics.channel_message_counts.get(channel_id, 0)
        schema_name = schema.name if schema is not None else ""
        channels[channel.topic] = {"schema": schema_name, "messages": count}
        is_image = schema_name in _IMAGE_SCHEMAS
        if is_image and "depth" not in channel.topic and not channel.topic.endswith("/labels"):
            frames = max(frames, count)
    start, end = statistics.message_start_time, statistics.message_end_time
    return {
        "path": str(path),
        "frames": frames,
        "duration_s": (end - start) / 1e9 if statistics.message_count else 0.0,
        "start_ns": start,
        "end_ns": end,
        "size_bytes": os.path.getsize(path),
        "messages": statistics.message_count,
        "channels": channels,
    }


def recording_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The recording's MCAP metadata records, by name (e.g. ``gngdt.scene`` of a synthetic
    scene); empty when it has none or no readable summary."""
    from mcap.reader import SeekingReader

    path = Path(path)
    try:
        with open(path, "rb") as stream:
            return {record.name: dict(record.metadata)
                    for record in SeekingReader(stream).iter_metadata()}
    except OSError as error:
        raise RecordingError(path, None, f"cannot open: {error.strerror or error}") from error
    except Exception as error:  # no summary / damaged index: no metadata to offer
        logger.debug("%s: no readable metadata (%s)", path, error)
        return {}
