"""gngdt's ROS 2 node on a real loopback router: its liveliness tokens come and go as ROS 2's
graph expects, every sample carries rmw_zenoh's attachment, a TRANSIENT_LOCAL subscription gets
a late publisher's history, and an independent rmw_zenoh client (zenoh-ros2-sdk) exchanges
messages with it both ways and sees its topics."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh
from helpers.ros2_sdk import message_class, sdk_session

from gngdt.io.ros2 import messages as m
from gngdt.io.ros2 import wire as w
from gngdt.io.ros2.node import Ros2Node
from gngdt.services.plumbing.session import client_config, open_config


def wait_for(condition: Callable[[], object], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.02)


@pytest.fixture
def session(router_endpoint: str) -> Iterator[zenoh.Session]:
    opened = open_config(client_config([router_endpoint]))
    yield opened
    opened.close()


def ros_tokens(session: zenoh.Session, domain: int) -> set[str]:
    return {str(reply.ok.key_expr) for reply in
            session.liveliness().get(w.liveliness_subscription_key(domain), timeout=2.0)
            if reply.ok is not None}


def test_tokens_appear_and_go(router_endpoint: str, session: zenoh.Session) -> None:
    observer = open_config(client_config([router_endpoint]))
    try:
        node = Ros2Node(session, "gngdt_cam0", domain_id=3)
        points = node.create_publisher("/gngdt/cam0/points", m.POINT_CLOUD2,
                                       m.type_hash(m.POINT_CLOUD2))
        info = node.create_subscription("/camera/camera/color/camera_info", m.CAMERA_INFO,
                                        m.type_hash(m.CAMERA_INFO), lambda *_: None,
                                        qos=w.QOS_SENSOR_DATA)
        expected = {node.token_key, points.token_key, info.token_key}
        wait_for(lambda: expected <= ros_tokens(observer, 3))
        zid = str(session.info.zid())
        assert node.token_key == f"@ros2_lv/3/{zid}/0/0/NN/%/%/gngdt_cam0"
        assert points.token_key == (
            f"@ros2_lv/3/{zid}/0/1/MP/%/%/gngdt_cam0/%gngdt%cam0%points/"
            f"sensor_msgs::msg::dds_::PointCloud2_/{m.type_hash(m.POINT_CLOUD2)}/::,10:,:,:,,")
        assert info.token_key.endswith(f"/0/2/MS/%/%/gngdt_cam0/%camera%camera%color%camera_info"
                                       f"/sensor_msgs::msg::dds_::CameraInfo_/"
                                       f"{m.type_hash(m.CAMERA_INFO)}/2::,5:,:,:,,")
        assert points.key == (f"3/gngdt/cam0/points/sensor_msgs::msg::dds_::PointCloud2_/"
                              f"{m.type_hash(m.POINT_CLOUD2)}")
        assert not ros_tokens(observer, 0)  # another domain sees nothing
        node.close()
        wait_for(lambda: not ros_tokens(observer, 3))
    finally:
        observer.close()


def test_samples_carry_the_attachment(router_endpoint: str, session: zenoh.Session) -> None:
    other = open_config(client_config([router_endpoint]))
    got: list[tuple[bytes, w.Attachment | None]] = []
    try:
        listener = Ros2Node(other, "listener")
        listener.create_subscription("/tf", m.TF_MESSAGE, m.type_hash(m.TF_MESSAGE),
                                     lambda payload, attachment: got.append((payload, attachment)),
                                     qos=w.QOS_TF)
        talker = Ros2Node(session, "gngdt_cam0")
        tf = talker.create_publisher("/tf", m.TF_MESSAGE, m.type_hash(m.TF_MESSAGE), w.QOS_TF)
        wait_for(lambda: tf.has_subscribers)
        transform = m.Transform("world", "camera", 10, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
        tf.publish(m.encode_tf([transform]), source_time_ns=123)
        tf.publish(m.encode_tf([transform]))
        wait_for(lambda: len(got) == 2)
        (payload, first), (_, second) = got
        assert m.decode_tf(payload) == [transform]
        assert first is not None and second is not None
        assert (first.sequence_number, second.sequence_number) == (1, 2)  # rmw_zenoh starts at 1
        assert first.source_timestamp_ns == 123
        assert abs(second.source_timestamp_ns - time.time_ns()) < 10e9
        assert first.gid == second.gid == w.gid_from_token(tf.token_key)
        talker.close()
        listener.close()
    finally:
        other.close()


def test_transient_local_subscription_gets_late_publishers_history(
        router_endpoint: str, session: zenoh.Session) -> None:
    """rmw_zenoh's TRANSIENT_LOCAL publisher (``/tf_static``) is a zenoh advanced publisher
    with a cache and publisher detection; the subscription declared after it gets its past."""
    import zenoh.ext

    config = client_config([router_endpoint])
    config.insert_json5("timestamping/enabled", "true")  # a cache needs timestamps
    robot = open_config(config)
    got: list[bytes] = []
    try:
        key = w.topic_keyexpr(0, "/tf_static", m.TF_MESSAGE, m.type_hash(m.TF_MESSAGE))
        static = zenoh.ext.declare_advanced_publisher(
            robot, key, cache=zenoh.ext.CacheConfig(max_samples=1), publisher_detection=True)
        extrinsics = m.Transform("camera_link", "camera_color_optical_frame", 0,
                                 (0.0, 0.015, 0.0), (-0.5, 0.5, -0.5, 0.5))
        static.put(m.encode_tf([extrinsics]), attachment=w.encode_attachment(1, 1, bytes(16)))
        node = Ros2Node(session, "gngdt_cam0")
        node.create_subscription("/tf_static", m.TF_MESSAGE, m.type_hash(m.TF_MESSAGE),
                                 lambda payload, _: got.append(payload),
                                 qos=w.Qos(durability=w.Durability.TRANSIENT_LOCAL, depth=100))
        wait_for(lambda: got)
        assert m.decode_tf(got[0]) == [extrinsics]
        node.close()
        static.undeclare()
    finally:
        robot.close()


def test_an_independent_client_and_our_node(router_endpoint: str, session: zenoh.Session,
                                            tmp_path: Path) -> None:
    port = int(router_endpoint.rsplit(":", 1)[1])
    clouds, frames, lock = [], [], threading.Lock()
    node = Ros2Node(session, "gngdt_cam0")
    with sdk_session(port, tmp_path) as sdk:
        subscriber = sdk.ROS2Subscriber("/gngdt/cam0/nodes", m.POINT_CLOUD2,
                                        callback=clouds.append, router_port=port)
        depth_pub = sdk.ROS2Publisher("/camera/camera/aligned_depth_to_color/image_raw", m.IMAGE,
                                      router_port=port, node_name="camera")
        try:
            nodes = node.create_publisher("/gngdt/cam0/nodes", m.POINT_CLOUD2,
                                          m.type_hash(m.POINT_CLOUD2))
            # the SDK computed the key (type name, RIHS01 hash) on its own
            assert subscriber.keyexpr == nodes.key
            node.create_subscription(
                "/camera/camera/aligned_depth_to_color/image_raw", m.IMAGE, m.type_hash(m.IMAGE),
                lambda payload, attachment: frames.append((m.decode_image(payload, 100),
                                                           attachment)))
            wait_for(lambda: nodes.has_subscribers)
            positions = np.arange(12, dtype=np.float32).reshape(4, 3)
            nodes.publish(m.encode_pointcloud2(
                positions, colors=np.full((4, 3), 200, np.uint8), labels={"pos": [0, 0, 1, -1]},
                stamp_ns=7, frame_id="world"))
            wait_for(lambda: clouds)
            assert (clouds[0].width, clouds[0].point_step, clouds[0].header.frame_id) == (
                4, 20, "world")
            assert [f.name for f in clouds[0].fields] == ["x", "y", "z", "rgb", "label_pos"]

            header = message_class("std_msgs/msg/Header")(
                stamp=message_class("builtin_interfaces/msg/Time")(sec=5, nanosec=1),
                frame_id="optical")
            depth = np.array([[0, 1000, 2000], [3000, 4000, 65535]], np.uint16)
            deadline = time.monotonic() + 10
            while not frames:  # the SDK publisher has no matching status: publish until heard
                assert time.monotonic() < deadline
                depth_pub.publish(header=header, height=2, width=3, encoding="16UC1",
                                  is_bigendian=0, step=6, data=depth.reshape(-1).view(np.uint8))
                time.sleep(0.1)
            with lock:
                image, attachment = frames[0]
            np.testing.assert_array_equal(image.pixels, depth)
            assert image.stamp_ns == 5_000_000_001
            assert attachment is not None and len(attachment.gid) == 16

            graph = dict(sdk.get_topic_names_and_types(router_port=port, timeout=1.0))
            assert graph["/gngdt/cam0/nodes"] == [m.POINT_CLOUD2]
            assert graph["/camera/camera/aligned_depth_to_color/image_raw"] == [m.IMAGE]
            info = sdk.get_topic_info("/gngdt/cam0/nodes", router_port=port, timeout=1.0,
                                      verbose=True)
            assert [(p.node_name, p.node_namespace) for p in info.publishers] == [
                ("gngdt_cam0", "/")]
        finally:
            node.close()
            subscriber.close()
            depth_pub.close()
