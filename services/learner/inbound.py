"""What arrives at the learner: points samples decoded once (`arrive`: the frame's stamp, its
cloud, or why it is malformed), the end of stream and the camera's calibration; every payload
bounded before it is copied out of zenoh."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gngdt.schemas.wire import FrameStamp
from gngdt.services.learner.messages import PointsMessage, decode_points

if TYPE_CHECKING:
    import zenoh

    from gngdt.core.learner.frame_learner import FrameLearner

log = logging.getLogger(__name__)

#: bytes a stream-end message may take (a real one is under 200)
MAX_EOS_BYTES = 64 * 1024
#: bytes per point a foreign cloud layout may use (gngdt's own uses 15)
MAX_POINT_STRIDE_BYTES = 64
#: bytes a calibration message may take (a real one is under 500)
MAX_CALIBRATION_BYTES = 64 * 1024


class EndOfStream:
    """Remembers the last end-of-stream announced on the camera (set from zenoh's thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.last_sequence: int | None = None
        self.received_at = 0.0

    def set(self, last_sequence: int) -> None:
        with self._lock:
            self.last_sequence = last_sequence
            self.received_at = time.monotonic()

    def finished(self, handled_sequence: int, drain_seconds: float = 5.0) -> bool:
        """True once the last frame was done with (learned or not), or ``drain_seconds`` after
        eos without it."""
        with self._lock:
            if self.last_sequence is None:
                return False
            return (handled_sequence >= self.last_sequence
                    or time.monotonic() - self.received_at > drain_seconds)


def payload_bytes(sample: zenoh.Sample, limit: int) -> bytes:
    """The sample's payload, refused (``MessageError``) before any copy when over ``limit``."""
    from gngdt.schemas.messages import MessageError

    size = len(sample.payload)
    if size > limit:
        raise MessageError(f"{size} bytes, more than the limit of {limit}")
    return sample.payload.to_bytes()


def attachment_bytes(sample: zenoh.Sample) -> bytes | None:
    attachment = sample.attachment
    if attachment is None or len(attachment) > 64:
        return None
    return attachment.to_bytes()


class LatestCalibration:
    """The camera's latest intrinsics (set from zenoh's thread), for tracking. A calibration
    that is malformed or cannot be a camera's is counted as malformed and never used (the one
    in use stays); it is said once until a good one comes."""

    def __init__(self, learner: FrameLearner) -> None:
        self.learner = learner
        self.intrinsics = None
        self._refusal_said = False

    def on_sample(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.images import calibration_to_intrinsics
        from gngdt.schemas.messages import MessageError

        try:
            self.intrinsics = calibration_to_intrinsics(
                payload_bytes(sample, MAX_CALIBRATION_BYTES))
            self._refusal_said = False
        except (MessageError, ValueError) as error:
            self.learner.counters.malformed_messages += 1
            if not self._refusal_said:
                log.warning("calibration refused, not used: %s (each one refused is counted "
                            "as malformed)", error)
                self._refusal_said = True


@dataclass(frozen=True)
class Received:
    """A points sample's bytes, copied out of zenoh on arrival: a sample kept waiting in a queue
    would hold its shared-memory buffer, and a capture whose pool is full sends over the network
    (measured: 230 of 300 clouds while the tracker's queue waited for the first map)."""

    #: None: not copied, ``problem`` says why (larger than the limit)
    payload: bytes | None
    attachment: bytes | None
    #: it came through shared memory (diagnostics)
    shared: bool = False
    problem: str = ""


def points_limit_bytes(max_cloud_points: int) -> int:
    """Bytes a points payload may take (a foreign layout's widest stride, and its header)."""
    return max_cloud_points * MAX_POINT_STRIDE_BYTES + 64 * 1024


def receive(sample: zenoh.Sample, limit_bytes: int) -> Received:
    """``sample``'s bytes (its payload only within ``limit_bytes``), out of zenoh's buffers."""
    from gngdt.schemas.messages import MessageError
    from gngdt.services.plumbing.session import through_shared_memory

    payload, problem = None, ""
    try:
        payload = payload_bytes(sample, limit_bytes)
    except MessageError as error:
        problem = str(error)
    return Received(payload, attachment_bytes(sample), through_shared_memory(sample), problem)


@dataclass(frozen=True)
class Arrival:
    """One points sample as the learner takes it: its ``stamp`` (None: its attachment is not a
    frame stamp), the decoded ``cloud``, or why it is malformed (``problem``)."""

    stamp: FrameStamp | None
    cloud: PointsMessage | None = None
    problem: str = ""
    #: it came through shared memory (diagnostics)
    shared: bool = False


def arrive(received: Received, max_cloud_points: int) -> Arrival:
    """Decode one points sample (`receive` bounded its payload before any copy); a malformed one
    says why instead."""
    from gngdt.schemas.messages import MessageError

    stamp = None
    try:
        stamp = FrameStamp.from_attachment(received.attachment)
        if received.payload is None:
            raise MessageError(received.problem)
        return Arrival(stamp, decode_points(received.payload, received.attachment,
                                            max_cloud_points), shared=received.shared)
    except ValueError as error:  # MessageError is a ValueError
        return Arrival(stamp, problem=str(error), shared=received.shared)
