"""The spatial hash grid of node positions and the winner searches (Step 2).

The grid is the `layout.Network`'s ``ghead``, ``gnext``, ``gprev``, ``gbucket`` and ``gcell``.
It gives the exact nearest two nodes by position; GNG and GNG-W search by brute force
(`nearest_two_weighted`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import flush_tiny, inlined
from gngdt.core.kernels.layout import MODE_GNG

# Below this many nodes a brute-force winner search is cheaper than the grid.
GRID_MIN_NODES = 48
# Grid cell edge in running node spacings (the search is fastest at about 1.5-2.5), and the factor
# by which the cell may drift from that before the grid is rebuilt.
GRID_CELL_SPACINGS = 2.0
GRID_CELL_TOLERANCE = 1.4
# Relative safety margin of the grid search's distance bounds: cell coordinates carry rounding
# errors of a few ulps, so a cell is skipped (or the search stopped) only when its bound beats the
# best distance by this factor. It costs nothing in exactness, only a rare extra cell visit.
BOUND_SLACK = 1e-9


# --------------------------------------------------------------------------- spatial hash grid


@inlined
def _bucket(cx, cy, cz, table_mask):
    return ((cx * 73856093) ^ (cy * 19349663) ^ (cz * 83492791)) & table_mask


@inlined
def _cell_of(pos, i, inv_cell):
    cx = math.floor(pos[i, 0] * inv_cell)
    cy = math.floor(pos[i, 1] * inv_cell)
    cz = 0.0
    if pos.shape[1] > 2:
        cz = math.floor(pos[i, 2] * inv_cell)
    return np.int64(cx), np.int64(cy), np.int64(cz)


@inlined
def grid_insert(net, i, inv_cell):
    """Put node ``i`` (not in the grid) at the head of its cell's bucket."""
    cx, cy, cz = _cell_of(net.pos, i, inv_cell)
    b = _bucket(cx, cy, cz, net.ghead.shape[0] - 1)
    net.gcell[i, 0] = cx
    net.gcell[i, 1] = cy
    net.gcell[i, 2] = cz
    net.gbucket[i] = b
    net.gprev[i] = -1
    head = net.ghead[b]
    net.gnext[i] = head
    if head >= 0:
        net.gprev[head] = i
    net.ghead[b] = i


@inlined
def grid_remove(net, i):
    """Take node ``i`` out of its bucket (nothing when it is not in the grid)."""
    gnext = net.gnext
    gprev = net.gprev
    b = net.gbucket[i]
    if b < 0:
        return
    if gprev[i] >= 0:
        gnext[gprev[i]] = gnext[i]
    else:
        net.ghead[b] = gnext[i]
    if gnext[i] >= 0:
        gprev[gnext[i]] = gprev[i]
    net.gbucket[i] = -1


@inlined
def _crossed_cell(old, new, inv_cell):
    """Whether a coordinate moving from ``old`` to ``new`` changes its cell."""
    return math.floor(old * inv_cell) != math.floor(new * inv_cell)


@inlined
def _move_toward(net, i, x0, x1, x2, dim, rate, grid_on, inv_cell):
    """Step 5 for a position: ``h_i += rate * (x - h_i)`` (`flush_tiny`), keeping node ``i``'s
    grid bucket.

    The grid invariant (each node is in the bucket of ``floor(h * inv_cell)``) lets the cell test
    compare the old and new coordinates instead of loading the stored cell.
    """
    pos = net.pos
    old0 = pos[i, 0]
    old1 = pos[i, 1]
    new0 = flush_tiny(old0 + rate * (x0 - old0))
    new1 = flush_tiny(old1 + rate * (x1 - old1))
    pos[i, 0] = new0
    pos[i, 1] = new1
    crossed = grid_on and (_crossed_cell(old0, new0, inv_cell)
                           or _crossed_cell(old1, new1, inv_cell))
    if dim > 2:
        old2 = pos[i, 2]
        new2 = flush_tiny(old2 + rate * (x2 - old2))
        pos[i, 2] = new2
        crossed = crossed or (grid_on and _crossed_cell(old2, new2, inv_cell))
    if crossed:
        grid_remove(net, i)
        grid_insert(net, i, inv_cell)


@njit(cache=True)
def _grid_rename(net, src, dst):
    """Node ``src`` becomes node ``dst`` (``dst`` is not in the grid)."""
    gnext = net.gnext
    gprev = net.gprev
    gbucket = net.gbucket
    gcell = net.gcell
    gbucket[dst] = gbucket[src]
    gbucket[src] = -1
    if gbucket[dst] < 0:
        return
    gnext[dst] = gnext[src]
    gprev[dst] = gprev[src]
    gcell[dst, 0] = gcell[src, 0]
    gcell[dst, 1] = gcell[src, 1]
    gcell[dst, 2] = gcell[src, 2]
    if gprev[dst] >= 0:
        gnext[gprev[dst]] = dst
    else:
        net.ghead[gbucket[dst]] = dst
    if gnext[dst] >= 0:
        gprev[gnext[dst]] = dst


