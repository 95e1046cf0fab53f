"""Wire conventions shared by every service: key expressions, encodings and the frame attachment.

Foxglove messages have no frame-sequence field, so every zenoh sample carries a 16-byte
attachment: frame sequence (uint64) and capture time (int64 nanoseconds), little-endian.
Sequences are below 2**63 (what every consumer's signed counters and rerun's timelines hold) and
capture times are after the epoch; anything else is refused as malformed.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

DEFAULT_CAMERA = "camera"

#: zenoh encodings, one per message type (docs/contracts.md "Topics").
ENCODING_RAW_IMAGE = "application/protobuf;foxglove.RawImage"
ENCODING_CALIBRATION = "application/protobuf;foxglove.CameraCalibration"
ENCODING_POINT_CLOUD = "application/protobuf;foxglove.PointCloud"
ENCODING_TOPOLOGY = "application/protobuf;gngdt.Topology"
ENCODING_STATUS = "application/protobuf;gngdt.LearnerStatus"
ENCODING_STREAM_END = "application/protobuf;gngdt.StreamEnd"
ENCODING_FRAME_ACK = "application/protobuf;gngdt.FrameAck"
ENCODING_SCENE_UPDATE = "application/protobuf;foxglove.SceneUpdate"
ENCODING_FRAME_TRANSFORM = "application/protobuf;foxglove.FrameTransform"

#: every stream of a camera (``gngdt/<cam>/<stream>``), by who publishes it (docs/contracts.md
#: "Topics")
CAPTURE_STREAMS = ("color", "depth", "calibration", "points", "tf", "eos")
#: "tf" is the camera's pose: capture's from a recording's poses, the learner's when it tracks
#: the camera (learn --track)
LEARNER_STREAMS = ("topology", "objects", "scene", "learner/status", "learner/ack", "tf")

_ATTACHMENT = struct.Struct("<Qq")

#: largest frame sequence accepted (signed 64-bit, as rerun's ``sequence`` timeline)
MAX_SEQUENCE = 2**63 - 1
#: a capture time further than this from the receiver's clock is impossible, not late: one
#: such stamp would poison every latency statistic for the next thousand frames
MAX_CLOCK_OFFSET_NS = 24 * 3600 * 1_000_000_000


#: every key gngdt uses (what the logger and `gngdt run` subscribe to)
ALL_KEYS = "gngdt/**"
#: a camera wildcard, for patterns over every camera (``topic(ANY_CAMERA, "points")``)
ANY_CAMERA = "*"
#: the services that announce themselves per camera with a liveliness token
#: ``gngdt/<cam>/<service>/alive`` (docs/contracts.md "Liveliness")
CAPTURE, LEARNER, BRIDGE = "capture", "learner", "ros2"
#: each logger's token is ``gngdt/logger/alive/<zenoh id>`` (a logger takes every camera)
LOGGER_ALIVE = "gngdt/logger/alive"


def topic(camera: str, name: str) -> str:
    """Key expression of one stream of one camera: ``topic("camera", "points")``;
    `ANY_CAMERA` gives the pattern over every camera."""
    if camera != ANY_CAMERA and (not camera or "/" in camera or "*" in camera or "$" in camera):
        raise ValueError(f"camera name must be a single key chunk, got {camera!r}")
    return f"gngdt/{camera}/{name}"


def alive_key(camera: str, service: str) -> str:
    """The liveliness token of one camera's ``service`` (`CAPTURE`, `LEARNER`, `BRIDGE`)."""
    return topic(camera, f"{service}/alive")


def learner_instance_key(camera: str, zenoh_id: str = "*") -> str:
    """The token each learner of ``camera`` declares (``*``: any learner's), so that a second
    learner of one camera can see the first."""
    return topic(camera, f"{LEARNER}/instance/{zenoh_id}")


def logger_alive_key(zenoh_id: str = "*") -> str:
    """One logger's liveliness token (``*``: any logger's)."""
    return f"{LOGGER_ALIVE}/{zenoh_id}"


def camera_of(key: str) -> str:
    """The camera a ``gngdt/<cam>/...`` key belongs to."""
    return key.split("/")[1]


@dataclass(frozen=True)
class FrameStamp:
    """Frame sequence number and capture time carried by every sample."""

    sequence: int
    capture_time_ns: int

    def __post_init__(self) -> None:
        if not 0 <= self.sequence <= MAX_SEQUENCE:
            raise ValueError(f"frame sequence {self.sequence} is outside 0..2**63-1")
        if self.capture_time_ns <= 0:
            raise ValueError(f"capture time {self.capture_time_ns} ns is not after the epoch")

    def to_attachment(self) -> bytes:
        return _ATTACHMENT.pack(self.sequence, self.capture_time_ns)

    @classmethod
    def from_attachment(cls, data: bytes | None) -> FrameStamp:
        """Parse an attachment; raises ``ValueError`` when absent, malformed or out of range."""
        if data is None or len(data) != _ATTACHMENT.size:
            raise ValueError("missing or malformed frame attachment")
        sequence, capture_time_ns = _ATTACHMENT.unpack(data)
        if sequence >= 2**63:  # timelines (rerun's, MCAP's) hold signed 64-bit sequences
            raise ValueError(f"frame sequence {sequence} is out of range")
        return cls(sequence, capture_time_ns)

    def check_clock(self, now_ns: int) -> None:
        """Raise ``ValueError`` when the capture time is more than a day from ``now_ns``."""
        if abs(now_ns - self.capture_time_ns) > MAX_CLOCK_OFFSET_NS:
            raise ValueError(f"impossible capture time {self.capture_time_ns} ns "
                             f"({(self.capture_time_ns - now_ns) / 1e9:+.3g} s from this clock)")
