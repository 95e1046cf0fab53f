"""Numba kernels of `segment_network` (`gngdt.core.segmentation.network`,
`gngdt.core.segmentation.supports`): the network's graph as CSR adjacency, edge elevations and long
edges, smooth patches, the boundary statistics between regions and their joins, support planes.

They take plain arrays (positions, normals, edges, labels) and return new ones.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit, types
from numba.typed import Dict

from gngdt.core.kernels._numba import inlined


@njit(cache=True)
def grow_patches(n, offsets, neighbours, usable, normals, seeds, cos_patch):
    """Region growing over usable edges (CSR ``offsets``/``neighbours``/``usable``), seeds in the
    given order; a node joins while its normal is within ``acos(cos_patch)`` of the patch's
    running mean normal. Returns (n,) int32 patch labels."""
    patch = np.full(n, -1, dtype=np.int32)
    queue = np.empty(n, dtype=np.int64)
    n_patches = 0
    for seed in seeds:
        if patch[seed] >= 0:
            continue
        patch[seed] = n_patches
        queue[0] = seed
        head = 0
        tail = 1
        sx = normals[seed, 0]
        sy = normals[seed, 1]
        sz = normals[seed, 2]
        while head < tail:
            u = queue[head]
            head += 1
            for slot in range(offsets[u], offsets[u + 1]):
                v = neighbours[slot]
                if not usable[slot] or patch[v] >= 0:
                    continue
                norm = math.sqrt(sx * sx + sy * sy + sz * sz)
                if norm <= 0.0:
                    continue
                if normals[v, 0] * sx + normals[v, 1] * sy + normals[v, 2] * sz < cos_patch * norm:
                    continue
                patch[v] = n_patches
                queue[tail] = v
                tail += 1
                sx += normals[v, 0]
                sy += normals[v, 1]
                sz += normals[v, 2]
        n_patches += 1
    return patch


# -------------------------------------------------------------------------------- region merging


@njit(cache=True)
def boundary_pairs(patch, offsets, neighbours, positions, normals, sin_concave, sin_crease):
    """Node pairs across patch borders, and what they say about the two patches.

    Position edges (u, v) and two-edge paths (u, v, w) whose ends lie in different patches (each
    pair once, from its lower end; a pair reached by two paths counts twice). Returns per pair
    the patches ``low`` < ``high`` (int64) and ``flags`` (uint8): bit 0 a position edge, bit 1
    that edge is convex (neither end rises above the other's tangent plane by more than
    ``asin(sin_concave)``), bit 2 a crease (one end rises above the other's tangent plane by more
    than ``asin(sin_crease)``: a sharp concave fold or a step, not the gentle bend of a curved
    surface). Elevations as `segmentation.edge_elevations`.
    """
    n = patch.size
    # a pair across patches has a node with a neighbour in another patch at or next to its
    # lower end: only those ends are visited
    border = np.zeros(n, dtype=np.bool_)
    for u in range(n):
        for slot in range(offsets[u], offsets[u + 1]):
            if patch[neighbours[slot]] != patch[u]:
                border[u] = True
                break
    visit = border.copy()
    capacity = 0
    for v in range(n):
        degree = offsets[v + 1] - offsets[v]
        if border[v]:
            for slot in range(offsets[v], offsets[v + 1]):
                visit[neighbours[slot]] = True
        capacity += degree * degree + degree
    low = np.empty(capacity, dtype=np.int64)
    high = np.empty(capacity, dtype=np.int64)
    flags = np.empty(capacity, dtype=np.uint8)
    count = 0
    for u in range(n):
        if not visit[u]:
            continue
        pu = patch[u]
        for slot in range(offsets[u], offsets[u + 1]):
            v = neighbours[slot]
            if v > u and patch[v] != pu:
                rise = _pair_rise(positions, normals, u, v)
                flag = 1
                if rise < sin_concave:
                    flag |= 2
                if rise > sin_crease:
                    flag |= 4
                low[count] = min(pu, patch[v])
                high[count] = max(pu, patch[v])
                flags[count] = flag
                count += 1
            for slot2 in range(offsets[v], offsets[v + 1]):
                w = neighbours[slot2]
                if w <= u or patch[w] == pu:
                    continue
                low[count] = min(pu, patch[w])
                high[count] = max(pu, patch[w])
                flags[count] = 4 if _pair_rise(positions, normals, u, w) > sin_crease else 0
                count += 1
    return low[:count], high[:count], flags[:count]


@inlined
def _pair_rise(positions, normals, i, j):
    """The larger of the two elevations' sines of node pair (i, j): how far either end rises
    above the other's tangent plane."""
    d0 = positions[j, 0] - positions[i, 0]
    d1 = positions[j, 1] - positions[i, 1]
    d2 = positions[j, 2] - positions[i, 2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length <= 0.0:
        return 0.0
    rise_j = (normals[i, 0] * d0 + normals[i, 1] * d1 + normals[i, 2] * d2) / length
    rise_i = -(normals[j, 0] * d0 + normals[j, 1] * d1 + normals[j, 2] * d2) / length
    return max(rise_j, rise_i)


@njit(cache=True)
def pair_statistics(n_regions, low, high, flags):
    """Per distinct region pair (low < high) of `boundary_pairs`' rows: the pair and (K, 4)
    int64 counts: position edges, convex edges, node pairs (edges and two-edge paths),
    creases. Linear time: rows are bucketed by ``low``, then summed per ``high``."""
    start = np.zeros(n_regions + 1, dtype=np.int64)
    for r in range(low.size):
        start[low[r] + 1] += 1
    for a in range(n_regions):
        start[a + 1] += start[a]
    fill = start[:-1].copy()
    order = np.empty(low.size, dtype=np.int64)
    for r in range(low.size):
        order[fill[low[r]]] = r
        fill[low[r]] += 1
    slot_of = np.full(n_regions, -1, dtype=np.int64)
    pair_low = np.empty(low.size, dtype=np.int64)
    pair_high = np.empty(low.size, dtype=np.int64)
    counts = np.zeros((low.size, 4), dtype=np.int64)
    n_pairs = 0
    for a in range(n_regions):
        first = n_pairs
        for k in range(start[a], start[a + 1]):
            r = order[k]
            b = high[r]
            s = slot_of[b]
            if s < 0:
                s = n_pairs
                slot_of[b] = s
                pair_low[s] = a
                pair_high[s] = b
                n_pairs += 1
            flag = flags[r]
            if flag & 1:
                counts[s, 0] += 1
                if flag & 2:
                    counts[s, 1] += 1
            counts[s, 2] += 1
            if flag & 4:
                counts[s, 3] += 1
        for s in range(first, n_pairs):
            slot_of[pair_high[s]] = -1
    return pair_low[:n_pairs], pair_high[:n_pairs], counts[:n_pairs]


@njit(cache=True)
def nodes_per_side(regions, offsets, neighbours, pair_low, pair_high):
    """(K,) int64 per region pair (pair_low[k], pair_high[k]) of `pair_statistics`: how many
    distinct nodes with a position edge across the pair lie on the side that has fewer (CSR
    ``offsets``/``neighbours``; regions: (n,) int)."""
    n_regions = 0
    for u in range(regions.size):
        n_regions = max(n_regions, regions[u] + 1)
    slot_of = Dict.empty(key_type=types.int64, value_type=types.int64)
    for k in range(pair_low.size):
        slot_of[pair_low[k] * n_regions + pair_high[k]] = k
    count = np.zeros((pair_low.size, 2), dtype=np.int64)
    seen = np.full(n_regions, -1, dtype=np.int64)  # the last node that counted each region
    for u in range(regions.size):
        own = regions[u]
        for slot in range(offsets[u], offsets[u + 1]):
            other = regions[neighbours[slot]]
            if other == own or seen[other] == u:
                continue
            seen[other] = u
            key = min(own, other) * n_regions + max(own, other)
            if key in slot_of:
                count[slot_of[key], 1 if own > other else 0] += 1
    result = np.empty(pair_low.size, dtype=np.int64)
    for k in range(pair_low.size):
        result[k] = min(count[k, 0], count[k, 1])
    return result


@inlined
def _find(parent, x):
    root = x
    while parent[root] != root:
        root = parent[root]
    while parent[x] != root:
        following = parent[x]
        parent[x] = root
        x = following
    return root


@inlined
def _may_join(counts, e, rule):
    """Whether pair slot e may join under ``rule`` (`join_regions`)."""
    edges = counts[e, 0]
    convex = counts[e, 1]
    return (edges >= rule[0] and convex >= rule[1]
            and (convex >= rule[2] * edges or counts[e, 3] == 0)
            and counts[e, 3] <= rule[3] * counts[e, 2])


@njit(cache=True)
def join_regions(n_regions, pair_low, pair_high, counts, fixed, rule):
    """Agglomerative merging of regions (patches) by their boundary statistics.

    pair_low, pair_high, counts: `pair_statistics`; fixed: (n_regions,) bool regions that never
    join anything (support surfaces); rule: (4,) float64 ``min_edges, min_convex,
    convex_share, crease_share``. Two adjacent regions may join when at least ``min_edges``
    position edges lie between them, at least ``min_convex`` of those are convex and
    ``convex_share`` of them are (or no node pair between them is a crease), and at most
    ``crease_share`` of the node pairs between them are creases. Pairs are joined surest first
    (fewest creases, most convex boundary, longest); after each join the statistics of the
    union with every neighbour are the sums of its parts', so later joins judge the whole union: a
    chain of small patches cannot carry one object into another once their union has creases
    between them. Returns (n_regions,) int64 the representative region of each.
    """
    n_pairs = pair_low.size
    counts = counts.copy()
    parent = np.arange(n_regions)
    key_slot = Dict.empty(key_type=types.int64, value_type=types.int64)
    # each region's pairs: singly linked lists of pair slots, concatenated on a join
    head = np.full(n_regions, -1, dtype=np.int64)
    tail = np.full(n_regions, -1, dtype=np.int64)
    size = np.zeros(n_regions, dtype=np.int64)
    link = np.full(2 * n_pairs, -1, dtype=np.int64)  # entry 2e: in low's list, 2e+1: high's
    heap = [(0.0, 0.0, 0, 0)]
    heap.pop()
    for e in range(n_pairs):
        a = pair_low[e]
        b = pair_high[e]
        key_slot[a * n_regions + b] = e
        for end, region in ((0, a), (1, b)):
            entry = 2 * e + end
            if head[region] < 0:
                head[region] = entry
            else:
                link[tail[region]] = entry
            tail[region] = entry
            size[region] += 1
        if not fixed[a] and not fixed[b] and _may_join(counts, e, rule):
            heapq.heappush(heap, _priority(counts, e))
    while heap:
        item = heapq.heappop(heap)
        e = item[3]
        a = _find(parent, pair_low[e])
        b = _find(parent, pair_high[e])
        if a == b:
            continue
        key = min(a, b) * n_regions + max(a, b)
        if _slot(key_slot, key) != e or not _may_join(counts, e, rule):
            continue
        if size[a] < size[b]:
            a, b = b, a
        parent[b] = a  # b's pairs move to a, summed where a has the same neighbour
        del key_slot[key]
        entry = head[b]
        while entry >= 0:
            f = entry // 2
            other = _find(parent, pair_high[f] if entry % 2 == 0 else pair_low[f])
            if other != a:
                old = min(b, other) * n_regions + max(b, other)
                if _slot(key_slot, old) == f:
                    del key_slot[old]
                    new = min(a, other) * n_regions + max(a, other)
                    g = _slot(key_slot, new)
                    if g >= 0:
                        for c in range(4):
                            counts[g, c] += counts[f, c]
                        target = g
                    else:
                        key_slot[new] = f
                        target = f
                    if not fixed[other] and _may_join(counts, target, rule):
                        heapq.heappush(heap, _priority(counts, target))
            entry = link[entry]
        if head[b] >= 0:
            if head[a] < 0:
                head[a] = head[b]
            else:
                link[tail[a]] = head[b]
            tail[a] = tail[b]
        size[a] += size[b]
    for r in range(n_regions):
        _find(parent, r)
    return parent


@inlined
def _slot(key_slot, key):
    """The pair slot stored under ``key``, -1 if none."""
    if key in key_slot:
        return key_slot[key]
    return -1


@inlined
def _priority(counts, e):
    """Heap key of pair slot e: fewest creases first, then the most convex boundary, then the
    longest."""
    return (counts[e, 3] / max(counts[e, 2], 1), -counts[e, 1] / max(counts[e, 0], 1),
            -counts[e, 0], e)


# ------------------------------------------------------------------------------- support planes


@njit(cache=True)
def grow_supports(offsets, neighbours, plane, seed, patch, n_patches, n_supports):
    """Support planes' nodes, and the patches left over.

    plane: (n,) int64 the support plane each node lies on (-1: none); seed: (n,) bool nodes of
    a support's own patch that lie on its plane. A support takes every node on its plane
    connected to its seeds through such nodes (breadth first over the CSR adjacency
    ``offsets``/``neighbours``). Returns (n,) int32 patches: support s is patch s; every other
    node keeps its ``patch`` (< n_patches) shifted by n_supports, except nodes that were in a
    support's patch but not taken, which get new patches, one per connected group.
    """
    n = plane.size
    result = np.full(n, -1, dtype=np.int32)
    queue = np.empty(n, dtype=np.int64)
    tail = 0
    for u in range(n):
        if seed[u]:
            result[u] = plane[u]
            queue[tail] = u
            tail += 1
    head = 0
    while head < tail:
        u = queue[head]
        head += 1
        for slot in range(offsets[u], offsets[u + 1]):
            v = neighbours[slot]
            if result[v] < 0 and plane[v] == result[u]:
                result[v] = result[u]
                queue[tail] = v
                tail += 1
    # support patches lose the nodes not taken: each connected group of them is a new patch
    was_support = np.zeros(n_patches, dtype=np.bool_)
    for u in range(n):
        if seed[u]:
            was_support[patch[u]] = True
    next_patch = n_supports + n_patches
    for u in range(n):
        if result[u] >= 0:
            continue
        if not was_support[patch[u]]:
            result[u] = n_supports + patch[u]
            continue
        result[u] = next_patch
        queue[0] = u
        head = 0
        tail = 1
        while head < tail:
            w = queue[head]
            head += 1
            for slot in range(offsets[w], offsets[w + 1]):
                v = neighbours[slot]
                if result[v] < 0 and patch[v] == patch[u]:
                    result[v] = next_patch
                    queue[tail] = v
                    tail += 1
        next_patch += 1
    return result


# -------------------------------------------------------------------------- edges and adjacency


@njit(cache=True)
def edge_rises(positions, normals, edges):
    """(E,) sines of the elevations of each edge's ends (`segmentation.edge_elevations`): how
    far j rises above i's tangent plane, and i above j's."""
    rise_of_j = np.zeros(edges.shape[0])
    rise_of_i = np.zeros(edges.shape[0])
    for k in range(edges.shape[0]):
        i = edges[k, 0]
        j = edges[k, 1]
        d0 = positions[j, 0] - positions[i, 0]
        d1 = positions[j, 1] - positions[i, 1]
        d2 = positions[j, 2] - positions[i, 2]
        length = max(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2), 1e-300)
        rise_of_j[k] = (normals[i, 0] * d0 + normals[i, 1] * d1 + normals[i, 2] * d2) / length
        rise_of_i[k] = -(normals[j, 0] * d0 + normals[j, 1] * d1 + normals[j, 2] * d2) / length
    return rise_of_j, rise_of_i