@njit(cache=True)
def grid_rebuild(net, n, cell_size):
    """Empty the grid and insert nodes ``0..n-1`` with a new ``cell_size``. O(n)."""
    gbucket = net.gbucket
    for i in range(gbucket.shape[0]):
        b = gbucket[i]
        if b >= 0:
            net.ghead[b] = -1
            gbucket[i] = -1
    inv_cell = 1.0 / cell_size
    for i in range(n):
        grid_insert(net, i, inv_cell)


@njit(cache=True)
def _grid_insert_new(net, i, inv_cell):
    """`grid_insert` out of line, for the rare insertion of Step 8."""
    grid_insert(net, i, inv_cell)


# --------------------------------------------------------------------------- winner search


@inlined
def _sq_dist(pos, i, x0, x1, x2, dim):
    """Squared distance between the point (x0, x1[, x2]) and row ``i`` of ``pos``."""
    t0 = x0 - pos[i, 0]
    t1 = x1 - pos[i, 1]
    if dim > 2:
        t2 = x2 - pos[i, 2]
        return t0 * t0 + t1 * t1 + t2 * t2
    return t0 * t0 + t1 * t1


@inlined
def _node_sq_dist(values, i, j):
    """Squared distance between rows ``i`` and ``j`` of ``values`` ((cap, 2) or (cap, 3))."""
    x2 = values[i, 2] if values.shape[1] > 2 else 0.0
    return _sq_dist(values, j, values[i, 0], values[i, 1], x2, values.shape[1])


@inlined
def nearest_two_brute(pos, n, x0, x1, x2, dim):
    """The two nodes nearest to ``x`` by position and their squared distances."""
    best1 = np.inf
    best2 = np.inf
    s1 = -1
    s2 = -1
    for i in range(n):
        d = _sq_dist(pos, i, x0, x1, x2, dim)
        if d < best1:
            best2 = best1
            s2 = s1
            best1 = d
            s1 = i
        elif d < best2:
            best2 = d
            s2 = i
    return s1, s2, best1, best2


def _first_cells(dim: int) -> np.ndarray:
    """(27, 3) or (9, 3) int64: the query's cell and its ring-1 neighbours, likely nearest first.

    Offsets are along each axis toward the query's nearer cell face (+1) or away from it (-1),
    ordered by the expected squared gap for a query uniform in its cell (near gap 1/4, far 3/4),
    so the two nearest nodes are usually found early and the remaining cells are pruned.
    """
    expected_gap2 = {0: 0.0, 1: 0.0625, -1: 0.5625}
    z_offsets = (-1, 0, 1) if dim == 3 else (0,)
    offsets = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in z_offsets]
    offsets.sort(key=lambda o: (sum(expected_gap2[v] for v in o), o))
    return np.array(offsets, dtype=np.int64)


FIRST_CELLS_3D = _first_cells(3)
FIRST_CELLS_2D = _first_cells(2)


@inlined
def _axis_gap(offset, toward_near, near, far):
    """Gap (in cells) along one axis from the query to the cell ``offset`` away."""
    if offset == 0:
        return 0.0
    return abs(offset) - 1 + (near if (offset > 0) == toward_near else far)


@inlined
def _scan_bucket(p, gnext, pos, x0, x1, x2, dim, s1, s2, best1, best2):
    """Fold the nodes of one bucket list (starting at ``p``) into the two nearest so far."""
    while p >= 0:
        d = _sq_dist(pos, p, x0, x1, x2, dim)
        if d < best1:
            best2 = best1
            s2 = s1
            best1 = d
            s1 = p
        elif d < best2 and p != s1:
            best2 = d
            s2 = p
        p = gnext[p]
    return s1, s2, best1, best2


@inlined
def query_axis(q):
    """One axis of a query ``q`` cells from the origin: its cell, whether the nearer face of
    that cell is the upper one, and the gaps (in cells) from the query to the near and far
    faces. The ring searches (`nearest_two_grid`, the segmentation's nearest node) start here."""
    f = np.floor(q)
    r = q - f
    near = min(r, 1.0 - r)
    return np.int64(f), r >= 0.5, near, 1.0 - near


