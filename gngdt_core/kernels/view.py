"""Numba kernels of the sensor's view: which nodes the sensor could have seen in one batch,
which remembered points it saw through, and what lies between two nodes (gaps of missing depth).

A batch of points in the camera frame (x right, y down, z forward) is binned on the image plane
by normalised coordinates ``u = x / z``, ``v = y / z`` into square cells ``cell`` wide; a cell
keeps the farthest and the nearest depth ``z`` measured in it (0: nothing measured).

A node is *seen* when, put in the camera frame, the cells around it out to ``reach`` (the node's
share of the surface: the running node spacing, in the model's units, seen at the node's depth)
are all measured and inside the grid, and it is not behind the farthest depth of its own cell by
more than ``margin`` times that depth: in free space in front of what the sensor measured, or on
it. Nodes behind the measured surface (occluded), outside the view, at its edge or next to holes
(where only part of what they stand for is in view, so they win fewer samples) are not seen.

A remembered point is *seen through* when it lies on a measured cell in front of the nearest
depth measured there by more than ``margin`` times that depth: every ray of that cell passed it
and hit something farther. Pure functions over arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import inlined

#: points nearer than this (in the camera's z, input units) are not binned
MIN_DEPTH = 1e-6
#: the neighbourhood a node needs measured is at most this many cells out from its own
MAX_REACH_CELLS = 8


@njit(cache=True)
def view_bounds(points):
    """(u_min, u_max, v_min, v_max, count) of the points in front of the camera.

    points: (M, 3) any float, camera frame."""
    u_min = np.inf
    u_max = -np.inf
    v_min = np.inf
    v_max = -np.inf
    count = 0
    for i in range(points.shape[0]):
        z = float(points[i, 2])
        if not z > MIN_DEPTH:  # also skips NaN
            continue
        u = points[i, 0] / z
        v = points[i, 1] / z
        if not (math.isfinite(u) and math.isfinite(v)):
            continue
        u_min = min(u_min, u)
        u_max = max(u_max, u)
        v_min = min(v_min, v)
        v_max = max(v_max, v)
        count += 1
    return u_min, u_max, v_min, v_max, count


@njit(cache=True)
def fill_depth_grid(points, u_min, v_min, inv_cell, zmax, zmin):
    """Farthest and nearest depth per cell into ``zmax`` and ``zmin`` (rows: v, columns: u;
    zeros beforehand)."""
    rows, columns = zmax.shape
    for i in range(points.shape[0]):
        z = float(points[i, 2])
        if not z > MIN_DEPTH:
            continue
        u = points[i, 0] / z
        v = points[i, 1] / z
        if not (math.isfinite(u) and math.isfinite(v)):
            continue
        column = min(int((u - u_min) * inv_cell), columns - 1)
        row = min(int((v - v_min) * inv_cell), rows - 1)
        if z > zmax[row, column]:
            zmax[row, column] = z
        if zmin[row, column] == 0.0 or z < zmin[row, column]:
            zmin[row, column] = z


@njit(cache=True)
def measured_counts(zmax):
    """(rows + 1, columns + 1) int64 summed-area table of the measured cells (zmax > 0)."""
    rows, columns = zmax.shape
    table = np.zeros((rows + 1, columns + 1), dtype=np.int64)
    for row in range(rows):
        running = 0
        for column in range(columns):
            if zmax[row, column] > 0.0:
                running += 1
            table[row + 1, column + 1] = table[row, column + 1] + running
    return table


@inlined
def _cell_of(points, i, camera_from_model, u_min, v_min, inv_cell, rows, columns):
    """(row, column, depth) of ``points[i]`` (model frame) in the camera's grid; row -1 when
    it is behind the camera or off the grid."""
    r = camera_from_model
    x = r[0, 0] * points[i, 0] + r[0, 1] * points[i, 1] + r[0, 2] * points[i, 2] + r[0, 3]
    y = r[1, 0] * points[i, 0] + r[1, 1] * points[i, 1] + r[1, 2] * points[i, 2] + r[1, 3]
    z = r[2, 0] * points[i, 0] + r[2, 1] * points[i, 1] + r[2, 2] * points[i, 2] + r[2, 3]
    if not z > MIN_DEPTH:
        return -1, -1, z
    fu = (x / z - u_min) * inv_cell
    fv = (y / z - v_min) * inv_cell
    if not (0.0 <= fu < columns and 0.0 <= fv < rows):
        return -1, -1, z
    return int(fv), int(fu), z


@inlined
def _all_measured(measured, row, column, ring):
    """Whether the cells within ``ring`` of (row, column) lie inside the grid and are all
    measured; measured: `measured_counts` of the grid."""
    low_row, high_row = row - ring, row + ring + 1
    low_column, high_column = column - ring, column + ring + 1
    if (low_row < 0 or low_column < 0 or high_row >= measured.shape[0]
            or high_column >= measured.shape[1]):
        return False
    count = (measured[high_row, high_column] - measured[low_row, high_column]
             - measured[high_row, low_column] + measured[low_row, low_column])
    return count == (2 * ring + 1) * (2 * ring + 1)


@njit(cache=True)
def judge_nodes(pos, n, camera_from_model, zmax, measured, u_min, v_min, inv_cell, margin, reach,
                seen):
    """``seen[i]`` = 1 for each node ``i < n`` the sensor could have seen, else 0.

    pos: (cap, 3) float64 node positions in the model's frame; camera_from_model: (4, 4);
    measured: `measured_counts` of ``zmax``; reach: a node's radius, model units.
    """
    rows, columns = zmax.shape
    for i in range(n):
        seen[i] = 0
        row, column, z = _cell_of(pos, i, camera_from_model, u_min, v_min, inv_cell, rows,
                                  columns)
        if row < 0:
            continue
        ring = max(1, min(MAX_REACH_CELLS, math.ceil(reach / z * inv_cell)))
        if not _all_measured(measured, row, column, ring):
            continue
        if z <= zmax[row, column] * (1.0 + margin):
            seen[i] = 1


@njit(cache=True)
def seen_through(points, n, camera_from_model, zmin, u_min, v_min, inv_cell, margin, through):
    """``through[i]`` = 1 for each point ``i < n`` the sensor saw through, else 0.

    points: (cap, 3) float64 in the model's frame; camera_from_model: (4, 4); zmin: nearest
    depth per cell (0: none measured); margin: as a fraction of that depth.
    """
    rows, columns = zmin.shape
    for i in range(n):
        through[i] = 0
        row, column, z = _cell_of(points, i, camera_from_model, u_min, v_min, inv_cell, rows,
                                  columns)
        if row < 0:
            continue
        nearest = zmin[row, column]
        if nearest > 0.0 and z < nearest * (1.0 - margin):
            through[i] = 1


@njit(cache=True)
def near_unmeasured(pos, n, camera_from_model, measured, u_min, v_min, inv_cell, reach, near):
    """``near[i]`` = 1 for each node ``i < n`` with an unmeasured cell (or the grid's edge)
    within ``reach`` (model units, seen at the node's depth) of its own cell, else 0. Nodes
    behind the camera or off the grid count as near."""
    rows, columns = measured.shape[0] - 1, measured.shape[1] - 1
    for i in range(n):
        near[i] = 1
        row, column, z = _cell_of(pos, i, camera_from_model, u_min, v_min, inv_cell, rows,
                                  columns)
        if row < 0:
            continue
        if _all_measured(measured, row, column, max(1, math.ceil(reach / z * inv_cell))):
            near[i] = 0


@njit(cache=True)
def gap_samples(pos, pairs, camera_from_model, zmin, zmax, u_min, v_min, inv_cell, margin,
                samples, missing, blocked, hidden):
    """For each pair (i, j) of ``pairs`` (P, 2), of ``samples`` points evenly inside the segment
    from node i to node j: ``missing[p]`` how many fall on unmeasured cells, ``blocked[p]`` how
    many the sensor saw through (in front of the nearest depth of their cell by more than
    ``margin`` times it), saw behind a nearer surface (behind the farthest by as much) or could
    not see (behind the camera, off the grid), ``hidden[p]`` how many of those it saw behind a
    nearer surface."""
    rows, columns = zmax.shape
    point = np.empty((1, 3))
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        missing[p] = 0
        blocked[p] = 0
        hidden[p] = 0
        for s in range(1, samples + 1):
            t = s / (samples + 1.0)
            for axis in range(3):
                point[0, axis] = pos[i, axis] * (1.0 - t) + pos[j, axis] * t
            row, column, z = _cell_of(point, 0, camera_from_model, u_min, v_min, inv_cell,
                                      rows, columns)
            if row < 0:
                blocked[p] += 1
            elif zmax[row, column] == 0.0:
                missing[p] += 1
            elif z > zmax[row, column] * (1.0 + margin):
                blocked[p] += 1
                hidden[p] += 1
            elif z < zmin[row, column] * (1.0 - margin):
                blocked[p] += 1
