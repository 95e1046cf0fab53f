"""MCAP recordings: gngdt's writer and reader, ROS 2 bags, damaged files, the summary."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.Log_pb2 import Log
from helpers.recordings import HEIGHT, INTRINSICS, PERIOD_NS, START_NS, WIDTH, make_frames
from helpers.ros2_bags import write_ros_bag
from mcap_protobuf.writer import Writer as ProtobufWriter

from gngdt.io.frame import Frame
from gngdt.io.mcap.reader import RecordingError, read_frames, recording_info
from gngdt.io.mcap.writer import RecordingWriter
from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration


def write(path: Path, frames: list[Frame], **options) -> Path:
    with RecordingWriter(path, **options) as writer:
        for frame in frames:
            writer.write_frame(frame)
    return path


# ------------------------------------------------------------------------ gngdt's own layout
@pytest.mark.parametrize("color_format", ["raw", "png"])
@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_lossless_round_trip(tmp_path: Path, color_format: str, compression: str) -> None:
    frames = make_frames(4, labels=True)
    path = write(tmp_path / "r.mcap", frames, color_format=color_format, compression=compression)
    restored = list(read_frames(path))
    assert len(restored) == len(frames)
    for original, copy in zip(frames, restored, strict=True):
        assert copy.index == original.index and copy.timestamp_ns == original.timestamp_ns
        np.testing.assert_array_equal(copy.color, original.color)
        np.testing.assert_array_equal(copy.depth, original.depth)
        np.testing.assert_array_equal(copy.labels, original.labels)
        assert copy.intrinsics == INTRINSICS
        assert copy.color.dtype == np.uint8 and copy.depth.dtype == np.uint16


def test_jpeg_colour_is_close(tmp_path: Path) -> None:
    smooth = np.broadcast_to(
        np.linspace(0, 255, WIDTH, dtype=np.uint8)[None, :, None], (HEIGHT, WIDTH, 3)
    ).copy()
    frame = make_frames(1)[0]
    frame.color = smooth
    (restored,) = read_frames(write(tmp_path / "j.mcap", [frame], color_format="jpeg"))
    assert np.abs(restored.color.astype(int) - smooth).mean() < 3
    np.testing.assert_array_equal(restored.depth, frame.depth)
    assert restored.labels is None


def test_channel_layout_follows_the_design(tmp_path: Path) -> None:
    path = write(tmp_path / "r.mcap", make_frames(3, labels=True))
    info = recording_info(path)
    assert info["frames"] == 3
    assert info["channels"] == {
        "/camera/color": {"schema": "foxglove.RawImage", "messages": 3},
        "/camera/depth": {"schema": "foxglove.RawImage", "messages": 3},
        "/camera/calibration": {"schema": "foxglove.CameraCalibration", "messages": 3},
        "/camera/labels": {"schema": "foxglove.RawImage", "messages": 3},
    }
    assert info["start_ns"] == START_NS and info["end_ns"] == START_NS + 2 * PERIOD_NS
    assert info["duration_s"] == pytest.approx(2 * PERIOD_NS / 1e9)
    assert info["size_bytes"] == path.stat().st_size


def test_unknown_channels_are_ignored(tmp_path: Path) -> None:
    frames = make_frames(2)
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as stream, ProtobufWriter(stream) as writer:
        for frame in frames:
            stamp = frame.timestamp_ns
            writer.write_message("/rosout", Log(message="hello"), log_time=stamp)
            writer.write_message(
                "/camera/calibration",
                intrinsics_to_calibration(INTRINSICS, timestamp_ns=stamp),
                log_time=stamp,
            )
            writer.write_message(
                "/camera/color", image_to_raw(frame.color, timestamp_ns=stamp), log_time=stamp
            )
            writer.write_message(
                "/camera/depth", image_to_raw(frame.depth, timestamp_ns=stamp), log_time=stamp
            )
            writer.write_message(
                "/other/thing",
                image_to_raw(np.zeros((2, 2, 3), np.uint8), timestamp_ns=stamp, encoding="rgb8"),
                log_time=stamp,
            )
    restored = list(read_frames(path, camera_prefix="/camera"))
    assert [f.timestamp_ns for f in restored] == [f.timestamp_ns for f in frames]
    np.testing.assert_array_equal(restored[1].color, frames[1].color)


def test_missing_calibration_is_an_error_unless_intrinsics_given(tmp_path: Path) -> None:
    path = tmp_path / "nocal.mcap"
    frame = make_frames(1)[0]
    with open(path, "wb") as stream, ProtobufWriter(stream) as writer:
        for topic, image in (("/camera/color", frame.color), ("/camera/depth", frame.depth)):
            writer.write_message(topic, image_to_raw(image, timestamp_ns=5), log_time=5)
    with pytest.raises(RecordingError, match=r"nocal\.mcap: frame 0: no calibration") as error:
        list(read_frames(path))
    assert error.value.path == str(path) and error.value.frame == 0
    (restored,) = read_frames(path, intrinsics=INTRINSICS)
    assert restored.intrinsics == INTRINSICS


def test_mismatched_depth_size_names_the_frame(tmp_path: Path) -> None:
    path = tmp_path / "bad.mcap"
    frames = make_frames(3)
    with open(path, "wb") as stream, ProtobufWriter(stream) as writer:
        for frame in frames:
            stamp = frame.timestamp_ns
            depth = frame.depth if frame.index < 2 else frame.depth[: HEIGHT // 2, : WIDTH // 2]
            writer.write_message(
                "/camera/calibration",
                intrinsics_to_calibration(INTRINSICS, timestamp_ns=stamp),
                log_time=stamp,
            )
            writer.write_message(
                "/camera/color", image_to_raw(frame.color, timestamp_ns=stamp), log_time=stamp
            )
            writer.write_message(
                "/camera/depth",
                image_to_raw(np.ascontiguousarray(depth), timestamp_ns=stamp),
                log_time=stamp,
            )
    reader = read_frames(path)
    assert [next(reader).index, next(reader).index] == [0, 1]
    with pytest.raises(
        RecordingError,
        match=r"bad\.mcap: frame 2: depth 32x24 does not match "
        r"colour 64x48",
    ):
        next(reader)


def test_writer_rejects_inconsistent_frames(tmp_path: Path) -> None:
    frame = make_frames(1)[0]
    frame.depth = frame.depth.astype(np.float32)
    with RecordingWriter(tmp_path / "w.mcap") as writer, pytest.raises(ValueError, match="frame 0"):
        writer.write_frame(frame)
    with pytest.raises(ValueError, match="color_format"):
        RecordingWriter(tmp_path / "x.mcap", color_format="gif")


def test_truncated_file_yields_frames_before_the_damage(tmp_path: Path) -> None:
    frames = make_frames(10)
    path = write(tmp_path / "full.mcap", frames, chunk_size=4096)
    data = path.read_bytes()
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(data[: int(len(data) * 0.6)])
    restored = []
    with pytest.raises(RecordingError, match=r"truncated\.mcap: frame \d+: truncated") as error:
        for frame in read_frames(truncated):
            restored.append(frame)
    assert 3 <= len(restored) < 10 and error.value.frame == len(restored)
    for original, copy in zip(frames, restored, strict=False):
        np.testing.assert_array_equal(copy.depth, original.depth)
    with pytest.raises(RecordingError, match="truncated"):
        recording_info(truncated)


def test_corrupt_chunk_yields_frames_before_the_damage(tmp_path: Path) -> None:
    path = write(tmp_path / "corrupt.mcap", make_frames(10), chunk_size=4096)
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(64)
    path.write_bytes(bytes(data))
    restored = []
    with pytest.raises(RecordingError, match=r"corrupt\.mcap: frame \d+"):
        for frame in read_frames(path):
            restored.append(frame)
    assert 2 <= len(restored) < 10


def test_not_an_mcap_file(tmp_path: Path) -> None:
    path = tmp_path / "text.mcap"
    path.write_text("hello")
    with pytest.raises(RecordingError, match=r"text\.mcap"):
        list(read_frames(path))
    with pytest.raises(RecordingError, match="cannot open"):
        list(read_frames(tmp_path / "missing.mcap"))


# ------------------------------------------------------------------------------------- ROS 2


@pytest.mark.parametrize(
    ("color_encoding", "depth_encoding", "big_endian_depth"),
    [("rgb8", "16UC1", False), ("bgr8", "16UC1", True), ("rgb8", "32FC1", False)],
)
def test_ros2_bag_is_read(
    tmp_path: Path, color_encoding: str, depth_encoding: str, big_endian_depth: bool
) -> None:
    frames = make_frames(3)
    for frame in frames:
        frame.depth[0, :5] = 0  # holes: NaN in 32FC1
    path = tmp_path / "bag.mcap"
    write_ros_bag(
        path,
        frames,
        color_encoding=color_encoding,
        depth_encoding=depth_encoding,
        big_endian_depth=big_endian_depth,
    )
    restored = list(read_frames(path))
    assert [f.timestamp_ns for f in restored] == [f.timestamp_ns for f in frames]
    for original, copy in zip(frames, restored, strict=True):
        np.testing.assert_array_equal(copy.color, original.color)
        np.testing.assert_array_equal(copy.depth, original.depth)  # mm; NaN -> 0
    assert restored[0].intrinsics.fx == INTRINSICS.fx and restored[0].intrinsics.cy == 23.5
    assert restored[0].intrinsics.distortion == (0.1, 0.0, 0.0, 0.0, 0.0)
    assert recording_info(path)["frames"] == 3


def test_ros2_unsynchronised_stamps_pair_within_the_skew(tmp_path: Path) -> None:
    frames = make_frames(3)
    path = tmp_path / "skewed.mcap"
    write_ros_bag(
        path, frames, color_encoding="rgb8", depth_encoding="16UC1", depth_skew_ns=2_000_000
    )
    with pytest.raises(RecordingError, match="no colour image was paired"):
        list(read_frames(path))  # exact pairing (the default) finds no pair and says so
    restored = list(read_frames(path, max_skew_ns=5_000_000))
    assert len(restored) == 3
    np.testing.assert_array_equal(restored[2].depth, frames[2].depth)


def test_a_bag_without_camera_info_needs_camera_json_and_says_so_before_reading(
        tmp_path: Path) -> None:
    """A bag recorded without CameraInfo is refused when opened, naming the fix; with
    --camera-json its frames carry those intrinsics, and --depth-scale says its depth units."""
    import json

    from gngdt.io.sources import SourceOptions, open_source

    frames = make_frames(2)
    bag = tmp_path / "no_info.mcap"
    write_ros_bag(bag, frames, color_encoding="rgb8", depth_encoding="16UC1", camera_info=False)
    with pytest.raises(RecordingError, match=r"no calibration channel .* --camera-json FILE"):
        open_source(bag)
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps({"fx": 50.0, "fy": 51.0, "cx": 20.0, "cy": 15.0}))
    source = open_source(bag, options=SourceOptions(camera_json=camera, depth_scale=10_000))
    assert "--camera-json" in source.camera_note
    read = [frame for _, frame in source.frames()]
    assert [(k.fx, k.fy, k.cx, k.cy) for k in (frame.intrinsics for frame in read)] == [
        (50.0, 51.0, 20.0, 15.0)] * 2
    # 0.1 mm units: the recording's 16-bit values are ten times the millimetres
    expected = np.rint(frames[0].depth / 10.0).astype(np.uint16)
    np.testing.assert_array_equal(read[0].depth, expected)
    camera.write_text(json.dumps({"fx": float("nan"), "fy": 1.0, "cx": 0.0, "cy": 0.0}))
    with pytest.raises(RecordingError, match="finite"):
        open_source(bag, options=SourceOptions(camera_json=camera))
    with pytest.raises(ValueError, match="--depth-scale must be a positive"):
        SourceOptions(depth_scale=0.0)
