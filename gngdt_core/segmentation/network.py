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
2b. Supports (`gngdt.core.segmentation.supports.find_supports`). A patch of at least
   ``min_plane_nodes`` nodes that is a plane (90 % of its nodes within ``plane_sigmas`` robust
   standard deviations of its own noise, and ``min_plane_offset_m``) at least
   ``support_min_extent_m`` wide both ways is a support: a table, a floor, a wall, a shelf's floor
   or side; any number, any orientation. It takes exactly the nodes on its plane connected to it;
   nodes off the plane leave (a case lying flat, 1-2 cm high, that the table's patch grew over), and
   nothing joins a support in step 4: an object resting on or leaning against it stays apart.
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
   never bridge two larger segments. A chain of fragments that touches one larger segment
   only hangs off it and joins it whole (mosd from scratch: objects fragmented 7.6 -> 6.8 of
   147, 5 seeds: the pixels of its nodes were no one's); in a chain between two larger
   segments (the crease between them) only the links next to one join it. The rest (fragments
   on their own, noise, the middle of a crease) are no segment (-1).
5b. Segments judged again (``rejoin_segments``). The nodes straddling a box's edge have normals
   between its faces', so each is a patch of its own with one or two edges to either face:
   step 4 could not join the faces (fewer than ``min_boundary_edges`` edges between them), and
   once step 5 gave the straddlers to one face, nothing judged the faces again. Now the
   segments are judged as the patches were in step 4 (unions, creases), with two more
   demands, because absorbed straddlers are weak evidence: at least ``min_boundary_edges`` of
   the edges between two segments are convex, from at least ``gaps.GAP_MIN_NODES`` nodes on
   each side (one node's word tied ycbv's gelatin box to the foam brick). Supports join
   nothing. mosd's tune half: objects fragmented 3.2 -> 1.0 of 79 (learned from scratch, 5
   seeds).

6. Gaps (`gngdt.core.segmentation.gaps`, whose constants are named here; with the frame's view only,
   ``bridge_gap_m`` > 0). Where the sensor measured no depth
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
   a mug's inside past its glossy rim, the rim perhaps cut into pieces), and
   ``ENCLOSING_SHARE`` of them face the other; here a line that runs partly over the gap and
   otherwise behind a nearer surface (from the inside to the rim, behind the container's wall)
   counts too. Such rim joins hold whatever creases the container's mouth adds; other joins
   go surest first, only while at most ``crease_share`` of the crossing pairs between the
   two growing unions are creases, and only with ``min_boundary_edges`` convex pairs (three
   pairs, two of them convex, tied the inside of mosd's bowls to their outside). Segments
   that already share ``min_boundary_edges`` position edges were judged in step 4 (or 5b) and
   are left as they are. A gap the view cannot show (``network_gap_m``): a stripe of missing
   rows narrower than the view's cells (about 5 pixels) leaves every cell measured, but the
   network has no nodes there and no edges across. Pairs of nodes at the network's border
   (their neighbours on one side) at most ``network_gap_m`` apart, with no neighbour of
   either near the middle between them and nothing else measured along the line (the sensor
   neither saw through it nor saw a nearer surface there), are judged as crossing a gap too,
   by convex share only: never as a rim or an opening, which a container's mouth whose rim
   returned depth would pass (mOSD labels a bowl's inside apart from its outside).

7. Roles (on demand: `Segmentation.roles`, `Segmentation.object_labels`;
   `gngdt.core.segmentation.supports.segment_roles`): each segment is a support (step 2b), clutter
   (background structure reaching the edge of the view or longer than ``max_object_extent_m``,
   and what borders mostly on it; bits narrower than ``min_object_extent_m`` or of fewer than
   ``min_object_nodes`` nodes) or an object; who rests on whom is recorded.

Labels are ordered by decreasing segment size; -1 is no segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np

from gngdt.core.clustering import rank_by_size
from gngdt.core.kernels import regions as RK
from gngdt.core.parameters import Flag, Interval, Settings, param
from gngdt.core.segmentation.gaps import GAP_MIN_NODES, GapRules, bridge_gaps
from gngdt.core.segmentation.supports import OBJECT, SegmentRoles, find_supports, segment_roles
from gngdt.core.sensor.view import SensorView

#: an edge longer than this many times the shortest edge at either end is left out (1-2 % of
#: the edges of a learned network; a streamed ycbv network tied the gelatin box to the foam
#: brick by one 7.4 cm edge between nodes 5-8 mm from their neighbours)
LONG_EDGE_RATIO = 6.0
#: cells of the view (`SensorView`) from its bounds within which a node is at the view's edge
VIEW_EDGE_CELLS = 2


@dataclass(frozen=True)
class SegmentationParams(Settings):
    """Parameters of `segment_network`, validated on construction (angles in degrees)."""

    WHAT: ClassVar[str] = "segmentation parameter"

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
                                    "... and the boundary has at least this many edges (this "
                                    "many convex ones when segments are judged again and "
                                    "across gaps) ...")
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
    rejoin_segments: bool = param(True, Flag(),
                                  "after fragments joined their segments (step 5), segments are "
                                  "judged again as patches are in step 4 (step 5b): the 1-node "
                                  "patches along a box's edge no longer keep its faces apart")
    bridge_gap_m: float = param(0.0, Interval(float, 0.0, 1.0),
                                "metres: segments apart by a gap of missing depth at most this "
                                "wide join where the two sides meet convexly (step 6; needs the "
                                "frame's view); 0: no bridging")
    network_gap_m: float = param(0.0, Interval(float, 0.0, 1.0),
                                 "metres: step 6 also judges node pairs at most this far apart "
                                 "across a region the network left empty with nothing else "
                                 "measured along them (a stripe of missing rows narrower than "
                                 "the view's cells); they join by convex share only, never as "
                                 "a rim or an opening; 0: only gaps the view shows")



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
        """Roles of the segments, who rests on whom, their planes
        (`gngdt.core.segmentation.supports`); judged on first use."""
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
    if params.rejoin_segments:
        labels = _rejoin(labels, adjacency, positions, normals, params, support_node)
    if view is not None and params.bridge_gap_m > 0 and labels.max() > 0:
        labels = bridge_gaps(labels, positions, normals, edges, view, camera_from_model,
                             support_node, _gap_rules(params))
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


def _gap_rules(params: SegmentationParams) -> GapRules:
    return GapRules(params.bridge_gap_m, params.min_boundary_edges, params.convex_share,
                    params.crease_share, _sine(params.concavity_angle_deg),
                    _sine(params.crease_angle_deg), params.network_gap_m)


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
                  fixed: np.ndarray | None = None, min_convex: int = 0,
                  min_nodes: int = 0) -> np.ndarray:
    """(n,) segment of each node: patches joined, best first, while the boundary between the
    two growing unions is mostly convex and free of creases (`kernels.regions.join_regions`).

    fixed: (n_patches,) bool patches that join nothing (support surfaces); min_convex: convex
    edges a join needs at least; min_nodes: a pair whose edges come from fewer distinct nodes
    on either side has no convex edges of its own (one node's word: it can still join as part
    of a union)."""
    n_patches = int(patches.max()) + 1
    offsets, neighbours, _ = adjacency
    low, high, flags = RK.boundary_pairs(patches, offsets, neighbours, positions, normals,
                                         _sine(params.concavity_angle_deg),
                                         _sine(params.crease_angle_deg))
    pair_low, pair_high, counts = RK.pair_statistics(n_patches, low, high, flags)
    if min_nodes > 1:
        counts[RK.nodes_per_side(patches, offsets, neighbours, pair_low, pair_high)
               < min_nodes, 1] = 0
    if fixed is None:
        fixed = np.zeros(n_patches, dtype=bool)
    rule = np.array([params.min_boundary_edges, min_convex, params.convex_share,
                     params.crease_share], dtype=np.float64)
    root = RK.join_regions(n_patches, pair_low, pair_high, counts, fixed, rule)
    return root[patches]


def _rejoin(labels: np.ndarray, adjacency: tuple, positions: np.ndarray, normals: np.ndarray,
            params: SegmentationParams, support_node: np.ndarray) -> np.ndarray:
    """(n,) segments after step 5b: step 4's joins judged again on the segments, each needing
    ``min_boundary_edges`` convex edges from ``GAP_MIN_NODES`` nodes on either side; supports
    and nodes of no segment (each a region of its own) join nothing."""
    n_labels = int(labels.max()) + 1
    none = labels < 0
    regions = labels.astype(np.int64)
    regions[none] = n_labels + np.arange(int(none.sum()))
    fixed = np.zeros(int(regions.max()) + 1, dtype=bool)
    fixed[n_labels:] = True
    fixed[regions[support_node]] = True
    joined = _join_patches(regions.astype(np.int32), adjacency, positions, normals, params, fixed,
                           params.min_boundary_edges, GAP_MIN_NODES)
    return np.where(none, -1, rank_by_size(joined)).astype(np.int32)


def _absorb_fragments(labels: np.ndarray, edges: np.ndarray, convex: np.ndarray,
                      min_nodes: int) -> np.ndarray:
    """Segments below ``min_nodes`` nodes (fragments) join a larger one, never bridging two.
    A chain of fragments (nodes straddling a crease, one node wide) that touches one larger
    segment only hangs off it and joins it whole; fragments next to several larger segments
    (the crease between them) each join the adjacent one they share the most convex edges
    with (then the most edges), and the rest of their chain is no one's
    (`kernels.regions.absorb_fragments`)."""
    if labels.size == 0:
        return labels
    small = np.bincount(labels) < min_nodes
    # only edges at a fragment can move one
    at_fragment = small[labels[edges[:, 0]]] | small[labels[edges[:, 1]]]
    return RK.absorb_fragments(labels, edges[at_fragment], convex[at_fragment], min_nodes)
