"""The logger's inbox: samples handed over from zenoh's threads to its loop, bounded in bytes."""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from gngdt.services.plumbing.session import MAX_MESSAGE_BYTES

if TYPE_CHECKING:
    import zenoh

#: streams where only the newest sample matters when the logger falls behind
LATEST_ONLY_STREAMS = ("color", "depth", "points", "objects")
#: the streams of a camera the logger's loop takes (the scene is the topology again, drawn for
#: Foxglove: raw outputs such as --mcap record it; acknowledgements are the capture's business)
LOGGED_STREAMS = ("calibration", "color", "depth", "points", "tf", "topology", "objects",
                  "learner/status", "eos")


#: bytes a sample of each stream may take; larger ones are refused before they are copied
#: (images, clouds and topologies: zenoh's own message limit)
STREAM_BYTE_LIMITS = {
    "calibration": 64 * 1024,
    "learner/status": 64 * 1024,
    "eos": 64 * 1024,
    "color": MAX_MESSAGE_BYTES,
    "depth": MAX_MESSAGE_BYTES,
    "points": MAX_MESSAGE_BYTES,
    "topology": MAX_MESSAGE_BYTES,
}


#: streams not in STREAM_BYTE_LIMITS
OTHER_STREAM_BYTE_LIMIT = 4 * 1024 * 1024


#: bytes the inbox may hold while the logger is busy
DEFAULT_QUEUE_MB = 256


def stream_of(key: str) -> str:
    """``learner/status`` of ``gngdt/<cam>/learner/status``."""
    return key.split("/", 2)[2] if key.count("/") >= 2 else ""


class Inbox:
    """Samples handed over from zenoh's threads; the callbacks never block.

    Images and clouds keep only the newest sample per key (older ones are counted as dropped);
    the other streams (calibration, topology, status) queue in arrival order. What it holds is
    bounded in bytes (``max_bytes``): a sample over its stream's limit (``STREAM_BYTE_LIMITS``)
    is refused before it is copied, and when the inbox is full the oldest queued samples make
    room; each is counted. Ends of stream are kept apart and never evicted (64 at most).
    """

    def __init__(self, max_bytes: int = DEFAULT_QUEUE_MB * 1024 * 1024,
                 wanted: Callable[[str, bytes | None], bool] | None = None) -> None:
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[bytes, bytes | None]] = {}
        self._queued: deque[tuple[str, bytes, bytes | None]] = deque()
        self._ends: list[tuple[str, bytes, bytes | None]] = []
        self._bytes = 0
        self.max_bytes = max_bytes
        self.dropped = 0
        self.oversized = 0
        self.arrived = threading.Event()
        #: asked before a payload is copied: frames the outputs would skip are not (``skipped``)
        self.wanted = wanted
        self.skipped = 0

    def put(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        stream = stream_of(key)
        if stream not in LOGGED_STREAMS:
            return
        size = len(sample.payload)
        if size > STREAM_BYTE_LIMITS.get(stream, OTHER_STREAM_BYTE_LIMIT) or size > self.max_bytes:
            with self._lock:
                self.oversized += 1
            return
        attachment = sample.attachment
        attachment = attachment.to_bytes() if attachment is not None and len(attachment) <= 64 \
            else None
        if self.wanted is not None and not self.wanted(key, attachment):
            self.skipped += 1
            return
        payload = sample.payload.to_bytes()
        with self._lock:
            if stream == "eos":
                if len(self._ends) < 64:
                    self._ends.append((key, payload, attachment))
                else:
                    self.dropped += 1
            elif stream in LATEST_ONLY_STREAMS:
                previous = self._latest.pop(key, None)
                if previous is not None:
                    self.dropped += 1
                    self._bytes -= len(previous[0])
                if self._make_room(size):
                    self._latest[key] = (payload, attachment)
                    self._bytes += size
            elif self._make_room(size):
                self._queued.append((key, payload, attachment))
                self._bytes += size
        self.arrived.set()

    def _make_room(self, size: int) -> bool:
        """Evict the oldest queued samples until ``size`` more bytes fit; False (the new sample
        is dropped) if they cannot."""
        while self._bytes + size > self.max_bytes and self._queued:
            self._bytes -= len(self._queued.popleft()[1])
            self.dropped += 1
        if self._bytes + size > self.max_bytes:
            self.dropped += 1
            return False
        return True

    def take(self) -> list[tuple[str, bytes, bytes | None]]:
        """Everything waiting: queued messages first (calibration before images), then latest,
        then the ends of stream."""
        with self._lock:
            taken = list(self._queued)
            taken += [(key, *value) for key, value in self._latest.items()]
            taken += self._ends
            self._queued.clear()
            self._latest.clear()
            self._ends = []
            self._bytes = 0
            self.arrived.clear()
        return taken
