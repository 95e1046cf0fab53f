"""Read-only queries of a learned network: nearest nodes of points, pixel labels, edge lists,
clusters.

The estimators' query methods (`NetworkQueries`, a base of `GrowingGas`: ``predict``,
``label_pixels``, ``edges``, ``clusters``, ``quantization_error``) validate their arguments and call
the pure functions below, over the estimator's network (`kernels.layout.Network`). Large batches
are split over the CPUs (the nearest-node kernels release the GIL).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from gngdt.core.clustering import COL, NOR, POS, connected_component_labels
from gngdt.core.gas.sampling import as_samples
from gngdt.core.kernels import layout as K
from gngdt.core.kernels import segmentation as SK
from gngdt.core.kernels.graph import edge_list
from gngdt.core.kernels.layout import I_NODES, Network
from gngdt.core.metrics import quantization_error as _rms_error
from gngdt.core.sensor.view import node_spacing

#: a nearest-node batch is split over the CPUs when each part gets at least this many points
#: (a stream's 30,000-point attention draw takes both cores of a 2-core machine)
PARALLEL_MIN_POINTS = 15_000
#: `label_pixels` searches the nearest node at every LABEL_ANCHOR_STRIDE-th pixel of every
#: LABEL_ANCHOR_STRIDE-th row, and fills the pixels between anchors that agree
LABEL_ANCHOR_STRIDE = 4


def split_range(n: int, min_part: int) -> list[int]:
    """Bounds of up to one part per usable CPU over ``range(n)``, each part >= ``min_part``."""
    parts = max(1, min(len(os.sched_getaffinity(0)), n // max(min_part, 1)))
    return [n * k // parts for k in range(parts + 1)]


def in_parallel(n_items: int, min_part: int, work: Callable[[int, int], object]) -> None:
    """``work(start, stop)`` over ``range(n_items)``, split over the CPUs when large (the
    kernels release the GIL)."""
    bounds = split_range(n_items, min_part)
    if len(bounds) == 2:
        work(0, n_items)
        return
    with ThreadPoolExecutor(len(bounds) - 1) as pool:
        list(pool.map(work, bounds[:-1], bounds[1:]))


def checked_query(positions: object, dim: int) -> np.ndarray:
    """``positions`` as an (N, dim) float32/float64 array; ValueError unless finite."""
    query = np.asarray(positions)
    if query.ndim != 2 or query.shape[1] != dim:
        raise ValueError(f"positions must have shape (N, {dim}), got {query.shape}")
    if query.dtype not in (np.float32, np.float64):
        query = query.astype(np.float64)
    if not np.isfinite(query).all():
        raise ValueError("positions contain NaN or inf")
    return query


def nearest_nodes(points: np.ndarray, net: Network) -> tuple[np.ndarray, np.ndarray]:
    """Winners (N,) int32 and squared distances (N,) of (N, 3) contiguous points among the
    nodes of ``net`` (3-D, at least one node), through its grid; large batches are split over
    the CPUs."""
    winners = np.empty(points.shape[0], dtype=np.int32)
    sq_distances = np.empty(points.shape[0])
    in_parallel(points.shape[0], PARALLEL_MIN_POINTS,
                lambda start, stop: SK.nearest_nodes(points, start, stop, net, winners,
                                                     sq_distances))
    return winners, sq_distances


def nearest_winners(query: np.ndarray, net: Network, use_grid: bool
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Winner (N,) int64 and distance (N,) float64 (position units) of each (N, D) query row:
    through the learner's grid when ``use_grid`` (3-D GNG-DT), else a k-d tree over the nodes."""
    if not use_grid:
        distances, winners = cKDTree(net.pos[: net.istate[I_NODES]]).query(query, k=1)
    else:
        winners, sq_distances = nearest_nodes(np.ascontiguousarray(query), net)
        distances = np.sqrt(sq_distances)
    return np.asarray(winners, dtype=np.int64), np.asarray(distances, dtype=np.float64)