@njit(cache=True)
def csr_adjacency(n, edges, flags):
    """CSR adjacency of an undirected edge list: offsets (n+1,), neighbours (2E,) and their
    flags (2E,); each node's neighbours in edge order, first as the edge's first end, then as
    its second (a stable sort of the concatenated ends)."""
    n_edges = edges.shape[0]
    offsets = np.zeros(n + 1, dtype=np.int64)
    for k in range(n_edges):
        offsets[edges[k, 0] + 1] += 1
        offsets[edges[k, 1] + 1] += 1
    for u in range(n):
        offsets[u + 1] += offsets[u]
    fill = offsets[:-1].copy()
    neighbours = np.empty(2 * n_edges, dtype=np.int64)
    usable = np.empty(2 * n_edges, dtype=np.bool_)
    for end in range(2):
        for k in range(n_edges):
            u = edges[k, end]
            neighbours[fill[u]] = edges[k, 1 - end]
            usable[fill[u]] = flags[k]
            fill[u] += 1
    return offsets, neighbours, usable


@njit(cache=True)
def long_edges(n, positions, edges, ratio):
    """(E,) bool: edges longer than ``ratio`` times the shortest edge at either end (the local
    spacing): stale edges across free space between two surfaces, not adjacency on one."""
    n_edges = edges.shape[0]
    length = np.empty(n_edges)
    shortest = np.full(n, np.inf)
    for k in range(n_edges):
        i = edges[k, 0]
        j = edges[k, 1]
        d0 = positions[j, 0] - positions[i, 0]
        d1 = positions[j, 1] - positions[i, 1]
        d2 = positions[j, 2] - positions[i, 2]
        length[k] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        shortest[i] = min(shortest[i], length[k])
        shortest[j] = min(shortest[j], length[k])
    result = np.empty(n_edges, dtype=np.bool_)
    for k in range(n_edges):
        spacing = max(shortest[edges[k, 0]], shortest[edges[k, 1]])
        result[k] = length[k] > ratio * spacing
    return result


