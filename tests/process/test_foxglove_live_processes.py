"""Live Foxglove: `gngdt run --foxglove` serves every stream on a Foxglove WebSocket, checked
with an independent client (the `websockets` package; foxglove-schemas-protobuf decodes):
a client that connects to a running pipeline gets a SceneUpdate, a PointCloud and a
FrameTransform within 5 s, the calibration too (sent again while quiet: no latched topics), on
the channels --mcap records; a port in use is an error before anything starts."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.foxglove_client import FoxgloveClient, decode
from helpers.processes import log_text

from gngdt.schemas.clouds import msg_to_cloud, transform_to_pose

REPO_ROOT = Path(__file__).resolve().parents[2]
#: what --mcap records of a run of a moving synthetic camera (the end of stream comes last)
CHANNELS = {"/camera/color", "/camera/depth", "/camera/calibration", "/camera/points", "/tf",
            "/camera/topology", "/camera/learner/status", "/camera/objects", "/camera/scene"}
WANTED = ("foxglove.SceneUpdate", "foxglove.PointCloud", "foxglove.FrameTransform",
          "foxglove.CameraCalibration")


def connect_when_served(url: str, process: subprocess.Popen, timeout_s: float) -> None:
    """Until the server at ``url`` accepts a WebSocket (the run's logger is up)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert process.poll() is None, log_text(process)
        try:
            with FoxgloveClient(url, subscribe_all=False, open_timeout=2.0):
                return
        except OSError:
            time.sleep(0.2)
    raise AssertionError(f"nothing served at {url}:\n{log_text(process)}")


def wait_for_clouds(url: str, process: subprocess.Popen, timeout_s: float) -> None:
    """Until a client receives a point cloud: capture, learner and logger are all running. A
    client that falls behind (this one, on a busy machine, takes every stream) is dropped by the
    server's guard, as designed: it connects again."""
    from websockets.exceptions import ConnectionClosed

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with FoxgloveClient(url) as client:
            try:
                while time.monotonic() < deadline:
                    assert process.poll() is None, log_text(process)
                    message = client.receive(1.0)
                    if (message is not None
                            and message.channel.schema_name == "foxglove.PointCloud"):
                        return
            except ConnectionClosed:
                continue
    raise AssertionError(f"no point cloud within {timeout_s} s:\n{log_text(process)}")


@pytest.mark.timeout(300)
def test_a_foxglove_client_gets_scene_cloud_and_transform_within_5_s(
        spawn: Callable, free_port: int, tmp_path: Path) -> None:
    url = f"ws://127.0.0.1:{free_port}"
    run = spawn("run", "synth:tabletop_walk:900", "--foxglove", "--bind",
                f"127.0.0.1:{free_port}", "--save", str(tmp_path / "run.rrd"), "--rate", "1")
    connect_when_served(url, run, 120)
    wait_for_clouds(url, run, 180)  # the first run on a machine compiles the learner's kernels
    time.sleep(2.0)  # the calibration was sent once, at the start: now only republishing has it
    decoded = {}
    with FoxgloveClient(url) as client:
        connected = time.monotonic()
        while time.monotonic() - connected < 5.0 and set(WANTED) - set(decoded):
            message = client.receive(5.0 - (time.monotonic() - connected))
            if message is not None:
                decoded.setdefault(message.channel.schema_name, (message, decode(message)))
        elapsed = time.monotonic() - connected
        topics = {channel.topic for channel in client.channels.values()}
        encodings = {channel.encoding for channel in client.channels.values()}
    run.send_signal(signal.SIGINT)
    assert set(WANTED) <= set(decoded), f"within 5 s: {sorted(decoded)}"
    assert elapsed < 5.0
    assert topics == CHANNELS and encodings == {"protobuf"}
    scene = decoded["foxglove.SceneUpdate"][1]
    assert scene.entities and {entity.frame_id for entity in scene.entities} == {"world"}
    cloud_message, cloud = decoded["foxglove.PointCloud"]
    positions, colors = msg_to_cloud(cloud)
    assert len(positions) > 1000 and colors is not None
    assert cloud_message.log_time_ns > 1.7e18  # the frame's capture time
    parent, child, matrix = transform_to_pose(decoded["foxglove.FrameTransform"][1])
    assert (parent, child) == ("world", "camera") and abs(matrix[2, 3]) > 0.1
    calibration = decoded["foxglove.CameraCalibration"][1]
    assert (calibration.width, calibration.height) == (640, 480)
    assert run.wait(60) in (0, 130), log_text(run)


def test_a_port_in_use_is_an_error_before_anything_starts(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        for command in (["run", "synth:tabletop:2", "--save", str(tmp_path / "x.rrd")],
                        ["log", "--save", str(tmp_path / "y.rrd")]):
            started = time.monotonic()
            completed = subprocess.run(
                [sys.executable, "-m", "gngdt.services.cli", *command, "--foxglove", "--bind",
                 f"127.0.0.1:{port}"], cwd=REPO_ROOT, capture_output=True, text=True,
                timeout=60, stdin=subprocess.DEVNULL)
            assert completed.returncode == 2, completed.stderr
            assert f"cannot serve Foxglove on 127.0.0.1:{port}" in completed.stderr
            assert "Traceback" not in completed.stderr
            assert time.monotonic() - started < 30
    assert not list(tmp_path.iterdir())  # no .rrd: nothing started


def test_a_client_that_stops_reading_costs_a_bounded_backlog() -> None:
    from gngdt.io.outputs.foxglove import FoxgloveServer

    server = FoxgloveServer("127.0.0.1", 0, backlog=8)
    try:
        channel = server.channel("/camera/depth", "foxglove.RawImage")
        with FoxgloveClient(f"ws://127.0.0.1:{server.port}") as client:
            deadline = time.monotonic() + 10
            while not channel.has_sinks() and time.monotonic() < deadline:
                client.receive(0.05)  # the advertisement, then our subscription
            assert channel.has_sinks()
            payload = bytes(1_000_000)
            for index in range(60):  # 60 MB while the client reads nothing
                channel.log(payload, log_time=index + 1)
            got = []
            while (message := client.receive(2.0)) is not None:
                got.append(message.log_time_ns)
    finally:
        server.stop()
    assert got[-1] == 60  # the newest is kept; the oldest were dropped
    assert len(got) < 30
