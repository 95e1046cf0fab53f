"""Wire schemas: bindings match the .proto; numpy packing round-trips and validates."""

from __future__ import annotations

import ast
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf import descriptor_pb2
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from gngdt.io.frame import CameraIntrinsics
from gngdt.schemas import (
    MessageError,
    calibration_to_intrinsics,
    cloud_to_msg,
    decode_status,
    decode_stream_end,
    decode_topology,
    encode_status,
    encode_stream_end,
    encode_topology,
    gngdt_pb2,
    image_to_raw,
    intrinsics_to_calibration,
    msg_to_cloud,
    pack_array,
    raw_to_image,
    unpack_array,
)
from gngdt.schemas.clouds import cloud_to_wire
from gngdt.schemas.generate import SCHEMA_DIR, generate

STAMP_NS = 1_700_000_000_123_456_789


# ------------------------------------------------------------------------------------ bindings
def _serialized_descriptor(generated_module: Path) -> bytes:
    """The FileDescriptorProto bytes a generated ``*_pb2.py`` registers (read, not imported)."""
    tree = ast.parse(generated_module.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "AddSerializedFile":
            return ast.literal_eval(node.args[0])
    raise AssertionError(f"{generated_module} registers no serialized file descriptor")


def test_checked_in_bindings_match_the_proto(tmp_path: Path) -> None:
    """Regenerate from gngdt.proto; compare FileDescriptorProtos (robust to protoc headers)."""
    generate(tmp_path)
    fresh = descriptor_pb2.FileDescriptorProto.FromString(
        _serialized_descriptor(tmp_path / "gngdt_pb2.py")
    )
    checked_in = descriptor_pb2.FileDescriptorProto.FromString(
        _serialized_descriptor(SCHEMA_DIR / "gngdt_pb2.py")
    )
    assert fresh == checked_in, \
        "schemas/gngdt_pb2.py is stale: run `python -m gngdt.schemas.generate`"
    loaded = descriptor_pb2.FileDescriptorProto()
    gngdt_pb2.DESCRIPTOR.CopyToProto(loaded)
    assert loaded == checked_in
    assert (tmp_path / "gngdt_pb2.pyi").read_text() == (SCHEMA_DIR / "gngdt_pb2.pyi").read_text()


# ---------------------------------------------------------------------------------- PackedArray
_PACKABLE = st.sampled_from(["float32", "uint8", "uint32", "int32", "float64", "int64"])


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(dtype=_PACKABLE, shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0)))
def test_pack_array_round_trips_bytes_exactly(array: np.ndarray) -> None:
    message = gngdt_pb2.PackedArray.FromString(pack_array(array).SerializeToString())
    restored = unpack_array(message, dtype=array.dtype, ndim=array.ndim)
    assert restored.shape == array.shape and restored.dtype == array.dtype
    assert restored.tobytes() == array.astype(array.dtype.newbyteorder("<")).tobytes()


def test_pack_array_writes_little_endian_regardless_of_input_order() -> None:
    big_endian = np.array([1.5, -2.0], dtype=">f4")
    message = pack_array(big_endian)
    assert message.dtype == "float32"
    assert message.data == struct.pack("<2f", 1.5, -2.0)


def test_unpack_array_validates_before_allocating() -> None:
    huge = gngdt_pb2.PackedArray(dtype="float32", shape=[10**9, 10**6], data=b"\0" * 8)
    with pytest.raises(MessageError, match="exceed the limit"):
        unpack_array(huge, max_elements=10**6)
    with pytest.raises(MessageError, match="needs"):
        unpack_array(huge)  # inconsistent size, detected from the header alone
    good = pack_array(np.zeros((4, 3), np.float32))
    with pytest.raises(MessageError, match="expected uint8"):
        unpack_array(good, dtype=np.uint8)
    with pytest.raises(MessageError, match="expected 1"):
        unpack_array(good, ndim=1)
    with pytest.raises(MessageError, match="unknown dtype"):
        unpack_array(gngdt_pb2.PackedArray(dtype="object", shape=[1], data=b"\0" * 8))


