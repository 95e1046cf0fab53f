"""Camera poses in: transform chains and interpolation, /tf in gngdt's layout and in ROS 2 bags,
and what happens when the transforms are bad or never connect."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from helpers.recordings import HEIGHT, INTRINSICS, WIDTH, make_frames
from helpers.ros2_bags import (
    CAMERA_INFO_MSGDEF,
    HEADER_MSGDEF,
    IMAGE_MSGDEF,
    ros_header,
    ros_image,
)
from mcap_ros2.writer import Writer as Ros2Writer
from scipy.spatial.transform import Rotation

from gngdt.io.mcap.reader import read_frames
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.io.tf_tree import (
    TransformError,
    TransformTree,
    matrix_to_pose,
    pose_to_matrix,
)

SECOND = 1_000_000_000


def rigid(rotvec: tuple[float, float, float], translation: tuple[float, float, float]):
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    matrix[:3, 3] = translation
    return matrix


def quaternion(matrix: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(matrix[:3, :3]).as_quat()


# ------------------------------------------------------------------------------ the tree
def test_lookup_interpolates_and_composes_a_chain():
    tree = TransformTree()
    mount = rigid((0.0, 0.0, 0.3), (0.1, 0.0, 0.5))
    tree.add("base", "camera", 0, mount[:3, 3], quaternion(mount), static=True)
    start, end = rigid((0, 0, 0), (0, 0, 0)), rigid((0, 0, 1.0), (2.0, 0, 0))
    tree.add("odom", "base", 0, start[:3, 3], quaternion(start))
    tree.add("odom", "base", 2 * SECOND, end[:3, 3], quaternion(end))
    halfway = rigid((0, 0, 0.5), (1.0, 0, 0))
    np.testing.assert_allclose(tree.lookup("odom", "camera", SECOND), halfway @ mount, atol=1e-12)
    # the other way round, and between two leaves of one tree
    np.testing.assert_allclose(tree.lookup("camera", "odom", SECOND),
                               np.linalg.inv(halfway @ mount), atol=1e-12)
    tree.add("base", "lidar", 0, [0, 0, 1.0], [0, 0, 0, 1], static=True)
    np.testing.assert_allclose(tree.lookup("lidar", "camera", 5)[:3, 3],
                               mount[:3, 3] - [0, 0, 1.0], atol=1e-12)
    assert tree.chain("odom", "camera") == ["odom", "base", "camera"]
    assert tree.chain("map", "camera") is None


def test_lookup_outside_the_samples_names_the_frames():
    tree = TransformTree(max_extrapolation_ns=10)
    for stamp in (0, SECOND):
        tree.add("map", "camera", stamp, [stamp / SECOND, 0, 0], [0, 0, 0, 1])
    assert tree.lookup("map", "camera", SECOND + 10)[0, 3] == 1.0  # held within the tolerance
    with pytest.raises(TransformError, match=r"'map' -> 'camera'.*1\.000 s"):
        tree.lookup("map", "camera", 2 * SECOND)
    with pytest.raises(TransformError, match="no transform chain from 'world' to 'camera'"):
        tree.lookup("world", "camera", 0)


@pytest.mark.parametrize(
    ("parent", "child", "translation", "rotation", "message"),
    [
        ("map", "camera", [0, 0, 0], [0, 0, 0, 2.0], "norm 2.0000"),
        ("map", "camera", [0, 0, 0], [1, 0, 0, 1], "not 1"),
        ("map", "camera", [0, np.nan, 0], [0, 0, 0, 1], "translation"),
        ("map", "map", [0, 0, 0], [0, 0, 0, 1], "different"),
        ("", "camera", [0, 0, 0], [0, 0, 0, 1], "non-empty"),
    ],
)
def test_bad_transforms_are_refused_with_their_frames(parent, child, translation, rotation,
                                                      message):
    with pytest.raises(TransformError, match=message) as error:
        TransformTree().add(parent, child, 0, translation, rotation)
    assert f"{parent!r} -> {child!r}" in str(error.value)


def test_a_nearly_unit_quaternion_is_normalised():
    tree = TransformTree()
    tree.add("map", "camera", 0, [0, 0, 0], [0, 0, 0, 1.004])
    np.testing.assert_allclose(tree.lookup("map", "camera", 0), np.eye(4), atol=1e-12)


def test_a_second_parent_and_a_loop_are_refused():
    tree = TransformTree()
    tree.add("map", "odom", 0, [0, 0, 0], [0, 0, 0, 1])
    with pytest.raises(TransformError, match="already has the parent 'map'"):
        tree.add("world", "odom", 0, [0, 0, 0], [0, 0, 0, 1])
    with pytest.raises(TransformError, match="loop"):
        tree.add("odom", "map", 0, [0, 0, 0], [0, 0, 0, 1])


# ------------------------------------------------------------------ gngdt's own layout
def test_a_foxglove_chain_is_resolved_at_each_image_time(tmp_path: Path):
    """world -> rig (dynamic, at other times than the images) -> camera (once, static-like)."""
    frames = make_frames(3)
    path = tmp_path / "chain.mcap"
    mount = rigid((0.1, 0.2, 0.3), (0.0, 0.1, 0.2))

    def rig(stamp_ns: int) -> np.ndarray:
        seconds = (stamp_ns - frames[0].timestamp_ns) / SECOND
        return rigid((0, 0, 0.2 * seconds), (seconds, 0, 1.0))

    with RecordingWriter(path) as writer:
        writer.write_transform(mount, "rig", "camera", frames[0].timestamp_ns, topic="/tf_static")
        for frame in frames:
            before = frame.timestamp_ns - 5_000_000
            writer.write_transform(rig(before), "world", "rig", before)
            writer.write_transform(rig(before + 10_000_000), "world", "rig", before + 10_000_000)
            writer.write_frame(frame)
    restored = list(read_frames(path))
    for frame in restored:  # halfway between two samples: exact for this constant-rate motion
        assert frame.pose.frame_id == "world"
        np.testing.assert_allclose(frame.pose.matrix, rig(frame.timestamp_ns) @ mount, atol=1e-9)


def test_a_chain_that_never_connects_warns_naming_the_frames(tmp_path: Path, caplog):
    frames = make_frames(2)
    path = tmp_path / "disconnected.mcap"
    with RecordingWriter(path, frame_id="camera_optical") as writer:
        for frame in frames:
            writer.write_transform(np.eye(4), "map", "base_link", frame.timestamp_ns)
            writer.write_frame(frame)
    with caplog.at_level(logging.WARNING):
        restored = list(read_frames(path))
    assert len(restored) == 2 and all(frame.pose is None for frame in restored)
    assert "never connect" in caplog.text and "'camera_optical'" in caplog.text
    assert "base_link" in caplog.text


def test_a_bad_transform_is_skipped_with_a_warning_and_the_rest_is_used(tmp_path: Path, caplog):
    """A hand-written recording: good /tf for every frame plus one stretched quaternion."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from mcap_protobuf.writer import Writer

    from gngdt.schemas.clouds import pose_to_transform
    from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration

    frames = make_frames(2)
    path = tmp_path / "bad_quaternion.mcap"
    pose = rigid((0, 0, 0.4), (1, 2, 3))
    with open(path, "wb") as stream:
        writer = Writer(stream)
        for frame in frames:
            stamp = frame.timestamp_ns
            bad = FrameTransform(parent_frame_id="world", child_frame_id="camera")
            bad.rotation.w = 3.0
            messages = [
                ("/tf", bad),
                ("/tf", pose_to_transform(pose, "world", "camera", timestamp_ns=stamp)),
                ("/camera/calibration", intrinsics_to_calibration(
                    frame.intrinsics, timestamp_ns=stamp, frame_id="camera")),
                ("/camera/depth", image_to_raw(frame.depth, timestamp_ns=stamp,
                                               frame_id="camera")),
                ("/camera/color", image_to_raw(frame.color, timestamp_ns=stamp,
                                               frame_id="camera")),
            ]
            for topic, message in messages:
                writer.write_message(topic, message, log_time=stamp, publish_time=stamp)
        writer.finish()
    with caplog.at_level(logging.WARNING):
        restored = list(read_frames(path))
    assert "'world' -> 'camera'" in caplog.text and "norm 3.0000" in caplog.text
    assert len(restored) == 2
    for frame in restored:
        np.testing.assert_allclose(frame.pose.matrix, pose, atol=1e-12)


