"""Numba kernels of the growing-gas learners: one learning loop for GNG-DT, GNG and GNG-W.

All network state lives in preallocated arrays owned by the Python estimator (`model.py`); the
kernels only read and write them, so a learning step allocates nothing.

Layout (``cap`` = node capacity = ``max_nodes``, ``K`` = ``MAX_DEGREE``):

- ``pos`` (cap, D) float64, ``col`` (cap, 3) float64, ``nor`` (cap, 3) float64 node properties;
  a normal of (0, 0, 0) means "undefined" (fewer than two position neighbours, or a degenerate
  neighbourhood) and never gets a normal edge.
- ``err`` (cap,) float64 accumulated errors stored *scaled*: true error = ``err * error_scale``
  (Fišer et al. 2013), so the global decay of Step 9 is one multiplication of ``error_scale``.
- Adjacency with a fixed maximum degree: ``nbr`` (cap, K) int32 neighbour index, ``age`` (cap, K)
  int32, ``emask`` (cap, K) uint8 bitmask of the properties the edge has (``POS_BIT`` always set:
  edges of other properties are a subset of the position edges), ``rev`` (cap, K) int32 the slot
  of the same edge in the neighbour's row, ``deg`` (cap,) int32. Slots ``[0, deg[i])`` are used.
  Degree overflow: if ``s1`` or ``s2`` already has ``K`` edges when Step 4 must create their edge,
  the edge is not created in that step (everything else proceeds); GNG degrees stay far below
  ``K`` in practice.
- Forgetting (GNG-U's utility, Fritzke 1997, judged only where the sensor can see): ``util``
  (cap,) float64 utility, the error the network would gain without the node (for each sample a
  node wins, the squared distance to the second winner minus that to the winner), decaying by
  ``utility_decay`` per step (GNG-U2's chi, Toda et al. 2016) through its own lazy scale
  ``util_scale``. A node ``judged`` (cap,) uint8 in the current call (one the sensor could see:
  in the view, not behind the measured surface) stores it scaled (true = ``util * util_scale``)
  and so decays; any other node stores it in true units, frozen, for the whole call. Every lambda
  steps the judged node of least utility is removed, with its edges, when ``max error >
  utility_k * its utility``. Utility counts only the current batch's samples (rows below
  ``iparams[Q_FRAME_ROWS]``), not those rehearsed from memory: it is what the sensor sees now.
- ``ids`` (cap,) int64 persistent node ids: a node keeps its id while its index changes (deletion
  moves the last node into the hole); a new node takes ``istate[I_NEXT_ID]``, which then grows, so
  an id is never reused.
- Spatial hash grid for the winner search: ``ghead`` (T,) int32 first node of each bucket,
  ``gnext``/``gprev`` (cap,) int32 doubly linked bucket lists, ``gbucket`` (cap,) int64 bucket of
  each node (-1: not in the grid), ``gcell`` (cap, 3) int64 integer cell of each node. A node's
  cell is ``floor(position * (1 / cell_size))`` per axis (the z cell is 0 in 2-D); every node
  in the grid is kept in the bucket of its current cell.
- ``istate`` int64: [n_nodes, n_steps, grid_active, next_id, nodes_forgotten]; ``fstate``
  float64: [error_scale, cell_size, spacing_ema, util_scale].

Nodes are deleted by swapping the last node into the hole, so indices stay compact.

Speed notes: a step takes well under a microsecond, so the per-step loop (`_learn_steps`) runs
without numba's reference counting, its helpers are inlined at the numba IR level
(``inline="always"``), and samples and nodes are read by index, never through array views.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

POS_BIT = 1
COL_BIT = 2
NOR_BIT = 4

MODE_GNGDT = 0
MODE_GNG = 1
MODE_GNGW = 2

MAX_DEGREE = 16
# Below this many nodes a brute-force winner search is cheaper than the grid.
GRID_MIN_NODES = 48
# Grid cell edge in running node spacings (the search is fastest at about 1.5-2.5), and the factor
# by which the cell may drift from that before the grid is rebuilt.
GRID_CELL_SPACINGS = 2.0
GRID_CELL_TOLERANCE = 1.4
# Renormalise stored errors when the global decay factor falls below this.
ERROR_SCALE_FLOOR = 1e-60
# Relative safety margin of the grid search's distance bounds: cell coordinates carry rounding
# errors of a few ulps, so a cell is skipped (or the search stopped) only when its bound beats the
# best distance by this factor. It costs nothing in exactness, only a rare extra cell visit.
BOUND_SLACK = 1e-9

# indices into istate / fstate / fparams / iparams
I_NODES, I_STEPS, I_GRID, I_NEXT_ID, I_FORGOTTEN = 0, 1, 2, 3, 4
F_ERROR_SCALE, F_CELL, F_SPACING, F_UTIL_SCALE = 0, 1, 2, 3
P_ETA1, P_ETA2, P_ALPHA, P_BETA, P_TAU_COL, P_TAU_NOR, P_MU = 0, 1, 2, 3, 4, 5, 6
P_VX, P_VY, P_VZ, P_W_POS, P_W_COL, P_UTILITY_K, P_UTILITY_DECAY = 7, 8, 9, 10, 11, 12, 13
Q_LAMBDA, Q_AGE_MAX, Q_MAX_NODES, Q_MODE, Q_HAS_COL, Q_HAS_NOR, Q_ORIENT, Q_FORGET = range(8)
#: rows of ``samples`` from this index on are rehearsed (earlier batches'): no utility
Q_FRAME_ROWS = 8

# helpers of the per-step loop: inlined into their callers at the numba IR level
inlined = njit(cache=True, inline="always")


# --------------------------------------------------------------------------- adjacency


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
def grid_insert(pos, ghead, gnext, gprev, gbucket, gcell, i, inv_cell):
    """Put node ``i`` (not in the grid) at the head of its cell's bucket."""
    cx, cy, cz = _cell_of(pos, i, inv_cell)
    b = _bucket(cx, cy, cz, ghead.shape[0] - 1)
    gcell[i, 0] = cx
    gcell[i, 1] = cy
    gcell[i, 2] = cz
    gbucket[i] = b
    gprev[i] = -1
    head = ghead[b]
    gnext[i] = head
    if head >= 0:
        gprev[head] = i
    ghead[b] = i