# --------------------------------------------------------------------------------------- images
@pytest.mark.parametrize(
    ("dtype", "shape", "encoding"),
    [
        (np.uint8, (5, 7, 3), "rgb8"),
        (np.uint16, (5, 7), "16UC1"),
        (np.float32, (5, 7), "32FC1"),
        (np.uint8, (5, 7), "mono8"),
    ],
)
def test_image_round_trip(dtype: type, shape: tuple[int, ...], encoding: str) -> None:
    rng = np.random.default_rng(1)
    image = (rng.random(shape) * 1000).astype(dtype)
    message = image_to_raw(image, timestamp_ns=STAMP_NS, frame_id="cam")
    assert message.encoding == encoding
    assert message.timestamp.seconds * 10**9 + message.timestamp.nanos == STAMP_NS
    restored = raw_to_image(message.SerializeToString())
    np.testing.assert_array_equal(restored, image)
    assert restored.flags.writeable and restored.flags.c_contiguous


def test_labels_are_mono16() -> None:
    labels = np.arange(12, dtype=np.uint16).reshape(3, 4)
    message = image_to_raw(labels, timestamp_ns=0, encoding="mono16")
    assert message.encoding == "mono16" and message.step == 8
    np.testing.assert_array_equal(raw_to_image(message), labels)


def test_bgr8_with_padded_rows_decodes_to_rgb() -> None:
    height, width, padding = 2, 3, 5
    bgr = np.arange(height * width * 3, dtype=np.uint8).reshape(height, width, 3)
    rows = np.zeros((height, width * 3 + padding), np.uint8)
    rows[:, : width * 3] = bgr.reshape(height, -1)
    message = RawImage(
        width=width, height=height, encoding="bgr8", step=width * 3 + padding, data=rows.tobytes()
    )
    np.testing.assert_array_equal(raw_to_image(message), bgr[..., ::-1])


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"step": 10}, "step 10"),
        ({"data": b"\0" * 30}, "needs 36"),
        ({"encoding": "yuv422"}, "not supported"),
        ({"width": 0}, "empty"),
        ({"width": 100_000, "height": 100_000, "step": 300_000}, "exceeds"),
    ],
)
def test_raw_to_image_rejects_inconsistent_messages(changes: dict, match: str) -> None:
    fields = {"width": 4, "height": 3, "encoding": "rgb8", "step": 12, "data": b"\0" * 36}
    with pytest.raises(MessageError, match=match):
        raw_to_image(RawImage(**(fields | changes)))


# ---------------------------------------------------------------------------------- calibration
def test_calibration_round_trip_and_matrices() -> None:
    intrinsics = CameraIntrinsics(640, 480, 517.3, 516.5, 318.6, 255.3, (0.26, -0.95, 0, 0, 1.16))
    message = intrinsics_to_calibration(intrinsics, timestamp_ns=STAMP_NS, frame_id="cam")
    assert message.distortion_model == "plumb_bob"
    np.testing.assert_array_equal(np.reshape(message.K, (3, 3)), intrinsics.matrix())
    np.testing.assert_array_equal(np.reshape(message.P, (3, 4))[:, :3], intrinsics.matrix())
    assert calibration_to_intrinsics(message.SerializeToString()) == intrinsics


def test_uncalibrated_camera_is_rejected() -> None:
    with pytest.raises(MessageError, match="uncalibrated"):
        calibration_to_intrinsics(CameraCalibration(width=4, height=3, K=[0.0] * 9))
    with pytest.raises(MessageError, match="expected 9"):
        calibration_to_intrinsics(CameraCalibration(width=4, height=3, K=[1.0] * 4))


