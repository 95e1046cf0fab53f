"""Camera poses of a recording: its transform channels (foxglove ``FrameTransform(s)``, ROS 2
``tf2_msgs/msg/TFMessage``) read into a :class:`TransformTree` in a first pass, then each frame's
pose looked up in the fixed frame (see :mod:`gngdt.io.mcap.reader`)."""

from __future__ import annotations

import logging
from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from gngdt.core.sensor.geometry import TransformError
from gngdt.io.errors import RecordingError
from gngdt.io.frame import CameraPose
from gngdt.io.mcap.decoding import DecodeFailure, MessageDecoder
from gngdt.io.mcap.limits import ReadLimits, open_messages
from gngdt.io.tf_tree import TransformTree

__all__ = ["FIXED_FRAME_CANDIDATES", "PoseLookup", "read_transforms"]

logger = logging.getLogger(__name__)

_TRANSFORM_SCHEMAS = frozenset(
    {"foxglove.FrameTransform", "foxglove.FrameTransforms", "tf2_msgs/msg/TFMessage"}
)
#: fixed frames tried, in this order, when the caller asks for "auto"
FIXED_FRAME_CANDIDATES = ("world", "map", "odom")
#: frames without a pose are warned about one by one up to this many, then only counted
MAX_POSE_WARNINGS = 5
#: a dynamic transform whose stamp is this much further from its message's log time than the
#: recording's transforms typically are (their median; a bag of simulated time has a large
#: but steady one) is ignored and counted: a forged or broken stamp, not a pose
FAR_STAMP_NS = 60_000_000_000


def _transform_samples(
    schema: Any, channel: Any, message: Any, decoder: MessageDecoder
) -> Iterator[tuple[str, str, int, list[float], list[float], bool]]:
    """(parent, child, stamp_ns, translation, quaternion xyzw, static) of one transform message."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    from gngdt.schemas.messages import MessageError, parse_message, timestamp_to_ns

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
        raise DecodeFailure(str(error)) from error
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
    decoder = MessageDecoder()
    bad = read = 0
    offsets = StampOffsets()
    try:
        for schema, channel, message in open_messages(stream, path, limits.max_chunk_bytes):
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
                    if not static:
                        offsets.add(child, stamp, stamp - message.log_time)
            except (DecodeFailure, TransformError) as error:
                bad += 1
                read += 1
                if bad <= MAX_POSE_WARNINGS:
                    logger.warning("%s: %s: %s; skipped", path, channel.topic, error)
    except RecordingError:  # a chunk beyond the limits: the file is refused
        raise
    except Exception as error:  # damaged file: keep the transforms read so far
        logger.debug("%s: transform pass stopped: %s", path, error)
    if bad > MAX_POSE_WARNINGS:
        logger.warning("%s: %d bad transform messages skipped in all", path, bad)
    far = offsets.discard_far(tree)
    if far:
        logger.warning("%s: %d transform samples stamped over %g s away from the others (against "
                       "their log times) ignored", path, far, FAR_STAMP_NS / 1e9)
    return tree


class StampOffsets:
    """Each dynamic transform sample's stamp minus its message's log time (12 bytes a sample),
    to find the samples stamped far from the others once every one is read."""

    def __init__(self) -> None:
        self._children: dict[str, int] = {}
        self._child = array("i")
        self._stamps = array("q")
        self._offsets = array("q")

    def add(self, child: str, stamp_ns: int, offset_ns: int) -> None:
        self._child.append(self._children.setdefault(child, len(self._children)))
        self._stamps.append(stamp_ns)
        self._offsets.append(max(-(2**63), min(offset_ns, 2**63 - 1)))

    def discard_far(self, tree: TransformTree) -> int:
        """Drop from ``tree`` the samples whose offset is over ``FAR_STAMP_NS`` from the median
        offset; how many went."""
        if not self._offsets:
            return 0
        offsets = np.frombuffer(self._offsets, dtype=np.int64).astype(np.float64)
        far = np.abs(offsets - np.median(offsets)) > FAR_STAMP_NS
        if not far.any():
            return 0
        children = np.frombuffer(self._child, dtype=np.int32)[far]
        stamps = np.frombuffer(self._stamps, dtype=np.int64)[far]
        names = list(self._children)  # by index
        return sum(tree.discard(names[index], stamps[children == index])
                   for index in np.unique(children).tolist())


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
