"""How a live learner spends the time between two frames, so that it keeps up with its camera.

A live learner receives a frame every ``interval`` seconds and may spend ``share`` of it on the
frame. Its work on a frame is learning (a fixed part, ``overhead``, plus the steps) and, after
some frames, publishing what it learned (segmentation, topology, objects, scene, status: a cost
``publish`` that does not shrink with the steps). Latest-frame-wins delivery drops the frames
that arrive while it is busy; so, rather than learn a few frames fully and drop the rest:

- **publishing** happens at most every ``publish_every_s`` of the stream's own clock (the
  frames' sensor times: the same frames of a file on every run, whatever the load), and takes at
  most ``PUBLISH_SHARE`` of the time: the learner publishes when at least ``publish /
  PUBLISH_SHARE`` seconds (and one frame interval) went by since it last did, or when it is ahead
  (it waited for the frame), so a busy machine publishes less often, and every learned frame is
  still learned;
- **learning**: each frame gets the steps that fit in what is left, ``share * interval -
  overhead - publish * interval / period``, at the steps per second measured on the last frames,
  within ``min_steps`` .. ``max_steps``. A learner that had to wait for the frame (it is ahead)
  gets a quarter more steps than the last frame, up to ``max_steps``: a producer that waits for
  the learner (a replay in lockstep) is never starved by its own pace.

The interval is the median spacing of the last frames' capture times, never shorter than
``min_interval_s`` (a camera's frame time: frames replayed faster than that still drop, as
before); speeds and costs are running medians, so one slow frame (a checkpoint, a page fault)
does not starve the next. Pure computation: the caller measures the times.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

#: frames the running medians look back over
WINDOW = 15
#: the shortest frame interval a budget is made for: 30 frames a second
MIN_INTERVAL_S = 1.0 / 30.0
#: publishing takes at most this share of the time
PUBLISH_SHARE = 0.25
#: ... and happens at least this often (seconds)
MAX_PUBLISH_PERIOD_S = 1.0
#: a learner that waited for its frame gets this many times the last frame's steps (up to max)
GROWTH = 1.25
#: a frame this close to its publication time (of the stream's clock) is published: a camera's
#: timestamps jitter, and 30 fps stamps three frames apart may fall a nanosecond short of 0.1 s
PUBLISH_SLACK_NS = 2_000_000


@dataclass(frozen=True)
class Budget:
    """One frame's budget: ``steps`` to learn in ``seconds`` of learning, a frame time of
    ``interval_s`` and a publication every ``publish_period_s`` (0 before the measurements:
    then ``steps`` is the maximum and every frame is published)."""

    steps: int
    seconds: float
    interval_s: float
    publish_period_s: float = 0.0


class StepBudget:
    """Learning steps and publications per frame from the time a live learner has (see the
    module docstring). share: of the frame interval, the part the learner may spend on a frame
    (0: no budget, every frame gets ``max_steps`` and is published); min_steps, max_steps: the
    bounds of a frame's steps; publish_every_s: the shortest time between two publications on
    the stream's clock (0: no such bound)."""

    def __init__(self, share: float, min_steps: int, max_steps: int,
                 min_interval_s: float = MIN_INTERVAL_S, publish_every_s: float = 0.0) -> None:
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"share must be in [0, 1], got {share}")
        if not 1 <= min_steps <= max_steps:
            raise ValueError(f"need 1 <= min_steps ({min_steps}) <= max_steps ({max_steps})")
        self.share = share
        self.min_steps = min_steps
        self.max_steps = max_steps
        self.min_interval_s = min_interval_s
        if publish_every_s < 0:
            raise ValueError(f"publish_every_s must be >= 0, got {publish_every_s}")
        self.publish_every_ns = round(publish_every_s * 1e9)
        self._last_published_sensor_ns: int | None = None
        self._intervals: deque[float] = deque(maxlen=WINDOW)
        self._speeds: deque[float] = deque(maxlen=WINDOW)
        self._overheads: deque[float] = deque(maxlen=WINDOW)
        self._publishing: deque[float] = deque(maxlen=WINDOW)
        self._last_stamp: tuple[int, int] | None = None
        self._waited = False
        self._skipped = False  # frames before the last one were dropped on the way
        self._last_published = -np.inf
        self.last = Budget(max_steps, 0.0, 0.0)

    def arrived(self, sequence: int, capture_time_ns: int, waited: bool = False) -> None:
        """A frame arrived: its sequence number and capture time (ns), and whether the learner
        was idle, waiting for it. The interval is the time between two received frames over the
        sequence numbers between them (frames dropped on the way count)."""
        if self._last_stamp is not None:
            frames = sequence - self._last_stamp[0]
            seconds = (capture_time_ns - self._last_stamp[1]) * 1e-9
            if 0 < frames and seconds > 0:
                self._intervals.append(seconds / frames)
        self._skipped = self._last_stamp is not None and sequence - self._last_stamp[0] > 1
        self._last_stamp = (sequence, capture_time_ns)
        self._waited = waited

    def learned(self, steps: int, learn_seconds: float, frame_seconds: float) -> None:
        """A frame was learned: ``steps`` in ``learn_seconds``, the whole frame but publishing
        (decoding, the steps' fixed costs, tracking) in ``frame_seconds``."""
        if steps > 0 and learn_seconds > 0:
            self._speeds.append(steps / learn_seconds)
        self._overheads.append(max(0.0, frame_seconds - learn_seconds))

    def published(self, seconds: float, now: float, sensor_ns: int) -> None:
        """What was learned was published, in ``seconds``, at time ``now`` (seconds), the frame
        taken by the sensor at ``sensor_ns`` (the stream's clock, ns)."""
        self._publishing.append(seconds)
        self._last_published = now
        self._last_published_sensor_ns = sensor_ns

    def publish_due(self, now: float, sensor_ns: int) -> bool:
        """Whether to publish after this frame (time ``now``, seconds, as given to
        `published`; taken by the sensor at ``sensor_ns``): ``publish_every_s`` of the stream's
        clock went by since the last publication (or that clock went back: a looped file, a
        restarted camera), and the learner's own period is over or it is ahead (it waited for
        the frame). With the stream's clock (``publish_every_s`` > 0) a learner that drops no
        frames (a replay it paces) publishes what that clock says, whatever its own pace: the
        same frames on every run."""
        last = self._last_published_sensor_ns
        if last is not None and 0 <= sensor_ns - last < self.publish_every_ns - PUBLISH_SLACK_NS:
            return False
        if self.publish_every_ns and not self._skipped:
            return True
        return self._waited or now - self._last_published >= self.last.publish_period_s

    def next(self) -> Budget:
        """The budget of the next frame (also kept as ``last``)."""
        if not self._intervals or (self.share and not self._speeds):
            self.last = Budget(self.max_steps, 0.0, 0.0)
            return self.last
        interval = max(float(np.median(self._intervals)), self.min_interval_s)
        publish = float(np.median(self._publishing)) if self._publishing else 0.0
        period = min(max(interval, publish / PUBLISH_SHARE), MAX_PUBLISH_PERIOD_S)
        if not self.share:  # every frame learned fully; publishing still kept to its share
            self.last = Budget(self.max_steps, 0.0, interval, period)
            return self.last
        seconds = max(0.0, interval * self.share - float(np.median(self._overheads))
                      - publish * interval / period)
        steps = int(float(np.median(self._speeds)) * seconds)
        if self._waited:  # ahead of the camera: take more time
            steps = max(steps, int(GROWTH * self.last.steps))
        self.last = Budget(min(self.max_steps, max(self.min_steps, steps)), seconds, interval,
                           period)
        return self.last
