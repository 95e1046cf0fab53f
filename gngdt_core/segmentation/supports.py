"""Support surfaces and segment roles in a segmented GNG-DT network.

- `find_supports` (segmentation step 2b): smooth patches that are large planes — a table, a
  floor, a wall, a shelf's floor or side, in any orientation, any number — keep exactly the
  nodes on their plane (distances judged against the plane's own noise, which grows with the
  square of the depth) connected to them; a piece that rises at least ``min_height_m`` above
  the plane leaves it (a case lying flat that the table's patch grew over), and with node
  colours, a piece of another colour leaves however low it is (a sheet).
- `segment_roles`: each segment is a **support** (a support plane that something rests on or
  leans against, or that reaches the edge of the view or is longer than an object: one seen
  whole, small, carrying nothing is a large flat object, a laptop's lid), **clutter**
  (background structure: seen only in part — it reaches the edge of the view — or longer than
  ``max_object_extent_m``, or bordering mostly on such structure; and bits: narrower than
  ``min_object_extent_m`` or of fewer than ``min_object_nodes`` nodes) or an **object**.
  `SegmentRoles.rests_on` records who rests on (or leans against) whom: supports, and objects
  stacked on a flat top.

Planes are fitted per group of nodes, twice: to all of them, then to those within
``INLIER_SIGMAS`` robust standard deviations of the first plane, so an object lying on a table
does not tilt the table's plane. Pure computation on arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: nodes within this many robust standard deviations of a group's first plane refit it
INLIER_SIGMAS = 3.0
#: robust standard deviation from the median absolute deviation (normal noise)
MAD_TO_SIGMA = 1.4826

#: RGB units (0-255): a support's colour varies by at least this much (wood grain, shading)
MIN_COLOUR_DISTANCE = 40.0

OBJECT, SUPPORT, CLUTTER = 0, 1, 2
ROLE_NAMES = ("object", "support", "clutter")


@dataclass(frozen=True)
class Planes:
    """Least-squares planes of K groups of nodes (`fit_planes`)."""

    #: (K, 3) metres, the centroid of each group's inliers
    centroid: np.ndarray
    #: (K, 3) unit normal, facing the sensor (the origin of the nodes' frame) where it can
    normal: np.ndarray
    #: (K,) metres, robust standard deviation of the nodes' distances to the plane
    sigma: np.ndarray
    #: (K, 2) metres, extent along the plane's two in-plane axes (larger first): the side of a
    #: uniform rectangle with the same spread (sqrt(12) standard deviations)
    extent: np.ndarray
    #: (K,) nodes in each group
    count: np.ndarray
    #: (K, 2, 3) unit in-plane axes, along the larger extent first
    axes: np.ndarray | None = None

    def distances(self, positions: np.ndarray, groups: np.ndarray) -> np.ndarray:
        """(n,) signed distance (metres) of each node to its group's plane, positive on the
        normal's side; ``groups`` (n,) int group of each node (all >= 0)."""
        offset = positions - self.centroid[groups]
        return np.einsum("ij,ij->i", offset, self.normal[groups])


def fit_planes(positions: np.ndarray, groups: np.ndarray, n_groups: int) -> Planes:
    """Planes of the nodes of each group 0..n_groups-1 (groups: (n,) int, -1 = none), fitted
    twice: to all the group's nodes, then to those within ``INLIER_SIGMAS`` robust standard
    deviations of the first plane. Groups of fewer than 3 nodes get a zero normal."""
    member = groups >= 0
    planes = _least_squares_planes(positions[member], groups[member], n_groups)
    distance = planes.distances(positions[member], groups[member])
    sigma = _robust_sigma(distance, groups[member], n_groups)
    inlier = np.abs(distance) <= INLIER_SIGMAS * np.maximum(sigma[groups[member]], 1e-9)
    refit = _least_squares_planes(positions[member][inlier], groups[member][inlier], n_groups)
    keep = refit.count >= 3
    planes = Planes(np.where(keep[:, None], refit.centroid, planes.centroid),
                    np.where(keep[:, None], refit.normal, planes.normal), planes.sigma,
                    np.where(keep[:, None], refit.extent, planes.extent), planes.count,
                    np.where(keep[:, None, None], refit.axes, planes.axes))
    distance = planes.distances(positions[member], groups[member])
    return Planes(planes.centroid, planes.normal,
                  _robust_sigma(distance, groups[member], n_groups), planes.extent,
                  planes.count, planes.axes)


