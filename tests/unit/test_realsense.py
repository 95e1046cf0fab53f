"""RealSense as a frame source: recordings the tests make with the SDK's own recorder (a known
scene, depth units of 1 mm and 0.1 mm) read back through alignment, damaged recordings refused
with the file named, and the live path on a recording the SDK lists as a connected camera."""

from __future__ import annotations

import logging
import shutil
import sqlite3
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.realsense import require_pyrealsense

require_pyrealsense()

import pyrealsense2 as rs  # noqa: E402

from gngdt.io.errors import RecordingError  # noqa: E402
from gngdt.io.realsense.sdk import unavailable_reason  # noqa: E402
from gngdt.io.realsense.stream import (  # noqa: E402
    DeviceLostError,
    DeviceNotFoundError,
    NoDeviceError,
    RealSenseError,
    color_to_rgb,
    depth_to_mm,
    list_devices,
)
from gngdt.io.sources import open_source  # noqa: E402
from gngdt.io.sources.realsense import RealSenseSource, parse_spec  # noqa: E402
from gngdt.io.synth.realsense import (  # noqa: E402
    BOX_FRONT_Y,
    BOX_RGB,
    VirtualRecording,
    known_scene,
    write_virtual_recording,
)

FRAMES = 12


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("realsense")


@pytest.fixture(scope="module", params=[0.001, 0.0001], ids=["1mm", "0.1mm"])
def recording(folder: Path, request: pytest.FixtureRequest) -> VirtualRecording:
    units = request.param
    wall_y = 1.5 if units == 0.001 else 1.23456  # sub-millimetre with 0.1 mm units
    return write_virtual_recording(folder / f"scene_{units}.db3", frames=FRAMES,
                                   depth_units=units, scene=known_scene(wall_y))


@pytest.fixture(scope="module")
def base(folder: Path) -> VirtualRecording:
    return write_virtual_recording(folder / "base.db3", frames=FRAMES)


def frames_of(source: RealSenseSource) -> list:
    return [frame for _, frame in source.frames()]


def image_ids(path: Path, like: str) -> list[int]:
    with sqlite3.connect(path) as connection:
        rows = connection.execute(
            "SELECT m.id FROM messages m JOIN topics t ON t.id = m.topic_id "
            "WHERE t.name LIKE ? ORDER BY m.timestamp", (like,)).fetchall()
    return [row[0] for row in rows]


# -- a good recording ------------------------------------------------------------------------


def test_the_sdk_writes_rosbag2_db3_and_open_source_detects_it(
        recording: VirtualRecording) -> None:
    assert recording.path.read_bytes()[:16] == b"SQLite format 3\x00"
    source = open_source(recording.path)
    assert isinstance(source, RealSenseSource) and not source.live
    assert f"{FRAMES} colour and {FRAMES} depth images" in source.describe()
    copy = recording.path.with_name("no_suffix")
    shutil.copy(recording.path, copy)
    assert isinstance(open_source(copy, "realsense"), RealSenseSource)


def test_colour_intrinsics_and_depth_units_read_back_exactly(
        recording: VirtualRecording) -> None:
    frames = frames_of(RealSenseSource(recording.path))
    color = recording.color_intrinsics
    for frame in frames:
        got = frame.intrinsics
        assert (got.fx, got.fy, got.cx, got.cy, got.width, got.height) == (
            color.fx, color.fy, color.cx, color.cy, color.width, color.height)
        assert frame.color.shape == (color.height, color.width, 3)
        assert frame.color.dtype == np.uint8 and frame.depth.dtype == np.uint16
        assert np.float32(frame.extras["depth_units_m"]) == np.float32(recording.depth_units)
    # the depth camera's intrinsics differ: alignment reprojected the depth into colour
    assert recording.depth_intrinsics.fx != color.fx


