"""A thread that handles the bridge's incoming samples off zenoh's threads, in arrival order,
holding a bounded number (the oldest are dropped when it falls behind, and counted). A sample it
cannot read is counted and skipped, never fatal."""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

log = logging.getLogger(__name__)

#: handle(stream, payload, attachment) of one sample; raises ValueError (or a subclass: the
#: decoders' errors) for a sample it cannot read
Handler = Callable[[str, bytes, bytes | None], None]
#: malformed samples are warned about one by one up to this many, then every this many
WARN_FIRST = 5
#: payload bytes that may wait (beside the sample in hand): three 4K colour images; at 8
#: samples a worker held 200 MB of them under a flood
MAX_WAITING_BYTES = 64 * 1024 * 1024


@dataclass
class WorkerCounts:
    """What a worker did: samples received, dropped (it fell behind), malformed (skipped) and
    failed (an unexpected error, logged with its traceback; skipped too)."""

    received: int = 0
    handled: int = 0
    dropped: int = 0
    malformed: int = 0
    failed: int = 0


class Worker:
    """``put`` (from any thread) queues a sample; the worker's thread hands each to ``handle``.

    At most ``capacity`` samples and ``max_bytes`` of payload wait; a new one beyond that
    evicts the oldest (counted as dropped). Samples of a stream in ``latest_only`` replace the
    one of their stream still waiting (counted as dropped too): only the newest image or cloud
    matters.
    """

    def __init__(self, name: str, handle: Handler, capacity: int = 16,
                 latest_only: tuple[str, ...] = (), max_bytes: int = MAX_WAITING_BYTES) -> None:
        self.name = name
        self.counts = WorkerCounts()
        self._handle = handle
        self._capacity = capacity
        self._max_bytes = max_bytes
        self._waiting_bytes = 0
        self._latest_only = latest_only
        self._queue: deque[tuple[str, bytes, bytes | None]] = deque()
        self._condition = threading.Condition()
        self._stopping = False
        self._busy = False
        self._thread = threading.Thread(target=self._run, name=f"ros2-{name}", daemon=True)

    def start(self) -> Worker:
        self._thread.start()
        return self

    def put(self, stream: str, payload: bytes, attachment: bytes | None) -> None:
        with self._condition:
            self.counts.received += 1
            if stream in self._latest_only:
                for index, (waiting, old, _) in enumerate(self._queue):
                    if waiting == stream:
                        del self._queue[index]
                        self._waiting_bytes -= len(old)
                        self.counts.dropped += 1
                        break
            while self._queue and (len(self._queue) >= self._capacity
                                   or self._waiting_bytes + len(payload) > self._max_bytes):
                self._waiting_bytes -= len(self._queue.popleft()[1])
                self.counts.dropped += 1
            self._queue.append((stream, payload, attachment))
            self._waiting_bytes += len(payload)
            self._condition.notify()

    def idle(self) -> bool:
        """Nothing waiting and nothing being handled."""
        with self._condition:
            return not self._queue and not self._busy

    def stop(self, timeout_s: float = 5.0) -> None:
        """Finish the sample in hand, drop the rest, end the thread."""
        with self._condition:
            self._stopping = True
            self._queue.clear()
            self._waiting_bytes = 0
            self._condition.notify()
        self._thread.join(timeout_s)

    def _run(self) -> None:
        while True:
            with self._condition:
                while not self._queue and not self._stopping:
                    self._condition.wait(0.5)
                if self._stopping:
                    return
                stream, payload, attachment = self._queue.popleft()
                self._waiting_bytes -= len(payload)
                self._busy = True
            try:
                self._handle(stream, payload, attachment)
                self.counts.handled += 1
            except ValueError as error:  # the decoders' errors: a bad sample
                self.counts.malformed += 1
                if self.counts.malformed <= WARN_FIRST or self.counts.malformed % 100 == 0:
                    log.warning("%s: skipped a bad %s sample (%d so far): %s", self.name, stream,
                                self.counts.malformed, error)
            except Exception:  # never let one sample stop the bridge
                self.counts.failed += 1
                log.exception("%s: handling a %s sample failed; skipped", self.name, stream)
            finally:
                with self._condition:
                    self._busy = False