@njit(cache=True)
def node_roughness(n, edges, steepest):
    """(n,) the largest ``steepest`` (per edge) of the edges at each node (0: none)."""
    roughness = np.zeros(n)
    for k in range(edges.shape[0]):
        value = steepest[k]
        if value > roughness[edges[k, 0]]:
            roughness[edges[k, 0]] = value
        if value > roughness[edges[k, 1]]:
            roughness[edges[k, 1]] = value
    return roughness


@njit(cache=True)
def absorb_fragments(labels, edges, convex, min_nodes):
    """Fragments (segments below ``min_nodes`` nodes) join a larger segment, never bridging
    two. Fragments linked by edges form chains; a chain that touches exactly one larger segment
    joins it whole; in any other chain each fragment next to a larger segment joins the one it
    shares the most convex edges with (then the most edges, then the lowest label).

    labels: (n,) int segment of every node (>= 0); edges: (E, 2) node pairs; convex: (E,) bool.
    Returns the new (n,) int64 labels."""
    labels = labels.astype(np.int64)
    n_labels = labels.max() + 1 if labels.size else 0
    sizes = np.zeros(n_labels, dtype=np.int64)
    for label in labels:
        sizes[label] += 1
    small = sizes < min_nodes
    chain = np.arange(n_labels)
    for e in range(edges.shape[0]):
        a, b = labels[edges[e, 0]], labels[edges[e, 1]]
        if small[a] and small[b]:
            ra, rb = _find(chain, a), _find(chain, b)
            if ra != rb:
                chain[max(ra, rb)] = min(ra, rb)
    # the larger segment each chain touches (-2: several), and each fragment's best neighbour
    sole_host = np.full(n_labels, -1, dtype=np.int64)
    score = Dict.empty(key_type=types.int64, value_type=types.float64)
    for e in range(edges.shape[0]):
        for side in range(2):
            fragment, host = labels[edges[e, side]], labels[edges[e, 1 - side]]
            if not small[fragment] or small[host]:
                continue
            root = _find(chain, fragment)
            if sole_host[root] == -1:
                sole_host[root] = host
            elif sole_host[root] != host:
                sole_host[root] = -2
            key = fragment * n_labels + host
            score[key] = score.get(key, 0.0) + convex[e] * (edges.shape[0] + 1.0) + 1.0
    best_score = np.full(n_labels, -1.0)
    destination = np.arange(n_labels)
    for key, value in score.items():
        fragment, host = key // n_labels, key % n_labels
        if value > best_score[fragment] or (value == best_score[fragment]
                                            and host < destination[fragment]):
            best_score[fragment] = value
            destination[fragment] = host
    for label in range(n_labels):
        if small[label]:
            host = sole_host[_find(chain, label)]
            if host >= 0:
                destination[label] = host
    return destination[labels]