def test_the_wall_and_the_box_are_where_the_scene_puts_them(
        recording: VirtualRecording) -> None:
    frame = frames_of(RealSenseSource(recording.path))[0]
    red = np.all(frame.color == np.asarray(BOX_RGB, np.uint8), axis=-1)
    kernel = np.ones((7, 7), np.uint8)
    box = cv2.erode(red.astype(np.uint8), kernel).astype(bool)
    wall = cv2.erode((~red).astype(np.uint8), kernel).astype(bool)
    assert box.sum() > 10_000 and wall.sum() > 200_000
    wall_mm = recording.scene.primitive("wall").center[1] * 1000.0
    # aligned depth is the depth camera's z: 1 mm units are exact, 0.1 mm ones round to 1 mm
    assert np.abs(frame.depth[wall].astype(np.float64) - wall_mm).max() <= 0.5 + 1e-6
    assert np.abs(frame.depth[box].astype(np.float64) - BOX_FRONT_Y * 1000.0).max() <= 0.5


def test_every_frame_once_in_order_then_a_clean_end(recording: VirtualRecording) -> None:
    started = time.monotonic()
    frames = frames_of(RealSenseSource(recording.path, frame_timeout_s=30.0))
    assert time.monotonic() - started < 10.0  # the end is the playback's, not a timeout
    assert [frame.index for frame in frames] == list(range(FRAMES))
    assert [frame.extras["frame_number"] for frame in frames] == list(range(FRAMES))
    stamps = np.array([frame.timestamp_ns for frame in frames], dtype=np.float64)
    assert np.abs(stamps - np.asarray(recording.timestamps_ms) * 1e6).max() < 1_000
    assert {frame.extras["timestamp_domain"] for frame in frames} == {"system_time"}


def test_a_second_pass_reads_the_same_frames(base: VirtualRecording) -> None:
    source = RealSenseSource(base.path)
    first, second = frames_of(source), frames_of(source)  # capture --loop, segment's check
    assert len(first) == len(second) == FRAMES
    assert np.array_equal(first[-1].depth, second[-1].depth)


# -- damaged recordings ------------------------------------------------------------------------


def test_missing_files_and_other_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such file"):
        open_source(tmp_path / "none.db3")
    text = tmp_path / "x.db3"
    text.write_text("not a recording\n" * 100)
    with pytest.raises(RecordingError, match=r"x\.db3: not a RealSense recording"):
        open_source(text)


def test_a_db3_without_images_is_no_realsense_recording(tmp_path: Path) -> None:
    path = tmp_path / "ros2.db3"
    with sqlite3.connect(path) as connection:
        connection.executescript(
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT);"
            "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp "
            "INTEGER, data BLOB);")
    with pytest.raises(RecordingError, match=r"0 depth and 0 colour.*converted to MCAP"):
        open_source(path)


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.95])
def test_a_truncated_db3_is_refused_when_opened(base: VirtualRecording, tmp_path: Path,
                                                fraction: float) -> None:
    data = base.path.read_bytes()
    cut = tmp_path / "cut.db3"
    cut.write_bytes(data[:int(len(data) * fraction)])
    started = time.monotonic()
    with pytest.raises(RecordingError, match=r"cut\.db3: .*(damaged|malformed)"):
        open_source(cut)
    assert time.monotonic() - started < 5.0


