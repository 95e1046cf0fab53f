"""The references a user would weigh a learned topology against, computed on the same points.

- k-means with as many centres as the topology has nodes (scikit-learn): close to the best
  quantization error that node budget can buy.
- A voxel grid downsampled to as many points as the topology has nodes (each voxel's mean point).
- DBSCAN clustering of the raw points (positions only), to put its adjusted Rand index beside ours.

Quantization errors follow eq. 17 of the paper: each point's winner is the nearest representative
by position; ``pos`` and ``col`` are root-mean-square distances to that winner's position/colour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gngdt.core.clustering import COL, POS
from gngdt.io.deproject import voxel_downsample, voxel_keys


@dataclass(frozen=True)
class Representatives:
    """A set of representatives of a point cloud and how well they quantize it.

    positions: (K, D) float64, same units as the points; colors: (K, 3) float64 (0-255) or None.
    quantization_error: eq. 17 {"pos": float, "col": float (absent without colours)}.
    details: method-specific figures (e.g. the voxel size in the points' units).
    """

    name: str
    positions: np.ndarray
    colors: np.ndarray | None
    quantization_error: dict[str, float]
    details: dict[str, float]


def quantization_error(
    positions: np.ndarray,
    colors: np.ndarray | None,
    representative_positions: np.ndarray,
    representative_colors: np.ndarray | None,
) -> dict[str, float]:
    """Eq. 17 against arbitrary representatives, the winner chosen by position (k-d tree).

    positions: (N, D) float; colors: (N, 3) or None; representative_*: (K, D) / (K, 3).
    """
    from scipy.spatial import cKDTree

    from gngdt.core.metrics import quantization_error as rms_error

    _, winners = cKDTree(representative_positions).query(positions, k=1)
    result = {POS: rms_error(positions, representative_positions, winners)}
    if colors is not None and representative_colors is not None:
        result[COL] = rms_error(colors, representative_colors, winners)
    return result


def _mean_colours(labels: np.ndarray, colors: np.ndarray | None, count: int) -> np.ndarray | None:
    """(count, 3) mean colour of the points carrying each label 0..count-1 (0 where none)."""
    if colors is None:
        return None
    colors = np.asarray(colors, dtype=np.float64)
    sums = np.zeros((count, colors.shape[1]))
    np.add.at(sums, labels, colors)
    members = np.bincount(labels, minlength=count)[:, None]
    return sums / np.maximum(members, 1)


def kmeans_reference(
    positions: np.ndarray,
    colors: np.ndarray | None,
    n_centres: int,
    *,
    fit_points: int = 20_000,
    random_state: int = 0,
) -> Representatives:
    """k-means (scikit-learn, k-means++ init, one run) with ``n_centres`` centres on positions.

    Fitted on at most ``fit_points`` randomly chosen points (for speed), evaluated on all points.
    A centre's colour is the mean colour of the points it wins.
    """
    from sklearn.cluster import KMeans

    positions = np.asarray(positions, dtype=np.float64)
    if n_centres < 1:
        raise ValueError(f"n_centres must be >= 1, got {n_centres}")
    rng = np.random.default_rng(random_state)
    sample = positions
    if len(positions) > fit_points:
        sample = positions[rng.choice(len(positions), size=fit_points, replace=False)]
    n_centres = min(n_centres, len(sample))
    model = KMeans(n_clusters=n_centres, n_init=1, random_state=random_state).fit(sample)
    centres = model.cluster_centers_
    labels = model.predict(positions)
    centre_colours = _mean_colours(labels, colors, n_centres)
    return Representatives(
        name="k-means",
        positions=centres,
        colors=centre_colours,
        quantization_error=quantization_error(positions, colors, centres, centre_colours),
        details={"centres": float(n_centres), "fit_points": float(len(sample))},
    )


def voxel_grid_reference(
    positions: np.ndarray, colors: np.ndarray | None, n_points: int, *, iterations: int = 40
) -> Representatives:
    """Voxel-grid downsampling to about ``n_points`` points (voxel size found by bisection).

    The number of occupied voxels falls as the voxel grows; bisection in log-size picks the size
    whose count is closest to ``n_points`` (reported in ``details``).
    """
    positions = np.asarray(positions, dtype=np.float64)
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    extent = float(np.max(np.ptp(positions, axis=0)))
    if extent == 0.0:
        raise ValueError("positions: all points coincide, no voxel grid can be fitted")
    small, large = extent * 1e-4, extent * 2.0

    def occupied(size: float) -> int:
        return len(np.unique(voxel_keys(positions, size)))

    best_size, best_gap = large, math.inf
    for _ in range(iterations):
        size = math.sqrt(small * large)
        count = occupied(size)
        if abs(count - n_points) < best_gap:
            best_size, best_gap = size, abs(count - n_points)
        if count == n_points:
            break
        if count > n_points:
            small = size
        else:
            large = size
    # the capture's own voxel grid, as a user would downsample before publishing
    centres, centre_colours = voxel_downsample(positions, colors, best_size)
    return Representatives(
        name="voxel grid",
        positions=centres,
        colors=centre_colours,
        quantization_error=quantization_error(positions, colors, centres, centre_colours),
        details={"voxel_size": best_size, "points": float(len(centres))},
    )


def dbscan_eps(positions: np.ndarray, min_samples: int) -> float:
    """A data-driven DBSCAN radius: 1.5 x the median distance to the min_samples-th neighbour."""
    from scipy.spatial import cKDTree

    distances, _ = cKDTree(positions).query(positions, k=min_samples + 1)
    return float(1.5 * np.median(distances[:, -1]))


def dbscan_labels(
    positions: np.ndarray, *, eps: float | None = None, min_samples: int = 10
) -> tuple[np.ndarray, float]:
    """DBSCAN (scikit-learn) of raw positions: ((N,) int labels, -1 = noise; the eps used)."""
    from sklearn.cluster import DBSCAN

    positions = np.asarray(positions, dtype=np.float64)
    if eps is None:
        eps = dbscan_eps(positions, min_samples)
    if eps <= 0:
        raise ValueError(f"eps must be > 0, got {eps}")
    labels = DBSCAN(eps=eps, min_samples=min_samples).fit_predict(positions)
    return labels.astype(np.int64), float(eps)