# ---------------------------------------------------------------------------------- point cloud
def test_cloud_round_trip_layout() -> None:
    rng = np.random.default_rng(2)
    positions = rng.normal(size=(1000, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (1000, 3), dtype=np.uint8)
    message = cloud_to_msg(positions, colors, timestamp_ns=STAMP_NS, frame_id="camera")
    assert message.point_stride == 15 and len(message.data) == 15 * 1000
    assert [(f.name, f.offset, f.type) for f in message.fields] == [
        ("x", 0, PackedElementField.FLOAT32),
        ("y", 4, PackedElementField.FLOAT32),
        ("z", 8, PackedElementField.FLOAT32),
        ("red", 12, PackedElementField.UINT8),
        ("green", 13, PackedElementField.UINT8),
        ("blue", 14, PackedElementField.UINT8),
    ]
    first = struct.unpack_from("<3f3B", message.data, 0)
    assert first == (*positions[0].tolist(), *colors[0].tolist())
    restored_positions, restored_colors = msg_to_cloud(message.SerializeToString())
    np.testing.assert_array_equal(restored_positions, positions)
    np.testing.assert_array_equal(restored_colors, colors)


def test_cloud_views_without_copy_equal_the_copies_and_are_read_only() -> None:
    rng = np.random.default_rng(3)
    positions = rng.normal(size=(1000, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (1000, 3), dtype=np.uint8)
    payload = cloud_to_msg(positions, colors, timestamp_ns=1).SerializeToString()
    view_positions, view_colors = msg_to_cloud(payload, copy=False)
    assert np.array_equal(view_positions, positions) and np.array_equal(view_colors, colors)
    assert not view_positions.flags.writeable and not view_colors.flags.writeable


@pytest.mark.parametrize("count", [0, 1, 7, 2000])
@pytest.mark.parametrize("with_colors", [True, False])
@pytest.mark.parametrize("posed", [True, False])
def test_cloud_to_wire_is_the_serialised_message_byte_for_byte(
        count: int, with_colors: bool, posed: bool) -> None:
    rng = np.random.default_rng(count)
    positions = rng.normal(size=(count, 3))  # float64: converted as cloud_to_msg does
    colors = rng.integers(0, 256, (count, 3), dtype=np.uint8) if with_colors else None
    pose = None
    if posed:
        pose = np.eye(4)
        pose[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
        pose[:3, 3] = [0.5, -2.0, 1.25]
    expected = cloud_to_msg(positions, colors, timestamp_ns=STAMP_NS, frame_id="map",
                            pose=pose).SerializeToString()
    wire = cloud_to_wire(positions, colors, timestamp_ns=STAMP_NS, frame_id="map", pose=pose)
    assert isinstance(wire, bytearray) and bytes(wire) == expected
    wire[:0] = b""  # no numpy view of it left behind: it can still be resized
    restored, restored_colors = msg_to_cloud(bytes(wire))
    np.testing.assert_array_equal(restored, positions.astype(np.float32))
    if with_colors:
        np.testing.assert_array_equal(restored_colors, colors)


def test_cloud_to_wire_validates_like_cloud_to_msg() -> None:
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        cloud_to_wire(np.zeros((4, 2), np.float32), timestamp_ns=0)
    with pytest.raises(ValueError, match="uint8"):
        cloud_to_wire(np.zeros((4, 3), np.float32), np.zeros((4, 3)), timestamp_ns=0)


def test_cloud_without_colors() -> None:
    positions = np.arange(12, dtype=np.float32).reshape(4, 3)
    message = cloud_to_msg(positions, timestamp_ns=0)
    restored, colors = msg_to_cloud(message)
    assert colors is None
    np.testing.assert_array_equal(restored, positions)


def test_foreign_cloud_layout_is_read() -> None:
    """A publisher with float64 xyz, colours first, padding and a 32-byte stride."""
    layout = np.dtype(
        {
            "names": ["blue", "green", "red", "intensity", "z", "y", "x"],
            "formats": ["u1", "u1", "u1", "<f4", "<f8", "<f8", "<f4"],
            "offsets": [0, 1, 2, 4, 8, 16, 24],
            "itemsize": 32,
        }
    )
    points = np.zeros(5, layout)
    points["x"], points["y"], points["z"] = [1, 2, 3, 4, 5], [6, 7, 8, 9, 10], [0.5] * 5
    points["red"], points["green"], points["blue"] = 200, [0, 1, 2, 3, 4], 7
    types = {
        "u1": PackedElementField.UINT8,
        "f4": PackedElementField.FLOAT32,
        "f8": PackedElementField.FLOAT64,
    }
    fields = [
        PackedElementField(name=name, offset=offset, type=types[dtype.str[1:]])
        for name, (dtype, offset) in layout.fields.items()
    ]
    message = PointCloud(point_stride=32, fields=fields, data=points.tobytes())
    positions, colors = msg_to_cloud(message)
    np.testing.assert_array_equal(positions[:, 0], [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(positions[:, 1], [6, 7, 8, 9, 10])
    np.testing.assert_array_equal(positions[:, 2], [0.5] * 5)
    np.testing.assert_array_equal(colors, np.stack([[200] * 5, range(5), [7] * 5], axis=1))


def test_cloud_validation() -> None:
    message = cloud_to_msg(np.zeros((10, 3), np.float32), timestamp_ns=0)
    with pytest.raises(MessageError, match="limit of 5"):
        msg_to_cloud(message, max_points=5)
    message.data = message.data[:-1]
    with pytest.raises(MessageError, match="not a multiple"):
        msg_to_cloud(message)
    no_z = PointCloud(point_stride=8, fields=message.fields[:2], data=b"\0" * 16)
    with pytest.raises(MessageError, match="no z field"):
        msg_to_cloud(no_z)


# ------------------------------------------------------------------------------------- topology
def _topology_arrays(nodes: int = 6) -> dict:
    rng = np.random.default_rng(3)
    return dict(
        positions=rng.normal(size=(nodes, 3)),
        colors=rng.uniform(-20, 300, size=(nodes, 3)),
        normals=rng.normal(size=(nodes, 3)),
        errors=rng.random(nodes),
        edges={"pos": np.array([[0, 1], [1, 2], [4, 5]]), "col": np.empty((0, 2), int)},
        clusterings={"pos": np.array([0, 0, 0, -1, 1, 1]), "col+nor": np.arange(nodes)},
        steps=1234,
        frame_sequence=42,
        timestamp_ns=STAMP_NS,
        frame_id="camera",
        quantization_error={"pos": 0.01, "col": 12.5},
        node_ids=np.array([3, 10, 11, 40, 41, 7])[:nodes],
        cluster_ids={"pos": np.array([12, 5])},
    )


def test_topology_round_trip() -> None:
    arrays = _topology_arrays()
    snapshot = decode_topology(encode_topology(**arrays).SerializeToString())
    np.testing.assert_array_equal(snapshot.positions, arrays["positions"].astype(np.float32))
    expected_colors = np.clip(np.rint(arrays["colors"]), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(snapshot.colors, expected_colors)
    np.testing.assert_array_equal(snapshot.normals, arrays["normals"].astype(np.float32))
    np.testing.assert_array_equal(snapshot.errors, arrays["errors"].astype(np.float32))
    assert snapshot.edges.keys() == {"pos", "col"}
    np.testing.assert_array_equal(snapshot.edges["pos"], arrays["edges"]["pos"])
    assert snapshot.edges["col"].shape == (0, 2) and snapshot.edges["pos"].dtype == np.uint32
    np.testing.assert_array_equal(snapshot.clusterings["pos"], arrays["clusterings"]["pos"])
    assert snapshot.cluster_counts == {"pos": 2, "col+nor": 6}
    np.testing.assert_array_equal(snapshot.node_ids, arrays["node_ids"])
    assert snapshot.node_ids.dtype == np.int64
    assert snapshot.cluster_ids.keys() == {"pos"}  # "col+nor" is published untracked
    np.testing.assert_array_equal(snapshot.cluster_ids["pos"], [12, 5])
    assert (snapshot.steps, snapshot.frame_sequence, snapshot.timestamp_ns) == (1234, 42, STAMP_NS)
    assert snapshot.frame_id == "camera" and snapshot.quantization_error == {
        "pos": 0.01,
        "col": 12.5,
    }


def test_topology_encoder_validates_inputs() -> None:
    arrays = _topology_arrays()
    with pytest.raises(ValueError, match="outside"):
        encode_topology(**(arrays | {"edges": {"pos": np.array([[0, 6]])}}))
    with pytest.raises(ValueError, match="normals"):
        encode_topology(**(arrays | {"normals": np.zeros((5, 3))}))
    with pytest.raises(ValueError, match="clusterings"):
        encode_topology(**(arrays | {"clusterings": {"pos": np.zeros(4)}}))
    with pytest.raises(ValueError, match="one id per label"):
        encode_topology(**(arrays | {"cluster_ids": {"pos": np.array([1, 2, 3])}}))
    with pytest.raises(ValueError, match="unknown clusterings"):
        encode_topology(**(arrays | {"cluster_ids": {"nor": np.array([1])}}))


def test_topology_decoder_rejects_inconsistent_messages() -> None:
    message = encode_topology(**_topology_arrays())
    message.edges[0].pairs.CopyFrom(pack_array(np.array([[0, 9]]), np.uint32))
    with pytest.raises(MessageError, match="node index 9"):
        decode_topology(message)
    message = encode_topology(**_topology_arrays())
    message.colors.CopyFrom(pack_array(np.zeros((5, 3)), np.uint8))
    with pytest.raises(MessageError, match="colors"):
        decode_topology(message)
    message = encode_topology(**_topology_arrays())
    message.clusterings[0].labels.CopyFrom(pack_array(np.zeros(5), np.int32))
    with pytest.raises(MessageError, match="5 labels for 6 nodes"):
        decode_topology(message)
    with pytest.raises(MessageError, match="limit"):
        decode_topology(encode_topology(**_topology_arrays()), max_nodes=5)
    message = encode_topology(**_topology_arrays())
    message.node_ids.CopyFrom(pack_array(np.arange(5), np.int64))
    with pytest.raises(MessageError, match="node_ids"):
        decode_topology(message)
    message = encode_topology(**_topology_arrays())
    message.clusterings[0].cluster_ids.CopyFrom(pack_array(np.arange(1), np.int64))
    with pytest.raises(MessageError, match="1 ids for 2 labels"):
        decode_topology(message)
    message.clusterings[0].cluster_ids.CopyFrom(pack_array(np.arange(10**6), np.int64))
    with pytest.raises(MessageError, match="limit"):  # refused before it is allocated
        decode_topology(message)


# ---------------------------------------------------------------------- status and stream end
def test_status_and_stream_end_round_trip() -> None:
    status = decode_status(
        encode_status(
            timestamp_ns=STAMP_NS,
            frame_sequence=7,
            steps=100,
            steps_per_second=5000.5,
            nodes=300,
            frames_dropped=2,
            latency_p99_ms=12.5,
            quantization_error={"pos": 0.1},
            cluster_counts={"col": 3},
        ).SerializeToString()
    )
    assert (status.timestamp_ns, status.frame_sequence, status.nodes) == (STAMP_NS, 7, 300)
    assert status.steps_per_second == 5000.5 and status.frames_dropped == 2
    assert status.quantization_error == {"pos": 0.1} and status.cluster_counts == {"col": 3}
    end = decode_stream_end(
        encode_stream_end(
            timestamp_ns=5, frames_sent=30, last_frame_sequence=29, recording="a.mcap"
        ).SerializeToString()
    )
    assert (end.timestamp_ns, end.frames_sent, end.last_frame_sequence) == (5, 30, 29)
    assert end.recording == "a.mcap"
    with pytest.raises(ValueError, match="no field"):
        encode_status(speed=1)


# ---------------------------------------------------------------------------- garbage payloads
_DECODERS = [
    decode_topology,
    decode_status,
    decode_stream_end,
    raw_to_image,
    msg_to_cloud,
    calibration_to_intrinsics,
    unpack_array,
]


@settings(max_examples=200, deadline=None)
@given(payload=st.binary(max_size=200), decoder_index=st.integers(0, len(_DECODERS) - 1))
def test_decoders_raise_only_message_error_on_garbage(payload: bytes, decoder_index: int) -> None:
    try:
        _DECODERS[decoder_index](payload)
    except MessageError:
        pass


def test_decoders_reject_non_bytes() -> None:
    for decoder in _DECODERS:
        with pytest.raises(MessageError):
            decoder(12345)


def test_negative_timestamp_round_trips() -> None:
    message = image_to_raw(np.zeros((1, 1), np.uint8), timestamp_ns=-1_500_000_000)
    assert message.timestamp.seconds == -2 and message.timestamp.nanos == 500_000_000
    assert math.isclose(message.timestamp.seconds + message.timestamp.nanos / 1e9, -1.5)


def test_frame_attachment_refuses_sequences_beyond_signed_64_bits() -> None:
    import struct

    from gngdt.schemas.wire import FrameStamp

    largest = FrameStamp(2**63 - 1, 5).to_attachment()
    assert FrameStamp.from_attachment(largest).sequence == 2**63 - 1
    # rerun's and MCAP's timelines are signed: such a frame would crash a consumer, not log it
    with pytest.raises(ValueError, match="out of range"):
        FrameStamp.from_attachment(struct.pack("<Qq", 2**63, 0))