@inlined
def grid_remove(ghead, gnext, gprev, gbucket, i):
    b = gbucket[i]
    if b < 0:
        return
    if gprev[i] >= 0:
        gnext[gprev[i]] = gnext[i]
    else:
        ghead[b] = gnext[i]
    if gnext[i] >= 0:
        gprev[gnext[i]] = gprev[i]
    gbucket[i] = -1


@inlined
def _crossed_cell(old, new, inv_cell):
    """Whether a coordinate moving from ``old`` to ``new`` changes its cell."""
    return math.floor(old * inv_cell) != math.floor(new * inv_cell)


@inlined
def _move_toward(pos, i, x0, x1, x2, dim, rate, grid_on, ghead, gnext, gprev, gbucket, gcell,
                 inv_cell):
    """Step 5 for a position: ``h_i += rate * (x - h_i)``, keeping node ``i``'s grid bucket.

    The grid invariant (each node is in the bucket of ``floor(h * inv_cell)``) lets the cell test
    compare the old and new coordinates instead of loading the stored cell.
    """
    old0 = pos[i, 0]
    old1 = pos[i, 1]
    new0 = old0 + rate * (x0 - old0)
    new1 = old1 + rate * (x1 - old1)
    pos[i, 0] = new0
    pos[i, 1] = new1
    crossed = grid_on and (_crossed_cell(old0, new0, inv_cell)
                           or _crossed_cell(old1, new1, inv_cell))
    if dim > 2:
        old2 = pos[i, 2]
        new2 = old2 + rate * (x2 - old2)
        pos[i, 2] = new2
        crossed = crossed or (grid_on and _crossed_cell(old2, new2, inv_cell))
    if crossed:
        grid_remove(ghead, gnext, gprev, gbucket, i)
        grid_insert(pos, ghead, gnext, gprev, gbucket, gcell, i, inv_cell)


@njit(cache=True)
def _grid_rename(ghead, gnext, gprev, gbucket, gcell, src, dst):
    """Node ``src`` becomes node ``dst`` (``dst`` is not in the grid)."""
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
        ghead[gbucket[dst]] = dst
    if gnext[dst] >= 0:
        gprev[gnext[dst]] = dst


