"""Hostile payloads on every topic: the services' own per-sample decode paths never raise
anything but ``ValueError`` (counted, skipped), and size limits hold before any allocation.

Property-based (hypothesis) on random bytes and on structurally valid messages with hostile
fields, plus one process-level flood of a running learner and logger over a real zenoh router.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gngdt.schemas import gngdt_pb2
from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.images import MAX_IMAGE_PIXELS, calibration_to_intrinsics, raw_to_image
from gngdt.schemas.messages import MessageError
from gngdt.schemas.topology import decode_topology, encode_topology
from gngdt.schemas.wire import FrameStamp
from gngdt.services.learner.messages import decode_points

FUZZ = settings(max_examples=200)  # on top of tests/conftest.py's profile

#: every stream the logger subscribes to (``gngdt/<cam>/<stream>``)
STREAMS = ("color", "depth", "calibration", "points", "topology", "objects", "learner/status",
           "eos")
UINT32 = st.integers(0, 2**32 - 1)
GOOD_ATTACHMENT = FrameStamp(1, time.time_ns()).to_attachment()  # a day of validity

attachments = st.one_of(st.none(), st.just(GOOD_ATTACHMENT), st.binary(max_size=32))


# ------------------------------------------------------------------------- message strategies
@st.composite
def hostile_clouds(draw: st.DrawFn) -> bytes:
    """A foxglove PointCloud with arbitrary stride, fields and data (often inconsistent)."""
    names = st.sampled_from(["x", "y", "z", "red", "green", "blue", "intensity", ""])
    cloud_fields = draw(st.lists(
        st.builds(PackedElementField, name=names, offset=st.integers(0, 2**32 - 1),
                  type=st.integers(0, 9)),
        max_size=8))
    if draw(st.booleans()):  # often a plausible layout, so decoding gets past the field checks
        cloud_fields = [PackedElementField(name=axis, offset=4 * index, type=7)
                        for index, axis in enumerate("xyz")] + cloud_fields
    message = PointCloud(point_stride=draw(st.one_of(st.integers(0, 40), UINT32)),
                         fields=cloud_fields, data=draw(st.binary(max_size=400)))
    return message.SerializeToString()


@st.composite
def hostile_images(draw: st.DrawFn) -> bytes:
    encodings = st.one_of(
        st.sampled_from(["rgb8", "bgr8", "rgba8", "mono8", "16UC1", "mono16", "32FC1"]),
        st.text(max_size=8))
    message = RawImage(width=draw(st.one_of(st.integers(0, 20), UINT32)),
                       height=draw(st.one_of(st.integers(0, 20), UINT32)),
                       step=draw(st.one_of(st.integers(0, 80), UINT32)),
                       encoding=draw(encodings), data=draw(st.binary(max_size=600)))
    return message.SerializeToString()


@st.composite
def hostile_calibrations(draw: st.DrawFn) -> bytes:
    numbers = st.floats(allow_nan=True, allow_infinity=True)
    message = CameraCalibration(width=draw(UINT32), height=draw(UINT32),
                                K=draw(st.lists(numbers, max_size=12)),
                                D=draw(st.lists(numbers, max_size=6)))
    return message.SerializeToString()


def hostile_arrays() -> st.SearchStrategy[gngdt_pb2.PackedArray]:
    dtypes = st.sampled_from(["float32", "uint8", "uint32", "int32", "float64", "object", ""])
    shapes = st.lists(st.one_of(st.integers(0, 8), st.integers(0, 2**32 - 1)), max_size=3)
    return st.builds(gngdt_pb2.PackedArray, dtype=dtypes, shape=shapes,
                     data=st.binary(max_size=200))


@st.composite
def hostile_topologies(draw: st.DrawFn) -> bytes:
    """A Topology from a valid one with some parts replaced by hostile arrays."""
    nodes = draw(st.integers(0, 6))
    rng = np.random.default_rng(draw(st.integers(0, 1000)))
    message = encode_topology(
        positions=rng.random((nodes, 3), dtype=np.float32),
        colors=rng.integers(0, 256, (nodes, 3)), normals=None, errors=None,
        edges={"pos": rng.integers(0, max(nodes, 1), (nodes, 2)) if nodes else np.zeros((0, 2))},
        clusterings={"pos": np.zeros(nodes, np.int32)},
        steps=1, frame_sequence=1, timestamp_ns=1, frame_id="camera")
    for part in draw(st.lists(st.sampled_from(["positions", "colors", "normals", "errors",
                                                "edges", "labels"]), max_size=3)):
        array = draw(hostile_arrays())
        if part == "edges":
            message.edges.add(property=draw(st.sampled_from(["pos", "col"])), pairs=array)
        elif part == "labels":
            message.clusterings.add(name=draw(st.sampled_from(["pos", "nor"])), labels=array)
        else:
            getattr(message, part).CopyFrom(array)
    return message.SerializeToString()


def any_payload() -> st.SearchStrategy[bytes]:
    return st.one_of(st.binary(max_size=300), hostile_clouds(), hostile_images(),
                     hostile_calibrations(), hostile_topologies())


# ------------------------------------------------------------------------- the learner's path
@FUZZ
@given(payload=st.one_of(st.binary(max_size=300), hostile_clouds()), attachment=attachments)
def test_learner_decode_path_raises_only_value_error(payload: bytes, attachment) -> None:
    try:
        stamp, positions, colors, frame_id, pose, _ = decode_points(payload, attachment)
    except ValueError:
        return
    assert isinstance(frame_id, str)
    assert pose is None or (pose.shape == (4, 4) and np.isfinite(pose).all())
    assert attachment == GOOD_ATTACHMENT and stamp.sequence == 1
    assert positions.dtype == np.float32 and positions.ndim == 2 and positions.shape[1] == 3
    assert len(positions) >= 1 and np.isfinite(positions).all()
    assert colors is None or (colors.dtype == np.uint8 and colors.shape == positions.shape)


def test_learner_refuses_a_cloud_over_its_point_limit_before_allocating() -> None:
    rng = np.random.default_rng(0)
    positions = rng.random((50_000, 3), dtype=np.float32)
    payload = cloud_to_msg(positions, rng.integers(0, 256, (50_000, 3), dtype=np.uint8),
                           timestamp_ns=1).SerializeToString()
    tracemalloc.start()
    try:
        with pytest.raises(MessageError, match="limit of 49999"):
            decode_points(payload, GOOD_ATTACHMENT, max_points=49_999)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < len(payload) + 100_000  # the protobuf copy of the data, no point arrays
    decoded = decode_points(payload, GOOD_ATTACHMENT, max_points=50_000).positions
    np.testing.assert_array_equal(decoded, positions)


def test_a_colourless_cloud_is_refused_before_it_can_shape_the_model() -> None:
    payload = cloud_to_msg(np.ones((10, 3), np.float32), timestamp_ns=1).SerializeToString()
    with pytest.raises(MessageError, match="colour"):
        decode_points(payload, GOOD_ATTACHMENT)


def test_overflowing_coordinates_are_not_learned() -> None:
    from gngdt.core import GNGDT

    model = GNGDT(max_nodes=20, random_state=0).partial_fit(np.ones((50, 3)) * [[1, 2, 3]])
    before = model.get_state()
    model.partial_fit(np.full((100, 3), 1e300))  # finite, but every squared distance is inf
    after = model.get_state()
    for name in ("pos", "col", "err", "nbr", "age"):
        np.testing.assert_array_equal(before[name], after[name])
    assert np.isfinite(model.positions_).all() and model.n_nodes_ == 2


# ------------------------------------------------------------------ the logger's decoders
@FUZZ
@given(payload=hostile_images())
def test_image_decoder_gives_the_declared_shape_or_message_error(payload: bytes) -> None:
    message = RawImage.FromString(payload)
    try:
        image = raw_to_image(payload)
    except MessageError:
        return
    assert image.shape[:2] == (message.height, message.width)
    assert image.flags.c_contiguous and image.flags.writeable


@FUZZ
@given(payload=hostile_calibrations())
def test_calibration_decoder_gives_usable_intrinsics_or_message_error(payload: bytes) -> None:
    try:
        intrinsics = calibration_to_intrinsics(payload)
    except MessageError:
        return
    assert intrinsics.fx > 0 and intrinsics.fy > 0
    assert np.isfinite([intrinsics.fx, intrinsics.fy]).all()
    assert intrinsics.width > 0 and intrinsics.height > 0


@FUZZ
@given(payload=hostile_topologies())
def test_topology_decoder_gives_a_consistent_snapshot_or_message_error(payload: bytes) -> None:
    try:
        snapshot = decode_topology(payload)
    except MessageError:
        return
    count = snapshot.node_count
    assert snapshot.positions.shape == (count, 3)
    for pairs in snapshot.edges.values():
        assert pairs.ndim == 2 and pairs.shape[1] == 2 and (pairs < max(count, 1)).all()
    for labels in snapshot.clusterings.values():
        assert labels.shape == (count,) and (labels >= -1).all()


@pytest.mark.parametrize(
    ("decode", "message", "match"),
    [
        (raw_to_image, RawImage(width=60_000, height=60_000, step=180_000, encoding="rgb8",
                                data=b"\x00" * 64), f"exceeds {MAX_IMAGE_PIXELS} pixels"),
        (raw_to_image, RawImage(width=4000, height=4000, step=12_000, encoding="rgb8",
                                data=b"\x00" * 64), "needs 48000000"),
        (decode_topology, gngdt_pb2.Topology(positions=gngdt_pb2.PackedArray(
            dtype="float32", shape=[2_000_000, 3], data=b"")), "exceed the limit"),
        (decode_topology, gngdt_pb2.Topology(positions=gngdt_pb2.PackedArray(
            dtype="float32", shape=[2**32 - 1, 2**32 - 1], data=b"")), "exceed the limit"),
    ],
)
def test_size_limits_are_checked_before_allocating(decode, message, match: str) -> None:
    payload = message.SerializeToString()
    tracemalloc.start()
    try:
        with pytest.raises(MessageError, match=match):
            decode(payload)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000, f"{peak} bytes allocated for a {len(payload)}-byte payload"


def test_topology_node_limit_is_the_callers() -> None:
    message = encode_topology(
        positions=np.zeros((11, 3), np.float32), colors=None, normals=None, errors=None,
        edges={}, clusterings={}, steps=0, frame_sequence=0, timestamp_ns=0, frame_id="c")
    assert decode_topology(message, max_nodes=11).node_count == 11
    with pytest.raises(MessageError, match="limit"):
        decode_topology(message.SerializeToString(), max_nodes=10)


@pytest.fixture(scope="module")
def dispatcher():
    """The logger's real per-sample path (decode + rerun logging) into an in-memory recording."""
    import rerun as rr

    from gngdt.io.outputs.rerun_log import DisplayRates, RerunLog
    from gngdt.io.outputs.rerun_output import RerunOutput
    from gngdt.services.logger.cameras import Cameras
    from gngdt.services.logger.dispatch import Dispatcher

    recording = rr.RecordingStream("gngdt-fuzz")
    recording.memory_recording()
    # every frame of every stream, so that every payload reaches its decoder
    rates = DisplayRates(image_every=1, depth_every=1, topology_every=1, cloud_every=1,
                         max_cloud_points=100)
    yield Dispatcher([RerunOutput(RerunLog(recording, rates))], Cameras())
    recording.disconnect()


