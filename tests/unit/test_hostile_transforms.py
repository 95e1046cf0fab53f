"""Transforms stamped far from the others, and floods of made-up frames (issue 38): a lookup is
bounded to the links of the camera's chain, a sample stamped far from the others is ignored and
counted, and a poisoned link never blocks the rest."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from mcap_protobuf.writer import Writer

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.mcap.reader import read_frames
from gngdt.io.tf_tree import TransformError, TransformTree
from gngdt.schemas.clouds import pose_to_transform
from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration

SECOND = 1_000_000_000
NOW = 1_700_000_000 * SECOND
#: 2038-01-19, the decoy's stamp in the issue
YEAR_2038 = 2_147_483_000 * SECOND
IDENTITY = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])


def test_each_link_is_held_over_its_own_window() -> None:
    """Before, the live bridge forgot every link's samples older than the newest stamp of any
    link minus 10 s: one 2038 stamp on an unrelated link left the camera's link one sample."""
    tree = TransformTree()
    for k in range(50):
        tree.add("odom", "camera", NOW + k * SECOND // 10, [k * 0.1, 0, 0], IDENTITY[1])
    tree.add("map", "decoy", YEAR_2038, *IDENTITY)
    tree.forget_stale(10 * SECOND)
    assert tree.samples == 51
    np.testing.assert_allclose(tree.lookup("odom", "camera", NOW + SECOND)[:3, 3], [1.0, 0, 0])


def test_a_window_around_the_images_drops_far_samples_and_frees_their_links() -> None:
    tree = TransformTree()
    tree.add("decoy", "camera", YEAR_2038, *IDENTITY)  # came first, stamped far ahead
    assert tree.forget_outside(NOW - 10 * SECOND, NOW + 10 * SECOND) == 1
    tree.add("odom", "camera", NOW, [1.0, 2.0, 3.0], IDENTITY[1])  # its link was freed
    np.testing.assert_allclose(tree.lookup("odom", "camera", NOW)[:3, 3], [1.0, 2.0, 3.0])
    tree.add("world", "odom", 0, *IDENTITY, static=True)
    assert tree.forget_outside(NOW + SECOND, NOW + 2 * SECOND) == 1  # statics stay
    assert tree.frames == {"world", "odom"}


def test_a_flood_of_made_up_frames_cannot_lock_the_cameras_links_out() -> None:
    """A live tree (``evict``) drops the link lookups used least recently to take a new one;
    before, the 1025th frame was refused, the camera's among them once a flood came first."""
    tree = TransformTree(max_links=50, evict=True)
    tree.add("odom", "base", NOW, *IDENTITY)
    tree.add("base", "camera", NOW, [0.0, 0.0, 1.0], IDENTITY[1])
    tree.lookup("odom", "camera", NOW)
    for index in range(1000):
        tree.add("map", f"decoy{index}", NOW, *IDENTITY)
    assert len(tree) == 50
    np.testing.assert_allclose(tree.lookup("odom", "camera", NOW)[:3, 3], [0.0, 0.0, 1.0])
    tree.add("odom", "lidar", NOW, *IDENTITY)  # a new real link still gets in
    strict = TransformTree(max_links=2)  # a recording's tree keeps its first links
    strict.add("a", "b", 0, *IDENTITY)
    strict.add("b", "c", 0, *IDENTITY)
    with pytest.raises(TransformError, match="more than 2 frames"):
        strict.add("c", "d", 0, *IDENTITY)


WIDTH, HEIGHT = 32, 24
CAMERA = CameraIntrinsics(WIDTH, HEIGHT, 30.0, 30.0, 15.5, 11.5)


def write_recording(path: Path, frames: int, posed: int,
                    forged: list[tuple[str, str, int]]) -> Path:
    """``frames`` frames, the first ``posed`` with a world -> camera transform at their stamp
    (x = their index), and ``forged`` (parent, child, stamp) transforms logged with frame 0."""
    rng = np.random.default_rng(0)
    with open(path, "wb") as stream:
        writer = Writer(stream)
        for index in range(frames):
            stamp = NOW + index * SECOND // 10
            pose = np.eye(4)
            pose[0, 3] = index
            messages = [("/tf", pose_to_transform(pose, parent, child, timestamp_ns=when))
                        for parent, child, when in (forged if index == 0 else [])]
            if index < posed:
                messages.append(("/tf", pose_to_transform(pose, "world", "camera",
                                                          timestamp_ns=stamp)))
            messages += [
                ("/camera/calibration", intrinsics_to_calibration(CAMERA, timestamp_ns=stamp,
                                                                  frame_id="camera")),
                ("/camera/color", image_to_raw(rng.integers(0, 256, (HEIGHT, WIDTH, 3),
                                                            dtype=np.uint8),
                                               timestamp_ns=stamp, frame_id="camera")),
                ("/camera/depth", image_to_raw(np.full((HEIGHT, WIDTH), 900, np.uint16),
                                               timestamp_ns=stamp, frame_id="camera"))]
            for topic, message in messages:
                writer.write_message(topic, message, log_time=stamp, publish_time=stamp)
        writer.finish()
    return path


def test_a_far_future_sample_on_the_cameras_link_is_ignored_in_a_recording(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Before, frames after the link's last real sample took a pose interpolated toward the
    2038 sample (the last real one, held for ever); now they have none, as without it."""
    path = write_recording(tmp_path / "forged.mcap", 6, 3,
                           [("world", "camera", YEAR_2038), ("map", "decoy", YEAR_2038)])
    with caplog.at_level(logging.WARNING):
        frames = list(read_frames(path))
    assert [frame.pose is not None for frame in frames] == [True] * 3 + [False] * 3
    for frame in frames[:3]:
        np.testing.assert_allclose(frame.pose.matrix[0, 3], frame.index)
    assert "2 transform samples stamped over 60 s away from the others" in caplog.text


def test_a_recording_in_simulated_time_keeps_every_pose(tmp_path: Path) -> None:
    """Stamps far from the log times, but all of them alike (a bag of simulated time)."""
    path = write_recording(tmp_path / "sim.mcap", 4, 4, [])
    sim = tmp_path / "sim_time.mcap"
    from mcap.reader import make_reader
    from mcap.writer import Writer as RawWriter

    with open(path, "rb") as source, open(sim, "wb") as target:
        reader = make_reader(source)
        writer = RawWriter(target)
        writer.start()
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id])
            writer.add_message(channels[channel.id], log_time=message.log_time + 3600 * SECOND,
                               data=message.data, publish_time=message.publish_time)
        writer.finish()
    assert all(frame.pose is not None for frame in read_frames(sim))
