"""RealSense through the commands: recordings the tests make with the SDK's recorder replayed
by `gngdt run`, `capture` and `segment` like any recording (the learned network lies on the
known scene's surfaces), legacy .bag files converted in a child process, and a camera that is
missing or lost: a clear message, a clean exit, the recording so far kept."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from helpers.realsense import DATA, require_pyrealsense

require_pyrealsense()

import pyrealsense2 as rs  # noqa: E402

from gngdt.io.errors import RecordingError  # noqa: E402
from gngdt.io.realsense.stream import DeviceLostError, list_devices  # noqa: E402
from gngdt.io.sources.realsense import RealSenseSource  # noqa: E402
from gngdt.io.synth.realsense import (  # noqa: E402
    BOX_FRONT_Y,
    BOX_SIZE,
    WALL_Y,
    VirtualRecording,
    d435_like_intrinsics,
    write_virtual_recording,
)

REPO_ROOT = Path(__file__).resolve().parents[2]


def gngdt(*arguments: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gngdt.services.cli", *arguments], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def known(tmp_path_factory: pytest.TempPathFactory) -> VirtualRecording:
    """20 frames of the wall and the box, 0.1 mm depth units (a D405-like camera)."""
    folder = tmp_path_factory.mktemp("realsense-run")
    return write_virtual_recording(folder / "known.db3", frames=20, depth_units=0.0001)


def no_camera() -> None:
    if list_devices(rs, rs.context()):
        pytest.skip("a RealSense device is connected to this machine")


def surface_distance(points_world: np.ndarray) -> np.ndarray:
    """(N,) metres from each point to the nearest surface of the known scene: the wall plane,
    or the box's surface (the box's signed distance, taken absolute)."""
    to_wall = np.abs(points_world[:, 1] - WALL_Y)
    center = np.array([0.0, BOX_FRONT_Y + BOX_SIZE[1] / 2, 0.0])
    q = np.abs(points_world - center) - np.asarray(BOX_SIZE) / 2
    signed = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    return np.minimum(to_wall, np.abs(signed))


@pytest.mark.timeout(300)
def test_run_on_a_realsense_recording_learns_the_known_surfaces(known: VirtualRecording,
                                                                tmp_path: Path) -> None:
    from mcap.reader import make_reader

    from gngdt.schemas.topology import decode_topology

    mcap = tmp_path / "run.mcap"
    completed = gngdt("run", str(known.path), "--save", str(tmp_path / "run.rrd"),
                      "--mcap", str(mcap), "--rate", "0.5")
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "frames sent:        20" in completed.stdout
    with open(mcap, "rb") as stream:
        topologies = [message.data for _, channel, message in make_reader(stream).iter_messages()
                      if channel.topic == "/camera/topology"]
    final = decode_topology(topologies[-1])  # the learner's network after the last frame
    assert final.frame_id == "camera" and final.node_count > 200
    pose = known.color_pose  # no poses in the recording: nodes in the colour camera's frame
    world = final.positions.astype(np.float64) @ pose[:3, :3].T + pose[:3, 3]
    distances = surface_distance(world)
    assert distances.max() < 0.01, f"{(distances >= 0.01).sum()} nodes off the surfaces, " \
        f"up to {distances.max() * 1000:.1f} mm"
    on_box = np.abs(world[:, 1] - BOX_FRONT_Y) < 0.01
    assert 10 < on_box.sum() < final.node_count - 100  # nodes on both the box and the wall


@pytest.mark.timeout(200)
def test_segment_reads_a_realsense_recording(known: VirtualRecording, tmp_path: Path) -> None:
    completed = gngdt("segment", str(known.path), "--out", str(tmp_path / "seg"))
    assert completed.returncode == 0, completed.stderr
    summary = json.loads((tmp_path / "seg" / "summary.json").read_text())
    assert summary["frames"] == 20 and summary["format"] == "realsense"
    assert summary["intrinsics"]["fx"] == known.color_intrinsics.fx
    assert len(list((tmp_path / "seg").glob("0000*.png"))) == 20


def test_a_legacy_bag_is_converted_and_reads_every_frame() -> None:
    # made by pyrealsense2 2.57.7, the last SDK writing ROS 1 .bag (tests/data/realsense)
    source = RealSenseSource(DATA / "legacy_64x48_3frames.bag")
    frames = [frame for _, frame in source.frames()]
    source.close()
    _, color = d435_like_intrinsics(64, 48)
    assert len(frames) == 3  # played directly, the SDK loses the first frameset
    got = frames[0].intrinsics
    assert (got.fx, got.fy, got.cx, got.cy, got.width, got.height) == (
        color.fx, color.fy, color.cx, color.cy, 64, 48)


def test_a_bag_that_hangs_the_sdk_is_contained() -> None:
    # the SDK's ROS 1 reader loops forever on this fuzzed copy, holding the GIL
    source = RealSenseSource(DATA / "corrupt_legacy_sdk_loops.bag", convert_timeout_s=3.0)
    started = time.monotonic()
    with pytest.raises(RecordingError, match=r"did not finish reading this legacy \.bag"):
        next(source.frames())
    assert time.monotonic() - started < 10.0


def test_a_truncated_legacy_bag_is_refused(tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    cut.write_bytes((DATA / "legacy_64x48_3frames.bag").read_bytes()[:20_000])
    with pytest.raises(RecordingError, match=r"cut\.bag: unreadable legacy \.bag"):
        next(RealSenseSource(cut).frames())


@pytest.mark.parametrize("command", [
    ("capture", "--realsense"), ("capture", "--realsense", "123456789012"),
    ("run", "--realsense"), ("record", "realsense", "--out", "{tmp}/x.mcap")])
def test_without_a_camera_each_command_says_so_and_starts_nothing(command: tuple,
                                                                  tmp_path: Path) -> None:
    no_camera()
    started = time.monotonic()
    completed = gngdt(*(part.format(tmp=tmp_path) for part in command), "--log-level",
                      "WARNING", timeout=60)
    assert completed.returncode == 2, completed.stderr
    assert "no RealSense device connected" in completed.stderr
    assert "Traceback" not in completed.stderr
    assert time.monotonic() - started < 30  # no 15 s SDK wait, no service started
    assert not (tmp_path / "x.mcap").exists()


@pytest.fixture(scope="module")
def camera_recording(tmp_path_factory: pytest.TempPathFactory) -> VirtualRecording:
    """3 s of the known scene at 320x240: what a simulated camera plays, in real time."""
    folder = tmp_path_factory.mktemp("realsense-camera")
    return write_virtual_recording(folder / "camera.db3", frames=90, width=320, height=240)


@pytest.fixture
def camera(camera_recording: VirtualRecording):
    """A context in which a recording (serial SIM-0001) is a connected camera."""
    path = camera_recording.path
    context = rs.context()
    device = context.load_device(str(path))  # the context holds it while we do
    yield context, path
    del device
    try:
        context.unload_device(str(path))
    except RuntimeError:
        pass  # unplugged by the test


def unplug_after(source: RealSenseSource, context, path: Path, frames: int) -> None:
    """Unplug the simulated camera once ``source`` has delivered ``frames`` frames."""
    def watch() -> None:
        while source._stream is None or source._stream.frames_read < frames:
            time.sleep(0.01)
        context.unload_device(str(path))

    threading.Thread(target=watch, daemon=True).start()


def test_record_keeps_what_a_lost_camera_gave(camera, tmp_path: Path) -> None:
    from gngdt.io.mcap.reader import read_frames
    from gngdt.services.cli import build_parser
    from gngdt.services.record import record_realsense

    context, path = camera
    source = RealSenseSource("realsense:SIM-0001:320x240@30", context=context)
    unplug_after(source, context, path, 2)
    args = build_parser().parse_args(["record", "realsense", "--out", str(tmp_path / "x.mcap")])
    assert record_realsense(source, args) == 1  # the camera was lost
    frames = list(read_frames(tmp_path / "x.mcap"))  # a complete, indexed file
    assert len(frames) >= 2
    assert frames[0].intrinsics.fx == pytest.approx(307.75)
    assert frames[0].depth.max() == 1500


@pytest.mark.timeout(120)
def test_capture_ends_the_stream_when_its_camera_is_lost(camera, router_endpoint: str) -> None:
    from gngdt.io.deproject import CloudOptions, FrameToCloud
    from gngdt.schemas.status import decode_stream_end
    from gngdt.services.capture import capture
    from gngdt.services.cli import build_parser
    from gngdt.services.plumbing.session import client_config, open_config, open_session
    from gngdt.services.replay_clock import ReplayClock

    context, path = camera
    ends: list = []
    listener = open_config(client_config([router_endpoint]))
    listener.declare_subscriber("gngdt/camera/eos", lambda sample: ends.append(
        decode_stream_end(sample.payload.to_bytes())))
    args = build_parser().parse_args(["capture", "--realsense", "SIM-0001", "--zenoh-connect",
                                      router_endpoint, "--wait-subscribers", "0"])
    source = RealSenseSource("realsense:SIM-0001:320x240@30", context=context)
    unplug_after(source, context, path, 2)
    session = open_session(args)
    try:
        replay = capture(args, source, ReplayClock(None), FrameToCloud(CloudOptions()), session)
    finally:
        session.close()
    deadline = time.monotonic() + 10
    while not ends and time.monotonic() < deadline:
        time.sleep(0.05)
    listener.close()
    assert isinstance(replay.error, DeviceLostError)
    assert "SIM-0001 was disconnected" in str(replay.error)
    assert replay.frames_read >= 2
    assert ends and ends[0].frames_sent == replay.frames_read  # the stream ended cleanly


def test_record_converts_a_realsense_recording(known: VirtualRecording, tmp_path: Path) -> None:
    from gngdt.io.mcap.reader import read_frames

    out = tmp_path / "known.mcap"
    completed = gngdt("record", "realsense", "--from", str(known.path), "--out", str(out))
    assert completed.returncode == 0, completed.stderr
    frames = list(read_frames(out))
    assert len(frames) == 20
    assert frames[0].intrinsics.fx == known.color_intrinsics.fx
