"""The learner's camera tracking (``gngdt learn --track``): the pose of each cloud that comes
without one, found by aligning it to the map learned so far (`gngdt.core.odometry.map_odometry`).

The first tracked cloud starts the map: its camera frame becomes the fixed frame
``TRACKED_FRAME`` (the camera's pose there is the identity); the learner learns it longer
(``first_frame_steps``), so that the next frame is aligned to a settled map. Every later cloud
is put back on its pixels (`gngdt.core.sensor.depth.organize`, from the camera's intrinsics) and
aligned to the map's surface (`MapSurface.from_model`); when the alignment fails the cloud is
lost: it is not learned, and the next one is aligned from the last tracked pose. The map must
not learn between `CameraTracking.locate` and the learning of the cloud it located (the surface
searches the model's own grid). Pure computation.
"""

from __future__ import annotations

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
    learned), ``first``: it starts the map; ``result``: the alignment (None for the first)."""

    pose: np.ndarray | None
    first: bool
    result: TrackingResult | None


class CameraTracking:
    """Poses of unposed clouds against the map (see the module docstring)."""

    def __init__(self, params: TrackerParams | None = None) -> None:
        self.odometry = MapOdometry(params)
        #: the last cloud's alignment (None before the second cloud)
        self.last: TrackingResult | None = None
        #: why the last cloud could not be tracked ("" when it was)
        self.problem = ""

    @property
    def started(self) -> bool:
        return self.odometry.pose_ is not None

    def reset(self) -> None:
        """Forget the map's frame: the next cloud starts a new map."""
        self.odometry.reset()
        self.last, self.problem = None, ""

    def locate(self, model: Any, positions: np.ndarray, colors: np.ndarray | None,
               camera: CameraIntrinsics | None, stamp_ns: int | None = None) -> Located:
        """The pose of a cloud (``positions`` (N, 3) float32 metres, camera frame, as its
        depth image's valid pixels deprojected with ``camera``; ``colors`` (N, 3) uint8 or
        None; ``stamp_ns`` its capture time, if known) in the map ``model`` (a `GNGDT` learned
        in ``TRACKED_FRAME``, or None)."""
        if not self.started or model is None or model.n_nodes_ == 0:
            self.odometry.reset(np.eye(4), stamp_ns)
            self.problem = ""
            return Located(np.eye(4), True, None)
        if camera is None:
            self.problem = "no calibration"
            self.odometry.n_lost_ += 1
            return Located(None, False, None)
        organized, image = organize(positions, colors, camera.width, camera.height, camera.fx,
                                    camera.fy, camera.cx, camera.cy)
        result = self.odometry.track(organized, image, MapSurface.from_model(model),
                                     stamp_ns=stamp_ns)
        self.last, self.problem = result, result.reason
        return Located(None if result.lost else result.pose, False, result)

    def get_state(self) -> dict[str, np.ndarray]:
        """The tracker's state (pose, motion, plane memory) as arrays, for a checkpoint."""
        return self.odometry.get_state()

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.odometry.set_state(state)
