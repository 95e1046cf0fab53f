"""The learned map as a camera tracker reads it: nodes with a normal, an intensity and its
gradient on the node's tangent plane (`MapSurface`), for `gngdt.core.odometry.map_odometry`.

Built once per frame from a fitted 3-D `GNGDT` (`MapSurface.from_model`: fresh normals,
colours, the position topology for the gradients, and the model's own grid for the nearest-node
search) or from plain arrays (`MapSurface.from_arrays`, searched with scipy's cKDTree). Pure
computation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from gngdt.core.clustering import COL, POS
from gngdt.core.kernels import odometry as OK

#: a nearest-node search: (M, 3) map-frame points in scan order -> ((M,) row of each point's
#: nearest node, -1 for none, (M,) distance, metres)
NearestSearch = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class MapSurface:
    """Nodes as planes for point-to-plane alignment.

    positions (N, 3) float64 metres in the map frame; normals (N, 3) unit; intensity (N,) 0..1
    (None: no colours); gradients (N, 3) intensity per metre on each node's tangent plane;
    spacing: median distance between a node and its nearest other node, metres.
    """

    positions: np.ndarray
    normals: np.ndarray
    intensity: np.ndarray | None
    gradients: np.ndarray | None
    spacing: float
    tree: cKDTree | None = field(repr=False)
    #: (N,) trust in each node 0..1 (weights its residuals); None: all 1
    weights: np.ndarray | None = None
    #: (N,) int64 persistent node ids (the model's ``node_ids_``), for the tracker's plane memory
    ids: np.ndarray | None = None
    #: nearest-node search instead of the tree (e.g. the model's own grid, `from_model`)
    search: NearestSearch | None = field(default=None, repr=False)

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M,) row of the nearest node of each (M, 3) point (-1: none) and (M,) distance."""
        if self.search is not None:
            return self.search(points)
        distance, row = self.tree.query(points, k=1)
        return row, distance

    @classmethod
    def from_arrays(cls, positions: np.ndarray, normals: np.ndarray,
                    colors: np.ndarray | None = None, edges: np.ndarray | None = None,
                    weights: np.ndarray | None = None, ids: np.ndarray | None = None
                    ) -> MapSurface:
        """Nodes ``positions`` (N, 3) metres and ``normals`` (N, 3) (zero: none; such nodes
        are left out), ``colors`` (N, 3) RGB 0..255 or None, ``edges`` (E, 2) node index pairs
        (the position topology) for the intensity gradients."""
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        length = np.linalg.norm(normals, axis=1)
        keep = np.flatnonzero(length > 0.5)
        unit = normals[keep] / length[keep, None]
        tree = cKDTree(positions[keep]) if len(keep) else None
        spacing = 0.0
        if len(keep) >= 2:
            spacing = float(np.median(tree.query(positions[keep], k=2)[0][:, 1]))
        intensity = gradients = None
        if colors is not None and len(keep):
            values = OK.intensities(np.asarray(colors).reshape(-1, 3))
            full = np.zeros_like(normals)
            full[keep] = unit
            pairs = np.zeros((0, 2), dtype=np.int64) if edges is None else np.asarray(edges)
            gradients = OK.node_gradients(positions, full, values, pairs.reshape(-1, 2),
                                          ridge=(0.5 * spacing) ** 2)[keep]
            intensity = values[keep]
        if weights is not None:
            weights = np.asarray(weights, dtype=np.float64).reshape(-1)[keep]
        if ids is not None:
            ids = np.asarray(ids, dtype=np.int64).reshape(-1)[keep]
        return cls(positions[keep], unit, intensity, gradients, spacing, tree, weights, ids)

    @classmethod
    def from_model(cls, model: Any, frozen: bool = False) -> MapSurface:
        """The surface of a fitted 3-D `GNGDT` (fresh normals, colours, position edges). The
        nearest-node search goes through the model's own grid (`GNGDT.predict`; on scan-ordered
        points about 4x faster than a cKDTree), so the model must not learn while the surface
        is in use, unless ``frozen``: then through a copy of the grid (`GNGDT.frozen_predict`),
        and the model may learn on (in another thread)."""
        colors = model.colors_ if COL in model.properties_ else None
        normals = model.fresh_normals()
        surface = cls.from_arrays(model.positions_, normals, colors, model.edges(POS),
                                  ids=model.node_ids_)
        row_of = np.full(model.n_nodes_ + 1, -1, dtype=np.int64)  # the last: "no node"
        row_of[np.flatnonzero(np.linalg.norm(normals, axis=1) > 0.5)] = np.arange(len(surface))
        predict = (model.frozen_predict() if frozen
                   else lambda points: model.predict(points, return_distance=True))

        def search(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            winners, distance = predict(points)
            return row_of[winners], distance

        return cls(surface.positions, surface.normals, surface.intensity, surface.gradients,
                   surface.spacing, surface.tree, surface.weights, surface.ids, search)

    def __len__(self) -> int:
        return len(self.positions)
