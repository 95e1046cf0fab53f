"""Connected components of a node graph (one topology or several combined), and the registry
of the clusterings gngdt publishes (`CLUSTERINGS`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def cluster_count(labels: np.ndarray) -> int:
    """Distinct clusters in ``labels`` (N,) int, not counting -1 (below min_size, or noise)."""
    labels = np.asarray(labels)
    # by a sort: numpy 2.4's hash-based `unique` took 10x as long for a network's labels
    kept = np.sort(labels[labels >= 0])
    return int(kept.size and 1 + np.count_nonzero(kept[1:] != kept[:-1]))


def connected_component_labels(n_nodes: int, edges: np.ndarray, min_size: int = 1) -> np.ndarray:
    """(n_nodes,) int32 component labels 0..k-1, largest component first (ties: lowest node).

    edges: (E, 2) integer node-index pairs. Nodes in components with fewer than ``min_size``
    nodes get -1.
    """
    if isinstance(min_size, bool) or not isinstance(min_size, (int, np.integer)) or min_size < 1:
        raise ValueError(f"min_size must be an integer >= 1, got {min_size!r}")
    if n_nodes == 0:
        return np.zeros(0, dtype=np.int32)
    # here: the registry below is read by light processes
    from gngdt.core.kernels.graph import component_roots

    edges = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    if edges.size and (edges.min() < 0 or edges.max() >= n_nodes):
        raise ValueError(f"edges must join nodes 0..{n_nodes - 1}")
    return rank_by_size(component_roots(n_nodes, edges), min_size)


def rank_by_size(labels: np.ndarray, min_size: int = 1) -> np.ndarray:
    """(N,) int32 relabelling of any integer ``labels`` (N,): 0..k-1 by decreasing group size
    (ties: the group holding the lowest index first); groups below ``min_size`` get -1."""
    n = labels.size
    _, dense = np.unique(labels, return_inverse=True)
    sizes = np.bincount(dense)
    first = np.full(sizes.size, n)
    np.minimum.at(first, dense, np.arange(n))
    ranking = np.lexsort((first, -sizes))  # by size descending, then first index
    kept = ranking[sizes[ranking] >= min_size]
    new_label = np.full(sizes.size, -1, dtype=np.int32)
    new_label[kept] = np.arange(kept.size, dtype=np.int32)
    return new_label[dense]


@dataclass(frozen=True)
class Clustering:
    """One way of grouping a network's nodes, published and drawn under ``name``.

    topologies: the edge sets whose connected components are its clusters (an edge counts where
    every named topology has it), or ``(CONVEXITY,)``: the segmentation by local convexity
    (`gngdt.core.segmentation.network`), whose segments are not plain components. Every clustering
    is drawn the same way: nodes and its edges coloured by persistent cluster id, grey outside any
    cluster (`gngdt.schemas.cluster_colors`).
    """

    name: str
    topologies: tuple[str, ...]
    #: what one cluster stands for, for people
    meaning: str

    @property
    def is_segmentation(self) -> bool:
        return self.topologies == (CONVEXITY,)


#: the paper's node properties, one topology (edge set) each: position, colour, normal
POS, COL, NOR = "pos", "col", "nor"
EDGE_PROPERTIES = (POS, COL, NOR)
#: the local-convexity topology (derived from positions, fresh normals and position edges)
CONVEXITY = "cvx"
#: every clustering gngdt publishes; the registry below holds them in the order views show them
SEGMENTS = Clustering("segments", (CONVEXITY,), "objects: segments by local convexity")
BY_POSITION = Clustering(POS, (POS,), "objects by shape: nodes joined by position edges")
BY_COLOUR = Clustering(COL, (COL,), "regions of one colour")
BY_NORMAL = Clustering(NOR, (NOR,), "planes: surfaces of one orientation")
BY_COLOUR_AND_NORMAL = Clustering(f"{COL}+{NOR}", (COL, NOR),
                                  "faces of one colour and one orientation")
#: read by the learner, the logger, the scene output and evaluation
CLUSTERINGS: dict[str, Clustering] = {
    clustering.name: clustering
    for clustering in (SEGMENTS, BY_POSITION, BY_COLOUR, BY_NORMAL, BY_COLOUR_AND_NORMAL)
}
#: the clusterings that are connected components of the paper's topologies (all but segments)
TOPOLOGY_CLUSTERINGS = tuple(name for name, clustering in CLUSTERINGS.items()
                             if not clustering.is_segmentation)


def clustering(name: str) -> Clustering:
    """The registered clustering ``name``; ValueError naming the known ones otherwise."""
    try:
        return CLUSTERINGS[name]
    except KeyError:
        raise ValueError(f"unknown clustering {name!r}; known: {', '.join(CLUSTERINGS)}") from None
