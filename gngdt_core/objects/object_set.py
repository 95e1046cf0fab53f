"""Objects from a learned network: one per cluster (or segment), with a persistent id.

An object is a cluster's nodes summarised: centroid, oriented bounding box (the principal axes of
its node positions and the extents along them), mean colour, dominant normal and node count. Its
id is the cluster's persistent id from a `ClusterIds`, so it stays the same from frame to frame
while the cluster keeps most of its nodes. A cluster becomes an object once it has at least
``min_size`` nodes and its track is confirmed (seen in ``confirm_frames`` labellings in a row):
fragments that split off for a frame or two and merge back are never published.

    finder = ObjectFinder("segments")         # or "pos", "col+nor" (CLUSTERINGS)
    for points, colors in frames:
        model.partial_fit(points, colors, n_steps=10_000)
        objects = finder.update(model)         # ObjectSet: ids, centres, sizes, ...
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gngdt.core.clustering import POS, SEGMENTS
from gngdt.core.clustering import clustering as clustering_spec
from gngdt.core.objects.ids import ClusterIds


@dataclass(frozen=True)
class ObjectSet:
    """K objects as arrays, row k = one object (positions in the network's units, e.g. metres).

    ids: (K,) int64 persistent ids; node_counts: (K,) int64; centroids: (K, 3) mean node position;
    centers: (K, 3) bounding-box centre; rotations: (K, 3, 3) box axes as columns (a proper
    rotation, box frame -> network frame; column 0 = the axis of largest spread); sizes: (K, 3)
    full box extents along those axes; colors: (K, 3) mean node colour (the input's scale);
    normals: (K, 3) unit dominant normal, sign-invariant mean of the node normals, turned toward
    the side most node normals face (zeros where no node has a normal); roles: (K,) int8 what
    each is (`gngdt.core.segmentation.supports`: OBJECT, SUPPORT a table or wall something rests on,
    CLUTTER background structure), judged for segments and OBJECT for clusters of other clusterings.
    """

    ids: np.ndarray
    node_counts: np.ndarray
    centroids: np.ndarray
    centers: np.ndarray
    rotations: np.ndarray
    sizes: np.ndarray
    colors: np.ndarray
    normals: np.ndarray
    roles: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def quaternions_xyzw(self) -> np.ndarray:
        """(K, 4) float64 box orientations as unit quaternions (x, y, z, w)."""
        if len(self) == 0:
            return np.zeros((0, 4))
        return Rotation.from_matrix(self.rotations).as_quat()


def drop_small(labels: np.ndarray, min_size: int) -> np.ndarray:
    """(N,) labels with the clusters of fewer than ``min_size`` nodes set to -1 (copies)."""
    labels = np.array(labels, copy=True)
    member = labels >= 0
    sizes = np.bincount(labels[member], minlength=1)  # every label may be -1 already
    labels[member & (sizes[np.maximum(labels, 0)] < min_size)] = -1
    return labels


def object_labels(labels: np.ndarray, confirmed: np.ndarray, min_size: int) -> np.ndarray:
    """(N,) labels with every cluster that is no object set to -1 (copies): fewer than
    ``min_size`` nodes, or not ``confirmed`` ((K,) bool per label, `ClusterIds.confirmed_`)."""
    labels = drop_small(labels, min_size)
    confirmed = np.asarray(confirmed, dtype=bool)
    member = labels >= 0
    if member.any() and confirmed.size <= labels.max():
        raise ValueError(f"confirmed must have an entry for every label 0..{labels.max()}, got "
                         f"{confirmed.shape}")
    unconfirmed = np.flatnonzero(member)[~confirmed[labels[member]]]
    labels[unconfirmed] = -1
    return labels


def describe_objects(positions: np.ndarray, colors: np.ndarray | None, normals: np.ndarray | None,
                     labels: np.ndarray, ids: np.ndarray | None = None,
                     roles: np.ndarray | None = None) -> ObjectSet:
    """One object per label 0..K-1 of ``labels`` (N,) int (-1: no object).

    positions: (N, 3) node positions; colors: (N, 3) or None; normals: (N, 3) unit or zero
    (undefined), or None; ids: (K,) int64 id of each label (default: the label itself); roles:
    (K,) int role of each label (`ObjectSet.roles`; default: every one an OBJECT).
    """
    positions = np.asarray(positions, dtype=np.float64)
    labels = np.asarray(labels).astype(np.int64)
    if positions.ndim != 2 or positions.shape[1] != 3 or labels.shape != positions.shape[:1]:
        raise ValueError(f"positions must be (N, 3) and labels (N,), got {positions.shape} and "
                         f"{labels.shape}")
    n_labels = int(labels.max()) + 1 if labels.size else 0
    ids = np.arange(n_labels) if ids is None else np.asarray(ids, dtype=np.int64)
    if ids.ndim != 1 or ids.size < n_labels:
        raise ValueError(f"ids must have an entry for every label 0..{n_labels - 1}, got "
                         f"{ids.shape}")
    n_labels = ids.size  # labels without nodes (e.g. dropped as too small) give no object
    roles = (np.zeros(n_labels, dtype=np.int8) if roles is None
             else np.asarray(roles, dtype=np.int8)[:n_labels])
    if roles.size < n_labels:
        raise ValueError(f"roles must have an entry for every label 0..{n_labels - 1}, got "
                         f"{roles.shape}")
    member = labels >= 0
    counts = np.bincount(labels[member], minlength=n_labels)
    present = counts > 0  # a label may have no node (e.g. -1 everywhere after filtering)
    keep = np.flatnonzero(present)
    remap = np.cumsum(present) - 1
    k = keep.size
    index = remap[labels[member]]
    points = positions[member]
    counts = counts[keep]

    def mean_of(values: np.ndarray) -> np.ndarray:
        sums = np.zeros((k, values.shape[1]))
        np.add.at(sums, index, values)
        return sums / counts[:, None]

    centroids = mean_of(points)
    offsets = points - centroids[index]
    scatter = np.zeros((k, 3, 3))
    np.add.at(scatter, index, offsets[:, :, None] * offsets[:, None, :])
    _, vectors = np.linalg.eigh(scatter)  # ascending eigenvalues
    rotations = vectors[:, :, ::-1].copy()  # columns: largest spread first
    rotations[:, :, 2] *= np.sign(np.linalg.det(rotations))[:, None]  # proper rotations
    local = np.einsum("nij,ni->nj", rotations[index], offsets)
    low = np.full((k, 3), np.inf)
    high = np.full((k, 3), -np.inf)
    np.minimum.at(low, index, local)
    np.maximum.at(high, index, local)
    sizes = high - low
    centers = centroids + np.einsum("kij,kj->ki", rotations, (low + high) / 2)
    mean_colors = mean_of(np.asarray(colors, dtype=np.float64)[member]) if colors is not None \
        else np.zeros((k, 3))
    dominant = _dominant_normals(np.asarray(normals, dtype=np.float64)[member], index, k) \
        if normals is not None else np.zeros((k, 3))
    return ObjectSet(ids=ids[keep], node_counts=counts.astype(np.int64), centroids=centroids,
                     centers=centers, rotations=rotations, sizes=sizes, colors=mean_colors,
                     normals=dominant, roles=roles[keep])


def _dominant_normals(normals: np.ndarray, index: np.ndarray, k: int) -> np.ndarray:
    """(k, 3): per object the principal direction of its defined node normals (sign-invariant
    mean), turned toward the side most of them face; zeros where none is defined."""
    defined = np.any(normals != 0.0, axis=1)
    moment = np.zeros((k, 3, 3))
    np.add.at(moment, index[defined], normals[defined, :, None] * normals[defined, None, :])
    _, vectors = np.linalg.eigh(moment)
    dominant = vectors[:, :, 2]
    votes = np.zeros(k)
    np.add.at(votes, index[defined], np.sign(np.einsum("ni,ni->n", normals[defined],
                                                       dominant[index[defined]])))
    dominant *= np.where(votes < 0, -1.0, 1.0)[:, None]
    has_normal = np.bincount(index[defined], minlength=k) > 0
    dominant[~has_normal] = 0.0
    return dominant


class ObjectFinder:
    """Objects of one clustering of a `GNGDT` (`gngdt.core.clustering.CLUSTERINGS`), with ids
    kept from call to call; the learner keeps one per clustering.

    min_size: fewest nodes of an object; confirm_frames: labellings in a row a cluster must be
    seen in before it is an object (defaults as the learner's). Other arguments go to
    `ClusterIds` (``ids``).
    """

    def __init__(self, clustering: str = SEGMENTS.name, min_size: int = 5, confirm_frames: int = 5,
                 **id_args: Any):
        self.clustering = clustering_spec(clustering)
        self.min_size = min_size
        self.ids = ClusterIds(confirm_frames=confirm_frames, **id_args)

    def labels(self, model: Any) -> np.ndarray:
        """(n_nodes,) int32 labels of the clustering (segments fall back to "pos" clusters on a
        model without a segmentation)."""
        topologies = self.clustering.topologies
        if self.clustering.is_segmentation:
            if hasattr(model, "segment"):
                return np.asarray(model.segment())
            topologies = (POS,)
        return model.clusters(*topologies, min_size=self.min_size)

    def label_ids(self, node_ids: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """(K,) int64 persistent id of each label 0..K-1 of this labelling (`ClusterIds`)."""
        return self.ids.update(node_ids, labels)

    def objects(self, model: Any, labels: np.ndarray, ids: np.ndarray,
                confirmed_only: bool = True, roles: np.ndarray | None = None) -> ObjectSet:
        """The confirmed clusters (every one when not ``confirmed_only``) of at least
        ``min_size`` nodes among ``labels`` (the labelling `label_ids` was last given, ``ids`` what
        it returned) as objects of ``model``; ``roles``: each label's (`ObjectSet.roles`)."""
        confirmed = self.ids.confirmed_
        if not confirmed_only:
            confirmed = np.ones_like(confirmed)
        return describe_objects(model.positions_, model.colors_, model.normals_,
                                object_labels(labels, confirmed, self.min_size), ids, roles)

    def update(self, model: Any) -> ObjectSet:
        """The model's objects now (confirmed clusters of at least ``min_size`` nodes); ids
        carried over from the previous call by node membership."""
        labels = self.labels(model)
        return self.objects(model, labels, self.label_ids(model.node_ids_, labels))