@inlined
def nearest_two_grid(net, n, x0, x1, x2, dim, cell_size, inv_cell):
    """Exact nearest two by position from the grid; returns s1, s2 and their squared distances.

    Visits the query's cell and its ring-1 neighbours (likely nearest first), skipping every cell
    whose box is farther than the current second-best distance, then further rings (pruned the
    same way) until no unvisited cell can hold a closer node. Falls back to brute force when the
    rings would cover more cells than there are nodes (a query far away from every node).
    """
    ghead = net.ghead
    gnext = net.gnext
    pos = net.pos
    table_mask = ghead.shape[0] - 1
    cx, up_x, near_x, far_x = query_axis(x0 * inv_cell)
    cy, up_y, near_y, far_y = query_axis(x1 * inv_cell)
    cz, up_z, near_z, far_z = query_axis(x2 * inv_cell if dim > 2 else 0.0)
    step_x = 1 if up_x else -1
    step_y = 1 if up_y else -1
    step_z = 1 if up_z else -1
    if dim > 2:
        first_cells = FIRST_CELLS_3D
        margin = min(near_x, near_y, near_z)
        far_gap = min(far_x, far_y, far_z)
    else:
        first_cells = FIRST_CELLS_2D
        margin = min(near_x, near_y)
        far_gap = min(far_x, far_y)
    # the first cells with offsets 0 or +1 only: the query's cell and those toward its near faces
    near_block = 1 << dim
    cell2 = cell_size * cell_size
    # a cell is skipped when (its gap in cells)^2 > best2 * prune
    prune = (1.0 + BOUND_SLACK) / cell2
    best1 = np.inf
    best2 = np.inf
    s1 = -1
    s2 = -1
    for e in range(first_cells.shape[0]):
        if e == near_block:
            # every cell left lies beyond a far face on some axis: when the nearest far face is
            # pruned, so is each of them (best2 only shrinks), as the per-cell test would find
            if far_gap * far_gap > best2 * prune:
                break
        ox = first_cells[e, 0]
        oy = first_cells[e, 1]
        oz = first_cells[e, 2]
        gx = 0.0 if ox == 0 else (near_x if ox > 0 else far_x)
        gy = 0.0 if oy == 0 else (near_y if oy > 0 else far_y)
        gz = 0.0 if oz == 0 else (near_z if oz > 0 else far_z)
        if gx * gx + gy * gy + gz * gz > best2 * prune:
            continue
        p = ghead[_bucket(cx + ox * step_x, cy + oy * step_y, cz + oz * step_z, table_mask)]
        s1, s2, best1, best2 = _scan_bucket(p, gnext, pos, x0, x1, x2, dim,
                                            s1, s2, best1, best2)
    r = 1
    while True:
        if s2 >= 0:
            # every unvisited cell is at least (r + margin) cells away
            bound = (r + margin) * cell_size
            if best2 * (1.0 + BOUND_SLACK) <= bound * bound:
                return s1, s2, best1, best2
        r += 1
        side = 2 * r + 1
        if side * side * (side if dim > 2 else 1) > 2 * n:
            return nearest_two_brute(pos, n, x0, x1, x2, dim)
        zr = r if dim > 2 else 0
        for dx in range(-r, r + 1):
            gx = _axis_gap(dx, up_x, near_x, far_x)
            for dy in range(-r, r + 1):
                gy = _axis_gap(dy, up_y, near_y, far_y)
                gxy = gx * gx + gy * gy
                if gxy > best2 * prune:
                    continue
                on_ring = abs(dx) == r or abs(dy) == r
                for dz in range(-zr, zr + 1):
                    if not on_ring and abs(dz) != r:
                        continue
                    gz = _axis_gap(dz, up_z, near_z, far_z)
                    if gxy + gz * gz > best2 * prune:
                        continue
                    p = ghead[_bucket(cx + dx, cy + dy, cz + dz, table_mask)]
                    s1, s2, best1, best2 = _scan_bucket(p, gnext, pos, x0, x1, x2, dim,
                                                        s1, s2, best1, best2)


@inlined
def nearest_two_weighted(pos, col, n, x0, x1, x2, dim, c0, c1, c2, mode, has_col, w_pos, w_col):
    """GNG / GNG-W winner search (eqs. 13-14) over position and colour; brute force.

    GNG: Euclidean distance over the concatenated vector (pos, col).
    GNG-W: ``w_pos * ||dpos|| + w_col * ||dcol||``.
    Returns s1, s2 and the error increment of s1 (GNG: squared distance; GNG-W: eq. 14).
    """
    best1 = np.inf
    best2 = np.inf
    s1 = -1
    s2 = -1
    err1 = 0.0
    for i in range(n):
        dp = _sq_dist(pos, i, x0, x1, x2, dim)
        dc = 0.0
        if has_col:
            dc = _sq_dist(col, i, c0, c1, c2, 3)
        if mode == MODE_GNG:
            d = dp + dc
            e = d
        else:
            d = w_pos * math.sqrt(dp) + w_col * math.sqrt(dc)
            e = w_pos * dp + w_col * dc
        if d < best1:
            best2 = best1
            s2 = s1
            best1 = d
            s1 = i
            err1 = e
        elif d < best2:
            best2 = d
            s2 = i
    return s1, s2, err1
