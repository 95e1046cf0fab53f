"""The robot side of the ROS 2 tests: zenoh-ros2-sdk, an rmw_zenoh client written by others from
rmw_zenoh's design (its own keys, tokens, attachment and CDR through rosbags), never gngdt's wire
code. No ROS 2, `ros2` CLI or rmw_zenohd can be installed here; this is the stand-in.

The SDK looks message definitions up in a registry, which would otherwise git-clone ROS's
interface repositories: it is given local ``pkg/msg/Type.msg`` files, split from rosbags' Jazzy
definitions, and a private cache folder, so it never reaches the network. Its session is one
per process (the first router wins) and its registry global: `sdk_session` sets both up and
resets them.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

#: every message type gngdt's bridge sends or takes
ROS_TYPES = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/PointCloud2",
    "visualization_msgs/msg/MarkerArray",
    "tf2_msgs/msg/TFMessage",
    "diagnostic_msgs/msg/DiagnosticArray",
)


def write_message_definitions(root: Path, types: tuple[str, ...] = ROS_TYPES) -> None:
    """``root/<pkg>/msg/<Type>.msg`` for ``types`` and everything they use, from rosbags'
    ROS 2 Jazzy store (``generate_msgdef`` concatenates them, split by lines of 80 ``=``)."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    separator = "=" * 80 + "\n"
    for ros_type in types:
        text, _ = store.generate_msgdef(ros_type, ros_version=2)
        name = ros_type
        for index, section in enumerate(text.split(separator)):
            if index:
                first, _, section = section.partition("\n")
                package, type_name = first.removeprefix("MSG: ").split("/")
                name = f"{package}/msg/{type_name}"
            package, _, type_name = name.split("/")
            path = root / package / "msg" / f"{type_name}.msg"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(section)


@contextlib.contextmanager
def sdk_session(router_port: int, folder: Path) -> Iterator[ModuleType]:
    """The SDK (module), its session connected to the router on ``127.0.0.1:router_port``,
    its message definitions and cache in ``folder``."""
    import zenoh_ros2_sdk
    from zenoh_ros2_sdk import message_registry
    from zenoh_ros2_sdk.session import ZenohSession

    definitions = folder / "msg-definitions"
    write_message_definitions(definitions)
    previous_cache = os.environ.get("ZENOH_ROS2_SDK_CACHE")
    os.environ["ZENOH_ROS2_SDK_CACHE"] = str(folder / "sdk-cache")  # never cloned into
    message_registry._registry = None
    message_registry.get_registry(str(definitions))
    ZenohSession.get_instance("127.0.0.1", router_port)
    try:
        yield zenoh_ros2_sdk
    finally:
        ZenohSession.get_instance().close()
        message_registry._registry = None
        if previous_cache is None:
            os.environ.pop("ZENOH_ROS2_SDK_CACHE", None)
        else:
            os.environ["ZENOH_ROS2_SDK_CACHE"] = previous_cache


def message_class(ros_type: str) -> type:
    """The SDK's (rosbags) class of a message type, for building nested fields."""
    from zenoh_ros2_sdk import get_message_class

    found = get_message_class(ros_type)
    assert found is not None, f"the SDK has no definition of {ros_type}"
    return found
