"""Calibrations with finite but absurd values (issue 38): a principal point 1e30 px off the image,
a focal length of 1e-30 px, a size that is not the images'. Every door that accepts a
calibration refuses them with one check (`CameraIntrinsics.problem`), says why, and nothing is
deprojected with them: foxglove CameraCalibration and ROS CameraInfo messages, MCAP recordings,
camera.json and --camera-json."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from mcap_protobuf.writer import Writer

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.errors import RecordingError
from gngdt.io.images import iter_image_frames, load_camera, read_camera_json
from gngdt.io.mcap.reader import read_frames
from gngdt.io.ros2.messages import CameraInfo, Ros2MessageError, decode_camera_info
from gngdt.schemas.images import (
    calibration_to_intrinsics,
    image_to_raw,
    intrinsics_from_k,
    intrinsics_to_calibration,
)
from gngdt.schemas.messages import MessageError

WIDTH, HEIGHT = 64, 48
GOOD = CameraIntrinsics(WIDTH, HEIGHT, 60.0, 60.0, 31.5, 23.5)
START_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333
#: each attack of the issue (and its neighbours), with what the refusal names
ABSURD = {
    "cx far left": (dict(cx=-1e30), "principal point cx"),
    "cy far below": (dict(cy=1e12), "principal point cy"),
    "fx 1e-300": (dict(fx=1e-300), "field of view"),
    "fx 1e-30": (dict(fx=1e-30), "field of view"),
    "fy a telescope": (dict(fy=1e30), "field of view"),
    "cx nan": (dict(cx=float("nan")), "finite"),
    "cy inf": (dict(cy=float("inf")), "finite"),
    "fx negative": (dict(fx=-60.0), "positive"),
}


def absurd(name: str) -> CameraIntrinsics:
    changes, _ = ABSURD[name]
    values = {"width": WIDTH, "height": HEIGHT, "fx": 60.0, "fy": 60.0, "cx": 31.5, "cy": 23.5}
    return CameraIntrinsics(**{**values, **changes})


def k_of(intrinsics: CameraIntrinsics) -> list[float]:
    return [intrinsics.fx, 0.0, intrinsics.cx, 0.0, intrinsics.fy, intrinsics.cy, 0.0, 0.0, 1.0]


def test_a_real_camera_passes() -> None:
    assert GOOD.problem() == "" and GOOD.problem((WIDTH, HEIGHT)) == ""
    d435 = CameraIntrinsics(640, 480, 615.5, 615.75, 318.6, 242.4)
    wide = CameraIntrinsics(1280, 720, 380.0, 380.0, 640.0, 360.0)  # ~118 degrees across
    assert d435.problem() == "" and wide.problem() == ""


@pytest.mark.parametrize("name", sorted(ABSURD))
def test_the_check_names_what_is_wrong(name: str) -> None:
    assert ABSURD[name][1] in absurd(name).problem()


def test_a_calibration_for_other_images_is_refused() -> None:
    assert "the images are 32x24" in GOOD.problem((32, 24))


@pytest.mark.parametrize("name", sorted(ABSURD))
def test_a_foxglove_calibration_with_absurd_values_is_refused(name: str) -> None:
    """The capture's own topic and MCAP recordings: before, cx=-1e30 was accepted and its
    clouds published 5e27 m away."""
    message = intrinsics_to_calibration(absurd(name), timestamp_ns=1)
    with pytest.raises(MessageError, match=ABSURD[name][1]):
        calibration_to_intrinsics(message.SerializeToString())
    with pytest.raises(MessageError, match=ABSURD[name][1]):
        intrinsics_from_k(WIDTH, HEIGHT, k_of(absurd(name)), ())


@pytest.mark.parametrize("name", sorted(ABSURD))
def test_a_ros_camera_info_with_absurd_values_is_refused(name: str) -> None:
    from gngdt.io.ros2.messages import encode_camera_info

    payload = encode_camera_info(CameraInfo(1, "camera", absurd(name)))
    with pytest.raises(Ros2MessageError, match=ABSURD[name][1]):
        decode_camera_info(payload)
    assert decode_camera_info(encode_camera_info(CameraInfo(1, "camera", GOOD))).intrinsics \
        == GOOD


def write_recording(path: Path, calibrations: list[CameraIntrinsics]) -> Path:
    """An MCAP of one frame per calibration (each frame's calibration, colour and depth)."""
    rng = np.random.default_rng(0)
    with open(path, "wb") as stream:
        writer = Writer(stream)
        for index, intrinsics in enumerate(calibrations):
            stamp = START_NS + index * PERIOD_NS
            color = rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
            depth = rng.integers(500, 3000, (HEIGHT, WIDTH), dtype=np.uint16)
            for topic, message in (
                    ("/camera/calibration", intrinsics_to_calibration(intrinsics,
                                                                      timestamp_ns=stamp)),
                    ("/camera/color", image_to_raw(color, timestamp_ns=stamp)),
                    ("/camera/depth", image_to_raw(depth, timestamp_ns=stamp))):
                writer.write_message(topic, message, log_time=stamp, publish_time=stamp)
        writer.finish()
    return path


def test_a_recording_calibrated_with_fx_1e_30_yields_no_frame(tmp_path: Path) -> None:
    """Before, its frames were read with fx = 1e-30 (clouds ~1e31 m wide)."""
    path = write_recording(tmp_path / "tiny_fx.mcap", [absurd("fx 1e-30")] * 3)
    with pytest.raises(RecordingError, match=r"tiny_fx\.mcap: frame 0: .*field of view"):
        list(read_frames(path))
    errors: list[RecordingError] = []
    with pytest.raises(RecordingError, match="no calibration") as refused:
        list(read_frames(path, on_bad_frame=errors.append))
    assert len(errors) == 1  # said once, not once per CameraInfo
    assert "3 calibration messages were refused" in str(refused.value)


def test_a_bad_calibration_between_good_ones_is_skipped_and_the_good_one_kept(
        tmp_path: Path) -> None:
    path = write_recording(tmp_path / "mixed.mcap", [GOOD, absurd("cx far left"),
                                                     absurd("cy far below"), GOOD])
    errors: list[RecordingError] = []
    frames = list(read_frames(path, on_bad_frame=errors.append))
    assert [frame.intrinsics for frame in frames] == [GOOD] * 4
    assert len(errors) == 1 and "principal point cx" in str(errors[0])


def test_a_camera_json_with_absurd_values_is_refused(tmp_path: Path) -> None:
    """An image folder's camera.json: fx, fy, cx, cy judged against its images' size."""
    import cv2

    folder = tmp_path / "redwood"
    for sub in ("color", "depth"):
        (folder / sub).mkdir(parents=True)
    cv2.imwrite(str(folder / "color" / "000000.png"), np.zeros((HEIGHT, WIDTH, 3), np.uint8))
    cv2.imwrite(str(folder / "depth" / "000000.png"), np.full((HEIGHT, WIDTH), 900, np.uint16))
    (folder / "camera.json").write_text(json.dumps({"fx": 60, "fy": 60, "cx": -1e30, "cy": 23}))
    camera = load_camera(folder, "redwood")  # the size is the images': known once read
    with pytest.raises(RecordingError, match=r"000000\.png: frame 0: .*principal point cx"):
        list(iter_image_frames(folder, "redwood", camera=camera))
    (folder / "camera.json").write_text(json.dumps(
        {"fx": 1e-30, "fy": 60, "cx": 32, "cy": 24, "width": WIDTH, "height": HEIGHT}))
    with pytest.raises(RecordingError, match=r"camera\.json: .*field of view"):
        load_camera(folder, "redwood")  # with a size: refused when read


def test_camera_json_for_a_recording_with_absurd_values_is_refused(tmp_path: Path) -> None:
    """``--camera-json`` (a bag recorded without CameraInfo)."""
    path = tmp_path / "camera.json"
    path.write_text(json.dumps({"fx": 60, "fy": 60, "cx": 32, "cy": 1e12}))
    camera = read_camera_json(path)
    recording = write_recording(tmp_path / "good.mcap", [GOOD])
    with pytest.raises(RecordingError, match=r"--camera-json refused: .*principal point cy"):
        list(read_frames(recording, camera=camera))
    skipped: list[RecordingError] = []  # not a bad frame to skip: no frame can be read with it
    with pytest.raises(RecordingError, match=r"--camera-json refused"):
        list(read_frames(recording, camera=camera, on_bad_frame=skipped.append))
    assert not skipped


def test_assumed_default_intrinsics_are_scaled_to_the_images(tmp_path: Path, caplog) -> None:
    """A folder without camera.json: the format's 640x480 defaults, scaled to its images (at
    64 px wide, fx 525 would be a field of view of 7 degrees)."""
    import cv2

    folder = tmp_path / "redwood"
    for sub in ("color", "depth"):
        (folder / sub).mkdir(parents=True)
    cv2.imwrite(str(folder / "color" / "000000.png"), np.zeros((HEIGHT, WIDTH, 3), np.uint8))
    cv2.imwrite(str(folder / "depth" / "000000.png"), np.full((HEIGHT, WIDTH), 900, np.uint16))
    with caplog.at_level(logging.WARNING):
        (frame,) = list(iter_image_frames(folder, "redwood"))
    intrinsics = frame.intrinsics
    np.testing.assert_allclose([intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy],
                               [52.5, 52.5, 31.95, 23.95])
