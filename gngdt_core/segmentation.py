"""Segments a robot can use, from a GNG-DT network: one per object, support surfaces apart.

The procedure works on what GNG-DT learns — node positions, surface normals (eq. 16) and the
position topology — and adds one more topology, **local convexity** (after LCCP, Stein et al.,
CVPR 2014, and CPC, Schoeler et al., CVPR 2015, whose supervoxel adjacency graph is what the
position topology is here):

1. Elevations. For a position edge (i, j) with unit direction d from i to j, the *elevation of j
   seen from i* is ``asin(n_i . d)``: how far j rises above i's tangent plane (normals face the
   sensor). Both ends below each other's tangent planes is a convex fold (a box's ridge), both
   near zero is flat, and one end above the other's plane is a concave fold (an object standing
   on a table, two boxes touching) or a step (one surface in front of another).
2. Smooth patches. Region growing over *smooth* edges (both elevations within
   ``smooth_angle_deg``), where a node joins a patch only while its normal stays within
   ``patch_angle_deg`` of the patch's mean normal, so slow drift (a rounded corner, a chain of
   straddling nodes at a crease) cannot carry a patch from a table onto an object.
2b. Supports (`gngdt_core.supports.find_supports`). A patch of at least ``min_plane_nodes``
   nodes that is a plane (90 % of its nodes within ``plane_sigmas`` robust standard deviations
   of its own noise, and ``min_plane_offset_m``) at least ``support_min_extent_m`` wide both
   ways is a support: a table, a floor, a wall, a shelf's floor or side; any number, any
   orientation. It takes exactly the nodes on its plane connected to it; nodes off the plane
   leave (a case lying flat, 1-2 cm high, that the table's patch grew over), and nothing joins
   a support in step 4: an object resting on or leaning against it stays apart.
3. Convexity topology. An edge is *convex* when neither end rises above the other's tangent
   plane by more than ``concavity_angle_deg`` (flat and convex folds; concave folds and steps
   are cut). These edges are the network's local-convexity topology (``convex_edges``).
4. Objects. Adjacent patches join, surest first (fewest creases, then the most convex
   boundary, then the longest), when at least ``min_boundary_edges`` position edges lie
   between them, ``convex_share`` of those are convex (or none of the pairs below is a crease:
   a smooth continuation, such as the two halves of a small mug whose noisy normals make some
   edges look slightly concave), and at most ``crease_share`` of the node pairs between them
   (edges and two-edge paths) are *creases*: one end rises above the other's tangent plane
   by more than ``crease_angle_deg``, a sharp concave fold or a step, where a curved surface
   (a bowl's inside) bends far less over two edges. After each join the union's boundary with every
   neighbour is judged as a whole (the counts are summed), so a chain of small patches along a
   crease — straddling nodes, the thin side of a box lying on another — cannot carry one object
   into another or into its support: once the union holds both, the creases between them
   count. (After LCCP's merging of convex-connected supervoxels, with CPC's idea of judging the
   union of segments rather than single adjacencies.)
5. Fragments. Segments of fewer than ``min_segment_nodes`` nodes (typically single nodes that
   straddle a crease) join the adjacent larger segment they share most convex edges with; they
   never bridge two larger segments. Those with no larger neighbour (chains of single nodes
   along cables, thin edges, noise) are no segment (-1).

6. Gaps (with the frame's view only, ``bridge_gap_m`` > 0). Where the sensor measured no depth
   (a glossy rim, a dark or shiny patch) the network has no edges, so one object can come out as
   two segments (a mug's inside and outside). Node pairs of two segments closer than
   ``bridge_gap_m`` are judged as edges would be, when the straight line between them crosses
   a gap: at least half of it lies where the sensor measured nothing and at most a third where
   it measured something else (saw through the line, or a nearer surface in front of it). The
   segments join when at least ``min_boundary_edges`` such pairs cross between them, from at
   least ``GAP_MIN_NODES`` distinct nodes on each side, and ``convex_share`` of those are
   convex, or ``RIM_SHARE`` of them (or ``RIM_PAIRS``) are *back
   to back*: convex with normals facing away from each other, the two faces of a thin wall at
   a rim (two objects facing each other across a gap meet concavely) — or one is seen through
   an opening of the other: ``ENCLOSED_SHARE`` of its nodes across a gap face their nearest
   nodes there from behind them and from inside them on the image (outside its convex hull:
   a mug's inside past its glossy rim, the rim perhaps cut into pieces), and most of them face
   the other; here a line that runs partly over the gap and otherwise behind a nearer surface
   (from the inside to the rim, behind the container's wall) counts too. Such rim
   joins hold whatever creases the container's mouth adds; other joins go surest first and
   only while at most ``crease_share`` of the crossing pairs between the two growing unions
   are creases. Segments that already share ``min_boundary_edges`` position
   edges were judged in step 4 and are left as they are.
7. Roles (on demand: `Segmentation.roles`, `Segmentation.object_labels`;
   `gngdt_core.supports.segment_roles`): each segment is a support (step 2b), clutter
   (background structure reaching the edge of the view or longer than ``max_object_extent_m``,
   and what borders mostly on it; bits narrower than ``min_object_extent_m`` or of fewer than
   ``min_object_nodes`` nodes) or an object; who rests on whom is recorded.

Labels are ordered by decreasing segment size; -1 is no segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from gngdt_core.clustering import rank_by_size
from gngdt_core.kernels import regions as RK
from gngdt_core.parameters import Interval, check_fields, from_mapping, param
from gngdt_core.supports import OBJECT, SegmentRoles, find_supports, segment_roles
from gngdt_core.view import SensorView

#: points judged along a node pair that may cross a gap of missing depth (step 6)
GAP_SAMPLES = 6
#: metres: a node borders a gap when the sensor measured no depth this close to it
GAP_BORDER_M = 0.005
#: a sample lies on something the sensor measured when within this share of its depth
GAP_DEPTH_MARGIN = 0.02
#: segments across a gap also join when this share of the pairs crossing it (or this many) are
#: back to back: convex with normals facing away from each other, the two faces of a thin wall
#: at a rim; a container's mouth adds many concave pairs (its far inner wall seen past the near
#: rim), which outvote them under the convex share (ycbv's mug: 0.889 -> 0.921 learned from
#: scratch, 0.820 -> 0.867 streamed; no effect on mosd, whose rims return depth)
RIM_SHARE = 0.2
RIM_PAIRS = 5
#: a segment this share of whose nodes across gaps face others from behind and from inside them
#: on the image is seen through an opening (a mug's inside past its glossy rim, which may be cut
#: into pieces) and joins the segment it faces most; chosen on ycbv's mug (0.912 -> 0.941
#: learned from scratch, 0.879 -> 0.912 streamed, seed-0 networks); at 0.7 the gelatin box
#: joined the mug in one streamed frame
ENCLOSED_SHARE = 0.8
#: ... from at least this many distinct nodes on each side: pairs fanning out of one node are one
#: node's word (a streamed ycbv network tied the foam brick to the mug by three pairs from one
#: node; 2, the fewest that is not one node: ycbv streamed merged 0.4 -> 0 per seed, 3 split mugs)
GAP_MIN_NODES = 2
#: an edge longer than this many times the shortest edge at either end is left out (1-2 % of
#: the edges of a learned network; a streamed ycbv network tied the gelatin box to the foam
#: brick by one 7.4 cm edge between nodes 5-8 mm from their neighbours)
LONG_EDGE_RATIO = 6.0
#: cells of the view (`SensorView`) from its bounds within which a node is at the view's edge
VIEW_EDGE_CELLS = 2


@dataclass(frozen=True)
class SegmentationParams:
    """Parameters of `segment_network`, validated on construction (angles in degrees)."""

    smooth_angle_deg: float = param(8.0, Interval(float, 0.0, 90.0, closed="right"),
                                    "an edge is smooth (inside a patch) when both elevations "
                                    "are within this angle")
    patch_angle_deg: float = param(30.0, Interval(float, 0.0, 90.0, closed="right"),
                                   "a node joins a patch only while its normal is within this "
                                   "angle of the patch's mean")
    concavity_angle_deg: float = param(10.0, Interval(float, 0.0, 90.0, closed="right"),
                                       "an edge is convex unless one end rises above the "
                                       "other's tangent plane by more than this")
    convex_share: float = param(0.5, Interval(float, 0.0, 1.0),
                                "adjacent patches merge when this share of their boundary "
                                "edges is convex ...")
    min_boundary_edges: int = param(3, Interval(int, 1),
                                    "... and the boundary has at least this many edges ...")
    crease_share: float = param(0.15, Interval(float, 0.0, 1.0),
                                "... and at most this share of the node pairs between them "
                                "(edges and two-edge paths) are creases")
    crease_angle_deg: float = param(25.0, Interval(float, 0.0, 90.0, closed="right"),
                                    "a node pair is a crease when one end rises above the "
                                    "other's tangent plane by more than this (a sharp concave "
                                    "fold or a step; a curved surface bends far less over two "
                                    "edges)")
    min_segment_nodes: int = param(4, Interval(int, 1),
                                   "segments smaller than this join a larger neighbour, or are "
                                   "no segment (-1)")
    min_plane_nodes: int = param(20, Interval(int, 3),
                                 "supports (step 2b): a smooth patch of at least this many "
                                 "nodes ...")
    plane_sigmas: float = param(3.0, Interval(float, 0.0, closed="neither"),
                                "... 90 % of them within this many robust standard deviations "
                                "of its own noise ...")
    min_plane_offset_m: float = param(0.003, Interval(float, 0.0),
                                      "... (and at least this many metres) of its plane ...")
    support_min_extent_m: float = param(0.25, Interval(float, 0.0),
                                        "... at least this many metres wide both ways")
    min_object_height_m: float = param(0.008, Interval(float, 0.0),
                                       "metres: nodes off a support's plane leave it only where "
                                       "they rise this high above it somewhere (lower: the "
                                       "plane's warp); lower objects are told from it by colour "
                                       "only")
    max_object_extent_m: float = param(0.5, Interval(float, 0.0, closed="neither"),
                                       "roles: a segment longer than this (metres) or reaching "
                                       "the edge of the view, or bordering mostly on such, is "
                                       "clutter ...")
    min_object_extent_m: float = param(0.02, Interval(float, 0.0),
                                       "... and so is one narrower than this (metres) ...")
    min_object_nodes: int = param(8, Interval(int, 1),
                                  "... or of fewer nodes than this; any other is an object")
    bridge_gap_m: float = param(0.0, Interval(float, 0.0, 1.0),
                                "metres: segments apart by a gap of missing depth at most this "
                                "wide join where the two sides meet convexly (step 6; needs the "
                                "frame's view); 0: no bridging")

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def from_dict(cls, values: dict) -> SegmentationParams:
        """From a mapping (e.g. a TOML table); ValueError naming an unknown key."""
        return from_mapping(cls, values, "segmentation parameter")


@dataclass(frozen=True)
class Segmentation:
    """Result of `segment_network` for a network of n nodes and E position edges."""

    #: (n,) int32 segment of each node, 0..n_segments-1 by decreasing size, -1 = none
    labels: np.ndarray
    #: (n,) int32 smooth patch of each node (step 2)
    patches: np.ndarray
    #: (E,) bool, per position edge: convex or flat (the local-convexity topology)
    convex: np.ndarray
    #: what the roles are judged from (filled by `segment_network`; None: every segment is an
    #: object)
    context: _RoleContext | None = field(default=None, repr=False, compare=False)

    @property
    def n_segments(self) -> int:
        return int(self.labels.max()) + 1 if self.labels.size else 0

    @cached_property
    def role_details(self) -> SegmentRoles:
        """Roles of the segments, who rests on whom, their planes (`gngdt_core.supports`);
        judged on first use."""
        context = self.context
        if context is None:
            return segment_roles(self.labels, np.zeros((self.labels.size, 3)),
                                 np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=bool),
                                 np.zeros(self.n_segments, dtype=bool), None,
                                 **_role_arguments(SegmentationParams()))
        is_support = np.zeros(self.n_segments, dtype=bool)
        on = self.labels >= 0
        is_support[self.labels[on & context.support_node]] = True
        return segment_roles(self.labels, context.positions, context.edges, context.concave,
                             is_support, context.at_view_edge, **_role_arguments(context.params))

    @property
    def roles(self) -> np.ndarray:
        """(n_segments,) int8 role of each segment: `supports.OBJECT`, `supports.SUPPORT`
        (a table, floor, wall or shelf something rests on) or `supports.CLUTTER`."""
        return self.role_details.roles

    def object_labels(self) -> np.ndarray:
        """(n,) int32 ``labels`` with every segment that is not an object (supports, clutter)
        set to -1: for consumers that want the objects only."""
        keep = np.concatenate([self.roles == OBJECT, [False]])
        return np.where(keep[self.labels], self.labels, -1).astype(np.int32)


@dataclass(frozen=True)
class _RoleContext:
    """The network a `Segmentation` was made from, for its roles."""

    positions: np.ndarray
    #: (E', 2) the position edges segmented (long ones left out) and (E',) which are concave
    edges: np.ndarray
    concave: np.ndarray
    #: (n,) bool: the node is on a support plane (step 2b)
    support_node: np.ndarray
    at_view_edge: np.ndarray | None
    params: SegmentationParams


def _role_arguments(params: SegmentationParams) -> dict:
    return {"max_object_extent_m": params.max_object_extent_m,
            "min_object_extent_m": params.min_object_extent_m,
            "min_object_nodes": params.min_object_nodes}


def edge_elevations(positions: np.ndarray, normals: np.ndarray,
                    edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sines of the elevations of each edge's ends: (E,) ``n_i . d`` and ``-n_j . d``.

    positions: (n, 3) metres; normals: (n, 3) unit, facing the sensor (zero where undefined:
    elevation 0); edges: (E, 2) node pairs (i, j); d: unit vector from i to j. The first is how
    far j rises above i's tangent plane, the second how far i rises above j's.
    """
    return RK.edge_rises(np.asarray(positions, dtype=np.float64),
                         np.asarray(normals, dtype=np.float64),
                         np.asarray(edges, dtype=np.int64).reshape(-1, 2))


