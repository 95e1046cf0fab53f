"""How gngdt draws a learned topology, the same in rerun and in Foxglove.

Colours follow persistent cluster ids (the learner's ``cluster_ids``), so a cluster keeps its colour
from frame to frame; nodes in no cluster are grey. Each clustering is drawn with its own edges: a
clustering of properties (``pos``, ``col+nor``) with the edges every named property has, any other
(``segments``) with the position edges inside one cluster.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from gngdt.core.clustering import POS

#: colour of nodes in no cluster (label -1), and of edges leaving a cluster
UNCLUSTERED_RGB = (150, 150, 150)
_GOLDEN = 0.618033988749895
#: `id_colors` of more ids than this colours each distinct id once (half the time for 2,400)
DISTINCT_FIRST = 64


def id_colors(ids: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 saturated colour per integer id (N,); -1 is grey. The same id always gets the
    same colour, and consecutive ids get distant hues (golden-ratio steps around the hue circle)."""
    ids = np.asarray(ids, dtype=np.int64)
    if ids.size > DISTINCT_FIRST:  # a network's nodes: few clusters, each id's colour made once
        distinct, inverse = np.unique(ids, return_inverse=True)
        return _hue_colors(distinct)[inverse]
    return _hue_colors(ids)


def _hue_colors(ids: np.ndarray) -> np.ndarray:
    hue = (ids.astype(np.float64) * _GOLDEN) % 1.0
    sector = hue * 6.0
    channel = np.clip(np.abs((sector[:, None] - np.array([3.0, 1.0, 5.0])) % 6.0 - 3.0) - 1.0, 0, 1)
    # vary brightness a little with the id too, so hues that come close differ in lightness
    value = 0.75 + 0.25 * ((ids % 3) / 2.0)
    colors = (40 + (215 * value)[:, None] * channel).astype(np.uint8)
    colors[ids < 0] = UNCLUSTERED_RGB
    return colors


def node_cluster_ids(labels: np.ndarray, cluster_ids: np.ndarray | None,
                     min_nodes: int = 1) -> np.ndarray:
    """(N,) int64 persistent cluster id of each node (labels (N,) int, -1 = none), -1 also for
    clusters of fewer than ``min_nodes`` nodes; without ``cluster_ids`` the labels themselves
    (stable only within one frame)."""
    labels = np.asarray(labels, dtype=np.int64)
    clustered = labels >= 0
    if min_nodes > 1 and clustered.any():
        too_small = np.bincount(labels[clustered]) < min_nodes
        labels = np.where(clustered & too_small[np.maximum(labels, 0)], -1, labels)
    if cluster_ids is None or len(cluster_ids) == 0:
        return labels
    return np.where(labels >= 0, np.asarray(cluster_ids)[np.maximum(labels, 0)], -1)


def node_colors(labels: np.ndarray, cluster_ids: np.ndarray | None,
                min_nodes: int = 1) -> np.ndarray:
    """(N, 3) uint8 colour of each node by its cluster's persistent id (grey: no cluster, or
    one of fewer than ``min_nodes`` nodes)."""
    return id_colors(node_cluster_ids(labels, cluster_ids, min_nodes))


def clustering_edges(name: str, edges: Mapping[str, np.ndarray], labels: np.ndarray) -> np.ndarray:
    """(E, 2) int64 edges drawn for clustering ``name``.

    ``edges``: property -> (E, 2) node-index pairs. A name made of properties ("col+nor") gets the
    edges all of them have; any other name (a segmentation) the position edges whose two ends are
    in the same cluster.
    """
    props = name.split("+")
    if all(prop in edges for prop in props):
        keys = None
        for prop in props:
            pairs = np.sort(np.asarray(edges[prop], dtype=np.int64).reshape(-1, 2), axis=1)
            prop_keys = _distinct(pairs[:, 0] << 32 | pairs[:, 1])
            keys = (prop_keys if keys is None
                    else np.intersect1d(keys, prop_keys, assume_unique=True))
        return np.stack([keys >> 32, keys & 0xFFFFFFFF], axis=1)
    pairs = np.asarray(edges.get(POS, np.zeros((0, 2))), dtype=np.int64).reshape(-1, 2)
    labels = np.asarray(labels)
    inside = (labels[pairs[:, 0]] >= 0) & (labels[pairs[:, 0]] == labels[pairs[:, 1]])
    return pairs[inside]


def _distinct(keys: np.ndarray) -> np.ndarray:
    """``np.unique(keys)`` of (K,) int64 by a sort (numpy's hash-based unique took 8x as long
    for a network's ~6,000 edges)."""
    keys = np.sort(keys)
    return keys[np.concatenate(([True], keys[1:] != keys[:-1]))] if keys.size else keys


def edge_colors(pairs: np.ndarray, colors: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(E, 3) uint8 colour per edge: its cluster's colour when both ends share a cluster, else
    grey. colors: (N, 3) node colours; labels: (N,) cluster labels or persistent ids (-1: none)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    labels = np.asarray(labels)
    same = (labels[pairs[:, 0]] >= 0) & (labels[pairs[:, 0]] == labels[pairs[:, 1]])
    result = np.empty((len(pairs), 3), dtype=np.uint8)
    result[:] = UNCLUSTERED_RGB
    result[same] = colors[pairs[same, 0]]
    return result


def edge_classes(pairs: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(E,) int64 class of each edge: the id both ends share (ids (N,), -1: none), else -1."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    ids = np.asarray(ids, dtype=np.int64)
    first, second = ids[pairs[:, 0]], ids[pairs[:, 1]]
    return np.where((first >= 0) & (first == second), first, -1)


def edge_strips(pairs: np.ndarray, classes: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edges ``pairs`` (E, 2) node indices as polylines: each edge is drawn exactly once, and
    edges of one class (``classes`` (E,), e.g. `edge_classes`) that meet at a node are chained.

    A graph of E edges drawn as E two-point lines repeats every node once per edge; chained, a
    mesh-like graph needs ~1.2 E points instead of 2 E (and a colour per polyline instead of per
    edge). At each node the edge ends of one class are paired up; following the pairs gives
    trails (from an unpaired end to another) and closed loops, which are cut at their smallest
    end. Each trail walked once in a compiled pass (`gngdt.core.kernels.strips`).

    Returns ``nodes`` (P,) int64 node index of every polyline point, ``starts`` (S + 1,) int64
    offset of each polyline in ``nodes`` (and their end) and ``strip_classes`` (S,) int64.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    classes = np.asarray(classes, dtype=np.int64).reshape(-1)
    loops = pairs[:, 0] == pairs[:, 1]
    if loops.any():  # a node joined to itself draws nothing
        pairs, classes = pairs[~loops], classes[~loops]
    empty = np.zeros(0, dtype=np.int64)
    if len(pairs) == 0:
        return empty, np.zeros(1, dtype=np.int64), empty
    from gngdt.core.kernels.strips import chain_edges  # numba: only where edges are drawn

    return chain_edges(pairs, classes)
