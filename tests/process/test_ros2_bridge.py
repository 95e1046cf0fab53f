"""`gngdt ros2` end to end through a router: a robot side written by others (zenoh-ros2-sdk, see
tests/helpers/ros2_sdk.py) publishes real Kinect frames as a ROS 2 camera driver would
(sensor_msgs/Image colour and depth + CameraInfo, with its liveliness tokens) and receives, through
the bridge and a real learner, gngdt's clouds, nodes and objects as ROS 2 messages; it also lists
gngdt's node and topics as ROS 2's graph does."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.ros2_sdk import message_class, sdk_session

from gngdt.services.plumbing.session import client_config, open_config

REPO_ROOT = Path(__file__).resolve().parents[2]
#: three consecutive real Kinect frames (PCL's ImageGrabber test data), outside the repository
FRAMES_DIR = REPO_ROOT.parent / "shared" / "data" / "rgbd" / "pcl_grabber_sequence"
#: realsense2_camera's topics, the bridge's defaults
COLOR, DEPTH, INFO = ("/camera/camera/color/image_raw",
                      "/camera/camera/aligned_depth_to_color/image_raw",
                      "/camera/camera/color/camera_info")


def real_frames() -> tuple[list[tuple[np.ndarray, np.ndarray]], dict]:
    """(colour (H, W, 3) uint8 RGB, depth (H, W) uint16 mm) of each frame, and camera.json;
    read with OpenCV, not gngdt's readers."""
    import cv2

    if not FRAMES_DIR.is_dir():
        pytest.skip(f"real RGB-D frames not found: {FRAMES_DIR} (../shared beside the clone)")
    camera = json.loads((FRAMES_DIR / "camera.json").read_text())
    assert camera["depth_scale"] == 1000.0  # depth already in millimetres
    frames = []
    for rgb_path in sorted(FRAMES_DIR.glob("*_rgb.tiff")):
        bgr = cv2.imread(str(rgb_path), cv2.IMREAD_COLOR)
        depth = cv2.imread(str(rgb_path).replace("_rgb.", "_depth."), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16
        frames.append((np.ascontiguousarray(bgr[..., ::-1]), depth))
    assert len(frames) == 3
    return frames, camera


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not within {timeout_s} s")
        time.sleep(0.05)


def gngdt_tokens(endpoint: str, camera: str = "camera") -> set[str]:
    session = open_config(client_config([endpoint]))
    try:
        return {str(reply.ok.key_expr) for reply in
                session.liveliness().get(f"gngdt/{camera}/**", timeout=2.0) if reply.ok}
    finally:
        session.close()


class Received:
    """Messages the robot side received, per topic (SDK callbacks run on zenoh's threads)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.messages: dict[str, list] = {}

    def callback(self, name: str) -> Callable:
        def on_message(message: object) -> None:
            with self.lock:
                self.messages.setdefault(name, []).append(message)
        return on_message

    def get(self, name: str) -> list:
        with self.lock:
            return list(self.messages.get(name, []))


class CameraDriver:
    """A ROS 2 camera driver's three publishers (SDK), one node 'camera'."""

    def __init__(self, sdk, port: int, camera: dict) -> None:
        self.camera = camera
        self.publishers = {topic: sdk.ROS2Publisher(topic, kind, router_port=port,
                                                    node_name="camera")
                           for topic, kind in ((INFO, "sensor_msgs/msg/CameraInfo"),
                                               (COLOR, "sensor_msgs/msg/Image"),
                                               (DEPTH, "sensor_msgs/msg/Image"))}
        self.header = message_class("std_msgs/msg/Header")
        self.time = message_class("builtin_interfaces/msg/Time")
        self.region = message_class("sensor_msgs/msg/RegionOfInterest")

    def publish(self, color: np.ndarray, depth: np.ndarray, stamp_ns: int) -> None:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        header = self.header(stamp=self.time(sec=sec, nanosec=nanosec),
                             frame_id="camera_color_optical_frame")
        c = self.camera
        height, width = depth.shape
        self.publishers[INFO].publish(
            header=header, height=height, width=width, distortion_model="plumb_bob",
            d=np.zeros(5), k=np.array([c["fx"], 0, c["cx"], 0, c["fy"], c["cy"], 0, 0, 1.0]),
            r=np.eye(3).reshape(-1),
            p=np.array([c["fx"], 0, c["cx"], 0, 0, c["fy"], c["cy"], 0, 0, 0, 1.0, 0]),
            binning_x=0, binning_y=0,
            roi=self.region(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        self.publishers[COLOR].publish(header=header, height=height, width=width,
                                       encoding="rgb8", is_bigendian=0, step=width * 3,
                                       data=color.reshape(-1))
        self.publishers[DEPTH].publish(header=header, height=height, width=width,
                                       encoding="16UC1", is_bigendian=0, step=width * 2,
                                       data=depth.reshape(-1).view(np.uint8))

    def close(self) -> None:
        for publisher in self.publishers.values():
            publisher.close()


def expected_cloud(color: np.ndarray, depth: np.ndarray, camera: dict
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The frame's pixels with depth in [0.1, 10] m (the bridge's defaults) as points, row by
    row: (N, 3) metres (pinhole model) and (N, 3) uint8 colours."""
    rows, cols = np.nonzero((depth >= 100) & (depth <= 10_000))
    z = depth[rows, cols] / 1000.0
    points = np.stack([(cols - camera["cx"]) / camera["fx"] * z,
                       (rows - camera["cy"]) / camera["fy"] * z, z], axis=1)
    return points, color[rows, cols]


def cloud_fields(message) -> dict[str, np.ndarray]:
    """A PointCloud2 (rosbags object) as per-field arrays, read with numpy from its fields."""
    kinds = {6: "<u4", 7: "<f4"}
    count = message.width * message.height
    raw = np.asarray(message.data, dtype=np.uint8).reshape(count, message.point_step)
    return {field.name: raw[:, field.offset:field.offset + 4].copy().view(
        kinds[field.datatype])[:, 0] for field in message.fields}


def check_graph(graph: dict, topic_info) -> None:
    """ROS 2's graph lists gngdt's topics with their types, and who is behind them."""
    assert graph["/gngdt/camera/points"] == ["sensor_msgs/msg/PointCloud2"]
    assert graph["/gngdt/camera/nodes"] == ["sensor_msgs/msg/PointCloud2"]
    assert graph["/gngdt/camera/graph"] == ["visualization_msgs/msg/MarkerArray"]
    assert graph["/gngdt/camera/objects"] == ["visualization_msgs/msg/MarkerArray"]
    assert graph["/gngdt/camera/status"] == ["diagnostic_msgs/msg/DiagnosticArray"]
    assert graph["/tf"] == ["tf2_msgs/msg/TFMessage"]
    assert graph[COLOR] == graph[DEPTH] == ["sensor_msgs/msg/Image"]
    assert graph[INFO] == ["sensor_msgs/msg/CameraInfo"]
    # the bridge's subscription to the colour topic, as `ros2 topic info -v` shows it
    assert "gngdt_camera" in {endpoint.node_name for endpoint in topic_info.subscribers}


def check_points(cloud, frames: list, sent: dict[int, int], camera: dict) -> np.ndarray:
    """The cloud of the real frame its stamp names, point for point; the expected points."""
    stamp = cloud.header.stamp.sec * 1_000_000_000 + cloud.header.stamp.nanosec
    color, depth = frames[sent[stamp]]
    points, colors = expected_cloud(color, depth, camera)
    fields = cloud_fields(cloud)
    assert [field.name for field in cloud.fields] == ["x", "y", "z", "rgb"]
    assert cloud.header.frame_id == "camera" and cloud.width == len(points) > 200_000
    np.testing.assert_allclose(np.stack([fields["x"], fields["y"], fields["z"]], axis=1),
                               points, atol=1e-5)
    rgb = fields["rgb"].view(np.uint32)
    np.testing.assert_array_equal(
        np.stack([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255], axis=1), colors)
    return points


def inside(points: np.ndarray, xyz: np.ndarray, margin: float = 0.05) -> bool:
    low, high = points.min(axis=0) - margin, points.max(axis=0) + margin
    return bool(((xyz >= low) & (xyz <= high)).all())


def check_nodes(nodes, points: np.ndarray) -> None:
    """Learned nodes: their fields, where the points are, unit normals."""
    node_fields = cloud_fields(nodes)
    assert list(node_fields)[:7] == ["x", "y", "z", "rgb", "normal_x", "normal_y", "normal_z"]
    assert {"label_pos", "label_col", "label_nor", "label_col_nor"} <= set(node_fields)
    assert 0 < nodes.width <= 1000  # the learner's default node budget
    assert inside(points, np.stack([node_fields[axis] for axis in "xyz"], axis=1))
    normals = np.stack([node_fields[f"normal_{axis}"] for axis in "xyz"], axis=1)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-3)


def check_objects(markers: list, points: np.ndarray) -> None:
    """A CUBE and a TEXT_VIEW_FACING label per object, same id, boxes where the points are."""
    cubes = [m for m in markers if m.ns == "objects" and m.action == 0]
    labels = [m for m in markers if m.ns == "object_labels" and m.action == 0]
    assert cubes and all(marker.type == 1 for marker in cubes)
    assert [m.id for m in labels] == [m.id for m in cubes] and all(m.type == 9 for m in labels)
    for marker in cubes:
        position = marker.pose.position
        assert inside(points, np.array([[position.x, position.y, position.z]]))
        assert min(marker.scale.x, marker.scale.y, marker.scale.z) > 0


def test_robot_camera_in_results_out(router_endpoint: str, spawn: Callable,
                                     tmp_path: Path) -> None:
    frames, camera = real_frames()
    port = int(router_endpoint.rsplit(":", 1)[1])
    learner = spawn("learn", "--zenoh-connect", router_endpoint, "--object-confirm-frames", "1",
                    "--samples-per-frame", "5000")
    bridge = spawn("ros2", "--zenoh-connect", router_endpoint)
    wait_for(lambda: {"gngdt/camera/learner/alive", "gngdt/camera/ros2/alive",
                      "gngdt/camera/capture/alive"} <= gngdt_tokens(router_endpoint), 120,
             "learner and bridge up")
    received = Received()
    with sdk_session(port, tmp_path) as sdk:
        subscribers = [sdk.ROS2Subscriber(f"/gngdt/camera/{name}", kind,
                                          callback=received.callback(name), router_port=port)
                       for name, kind in (("points", "sensor_msgs/msg/PointCloud2"),
                                          ("nodes", "sensor_msgs/msg/PointCloud2"),
                                          ("objects", "visualization_msgs/msg/MarkerArray"),
                                          ("graph", "visualization_msgs/msg/MarkerArray"),
                                          ("status", "diagnostic_msgs/msg/DiagnosticArray"))]
        # ROS 2's graph, as `ros2 topic list -t` builds it from the liveliness tokens
        graph = dict(sdk.get_topic_names_and_types(router_port=port, timeout=1.0))
        driver = CameraDriver(sdk, port, camera)
        sent: dict[int, int] = {}
        try:
            deadline = time.monotonic() + 120
            index = 0
            while not all(received.get(name) for name in ("points", "nodes", "objects")):
                assert time.monotonic() < deadline, (
                    f"received {({k: len(v) for k, v in received.messages.items()})}; bridge "
                    f"log:\n{Path(bridge.log_path).read_text()[-3000:]}")
                assert bridge.poll() is None and learner.poll() is None
                stamp = time.time_ns()
                sent[stamp] = index % len(frames)
                driver.publish(*frames[index % len(frames)], stamp)
                index += 1
                time.sleep(0.2)  # a slow camera: 5 frames a second
            topic_info = sdk.get_topic_info(COLOR, router_port=port, timeout=1.0, verbose=True)
        finally:
            driver.close()
            for subscriber in subscribers:
                subscriber.close()

    check_graph(graph, topic_info)
    points = check_points(received.get("points")[0], frames, sent, camera)
    check_nodes(received.get("nodes")[-1], points)
    check_objects(received.get("objects")[-1].markers, points)


def gngdt_clouds(endpoint: str) -> tuple[object, list]:
    """A gngdt-side client keeping every ``gngdt/camera/points`` cloud's frame_id and pose."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from gngdt.schemas.clouds import cloud_pose

    session = open_config(client_config([endpoint]))
    clouds: list = []

    def on_points(sample) -> None:
        message = PointCloud.FromString(sample.payload.to_bytes())
        clouds.append((message.frame_id, cloud_pose(message)))

    session.declare_subscriber("gngdt/camera/points", on_points)
    return session, clouds


def refused(send: Callable[[], None], refusals: Callable[[], int], what: str,
            count: int = 1) -> None:
    """Send bad input until the bridge's status counts ``count`` more refusals than before it
    (a frame's colour and depth images are two).

    The SDK's publishers and a raw put drop what a busy link cannot take (congestion control
    DROP), so one try can be lost before it reaches the bridge; a try is given 10 s (the status
    comes once a second). A lost try counted late would only make the count larger."""
    before = refusals()
    for _ in range(6):
        send()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if refusals() >= before + count:
                return
            time.sleep(0.1)
    raise AssertionError(f"{what} was never counted in the status ({before} before it)")


def publish_bad_input(sdk, driver: CameraDriver, refusals: Callable[[], int]) -> None:
    """Six images the bridge must refuse as malformed: three of garbage on the colour key, a
    yuv422 image, a frame over 640x480 (colour and depth), each sent until counted (`refused`):
    one at a time, since the bridge holds at most 8 samples, and a burst beyond that, on a
    machine too busy to keep up, would be dropped (counted as such) before being refused."""
    noise = sdk.ZenohSession.get_instance().session
    for garbage in (b"", b"\x00\x01\x00\x00", bytes(range(256)) * 3):
        refused(lambda garbage=garbage: noise.put(driver.publishers[COLOR].keyexpr, garbage),
                refusals, f"{len(garbage)} bytes of garbage")
    refused(lambda: driver.publishers[COLOR].publish(
        header=driver.header(stamp=driver.time(sec=1, nanosec=0), frame_id="x"),
        height=1, width=2, encoding="yuv422", is_bigendian=0, step=4,
        data=np.zeros(4, np.uint8)), refusals, "a yuv422 image")
    big = np.zeros((481, 640, 3), np.uint8)  # one row over --max-frame-pixels
    refused(lambda: driver.publish(big, np.zeros((481, 640), np.uint16), time.time_ns()),
            refusals, "a frame over --max-frame-pixels (colour and depth)", count=2)


def camera_in_world(stamp_ns: int, translation: tuple[float, float, float]):
    """A geometry_msgs/TransformStamped world -> camera_color_optical_frame (SDK classes)."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    x, y, z = translation
    return message_class("geometry_msgs/msg/TransformStamped")(
        header=message_class("std_msgs/msg/Header")(
            stamp=message_class("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec),
            frame_id="world"),
        child_frame_id="camera_color_optical_frame",
        transform=message_class("geometry_msgs/msg/Transform")(
            translation=message_class("geometry_msgs/msg/Vector3")(x=x, y=y, z=z),
            rotation=message_class("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0)))


def test_bad_input_is_counted_and_skipped_and_poses_come_from_tf(
        router_endpoint: str, spawn: Callable, tmp_path: Path) -> None:
    """Garbage, an unsupported encoding, an image over the size limit and an uncalibrated
    CameraInfo are skipped and counted in /gngdt/<cam>/status; good frames go on, posed from
    /tf in --fixed-frame; a stop signal ends the bridge cleanly, its tokens gone."""
    import signal

    frames, camera = real_frames()
    port = int(router_endpoint.rsplit(":", 1)[1])
    bridge = spawn("ros2", "--zenoh-connect", router_endpoint, "--fixed-frame", "world",
                   "--max-frame-pixels", str(640 * 480))
    wait_for(lambda: "gngdt/camera/ros2/alive" in gngdt_tokens(router_endpoint), 60, "bridge up")
    session, clouds = gngdt_clouds(router_endpoint)
    received = Received()
    try:
        with sdk_session(port, tmp_path) as sdk:
            status = sdk.ROS2Subscriber("/gngdt/camera/status",
                                        "diagnostic_msgs/msg/DiagnosticArray",
                                        callback=received.callback("status"), router_port=port)
            tf = sdk.ROS2Publisher("/tf", "tf2_msgs/msg/TFMessage", router_port=port,
                                   node_name="robot_state_publisher")
            driver = CameraDriver(sdk, port, camera)
            color, depth = frames[0]

            def status_values() -> dict[str, str]:
                latest = received.get("status")
                ours = [s for s in latest[-1].status if s.name == "gngdt/camera/ros2"] \
                    if latest else []
                return {kv.key: kv.value for kv in ours[0].values} if ours else {}

            def refusals() -> int:
                values = status_values()
                return (int(values.get("camera/images/malformed", 0))
                        + int(values.get("camera/calibrations_refused", 0)))

            try:
                publish_bad_input(sdk, driver, refusals)
                # 6 or more: a message sent again may be counted twice; none made a cloud
                values = status_values()
                malformed = int(values["camera/images/malformed"])
                assert malformed >= 6 and values["camera/frames_published"] == "0", str(values)
                uncalibrated = driver_with(driver, dict(driver.camera, fx=0.0, fy=0.0))
                refused(lambda: CameraDriver.publish(uncalibrated, color, depth, 1), refusals,
                        "an uncalibrated CameraInfo")
                calibrations_refused = int(status_values()["camera/calibrations_refused"])
                deadline = time.monotonic() + 60
                while not any(frame_id == "world" for frame_id, _ in clouds):
                    assert time.monotonic() < deadline and bridge.poll() is None, \
                        Path(bridge.log_path).read_text()[-3000:]
                    stamp = time.time_ns()
                    tf.publish(transforms=[camera_in_world(stamp, (1.0, 2.0, 3.0))])
                    driver.publish(color, depth, stamp)
                    time.sleep(0.2)
                # the uncalibrated CameraInfo counted (each time sent), and no good frame since
                assert int(status_values()["camera/images/malformed"]) == malformed
                assert int(status_values()["camera/calibrations_refused"]) \
                    == calibrations_refused >= 1
            finally:
                driver.close()
                tf.close()
                status.close()
        pose = next(pose for frame_id, pose in clouds if frame_id == "world")
        np.testing.assert_allclose(pose[:3, 3], [1.0, 2.0, 3.0])
        assert bridge.poll() is None  # alive after all that
        bridge.send_signal(signal.SIGINT)
        assert bridge.wait(30) == 0
        assert not gngdt_tokens(router_endpoint)
        ros_tokens = [reply for reply in session.liveliness().get("@ros2_lv/0/**", timeout=2.0)
                      if reply.ok is not None and "gngdt_camera" in str(reply.ok.key_expr)]
        assert not ros_tokens
    finally:
        session.close()
    log = Path(bridge.log_path).read_text()
    assert "Traceback" not in log
    assert "yuv422" in log and "exceeds the limit" in log  # each refusal says why


def driver_with(driver: CameraDriver, camera: dict) -> CameraDriver:
    """The same publishers, other intrinsics in the CameraInfo."""
    other = CameraDriver.__new__(CameraDriver)
    other.__dict__.update(driver.__dict__, camera=camera)
    return other


def test_bad_options_are_refused_before_starting(spawn: Callable) -> None:
    for options, said in ((["--cam", "cam-0"], "--cam 'cam-0'"),
                          (["--domain", "999"], "--domain"),
                          (["--voxel", "-1"], "--voxel")):
        process = spawn("ros2", *options, "--router-wait", "0")
        assert process.wait(60) == 2
        assert said in Path(process.log_path).read_text()


def test_run_with_ros2_publishes_the_results_into_ros(
        router_endpoint: str, spawn: Callable, tmp_path: Path) -> None:
    """`gngdt run --ros2 ENDPOINT` on a recording whose camera moves: the bridge joins the ROS 2
    router, the robot side gets nodes, clouds in the camera frame and the camera's pose on
    /tf (one of the recording's poses), and run ends as usual."""
    from helpers.synthetic import render_small_recording

    from gngdt.io.mcap.reader import read_frames

    recording = render_small_recording(tmp_path, "tabletop_walk", 6)
    poses = [frame.pose.matrix for frame in read_frames(recording)]
    port = int(router_endpoint.rsplit(":", 1)[1])
    received = Received()
    with sdk_session(port, tmp_path) as sdk:
        subscribers = [sdk.ROS2Subscriber(name, kind, callback=received.callback(name),
                                          router_port=port)
                       for name, kind in (("/gngdt/camera/nodes", "sensor_msgs/msg/PointCloud2"),
                                          ("/gngdt/camera/points", "sensor_msgs/msg/PointCloud2"),
                                          ("/tf", "tf2_msgs/msg/TFMessage"))]
        try:
            run = spawn("run", str(recording), "--rate", "0.5", "--ros2", router_endpoint,
                        "--save", str(tmp_path / "run.rrd"))
            assert run.wait(300) == 0, Path(run.log_path).read_text()[-3000:]
        finally:
            for subscriber in subscribers:
                subscriber.close()
    assert received.get("/gngdt/camera/nodes")
    clouds = received.get("/gngdt/camera/points")
    assert clouds and {cloud.header.frame_id for cloud in clouds} == {"camera"}
    transforms = [t for message in received.get("/tf") for t in message.transforms]
    assert transforms and {(t.header.frame_id, t.child_frame_id) for t in transforms} == {
        ("world", "camera")}
    for t in transforms:
        translation = [t.transform.translation.x, t.transform.translation.y,
                       t.transform.translation.z]
        assert min(np.abs(pose[:3, 3] - translation).max() for pose in poses) < 1e-6


def test_objects_gone_are_deleted(router_endpoint: str, spawn: Callable, tmp_path: Path) -> None:
    """Two objects updates as the learner publishes them (ids 1, 2; then 2 alone): the second
    MarkerArray deletes object 1's cube and label."""
    from gngdt.schemas.scene import objects_to_scene_update
    from gngdt.schemas.wire import ENCODING_SCENE_UPDATE

    def update(ids: list[int]) -> bytes:
        count = len(ids)
        return objects_to_scene_update(
            ids=np.array(ids), centers=np.ones((count, 3)),
            quaternions_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (count, 1)),
            sizes=np.full((count, 3), 0.1), colors=np.full((count, 3), 200, np.uint8),
            node_counts=np.full(count, 9), centroids=np.ones((count, 3)),
            mean_colors=np.full((count, 3), 100.0), normals=np.tile([0.0, 0.0, 1.0], (count, 1)),
            timestamp_ns=time.time_ns(), frame_id="world").SerializeToString()

    port = int(router_endpoint.rsplit(":", 1)[1])
    spawn("ros2", "--zenoh-connect", router_endpoint, "--no-input")
    wait_for(lambda: "gngdt/camera/ros2/alive" in gngdt_tokens(router_endpoint), 60, "bridge up")
    session = open_config(client_config([router_endpoint]))
    received = Received()
    try:
        publisher = session.declare_publisher("gngdt/camera/objects",
                                              encoding=ENCODING_SCENE_UPDATE)
        with sdk_session(port, tmp_path) as sdk:
            subscriber = sdk.ROS2Subscriber("/gngdt/camera/objects",
                                            "visualization_msgs/msg/MarkerArray",
                                            callback=received.callback("objects"),
                                            router_port=port)
            try:
                deadline = time.monotonic() + 30
                while not received.get("objects"):  # until the bridge's publisher matches
                    assert time.monotonic() < deadline
                    publisher.put(update([1, 2]))
                    time.sleep(0.2)
                publisher.put(update([2]))
                wait_for(lambda: any(m.action == 2 for message in received.get("objects")
                                     for m in message.markers), 10, "a DELETE")
            finally:
                subscriber.close()
    finally:
        session.close()
    last = received.get("objects")[-1].markers
    assert [(m.ns, m.id, m.action) for m in last] == [
        ("objects", 2, 0), ("object_labels", 2, 0), ("objects", 1, 2), ("object_labels", 1, 2)]
    assert last[0].header.frame_id == "world"


def test_ros2_side_on_its_own_router_and_nothing_listening(
        router_endpoint: str, spawn: Callable) -> None:
    """``--ros2-connect``: gngdt's side on gngdt's router, the ROS 2 node on the other one; the
    bridge is a client of both and listens nowhere (no port, no scouting socket)."""
    from helpers.processes import bound_sockets

    from gngdt.services.plumbing.session import free_tcp_port, router_config

    ros_endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    ros_router = open_config(router_config([ros_endpoint]), what="router")
    try:
        bridge = spawn("ros2", "--zenoh-connect", router_endpoint, "--ros2-connect", ros_endpoint)
        wait_for(lambda: "gngdt/camera/ros2/alive" in gngdt_tokens(router_endpoint), 60,
                 "bridge up")

        def ros_tokens(endpoint: str) -> set[str]:
            session = open_config(client_config([endpoint]))
            try:
                return {str(reply.ok.key_expr) for reply in
                        session.liveliness().get("@ros2_lv/0/**", timeout=2.0) if reply.ok}
            finally:
                session.close()

        wait_for(lambda: any("/NN/%/%/gngdt_camera" in key for key in ros_tokens(ros_endpoint)),
                 30, "the node in the ROS 2 router's graph")
        assert not ros_tokens(router_endpoint)
        assert bound_sockets(bridge.pid) == []
    finally:
        ros_router.close()
