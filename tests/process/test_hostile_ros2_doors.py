"""`gngdt ros2` under a hostile or careless robot side (issue 38), written with zenoh-ros2-sdk
(tests/ros2_sdk.py): CameraInfo with finite absurd values, a /tf stamp in 2038. The bridge
refuses and counts them, says so once, and nothing reaches the learner's map; the good frames
around them go on."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import log_text, wait_for
from helpers.ros2_sdk import message_class, sdk_session

from gngdt.schemas.topology import decode_topology
from gngdt.services.plumbing.session import client_config, open_config

COLOR, DEPTH, INFO = ("/camera/camera/color/image_raw",
                      "/camera/camera/aligned_depth_to_color/image_raw",
                      "/camera/camera/color/camera_info")
OPTICAL = "camera_color_optical_frame"
WIDTH, HEIGHT = 160, 120
CAMERA = {"fx": 150.0, "fy": 150.0, "cx": 79.5, "cy": 59.5}
#: 2038-01-19: the decoy's stamp in the issue
YEAR_2038_NS = 2_147_483_000 * 1_000_000_000


def frame_pixels(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(colour (H, W, 3) uint8, depth (H, W) uint16 mm): a wall 0.9-1.1 m away."""
    rng = np.random.default_rng(seed)
    depth = (900 + 200 * np.linspace(0, 1, WIDTH)[None, :] + np.zeros((HEIGHT, 1))).astype(
        np.uint16)
    return rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8), depth


