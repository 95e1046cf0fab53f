"""What a recording's transforms may cost the reader: samples kept compactly and up to a limit
(later frames then say they have no pose), frames per tree bounded, stamps beyond 64 bits
refused as bad transforms, samples in any order looked up as if they came in order."""

from __future__ import annotations

import dataclasses
import logging
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from gngdt.io.mcap.reader import ReadLimits, read_frames
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.io.tf_tree import TransformError, TransformTree

MS = 1_000_000


def _moving_camera(stamp_ns: int) -> np.ndarray:
    """(4, 4) world_from_camera: 1 m/s along x."""
    matrix = np.eye(4)
    matrix[0, 3] = stamp_ns / 1e9
    return matrix


def test_transforms_beyond_the_limit_are_not_read_and_later_frames_say_so(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from gngdt.io.synth.render import render_scene

    path = tmp_path / "long-tf.mcap"
    frames = [dataclasses.replace(frame, timestamp_ns=(index + 1) * 100 * MS)
              for index, frame in enumerate(render_scene("data2", 4, width=32, height=24))]
    with RecordingWriter(path) as writer:
        for stamp in range(90 * MS, 420 * MS, MS):  # 1 kHz: 330 samples, 150 read (to 0.239 s)
            writer.write_transform(_moving_camera(stamp), "world", "camera", stamp)
        for frame in frames:
            writer.write_frame(frame)
    with caplog.at_level(logging.WARNING):
        read = list(read_frames(path, limits=ReadLimits(max_transform_samples=150)))
    assert "more than 150 transform samples (--max-transforms)" in caplog.text
    assert [frame.pose is not None for frame in read] == [True, True, False, False]
    np.testing.assert_allclose(read[1].pose.matrix, _moving_camera(200 * MS), atol=1e-9)
    assert "no transform 'world' -> 'camera' at 0.300 s" in read[2].pose_error
    # and with the default limit, every frame has its pose
    assert all(frame.pose is not None for frame in read_frames(path))


def test_samples_cost_64_bytes_each_and_any_order_is_looked_up_in_order() -> None:
    stamps = np.arange(10_000, dtype=np.int64) * MS
    shuffled = np.random.default_rng(0).permutation(stamps)
    any_order = TransformTree()
    tracemalloc.start()
    for stamp in shuffled:
        any_order.add("world", "camera", int(stamp), [stamp / 1e9, 0.0, 0.0], [0, 0, 0, 1])
    held, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert any_order.samples == 10_000
    assert held < 10_000 * 100, f"{held / 10_000:.0f} bytes a sample"  # tuples: ~400
    for query in (0, 5 * MS + MS // 4, 999 * MS, 9_999 * MS):
        expected = np.eye(4)
        expected[0, 3] = query / 1e9  # x = t (s): interpolated between its two neighbours
        np.testing.assert_allclose(any_order.lookup("world", "camera", query), expected,
                                   atol=1e-12)


def test_a_tree_holds_a_bounded_number_of_frames() -> None:
    tree = TransformTree(max_links=50)
    for index in range(50):  # a chain: each new link walks its parent's ancestors
        tree.add(f"f{index}", f"f{index + 1}", 0, [0, 0, 0], [0, 0, 0, 1])
    with pytest.raises(TransformError, match="'f50' -> 'f51': more than 50 frames"):
        tree.add("f50", "f51", 0, [0, 0, 0], [0, 0, 0, 1])
    tree.add("f0", "f1", 1, [0, 0, 0], [0, 0, 0, 1])  # a known link still takes samples
    assert TransformTree().max_links == 1024


@pytest.mark.parametrize("stamp", [2**63, -(2**63) - 1, 9_223_372_036 * 10**9 * 1000])
def test_a_stamp_beyond_64_bits_is_a_bad_transform(stamp: int) -> None:
    with pytest.raises(TransformError, match="beyond 64 bits"):
        TransformTree().add("world", "camera", stamp, [0, 0, 0], [0, 0, 0, 1])


def test_a_transform_stamped_beyond_64_bits_in_a_recording_is_skipped_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from mcap_protobuf.writer import Writer

    from gngdt.io.mcap.reader import read_transforms

    path = tmp_path / "far-future.mcap"
    with open(path, "wb") as file, Writer(file) as writer:
        for seconds in (1, 2**62, 2):  # 2**62 s is beyond int64 nanoseconds
            transform = FrameTransform(parent_frame_id="world", child_frame_id="camera")
            transform.timestamp.seconds, transform.rotation.w = seconds, 1.0
            writer.write_message("/tf", transform, log_time=seconds, publish_time=1)
    with open(path, "rb") as stream, caplog.at_level(logging.WARNING):
        tree = read_transforms(stream, path)
    assert tree.samples == 2  # the pass went on after the bad one
    assert "beyond 64 bits; skipped" in caplog.text
