"""Virtual Kinect scenes that move: a walking camera, an object that vanishes, one that slides;
their poses and ground truth in the recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers.synthetic import segment_mask, world_points

from gngdt.io.mcap.reader import read_frames, recording_metadata
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.io.synth.render import SCENE_METADATA, SCENES, render_scene, scene_metadata
from gngdt.io.synth.scenes import build_scene

WIDTH, HEIGHT = 160, 120


def test_moving_scenes_are_listed():
    assert {"tabletop_walk", "tabletop_vanish", "tabletop_move"} <= set(SCENES)


def test_a_vanished_object_is_seen_before_and_never_after():
    fps = 5.0  # the red box vanishes 2 s in: frame 10
    frames = list(render_scene("tabletop_vanish", 14, width=WIDTH, height=HEIGHT, fps=fps))
    box_ids = {i for i, name in frames[0].extras["segments"].items() if name.startswith("red_box")}
    seen = [bool(np.isin(f.labels, list(box_ids)).any()) for f in frames]
    assert seen == [True] * 10 + [False] * 4
    # the table top under it comes into view where the box stood
    before, after = (world_points(f, segment_mask(f, "table_top/top")) for f in frames[9:11])
    box_footprint = np.linalg.norm(after[:, :2] - [-0.35, 0.25], axis=1) < 0.06
    assert box_footprint.sum() > 5
    assert (np.linalg.norm(before[:, :2] - [-0.35, 0.25], axis=1) < 0.06).sum() == 0


def test_a_moved_object_is_where_its_motion_says():
    fps = 2.0  # moves from 2 s to 3.5 s: frames 4..7
    frames = list(render_scene("tabletop_move", 9, width=320, height=240, fps=fps))
    centres = [sphere_centre(world_points(f, segment_mask(f, "blue_sphere/surface")))
               for f in frames]
    np.testing.assert_allclose(centres[0], [0.15, 0.15, 0.74 + 0.08], atol=0.01)
    np.testing.assert_allclose(centres[4] - centres[0], 0.0, atol=0.01)
    np.testing.assert_allclose(centres[6] - centres[0], [0.0, 0.2, 0.0], atol=0.01)
    np.testing.assert_allclose(centres[8] - centres[0], [0.0, 0.3, 0.0], atol=0.01)


def sphere_centre(points: np.ndarray) -> np.ndarray:
    """Least-squares sphere centre: |p|^2 = 2 c.p + (r^2 - |c|^2) is linear in c."""
    design = np.column_stack([2 * points, np.ones(len(points))])
    solution, *_ = np.linalg.lstsq(design, np.sum(points**2, axis=1), rcond=None)
    return solution[:3]


def test_the_walking_camera_sees_the_crate_then_the_bin_in_a_static_scene():
    # period 8 s: frame 0 at the start, frame 4 (4 s at 1 fps) at the far end
    frames = list(render_scene("tabletop_walk", 5, width=WIDTH, height=HEIGHT, fps=1.0))
    travel = np.linalg.norm(frames[4].pose.position - frames[0].pose.position)
    assert travel == pytest.approx(3.2, abs=1e-9)
    names = frames[0].extras["segments"]

    def sees(frame, primitive: str) -> bool:
        ids = [i for i, name in names.items() if name.startswith(primitive + "/")]
        return bool(np.isin(frame.labels, ids).sum() > 20)

    assert sees(frames[0], "crate") and not sees(frames[0], "bin")
    assert sees(frames[4], "bin") and not sees(frames[4], "crate")
    # static world: with the poses, every frame puts the floor at z = 0 and the wall at y = 1.5
    for frame in frames:
        floor = world_points(frame, segment_mask(frame, "floor/surface"))
        wall = world_points(frame, segment_mask(frame, "wall/surface"))
        assert np.abs(np.median(floor[:, 2])) < 0.01
        assert np.abs(np.median(wall[:, 1]) - 1.5) < 0.02


def test_a_recording_carries_poses_and_the_scene_description(tmp_path: Path):
    scene = build_scene("tabletop_vanish")
    path = tmp_path / "vanish.mcap"
    rendered = list(render_scene("tabletop_vanish", 4, width=WIDTH, height=HEIGHT, fps=3.0))
    with RecordingWriter(path) as writer:
        writer.add_metadata(SCENE_METADATA, scene_metadata(scene, 3.0))
        for frame in rendered:
            writer.write_frame(frame)
    restored = list(read_frames(path))
    assert [f.pose.frame_id for f in restored] == ["world"] * 4
    for original, copy in zip(rendered, restored, strict=True):
        np.testing.assert_allclose(copy.pose.matrix, original.pose.matrix, atol=1e-12)
    described = recording_metadata(path)[SCENE_METADATA]
    assert described["scene"] == "tabletop_vanish"
    assert json.loads(described["motions"]) == [
        {"primitive": "red_box", "kind": "vanish", "start_frame": 6, "end_frame": 6,
         "offset_m": [0.0, 0.0, 0.0]}
    ]
    segments = json.loads(described["segments"])
    assert segments == {str(k): v for k, v in rendered[0].extras["segments"].items()}
    # without poses asked for, none are attached
    assert all(f.pose is None for f in read_frames(path, fixed_frame=None))