# ------------------------------------------------------------------------------- ROS 2
TF_MSGDEF = (
    """geometry_msgs/TransformStamped[] transforms
================================================================================
MSG: geometry_msgs/TransformStamped
std_msgs/Header header
string child_frame_id
geometry_msgs/Transform transform
================================================================================
MSG: geometry_msgs/Transform
geometry_msgs/Vector3 translation
geometry_msgs/Quaternion rotation
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w"""
    + HEADER_MSGDEF
)


def _stamped(parent: str, child: str, stamp_ns: int, matrix: np.ndarray) -> dict:
    header = ros_header(stamp_ns)
    header["frame_id"] = parent
    x, y, z = matrix[:3, 3]
    qx, qy, qz, qw = quaternion(matrix)
    return {
        "header": header,
        "child_frame_id": child,
        "transform": {"translation": {"x": x, "y": y, "z": z},
                      "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}},
    }


def write_posed_ros_bag(path: Path, frames, odom_from_base, base_from_optical,
                        tf_period_ns: int = 10_000_000) -> None:
    """A robot bag: /tf odom -> base_link at 100 Hz (not at the image stamps), /tf_static
    base_link -> camera_link -> camera_color_optical, images in camera_color_optical."""
    with open(path, "wb") as stream:
        writer = Ros2Writer(stream)
        image_schema = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE_MSGDEF)
        info_schema = writer.register_msgdef("sensor_msgs/msg/CameraInfo", CAMERA_INFO_MSGDEF)
        tf_schema = writer.register_msgdef("tf2_msgs/msg/TFMessage", TF_MSGDEF)
        first = frames[0].timestamp_ns
        link = rigid((0, 0, 0), (0.2, 0.0, 0.3))
        optical = np.linalg.inv(link) @ base_from_optical
        writer.write_message("/tf_static", tf_schema, {"transforms": [
            _stamped("base_link", "camera_link", first, link),
            _stamped("camera_link", "camera_color_optical", first, optical),
        ]}, log_time=first - 1)
        stamp = first - 3_000_000
        for frame in frames:
            while stamp <= frame.timestamp_ns + tf_period_ns:
                writer.write_message("/tf", tf_schema, {"transforms": [
                    _stamped("odom", "base_link", stamp, odom_from_base(stamp))]}, log_time=stamp)
                stamp += tf_period_ns
            writer.write_message("/camera/color/image_raw", image_schema,
                                 ros_image(frame.timestamp_ns, frame.color, "rgb8"),
                                 log_time=frame.timestamp_ns + 10)
            k = INTRINSICS.matrix().ravel().tolist()
            writer.write_message("/camera/color/camera_info", info_schema, {
                "header": ros_header(frame.timestamp_ns), "height": HEIGHT, "width": WIDTH,
                "distortion_model": "plumb_bob", "d": [0.0] * 5, "k": k,
                "r": np.eye(3).ravel().tolist(), "p": [*k[:3], 0, *k[3:6], 0, *k[6:], 0],
                "binning_x": 0, "binning_y": 0,
                "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0,
                        "do_rectify": False}}, log_time=frame.timestamp_ns + 20)
            writer.write_message("/camera/aligned_depth_to_color/image_raw", image_schema,
                                 ros_image(frame.timestamp_ns, frame.depth, "16UC1"),
                                 log_time=frame.timestamp_ns + 30)
        writer.finish()


