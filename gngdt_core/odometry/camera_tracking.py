"""The learner's camera tracking (``gngdt learn --track``): the pose of each cloud that comes
without one, found by aligning it to the map learned so far (`gngdt.core.odometry.map_odometry`).

The first tracked cloud starts the map: its camera frame becomes the fixed frame
``TRACKED_FRAME`` (the camera's pose there is the identity); the learner learns it longer
(``first_frame_steps``), so that the next frame is aligned to a settled map. Every later cloud
is put back on its pixels (`gngdt.core.sensor.depth.organize`, from the camera's intrinsics) and
aligned to the map as it was after the last learned frame (`update_map`: a frozen copy of the
network's surface, `MapSurface.from_model(frozen=True)`), so tracking may run in its own thread
while the map learns; when the alignment fails the cloud is lost: it is not learned, and the
next one is aligned from the last tracked pose, or relocalised against the whole map. The
poses the map was learned from are kept for that (`MapOdometry.keyframes`). Pure computation;
`locate`, `update_map` and the state are guarded by one lock.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from gngdt.core.odometry.map_odometry import MapOdometry, TrackerParams, TrackingResult
from gngdt.core.odometry.map_surface import MapSurface
from gngdt.core.sensor.depth import organize
from gngdt.core.sensor.geometry import CameraIntrinsics

#: the fixed frame of a tracked map: the first tracked camera's frame, drifting as odometry
#: does (REP 105's ``odom``)
TRACKED_FRAME = "odom"


@dataclass(frozen=True)
class Located:
    """Where one cloud was found: ``pose`` (4, 4) camera-to-``odom`` (None: lost, not to be
    learned), ``first``: it starts the map; ``result``: the alignment (None for the first);
    ``problem``: why it was lost ("" when it was not)."""

    pose: np.ndarray | None
    first: bool
    result: TrackingResult | None
    problem: str = ""


class CameraTracking:
    """Poses of unposed clouds against the map (see the module docstring)."""

    def __init__(self, params: TrackerParams | None = None) -> None:
        self.odometry = MapOdometry(params)
        #: the map as the tracker aligns to it (None before the first learned frame)
        self.surface: MapSurface | None = None
        #: the last cloud's alignment (None before the second cloud)
        self.last: TrackingResult | None = None
        #: why the last cloud could not be tracked ("" when it was)
        self.problem = ""
        self._lock = threading.RLock()
        #: set once there is a map to track against (`update_map`)
        self.map_ready = threading.Event()

    @property
    def started(self) -> bool:
        return self.odometry.pose_ is not None

    @property
    def waiting_for_map(self) -> bool:
        """The map's first frame is located but not learned yet: later frames need it."""
        return self.started and self.surface is None

    def reset(self) -> None:
        """Forget the map's frame: the next cloud starts a new map."""
        with self._lock:
            self.odometry.reset()
            self.surface, self.last, self.problem = None, None, ""
            self.map_ready.clear()

    def update_map(self, model: Any, pose: np.ndarray | None) -> None:
        """The map after learning a frame (``model``, a fitted 3-D `GNGDT` in
        ``TRACKED_FRAME``) taken at ``pose`` (kept as a keyframe for relocalisation)."""
        surface = MapSurface.from_model(model, frozen=True)  # built outside the lock
        with self._lock:
            self.surface = surface
            if pose is not None:
                self.odometry.remember_keyframe(pose)
            self.map_ready.set()

    def locate(self, positions: np.ndarray, colors: np.ndarray | None,
               camera: CameraIntrinsics | None, stamp_ns: int | None = None) -> Located:
        """The pose of a cloud (``positions`` (N, 3) float32 metres, camera frame, as its
        depth image's valid pixels deprojected with ``camera``; ``colors`` (N, 3) uint8 or
        None; ``stamp_ns`` its capture time, if known) in the map of the last `update_map`."""
        with self._lock:
            if not self.started:
                self.odometry.reset(np.eye(4), stamp_ns)
                self.problem = ""
                return Located(np.eye(4), True, None)
            surface = self.surface
        if camera is None:
            return self._lost("no calibration")
        if surface is None:
            return self._lost("no map")
        stride = self.odometry.pixel_stride  # the pixels between are never looked at
        organized, image = organize(positions, colors, camera.width, camera.height, camera.fx,
                                    camera.fy, camera.cx, camera.cy, stride)
        with self._lock:
            result = self.odometry.track(organized, image, surface, stamp_ns=stamp_ns,
                                         stride=stride)
            self.last, self.problem = result, result.reason
        return Located(None if result.lost else result.pose, False, result, result.reason)

    def _lost(self, problem: str) -> Located:
        with self._lock:
            self.problem = problem
            self.odometry.n_lost_ += 1
        return Located(None, False, None, problem)

    def get_state(self) -> dict[str, np.ndarray]:
        """The tracker's state (pose, motion, keyframes, plane memory) as arrays, for a
        checkpoint."""
        with self._lock:
            return self.odometry.get_state()

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        with self._lock:
            self.odometry.set_state(state)
