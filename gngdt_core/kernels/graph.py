"""The adjacency with a fixed maximum degree: edge slots, edges, node deletion.

They work on a `layout.Network`'s ``nbr``, ``age``, ``emask``, ``rev`` and ``deg``; deleting a
node moves the last node's properties, edges and grid entry into its place.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import inlined
from gngdt.core.kernels.grid import _grid_rename, grid_remove


@inlined
def find_slot(net, i, j):
    """Slot of neighbour ``j`` in row ``i``, or -1."""
    for k in range(net.deg[i]):
        if net.nbr[i, k] == j:
            return k
    return -1


@inlined
def add_edge(net, i, j, mask):
    """Connect ``i`` and ``j`` with age 0 and property bits ``mask``; False on degree overflow."""
    nbr = net.nbr
    deg = net.deg
    ki = deg[i]
    kj = deg[j]
    if ki >= nbr.shape[1] or kj >= nbr.shape[1]:
        return False
    nbr[i, ki] = j
    nbr[j, kj] = i
    net.age[i, ki] = 0
    net.age[j, kj] = 0
    net.emask[i, ki] = mask
    net.emask[j, kj] = mask
    net.rev[i, ki] = kj
    net.rev[j, kj] = ki
    deg[i] = ki + 1
    deg[j] = kj + 1
    return True


@inlined
def _drop_slot(net, i, k):
    """Remove slot ``k`` of row ``i`` only (the twin is handled by the caller)."""
    nbr = net.nbr
    rev = net.rev
    last = net.deg[i] - 1
    if k != last:
        nbr[i, k] = nbr[i, last]
        net.age[i, k] = net.age[i, last]
        net.emask[i, k] = net.emask[i, last]
        rev[i, k] = rev[i, last]
        rev[nbr[i, k], rev[i, k]] = k
    net.deg[i] = last


@inlined
def remove_edge(net, i, k):
    """Delete the edge at slot ``k`` of node ``i`` (all properties), from both endpoints."""
    j = net.nbr[i, k]
    kj = net.rev[i, k]
    _drop_slot(net, i, k)
    _drop_slot(net, j, kj)


@njit(cache=True)
def delete_node(net, i, n):
    """Delete isolated node ``i`` of the ``n`` in use by moving the last node ``n-1`` into its
    slot. Returns n - 1 (the index the moved node had)."""
    grid_remove(net, i)
    last = n - 1
    pos = net.pos
    nbr = net.nbr
    deg = net.deg
    if i != last:
        for a in range(pos.shape[1]):
            pos[i, a] = pos[last, a]
        for a in range(3):
            net.col[i, a] = net.col[last, a]
            net.nor[i, a] = net.nor[last, a]
        net.err[i] = net.err[last]
        net.ids[i] = net.ids[last]
        net.util[i] = net.util[last]
        net.judged[i] = net.judged[last]
        net.wins[i] = net.wins[last]
        d = deg[last]
        for k in range(d):
            j = nbr[last, k]
            nbr[i, k] = j
            net.age[i, k] = net.age[last, k]
            net.emask[i, k] = net.emask[last, k]
            net.rev[i, k] = net.rev[last, k]
            nbr[j, net.rev[last, k]] = i
        deg[i] = d
        _grid_rename(net, last, i)
    deg[last] = 0
    return last


@njit(cache=True)
def edge_list(nbr, deg, emask, n, mask):
    """(E, 2) int64 pairs ``i < j`` of the edges among the first ``n`` nodes whose property bits
    include every bit of ``mask``, by ``i`` then by slot: ``nbr`` (cap, K) int32 neighbours,
    ``deg`` (cap,) int32 slots in use, ``emask`` (cap, K) uint8 property bits of each slot."""
    count = 0
    for i in range(n):
        for k in range(deg[i]):
            if nbr[i, k] > i and (emask[i, k] & mask) == mask:
                count += 1
    pairs = np.empty((count, 2), dtype=np.int64)
    e = 0
    for i in range(n):
        for k in range(deg[i]):
            j = nbr[i, k]
            if j > i and (emask[i, k] & mask) == mask:
                pairs[e, 0] = i
                pairs[e, 1] = j
                e += 1
    return pairs


@njit(cache=True)
def component_roots(n, pairs):
    """(n,) int64 a representative node of each node's connected component in the graph of
    ``pairs`` (E, 2) int64 node indices, 0 <= index < n (union-find with path halving)."""
    parent = np.arange(n)
    for e in range(pairs.shape[0]):
        a = pairs[e, 0]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        b = pairs[e, 1]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
    for i in range(n):  # parents have lower indices: one pass in order resolves every root
        parent[i] = parent[parent[i]]
    return parent