def _least_squares_planes(positions: np.ndarray, groups: np.ndarray, n_groups: int) -> Planes:
    count = np.bincount(groups, minlength=n_groups).astype(np.float64)
    safe = np.maximum(count, 1.0)
    centroid = np.stack([np.bincount(groups, positions[:, k], n_groups) for k in range(3)],
                        axis=1) / safe[:, None]
    centred = positions - centroid[groups]
    covariance = np.empty((n_groups, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            covariance[:, a, b] = covariance[:, b, a] = np.bincount(
                groups, centred[:, a] * centred[:, b], n_groups) / safe
    values, vectors = np.linalg.eigh(covariance)  # ascending: the normal is the first
    normal = vectors[:, :, 0]
    towards_sensor = np.einsum("ij,ij->i", normal, -centroid) >= 0.0
    normal = np.where(towards_sensor[:, None], normal, -normal)
    normal[count < 3] = 0.0
    extent = np.sqrt(12.0 * np.maximum(values[:, [2, 1]], 0.0))
    return Planes(centroid, normal, np.sqrt(np.maximum(values[:, 0], 0.0)), extent,
                  count.astype(np.int64), np.transpose(vectors[:, :, [2, 1]], (0, 2, 1)))


def _robust_sigma(distance: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups,) MAD_TO_SIGMA x the median absolute distance of each group (0: empty)."""
    sigma = np.zeros(n_groups)
    if distance.size == 0:
        return sigma
    order = np.lexsort((np.abs(distance), groups))
    sorted_groups = groups[order]
    start = np.searchsorted(sorted_groups, np.arange(n_groups), side="left")
    stop = np.searchsorted(sorted_groups, np.arange(n_groups), side="right")
    present = stop > start
    middle = (start + stop - 1) // 2
    sigma[present] = MAD_TO_SIGMA * np.abs(distance[order][middle[present]])
    return sigma


@dataclass(frozen=True)
class Supports:
    """Support planes found among the smooth patches (`find_supports`)."""

    #: (n,) int32 patches after the supports took their nodes (the supports' patches first)
    patches: np.ndarray
    #: (n_patches,) bool: the patch is a support plane
    is_support: np.ndarray


def find_supports(patches: np.ndarray, positions: np.ndarray, normals: np.ndarray,
                  adjacency: tuple, *, min_nodes: int, min_extent_m: float,
                  plane_sigmas: float, min_offset_m: float, cos_normal: float,
                  min_height_m: float = 0.0, depths: np.ndarray | None = None,
                  colors: np.ndarray | None = None) -> Supports:
    """Support planes (tables, floors, walls, shelf floors and sides: any orientation, any
    number) and their nodes.

    A smooth patch of at least ``min_nodes`` nodes is a support plane when at least 90 % of its
    nodes lie within ``plane_sigmas`` robust standard deviations (and ``min_offset_m``) of its
    plane and it spans at least ``min_extent_m`` along both in-plane axes. Its nodes are then
    exactly those on the plane (that close, normals within ``acos(cos_normal)`` of its normal)
    connected to the patch's own such nodes by position edges (``adjacency``: CSR offsets and
    neighbours): pieces of the same table cut off by noise join it, and nodes of the patch off
    the plane (a thin case the patch grew over) leave it as patches of their own, one per
    connected group, when it rises at least ``min_height_m`` above the plane somewhere (a
    shallower group is the plane's own warp or noise: a real table or floor bends by a few
    millimetres). Supports are patches 0..S-1 of the result.

    depths: (n,) metres from the sensor along its axis (None: all alike). A depth sensor's
    noise grows with the square of the depth, so distances to a plane are judged in units of
    ``depth ** 2``: the far end of a floor 4 m away stays on it, a case 1 cm high at 1 m leaves.

    colors: (n, 3) RGB of the nodes (None: not used). A support is then also one colour: a
    node on its plane whose colour lies farther from the support's median colour than
    ``plane_sigmas`` robust standard deviations of the support's own colours (and than
    ``MIN_COLOUR_DISTANCE``) is not taken: something flat of another colour lying on it (a
    sheet, a flat case thinner than the plane's noise).
    """
    from gngdt.core.kernels import regions as RK

    n = patches.size
    n_patches = int(patches.max()) + 1 if n else 0
    noise = np.ones(n) if depths is None else np.square(np.maximum(depths, 1e-3))
    fits = _plane_patches(patches, n_patches, positions, noise, min_nodes=min_nodes,
                          min_extent_m=min_extent_m, plane_sigmas=plane_sigmas,
                          min_offset_m=min_offset_m)
    if not fits:
        return Supports(patches, np.zeros(n_patches, dtype=bool))
    normal = np.concatenate([plane.normal for _, plane, _ in fits])
    offset = np.einsum("kj,kj->k", np.concatenate([plane.centroid for _, plane, _ in fits]),
                       normal)
    limit = np.maximum(np.array([limit for _, _, limit in fits])[None, :] * noise[:, None],
                       min_offset_m)
    own = np.array([patch for patch, _, _ in fits])
    # each node's nearest support plane it lies on (distance and normal), if any
    distance = np.abs(positions @ normal.T - offset)
    on = (distance <= limit) & (np.abs(normals @ normal.T) >= cos_normal)
    plane_of = np.where(on.any(axis=1), np.argmin(np.where(on, distance, np.inf), axis=1), -1)
    seed = (plane_of >= 0) & (patches == own[np.maximum(plane_of, 0)])
    other_colour = np.zeros(n, dtype=bool)
    if colors is not None:
        coloured = _same_colour(plane_of, seed, np.asarray(colors, dtype=np.float64),
                                len(fits), plane_sigmas)
        other_colour = coloured != plane_of
        plane_of = coloured
        seed &= plane_of >= 0
    offsets, neighbours, _ = adjacency
    result = RK.grow_supports(offsets, neighbours, plane_of.astype(np.int64), seed, patches,
                              n_patches, len(fits))
    left = result >= len(fits) + n_patches  # nodes that left a support's patch
    if left.any():
        origin = np.full(n_patches, -1)
        origin[own] = np.arange(len(fits))
        support_of = origin[patches[left]]
        height = np.abs(np.einsum("ij,ij->i", positions[left], normal[support_of])
                        - offset[support_of])
        result = _return_low_pieces(result, left, support_of, height, other_colour[left],
                                    min_height_m)
    is_support = np.zeros(int(result.max()) + 1, dtype=bool)
    is_support[: len(fits)] = True
    return Supports(result, is_support)


def _plane_patches(patches: np.ndarray, n_patches: int, positions: np.ndarray,
                   noise: np.ndarray, *, min_nodes: int, min_extent_m: float,
                   plane_sigmas: float, min_offset_m: float) -> list[tuple[int, Planes, float]]:
    """The patches that are support planes (`find_supports`): each as (patch, its plane, the
    largest distance to it that is on it, per unit of ``noise``); in patch order."""
    order = np.argsort(patches, kind="stable")
    starts = np.searchsorted(patches[order], np.arange(n_patches + 1))
    sizes = np.diff(starts)
    # only patches at least min_extent_m long along some axis can be that wide in-plane
    large = np.flatnonzero(sizes >= max(min_nodes, 3))
    if large.size == 0:
        return []
    ordered = positions[order]
    ordered_noise = noise[order]
    fits = []
    wide = _second_extent(ordered, starts[:-1], sizes, large) >= min_extent_m
    for patch in large[wide]:
        nodes = ordered[starts[patch]:starts[patch + 1]]
        scale = ordered_noise[starts[patch]:starts[patch + 1]]
        plane = _fit_one_plane(nodes)
        distance = np.abs(plane.distances(nodes, np.zeros(len(nodes), dtype=np.int64)))
        # the plane's noise per unit of depth squared, robustly
        spread = MAD_TO_SIGMA * np.median(distance / scale)
        near = distance <= np.maximum(plane_sigmas * spread * scale, min_offset_m)
        if near.mean() >= 0.9 and plane.extent[0, 1] >= min_extent_m:
            fits.append((int(patch), plane, plane_sigmas * spread))
    return fits


def _return_low_pieces(result: np.ndarray, left: np.ndarray, support_of: np.ndarray,
                       height: np.ndarray, other_colour: np.ndarray,
                       min_height_m: float) -> np.ndarray:
    """``result`` (`RK.grow_supports`) with each piece of the nodes that ``left`` a support's
    patch back on its support (``support_of``, per node that left) unless it rises at least
    ``min_height_m`` (``height``) above the plane somewhere or holds a node of another colour
    (``other_colour``); patches renumbered without the emptied ones."""
    pieces, piece_of = np.unique(result[left], return_inverse=True)
    tallest = np.zeros(pieces.size)
    np.maximum.at(tallest, piece_of, height)
    # a piece of another colour leaves however low it is
    coloured = np.zeros(pieces.size, dtype=bool)
    coloured[piece_of[other_colour]] = True
    back = (tallest < min_height_m)[piece_of] & ~coloured[piece_of]
    result = result.copy()
    result[np.flatnonzero(left)[back]] = support_of[back]
    present = np.zeros(int(result.max()) + 1, dtype=bool)
    present[result] = True  # renumbered without the emptied patches
    return (np.cumsum(present) - 1).astype(np.int32)[result]


def _second_extent(ordered: np.ndarray, starts: np.ndarray, sizes: np.ndarray,
                   which: np.ndarray) -> np.ndarray:
    """(K,) the second largest extent (sqrt(12) standard deviations) of the groups ``which``
    (K,) of the consecutive groups of the rows of ``ordered`` (n, 3): group k is rows
    ``starts[k]`` .. ``starts[k] + sizes[k] - 1``, every group non-empty, the last ending at n.
    """
    count = sizes[which, None].astype(np.float64)
    mean = np.add.reduceat(ordered, starts, axis=0)[which] / count
    products = ordered[:, [0, 0, 0, 1, 1, 2]] * ordered[:, [0, 1, 2, 1, 2, 2]]
    second = np.add.reduceat(products, starts, axis=0)[which] / count
    covariance = np.empty((len(which), 3, 3))
    for k, (a, b) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        covariance[:, a, b] = covariance[:, b, a] = second[:, k] - mean[:, a] * mean[:, b]
    values = np.linalg.eigvalsh(covariance)
    return np.sqrt(12.0 * np.maximum(values[:, 1], 0.0))


def _same_colour(plane_of: np.ndarray, seed: np.ndarray, colors: np.ndarray, n_planes: int,
                 sigmas: float) -> np.ndarray:
    """``plane_of`` with -1 for nodes whose colour is far from their plane's (`find_supports`);
    a plane's colour: the median of its seeds', its spread: their median distance to it."""
    result = plane_of.copy()
    for plane in range(n_planes):
        own = seed & (plane_of == plane)
        if not own.any():
            continue
        median = np.median(colors[own], axis=0)
        spread = MAD_TO_SIGMA * np.median(np.linalg.norm(colors[own] - median, axis=1))
        on = np.flatnonzero(plane_of == plane)
        far = np.linalg.norm(colors[on] - median, axis=1) > max(sigmas * spread,
                                                                MIN_COLOUR_DISTANCE)
        result[on[far]] = -1
    return result


def _fit_one_plane(nodes: np.ndarray) -> Planes:
    """`fit_planes` of one group of nodes (m, 3), m >= 3."""
    def fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        centroid = points.mean(axis=0)
        values, vectors = np.linalg.eigh(np.cov(points, rowvar=False, bias=True))
        return centroid, vectors[:, 0], values

    centroid, normal, _ = fit(nodes)
    distance = (nodes - centroid) @ normal
    sigma = MAD_TO_SIGMA * np.median(np.abs(distance))
    inlier = np.abs(distance) <= INLIER_SIGMAS * max(sigma, 1e-9)
    if inlier.sum() >= 3:
        centroid, normal, values = fit(nodes[inlier])
    else:
        values = np.linalg.eigvalsh(np.cov(nodes, rowvar=False, bias=True))
    if normal @ -centroid < 0:
        normal = -normal
    sigma = MAD_TO_SIGMA * np.median(np.abs((nodes - centroid) @ normal))
    extent = np.sqrt(12.0 * np.maximum(values[[2, 1]], 0.0))
    return Planes(centroid[None], normal[None], np.array([sigma]), extent[None],
                  np.array([len(nodes)]))


@dataclass(frozen=True)
class SegmentRoles:
    """Roles of the segments of one segmentation (`segment_roles`)."""

    #: (n_segments,) int8: OBJECT, SUPPORT or CLUTTER
    roles: np.ndarray
    #: (R, 2) int: segment pairs (upper, lower): the first rests on (or leans against) the second
    rests_on: np.ndarray
    #: planes of the segments (`fit_planes`), for the supports' normals and extents
    planes: Planes


def segment_roles(labels: np.ndarray, positions: np.ndarray, edges: np.ndarray,
                  concave: np.ndarray, is_support: np.ndarray, at_view_edge: np.ndarray | None,
                  *, max_object_extent_m: float, min_object_extent_m: float,
                  min_object_nodes: int) -> SegmentRoles:
    """Role of every segment (module docstring).

    labels: (n,) segment of each node (-1 none); positions: (n, 3) metres; edges: (E, 2)
    position edges; concave: (E,) bool, the edge is not convex (one end rises above the
    other's tangent plane); is_support: (n_segments,) bool, the segment is a support plane
    (`find_supports`); at_view_edge: (n,) bool nodes at the edge of the sensor's view (None:
    unknown). A segment rests on (or leans against) a support or a flat-topped segment when a
    concave edge joins them and it lies on that plane's sensor side.
    """
    n_segments = int(labels.max()) + 1 if labels.size else 0
    roles = np.full(n_segments, OBJECT, dtype=np.int8)
    planes = fit_planes(positions, labels, n_segments)
    if n_segments == 0:
        return SegmentRoles(roles, np.zeros((0, 2), dtype=np.int64), planes)
    roles[is_support[:n_segments]] = SUPPORT
    member = labels >= 0
    limit = np.maximum(INLIER_SIGMAS * planes.sigma, 1e-9)
    off = np.abs(planes.distances(positions[member], labels[member])) > limit[labels[member]]
    flat = (planes.count >= 3) & (np.bincount(labels[member][off], minlength=n_segments)
                                  < 0.1 * planes.count)
    # who rests on whom: concave edges between segments, the upper one on the plane's side ...
    a, b = labels[edges[:, 0]], labels[edges[:, 1]]
    touching = (a >= 0) & (b >= 0) & (a != b)
    between = touching & concave
    upper = np.concatenate([a[between], b[between]])
    lower = np.concatenate([b[between], a[between]])
    height = np.einsum("ij,ij->i", planes.centroid[upper] - planes.centroid[lower],
                       planes.normal[lower])
    # ... and over it: the upper one's centre within the lower one's extent along its plane
    along = np.abs(np.einsum("ikj,ij->ik", planes.axes[lower],
                             planes.centroid[upper] - planes.centroid[lower]))
    over = (along <= 0.5 * planes.extent[lower]).all(axis=1)
    resting = (flat | (roles == SUPPORT))[lower] & (height > limit[lower]) & over & (
        roles[upper] != SUPPORT)
    pairs = np.unique(np.stack([upper[resting], lower[resting]], axis=1), axis=0)
    too_large = planes.extent[:, 0] > max_object_extent_m
    too_small = (planes.count < min_object_nodes) | (planes.extent[:, 1] < min_object_extent_m)
    partial = np.zeros(n_segments, dtype=bool)
    if at_view_edge is not None:
        partial[np.unique(labels[member & at_view_edge])] = True
    # a support plane seen whole, no larger than an object, that nothing rests on is a large
    # flat object (a laptop's lid, a tray): its role is judged as any other segment's
    carries = np.zeros(n_segments, dtype=bool)
    carries[pairs[:, 1]] = True
    roles[(roles == SUPPORT) & ~(carries | partial | too_large)] = OBJECT
    structure = (roles != SUPPORT) & (too_large | partial)
    # a segment bordering mostly on such background structure is a piece of it (a key of a
    # keyboard cut by the view's edge): judged until nothing changes; small bits do not count
    structure = _spread(structure, ~too_small & (roles != SUPPORT), a[touching], b[touching])
    roles[(roles != SUPPORT) & (structure | too_small)] = CLUTTER
    return SegmentRoles(roles, pairs, planes)


def _spread(marked: np.ndarray, eligible: np.ndarray, a: np.ndarray,
            b: np.ndarray) -> np.ndarray:
    """(K,) bool: ``marked`` segments, and every ``eligible`` one whose edges (a[k], b[k]) to
    other non-small segments mostly reach marked ones, repeated until none is added."""
    marked = marked.copy()
    source = np.concatenate([a, b])
    target = np.concatenate([b, a])
    counted = eligible[target] | marked[target]
    border = np.bincount(source[counted], minlength=marked.size)
    while True:
        on_marked = np.bincount(source[marked[target]], minlength=marked.size)
        turning = eligible & ~marked & (2 * on_marked > border)
        if not turning.any():
            return marked
        marked[turning] = True
