"""Broken recordings: truncated files, wrong schemas, mismatched sizes, bad depth values, missing
calibration. Each gives a clear message naming the file and the frame, and capture goes on with
the next good frame where one exists (reader's ``on_bad_frame``, and the capture process)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from helpers.raw_recordings import HEIGHT, INTRINSICS, WIDTH, RawRecording
from helpers.recordings import PERIOD_NS, START_NS

from gngdt.io.mcap.reader import RecordingError, read_frames
from gngdt.services.capture import CloudOptions, FrameToCloud


def read_skipping(path: Path) -> tuple[list, list[RecordingError]]:
    errors: list[RecordingError] = []
    frames = list(read_frames(path, on_bad_frame=errors.append))
    return frames, errors


def test_mismatched_sizes_are_skipped_and_named(tmp_path: Path) -> None:
    path = tmp_path / "mismatch.mcap"
    recording = RawRecording(path)
    for index in range(6):
        if index == 2:  # depth of another size than colour
            recording.write_frame(index, depth=np.ones((HEIGHT // 2, WIDTH // 2), np.uint16))
        elif index == 4:  # colour of another size than the calibration
            recording.write_frame(index, color=np.zeros((HEIGHT * 2, WIDTH * 2, 3), np.uint8),
                                  depth=np.ones((HEIGHT * 2, WIDTH * 2), np.uint16))
        else:
            recording.write_frame(index)
    recording.close()

    frames, errors = read_skipping(path)
    assert [frame.index for frame in frames] == [0, 1, 3, 5]
    assert [str(error) for error in errors] == [
        f"{path}: frame 2: depth 20x15 does not match colour 40x30",
        f"{path}: frame 4: calibration is for 40x30, colour is 80x60",
    ]
    with pytest.raises(RecordingError, match=r"mismatch\.mcap: frame 2: depth 20x15"):
        list(read_frames(path))  # without on_bad_frame the first bad frame stops the reading


def test_undecodable_messages_under_a_valid_schema_are_skipped(tmp_path: Path) -> None:
    path = tmp_path / "garbage.mcap"
    recording = RawRecording(path)
    recording.write_frame(0)
    recording.write_frame(1, color_bytes=b"\x0a\xff\xff\x03 not a RawImage")
    short = RawImage(width=WIDTH, height=HEIGHT, step=WIDTH * 3, encoding="rgb8", data=b"\x01")
    recording.write_frame(2, color_bytes=short.SerializeToString())
    recording.write_frame(3)
    recording.close()

    frames, errors = read_skipping(path)
    assert len(frames) == 2
    assert np.array_equal(frames[1].color, np.random.default_rng(3).integers(
        0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8))  # the frame after the bad ones, intact
    assert len(errors) == 2
    assert all(str(path) in str(error) and "/camera/color" in str(error) for error in errors)
    assert "cannot decode foxglove.RawImage" in str(errors[0])
    assert "needs 3600" in str(errors[1])


def test_wrong_schema_is_not_taken_for_images(tmp_path: Path) -> None:
    path = tmp_path / "wrong_schema.mcap"
    recording = RawRecording(path)
    stamp = START_NS
    # images written under the calibration schema: they are not images
    recording.write("/camera/color", CameraCalibration, b"", stamp)
    recording.write("/camera/depth", CameraCalibration, b"", stamp)
    recording.close()
    with pytest.raises(RecordingError, match=r"wrong_schema\.mcap: .*calibration|image channel"):
        list(read_frames(path, on_bad_frame=lambda error: None))


@pytest.mark.parametrize("encoding", ["32FC1", "16UC1"])
def test_nan_inf_negative_and_zero_depth_never_become_points(
    tmp_path: Path, encoding: str
) -> None:
    path = tmp_path / f"depth_{encoding}.mcap"
    recording = RawRecording(path)
    depth_m = np.full((HEIGHT, WIDTH), 1.5, np.float32)
    depth_m[0, :] = np.nan
    depth_m[1, :] = np.inf
    depth_m[2, :] = -np.inf
    depth_m[3, :] = -2.0
    depth_m[4, :] = 0.0
    depth_m[5, :] = 1e9  # beyond the capture's range
    valid_pixels = (HEIGHT - 6) * WIDTH
    if encoding == "16UC1":  # an unsigned format cannot hold NaN/negative: 0 and 65535 mm
        depth = np.where(np.isfinite(depth_m) & (depth_m > 0), np.minimum(depth_m * 1000, 65535),
                         0).astype(np.uint16)
        depth[1, :] = 65535
    else:
        depth = depth_m
    recording.write_frame(0, depth=depth)
    recording.close()

    (frame,) = list(read_frames(path))
    assert frame.depth.dtype == np.uint16
    positions, colors = FrameToCloud(CloudOptions(max_depth_m=10.0))(frame)
    assert len(positions) == valid_pixels
    assert np.isfinite(positions).all() and (positions[:, 2] > 0).all()
    np.testing.assert_allclose(positions[:, 2], 1.5, atol=1e-3)
    assert colors.shape == (valid_pixels, 3)


def test_missing_calibration_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "uncalibrated.mcap"
    recording = RawRecording(path)
    for index in range(3):
        recording.write_frame(index, calibration=False)
    recording.close()
    with pytest.raises(RecordingError, match=r"uncalibrated\.mcap: .*no calibration"):
        list(read_frames(path, on_bad_frame=lambda error: None))
    assert len(list(read_frames(path, intrinsics=INTRINSICS))) == 3


def test_bad_calibration_message_is_skipped_and_the_last_good_one_kept(tmp_path: Path) -> None:
    path = tmp_path / "bad_calibration.mcap"
    recording = RawRecording(path)
    recording.write_frame(0)
    uncalibrated = CameraCalibration(width=WIDTH, height=HEIGHT, K=[0.0] * 9)
    recording.write("/camera/calibration", CameraCalibration, uncalibrated.SerializeToString(),
                    START_NS + PERIOD_NS)
    recording.write_frame(1, calibration=False)
    recording.close()
    frames, errors = read_skipping(path)
    assert [frame.intrinsics for frame in frames] == [INTRINSICS, INTRINSICS]
    assert len(errors) == 1 and "uncalibrated or invalid" in str(errors[0])
    assert "bad_calibration.mcap: frame 1" in str(errors[0])


def test_truncated_file_still_ends_the_reading_after_the_good_frames(tmp_path: Path) -> None:
    path = tmp_path / "truncated.mcap"
    recording = RawRecording(path)
    for index in range(40):
        recording.write_frame(index)
    recording.close()
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    errors: list[RecordingError] = []
    reader = read_frames(path, on_bad_frame=errors.append)
    frames = []
    with pytest.raises(RecordingError, match=r"truncated\.mcap: frame \d+: (truncated|corrupt)"):
        for frame in reader:
            frames.append(frame)
    assert 0 < len(frames) < 40 and not errors
    assert [frame.index for frame in frames] == list(range(len(frames)))


