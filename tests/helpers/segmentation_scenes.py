"""Small constructed networks for the segmentation tests (no learning): nodes on jittered
grids over rectangles, tables, boxes and walls, edges between near nodes, and what a
segmentation made of them."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from gngdt.core.segmentation.network import SegmentationParams, segment_network

SPACING = 0.01  # metres between neighbouring nodes
TABLE_Y = 0.25  # the table's top (camera frame: y down, looking along +z)


def rectangle(corner: tuple[float, float, float], u: tuple[float, float, float],
              v: tuple[float, float, float], rng: np.random.Generator,
              spacing: float = SPACING) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on the rectangle ``corner + a u + b v`` (a, b in [0, 1]) on a jittered grid, and
    its unit normal facing the camera at the origin: (m, 3) positions, (m, 3) normals."""
    corner, u, v = (np.asarray(x, dtype=np.float64) for x in (corner, u, v))
    nu = max(round(float(np.linalg.norm(u)) / spacing), 1)
    nv = max(round(float(np.linalg.norm(v)) / spacing), 1)
    a, b = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
    points = corner + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    points += rng.normal(0.0, 0.0005, points.shape)
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal)
    if normal @ -(corner + 0.5 * u + 0.5 * v) < 0:
        normal = -normal
    return points, np.tile(normal, (len(points), 1))


def network(parts: list[tuple[np.ndarray, np.ndarray]],
            spacing: float = SPACING) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A network over the parts' nodes: edges between nodes closer than 1.5 spacings;
    returns positions, normals, edges and each node's part."""
    positions = np.vstack([p for p, _ in parts])
    normals = np.vstack([n for _, n in parts])
    part = np.concatenate([np.full(len(p), k) for k, (p, _) in enumerate(parts)])
    edges = cKDTree(positions).query_pairs(1.5 * spacing, output_type="ndarray")
    return positions, normals, edges, part


def table(rng: np.random.Generator, holes: list[tuple[float, float, float, float]] = (),
          z: tuple[float, float] = (0.6, 1.1)) -> tuple[np.ndarray, np.ndarray]:
    """The table top (x -0.3..0.3), without the rectangles ``holes`` (x0, x1, z0, z1) that
    objects stand on."""
    points, normals = rectangle((-0.3, TABLE_Y, z[0]), (0.6, 0, 0), (0, 0, z[1] - z[0]), rng)
    keep = np.ones(len(points), dtype=bool)
    for x0, x1, z0, z1 in holes:
        keep &= ~((points[:, 0] > x0) & (points[:, 0] < x1)
                  & (points[:, 2] > z0) & (points[:, 2] < z1))
    return points[keep], normals[keep]


def box(rng: np.random.Generator, x: tuple[float, float], bottom: float, height: float,
        z: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The faces of a box a camera above and in front sees: its top and its front."""
    top = rectangle((x[0], bottom - height, z[0]), (x[1] - x[0], 0, 0), (0, 0, z[1] - z[0]), rng)
    front = rectangle((x[0], bottom - height, z[0]), (x[1] - x[0], 0, 0), (0, height, 0), rng)
    return np.vstack([top[0], front[0]]), np.vstack([top[1], front[1]])


def majority(labels: np.ndarray, part: np.ndarray, which: int) -> tuple[int, float]:
    """The segment holding most of part ``which``'s nodes, and the share it holds."""
    values, counts = np.unique(labels[part == which], return_counts=True)
    return int(values[counts.argmax()]), float(counts.max() / counts.sum())


def segment(positions, normals, edges, **params):
    """The segmentation of a network with ``SegmentationParams(**params)``."""
    return segment_network(positions, normals, edges, SegmentationParams(**params))


def table_wall_and_box(rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """Parts 0, 1, 2: a table, a wall behind it and a box on the table leaning on the wall."""
    wall = rectangle((-0.3, TABLE_Y - 0.4, 1.1), (0.6, 0, 0), (0, 0.4, 0), rng)
    # the box's back touches the wall; its footprint is cut out of the table
    return [table(rng, [(-0.06, 0.06, 0.98, 1.1)]), wall,
            box(rng, (-0.06, 0.06), TABLE_Y, 0.12, (0.98, 1.1))]
