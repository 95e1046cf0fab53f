"""The learner's tracker thread (``--track``): every frame posed as it arrives, apart from
learning.

Each points sample goes into a short queue (`FrameQueue`; when it is full the oldest waiting
frame goes, counted as dropped); the tracker thread decodes it, aligns it to the map as it was
after the last learned frame (`FrameLearner.locate`), publishes the camera's pose at once on
``gngdt/<cam>/tf``, and hands the frame to the learner (`Handover`). The learner learns, of the
frames handed over while it learned the last one, the one that adds most to the map
(`gngdt.core.learner.keyframes`), and acknowledges every one (learned, posed, or lost and why).
While the map's first frame is being learned, later frames wait for it (`FIRST_MAP_WAIT_S`).
A file read frame by frame (one frame in flight) is tracked and learned frame after frame, so it
gives the same poses and map whatever the load.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gngdt.core.learner.results import FrameResult
from gngdt.services.learner.inbound import (
    Arrival,
    Received,
    arrive,
    points_limit_bytes,
    receive,
)

if TYPE_CHECKING:
    import zenoh

    from gngdt.core.learner.frame_learner import FrameLearner
    from gngdt.core.sensor.geometry import CameraIntrinsics

log = logging.getLogger(__name__)

#: frames waiting for the tracker at most (a second at 30 fps: the map's first frame is learned
#: meanwhile); beyond it the oldest is dropped
QUEUE_FRAMES = 32
#: how long later frames wait for the map's first frame to be learned, at most
FIRST_MAP_WAIT_S = 30.0
#: the learner learns a frame while at most this many wait for the tracker (posing every frame
#: comes first, learning takes the time that is left) ...
TRACKER_BACKLOG = 2
#: ... and, however far behind the tracker is, at least one this often (seconds): a camera
#: moving into new ground needs the map to grow with it
MAX_MAP_AGE_S = 0.25


class FrameQueue:
    """Points samples waiting to be taken (by the tracker; without one, by the learner: a queue
    of one, the latest wins), oldest first, filled from zenoh's thread. Each is copied out of
    zenoh as it arrives (`receive`: its payload within the limit of ``max_cloud_points``)."""

    def __init__(self, max_cloud_points: int, capacity: int = QUEUE_FRAMES) -> None:
        self._samples: deque[Received] = deque(maxlen=capacity)
        self._limit_bytes = points_limit_bytes(max_cloud_points)
        self._arrived = threading.Condition()
        self.dropped = 0

    def put(self, sample: zenoh.Sample) -> None:
        received = receive(sample, self._limit_bytes)
        with self._arrived:
            self.dropped += len(self._samples) == self._samples.maxlen
            self._samples.append(received)
            self._arrived.notify()

    def __len__(self) -> int:
        with self._arrived:
            return len(self._samples)

    def get(self, timeout_s: float) -> Received | None:
        with self._arrived:
            if not self._samples:
                self._arrived.wait(timeout_s)
            return self._samples.popleft() if self._samples else None

    def wait(self, timeout_s: float) -> None:
        """Until a sample waits (taking none), at most ``timeout_s`` seconds."""
        with self._arrived:
            if not self._samples:
                self._arrived.wait(timeout_s)


@dataclass(frozen=True)
class Tracked:
    """One frame as the tracker hands it to the learner: what arrived, and where its camera was
    (None: it came with a pose of its own, or malformed)."""

    arrival: Arrival
    located: FrameResult | None


class Handover:
    """Tracked frames waiting for the learner, in arrival order."""

    def __init__(self) -> None:
        self._frames: list[Tracked] = []
        self._handed = threading.Condition()

    def put(self, tracked: Tracked) -> None:
        with self._handed:
            self._frames.append(tracked)
            self._handed.notify()

    def take(self) -> list[Tracked]:
        """Every frame handed over since the last call."""
        with self._handed:
            frames, self._frames = self._frames, []
        return frames

    def wait(self, timeout_s: float) -> None:
        """Until the tracker hands a frame over (or one waits already), at most
        ``timeout_s`` seconds."""
        with self._handed:
            if not self._frames:
                self._handed.wait(timeout_s)


class TrackerThread(threading.Thread):
    """Poses every frame of ``queue`` as it comes (see the module docstring)."""

    def __init__(self, learner: FrameLearner, queue: FrameQueue, handover: Handover,
                 calibration: Callable[[], CameraIntrinsics | None],
                 publish_pose: Callable[[Arrival, FrameResult], None]) -> None:
        super().__init__(name="tracker", daemon=True)
        self.learner = learner
        self.queue = queue
        self.handover = handover
        self.calibration = calibration
        self.publish_pose = publish_pose
        self.stopping = threading.Event()
        #: the reason the thread died, if it did (said by the learner)
        self.failure: BaseException | None = None

    def run(self) -> None:
        try:
            while not self.stopping.is_set():
                received = self.queue.get(0.1)
                if received is not None:
                    self.handover.put(self.track(received))
        except BaseException as error:  # said and acted on by the learner's loop
            self.failure = error

    def track(self, received: Received) -> Tracked:
        """Decode one sample and, when its cloud has no pose, find it."""
        arrival = arrive(received, self.learner.options.max_cloud_points)
        cloud = arrival.cloud
        if cloud is None or cloud.pose is not None:
            return Tracked(arrival, None)
        self._wait_for_first_map()
        located = self.learner.locate(cloud.positions, cloud.colors, self.calibration(),
                                      cloud.sensor_ns)
        if located.posed:
            self.publish_pose(arrival, located)
        return Tracked(arrival, located)

    def _wait_for_first_map(self) -> None:
        """A frame after the map's first waits until that one is learned (bounded)."""
        tracking = self.learner.tracking
        if tracking.waiting_for_map:
            tracking.map_ready.wait(FIRST_MAP_WAIT_S)

    def stop(self) -> None:
        self.stopping.set()
        self.join(5.0)
