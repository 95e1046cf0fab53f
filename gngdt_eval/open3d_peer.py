"""The classic peer segmentation, with Open3D: voxel downsampling, the dominant plane by RANSAC
(the support surface), DBSCAN of the rest; each pixel takes the label of its nearest voxel.

Labels: 1 = the plane, 2... = DBSCAN clusters, 0 = no segment (no depth, DBSCAN noise). Open3D
is an optional extra (``pip install -e '.[peers]'``; its wheel needs the system library
libusb-1.0); `load_open3d` says why it is not there.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import asdict, dataclass
from types import ModuleType
from typing import Any

import numpy as np

INSTALL_HINT = "pip install -e '.[peers]' (Open3D's wheel also needs libusb-1.0: " \
               "apt-get install libusb-1.0-0)"


@dataclass(frozen=True)
class PeerParams:
    """Parameters of the peer (metres)."""

    voxel_m: float = 0.003
    plane_distance_m: float = 0.005
    ransac_n: int = 3
    ransac_iterations: int = 1000
    dbscan_eps_m: float = 0.010
    dbscan_min_points: int = 20
    seed: int = 0

    def describe(self) -> str:
        return (f"Open3D: voxel {self.voxel_m * 1000:g} mm; plane RANSAC "
                f"{self.plane_distance_m * 1000:g} mm ({self.ransac_n} points, "
                f"{self.ransac_iterations} iterations); DBSCAN eps "
                f"{self.dbscan_eps_m * 1000:g} mm, min {self.dbscan_min_points} points; "
                "pixels take their nearest voxel's label, DBSCAN noise = no segment")

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def load_open3d(module_name: str = "open3d") -> tuple[ModuleType | None, str]:
    """(the module, its version) or (None, why it cannot be used)."""
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:  # not installed, or a system library missing (libusb)
        return None, f"{module_name} cannot be imported ({error}); {INSTALL_HINT}"
    return module, f"{module_name} {getattr(module, '__version__', '?')}"


class Open3DPeer:
    """Segments organized point arrays with Open3D (see the module docstring)."""

    def __init__(self, open3d: ModuleType, params: PeerParams | None = None) -> None:
        self.o3d = open3d
        self.params = params or PeerParams()

    def segment(self, points: np.ndarray) -> tuple[np.ndarray, dict[str, float]]:
        """points: (H, W, 3) float32 metres, NaN where there is no depth. Returns (H, W) int32
        labels and milliseconds per phase (voxel, plane, dbscan, label)."""
        from scipy.spatial import cKDTree

        o3d, params = self.o3d, self.params
        laps: dict[str, float] = {}
        last = time.perf_counter()

        def lap(name: str) -> None:
            nonlocal last
            now = time.perf_counter()
            laps[name] = (now - last) * 1000.0
            last = now

        height, width, _ = points.shape
        flat = points.reshape(-1, 3)
        valid = np.flatnonzero(np.isfinite(flat).all(axis=1))
        labels = np.zeros(height * width, dtype=np.int32)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(flat[valid].astype(np.float64)))
        voxels = cloud.voxel_down_sample(params.voxel_m)
        lap("voxel")
        n_voxels = len(voxels.points)
        voxel_labels = np.zeros(n_voxels, dtype=np.int32)
        if n_voxels >= params.ransac_n:
            o3d.utility.random.seed(params.seed)
            _, inliers = voxels.segment_plane(params.plane_distance_m, params.ransac_n,
                                              params.ransac_iterations)
            voxel_labels[np.asarray(inliers, dtype=np.int64)] = 1
        lap("plane")
        rest = np.flatnonzero(voxel_labels == 0)
        if rest.size:
            clusters = np.asarray(voxels.select_by_index(rest).cluster_dbscan(
                params.dbscan_eps_m, params.dbscan_min_points))
            voxel_labels[rest] = np.where(clusters >= 0, clusters + 2, 0)
        lap("dbscan")
        if n_voxels:
            _, nearest = cKDTree(np.asarray(voxels.points)).query(flat[valid], workers=-1)
            labels[valid] = voxel_labels[nearest]
        lap("label")
        return labels.reshape(height, width), laps
