"""Evaluation measures: the paper's (eqs. 17-18), the adjusted Rand index, and ghost nodes."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def quantization_error(samples: np.ndarray, node_values: np.ndarray, winners: np.ndarray) -> float:
    """Eq. 17: sqrt(mean_i ||v_i - h_{s1(i)}||^2).

    samples: (N, F) property values of the inputs; node_values: (n_nodes, F) the same property
    of the nodes; winners: (N,) int winner node of each sample (chosen by position).
    """
    if len(samples) == 0:
        return float("nan")
    residual = np.asarray(samples, dtype=np.float64) - np.asarray(node_values)[winners]
    return float(np.sqrt(np.mean(np.sum(residual * residual, axis=1))))


def cluster_centre_errors(
    node_positions: np.ndarray, node_labels: np.ndarray, true_centres: np.ndarray
) -> np.ndarray:
    """Eq. 18: distance between each true centre and the centroid of its cluster.

    node_positions: (n_nodes, D); node_labels: (n_nodes,) int, -1 = no cluster; true_centres:
    (k, D). Clusters are matched one-to-one to the true centres by minimum total centroid
    distance (Hungarian method). Returns (k,) float64; inf for a centre left without a cluster.
    """
    node_positions = np.asarray(node_positions, dtype=np.float64)
    true_centres = np.asarray(true_centres, dtype=np.float64)
    labels = np.asarray(node_labels)
    cluster_ids = np.unique(labels[labels >= 0])
    errors = np.full(len(true_centres), np.inf)
    if cluster_ids.size == 0:
        return errors
    centroids = np.stack([node_positions[labels == c].mean(axis=0) for c in cluster_ids])
    distances = np.linalg.norm(true_centres[:, None, :] - centroids[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(distances)
    errors[rows] = distances[rows, cols]
    return errors


def adjusted_rand_index(labels_true: np.ndarray, labels_pred: np.ndarray) -> float:
    """Adjusted Rand index (Hubert & Arabie) of two labellings of the same items.

    Every distinct value is a cluster (including -1). 1.0 for identical partitions, about 0 for
    independent ones.
    """
    labels_true = np.asarray(labels_true).ravel()
    labels_pred = np.asarray(labels_pred).ravel()
    if labels_true.shape != labels_pred.shape:
        raise ValueError(f"labels_true and labels_pred differ in length: "
                         f"{labels_true.size} vs {labels_pred.size}")
    n = labels_true.size
    if n < 2:
        return 1.0
    _, true_idx = np.unique(labels_true, return_inverse=True)
    _, pred_idx = np.unique(labels_pred, return_inverse=True)
    contingency = np.zeros((true_idx.max() + 1, pred_idx.max() + 1), dtype=np.int64)
    np.add.at(contingency, (true_idx, pred_idx), 1)

    def pairs(counts: np.ndarray) -> float:
        counts = counts.astype(np.float64)
        return float(np.sum(counts * (counts - 1.0) / 2.0))

    index = pairs(contingency)
    sum_rows = pairs(contingency.sum(axis=1))
    sum_cols = pairs(contingency.sum(axis=0))
    total = n * (n - 1) / 2.0
    expected = sum_rows * sum_cols / total
    maximum = 0.5 * (sum_rows + sum_cols)
    if maximum == expected:  # both partitions trivial (all one cluster or all singletons)
        return 1.0
    return (index - expected) / (maximum - expected)


def ghost_nodes(
    node_positions: np.ndarray,
    camera_points: np.ndarray,
    camera_pose: np.ndarray | None = None,
    distance: float = 0.05,
    margin: float = 0.05,
    reach: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Which nodes the sensor could have seen in a batch, and which of those are ghosts.

    node_positions: (N, 3) in the model's frame; camera_points: (M, 3) the batch, camera frame;
    camera_pose: (4, 4) camera-to-model (None: the model is in the camera frame). A node is seen
    as in `gngdt.core.sensor.view.seen_nodes` (depth tolerance ``margin``, a fraction of the depth)
    and a ghost when it is seen and farther than ``distance`` (the data's units) from every point of
    the batch: the sensor looked there and found nothing. ``reach``: as in `seen_nodes` (default:
    the nodes' spacing, measured here). Returns (seen, ghost), (N,) bool each.
    """
    from scipy.spatial import cKDTree

    from gngdt.core.sensor.view import seen_nodes

    nodes = np.asarray(node_positions, dtype=np.float64)
    seen = seen_nodes(nodes, camera_points, camera_pose, margin, reach)
    ghost = np.zeros(len(nodes), dtype=bool)
    points = np.asarray(camera_points, dtype=np.float64)
    if seen.any() and len(points):
        if camera_pose is not None:
            points = points @ camera_pose[:3, :3].T + camera_pose[:3, 3]
        # built for one query: midpoint splits build in half the time of median ones
        tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
        nearest, _ = tree.query(nodes[seen], k=1, distance_upper_bound=distance)
        ghost[np.flatnonzero(seen)[~np.isfinite(nearest)]] = True
    return seen, ghost
