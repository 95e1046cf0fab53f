"""Issue 35, "say what happened", with real processes: what a child service refuses, serves,
assumes or fails to write reaches the person at `gngdt run`'s terminal, in its summary and its
exit status; a capture started by hand waits for a learner that is still compiling."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.summaries import every_frame_sent

REPO_ROOT = Path(__file__).resolve().parents[2]
GNGDT = [sys.executable, "-m", "gngdt.services.cli"]


def gngdt_run(*arguments: str, timeout_s: float = 240) -> subprocess.CompletedProcess:
    """`gngdt run ARGUMENTS` to its end (its children die with it)."""
    return subprocess.run([*GNGDT, "run", *arguments], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=timeout_s)


@pytest.fixture
def started() -> Iterator[list[subprocess.Popen]]:
    """Processes a test starts itself: each stopped by pid at teardown, pass or fail."""
    processes: list[subprocess.Popen] = []
    yield processes
    for process in processes:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def write_folder(folder: Path, recording: Path, camera: bool, metres: bool = False) -> Path:
    """A colour/ + depth/ folder of ``recording``'s frames (depth in metres as uint16 with
    ``metres``), with a camera.json (fx, fy, cx, cy, depth_scale 1000) or none."""
    from gngdt.io.mcap.reader import read_frames

    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    frames = list(read_frames(recording))
    for index, frame in enumerate(frames):
        depth = np.round(frame.depth / 1000.0).astype(np.uint16) if metres else frame.depth
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"), frame.color[..., ::-1])
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"), depth)
    if camera:
        k = frames[0].intrinsics
        (folder / "camera.json").write_text(json.dumps(
            {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "depth_scale": 1000.0}))
    return folder


# ------------------------------------------------------------------ 1: refusals
@pytest.mark.timeout(300)
def test_what_capture_refused_reaches_the_run_and_a_capture_that_sent_nothing_fails(
    tabletop_recording: Path, router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    """A --camera-json for 640x480 on 320x240 frames: capture alone exits 2 saying why (it
    used to skip every frame and exit 0); `gngdt run` prints capture's reason in its summary,
    exits 2 (capture's refusal), and leaves no .rrd behind (it learned nothing)."""
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"fx": 525, "fy": 525, "cx": 320, "cy": 240, "width": 640,
                                 "height": 480}))
    reason = "--camera-json refused: calibration is for 640x480, the images are 320x240"
    capture = spawn("capture", str(tabletop_recording), "--camera-json", str(wrong), "--fast",
                    "--realtime", "--wait-subscribers", "0", "--zenoh-connect", router_endpoint)
    assert capture.wait(120) == 2
    said = Path(capture.log_path).read_text()
    assert f"frame 0: {reason}" in said

    rrd = tmp_path / "run.rrd"
    ran = gngdt_run(str(tabletop_recording), "--camera-json", str(wrong), "--save", str(rrd))
    assert ran.returncode == 2, ran.stdout + ran.stderr
    assert f"WARNING: the reading stopped: {tabletop_recording}: frame 0: {reason}" in ran.stdout
    assert "removed: the run failed and the learner learned no frame" in ran.stdout
    assert not rrd.exists()
    assert "capture failed (exit 2)" in ran.stderr


# ------------------------------------------------------------------ 3: wrong endpoint
@pytest.mark.timeout(120)
def test_nothing_listening_at_the_ros2_endpoint_is_said_within_seconds(
    tabletop_recording: Path, free_port: int, tmp_path: Path
) -> None:
    """It took 68 s and ended with advice docs/ros2.md contradicts (`gngdt router`)."""
    started = time.monotonic()
    ran = gngdt_run(str(tabletop_recording), "--ros2", f"tcp/127.0.0.1:{free_port}", "--save",
                    str(tmp_path / "run.rrd"), timeout_s=60)
    elapsed = time.monotonic() - started
    assert ran.returncode == 2, ran.stdout + ran.stderr
    assert elapsed < 5.0 + 10.0  # said at once; Python's start on a busy machine is the margin
    said = ran.stderr
    assert f"--ros2 tcp/127.0.0.1:{free_port}: nothing listens there" in said
    assert "ros2 run rmw_zenoh_cpp rmw_zenohd" in said and "docs/ros2.md" in said
    assert "start one with `gngdt router`" not in said
    docs = (REPO_ROOT / "docs" / "ros2.md").read_text()
    assert "ros2 run rmw_zenoh_cpp rmw_zenohd" in docs and "Not `gngdt router`" in docs
    assert not (tmp_path / "run.rrd").exists()