def segment_network(positions: np.ndarray, normals: np.ndarray, edges: np.ndarray,
                    params: SegmentationParams | None = None, view: SensorView | None = None,
                    camera_from_model: np.ndarray | None = None,
                    colors: np.ndarray | None = None) -> Segmentation:
    """Segments of a network (see the module docstring for the procedure).

    positions: (n, 3) float, metres; normals: (n, 3) float unit normals facing the sensor (zero
    where undefined); edges: (E, 2) int position-topology node pairs. view: what the sensor
    measured in the frame just learned (`SensorView.of` its points in the camera frame), for
    step 6; camera_from_model: (4, 4) from the network's frame to that camera's (None: the
    same frame). colors: (n, 3) RGB of the nodes (0-255), for step 2b's colour evidence (None:
    geometry only; `GNGDT.segmentation` does not pass them yet).
    """
    params = params or SegmentationParams()
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    n = positions.shape[0]
    if positions.shape != (n, 3) or normals.shape != (n, 3):
        raise ValueError(f"positions and normals must be (n, 3), got {positions.shape} and "
                         f"{normals.shape}")
    if n == 0:
        empty = np.zeros(0, dtype=np.int32)
        return Segmentation(empty, empty, np.zeros(len(edges), dtype=bool))
    # long edges span free space between two surfaces (stale in a streamed network): no
    # adjacency, and not in the convexity topology
    spanning = RK.long_edges(n, positions, edges, LONG_EDGE_RATIO)
    all_edges, edges = edges, edges[~spanning]
    rise_of_j, rise_of_i = edge_elevations(positions, normals, edges)
    smooth = np.maximum(np.abs(rise_of_j), np.abs(rise_of_i)) < _sine(params.smooth_angle_deg)
    concavity = np.maximum(rise_of_j, rise_of_i)
    convex = concavity < _sine(params.concavity_angle_deg)
    adjacency = _adjacency(n, edges, smooth)
    patches = _smooth_patches(n, edges, adjacency, normals, rise_of_j, rise_of_i,
                              math.cos(math.radians(params.patch_angle_deg)))
    camera_from_model = np.eye(4) if camera_from_model is None else camera_from_model
    depths = positions @ camera_from_model[2, :3] + camera_from_model[2, 3]
    # a support grows over every edge, long ones too: a sparse table's far nodes are on its plane
    supports = find_supports(patches, positions, normals,
                             _adjacency(n, all_edges, np.ones(len(all_edges), dtype=bool)),
                             depths=depths,
                             min_nodes=params.min_plane_nodes,
                             min_extent_m=params.support_min_extent_m,
                             plane_sigmas=params.plane_sigmas,
                             min_offset_m=params.min_plane_offset_m,
                             min_height_m=params.min_object_height_m,
                             cos_normal=math.cos(math.radians(params.patch_angle_deg)),
                             colors=colors)
    patches = supports.patches
    support_node = supports.is_support[patches]
    objects = _join_patches(patches, adjacency, positions, normals, params, supports.is_support)
    labels = rank_by_size(_absorb_fragments(objects, edges, convex, params.min_segment_nodes),
                          params.min_segment_nodes)
    if view is not None and params.bridge_gap_m > 0 and labels.max() > 0:
        labels = _bridge_gaps(labels, positions, normals, edges, params, view, camera_from_model,
                              support_node)
    at_view_edge = None if view is None else _at_view_edge(positions, view, camera_from_model)
    convex_all = np.zeros(len(all_edges), dtype=bool)
    convex_all[~spanning] = convex
    return Segmentation(labels, patches, convex_all,
                        _RoleContext(positions, edges, ~convex, support_node, at_view_edge,
                                     params))


