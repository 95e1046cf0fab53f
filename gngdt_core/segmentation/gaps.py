"""Step 6 of `gngdt.core.segmentation.network.segment_network`: segments joined across gaps of
missing depth.

Where the sensor measured no depth (a glossy rim, a dark or shiny patch) the network has no
edges, so one object can come out as two segments (a mug's inside and outside). Node pairs of
two segments closer than the bridge are judged as edges would be where their straight line
crosses a gap; rims (back to back pairs) and openings (one segment seen through the other's)
join too. A stripe of missing depth narrower than the view's cells shows only in the network
(a band without nodes): pairs of the network's border nodes across such a band are judged as
well (``network_gap_m``), by convex share only. The procedure is written out in
`gngdt.core.segmentation.network`'s docstring, step 6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gngdt.core.clustering import rank_by_size
from gngdt.core.kernels import gaps as GK
from gngdt.core.kernels import regions as RK
from gngdt.core.sensor.view import SensorView

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
#: into pieces); chosen on ycbv's mug (0.912 -> 0.941 learned from scratch, 0.879 -> 0.912
#: streamed, seed-0 networks); at 0.7 the gelatin box joined the mug in one streamed frame
ENCLOSED_SHARE = 0.8
#: ... and joins each segment that this share of those nodes face (the rim's pieces, the wall
#: below it), not just the one most face: set to RIM_SHARE before measuring; ycbv from scratch
#: 0.917 -> 0.930 (5 seeds, cached networks), mosd unchanged
ENCLOSING_SHARE = 0.2
#: ... from at least this many distinct nodes on each side: pairs fanning out of one node are one
#: node's word (a streamed ycbv network tied the foam brick to the mug by three pairs from one
#: node; 2, the fewest that is not one node: ycbv streamed merged 0.4 -> 0 per seed, 3 split mugs)
GAP_MIN_NODES = 2
#: network gaps (``network_gap_m``): a node is at the network's border when the unit vectors
#: to its neighbours sum to more than this share of its degree (its neighbours lie mostly on one
#: side; inside a surface they cancel out: median 0.2, p90 0.46 on a damaged mosd frame) ...
BORDER_RESULTANT = 0.3
#: ... and a pair of such nodes spans a region the network left empty when no neighbour of
#: either end lies nearer the middle between them than this share of half their distance
EMPTY_SHARE = 0.8


@dataclass(frozen=True)
class GapRules:
    """What step 6 takes from `SegmentationParams` (see its fields)."""

    #: metres: node pairs at most this far apart are judged (``bridge_gap_m``)
    gap_m: float
    #: pairs needed between two segments (``min_boundary_edges``)
    min_pairs: int
    convex_share: float
    crease_share: float
    #: sines of ``concavity_angle_deg`` and ``crease_angle_deg``
    concavity_sine: float
    crease_sine: float
    #: metres: node pairs at most this far apart across a region the network left empty are
    #: judged too (``network_gap_m``; 0: only gaps the view shows)
    network_gap_m: float = 0.0


def bridge_gaps(labels: np.ndarray, positions: np.ndarray, normals: np.ndarray,
                edges: np.ndarray, view: SensorView, camera_from_model: np.ndarray,
                support_node: np.ndarray, rules: GapRules) -> np.ndarray:
    """(n,) int32 segments after step 6: segments joined across gaps of missing depth; nothing
    joins a support.

    labels: (n,) segment of each node (-1 none); positions, normals: (n, 3) float64, metres and
    unit normals facing the sensor; edges: (E, 2) position edges (segment pairs sharing
    ``rules.min_pairs`` of them were judged in step 4 and are left as they are); view: what the
    sensor measured in the frame; camera_from_model: (4, 4); support_node: (n,) bool nodes on
    a support plane."""
    pairs, pair_key, over_gap, network = _pairs_across_gaps(labels, positions, edges, rules,
                                                            view, camera_from_model,
                                                            support_node)
    if len(pairs) == 0:
        return labels
    n_labels = int(labels.max()) + 1
    rise = np.maximum(*RK.edge_rises(positions, normals, pairs))
    convex = rise < rules.concavity_sine
    # the two faces of a thin wall (a mug's rim: its outside and its inside) face away from
    # each other and meet convexly; two objects facing each other across a gap meet concavely
    opposed = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) < 0.0
    keys, pair_of_key = np.unique(pair_key, return_inverse=True)

    def count(flags: np.ndarray) -> np.ndarray:
        return np.bincount(pair_of_key, weights=flags, minlength=len(keys))

    def enough(among: np.ndarray) -> np.ndarray:
        nodes = _nodes_per_side(labels, pairs[among], pair_of_key[among], keys, n_labels)
        return (count(among) >= rules.min_pairs) & (nodes >= GAP_MIN_NODES)

    crossing, convex_count = count(over_gap), count(over_gap & convex)
    # rims and openings only where the sensor measured the gap: a gap only the network shows
    # may be a container's mouth whose rim returned depth (mOSD labels inside and outside apart)
    sensed = over_gap & ~network
    back_to_back = count(sensed & opposed & convex)
    rim = enough(sensed) & ((back_to_back >= RIM_SHARE * count(sensed))
                            | (back_to_back >= RIM_PAIRS))
    if ENCLOSED_SHARE <= 1.0:
        # a container's inside faces its rim over the gap and behind its wall alike
        rim |= enough(~network) & _enclosed(labels, positions, pairs[~network], keys,
                                            n_labels, camera_from_model)
    # a join by convex share needs min_pairs convex pairs (3 pairs, 2 convex tied the inside
    # of mosd's bowls to their outside across the gap at their rims)
    join = rim | (enough(over_gap) & (convex_count >= rules.convex_share * crossing)
                  & (convex_count >= rules.min_pairs))
    if not join.any():
        return labels
    creases = count(over_gap & (rise > rules.crease_sine))
    root = _join_across_gaps(n_labels, keys // n_labels, keys % n_labels, crossing, creases,
                             join, rim, convex_count + back_to_back, rules.crease_share)
    merged = labels.copy()
    on = labels >= 0
    merged[on] = rank_by_size(root[labels[on]])
    return merged


def _pairs_across_gaps(labels: np.ndarray, positions: np.ndarray, edges: np.ndarray,
                       rules: GapRules, view: SensorView,
                       camera_from_model: np.ndarray, support_node: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Node pairs of two segments (neither a support, not judged in step 4) closer than
    ``rules.gap_m`` whose straight line crosses a gap: (P, 2) pairs, (P,) their segment pair
    keys (`_segment_pair_keys`), (P,) bool ``over_gap``: at least half the line lies where
    the sensor measured nothing and at most a third where it measured something else, and (P,)
    bool ``network``: the pair crosses a gap only the network shows (`_network_gap_pairs`,
    ``over_gap`` too). The others returned run partly over a gap and otherwise behind a
    nearer surface, never where the sensor saw through: from a container's inside to its rim,
    behind its wall."""
    from scipy.spatial import cKDTree

    n_labels = int(labels.max()) + 1
    on_support = np.zeros(n_labels + 1, dtype=bool)
    on_support[labels[support_node]] = True
    # segment pairs with enough shared edges were judged on those edges (step 4), per key
    edge_keys = _segment_pair_keys(labels, edges, n_labels)
    judged = np.bincount(edge_keys[edge_keys >= 0],
                         minlength=n_labels * n_labels) >= rules.min_pairs
    candidates = np.flatnonzero(
        (labels >= 0) & ~on_support[labels]
        & view.near_unmeasured(positions, camera_from_model, GAP_BORDER_M))
    pairs = np.zeros((0, 2), dtype=np.int64)
    if candidates.size >= 2:
        pairs = candidates[cKDTree(positions[candidates]).query_pairs(rules.gap_m,
                                                                      output_type="ndarray")]
    pair_key = _segment_pair_keys(labels, pairs, n_labels)
    unjudged = (pair_key >= 0) & ~judged[np.maximum(pair_key, 0)]
    pairs, pair_key = pairs[unjudged], pair_key[unjudged]
    missing, blocked, hidden = view.gap_samples(positions, pairs, camera_from_model,
                                                GAP_DEPTH_MARGIN, GAP_SAMPLES)
    over_gap = (2 * missing >= GAP_SAMPLES) & (3 * blocked <= GAP_SAMPLES)
    keep = over_gap | ((missing > 0) & (blocked == hidden))
    pairs, pair_key, over_gap = pairs[keep], pair_key[keep], over_gap[keep]
    network = np.zeros(len(pairs), dtype=bool)
    if rules.network_gap_m > 0:
        extra, extra_key = _network_gap_pairs(labels, positions, edges, on_support, view,
                                              camera_from_model, judged, rules.network_gap_m)
        new = ~np.isin(extra[:, 0] * len(labels) + extra[:, 1],
                       pairs[:, 0] * len(labels) + pairs[:, 1])
        pairs = np.concatenate([pairs, extra[new]])
        pair_key = np.concatenate([pair_key, extra_key[new]])
        over_gap = np.concatenate([over_gap, np.ones(int(new.sum()), dtype=bool)])
        network = np.concatenate([network, np.ones(int(new.sum()), dtype=bool)])
    return pairs, pair_key, over_gap, network


