"""The segmentation rules of issue 26 on small constructed networks (no learning): several
support planes, objects resting or leaning on them, stacking, thin flat objects, fragments whose
union is convex, gaps at a rim, segment roles."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.segmentation_scenes import (
    SPACING,
    TABLE_Y,
    box,
    majority,
    network,
    rectangle,
    segment,
    table,
    table_wall_and_box,
)

from gngdt.core.segmentation.network import SegmentationParams, segment_network
from gngdt.core.segmentation.supports import CLUTTER, OBJECT, SUPPORT, fit_planes

# ------------------------------------------------------------------------- several supports


def test_a_box_leaning_against_a_wall_is_apart_from_the_wall_and_the_table() -> None:
    positions, normals, edges, part = network(table_wall_and_box(np.random.default_rng(0)))
    result = segment(positions, normals, edges)
    table_segment, table_share = majority(result.labels, part, 0)
    wall_segment, wall_share = majority(result.labels, part, 1)
    box_segment, box_share = majority(result.labels, part, 2)
    assert len({table_segment, wall_segment, box_segment}) == 3
    assert min(table_share, wall_share, box_share) > 0.95
    # two supports of different orientation; the box is an object resting on / leaning on them
    roles = result.roles
    assert roles[table_segment] == SUPPORT and roles[wall_segment] == SUPPORT
    assert roles[box_segment] == OBJECT
    rests_on = {tuple(pair) for pair in result.role_details.rests_on.tolist()}
    assert (box_segment, table_segment) in rests_on
    assert (box_segment, wall_segment) in rests_on
    objects = result.object_labels()
    assert set(np.unique(objects)) == {-1, box_segment}


def test_a_thin_case_lying_flat_is_not_part_of_the_table() -> None:
    # a case 1 cm high whose edges slope down to the table over 6 cm (as straddling nodes
    # smooth a low edge): no edge on the way is concave enough to cut, so the table's segment
    # grows over it unless the table's plane keeps only its own nodes
    rng = np.random.default_rng(1)
    height, slope = 0.01, 0.06
    x0, x1, z0, z1 = -0.06, 0.06, 0.85, 0.91
    flat = table(rng, [(x0 - slope, x1 + slope, z0 - slope, z1 + slope)], z=(0.6, 1.2))
    top = rectangle((x0, TABLE_Y - height, z0), (x1 - x0, 0, 0), (0, 0, z1 - z0), rng)
    ramps = []
    for corner, u, v in (((x0, TABLE_Y - height, z0), (x1 - x0, 0, 0), (0, height, -slope)),
                         ((x0, TABLE_Y - height, z1), (x1 - x0, 0, 0), (0, height, slope)),
                         ((x0, TABLE_Y - height, z0), (0, 0, z1 - z0), (-slope, height, 0)),
                         ((x1, TABLE_Y - height, z0), (0, 0, z1 - z0), (slope, height, 0))):
        ramps.append(rectangle(corner, u, v, rng))
    around = np.vstack([r[0] for r in ramps]), np.vstack([r[1] for r in ramps])
    positions, normals, edges, part = network([flat, top, around])
    old = segment(positions, normals, edges, min_plane_nodes=10**9)  # no support planes
    assert majority(old.labels, part, 1)[0] == majority(old.labels, part, 0)[0]
    result = segment(positions, normals, edges)
    table_segment, table_share = majority(result.labels, part, 0)
    case_segment, case_share = majority(result.labels, part, 1)
    assert case_segment != table_segment and case_share > 0.95 and table_share > 0.95
    assert result.roles[table_segment] == SUPPORT and result.roles[case_segment] == OBJECT
    # the sloping rim goes with the case where it is more than 3 mm above the table
    rim = part == 2
    above = TABLE_Y - positions[:, 1] > 0.004
    assert np.mean(result.labels[rim & above] == case_segment) > 0.8


# -------------------------------------------------------------------- stacking and touching


def test_a_box_stacked_on_a_wider_box_is_its_own_segment() -> None:
    rng = np.random.default_rng(2)
    lower = box(rng, (-0.12, 0.12), TABLE_Y, 0.04, (0.8, 0.96))
    # the upper box stands on the lower one's top, set back 3 cm: cut it out of that top
    keep = ~((lower[0][:, 0] > -0.06) & (lower[0][:, 0] < 0.06) & (lower[0][:, 2] > 0.83)
             & (lower[0][:, 2] < 0.93) & (lower[0][:, 1] < TABLE_Y - 0.035))
    upper = box(rng, (-0.06, 0.06), TABLE_Y - 0.04, 0.05, (0.83, 0.93))
    parts = [table(rng, [(-0.12, 0.12, 0.8, 0.96)]), (lower[0][keep], lower[1][keep]), upper]
    positions, normals, edges, part = network(parts)
    result = segment(positions, normals, edges)
    segments = [majority(result.labels, part, k) for k in range(3)]
    assert len({s for s, _ in segments}) == 3 and min(share for _, share in segments) > 0.9
    roles = result.roles
    assert [roles[s] for s, _ in segments] == [SUPPORT, OBJECT, OBJECT]
    rests_on = {tuple(pair) for pair in result.role_details.rests_on.tolist()}
    assert (segments[2][0], segments[1][0]) in rests_on  # stacking: upper on lower
    assert (segments[1][0], segments[0][0]) in rests_on


def test_touching_boxes_side_by_side_are_two_and_each_box_is_one() -> None:
    # touching along x = 0; the right one taller and 3 cm deeper, so the left one's top meets
    # its side in a concave corner and the fronts make a step. (Fronts flush in one plane and
    # tops level are one smooth surface: only colour or a seam could tell them apart.)
    rng = np.random.default_rng(3)
    left = box(rng, (-0.11, 0.0), TABLE_Y, 0.10, (0.8, 0.9))
    right = box(rng, (0.0, 0.11), TABLE_Y, 0.14, (0.83, 0.93))
    # the right box's left side shows above the left box
    side = rectangle((0.0, TABLE_Y - 0.14, 0.83), (0, 0, 0.1), (0, 0.04, 0), rng)
    parts = [table(rng, [(-0.11, 0.11, 0.8, 0.93)]), (left[0], left[1]),
             (np.vstack([right[0], side[0]]), np.vstack([right[1], side[1]]))]
    positions, normals, edges, part = network(parts)
    result = segment(positions, normals, edges)
    segments = [majority(result.labels, part, k) for k in range(3)]
    assert len({s for s, _ in segments}) == 3 and min(share for _, share in segments) > 0.9


# ------------------------------------------------------------------------------ fragments


def test_a_lying_cylinder_is_one_segment() -> None:
    # a can lying on its side (radius 4 cm): its visible half is cut into several patches by
    # the patch angle, which meet convexly and join; the table stays apart
    rng = np.random.default_rng(4)
    radius, x0, x1, z_axis = 0.04, -0.1, 0.1, 0.85
    angles = np.linspace(np.pi, 2 * np.pi, 26)[1:-1]  # the upper half, y < axis
    xs = np.arange(x0, x1, SPACING)
    a, x = np.meshgrid(angles, xs)
    y = TABLE_Y - radius + radius * np.sin(a)
    z = z_axis + radius * np.cos(a)
    can = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    can_normals = np.column_stack([np.zeros(x.size), np.sin(a).ravel(), np.cos(a).ravel()])
    facing = np.einsum("ij,ij->i", can_normals, -can) > 0
    parts = [table(rng, [(x0, x1, z_axis - radius, z_axis + radius)]),
             (can[facing], can_normals[facing])]
    positions, normals, edges, part = network(parts)
    result = segment(positions, normals, edges)
    can_segment, can_share = majority(result.labels, part, 1)
    table_segment, _ = majority(result.labels, part, 0)
    assert can_share > 0.9 and can_segment != table_segment
    assert len(np.unique(result.patches[part == 1])) > 1  # several patches, one segment


def test_the_crease_check_keeps_a_chain_of_small_patches_from_joining_two_objects() -> None:
    # two boxes stacked flush (same footprint): their fronts meet flat, so only the lower
    # box's top sliver (a concave crease with the upper box's front) separates them; the
    # union check counts the creases between the two growing segments
    rng = np.random.default_rng(5)
    lower = box(rng, (-0.08, 0.08), TABLE_Y, 0.05, (0.8, 0.9))
    upper = box(rng, (-0.08, 0.08), TABLE_Y - 0.05, 0.05, (0.83, 0.9))
    parts = [table(rng, [(-0.08, 0.08, 0.8, 0.9)]), lower, upper]
    positions, normals, edges, part = network(parts)
    result = segment(positions, normals, edges)
    lower_segment, _ = majority(result.labels, part, 1)
    upper_segment, _ = majority(result.labels, part, 2)
    assert lower_segment != upper_segment


# --------------------------------------------------------------------------- roles, planes


def test_clutter_is_what_reaches_the_view_edge_is_too_long_or_too_small() -> None:
    from gngdt.core.segmentation.supports import segment_roles

    rng = np.random.default_rng(6)
    small = rectangle((0, 0, 1), (0.01, 0, 0), (0, 0.01, 0), rng, spacing=0.004)[0]
    long = rectangle((0, 0.2, 1), (0.8, 0, 0), (0, 0.05, 0), rng)[0]
    cup = rectangle((0.3, 0.3, 1), (0.06, 0, 0), (0, 0.06, 0), rng)[0]
    cut = rectangle((0.5, 0.4, 1), (0.06, 0, 0), (0, 0.06, 0), rng)[0]
    positions = np.vstack([small, long, cup, cut])
    labels = np.concatenate([np.full(len(p), k) for k, p in enumerate((small, long, cup, cut))])
    at_edge = labels == 3
    roles = segment_roles(labels, positions, np.zeros((0, 2), dtype=np.int64),
                          np.zeros(0, dtype=bool), np.zeros(4, dtype=bool), at_edge,
                          max_object_extent_m=0.5, min_object_extent_m=0.02,
                          min_object_nodes=8).roles
    assert roles.tolist() == [CLUTTER, CLUTTER, OBJECT, CLUTTER]


def test_planes_are_fitted_robustly_per_group() -> None:
    rng = np.random.default_rng(7)
    flat, _ = rectangle((-0.2, 0.3, 0.8), (0.4, 0, 0), (0, 0, 0.3), rng)
    outliers = flat[:20] + np.array([0.0, -0.05, 0.0])  # 20 nodes 5 cm above the plane
    tilted, _ = rectangle((0, 0, 1), (0.2, 0, 0.2), (0, 0.2, 0), rng)
    positions = np.vstack([flat, outliers, tilted])
    groups = np.concatenate([np.zeros(len(flat) + 20, dtype=int), np.ones(len(tilted), int)])
    planes = fit_planes(positions, groups, 2)
    assert planes.normal[0] == pytest.approx([0, -1, 0], abs=0.01)  # faces the camera
    assert abs(planes.normal[1] @ np.array([1, 0, -1]) / np.sqrt(2)) > 0.99
    assert planes.sigma[0] < 0.002  # the outliers do not count
    assert planes.extent[0] == pytest.approx([0.4, 0.3], rel=0.1)


def test_colour_tells_a_sheet_lying_flat_from_the_table_when_colours_are_given() -> None:
    # a sheet 1 mm thick: geometry cannot tell it from the table, its colour can
    rng = np.random.default_rng(8)
    flat = table(rng, [(-0.1, 0.1, 0.8, 0.95)], z=(0.6, 1.2))
    sheet = rectangle((-0.1, TABLE_Y - 0.001, 0.8), (0.2, 0, 0), (0, 0, 0.15), rng)
    positions, normals, edges, part = network([flat, sheet])
    wood = np.array([180.0, 140.0, 100.0]) + rng.normal(0.0, 8.0, (len(flat[0]), 3))
    red = np.array([200.0, 30.0, 30.0]) + rng.normal(0.0, 8.0, (len(sheet[0]), 3))
    colors = np.vstack([wood, red])
    plain = segment(positions, normals, edges)
    assert majority(plain.labels, part, 1)[0] == majority(plain.labels, part, 0)[0]
    result = segment_network(positions, normals, edges, SegmentationParams(), colors=colors)
    table_segment, table_share = majority(result.labels, part, 0)
    sheet_segment, sheet_share = majority(result.labels, part, 1)
    assert sheet_segment != table_segment and min(table_share, sheet_share) > 0.95
    assert result.roles[sheet_segment] == OBJECT


def test_a_long_stale_edge_across_free_space_does_not_join_two_objects() -> None:
    # two boxes 8 cm apart, one edge between them (a streamed network keeps such edges for a
    # while after the surfaces moved apart); every other edge is 1-1.5 cm long
    rng = np.random.default_rng(9)
    left = box(rng, (-0.14, -0.04), TABLE_Y, 0.08, (0.8, 0.9))
    right = box(rng, (0.04, 0.14), TABLE_Y, 0.08, (0.8, 0.9))
    parts = [table(rng, [(-0.14, -0.04, 0.8, 0.9), (0.04, 0.14, 0.8, 0.9)]), left, right]
    positions, normals, edges, part = network(parts)
    # the nearest pair of nodes on the two boxes' tops
    a = np.flatnonzero(part == 1)[np.argmax(positions[part == 1, 0])]
    b = np.flatnonzero(part == 2)[np.argmin(positions[part == 2, 0])]
    stale = np.vstack([edges, [[a, b]]])
    result = segment(positions, normals, stale)
    assert majority(result.labels, part, 1)[0] != majority(result.labels, part, 2)[0]
    assert not result.convex[-1]  # not in the convexity topology
    assert result.convex.shape == (len(stale),)