def _at_view_edge(positions: np.ndarray, view: SensorView,
                  camera_from_model: np.ndarray) -> np.ndarray:
    """(n,) bool: nodes that project within ``VIEW_EDGE_CELLS`` cells of the view's bounds (or
    outside them, or behind the camera): what they belong to was seen only in part."""
    camera = positions @ camera_from_model[:3, :3].T + camera_from_model[:3, 3]
    z = camera[:, 2]
    ahead = z > 0
    safe = np.where(ahead, z, 1.0)
    rows, columns = view.zmax.shape
    u = (camera[:, 0] / safe - view.u_min) * view.inv_cell
    v = (camera[:, 1] / safe - view.v_min) * view.inv_cell
    margin = VIEW_EDGE_CELLS
    inside = (u >= margin) & (u <= columns - margin) & (v >= margin) & (v <= rows - margin)
    return ~(ahead & inside)


def _sine(degrees: float) -> float:
    return math.sin(math.radians(degrees))


def _smooth_patches(n: int, edges: np.ndarray, adjacency: tuple, normals: np.ndarray,
                    rise_of_j: np.ndarray, rise_of_i: np.ndarray, cos_patch: float) -> np.ndarray:
    """(n,) int32 patch of each node: region growing over smooth edges (``adjacency``'s flags),
    flattest seeds first."""
    steepest = np.maximum(np.abs(rise_of_j), np.abs(rise_of_i))
    seeds = np.argsort(RK.node_roughness(n, edges, steepest), kind="stable")
    offsets, neighbours, usable = adjacency
    return RK.grow_patches(n, offsets, neighbours, usable, normals, seeds, cos_patch)