@njit(cache=True)
def grid_rebuild(pos, n, ghead, gnext, gprev, gbucket, gcell, cell_size):
    """Empty the grid and insert nodes ``0..n-1`` with a new ``cell_size``. O(n)."""
    for i in range(gbucket.shape[0]):
        b = gbucket[i]
        if b >= 0:
            ghead[b] = -1
            gbucket[i] = -1
    inv_cell = 1.0 / cell_size
    for i in range(n):
        grid_insert(pos, ghead, gnext, gprev, gbucket, gcell, i, inv_cell)


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
def nearest_two_grid(pos, n, x0, x1, x2, dim, ghead, gnext, cell_size, inv_cell):
    """Exact nearest two by position from the grid; returns s1, s2 and their squared distances.

    Visits the query's cell and its ring-1 neighbours (likely nearest first), skipping every cell
    whose box is farther than the current second-best distance, then further rings (pruned the
    same way) until no unvisited cell can hold a closer node. Falls back to brute force when the
    rings would cover more cells than there are nodes (a query far away from every node).
    """
    table_mask = ghead.shape[0] - 1
    qx = x0 * inv_cell
    qy = x1 * inv_cell
    qz = x2 * inv_cell if dim > 2 else 0.0
    fx = math.floor(qx)
    fy = math.floor(qy)
    fz = math.floor(qz)
    cx = np.int64(fx)
    cy = np.int64(fy)
    cz = np.int64(fz)
    # per axis: is the nearer face on the + side, and the gaps (in cells) to the near/far face
    rx = qx - fx
    ry = qy - fy
    rz = qz - fz
    up_x = rx >= 0.5
    up_y = ry >= 0.5
    up_z = rz >= 0.5
    near_x = min(rx, 1.0 - rx)
    near_y = min(ry, 1.0 - ry)
    near_z = min(rz, 1.0 - rz)
    far_x = 1.0 - near_x
    far_y = 1.0 - near_y
    far_z = 1.0 - near_z
    step_x = 1 if up_x else -1
    step_y = 1 if up_y else -1
    step_z = 1 if up_z else -1
    if dim > 2:
        first_cells = FIRST_CELLS_3D
        margin = min(near_x, near_y, near_z)
    else:
        first_cells = FIRST_CELLS_2D
        margin = min(near_x, near_y)
    cell2 = cell_size * cell_size
    # a cell is skipped when (its gap in cells)^2 > best2 * prune
    prune = (1.0 + BOUND_SLACK) / cell2
    best1 = np.inf
    best2 = np.inf
    s1 = -1
    s2 = -1
    for e in range(first_cells.shape[0]):
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


# --------------------------------------------------------------------------- normals (eq. 16)


