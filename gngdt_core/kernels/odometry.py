"""Kernels of frame-to-map camera tracking (`gngdt.core.odometry.map_odometry`): rigid motions,
normals of an organized frame, node colour gradients and the Gauss-Newton normal equations of
point-to-plane ICP. Pure functions over arrays.

Conventions: a pose is a (4, 4) float64 rigid transform; a twist ``xi`` (6,) is (rotation
vector, translation), metres and radians. A linearisation is taken about a centre ``c`` (the
frame's centroid in the map frame) so that rotation and translation stay decoupled: the update
``xi`` moves a map-frame point ``p`` to ``c + exp(xi[:3]) (p - c) + xi[3:]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.spatial.transform import Rotation

from gngdt.core.kernels._numba import inlined
from gngdt.core.sensor.geometry import rigid_inverse

#: Rec. 601 luma weights: a colour's intensity, 0..1 for 0..255 channels
LUMA = np.array([0.299, 0.587, 0.114]) / 255.0


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix of (3,) ``v``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def so3_exp(omega: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the rotation vector ``omega`` (3,) radians (Rodrigues)."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3) + skew(omega)
    k = skew(omega / angle)
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def so3_log(rotation: np.ndarray) -> np.ndarray:
    """(3,) rotation vector, radians, of a (3, 3) rotation (the inverse of `so3_exp`)."""
    return Rotation.from_matrix(rotation).as_rotvec()


def _left_jacobian(omega: np.ndarray) -> np.ndarray:
    """(3, 3) SO(3)'s left Jacobian at ``omega`` (3,): it maps a screw's axis part to the
    translation its exponential makes."""
    angle = float(np.linalg.norm(omega))
    k = skew(omega)
    if angle < 1e-6:
        return np.eye(3) + k / 2.0 + (k @ k) / 6.0
    return (np.eye(3) + (1.0 - math.cos(angle)) / angle ** 2 * k
            + (angle - math.sin(angle)) / angle ** 3 * (k @ k))


def scaled_motion(motion: np.ndarray, fraction: float) -> np.ndarray:
    """(4, 4) the rigid ``motion`` continued for ``fraction`` of itself along its screw: 0 gives
    the identity, 1 the motion, 2 the motion applied twice (a constant velocity's motion over
    ``fraction`` times the time ``motion`` took)."""
    omega = so3_log(motion[:3, :3])
    axis_part = np.linalg.solve(_left_jacobian(omega), motion[:3, 3])
    scaled = np.eye(4)
    scaled[:3, :3] = so3_exp(fraction * omega)
    scaled[:3, 3] = _left_jacobian(fraction * omega) @ (fraction * axis_part)
    return scaled


def update_about(xi: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(4, 4) the rigid motion ``p -> c + exp(xi[:3]) (p - c) + xi[3:]``."""
    rotation = so3_exp(xi[:3])
    motion = np.eye(4)
    motion[:3, :3] = rotation
    motion[:3, 3] = centre - rotation @ centre + xi[3:]
    return motion


def orthonormalised(pose: np.ndarray) -> np.ndarray:
    """(4, 4) ``pose`` with its rotation replaced by the nearest orthonormal one (SVD), so that
    rounding does not build up over many composed updates."""
    u, _, vt = np.linalg.svd(pose[:3, :3])
    fixed = pose.copy()
    fixed[:3, :3] = u @ vt
    fixed[3] = (0.0, 0.0, 0.0, 1.0)
    return fixed


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """Angle of a (3, 3) rotation, degrees."""
    cosine = (np.trace(rotation) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, cosine))))