def _adjacency(n: int, edges: np.ndarray,
               flags: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR adjacency of an undirected edge list: offsets (n+1,), neighbours and their flags."""
    return RK.csr_adjacency(n, edges, flags)


def _join_patches(patches: np.ndarray, adjacency: tuple, positions: np.ndarray,
                  normals: np.ndarray, params: SegmentationParams,
                  fixed: np.ndarray | None = None) -> np.ndarray:
    """(n,) segment of each node: patches joined, best first, while the boundary between the
    two growing unions is mostly convex and free of creases (`kernels.regions.join_regions`).

    fixed: (n_patches,) bool patches that join nothing (support surfaces)."""
    n_patches = int(patches.max()) + 1
    offsets, neighbours, _ = adjacency
    low, high, flags = RK.boundary_pairs(patches, offsets, neighbours, positions, normals,
                                         _sine(params.concavity_angle_deg),
                                         _sine(params.crease_angle_deg))
    pair_low, pair_high, counts = RK.pair_statistics(n_patches, low, high, flags)
    if fixed is None:
        fixed = np.zeros(n_patches, dtype=bool)
    root = RK.join_regions(n_patches, pair_low, pair_high, counts, fixed,
                           params.min_boundary_edges, params.convex_share, params.crease_share)
    return root[patches]


def _absorb_fragments(labels: np.ndarray, edges: np.ndarray, convex: np.ndarray,
                      min_nodes: int) -> np.ndarray:
    """Segments below ``min_nodes`` nodes join the adjacent larger segment with the most convex
    edges to them (then the most edges). Only small-to-large moves, so nothing bridges."""
    n_labels = int(labels.max()) + 1
    small = np.bincount(labels, minlength=n_labels) < min_nodes
    a, b = labels[edges[:, 0]], labels[edges[:, 1]]
    source = np.concatenate([a, b])
    target = np.concatenate([b, a])
    edge_convex = np.concatenate([convex, convex])
    moving = small[source] & ~small[target]
    if not moving.any():
        return labels
    pair = source[moving].astype(np.int64) * n_labels + target[moving]
    pairs, pair_of_edge = np.unique(pair, return_inverse=True)
    score = (np.bincount(pair_of_edge, weights=edge_convex[moving]) * (len(edges) + 1)
             + np.bincount(pair_of_edge))
    fragment, host = pairs // n_labels, pairs % n_labels
    best_first = np.lexsort((-score, fragment))
    first = np.ones(best_first.size, dtype=bool)
    first[1:] = fragment[best_first][1:] != fragment[best_first][:-1]
    destination = np.arange(n_labels)
    destination[fragment[best_first][first]] = host[best_first][first]
    return destination[labels]


def _bridge_gaps(labels: np.ndarray, positions: np.ndarray, normals: np.ndarray,
                 edges: np.ndarray, params: SegmentationParams, view: SensorView,
                 camera_from_model: np.ndarray, support_node: np.ndarray) -> np.ndarray:
    """(n,) int32 segments after step 6: segments joined across gaps of missing depth; nothing
    joins a support (``support_node``: (n,) bool nodes on a support plane)."""
    pairs, pair_key, over_gap = _pairs_across_gaps(labels, positions, edges, params, view,
                                                   camera_from_model, support_node)
    if len(pairs) == 0:
        return labels
    n_labels = int(labels.max()) + 1
    rise_of_j, rise_of_i = edge_elevations(positions, normals, pairs)
    rise = np.maximum(rise_of_j, rise_of_i)
    convex = rise < _sine(params.concavity_angle_deg)
    # the two faces of a thin wall (a mug's rim: its outside and its inside) face away from
    # each other and meet convexly; two objects facing each other across a gap meet concavely
    opposed = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) < 0.0
    keys, pair_of_key = np.unique(pair_key, return_inverse=True)

    def count(flags: np.ndarray) -> np.ndarray:
        return np.bincount(pair_of_key, weights=flags, minlength=len(keys))

    def enough(among: np.ndarray) -> np.ndarray:
        nodes = _nodes_per_side(labels, pairs[among], pair_of_key[among], keys, n_labels)
        return (count(among) >= params.min_boundary_edges) & (nodes >= GAP_MIN_NODES)

    crossing, convex_count = count(over_gap), count(over_gap & convex)
    back_to_back = count(over_gap & opposed & convex)
    enough_over_gap = enough(over_gap)
    rim = enough_over_gap & ((back_to_back >= RIM_SHARE * crossing)
                             | (back_to_back >= RIM_PAIRS))
    if ENCLOSED_SHARE <= 1.0:
        # a container's inside faces its rim over the gap and behind its wall alike
        every = np.ones(len(pairs), dtype=bool)
        rim |= enough(every) & _enclosed(labels, positions, pairs, keys, n_labels,
                                         camera_from_model)
    join = rim | (enough_over_gap & (convex_count >= params.convex_share * crossing))
    if not join.any():
        return labels
    creases = count(over_gap & (rise > _sine(params.crease_angle_deg)))
    root = _join_across_gaps(n_labels, keys // n_labels, keys % n_labels, crossing, creases,
                             join, rim, convex_count + back_to_back, params.crease_share)
    merged = labels.copy()
    on = labels >= 0
    merged[on] = rank_by_size(root[labels[on]])
    return merged


def _pairs_across_gaps(labels: np.ndarray, positions: np.ndarray, edges: np.ndarray,
                       params: SegmentationParams, view: SensorView,
                       camera_from_model: np.ndarray, support_node: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node pairs of two segments (neither a support, not judged in step 4) closer than
    ``bridge_gap_m`` whose straight line crosses a gap: (P, 2) pairs, (P,) their segment pair
    keys (`_segment_pair_keys`) and (P,) bool ``over_gap``: at least half the line lies where
    the sensor measured nothing and at most a third where it measured something else. The
    others returned run partly over a gap and otherwise behind a nearer surface, never where
    the sensor saw through: from a container's inside to its rim, behind its wall."""
    from scipy.spatial import cKDTree

    none = (np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64),
            np.zeros(0, dtype=bool))
    on_support = np.zeros(int(labels.max()) + 2, dtype=bool)
    on_support[labels[support_node]] = True
    candidates = np.flatnonzero(
        (labels >= 0) & ~on_support[labels]
        & view.near_unmeasured(positions, camera_from_model, GAP_BORDER_M))
    if candidates.size < 2:
        return none
    pairs = candidates[cKDTree(positions[candidates]).query_pairs(params.bridge_gap_m,
                                                                  output_type="ndarray")]
    n_labels = int(labels.max()) + 1
    pair_key = _segment_pair_keys(labels, pairs, n_labels)
    # segment pairs with enough shared edges were judged on those edges (step 4)
    edge_keys, shared = np.unique(_segment_pair_keys(labels, edges, n_labels),
                                  return_counts=True)
    judged = edge_keys[(edge_keys >= 0) & (shared >= params.min_boundary_edges)]
    unjudged = (pair_key >= 0) & ~np.isin(pair_key, judged)
    pairs, pair_key = pairs[unjudged], pair_key[unjudged]
    missing, blocked, hidden = view.gap_samples(positions, pairs, camera_from_model,
                                                GAP_DEPTH_MARGIN, GAP_SAMPLES)
    over_gap = (2 * missing >= GAP_SAMPLES) & (3 * blocked <= GAP_SAMPLES)
    keep = over_gap | ((missing > 0) & (blocked == hidden))
    return pairs[keep], pair_key[keep], over_gap[keep]


