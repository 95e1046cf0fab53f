"""The virtual Kinect: shapes, determinism, geometry, the depth sensor model, scene ground truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers.synthetic import segment_mask, world_points
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from gngdt.io.frame import Frame
from gngdt.io.synth.motion import Orbit
from gngdt.io.synth.primitives import Cylinder, Rectangle, Sphere, box, triangular_prism
from gngdt.io.synth.render import (
    SCENE_GROUND_TRUTH,
    SCENES,
    RayHits,
    cast_rays,
    kinect_depth,
    kinect_intrinsics,
    render_frame,
    render_scene,
)
from gngdt.io.synth.scenes import Scene, build_scene

WIDTH, HEIGHT = 160, 120


def test_frames_have_the_documented_shapes_types_and_intrinsics():
    frames = list(render_scene("tabletop", 2, width=WIDTH, height=HEIGHT, fps=10.0))
    assert [f.index for f in frames] == [0, 1]
    assert frames[1].timestamp_ns - frames[0].timestamp_ns == 100_000_000
    for frame in frames:
        assert frame.color.shape == (HEIGHT, WIDTH, 3) and frame.color.dtype == np.uint8
        assert frame.depth.shape == (HEIGHT, WIDTH) and frame.depth.dtype == np.uint16
        assert frame.labels.shape == (HEIGHT, WIDTH) and frame.labels.dtype == np.uint16
        k = frame.intrinsics
        assert (k.width, k.height) == (WIDTH, HEIGHT)
        assert k.fx == k.fy == pytest.approx(525.0 * WIDTH / 640)
        assert (k.cx, k.cy) == pytest.approx(((WIDTH - 1) / 2, (HEIGHT - 1) / 2))
        pose = frame.pose.matrix
        assert pose.shape == (4, 4)
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-12)
        assert np.linalg.det(pose[:3, :3]) == pytest.approx(1.0)
        # every label names a segment; holes carry no label
        assert set(np.unique(frame.labels)) - {0} <= set(frame.extras["segments"])
        assert not np.any(frame.labels[frame.depth == 0])
        assert np.count_nonzero(frame.depth) > 0.8 * frame.depth.size


def test_defaults_are_kinect_vga():
    frame = next(iter(render_scene("data2", 1)))
    assert frame.depth.shape == (480, 640)
    assert frame.intrinsics.fx == 525.0


def test_same_seed_same_frames_other_seed_other_noise():
    def render(seed: int) -> list[Frame]:
        return list(render_scene("data2", 3, width=WIDTH, height=HEIGHT, seed=seed))

    first, again, other = render(7), render(7), render(8)
    for a, b, c in zip(first, again, other, strict=True):
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.labels, b.labels)
        assert not np.array_equal(a.depth, c.depth)  # noise differs ...
        np.testing.assert_array_equal(a.pose.matrix, c.pose.matrix)
        valid = (a.depth > 0) & (c.depth > 0)
        # ... but the geometry does not: a few mm apart at ~1.3 m
        difference = np.abs(a.depth[valid].astype(int) - c.depth[valid].astype(int))
        assert np.median(difference) <= 10


def test_a_frame_does_not_depend_on_the_frames_before_it():
    long = list(render_scene("tabletop", 4, width=WIDTH, height=HEIGHT, seed=3))
    short = list(render_scene("tabletop", 2, width=WIDTH, height=HEIGHT, seed=3))
    for a, b in zip(short, long[:2], strict=True):
        np.testing.assert_array_equal(a.depth, b.depth)


def test_colour_noise_is_optional_seeded_and_small():
    flat = next(iter(render_scene("tabletop", 1, width=WIDTH, height=HEIGHT)))
    noisy = [
        next(iter(render_scene("tabletop", 1, width=WIDTH, height=HEIGHT, seed=s, color_noise=2)))
        for s in (1, 2)
    ]
    assert not np.array_equal(noisy[0].color, noisy[1].color)
    difference = noisy[0].color.astype(float) - flat.color
    assert 1.5 < difference.std() < 2.5
    # flat colours: one colour per material
    table = segment_mask(flat, "table_top/top")
    assert len(np.unique(flat.color[table], axis=0)) == 1


def test_the_camera_moves_smoothly_and_keeps_looking_at_the_scene():
    frames = list(render_scene("tabletop", 3, width=WIDTH, height=HEIGHT))
    positions = [f.pose.position for f in frames]
    step = np.linalg.norm(positions[1] - positions[0])
    assert 0 < step < 0.05  # metres per frame at 30 fps
    overlap = np.mean(frames[0].labels == frames[1].labels)
    assert overlap > 0.9


def test_plane_pixels_deproject_onto_the_known_planes():
    frame = next(iter(render_scene("tabletop", 1, width=WIDTH, height=HEIGHT)))
    floor = world_points(frame, segment_mask(frame, "floor/surface"))
    wall = world_points(frame, segment_mask(frame, "wall/surface"))
    table = world_points(frame, segment_mask(frame, "table_top/top"))
    assert len(floor) > 1000 and len(wall) > 1000 and len(table) > 500
    # floor z = 0, wall y = 1.5, table top z = 0.74 (scenes.tabletop_scene); noise ~ 5-15 mm
    assert np.median(np.abs(floor[:, 2])) < 0.01
    assert np.median(np.abs(wall[:, 1] - 1.5)) < 0.02
    assert np.median(np.abs(table[:, 2] - 0.74)) < 0.01
    assert np.all(np.abs(table[:, 2] - 0.74) < 0.06)


def test_curved_pixels_deproject_onto_the_known_solids():
    frame = next(iter(render_scene("tabletop", 1, width=WIDTH, height=HEIGHT)))
    sphere = world_points(frame, segment_mask(frame, "blue_sphere/surface"))
    radius = np.linalg.norm(sphere - [0.15, 0.15, 0.74 + 0.08], axis=1)
    assert len(sphere) > 20
    assert np.median(np.abs(radius - 0.08)) < 0.01

    frame = next(iter(render_scene("data2", 1, width=WIDTH, height=HEIGHT)))
    cylinder = world_points(frame, segment_mask(frame, "half_cylinder/side"))
    # axis along x through (y, z) = (-0.2, 0), radius 0.1
    radius = np.hypot(cylinder[:, 1] + 0.2, cylinder[:, 2])
    assert len(cylinder) > 200
    assert np.median(np.abs(radius - 0.1)) < 0.005
    assert np.all(cylinder[:, 2] > -0.02)  # only the upper half shows


def flat_plane_hits(depth_m: float, cos_incidence: float, size: int = 200) -> RayHits:
    shape = (size, size)
    return RayHits(
        depth=np.full(shape, depth_m),
        primitive=np.zeros(shape, dtype=np.int16),
        face=np.zeros(shape, dtype=np.int8),
        cos_incidence=np.full(shape, cos_incidence),
    )


@pytest.mark.parametrize(("depth_m", "expected_sigma_mm"), [(1.0, 1.5), (2.0, 6.0)])
def test_depth_noise_grows_with_depth_squared(depth_m, expected_sigma_mm):
    depth = kinect_depth(flat_plane_hits(depth_m, 1.0), np.random.default_rng(0))
    millimetres = depth.astype(float)
    assert np.all(depth > 0)
    assert abs(np.mean(millimetres) - depth_m * 1000) < 1.0
    # quantisation (disparity steps, then mm) adds a little spread
    assert expected_sigma_mm * 0.8 < np.std(millimetres) < expected_sigma_mm * 1.6


def test_depth_is_in_whole_millimetres_on_kinect_disparity_steps():
    depth = kinect_depth(flat_plane_hits(2.0, 1.0), np.random.default_rng(1))
    levels = np.unique(depth)
    # at 2 m a Kinect v1 reports depths ~11 mm apart, not every millimetre
    assert 3 <= len(levels) <= 12
    assert 8 <= np.median(np.diff(levels)) <= 14


def test_grazing_surfaces_and_far_surfaces_give_holes():
    rng = np.random.default_rng(0)
    assert np.all(kinect_depth(flat_plane_hits(1.5, math.cos(math.radians(80))), rng) == 0)
    assert np.all(kinect_depth(flat_plane_hits(1.5, math.cos(math.radians(70))), rng) > 0)
    assert np.all(kinect_depth(flat_plane_hits(6.0, 1.0), rng) == 0)


def single_object_scene(primitives, target, distance=1.5, elevation=0.0) -> Scene:
    return Scene(
        name="test",
        description="test scene",
        primitives=tuple(primitives),
        orbit=Orbit(
            target=target,
            distance=distance,
            elevation_deg=elevation,
            azimuth_swing_deg=0.0,
            period_s=1.0,
        ),
        background=(0, 0, 0),
        ground_truth={},
    )


def test_holes_follow_the_incidence_angle_on_a_tilted_plane():
    # A floor seen from 1 m up at a shallow angle: incidence grows towards the horizon.
    floor = Rectangle("floor", (100, 100, 100), half_size=(20.0, 20.0))
    scene = single_object_scene([floor], target=(0.0, 2.0, 0.0), distance=2.2, elevation=27.0)
    intrinsics = kinect_intrinsics(WIDTH, HEIGHT)
    frame = render_frame(scene, 0, intrinsics)
    pose = frame.pose.matrix
    k = intrinsics
    columns, rows = np.meshgrid(np.arange(k.width), np.arange(k.height))
    rays = np.stack([(columns - k.cx) / k.fx, (rows - k.cy) / k.fy, np.ones(rows.shape)], -1)
    directions = rays @ pose[:3, :3].T
    cos_incidence = np.abs(directions[..., 2]) / np.linalg.norm(directions, axis=-1)
    hits_floor = directions[..., 2] < 0
    range_m = pose[2, 3] / np.maximum(-directions[..., 2], 1e-9)  # camera z, metres
    in_range = hits_floor & (range_m < 4.3)
    grazing = in_range & (cos_incidence < math.cos(math.radians(77)))
    facing = in_range & (cos_incidence > math.cos(math.radians(73)))
    assert grazing.sum() > 100 and facing.sum() > 100
    assert np.all(frame.depth[grazing] == 0)
    assert np.mean(frame.depth[facing] > 0) > 0.99


def test_depth_discontinuities_give_holes_on_both_sides():
    wall = Rectangle(
        "wall",
        (200, 200, 200),
        center=(0.0, 1.0, 0.0),
        normal=(0.0, -1.0, 0.0),
        half_size=(3.0, 3.0),
    )
    block = box("block", (200, 0, 0), center=(0.0, 0.0, 0.0), size=(0.3, 0.1, 0.3))
    scene = single_object_scene([wall, block], target=(0.0, 0.0, 0.0), distance=1.5)
    frame = render_frame(scene, 0, kinect_intrinsics(WIDTH, HEIGHT))
    row = frame.depth[HEIGHT // 2]
    # along the middle row: wall (2.5 m), block (1.45 m), wall again, separated by holes
    is_block = (row > 1300) & (row < 1600)
    is_wall = row > 2300
    assert is_block.sum() > 10 and is_wall.sum() > 20
    first, last = np.flatnonzero(is_block)[[0, -1]]
    assert row[first - 1] == 0 and row[last + 1] == 0
    assert np.all(is_block[first : last + 1])
    assert np.all(is_wall[: first - 2]) and np.all(is_wall[last + 3 :])
    assert np.count_nonzero(row == 0) <= 4


def test_primitives_intersect_rays_where_geometry_says():
    origin = np.array([0.0, -2.0, 0.5])
    straight = np.array([[0.0, 1.0, 0.0]])
    sphere = Sphere("s", (0, 0, 0), center=(0.0, 0.0, 0.5), radius=0.25)
    cylinder = Cylinder("c", (0, 0, 0), base_center=(0.0, 0.0, 0.0), radius=0.3, height=1.0)
    block = box("b", (0, 0, 0), center=(0.0, 0.0, 0.5), size=(1.0, 0.4, 1.0), yaw_deg=90.0)
    prism = triangular_prism("p", (0, 0, 0), (0.0, 0.0, 0.0), length=1.0, width=1.0, height=1.0)
    # distance to the first surface along +y, and the face hit
    expectations = [
        (sphere, 1.75, "surface"),
        (cylinder, 1.7, "side"),
        (block, 1.5, "left"),
        (prism, 1.75, "front_slope"),
    ]  # prism slope at z=0.5 is at y=-0.25
    for primitive, distance, face_name in expectations:
        t, face = primitive.intersect(origin, straight)
        assert t[0] == pytest.approx(distance), primitive.name
        assert primitive.face_names[face[0]] == face_name
    upward = np.array([[0.0, 0.0, 1.0]])
    assert np.isinf(sphere.intersect(origin, upward)[0][0])
    t, face = cylinder.intersect(np.array([0.1, 0.0, 3.0]), np.array([[0.0, 0.0, -1.0]]))
    assert t[0] == pytest.approx(2.0) and cylinder.face_names[face[0]] == "top_cap"


def pixel_regions(
    points: np.ndarray,
    depth: np.ndarray,
    normals: np.ndarray,
    colors: np.ndarray,
    valid: np.ndarray,
    *,
    by_color: bool,
    by_normal: bool,
    min_share: float = 0.004,
) -> int:
    """Connected regions of valid pixels, linking 4-neighbours that touch in 3D (closer than 6%
    of their depth: pixels on a floor seen at 75 degrees are ~3% apart at 160x120) and,
    if asked, have the same colour (RGB distance < 10) and normal (< 25 degrees apart: a
    curved surface spans ~10 degrees per pixel at 160x120, the scenes' edges are >= 45 degrees).

    Regions smaller than ``min_share`` of the valid pixels (slivers at edges) are not counted.
    """
    height, width = valid.shape
    index = np.arange(height * width).reshape(height, width)
    sources, targets = [], []
    for a, b in (
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
    ):
        linked = valid[a] & valid[b]
        linked &= np.linalg.norm(points[a] - points[b], axis=-1) < 0.06 * depth[a]
        if by_color:
            linked &= np.linalg.norm(colors[a].astype(float) - colors[b], axis=-1) < 10
        if by_normal:
            linked &= np.einsum("...i,...i->...", normals[a], normals[b]) > math.cos(
                math.radians(25)
            )
        sources.append(index[a][linked])
        targets.append(index[b][linked])
    sources, targets = np.concatenate(sources), np.concatenate(targets)
    graph = coo_matrix((np.ones(len(sources)), (sources, targets)), shape=(index.size,) * 2)
    _, component = connected_components(graph, directed=False)
    sizes = np.bincount(component[valid.ravel()])
    return int(np.count_nonzero(sizes >= min_share * valid.sum()))


#: GNG-DT topology -> (links need the same colour, links need the same normal)
TOPOLOGIES = {
    "pos": (False, False),
    "col": (True, False),
    "nor": (False, True),
    "col+nor": (True, True),
}


@pytest.mark.parametrize("scene_name", ["data2", "tabletop"])
def test_documented_ground_truth_matches_what_the_camera_sees(scene_name):
    """Count colour / normal regions in noise-free renderings along the whole camera path."""
    scene = build_scene(scene_name)
    truth = SCENE_GROUND_TRUTH[scene_name]
    intrinsics = kinect_intrinsics(WIDTH, HEIGHT)
    # eight poses spread over one period of the orbit
    fps = 8 / scene.orbit.period_s
    for index in range(8):
        frame = render_frame(scene, index, intrinsics, fps=fps)
        hits = cast_rays(scene, frame.pose.matrix, intrinsics)
        pose = frame.pose.matrix
        k = intrinsics
        columns, rows = np.meshgrid(np.arange(k.width), np.arange(k.height))
        rays = np.stack([(columns - k.cx) / k.fx, (rows - k.cy) / k.fy, np.ones(rows.shape)], -1)
        depth = np.where(np.isfinite(hits.depth), hits.depth, 0.0)
        points = (rays * depth[..., None]) @ pose[:3, :3].T + pose[:3, 3]
        normals = np.zeros_like(points)
        for number, primitive in enumerate(scene.primitives):
            on = hits.primitive == number
            normals[on] = primitive.normals(points[on], hits.face[on].astype(np.intp))
        valid = frame.depth > 0
        counts = {
            name: pixel_regions(
                points, depth, normals, frame.color, valid, by_color=by_color, by_normal=by_normal
            )
            for name, (by_color, by_normal) in TOPOLOGIES.items()
            if name in truth
        }
        expected = {name: truth[name] for name in counts}
        assert counts == expected, f"{scene_name} frame {index}"


def test_scenes_are_listed_with_descriptions():
    assert {"data2", "tabletop"} <= set(SCENES)
    assert all(isinstance(text, str) and text for text in SCENES.values())
    assert SCENE_GROUND_TRUTH["data2"] == {"pos": 1, "col": 3, "nor": 4, "col+nor": 5}


@pytest.mark.parametrize(
    ("arguments", "parameter"),
    [
        ({"scene": "kitchen"}, "scene"),
        ({"frames": 0}, "frames"),
        ({"frames": 2.5}, "frames"),
        ({"width": 0}, "width"),
        ({"height": -480}, "height"),
        ({"width": "640"}, "width"),
        ({"fps": 0.0}, "fps"),
        ({"seed": -1}, "seed"),
        ({"color_noise": -1.0}, "color_noise"),
    ],
)
def test_bad_parameters_are_refused_before_rendering(arguments, parameter):
    call = {"scene": "tabletop", "frames": 1, **arguments}
    scene, frames = call.pop("scene"), call.pop("frames")
    with pytest.raises(ValueError, match=parameter):
        render_scene(scene, frames, **call)  # raises at the call, not at the first frame


RECORDINGS = Path(__file__).resolve().parents[2] / "recordings"


def test_bundled_small_recording_is_what_the_renderer_makes_today():
    """recordings/README.md's command remakes tabletop_small.mcap; if not, regenerate them."""
    from gngdt.io.mcap.reader import read_frames

    path = RECORDINGS / "tabletop_small.mcap"
    recorded = list(read_frames(path))
    rendered = list(render_scene("tabletop", 10, width=320, height=240))
    assert len(recorded) == len(rendered) == 10
    # Another CPU may round a last floating-point bit differently, moving a pixel across a
    # millimetre or a silhouette: allow a handful of such pixels, not a changed scene.
    for stored, fresh in zip(recorded, rendered, strict=True):
        assert stored.timestamp_ns == fresh.timestamp_ns
        assert np.mean(stored.depth != fresh.depth) < 1e-3
        assert np.mean(np.any(stored.color != fresh.color, axis=-1)) < 1e-3
        assert np.mean(stored.labels != fresh.labels) < 1e-3


def test_bundled_recordings_stay_small():
    sizes = {path.name: path.stat().st_size for path in RECORDINGS.glob("*.mcap")}
    assert {"tabletop.mcap", "data2.mcap", "tabletop_small.mcap"} <= set(sizes)
    assert sum(sizes.values()) < 20e6
