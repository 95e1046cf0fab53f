"""How many learning steps a frame gets when the learner must keep up with its camera.

A live learner receives a frame every ``interval`` seconds. It keeps up when its whole work on
a frame (learning plus everything else: segmentation, publishing) fits in ``share`` of that
interval; latest-frame-wins delivery drops the frames that arrive while it is still busy. On a
quiet machine ``max_steps`` (``samples_per_frame``) fit; when the machine is busy, fewer steps
fit in the same time, and `StepBudget` gives each frame the steps that do: the learning time
left once the rest of the work is done (``interval * share - overhead``) times the steps per
second measured on the last frames, within ``min_steps`` .. ``max_steps``. Every frame then
contributes some steps, rather than a busy learner learning a few frames fully and dropping
the rest.

The interval is the median spacing of the last frames' capture times, never shorter than
``min_interval_s`` (a camera's frame time: frames replayed faster than that still drop, as
before); speeds and overheads are running medians, so one slow frame (a checkpoint, a page
fault) does not starve the next. Pure computation: the caller measures the times.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

#: frames the running medians look back over
WINDOW = 15
#: the shortest frame interval a budget is made for: 30 frames a second
MIN_INTERVAL_S = 1.0 / 30.0


@dataclass(frozen=True)
class Budget:
    """One frame's budget: ``steps`` to learn, in ``seconds`` of learning out of a frame time
    of ``interval_s`` (0 before two frames were seen: then ``steps`` is the maximum)."""

    steps: int
    seconds: float
    interval_s: float


class StepBudget:
    """Learning steps per frame from the time a live learner has (see the module docstring).

    share: of the frame interval, the part the learner may spend on a frame (0: no budget,
    every frame gets ``max_steps``); min_steps, max_steps: the bounds of a frame's steps.
    """

    def __init__(self, share: float, min_steps: int, max_steps: int,
                 min_interval_s: float = MIN_INTERVAL_S) -> None:
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"share must be in [0, 1], got {share}")
        if not 1 <= min_steps <= max_steps:
            raise ValueError(f"need 1 <= min_steps ({min_steps}) <= max_steps ({max_steps})")
        self.share = share
        self.min_steps = min_steps
        self.max_steps = max_steps
        self.min_interval_s = min_interval_s
        self._intervals: deque[float] = deque(maxlen=WINDOW)
        self._speeds: deque[float] = deque(maxlen=WINDOW)
        self._overheads: deque[float] = deque(maxlen=WINDOW)
        self._last_stamp: tuple[int, int] | None = None
        self.last = Budget(max_steps, 0.0, 0.0)

    def arrived(self, sequence: int, capture_time_ns: int) -> None:
        """A frame arrived: its sequence number and capture time (ns); the interval is the
        time between two received frames over the sequence numbers between them (frames
        dropped on the way count)."""
        if self._last_stamp is not None:
            frames = sequence - self._last_stamp[0]
            seconds = (capture_time_ns - self._last_stamp[1]) * 1e-9
            if 0 < frames and seconds > 0:
                self._intervals.append(seconds / frames)
        self._last_stamp = (sequence, capture_time_ns)

    def learned(self, steps: int, learn_seconds: float, total_seconds: float) -> None:
        """A frame was handled: ``steps`` learned in ``learn_seconds``, the whole frame (with
        segmentation and publishing) in ``total_seconds``."""
        if steps > 0 and learn_seconds > 0:
            self._speeds.append(steps / learn_seconds)
        self._overheads.append(max(0.0, total_seconds - learn_seconds))

    def next(self) -> Budget:
        """The budget of the next frame (also kept as ``last``)."""
        if not self.share or not self._intervals or not self._speeds:
            self.last = Budget(self.max_steps, 0.0, 0.0)
            return self.last
        interval = max(float(np.median(self._intervals)), self.min_interval_s)
        seconds = max(0.0, interval * self.share - float(np.median(self._overheads)))
        steps = int(float(np.median(self._speeds)) * seconds)
        self.last = Budget(min(self.max_steps, max(self.min_steps, steps)), seconds, interval)
        return self.last