def _nodes_per_side(labels: np.ndarray, pairs: np.ndarray, pair_of_key: np.ndarray,
                    keys: np.ndarray, n_labels: int) -> np.ndarray:
    """(K,) int per segment pair ``keys``: how many distinct nodes the pairs crossing between
    them have on the side that has fewer (pairs fanning out of one node are one node's word)."""
    node = np.concatenate([pairs[:, 0], pairs[:, 1]])
    key = np.concatenate([pair_of_key, pair_of_key]).astype(np.int64)
    on_low = (labels[node] == keys[key] // n_labels).astype(np.int64)
    side, counts = np.unique(np.unique((key * 2 + on_low) * len(labels) + node) // len(labels),
                             return_counts=True)
    per_side = np.zeros((len(keys), 2), dtype=np.int64)
    per_side[side // 2, side % 2] = counts
    return per_side.min(axis=1)


def _enclosed(labels: np.ndarray, positions: np.ndarray, pairs: np.ndarray,
              keys: np.ndarray, n_labels: int, camera_from_model: np.ndarray) -> np.ndarray:
    """(K,) bool per segment pair ``keys``: one of the two is seen through an opening of the
    other. Of its nodes with a partner across a gap (``pairs``), at least ``ENCLOSED_SHARE``
    have their nearest partner in the other, lie behind it (farther from the sensor) and inside
    it on the image (the partner outside the enclosed segment's convex hull on the image): a
    mug's inside seen past its glossy rim, not a wall seen past an object in front of it."""
    camera = positions @ camera_from_model[:3, :3].T + camera_from_model[:3, 3]
    depth = np.maximum(camera[:, 2], 1e-9)
    image = camera[:, :2] / depth[:, None]
    length = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    node = np.concatenate([pairs[:, 0], pairs[:, 1]])
    partner = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.lexsort((np.concatenate([length, length]), node))
    first = np.ones(order.size, dtype=bool)
    first[1:] = node[order][1:] != node[order][:-1]
    node, partner = node[order][first], partner[order][first]
    inner, outer = labels[node].astype(np.int64), labels[partner].astype(np.int64)
    through = (depth[node] > depth[partner]) & _outside_hulls(image, labels, inner, partner)
    facing = np.bincount(inner[through] * n_labels + outer[through],
                         minlength=n_labels * n_labels).reshape(n_labels, n_labels)
    borders = np.bincount(inner, minlength=n_labels)
    # the rim may be cut into several segments: what counts is how much of the border faces
    # some segment through the opening; the enclosed one joins the one it faces most
    enclosed = facing.sum(axis=1) >= ENCLOSED_SHARE * np.maximum(borders, 1)
    most = facing.argmax(axis=1)
    low, high = keys // n_labels, keys % n_labels
    return (enclosed[low] & (most[low] == high)) | (enclosed[high] & (most[high] == low))


def _outside_hulls(image: np.ndarray, labels: np.ndarray, segments: np.ndarray,
                   points: np.ndarray) -> np.ndarray:
    """(P,) bool: node ``points[k]`` lies outside the convex hull of segment ``segments[k]`` on
    the image (``image``: (n, 2) x/z, y/z of every node). A hull, not the distance from the
    segment's centre: an opening seen at a slant is a wide ellipse, and a rim node past its
    narrow end can be nearer the centre than the inside's node it faces (ycbv's mug)."""
    from scipy.spatial import ConvexHull

    outside = np.zeros(len(points), dtype=bool)
    for segment in np.unique(segments):
        asked = segments == segment
        members = image[labels == segment]
        if len(members) < 3:
            outside[asked] = True  # no area: nothing lies inside it
            continue
        # joggled: a segment whose nodes line up on the image still gets a (thin) hull
        facets = ConvexHull(members, qhull_options="QJ").equations
        signed = image[points[asked]] @ facets[:, :2].T + facets[:, 2]
        outside[asked] = (signed > 0.0).any(axis=1)
    return outside


def _join_across_gaps(n_labels: int, low: np.ndarray, high: np.ndarray, crossing: np.ndarray,
                      creases: np.ndarray, joinable: np.ndarray, rim: np.ndarray,
                      strength: np.ndarray, crease_share: float) -> np.ndarray:
    """(n_labels,) representative of each segment after joining the ``joinable`` segment pairs
    (low, high), strongest first, each only while at most ``crease_share`` of all the pairs
    crossing gaps between the two growing unions are creases (as step 4): a box that three
    pairs tie to a mug's inside stays apart when twenty creases tie it to the mug's outside.
    A ``rim`` pair (back to back across a thin wall) joins regardless: a container's mouth is
    full of creases between its inside and its outside."""
    parent = np.arange(n_labels)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for k in np.flatnonzero(joinable)[np.argsort(-strength[joinable], kind="stable")]:
        a, b = find(int(low[k])), find(int(high[k]))
        if a == b:
            continue
        if rim[k]:
            parent[b] = a
            continue
        root_low = np.array([find(int(x)) for x in low])
        root_high = np.array([find(int(x)) for x in high])
        between = ((root_low == a) & (root_high == b)) | ((root_low == b) & (root_high == a))
        if creases[between].sum() <= crease_share * crossing[between].sum():
            parent[b] = a
    return np.array([find(x) for x in range(n_labels)])


def _segment_pair_keys(labels: np.ndarray, pairs: np.ndarray, n_labels: int) -> np.ndarray:
    """(P,) int64 key ``low * n_labels + high`` of the segments at the ends of each node pair;
    -1 where both ends are in one segment (or either in none)."""
    a = labels[pairs[:, 0]].astype(np.int64)
    b = labels[pairs[:, 1]].astype(np.int64)
    key = np.minimum(a, b) * n_labels + np.maximum(a, b)
    return np.where((a != b) & (a >= 0) & (b >= 0), key, -1)