@njit(cache=True)
def outside_convex_hull(points, queries):
    """(Q,) bool: which ``queries`` (Q, 2) lie strictly outside the convex hull of ``points``
    (P >= 1, 2) (Andrew's monotone chain; when the points span no area the hull is a segment
    or a point and anything off it is outside)."""
    by_y = np.argsort(points[:, 1], kind="mergesort")
    order = by_y[np.argsort(points[by_y, 0], kind="mergesort")]  # by x, then y
    n = len(points)
    hull = np.empty((2 * n + 1, 2))
    size = 0
    for k in range(n):  # lower hull, left to right
        while size >= 2 and _turn(hull[size - 2], hull[size - 1], points[order[k]]) <= 0.0:
            size -= 1
        hull[size] = points[order[k]]
        size += 1
    lower = size + 1
    for k in range(n - 2, -1, -1):  # upper hull, right to left
        while size >= lower and _turn(hull[size - 2], hull[size - 1], points[order[k]]) <= 0.0:
            size -= 1
        hull[size] = points[order[k]]
        size += 1
    size = max(size - 1, 1)  # the last point is the first
    outside = np.zeros(len(queries), dtype=np.bool_)
    for q in range(len(queries)):
        if size < 3:  # no area: only what lies on the segment (or the point) is inside
            outside[q] = not _on_segment(hull[0], hull[size - 1], queries[q])
            continue
        for k in range(size):
            if _turn(hull[k], hull[(k + 1) % size], queries[q]) < 0.0:
                outside[q] = True
                break
    return outside


@inlined
def _turn(o, a, b):
    """Twice the signed area of (o, a, b): > 0 when b lies left of o -> a."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


@inlined
def _on_segment(a, b, q):
    return (_turn(a, b, q) == 0.0 and min(a[0], b[0]) <= q[0] <= max(a[0], b[0])
            and min(a[1], b[1]) <= q[1] <= max(a[1], b[1]))