@njit(cache=True)
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (closed form).

    Returns (x, y, z, ok); ok is False when the eigenvector is not unique (e.g. an isotropic or
    rank-one matrix), in which case the vector is zero.
    """
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    if p2 <= 0.0:
        return 0.0, 0.0, 0.0, False
    p = math.sqrt(p2 / 6.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    ) / (p * p * p)
    half_det = min(1.0, max(-1.0, det / 2.0))
    phi = math.acos(half_det) / 3.0
    smallest = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    # rows of (A - smallest I); the eigenvector is orthogonal to all of them
    m00 = a00 - smallest
    m11 = a11 - smallest
    m22 = a22 - smallest
    # cross products of row pairs: (r0 x r1), (r0 x r2), (r1 x r2)
    c0x = a01 * a12 - a02 * m11
    c0y = a02 * a01 - m00 * a12
    c0z = m00 * m11 - a01 * a01
    c1x = a01 * m22 - a02 * a12
    c1y = a02 * a02 - m00 * m22
    c1z = m00 * a12 - a01 * a02
    c2x = m11 * m22 - a12 * a12
    c2y = a12 * a02 - a01 * m22
    c2z = a01 * a12 - m11 * a02
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    if n0 >= n1 and n0 >= n2:
        vx, vy, vz, nn = c0x, c0y, c0z, n0
    elif n1 >= n2:
        vx, vy, vz, nn = c1x, c1y, c1z, n1
    else:
        vx, vy, vz, nn = c2x, c2y, c2z, n2
    # relative to the matrix scale squared: below this the two smallest eigenvalues coincide
    if nn <= 1e-20 * p2 * p2:
        return 0.0, 0.0, 0.0, False
    inv = 1.0 / math.sqrt(nn)
    return vx * inv, vy * inv, vz * inv, True


@inlined
def _orient(nor, pos, i, vx, vy, vz):
    """Flip normal ``i`` so that it points toward the viewpoint."""
    dot = (
        nor[i, 0] * (vx - pos[i, 0]) + nor[i, 1] * (vy - pos[i, 1]) + nor[i, 2] * (vz - pos[i, 2])
    )
    if dot < 0.0:
        nor[i, 0] = -nor[i, 0]
        nor[i, 1] = -nor[i, 1]
        nor[i, 2] = -nor[i, 2]


@inlined
def _set_normal(nor, i, x, y, z):
    nor[i, 0] = x
    nor[i, 1] = y
    nor[i, 2] = z


@inlined
def compute_normal(i, pos, nor, nbr, deg, mu, orient, vx, vy, vz):
    """Eq. 16: normal of node ``i`` from its position neighbours, written to ``nor[i]``.

    As the paper: weighted centroid ``m = (h_i + sum w_j h_j) / (1 + sum w_j)`` with
    ``w_j = exp(-||h_i - h_j||^2 / mu^2)``; covariance ``sum_j (h_j - m)(h_j - m)^T`` over the
    k neighbours (unweighted); normal = eigenvector of its smallest eigenvalue. ``mu <= 0``
    means the scale-free default: ``mu`` = mean distance from ``i`` to its neighbours.
    Undefined (zero) with fewer than two neighbours.
    """
    k_count = deg[i]
    if k_count < 2:
        _set_normal(nor, i, 0.0, 0.0, 0.0)
        return
    px = pos[i, 0]
    py = pos[i, 1]
    pz = pos[i, 2]
    if mu <= 0.0:
        total = 0.0
        for k in range(k_count):
            total += math.sqrt(_sq_dist(pos, nbr[i, k], px, py, pz, 3))
        mu = total / k_count
        if mu <= 0.0:
            _set_normal(nor, i, 0.0, 0.0, 0.0)
            return
    # one pass in coordinates d_j = h_j - h_i: the weighted sums give the centroid m, the plain
    # sums S1 = sum d_j and S2 = sum d_j d_j^T give sum (d_j - m)(d_j - m)^T
    #   = S2 - m S1^T - S1 m^T + k m m^T
    inv_mu2 = 1.0 / (mu * mu)
    wsum = 1.0
    wx = 0.0
    wy = 0.0
    wz = 0.0
    sx = 0.0
    sy = 0.0
    sz = 0.0
    c00 = 0.0
    c01 = 0.0
    c02 = 0.0
    c11 = 0.0
    c12 = 0.0
    c22 = 0.0
    for k in range(k_count):
        j = nbr[i, k]
        dx = pos[j, 0] - px
        dy = pos[j, 1] - py
        dz = pos[j, 2] - pz
        w = math.exp(-(dx * dx + dy * dy + dz * dz) * inv_mu2)
        wsum += w
        wx += w * dx
        wy += w * dy
        wz += w * dz
        sx += dx
        sy += dy
        sz += dz
        c00 += dx * dx
        c01 += dx * dy
        c02 += dx * dz
        c11 += dy * dy
        c12 += dy * dz
        c22 += dz * dz
    mx = wx / wsum
    my = wy / wsum
    mz = wz / wsum
    c00 += k_count * mx * mx - 2.0 * mx * sx
    c01 += k_count * mx * my - mx * sy - sx * my
    c02 += k_count * mx * mz - mx * sz - sx * mz
    c11 += k_count * my * my - 2.0 * my * sy
    c12 += k_count * my * mz - my * sz - sy * mz
    c22 += k_count * mz * mz - 2.0 * mz * sz
    x, y, z, ok = smallest_eigenvector(c00, c01, c02, c11, c12, c22)
    _set_normal(nor, i, x, y, z)
    if ok and orient:
        _orient(nor, pos, i, vx, vy, vz)


@inlined
def _normal_defined(nor, i):
    return nor[i, 0] != 0.0 or nor[i, 1] != 0.0 or nor[i, 2] != 0.0


@inlined
def normals_close(nor, i, j, tau):
    """Eq. 4/9 for normals, sign-invariant: min(||n_i - n_j||, ||n_i + n_j||) < tau."""
    if not (_normal_defined(nor, i) and _normal_defined(nor, j)):
        return False
    dm = 0.0
    dp = 0.0
    for a in range(3):
        t = nor[i, a] - nor[j, a]
        dm += t * t
        t = nor[i, a] + nor[j, a]
        dp += t * t
    return min(dm, dp) < tau * tau


@inlined
def colours_close(col, i, j, tau):
    """Eq. 4/9 for colours: ||c_i - c_j|| < tau."""
    return _node_sq_dist(col, i, j) < tau * tau


@inlined
def property_bits(col, nor, i, j, has_col, has_nor, tau_col, tau_nor):
    """Position bit plus the bits of the other properties whose eq. 4/9 test holds for (i, j)."""
    mask = POS_BIT
    if has_col and colours_close(col, i, j, tau_col):
        mask |= COL_BIT
    if has_nor and normals_close(nor, i, j, tau_nor):
        mask |= NOR_BIT
    return mask


# --------------------------------------------------------------------------- node deletion


@njit(cache=True)
def delete_node(i, n, pos, col, nor, err, nbr, age, emask, rev, deg, ids, util, judged,
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


# --------------------------------------------------------------------------- the learning loop


@njit(cache=True)
def learn(samples, sample_colors, order,
          pos, col, nor, err, nbr, age, emask, rev, deg, ids, util, judged,
          ghead, gnext, gprev, gbucket, gcell,
          istate, fstate, fparams, iparams):
    """Run one learning step (Steps 1-9) per index in ``order`` (rows of ``samples``).

    samples: (N, D) float64 positions; sample_colors: (N, 3) float64, or any (1, 3) placeholder
    without colour (then never read). With forgetting on, ``judged`` marks the nodes the sensor
    could see in this call (see the module docstring); nodes inserted during it are judged.
    """
    # scratch for Step 7 (the neighbours whose edge to s1 just expired) and for forgetting (a
    # node and its neighbours)
    candidates = np.empty(nbr.shape[1] + 1, dtype=np.int64)
    forget = iparams[Q_FORGET] != 0
    if forget:  # utilities of the nodes not judged now: frozen, in true units, for this call
        _rescale_unjudged(util, judged, istate[I_NODES], fstate[F_UTIL_SCALE])
    _learn_steps(samples, sample_colors, order,
                 pos, col, nor, err, nbr, age, emask, rev, deg, ids, util, judged,
                 ghead, gnext, gprev, gbucket, gcell,
                 istate, fstate, fparams, iparams, candidates)
    if forget:
        _rescale_unjudged(util, judged, istate[I_NODES], 1.0 / fstate[F_UTIL_SCALE])


@njit(cache=True)
def _rescale_unjudged(util, judged, n, factor):
    for i in range(n):
        if judged[i] == 0:
            util[i] *= factor


@njit(cache=True)
def forget_least_useful(n, err, util, judged, error_scale, util_scale, utility_k, candidates,
                        pos, col, nor, nbr, age, emask, rev, deg, ids,
                        ghead, gnext, gprev, gbucket, gcell):
    """GNG-U's removal among the judged nodes: the judged node ``l`` of least utility goes, with
    its edges and any neighbour left without one, when ``max error > utility_k * U_l`` (true,
    unscaled values). Returns (new n, nodes removed).
    """
    max_err = 0.0
    least = -1
    least_util = np.inf
    for i in range(n):
        if err[i] > max_err:
            max_err = err[i]
        if judged[i] != 0 and util[i] < least_util:
            least_util = util[i]
            least = i
    if least < 0 or n <= 2 or not max_err * error_scale > utility_k * least_util * util_scale:
        return n, 0
    n_candidates = 0
    while deg[least] > 0:
        k = deg[least] - 1
        candidates[n_candidates] = nbr[least, k]
        n_candidates += 1
        remove_edge(nbr, age, emask, rev, deg, least, k)
    candidates[n_candidates] = least
    n_candidates += 1
    removed = 0
    for q in range(n_candidates):
        j = candidates[q]
        if deg[j] == 0 and n > 2:
            last = delete_node(j, n, pos, col, nor, err, nbr, age, emask, rev, deg, ids, util,
                               judged, ghead, gnext, gprev, gbucket, gcell)
            n -= 1
            removed += 1
            for q2 in range(q + 1, n_candidates):
                if candidates[q2] == last:
                    candidates[q2] = j
    return n, removed


# Compiled without the numba runtime (``_nrt=False``, the option numba uses for its own hot
# helpers): every array here is owned by the caller, so the atomic reference counting that numba
# would otherwise emit around each inlined helper is pure overhead (it cost ~40% of a step).
# Without the runtime the function cannot allocate; numba refuses to compile it if it tries.
@njit(cache=True, _nrt=False)
def _learn_steps(samples, sample_colors, order,
                 pos, col, nor, err, nbr, age, emask, rev, deg, ids, util, judged,
                 ghead, gnext, gprev, gbucket, gcell,
                 istate, fstate, fparams, iparams, candidates):
    """The body of `learn`; ``candidates`` (MAX_DEGREE + 1,) int64 scratch."""
    eta1 = fparams[P_ETA1]
    eta2 = fparams[P_ETA2]
    alpha = fparams[P_ALPHA]
    beta = fparams[P_BETA]
    tau_col = fparams[P_TAU_COL]
    tau_nor = fparams[P_TAU_NOR]
    mu = fparams[P_MU]
    vx = fparams[P_VX]
    vy = fparams[P_VY]
    vz = fparams[P_VZ]
    w_pos = fparams[P_W_POS]
    w_col = fparams[P_W_COL]
    lam = iparams[Q_LAMBDA]
    age_max = iparams[Q_AGE_MAX]
    max_nodes = iparams[Q_MAX_NODES]
    mode = iparams[Q_MODE]
    has_col = iparams[Q_HAS_COL] != 0
    has_nor = iparams[Q_HAS_NOR] != 0
    orient = iparams[Q_ORIENT] != 0
    forget = iparams[Q_FORGET] != 0
    frame_rows = iparams[Q_FRAME_ROWS]
    utility_k = fparams[P_UTILITY_K]
    utility_decay = fparams[P_UTILITY_DECAY]
    # in GNG / GNG-W colour is part of the input vector and follows the single topology
    col_follows_pos = mode != MODE_GNGDT

    n = istate[I_NODES]
    t = istate[I_STEPS]
    next_id = istate[I_NEXT_ID]
    forgotten = istate[I_FORGOTTEN]
    grid_on = istate[I_GRID] != 0
    error_scale = fstate[F_ERROR_SCALE]
    util_scale = fstate[F_UTIL_SCALE]
    cell_size = fstate[F_CELL]
    inv_cell = 1.0 / cell_size if grid_on else 0.0
    spacing = fstate[F_SPACING]
    dim = pos.shape[1]
    # steps since the last Step 8 (t % lam, counted instead of divided each step)
    phase = t % lam

    for idx in order:
        x0 = samples[idx, 0]
        x1 = samples[idx, 1]
        x2 = samples[idx, 2] if dim > 2 else 0.0
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        if has_col:  # without colour, sample_colors is a (1, 3) placeholder: never index it
            c0 = sample_colors[idx, 0]
            c1 = sample_colors[idx, 1]
            c2 = sample_colors[idx, 2]
        t += 1
        phase += 1
        if phase == lam:
            phase = 0
        # Step 2 (and the error of Step 3)
        if mode == MODE_GNGDT:
            if grid_on:
                s1, s2, err_add, second = nearest_two_grid(pos, n, x0, x1, x2, dim, ghead,
                                                           gnext, cell_size, inv_cell)
            else:
                s1, s2, err_add, second = nearest_two_brute(pos, n, x0, x1, x2, dim)
        else:
            s1, s2, err_add = nearest_two_weighted(pos, col, n, x0, x1, x2, dim, c0, c1, c2,
                                                   mode, has_col, w_pos, w_col)
            second = err_add
        if s2 < 0:  # every distance overflowed (|x| ~ 1e154): no winner, learn nothing
            continue
        # Step 3
        err[s1] += err_add / error_scale
        # GNG-U: what the network would lose without s1, by what the sensor sees now
        if forget and judged[s1] != 0 and idx < frame_rows:
            util[s1] += (second - err_add) / util_scale
        # running node spacing (distance between winners) sizes the grid cells
        d12 = math.sqrt(_node_sq_dist(pos, s1, s2))
        if spacing <= 0.0:
            spacing = d12
        else:
            spacing += 0.01 * (d12 - spacing)
        # Step 4
        k12 = find_slot(nbr, deg, s1, s2)
        if k12 < 0:
            if add_edge(nbr, age, emask, rev, deg, s1, s2, POS_BIT):
                k12 = deg[s1] - 1
        if k12 >= 0:
            mask = property_bits(col, nor, s1, s2, has_col, has_nor, tau_col, tau_nor)
            age[s1, k12] = 0
            emask[s1, k12] = mask
            k21 = rev[s1, k12]
            age[s2, k21] = 0
            emask[s2, k21] = mask
        # Step 5: the winner moves in every input property ...
        _move_toward(pos, s1, x0, x1, x2, dim, eta1, grid_on, ghead, gnext, gprev, gbucket,
                     gcell, inv_cell)
        if has_col:
            col[s1, 0] += eta1 * (c0 - col[s1, 0])
            col[s1, 1] += eta1 * (c1 - col[s1, 1])
            col[s1, 2] += eta1 * (c2 - col[s1, 2])
        # ... each neighbour in property o only along an edge of o. Step 6: ages.
        for k in range(deg[s1]):
            j = nbr[s1, k]
            _move_toward(pos, j, x0, x1, x2, dim, eta2, grid_on, ghead, gnext, gprev, gbucket,
                         gcell, inv_cell)
            if has_col and (col_follows_pos or (emask[s1, k] & COL_BIT) != 0):
                col[j, 0] += eta2 * (c0 - col[j, 0])
                col[j, 1] += eta2 * (c1 - col[j, 1])
                col[j, 2] += eta2 * (c2 - col[j, 2])
            age[s1, k] += 1
            age[j, rev[s1, k]] += 1
        # Step 7: delete old edges of s1, then nodes left without position edges
        n_candidates = 0
        k = 0
        while k < deg[s1]:
            if age[s1, k] > age_max:
                candidates[n_candidates] = nbr[s1, k]
                n_candidates += 1
                remove_edge(nbr, age, emask, rev, deg, s1, k)
            else:
                k += 1
        for q in range(n_candidates):
            j = candidates[q]
            if deg[j] == 0:
                last = delete_node(j, n, pos, col, nor, err, nbr, age, emask, rev, deg, ids,
                                   util, judged, ghead, gnext, gprev, gbucket, gcell)
                n -= 1
                if s1 == last:
                    s1 = j
                for q2 in range(q + 1, n_candidates):
                    if candidates[q2] == last:
                        candidates[q2] = j
        if deg[s1] == 0:
            delete_node(s1, n, pos, col, nor, err, nbr, age, emask, rev, deg, ids,
                        util, judged, ghead, gnext, gprev, gbucket, gcell)
            n -= 1
        elif has_nor:
            compute_normal(s1, pos, nor, nbr, deg, mu, orient, vx, vy, vz)
        # Step 8: insertion every lambda steps, until max_nodes
        if phase == 0:
            if forget:
                n, removed = forget_least_useful(n, err, util, judged, error_scale, util_scale,
                                                 utility_k, candidates, pos, col, nor, nbr, age,
                                                 emask, rev, deg, ids, ghead, gnext, gprev,
                                                 gbucket, gcell)
                forgotten += removed
            if n < max_nodes:
                n = _insert_node(n, pos, col, nor, err, nbr, age, emask, rev, deg,
                                 has_col, has_nor, tau_col, tau_nor, alpha, orient, vx, vy, vz,
                                 forget, util, judged, util_scale)
                ids[n - 1] = next_id
                next_id += 1
                if grid_on:
                    _grid_insert_new(pos, ghead, gnext, gprev, gbucket, gcell, n - 1, inv_cell)
            # keep grid cells about GRID_CELL_SPACINGS node spacings wide (amortised O(n) per
            # lambda steps); the cell size only affects speed, never the winners found
            target_cell = GRID_CELL_SPACINGS * spacing
            if mode == MODE_GNGDT and n >= GRID_MIN_NODES and spacing > 0.0 and (
                not grid_on
                or cell_size > GRID_CELL_TOLERANCE * target_cell
                or target_cell > GRID_CELL_TOLERANCE * cell_size
            ):
                cell_size = target_cell
                inv_cell = 1.0 / cell_size
                grid_rebuild(pos, n, ghead, gnext, gprev, gbucket, gcell, cell_size)
                grid_on = True
        # Step 9, lazily: true error = stored error * error_scale
        error_scale *= 1.0 - beta
        if error_scale < ERROR_SCALE_FLOOR:
            for i in range(n):
                err[i] *= error_scale
            error_scale = 1.0
        if forget:  # the judged nodes' utilities decay (the others are frozen, in true units)
            util_scale *= 1.0 - utility_decay
            if util_scale < ERROR_SCALE_FLOOR:
                for i in range(n):
                    if judged[i] != 0:
                        util[i] *= util_scale
                util_scale = 1.0

    istate[I_NODES] = n
    istate[I_STEPS] = t
    istate[I_GRID] = 1 if grid_on else 0
    istate[I_NEXT_ID] = next_id
    istate[I_FORGOTTEN] = forgotten
    fstate[F_ERROR_SCALE] = error_scale
    fstate[F_UTIL_SCALE] = util_scale
    fstate[F_CELL] = cell_size
    fstate[F_SPACING] = spacing


@njit(cache=True)
def _grid_insert_new(pos, ghead, gnext, gprev, gbucket, gcell, i, inv_cell):
    """`grid_insert` out of line, for the rare insertion of Step 8."""
    grid_insert(pos, ghead, gnext, gprev, gbucket, gcell, i, inv_cell)


@njit(cache=True)
def _insert_node(n, pos, col, nor, err, nbr, age, emask, rev, deg,
                 has_col, has_nor, tau_col, tau_nor, alpha, orient, vx, vy, vz,
                 forget, util, judged, util_scale):
    """Step 8 i-vi: new node halfway between the max-error node and its max-error neighbour.

    With forgetting, the new node is judged and takes the mean utility of the two (GNG-U).
    """
    u = 0
    for i in range(1, n):
        if err[i] > err[u]:
            u = i
    ku = 0
    for k in range(1, deg[u]):
        if err[nbr[u, k]] > err[nbr[u, ku]]:
            ku = k
    f = nbr[u, ku]
    r = n
    for a in range(pos.shape[1]):
        pos[r, a] = 0.5 * (pos[u, a] + pos[f, a])
    for a in range(3):
        col[r, a] = 0.5 * (col[u, a] + col[f, a])
    _interpolate_normal(nor, pos, u, f, r, orient, vx, vy, vz)
    deg[r] = 0
    remove_edge(nbr, age, emask, rev, deg, u, ku)
    add_edge(nbr, age, emask, rev, deg, u, r,
             property_bits(col, nor, u, r, has_col, has_nor, tau_col, tau_nor))
    add_edge(nbr, age, emask, rev, deg, r, f,
             property_bits(col, nor, r, f, has_col, has_nor, tau_col, tau_nor))
    err[u] -= alpha * err[u]
    err[f] -= alpha * err[f]
    err[r] = 0.5 * (err[u] + err[f])
    if forget:
        scaled_u = util[u] if judged[u] != 0 else util[u] / util_scale
        scaled_f = util[f] if judged[f] != 0 else util[f] / util_scale
        util[r] = 0.5 * (scaled_u + scaled_f)
        judged[r] = 1
    return n + 1


@njit(cache=True)
def _interpolate_normal(nor, pos, u, f, r, orient, vx, vy, vz):
    """Normal of a new node: the sign-aligned mean of its parents' normals, renormalised."""
    sign = 1.0
    if nor[u, 0] * nor[f, 0] + nor[u, 1] * nor[f, 1] + nor[u, 2] * nor[f, 2] < 0.0:
        sign = -1.0
    norm2 = 0.0
    for a in range(3):
        nor[r, a] = nor[u, a] + sign * nor[f, a]
        norm2 += nor[r, a] * nor[r, a]
    if norm2 > 1e-24:
        inv = 1.0 / math.sqrt(norm2)
        for a in range(3):
            nor[r, a] *= inv
        if orient:
            _orient(nor, pos, r, vx, vy, vz)
    else:
        for a in range(3):
            nor[r, a] = 0.0
