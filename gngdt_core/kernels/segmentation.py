"""Numba kernels over a learned network: fresh normals, property bits, nearest-node labelling;
and over a depth image: veil pixels.

They read a network (`kernels.layout.Network`) and write only their outputs; the learning loop
never calls them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import inlined
from gngdt.core.kernels.grid import (
    BOUND_SLACK,
    _axis_gap,
    _bucket,
    _sq_dist,
    nearest_two_brute,
    nearest_two_grid,
    query_axis,
)
from gngdt.core.kernels.layout import F_CELL, I_GRID, I_NODES
from gngdt.core.kernels.normals import compute_normal, property_bits


@njit(cache=True, nogil=True)
def refresh_normals(net, mu, orient, vx, vy, vz):
    """Eq. 16 for every node of ``net`` from the current positions, written to ``net.nor``."""
    for i in range(net.istate[I_NODES]):
        compute_normal(net, i, mu, orient, vx, vy, vz)


@njit(cache=True, nogil=True)
def refresh_property_bits(net, has_col, has_nor, tau_col, tau_nor):
    """Eqs. 4/9 for every edge of ``net`` from the current colours and normals."""
    for i in range(net.istate[I_NODES]):
        for k in range(net.deg[i]):
            j = net.nbr[i, k]
            if j > i:
                mask = property_bits(net, i, j, has_col, has_nor, tau_col, tau_nor)
                net.emask[i, k] = mask
                net.emask[j, net.rev[i, k]] = mask


@inlined
def _nearest_brute(pos, n, x0, x1, x2):
    best = np.inf
    s = -1
    for i in range(n):
        d = _sq_dist(pos, i, x0, x1, x2, 3)
        if d < best:
            best = d
            s = i
    return s, best


@inlined
def _nearest_grid(net, n, x0, x1, x2, cell_size, inv_cell, guess):
    """Exact nearest node by position from the grid, starting from node ``guess`` (or -1).

    Rings of cells around the query's cell are visited outward; a cell is skipped when its box
    is farther than the best distance so far, and the search stops when no unvisited ring can
    hold a closer node. A good guess (the previous pixel's winner) prunes almost every cell.
    """
    pos = net.pos
    ghead = net.ghead
    gnext = net.gnext
    table_mask = ghead.shape[0] - 1
    cx, up_x, near_x, far_x = query_axis(x0 * inv_cell)
    cy, up_y, near_y, far_y = query_axis(x1 * inv_cell)
    cz, up_z, near_z, far_z = query_axis(x2 * inv_cell)
    margin = min(near_x, near_y, near_z)
    prune = (1.0 + BOUND_SLACK) * inv_cell * inv_cell
    best = np.inf
    s = -1
    if guess >= 0:
        best = _sq_dist(pos, guess, x0, x1, x2, 3)
        s = guess
    r = 0
    while True:
        if r > 0:
            bound = (r - 1 + margin) * cell_size
            if best * (1.0 + BOUND_SLACK) <= bound * bound:
                return s, best
            side = 2 * r + 1
            if side * side * side > 2 * n:
                return _nearest_brute(pos, n, x0, x1, x2)
        for dx in range(-r, r + 1):
            gx = _axis_gap(dx, up_x, near_x, far_x)
            for dy in range(-r, r + 1):
                gy = _axis_gap(dy, up_y, near_y, far_y)
                gxy = gx * gx + gy * gy
                if gxy > best * prune:
                    continue
                on_ring = abs(dx) == r or abs(dy) == r
                for dz in range(-r, r + 1):
                    if not on_ring and abs(dz) != r:
                        continue
                    gz = _axis_gap(dz, up_z, near_z, far_z)
                    if gxy + gz * gz > best * prune:
                        continue
                    p = ghead[_bucket(cx + dx, cy + dy, cz + dz, table_mask)]
                    while p >= 0:
                        d = _sq_dist(pos, p, x0, x1, x2, 3)
                        if d < best:
                            best = d
                            s = p
                        p = gnext[p]
        r += 1


@njit(cache=True, nogil=True)
def nearest_nodes(points, start, stop, net, winners, sq_distances):
    """Nearest node by position of points ``start..stop-1``, through the learner's hash grid.

    points: (N, 3) float32/float64, ideally in scan order (each search starts from the previous
    point's winner); net: a 3-D network with at least one node. Writes ``winners`` (N,) int32
    and ``sq_distances`` (N,) float64 in that range. Exact; brute force without a grid (few
    nodes). Releases the GIL, so threads can label disjoint ranges at once.
    """
    search = _search_of(net)
    guess = -1
    for q in range(start, stop):
        s, d = _nearest(net, search, np.float64(points[q, 0]), np.float64(points[q, 1]),
                        np.float64(points[q, 2]), guess)
        winners[q] = s
        sq_distances[q] = d
        guess = s


@njit(cache=True)
def nearest_other_sq_distances(net, sq_distances):
    """Squared distance from each node of a 3-D network with at least two nodes to its nearest
    other node, into ``sq_distances`` (n,) float64: the learner's exact two-nearest search at the
    node's own position (the node itself, or a node on it, is one of the two)."""
    n, grid_on, cell_size, inv_cell = _search_of(net)
    pos = net.pos
    for i in range(n):
        if grid_on:
            s1, _, best1, best2 = nearest_two_grid(net, n, pos[i, 0], pos[i, 1], pos[i, 2], 3,
                                                   cell_size, inv_cell)
        else:
            s1, _, best1, best2 = nearest_two_brute(pos, n, pos[i, 0], pos[i, 1], pos[i, 2], 3)
        sq_distances[i] = best2 if s1 == i else best1


@inlined
def _search_of(net):
    """What a nearest-node search reads of ``net`` once: its node count, whether the grid is
    active, the grid's cell size and its inverse."""
    grid_on = net.istate[I_GRID] != 0
    cell_size = net.fstate[F_CELL]
    return net.istate[I_NODES], grid_on, cell_size, 1.0 / cell_size if grid_on else 0.0


@inlined
def _nearest(net, search, x0, x1, x2, guess):
    """Nearest node of ``net`` to (x0, x1, x2) and its squared distance: through the grid when
    it is active (starting from node ``guess``, or -1), else by brute force; ``search`` is
    `_search_of` the network."""
    n, grid_on, cell_size, inv_cell = search
    if grid_on:
        return _nearest_grid(net, n, x0, x1, x2, cell_size, inv_cell, guess)
    return _nearest_brute(net.pos, n, x0, x1, x2)


@inlined
def _agreed_label(out, valid, r0, r1, c0, c1):
    """The label that the valid ones of the distinct anchors (r0|r1, c0|c1) share, when at
    least two are valid and all valid ones agree; -1 otherwise."""
    label = -1
    n_valid = 0
    for corner in range(4):
        rr = r1 if corner & 2 else r0
        cc = c1 if corner & 1 else c0
        if (corner & 2 and r1 == r0) or (corner & 1 and c1 == c0) or not valid[rr, cc]:
            continue
        if n_valid and out[rr, cc] != label:
            return -1
        label = out[rr, cc]
        n_valid += 1
    return label if n_valid >= 2 else -1


@njit(cache=True, nogil=True)
def label_pixels(points, valid, node_labels, stride, anchors, row_start, row_stop, net, out):
    """Nearest node's label + 1 (0 where not ``valid``) of the pixels of rows
    ``row_start..row_stop-1``, in two passes over the whole image.

    ``anchors`` True: the anchor pixels (row and column multiples of ``stride``), each searched.
    False: every other pixel; one whose surrounding anchors (2 or 4, at most ``stride`` pixels
    away, in the image) include at least two valid ones, all of one label, takes it; any other
    is searched.
    points: (H, W, 3) float32/float64 metres; valid: (H, W) bool; node_labels: (n,) int32, -1 =
    no label; net: a 3-D network with at least one node; out: (H, W) int32, written at the
    pass's pixels only.
    """
    search = _search_of(net)
    guess = -1
    height, width = valid.shape
    for r in range(row_start, row_stop):
        row_offset = r % stride
        if anchors and row_offset:
            continue
        r0 = r - row_offset
        r1 = r0 + stride if row_offset and r0 + stride < height else r0
        for c0 in range(0, width, stride):
            if anchors:
                first, stop, label = c0, c0 + 1, -1
            else:  # the anchors' label is judged once per row of a block, not per pixel
                first = c0 + 1 if row_offset == 0 else c0
                stop = min(c0 + stride, width)
                c1 = c0 + stride if c0 + stride < width else c0
                label = _agreed_label(out, valid, r0, r1, c0, c1)
            for c in range(first, stop):
                if not valid[r, c]:
                    out[r, c] = 0
                elif label >= 0:
                    out[r, c] = label
                else:
                    s, _ = _nearest(net, search, np.float64(points[r, c, 0]),
                                    np.float64(points[r, c, 1]), np.float64(points[r, c, 2]),
                                    guess)
                    out[r, c] = node_labels[s] + 1
                    guess = s


@njit(cache=True, nogil=True)
def veil_pixels(depth, ratio, out):
    """out (H, W) bool: True where the pixel's depth differs from a 4-neighbour's by more than
    ``ratio`` of the nearer of the two; depth (H, W) float, NaN or <= 0 = no measurement (never
    a veil pixel, and no neighbour)."""
    height, width = depth.shape
    out[:] = False
    for r in range(height):
        for c in range(width):
            z = depth[r, c]
            if not z > 0.0:
                continue
            if c + 1 < width:  # each pair once: the right and the lower neighbour
                other = depth[r, c + 1]
                if other > 0.0 and abs(other - z) > ratio * min(z, other):
                    out[r, c] = True
                    out[r, c + 1] = True
            if r + 1 < height:
                other = depth[r + 1, c]
                if other > 0.0 and abs(other - z) > ratio * min(z, other):
                    out[r, c] = True
                    out[r + 1, c] = True