def _network_gap_pairs(labels: np.ndarray, positions: np.ndarray, edges: np.ndarray,
                       on_support: np.ndarray, view: SensorView, camera_from_model: np.ndarray,
                       judged: np.ndarray, reach_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Node pairs across a gap only the network shows (a stripe of missing rows narrower than
    the view's cells): (P, 2) pairs of nodes of two segments (neither a support, their pair
    not ``judged``: (n_labels ** 2,) bool per segment pair key) at the network's border
    (`kernels.gaps.border_nodes`), at most ``reach_m`` apart, with no neighbour of either end
    near the middle between them (`kernels.gaps.empty_between`) and nothing else measured
    along the line (the sensor neither saw through it nor saw a nearer surface); and (P,)
    their segment pair keys."""
    offsets, neighbours, _ = RK.csr_adjacency(len(labels), edges, np.ones(len(edges),
                                                                          dtype=bool))
    nodes = np.flatnonzero((labels >= 0) & ~on_support[labels]
                           & GK.border_nodes(positions, offsets, neighbours, BORDER_RESULTANT))
    pairs = GK.close_pairs_between(positions, nodes, labels.astype(np.int64), reach_m)
    key = _segment_pair_keys(labels, pairs, int(labels.max()) + 1)
    keep = ~judged[key]
    keep[keep] = GK.empty_between(positions, offsets, neighbours, pairs[keep], EMPTY_SHARE)
    pairs, key = pairs[keep], key[keep]
    _, blocked, _ = view.gap_samples(positions, pairs, camera_from_model, GAP_DEPTH_MARGIN,
                                     GAP_SAMPLES)
    return pairs[blocked == 0], key[blocked == 0]


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
    mug's inside seen past its glossy rim, not a wall seen past an object in front of it. It
    joins each segment that ``ENCLOSING_SHARE`` of those nodes face."""
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
    borders = np.bincount(inner, minlength=n_labels)
    behind = depth[node] > depth[partner]
    # only segments that could be enclosed get a hull
    could = np.bincount(inner[behind], minlength=n_labels) >= ENCLOSED_SHARE * borders
    through = behind & could[inner]
    through[through] = _outside_hulls(image, labels, inner[through], partner[through])
    facing = np.bincount(inner[through] * n_labels + outer[through],
                         minlength=n_labels * n_labels).reshape(n_labels, n_labels)
    # the rim may be cut into several segments (and the wall below it another): what counts is
    # how much of the border faces some segment through the opening; the enclosed one joins
    # each that a good share of it faces
    faced = facing.sum(axis=1)
    enclosed = faced >= ENCLOSED_SHARE * np.maximum(borders, 1)
    enclosing = facing >= ENCLOSING_SHARE * np.maximum(faced, 1)[:, None]
    low, high = keys // n_labels, keys % n_labels
    return ((enclosed[low] & enclosing[low, high]) | (enclosed[high] & enclosing[high, low]))


def _outside_hulls(image: np.ndarray, labels: np.ndarray, segments: np.ndarray,
                   points: np.ndarray) -> np.ndarray:
    """(P,) bool: node ``points[k]`` lies outside the convex hull of segment ``segments[k]`` on
    the image (``image``: (n, 2) x/z, y/z of every node). A hull, not the distance from the
    segment's centre: an opening seen at a slant is a wide ellipse, and a rim node past its
    narrow end can be nearer the centre than the inside's node it faces (ycbv's mug)."""
    outside = np.zeros(len(points), dtype=bool)
    by_segment = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[by_segment], np.arange(int(labels.max()) + 2))
    for segment in np.unique(segments):
        asked = segments == segment
        members = image[by_segment[starts[segment]:starts[segment + 1]]]
        outside[asked] = RK.outside_convex_hull(members, image[points[asked]])
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
    order = np.flatnonzero(joinable)[np.argsort(-strength[joinable], kind="stable")]
    return GK.join_across_gaps(n_labels, low.astype(np.int64), high.astype(np.int64),
                               crossing.astype(np.float64), creases.astype(np.float64),
                               order.astype(np.int64), rim, crease_share)


def _segment_pair_keys(labels: np.ndarray, pairs: np.ndarray, n_labels: int) -> np.ndarray:
    """(P,) int64 key ``low * n_labels + high`` of the segments at the ends of each node pair;
    -1 where both ends are in one segment (or either in none)."""
    a = labels[pairs[:, 0]].astype(np.int64)
    b = labels[pairs[:, 1]].astype(np.int64)
    key = np.minimum(a, b) * n_labels + np.maximum(a, b)
    return np.where((a != b) & (a >= 0) & (b >= 0), key, -1)
