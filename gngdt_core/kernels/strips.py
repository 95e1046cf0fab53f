"""Edges chained into polylines (`gngdt.schemas.cluster_colors.edge_strips`), in one compiled
pass."""

from __future__ import annotations

import numpy as np
from numba import njit


def chain_edges(pairs: np.ndarray, classes: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """See `_chain_edges`; the ends' (class, node) order is sorted by NumPy (`stable_order`)."""
    pairs = np.ascontiguousarray(pairs, dtype=np.int64)
    classes = np.ascontiguousarray(classes, dtype=np.int64)
    ends = pairs.ravel()
    lowest = int(ends.min())
    span = int(ends.max()) - lowest + 1
    keys = (np.repeat(classes, 2) + 1) * span + (ends - lowest)
    return _chain_edges(pairs, classes, keys, stable_order(keys))


def stable_order(keys: np.ndarray) -> np.ndarray:
    """``np.argsort(keys, kind="stable")`` of (M,) int64 ``keys`` >= 0: as numpy's default sort
    of the distinct keys (key, index) when they fit in an int64 (4x faster than its stable
    sort of int64)."""
    count = keys.size
    if count and int(keys.max()) < 2**62 // count:
        return np.argsort(keys * count + np.arange(count))
    return np.argsort(keys, kind="stable")


@njit(cache=True)
def _chain_edges(pairs, classes, keys, order):
    """`edge_strips` of loop-free ``pairs`` (E, 2) int64 and ``classes`` (E,) int64, E >= 1:
    the same (nodes, starts, strip_classes), by walking each trail instead of pointer jumping.

    Traversal h walks edge h >> 1 from its end h to end h ^ 1; at each node the ends of one
    class are paired in (class, node, index) order; a trail follows the pairs, a closed loop is
    cut at its smallest traversal, and of the two directions of a trail the one with the
    smaller first traversal is kept. Trails are listed by first traversal.
    """
    n_ends = 2 * pairs.shape[0]
    ends = pairs.ravel()
    partner = np.full(n_ends, -1, dtype=np.int64)
    group_start = 0
    for i in range(n_ends - 1):
        if i > 0 and keys[order[i]] != keys[order[i - 1]]:
            group_start = i
        if keys[order[i + 1]] == keys[order[i]] and (i - group_start) % 2 == 0:
            partner[order[i]] = order[i + 1]
            partner[order[i + 1]] = order[i]
    # the traversal after t starts at the end paired with t's arrival end
    after = np.full(n_ends, -1, dtype=np.int64)
    has_before = np.zeros(n_ends, dtype=np.bool_)
    for t in range(n_ends):
        p = partner[t ^ 1]
        if p >= 0:
            after[t] = p
            has_before[p] = True
    head = np.full(n_ends, -1, dtype=np.int64)
    for t in range(n_ends):  # open trails start where nothing comes before
        if not has_before[t]:
            u = t
            while u >= 0:
                head[u] = t
                u = after[u]
    for t in range(n_ends):  # what is left are closed loops, cut at their smallest traversal
        if head[t] < 0:
            u = t
            while head[u] < 0:
                head[u] = t
                u = after[u]
    # kept trails, by first traversal: each point once, plus one start point per trail
    n_trails = 0
    n_points = 0
    for t in range(n_ends):
        if head[t] == t and t < head[t ^ 1]:
            n_trails += 1
            u = t
            while True:
                n_points += 1
                u = after[u]
                if u < 0 or u == t:
                    break
    nodes = np.empty(n_points + n_trails, dtype=np.int64)
    starts = np.empty(n_trails + 1, dtype=np.int64)
    strip_classes = np.empty(n_trails, dtype=np.int64)
    k = 0
    s = 0
    for t in range(n_ends):
        if head[t] == t and t < head[t ^ 1]:
            starts[s] = k
            strip_classes[s] = classes[t >> 1]
            s += 1
            nodes[k] = ends[t]
            k += 1
            u = t
            while True:
                nodes[k] = ends[u ^ 1]
                k += 1
                u = after[u]
                if u < 0 or u == t:
                    break
    starts[n_trails] = k
    return nodes, starts, strip_classes
