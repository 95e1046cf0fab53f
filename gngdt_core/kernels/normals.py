"""Normals (eq. 16) and the tests of eqs. 4/9 that give an edge its property bits.

A normal of (0, 0, 0) means "undefined" and never gets a normal edge (see `layout`).
"""

from __future__ import annotations

import math

from numba import njit

from gngdt.core.kernels._numba import flush_tiny, inlined
from gngdt.core.kernels.grid import _node_sq_dist, _sq_dist
from gngdt.core.kernels.layout import COL_BIT, NOR_BIT, POS_BIT

# Newton steps on the characteristic cubic before `smallest_eigenvalue` takes the closed form.
NEWTON_MAX_STEPS = 40


@inlined
def _smallest_eigenvalue_trig(q, p2, a00, a01, a02, a11, a12, a22):
    """The smallest eigenvalue in closed form (trigonometric solution of the cubic); ``q`` is
    the trace / 3, ``p2`` > 0 the squared Frobenius norm of (A - qI)."""
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p = math.sqrt(p2 / 6.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    ) / (p * p * p)
    half_det = min(1.0, max(-1.0, det / 2.0))
    phi = math.acos(half_det) / 3.0
    return q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)


@inlined
def smallest_eigenvalue(q, p2, a00, a01, a02, a11, a12, a22):
    """The smallest eigenvalue of a symmetric 3x3 matrix (``q``, ``p2`` as
    `_smallest_eigenvalue_trig`).

    A covariance (positive semi-definite: every coefficient of its characteristic cubic
    ``l^3 - tr l^2 + c2 l - det`` has the sign that leaves no negative root) takes Newton's
    method from 0: the cubic is increasing and concave left of its smallest root, so the steps
    rise monotonically to it, and they stop when one no longer rises (full precision; one to a
    few steps for a surface's points, where that root is far below the others). Other matrices,
    and the rare ones whose two smallest roots nearly coincide (slow steps), take the closed form
    (an arccosine and a cosine, several times the cost).
    """
    trace = a00 + a11 + a22
    c2 = a00 * a11 + a00 * a22 + a11 * a22 - a01 * a01 - a02 * a02 - a12 * a12
    det = (a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02)
           + a02 * (a01 * a12 - a11 * a02))
    if trace >= 0.0 and c2 >= 0.0 and det >= 0.0:
        root = 0.0
        for _ in range(NEWTON_MAX_STEPS):
            value = ((root - trace) * root + c2) * root - det
            slope = (3.0 * root - 2.0 * trace) * root + c2
            if not slope > 0.0:
                break
            step = root - value / slope
            if not step > root:
                return root
            root = step
    return _smallest_eigenvalue_trig(q, p2, a00, a01, a02, a11, a12, a22)


@njit(cache=True)
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix.

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
    smallest = smallest_eigenvalue(q, p2, a00, a01, a02, a11, a12, a22)
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
    nor[i, 0] = flush_tiny(x)
    nor[i, 1] = flush_tiny(y)
    nor[i, 2] = flush_tiny(z)


@inlined
def compute_normal(net, i, mu, orient, vx, vy, vz):
    """Eq. 16: normal of node ``i`` of ``net`` from its position neighbours, written to
    ``net.nor[i]``.

    As the paper: weighted centroid ``m = (h_i + sum w_j h_j) / (1 + sum w_j)`` with
    ``w_j = exp(-||h_i - h_j||^2 / mu^2)``; covariance ``sum_j (h_j - m)(h_j - m)^T`` over the
    k neighbours (unweighted); normal = eigenvector of its smallest eigenvalue. ``mu <= 0``
    means the scale-free default: ``mu`` = mean distance from ``i`` to its neighbours.
    Undefined (zero) with fewer than two neighbours.
    """
    pos = net.pos
    nor = net.nor
    nbr = net.nbr
    k_count = net.deg[i]
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
def property_bits(net, i, j, has_col, has_nor, tau_col, tau_nor):
    """Position bit plus the bits of the other properties whose eq. 4/9 test holds for nodes
    (i, j) of ``net``."""
    mask = POS_BIT
    if has_col and colours_close(net.col, i, j, tau_col):
        mask |= COL_BIT
    if has_nor and normals_close(net.nor, i, j, tau_nor):
        mask |= NOR_BIT
    return mask


@njit(cache=True)
def _interpolate_normal(net, u, f, r, orient, vx, vy, vz):
    """Normal of a new node ``r``: the sign-aligned mean of its parents' (``u``, ``f``)
    normals, renormalised."""
    nor = net.nor
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
            _orient(nor, net.pos, r, vx, vy, vz)
    else:
        for a in range(3):
            nor[r, a] = 0.0
