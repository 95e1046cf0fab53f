"""The real rclpy (ROS 2 Jazzy's wheels, in their own venv) as codec oracle: every message gngdt
publishes, decoded by ROS 2's own code (``rclpy.serialization.deserialize_message``) field by
field; messages rclpy serialises, read by gngdt; type hashes equal to those the ROS packages
ship (``share/<pkg>/msg/<Type>.json``). Fast-CDR leaves padding bytes uninitialised, so decoded
fields are compared, not bytes.

Not covered here: tf2_msgs/TFMessage (no ros-jazzy-tf2-msgs wheel on the package index; rosbags,
mcap-ros2 and zenoh-ros2-sdk decode it in the other tests).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.ros2 import markers as mk
from gngdt.io.ros2 import messages as m

REPO_ROOT = Path(__file__).resolve().parents[2]
ORACLE_PYTHON = REPO_ROOT / ".venv-ros2-oracle" / "bin" / "python"
ORACLE_SCRIPT = REPO_ROOT / "tests" / "helpers" / "ros2_oracle.py"
HOW_TO_CREATE = ("python3 -m venv .venv-ros2-oracle && .venv-ros2-oracle/bin/pip install -r "
                 "tests/ros2-oracle-requirements.txt (in the repository; .ci/run does it)")


def oracle(*arguments: str) -> object:
    """Run the oracle script with the real rclpy; its JSON answer."""
    if not ORACLE_PYTHON.exists():
        pytest.skip(f"the rclpy oracle venv {ORACLE_PYTHON.parent.parent} is absent; create it: "
                    f"{HOW_TO_CREATE}")
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("RMW_IMPLEMENTATION", "PYTHONPATH", "PYTHONHOME")}
    done = subprocess.run([str(ORACLE_PYTHON), str(ORACLE_SCRIPT), *arguments],
                          capture_output=True, text=True, timeout=120, env=environment,
                          check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def decoded_by_rclpy(tmp_path: Path, messages: dict[str, tuple[str, bytes]]) -> dict:
    manifest = {}
    for name, (ros_type, data) in messages.items():
        (tmp_path / f"{name}.cdr").write_bytes(data)
        manifest[name] = ros_type
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    return oracle("decode", str(tmp_path))


def cloud_columns(message: dict) -> dict[str, np.ndarray]:
    kinds = {6: "<u4", 7: "<f4"}
    raw = np.array(message["data"], np.uint8).reshape(message["width"], message["point_step"])
    return {f["name"]: raw[:, f["offset"]:f["offset"] + 4].copy().view(kinds[f["datatype"]])[:, 0]
            for f in message["fields"]}


def test_type_hashes_equal_the_ros_packages() -> None:
    types = [m.POINT_CLOUD2, m.IMAGE, m.CAMERA_INFO, m.MARKER_ARRAY, m.DIAGNOSTIC_ARRAY]
    shipped = oracle("hashes", *types)
    assert shipped == {ros_type: m.type_hash(ros_type) for ros_type in types}


def test_published_messages_decoded_by_rclpy(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    positions = rng.normal(size=(30, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (30, 3), dtype=np.uint8)
    normals = rng.normal(size=(30, 3)).astype(np.float32)
    labels = {"pos": rng.integers(-1, 4, 30), "col+nor": rng.integers(0, 3, 30)}
    objects = [mk.ObjectMarker(4, (0.1, 0.2, 1.5), (0.3, 0.2, 0.1), (0.0, 0.0, 0.6, 0.8),
                               (0.2, 0.4, 0.6, 0.35), "#4")]
    messages = {
        "points": (m.POINT_CLOUD2, m.encode_pointcloud2(
            positions, colors=colors, stamp_ns=3_000_000_007, frame_id="camera")),
        "nodes": (m.POINT_CLOUD2, m.encode_pointcloud2(
            positions, colors=colors, normals=normals, labels=labels, stamp_ns=5,
            frame_id="world")),
        "graph": (m.MARKER_ARRAY, mk.encode_graph_markers(
            positions, {"pos": (np.array([[0, 1], [2, 3]]),
                                np.array([[255, 0, 0], [0, 255, 0]], np.uint8)),
                        "col": (np.zeros((0, 2), np.int64), np.zeros((0, 3), np.uint8))},
            stamp_ns=6, frame_id="world")),
        "objects": (m.MARKER_ARRAY, mk.encode_object_markers(
            objects, gone_ids=[9], stamp_ns=7, frame_id="world")),
        "status": (m.DIAGNOSTIC_ARRAY, m.encode_diagnostics(
            [m.Status("gngdt/camera/ros2", m.WARN, "skipped 2", "camera", {"k": 1})],
            stamp_ns=8)),
    }
    got = decoded_by_rclpy(tmp_path, messages)

    points = got["points"]
    assert points["header"] == {"stamp": {"sec": 3, "nanosec": 7}, "frame_id": "camera"}
    assert [f["name"] for f in points["fields"]] == ["x", "y", "z", "rgb"]
    columns = cloud_columns(points)
    np.testing.assert_array_equal(np.stack([columns[a] for a in "xyz"], 1), positions)
    rgb = columns["rgb"].view(np.uint32)
    np.testing.assert_array_equal(np.stack([rgb >> 16, (rgb >> 8) & 255, rgb & 255], 1), colors)

    nodes = got["nodes"]
    assert (nodes["height"], nodes["width"], nodes["point_step"], nodes["is_dense"]) == (
        1, 30, 36, True)
    assert [(f["name"], f["datatype"]) for f in nodes["fields"]][-2:] == [
        ("label_pos", 6), ("label_col_nor", 6)]
    columns = cloud_columns(nodes)
    np.testing.assert_array_equal(np.stack([columns[f"normal_{a}"] for a in "xyz"], 1), normals)
    np.testing.assert_array_equal(columns["label_pos"], labels["pos"].astype(np.uint32))
    np.testing.assert_array_equal(columns["label_col_nor"], labels["col+nor"])

    lines, deleted = got["graph"]["markers"]
    assert (lines["ns"], lines["type"], lines["action"]) == ("pos", 5, 0)
    assert (deleted["ns"], deleted["action"]) == ("col", 2)
    np.testing.assert_allclose([[p["x"], p["y"], p["z"]] for p in lines["points"]],
                               positions[[0, 1, 2, 3]], rtol=1e-6)
    assert [[c["r"], c["g"], c["b"], c["a"]] for c in lines["colors"]] == [
        [1, 0, 0, 1], [1, 0, 0, 1], [0, 1, 0, 1], [0, 1, 0, 1]]

    cube, text, gone_cube, gone_text = got["objects"]["markers"]
    assert [(x["ns"], x["id"], x["type"], x["action"]) for x in (cube, text, gone_cube,
                                                               gone_text)] == [
        ("objects", 4, 1, 0), ("object_labels", 4, 9, 0), ("objects", 9, 1, 2),
        ("object_labels", 9, 9, 2)]
    assert cube["pose"] == {"position": {"x": 0.1, "y": 0.2, "z": 1.5},
                            "orientation": {"x": 0.0, "y": 0.0, "z": 0.6, "w": 0.8}}
    assert cube["scale"] == pytest.approx({"x": 0.3, "y": 0.2, "z": 0.1})
    assert cube["color"] == pytest.approx({"r": 0.2, "g": 0.4, "b": 0.6, "a": 0.35})
    assert text["text"] == "#4" and cube["header"]["frame_id"] == "world"

    status = got["status"]["status"][0]
    assert (status["level"], status["name"], status["message"], status["hardware_id"]) == (
        [m.WARN], "gngdt/camera/ros2", "skipped 2", "camera")  # 'byte': bytes in rclpy
    assert status["values"] == [{"key": "k", "value": "1"}]


def test_messages_serialised_by_rclpy_read_by_gngdt(tmp_path: Path) -> None:
    put_in = oracle("serialize", str(tmp_path))
    depth = m.decode_image((tmp_path / "depth.cdr").read_bytes(), max_pixels=100)
    assert (depth.stamp_ns, depth.frame_id, depth.encoding) == (
        12_000_000_034, "camera_color_optical_frame", "16UC1")
    np.testing.assert_array_equal(depth.pixels, np.array(put_in["depth"], np.uint16))
    color = m.decode_image((tmp_path / "color.cdr").read_bytes(), max_pixels=100)
    np.testing.assert_array_equal(color.pixels, np.array([put_in["color_rgb"]], np.uint8))
    info = m.decode_camera_info((tmp_path / "camera_info.cdr").read_bytes())
    assert info.intrinsics == CameraIntrinsics(640, 480, 615.0, 616.0, 320.5, 240.5,
                                               (0.1, 0.0, 0.0, 0.0, 0.0))
