"""Numba kernels of step 6 of `segment_network` (`gngdt.core.segmentation.gaps`): node pairs
across a gap only the network shows (the network's border nodes, pairs of them close in space
whose middle no node is near), and the joins of segments across gaps.

They take plain arrays (positions, CSR adjacency, labels, pairs) and return new ones.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import inlined
from gngdt.core.kernels.regions import _find


@njit(cache=True)
def join_across_gaps(n_labels, low, high, crossing, creases, order, rim, crease_share):
    """(n_labels,) int64 representative of each segment after joining the segment pairs
    (low[k], high[k]) for k in ``order``, each only while at most ``crease_share`` of all the
    node pairs crossing between the two growing unions (``crossing``, per segment pair) are
    creases (``creases``); a ``rim`` pair joins regardless (`segmentation.gaps`)."""
    parent = np.arange(n_labels)
    for k in order:
        a = _find(parent, low[k])
        b = _find(parent, high[k])
        if a == b:
            continue
        if not rim[k]:
            total = 0.0
            folded = 0.0
            for q in range(low.size):
                x = _find(parent, low[q])
                y = _find(parent, high[q])
                if (x == a and y == b) or (x == b and y == a):
                    total += crossing[q]
                    folded += creases[q]
            if folded > crease_share * total:
                continue
        parent[b] = a
    for x in range(n_labels):
        _find(parent, x)
    return parent


@njit(cache=True)
def close_pairs_between(positions, nodes, labels, reach):
    """(P, 2) int64 pairs (i, j), i < j, of ``nodes`` at most ``reach`` apart whose
    ``labels`` differ (both >= 0): a hash grid of cells ``reach`` wide; each pair of cells is
    visited once (a cell and the cells after it in key order among its 26 neighbours)."""
    m = nodes.size
    inv = 1.0 / reach
    cell = np.empty((m, 3), dtype=np.int64)
    key = np.empty(m, dtype=np.int64)
    for k in range(m):
        for axis in range(3):
            cell[k, axis] = np.int64(math.floor(positions[nodes[k], axis] * inv))
        key[k] = _cell_key(cell[k, 0], cell[k, 1], cell[k, 2])
    order = np.argsort(key)
    sorted_key = key[order]
    limit = reach * reach
    capacity = 4 * m + 16
    result = np.empty((capacity, 2), dtype=np.int64)
    count = 0
    # runs of three consecutive keys (z - 1 .. z + 1) at these (dx, dy), and the own run from
    # the node's place on: every pair of nearby nodes once
    later = ((0, 1), (1, -1), (1, 0), (1, 1))
    for a in range(m):
        k = order[a]
        i = nodes[k]
        if labels[i] < 0:
            continue
        for run in range(5):
            if run == 0:
                slot = a + 1
                last = _cell_key(cell[k, 0], cell[k, 1], cell[k, 2] + 1)
            else:
                dx, dy = later[run - 1]
                first = _cell_key(cell[k, 0] + dx, cell[k, 1] + dy, cell[k, 2] - 1)
                slot = _lower_bound(sorted_key, first)
                last = first + 2
            while slot < m and sorted_key[slot] <= last:
                j = nodes[order[slot]]
                slot += 1
                if labels[j] < 0 or labels[j] == labels[i]:
                    continue
                d = ((positions[i, 0] - positions[j, 0]) ** 2
                     + (positions[i, 1] - positions[j, 1]) ** 2
                     + (positions[i, 2] - positions[j, 2]) ** 2)
                if d > limit:
                    continue
                if count == capacity:
                    grown = np.empty((2 * capacity, 2), dtype=np.int64)
                    grown[:count] = result[:count]
                    result = grown
                    capacity *= 2
                result[count, 0] = min(i, j)
                result[count, 1] = max(i, j)
                count += 1
    return result[:count].copy()


@inlined
def _lower_bound(values, target):
    """The first index of ascending ``values`` whose value is >= ``target``."""
    low, high = 0, values.size
    while low < high:
        middle = (low + high) >> 1
        if values[middle] < target:
            low = middle + 1
        else:
            high = middle
    return low


@inlined
def _cell_key(x, y, z):
    """One int64 per grid cell (cells within 2**20 of the origin on each axis); cells with the
    same x and y and consecutive z have consecutive keys."""
    return ((x + (1 << 20)) << 42) | ((y + (1 << 20)) << 21) | (z + (1 << 20))


@njit(cache=True)
def border_nodes(positions, offsets, neighbours, share):
    """(n,) bool: nodes whose unit vectors to their neighbours (CSR ``offsets``/``neighbours``)
    sum to more than ``share`` of their degree: their neighbours lie mostly on one side, at the
    border of the network (an object's outline, a stripe of missing depth); nodes without
    neighbours too."""
    n = offsets.size - 1
    result = np.zeros(n, dtype=np.bool_)
    for u in range(n):
        sx = sy = sz = 0.0
        for slot in range(offsets[u], offsets[u + 1]):
            v = neighbours[slot]
            d0 = positions[v, 0] - positions[u, 0]
            d1 = positions[v, 1] - positions[u, 1]
            d2 = positions[v, 2] - positions[u, 2]
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if length > 0.0:
                sx += d0 / length
                sy += d1 / length
                sz += d2 / length
        degree = offsets[u + 1] - offsets[u]
        result[u] = degree == 0 or math.sqrt(sx * sx + sy * sy + sz * sz) > share * degree
    return result


@njit(cache=True)
def empty_between(positions, offsets, neighbours, pairs, share):
    """(P,) bool: for each node pair (i, j) of ``pairs`` (P, 2), no neighbour of i or j (CSR
    ``offsets``/``neighbours``) lies nearer the middle of i and j than ``share`` of half their
    distance: the line between them crosses a region the network left empty."""
    result = np.ones(pairs.shape[0], dtype=np.bool_)
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        m0 = 0.5 * (positions[i, 0] + positions[j, 0])
        m1 = 0.5 * (positions[i, 1] + positions[j, 1])
        m2 = 0.5 * (positions[i, 2] + positions[j, 2])
        half = 0.5 * math.sqrt((positions[i, 0] - positions[j, 0]) ** 2
                               + (positions[i, 1] - positions[j, 1]) ** 2
                               + (positions[i, 2] - positions[j, 2]) ** 2)
        limit = (share * half) ** 2
        for end in (i, j):
            for slot in range(offsets[end], offsets[end + 1]):
                v = neighbours[slot]
                if v == i or v == j:
                    continue
                d = ((positions[v, 0] - m0) ** 2 + (positions[v, 1] - m1) ** 2
                     + (positions[v, 2] - m2) ** 2)
                if d < limit:
                    result[p] = False
    return result