def test_an_undecodable_image_ends_playback_and_is_reported(
        base: VirtualRecording, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    bad = tmp_path / "bad.db3"
    shutil.copy(base.path, bad)
    depth_ids = image_ids(bad, "%Depth_0/image/data%")
    with sqlite3.connect(bad) as connection:
        blob = bytearray(connection.execute("SELECT data FROM messages WHERE id=?",
                                            (depth_ids[5],)).fetchone()[0])
        at = blob.find(b"\x89PNG")
        blob[at:at + 8] = b"XXXXXXXX"  # that PNG no longer decodes
        connection.execute("UPDATE messages SET data=? WHERE id=?", (bytes(blob), depth_ids[5]))
    got = []
    with pytest.raises(RealSenseError, match=r"early, after 5 frames: 5 of 12 depth"):
        for _, frame in RealSenseSource(bad).frames():
            got.append(frame)
    assert len(got) == 5
    with caplog.at_level(logging.WARNING):
        assert len(frames_of(RealSenseSource(bad, strict=False))) == 5
    assert "stopped early, after 5 frames" in caplog.text


def test_a_gap_in_one_stream_repeats_no_frame(base: VirtualRecording, tmp_path: Path) -> None:
    gap = tmp_path / "gap.db3"
    shutil.copy(base.path, gap)
    color_ids = image_ids(gap, "%Color_0/image/data%")
    with sqlite3.connect(gap) as connection:
        connection.executemany("DELETE FROM messages WHERE id=?",
                               [(i,) for i in color_ids[3:6]])
    frames = frames_of(RealSenseSource(gap))
    assert [f.extras["frame_number"] for f in frames] == [0, 1, 2, *range(6, FRAMES)]


def test_one_stream_ending_early_is_the_end_not_damage(base: VirtualRecording,
                                                       tmp_path: Path) -> None:
    short = tmp_path / "short.db3"
    shutil.copy(base.path, short)
    depth_ids = image_ids(short, "%Depth_0/image/data%")
    with sqlite3.connect(short) as connection:
        connection.executemany("DELETE FROM messages WHERE id=?", [(i,) for i in depth_ids[-3:]])
    frames = frames_of(RealSenseSource(short))  # strict: an early stop would raise
    assert [f.extras["frame_number"] for f in frames] == list(range(FRAMES - 3))


def test_a_stalled_playback_raises(base: VirtualRecording) -> None:
    source = RealSenseSource(base.path, frame_timeout_s=0.5)
    frames = source.frames()
    next(frames)
    source._stream._playback.pause()  # the SDK's playback stops delivering
    started = time.monotonic()
    with pytest.raises(RealSenseError, match="stalled"):
        for _ in frames:
            pass
    assert time.monotonic() - started < 3.0


# -- the live path: a recording the SDK lists as a connected camera ---------------------------


def test_no_device_is_said_at_once() -> None:
    if list_devices(rs, rs.context()):
        pytest.skip("a RealSense device is connected to this machine")
    for spec in ("realsense:", "realsense:123456789"):
        started = time.monotonic()
        with pytest.raises(NoDeviceError, match="no RealSense device connected"):
            open_source(spec)
        assert time.monotonic() - started < 2.0  # starting a pipeline would wait 15 s


@pytest.fixture
def camera(folder: Path):
    """A context in which a 40-frame recording (serial SIM-0001) is a connected camera."""
    path = folder / "camera.db3"
    if not path.exists():
        write_virtual_recording(path, frames=40, serial="SIM-0001")
    context = rs.context()
    device = context.load_device(str(path))  # the context holds it while we do
    yield context, path, device
    try:
        context.unload_device(str(path))
    except RuntimeError:
        pass  # unplugged by the test


def test_a_wrong_serial_lists_the_connected_ones(camera) -> None:
    context, _, _ = camera
    with pytest.raises(DeviceNotFoundError, match=r"'nope'; connected: SIM-0001"):
        RealSenseSource("realsense:nope", context=context)


def test_a_mode_the_camera_cannot_stream_is_refused(camera) -> None:
    context, _, _ = camera
    source = RealSenseSource("realsense:SIM-0001:1280x720@30", context=context)
    with pytest.raises(RealSenseError, match=r"cannot stream .* 1280x720 at 30 fps"):
        next(source.frames())


def test_a_camera_unplugged_mid_stream_ends_it_with_a_clear_error(camera) -> None:
    context, path, _ = camera
    source = RealSenseSource("realsense:SIM-0001", context=context, frame_timeout_s=5.0)
    assert source.live and "SIM-0001" in source.describe()
    count, started = 0, time.monotonic()
    with pytest.raises(DeviceLostError, match=r"SIM-0001 was disconnected after \d+ frames"):
        for _, frame in source.frames():
            count += 1
            assert frame.intrinsics.fx == pytest.approx(615.5)
            if count == 3:
                threading.Timer(0.05, context.unload_device, args=(str(path),)).start()
    assert count >= 3 and time.monotonic() - started < 4.0


def test_a_camera_that_stops_streaming_ends_it(camera) -> None:
    context, _, _ = camera
    source = RealSenseSource("realsense:SIM-0001", context=context, frame_timeout_s=0.5)
    count = 0
    with pytest.raises(DeviceLostError, match="stopped streaming"):
        for _ in source.frames():  # the loaded recording plays its 40 frames, then nothing
            count += 1
    assert count > 0


def test_close_from_another_thread_ends_the_stream(camera) -> None:
    context, _, _ = camera
    source = RealSenseSource("realsense:SIM-0001", context=context)
    count, started = 0, time.monotonic()
    for _ in source.frames():
        count += 1
        if count == 2:
            threading.Thread(target=source.close).start()
    assert count >= 2 and time.monotonic() - started < 3.0


def test_a_live_camera_has_no_end_to_check(camera) -> None:
    context, _, _ = camera
    with pytest.raises(RecordingError, match="record it first"):
        RealSenseSource("realsense:SIM-0001", context=context).check()


# -- conversions and messages ------------------------------------------------------------------


def test_specs() -> None:
    assert parse_spec("realsense:") == (None, parse_spec("realsense:")[1])
    serial, mode = parse_spec("realsense:123:848x480@15")
    assert (serial, mode.width, mode.height, mode.fps) == ("123", 848, 480, 15)
    assert parse_spec("realsense::320x240")[1].fps == 30
    with pytest.raises(ValueError, match="WIDTHxHEIGHT"):
        parse_spec("realsense:1:big")


def test_depth_units_to_millimetres() -> None:
    raw = np.array([[0, 1, 15000, 12345, 65535]], np.uint16)
    mm, overflow = depth_to_mm(raw, float(np.float32(0.001)))
    assert overflow == 0 and mm.tolist() == raw.tolist() and mm is not raw
    mm, overflow = depth_to_mm(raw, float(np.float32(0.0001)))
    assert overflow == 0 and mm.tolist() == [[0, 0, 1500, 1234, 6553]]
    mm, overflow = depth_to_mm(raw, 0.01)  # 1 cm units: beyond 65.535 m does not fit in mm
    assert overflow == 3 and mm.tolist() == [[0, 10, 0, 0, 0]]


def test_colour_formats() -> None:
    rgb = np.random.default_rng(0).integers(0, 256, (4, 6, 3), dtype=np.uint8)
    assert np.array_equal(color_to_rgb(rs, rgb[..., ::-1].copy(), rs.format.bgr8), rgb)
    rgba = np.dstack([rgb, np.full((4, 6), 255, np.uint8)])
    assert np.array_equal(color_to_rgb(rs, rgba, rs.format.rgba8), rgb)
    assert np.array_equal(color_to_rgb(rs, rgba[..., [2, 1, 0, 3]].copy(), rs.format.bgra8), rgb)
    assert color_to_rgb(rs, np.full((4, 12), 128, np.uint8), rs.format.yuyv).shape == (4, 6, 3)


def test_what_a_user_without_the_extra_or_libusb_is_told() -> None:
    missing = ModuleNotFoundError("No module named 'pyrealsense2'", name="pyrealsense2")
    assert "pip install 'gngdt[realsense]'" in unavailable_reason(missing)
    no_libusb = ImportError("libusb-1.0.so.0: cannot open shared object file: No such file")
    assert "apt-get install libusb-1.0-0" in unavailable_reason(no_libusb)