def motion_size(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(translation metres, rotation degrees) of ``a^-1 b`` for (4, 4) poses ``a``, ``b``."""
    delta = rigid_inverse(a) @ b
    return float(np.linalg.norm(delta[:3, 3])), rotation_angle_deg(delta[:3, :3])


def intensities(colors: np.ndarray) -> np.ndarray:
    """(N,) float64 luma 0..1 of (N, 3) RGB colours on the 0..255 scale."""
    return np.asarray(colors, dtype=np.float64) @ LUMA


def organized_normals(points: np.ndarray, max_jump: float) -> np.ndarray:
    """(h, w, 3) float64 unit normals of an organized cloud ``points`` (h, w, 3) metres (NaN:
    none), from central differences between each point's grid neighbours, facing the camera
    (z < 0 side); NaN on the border, next to a missing point, and where a neighbour's depth
    differs from the point's by more than ``max_jump`` times its depth (a depth edge)."""
    p = np.asarray(points, dtype=np.float64)
    normals = np.full(p.shape, np.nan)
    if p.shape[0] < 3 or p.shape[1] < 3:
        return normals
    centre = p[1:-1, 1:-1]
    left, right = p[1:-1, :-2], p[1:-1, 2:]
    up, down = p[:-2, 1:-1], p[2:, 1:-1]
    n = np.cross(right - left, down - up)
    length = np.linalg.norm(n, axis=2)
    z = centre[..., 2]
    with np.errstate(invalid="ignore"):
        jump = np.maximum.reduce([np.abs(q[..., 2] - z) for q in (left, right, up, down)])
        good = (length > 0) & (jump <= max_jump * z)
    n = n / np.where(good, length, 1.0)[..., None]
    flip = np.einsum("hwk,hwk->hw", n, centre) > 0  # face the camera at the origin
    n[flip] *= -1.0
    n[~good] = np.nan
    normals[1:-1, 1:-1] = n
    return normals


def node_gradients(positions: np.ndarray, normals: np.ndarray, values: np.ndarray,
                   edges: np.ndarray, ridge: float) -> np.ndarray:
    """(N, 3) gradient of a scalar node property ``values`` (N,) in each node's tangent plane.

    Least squares over the node's edges: ``values[j] - values[i] ~ g . t_ij`` with ``t_ij`` the
    edge vector projected onto node i's tangent plane (``normals`` (N, 3) unit; zero normal: no
    projection); ``ridge`` (units of squared metres) keeps nodes with one or two edges from
    getting a huge gradient. Zero for nodes without edges. ``edges``: (E, 2) node index pairs.
    """
    n_nodes = len(positions)
    a = np.zeros((n_nodes, 3, 3))
    b = np.zeros((n_nodes, 3))
    if len(edges):
        for i, j in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
            d = positions[j] - positions[i]
            d -= np.einsum("ek,ek->e", d, normals[i])[:, None] * normals[i]
            outer = (d[:, :, None] * d[:, None, :]).reshape(-1, 9)
            for k in range(9):
                a.reshape(-1, 9)[:, k] += np.bincount(i, weights=outer[:, k], minlength=n_nodes)
            for k in range(3):
                b[:, k] += np.bincount(i, weights=d[:, k] * (values[j] - values[i]),
                                       minlength=n_nodes)
    a += ridge * np.eye(3)
    return np.linalg.solve(a, b[..., None])[..., 0]


@inlined
def add_residual(q0, q1, q2, d0, d1, d2, w, r, jac, hessian, gradient):
    """Add one residual ``r`` with weight ``w`` to the upper triangle of ``hessian`` (6, 6) and
    to ``gradient`` (6,): its Jacobian over the twist is ``(q x d, d)``, q the point about the
    twist's centre and d the residual's direction (``jac`` (6,) is scratch)."""
    jac[0] = q1 * d2 - q2 * d1
    jac[1] = q2 * d0 - q0 * d2
    jac[2] = q0 * d1 - q1 * d0
    jac[3] = d0
    jac[4] = d1
    jac[5] = d2
    for i in range(6):
        wi = w * jac[i]
        gradient[i] += wi * r
        for j in range(i, 6):
            hessian[i, j] += wi * jac[j]


@njit(cache=True, nogil=True)
def normal_equations(points, node, anchors, directions, offsets, weights, inliers, centre, huber,
                     hessian, gradient):
    """Add one residual family's Gauss-Newton system to ``hessian`` (6, 6) and ``gradient`` (6,).

    Residual of row k, paired with node ``node[k]``: ``r = directions[node[k]] . (points[k] -
    anchors[node[k]]) + offsets[k]`` (a colour gradient and the intensity difference for
    colour), Huber-weighted with threshold ``huber`` and weighted by ``weights[k]`` (rows not
    ``inliers``, or of weight 0, skipped). ``points`` (M, 3) in the map frame under the current
    pose; ``anchors``, ``directions`` (N, 3) per node (indexed here: gathering them into (M, 3)
    arrays first took a third of the colour system's time). The Jacobian of ``r`` over the
    twist about ``centre`` is ``((points[k] - centre) x d, d)``. Returns (sum of weighted
    squared residuals, sum of weights).
    """
    cost = 0.0
    total = 0.0
    jac = np.empty(6)
    for k in range(points.shape[0]):
        if not inliers[k] or weights[k] <= 0.0:
            continue
        n = node[k]
        d0 = directions[n, 0]
        d1 = directions[n, 1]
        d2 = directions[n, 2]
        p0 = points[k, 0]
        p1 = points[k, 1]
        p2 = points[k, 2]
        r = (d0 * (p0 - anchors[n, 0]) + d1 * (p1 - anchors[n, 1]) + d2 * (p2 - anchors[n, 2])
             + offsets[k])
        a = abs(r)
        w = weights[k] if a <= huber else weights[k] * huber / a
        add_residual(p0 - centre[0], p1 - centre[1], p2 - centre[2], d0, d1, d2, w, r, jac,
                     hessian, gradient)
        cost += w * r * r
        total += weights[k]
    for i in range(6):
        for j in range(i):
            hessian[i, j] = hessian[j, i]
    return cost, total


def constrained_step(hessian: np.ndarray, gradient: np.ndarray, scale: float,
                     min_eigenvalue: float) -> tuple[np.ndarray, float]:
    """Gauss-Newton step of ``hessian @ xi = -gradient`` restricted to the well-constrained
    directions, and the smallest eigenvalue of the scaled system.

    Rotation is made comparable to translation by ``scale`` (metres: the frame's extent about
    the centre), so the eigenvalues are per unit of motion of a typical point. Directions whose
    eigenvalue is below ``min_eigenvalue`` get no update (they keep the prediction; Zhang et al.
    2016, "On degeneracy of optimization-based state estimation problems").
    """
    s = np.array([scale, scale, scale, 1.0, 1.0, 1.0])
    scaled = hessian / np.outer(s, s)
    values, vectors = np.linalg.eigh(scaled)
    rhs = vectors.T @ (-gradient / s)
    keep = values > max(min_eigenvalue, 1e-12)
    step = vectors[:, keep] @ (rhs[keep] / values[keep])
    return step / s, float(values[0])


@njit(cache=True, nogil=True)
def point_to_plane(points, normals, sigma, rotation, translation, node, gated, anchors,
                   node_normals, node_trust, cos_min, huber_sigma, inlier_sigma, node_robust,
                   map_noise, inverse_variance, world, residual, weight, inlier, hessian,
                   gradient):
    """One Gauss-Newton system of point-to-plane ICP against node planes, in two passes.

    points, normals (M, 3): the frame's points and unit normals, camera frame; sigma (M,) their
    depth noise, metres; rotation (3, 3), translation (3,): the pose estimate (camera to map);
    node (M,) each point's nearest node, gated (M,) bool whether within the level's gate;
    anchors, node_normals (N, 3): a point on each node's plane and its unit normal; node_trust
    (N,) each node's weight. A pair is used when gated and the two normals are within the angle
    of ``cos_min`` (sign-invariant). Weights: the node's trust, times 1 / sigma^2 (relative to
    ``sigma = 1``... only with ``inverse_variance``), times a Cauchy weight of the node's mean
    residual in sigmas of that mean (scale ``node_robust``; 0: off), times Huber from
    ``huber_sigma`` sigmas. Writes world (M, 3) the points in the map frame, residual (M,)
    (0 where unused), weight (M,) the final weights (0: unused), inlier (M,) bool (used and
    within ``inlier_sigma`` sigmas), and adds the system about the paired points' centroid to
    ``hessian`` (6, 6) and ``gradient`` (6,). Returns (centroid (3,), RMS distance of the paired
    points from it, sum of weights, points used).
    """
    m = points.shape[0]
    n = anchors.shape[0]
    sum_r = np.zeros(n)
    sum_s2 = np.zeros(n)
    count = np.zeros(n)
    centre = np.zeros(3)
    used = 0
    for k in range(m):
        for a in range(3):
            world[k, a] = (rotation[a, 0] * points[k, 0] + rotation[a, 1] * points[k, 1]
                           + rotation[a, 2] * points[k, 2] + translation[a])
        weight[k] = 0.0
        residual[k] = 0.0
        inlier[k] = False
        if not gated[k]:
            continue
        i = node[k]
        cosine = 0.0
        r = 0.0
        for a in range(3):
            turned = (rotation[a, 0] * normals[k, 0] + rotation[a, 1] * normals[k, 1]
                      + rotation[a, 2] * normals[k, 2])
            cosine += turned * node_normals[i, a]
            r += node_normals[i, a] * (world[k, a] - anchors[i, a])
        if abs(cosine) < cos_min or node_trust[i] <= 0.0:
            continue
        residual[k] = r
        s2 = sigma[k] * sigma[k]
        weight[k] = node_trust[i] / s2 if inverse_variance else node_trust[i]
        sum_r[i] += r
        sum_s2[i] += s2
        count[i] += 1.0
        for a in range(3):
            centre[a] += world[k, a]
        used += 1
    if used == 0:
        return centre, 0.0, 0.0, 0
    for a in range(3):
        centre[a] /= used
    spread = 0.0
    total = 0.0
    jac = np.empty(6)
    for k in range(m):
        w = weight[k]
        if w <= 0.0:
            continue
        i = node[k]
        r = residual[k]
        if node_robust > 0.0:
            mean = sum_r[i] / count[i]
            chi = mean / math.sqrt(sum_s2[i] / (count[i] * count[i]) + map_noise * map_noise)
            w /= 1.0 + (chi / node_robust) ** 2
        a_r = abs(r)
        limit = huber_sigma * sigma[k]
        inlier[k] = a_r < inlier_sigma * sigma[k]
        total += w
        if a_r > limit:
            w *= limit / a_r
        weight[k] = w
        q0 = world[k, 0] - centre[0]
        q1 = world[k, 1] - centre[1]
        q2 = world[k, 2] - centre[2]
        spread += q0 * q0 + q1 * q1 + q2 * q2
        add_residual(q0, q1, q2, node_normals[i, 0], node_normals[i, 1], node_normals[i, 2], w,
                     r, jac, hessian, gradient)
    for a in range(6):
        for b in range(a):
            hessian[a, b] = hessian[b, a]
    return centre, math.sqrt(spread / used), total, used


@njit(cache=True, nogil=True)
def organize_points(points, colors, fx, fy, cx, cy, width, height, stride, organized, image):
    """Put deprojected ``points`` (N, 3) camera frame back on their pixels of a ``width`` x
    ``height`` image, keeping every ``stride``-th row and column: ``organized``
    (ceil(height / stride), ceil(width / stride), 3) float32 (NaN-filled by the caller) gets each
    point at the pixel nearest its projection, ``image`` (same rows and columns, 3) uint8 its
    colour (``colors`` (N, 3) uint8; an empty array when there are none). Points not in front of
    the camera, non-finite, off the image or between the kept pixels are dropped. Returns how
    many were placed."""
    with_color = colors.shape[0] == points.shape[0]
    placed = 0
    for k in range(points.shape[0]):
        x, y, z = points[k, 0], points[k, 1], points[k, 2]
        if not (z > 0.0 and np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
            continue
        u = np.rint(fx * x / z + cx)
        v = np.rint(fy * y / z + cy)
        if not (0.0 <= u < width and 0.0 <= v < height):
            continue
        row, column = int(v), int(u)
        if row % stride or column % stride:
            continue
        i, j = row // stride, column // stride
        organized[i, j, 0] = x
        organized[i, j, 1] = y
        organized[i, j, 2] = z
        if with_color:
            image[i, j, 0] = colors[k, 0]
            image[i, j, 1] = colors[k, 1]
            image[i, j, 2] = colors[k, 2]
        placed += 1
    return placed