@pytest.mark.timeout(120)
def test_the_bridge_by_hand_names_ros2s_router_when_none_answers(
    router_endpoint: str, spawn: Callable
) -> None:
    from gngdt.services.plumbing.session import free_tcp_port

    bridge = spawn("ros2", "--no-input", "--zenoh-connect", router_endpoint, "--ros2-connect",
                   f"tcp/127.0.0.1:{free_tcp_port()}", "--router-wait", "0")
    assert bridge.wait(60) == 1
    said = Path(bridge.log_path).read_text()
    assert "cannot open zenoh ROS 2 session" in said
    assert "ros2 run rmw_zenoh_cpp rmw_zenohd" in said
    assert "start one with `gngdt router`" not in said


@pytest.mark.timeout(120)
def test_a_service_by_hand_says_at_once_that_no_router_answers_and_what_to_start(
    tabletop_recording: Path, free_port: int, spawn: Callable
) -> None:
    """It keeps waiting for one (--router-wait), saying what docs/ros2.md says to start."""
    started = time.monotonic()
    learner = spawn("learn", "--zenoh-connect", f"tcp/127.0.0.1:{free_port}", "--router-wait",
                    "60")
    deadline = started + 60
    while "no zenoh router at" not in Path(learner.log_path).read_text():
        assert learner.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    said_after = time.monotonic() - started
    said = Path(learner.log_path).read_text()
    assert f"no zenoh router at tcp/127.0.0.1:{free_port} yet" in said
    assert "start one with `gngdt router`; beside ROS 2, rmw_zenohd is the router" in said
    assert "preparing the learning kernels" not in said  # said before any long work
    assert said_after < 5.0 + 15.0, said_after  # Python's start on a busy machine: the margin
    learner.send_signal(signal.SIGINT)
    assert learner.wait(30) in (0, 130)