def test_a_ros2_bag_gives_poses_through_tf_and_tf_static(tmp_path: Path, caplog):
    frames = make_frames(3)
    first = frames[0].timestamp_ns

    def odom_from_base(stamp_ns: int) -> np.ndarray:
        seconds = (stamp_ns - first) / SECOND
        return rigid((0, 0, 0.3 * seconds), (0.5 * seconds, 0.1 * seconds, 0.0))

    base_from_optical = rigid((-np.pi / 2, 0, -np.pi / 2), (0.2, 0.0, 0.3))  # z forward
    path = tmp_path / "robot.mcap"
    write_posed_ros_bag(path, frames, odom_from_base, base_from_optical)
    with caplog.at_level(logging.INFO):
        restored = list(read_frames(path))
    assert "'odom'" in caplog.text and "odom -> base_link -> camera_link" in caplog.text
    for frame in restored:
        assert frame.pose.frame_id == "odom"  # auto: no world or map, so odom
        expected = odom_from_base(frame.timestamp_ns) @ base_from_optical
        np.testing.assert_allclose(frame.pose.matrix, expected, atol=1e-6)
    named = list(read_frames(path, fixed_frame="base_link"))
    np.testing.assert_allclose(named[1].pose.matrix, base_from_optical, atol=1e-9)


def test_pose_matrix_validation_is_shared_with_the_tree():
    with pytest.raises(TransformError, match="norm"):
        pose_to_matrix([0, 0, 0], [0, 0, 0, 0])


def test_quaternion_conversions_agree_with_scipy():
    rng = np.random.default_rng(7)
    rotations = Rotation.random(200, random_state=7)
    # also the awkward ones: half turns about each axis, identity, near-half turns
    special = Rotation.from_rotvec(np.pi * np.eye(3) * (1 - 1e-9)).as_quat()
    quaternions = np.vstack([rotations.as_quat(), special, [0, 0, 0, 1], [1, 0, 0, 0]])
    for q in quaternions:
        translation = rng.normal(size=3)
        matrix = pose_to_matrix(translation, q)
        np.testing.assert_allclose(matrix[:3, :3], Rotation.from_quat(q).as_matrix(), atol=1e-12)
        back_t, back_q = matrix_to_pose(matrix)
        np.testing.assert_allclose(back_t, translation)
        np.testing.assert_allclose(Rotation.from_quat(back_q).as_matrix(), matrix[:3, :3],
                                   atol=1e-12)
        assert back_q[3] >= 0
    # interpolation follows scipy's Slerp, the shorter way round
    tree = TransformTree()
    q0, q1 = rotations[0].as_quat(), -rotations[1].as_quat()  # opposite sign, same rotation
    tree.add("map", "camera", 0, [0, 0, 0], q0)
    tree.add("map", "camera", SECOND, [0, 0, 0], q1)
    from scipy.spatial.transform import Slerp

    expected = Slerp([0, 1], Rotation.from_quat([q0, q1]))(0.3).as_matrix()
    np.testing.assert_allclose(tree.lookup("map", "camera", int(0.3 * SECOND))[:3, :3],
                               expected, atol=1e-9)