#: sequence 2**63: rerun's signed sequence timeline cannot hold it (found by this fuzz test)
SEQUENCE_2_63 = b"\x00" * 7 + b"\x80" + FrameStamp(0, time.time_ns()).to_attachment()[8:]


@FUZZ
@given(stream=st.sampled_from(STREAMS), payload=any_payload(), attachment=attachments)
@example(stream="color", payload=b"", attachment=SEQUENCE_2_63)
@example(stream="points", payload=b"", attachment=b"\x00" * 8 + b"\x00" * 7 + b"\x80")
def test_logger_dispatch_counts_malformed_and_never_raises(
    dispatcher, stream: str, payload: bytes, attachment
) -> None:
    before = dispatcher.malformed
    dispatcher.handle(f"gngdt/fuzzcam/{stream}", payload, attachment)
    assert dispatcher.malformed in (before, before + 1)
    if attachment != GOOD_ATTACHMENT:
        assert dispatcher.malformed == before + 1  # no frame stamp: never logged


# ------------------------------------------------------------ flooding the running services


# ------------------------------------------------------------------ stamps and counters
@pytest.mark.parametrize(("sequence", "capture_time_ns"), [
    (2**63, 1), (2**64 - 1, time.time_ns()), (0, 0), (0, -(2**63)), (1, -1)])
