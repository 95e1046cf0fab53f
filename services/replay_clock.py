"""The clocks of a replay: when each frame of a file leaves (its recorded spacing over a rate,
long gaps shortened) and the sensor time its cloud carries (the file's own timing from the
replay's start, whatever the load)."""

from __future__ import annotations

import logging
import threading
import time

log = logging.getLogger(__name__)

#: longest wait between two frames at the recorded rate
DEFAULT_MAX_GAP_S = 5.0


class ReplayClock:
    """Sleeps so that frames leave at their recorded spacing divided by ``rate``.

    A gap between two frames longer than ``max_gap_s`` (after the rate) is shortened to it, with a
    warning: a recording with a jump in its stamps must not stall the pipeline for days.
    """

    def __init__(self, rate: float | None, max_gap_s: float = DEFAULT_MAX_GAP_S) -> None:
        if rate is not None and rate <= 0:
            raise ValueError(f"--rate must be positive, got {rate}")
        if max_gap_s <= 0:
            raise ValueError(f"--max-gap must be positive, got {max_gap_s}")
        self.rate = rate
        self.max_gap_s = max_gap_s
        self._due = 0.0
        self._previous_ns: int | None = None

    def wait_for(self, recorded_ns: int, stop: threading.Event, frame_index: int = 0) -> None:
        if self.rate is None:
            return
        if self._previous_ns is None or recorded_ns < self._previous_ns:
            # first frame, or a loop restarted the recording
            self._due = time.monotonic()
        else:
            gap_s = (recorded_ns - self._previous_ns) * 1e-9 / self.rate
            if gap_s > self.max_gap_s:
                log.warning("frame %d is stamped %.3g s after the previous one; waiting %g s "
                            "instead (--max-gap)", frame_index, gap_s, self.max_gap_s)
                gap_s = self.max_gap_s
            self._due += gap_s
        self._previous_ns = recorded_ns
        delay = self._due - time.monotonic()
        if delay > 1.0:
            log.info("waiting %.1f s for frame %d (its recorded time)", delay, frame_index)
        while delay > 0 and not stop.wait(min(delay, 0.5)):  # short waits: see lifecycle
            delay = self._due - time.monotonic()


class RecordedClock:
    """Sensor times of a file read frame by frame: the time the replay started plus each
    frame's recorded time since the first frame, so that the learner's motion and pose checks
    see the recording's own timing whatever the load (the attachments keep the time each frame
    was sent: latency is measured from there)."""

    def __init__(self) -> None:
        self._start_ns = time.time_ns()
        self._first_ns: int | None = None
        self._last_ns = 0

    def stamp(self, recorded_ns: int) -> int:
        if self._first_ns is None or recorded_ns < self._first_ns:  # first, or a loop restarted
            self._start_ns = max(time.time_ns(), self._last_ns + 1)
            self._first_ns = recorded_ns
        self._last_ns = self._start_ns + recorded_ns - self._first_ns
        return self._last_ns
