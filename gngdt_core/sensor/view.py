"""What the sensor saw in one batch, and which nodes it could have seen (see `kernels.view`).

Used by `GNGDT` to judge only those nodes when forgetting, and by the metrics over time (ghost
share). Pure computation on arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gngdt.core.kernels import view as V

#: cells are sized so that a batch puts about this many points in each (fewer points: coarser);
#: at 8 a cell is empty by chance once in ~3,000, so a node's neighbourhood rarely looks holed
POINTS_PER_CELL = 8.0
#: finest cell, in normalised image units (0.002 is ~1 pixel of a VGA Kinect)
MIN_CELL = 0.002
#: the grid never has more cells than this along a side
MAX_CELLS_PER_SIDE = 512


@dataclass(frozen=True)
class SensorView:
    """A batch's depth grid: ``zmax`` and ``zmin`` (rows, columns) float64 farthest and nearest
    depth per cell (0: none), cells ``1 / inv_cell`` wide from ``(u_min, v_min)`` in normalised
    image coordinates."""

    zmax: np.ndarray
    zmin: np.ndarray
    u_min: float
    v_min: float
    inv_cell: float
    #: `kernels.view.measured_counts` of zmax
    measured: np.ndarray

    @classmethod
    def of(cls, camera_points: np.ndarray) -> SensorView | None:
        """The view of ``camera_points`` (M, 3) in the camera frame (x right, y down, z
        forward); None when no point is in front of the camera."""
        points = np.asarray(camera_points)
        u_min, u_max, v_min, v_max, count = V.view_bounds(points)
        if count == 0:
            return None
        width, height = max(u_max - u_min, 0.0), max(v_max - v_min, 0.0)
        cell = max(math.sqrt(width * height * POINTS_PER_CELL / count), MIN_CELL,
                   max(width, height) / (MAX_CELLS_PER_SIDE - 1))
        columns = int(width / cell) + 1
        rows = int(height / cell) + 1
        zmax = np.zeros((rows, columns))
        zmin = np.zeros((rows, columns))
        V.fill_depth_grid(points, u_min, v_min, 1.0 / cell, zmax, zmin)
        return cls(zmax, zmin, float(u_min), float(v_min), 1.0 / cell, V.measured_counts(zmax))

    def judge(self, positions: np.ndarray, n: int, camera_from_model: np.ndarray,
              margin: float, reach: float, seen: np.ndarray) -> None:
        """Write into ``seen[:n]`` (uint8) which of ``positions[:n]`` (model frame, float64) the
        sensor could have seen; ``margin``: depth tolerance as a fraction of the depth; ``reach``:
        how far around a node must be in view, model units (the node spacing)."""
        V.judge_nodes(positions, n, camera_from_model, self.zmax, self.measured, self.u_min,
                      self.v_min, self.inv_cell, float(margin), float(reach), seen)

    def seen_through(self, points: np.ndarray, n: int, camera_from_model: np.ndarray,
                     margin: float) -> np.ndarray:
        """(n,) bool: which of ``points[:n]`` (model frame, float64) the sensor saw through: in
        front of the nearest depth measured in their cell by more than ``margin`` times it."""
        through = np.zeros(n, dtype=np.uint8)
        V.seen_through(points, n, camera_from_model, self.zmin, self.u_min, self.v_min,
                       self.inv_cell, float(margin), through)
        return through.astype(bool)

    def near_unmeasured(self, positions: np.ndarray, camera_from_model: np.ndarray,
                        reach: float) -> np.ndarray:
        """(n,) bool: which of ``positions`` (n, 3) (model frame, float64) have a cell without
        depth, or the view's edge, within ``reach`` (model units) on the image."""
        near = np.zeros(len(positions), dtype=np.uint8)
        V.near_unmeasured(positions, len(positions), camera_from_model, self.measured,
                          self.u_min, self.v_min, self.inv_cell, float(reach), near)
        return near.astype(bool)

    def gap_samples(self, positions: np.ndarray, pairs: np.ndarray,
                    camera_from_model: np.ndarray, margin: float,
                    samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Of ``samples`` points evenly inside each segment ``pairs`` (P, 2) of ``positions``
        (model frame, float64): (P,) how many fall where the sensor measured no depth, (P,)
        how many where it measured something else (saw through them, or a nearer surface hid
        them; ``margin`` as a fraction of the depth) or could not see, and (P,) how many of
        those a nearer surface hid."""
        missing, blocked, hidden = (np.zeros(len(pairs), dtype=np.int64) for _ in range(3))
        V.gap_samples(positions, pairs, camera_from_model, self.zmin, self.zmax, self.u_min,
                      self.v_min, self.inv_cell, float(margin), int(samples), missing, blocked,
                      hidden)
        return missing, blocked, hidden


def node_spacing(node_positions: np.ndarray) -> float:
    """Median distance from a node to its nearest other node (0 with fewer than two)."""
    from scipy.spatial import cKDTree

    if len(node_positions) < 2:
        return 0.0
    distances, _ = cKDTree(node_positions).query(node_positions, k=2)
    return float(np.median(distances[:, 1]))


def seen_nodes(node_positions: np.ndarray, camera_points: np.ndarray,
               camera_pose: np.ndarray | None = None, margin: float = 0.05,
               reach: float | None = None) -> np.ndarray:
    """(N,) bool: which nodes (``node_positions`` (N, 3), model frame) the sensor could have
    seen in a batch of ``camera_points`` (M, 3), camera frame. ``camera_pose`` (4, 4)
    camera-to-model (None: the model is in the camera frame); ``reach``: how far around a node
    must be in view (default: `node_spacing`)."""
    positions = np.ascontiguousarray(node_positions, dtype=np.float64)
    seen = np.zeros(len(positions), dtype=np.uint8)
    view = SensorView.of(camera_points)
    if view is not None and len(positions):
        camera_from_model = np.eye(4) if camera_pose is None else rigid_inverse(camera_pose)
        spacing = node_spacing(positions) if reach is None else reach
        view.judge(positions, len(positions), camera_from_model, margin, spacing, seen)
    return seen.astype(bool)


def see_batch(camera_samples: np.ndarray, camera_pose: np.ndarray | None,
              positions: np.ndarray, n: int, judged: np.ndarray | None, dim: int,
              spacing: float, margin: float, memory: Any = None) -> None:
    """What a batch's sensor saw: mark in ``judged`` (N,) uint8 (None: not forgetting) the
    nodes it judges (forgetting): in 3-D, those of ``positions`` (first ``n`` rows, model
    frame) it could have seen given these camera-frame samples (M, 3) and ``camera_pose``
    (4, 4) camera-to-model (None: the model is in the camera frame); in 2-D, all of them
    (plain GNG-U); and drop the samples of ``memory`` (a `SampleMemory`, rehearsal) it saw
    through. ``spacing``: the running node spacing; ``margin``: ``view_depth_margin``."""
    if judged is not None:
        judged[:n] = 1 if dim != 3 else 0
    if dim != 3:
        return
    view = SensorView.of(camera_samples)
    if view is None:
        return
    camera_from_model = np.eye(4) if camera_pose is None else rigid_inverse(camera_pose)
    if judged is not None:
        view.judge(positions, n, camera_from_model, margin, spacing, judged)
    if memory is not None:
        memory.carve(view, camera_from_model, margin)


def rigid_inverse(matrix: np.ndarray) -> np.ndarray:
    """(4, 4) inverse of a rigid transform (rotation and translation)."""
    inverse = np.eye(4)
    rotation_t = np.asarray(matrix, dtype=np.float64)[:3, :3].T
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ np.asarray(matrix, dtype=np.float64)[:3, 3]
    return inverse
