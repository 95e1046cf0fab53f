"""Frame-to-map tracking (`gngdt.core.odometry.map_odometry`) on constructed scenes: a known rigid
motion is recovered, frames that cannot be aligned are reported lost and never move the pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.kernels import odometry as OK
from gngdt.core.odometry.map_odometry import MapOdometry, TrackerParams
from gngdt.core.odometry.map_surface import MapSurface
from gngdt.core.sensor.depth import organize
from gngdt.core.sensor.geometry import rigid_inverse

WIDTH, HEIGHT, FOCAL = 160, 120, 130.0


def look_at(position, target) -> np.ndarray:
    """(4, 4) camera-to-world of a level camera (x right, y down, z forward), world z up."""
    position = np.asarray(position, dtype=float)
    forward = np.asarray(target, dtype=float) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
    pose[:3, 3] = position
    return pose


def moved(pose: np.ndarray, translation, angles_deg) -> np.ndarray:
    """``pose`` moved by a translation (world) and a rotation about the camera centre."""
    rotation = OK.so3_exp(np.radians(np.asarray(angles_deg, dtype=float)))
    result = pose.copy()
    result[:3, :3] = rotation @ pose[:3, :3]
    result[:3, 3] += translation
    return result


class Rect:
    """A textured rectangle: centre, unit normal, in-plane axis u, half sizes (metres)."""

    def __init__(self, centre, normal, u, half, color=(128, 128, 128), texture=None):
        self.c = np.asarray(centre, dtype=float)
        self.n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
        self.u = np.asarray(u, dtype=float) / np.linalg.norm(u)
        self.v = np.cross(self.n, self.u)
        self.half = half
        self.color = np.asarray(color, dtype=float)
        self.texture = texture  # (a, b) plane coordinates -> (K, 3) colour, or None

    def colors(self, points: np.ndarray) -> np.ndarray:
        if self.texture is None:
            return np.broadcast_to(self.color, points.shape).copy()
        d = points - self.c
        return self.texture(d @ self.u, d @ self.v)

    def samples(self, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grid points (K, 3), normals and colours."""
        a = np.arange(-self.half[0] + spacing / 2, self.half[0], spacing)
        b = np.arange(-self.half[1] + spacing / 2, self.half[1], spacing)
        aa, bb = np.meshgrid(a, b)
        points = self.c + aa.reshape(-1, 1) * self.u + bb.reshape(-1, 1) * self.v
        return points, np.broadcast_to(self.n, points.shape).copy(), self.colors(points)


