"""The adjacency with a fixed maximum degree: edge slots, edges, node deletion.

Arrays: ``nbr``, ``age``, ``emask``, ``rev``, ``deg`` (see `layout`); deleting a node moves the
last node's properties, edges and grid entry into its place.
"""

from __future__ import annotations

from numba import njit

from gngdt.core.kernels._numba import inlined
from gngdt.core.kernels.grid import _grid_rename, grid_remove


@inlined
def find_slot(nbr, deg, i, j):
    """Slot of neighbour ``j`` in row ``i``, or -1."""
    for k in range(deg[i]):
        if nbr[i, k] == j:
            return k
    return -1


@inlined
def add_edge(nbr, age, emask, rev, deg, i, j, mask):
    """Connect ``i`` and ``j`` with age 0 and property bits ``mask``; False on degree overflow."""
    ki = deg[i]
    kj = deg[j]
    if ki >= nbr.shape[1] or kj >= nbr.shape[1]:
        return False
    nbr[i, ki] = j
    nbr[j, kj] = i
    age[i, ki] = 0
    age[j, kj] = 0
    emask[i, ki] = mask
    emask[j, kj] = mask
    rev[i, ki] = kj
    rev[j, kj] = ki
    deg[i] = ki + 1
    deg[j] = kj + 1
    return True


@inlined
def _drop_slot(nbr, age, emask, rev, deg, i, k):
    """Remove slot ``k`` of row ``i`` only (the twin is handled by the caller)."""
    last = deg[i] - 1
    if k != last:
        nbr[i, k] = nbr[i, last]
        age[i, k] = age[i, last]
        emask[i, k] = emask[i, last]
        rev[i, k] = rev[i, last]
        rev[nbr[i, k], rev[i, k]] = k
    deg[i] = last


@inlined
def remove_edge(nbr, age, emask, rev, deg, i, k):
    """Delete the edge at slot ``k`` of node ``i`` (all properties), from both endpoints."""
    j = nbr[i, k]
    kj = rev[i, k]
    _drop_slot(nbr, age, emask, rev, deg, i, k)
    _drop_slot(nbr, age, emask, rev, deg, j, kj)


@njit(cache=True)
def delete_node(i, n, pos, col, nor, err, nbr, age, emask, rev, deg, ids, util, judged, wins,
                ghead, gnext, gprev, gbucket, gcell):
    """Delete isolated node ``i`` by moving the last node ``n-1`` into its slot. Returns n - 1."""
    grid_remove(ghead, gnext, gprev, gbucket, i)
    last = n - 1
    if i != last:
        for a in range(pos.shape[1]):
            pos[i, a] = pos[last, a]
        for a in range(3):
            col[i, a] = col[last, a]
            nor[i, a] = nor[last, a]
        err[i] = err[last]
        ids[i] = ids[last]
        util[i] = util[last]
        judged[i] = judged[last]
        wins[i] = wins[last]
        d = deg[last]
        for k in range(d):
            j = nbr[last, k]
            nbr[i, k] = j
            age[i, k] = age[last, k]
            emask[i, k] = emask[last, k]
            rev[i, k] = rev[last, k]
            nbr[j, rev[last, k]] = i
        deg[i] = d
        _grid_rename(ghead, gnext, gprev, gbucket, gcell, last, i)
    deg[last] = 0
    return last
