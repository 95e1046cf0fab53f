"""The world's up axis follows the data: the cameras' poses, or a static camera's largest
horizontal plane; and the rerun log states it instead of forcing +Z."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gngdt.core.sensor.geometry import quaternion_to_rotation
from gngdt.io.outputs.up_axis import axis_name, nearest_axis, up_from_planes, up_from_rotations
from gngdt.io.synth.motion import look_at
from gngdt.io.synth.render import render_scene


def walk_rotations(frames: int = 60) -> np.ndarray:
    return np.array([frame.pose.matrix[:3, :3] for frame in render_scene(
        "tabletop_walk", frames, width=16, height=12)])


def test_the_poses_of_a_walk_in_a_z_up_world_say_z_is_up() -> None:
    up = up_from_rotations(walk_rotations())
    assert axis_name(*nearest_axis(up)) == "+Z"
    assert up[2] > 0.8  # the camera looks down at the table a little: not exactly +z


def test_the_same_walk_in_a_frame_whose_down_is_y_says_minus_y() -> None:
    # a world like many real captures' (7-Scenes, the real kitchen walk): +y points down
    y_down = quaternion_to_rotation([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])  # +90° about x
    assert np.allclose(y_down @ [0, 0, 1], [0, -1, 0])  # the old up is -y there
    rotations = np.einsum("ij,kjl->kil", y_down, walk_rotations())
    assert axis_name(*nearest_axis(up_from_rotations(rotations))) == "-Y"


def test_no_pose_no_up() -> None:
    assert up_from_rotations(np.zeros((0, 3, 3))) is None


def plane_nodes(normal: np.ndarray, center: np.ndarray, count: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` nodes on a plane through ``center`` with ``normal`` (unit), normals flipped at
    random (a learner's normals have no set sign)."""
    basis = np.linalg.svd(normal[None, :])[2][1:]  # two vectors in the plane
    positions = center + rng.uniform(-0.5, 0.5, (count, 2)) @ basis
    signs = rng.choice([-1.0, 1.0], count)[:, None]
    return positions, normal * signs


@pytest.mark.parametrize(("pitch_deg", "expected"), [(0, "-Y"), (30, "-Y"), (55, "-Z")])
def test_a_static_camera_stands_over_its_largest_horizontal_plane(pitch_deg: float,
                                                                  expected: str) -> None:
    rng = np.random.default_rng(0)
    # a camera pitched down: the table's up, in the camera's frame (x right, y down, z forward)
    pitch = np.radians(pitch_deg)
    pose = look_at(np.array([0.0, 0.0, 1.0]), np.array([0.0, np.cos(pitch), 1 - np.sin(pitch)]))
    world_to_camera = pose[:3, :3].T
    table_up = world_to_camera @ [0.0, 0.0, 1.0]
    table_center = world_to_camera @ ([0.0, 1.0, 0.3] - pose[:3, 3])
    wall_normal = world_to_camera @ [0.0, -1.0, 0.0]
    wall_center = world_to_camera @ ([0.0, 2.0, 1.0] - pose[:3, 3])
    table = plane_nodes(table_up, table_center, 300, rng)
    wall = plane_nodes(wall_normal, wall_center, 500, rng)  # larger, but not horizontal
    positions = np.vstack([table[0], wall[0]])
    normals = np.vstack([table[1], wall[1]])
    labels = np.repeat([0, 1], [300, 500])
    found = up_from_planes(positions, normals, labels)
    assert found is not None and found[1] == 300
    assert np.allclose(found[0], table_up, atol=1e-6)
    assert axis_name(*nearest_axis(found[0])) == expected


def test_curved_or_small_clusters_are_no_floor() -> None:
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(400, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    positions = rng.normal(size=(400, 3)) + np.array([0.0, 0.0, 2.0])
    assert up_from_planes(positions, normals, np.zeros(400, int)) is None  # a sphere
    small = plane_nodes(np.array([0.0, -1.0, 0.0]), np.array([0.0, 1.0, 2.0]), 10, rng)
    assert up_from_planes(*small, np.zeros(10, int)) is None


def test_the_rerun_log_states_the_up_it_found_and_never_forces_z(tmp_path: Path) -> None:
    import rerun as rr
    from rerun.chunk import RrdReader

    from gngdt.io.outputs.rerun_blueprint import EntityPaths
    from gngdt.io.outputs.rerun_log import RerunLog

    path = tmp_path / "up.rrd"
    rec = rr.RecordingStream("gngdt-test")
    rec.save(str(path))
    rerun_log = RerunLog(rec)
    assert axis_name(*rerun_log.up_axis) == "-Y"  # a static camera's own up, to begin with
    y_down = quaternion_to_rotation([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])
    for rotation in walk_rotations(10):
        pose = np.eye(4)
        pose[:3, :3] = y_down @ rotation
        rerun_log.camera_pose(EntityPaths("camera"), pose)
    assert axis_name(*rerun_log.up_axis) == "-Y" and rerun_log.up_from == "the camera poses"
    rec.flush()
    rec.disconnect()
    stated = {}
    for chunk in RrdReader(str(path)).stream().collect().stream():
        if str(chunk.entity_path) == "/world":
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                stated[name] = batch.column(name).to_pylist()[-1]
    coordinates = next(value for name, value in stated.items() if "ViewCoordinates" in name)
    assert [int(v) for v in np.ravel(coordinates)] == [
        v.value for v in rr.ViewCoordinates.RIGHT_HAND_Y_DOWN.coordinates]
    assert np.ravel([value for name, value in stated.items() if "up_axis" in name])[0] == "-Y"


def test_a_static_cameras_rerun_log_takes_up_from_its_table(tmp_path: Path) -> None:
    import rerun as rr

    from gngdt.io.outputs.rerun_blueprint import EntityPaths
    from gngdt.io.outputs.rerun_log import RerunLog
    from gngdt.schemas.topology import TopologySnapshot

    rng = np.random.default_rng(2)
    pitch = np.radians(55)  # looking down at the table steeply: its up is nearest the camera's -z
    table_up = np.array([0.0, -np.cos(pitch), -np.sin(pitch)])
    positions, normals = plane_nodes(table_up, np.array([0.0, 0.5, 1.2]), 200, rng)
    empty = np.zeros((0, 2), np.uint32)
    snapshot = TopologySnapshot(
        positions=positions.astype(np.float32), colors=np.zeros((200, 3), np.uint8),
        normals=normals.astype(np.float32), errors=None,
        edges={name: empty for name in ("pos", "col", "nor")},
        clusterings={"nor": np.zeros(200, np.int32)}, steps=0, frame_sequence=0,
        timestamp_ns=1, frame_id="camera", cluster_counts={"nor": 1})
    rec = rr.RecordingStream("gngdt-test")
    rec.save(str(tmp_path / "static.rrd"))
    rerun_log = RerunLog(rec)
    rerun_log.topology(EntityPaths("camera"), snapshot, draw=True)
    assert axis_name(*rerun_log.up_axis) == "-Z"
    assert rerun_log.up_from == "the largest horizontal plane"
    assert np.allclose(rerun_log.up_vector, table_up)
    rec.disconnect()