# ------------------------------------------------------------------ 4: units and layouts
@pytest.mark.timeout(300)
def test_assumed_camera_parameters_and_implausible_depth_are_warnings_in_the_summary(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    """A folder without camera.json: every assumed parameter a WARNING naming its setter (it
    was the first log line only); depth in metres stored as uint16: the depth check's WARNING,
    the frames sent without their (empty) clouds, exit 3."""
    bare = write_folder(tmp_path / "bare", tabletop_recording, camera=False)
    ran = gngdt_run(str(bare), "--save", str(tmp_path / "bare.rrd"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    warnings = [line for line in ran.stdout.splitlines() if line.startswith("WARNING: ")]
    assert any(line.startswith("WARNING: fx=525 fy=525 cx=319.5 cy=239.5 px assumed") and
               "--camera-json" in line for line in warnings), ran.stdout
    assert any(line.startswith("WARNING: depth_scale=1000 units per metre assumed") and
               "--depth-scale" in line and "TUM's frames use 5000" in line
               for line in warnings), ran.stdout

    metres = write_folder(tmp_path / "metres", tabletop_recording, camera=True, metres=True)
    ran = gngdt_run(str(metres), "--save", str(tmp_path / "metres.rrd"))
    assert ran.returncode == 3, ran.stdout + ran.stderr
    assert re.search(r"^WARNING: the median depth is 0\.00\d m, outside the 0\.1-20 m .*"
                     r"--depth-scale", ran.stdout, re.MULTILINE), ran.stdout
    assert ("sent without cloud: 8 frames: no depth between --min-depth 0.1 m and --max-depth "
            "10 m (8)") in ran.stdout
    assert "the learner learned nothing" in ran.stderr


# ------------------------------------------------------------------ 6: writers that stop
@pytest.mark.timeout(300)
def test_an_mcap_writer_that_stopped_is_a_warning_with_its_reason_and_flag(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    """It used to leave a readable but empty MCAP, exit 0, the summary saying only (0.0 MB)."""
    mcap = tmp_path / "all.mcap"
    ran = gngdt_run(str(tabletop_recording), "--mcap", str(mcap), "--min-free-mb", "100000000",
                    "--save", str(tmp_path / "run.rrd"))
    assert ran.returncode == 4, ran.stdout + ran.stderr
    assert re.search(rf"^WARNING: recording to {re.escape(str(mcap))} stopped early: only \d+ MB "
                     r"are free on its disk \(--min-free-mb 100000000\)", ran.stdout,
                     re.MULTILINE), ran.stdout
    assert f"{mcap} stopped writing before the end" in ran.stderr


# ------------------------------------------------------------------ 2: live outputs
@pytest.mark.timeout(300)
def test_foxglove_is_said_when_up_and_serves_on_after_the_file_with_linger(
    tabletop_recording: Path, free_port: int, tmp_path: Path, started: list
) -> None:
    from helpers.foxglove_client import FoxgloveClient

    url = f"ws://127.0.0.1:{free_port}"
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        run = subprocess.Popen([*GNGDT, "run", str(tabletop_recording), "--foxglove", "--bind",
                                f"127.0.0.1:{free_port}", "--linger", "--save",
                                str(tmp_path / "run.rrd")], cwd=REPO_ROOT, stdout=output,
                               stderr=output, start_new_session=True)
    started.append(run)
    deadline = time.monotonic() + 180
    while "the file ended; still serving" not in log_path.read_text():
        assert run.poll() is None and time.monotonic() < deadline, log_path.read_text()
        time.sleep(0.1)
    said = log_path.read_text()
    up = said.index(f"serving the Foxglove WebSocket at {url} (open it in Foxglove")
    assert up < said.index("replaying")  # said once the server is up, before the stream
    assert "Open connection > Foxglove WebSocket > " + url in said
    schemas = set()
    with FoxgloveClient(url) as client:  # the file is over, the server still serves it
        until = time.monotonic() + 30
        while "gngdt.Topology" not in schemas and time.monotonic() < until:
            message = client.receive(1.0)
            if message is not None:
                schemas.add(message.channel.schema_name)
    assert "gngdt.Topology" in schemas, schemas  # the last network, again for a late client
    run.send_signal(signal.SIGINT)  # the end of lingering, not of the run's work
    assert run.wait(60) == 0, log_path.read_text()
    summary = log_path.read_text()
    assert f"foxglove:           {url} (open it in Foxglove" in summary
    assert "served after the file ended too (--linger)" in summary


@pytest.mark.timeout(300)
def test_served_viewer_is_said_and_the_summary_describes_what_was_served(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    from gngdt.services.plumbing.session import free_tcp_port

    web, grpc = free_tcp_port(), free_tcp_port()
    ran = gngdt_run(str(tabletop_recording), "--serve", "--web-port", str(web), "--grpc-port",
                    str(grpc), "--linger", "2")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    page = (f"http://127.0.0.1:{web}?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy")
    assert f"serving the rerun web viewer at {page}" in ran.stderr
    assert f"web viewer:         {page}" in ran.stdout
    assert "rerun:              served by --serve, not saved" in ran.stdout
    assert ".rrd" not in ran.stdout.split("rerun:")[1].split("\n")[1]  # no file described
    assert "  to the viewer:" in ran.stdout and "in the .rrd" not in ran.stdout


@pytest.mark.timeout(300)
def test_a_served_page_answers_while_the_run_lingers(
    tabletop_recording: Path, tmp_path: Path, started: list
) -> None:
    from gngdt.services.plumbing.session import free_tcp_port

    web, grpc = free_tcp_port(), free_tcp_port()
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        run = subprocess.Popen([*GNGDT, "run", str(tabletop_recording), "--serve", "--web-port",
                                str(web), "--grpc-port", str(grpc), "--linger"], cwd=REPO_ROOT,
                               stdout=output, stderr=output, start_new_session=True)
    started.append(run)
    deadline = time.monotonic() + 180
    while "the file ended; still serving" not in log_path.read_text():
        assert run.poll() is None and time.monotonic() < deadline, log_path.read_text()
        time.sleep(0.1)
    page = re.search(r"still serving the rerun web viewer at (\S+)", log_path.read_text())
    with urllib.request.urlopen(page.group(1), timeout=30) as response:
        assert response.status == 200
    run.send_signal(signal.SIGINT)
    assert run.wait(60) == 0, log_path.read_text()


@pytest.mark.timeout(300)
def test_without_linger_the_summary_says_the_server_closed_and_how_to_keep_it(
    tabletop_recording: Path, free_port: int, tmp_path: Path
) -> None:
    ran = gngdt_run(str(tabletop_recording), "--foxglove", "--bind", f"127.0.0.1:{free_port}",
                    "--save", str(tmp_path / "run.rrd"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert (f"foxglove:           ws://127.0.0.1:{free_port}" in ran.stdout)
    assert ("closed when the file ended; --linger keeps it serving after the file ends (until "
            "Ctrl-C; --linger 60: a minute)") in ran.stdout


@pytest.mark.timeout(300)
def test_ros2_has_a_summary_line(
    tabletop_recording: Path, router_endpoint: str, tmp_path: Path
) -> None:
    """The ROS 2 side here is a zenoh router on loopback (nothing of ROS 2 runs here): the line
    names the node, the router used, the topics and what went out."""
    ran = gngdt_run(str(tabletop_recording), "--ros2", router_endpoint, "--save",
                    str(tmp_path / "run.rrd"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    line = next(line for line in ran.stdout.splitlines() if line.startswith("ros2:"))
    assert f"node /gngdt_camera (domain 0) on the router at {router_endpoint}:" in line, line
    counts = re.search(r": (\d+) messages? out \((.*?)\)", line)
    published = dict(item.split() for item in counts.group(2).split(", "))
    assert int(counts.group(1)) == sum(int(value) for value in published.values())
    assert int(published["status"]) >= 1  # the bridge's diagnostics go out whoever listens
    assert "/gngdt/camera/points" in line and "/gngdt/camera/graph" in line


# ------------------------------------------------------------------ 5: counts that add up
@pytest.mark.timeout(300)
@pytest.mark.parametrize("mode", [(), ("--realtime", "--fast"), ("--track", "--realtime")])
def test_every_frame_sent_is_accounted_for_in_every_mode(
    mode: tuple[str, ...], tabletop_recording: Path, tmp_path: Path
) -> None:
    ran = gngdt_run(str(tabletop_recording), *mode, "--save", str(tmp_path / "run.rrd"))
    assert ran.returncode in (0, 3), ran.stdout + ran.stderr
    sent, terms = every_frame_sent(ran.stdout)
    assert sent == 8 == sum(terms.values()), ran.stdout
    assert {"learned", "dropped", "malformed", "refused"} <= set(terms)
    learned = int(re.search(r"frames learned:\s+(\d+) of 8 sent", ran.stdout).group(1))
    assert learned == terms["learned"] >= 1
    if not mode:  # a file read frame by frame: every frame learned
        assert terms == {"learned": 8, "dropped": 0, "malformed": 0, "refused": 0}


# ------------------------------------------------------------------ 5: a learner compiling
@pytest.mark.timeout(900)
def test_a_capture_by_hand_waits_for_a_learner_still_compiling_its_kernels(
    tabletop_recording: Path, router_endpoint: str, tmp_path: Path, started: list
) -> None:
    """A learner on a cold kernel cache (its own, empty NUMBA_CACHE_DIR) compiles for a
    minute or more, announced (its instance token) but not yet taking frames; a capture
    waiting only --wait-learner 2 s used to replay the whole file before it listened. It now
    waits for it, says so every 10 s, and every frame is learned."""
    from gngdt.schemas.status import decode_status
    from gngdt.services.plumbing.session import client_config, open_config

    statuses: list = []
    watcher = open_config(client_config([router_endpoint]))
    watcher.declare_subscriber("gngdt/camera/learner/status", lambda sample: statuses.append(
        decode_status(sample.payload.to_bytes())))
    logs = {name: tmp_path / f"{name}.log" for name in ("learn", "capture")}
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cold-numba-cache")}
    try:
        with open(logs["learn"], "wb") as output:
            learner = subprocess.Popen(
                [*GNGDT, "learn", "--exit-on-eos", "--zenoh-connect", router_endpoint],
                cwd=REPO_ROOT, stdout=output, stderr=output, start_new_session=True,
                env=environment)
        started.append(learner)
        deadline = time.monotonic() + 120
        while "preparing the learning kernels" not in logs["learn"].read_text():
            assert learner.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        with open(logs["capture"], "wb") as output:
            capture = subprocess.Popen(
                [*GNGDT, "capture", str(tabletop_recording), "--fast", "--wait-learner", "2",
                 "--zenoh-connect", router_endpoint], cwd=REPO_ROOT, stdout=output,
                stderr=output, start_new_session=True)
        started.append(capture)
        assert capture.wait(800) == 0, logs["capture"].read_text()
        assert learner.wait(120) == 0, logs["learn"].read_text()
    finally:
        watcher.close()
    learned = logs["learn"].read_text()
    compile_s = float(re.search(r"kernels ready in ([\d.]+) s", learned).group(1))
    said = logs["capture"].read_text()
    assert "no learner of camera" not in said  # it never gave up on it
    if compile_s > 15:  # long enough for the wait to be said at least once
        assert ("waiting for the learner of camera 'camera': it is starting (compiling its "
                "kernels") in said, said
    assert "every frame once the learner took the one before" in said
    assert statuses and statuses[-1].frames_used == 8, [s.frames_used for s in statuses]
