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
through any chain of frames, interpolated (:mod:`gngdt.io.mcap.poses`, :mod:`gngdt.io.tf_tree`).
The fixed frame is ``fixed_frame``, or with ``"auto"`` the first of ``world``, ``map``, ``odom``
connected to the camera, else the root of the camera's tree. A recording whose transforms never
connect the fixed frame and the camera gives frames without a pose, with one warning naming the
frames; a frame whose time the transforms do not cover has no pose either (warned), and says why
in ``frame.pose_error``: the recording has poses, only not for that frame.

Messages are read in file order, one chunk inflated at a time (MCAP writers write in log-time
order; see :func:`gngdt.io.mcap.limits.open_messages` for why not mcap's merge by log time).
Frames (:mod:`gngdt.io.mcap.frame_assembly`): a colour image and a depth image are paired when their
stamps (the message's own timestamp/header stamp, else the MCAP ``log_time``) differ by at most
``max_skew_ns`` (default 0: the same stamp, as gngdt writes them). The frame takes the colour
stamp, the latest calibration (frames wait for the first one, up to
``MAX_FRAMES_WITHOUT_CALIBRATION`` of them), and labels carrying the colour stamp if they came
before the pair. Depth is normalised to uint16 millimetres (32FC1 metres -> mm, NaN/negative ->
0), colour to RGB uint8.

A damaged file yields every frame before the damage, then raises :class:`RecordingError`.
With ``on_bad_frame``, a bad *frame* (an undecodable image or calibration message, colour/depth/
calibration sizes that disagree) is reported to it and skipped, and reading goes on with the next
good frame; only damage to the file itself (truncation, corrupt chunks) still ends the reading.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame
from gngdt.io.images import CameraParameters
from gngdt.io.mcap.decoding import (
    FOXGLOVE_SCHEMAS,
    ROS_SCHEMAS,
    DecodeFailure,
    MessageDecoder,
    decode_compressed,
    normalize_depth,
)
from gngdt.io.mcap.frame_assembly import BadFrameHandler, DecodedImage, FrameAssembler
from gngdt.io.mcap.limits import ReadLimits, open_messages
from gngdt.io.mcap.poses import FIXED_FRAME_CANDIDATES, PoseLookup, read_transforms

__all__ = [
    "FIXED_FRAME_CANDIDATES",
    "MCAP_MAGIC",
    "BadFrameHandler",
    "PoseLookup",
    "ReadLimits",
    "RecordingError",
    "check_recording",
    "decode_compressed",
    "normalize_depth",
    "read_frames",
    "read_transforms",
    "recording_info",
    "recording_metadata",
]

logger = logging.getLogger(__name__)

#: schemas of image channels, counted by :func:`recording_info`
_IMAGE_SCHEMAS = frozenset(
    {
        "foxglove.RawImage",
        "foxglove.CompressedImage",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
    }
)

#: the 8 bytes every MCAP file starts with
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
    camera: CameraParameters | None = None,
    depth_scale: float | None = None,
) -> Iterator[Frame]:
    """Yield the frames of an MCAP recording in file order (see the module docstring).

    camera_prefix: only topics under it (``"/camera"``, ``"/kinect"``). intrinsics: used until a
    calibration message arrives (and when the recording has none). max_skew_ns: largest stamp
    difference between a paired colour and depth image. on_bad_frame: called with the
    RecordingError of each bad frame, which is then skipped (default: raise it). fixed_frame:
    the frame poses are given in (``"auto"``: see the module docstring; None: no poses).
    limits: what reading may cost (:class:`ReadLimits`; an image over the pixel limit is a bad
    frame, a chunk over the chunk limit refuses the file before it is inflated, after the
    frames before it, or before any frame when the first pass reads transforms).
    camera: intrinsics that replace the recording's calibration (a bag without CameraInfo);
    depth_scale: units per metre of its 16-bit depth images (default: millimetres, or the
    camera's).
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
        poses = None
        if fixed_frame is not None:
            transforms = read_transforms(stream, path, limits)
            if len(transforms):
                poses = PoseLookup(path, transforms, fixed_frame)
            stream.seek(0)
        assembler = FrameAssembler(path, intrinsics, max_skew_ns, on_bad_frame, poses,
                                    limits.max_held_bytes, camera, depth_scale)
        yield from _read_stream(path, stream, camera_prefix, assembler, limits)


def _read_stream(
    path: Path, stream: IO[bytes], camera_prefix: str | None, assembler: FrameAssembler,
    limits: ReadLimits,
) -> Iterator[Frame]:
    max_skew_ns = assembler.max_skew_ns
    decoder = MessageDecoder()
    chosen: dict[str, str] = {}  # role -> topic
    try:
        messages = open_messages(stream, path, limits.max_chunk_bytes)
        for schema, channel, message in messages:
            if schema is None or schema.name not in FOXGLOVE_SCHEMAS | ROS_SCHEMAS:
                continue
            if not _topic_matches(channel.topic, camera_prefix):
                continue
            try:
                payload = decoder.parse(schema, message)
                role = decoder.role(schema.name, channel.topic, payload)
                if role is None or chosen.setdefault(role, channel.topic) != channel.topic:
                    continue
                if role == "calibration":
                    yield from _calibrated(assembler, decoder, schema.name, payload,
                                           channel.topic)
                    continue
                image = DecodedImage(
                    decoder.stamp_ns(schema.name, payload, message.log_time),
                    decoder.pixels(schema.name, payload, limits.max_frame_pixels),
                    decoder.frame_id(schema.name, payload),
                )
            except DecodeFailure as failure:
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


def _calibrated(assembler: FrameAssembler, decoder: MessageDecoder, schema_name: str,
                payload: Any, topic: str) -> Iterator[Frame]:
    """The frames a calibration message releases; one that cannot be a camera's is refused
    (`FrameAssembler.refuse_calibration`)."""
    try:
        intrinsics = decoder.intrinsics(schema_name, payload)
    except DecodeFailure as failure:
        reason = f"{topic}: {failure}"
        if assembler.refuse_calibration(reason):
            assembler.skip_or_raise(assembler.error(reason))
        return
    yield from assembler.add_calibration(intrinsics)


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