def test_impossible_stamps_are_malformed(sequence: int, capture_time_ns: int) -> None:
    import struct

    attachment = struct.pack("<Qq", sequence, capture_time_ns)
    with pytest.raises(ValueError, match=r"sequence|capture time"):
        FrameStamp.from_attachment(attachment)


def test_a_capture_time_a_day_away_from_this_clock_is_refused_by_the_learner() -> None:
    payload = cloud_to_msg(np.ones((10, 3), np.float32), np.ones((10, 3), np.uint8),
                           timestamp_ns=1).SerializeToString()
    now = time.time_ns()
    for offset_s in (-2 * 86400, 2 * 86400):
        attachment = FrameStamp(3, now + offset_s * 10**9).to_attachment()
        with pytest.raises(ValueError, match="impossible capture time"):
            decode_points(payload, attachment, now_ns=now)
    stamp = decode_points(payload, FrameStamp(3, now - 10**9).to_attachment(), now_ns=now).stamp
    assert stamp.sequence == 3


def test_learner_counters_saturate_and_always_encode() -> None:
    from gngdt.core.learner.results import MAX_COUNTER, Counters
    from gngdt.schemas.status import encode_status

    counters = Counters()
    for sequence in (0, 2**63 - 1, 0, 2**63 - 1, 5, 2**40, 2**40 + 3):
        counters.note_sequence(sequence)
    assert 0 <= counters.frames_dropped <= MAX_COUNTER
    assert counters.frames_dropped == 2  # only the real gap 2**40 -> 2**40 + 3
    counters.frames_dropped = MAX_COUNTER - 1
    counters.note_sequence(2**40 + 10)
    assert counters.frames_dropped == MAX_COUNTER
    encode_status(frames_dropped=counters.frames_dropped, frame_sequence=counters.last_sequence)
