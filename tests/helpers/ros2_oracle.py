"""Run by the real rclpy's Python (its own venv, .venv-ros2-oracle; see
tests/ros2-oracle-requirements.txt), never imported by gngdt's: ROS 2's own message code as a
codec oracle. Standard library and the ROS packages only.

    python ros2_oracle.py decode DIR      # DIR/manifest.json {name: ros type}, DIR/<name>.cdr
    python ros2_oracle.py serialize DIR   # writes messages made by rclpy: DIR/<name>.cdr
    python ros2_oracle.py hashes TYPE...  # RIHS01 hashes from the packages' share/*/msg/*.json

Prints JSON on stdout: decoded messages as plain values (fields by name; byte sequences as
lists of ints), or {type: hash}.
"""

from __future__ import annotations

import array
import importlib
import json
import sys
from pathlib import Path


def message_class(ros_type: str) -> type:
    package, kind, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def plain(value: object) -> object:
    """A ROS message (or field value) as JSON-able values."""
    if hasattr(value, "get_fields_and_field_types"):
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, bytes | bytearray):
        return list(value)
    if isinstance(value, array.array) or hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [plain(item) for item in value]
    return value


def decode(folder: Path) -> dict:
    from rclpy.serialization import deserialize_message

    manifest = json.loads((folder / "manifest.json").read_text())
    return {name: plain(deserialize_message((folder / f"{name}.cdr").read_bytes(),
                                            message_class(ros_type)))
            for name, ros_type in manifest.items()}


def serialize(folder: Path) -> dict:
    """Messages as a driver written with rclpy sends them; what was put in, for the test."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import CameraInfo, Image

    depth = Image()
    depth.header.frame_id = "camera_color_optical_frame"
    depth.header.stamp.sec, depth.header.stamp.nanosec = 12, 34
    depth.height, depth.width, depth.encoding, depth.step = 2, 3, "16UC1", 8  # padded rows
    millimetres = [[1, 2, 3], [400, 500, 65535]]
    rows = b"".join(b"".join(v.to_bytes(2, "little") for v in row) + b"\xee\xee"
                    for row in millimetres)
    depth.data = rows
    color = Image()
    color.header.frame_id = "camera_color_optical_frame"
    color.height, color.width, color.encoding, color.step = 1, 2, "bgr8", 6
    color.data = bytes([10, 20, 30, 40, 50, 60])  # b, g, r per pixel
    info = CameraInfo()
    info.header.frame_id = "camera_color_optical_frame"
    info.width, info.height = 640, 480
    info.k = [615.0, 0.0, 320.5, 0.0, 616.0, 240.5, 0.0, 0.0, 1.0]
    info.distortion_model = "plumb_bob"
    info.d = [0.1, 0.0, 0.0, 0.0, 0.0]
    for name, message in (("depth", depth), ("color", color), ("camera_info", info)):
        (folder / f"{name}.cdr").write_bytes(serialize_message(message))
    return {"depth": millimetres, "color_rgb": [[30, 20, 10], [60, 50, 40]]}


def hashes(types: list[str]) -> dict:
    """Each type's own hash, from ``<prefix>/share/<pkg>/msg/<Type>.json`` (None: not installed)."""
    found = {}
    for ros_type in types:
        package, kind, name = ros_type.split("/")
        path = Path(sys.prefix) / "share" / package / kind / f"{name}.json"
        if not path.is_file():
            found[ros_type] = None
            continue
        entries = json.loads(path.read_text())["type_hashes"]
        found[ros_type] = next(entry["hash_string"] for entry in entries
                               if entry["type_name"] == ros_type)
    return found


if __name__ == "__main__":
    command, *arguments = sys.argv[1:]
    if command == "decode":
        result = decode(Path(arguments[0]))
    elif command == "serialize":
        result = serialize(Path(arguments[0]))
    else:
        result = hashes(arguments)
    json.dump(result, sys.stdout)