def render(rects: list[Rect], pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Organized points (H, W, 3) camera frame (NaN: nothing hit) and colours (H, W, 3) uint8."""
    u = (np.arange(WIDTH) - (WIDTH - 1) / 2) / FOCAL
    v = (np.arange(HEIGHT) - (HEIGHT - 1) / 2) / FOCAL
    rays = np.stack(np.broadcast_arrays(u[None, :], v[:, None], 1.0), axis=-1).reshape(-1, 3)
    directions = rays @ pose[:3, :3].T
    origin = pose[:3, 3]
    depth = np.full(len(rays), np.inf)
    colors = np.zeros((len(rays), 3))
    for rect in rects:
        denominator = directions @ rect.n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((rect.c - origin) @ rect.n) / denominator
        hit = origin + t[:, None] * directions
        d = hit - rect.c
        inside = ((np.abs(d @ rect.u) <= rect.half[0]) & (np.abs(d @ rect.v) <= rect.half[1])
                  & (t > 1e-6) & (t < depth))
        depth[inside] = t[inside]
        colors[inside] = rect.colors(hit[inside])
    points = rays * np.where(np.isfinite(depth), depth, np.nan)[:, None]
    return (points.reshape(HEIGHT, WIDTH, 3),
            np.clip(colors, 0, 255).astype(np.uint8).reshape(HEIGHT, WIDTH, 3))


def room() -> list[Rect]:
    """The inside of a 4 x 4 x 2.5 m room with a 0.6 m crate and a 1 x 0.8 m table top."""
    walls = [
        Rect((0, 0, 0), (0, 0, 1), (1, 0, 0), (2, 2), (100, 100, 110)),
        Rect((0, 0, 2.5), (0, 0, -1), (1, 0, 0), (2, 2), (240, 240, 240)),
        Rect((0, 2, 1.25), (0, -1, 0), (1, 0, 0), (2, 1.25), (220, 210, 190)),
        Rect((0, -2, 1.25), (0, 1, 0), (1, 0, 0), (2, 1.25), (200, 200, 220)),
        Rect((2, 0, 1.25), (-1, 0, 0), (0, 1, 0), (2, 1.25), (190, 220, 200)),
        Rect((-2, 0, 1.25), (1, 0, 0), (0, 1, 0), (2, 1.25), (210, 190, 200)),
    ]
    crate = [Rect((0.8 + 0.3 * s * (a == 0), 1.0 + 0.3 * s * (a == 1), 0.3 + 0.3 * s * (a == 2)),
                  np.eye(3)[a] * s, np.eye(3)[(a + 1) % 3], (0.3, 0.3), (60, 140, 160))
             for a in range(3) for s in (-1, 1)]
    table = [Rect((-0.6, 0.9, 0.75), (0, 0, 1), (1, 0, 0), (0.5, 0.4), (150, 105, 60))]
    return walls + crate + table


def surface_of(rects: list[Rect], spacing: float = 0.03) -> MapSurface:
    """A map of exact nodes and normals on ``rects`` (no GNG: the tracker alone is tested)."""
    samples = [rect.samples(spacing) for rect in rects]
    points = np.concatenate([s[0] for s in samples])
    return MapSurface.from_arrays(points, np.concatenate([s[1] for s in samples]),
                                  np.concatenate([s[2] for s in samples]),
                                  ids=np.arange(len(points)))


START = look_at((-1.0, -1.2, 1.5), (0.3, 1.0, 0.6))


def test_known_motion_of_a_room_is_recovered() -> None:
    """5 cm and 3 degrees of motion, from a start at the previous pose: < 1 mm, < 0.05 deg."""
    rects = room()
    truth = moved(START, (0.04, -0.02, 0.025), (1.5, -2.0, 1.0))
    points, colors = render(rects, truth)
    odometry = MapOdometry(min_points=100).reset(START)
    result = odometry.track(points, colors, surface_of(rects))
    assert not result.lost, result.reason
    translation, rotation = OK.motion_size(truth, result.pose)
    assert translation < 1e-3 and rotation < 0.05, (translation, rotation)
    np.testing.assert_allclose(odometry.pose_, result.pose)
    assert odometry.n_tracked_ == 1 and odometry.n_lost_ == 0
    assert result.inlier_share > 0.9 and result.constraint > 0.01


def test_a_learned_map_tracks_too() -> None:
    """The same motion against a GNG-DT network learned from the first frame."""
    rects = room()
    points, colors = render(rects, START)
    valid = np.isfinite(points[..., 2])
    model = GNGDT(max_nodes=1500, lambda_=50, eta1=0.1, random_state=0)
    model.partial_fit(points[valid], colors[valid], n_steps=100_000, camera_pose=START)
    truth = moved(START, (0.03, 0.02, -0.02), (-1.0, 1.0, 2.0))
    moved_points, moved_colors = render(rects, truth)
    result = MapOdometry(min_points=100).reset(START).track(
        moved_points, moved_colors, MapSurface.from_model(model))
    assert not result.lost, result.reason
    translation, rotation = OK.motion_size(truth, result.pose)
    assert translation < 5e-3 and rotation < 0.3, (translation, rotation)


def test_constant_velocity_prediction() -> None:
    """After two tracked frames the next is searched from the pose moved by the last motion."""
    rects = room()
    surface = surface_of(rects)
    step = moved(np.eye(4), (0.02, 0.0, 0.0), (0.0, 0.0, 1.0))
    odometry = MapOdometry(min_points=100).reset(START)
    pose = START
    for _ in range(2):
        pose = pose @ step
        points, colors = render(rects, pose)
        assert not odometry.track(points, colors, surface).lost
    expected = odometry.pose_ @ step
    translation, rotation = OK.motion_size(expected, odometry.predict())
    assert translation < 1e-3 and rotation < 0.05


def plane_view(texture=None) -> tuple[list[Rect], np.ndarray]:
    """A 6 x 6 m floor seen from 1.2 m straight above."""
    floor = [Rect((0, 0, 0), (0, 0, 1), (1, 0, 0), (3, 3), (120, 120, 120), texture)]
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking down (z forward = world -z)
    pose[:3, 3] = (0.0, 0.0, 1.2)
    return floor, pose


def test_featureless_plane_sliding_along_itself_is_lost() -> None:
    """Nothing tells a uniform floor's in-plane motion: lost (degenerate), pose kept."""
    rects, pose = plane_view()
    truth = moved(pose, (0.05, 0.03, 0.0), (0.0, 0.0, 0.0))
    points, colors = render(rects, truth)
    odometry = MapOdometry(min_points=100).reset(pose)
    result = odometry.track(points, colors, surface_of(rects))
    assert result.lost and result.reason == "degenerate"
    np.testing.assert_array_equal(odometry.pose_, pose)
    assert odometry.n_lost_ == 1 and odometry.n_tracked_ == 0
    assert result.geometry_constraint < 1e-6


def test_colour_breaks_the_tie_on_a_textured_plane() -> None:
    """The same slide over a floor with a smooth colour pattern: tracked through colour."""
    def texture(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        value = 128 + 60 * np.sin(2 * math.pi * a / 0.5) + 60 * np.sin(2 * math.pi * b / 0.7)
        return np.stack([value, value * 0.8, value * 0.6], axis=-1)

    rects, pose = plane_view(texture)
    truth = moved(pose, (0.02, 0.015, 0.0), (0.0, 0.0, 0.5))
    points, colors = render(rects, truth)
    surface = MapSurface.from_arrays(*_textured_nodes(rects[0], spacing=0.03))
    result = MapOdometry(min_points=100, color_weight=1.0).reset(pose).track(
        points, colors, surface)
    assert not result.lost, result.reason
    assert result.used_color
    translation, rotation = OK.motion_size(truth, result.pose)
    assert translation < 3e-3 and rotation < 0.2, (translation, rotation)


def _textured_nodes(rect: Rect, spacing: float):
    """Nodes on a grid with their position edges (4-neighbours), for the colour gradients."""
    points, normals, colors = rect.samples(spacing)
    columns = round(2 * rect.half[0] / spacing)
    index = np.arange(len(points)).reshape(-1, columns)
    edges = np.concatenate([np.stack([index[:, :-1].ravel(), index[:, 1:].ravel()], 1),
                            np.stack([index[:-1].ravel(), index[1:].ravel()], 1)])
    return points, normals, colors, edges


def test_a_different_scene_is_lost() -> None:
    """A frame of somewhere else (a small box room) against the big room's map: lost."""
    rects = room()
    other = [Rect((0, 0, 0), (0, 0, 1), (1, 0, 0), (0.7, 0.7)),
             Rect((0, 0.7, 0.5), (0, -1, 0), (1, 0, 0), (0.7, 0.5)),
             Rect((0.7, 0, 0.5), (-1, 0, 0), (0, 1, 0), (0.7, 0.5)),
             Rect((-0.7, 0, 0.5), (1, 0, 0), (0, 1, 0), (0.7, 0.5))]
    pose = look_at((0.0, -0.6, 0.9), (0.1, 0.7, 0.2))
    points, colors = render(other, pose)
    odometry = MapOdometry(min_points=100).reset(pose)
    result = odometry.track(points, colors, surface_of(rects))
    assert result.lost, (result.inlier_share, result.rms_m)
    np.testing.assert_array_equal(odometry.pose_, pose)


def test_a_kidnapped_camera_is_lost() -> None:
    """The same room seen from across it (2.9 m and 150 degrees from the prediction): lost."""
    rects = room()
    points, colors = render(rects, look_at((1.2, 1.0, 1.2), (-1.5, -1.0, 0.5)))
    odometry = MapOdometry(min_points=100).reset(START)
    result = odometry.track(points, colors, surface_of(rects))
    assert result.lost
    np.testing.assert_array_equal(odometry.pose_, START)


def test_after_a_loss_the_motion_goes_on_and_tracking_resumes() -> None:
    """A lost frame leaves the motion as it was: the next is predicted one motion on (frames
    without stamps) and tracked."""
    rects = room()
    surface = surface_of(rects)
    odometry = MapOdometry(min_points=100).reset(START)
    for k in (1, 2):
        points, colors = render(rects, moved(START, (0.02 * k, 0, 0), (0, 0, 0)))
        assert not odometry.track(points, colors, surface).lost
    empty = np.full((HEIGHT, WIDTH, 3), np.nan)
    lost = odometry.track(empty, None, surface)
    assert lost.lost and lost.reason == "too few points"
    assert OK.motion_size(odometry.pose_, odometry.predict())[0] == pytest.approx(0.02, abs=1e-4)
    truth = moved(START, (0.06, 0.01, 0), (0, 0, 1))
    points, colors = render(rects, truth)
    result = odometry.track(points, colors, surface)
    assert not result.lost
    assert OK.motion_size(truth, result.pose)[0] < 1e-3


def walking(odometry: MapOdometry, surface: MapSurface, rects: list[Rect], step: np.ndarray,
            frames: int, period_ns: int) -> np.ndarray:
    """Track ``frames`` frames of a camera moving by ``step`` (4, 4) every ``period_ns`` from
    START (stamped 0): the last true pose."""
    pose = START
    for k in range(1, frames + 1):
        pose = pose @ step
        points, colors = render(rects, pose)
        result = odometry.track(points, colors, surface, stamp_ns=k * period_ns)
        assert not result.lost and OK.motion_size(pose, result.pose)[0] < 2e-3, result
    return pose


STEP = moved(np.eye(4), (0.0, 0.0, 0.06), (0.0, 1.5, 0.0))  # 6 cm forward, 1.5 degrees
PERIOD_NS = 100_000_000  # 10 frames a second


@pytest.mark.parametrize("dropped", [3, 5])
def test_dropped_frames_are_predicted_over_the_time_they_took(dropped: int) -> None:
    """A busy learner skipped frames: the motion is continued over the time since the last
    tracked frame (with one frame's motion the estimate would be ``dropped`` motions, 18-30
    cm, from the prediction: lost but for the search)."""
    rects = room()
    surface = surface_of(rects)
    odometry = MapOdometry(min_points=100).reset(START, 0)
    pose = walking(odometry, surface, rects, STEP, 2, PERIOD_NS)
    truth = pose @ np.linalg.matrix_power(STEP, dropped + 1)
    stamp = (2 + dropped + 1) * PERIOD_NS
    prediction = odometry.predict(stamp)
    assert OK.motion_size(truth, prediction)[0] < 1e-3
    points, colors = render(rects, truth)
    result = odometry.track(points, colors, surface, stamp_ns=stamp)
    assert not result.lost, result.reason
    assert OK.motion_size(truth, result.pose)[0] < 2e-3
    assert odometry.motion_span_s_ == pytest.approx((dropped + 1) * PERIOD_NS * 1e-9)
    # the same without stamps, nor the searches that find a camera farther on than predicted
    one_frame = MapOdometry(min_points=100, search_steps=0, relocalise=False).reset(START)
    walking(one_frame, surface, rects, STEP, 2, PERIOD_NS)
    assert one_frame.track(points, colors, surface).lost


def test_the_motion_is_continued_for_coast_s_at_most() -> None:
    rects = room()
    surface = surface_of(rects)
    odometry = MapOdometry(min_points=100, coast_s=0.3).reset(START, 0)
    walking(odometry, surface, rects, STEP, 2, PERIOD_NS)
    later = odometry.predict(2 * PERIOD_NS + 10**9)  # 1 s later: 0.3 s, three motions
    expected = odometry.pose_ @ np.linalg.matrix_power(odometry.velocity_, 3)
    assert OK.motion_size(expected, later)[0] < 1e-9
    np.testing.assert_allclose(odometry.predict(PERIOD_NS), odometry.pose_, atol=1e-12)


def test_a_camera_that_stopped_is_found_where_it_was() -> None:
    """The prediction runs on (0.3 m) past a camera that stopped: the alignment from it fails,
    the one from the last tracked pose holds."""
    rects = room()
    surface = surface_of(rects)
    fast = moved(np.eye(4), (0.0, 0.0, 0.1), (0.0, 0.0, 0.0))
    odometry = MapOdometry(min_points=100).reset(START, 0)
    pose = walking(odometry, surface, rects, fast, 2, PERIOD_NS)
    stamp = 5 * PERIOD_NS
    assert OK.motion_size(pose, odometry.predict(stamp))[0] == pytest.approx(0.3, abs=1e-4)
    points, colors = render(rects, pose)
    result = odometry.track(points, colors, surface, stamp_ns=stamp)
    assert not result.lost, result.reason
    assert OK.motion_size(pose, result.pose)[0] < 1e-3
    no_retry = MapOdometry(min_points=100).reset(START, 0)  # from the prediction alone
    walking(no_retry, surface, rects, fast, 2, PERIOD_NS)
    assert no_retry.track(points, colors, surface, initial_pose=no_retry.predict(stamp)).lost


def test_the_second_frame_is_searched_for() -> None:
    """No motion is known before the second frame: a camera 40 cm to the side of the first
    frame's pose is found by the search (from the first pose alone it is not)."""
    rects = room()
    surface = surface_of(rects)
    truth = START @ moved(np.eye(4), (0.4, 0.0, 0.0), (0.0, 0.0, 0.0))
    points, colors = render(rects, truth)
    result = MapOdometry(min_points=100).reset(START).track(points, colors, surface)
    assert not result.lost, result.reason
    assert OK.motion_size(truth, result.pose)[0] < 2e-3
    unsearched = MapOdometry(min_points=100, search_steps=0).reset(START).track(
        points, colors, surface)
    assert unsearched.lost or OK.motion_size(truth, unsearched.pose)[0] > 0.05


@pytest.mark.parametrize("axis", [0, 1])
def test_a_camera_that_turned_before_the_second_frame_is_searched_for(axis: int) -> None:
    """The camera turned 15 degrees (pitch, yaw) while the map's first frame was learned: found
    by the search's turned starts (without them it is lost)."""
    rects = room()
    surface = surface_of(rects)
    truth = START @ moved(np.eye(4), (0.0, 0.0, 0.0), 15.0 * np.eye(3)[axis])
    points, colors = render(rects, truth)
    result = MapOdometry(min_points=100).reset(START).track(points, colors, surface)
    assert not result.lost, result.reason
    assert OK.motion_size(truth, result.pose)[1] < 0.05
    assert MapOdometry(min_points=100, search_turn_deg=0.0).reset(START).track(
        points, colors, surface).lost


@pytest.mark.parametrize("search_steps", [3, 0])
def test_a_camera_farther_on_than_predicted_is_searched_for(search_steps: int) -> None:
    """After a lost frame the camera sped up: 23 cm past the prediction (35 cm past the last
    tracked pose) neither start holds, the search around the prediction does."""
    rects = room()
    surface = surface_of(rects)
    odometry = MapOdometry(min_points=100, search_steps=search_steps).reset(START, 0)
    pose = walking(odometry, surface, rects, STEP, 2, PERIOD_NS)
    assert odometry.track(np.full((HEIGHT, WIDTH, 3), np.nan), None, surface,
                          stamp_ns=3 * PERIOD_NS).lost
    truth = pose @ moved(np.eye(4), (0.0, 0.0, 0.35), (0.0, 0.0, 0.0))
    points, colors = render(rects, truth)
    result = odometry.track(points, colors, surface, stamp_ns=4 * PERIOD_NS)
    if search_steps:
        assert not result.lost, result.reason
        assert OK.motion_size(truth, result.pose)[0] < 2e-3
    else:
        assert result.lost


def test_scaled_motion_follows_the_screw() -> None:
    motion = moved(np.eye(4), (0.05, -0.02, 0.1), (3.0, -8.0, 20.0))
    np.testing.assert_allclose(OK.scaled_motion(motion, 1.0), motion, atol=1e-12)
    np.testing.assert_allclose(OK.scaled_motion(motion, 3.0),
                               np.linalg.matrix_power(motion, 3), atol=1e-12)
    np.testing.assert_allclose(OK.scaled_motion(motion, 0.0), np.eye(4), atol=1e-12)
    half = OK.scaled_motion(motion, 0.5)
    np.testing.assert_allclose(half @ half, motion, atol=1e-12)


def test_no_map_is_lost() -> None:
    points, colors = render(room(), START)
    result = MapOdometry().reset(START).track(
        points, colors, MapSurface.from_arrays(np.zeros((0, 3)), np.zeros((0, 3))))
    assert result.lost and result.reason == "no map"


@pytest.mark.parametrize("params", [
    {"strides": (8, 4), "iterations": (5,), "gates_m": (0.1, 0.05)},
    {"strides": (0,), "iterations": (5,), "gates_m": (0.1,)},
    {"huber_sigma": 0.0}, {"normal_angle_deg": 120.0}, {"min_inlier_share": 1.5},
    {"color_weight": -1.0}, {"min_points": 2}, {"max_depth_m": 0.1, "min_depth_m": 0.3},
])
def test_parameters_are_checked(params: dict) -> None:
    with pytest.raises(ValueError):
        MapOdometry(**params)
    with pytest.raises(ValueError):
        TrackerParams.from_dict(params)


def test_parameters_from_a_profile_table() -> None:
    """A [tracker] table: lists become tuples, unknown keys are named."""
    params = TrackerParams.from_dict({"strides": [4], "iterations": [3], "gates_m": [0.1]})
    assert params.strides == (4,) and MapOdometry(params).params.gates_m == (0.1,)
    with pytest.raises(ValueError, match="stride_px"):
        TrackerParams.from_dict({"stride_px": 4})
    with pytest.raises(ValueError, match="motion_model"):
        TrackerParams(motion_model=1)


def test_a_pose_must_be_rigid() -> None:
    with pytest.raises(ValueError, match="rigid"):
        MapOdometry().reset(np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="organized"):
        MapOdometry().track(np.zeros((10, 3)), None, surface_of(room()))


def test_kernels_rigid_motion_helpers() -> None:
    xi = np.array([0.01, -0.02, 0.03, 0.1, 0.2, -0.1])
    centre = np.array([1.0, 2.0, 0.5])
    motion = OK.update_about(xi, centre)
    np.testing.assert_allclose(motion[:3, :3] @ motion[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(motion[:3, :3] @ centre + motion[:3, 3], centre + xi[3:])
    np.testing.assert_allclose(rigid_inverse(motion) @ motion, np.eye(4), atol=1e-12)
    assert OK.rotation_angle_deg(motion[:3, :3]) == pytest.approx(
        math.degrees(np.linalg.norm(xi[:3])))


def test_state_round_trip_continues_the_same() -> None:
    """A tracker restored from `get_state` (a checkpoint) predicts and tracks as the original."""
    rects = room()
    surface = surface_of(rects)
    odometry = MapOdometry(min_points=100).reset(START)
    for k in range(1, 3):
        points, colors = render(rects, moved(START, (0.02 * k, 0, 0), (0, 0, k)))
        assert not odometry.track(points, colors, surface, stamp_ns=k * PERIOD_NS).lost
    restored = MapOdometry(min_points=100).set_state(
        {key: value.copy() for key, value in odometry.get_state().items()})
    np.testing.assert_array_equal(restored.predict(5 * PERIOD_NS),
                                  odometry.predict(5 * PERIOD_NS))
    old = {key: value for key, value in odometry.get_state().items()  # before stamps were kept
           if key not in ("stamp_ns", "motion_span_s")}
    np.testing.assert_allclose(MapOdometry().set_state(old).predict(5 * PERIOD_NS),
                               odometry.pose_ @ odometry.velocity_, atol=1e-12)
    points, colors = render(rects, moved(START, (0.06, 0, 0), (0, 0, 3)))
    np.testing.assert_allclose(restored.track(points, colors, surface).pose,
                               odometry.track(points, colors, surface).pose)
    state = odometry.get_state()
    assert len(state["plane_ids"]) == len(surface)
    state["plane_counts"] = state["plane_counts"][:-1]
    with pytest.raises(ValueError, match="plane memory"):
        MapOdometry().set_state(state)
    assert MapOdometry().set_state(MapOdometry().get_state()).pose_ is None


def test_organize_puts_deprojected_points_back_on_their_pixels() -> None:
    """The learner's points (valid pixels only) and the calibration give the organized cloud."""
    points, colors = render(room(), START)
    valid = np.isfinite(points[..., 2])
    centre = ((WIDTH - 1) / 2, (HEIGHT - 1) / 2)
    organized, image = organize(points[valid], colors[valid], WIDTH, HEIGHT, FOCAL, FOCAL,
                                *centre)
    np.testing.assert_array_equal(np.isfinite(organized[..., 2]), valid)
    np.testing.assert_allclose(organized[valid], points[valid].astype(np.float32))
    np.testing.assert_array_equal(image[valid], colors[valid])
    assert organize(np.zeros((0, 3)), None, 4, 3, 1.0, 1.0, 1.5, 1.0)[1] is None


@pytest.mark.parametrize("stride", [2, 3, 4])
def test_organize_keeps_every_stride_th_pixel_as_the_whole_image_does(stride: int) -> None:
    """Organized at a stride: the whole image's ``[::stride, ::stride]``, points and colours
    (the image's odd size included)."""
    points, colors = render(room(), START)
    valid = np.isfinite(points[..., 2])
    centre = ((WIDTH - 1) / 2, (HEIGHT - 1) / 2)
    whole, whole_image = organize(points[valid], colors[valid], WIDTH - 1, HEIGHT - 1, FOCAL,
                                  FOCAL, *centre)
    kept, kept_image = organize(points[valid], colors[valid], WIDTH - 1, HEIGHT - 1, FOCAL,
                                FOCAL, *centre, stride=stride)
    np.testing.assert_array_equal(kept, whole[::stride, ::stride])
    np.testing.assert_array_equal(kept_image, whole_image[::stride, ::stride])
    with pytest.raises(ValueError, match="stride"):
        organize(points[valid], None, WIDTH, HEIGHT, FOCAL, FOCAL, *centre, stride=0)


def test_tracking_the_levels_pixels_alone_finds_the_same_pose() -> None:
    """A frame given as only the pixels the levels look at (`pixel_stride`) is tracked to the
    very pose the whole frame is; a stride the levels do not fall on is refused."""
    surface = surface_of(room())
    points, colors = render(room(), moved(START, (0.04, -0.02, 0.03), (2, -3, 1)))
    stride = MapOdometry().pixel_stride
    assert stride == math.gcd(*TrackerParams().strides) > 1
    whole, sparse = MapOdometry(min_points=100), MapOdometry(min_points=100)
    for odometry in (whole, sparse):
        odometry.reset(START)
    expected = whole.track(points, colors, surface)
    found = sparse.track(points[::stride, ::stride], colors[::stride, ::stride], surface,
                         stride=stride)
    assert not expected.lost, expected.reason
    np.testing.assert_array_equal(found.pose, expected.pose)
    with pytest.raises(ValueError, match="does not divide"):
        MapOdometry().track(points, colors, surface, stride=stride * 2 + 1)
