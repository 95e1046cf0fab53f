"""Which way is up, from what gngdt knows about a scene: no gravity sensor, so the data says.

- With camera poses (a fixed frame): a hand-held or mounted camera is held about level, so its
  up (``-y`` of its frame: x right, y down, z forward) averaged over its poses is the world's up,
  whatever the fixed frame's convention (z up in ROS and the synthetic scenes; about -y in many
  real captures).
- A static camera (its own frame): the largest plane that could be the floor or a table, i.e.
  whose normal (turned towards the camera) is within ``MAX_TILT_DEG`` of the camera's up; a
  camera pitched down by up to that much still finds its table. Without such a plane, the
  camera's own up.

Viewers take an axis, so `nearest_axis` names the frame's axis closest to the up found.
"""

from __future__ import annotations

import numpy as np

#: a plane whose normal is further than this from the camera's up is not taken for the floor
MAX_TILT_DEG = 60.0
#: planes of fewer nodes are not considered
MIN_PLANE_NODES = 20
#: a cluster whose normals' mean is shorter than this is curved, not a plane
MIN_NORMAL_AGREEMENT = 0.9
#: the camera's up in its own frame (x right, y down, z forward)
CAMERA_UP = (0.0, -1.0, 0.0)


class PoseUp:
    """The up of a fixed frame from the camera poses seen so far: the mean of the cameras' up
    (``-R[:, 1]`` of each camera-to-frame rotation R)."""

    def __init__(self) -> None:
        self._sum = np.zeros(3)
        self.count = 0

    def add(self, rotation: np.ndarray) -> None:
        """One pose's (3, 3) camera-to-frame rotation."""
        self._sum -= np.asarray(rotation, dtype=np.float64)[:, 1]
        self.count += 1

    @property
    def up(self) -> np.ndarray | None:
        """(3,) unit vector, or None when no pose came or the cameras' ups cancel out."""
        norm = float(np.linalg.norm(self._sum))
        return self._sum / norm if self.count and norm > 1e-6 * self.count else None


def up_from_rotations(rotations: np.ndarray) -> np.ndarray | None:
    """(3,) unit up of a fixed frame from ``rotations`` (K, 3, 3) camera-to-frame (`PoseUp`)."""
    estimate = PoseUp()
    for rotation in np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3):
        estimate.add(rotation)
    return estimate.up


def up_from_planes(positions: np.ndarray, normals: np.ndarray, labels: np.ndarray,
                   max_tilt_deg: float = MAX_TILT_DEG,
                   min_nodes: int = MIN_PLANE_NODES) -> tuple[np.ndarray, int] | None:
    """``(up, nodes)`` of the largest plane a static camera could stand over, in the camera's
    frame: ``positions`` (N, 3) metres and ``normals`` (N, 3) unit of nodes, ``labels`` (N,) their
    clusters by normal (-1: none). The plane's normal is turned towards the camera (the origin);
    None when no cluster of ``min_nodes`` is flat and within ``max_tilt_deg`` of `CAMERA_UP`."""
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    labels = np.asarray(labels)
    away = np.einsum("ij,ij->i", normals, -positions) < 0
    facing = np.where(away[:, None], -normals, normals)
    limit = np.cos(np.radians(max_tilt_deg))
    best: tuple[np.ndarray, int] | None = None
    for label in np.unique(labels[labels >= 0]):
        members = labels == label
        count = int(members.sum())
        if count < min_nodes or (best is not None and count <= best[1]):
            continue
        mean = facing[members].mean(axis=0)
        norm = float(np.linalg.norm(mean))
        if norm < MIN_NORMAL_AGREEMENT:
            continue
        if float(mean @ CAMERA_UP) / norm >= limit:
            best = (mean / norm, count)
    return best


def nearest_axis(up: np.ndarray) -> tuple[int, int]:
    """``(axis, sign)`` of the frame's axis nearest ``up``: axis 0, 1, 2 for x, y, z."""
    up = np.asarray(up, dtype=np.float64)
    axis = int(np.argmax(np.abs(up)))
    return axis, 1 if up[axis] >= 0 else -1


def axis_name(axis: int, sign: int) -> str:
    """``"+Z"``, ``"-Y"``, ..."""
    return f"{'+' if sign > 0 else '-'}{'XYZ'[axis]}"
