"""Every ROS 2 message gngdt publishes, decoded by code that is not gngdt's: rosbags' CDR codec
(its type store used directly) and mcap-ros2-support's (a second CDR reader, driven by the
message definition text), field by field; and the messages gngdt takes (Image, CameraInfo,
TFMessage) made by rosbags and read by gngdt, including damaged ones. The real rclpy decodes the
same messages in tests/process/test_ros2_oracle.py."""

from __future__ import annotations

import random

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.ros2 import markers as mk
from gngdt.io.ros2 import messages as m

STORE = get_typestore(Stores.ROS2_JAZZY)  # the independent codec (not gngdt.io.ros2)

#: RIHS01 hashes measured and noted in ECOSYSTEM-NOTES ("ROS 2 over zenoh"); the rest are
#: compared with the ROS packages' own share/*/msg/*.json by the oracle test
NOTED_HASHES = {
    m.POINT_CLOUD2: "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    m.TF_MESSAGE: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    m.MARKER_ARRAY: "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf",
}


def by_mcap_ros2(data: bytes, ros_type: str):
    """Decode CDR with mcap-ros2-support, from the type's message definition text."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    text, _ = STORE.generate_msgdef(ros_type, ros_version=2)
    schema = Schema(id=1, name=ros_type, encoding="ros2msg", data=text.encode())
    return DecoderFactory().decoder_for("cdr", schema)(data)


def cloud(n: int = 40, seed: int = 0):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(n, 3)).astype(np.float32),
            rng.integers(0, 256, (n, 3), dtype=np.uint8),
            rng.normal(size=(n, 3)).astype(np.float32),
            {"pos": rng.integers(-1, 5, n), "col+nor": rng.integers(0, 3, n)})


def fields_of(message) -> dict[str, np.ndarray]:
    """Per-field (N,) arrays of a decoded PointCloud2, read from its declared fields."""
    kinds = {6: "<u4", 7: "<f4"}
    raw = np.frombuffer(bytes(message.data), np.uint8).reshape(message.width,
                                                                message.point_step)
    return {f.name: raw[:, f.offset:f.offset + 4].copy().view(kinds[f.datatype])[:, 0]
            for f in message.fields}


@pytest.mark.parametrize("ros_type", sorted(NOTED_HASHES))
def test_type_hashes_are_the_noted_ones(ros_type: str) -> None:
    assert m.type_hash(ros_type) == NOTED_HASHES[ros_type]


@pytest.mark.parametrize("decode", [STORE.deserialize_cdr, by_mcap_ros2], ids=["rosbags", "mcap"])
def test_nodes_cloud_field_by_field(decode) -> None:
    positions, colors, normals, labels = cloud()
    data = m.encode_pointcloud2(positions, colors=colors, normals=normals, labels=labels,
                                stamp_ns=1_700_000_000_123_456_789, frame_id="map")
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian
    message = decode(data, m.POINT_CLOUD2)
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (1_700_000_000, 123456789)
    assert message.header.frame_id == "map"
    assert (message.height, message.width, message.point_step, message.row_step) == (
        1, 40, 36, 36 * 40)
    assert not message.is_bigendian and message.is_dense
    assert [(f.name, f.offset, f.datatype, f.count) for f in message.fields] == [
        ("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 12, 7, 1),
        ("normal_x", 16, 7, 1), ("normal_y", 20, 7, 1), ("normal_z", 24, 7, 1),
        ("label_pos", 28, 6, 1), ("label_col_nor", 32, 6, 1)]
    got = fields_of(message)
    np.testing.assert_array_equal(np.stack([got["x"], got["y"], got["z"]], 1), positions)
    np.testing.assert_array_equal(
        np.stack([got["normal_x"], got["normal_y"], got["normal_z"]], 1), normals)
    # RViz/PCL: a float32 'rgb' whose bits are 0x00RRGGBB
    rgb = got["rgb"].view(np.uint32)
    np.testing.assert_array_equal(np.stack([rgb >> 16, (rgb >> 8) & 255, rgb & 255], 1), colors)
    assert not (rgb >> 24).any()
    np.testing.assert_array_equal(got["label_pos"], labels["pos"].astype(np.uint32))
    assert (got["label_pos"][labels["pos"] == -1] == 0xFFFFFFFF).all()
    np.testing.assert_array_equal(got["label_col_nor"], labels["col+nor"])


def test_points_cloud_and_refusals() -> None:
    positions, colors, _, _ = cloud(7)
    message = STORE.deserialize_cdr(
        m.encode_pointcloud2(positions, colors=colors, stamp_ns=5, frame_id="camera"),
        m.POINT_CLOUD2)
    assert [f.name for f in message.fields] == ["x", "y", "z", "rgb"]
    assert message.point_step == 16
    empty = STORE.deserialize_cdr(m.encode_pointcloud2(
        np.zeros((0, 3), np.float32), colors=np.zeros((0, 3), np.uint8), stamp_ns=0,
        frame_id="camera"), m.POINT_CLOUD2)
    assert empty.width == 0 and len(empty.data) == 0
    nan = np.full((2, 3), np.nan, np.float32)
    assert not STORE.deserialize_cdr(m.encode_pointcloud2(nan, stamp_ns=0, frame_id="c"),
                                     m.POINT_CLOUD2).is_dense
    for bad in ({"positions": np.zeros((4, 2), np.float32)},
                {"colors": np.zeros((4, 3), np.float32)},
                {"normals": np.zeros((3, 3), np.float32)},
                {"labels": {"a": np.zeros(3)}},
                {"labels": {"a+b": np.zeros(4), "a_b": np.zeros(4)}}):  # same field name
        arguments = {"positions": np.zeros((4, 3), np.float32), "stamp_ns": 0, "frame_id": "c",
                     **bad}
        with pytest.raises(ValueError):
            m.encode_pointcloud2(**arguments)


@pytest.mark.parametrize("decode", [STORE.deserialize_cdr, by_mcap_ros2], ids=["rosbags", "mcap"])
def test_graph_markers_field_by_field(decode) -> None:
    positions = np.arange(18, dtype=np.float32).reshape(6, 3) / 10
    layers = {"pos": (np.array([[0, 1], [1, 2], [3, 4]]),
                      np.array([[255, 0, 0], [255, 0, 0], [0, 0, 255]], np.uint8)),
              "nor": (np.zeros((0, 2), np.int64), np.zeros((0, 3), np.uint8))}
    data = mk.encode_graph_markers(positions, layers, stamp_ns=42, frame_id="map",
                                   line_width=0.01)
    markers = decode(data, m.MARKER_ARRAY).markers
    assert [(x.ns, x.id, x.type, x.action) for x in markers] == [
        ("pos", 0, 5, 0), ("nor", 0, 5, 2)]  # LINE_LIST ADD; DELETE for no edges
    lines = markers[0]
    assert lines.header.frame_id == "map" and lines.header.stamp.nanosec == 42
    assert lines.scale.x == pytest.approx(0.01) and lines.pose.orientation.w == 1.0
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in lines.points],
                               positions[[0, 1, 1, 2, 3, 4]], rtol=1e-6)
    np.testing.assert_allclose([[c.r, c.g, c.b, c.a] for c in lines.colors],
                               [[1, 0, 0, 1]] * 4 + [[0, 0, 1, 1]] * 2)
    with pytest.raises(ValueError, match="outside"):
        mk.encode_graph_markers(positions, {"pos": (np.array([[0, 9]]), np.zeros((1, 3)))},
                                stamp_ns=0, frame_id="map")


@pytest.mark.parametrize("decode", [STORE.deserialize_cdr, by_mcap_ros2], ids=["rosbags", "mcap"])
def test_object_markers_field_by_field(decode) -> None:
    objects = [mk.ObjectMarker(7, (1.0, 2.0, 3.0), (0.2, 0.3, 0.4), (0.0, 0.0, 0.6, 0.8),
                               (1.0, 0.0, 0.0, 0.35), "#7"),
               mk.ObjectMarker(9, (0.0, 0.0, 1.0), (0.1, 0.1, 0.1), (0.0, 0.0, 0.0, 1.0),
                               (0.0, 1.0, 0.0, 0.35), "#9")]
    data = mk.encode_object_markers(objects, gone_ids=[3], stamp_ns=10, frame_id="map")
    markers = decode(data, m.MARKER_ARRAY).markers
    assert [(x.ns, x.id, x.type, x.action) for x in markers] == [
        ("objects", 7, 1, 0), ("object_labels", 7, 9, 0),
        ("objects", 9, 1, 0), ("object_labels", 9, 9, 0),
        ("objects", 3, 1, 2), ("object_labels", 3, 9, 2)]
    cube, text = markers[0], markers[1]
    assert (cube.pose.position.x, cube.pose.position.y, cube.pose.position.z) == (1.0, 2.0, 3.0)
    q = cube.pose.orientation
    assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.6, 0.8)
    assert (cube.scale.x, cube.scale.y, cube.scale.z) == pytest.approx((0.2, 0.3, 0.4))
    assert (cube.color.r, cube.color.g, cube.color.b, cube.color.a) == pytest.approx(
        (1.0, 0.0, 0.0, 0.35))
    assert text.text == "#7" and markers[3].text == "#9" and text.scale.z > 0
    assert cube.header.frame_id == "map" and cube.lifetime.sec == 0  # until deleted


@pytest.mark.parametrize("decode", [STORE.deserialize_cdr, by_mcap_ros2], ids=["rosbags", "mcap"])
def test_tf_field_by_field_and_back(decode) -> None:
    transforms = [m.Transform("world", "camera", 1_234_567_890_123, (1.0, -2.0, 0.5),
                              (0.0, 0.0, 0.7071067811865476, 0.7071067811865476)),
                  m.Transform("camera", "camera_optical", 1_234_567_890_123, (0.0, 0.015, 0.0),
                              (-0.5, 0.5, -0.5, 0.5))]
    data = m.encode_tf(transforms)
    message = decode(data, m.TF_MESSAGE)
    first = message.transforms[0]
    assert (first.header.frame_id, first.child_frame_id) == ("world", "camera")
    assert (first.header.stamp.sec, first.header.stamp.nanosec) == (1234, 567890123)
    t = first.transform.translation
    assert (t.x, t.y, t.z) == (1.0, -2.0, 0.5)
    assert message.transforms[1].transform.rotation.x == -0.5
    assert m.decode_tf(data) == transforms


@pytest.mark.parametrize("decode", [STORE.deserialize_cdr, by_mcap_ros2], ids=["rosbags", "mcap"])
def test_diagnostics_field_by_field(decode) -> None:
    data = m.encode_diagnostics(
        [m.Status("gngdt/cam0/learner", m.WARN, "slow", "cam0", {"nodes": 812, "fps": 14.5}),
         m.Status("gngdt/cam0/ros2")], stamp_ns=99)
    message = decode(data, m.DIAGNOSTIC_ARRAY)
    assert message.header.stamp.nanosec == 99
    first = message.status[0]
    level = first.level if isinstance(first.level, int) else first.level[0]
    assert (level, first.name, first.message, first.hardware_id) == (
        m.WARN, "gngdt/cam0/learner", "slow", "cam0")
    assert [(kv.key, kv.value) for kv in first.values] == [("nodes", "812"), ("fps", "14.5")]
    assert list(message.status[1].values) == []
    with pytest.raises(ValueError):
        m.encode_diagnostics([m.Status("x", level=7)], stamp_ns=0)


def image_message(encoding: str, height: int, width: int, step: int, data: np.ndarray,
                  big_endian: bool = False) -> bytes:
    """A sensor_msgs/Image made by rosbags (as a driver would send it)."""
    types = STORE.types
    message = types[m.IMAGE](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=12, nanosec=34), frame_id="optical"),
        height=height, width=width, encoding=encoding, is_bigendian=int(big_endian), step=step,
        data=np.ascontiguousarray(data).reshape(-1).view(np.uint8))
    return bytes(STORE.serialize_cdr(message, m.IMAGE))


def test_images_decoded_as_drivers_send_them() -> None:
    rgb = np.random.default_rng(1).integers(0, 256, (4, 5, 3), dtype=np.uint8)
    image = m.decode_image(image_message("rgb8", 4, 5, 15, rgb), max_pixels=100)
    assert (image.stamp_ns, image.frame_id, image.encoding) == (12_000_000_034, "optical", "rgb8")
    np.testing.assert_array_equal(image.pixels, rgb)
    bgr = m.decode_image(image_message("bgr8", 4, 5, 15, rgb[..., ::-1]), max_pixels=100)
    np.testing.assert_array_equal(bgr.pixels, rgb)  # always RGB
    padded = np.zeros((4, 20), np.uint8)  # rows padded from 15 to 20 bytes
    padded[:, :15] = rgb.reshape(4, 15)
    np.testing.assert_array_equal(
        m.decode_image(image_message("rgb8", 4, 5, 20, padded), max_pixels=100).pixels, rgb)
    millimetres = np.array([[0, 1000, 65535], [1, 2, 3]], np.uint16)
    np.testing.assert_array_equal(m.decode_image(
        image_message("16UC1", 2, 3, 6, millimetres), max_pixels=100).pixels, millimetres)
    big = m.decode_image(image_message("16UC1", 2, 3, 6, millimetres.astype(">u2"),
                                       big_endian=True), max_pixels=100)
    np.testing.assert_array_equal(big.pixels, millimetres)
    metres = np.array([[0.5, np.nan], [0.0, 3.25]], np.float32)
    np.testing.assert_array_equal(m.decode_image(
        image_message("32FC1", 2, 2, 8, metres), max_pixels=100).pixels, metres)
    # and gngdt's own encoder (benchmarks, tests) writes what rosbags reads
    again = STORE.deserialize_cdr(m.encode_image(millimetres, "16UC1", stamp_ns=7,
                                                 frame_id="d"), m.IMAGE)
    assert (again.encoding, again.step, again.height, again.width) == ("16UC1", 6, 2, 3)
    np.testing.assert_array_equal(np.asarray(again.data).view("<u2").reshape(2, 3), millimetres)


def test_an_image_is_copied_once_when_decoded() -> None:
    """Under an image flood every copy of a 4K frame counts: the pixels are the one copy."""
    import tracemalloc

    rgb = np.random.default_rng(2).integers(0, 256, (1080, 1920, 3), dtype=np.uint8)
    data = image_message("rgb8", 1080, 1920, 1920 * 3, rgb)
    tracemalloc.start()
    try:
        image = m.decode_image(data, max_pixels=1920 * 1080)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    np.testing.assert_array_equal(image.pixels, rgb)
    assert peak < 1.1 * rgb.nbytes


def test_bad_images_are_refused_with_a_reason() -> None:
    ok = np.zeros(24, np.uint8)
    for data, reason in ((image_message("rgb8", 2, 4, 8, ok), "step"),
                         (image_message("16UC1", 3, 4, 8, ok[:20]), "bytes"),
                         (image_message("yuv422", 2, 2, 4, ok), "encoding"),
                         (image_message("16UC1", 0, 4, 8, ok), "empty"),
                         (image_message("rgb8", 100, 100, 300, np.zeros(30000, np.uint8)),
                          "limit")):
        with pytest.raises(m.Ros2MessageError, match=reason):
            m.decode_image(data, max_pixels=5000)


def test_camera_info_from_a_driver_and_back() -> None:
    types = STORE.types
    message = types[m.CAMERA_INFO](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=3, nanosec=0), frame_id="optical"),
        height=480, width=640, distortion_model="plumb_bob",
        d=np.array([0.1, 0.0, 0.0, 0.0, 0.0]),
        k=np.array([615.0, 0, 320.5, 0, 616.0, 240.5, 0, 0, 1]), r=np.eye(3).reshape(-1),
        p=np.zeros(12), binning_x=0, binning_y=0,
        roi=types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                       do_rectify=False))
    info = m.decode_camera_info(bytes(STORE.serialize_cdr(message, m.CAMERA_INFO)))
    assert (info.stamp_ns, info.frame_id) == (3_000_000_000, "optical")
    assert info.intrinsics == CameraIntrinsics(640, 480, 615.0, 616.0, 320.5, 240.5,
                                               (0.1, 0.0, 0.0, 0.0, 0.0))
    back = STORE.deserialize_cdr(m.encode_camera_info(info), m.CAMERA_INFO)
    assert list(back.k) == [615.0, 0, 320.5, 0, 616.0, 240.5, 0, 0, 1]
    assert list(back.p[:4]) == [615.0, 0.0, 320.5, 0.0]
    message.k = np.zeros(9)  # an uncalibrated camera
    with pytest.raises(m.Ros2MessageError, match="uncalibrated"):
        m.decode_camera_info(bytes(STORE.serialize_cdr(message, m.CAMERA_INFO)))


@pytest.mark.parametrize("decoder", ["image", "camera_info", "tf"])
def test_damaged_cdr_is_refused_never_crashes(decoder: str) -> None:
    """Truncations, flipped bytes and noise: a Ros2MessageError (a ValueError the bridge counts
    and skips) or a valid message, never another exception."""
    good = {"image": image_message("16UC1", 2, 3, 6, np.arange(6, dtype=np.uint16)),
            "camera_info": m.encode_camera_info(m.CameraInfo(0, "c", CameraIntrinsics(
                640, 480, 500.0, 500.0, 320.0, 240.0))),
            "tf": m.encode_tf([m.Transform("a", "b", 1, (0, 0, 0), (0, 0, 0, 1))])}[decoder]
    decode = {"image": lambda data: m.decode_image(data, max_pixels=10_000),
              "camera_info": m.decode_camera_info, "tf": m.decode_tf}[decoder]
    rng = random.Random(0)
    damaged = [good[:cut] for cut in range(len(good))]
    for _ in range(300):
        data = bytearray(good)
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        damaged.append(bytes(data))
    damaged += [bytes(rng.randrange(256) for _ in range(rng.randint(0, 200))) for _ in range(100)]
    for data in damaged:
        try:
            decode(data)
        except m.Ros2MessageError:
            pass
