"""Node planes refined by the frames a camera tracker aligned (`gngdt.core.odometry.map_odometry`).

A GNG node moves with every sample it wins (eta1 times the sensor noise) and, on a sparse map,
stands for several centimetres of surface: aligning frames to its raw tangent plane leaves
millimetres of error per frame. The plane memory keeps, per node (by its persistent id), a
point on its plane: the node moved along its normal by the running mean of the residuals of the
points tracked frames paired with it (over at most ``capacity`` points), stored as an absolute
point so that node jitter does not move it. Each side of a plane is remembered apart (a node in
a thin panel stands for two faces seen from opposite sides), told apart against a fixed
direction, since the model orients its normals toward the last camera. A remembered plane
farther than ``reset_m`` from its node is forgotten (the surface moved). Pure computation.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: a fixed direction telling the two sides of a node's plane apart (any direction few surface
#: normals are perpendicular to)
SIDE_DIRECTION = np.array([0.267, 0.535, 0.802])


class PlaneMemory:
    """Per node id and side: a point on its plane (3,), the points averaged into it, and their
    mean squared normalised residual about it (its spread).

    ids: (K,) int64 sorted; points: (K, 2, 3) metres; counts: (K, 2); spread: (K, 2).
    """

    def __init__(self, capacity: int, reset_m: float) -> None:
        self.capacity = capacity
        self.reset_m = reset_m
        self.ids = np.zeros(0, dtype=np.int64)
        self.points = np.zeros((0, 2, 3))
        self.counts = np.zeros((0, 2))
        self.spread = np.zeros((0, 2))

    def _lookup(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row of each id in the memory, whether it is there) for (N,) ``ids``."""
        if not len(self.ids):
            return np.zeros(len(ids), dtype=np.intp), np.zeros(len(ids), dtype=bool)
        at = np.clip(np.searchsorted(self.ids, ids), 0, len(self.ids) - 1)
        return at, self.ids[at] == ids

    def anchors(self, positions: np.ndarray, normals: np.ndarray, ids: np.ndarray | None,
                camera: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per node (``positions``, ``normals`` (N, 3), ``ids`` (N,) or None), for the side of
        its plane facing ``camera`` (3,) (the camera centre, map frame): (N, 3) a point on the
        plane (the node moved along its normal by the remembered offset, or the node itself),
        (N,) points averaged into it, (N,) their spread (1 where unknown), and (N,) int the
        side (0: the normal's, 1: the other)."""
        anchors = positions.copy()
        facing = np.sign(np.einsum("nk,nk->n", camera - anchors, normals))
        side = (facing * (normals @ SIDE_DIRECTION) < 0).astype(np.intp)
        counts = np.zeros(len(anchors))
        spread = np.ones(len(anchors))
        if not self.capacity or ids is None or not len(self.ids):
            return anchors, counts, spread, side
        at, known = self._lookup(ids)
        offset = np.einsum("nk,nk->n", self.points[at, side] - anchors, normals)
        known &= self.counts[at, side] > 0
        known &= np.abs(offset) < self.reset_m  # the surface moved: start again
        anchors[known] += offset[known, None] * normals[known]
        counts[known] = self.counts[at[known], side[known]]
        spread[known] = self.spread[at[known], side[known]]
        return anchors, counts, spread, side

    def remember(self, positions: np.ndarray, normals: np.ndarray, ids: np.ndarray,
                 planes: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                 node: np.ndarray, residual: np.ndarray, sigma: np.ndarray) -> None:
        """Average a tracked frame's inlier residuals into each node's plane (the side seen),
        and their squared normalised deviation from it into the node's spread.

        planes: `anchors`' result for this frame; node (M,) each inlier's node row, residual
        (M,) its point-to-plane residual and sigma (M,) its noise, metres."""
        anchors, counts, spread, side = planes
        n = len(anchors)
        total = counts + np.bincount(node, minlength=n)
        shift = np.bincount(node, weights=residual, minlength=n) / np.maximum(total, 1.0)
        deviation = np.bincount(node, weights=((residual - shift[node]) / sigma) ** 2,
                                minlength=n)
        spread = (counts * spread + deviation) / np.maximum(total, 1.0)
        spread[total == 0] = 1.0
        # carry the other side over from the memory, write the side seen
        new_points = np.repeat(positions[:, None, :], 2, axis=1)
        new_counts = np.zeros((n, 2))
        new_spread = np.ones((n, 2))
        at, known = self._lookup(ids)
        new_points[known] = self.points[at[known]]
        new_counts[known] = self.counts[at[known]]
        new_spread[known] = self.spread[at[known]]
        rows = np.arange(n)
        new_points[rows, side] = anchors + shift[:, None] * normals
        new_counts[rows, side] = np.minimum(total, self.capacity)
        new_spread[rows, side] = spread
        order = np.argsort(ids)
        self.ids, self.points = ids[order], new_points[order]
        self.counts, self.spread = new_counts[order], new_spread[order]

    def get_state(self) -> dict[str, np.ndarray]:
        return {"plane_ids": self.ids.copy(), "plane_points": self.points.copy(),
                "plane_counts": self.counts.copy(), "plane_spread": self.spread.copy()}

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue from `get_state`'s arrays; ValueError when they do not fit together."""
        ids = np.asarray(state["plane_ids"], dtype=np.int64).reshape(-1)
        n = len(ids)
        points = np.asarray(state["plane_points"], dtype=np.float64)
        counts = np.asarray(state["plane_counts"], dtype=np.float64)
        spread = np.asarray(state["plane_spread"], dtype=np.float64)
        if points.shape != (n, 2, 3) or counts.shape != (n, 2) or spread.shape != (n, 2):
            raise ValueError("tracker state: plane memory arrays do not match their ids")
        if n and np.any(np.diff(ids) <= 0):
            raise ValueError("tracker state: plane ids must be sorted and unique")
        if not (np.isfinite(points).all() and np.isfinite(counts).all()
                and np.isfinite(spread).all()):
            raise ValueError("tracker state: plane memory must be finite")
        self.ids, self.points = ids.copy(), points.copy()
        self.counts, self.spread = counts.copy(), spread.copy()