class Robot:
    """A camera driver's three publishers, /tf, and the bridge's status (SDK, one session)."""

    def __init__(self, sdk, port: int) -> None:
        kinds = {INFO: "sensor_msgs/msg/CameraInfo", COLOR: "sensor_msgs/msg/Image",
                 DEPTH: "sensor_msgs/msg/Image", "/tf": "tf2_msgs/msg/TFMessage"}
        self.publishers = {topic: sdk.ROS2Publisher(topic, kind, router_port=port,
                                                    node_name="camera")
                           for topic, kind in kinds.items()}
        self._lock = threading.Lock()
        self._status: dict[str, str] = {}
        self.status_subscriber = sdk.ROS2Subscriber(
            "/gngdt/camera/status", "diagnostic_msgs/msg/DiagnosticArray",
            callback=self._on_status, router_port=port)

    def _on_status(self, message) -> None:
        ours = [s for s in message.status if s.name == "gngdt/camera/ros2"]
        if ours:
            with self._lock:
                self._status = {kv.key: kv.value for kv in ours[0].values}

    def count(self, key: str) -> int:
        with self._lock:
            return int(self._status.get(f"camera/{key}", 0))

    @staticmethod
    def header(stamp_ns: int, frame_id: str):
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return message_class("std_msgs/msg/Header")(
            stamp=message_class("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec),
            frame_id=frame_id)

    def publish_frame(self, seed: int, stamp_ns: int, camera: dict | None = None) -> None:
        """CameraInfo (``camera``'s values, default the real ones), colour and depth."""
        c = camera or CAMERA
        header = self.header(stamp_ns, OPTICAL)
        self.publishers[INFO].publish(
            header=header, height=HEIGHT, width=WIDTH, distortion_model="plumb_bob",
            d=np.zeros(5), k=np.array([c["fx"], 0, c["cx"], 0, c["fy"], c["cy"], 0, 0, 1.0]),
            r=np.eye(3).reshape(-1),
            p=np.array([c["fx"], 0, c["cx"], 0, 0, c["fy"], c["cy"], 0, 0, 0, 1.0, 0]),
            binning_x=0, binning_y=0,
            roi=message_class("sensor_msgs/msg/RegionOfInterest")(
                x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        color, depth = frame_pixels(seed)
        self.publishers[COLOR].publish(header=header, height=HEIGHT, width=WIDTH,
                                       encoding="rgb8", is_bigendian=0, step=WIDTH * 3,
                                       data=color.reshape(-1))
        self.publishers[DEPTH].publish(header=header, height=HEIGHT, width=WIDTH,
                                       encoding="16UC1", is_bigendian=0, step=WIDTH * 2,
                                       data=depth.reshape(-1).view(np.uint8))

    def publish_transform(self, parent: str, child: str, stamp_ns: int,
                          translation: tuple[float, float, float]) -> None:
        x, y, z = translation
        stamped = message_class("geometry_msgs/msg/TransformStamped")(
            header=self.header(stamp_ns, parent), child_frame_id=child,
            transform=message_class("geometry_msgs/msg/Transform")(
                translation=message_class("geometry_msgs/msg/Vector3")(x=x, y=y, z=z),
                rotation=message_class("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0,
                                                                       w=1.0)))
        self.publishers["/tf"].publish(transforms=[stamped])

    def close(self) -> None:
        self.status_subscriber.close()
        for publisher in self.publishers.values():
            publisher.close()


class Clouds:
    """gngdt's side of the router: every cloud the bridge publishes (frame_id, points)."""

    def __init__(self, endpoint: str) -> None:
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        from gngdt.schemas.clouds import cloud_pose, msg_to_cloud

        self.session = open_config(client_config([endpoint]))
        #: (frame_id, (N, 3) points in the camera frame, (4, 4) pose or None) of each
        self.received: list[tuple[str, np.ndarray, np.ndarray | None]] = []

        def on_points(sample) -> None:
            message = PointCloud.FromString(sample.payload.to_bytes())
            self.received.append((message.frame_id, msg_to_cloud(message)[0],
                                  cloud_pose(message)))

        self.session.declare_subscriber("gngdt/camera/points", on_points)

    def topology(self):
        replies = [reply for reply in self.session.get("gngdt/camera/topology", timeout=10)
                   if reply.ok is not None]
        return decode_topology(replies[0].ok.payload.to_bytes()) if replies else None

    def close(self) -> None:
        self.session.close()


ABSURD_CAMERAS = [dict(CAMERA, cx=-1e30), dict(CAMERA, cy=1e12), dict(CAMERA, fx=1e-300)]


@pytest.mark.timeout(300)
def test_absurd_camera_info_is_refused_counted_said_once_and_never_learned(
        router_endpoint: str, spawn: Callable, tmp_path: Path) -> None:
    """Before, cx = -1e30 made clouds 5e27 m away and the learner learned them."""
    port = int(router_endpoint.rsplit(":", 1)[1])
    learner = spawn("learn", "--zenoh-connect", router_endpoint, "--samples-per-frame", "2000")
    bridge = spawn("ros2", "--zenoh-connect", router_endpoint)
    wait_for(lambda: "learning from" in log_text(learner)
             and "camera in, results out" in log_text(bridge), 120, "learner and bridge up")
    clouds = Clouds(router_endpoint)
    try:
        with sdk_session(port, tmp_path) as sdk:
            robot = Robot(sdk, port)
            try:
                sent = 0  # until 6 reached the bridge (the first may come before it listens)
                while robot.count("calibrations_refused") < 6:
                    assert sent < 60, f"{robot.count('calibrations_refused')} refused"
                    robot.publish_frame(sent, time.time_ns(), ABSURD_CAMERAS[sent % 3])
                    sent += 1
                    settled = time.monotonic() + 3  # its three messages, or it was lost
                    while (robot.count("calibrations_refused") < 6
                           and robot.count("images/received") < 3 * sent
                           and time.monotonic() < settled):
                        time.sleep(0.05)
                wait_for(lambda: robot.count("images/handled") + robot.count("images/dropped")
                         == robot.count("images/received"), 30, "every sample handled")
                time.sleep(0.5)  # a cloud published for the last one would be here by now
                assert not clouds.received  # nothing deprojected with them
                index = 0

                def learned() -> bool:
                    nonlocal index
                    robot.publish_frame(index, time.time_ns())
                    index += 1
                    time.sleep(0.2)
                    return len(clouds.received) >= 3 and clouds.topology() is not None

                wait_for(learned, 120, "good frames learned after the refused ones")
            finally:
                robot.close()
        topology = clouds.topology()
    finally:
        clouds.close()
    # the map holds the wall, 0.9-1.1 m away, and nothing 1e27 m off
    assert topology.positions.shape[0] > 0
    assert np.abs(topology.positions).max() < 2.0
    for _, points, _ in clouds.received:
        assert np.abs(points).max() < 2.0
    log = log_text(bridge)
    assert log.count("CameraInfo refused (") == 1, log[-3000:]  # said once, not per message
    assert "Traceback" not in log and "Traceback" not in log_text(learner)
    assert bridge.poll() is None and learner.poll() is None


#: the camera's images reach the bridge this late behind /tf (a slow driver or link): each
#: frame's pose is interpolated in the /tf the bridge holds from that long ago
CAMERA_LATENCY_NS = 1_500_000_000


class TfStream:
    """/tf ``odom -> camera_color_optical_frame`` at (1, 2, 3), stamped now, every 50 ms."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(0.05):
            self.robot.publish_transform("odom", OPTICAL, time.time_ns(), (1.0, 2.0, 3.0))

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)


@pytest.mark.timeout(300)
def test_a_far_future_transform_neither_stops_the_poses_nor_is_used(
        router_endpoint: str, spawn: Callable, tmp_path: Path) -> None:
    """Before, one transform ``map -> decoy`` stamped 2038 (unrelated to the camera) made the
    bridge forget, every second, every other link's samples but the newest: no frame stamped
    further back than that had a pose from then on. A forged sample on the camera's own link
    is ignored too, counted in the status."""
    port = int(router_endpoint.rsplit(":", 1)[1])
    bridge = spawn("ros2", "--zenoh-connect", router_endpoint, "--fixed-frame", "odom")
    wait_for(lambda: "camera in, results out" in log_text(bridge), 60, "bridge up")
    clouds = Clouds(router_endpoint)
    try:
        with sdk_session(port, tmp_path) as sdk:
            robot = Robot(sdk, port)
            tf = TfStream(robot)
            sent = 0

            def posed_frames(wanted: int) -> Callable[[], bool]:
                """Publish one late frame per call until ``wanted`` more clouds came."""
                goal = len(clouds.received) + wanted

                def more() -> bool:
                    nonlocal sent
                    robot.publish_frame(sent, time.time_ns() - CAMERA_LATENCY_NS)
                    sent += 1
                    time.sleep(0.15)
                    return len(clouds.received) >= goal
                return more

            try:
                wait_for(posed_frames(2), 60, "posed clouds")
                robot.publish_transform("map", "decoy", YEAR_2038_NS, (0.0, 0.0, 0.0))
                robot.publish_transform("odom", OPTICAL, YEAR_2038_NS, (50.0, 50.0, 50.0))
                started = time.monotonic()
                wait_for(posed_frames(10), 90, "posed clouds after the 2038 stamps")
                assert time.monotonic() - started > 1.0  # past a pruning of the window
                wait_for(lambda: robot.count("transforms_far_off") >= 2, 60,
                         "the two far-future transforms counted")
            finally:
                tf.close()
                robot.close()
    finally:
        clouds.close()
    assert {frame_id for frame_id, _, _ in clouds.received} == {"odom"}
    for _, _, pose in clouds.received:  # never the forged (50, 50, 50)
        np.testing.assert_allclose(pose[:3, 3], [1.0, 2.0, 3.0])
    log = log_text(bridge)
    assert "ignored" in log and "Traceback" not in log
    assert bridge.poll() is None