#: a nearest-node search: (N, D) points -> (N,) int64 winners and (N,) float64 distances
Predict = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def frozen_predict(net: Network, dim: int, gngdt: bool) -> Predict:
    """Winners and distances (as `nearest_winners`) of (N, dim) points, over a copy of what a
    search reads of ``net`` as it is now (positions, grid, node count: a network that learns on
    meanwhile does not change it; searched from another thread, the search releases the GIL);
    ``gngdt``: a GNG-DT network (its grid is searched in 3-D)."""
    n = int(net.istate[I_NODES])
    if n == 0:
        raise ValueError("the model has no nodes yet: call fit or partial_fit first")
    frozen = net._replace(pos=net.pos[:n].copy(), ghead=net.ghead.copy(),
                          gnext=net.gnext[:n].copy(), istate=net.istate.copy(),
                          fstate=net.fstate.copy())

    def predict(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return nearest_winners(checked_query(points, dim), frozen, gngdt and dim == 3)

    return predict


def label_pixels(points: np.ndarray, node_labels: np.ndarray, net: Network) -> np.ndarray:
    """(H, W) int32: each pixel's nearest node's ``node_labels`` entry + 1, 0 where the pixel
    has no point or its node has label -1 (see `GNGDT.label_pixels`).

    points: (H, W, 3) metres, an organized cloud in the network's frame; node_labels:
    (n_nodes,) int; net: a 3-D network with at least one node. ValueError on other shapes.
    """
    n_nodes = int(net.istate[I_NODES])
    if points.ndim != 3 or points.shape[2] != 3:
        raise ValueError(f"points must have shape (H, W, 3), got {points.shape}")
    node_labels = np.asarray(node_labels, dtype=np.int32)
    if node_labels.shape != (n_nodes,):
        raise ValueError(f"node_labels must have shape ({n_nodes},), got {node_labels.shape}")
    if points.dtype not in (np.float32, np.float64):
        points = points.astype(np.float64)
    points = np.ascontiguousarray(points)
    valid = np.isfinite(points[..., 2])
    out = np.empty(valid.shape, dtype=np.int32)
    # the work is mostly the searches, about one pixel in stride^2 (the anchors): a
    # 640x480 frame is one thread's work, which two threads did no faster on 2 cores
    min_rows = PARALLEL_MIN_POINTS * LABEL_ANCHOR_STRIDE**2 // max(points.shape[1], 1)
    for anchors in (True, False):  # every anchor first: the second pass reads them
        in_parallel(points.shape[0], min_rows,
                    lambda start, stop, anchors=anchors: SK.label_pixels(
                        points, valid, node_labels, LABEL_ANCHOR_STRIDE, anchors,
                        start, stop, net, out))
    return out


def edge_pairs(net: Network, mask: int) -> np.ndarray:
    """(E, 2) int64 node-index pairs ``i < j`` of the edges of ``net`` that have every property
    bit of ``mask``."""
    return edge_list(net.nbr, net.deg, net.emask, int(net.istate[I_NODES]), mask)


_PROPERTY_BITS = {POS: K.POS_BIT, COL: K.COL_BIT, NOR: K.NOR_BIT}


class NetworkQueries:
    """The estimators' read-only queries (a base of `gngdt.core.gas.model.GrowingGas`, whose
    network, ``properties_`` and node arrays they read)."""

    def edges(self, *props: str) -> np.ndarray:
        """(E, 2) int64 node-index pairs ``i < j`` of the named topologies combined.

        An edge is kept where every named property has it (``edges("col", "nor")``); no name
        means "pos".
        """
        return self._edges_with(self._property_mask(props or (POS,)))

    def _property_mask(self, props: tuple[str, ...]) -> int:
        mask = 0
        for prop in props:
            if prop not in self.properties_:
                raise ValueError(f"unknown property {prop!r}; this model has {self.properties_}")
            mask |= _PROPERTY_BITS[prop]
        return mask

    def _edges_with(self, mask: int) -> np.ndarray:
        if self.n_nodes_ == 0:
            return np.zeros((0, 2), dtype=np.int64)
        return edge_pairs(self._network, mask)

    def clusters(self, *props: str, min_size: int = 1) -> np.ndarray:
        """(n_nodes,) int32 connected-component labels of the named topologies combined.

        An edge is kept where every named property has it (``clusters("col", "nor")``); no name
        means "pos". Labels 0..k-1 by decreasing cluster size; -1 for clusters below ``min_size``.
        """
        mask = self._property_mask(props or (POS,))
        return connected_component_labels(self.n_nodes_, self._edges_with(mask), min_size)

    def node_spacing(self) -> float:
        """Median distance from a node to its nearest other node (0 with fewer than two), as
        `gngdt.core.sensor.view.node_spacing` gives it; in 3-D by the learner's own search (its
        grid in GNG-DT) instead of a k-d tree built for it."""
        n = self.n_nodes_
        if n < 2 or self._dim != 3:
            return node_spacing(self.positions_)
        sq_distances = np.empty(n)
        SK.nearest_other_sq_distances(self._network, sq_distances)
        return float(np.median(np.sqrt(sq_distances)))

    def predict(self, positions: Any, return_distance: bool = False) -> Any:
        """(N,) int64 index of the winner node (nearest by position) of each row; with
        ``return_distance``, also (N,) float64 the distance to it (input units).

        Rows in scan order (a depth image's pixels row by row) are fastest: each search starts
        from the previous row's winner in the learner's own spatial grid.
        """
        if self.n_nodes_ == 0:
            raise ValueError("the model has no nodes yet: call fit or partial_fit first")
        query = checked_query(positions, self._dim)
        use_grid = self._dim == 3 and self._MODE == K.MODE_GNGDT
        winners, distances = nearest_winners(query, self._network, use_grid)
        return (winners, distances) if return_distance else winners

    def frozen_predict(self) -> Predict:
        """`predict` with distances over a copy of the network now (it may learn on meanwhile)."""
        return frozen_predict(self._network, self._dim, self._MODE == K.MODE_GNGDT)

    def label_pixels(self, points: np.ndarray, node_labels: np.ndarray) -> np.ndarray:
        """(H, W) int32: each pixel's nearest node's ``node_labels`` entry + 1; 0 where the
        pixel has no point (NaN depth) or its node has label -1.

        points: (H, W, 3) float32/float64 metres, an organized cloud: one point per pixel, in
        the network's frame, x and y finite wherever z is (as deprojection gives them);
        node_labels: (n_nodes,) int, e.g. ``segment()``. The nearest node is searched at every
        ``LABEL_ANCHOR_STRIDE``-th pixel of every such row (every 4th); a pixel between such
        pixels that all agree takes their label without a search (a label region narrower than
        the stride can be missed there), every other pixel is searched exactly. On the real
        640x480 Kinect frames of ../shared/data/labelled 0.03-0.06 % of the pixels (at most
        0.09 %) differ from ``node_labels[predict(...)]``, at under a third of its CPU time.
        """
        if self.n_nodes_ == 0:
            raise ValueError("the model has no nodes yet: call fit or partial_fit first")
        if self._dim != 3 or self._MODE != K.MODE_GNGDT:
            raise ValueError("label_pixels needs a GNG-DT network of 3D positions")
        return label_pixels(points, node_labels, self._network)

    def quantization_error(self, positions: Any, colors: Any = None) -> dict[str, float]:
        """Eq. 17 per property: RMS distance of each sample to its (position) winner node.

        Returns {"pos": r_pos} plus "col" when colours are given and learned. Rows with NaN/inf
        are ignored.
        """
        samples, sample_colors, _ = as_samples(positions, colors)
        winners = self.predict(samples)
        result = {POS: _rms_error(samples, self.positions_, winners)}
        if sample_colors is not None and self._has_col:
            result[COL] = _rms_error(sample_colors, self.colors_, winners)
        return result
