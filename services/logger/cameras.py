"""The cameras the logger knows, and when each one's stream is over."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gngdt.schemas.wire import ANY_CAMERA, CAPTURE, alive_key, camera_of

if TYPE_CHECKING:
    import zenoh

    from gngdt.io.outputs import StreamSample

log = logging.getLogger(__name__)

DEFAULT_MAX_CAMERAS = 16


@dataclass
class CameraProgress:
    """What the logger knows about one camera's stream, to decide when it is over."""

    eos_last_sequence: int | None = None
    eos_at: float = 0.0
    #: when the camera's capture left without an end of stream (its liveliness token went)
    capture_gone_at: float | None = None
    #: the learner's last status and last topology were its settled, final ones. Each is
    #: judged on its own stream: the logger's subscribers hand samples over on threads of their
    #: own, so the status may come before the topology sent ahead of it, and the end of stream
    #: after both
    settled: bool = False
    settled_topology: bool = False

    def finished(self, drain_seconds: float) -> bool:
        if self.eos_last_sequence is None:
            return (self.capture_gone_at is not None
                    and time.monotonic() - self.capture_gone_at > drain_seconds)
        return ((self.settled and self.settled_topology)
                or time.monotonic() - self.eos_at > drain_seconds)


class CaptureWatch:
    """Captures coming and going (their liveliness tokens ``gngdt/<cam>/capture/alive``): a
    camera is expected from its capture's start, not only from its first message."""

    KEY = alive_key(ANY_CAMERA, CAPTURE)

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._events: list[tuple[str, bool]] = []

    def on_token(self, sample: zenoh.Sample) -> None:
        import zenoh

        camera = camera_of(str(sample.key_expr))
        with self._lock:
            self._events.append((camera, sample.kind == zenoh.SampleKind.PUT))

    def take(self) -> list[tuple[str, bool]]:
        """(camera, capture alive) events since the last call."""
        with self._lock:
            events, self._events = self._events, []
        return events


class Cameras:
    """Every camera the logger has heard of, up to ``max_cameras``, with its progress.

    A camera becomes known with its first valid message (or its capture's token); messages of
    further cameras are refused and counted, so that garbage on made-up camera names cannot
    grow the recording.
    """

    def __init__(self, max_cameras: int = DEFAULT_MAX_CAMERAS) -> None:
        self.max_cameras = max_cameras
        self.progress: dict[str, CameraProgress] = {}
        self.refused = 0

    def __contains__(self, camera: str) -> bool:
        return camera in self.progress

    def names(self) -> list[str]:
        return list(self.progress)

    def admit(self, camera: str) -> bool:
        """Room for one more camera? Refusals are counted, the first one logged."""
        if camera in self.progress or len(self.progress) < self.max_cameras:
            return True
        if self.refused == 0:
            log.warning("more than %d cameras (--max-cameras): messages of %r and further "
                        "cameras are refused", self.max_cameras, camera)
        self.refused += 1
        return False

    def add(self, camera: str) -> None:
        self.progress.setdefault(camera, CameraProgress())

    def note(self, sample: StreamSample) -> None:
        """Progress from one valid sample: topologies, the learner's settling, the end of
        stream (ValueError when one of these is malformed)."""
        progress = self.progress[sample.camera]
        camera, stream = sample.camera, sample.stream
        if stream == "topology":
            progress.settled_topology = sample.topology.settled
        elif stream == "learner/status":
            progress.settled = sample.status.settled
        elif stream == "eos":
            end = sample.stream_end
            progress.eos_last_sequence = end.last_frame_sequence
            progress.eos_at = time.monotonic()
            log.info("%s: end of stream after %d frames", camera, end.frames_sent)

    def capture_seen(self, camera: str, alive: bool) -> bool:
        """A capture of ``camera`` started (``alive``) or left; True when the camera is new."""
        new = camera not in self.progress
        if new and not self.admit(camera):
            return False
        self.add(camera)
        self.progress[camera].capture_gone_at = None if alive else time.monotonic()
        return new

    def all_finished(self, drain_seconds: float) -> bool:
        return bool(self.progress) and all(
            progress.finished(drain_seconds) for progress in self.progress.values())
